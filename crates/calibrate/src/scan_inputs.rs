//! A self-calibration's inputs from a simulator log or a rosbag2
//! recording: the wheels, the scans of one lidar in its own frame and the
//! gyro's rates.

use anyhow::{Context, bail};
use twindrive_estimation::WheelSample;
use twindrive_estimation::localize::Scan;
use twindrive_log::{MissionLog, RangeSensorInfo, SensorKind};
use twindrive_ros::extract::{self, Stamps, WheelSource};

use crate::inputs;

pub use twindrive_kinematics::MIN_SCAN_BEAMS;

/// What a self-calibration reads from a recording.
#[derive(Debug, Clone)]
pub struct ScanRecording {
    pub wheels: Vec<WheelSample>,
    /// The robot's own odometry, when read (`(t_s, pose)`, time-ordered,
    /// on the scans' clock).
    pub odometry: Vec<(f64, twindrive_kinematics::Pose)>,
    pub scans: Vec<Scan>,
    pub gyro: Vec<(f64, f64)>,
    /// The lidar as the recording describes it (its mount is a guess).
    pub lidar: RangeSensorInfo,
    pub nominal: Option<[f64; 3]>,
    pub ticks_per_rev: Option<u32>,
    pub time_origin_s: f64,
}

/// The lidar called `name`, or the log's first lidar with at least
/// [`MIN_SCAN_BEAMS`] beams. An error names the sensors the log has.
pub fn lidar_of<'a>(
    log: &'a MissionLog,
    name: Option<&str>,
) -> anyhow::Result<(usize, &'a RangeSensorInfo)> {
    let sensors: Vec<&RangeSensorInfo> = log.header.range_sensors.iter().collect();
    choose_lidar(&sensors, name, "the log")
}

/// The one rule for which lidar a recording's or a twin's scans come
/// from: the sensor called `name`, or else the first lidar with at least
/// [`MIN_SCAN_BEAMS`] beams (a sparse lidar listed first is passed over).
/// A named ranger or sparse lidar is refused. An error names `owner`
/// ("the log", "the twin's robot in `site`") and the sensors it has.
pub fn choose_lidar<'a>(
    sensors: &[&'a RangeSensorInfo],
    name: Option<&str>,
    owner: &str,
) -> anyhow::Result<(usize, &'a RangeSensorInfo)> {
    let have = || {
        let have: Vec<String> = sensors
            .iter()
            .map(|s| match s.kind {
                SensorKind::Ranger => format!("{} (a ranger)", s.name),
                SensorKind::Lidar => format!("{} (a lidar of {} beams)", s.name, s.beams),
            })
            .collect();
        if have.is_empty() {
            "none".to_string()
        } else {
            have.join(", ")
        }
    };
    let usable = |s: &RangeSensorInfo| s.is_scanning_lidar();
    let Some(name) = name else {
        if let Some(i) = sensors.iter().position(|s| usable(s)) {
            return Ok((i, sensors[i]));
        }
        if let Some(sparse) = sensors.iter().find(|s| s.kind == SensorKind::Lidar) {
            bail!(
                "{owner} has no lidar with enough beams to match scan to scan (at least {MIN_SCAN_BEAMS}): \
                 the lidar `{}` has {}; its range sensors: {}",
                sparse.name,
                sparse.beams,
                have()
            );
        }
        bail!(
            "{owner} has no lidar to match scan to scan; its range sensors: {}",
            have()
        );
    };
    let flag = format!("--scan-sensor {name}: ");
    match sensors.iter().position(|s| s.name == name) {
        None => bail!(
            "{flag}{owner} has no range sensor of that name; its range sensors: {}",
            have()
        ),
        Some(i) if sensors[i].kind != SensorKind::Lidar => bail!(
            "{flag}`{}` is a {}, not a lidar: only a lidar's scans can be matched scan to scan; \
             {owner}'s range sensors: {}",
            sensors[i].name,
            sensors[i].kind,
            have()
        ),
        Some(i) if !usable(sensors[i]) => bail!(
            "{flag}the lidar `{}` has {} beams, too few to match scan to scan (at least {MIN_SCAN_BEAMS}); \
             {owner}'s range sensors: {}",
            sensors[i].name,
            sensors[i].beams,
            have()
        ),
        Some(i) => Ok((i, sensors[i])),
    }
}

/// Whether a calibration of `log` with `--reference auto` uses its scans:
/// it has a lidar and no tracker sample.
pub fn prefers_scans(log: &MissionLog) -> bool {
    lidar_of(log, None).is_ok() && log.tracker_poses().next().is_none()
}

