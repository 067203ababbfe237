//! The circular-arc motion step (paper eq. 1) and encoder increments
//! (paper eqs. 2-3, with the heading sign flipped to REP-103).

use crate::{DiffDriveParams, Pose};

/// Below this |a| the Taylor series of sin(a)/a is exact to f64 precision
/// (the first omitted term, a⁶/5040, is about 2e-22, far below 1 ulp of 1).
const SERIES_LIMIT: f64 = 1e-3;

/// sin(a)/a, exact near a = 0.
#[inline]
pub fn sinc(a: f64) -> f64 {
    if a.abs() < SERIES_LIMIT {
        // Multiplications by the reciprocals: divisions are slow, and the
        // correction terms are far below 1 ulp of the result either way.
        let a2 = a * a;
        1.0 - a2 * (1.0 / 6.0) * (1.0 - a2 * (1.0 / 20.0))
    } else {
        a.sin() / a
    }
}

/// d/da [sin(a)/a], exact near a = 0.
#[inline]
pub fn sinc_derivative(a: f64) -> f64 {
    if a.abs() < SERIES_LIMIT {
        let a2 = a * a;
        -a * (1.0 / 3.0) * (1.0 - a2 * (1.0 / 10.0) * (1.0 - a2 * (1.0 / 28.0)))
    } else {
        let (s, c) = a.sin_cos();
        (a * c - s) / (a * a)
    }
}

/// `(sinc(a), sinc'(a))` with one sine and cosine.
#[inline]
pub fn sinc_and_derivative(a: f64) -> (f64, f64) {
    if a.abs() < SERIES_LIMIT {
        (sinc(a), sinc_derivative(a))
    } else {
        let (s, c) = a.sin_cos();
        (s / a, (a * c - s) / (a * a))
    }
}

/// Ground travel of a wheel for an encoder increment (paper eq. 2, one wheel).
#[inline]
pub fn wheel_travel_m(delta_ticks: f64, diameter_m: f64, ticks_per_rev: f64) -> f64 {
    std::f64::consts::PI * diameter_m * delta_ticks / ticks_per_rev
}

/// Arc length and heading change for encoder increments (paper eqs. 2-3,
/// heading sign flipped to REP-103: `Δθ = π (dR ΔeR − dL ΔeL) / (e_res b)`).
#[inline]
pub fn encoder_increment(
    params: &DiffDriveParams,
    ticks_per_rev: f64,
    delta_left_ticks: f64,
    delta_right_ticks: f64,
) -> (f64, f64) {
    let left_m = wheel_travel_m(delta_left_ticks, params.left_diameter_m, ticks_per_rev);
    let right_m = wheel_travel_m(delta_right_ticks, params.right_diameter_m, ticks_per_rev);
    body_increment(left_m, right_m, params.wheelbase_m)
}

/// Arc length of the wheel-axle centre and heading change for the given wheel
/// travels. REP-103: turning left (right wheel travels further) is positive.
#[inline]
pub fn body_increment(left_m: f64, right_m: f64, wheelbase_m: f64) -> (f64, f64) {
    (0.5 * (left_m + right_m), (right_m - left_m) / wheelbase_m)
}

/// Moves `pose` along a circular arc of length `ds_m` that turns by `dtheta_rad`
/// (paper eq. 1).
#[inline]
pub fn arc_step(pose: &Pose, ds_m: f64, dtheta_rad: f64) -> Pose {
    let half = 0.5 * dtheta_rad;
    let chord = ds_m * sinc(half);
    let (s, c) = (pose.heading_rad + half).sin_cos();
    Pose {
        x_m: pose.x_m + chord * c,
        y_m: pose.y_m + chord * s,
        heading_rad: pose.heading_rad + dtheta_rad,
    }
}

/// One step from wheel *rotations* (radians) through the given parameters.
/// The heading is not wrapped, so it stays continuous over many turns.
#[inline]
pub fn arc_step_wheels(
    pose: &Pose,
    params: &DiffDriveParams,
    left_rad: f64,
    right_rad: f64,
) -> Pose {
    let (left_m, right_m) = params.wheel_travel_from_angles(left_rad, right_rad);
    let (ds, dtheta) = body_increment(left_m, right_m, params.wheelbase_m);
    arc_step(pose, ds, dtheta)
}

/// Dead reckoning from cumulative wheel angles: the pose stepped by
/// [`arc_step_wheels`] on each increment since the angles last seen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelOdometry {
    pub pose: Pose,
    last_rad: Option<[f64; 2]>,
}

impl WheelOdometry {
    /// Starting at `pose`; the first angles given only set the reference.
    pub fn new(pose: Pose) -> Self {
        Self {
            pose,
            last_rad: None,
        }
    }

    /// Steps through the rotation since the last angles (left, right,
    /// cumulative radians) with `params`; the pose after it.
    pub fn advance(&mut self, params: &DiffDriveParams, wheels_rad: [f64; 2]) -> Pose {
        if let Some(prev) = self.last_rad {
            self.pose = arc_step_wheels(
                &self.pose,
                params,
                wheels_rad[0] - prev[0],
                wheels_rad[1] - prev[1],
            );
        }
        self.last_rad = Some(wheels_rad);
        self.pose
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI, TAU};

