//! Laser odometry for self-calibration: how the lidar moved over each
//! interval of a drive, measured by matching its scans, beside the encoder
//! increments (and the gyro's turn) over the same interval: the
//! [`RelativeMotion`]s that [`fit`](super::fit) and
//! [`closed_form`](super::closed_form) take.
//!
//! Consecutive scans are matched first, each from the motion the encoders
//! and the current guesses predict; their chain is the prior for matching
//! the scans that open and close each interval (about `interval_s` apart)
//! directly, so an interval's motion is one match, not a sum of small ones.
//! A refused match is counted by its reason and its interval left out.

use std::collections::BTreeMap;

use crate::WheelSample;
use crate::localize::{MatchSettings, Scan, ScanReference, register};

use super::{RelativeMotion, predict_laser_motion};

/// How scans become relative motions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaserOdometrySettings {
    /// Target length of an interval (s).
    pub interval_s: f64,
    /// Intervals in which neither wheel turned by this much (rad) are left
    /// out: a standstill says nothing of the wheels.
    pub min_wheel_turn_rad: f64,
    pub matcher: MatchSettings,
}

impl Default for LaserOdometrySettings {
    fn default() -> Self {
        Self {
            interval_s: 1.0,
            min_wheel_turn_rad: 0.05,
            matcher: MatchSettings::scan_to_scan(),
        }
    }
}

/// The relative motions of a drive and what the matcher refused.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserOdometry {
    pub motions: Vec<RelativeMotion>,
    /// Scans read.
    pub scans: usize,
    /// Consecutive pairs matched, and refused by reason.
    pub consecutive_matched: usize,
    pub consecutive_refused: BTreeMap<&'static str, usize>,
    /// Intervals matched, left out as standstills, and refused by reason.
    pub intervals: usize,
    pub standstills: usize,
    pub refused: BTreeMap<&'static str, usize>,
}

impl LaserOdometry {
    /// The refusals as "N degenerate, M too few inliers".
    pub fn refusals(&self) -> String {
        let parts: Vec<String> = self
            .refused
            .iter()
            .map(|(kind, n)| format!("{n} {kind}"))
            .collect();
        if parts.is_empty() {
            "none".into()
        } else {
            parts.join(", ")
        }
    }
}

/// Cumulative wheel angles at `t_s`, interpolated between the samples
/// around it (clamped at the ends).
fn wheels_at(wheels: &[WheelSample], t_s: f64) -> [f64; 2] {
    let i = wheels.partition_point(|w| w.t_s <= t_s);
    if i == 0 {
        return [wheels[0].left_rad, wheels[0].right_rad];
    }
    if i == wheels.len() {
        let w = &wheels[i - 1];
        return [w.left_rad, w.right_rad];
    }
    let (a, b) = (&wheels[i - 1], &wheels[i]);
    let f = if b.t_s > a.t_s {
        (t_s - a.t_s) / (b.t_s - a.t_s)
    } else {
        0.0
    };
    [
        a.left_rad + f * (b.left_rad - a.left_rad),
        a.right_rad + f * (b.right_rad - a.right_rad),
    ]
}

/// The encoder increments between `t0_s` and `t1_s`: one step per encoder
/// sample inside, the ends interpolated.
pub fn wheel_steps(wheels: &[WheelSample], t0_s: f64, t1_s: f64) -> Vec<[f64; 2]> {
    if wheels.is_empty() || t1_s <= t0_s {
        return Vec::new();
    }
    let mut steps = Vec::new();
    let mut last = wheels_at(wheels, t0_s);
    let first = wheels.partition_point(|w| w.t_s <= t0_s);
    for w in wheels[first..].iter().take_while(|w| w.t_s < t1_s) {
        steps.push([w.left_rad - last[0], w.right_rad - last[1]]);
        last = [w.left_rad, w.right_rad];
    }
    let end = wheels_at(wheels, t1_s);
    steps.push([end[0] - last[0], end[1] - last[1]]);
    steps
}

