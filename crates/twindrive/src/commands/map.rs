//! `twindrive map`: the site's map from a drive's encoders and scans and a
//! calibration (the work is `twindrive_calibrate::site_map`'s).

use std::time::Instant;

use anyhow::Context;
use twindrive_calibrate::inputs;
use twindrive_calibrate::scan_inputs::{self, BagScanSource, ScanRecording};
use twindrive_calibrate::site_map::{self, MapJob, SiteRobot, SiteScenario};
use twindrive_estimation::mapping::MappingSettings;
use twindrive_kinematics::Pose;
use twindrive_ros::extract::WheelSource;

use crate::cli::MapArgs;
use crate::flags::{joint_signal, read_calibration, read_lidar_mount, stamps};

pub fn run(args: &MapArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let params = read_calibration(&args.calibration)?;
    let calibrated_mount = read_lidar_mount(&args.calibration)?;
    let signs = [f64::from(args.left_sign), f64::from(args.right_sign)];
    let (rec, start, robot) = match (&args.log_dir, &args.bag) {
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
            (rec, h.start, robot)
        }
        (None, Some(path)) => {
            let source = BagScanSource {
                path: path.clone(),
                stamps: stamps(args.stamps),
                wheels: WheelSource::Joints {
                    topic: args.joint_topic.clone(),
                    left: args.left_joint.clone().context("--left-joint")?,
                    right: args.right_joint.clone().context("--right-joint")?,
                    signal: joint_signal(args.joint_signal),
                },
                scan_topic: args.scan_topic.clone().context("--scan-topic")?,
                imu_topic: None,
                base_frame: args.base_frame.clone(),
            };
            let (rec, _) = scan_inputs::from_bag(&source, signs)?;
            let robot = SiteRobot {
                footprint_radius_m: args.footprint_radius_m,
                max_wheel_speed_rad_s: args.max_wheel_speed_rad_s,
                max_wheel_accel_rad_s2: args.max_wheel_accel_rad_s2,
                ticks_per_rev: 4096,
                scan_rate_hz: scan_rate_hz(&rec),
                gyro: None,
            };
            (rec, Pose::new(0.0, 0.0, 0.0), robot)
        }
        _ => unreachable!("clap requires LOG_DIR or --bag, not both"),
    };
    let mut lidar = rec.lidar.clone();
    match &calibrated_mount {
        Some((name, mount)) => {
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
        None => tracing::warn!(
            "{} has no lidar_mount (not a self-calibration): the recording's mount of {} is used",
            args.calibration.display(),
            lidar.name
        ),
    }
    let job = MapJob {
        wheels: rec.wheels,
        scans: rec.scans,
        lidar,
        params,
        start,
        settings: MappingSettings {
            resolution_m: args.resolution_m,
            ..MappingSettings::default()
        },
        prior: None,
    };
    tracing::info!(elapsed_s = started.elapsed().as_secs_f64(), "read inputs");
    let bar = twindrive_progress::bar(2 * job.scans.len() as u64, "mapping");
    let map = site_map::map_site(&job, |done, _| bar.set_position(done as u64))?;
    bar.finish_and_clear();
    let scenario = match &args.mission {
        Some(path) => SiteScenario::Mission {
            text: std::fs::read_to_string(path)
                .with_context(|| format!("--mission: reading {}", path.display()))?,
            path: path.clone(),
        },
        None => SiteScenario::Hold(robot),
    };
    let name = args
        .out
        .file_name()
        .map_or("site".into(), |n| n.to_string_lossy().into_owned());
    let site = site_map::site_toml(&name, &map, &job, &scenario)?;
    let report = map.report(&job);
    site_map::write_site(&args.out, &map, &report, &site)?;
    tracing::info!(elapsed_s = started.elapsed().as_secs_f64(), "mapped");
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
