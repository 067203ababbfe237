//! Localization against the site's map: where the robot is, from its range
//! readings and the walls the twin knows. The filter fuses the result as
//! a pose measurement ([`AugmentedEkf::update_pose_information`]), so the
//! robot tracks its plan in the site's frame and its wheel parameters
//! converge while it works (the paper's future work: the augmented EKF on
//! the physical robot, without a motion-capture reference).
//!
//! [`AugmentedEkf::update_pose_information`]: crate::AugmentedEkf::update_pose_information

mod scan_match;
mod segment_map;

pub use scan_match::{MatchSettings, ScanMatch, cost, match_points, search};
pub use segment_map::SegmentMap;
