//! The digital twin: a 2D world, a differential-drive robot with hidden true
//! kinematics, encoders, range sensors, a bump sensor, a gyro and an
//! external pose tracker, driven by a controller, recorded as a [`MissionLog`].
//!
//! ```no_run
//! use twindrive_sim::{Scenario, Simulator};
//! let scenario = Scenario::load("scenarios/wall_following.toml".as_ref())?;
//! let log = Simulator::new(scenario).run(|_, _| {});
//! println!("{} steps", log.steps.len());
//! # Ok::<(), twindrive_sim::SimError>(())
//! ```
//!
//! [`MissionLog`]: twindrive_log::MissionLog

pub mod builtin;
mod config;
pub mod controller;
pub mod manual;
pub mod map;
mod scan;
pub mod scenario;
mod simulator;
mod summary;
mod world;

pub use config::{
    ControllerConfig, GyroConfig, RangeSensorConfig, RobotConfig, Scenario, TrackerConfig,
};
pub use scan::{Fan, ScanKernel};
pub use simulator::{Contacts, RangeModel, Sensed, SensorModel, Simulator, StepOutput};
pub use summary::MissionSummary;
pub use world::{Nearest, World, polyline_segments, rectangle_segments};

/// Re-exported so users of [`World`] need not depend on parry2d directly.
pub use parry2d_f64::math::Vector;

use std::path::{Path, PathBuf};

/// A scenario, map or command file that cannot be used. Each names the file;
/// field errors name the field as a dotted path (`robot.true_params.left_diameter_m`).
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {message}", path.display())]
    Scenario { path: PathBuf, message: String },
    #[error("{}: field `{field}` {message}", path.display())]
    Field {
        path: PathBuf,
        field: String,
        message: String,
    },
    #[error("{}, line {line}: {message}", path.display())]
    Commands {
        path: PathBuf,
        line: usize,
        message: String,
    },
}

impl SimError {
    pub(crate) fn field(path: &Path, field: &str, message: String) -> Self {
        Self::Field {
            path: path.to_path_buf(),
            field: field.to_string(),
            message,
        }
    }
}
