//! Simulated calibration data for the estimator tests.
#![allow(dead_code)]

use std::path::Path;

use twindrive_estimation::{PoseSample, WheelSample};
use twindrive_log::MissionLog;
use twindrive_sim::{Scenario, Simulator};

pub const TRUTH: [f64; 3] = [0.0652, 0.0665, 0.2678];
pub const NOMINAL: [f64; 3] = [0.066, 0.066, 0.26];

pub fn scenario(name: &str) -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenarios")
        .join(name);
    Scenario::load(&path).unwrap()
}

pub fn simulate(mut sc: Scenario, seed: Option<u64>, duration_s: Option<f64>) -> MissionLog {
    if let Some(s) = seed {
        sc.seed = s;
    }
    if let Some(d) = duration_s {
        sc.steps = (d / sc.dt_s()).round() as u64;
    }
    Simulator::new(sc).run(|_, _| {})
}

/// Encoder and tracker samples of a simulated log.
pub fn samples(log: &MissionLog) -> (Vec<WheelSample>, Vec<PoseSample>) {
    let wheels = log
        .wheel_angles()
        .map(|(t_s, left_rad, right_rad)| WheelSample {
            t_s,
            left_rad,
            right_rad,
        })
        .collect();
    let poses = log
        .tracker_poses()
        .map(|(t_s, p)| PoseSample {
            t_s,
            x_m: p.x_m,
            y_m: p.y_m,
            heading_rad: Some(p.heading_rad),
        })
        .collect();
    (wheels, poses)
}
