//! Re-timing a fixed geometric path under wheel speed and acceleration
//! limits: time-optimal path parameterisation for a differential drive, in
//! the reachability form of TOPP-RA (Pham & Pham 2018).
//!
//! Each segment of a path is one arc with fixed wheel rotation increments
//! `d_k = [left, right]` (radians); only its duration is free. With the
//! segment's rate `r_k = 1/τ_k` and the state `u_k = r_k²`, the wheels turn
//! at `d_k r_k`. The speed change between consecutive segments over the time
//! between their centres is `(d_k+1 r_k+1 − d_k r_k) · 2 r_k r_k+1 /
//! (r_k + r_k+1)`; approximating that factor by the arithmetic mean
//! `(r_k + r_k+1) / 2` and the product `r_k r_k+1` by `(u_k + u_k+1) / 2`
//! (both close where rates change smoothly) makes it linear in
//! `(u_k, u_k+1)`:
//! `u_k (d_k+1 − 3 d_k) / 4 + u_k+1 (3 d_k+1 − d_k) / 4`.
//! Callers check the result per segment and lengthen the few segments where
//! the approximation was optimistic.
//! A backward pass finds for each segment the largest `u` from which the
//! path can still be driven to a stop within the limits; a forward pass from
//! rest then takes the largest `u` the previous segment and that bound
//! allow. Both passes are linear in the number of segments.

use crate::error::PipelineError;

pub use twindrive_plan::WheelLimits;

/// The interval of `u_k+1` that keeps the change from segment `k` within
/// the acceleration limit given `u_k`, intersected with `[floor, hi]`;
/// `None` if empty.
fn next_interval(
    a: &[f64; 2],
    c: &[f64; 2],
    u: f64,
    alpha: f64,
    floor: f64,
    hi: f64,
) -> Option<(f64, f64)> {
    let (mut lo, mut up) = (floor, hi);
    for w in 0..2 {
        let base = a[w] * u;
        if c[w].abs() < 1e-300 {
            if base.abs() > alpha * (1.0 + 1e-12) {
                return None;
            }
            continue;
        }
        let (y1, y2) = ((-alpha - base) / c[w], (alpha - base) / c[w]);
        lo = lo.max(y1.min(y2));
        up = up.min(y1.max(y2));
    }
    // Round-off of the passes: an interval empty by a hair is a point.
    let slack = 1e-9 * lo.abs().max(up.abs()).max(1e-300);
    if lo <= up + slack {
        Some((lo.min(up), up.max(lo.min(hi))))
    } else {
        None
    }
}

