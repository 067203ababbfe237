//! The path type shared by every stage of the pipeline.

use serde::{Deserialize, Serialize};
use twindrive_kinematics::Pose;

/// One sample of a planar path: where the robot is at a time and how it moves.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PathSample {
    pub t_s: f64,
    pub pose: Pose,
    /// Linear velocity along the heading (negative when reversing).
    pub v_m_s: f64,
    /// Angular velocity, counter-clockwise positive.
    pub omega_rad_s: f64,
}

impl PathSample {
    pub fn position(&self) -> [f64; 2] {
        [self.pose.x_m, self.pose.y_m]
    }
}

/// Length of the polyline through the samples' positions.
pub fn path_length_m(samples: &[PathSample]) -> f64 {
    samples
        .windows(2)
        .map(|w| w[0].pose.distance_to(&w[1].pose))
        .fold(0.0, |a, d| a + d)
}
