//! Calibration of a differential-drive robot's wheel diameters and
//! wheelbase from its encoders and an absolute pose reference (a tracker,
//! motion capture, a localizer), as `twindrive calibrate` and the demo run
//! it:
//!
//! - [`inputs`]: recordings into samples (simulator logs, CSV pairs,
//!   rosbag2 recordings);
//! - [`job`]: one calibration's checked inputs ([`Job`]);
//! - [`run`]: the calibration ([`calibrate`]): the clock offset, the
//!   window, the augmented EKF (and smoother) beside the batch fit, NEES
//!   against the truth where a simulator log has it;
//! - [`report`]: `calib.json` ([`Report`]) and what the figures are drawn from;
//! - [`output`]: the report, trajectories and figures on disk;
//! - [`figures`]: the parameter and innovation figures;
//! - [`drive`]: the built-in calibration drive ([`calibrate_like`]);
//! - [`bag_info`]: what a rosbag2 recording holds and which of it a
//!   calibration can use (`twindrive bag info`);
//! - [`described_wheels`]: the nominal wheels a recording's robot
//!   description (`/robot_description`, a URDF) gives;
//! - [`self_cal`]: self-calibration with no pose reference: the wheels and
//!   the lidar's mount (and a gyro) from encoders and scans
//!   ([`self_calibrate`]), its inputs from logs ([`scan_inputs`]);
//! - [`site_map`]: the site's map from the same inputs and the calibration
//!   (`twindrive map`): map_server files and `site.toml` for the twin;
//! - [`site_update`]: the twin's map extended by a mission's robot logs
//!   (`twindrive master --site-maps`).

pub mod bag_info;
pub mod described_wheels;
pub mod drive;
pub mod figures;
pub mod inputs;
pub mod job;
pub mod output;
pub mod report;
pub mod run;
pub mod scan_inputs;
pub mod self_cal;
pub mod site_map;
pub mod site_update;

pub use drive::{calibrate_like, calibration_job};
pub use job::{Job, Method, Offset};
pub use output::{write_outputs, write_scan_outputs};
pub use report::{Artefacts, Report, print_report};
pub use run::calibrate;
pub use self_cal::{ScanJob, ScanReport, print_scan_report, self_calibrate};
