//! `twindrive map`: the site's map from a drive's scans and its motion (the
//! encoders and a calibration, or the robot's own odometry: a bag's, or a
//! CARMEN log's; the work is `twindrive_calibrate::site_map`'s).

use std::time::Instant;

use anyhow::Context;
use twindrive_calibrate::described_wheels::described_wheels;
use twindrive_calibrate::inputs;
use twindrive_calibrate::scan_inputs::{self, BagScanSource, ScanRecording};
use twindrive_calibrate::site_map::{self, MapJob, Motion, SiteRobot, SiteScenario};
use twindrive_estimation::mapping::MappingSettings;
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_ros::extract::{PoseSource, WheelSource};

use crate::cli::MapArgs;
use crate::flags::{joint_signal, read_calibration, read_lidar_mount, speed_source, stamps};
use crate::usage::usage;

pub fn run(args: &MapArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let calibration = match &args.calibration {
        Some(path) => Some((read_calibration(path)?, read_lidar_mount(path)?)),
        None => None,
    };
    let signs = [f64::from(args.left_sign), f64::from(args.right_sign)];
    // The robot's own odometry places the scans (no calibration needed).
    let from_odometry = args.odom_topic.is_some() || args.carmen.is_some();
    if calibration.is_none() && !from_odometry && args.bag.is_none() {
        return Err(usage(
            "--calibration: mapping a log from its wheel angles needs the calibrated wheels (calib.json from \
             `twindrive calibrate`)",
        ));
    }
    // The site's robot's wheels when neither a calibration nor a mission
    // gives them: the flags', else (a bag) the recording's robot
    // description's.
    let given = calibration.is_some() || args.mission.is_some();
    let flag_wheels = match (args.wheel_diameter_m, args.wheelbase_m) {
        (Some(d), Some(b)) => Some(DiffDriveParams {
            left_diameter_m: d,
            right_diameter_m: d,
            wheelbase_m: b,
        }),
        _ => None,
    };
    let (mut rec, start, robot, nominal) = match (&args.log_dir, &args.bag) {
        _ if args.carmen.is_some() => {
            let path = args.carmen.as_deref().expect("matched on is_some");
            let rec = scan_inputs::from_carmen(path)?;
            let robot = described_robot(args, &rec);
            (rec, Pose::new(0.0, 0.0, 0.0), robot, flag_wheels)
        }
        (Some(dir), None) => {
            let log = inputs::read_log_dir(dir)?;
            let rec = ScanRecording::from_log(&log, args.scan_sensor.as_deref(), signs)?;
            let h = &log.header;
            let robot = SiteRobot {
                footprint_radius_m: h.footprint_radius_m,
                max_wheel_speed_rad_s: h.max_wheel_speed_rad_s,
                max_wheel_accel_rad_s2: h.max_wheel_accel_rad_s2,
                ticks_per_rev: h.ticks_per_rev,
                scan_rate_hz: scan_rate_hz(&rec),
                gyro: h.gyro.as_ref().map(|g| (g.name.clone(), g.rate_hz)),
            };
            (rec, h.start, robot, None)
        }
        (None, Some(path)) => {
            let wheels = match (&args.left_joint, &args.right_joint) {
                (Some(left), Some(right)) => Some(WheelSource::Joints {
                    topic: args.joint_topic.clone(),
                    left: left.clone(),
                    right: right.clone(),
                    signal: joint_signal(args.joint_signal),
                }),
                (None, None) => speed_source(&args.speeds),
                _ => {
                    return Err(usage(
                        "--left-joint and --right-joint name the two wheels together",
                    ));
                }
            };
            if wheels.is_none() && args.odom_topic.is_none() {
                return Err(usage(
                    "--bag: name how the robot moved: --odom-topic (nav_msgs/msg/Odometry, or a TF topic with odom -> base), \
                     --left-joint and --right-joint, or --left-speed-topic and --right-speed-topic \
                     (`twindrive bag info` lists the bag's topics and suggests the command line)",
                ));
            }
            // Read before the drive: a bag that cannot give them is
            // refused at once.
            let nominal = match flag_wheels {
                _ if given => None,
                Some(p) => Some(p),
                None => Some(described_nominal(args, path, wheels.is_some())?),
            };
            let source = BagScanSource {
                path: path.clone(),
                stamps: stamps(args.stamps),
                wheels,
                odometry: args.odom_topic.clone().map(|topic| PoseSource {
                    topic,
                    frame: None,
                    parent: None,
                }),
                scan_topic: args.scan_topic.clone().context("--scan-topic")?,
                imu_topic: None,
                base_frame: args.base_frame.clone(),
            };
            let (rec, _) = scan_inputs::from_bag(&source, signs)?;
            let robot = described_robot(args, &rec);
            (rec, Pose::new(0.0, 0.0, 0.0), robot, nominal)
        }
        _ => unreachable!("clap requires one of LOG_DIR, --bag and --carmen"),
    };
    if let Some(duration_s) = args.until_s {
        let before = rec.scans.len();
        rec.truncate_to(duration_s);
        tracing::info!(
            scans = rec.scans.len(),
            of = before,
            "--until-s {duration_s}: the first {duration_s} s"
        );
    }
    let scenario = match &args.mission {
        Some(path) => SiteScenario::Mission {
            text: std::fs::read_to_string(path)
                .with_context(|| format!("--mission: reading {}", path.display()))?,
            path: path.clone(),
        },
        None => SiteScenario::Hold(robot),
    };
    // The site's robot's wheels: the calibration's, else the mission's,
    // else as given or described.
    let params = match (&calibration, &scenario) {
        (Some((params, _)), _) => *params,
        (None, SiteScenario::Mission { text, path }) => {
            twindrive_sim::Scenario::from_toml(text, path)
                .map_err(|e| anyhow::anyhow!("--mission: {e}"))?
                .robot
                .true_params
        }
        (None, SiteScenario::Hold(_)) => match nominal {
            Some(p) => p,
            None => {
                return Err(usage(
                    "--carmen without --calibration: give site.toml's robot its wheels with \
                     --wheel-diameter-m and --wheelbase-m, or a --mission scenario that has them",
                ));
            }
        },
    };
    let mut lidar = rec.lidar.clone();
    match calibration.as_ref().map(|(_, mount)| mount) {
        Some(Some((name, mount))) => {
            if let Some(name) = name
                && *name != lidar.name
            {
                tracing::warn!(
                    calibrated = %name,
                    mapping = %lidar.name,
                    "the calibration's lidar is not the one mapped with; using its mount anyway"
                );
            }
            lidar.mount = *mount;
        }
        Some(None) => tracing::warn!(
            "{} has no lidar_mount (not a self-calibration): the recording's mount of {} is used",
            args.calibration
                .as_deref()
                .unwrap_or(std::path::Path::new(""))
                .display(),
            lidar.name
        ),
        None => tracing::info!(lidar = %lidar.name, "the lidar's mount is the recording's"),
    }
    let motion = if from_odometry {
        Motion::Odometry(rec.odometry)
    } else {
        Motion::Wheels(rec.wheels)
    };
    let job = MapJob {
        motion,
        scans: rec.scans,
        lidar,
        params,
        start,
        settings: MappingSettings {
            resolution_m: args.resolution_m,
            ..MappingSettings::default()
        },
        prior: None,
        time_origin_s: rec.time_origin_s,
    };
    tracing::info!(elapsed_s = started.elapsed().as_secs_f64(), "read inputs");
    // Two passes over the scans: locating each (the SLAM), then drawing
    // each into the map.
    let bar = twindrive_progress::bar(
        2 * job.scans.len() as u64,
        &format!("mapping {} scans (locating, then drawing)", job.scans.len()),
    );
    let map = site_map::map_site(&job, |done, _| bar.set_position(done as u64))?;
    bar.finish();
    let name = args
        .out
        .file_name()
        .map_or("site".into(), |n| n.to_string_lossy().into_owned());
    let report = map.report(&job);
    site_map::write_site(&args.out, &map, &job, &report, |start| {
        site_map::site_toml(&name, &map, &job, &scenario, start)
    })?;
    tracing::info!(elapsed_s = started.elapsed().as_secs_f64(), "mapped");
    println!("{}", report.closures_line());
    println!(
        "map: {} scans ({} matched to the map{}), {:.1} m driven; {} x {} cells of {} m: {} free, {} occupied, {} unknown -> {}/map.yaml, {}/site.toml",
        report.scans,
        report.scans_matched,
        report
            .scans_unmatched
            .iter()
            .map(|(k, n)| format!(", {n} {k}"))
            .collect::<String>(),
        report.path_length_m,
        report.width_cells,
        report.height_cells,
        report.resolution_m,
        report.free_cells,
        report.occupied_cells,
        report.unknown_cells,
        args.out.display(),
        args.out.display(),
    );
    Ok(())
}

