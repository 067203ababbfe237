//! Self-calibration from relative laser motions: the wheel diameters, the
//! wheelbase and the lidar's mount on the robot (plus a gyro's bias and
//! scale), from encoder increments and the lidar frame's motion as a scan
//! matcher measures it. The method of A. Censi, A. Franchi, L. Marchionni,
//! G. Oriolo, "Simultaneous Calibration of Odometry and Sensor Parameters for
//! Mobile Robots", IEEE T-RO 29(2):475-492, 2013.
//!
//! Frames and conventions (REP-103): x forward, y left, heading
//! counter-clockwise positive; SI units; wheel sizes are *diameters* (m);
//! wheel rotations are radians, forward positive. The paper's eq. (3) (like
//! the twindrive paper's) writes the heading change with the opposite sign;
//! here `Δθ = (Δs_R − Δs_L)/b`, and Censi's own code (`J21 = −r_L/b`,
//! `J22 = r_R/b`) agrees with this.
//!
//! - `base_link` is the robot frame, at the middle of the axle.
//! - `ℓ = (ℓx, ℓy, ℓθ)` is the lidar's pose in `base_link` (the mount).
//! - A [`RelativeMotion`] holds the encoder increments over an interval and
//!   the lidar frame's motion over it, expressed in the lidar frame at the
//!   start of the interval: `laser = [dx, dy, dθ]`.
//! - The odometry `o(p)`, `p = (dL, dR, b)`, is the robot's motion over the
//!   interval in `base_link` at its start: exact arcs chained over the
//!   encoder steps from (0, 0, 0).
//! - The lidar's motion predicted from it is `s = ℓ⁻¹ ⊕ o ⊕ ℓ` (⊕ is SE(2)
//!   composition): `s_θ = o_θ` and `s_xy = R(−ℓθ)·[R(o_θ)·ℓ_xy + o_xy − ℓ_xy]`.
//!
//! Two estimators:
//! - [`closed_form`]: Censi's two-step method, which needs no initial guess
//!   at all (not of the mount either), with his outlier trimming and his
//!   Cramér-Rao covariance. It treats each motion as one arc at constant
//!   wheel speeds.
//! - [`fit`]: maximum likelihood by Levenberg-Marquardt over
//!   `[dL, dR, b, ℓx, ℓy, ℓθ]` (and the gyro's bias and scale), exact over
//!   every encoder step, with the odometry noise in the weights, the laser
//!   noise fitted to the residuals, trimming and a Huber weight, standard
//!   deviations from the inverse information and an identifiability report
//!   over all parameters.

mod closed_form;
mod fit;
mod identifiability;
mod laser_odometry;
mod model;

pub use closed_form::{ClosedFormConfig, Estimate6, closed_form, closed_form_with};
pub use fit::{GyroCalibration, LaserNoise, SelfCalConfig, SelfCalResult, fit};
pub use identifiability::{PARAMETER_NAMES, SCALE_NOTE, identifiability};
pub use laser_odometry::{
    LaserOdometry, LaserOdometrySettings, gyro_turn, laser_odometry, wheel_steps,
};
pub use model::predict_laser_motion;

use serde::{Deserialize, Serialize};

/// One interval of the drive: encoder increments and the lidar frame's
/// measured motion (see the [module](self) for the frames).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RelativeMotion {
    /// Start of the interval (s).
    pub t0_s: f64,
    /// End of the interval (s).
    pub t1_s: f64,
    /// Successive encoder increments over the interval in wheel radians,
    /// `[left, right]`, forward positive. One step for a motion at constant
    /// wheel speeds (Censi's tuples); none for a standstill.
    pub wheel_steps: Vec<[f64; 2]>,
    /// The lidar frame's motion over the interval, expressed in the lidar
    /// frame at `t0_s`: `[dx (m), dy (m), dθ (rad)]`.
    pub laser: [f64; 3],
    /// The scan matcher's covariance of `laser` (m², m·rad, rad²), if it
    /// gives one; [`fit`] scales it by a fitted factor. Without it the fit
    /// estimates one standard deviation per axis from the residuals, as
    /// Censi does.
    pub laser_cov: Option<[[f64; 3]; 3]>,
    /// The gyro's z rate integrated over the interval (rad), if the robot
    /// has a gyro.
    pub gyro_rad: Option<f64>,
}

impl RelativeMotion {
    /// A motion at constant wheel speeds: one encoder step (a Censi tuple
    /// `{T, phi_l, phi_r, sm}` is `constant_speed(0, T, [phi_l·T, phi_r·T], sm)`).
    pub fn constant_speed(t0_s: f64, t1_s: f64, wheels_rad: [f64; 2], laser: [f64; 3]) -> Self {
        Self {
            t0_s,
            t1_s,
            wheel_steps: vec![wheels_rad],
            laser,
            laser_cov: None,
            gyro_rad: None,
        }
    }

    /// Total wheel rotations `[left, right]` (rad) over the interval.
    pub fn total_wheel_rad(&self) -> [f64; 2] {
        self.wheel_steps
            .iter()
            .fold([0.0, 0.0], |acc, s| [acc[0] + s[0], acc[1] + s[1]])
    }

    /// Length of the interval (s).
    pub fn duration_s(&self) -> f64 {
        self.t1_s - self.t0_s
    }

    /// Why this motion cannot be used, if it cannot.
    fn problem(&self) -> Option<&'static str> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !finite(&[self.t0_s, self.t1_s]) || self.t1_s < self.t0_s {
            return Some("its interval is not finite or ends before it starts");
        }
        if !self.wheel_steps.iter().all(|s| finite(s)) {
            return Some("an encoder increment is not finite");
        }
        if !finite(&self.laser) {
            return Some("its laser motion is not finite");
        }
        if let Some(c) = &self.laser_cov {
            let m = nalgebra::Matrix3::from_fn(|i, j| c[i][j]);
            let symmetric = (0..3).all(|i| (0..3).all(|j| m[(i, j)] == m[(j, i)]));
            if !finite(m.as_slice()) || !symmetric || m.cholesky().is_none() {
                return Some("its laser covariance is not symmetric positive-definite");
            }
        }
        if self.gyro_rad.is_some_and(|g| !g.is_finite()) {
            return Some("its gyro angle is not finite");
        }
        None
    }
}

/// At least this many motions are needed: six parameters, three residuals
/// each, and the noise levels estimated from what is left over.
pub const MIN_MOTIONS: usize = 10;

/// The first motion that cannot be used, as a sentence.
fn check_motions(motions: &[RelativeMotion]) -> Result<(), String> {
    if motions.len() < MIN_MOTIONS {
        return Err(format!(
            "only {} relative motions; the self-calibration needs at least {MIN_MOTIONS}",
            motions.len()
        ));
    }
    for (k, m) in motions.iter().enumerate() {
        if let Some(why) = m.problem() {
            return Err(format!("relative motion {k} cannot be used: {why}"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
