//! `twindrive calibrate`: wheel diameters and wheelbase from encoders plus an
//! absolute pose reference, or with the lidar's mount from encoders and
//! scans alone (the work is `twindrive-calibrate`'s).

use std::time::Instant;

use anyhow::{Context, bail};
use twindrive_calibrate::described_wheels::described_wheels;
use twindrive_calibrate::inputs::{self, BagSource, INPUTS, Source};
use twindrive_calibrate::scan_inputs::{self, BagScanSource, ScanRecording};
use twindrive_calibrate::{Job, Method, Offset, ScanJob};
use twindrive_estimation::FilterConfig;
use twindrive_estimation::selfcal::LaserOdometrySettings;
use twindrive_kinematics::Pose;
use twindrive_ros::extract::{PoseSource, WheelSource};

use crate::cli::{CalibrateArgs, MethodArg, ReferenceArg};
use crate::flags::{joint_signal, speed_source, stamps};
use crate::usage::{OrUsage, usage};

pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    if let (Some(path), Some(scan_topic)) = (&args.bag, &args.scan_topic) {
        let source = BagScanSource {
            path: path.clone(),
            stamps: stamps(args.stamps),
            wheels: Some(wheel_source(args)?.ok_or_else(|| {
                usage("--scan-topic: name the wheels with --left-joint and --right-joint, or --ticks-topic")
            })?),
            odometry: None,
            scan_topic: scan_topic.clone(),
            imu_topic: args.imu_topic.clone(),
            base_frame: args.base_frame.clone(),
        };
        let signs = [f64::from(args.left_sign), f64::from(args.right_sign)];
        let (rec, mount) = scan_inputs::from_bag(&source, signs)?;
        let source = if mount.is_some() {
            "/tf_static"
        } else {
            "none in the bag"
        };
        return run_scans(args, rec, source, started);
    }
    let log = match (&args.log_dir, args.reference) {
        (Some(dir), _) => Some(inputs::read_log_dir(dir)?),
        (None, ReferenceArg::Scans) => {
            return Err(usage(
                "--reference scans needs a simulator output directory (LOG_DIR) or --bag with --scan-topic",
            ));
        }
        (None, _) => None,
    };
    if let Some(log) = &log {
        let scans = match args.reference {
            ReferenceArg::Scans => true,
            ReferenceArg::Poses => false,
            ReferenceArg::Auto => scan_inputs::prefers_scans(log),
        };
        if scans {
            let signs = [f64::from(args.left_sign), f64::from(args.right_sign)];
            let rec = ScanRecording::from_log(log, args.scan_sensor.as_deref(), signs)?;
            check_ticks(args.ticks_per_rev, rec.ticks_per_rev)?;
            return run_scans(args, rec, "the log header", started);
        }
    }
    let job = resolve(args, log.as_ref())?;
    tracing::info!(elapsed_s = started.elapsed().as_secs_f64(), "read inputs");
    let total = job.wheels.len() + job.poses.len();
    let bar = twindrive_progress::bar(total as u64, "calibrating");
    let (report, artefacts) =
        twindrive_calibrate::calibrate(job, |done, _| bar.set_position(done as u64))?;
    bar.finish_and_clear();
    let stage = Instant::now();
    twindrive_calibrate::write_outputs(&report, &artefacts, &args.out)?;
    tracing::info!(elapsed_s = stage.elapsed().as_secs_f64(), "wrote outputs");
    tracing::info!(elapsed_s = started.elapsed().as_secs_f64(), "calibrated");
    twindrive_calibrate::print_report(&report, &args.out, &mut std::io::stdout().lock())?;
    Ok(())
}

impl From<MethodArg> for Method {
    fn from(m: MethodArg) -> Self {
        match m {
            MethodArg::Ekf => Method::Ekf,
            MethodArg::Smoother => Method::Smoother,
            MethodArg::Batch => Method::Batch,
        }
    }
}

