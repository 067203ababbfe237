//! The robot's range sensors as mounted: what a log header and a plan say
//! of them.

use serde::{Deserialize, Serialize};

use crate::Pose;

/// A range sensor as mounted on the robot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RangeSensorInfo {
    pub name: String,
    /// Mount pose in the robot body frame.
    pub mount: Pose,
    pub beams: u32,
    /// Angular field of view spanned by the beams (ignored for one beam).
    pub fov_rad: f64,
    pub min_range_m: f64,
    pub max_range_m: f64,
}

impl RangeSensorInfo {
    /// Beam angle relative to the mount heading. A full circle spreads the
    /// beams over [-π, π); a narrower field spans [-fov/2, fov/2] inclusive.
    pub fn beam_angle_rad(&self, beam: u32) -> f64 {
        let (start, step) = self.angle_min_and_increment();
        start + step * f64::from(beam)
    }

    /// `(angle_min, angle_increment)` as in a ROS `LaserScan`.
    pub fn angle_min_and_increment(&self) -> (f64, f64) {
        use std::f64::consts::{PI, TAU};
        if self.beams <= 1 {
            (0.0, 0.0)
        } else if self.fov_rad >= TAU - 1e-9 {
            (-PI, TAU / f64::from(self.beams))
        } else {
            (
                -0.5 * self.fov_rad,
                self.fov_rad / f64::from(self.beams - 1),
            )
        }
    }
}
