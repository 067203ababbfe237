//! Body velocity <-> wheel angular speed.

use crate::DiffDriveParams;

/// Wheel angular speeds (rad/s) that produce linear speed `v_m_s` and angular
/// speed `omega_rad_s` (counter-clockwise positive).
#[inline]
pub fn wheel_speeds(params: &DiffDriveParams, v_m_s: f64, omega_rad_s: f64) -> (f64, f64) {
    let half_track = 0.5 * params.wheelbase_m * omega_rad_s;
    (
        (v_m_s - half_track) / (0.5 * params.left_diameter_m),
        (v_m_s + half_track) / (0.5 * params.right_diameter_m),
    )
}

/// Linear and angular body speed for the given wheel angular speeds.
#[inline]
pub fn body_velocity(params: &DiffDriveParams, left_rad_s: f64, right_rad_s: f64) -> (f64, f64) {
    let (left_m_s, right_m_s) = params.wheel_travel_from_angles(left_rad_s, right_rad_s);
    (
        0.5 * (left_m_s + right_m_s),
        (right_m_s - left_m_s) / params.wheelbase_m,
    )
}

/// Cumulative wheel angles (rad, from zero) at each of `samples`' times,
/// from wheel speeds (rad/s) sampled at those times: the trapezoid rule.
pub fn wheel_angles_from_speeds(
    samples: impl IntoIterator<Item = (f64, [f64; 2])>,
) -> Vec<(f64, [f64; 2])> {
    let mut out: Vec<(f64, [f64; 2])> = Vec::new();
    let mut previous: Option<(f64, [f64; 2])> = None;
    let mut angle = [0.0; 2];
    for (t, speed) in samples {
        if let Some((tp, vp)) = previous {
            let dt = t - tp;
            for w in 0..2 {
                angle[w] += 0.5 * dt * (speed[w] + vp[w]);
            }
        }
        previous = Some((t, speed));
        out.push((t, angle));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speeds_integrate_by_the_trapezoid_rule() {
        let a =
            wheel_angles_from_speeds([(0.0, [0.0, 1.0]), (1.0, [2.0, 1.0]), (3.0, [2.0, -1.0])]);
        assert_eq!(
            a,
            vec![(0.0, [0.0, 0.0]), (1.0, [1.0, 1.0]), (3.0, [5.0, 1.0])]
        );
        assert!(wheel_angles_from_speeds([]).is_empty());
    }

    #[test]
    fn round_trip() {
        let p = DiffDriveParams::new(0.064, 0.066, 0.26);
        for (v, w) in [(0.0, 0.0), (0.3, 0.0), (0.0, 1.2), (-0.2, 0.7), (0.5, -2.0)] {
            let (l, r) = wheel_speeds(&p, v, w);
            let (v2, w2) = body_velocity(&p, l, r);
            assert!((v - v2).abs() < 1e-12 && (w - w2).abs() < 1e-12);
        }
        // Turning left spins the right wheel faster.
        let (l, r) = wheel_speeds(&p, 0.2, 0.5);
        assert!(r > l);
    }
}
