//! The offset between the encoder clock and the pose clock, when the two
//! recordings share none: the heading rate seen by the encoders (any rough
//! parameters will do; a scale error does not move the peak) is
//! cross-correlated with the heading rate of the pose reference.
//!
//! Convention: `t_pose = t_encoder + offset_s`.

use serde::{Deserialize, Serialize};

use crate::dead_reckoning::wheel_angles_at;
use crate::online::{PoseSample, WheelSample};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClockOffset {
    pub offset_s: f64,
    /// Pearson correlation at the peak.
    pub correlation: f64,
}

/// Heading-rate signal of the encoders on a uniform grid starting at `t0`.
fn encoder_rate(wheels: &[WheelSample], params: [f64; 3], t0: f64, dt: f64, n: usize) -> Vec<f64> {
    let heading = |t: f64| {
        wheel_angles_at(wheels, t).map(|(l, r)| (params[1] * r - params[0] * l) / (2.0 * params[2]))
    };
    let samples: Vec<f64> = (0..=n)
        .map(|k| heading(t0 + k as f64 * dt).unwrap_or(f64::NAN))
        .collect();
    central_rate(&samples, dt)
}

/// Half-width of the symmetric difference that turns angles into rates: long
/// enough to average out reference noise, symmetric so it shifts nothing.
const RATE_HALF_WINDOW_S: f64 = 0.1;

/// `(v[k + w] − v[k − w]) / (2 w dt)`, NaN where the window leaves the data.
fn central_rate(samples: &[f64], dt: f64) -> Vec<f64> {
    let w = ((RATE_HALF_WINDOW_S / dt).round() as usize).max(1);
    (0..samples.len())
        .map(|k| {
            if k < w || k + w >= samples.len() {
                f64::NAN
            } else {
                (samples[k + w] - samples[k - w]) / (2.0 * w as f64 * dt)
            }
        })
        .collect()
}

/// Heading-rate (or, without headings, speed) signal of the poses.
fn pose_rate(poses: &[PoseSample], t0: f64, dt: f64, n: usize, use_heading: bool) -> Vec<f64> {
    // Unwrapped heading or cumulative distance, then interpolated on the grid.
    let heading = |p: &PoseSample| p.heading_rad.unwrap_or(0.0);
    let mut value: Vec<(f64, f64)> = Vec::with_capacity(poses.len());
    let mut acc = 0.0;
    for (i, p) in poses.iter().enumerate() {
        acc = match (i.checked_sub(1).map(|j| &poses[j]), use_heading) {
            (None, true) => heading(p),
            (None, false) => 0.0,
            (Some(q), true) => acc + twindrive_kinematics::wrap_angle(heading(p) - heading(q)),
            (Some(q), false) => acc + (p.x_m - q.x_m).hypot(p.y_m - q.y_m),
        };
        value.push((p.t_s, acc));
    }
    let at = |t: f64| -> f64 {
        let k = value.partition_point(|v| v.0 <= t);
        if k == 0 || k >= value.len() {
            return f64::NAN;
        }
        let (a, b) = (value[k - 1], value[k]);
        // Long gaps (dropouts) carry no rate information.
        if b.0 - a.0 > 0.5 {
            return f64::NAN;
        }
        a.1 + (t - a.0) / (b.0 - a.0) * (b.1 - a.1)
    };
    let samples: Vec<f64> = (0..=n).map(|k| at(t0 + k as f64 * dt)).collect();
    central_rate(&samples, dt)
}

/// Pearson correlation of `a[i]` with `b[i + lag]` over the finite overlap.
fn correlation(a: &[f64], b: &[f64], lag: i64) -> Option<f64> {
    let (mut n, mut sa, mut sb, mut saa, mut sbb, mut sab) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let start = (-lag).max(0) as usize;
    let end = (b.len() as i64 - lag).min(a.len() as i64).max(0) as usize;
    for i in start..end {
        let (x, y) = (a[i], b[(i as i64 + lag) as usize]);
        if x.is_nan() || y.is_nan() {
            continue;
        }
        n += 1.0;
        sa += x;
        sb += y;
        saa += x * x;
        sbb += y * y;
        sab += x * y;
    }
    if n < 50.0 {
        return None;
    }
    let cov = sab - sa * sb / n;
    let va = saa - sa * sa / n;
    let vb = sbb - sb * sb / n;
    (va > 0.0 && vb > 0.0).then(|| cov / (va * vb).sqrt())
}

/// Best lag of `b` against `a` among `lags`, with its correlation.
fn best_lag(a: &[f64], b: &[f64], lags: impl Iterator<Item = i64>) -> Option<(i64, f64)> {
    lags.filter_map(|l| correlation(a, b, l).map(|c| (l, c)))
        .max_by(|x, y| x.1.total_cmp(&y.1))
}

/// Estimates the offset, requiring at least `min_overlap_s` of overlap.
pub fn estimate_offset(
    wheels: &[WheelSample],
    poses: &[PoseSample],
    params: [f64; 3],
    min_overlap_s: f64,
) -> Option<ClockOffset> {
    let (w0, w1) = (wheels.first()?.t_s, wheels.last()?.t_s);
    let (p0, p1) = (poses.first()?.t_s, poses.last()?.t_s);
    let use_heading = poses.iter().all(|p| p.heading_rad.is_some());
    let search = |dt: f64, lo: f64, hi: f64| -> Option<(f64, f64)> {
        // Encoder signal on its own grid; pose signal on a grid aligned to it
        // by whole samples of `dt` for offsets in [lo, hi].
        let n_w = ((w1 - w0) / dt) as usize;
        let a = encoder_rate(wheels, params, w0, dt, n_w);
        let base = w0 + lo;
        let n_p = ((p1 - base).max(0.0) / dt) as usize + 1;
        let b = pose_rate(poses, base, dt, n_p, use_heading);
        let lags = 0..=((hi - lo) / dt).ceil() as i64;
        let (lag, corr) = best_lag(&a, &b, lags)?;
        // Parabolic refinement of the peak.
        let c = |l: i64| correlation(&a, &b, l).unwrap_or(corr);
        let (cm, cp) = (c(lag - 1), c(lag + 1));
        let denom = cm - 2.0 * corr + cp;
        let frac = if denom < 0.0 {
            (0.5 * (cm - cp) / denom).clamp(-0.5, 0.5)
        } else {
            0.0
        };
        Some((lo + (lag as f64 + frac) * dt, corr))
    };
    // Offsets that leave at least `min_overlap_s` of overlap.
    let lo = p0 - w1 + min_overlap_s;
    let hi = p1 - w0 - min_overlap_s;
    if hi < lo {
        return None;
    }
    let coarse_dt = ((hi - lo) / 4000.0).max(0.1);
    let (coarse, _) = search(coarse_dt, lo, hi)?;
    let (mid, _) = search(0.02, coarse - 2.0 * coarse_dt, coarse + 2.0 * coarse_dt)?;
    let (fine, corr) = search(0.005, mid - 0.05, mid + 0.05)?;
    Some(ClockOffset {
        offset_s: fine,
        correlation: corr,
    })
}
