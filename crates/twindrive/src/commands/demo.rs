//! The case study end to end: calibration drive -> calibration -> the
//! paper's Table 1 and Section 6 -> wall-following mission on the twin.

use std::io::Write;
use std::path::Path;

use anyhow::Context;
use twindrive_estimation::FilterConfig;
use twindrive_sim::Scenario;

use super::calibrate::{self, Job, Offset};
use super::simulate::{print_summary, simulate_into};
use crate::cli::Method;
use crate::output::Staging;
use crate::{evidence, inputs, progress};

fn builtin(name: &str) -> anyhow::Result<Scenario> {
    twindrive_sim::builtin::load(name)
        .with_context(|| format!("{name} is not built in"))?
        .with_context(|| format!("the built-in {name} scenario"))
}

pub fn run(out: &Path) -> anyhow::Result<()> {
    let mut stdout = std::io::stdout().lock();

    // 1. The calibration drive on the twin, and its calibration.
    let cal_scenario = builtin("calibration_drive")?;
    let tracker = cal_scenario
        .tracker
        .clone()
        .context("the calibration drive has a tracker")?;
    let nominal = cal_scenario.robot.nominal_params;
    let nominal = [
        nominal.left_diameter_m,
        nominal.right_diameter_m,
        nominal.wheelbase_m,
    ];
    let cal_dir = out.join("calibration_drive");
    let (cal_summary, cal_log) = simulate_into(cal_scenario, &cal_dir)?;
    print_summary(&cal_summary, &cal_dir)?;

    let mut filter = FilterConfig::default();
    filter.noise.position_std_m = tracker.position_noise_std_m;
    filter.noise.heading_std_rad = tracker.heading_noise_std_rad;
    filter.noise.wheel_rad2_per_rad = 1e-6;
    let job = Job {
        wheels: inputs::wheels_from_log(&cal_log),
        poses: inputs::poses_from_log(&cal_log),
        initial: nominal,
        offset: Offset::Given(0.0),
        start_s: None,
        end_s: None,
        method: Method::Smoother,
        filter,
        param_rel_std: 0.1,
        batch_window_s: 1.0,
        ticks_per_rev: Some(cal_log.header.ticks_per_rev),
        truth: Some(
            cal_log
                .steps
                .iter()
                .map(|s| (s.t_s(), s.ground_truth))
                .collect(),
        ),
    };
    let bar = progress::bar((job.wheels.len() + job.poses.len()) as u64, "calibrating");
    let (report, artefacts) = calibrate::calibrate(job, |d, _| bar.set_position(d as u64))?;
    bar.finish_and_clear();
    let calib_path = out.join("calibration").join("calib.json");
    calibrate::write_outputs(&report, &artefacts, &calib_path)?;
    let calibrated = [
        report.left_diameter_m,
        report.right_diameter_m,
        report.wheelbase_m,
    ];
    writeln!(
        stdout,
        "calibration: dL {:.5} m, dR {:.5} m, b {:.5} m (nominal {:.3}, {:.3}, {:.3}) -> {}",
        calibrated[0],
        calibrated[1],
        calibrated[2],
        nominal[0],
        nominal[1],
        nominal[2],
        calib_path.display()
    )?;

    // 2. The wall-following mission (paper section 5.1).
    let wf_dir = out.join("wall_following");
    let (wf_summary, wf_log) = simulate_into(builtin("wall_following")?, &wf_dir)?;
    print_summary(&wf_summary, &wf_dir)?;

    // 3. The paper's evidence.
    let ev_dir = out.join("evidence");
    let staging = Staging::new(&ev_dir, "demo")?;
    let t1 = evidence::table1(&cal_log, nominal, calibrated, staging.dir())?;
    let s6 = evidence::section6(&wf_log, calibrated, staging.dir())?;
    let md = evidence::markdown(&t1, &s6);
    staging.write_with("evidence.md", |w| Ok(w.write_all(md.as_bytes())?))?;
    staging.write_with("evidence.json", |w| {
        serde_json::to_writer_pretty(w, &serde_json::json!({ "table1": t1, "section6": s6 }))
            .map_err(Into::into)
    })?;
    staging.commit()?;
    for r in &t1.rows {
        writeln!(
            stdout,
            "Table 1  {:<28} major {:.4} m ({:+.3} %), minor {:.4} m ({:+.3} %), area {:.4} m² ({:+.3} %)",
            r.source,
            r.major_axis_m,
            r.major_error_pct,
            r.minor_axis_m,
            r.minor_error_pct,
            r.area_m2,
            r.area_error_pct
        )?;
    }
    for e in &s6.wheelbase_perturbation {
        writeln!(
            stdout,
            "Section 6  {:<16} MSE {:.4} m², sum of absolute differences {:.1} m",
            e.label, e.mean_squared_error_m2, e.sum_abs_difference_m
        )?;
    }
    writeln!(
        stdout,
        "evidence in {}/ (evidence.md, figures)",
        ev_dir.display()
    )?;
    Ok(())
}
