//! Turning log files into estimator samples: simulator log directories and
//! generic encoder/pose CSV files.

use std::path::Path;

use anyhow::{Context, bail};
use twindrive_estimation::{PoseSample, WheelSample};
use twindrive_log::MissionLog;
use twindrive_log::calib_csv::{EncoderCsv, PoseCsv, WheelColumns};

use crate::cli::{CalibrateArgs, JointSignalArg, StampsArg};

/// A mission log: a directory `simulate` wrote, or a log MCAP (robot logs,
/// rehearsals).
pub fn read_mission_log(path: &Path) -> anyhow::Result<MissionLog> {
    if path.is_dir() {
        Ok(twindrive_log::read_log_dir(path)?)
    } else {
        Ok(twindrive_log::read_mcap(path)?)
    }
}

/// Encoder ticks of a simulated log as cumulative wheel angles.
pub fn wheels_from_log(log: &MissionLog) -> Vec<WheelSample> {
    log.wheel_angles()
        .map(|(t_s, left_rad, right_rad)| WheelSample {
            t_s,
            left_rad,
            right_rad,
        })
        .collect()
}

/// Tracker poses of a simulated log.
pub fn poses_from_log(log: &MissionLog) -> Vec<PoseSample> {
    log.tracker_poses()
        .map(|(t_s, p)| PoseSample {
            t_s,
            x_m: p.x_m,
            y_m: p.y_m,
            heading_rad: Some(p.heading_rad),
        })
        .collect()
}

/// Cumulative wheel angles from an encoder CSV. Ticks need `ticks_per_rev`;
/// wheel speeds are integrated with the trapezoid rule. Signs flip counters
/// that run backwards.
pub fn wheels_from_csv(
    enc: &EncoderCsv,
    path: &Path,
    ticks_per_rev: Option<u32>,
    signs: [f64; 2],
) -> anyhow::Result<Vec<WheelSample>> {
    let n = enc.t_s.len();
    let mut out = Vec::with_capacity(n);
    match enc.columns {
        WheelColumns::Ticks => {
            let tpr = ticks_per_rev.with_context(|| {
                format!(
                    "{}: holds encoder ticks, so --ticks-per-rev is needed",
                    path.display()
                )
            })?;
            if tpr == 0 {
                bail!("--ticks-per-rev must be > 0");
            }
            let k = std::f64::consts::TAU / f64::from(tpr);
            for i in 0..n {
                out.push(WheelSample {
                    t_s: enc.t_s[i],
                    left_rad: signs[0] * enc.left[i] * k,
                    right_rad: signs[1] * enc.right[i] * k,
                });
            }
        }
        WheelColumns::RadPerSecond => {
            let speeds = (0..n).map(|i| (enc.t_s[i], [enc.left[i], enc.right[i]]));
            for (t_s, [l, r]) in twindrive_kinematics::wheel_angles_from_speeds(speeds) {
                out.push(WheelSample {
                    t_s,
                    left_rad: signs[0] * l,
                    right_rad: signs[1] * r,
                });
            }
        }
    }
    Ok(out)
}

pub fn poses_from_csv(p: &PoseCsv) -> Vec<PoseSample> {
    (0..p.t_s.len())
        .map(|i| PoseSample {
            t_s: p.t_s[i],
            x_m: p.x_m[i],
            y_m: p.y_m[i],
            heading_rad: (!p.theta_rad[i].is_nan()).then_some(p.theta_rad[i]),
        })
        .collect()
}

