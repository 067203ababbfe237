//! How well parameters dead-reckon against a reference: fixed-length windows,
//! each started from the reference pose.

use serde::{Deserialize, Serialize};
use twindrive_kinematics::{DiffDriveParams, Pose, wrap_angle};

use crate::dead_reckoning::{dead_reckon, pose_at};
use crate::online::{PoseSample, WheelSample};

/// Errors at the end of one window.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WindowError {
    pub t0_s: f64,
    pub t1_s: f64,
    /// Distance between the dead-reckoned and the reference end position.
    pub position_error_m: f64,
    /// |dead-reckoned − reference| end heading, wrapped.
    pub heading_error_rad: f64,
    /// Dead-reckoned minus reference path length.
    pub path_length_error_m: f64,
    pub reference_length_m: f64,
}

/// The reference as a track of planar poses (headings required).
pub fn reference_track(poses: &[PoseSample]) -> Vec<(f64, Pose)> {
    poses
        .iter()
        .filter_map(|p| p.heading_rad.map(|h| (p.t_s, Pose::new(p.x_m, p.y_m, h))))
        .collect()
}

/// Path length sampled every `step_s` (dense reference noise would add length).
fn track_length(track: &[(f64, Pose)], t0: f64, t1: f64, step_s: f64) -> Option<f64> {
    let n = ((t1 - t0) / step_s).ceil() as usize;
    let mut prev = pose_at(track, t0)?;
    let mut len = 0.0;
    for k in 1..=n {
        let p = pose_at(track, (t0 + k as f64 * step_s).min(t1))?;
        len += prev.distance_to(&p);
        prev = p;
    }
    Some(len)
}

/// Dead-reckons consecutive windows of `window_s` in `[from_s, to_s]`, each
/// from the reference pose at its start. Windows the data does not cover
/// are skipped.
pub fn dead_reckoning_windows(
    wheels: &[WheelSample],
    reference: &[(f64, Pose)],
    params: &DiffDriveParams,
    from_s: f64,
    to_s: f64,
    window_s: f64,
) -> Vec<WindowError> {
    let mut out = Vec::new();
    let mut t0 = from_s;
    while t0 + window_s <= to_s + 1e-9 {
        let t1 = t0 + window_s;
        if let (Some(start), Some(end)) = (pose_at(reference, t0), pose_at(reference, t1)) {
            let track = dead_reckon(wheels, start, t0, t1, params);
            let dr_track: Vec<(f64, Pose)> = track.clone();
            if let (Some(&(_, last)), Some(ref_len), Some(dr_len)) = (
                track.last(),
                track_length(reference, t0, t1, 0.1),
                track_length(&dr_track, t0, t1, 0.1),
            ) {
                out.push(WindowError {
                    t0_s: t0,
                    t1_s: t1,
                    position_error_m: last.distance_to(&end),
                    heading_error_rad: wrap_angle(last.heading_rad - end.heading_rad).abs(),
                    path_length_error_m: dr_len - ref_len,
                    reference_length_m: ref_len,
                });
            }
        }
        t0 = t1;
    }
    out
}

/// Mean of a window error field.
pub fn mean(windows: &[WindowError], field: impl Fn(&WindowError) -> f64) -> f64 {
    if windows.is_empty() {
        return f64::NAN;
    }
    windows.iter().map(field).sum::<f64>() / windows.len() as f64
}
