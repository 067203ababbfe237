//! What the master makes of a robot log it received: the log itself, its
//! CSV and header, the real and the predicted track, and the range
//! readings against the plan's map, with figures.

use std::path::Path;

use anyhow::Context;
use twindrive_log::MissionLog;
use twindrive_mission::plan::{MissionPlan, PlanGeometry};

use twindrive_files::write_durably;

/// A robot log as received, into `dir`: the MCAP, the CSV and header, the real track
/// (TUM), the plan's (TUM), and range residuals against the plan over time.
pub fn write_robot_log(
    dir: &Path,
    plan: Option<&MissionPlan>,
    mcap: &[u8],
) -> anyhow::Result<MissionLog> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mcap_path = dir.join("log.mcap");
    write_durably(&mcap_path, mcap).with_context(|| format!("writing {}", mcap_path.display()))?;
    let log = twindrive_log::read_mcap_bytes(mcap, &mcap_path)
        .with_context(|| format!("reading the robot's log {}", mcap_path.display()))?;
    let mut csv = Vec::new();
    twindrive_log::write_csv(&log, &mut csv)?;
    write_durably(&dir.join("log.csv"), &csv)?;
    write_durably(
        &dir.join("log.meta.json"),
        &serde_json::to_vec_pretty(&log.header)?,
    )?;
    let mut tum = Vec::new();
    twindrive_log::write_tum(log.steps.iter().map(|s| (s.t_ns, s.ground_truth)), &mut tum)?;
    write_durably(&dir.join("real.tum"), &tum)?;
    if let Some(plan) = plan {
        let mut predicted = Vec::new();
        plan.write_tum(&mut predicted)?;
        write_durably(&dir.join("predicted.tum"), &predicted)?;
        // Range readings against what the plan's map predicts at the pose
        // the log records (the truth on a simulated site, the robot's
        // estimate on a real one).
        let mut rows = String::from("t_s,beam,measured_m,predicted_m,residual_m\n");
        let beams = log.beams_per_step();
        let mut model = plan.range_model();
        let mut predicted = vec![0.0; model.beams()];
        let mut residuals: Vec<(f64, f64)> = Vec::new();
        for (i, step) in log.steps.iter().enumerate() {
            let fresh = &log.ranges[i * beams..(i + 1) * beams];
            if !fresh.iter().any(|m| m.is_finite()) {
                continue;
            }
            model.read(&step.ground_truth, &mut predicted);
            for b in 0..beams {
                let m = log.ranges[i * beams + b];
                let Some(&p) = predicted.get(b) else {
                    continue;
                };
                if m.is_finite() {
                    residuals.push((step.t_s(), m - p));
                    rows.push_str(&format!(
                        "{:.3},{b},{m:.4},{p:.4},{:.4}\n",
                        step.t_s(),
                        m - p
                    ));
                }
            }
        }
        write_durably(&dir.join("range_residuals.csv"), rows.as_bytes())?;
        comparison_figures(&log, plan, &residuals, dir)?;
    }
    Ok(log)
}

/// `comparison.svg|png`: the plan's path against the robot's true one;
/// `range_residuals.svg|png`: measured minus predicted range over time
/// (when the log has range readings).
fn comparison_figures(
    log: &MissionLog,
    plan: &MissionPlan,
    residuals: &[(f64, f64)],
    dir: &Path,
) -> anyhow::Result<()> {
    use twindrive_plot::{Series, TimeFigure, WorldFigure, palette};
    let predicted: Vec<(f64, f64)> = plan.samples.iter().map(|s| (s.x_m, s.y_m)).collect();
    let real: Vec<(f64, f64)> = log
        .steps
        .iter()
        .map(|s| (s.ground_truth.x_m, s.ground_truth.y_m))
        .collect();
    // The prediction a pale band: the robot's path runs along it.
    WorldFigure {
        title: "predicted (the plan) against real (the robot)",
        regions: &[],
        references: &[Series {
            label: "predicted",
            points: &predicted,
            color: palette::ALT,
        }],
        walls: &[],
        paths: &[Series {
            label: "real",
            points: &real,
            color: palette::TRUTH,
        }],
        markers: &[],
        outlines: &[],
    }
    .write(&dir.join("comparison"))?;
    if residuals.is_empty() {
        // A log that ended before any range reading (a fault at the start).
        return Ok(());
    }
    let thin = twindrive_plot::decimate(residuals, 0.0);
    TimeFigure {
        title: "range readings: measured minus the twin's prediction",
        strip: None,
        x_label: "time since the plan started (s)",
        y_label: "residual (m)",
        series: &[Series {
            label: "residual",
            points: &thin,
            color: palette::BAD,
        }],
        markers: &[],
        bands: &[],
    }
    .write(&dir.join("range_residuals"))?;
    Ok(())
}
