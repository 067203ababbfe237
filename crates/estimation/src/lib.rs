//! Kinematic calibration of a differential-drive robot (paper sections
//! 4.3-4.5): estimate the wheel diameters and the wheelbase from encoder
//! counts and an external absolute pose.
//!
//! - [`AugmentedEkf`]: the filter over [x, y, θ, dL, dR, b];
//! - [`OnlineCalibrator`]: samples as they arrive, at any rates;
//! - [`run_filter`] and [`rts_smooth`]: the same filter over a whole log, and
//!   its smoother;
//! - [`batch`]: an independent Levenberg-Marquardt fit used as a cross-check;
//! - [`clock`]: the offset between an encoder clock and a pose clock;
//! - [`selfcal`]: self-calibration of the wheels and a lidar's mount (and a
//!   gyro) from relative laser motions, without an external pose reference;
//! - [`slam`]: the site's map from a long real drive: submaps, loop
//!   closure by branch-and-bound, a sparse pose graph;
//! - [`ellipse_fit`], [`dead_reckoning`]: for the paper's evidence.
//!
//! REP-103 throughout; the paper's eq. (3) has the opposite heading sign.

pub mod batch;
pub mod clock;
mod covariance;
pub mod dead_reckoning;
mod ekf;
pub mod ellipse_fit;
pub mod evaluation;
pub mod localize;
pub mod mapping;
mod odometry_chain;
mod offline;
mod online;
pub mod relations;
pub mod se2;
pub mod selfcal;
pub mod slam;
mod smoother;

pub use covariance::{PackedCovariance, PackedEstimate, chain};
pub use ekf::{
    AugmentedEkf, FilterError, FilterStats, GateConfig, InformationOutcome, NoiseModel,
    StateAndCovariance, UpdateOutcome, chi2_quantile, nees,
};
pub use offline::{FilterRun, run_filter, smooth};
pub use online::{
    CalibrationError, Estimate, FilterConfig, FilterHistory, InnovationRecord, OnlineCalibrator,
    PoseSample, WheelSample, initial_estimate,
};
pub use smoother::rts_smooth;
pub use twindrive_kinematics::{AugmentedState, Mat6, StateVec, Transition};
