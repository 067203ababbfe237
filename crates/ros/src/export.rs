//! A mission log as a rosbag2 recording with standard ROS 2 types, so
//! `ros2 bag play`, RViz, Foxglove and PlotJuggler read it as they would a
//! robot's own recording.
//!
//! | topic | type | when |
//! |---|---|---|
//! | `/joint_states` | `sensor_msgs/msg/JointState` (`left_wheel_joint`, `right_wheel_joint`: angle from the encoders, speed) | each encoder sample |
//! | `/odom` | `nav_msgs/msg/Odometry`, `odom` → `base_link`, dead reckoning with the nominal parameters | each encoder sample |
//! | `/ground_truth` | `nav_msgs/msg/Odometry`, `map` → `base_link`, the simulator's true pose | each encoder sample |
//! | `/tracker/pose` | `geometry_msgs/msg/PoseStamped` in `map`, the external reference | each tracker sample |
//! | `/cmd_vel` | `geometry_msgs/msg/Twist`, the commanded wheel speeds through the nominal parameters | each encoder sample |
//! | `/bump` | `irobot_create_msgs/msg/HazardDetectionVector` (one `BUMP` while pressed) | each encoder sample |
//! | `/<sensor>` | `sensor_msgs/msg/Range` (`INFRARED`) for a ranger, `sensor_msgs/msg/LaserScan` for a lidar | each reading |
//! | `/tf` | `tf2_msgs/msg/TFMessage`: `odom` → `base_link`; `map` → `odom` from the tracker | encoder / tracker samples |
//! | `/imu` | `sensor_msgs/msg/Imu` in `imu_link`: the gyro's yaw rate as `angular_velocity.z`, no orientation or acceleration (covariance −1) | each gyro sample, when the log has a gyro |
//! | `/tf_static` | `base_link` → `<sensor>_link`, and `imu_link` (identity) with a gyro | once, latched |
//! | `/robot_description` | `std_msgs/msg/String`: the robot's URDF ([`crate::urdf::describe`]): the wheels with the nominal parameters on `wheel_left_joint` and `wheel_right_joint`, the footprint, the `/tf_static` frames | once, latched |
//! | `/map` | `nav_msgs/msg/OccupancyGrid` | once, latched |
//! | `/plan` | `nav_msgs/msg/Path` | once, latched, when a plan is given |
//!
//! Times are the log's times plus `start_ns` (the log counts from the
//! mission's start; pass the wall-clock start to place it in time).

use twindrive_kinematics::{DiffDriveParams, Pose, arc_step_wheels};
use twindrive_log::{MissionLog, SensorKind, WorldMap};

use crate::bag::{BagWriter, WriteError};
use crate::msgs::{
    Covariance, Distro, HazardDetection, HazardDetectionVector, Header, Imu, JointState, LaserScan,
    MapMetaData, OccupancyGrid, Odometry, Path, PoseStamped, PoseWithCovariance, Range, StringMsg,
    TFMessage, Time, TransformStamped, Twist, TwistWithCovariance,
};
use crate::qos::Qos;

/// Joint names of the wheels in `/joint_states` (as TurtleBot 3 names them).
pub const LEFT_WHEEL_JOINT: &str = "wheel_left_joint";
pub const RIGHT_WHEEL_JOINT: &str = "wheel_right_joint";

/// The frame of the gyro's `/imu` messages; `base_link` → it is the identity.
pub const IMU_FRAME: &str = "imu_link";

/// Cell size of the `/map` grid drawn from wall segments (m).
const MAP_RESOLUTION_M: f64 = 0.05;
/// Free margin around the walls' bounding box (m).
const MAP_MARGIN_M: f64 = 0.5;

/// What besides the log goes into the bag.
#[derive(Debug, Clone, Default)]
pub struct ExportOptions<'a> {
    /// Added to every log time (ns since the Unix epoch of the log's t = 0).
    pub start_ns: u64,
    pub map: Option<&'a WorldMap>,
    /// A plan's poses, each with its plan time (ns since the log's t = 0).
    pub plan: Option<&'a [(u64, Pose)]>,
}

