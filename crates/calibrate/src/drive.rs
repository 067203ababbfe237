//! The built-in calibration drive: how the demo and the experiments
//! calibrate a twin the way an operator would.

use anyhow::Context;
use twindrive_estimation::FilterConfig;
use twindrive_kinematics::DiffDriveParams;

use crate::inputs;
use crate::job::{Job, Method, Offset};
use crate::run::calibrate;

/// The calibration of a calibration drive's log: the tracker's noise, the
/// operator's `nominal` [dL, dR, b] as the start, 10 % standard deviation.
pub fn calibration_job(
    log: &twindrive_log::MissionLog,
    tracker: &twindrive_sim::TrackerConfig,
    nominal: [f64; 3],
    method: Method,
) -> Job {
    let mut filter = FilterConfig::default();
    filter.noise.position_std_m = tracker.position_noise_std_m;
    filter.noise.heading_std_rad = tracker.heading_noise_std_rad;
    filter.noise.wheel_rad2_per_rad = 1e-6;
    Job {
        wheels: inputs::wheels_from_log(log),
        poses: inputs::poses_from_log(log),
        initial: nominal,
        offset: Offset::Given(0.0),
        start_s: None,
        end_s: None,
        method,
        filter,
        param_rel_std: 0.1,
        batch_window_s: 1.0,
        ticks_per_rev: Some(log.header.ticks_per_rev),
        truth: Some(inputs::truth_from_log(log)),
        time_origin_s: 0.0,
    }
}

/// `twin`'s parameters as calibration finds them: the built-in calibration
/// drive run with `twin`'s robot (its hidden truth, the operator's nominal
/// values, its encoders), calibrated by the augmented EKF.
pub fn calibrate_like(twin: &twindrive_sim::Scenario) -> anyhow::Result<DiffDriveParams> {
    let mut drive = twindrive_sim::builtin::load("calibration_drive")
        .context("calibration_drive is not built in")?
        .context("the built-in calibration_drive scenario")?;
    drive.robot.true_params = twin.robot.true_params;
    drive.robot.nominal_params = twin.robot.nominal_params;
    drive.robot.encoder = twin.robot.encoder;
    let tracker = drive
        .tracker
        .clone()
        .context("the calibration drive has a tracker")?;
    let n = drive.robot.nominal_params;
    let nominal = [n.left_diameter_m, n.right_diameter_m, n.wheelbase_m];
    let log = twindrive_sim::Simulator::new(drive).run(|_, _| {});
    let job = calibration_job(&log, &tracker, nominal, Method::Ekf);
    let (report, _) = calibrate(job, |_, _| {})?;
    Ok(DiffDriveParams::new(
        report.left_diameter_m,
        report.right_diameter_m,
        report.wheelbase_m,
    ))
}
