//! The mission planner (paper section 5): re-creates the executed path from
//! the log's encoder counts and sampling times with the *calibrated*
//! parameters, which is what the robot's own odometry says, not from the
//! twin's hidden ground truth. The start pose is the one the operator placed
//! the robot at (`LogHeader::start`).
//!
//! Encoder counts are quantised: at 100 Hz a wheel turns a few ticks per
//! sample, so differences of raw counts jitter by a tick (tens of percent of
//! the speed) and their changes look like accelerations far above any real
//! motor's. The cumulative wheel angles are therefore smoothed first with a
//! Savitzky-Golay filter (local quadratic fits over `smoothing_window_s`),
//! which keeps constant accelerations exact and leaves the integrated path
//! within a fraction of a tick of the raw one.

use twindrive_kinematics::{DiffDriveParams, arc_step_wheels, body_increment};
use twindrive_log::MissionLog;

use crate::error::PipelineError;
use crate::path::PathSample;

/// Planner settings.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlannerSettings {
    /// Span of the local quadratic fits that smooth the encoder angles
    /// (0: use the raw counts).
    pub smoothing_window_s: f64,
}

impl Default for PlannerSettings {
    fn default() -> Self {
        Self {
            smoothing_window_s: 0.6,
        }
    }
}

/// Savitzky-Golay smoothing (quadratic, symmetric windows of up to
/// `2 half + 1` samples, shrinking near the ends).
pub fn savitzky_golay(values: &[f64], half: usize) -> Vec<f64> {
    let n = values.len();
    // No window is wider than the data.
    let half = half.min(n.saturating_sub(1) / 2);
    let coefficients = |m: usize| -> Vec<f64> {
        let mf = m as f64;
        let norm = (2.0 * mf - 1.0) * (2.0 * mf + 1.0) * (2.0 * mf + 3.0);
        (0..=2 * m)
            .map(|i| {
                let j = i as f64 - mf;
                (3.0 * (3.0 * mf * mf + 3.0 * mf - 1.0) - 15.0 * j * j) / norm
            })
            .collect()
    };
    // Interior samples use the full width; only the ends need the narrower
    // ones, which are made when first needed.
    let mut table: Vec<Option<Vec<f64>>> = vec![None; half + 1];
    (0..n)
        .map(|k| {
            let m = half.min(k).min(n - 1 - k);
            if m < 2 {
                return values[k];
            }
            table[m]
                .get_or_insert_with(|| coefficients(m))
                .iter()
                .zip(&values[k - m..=k + m])
                .map(|(c, v)| c * v)
                .sum()
        })
        .collect()
}

/// The wheel angles smoothed (Savitzky-Golay, windows of `half` samples
/// each side) stretch by stretch between standstills: where neither
/// wheel's count changes for `half` samples or more the robot stands, and
/// stands exactly (a dwell is not smoothed into a creep); each moving
/// stretch is smoothed on its own, its windows shrinking to the raw counts
/// at the standstills on either side, as at the log's ends.
fn smooth_moving(encoders: &[(f64, [f64; 2])], half: usize) -> Vec<[f64; 2]> {
    let n = encoders.len();
    let mut still = vec![false; n];
    let mut k = 0;
    while k < n {
        let run = encoders[k..]
            .iter()
            .take_while(|e| e.1 == encoders[k].1)
            .count();
        if run > half.max(1) {
            still[k..k + run].fill(true);
        }
        k += run;
    }
    let mut out: Vec<[f64; 2]> = encoders.iter().map(|e| e.1).collect();
    let mut k = 0;
    while k < n {
        if still[k] {
            k += 1;
            continue;
        }
        // From the standstill before (or the start) to the one after (or
        // the end), both ends kept as they are.
        let a = k.saturating_sub(1);
        let b = (k..n).find(|&j| still[j]).unwrap_or(n - 1);
        let smooth = |wheel: usize| {
            let values: Vec<f64> = encoders[a..=b].iter().map(|e| e.1[wheel]).collect();
            savitzky_golay(&values, half)
        };
        let (left, right) = (smooth(0), smooth(1));
        for (o, (l, r)) in out[a..=b].iter_mut().zip(left.into_iter().zip(right)) {
            *o = [l, r];
        }
        k = b + 1;
    }
    out
}

