use serde::{Deserialize, Serialize};

/// The three kinematic unknowns of a differential-drive robot.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiffDriveParams {
    pub left_diameter_m: f64,
    pub right_diameter_m: f64,
    /// Distance between the wheel contact points.
    pub wheelbase_m: f64,
}

/// A parameter that is not a finite positive number.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field} must be a finite number > 0, got {value}")]
pub struct ParamError {
    pub field: &'static str,
    pub value: f64,
}

fn positive(field: &'static str, value: f64) -> Result<(), ParamError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(ParamError { field, value })
    }
}

impl DiffDriveParams {
    pub const fn new(left_diameter_m: f64, right_diameter_m: f64, wheelbase_m: f64) -> Self {
        Self {
            left_diameter_m,
            right_diameter_m,
            wheelbase_m,
        }
    }

    /// Checks every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ParamError> {
        positive("left_diameter_m", self.left_diameter_m)?;
        positive("right_diameter_m", self.right_diameter_m)?;
        positive("wheelbase_m", self.wheelbase_m)
    }

    /// Ground travel of each wheel for the given wheel rotations (radians).
    pub fn wheel_travel_from_angles(&self, left_rad: f64, right_rad: f64) -> (f64, f64) {
        (
            0.5 * self.left_diameter_m * left_rad,
            0.5 * self.right_diameter_m * right_rad,
        )
    }
}

/// Incremental wheel encoders with a known resolution.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncoderSpec {
    pub ticks_per_rev: u32,
}

impl EncoderSpec {
    /// Wheel rotation, in radians, of one tick.
    pub fn rad_per_tick(&self) -> f64 {
        std::f64::consts::TAU / f64::from(self.ticks_per_rev)
    }

    /// Cumulative tick count for a cumulative wheel angle. Flooring the
    /// exact angle (rather than accumulating rounded increments) keeps the
    /// count within one tick of the true travel forever.
    pub fn ticks_for_angle(&self, wheel_angle_rad: f64) -> i64 {
        (wheel_angle_rad / self.rad_per_tick()).floor() as i64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validate_names_the_bad_field() {
        let err = DiffDriveParams::new(0.1, -0.1, 0.3).validate().unwrap_err();
        assert_eq!(err.field, "right_diameter_m");
        let err = DiffDriveParams::new(0.1, 0.1, f64::NAN)
            .validate()
            .unwrap_err();
        assert_eq!(err.field, "wheelbase_m");
        assert!(DiffDriveParams::new(0.1, 0.1, 0.3).validate().is_ok());
    }

    #[test]
    fn ticks_stay_within_one_of_truth() {
        let enc = EncoderSpec { ticks_per_rev: 703 };
        let mut angle = 0.0;
        for k in 0..100_000 {
            angle += 0.0123 * ((k as f64) * 0.01).sin();
            let exact = angle / enc.rad_per_tick();
            let ticks = enc.ticks_for_angle(angle) as f64;
            assert!(exact - ticks >= 0.0 && exact - ticks < 1.0);
        }
    }
}