/// The scans of range sensor `sensor` of `log`, in its own frame.
pub fn scans_from_log(log: &MissionLog, sensor: usize) -> Vec<Scan> {
    let info = &log.header.range_sensors[sensor];
    let (angle_min_rad, increment_rad) = info.angle_min_and_increment();
    (0..log.steps.len())
        .filter_map(|i| {
            let ranges = log.range_reading(i, sensor)?;
            Some(Scan {
                t_s: log.steps[i].t_s(),
                angle_min_rad,
                increment_rad,
                range_min_m: info.min_range_m,
                range_max_m: info.max_range_m,
                ranges_m: ranges.iter().map(|r| *r as f32).collect(),
            })
        })
        .collect()
}

impl ScanRecording {
    /// A simulator log's wheels (`signs` flip counters that run
    /// backwards), the scans of its lidar `sensor` (or the one
    /// [`choose_lidar`] picks) and its gyro. Never its true track.
    pub fn from_log(
        log: &MissionLog,
        sensor: Option<&str>,
        signs: [f64; 2],
    ) -> anyhow::Result<Self> {
        let (index, lidar) = lidar_of(log, sensor)?;
        let n = log.header.nominal;
        Ok(Self {
            wheels: inputs::signed_wheels_from_log(log, signs),
            odometry: Vec::new(),
            scans: scans_from_log(log, index),
            gyro: log.gyro_rates().collect(),
            lidar: lidar.clone(),
            nominal: Some([n.left_diameter_m, n.right_diameter_m, n.wheelbase_m]),
            ticks_per_rev: Some(log.header.ticks_per_rev),
            time_origin_s: 0.0,
        })
    }
}

/// What to read from a rosbag2 recording for a self-calibration.
#[derive(Debug, Clone)]
pub struct BagScanSource {
    pub path: std::path::PathBuf,
    pub stamps: Stamps,
    /// The wheels (a self-calibration needs them; a map takes them or
    /// the odometry).
    pub wheels: Option<WheelSource>,
    /// The robot's own odometry: `nav_msgs/msg/Odometry`, or a TF topic
    /// (`frame`: the robot's frame; default the base frame).
    pub odometry: Option<twindrive_ros::extract::PoseSource>,
    /// The `sensor_msgs/msg/LaserScan` topic.
    pub scan_topic: String,
    /// The `sensor_msgs/msg/Imu` topic, if the robot's gyro is to be used.
    pub imu_topic: Option<String>,
    /// The robot's frame in the TF tree (default: `base_link`, else
    /// `base_footprint`).
    pub base_frame: Option<String>,
}