/// The gyro's turn between `t0_s` and `t1_s` (rad): its rate samples
/// `(t_s, rad_s)` integrated by trapezoids, the ends interpolated.
pub fn gyro_turn(gyro: &[(f64, f64)], t0_s: f64, t1_s: f64) -> Option<f64> {
    let covered = gyro.first()?.0 <= t0_s && gyro.last()?.0 >= t1_s;
    if !covered || t1_s <= t0_s {
        return None;
    }
    let rate_at = |t: f64| {
        let i = gyro.partition_point(|g| g.0 <= t).clamp(1, gyro.len() - 1);
        let (a, b) = (gyro[i - 1], gyro[i]);
        if b.0 > a.0 {
            a.1 + (t - a.0) / (b.0 - a.0) * (b.1 - a.1)
        } else {
            a.1
        }
    };
    let mut turn = 0.0;
    let mut last = (t0_s, rate_at(t0_s));
    let first = gyro.partition_point(|g| g.0 <= t0_s);
    for &g in gyro[first..].iter().take_while(|g| g.0 < t1_s) {
        turn += 0.5 * (g.1 + last.1) * (g.0 - last.0);
        last = g;
    }
    turn += 0.5 * (rate_at(t1_s) + last.1) * (t1_s - last.0);
    Some(turn)
}

/// `a ⊕ b` in SE(2).
fn compose(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    let (s, c) = a[2].sin_cos();
    [
        a[0] + c * b[0] - s * b[1],
        a[1] + s * b[0] + c * b[1],
        a[2] + b[2],
    ]
}

/// The relative motions of a drive: `scans` in time order, `wheels` the
/// cumulative encoder angles, `gyro` the gyro's rate samples (empty for
/// none), `guess` the starting `[dL, dR, b, ℓx, ℓy, ℓθ]` the priors are
/// predicted with. `progress(done, total)` follows the scans.
pub fn laser_odometry(
    scans: &[Scan],
    wheels: &[WheelSample],
    gyro: &[(f64, f64)],
    guess: [f64; 6],
    settings: &LaserOdometrySettings,
    mut progress: impl FnMut(usize, usize),
) -> LaserOdometry {
    let m = &settings.matcher;
    let reach = m.outlier_m + 0.2;
    let mut out = LaserOdometry {
        motions: Vec::new(),
        scans: scans.len(),
        consecutive_matched: 0,
        consecutive_refused: BTreeMap::new(),
        intervals: 0,
        standstills: 0,
        refused: BTreeMap::new(),
    };
    if scans.len() < 2 || wheels.len() < 2 {
        return out;
    }
    let points: Vec<Vec<[f64; 2]>> = scans.iter().map(Scan::points).collect();
    // The lidar's motion from scan k - 1 to scan k, matched or predicted.
    let mut step_motion = vec![[0.0; 3]; scans.len()];
    let mut previous = ScanReference::new(&scans[0], reach);
    for k in 1..scans.len() {
        let steps = wheel_steps(wheels, scans[k - 1].t_s, scans[k].t_s);
        let predicted = predict_laser_motion(&steps, guess);
        step_motion[k] = match register(&previous, &points[k], predicted, m) {
            Ok(matched) => {
                out.consecutive_matched += 1;
                matched.pose
            }
            Err(refusal) => {
                *out.consecutive_refused.entry(refusal.kind()).or_default() += 1;
                predicted
            }
        };
        previous = ScanReference::new(&scans[k], reach);
        if k % 64 == 0 {
            progress(k, scans.len());
        }
    }
    // Intervals: from each opening scan to the first scan `interval_s`
    // later, matched directly from the chain between them.
    let mut a = 0;
    while a + 1 < scans.len() {
        let mut b = a + 1;
        let mut prior = step_motion[b];
        // A microsecond's slack: stamps rounded on their way through a
        // recording (a Unix time in f64 is good to 0.2 µs) must not move an
        // interval's end by a scan.
        while b + 1 < scans.len() && scans[b].t_s - scans[a].t_s < settings.interval_s - 1e-6 {
            b += 1;
            prior = compose(prior, step_motion[b]);
        }
        let (t0_s, t1_s) = (scans[a].t_s, scans[b].t_s);
        let steps = wheel_steps(wheels, t0_s, t1_s);
        let turned = steps
            .iter()
            .fold([0.0f64; 2], |acc, s| [acc[0] + s[0], acc[1] + s[1]]);
        if turned[0].abs().max(turned[1].abs()) < settings.min_wheel_turn_rad {
            out.standstills += 1;
        } else {
            let reference = ScanReference::new(&scans[a], reach);
            match register(&reference, &points[b], prior, m) {
                Ok(matched) => {
                    out.intervals += 1;
                    out.motions.push(RelativeMotion {
                        t0_s,
                        t1_s,
                        wheel_steps: steps,
                        laser: matched.pose,
                        laser_cov: matched.covariance,
                        gyro_rad: gyro_turn(gyro, t0_s, t1_s),
                    });
                }
                Err(refusal) => *out.refused.entry(refusal.kind()).or_default() += 1,
            }
        }
        a = b;
    }
    progress(scans.len(), scans.len());
    out
}
