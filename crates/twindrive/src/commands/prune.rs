//! `twindrive prune`: redundancy removal alone, on any path file.

use std::io::Write;
use std::path::Path;

use anyhow::{Context, bail};
use twindrive_kinematics::Pose;
use twindrive_mission::PathSample;
use twindrive_mission::redundancy::{DeletionReason, RedundancyConfig, remove_redundancy};

use crate::output::Staging;

/// Reads `t,x,y,theta` CSV or TUM; velocities from the displacement along
/// the heading (negative when reversing).
pub fn read_path(path: &Path) -> anyhow::Result<Vec<PathSample>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text
        .lines()
        .enumerate()
        .skip_while(|(_, l)| l.trim().is_empty());
    let first = lines.clone().next().map_or("", |(_, l)| l);
    let mut samples: Vec<PathSample> = Vec::new();
    if first.trim_start().starts_with('t') {
        let (header_line, header) = lines.next().expect("a first line");
        let cols: Vec<&str> = header.split(',').map(str::trim).collect();
        if cols.len() < 4 || cols[..4] != ["t", "x", "y", "theta"] {
            bail!(
                "{}, line {}: expected the header `t,x,y,theta`, found `{header}`",
                path.display(),
                header_line + 1
            );
        }
        for (i, line) in lines {
            if line.trim().is_empty() {
                continue;
            }
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            let mut v = [0.0; 4];
            for (c, slot) in v.iter_mut().enumerate() {
                let text = fields.get(c).copied().unwrap_or("");
                *slot = text
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .with_context(|| {
                        format!(
                            "{}, line {}, column `{}`: expected a finite number, found `{text}`",
                            path.display(),
                            i + 1,
                            cols[c]
                        )
                    })?;
            }
            samples.push(PathSample {
                t_s: v[0],
                pose: Pose::new(v[1], v[2], v[3]),
                v_m_s: 0.0,
                omega_rad_s: 0.0,
            });
        }
    } else {
        for (t_ns, pose) in twindrive_log::read_tum(path)? {
            samples.push(PathSample {
                t_s: t_ns as f64 * 1e-9,
                pose,
                v_m_s: 0.0,
                omega_rad_s: 0.0,
            });
        }
    }
    if samples.is_empty() {
        bail!("{}: no path samples", path.display());
    }
    for k in 0..samples.len().saturating_sub(1) {
        let (a, b) = (samples[k], samples[k + 1]);
        let dt = b.t_s - a.t_s;
        if dt <= 0.0 {
            bail!(
                "{}: sample {} at t = {} s is not after the previous one (t = {} s)",
                path.display(),
                k + 1,
                b.t_s,
                a.t_s
            );
        }
        let (s, c) = a.pose.heading_rad.sin_cos();
        let along = (b.pose.x_m - a.pose.x_m) * c + (b.pose.y_m - a.pose.y_m) * s;
        samples[k].v_m_s = along / dt;
        samples[k].omega_rad_s =
            twindrive_kinematics::wrap_angle(b.pose.heading_rad - a.pose.heading_rad) / dt;
    }
    Ok(samples)
}

pub fn run(
    path: &Path,
    pinch_distance: f64,
    min_loop_length: Option<f64>,
    min_loop_duration: f64,
    keep_reversals: bool,
    out: &Path,
) -> anyhow::Result<()> {
    let mut cfg = RedundancyConfig::with_pinch_distance(pinch_distance);
    cfg.min_loop_length_m = min_loop_length;
    cfg.min_loop_duration_s = min_loop_duration;
    cfg.reversing_is_redundant = !keep_reversals;
    cfg.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    let samples = read_path(path)?;
    let pruned = remove_redundancy(&samples, &cfg)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let kept = pruned.apply(&samples);
    let (dir, _, file_name) = crate::output::split_out_path(out, "pruned")?;
    let staging = Staging::new(&dir, "prune")?;
    staging.write_with(&file_name, |w| {
        let mut buf = ryu::Buffer::new();
        writeln!(w, "t,x,y,theta")?;
        for s in &kept {
            let row = [s.t_s, s.pose.x_m, s.pose.y_m, s.pose.heading_rad];
            for (k, v) in row.iter().enumerate() {
                if k > 0 {
                    w.write_all(b",")?;
                }
                w.write_all(buf.format(*v).as_bytes())?;
            }
            w.write_all(b"\n")?;
        }
        Ok(())
    })?;
    staging.commit()?;
    let count = |r: DeletionReason| pruned.deletions.iter().filter(|d| d.reason == r).count();
    // From +0.0: an empty float sum is -0.0, which would print as "-0.00".
    let removed_m = pruned.deletions.iter().fold(0.0, |a, d| a + d.length_m);
    writeln!(
        std::io::stdout().lock(),
        "removed {} loop(s), {} crossing loop(s) and {} reversal kink(s) ({:.2} m of {:.2} m); kept {} of {} samples -> {}",
        count(DeletionReason::Loop),
        count(DeletionReason::Crossing),
        count(DeletionReason::Reversal),
        removed_m,
        twindrive_mission::path_length_m(&samples),
        kept.len(),
        samples.len(),
        out.display()
    )?;
    Ok(())
}