/// The executed path at every encoder sample. `v_m_s` and `omega_rad_s` of a
/// sample are the velocities over the interval that starts there (the last
/// sample's are zero).
pub fn executed_path(
    log: &MissionLog,
    params: &DiffDriveParams,
    settings: &PlannerSettings,
) -> Result<Vec<PathSample>, PipelineError> {
    if log.steps.is_empty() {
        return Err(PipelineError::EmptyLog);
    }
    let rad_per_tick = std::f64::consts::TAU / f64::from(log.header.ticks_per_rev);
    let encoders: Vec<(f64, [f64; 2])> = log
        .steps
        .iter()
        .filter_map(|s| {
            s.encoder_ticks
                .map(|[l, r]| (s.t_s(), [l as f64 * rad_per_tick, r as f64 * rad_per_tick]))
        })
        .collect();
    if encoders.len() < 2 {
        return Err(PipelineError::NoEncoderData(encoders.len()));
    }
    if !(settings.smoothing_window_s.is_finite() && settings.smoothing_window_s >= 0.0) {
        return Err(PipelineError::Value(
            twindrive_plan::PlanError::BadSetting {
                field: "smoothing_window_s",
                value: settings.smoothing_window_s,
            },
        ));
    }
    for (k, w) in encoders.windows(2).enumerate() {
        if w[1].0 <= w[0].0 || !w[1].0.is_finite() {
            return Err(PipelineError::Value(
                twindrive_plan::PlanError::TimeNotIncreasing {
                    index: k + 1,
                    t_s: w[1].0,
                    previous_s: w[0].0,
                },
            ));
        }
    }
    let span = encoders.last().expect("two at least").0 - encoders[0].0;
    let period = span / (encoders.len() - 1) as f64;
    let half = (0.5 * settings.smoothing_window_s / period).round() as usize;
    let smoothed = smooth_moving(&encoders, half);
    let encoders: Vec<(f64, [f64; 2])> = encoders
        .iter()
        .zip(smoothed)
        .map(|(e, a)| (e.0, a))
        .collect();
    let mut out = Vec::with_capacity(encoders.len());
    let mut pose = log.header.start;
    for w in encoders.windows(2) {
        let ((t0, a0), (t1, a1)) = (w[0], w[1]);
        let (dl, dr) = (a1[0] - a0[0], a1[1] - a0[1]);
        let (left_m, right_m) = params.wheel_travel_from_angles(dl, dr);
        let (ds, dtheta) = body_increment(left_m, right_m, params.wheelbase_m);
        let dt = t1 - t0;
        out.push(PathSample {
            t_s: t0,
            pose,
            v_m_s: ds / dt,
            omega_rad_s: dtheta / dt,
        });
        pose = arc_step_wheels(&pose, params, dl, dr);
    }
    out.push(PathSample {
        t_s: encoders.last().expect("two at least").0,
        pose,
        v_m_s: 0.0,
        omega_rad_s: 0.0,
    });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smoothing_keeps_quadratics_and_copes_with_short_and_dense_data() {
        let q: Vec<f64> = (0..50)
            .map(|k| 0.5 * (k as f64).powi(2) - 3.0 * k as f64)
            .collect();
        let s = savitzky_golay(&q, 7);
        for (a, b) in q.iter().zip(&s) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
        // A window far wider than the data (dense time stamps) costs nothing.
        assert_eq!(savitzky_golay(&[1.0, 2.0], usize::MAX / 2), vec![1.0, 2.0]);
        assert_eq!(savitzky_golay(&[], 10), Vec::<f64>::new());
    }
}