    #[test]
    fn sinc_is_continuous_across_the_series_limit() {
        for a in [1e-3 - 1e-12, 1e-3 + 1e-12, -1e-3 + 1e-12, -1e-3 - 1e-12] {
            assert!((sinc(a) - a.sin() / a).abs() < 1e-15);
            let direct = (a * a.cos() - a.sin()) / (a * a);
            // The direct formula loses digits near zero; agree to its accuracy.
            assert!((sinc_derivative(a) - direct).abs() < 1e-9);
        }
        assert_eq!(sinc(0.0), 1.0);
        for a in [0.0, 5e-4, -5e-4, 0.3, -2.0] {
            let (s, d) = sinc_and_derivative(a);
            assert!((s - sinc(a)).abs() < 1e-16 && (d - sinc_derivative(a)).abs() < 1e-16);
        }
        assert_eq!(sinc_derivative(0.0), 0.0);
    }

    #[test]
    fn encoder_increment_is_the_papers_eqs_2_and_3_with_rep103_heading() {
        let p = DiffDriveParams::new(0.0644, 0.0651, 0.26);
        let (e_res, de_l, de_r) = (512.0, 37.0, 45.0);
        let (ds, dth) = encoder_increment(&p, e_res, de_l, de_r);
        let paper_ds = PI * (p.left_diameter_m * de_l + p.right_diameter_m * de_r) / (2.0 * e_res);
        let paper_dth =
            PI * (p.left_diameter_m * de_l - p.right_diameter_m * de_r) / (e_res * p.wheelbase_m);
        assert!((ds - paper_ds).abs() < 1e-15);
        assert!(
            (dth + paper_dth).abs() < 1e-15,
            "REP-103 flips the paper's sign"
        );
        assert!(
            dth > 0.0,
            "the right wheel went further: a left (counter-clockwise) turn"
        );
    }

    #[test]
    fn straight_line() {
        let p = DiffDriveParams::new(0.1, 0.1, 0.3);
        let mut pose = Pose::new(1.0, 2.0, FRAC_PI_2);
        for _ in 0..1000 {
            pose = arc_step_wheels(&pose, &p, 0.02, 0.02);
        }
        // 1000 * 0.02 rad * 0.05 m = 1 m along +y.
        assert!((pose.x_m - 1.0).abs() < 1e-12);
        assert!((pose.y_m - 3.0).abs() < 1e-12);
        assert_eq!(pose.heading_rad, FRAC_PI_2);
    }

    #[test]
    fn spin_in_place() {
        let p = DiffDriveParams::new(0.1, 0.1, 0.3);
        let mut pose = Pose::new(-0.5, 0.25, 0.3);
        // Each wheel travels 0.05 * w in opposite directions: dθ = 2*0.05*w/0.3.
        // Each step turns the body by TAU / 1000.
        let w = TAU * 0.3 / (2.0 * 0.05) / 1000.0;
        for _ in 0..1000 {
            pose = arc_step_wheels(&pose, &p, -w, w);
        }
        assert!((pose.x_m + 0.5).abs() < 1e-15 && (pose.y_m - 0.25).abs() < 1e-15);
        assert!((pose.heading_rad - 0.3 - TAU).abs() < 1e-12);
    }

    #[test]
    fn circle_radius_matches_closed_form() {
        // Unequal wheels: R = b/2 * (sR + sL)/(sR - sL).
        let p = DiffDriveParams::new(0.10, 0.11, 0.32);
        let (wl, wr) = (0.013, 0.017);
        let (sl, sr) = (0.05 * wl, 0.055 * wr);
        let radius = 0.16 * (sr + sl) / (sr - sl);
        let start = Pose::new(0.0, 0.0, 0.0);
        let centre = (0.0, radius);
        let mut pose = start;
        let mut max_err: f64 = 0.0;
        for _ in 0..20_000 {
            pose = arc_step_wheels(&pose, &p, wl, wr);
            let r = (pose.x_m - centre.0).hypot(pose.y_m - centre.1);
            max_err = max_err.max((r - radius).abs());
        }
        assert!(
            pose.heading_rad > 2.0 * PI,
            "drove at least one full circle"
        );
        assert!(max_err < 1e-10, "radius error {max_err}");
    }

    #[test]
    fn arc_matches_fine_integration() {
        let start = Pose::new(0.3, -0.2, 1.0);
        let (ds, dth) = (0.4, 0.9);
        let exact = arc_step(&start, ds, dth);
        let mut pose = start;
        let n = 100_000;
        for _ in 0..n {
            pose = arc_step(&pose, ds / n as f64, dth / n as f64);
        }
        // 1e5 summed steps accumulate ~1e-16 rounding each.
        assert!(exact.distance_to(&pose) < 1e-10);
        assert!((exact.heading_rad - pose.heading_rad).abs() < 1e-10);
    }
}