/// A self-calibration's inputs from a bag, and the mount `/tf_static`
/// gives the lidar's frame (the matcher's first guess), if any.
pub fn from_bag(
    source: &BagScanSource,
    signs: [f64; 2],
) -> anyhow::Result<(ScanRecording, Option<twindrive_kinematics::Pose>)> {
    let bag = twindrive_ros::Bag::open(&source.path).context("--bag")?;
    for d in bag.damage() {
        tracing::warn!("{d}; calibrating from what was read");
    }
    let stamps = source.stamps;
    let base = source
        .base_frame
        .clone()
        .or_else(|| extract::base_frame_guess(&bag))
        .unwrap_or_else(|| "base_link".into());
    let odometry_source = source.odometry.clone().map(|mut o| {
        if o.frame.is_none()
            && bag
                .schema(&o.topic)
                .is_ok_and(|s| s.root().name == "tf2_msgs/msg/TFMessage")
        {
            o.frame = Some(base.clone());
        }
        o
    });
    let (wheels, odometry, scans, imu) = std::thread::scope(|scope| {
        let w = scope.spawn(|| {
            source
                .wheels
                .as_ref()
                .map(|w| extract::wheel_track(&bag, w, stamps))
                .transpose()
        });
        let o = odometry_source
            .as_ref()
            .map(|o| extract::pose_track(&bag, o, stamps));
        let i = source
            .imu_topic
            .as_ref()
            .map(|t| extract::imu_rate_track(&bag, t, stamps));
        let s = extract::scan_track(&bag, &source.scan_topic, stamps);
        (w.join(), o, s, i)
    });
    let wheels = wheels.map_err(|_| anyhow::anyhow!("reading the wheels panicked"))??;
    let odometry = odometry.transpose().context("--odom-topic")?;
    let scans = scans.context("--scan-topic")?;
    let imu = imu.transpose().context("--imu-topic")?;
    let mount = extract::static_transform(&bag, &base, &scans.frame_id)?;
    let mut flip_scans = false;
    let mount = mount.map(|m| {
        if m.upside_down {
            tracing::warn!(
                frame = %scans.frame_id,
                "the lidar is mounted upside down (roll {:.2} rad): its beams are mirrored",
                m.roll_rad
            );
            flip_scans = true;
        }
        twindrive_kinematics::Pose::new(m.x_m, m.y_m, m.heading_rad)
    });
    let mut gyro_sign = 1.0;
    if let Some(imu) = &imu
        && let Ok(Some(m)) = extract::static_transform(&bag, &base, &imu.frame_id)
        && m.upside_down
    {
        tracing::warn!(frame = %imu.frame_id, "the IMU is mounted upside down: its yaw rate is negated");
        gyro_sign = -1.0;
    }
    tracing::info!(
        wheel_samples = wheels.as_ref().map_or(0, |w| w.samples.len()),
        odometry_samples = odometry.as_ref().map_or(0, |o| o.samples.len()),
        scans = scans.scans.len(),
        malformed_scans = scans.malformed,
        gyro_samples = imu.as_ref().map_or(0, |i| i.samples.len()),
        "read the bag"
    );
    let origin = scans.scans[0].t_s.floor();
    let first = &scans.scans[0];
    let beams = first.ranges_m.len() as u32;
    let lidar = RangeSensorInfo {
        kind: SensorKind::Lidar,
        name: scans.frame_id.clone(),
        mount: mount.unwrap_or(twindrive_kinematics::Pose::new(0.0, 0.0, 0.0)),
        beams,
        fov_rad: first.increment_rad.abs() * f64::from(beams),
        min_range_m: first.range_min_m,
        max_range_m: first.range_max_m,
    };
    let recording = ScanRecording {
        wheels: wheels
            .map(|w| inputs::bag_wheels(&w.samples, origin, signs))
            .unwrap_or_default(),
        odometry: odometry
            .map(|o| {
                o.samples
                    .iter()
                    .map(|&(t, x, y, h)| (t - origin, twindrive_kinematics::Pose::new(x, y, h)))
                    .collect()
            })
            .unwrap_or_default(),
        scans: scans
            .scans
            .iter()
            .map(|s| {
                // Mirrored beams: bearing a seen upside down is −a.
                let (angle_min_rad, increment_rad) = if flip_scans {
                    (-s.angle_min_rad, -s.increment_rad)
                } else {
                    (s.angle_min_rad, s.increment_rad)
                };
                Scan {
                    t_s: s.t_s - origin,
                    angle_min_rad,
                    increment_rad,
                    range_min_m: s.range_min_m,
                    range_max_m: s.range_max_m,
                    ranges_m: s.ranges_m.clone(),
                }
            })
            .collect(),
        gyro: imu
            .map(|i| {
                i.samples
                    .iter()
                    .map(|&(t, z)| (t - origin, gyro_sign * z))
                    .collect()
            })
            .unwrap_or_default(),
        lidar,
        nominal: None,
        ticks_per_rev: None,
        time_origin_s: origin,
    };
    Ok((recording, mount))
}

/// How far a laser line's mount may stray from the first line's before a
/// warning (m, rad): the mount is one rigid transform.
const MOUNT_TOLERANCE: f64 = 0.01;

/// A map's inputs from a CARMEN log (`.clf`, `.clf.gz`; the 2D SLAM
/// benchmark's logs, read as they are): the laser lines' scans in the
/// laser's frame, the robot's own odometry (its `ODOM` lines, else the
/// robot pose in each laser line) and the laser's mount, robot⁻¹ ⊕ laser
/// from the laser lines. Times are the lines' `ipc_timestamp`, counted
/// from the first scan's whole second. Readings at or above
/// [`CarmenLog::no_return_from_m`] are no return.
pub fn from_carmen(path: &std::path::Path) -> anyhow::Result<ScanRecording> {
    use twindrive_log::carmen::CarmenLog;
    let log = CarmenLog::read(path)?;
    let Some(first) = log.lasers.first() else {
        bail!(
            "{}: no FLASER or ROBOTLASER1 line: a map needs the laser's scans",
            path.display()
        );
    };
    let no_return_m = log.no_return_from_m();
    let mount = first.mount();
    let strays = log
        .lasers
        .iter()
        .filter(|l| {
            let m = l.mount();
            (m.x_m - mount.x_m).hypot(m.y_m - mount.y_m) > MOUNT_TOLERANCE
                || twindrive_kinematics::wrap_angle(m.heading_rad - mount.heading_rad).abs()
                    > MOUNT_TOLERANCE
        })
        .count();
    if strays > 0 {
        tracing::warn!(
            strays,
            lines = log.lasers.len(),
            "laser lines whose laser pose is not the first line's mount on the robot; \
             mapping with the first's ({:.3} m, {:.3} m, {:.3} rad)",
            mount.x_m,
            mount.y_m,
            mount.heading_rad
        );
    }
    let origin = first.t_s.floor();
    let odometry: Vec<(f64, twindrive_kinematics::Pose)> = log
        .robot_odometry()
        .into_iter()
        .map(|(t, p)| (t - origin, p))
        .collect();
    tracing::info!(
        scans = log.lasers.len(),
        odom_lines = log.odometry.len(),
        odometry = if log.odometry.is_empty() {
            "the laser lines' robot pose"
        } else {
            "ODOM lines"
        },
        no_return_from_m = no_return_m,
        mount_x_m = mount.x_m,
        mount_y_m = mount.y_m,
        mount_heading_rad = mount.heading_rad,
        skipped = ?log.skipped,
        "read the CARMEN log"
    );
    let beams = first.ranges_m.len() as u32;
    let lidar = RangeSensorInfo {
        kind: SensorKind::Lidar,
        name: match first.line_kind {
            twindrive_log::carmen::LaserLine::Flaser => "FLASER".into(),
            twindrive_log::carmen::LaserLine::RobotLaser1 => "ROBOTLASER1".into(),
        },
        mount,
        beams,
        fov_rad: first.increment_rad * f64::from(beams),
        min_range_m: 0.0,
        max_range_m: no_return_m,
    };
    let scans = log
        .lasers
        .iter()
        .map(|l| Scan {
            t_s: l.t_s - origin,
            angle_min_rad: l.angle_min_rad,
            increment_rad: l.increment_rad,
            range_min_m: 0.0,
            range_max_m: no_return_m,
            ranges_m: l.ranges_m.clone(),
        })
        .collect();
    Ok(ScanRecording {
        wheels: Vec::new(),
        odometry,
        scans,
        gyro: Vec::new(),
        lidar,
        nominal: None,
        ticks_per_rev: None,
        time_origin_s: origin,
    })
}