/// How many messages each topic got.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ExportSummary {
    pub topics: Vec<(String, &'static str, u64)>,
    pub metadata_yaml: String,
}

fn pose_of(p: &Pose) -> crate::msgs::Pose {
    crate::msgs::Pose::planar(p.x_m, p.y_m, p.heading_rad)
}

/// `a ⊕ b`: pose `b` given in frame `a`, expressed in `a`'s parent.
fn compose(a: &Pose, b: &Pose) -> Pose {
    let (x, y) = a.transform_point(b.x_m, b.y_m);
    Pose::new(x, y, a.heading_rad + b.heading_rad)
}

/// `a⁻¹`.
fn inverse(a: &Pose) -> Pose {
    let (s, c) = a.heading_rad.sin_cos();
    Pose::new(
        -(c * a.x_m + s * a.y_m),
        s * a.x_m - c * a.y_m,
        -a.heading_rad,
    )
}

/// Writes `log` into `bag` (a storage file of either storage, whose
/// distribution sets the message definitions) and finishes it.
pub fn write_log_bag(
    log: &MissionLog,
    options: &ExportOptions<'_>,
    mut bag: BagWriter<'_>,
) -> Result<ExportSummary, WriteError> {
    let h = &log.header;
    let nominal: DiffDriveParams = h.nominal;
    let t0 = options.start_ns;
    let distro = bag.distro();

    // Latched topics first, at the start time, so a player sends them first.
    let tf_static = bag.topic::<TFMessage>("/tf_static", Qos::LATCHED)?;
    let description = bag.topic::<StringMsg>(crate::extract::ROBOT_DESCRIPTION, Qos::LATCHED)?;
    let map_topic = match options.map {
        Some(_) => Some(bag.topic::<OccupancyGrid>("/map", Qos::LATCHED)?),
        None => None,
    };
    let plan_topic = match options.plan {
        Some(_) => Some(bag.topic::<Path>("/plan", Qos::LATCHED)?),
        None => None,
    };
    let joints = bag.topic::<JointState>("/joint_states", Qos::DEFAULT)?;
    let odom = bag.topic::<Odometry>("/odom", Qos::DEFAULT)?;
    let truth = bag.topic::<Odometry>("/ground_truth", Qos::DEFAULT)?;
    let tracker = bag.topic::<PoseStamped>("/tracker/pose", Qos::DEFAULT)?;
    let cmd_vel = bag.topic::<Twist>("/cmd_vel", Qos::DEFAULT)?;
    let bump = bag.topic::<HazardDetectionVector>("/bump", Qos::DEFAULT)?;
    let tf = bag.topic::<TFMessage>("/tf", Qos::DEFAULT)?;
    let sensors: Vec<_> = h
        .range_sensors
        .iter()
        .map(|s| {
            let name = format!("/{}", s.name);
            if s.kind == SensorKind::Ranger {
                bag.topic::<Range>(&name, Qos::DEFAULT)
            } else {
                bag.topic::<LaserScan>(&name, Qos::DEFAULT)
            }
        })
        .collect::<Result<_, _>>()?;
    let imu = match h.gyro {
        Some(_) => Some(bag.topic::<Imu>("/imu", Qos::DEFAULT)?),
        None => None,
    };

    let mut transforms: Vec<_> = h
        .range_sensors
        .iter()
        .map(|s| {
            TransformStamped::planar(
                t0,
                "base_link",
                &format!("{}_link", s.name),
                s.mount.x_m,
                s.mount.y_m,
                s.mount.heading_rad,
            )
        })
        .collect();
    if imu.is_some() {
        transforms.push(TransformStamped::planar(
            t0,
            "base_link",
            IMU_FRAME,
            0.0,
            0.0,
            0.0,
        ));
    }
    // The URDF's frames: those of /tf_static.
    let mut frames: Vec<(String, Pose)> = h
        .range_sensors
        .iter()
        .map(|s| (format!("{}_link", s.name), s.mount))
        .collect();
    if imu.is_some() {
        frames.push((IMU_FRAME.to_string(), Pose::new(0.0, 0.0, 0.0)));
    }
    bag.write(tf_static, t0, &TFMessage { transforms })?;
    bag.write(
        description,
        t0,
        &StringMsg {
            data: crate::urdf::describe(
                &h.scenario,
                &nominal,
                h.footprint_radius_m,
                [LEFT_WHEEL_JOINT, RIGHT_WHEEL_JOINT],
                &frames,
            ),
        },
    )?;
    if let (Some(topic), Some(map)) = (map_topic, options.map) {
        bag.write(topic, t0, &occupancy_grid(map, t0))?;
    }
    if let (Some(topic), Some(plan)) = (plan_topic, options.plan) {
        let poses = plan
            .iter()
            .map(|(t, p)| PoseStamped {
                header: Header::new(t0 + t, "map"),
                pose: pose_of(p),
            })
            .collect();
        bag.write(
            topic,
            t0,
            &Path {
                header: Header::new(t0, "map"),
                poses,
            },
        )?;
    }

    let rad_per_tick = std::f64::consts::TAU / f64::from(h.ticks_per_rev);
    // The odometry frame starts where the robot starts; `map` → `odom` is
    // the start pose until the tracker says otherwise.
    let mut odom_pose = Pose::new(0.0, 0.0, 0.0);
    let mut last_angles: Option<[f64; 2]> = None;
    let pose_cov = Covariance::diagonal([1e-4, 1e-4, 1e6, 1e6, 1e6, 1e-3]);
    let twist_cov = Covariance::diagonal([1e-4, 1e6, 1e6, 1e6, 1e6, 1e-3]);
    let map_to_odom = |odom_pose: &Pose, map_pose: &Pose| compose(map_pose, &inverse(odom_pose));
    let mut published_map_to_odom = false;
    for (k, s) in log.steps.iter().enumerate() {
        let t = t0 + s.t_ns;
        if let Some([l, r]) = s.encoder_ticks {
            let angles = [l as f64 * rad_per_tick, r as f64 * rad_per_tick];
            if let Some(prev) = last_angles {
                odom_pose = arc_step_wheels(
                    &odom_pose,
                    &nominal,
                    angles[0] - prev[0],
                    angles[1] - prev[1],
                );
            }
            last_angles = Some(angles);
            bag.write(
                joints,
                t,
                &JointState {
                    header: Header::new(t, ""),
                    name: vec![LEFT_WHEEL_JOINT.into(), RIGHT_WHEEL_JOINT.into()],
                    position: angles.to_vec(),
                    velocity: s.wheel_rad_s.to_vec(),
                    effort: Vec::new(),
                },
            )?;
            let (v, w) =
                twindrive_kinematics::body_velocity(&nominal, s.wheel_rad_s[0], s.wheel_rad_s[1]);
            let twist = TwistWithCovariance {
                twist: Twist::planar(v, w),
                covariance: twist_cov,
            };
            bag.write(
                odom,
                t,
                &Odometry {
                    header: Header::new(t, "odom"),
                    child_frame_id: "base_link".into(),
                    pose: PoseWithCovariance {
                        pose: pose_of(&odom_pose),
                        covariance: pose_cov,
                    },
                    twist,
                },
            )?;
            bag.write(
                truth,
                t,
                &Odometry {
                    header: Header::new(t, "map"),
                    child_frame_id: "base_link".into(),
                    pose: PoseWithCovariance {
                        pose: pose_of(&s.ground_truth),
                        covariance: Covariance::default(),
                    },
                    twist: TwistWithCovariance::default(),
                },
            )?;
            let (cv, cw) = twindrive_kinematics::body_velocity(
                &nominal,
                s.cmd_wheel_rad_s[0],
                s.cmd_wheel_rad_s[1],
            );
            bag.write(cmd_vel, t, &Twist::planar(cv, cw))?;
            let detections = if s.bump {
                vec![HazardDetection {
                    header: Header::new(t, "base_link"),
                    kind: HazardDetection::BUMP,
                }]
            } else {
                Vec::new()
            };
            bag.write(
                bump,
                t,
                &HazardDetectionVector {
                    header: Header::new(t, "base_link"),
                    detections,
                },
            )?;
            let mut transforms = vec![TransformStamped::planar(
                t,
                "odom",
                "base_link",
                odom_pose.x_m,
                odom_pose.y_m,
                odom_pose.heading_rad,
            )];
            if !published_map_to_odom {
                let m = map_to_odom(&odom_pose, &h.start);
                transforms.push(TransformStamped::planar(
                    t,
                    "map",
                    "odom",
                    m.x_m,
                    m.y_m,
                    m.heading_rad,
                ));
                published_map_to_odom = true;
            }
            bag.write(tf, t, &TFMessage { transforms })?;
        }
        if let Some(p) = s.tracker {
            bag.write(
                tracker,
                t,
                &PoseStamped {
                    header: Header::new(t, "map"),
                    pose: pose_of(&p),
                },
            )?;
            let m = map_to_odom(&odom_pose, &p);
            bag.write(
                tf,
                t,
                &TFMessage {
                    transforms: vec![TransformStamped::planar(
                        t,
                        "map",
                        "odom",
                        m.x_m,
                        m.y_m,
                        m.heading_rad,
                    )],
                },
            )?;
        }
        if let (Some(topic), Some(z)) = (imu, s.gyro_z_rad_s) {
            bag.write(topic, t, &Imu::yaw_rate(Header::new(t, IMU_FRAME), z))?;
        }
        for (i, info) in h.range_sensors.iter().enumerate() {
            let Some(reading) = log.range_reading(k, i) else {
                continue;
            };
            let header = Header::new(t, &format!("{}_link", info.name));
            if info.kind == SensorKind::Ranger {
                bag.write(
                    sensors[i],
                    t,
                    &Range {
                        header,
                        radiation_type: Range::INFRARED,
                        field_of_view: info.fov_rad as f32,
                        min_range: info.min_range_m as f32,
                        max_range: info.max_range_m as f32,
                        range: reading[0] as f32,
                        variance: (distro != Distro::Humble).then_some(0.0),
                    },
                )?;
            } else {
                let (angle_min, increment) = info.angle_min_and_increment();
                bag.write(
                    sensors[i],
                    t,
                    &LaserScan {
                        header,
                        angle_min: angle_min as f32,
                        angle_max: info.beam_angle_rad(info.beams - 1) as f32,
                        angle_increment: increment as f32,
                        time_increment: 0.0,
                        scan_time: 0.0,
                        range_min: info.min_range_m as f32,
                        range_max: info.max_range_m as f32,
                        ranges: reading.iter().map(|r| *r as f32).collect(),
                        intensities: Vec::new(),
                    },
                )?;
            }
        }
    }
    let counts = bag.topic_counts();
    let metadata_yaml = bag.finish()?;
    Ok(ExportSummary {
        topics: counts,
        metadata_yaml,
    })
}

