//! Re-compute control (paper section 5): linear and angular velocity along a
//! path, then each wheel's speed by inverse kinematics with the calibrated
//! diameters and wheelbase.
//!
//! Segment `k` (from sample `k` to `k + 1`) is driven as one circular arc at
//! constant wheel speeds: it turns by the heading change (along the shorter
//! arc) and its chord is the displacement projected on the mid-arc heading.
//! For poses that came from arcs (dead reckoning) this reproduces the path
//! exactly through the forward model; where a deletion joined two distant
//! poses the part of the jump a differential drive cannot make (sideways) is
//! dropped, and the speeds show a spike for the filter to remove.

use twindrive_kinematics::{DiffDriveParams, sinc, wheel_speeds, wrap_angle};

use crate::path::PathSample;

/// Body and wheel speeds held over one segment.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WheelCommand {
    pub v_m_s: f64,
    pub omega_rad_s: f64,
    pub left_rad_s: f64,
    pub right_rad_s: f64,
}

impl WheelCommand {
    pub const STOP: WheelCommand = WheelCommand {
        v_m_s: 0.0,
        omega_rad_s: 0.0,
        left_rad_s: 0.0,
        right_rad_s: 0.0,
    };

    pub fn wheels(&self) -> [f64; 2] {
        [self.left_rad_s, self.right_rad_s]
    }
}

/// Arc length (signed) and heading change of the arc from `a` to `b`.
pub fn segment_arc(a: &PathSample, b: &PathSample) -> (f64, f64) {
    let dtheta = wrap_angle(b.pose.heading_rad - a.pose.heading_rad);
    let mid = a.pose.heading_rad + 0.5 * dtheta;
    let (s, c) = mid.sin_cos();
    let chord = (b.pose.x_m - a.pose.x_m) * c + (b.pose.y_m - a.pose.y_m) * s;
    (chord / sinc(0.5 * dtheta), dtheta)
}

/// The command of every segment, plus a final stop: one per sample. Writes
/// the body velocities into the samples too.
pub fn recompute(samples: &mut [PathSample], params: &DiffDriveParams) -> Vec<WheelCommand> {
    let mut out = Vec::with_capacity(samples.len());
    for k in 0..samples.len().saturating_sub(1) {
        let (a, b) = (&samples[k], &samples[k + 1]);
        let dt = b.t_s - a.t_s;
        let (ds, dtheta) = segment_arc(a, b);
        let (v, omega) = (ds / dt, dtheta / dt);
        let (l, r) = wheel_speeds(params, v, omega);
        out.push(WheelCommand {
            v_m_s: v,
            omega_rad_s: omega,
            left_rad_s: l,
            right_rad_s: r,
        });
        samples[k].v_m_s = v;
        samples[k].omega_rad_s = omega;
    }
    if let Some(last) = samples.last_mut() {
        last.v_m_s = 0.0;
        last.omega_rad_s = 0.0;
        out.push(WheelCommand::STOP);
    }
    out
}

/// Drives the commands through the forward model from the first sample's
/// pose: the pose reached at each sample time.
pub fn forward(
    samples: &[PathSample],
    commands: &[WheelCommand],
    params: &DiffDriveParams,
) -> Vec<twindrive_kinematics::Pose> {
    let Some(first) = samples.first() else {
        return Vec::new();
    };
    let mut pose = first.pose;
    let mut out = vec![pose];
    for (w, c) in samples.windows(2).zip(commands) {
        let dt = w[1].t_s - w[0].t_s;
        pose = twindrive_kinematics::arc_step_wheels(
            &pose,
            params,
            c.left_rad_s * dt,
            c.right_rad_s * dt,
        );
        out.push(pose);
    }
    out
}