/// Fastest admissible durations for segments with wheel increments
/// `increments` (radians), from rest to rest, each lasting at least
/// `min_duration_s[k]` (zero for no bound).
pub fn fastest_durations(
    increments: &[[f64; 2]],
    min_duration_s: &[f64],
    limits: &WheelLimits,
) -> Result<Vec<f64>, PipelineError> {
    limits.validate()?;
    let n = increments.len();
    assert_eq!(n, min_duration_s.len(), "one minimum duration per segment");
    if n == 0 {
        return Ok(Vec::new());
    }
    let (omega, alpha) = (limits.max_speed_rad_s, limits.max_accel_rad_s2);
    let peak = |d: &[f64; 2]| d[0].abs().max(d[1].abs());
    let mut cap: Vec<f64> = increments
        .iter()
        .zip(min_duration_s)
        .map(|(d, m)| {
            let by_speed = if peak(d) > 0.0 {
                (omega / peak(d)).powi(2)
            } else {
                f64::INFINITY
            };
            let by_min = if *m > 0.0 {
                m.recip().powi(2)
            } else {
                f64::INFINITY
            };
            by_speed.min(by_min)
        })
        .collect();
    if let Some(k) = cap.iter().position(|c| !c.is_finite()) {
        return Err(PipelineError::Infeasible(format!(
            "segment {k} moves neither wheel and has no minimum duration"
        )));
    }
    // From rest over the first half segment, to rest over the last:
    // 2 |d| u ≤ α.
    for k in [0, n - 1] {
        if peak(&increments[k]) > 0.0 {
            cap[k] = cap[k].min(alpha / (2.0 * peak(&increments[k])));
        }
    }
    // Acceleration coefficients between segments k and k+1: a u_k + c u_k+1.
    let coeff: Vec<([f64; 2], [f64; 2])> = increments
        .windows(2)
        .map(|w| {
            let (d, e) = (&w[0], &w[1]);
            (
                [0.25 * (e[0] - 3.0 * d[0]), 0.25 * (e[1] - 3.0 * d[1])],
                [0.25 * (3.0 * e[0] - d[0]), 0.25 * (3.0 * e[1] - d[1])],
            )
        })
        .collect();
    // Backward: the largest u of each segment that can still reach the end.
    // The next segment must keep a quarter of what it could do even from
    // standing still: the linear model overstates a change from a fast
    // segment into a much slower one, and would otherwise starve the slower
    // one to a crawl.
    let mut hi = vec![0.0; n];
    let mut floor = vec![0.0; n];
    hi[n - 1] = cap[n - 1];
    for k in (0..n - 1).rev() {
        let (a, c) = &coeff[k];
        let reach_from_rest = alpha / c[0].abs().max(c[1].abs()).max(1e-300);
        floor[k + 1] = 0.25 * hi[k + 1].min(reach_from_rest);
        let feasible = |u: f64| next_interval(a, c, u, alpha, floor[k + 1], hi[k + 1]).is_some();
        hi[k] = if feasible(cap[k]) {
            cap[k]
        } else {
            // The feasible set is an interval containing 0: bisect its top.
            let (mut lo, mut up) = (0.0, cap[k]);
            for _ in 0..100 {
                let mid = 0.5 * (lo + up);
                if feasible(mid) {
                    lo = mid;
                } else {
                    up = mid;
                }
                if up - lo <= 1e-12 * up {
                    break;
                }
            }
            lo
        };
    }
    // Forward from rest: as fast as the previous segment and the bound allow.
    let mut u = vec![0.0; n];
    u[0] = hi[0];
    for k in 0..n - 1 {
        let (a, c) = &coeff[k];
        u[k + 1] = match next_interval(a, c, u[k], alpha, floor[k + 1], hi[k + 1]) {
            Some((_, top)) => top.min(hi[k + 1]),
            None => {
                return Err(PipelineError::Infeasible(format!(
                    "re-timing found no admissible speed at segment {}",
                    k + 1
                )));
            }
        };
    }
    u.iter()
        .enumerate()
        .map(|(k, u)| {
            if *u > 0.0 {
                Ok(1.0 / u.sqrt())
            } else {
                Err(PipelineError::Infeasible(format!(
                    "segment {k} cannot be driven within the limits"
                )))
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    const LIMITS: WheelLimits = WheelLimits {
        max_speed_rad_s: 10.0,
        max_accel_rad_s2: 20.0,
    };

    /// Peak wheel speed and speed change between segment centres.
    fn peaks(increments: &[[f64; 2]], t: &[f64]) -> (f64, f64) {
        let speeds: Vec<[f64; 2]> = increments
            .iter()
            .zip(t)
            .map(|(d, t)| [d[0] / t, d[1] / t])
            .collect();
        let mut speed: f64 = 0.0;
        let mut accel: f64 = 0.0;
        for (k, now) in speeds.iter().enumerate() {
            speed = speed.max(now[0].abs()).max(now[1].abs());
            if k > 0 {
                let span = 0.5 * (t[k - 1] + t[k]);
                let before = speeds[k - 1];
                for (a, b) in now.iter().zip(before) {
                    accel = accel.max((a - b).abs() / span);
                }
            }
        }
        (speed, accel)
    }

    #[test]
    fn a_straight_run_accelerates_cruises_and_stops_within_the_limits() {
        let inc = vec![[0.05, 0.05]; 800];
        let t = fastest_durations(&inc, &vec![0.0; 800], &LIMITS).unwrap();
        let (speed, accel) = peaks(&inc, &t);
        assert!(speed <= 10.0 * (1.0 + 1e-9), "{speed}");
        assert!(accel <= 20.0 * 1.05, "{accel}");
        // The bang-bang profile: 40 rad at 10 rad/s with 0.5 s ramps.
        let total: f64 = t.iter().sum();
        let ideal = 40.0 / 10.0 + 10.0 / 20.0;
        assert!((total - ideal).abs() < 0.02 * ideal, "{total} vs {ideal}");
    }

    #[test]
    fn random_paths_respect_the_limits() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..50 {
            let n = rng.random_range(2..300);
            // Smooth random curvature: the wheels' increments drift.
            let mut d: [f64; 2] = [0.05, 0.05];
            let inc: Vec<[f64; 2]> = (0..n)
                .map(|_| {
                    d[0] = (d[0] + rng.random_range(-0.001..0.001)).clamp(-0.08, 0.08);
                    d[1] = (d[1] + rng.random_range(-0.001..0.001)).clamp(-0.08, 0.08);
                    d
                })
                .collect();
            let mins: Vec<f64> = (0..n).map(|_| rng.random_range(0.0..0.02)).collect();
            let t = fastest_durations(&inc, &mins, &LIMITS).unwrap();
            let (speed, accel) = peaks(&inc, &t);
            assert!(speed <= 10.0 * (1.0 + 1e-9), "{speed}");
            // The per-segment check and the continuous model differ a little
            // on jagged paths; callers plan with a margin and check (see
            // `spikes::time_optimal`, whose output must pass the check).
            assert!(accel <= 20.0 * 1.3, "{accel}");
            for (ti, m) in t.iter().zip(&mins) {
                assert!(*ti >= m * (1.0 - 1e-9), "{ti} < {m}");
            }
        }
    }

    #[test]
    fn bad_limits_and_motionless_segments_are_errors() {
        let bad = WheelLimits {
            max_speed_rad_s: 0.0,
            ..LIMITS
        };
        assert!(matches!(
            fastest_durations(&[[0.1, 0.1]], &[0.0], &bad),
            Err(PipelineError::Value(
                twindrive_plan::PlanError::BadSetting {
                    field: "max_wheel_speed_rad_s",
                    ..
                }
            ))
        ));
        assert!(matches!(
            fastest_durations(&[[0.1, 0.1], [0.0, 0.0], [0.0, 0.0]], &[0.0; 3], &LIMITS),
            Err(PipelineError::Infeasible(_))
        ));
    }
}
