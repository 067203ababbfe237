//! One calibration's inputs, checked: the samples, the starting guess, the
//! clock offset, the window and the noise model.

use serde::Serialize;
use twindrive_estimation::{FilterConfig, PoseSample, WheelSample};
use twindrive_kinematics::Pose;

/// Which estimate a calibration reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The augmented EKF's final estimate.
    Ekf,
    /// The EKF followed by a Rauch-Tung-Striebel smoother (same final
    /// parameters, better history).
    Smoother,
    /// Levenberg-Marquardt over relative motions between pose samples.
    Batch,
}

/// How the clock offset between the two logs is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Offset {
    Given(f64),
    Auto,
}

/// Everything one calibration needs, checked.
#[derive(Debug, Clone)]
pub struct Job {
    pub wheels: Vec<WheelSample>,
    pub poses: Vec<PoseSample>,
    pub initial: [f64; 3],
    pub offset: Offset,
    /// Only poses in this interval of the pose clock are used.
    pub start_s: Option<f64>,
    pub end_s: Option<f64>,
    pub method: Method,
    pub filter: FilterConfig,
    pub param_rel_std: f64,
    pub batch_window_s: f64,
    pub ticks_per_rev: Option<u32>,
    /// The true pose track, when the log has one (simulations).
    pub truth: Option<Vec<(f64, Pose)>>,
    /// Subtracted from the input's times (bags: Unix seconds).
    pub time_origin_s: f64,
}
