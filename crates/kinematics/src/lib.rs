//! Differential-drive kinematics (paper eqs. 1-3), in REP-103 conventions.
//!
//! Frames: x forward, y left, heading counter-clockwise positive, SI units,
//! radians. Wheel sizes are *diameters* in metres.
//!
//! The paper's eq. (3) writes `Δθ = (Δs_L − Δs_R)/b`, i.e. a clockwise-positive
//! heading. This crate uses REP-103, so `Δθ = (Δs_R − Δs_L)/b` throughout.

mod arc;
mod inverse;
mod jacobian;
mod params;
mod sensor;

pub use arc::{
    WheelOdometry, arc_step, arc_step_wheels, body_increment, encoder_increment, sinc,
    sinc_derivative, wheel_travel_m,
};
pub use inverse::{body_velocity, wheel_angles_from_speeds, wheel_speeds};
pub use jacobian::{
    AugmentedState, Mat6, Mat6x2, StateVec, StepJacobian, Transition, step_augmented,
    step_jacobians, step_with_jacobian, step_with_jacobians,
};
pub use params::{DiffDriveParams, EncoderSpec, ParamError};
pub use sensor::{MIN_SCAN_BEAMS, RangeSensorInfo, SensorKind};

use serde::{Deserialize, Serialize};

/// A planar pose in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pose {
    pub x_m: f64,
    pub y_m: f64,
    /// Counter-clockwise positive (REP-103).
    pub heading_rad: f64,
}

impl Pose {
    pub const fn new(x_m: f64, y_m: f64, heading_rad: f64) -> Self {
        Self {
            x_m,
            y_m,
            heading_rad,
        }
    }

    /// Maps a point given in the robot body frame into the world frame.
    pub fn transform_point(&self, body_x_m: f64, body_y_m: f64) -> (f64, f64) {
        let (s, c) = self.heading_rad.sin_cos();
        (
            self.x_m + c * body_x_m - s * body_y_m,
            self.y_m + s * body_x_m + c * body_y_m,
        )
    }

    /// Euclidean distance between the positions of two poses.
    pub fn distance_to(&self, other: &Pose) -> f64 {
        (self.x_m - other.x_m).hypot(self.y_m - other.y_m)
    }
}

/// Wraps an angle into (-π, π].
pub fn wrap_angle(angle_rad: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    if angle_rad > -PI && angle_rad <= PI {
        return angle_rad;
    }
    // One floor instead of a remainder (`fmod` is slow); lands in [-π, π).
    let wrapped = angle_rad - TAU * ((angle_rad + PI) / TAU).floor();
    if wrapped <= -PI {
        wrapped + TAU
    } else {
        wrapped
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn wrap_angle_range() {
        for k in -20..20 {
            let a = k as f64 * 0.77;
            let w = wrap_angle(a);
            assert!(w > -PI && w <= PI, "{a} -> {w}");
            assert!(
                ((a - w) / (2.0 * PI)).fract().abs() < 1e-9
                    || ((a - w) / (2.0 * PI)).fract().abs() > 1.0 - 1e-9
            );
        }
        assert_eq!(wrap_angle(PI), PI);
        assert_eq!(wrap_angle(-PI), PI);
        assert_eq!(wrap_angle(3.0 * PI), PI);
        assert!((wrap_angle(100.0) - (100.0 - 32.0 * PI)).abs() < 1e-12);
        assert!((wrap_angle(-7.0) - (-7.0 + 2.0 * PI)).abs() < 1e-15);
    }
}