/// The wheels a bag is read for, as the command line names them.
fn wheel_source(args: &CalibrateArgs) -> anyhow::Result<Option<WheelSource>> {
    Ok(
        match (&args.ticks_topic, &args.left_joint, &args.right_joint) {
            (Some(topic), _, _) => Some(WheelSource::Ticks {
                topic: topic.clone(),
                left_field: args.left_field.clone().context("--left-field")?,
                right_field: args.right_field.clone().context("--right-field")?,
                ticks_per_rev: args.ticks_per_rev.context("--ticks-per-rev")?,
            }),
            (None, Some(l), Some(r)) => Some(WheelSource::Joints {
                topic: args.joint_topic.clone(),
                left: l.clone(),
                right: r.clone(),
                signal: joint_signal(args.joint_signal),
            }),
            _ => speed_source(&args.speeds),
        },
    )
}

/// Where the command line says the samples are.
fn source(args: &CalibrateArgs) -> anyhow::Result<Source> {
    Ok(
        match (&args.log_dir, &args.encoders, &args.poses, &args.bag) {
            (None, None, None, Some(path)) => Source::Bag(BagSource {
                path: path.clone(),
                stamps: stamps(args.stamps),
                wheels: wheel_source(args)?,
                poses: PoseSource {
                    topic: args.pose_topic.clone().context("--pose-topic")?,
                    frame: args.pose_frame.clone(),
                    parent: args.pose_parent.clone(),
                },
            }),
            (Some(dir), None, None, None) => Source::LogDir(dir.clone()),
            (None, Some(encoders), Some(poses), None) => Source::Csv {
                encoders: encoders.clone(),
                poses: poses.clone(),
            },
            _ => return Err(usage(INPUTS)),
        },
    )
}

/// A self-calibration from a recording's scans; `mount_source` says where
/// the recording's mount of the lidar came from.
fn run_scans(
    args: &CalibrateArgs,
    rec: ScanRecording,
    mount_source: &str,
    started: Instant,
) -> anyhow::Result<()> {
    let initial = match (&args.initial, rec.nominal) {
        (Some(text), _) => parse_initial(text).or_usage()?,
        (None, Some(i)) => i,
        (None, None) => described_initial(args, "bag inputs")?,
    };
    let (mount_guess, mount_source) = match &args.mount {
        Some(text) => (parse_mount(text).or_usage()?, "--mount".to_string()),
        None => (rec.lidar.mount, mount_source.to_string()),
    };
    let job = ScanJob {
        wheels: rec.wheels,
        scans: rec.scans,
        gyro: rec.gyro,
        initial,
        lidar: rec.lidar.name.clone(),
        mount_guess,
        mount_source,
        settings: LaserOdometrySettings {
            interval_s: args.interval_s,
            ..LaserOdometrySettings::default()
        },
        ticks_per_rev: rec.ticks_per_rev,
        time_origin_s: rec.time_origin_s,
    };
    tracing::info!(elapsed_s = started.elapsed().as_secs_f64(), "read inputs");
    let bar = twindrive_progress::bar(job.scans.len() as u64, "matching scans");
    let (report, artefacts) =
        twindrive_calibrate::self_calibrate(job, |done, _| bar.set_position(done as u64))?;
    bar.finish_and_clear();
    twindrive_calibrate::write_scan_outputs(&report, &artefacts, &args.out)?;
    tracing::info!(
        elapsed_s = started.elapsed().as_secs_f64(),
        "self-calibrated"
    );
    twindrive_calibrate::print_scan_report(&report, &args.out, &mut std::io::stdout().lock())?;
    Ok(())
}

/// `--ticks-per-rev` must agree with a log header's.
fn check_ticks(given: Option<u32>, header: Option<u32>) -> anyhow::Result<()> {
    match (given, header) {
        (Some(t), Some(tpr)) if t != tpr => Err(usage(format!(
            "--ticks-per-rev {t} contradicts the log header's ticks_per_rev {tpr}"
        ))),
        _ => Ok(()),
    }
}