impl ScanRecording {
    /// Keeps the scans of the first `duration_s` seconds from the first
    /// scan (and the motion samples up to the last of them).
    pub fn truncate_to(&mut self, duration_s: f64) {
        let Some(first) = self.scans.first() else {
            return;
        };
        let end_s = first.t_s + duration_s;
        self.scans.retain(|s| s.t_s <= end_s);
        let last_s = self.scans.last().map_or(end_s, |s| s.t_s);
        // One motion sample past the last scan still places it.
        let keep = |times: &[f64]| {
            times
                .iter()
                .position(|t| *t > last_s)
                .map_or(usize::MAX, |k| k + 1)
        };
        let k = keep(&self.odometry.iter().map(|o| o.0).collect::<Vec<_>>());
        self.odometry.truncate(k);
        let k = keep(&self.wheels.iter().map(|w| w.t_s).collect::<Vec<_>>());
        self.wheels.truncate(k);
        let k = keep(&self.gyro.iter().map(|g| g.0).collect::<Vec<_>>());
        self.gyro.truncate(k);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A log of the mapping bench's robot: a 360-beam lidar and a side IR.
    fn log_with(sensors: impl FnOnce(&mut Vec<RangeSensorInfo>)) -> MissionLog {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../bench/mapping_drive.toml");
        let mut header = twindrive_sim::Scenario::load(&path).unwrap().log_header();
        sensors(&mut header.range_sensors);
        MissionLog::new(header)
    }

    #[test]
    fn scans_come_from_a_lidar_and_a_ranger_or_a_sparse_lidar_is_refused_by_name() {
        let log = log_with(|_| {});
        let (i, lidar) = lidar_of(&log, None).unwrap();
        assert_eq!((i, lidar.kind), (0, SensorKind::Lidar));
        // With the ranger first, the lidar is still the one found.
        let log = log_with(|s| s.reverse());
        assert_eq!(lidar_of(&log, None).unwrap().1.name, "lidar");
        let e = lidar_of(&log, Some("side_ir")).unwrap_err().to_string();
        assert!(
            e.contains("--scan-sensor side_ir: `side_ir` is a ranger, not a lidar")
                && e.contains("side_ir (a ranger), lidar (a lidar of 360 beams)"),
            "{e}"
        );
        let sparse = log_with(|s| s[0].beams = 12);
        let e = lidar_of(&sparse, None).unwrap_err().to_string();
        assert!(
            e.contains("the log has no lidar with enough beams")
                && e.contains("the lidar `lidar` has 12"),
            "{e}"
        );
        let e = lidar_of(&sparse, Some("lidar")).unwrap_err().to_string();
        assert!(e.contains("the lidar `lidar` has 12 beams, too few"), "{e}");
        // A sparse lidar listed first is passed over for a usable one.
        let two = log_with(|s| {
            let mut front = s[0].clone();
            front.name = "bumper_lidar".into();
            front.beams = 12;
            s.insert(0, front);
        });
        let (i, lidar) = lidar_of(&two, None).unwrap();
        assert_eq!((i, lidar.name.as_str()), (1, "lidar"));
        let rangers = log_with(|s| s.retain(|s| s.kind == SensorKind::Ranger));
        let e = lidar_of(&rangers, None).unwrap_err().to_string();
        assert!(
            e.contains(
                "the log has no lidar to match scan to scan; its range sensors: side_ir (a ranger)"
            ),
            "{e}"
        );
    }
}