/// The world as an occupancy grid: the map's own grid when it has one, else
/// its walls and boxes drawn into a grid around them.
pub fn occupancy_grid(map: &WorldMap, t_ns: u64) -> OccupancyGrid {
    if let Some(g) = &map.grid {
        return OccupancyGrid {
            header: Header::new(t_ns, "map"),
            info: MapMetaData {
                map_load_time: Time::from_ns(t_ns),
                resolution: g.resolution_m as f32,
                width: g.width,
                height: g.height,
                origin: crate::msgs::Pose::planar(g.origin[0], g.origin[1], g.origin[2]),
            },
            data: g
                .cells
                .iter()
                .map(|&c| if c == 255 { -1 } else { c.min(100) as i8 })
                .collect(),
        };
    }
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for [x0, y0, x1, y1] in map.segments.iter().chain(&map.boxes) {
        lo = [lo[0].min(x0.min(*x1)), lo[1].min(y0.min(*y1))];
        hi = [hi[0].max(x0.max(*x1)), hi[1].max(y0.max(*y1))];
    }
    if !lo[0].is_finite() {
        lo = [0.0, 0.0];
        hi = [0.0, 0.0];
    }
    let r = MAP_RESOLUTION_M;
    let origin = [lo[0] - MAP_MARGIN_M, lo[1] - MAP_MARGIN_M];
    let width = (((hi[0] - lo[0]) + 2.0 * MAP_MARGIN_M) / r).ceil() as u32;
    let height = (((hi[1] - lo[1]) + 2.0 * MAP_MARGIN_M) / r).ceil() as u32;
    let mut data = vec![0i8; width as usize * height as usize];
    let mut mark = |x: f64, y: f64| {
        let (c, rw) = ((x - origin[0]) / r, (y - origin[1]) / r);
        if c >= 0.0 && rw >= 0.0 && (c as u32) < width && (rw as u32) < height {
            data[rw as usize * width as usize + c as usize] = 100;
        }
    };
    for [x0, y0, x1, y1] in &map.segments {
        let n = ((x1 - x0).hypot(y1 - y0) / (0.25 * r)).ceil().max(1.0) as usize;
        for i in 0..=n {
            let f = i as f64 / n as f64;
            mark(x0 + f * (x1 - x0), y0 + f * (y1 - y0));
        }
    }
    for [x0, y0, x1, y1] in &map.boxes {
        let mut y = *y0;
        while y <= *y1 {
            let mut x = *x0;
            while x <= *x1 {
                mark(x, y);
                x += 0.5 * r;
            }
            y += 0.5 * r;
        }
    }
    OccupancyGrid {
        header: Header::new(t_ns, "map"),
        info: MapMetaData {
            map_load_time: Time::from_ns(t_ns),
            resolution: r as f32,
            width,
            height,
            origin: crate::msgs::Pose::planar(origin[0], origin[1], 0.0),
        },
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compose_and_inverse_agree() {
        let a = Pose::new(1.0, 2.0, 0.7);
        let b = Pose::new(-0.3, 0.5, -1.2);
        let ab = compose(&a, &b);
        let back = compose(&inverse(&a), &ab);
        assert!((back.x_m - b.x_m).abs() < 1e-12 && (back.y_m - b.y_m).abs() < 1e-12);
        assert!((back.heading_rad - b.heading_rad).abs() < 1e-12);
    }

    /// A short log with a gyro sampling every other step.
    fn gyro_log(gyro: bool) -> MissionLog {
        let mut log = MissionLog::new(twindrive_log::LogHeader {
            format: twindrive_log::LOG_FORMAT.into(),
            version: twindrive_log::LOG_VERSION,
            scenario: "gyro".into(),
            seed: 1,
            dt_s: 0.01,
            ticks_per_rev: 512,
            nominal: DiffDriveParams::new(0.066, 0.066, 0.26),
            footprint_radius_m: 0.15,
            max_wheel_speed_rad_s: 12.0,
            max_wheel_accel_rad_s2: 30.0,
            start: Pose::new(1.0, 2.0, 0.5),
            range_sensors: Vec::new(),
            gyro: gyro.then(|| twindrive_log::GyroInfo {
                name: "gyro".into(),
                rate_hz: 50.0,
            }),
            goals: Default::default(),
        });
        for k in 0..10u64 {
            log.steps.push(twindrive_log::StepRecord {
                t_ns: k * 10_000_000,
                cmd_wheel_rad_s: [1.0, 2.0],
                wheel_rad_s: [1.0, 2.0],
                encoder_ticks: Some([k as i64, 2 * k as i64]),
                bump: false,
                tracker: None,
                ground_truth: Pose::new(1.0, 2.0, 0.5 + 0.01 * k as f64),
                gyro_z_rad_s: (gyro && k % 2 == 0).then_some(1.0 / 3.0 - k as f64 * 1e-3),
            });
        }
        log
    }

    /// Writes `log` as a bag in `dir` and opens it with the project's reader.
    fn write_and_open(log: &MissionLog, dir: &std::path::Path, sqlite3: bool) -> crate::Bag {
        let options = ExportOptions::default();
        let summary = if sqlite3 {
            let bag = BagWriter::sqlite3(&dir.join("g_0.db3"), "g_0.db3", Distro::Jazzy).unwrap();
            write_log_bag(log, &options, bag).unwrap()
        } else {
            let file = std::fs::File::create(dir.join("g_0.mcap")).unwrap();
            let bag =
                BagWriter::mcap(std::io::BufWriter::new(file), "g_0.mcap", Distro::Jazzy).unwrap();
            write_log_bag(log, &options, bag).unwrap()
        };
        std::fs::write(dir.join("metadata.yaml"), &summary.metadata_yaml).unwrap();
        crate::Bag::open(dir).unwrap()
    }

    /// `/tf_static`'s transforms: child frame, [x, y, qz, qw].
    fn static_frames(bag: &crate::Bag) -> Vec<(String, [f64; 4])> {
        let schema = bag.schema("/tf_static").unwrap();
        let transforms = schema.path("transforms").unwrap();
        let crate::schema::Base::Message(ts) = transforms.ty.base else {
            panic!("`transforms` is not a list of messages");
        };
        let inner = |dotted: &str| schema.path_from(ts, dotted).unwrap();
        let child = inner("child_frame_id");
        let nums = [
            inner("transform.translation.x"),
            inner("transform.translation.y"),
            inner("transform.rotation.z"),
            inner("transform.rotation.w"),
        ];
        let mut frames = Vec::new();
        bag.for_each("/tf_static", |m| {
            for t in m.value.at(&transforms).unwrap().as_array().unwrap() {
                let name = t.at(&child).unwrap().as_str().unwrap().to_string();
                frames.push((
                    name,
                    nums.each_ref().map(|p| t.at(p).unwrap().as_f64().unwrap()),
                ));
            }
            Ok(())
        })
        .unwrap();
        frames
    }

    #[test]
    fn a_gyro_goes_to_imu_and_reads_back_exactly() {
        let log = gyro_log(true);
        for sqlite3 in [false, true] {
            let dir = tempfile::tempdir().unwrap();
            let bag = write_and_open(&log, dir.path(), sqlite3);
            assert_eq!(bag.topic("/imu").unwrap().type_name, "sensor_msgs/msg/Imu");
            let schema = bag.schema("/imu").unwrap();
            let path = |p: &str| schema.path(p).unwrap();
            let (z, frame, stamp) = (
                path("angular_velocity.z"),
                path("header.frame_id"),
                path("header.stamp.nanosec"),
            );
            let covariances = [
                path("orientation_covariance"),
                path("angular_velocity_covariance"),
                path("linear_acceleration_covariance"),
            ];
            let mut read = Vec::new();
            bag.for_each("/imu", |m| {
                let v = m.value;
                assert_eq!(v.at(&frame).unwrap().as_str(), Some(IMU_FRAME));
                let firsts: Vec<f64> = covariances
                    .iter()
                    .map(|c| v.at(c).unwrap().as_array().unwrap()[0].as_f64().unwrap())
                    .collect();
                assert_eq!(firsts, [-1.0, 0.0, -1.0]);
                let ns = v.at(&stamp).unwrap().as_i64().unwrap() as u64;
                assert_eq!(ns, m.log_time_ns);
                read.push((
                    twindrive_log::seconds_from_ns(ns),
                    v.at(&z).unwrap().as_f64().unwrap(),
                ));
                Ok(())
            })
            .unwrap();
            assert_eq!(read, log.gyro_rates().collect::<Vec<_>>());
            assert_eq!(read.len(), 5);
            assert_eq!(
                static_frames(&bag),
                [(IMU_FRAME.to_string(), [0.0, 0.0, 0.0, 1.0])]
            );
        }

        let dir = tempfile::tempdir().unwrap();
        let plain = write_and_open(&gyro_log(false), dir.path(), false);
        assert!(plain.topic("/imu").is_none());
        assert!(static_frames(&plain).is_empty());
    }

    #[test]
    fn walls_are_drawn_into_the_grid() {
        let map = WorldMap {
            segments: vec![[0.0, 0.0, 2.0, 0.0]],
            boxes: vec![[1.0, 1.0, 1.2, 1.2]],
            grid: None,
        };
        let g = occupancy_grid(&map, 0);
        let at = |x: f64, y: f64| {
            let c = ((x - g.info.origin.position.x) / 0.05) as usize;
            let r = ((y - g.info.origin.position.y) / 0.05) as usize;
            g.data[r * g.info.width as usize + c]
        };
        assert_eq!(at(1.0, 0.01), 100);
        assert_eq!(at(1.1, 1.1), 100);
        assert_eq!(at(1.0, 0.5), 0);
        assert_eq!(g.info.width, 60);
    }
}
