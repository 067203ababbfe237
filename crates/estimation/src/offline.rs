//! The offline runner: the online filter over a whole log, plus the smoother.

use crate::covariance::PackedEstimate;
use crate::ekf::FilterStats;
use crate::online::{
    CalibrationError, Estimate, FilterConfig, FilterHistory, OnlineCalibrator, PoseSample,
    WheelSample, initial_estimate,
};
use crate::smoother::rts_smooth;

/// Everything an offline filter run produces.
#[derive(Debug, Clone)]
pub struct FilterRun {
    /// Final filtered estimate.
    pub estimate: Estimate,
    pub stats: FilterStats,
    pub history: Option<FilterHistory>,
}

/// Heading of the first metre of a position-only track.
fn initial_heading(poses: &[PoseSample]) -> f64 {
    let p0 = &poses[0];
    poses
        .iter()
        .find(|p| (p.x_m - p0.x_m).hypot(p.y_m - p0.y_m) > 0.5)
        .map_or(0.0, |p| (p.y_m - p0.y_m).atan2(p.x_m - p0.x_m))
}

/// Runs the filter over time-sorted `wheels` and `poses` (the same time
/// base). The first pose at or after the first encoder sample initialises
/// the pose; `params` = [dL, dR, b] start it with `param_rel_std` relative
/// standard deviation. `progress(done, total)` is called now and then.
pub fn run_filter(
    wheels: &[WheelSample],
    poses: &[PoseSample],
    params: [f64; 3],
    param_rel_std: f64,
    config: FilterConfig,
    keep_history: bool,
    mut progress: impl FnMut(usize, usize),
) -> Result<FilterRun, CalibrationError> {
    let first_wheel = wheels
        .first()
        .ok_or_else(|| CalibrationError::Input("no encoder samples".into()))?;
    let start = poses
        .iter()
        .position(|p| p.t_s >= first_wheel.t_s)
        .ok_or_else(|| {
            CalibrationError::Input("no pose sample at or after the first encoder sample".into())
        })?;
    let poses = &poses[start..];
    let mut first = poses[0];
    if first.heading_rad.is_none() {
        first.heading_rad = Some(initial_heading(poses));
    }
    let mut init = initial_estimate(&first, params, &config.noise, param_rel_std);
    if poses[0].heading_rad.is_none() {
        init.covariance[(2, 2)] = 0.3f64.powi(2);
    }
    let mut cal = OnlineCalibrator::new(init, first.t_s, config, keep_history);
    cal.reserve(poses.len());
    // Feed both streams in time order, from the first pose on (earlier
    // encoder samples only anchor the wheel angles).
    let (mut i, mut j) = (0, 1);
    let total = wheels.len() + poses.len() - 1;
    let mut done = 0;
    while j < poses.len() || i < wheels.len() {
        let take_pose = match (wheels.get(i), poses.get(j)) {
            (Some(w), Some(p)) => p.t_s <= w.t_s,
            (None, Some(_)) => true,
            _ => false,
        };
        if take_pose {
            // Poses after the last encoder sample cannot be fused.
            if i >= wheels.len() {
                break;
            }
            cal.push_pose(poses[j])?;
            j += 1;
        } else {
            cal.push_wheels(wheels[i])?;
            i += 1;
        }
        done += 1;
        if done % 65_536 == 0 {
            progress(done, total);
        }
    }
    progress(total, total);
    let estimate = cal.estimate();
    let stats = *cal.stats();
    Ok(FilterRun {
        estimate,
        stats,
        history: cal.into_history(),
    })
}

/// Smoothed node estimates of a run kept with history.
pub fn smooth(run: &FilterRun) -> Result<Vec<PackedEstimate>, CalibrationError> {
    let history = run.history.as_ref().ok_or_else(|| {
        CalibrationError::Input("the filter run kept no history to smooth".into())
    })?;
    rts_smooth(history).ok_or_else(|| {
        CalibrationError::Input(
            "a predicted covariance was not positive-definite while smoothing".into(),
        )
    })
}
