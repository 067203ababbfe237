//! Turning recordings into estimator samples: simulator log directories,
//! generic encoder/pose CSV files and rosbag2 recordings.

use std::path::Path;

use anyhow::{Context, bail};
use twindrive_estimation::{PoseSample, WheelSample};
use twindrive_log::MissionLog;
use twindrive_log::calib_csv::{EncoderCsv, PoseCsv, WheelColumns};

use twindrive_kinematics::Pose;
use twindrive_ros::extract::{self, PoseSource, Stamps, WheelSource};

/// Where a calibration's samples come from.
#[derive(Debug, Clone)]
pub enum Source {
    /// A simulator output directory (`log.csv` and `log.meta.json`).
    LogDir(std::path::PathBuf),
    /// An encoder CSV and a pose CSV.
    Csv {
        encoders: std::path::PathBuf,
        poses: std::path::PathBuf,
    },
    /// A rosbag2 recording.
    Bag(BagSource),
}

/// What to read from a rosbag2 recording.
#[derive(Debug, Clone)]
pub struct BagSource {
    pub path: std::path::PathBuf,
    pub stamps: Stamps,
    /// The wheels; `None` fails with the topics the bag has.
    pub wheels: Option<WheelSource>,
    pub poses: PoseSource,
}

/// A recording read into samples.
#[derive(Debug, Clone)]
pub struct Recording {
    pub wheels: Vec<WheelSample>,
    pub poses: Vec<PoseSample>,
    /// The parameters the recording says the operator believes (simulator
    /// logs), a calibration's default start.
    pub nominal: Option<[f64; 3]>,
    pub ticks_per_rev: Option<u32>,
    /// The true pose track (simulator logs).
    pub truth: Option<Vec<(f64, Pose)>>,
    /// Subtracted from the input's times (bags: Unix seconds).
    pub time_origin_s: f64,
}

/// Reads `source`. `signs` flip wheel counters that run backwards;
/// `ticks_per_rev` is needed for CSV ticks (a simulator log carries its own).
pub fn read(
    source: &Source,
    ticks_per_rev: Option<u32>,
    signs: [f64; 2],
) -> anyhow::Result<Recording> {
    match source {
        Source::Bag(bag) => {
            let (wheels, poses, time_origin_s) = from_bag(bag, signs)?;
            Ok(Recording {
                wheels,
                poses,
                nominal: None,
                ticks_per_rev,
                truth: None,
                time_origin_s,
            })
        }
        Source::LogDir(dir) => Ok(recording_from_log(&read_log_dir(dir)?, signs)),
        Source::Csv { encoders, poses } => {
            // The two files are read side by side.
            let (e, p) = std::thread::scope(|scope| {
                let e = scope.spawn(|| twindrive_log::calib_csv::read_encoder_csv(encoders));
                let p = twindrive_log::calib_csv::read_pose_csv(poses);
                (e.join(), p)
            });
            let e = e
                .map_err(|_| anyhow::anyhow!("reading the encoder log panicked"))?
                .context("--encoders")?;
            let p = p.context("--poses")?;
            Ok(Recording {
                wheels: wheels_from_csv(&e, encoders, ticks_per_rev, signs)?,
                poses: poses_from_csv(&p),
                nominal: None,
                ticks_per_rev,
                truth: None,
                time_origin_s: 0.0,
            })
        }
    }
}

/// A simulator log's wheels (`signs` flip counters that run backwards),
/// tracker poses, nominal parameters and true track.
pub fn recording_from_log(log: &MissionLog, signs: [f64; 2]) -> Recording {
    let n = log.header.nominal;
    Recording {
        wheels: signed_wheels_from_log(log, signs),
        poses: poses_from_log(log),
        nominal: Some([n.left_diameter_m, n.right_diameter_m, n.wheelbase_m]),
        ticks_per_rev: Some(log.header.ticks_per_rev),
        truth: Some(truth_from_log(log)),
        time_origin_s: 0.0,
    }
}

/// [`wheels_from_log`] with `signs` applied.
pub fn signed_wheels_from_log(log: &MissionLog, signs: [f64; 2]) -> Vec<WheelSample> {
    let mut wheels = wheels_from_log(log);
    for w in &mut wheels {
        w.left_rad *= signs[0];
        w.right_rad *= signs[1];
    }
    wheels
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

/// The true pose track of a simulated log.
pub fn truth_from_log(log: &MissionLog) -> Vec<(f64, Pose)> {
    log.steps
        .iter()
        .map(|s| (s.t_s(), s.ground_truth))
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

/// A bag's wheel track `(t, left, right)` as samples, times less `origin`,
/// `signs` applied.
pub fn bag_wheels(samples: &[(f64, f64, f64)], origin: f64, signs: [f64; 2]) -> Vec<WheelSample> {
    samples
        .iter()
        .map(|&(t, l, r)| WheelSample {
            t_s: t - origin,
            left_rad: signs[0] * l,
            right_rad: signs[1] * r,
        })
        .collect()
}

/// Wheel angles and reference poses from a rosbag2 recording, with times
/// counted from the first pose's whole second (returned third).
pub fn from_bag(
    source: &BagSource,
    signs: [f64; 2],
) -> anyhow::Result<(Vec<WheelSample>, Vec<PoseSample>, f64)> {
    let bag = twindrive_ros::Bag::open(&source.path).context("--bag")?;
    for d in bag.damage() {
        tracing::warn!("{d}; calibrating from what was read");
    }
    let stamps = source.stamps;
    let Some(wheel_source) = &source.wheels else {
        bail!(
            "--bag: name the wheels with --left-joint and --right-joint (on --joint-topic, default /joint_states), \
             or with --ticks-topic, --left-field and --right-field; the bag has: {}",
            bag.describe_topics()
        );
    };
    let pose_source = &source.poses;
    let (wheels, poses) = std::thread::scope(|scope| {
        let w = scope.spawn(|| extract::wheel_track(&bag, wheel_source, stamps));
        let p = extract::pose_track(&bag, pose_source, stamps);
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
        bag_wheels(&wheels.samples, origin, signs),
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

/// The three ways to give `calibrate` its data.
pub const INPUTS: &str = "give a simulator output directory (log.csv + log.meta.json from `twindrive simulate`), \
     both --encoders E.csv and --poses P.csv, or --bag BAG (a rosbag2 directory or one .mcap/.db3 file)";

/// A simulator output directory's log; any other directory is refused with
/// what `calibrate` expects.
pub fn read_log_dir(dir: &Path) -> anyhow::Result<twindrive_log::MissionLog> {
    if !dir.join("log.meta.json").is_file() {
        let what = if !dir.exists() {
            "does not exist"
        } else if !dir.is_dir() {
            "is a file, not a simulator output directory"
        } else {
            "is not a simulator log (no log.meta.json in it)"
        };
        bail!("{}: {what}; {INPUTS}", dir.display());
    }
    Ok(twindrive_log::read_log_dir(dir)?)
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
