//! `twindrive prune`: redundancy removal alone, on any path file.

use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;

use anyhow::{Context, bail};
use twindrive_kinematics::Pose;
use twindrive_mission::PathSample;
use twindrive_mission::redundancy::{
    DeletionReason, Pruned, RedundancyConfig, remove_redundancy, route_coverage,
};

use crate::cli::PruneArgs;
use crate::usage::OrUsage;
use twindrive_files::Staging;

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

pub fn run(args: &PruneArgs) -> anyhow::Result<()> {
    let (path, out) = (&args.path, &args.out);
    let mut cfg = RedundancyConfig::with_pinch_distance(args.pinch_distance);
    args.redundancy.apply(&mut cfg);
    cfg.validate().or_usage()?;
    let samples = read_path(path)?;
    let pruned = remove_redundancy(&samples, &cfg)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let kept = pruned.apply(&samples);
    let coverage = route_coverage(&samples, &kept, pruned.coverage_radius_m)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    write_file(out, "pruned", "prune", |w| {
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
    if let Some(file) = &args.details {
        write_file(file, "prune_details", "prune-details", |w| {
            Ok(w.write_all(details(&pruned).as_bytes())?)
        })?;
    }
    let count = |r: DeletionReason| pruned.deletions.iter().filter(|d| d.reason == r).count();
    // From +0.0: an empty float sum is -0.0, which would print as "-0.00".
    let removed_m = pruned.deletions.iter().fold(0.0, |a, d| a + d.length_m);
    let trailing_m = pruned
        .deletions
        .iter()
        .filter(|d| d.reason == DeletionReason::TrailingRetrace)
        .fold(0.0, |a, d| a + d.length_m);
    let mut o = std::io::stdout().lock();
    writeln!(
        o,
        "removed {} loop(s), {} crossing loop(s), {} reversal kink(s) and {:.2} m of trailing retrace ({:.2} m of {:.2} m); kept {} of {} samples -> {}",
        count(DeletionReason::Loop),
        count(DeletionReason::Crossing),
        count(DeletionReason::Reversal),
        trailing_m,
        removed_m,
        coverage.route_length_m,
        kept.len(),
        samples.len(),
        out.display()
    )?;
    writeln!(
        o,
        "coverage within {} m: {:.2} % of the input's length, {:.3} m uncovered; output {:.2} m",
        coverage.radius_m, coverage.covered_percent, coverage.uncovered_m, coverage.plan_length_m
    )?;
    if !pruned.refused.is_empty() {
        let refused = |r: DeletionReason| pruned.refused.iter().filter(|c| c.reason == r).count();
        let kept_m = pruned.refused.iter().fold(0.0, |a, c| a + c.would_drop_m);
        let shown = match (&args.details, args.verbose) {
            (Some(file), _) => format!("each in {}", file.display()),
            (None, true) => "each below".to_owned(),
            (None, false) => "each with -v or --details FILE".to_owned(),
        };
        writeln!(
            o,
            "refused {} cut(s) that would have dropped explored ground ({:.2} m in all): {} loop(s), {} crossing loop(s), {} reversal kink(s), {} trailing retrace(s); {shown}",
            pruned.refused.len(),
            kept_m,
            refused(DeletionReason::Loop),
            refused(DeletionReason::Crossing),
            refused(DeletionReason::Reversal),
            refused(DeletionReason::TrailingRetrace),
        )?;
    }
    if args.verbose {
        o.write_all(details(&pruned).as_bytes())?;
    }
    Ok(())
}

/// One line per cut made and per cut refused, in input order of each.
fn details(pruned: &Pruned) -> String {
    let mut text = String::new();
    for d in &pruned.deletions {
        let _ = writeln!(
            text,
            "removed: {:?} from t = {} s to t = {} s ({:.2} m, samples {} to {})",
            d.reason, d.t_start_s, d.t_end_s, d.length_m, d.first_removed, d.last_removed
        );
    }
    for r in &pruned.refused {
        let _ = writeln!(
            text,
            "refused: {:?} cut from t = {} s to t = {} s ({:.2} m) would have dropped {:.2} m of explored ground",
            r.reason, r.t_start_s, r.t_end_s, r.length_m, r.would_drop_m
        );
    }
    text
}

/// Writes one output file whole or not at all (staged beside it).
fn write_file(
    path: &Path,
    default_stem: &str,
    producer: &str,
    fill: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let (dir, _, file_name) = twindrive_files::split_out_path(path, default_stem)?;
    let staging = Staging::new(&dir, producer)?;
    staging.write_with(&file_name, fill)?;
    staging.commit()
}