/// Reads the inputs named on the command line into a [`Job`]; a log
/// directory already read is `log`.
fn resolve(args: &CalibrateArgs, log: Option<&twindrive_log::MissionLog>) -> anyhow::Result<Job> {
    let signs = [f64::from(args.left_sign), f64::from(args.right_sign)];
    let source = source(args)?;
    let recording = match (&source, log) {
        (Source::LogDir(_), Some(log)) => inputs::recording_from_log(log, signs),
        _ => inputs::read(&source, args.ticks_per_rev, signs)?,
    };
    if let Source::LogDir(_) = &source {
        check_ticks(args.ticks_per_rev, recording.ticks_per_rev)?;
    }
    if recording.wheels.len() < 2 {
        bail!(
            "the encoder log has {} samples; need at least 2",
            recording.wheels.len()
        );
    }
    if recording.poses.is_empty() {
        bail!("the pose log has no samples");
    }
    let initial = match (&args.initial, recording.nominal) {
        (Some(text), _) => parse_initial(text).or_usage()?,
        (None, Some(i)) => i,
        (None, None) => described_initial(args, "CSV and bag inputs")?,
    };
    let offset = match args.time_offset.trim() {
        "auto" => Offset::Auto,
        text => Offset::Given(
            text.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    usage(format!(
                        "--time-offset: expected `auto` or seconds, got `{text}`"
                    ))
                })?,
        ),
    };
    let mut filter = FilterConfig::default();
    filter.noise.position_std_m = args.position_std_m;
    filter.noise.heading_std_rad = args.heading_std_rad;
    filter.noise.wheel_rad2_per_rad = args.wheel_noise;
    if let Some(rw) = args.param_random_walk {
        filter.noise.param_random_walk_m2_per_s = Some([rw; 3]);
    }
    Ok(Job {
        wheels: recording.wheels,
        poses: recording.poses,
        initial,
        offset,
        start_s: args.start_s,
        end_s: args.end_s,
        method: args.method.into(),
        filter,
        param_rel_std: 0.1,
        batch_window_s: args.batch_window_s,
        ticks_per_rev: recording.ticks_per_rev,
        truth: recording.truth,
        time_origin_s: recording.time_origin_s,
    })
}

/// The calibration's start without --initial for inputs (`what`) that
/// carry no nominal wheels: a bag's robot description's, said on the
/// terminal; else a usage error asking for --initial (with why the bag
/// cannot give them).
fn described_initial(args: &CalibrateArgs, what: &str) -> anyhow::Result<[f64; 3]> {
    let need = format!("--initial DL,DR,B (metres) is needed for {what}");
    let Some(bag) = &args.bag else {
        return Err(usage(need));
    };
    match described_wheels(bag)? {
        Ok(described) => {
            println!("{}", described.summary());
            let p = described.params();
            Ok([p.left_diameter_m, p.right_diameter_m, p.wheelbase_m])
        }
        Err(why) => Err(usage(format!("{need} ({why})"))),
    }
}

fn parse_initial(text: &str) -> anyhow::Result<[f64; 3]> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [l, r, b] = parts[..] else {
        bail!("--initial: expected three numbers DL,DR,B in metres, got `{text}`");
    };
    let mut out = [0.0; 3];
    for (i, (p, name)) in [l, r, b]
        .iter()
        .zip(["left diameter", "right diameter", "wheelbase"])
        .enumerate()
    {
        out[i] = p
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v > 0.0)
            .with_context(|| {
                format!("--initial: the {name} must be a finite number > 0 (metres), got `{p}`")
            })?;
    }
    Ok(out)
}

fn parse_mount(text: &str) -> anyhow::Result<Pose> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [x, y, h] = parts[..] else {
        bail!("--mount: expected three numbers X,Y,HEADING (m, m, rad), got `{text}`");
    };
    let mut out = [0.0; 3];
    for (i, (p, name)) in [x, y, h].iter().zip(["x", "y", "heading"]).enumerate() {
        out[i] = p
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .with_context(|| format!("--mount: the {name} must be a finite number, got `{p}`"))?;
    }
    Ok(Pose::new(out[0], out[1], out[2]))
}
