//! Scan matching and localization against the site's map: where the robot
//! is, from its range readings and the walls the twin knows, and how the
//! lidar moved between two scans (laser odometry, for self-calibration and
//! for drawing the map). One matcher ([`register`]) against three kinds of
//! [`Reference`]: the site's walls ([`SegmentMap`]), the previous scan
//! ([`ScanReference`]) and a map of points ([`PointMap`]).
//!
//! The filter fuses a match as a pose measurement
//! ([`AugmentedEkf::update_pose_information`]), so the robot tracks its
//! plan in the site's frame and its wheel parameters converge while it
//! works (the paper's future work: the augmented EKF on the physical
//! robot, without a motion-capture reference).
//!
//! [`AugmentedEkf::update_pose_information`]: crate::AugmentedEkf::update_pose_information

mod point_map;
mod reference;
mod refusal;
mod scan;
mod scan_match;
mod scan_ref;
mod segment_map;
#[cfg(test)]
pub(crate) mod testkit;

pub use point_map::PointMap;
pub use reference::{Anchor, Reference};
pub use refusal::Refusal;
pub use scan::Scan;
pub use scan_match::{MatchSettings, ScanMatch, cost, match_points, register, search};
pub use scan_ref::ScanReference;
pub use segment_map::SegmentMap;
