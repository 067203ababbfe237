//! Dead reckoning from cumulative wheel angles with given parameters.

use twindrive_kinematics::{DiffDriveParams, Pose, arc_step_wheels};

use crate::online::WheelSample;

/// Index of the last sample at or before `t_s` (binary search).
fn bracket(wheels: &[WheelSample], t_s: f64) -> Option<usize> {
    let k = wheels.partition_point(|w| w.t_s <= t_s);
    k.checked_sub(1)
}

/// Cumulative wheel angles at `t_s`, linearly interpolated; `None` outside the samples.
pub fn wheel_angles_at(wheels: &[WheelSample], t_s: f64) -> Option<(f64, f64)> {
    let k = bracket(wheels, t_s)?;
    let a = &wheels[k];
    if a.t_s == t_s {
        return Some((a.left_rad, a.right_rad));
    }
    let b = wheels.get(k + 1)?;
    let f = (t_s - a.t_s) / (b.t_s - a.t_s);
    Some((
        a.left_rad + f * (b.left_rad - a.left_rad),
        a.right_rad + f * (b.right_rad - a.right_rad),
    ))
}

/// Integrates from `start` at `t0_s` to `t1_s`, returning the pose at
/// `t0_s` and at every encoder sample strictly inside, then at `t1_s`.
/// Empty if the encoder samples do not cover `[t0_s, t1_s]`.
pub fn dead_reckon(
    wheels: &[WheelSample],
    start: Pose,
    t0_s: f64,
    t1_s: f64,
    params: &DiffDriveParams,
) -> Vec<(f64, Pose)> {
    let (Some(mut at), Some(_)) = (wheel_angles_at(wheels, t0_s), wheel_angles_at(wheels, t1_s))
    else {
        return Vec::new();
    };
    let mut pose = start;
    let mut out = vec![(t0_s, pose)];
    let first = wheels.partition_point(|w| w.t_s <= t0_s);
    for w in wheels[first..].iter().take_while(|w| w.t_s < t1_s) {
        pose = arc_step_wheels(&pose, params, w.left_rad - at.0, w.right_rad - at.1);
        at = (w.left_rad, w.right_rad);
        out.push((w.t_s, pose));
    }
    let end = wheel_angles_at(wheels, t1_s).expect("checked above");
    if t1_s > out.last().expect("non-empty").0 {
        pose = arc_step_wheels(&pose, params, end.0 - at.0, end.1 - at.1);
        out.push((t1_s, pose));
    }
    out
}

/// The pose of a time-sorted track at `t_s`, interpolated (heading along the
/// shorter arc); `None` outside the track.
pub fn pose_at(track: &[(f64, Pose)], t_s: f64) -> Option<Pose> {
    let k = track.partition_point(|(t, _)| *t <= t_s).checked_sub(1)?;
    let (ta, a) = track[k];
    if ta == t_s {
        return Some(a);
    }
    let (tb, b) = *track.get(k + 1)?;
    let f = (t_s - ta) / (tb - ta);
    let dh = twindrive_kinematics::wrap_angle(b.heading_rad - a.heading_rad);
    Some(Pose::new(
        a.x_m + f * (b.x_m - a.x_m),
        a.y_m + f * (b.y_m - a.y_m),
        a.heading_rad + f * dh,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_line_and_interpolation() {
        let p = DiffDriveParams::new(0.1, 0.1, 0.3);
        // 20 rad/s on both wheels = 1 m/s.
        let wheels: Vec<WheelSample> = (0..=10)
            .map(|k| WheelSample {
                t_s: k as f64 * 0.1,
                left_rad: 2.0 * k as f64,
                right_rad: 2.0 * k as f64,
            })
            .collect();
        let track = dead_reckon(&wheels, Pose::new(0.0, 0.0, 0.0), 0.05, 0.95, &p);
        assert_eq!(track.first().unwrap().0, 0.05);
        assert_eq!(track.last().unwrap().0, 0.95);
        assert!((track.last().unwrap().1.x_m - 0.9).abs() < 1e-12);
        let mid = pose_at(&track, 0.5).unwrap();
        assert!((mid.x_m - 0.45).abs() < 1e-12);
        assert!(dead_reckon(&wheels, Pose::default(), 0.5, 2.0, &p).is_empty());
    }
}