/// The nominal wheels of a bag mapped with neither a calibration nor a
/// mission, and without both of --wheel-diameter-m and --wheelbase-m: the
/// recording's robot description's (a flag given alone wins over its
/// part), said on the terminal; a usage error with the flags' advice and
/// why the recording cannot give them otherwise. `from_wheels`: the drive
/// is dead-reckoned from the wheels (else the site's robot only needs them).
fn described_nominal(
    args: &MapArgs,
    bag: &std::path::Path,
    from_wheels: bool,
) -> anyhow::Result<DiffDriveParams> {
    let described = described_wheels(bag)?.map_err(|why| {
        usage(if from_wheels {
            format!(
                "mapping from the wheels needs their size to turn angles into metres: --calibration \
                 (calib.json from `twindrive calibrate`), or the nominal --wheel-diameter-m and --wheelbase-m; \
                 or map from --odom-topic ({why})"
            )
        } else {
            format!(
                "--odom-topic without --calibration: give site.toml's robot its wheels with \
                 --wheel-diameter-m and --wheelbase-m, or a --mission scenario that has them ({why})"
            )
        })
    })?;
    println!("{}", described.summary());
    let mut params = described.params();
    if let Some(d) = args.wheel_diameter_m {
        println!("--wheel-diameter-m {d} given: both wheels' diameter is {d} m");
        params.left_diameter_m = d;
        params.right_diameter_m = d;
    }
    if let Some(b) = args.wheelbase_m {
        println!("--wheelbase-m {b} given: the wheelbase is {b} m");
        params.wheelbase_m = b;
    }
    Ok(params)
}

/// The site's robot of a recording that does not describe one (a bag, a
/// CARMEN log): what the flags say, the scans' own rate.
fn described_robot(args: &MapArgs, rec: &ScanRecording) -> SiteRobot {
    SiteRobot {
        footprint_radius_m: args.footprint_radius_m,
        max_wheel_speed_rad_s: args.max_wheel_speed_rad_s,
        max_wheel_accel_rad_s2: args.max_wheel_accel_rad_s2,
        ticks_per_rev: 4096,
        scan_rate_hz: scan_rate_hz(rec),
        gyro: None,
    }
}
/// The lidar's rate from its scans' times (10 Hz if they do not say).
fn scan_rate_hz(rec: &ScanRecording) -> f64 {
    let (Some(a), Some(b)) = (rec.scans.first(), rec.scans.last()) else {
        return 10.0;
    };
    let n = rec.scans.len() as f64 - 1.0;
    if n >= 1.0 && b.t_s > a.t_s {
        (n / (b.t_s - a.t_s) * 1e3).round() / 1e3
    } else {
        10.0
    }
}