/// Wheel angles and reference poses from a rosbag2 recording, with times
/// counted from the first pose's whole second (returned third).
pub fn from_bag(
    args: &CalibrateArgs,
    signs: [f64; 2],
) -> anyhow::Result<(Vec<WheelSample>, Vec<PoseSample>, f64)> {
    use twindrive_ros::extract::{self, JointSignal, PoseSource, Stamps, WheelSource};
    let path = args.bag.as_deref().expect("called with --bag");
    let bag = twindrive_ros::Bag::open(path).context("--bag")?;
    let stamps = match args.stamps {
        StampsArg::Header => Stamps::Header,
        StampsArg::Log => Stamps::LogTime,
    };
    let wheel_source = match (&args.ticks_topic, &args.left_joint, &args.right_joint) {
        (Some(topic), _, _) => WheelSource::Ticks {
            topic: topic.clone(),
            left_field: args.left_field.clone().expect("clap requires it"),
            right_field: args.right_field.clone().expect("clap requires it"),
            ticks_per_rev: args.ticks_per_rev.expect("clap requires it"),
        },
        (None, Some(l), Some(r)) => WheelSource::Joints {
            topic: args.joint_topic.clone(),
            left: l.clone(),
            right: r.clone(),
            signal: match args.joint_signal {
                JointSignalArg::Auto => JointSignal::Auto,
                JointSignalArg::Position => JointSignal::Position,
                JointSignalArg::Velocity => JointSignal::Velocity,
            },
        },
        _ => bail!(
            "--bag: name the wheels with --left-joint and --right-joint (on --joint-topic, default /joint_states), \
             or with --ticks-topic, --left-field and --right-field; the bag has: {}",
            bag.describe_topics()
        ),
    };
    let pose_source = PoseSource {
        topic: args.pose_topic.clone().expect("clap requires it"),
        frame: args.pose_frame.clone(),
        parent: args.pose_parent.clone(),
    };
    let (wheels, poses) = std::thread::scope(|scope| {
        let w = scope.spawn(|| extract::wheel_track(&bag, &wheel_source, stamps));
        let p = extract::pose_track(&bag, &pose_source, stamps);
        (w.join(), p)
    });
    let wheels = wheels.map_err(|_| anyhow::anyhow!("reading the wheels panicked"))??;
    let poses = poses?;
    tracing::info!(
        wheel_samples = wheels.samples.len(),
        wheel_signal = %wheels.used,
        other_messages = wheels.skipped,
        poses = poses.samples.len(),
        pose_type = %poses.used,
        "read the bag"
    );
    let origin = poses.samples[0].0.floor();
    Ok((
        wheels
            .samples
            .iter()
            .map(|&(t, l, r)| WheelSample {
                t_s: t - origin,
                left_rad: signs[0] * l,
                right_rad: signs[1] * r,
            })
            .collect(),
        poses
            .samples
            .iter()
            .map(|&(t, x, y, h)| PoseSample {
                t_s: t - origin,
                x_m: x,
                y_m: y,
                heading_rad: Some(h),
            })
            .collect(),
        origin,
    ))
}

/// Shifts encoder times onto the pose clock.
pub fn shift(wheels: &mut [WheelSample], offset_s: f64) {
    for w in wheels {
        w.t_s += offset_s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wheel_speeds_integrate_and_signs_apply() {
        let enc = EncoderCsv {
            columns: WheelColumns::RadPerSecond,
            t_s: vec![0.0, 1.0, 2.0],
            left: vec![1.0, 1.0, 3.0],
            right: vec![2.0, 2.0, 2.0],
        };
        let w = wheels_from_csv(&enc, Path::new("e.csv"), None, [1.0, -1.0]).unwrap();
        assert_eq!((w[2].left_rad, w[2].right_rad), (3.0, -4.0));
        let ticks = EncoderCsv {
            columns: WheelColumns::Ticks,
            ..enc
        };
        let err = wheels_from_csv(&ticks, Path::new("e.csv"), None, [1.0, 1.0])
            .unwrap_err()
            .to_string();
        assert!(err.contains("--ticks-per-rev is needed"));
        let w = wheels_from_csv(&ticks, Path::new("e.csv"), Some(4), [-1.0, 1.0]).unwrap();
        assert!((w[2].left_rad + 3.0 * std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }
}
