//! Scans, IMU rates and mounts read back from bags written with
//! [`BagWriter`], in both storages.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use super::*;
use crate::bag::BagWriter;
use crate::msgs::*;
use crate::qos::Qos;

#[derive(Debug, Clone, Copy)]
enum Kind {
    Mcap,
    Sqlite3(Distro),
}

const KINDS: [Kind; 3] = [
    Kind::Mcap,
    Kind::Sqlite3(Distro::Jazzy),
    Kind::Sqlite3(Distro::Humble),
];

/// A bag of `kind` in `dir` holding what `fill` writes.
fn write_bag(dir: &std::path::Path, kind: Kind, fill: impl FnOnce(&mut BagWriter<'_>)) -> Bag {
    let path = match kind {
        Kind::Mcap => {
            let path = dir.join("t.mcap");
            let f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
            let mut w = BagWriter::mcap(f, "t.mcap", Distro::Jazzy).unwrap();
            fill(&mut w);
            w.finish().unwrap();
            path
        }
        Kind::Sqlite3(distro) => {
            let path = dir.join("t.db3");
            let mut w = BagWriter::sqlite3(&path, "t.db3", distro).unwrap();
            fill(&mut w);
            w.finish().unwrap();
            path
        }
    };
    Bag::open(&path).unwrap()
}

const S: u64 = 1_000_000_000;
const MS: u64 = 1_000_000;

/// A scan of `ranges.len()` beams from −1.5 rad in steps of `step`.
fn laser(stamp_ns: u64, frame: &str, step: f32, ranges: Vec<f32>) -> LaserScan {
    LaserScan {
        header: Header::new(stamp_ns, frame),
        angle_min: -1.5,
        angle_max: -1.5 + step * (ranges.len() - 1) as f32,
        angle_increment: step,
        time_increment: 1e-4,
        scan_time: 0.1,
        range_min: 0.12,
        range_max: 3.5,
        ranges,
        intensities: Vec::new(),
    }
}

/// `/scan` in log order: (header stamp, message). Message 2 is malformed
/// (3 ranges where the angles make 5); 3 and 4 are stamped out of order; 5
/// is another sensor's; 6 repeats 3's stamp.
fn scans() -> Vec<LaserScan> {
    let five = |first: f32| vec![first, 0.05, 2.0, 3.5, 3.0];
    let mut bad = laser(1200 * MS, "laser", 0.25, five(1.2));
    bad.ranges.truncate(3);
    vec![
        laser(
            1000 * MS,
            "laser",
            0.25,
            vec![1.0, 3.5, f32::NAN, f32::INFINITY, f32::NEG_INFINITY],
        ),
        laser(1100 * MS, "laser", 0.25, five(1.1)),
        bad,
        laser(1400 * MS, "laser", 0.25, five(1.4)),
        laser(1300 * MS, "laser", 0.25, five(1.3)),
        laser(1500 * MS, "other_laser", 0.25, five(1.5)),
        laser(1400 * MS, "laser", 0.25, five(9.9)),
    ]
}

/// `/imu` in log order: 1 and 2 stamped out of order, 3 says its angular
/// velocity is not measured, 5 has a NaN rate.
fn imus() -> Vec<Imu> {
    (0..6u64)
        .map(|k| {
            let stamp = 2 * S + [0, 200, 100, 300, 400, 500][k as usize] * MS;
            let mut m = Imu::yaw_rate(Header::new(stamp, "imu_link"), 0.1 * k as f64 - 0.25);
            if k == 3 {
                m.angular_velocity_covariance = Imu::NOT_MEASURED;
            }
            if k == 5 {
                m.angular_velocity.z = f64::NAN;
            }
            m
        })
        .collect()
}

/// `Rz(yaw) Rx(roll)`, the only rotations the test tree uses.
fn quaternion(roll: f64, yaw: f64) -> Quaternion {
    let (sr, cr) = (0.5 * roll).sin_cos();
    let (sy, cy) = (0.5 * yaw).sin_cos();
    // (0, 0, sy, cy) · (sr, 0, 0, cr)
    Quaternion {
        x: cy * sr,
        y: sy * sr,
        z: sy * cr,
        w: cy * cr,
    }
}

fn link(parent: &str, child: &str, t: [f64; 3], roll: f64, yaw: f64) -> TransformStamped {
    TransformStamped {
        header: Header::new(5 * S, parent),
        child_frame_id: child.into(),
        transform: Transform {
            translation: Vector3 {
                x: t[0],
                y: t[1],
                z: t[2],
            },
            rotation: quaternion(roll, yaw),
        },
    }
}

/// The whole test bag; the lidar rolled by `roll` on `base_scan`.
fn sensor_bag(dir: &std::path::Path, kind: Kind, roll: f64) -> Bag {
    write_bag(dir, kind, |w| {
        let tf_static = w.topic::<TFMessage>("/tf_static", Qos::LATCHED).unwrap();
        let tf = w.topic::<TFMessage>("/tf", Qos::DEFAULT).unwrap();
        let scan = w.topic::<LaserScan>("/scan", Qos::DEFAULT).unwrap();
        let scan2 = w.topic::<LaserScan>("/scan2", Qos::DEFAULT).unwrap();
        let bad = w.topic::<LaserScan>("/bad_scan", Qos::DEFAULT).unwrap();
        let imu = w.topic::<Imu>("/imu", Qos::DEFAULT).unwrap();
        let cmd = w.topic::<Twist>("/cmd_vel", Qos::DEFAULT).unwrap();
        // Two messages, as two publishers would send them; ROS 1 style
        // leading slashes on base_scan.
        w.write(
            tf_static,
            5 * S,
            &TFMessage {
                transforms: vec![
                    link(
                        "base_link",
                        "/base_scan",
                        [-0.064, 0.0, 0.122],
                        0.0,
                        FRAC_PI_2,
                    ),
                    link("base_link", "imu_link", [0.1, 0.0, 0.05], 0.0, 0.0),
                ],
            },
        )
        .unwrap();
        w.write(
            tf_static,
            5 * S,
            &TFMessage {
                transforms: vec![link("/base_scan", "laser", [0.02, 0.01, 0.03], roll, 0.5)],
            },
        )
        .unwrap();
        for k in 0..3u64 {
            let t = 5 * S + k * 100 * MS;
            w.write(
                tf,
                t,
                &TFMessage {
                    transforms: vec![
                        TransformStamped::planar(t, "odom", "base_link", k as f64, 0.0, 0.0),
                        // Ignored: /tf_static has this link.
                        TransformStamped::planar(t, "base_scan", "laser", 9.0, 9.0, 1.0),
                        // Only in /tf; its first value is used.
                        TransformStamped::planar(
                            t,
                            "base_scan",
                            "laser2",
                            0.3,
                            0.0,
                            0.25 + k as f64,
                        ),
                        TransformStamped::planar(t, "world", "camera", 1.0, 0.0, 0.0),
                    ],
                },
            )
            .unwrap();
        }
        for (k, m) in scans().iter().enumerate() {
            w.write(scan, 5 * S + k as u64 * 100 * MS, m).unwrap();
        }
        // A clockwise scanner.
        w.write(scan2, 5 * S, &laser(S, "laser2", -0.5, vec![1.0; 4]))
            .unwrap();
        w.write(bad, 5 * S, &scans()[2]).unwrap();
        for (k, m) in imus().iter().enumerate() {
            w.write(imu, 5 * S + k as u64 * 100 * MS, m).unwrap();
        }
        w.write(cmd, 5 * S, &Twist::planar(0.1, 0.0)).unwrap();
    })
}

fn seconds_of(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

/// `m` as [`ScanData`] at `t_s`, compared bit for bit (NaN included).
fn assert_scan(got: &ScanData, m: &LaserScan, t_s: f64) {
    assert_eq!(got.t_s, t_s);
    assert_eq!(got.angle_min_rad, f64::from(m.angle_min));
    assert_eq!(got.increment_rad, f64::from(m.angle_increment));
    assert_eq!(got.range_min_m, f64::from(m.range_min));
    assert_eq!(got.range_max_m, f64::from(m.range_max));
    let bits = |r: &[f32]| r.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&got.ranges_m), bits(&m.ranges));
}

#[test]
fn scans_come_out_whole_and_in_time_order() {
    for kind in KINDS {
        let dir = tempfile::tempdir().unwrap();
        let bag = sensor_bag(dir.path(), kind, 0.0);
        let sent = scans();

        let by_stamp = scan_track(&bag, "/scan", Stamps::Header).unwrap();
        assert_eq!(by_stamp.frame_id, "laser", "{kind:?}");
        assert_eq!(
            (by_stamp.malformed, by_stamp.other_frame, by_stamp.repeated),
            (1, 1, 1)
        );
        let order = [0, 1, 4, 3];
        assert_eq!(by_stamp.scans.len(), order.len());
        for (got, k) in by_stamp.scans.iter().zip(order) {
            let m = &sent[k];
            assert_scan(got, m, seconds_of(m.header.stamp.as_ns() as u64));
        }
        // Max range, below range_min, NaN and ±inf are kept as recorded.
        let first = &by_stamp.scans[0].ranges_m;
        assert!(first[1] == 3.5 && first[2].is_nan() && first[3] == f32::INFINITY);
        assert_eq!(first[4], f32::NEG_INFINITY);

        let by_log = scan_track(&bag, "/scan", Stamps::LogTime).unwrap();
        assert_eq!(
            (by_log.malformed, by_log.other_frame, by_log.repeated),
            (1, 1, 0)
        );
        let order = [0, 1, 3, 4, 6];
        assert_eq!(by_log.scans.len(), order.len());
        for (got, k) in by_log.scans.iter().zip(order) {
            assert_scan(got, &sent[k], seconds_of(5 * S + k as u64 * 100 * MS));
        }

        let cw = scan_track(&bag, "/scan2", Stamps::Header).unwrap();
        assert_eq!(cw.scans[0].increment_rad, -0.5);
        assert_eq!(cw.frame_id, "laser2");
    }
}

#[test]
fn imu_rates_come_out_in_time_order() {
    for kind in KINDS {
        let dir = tempfile::tempdir().unwrap();
        let bag = sensor_bag(dir.path(), kind, 0.0);
        let sent = imus();
        let rate = |k: usize| sent[k].angular_velocity.z;
        let by_stamp = imu_rate_track(&bag, "/imu", Stamps::Header).unwrap();
        assert_eq!(by_stamp.frame_id, "imu_link");
        assert_eq!(
            (by_stamp.skipped, by_stamp.other_frame, by_stamp.repeated),
            (2, 0, 0)
        );
        let stamp = |k: usize| seconds_of(sent[k].header.stamp.as_ns() as u64);
        assert_eq!(
            by_stamp.samples,
            [0, 2, 1, 4].map(|k| (stamp(k), rate(k))),
            "{kind:?}"
        );
        let by_log = imu_rate_track(&bag, "/imu", Stamps::LogTime).unwrap();
        let logged = |k: usize| seconds_of(5 * S + k as u64 * 100 * MS);
        assert_eq!(by_log.samples, [0, 1, 2, 4].map(|k| (logged(k), rate(k))));
    }
}

#[test]
fn missing_wrong_and_malformed_topics_say_what_there_is() {
    let dir = tempfile::tempdir().unwrap();
    let bag = sensor_bag(dir.path(), Kind::Mcap, 0.0);
    let e = scan_track(&bag, "/scan_front", Stamps::Header)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("topic `/scan_front`: not in the bag; the sensor_msgs/msg/LaserScan topics are: /bad_scan (1 messages), /scan (7 messages), /scan2 (1 messages)"),
        "{e}"
    );
    let e = scan_track(&bag, "/imu", Stamps::Header)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("topic `/imu`: is sensor_msgs/msg/Imu, not sensor_msgs/msg/LaserScan;")
            && e.contains("/scan (7 messages)"),
        "{e}"
    );
    let e = imu_rate_track(&bag, "/cmd_vel", Stamps::Header)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("is geometry_msgs/msg/Twist, not sensor_msgs/msg/Imu; the sensor_msgs/msg/Imu topics are: /imu (6 messages)"),
        "{e}"
    );
    let e = scan_track(&bag, "/bad_scan", Stamps::Header)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no well-formed scan: all 1 are malformed (the first, message 0: 3 ranges, but angle_min -1.5 to angle_max -0.5 at angle_increment 0.25 makes 5 beams)"),
        "{e}"
    );

    let dir = tempfile::tempdir().unwrap();
    let plain = write_bag(dir.path(), Kind::Mcap, |w| {
        let cmd = w.topic::<Twist>("/cmd_vel", Qos::DEFAULT).unwrap();
        w.write(cmd, S, &Twist::planar(0.1, 0.0)).unwrap();
    });
    let e = scan_track(&plain, "/scan", Stamps::Header)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("not in the bag; the bag has no sensor_msgs/msg/LaserScan topic; its topics: /cmd_vel (geometry_msgs/msg/Twist, 1 messages)"),
        "{e}"
    );
    assert_eq!(
        static_transform(&plain, "base_link", "laser").unwrap(),
        None
    );
    assert_eq!(base_frame_guess(&plain), None);
}

#[test]
fn unstamped_scans_ask_for_log_times() {
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), Kind::Mcap, |w| {
        let scan = w.topic::<LaserScan>("/scan", Qos::DEFAULT).unwrap();
        for k in 0..3 {
            w.write(scan, S + k * MS, &laser(0, "laser", 0.25, vec![1.0; 3]))
                .unwrap();
        }
    });
    let e = scan_track(&bag, "/scan", Stamps::Header)
        .unwrap_err()
        .to_string();
    assert!(e.contains("every header.stamp is zero"), "{e}");
    assert_eq!(
        scan_track(&bag, "/scan", Stamps::LogTime)
            .unwrap()
            .scans
            .len(),
        3
    );
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-12
}

/// `a − b` wrapped into (−π, π].
fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(TAU);
    if d > PI { d - TAU } else { d }
}

#[test]
fn the_tf_chain_composes_both_ways() {
    for kind in KINDS {
        for flipped in [false, true] {
            let dir = tempfile::tempdir().unwrap();
            let roll = if flipped { PI } else { 0.0 };
            let bag = sensor_bag(dir.path(), kind, roll);
            // By hand: base_scan turned a quarter turn left, so the laser's
            // offset (0.02, 0.01) in it is (−0.01, 0.02) in base_link.
            let heading = FRAC_PI_2 + 0.5;
            let m = static_transform(&bag, "base_link", "laser")
                .unwrap()
                .unwrap();
            assert!(
                close(m.x_m, -0.074) && close(m.y_m, 0.02) && close(m.z_m, 0.152),
                "{m:?}"
            );
            assert!(close(angle_diff(m.heading_rad, heading), 0.0), "{m:?}");
            assert!(close(angle_diff(m.roll_rad, roll), 0.0) && close(m.pitch_rad, 0.0));
            assert_eq!(m.upside_down, flipped);
            assert_eq!(m.chain, ["base_link", "base_scan", "laser"]);
            assert!(!m.from_tf);
            // Frames with a leading slash are the same frames.
            assert_eq!(
                static_transform(&bag, "/base_link", "/laser").unwrap(),
                Some(m.clone())
            );

            // Sideways through the common ancestor: imu_link sits 0.1 m
            // ahead of base_link and 0.05 m up.
            let s = static_transform(&bag, "imu_link", "laser")
                .unwrap()
                .unwrap();
            assert!(close(s.x_m, -0.174) && close(s.y_m, 0.02) && close(s.z_m, 0.102));
            assert!(close(angle_diff(s.heading_rad, heading), 0.0));
            assert_eq!(s.chain, ["imu_link", "base_link", "base_scan", "laser"]);
            assert_eq!(s.upside_down, flipped);

            // Up the tree: base_link in the laser frame. Upright, the
            // inverse turns by −heading; upside down, the mirror turns the
            // same way (Rx(π) Rz(−h) has its x axis at +h).
            let (sh, ch) = heading.sin_cos();
            let (a, b) = (ch * -0.074 + sh * 0.02, sh * 0.074 + ch * 0.02);
            let u = static_transform(&bag, "laser", "base_link")
                .unwrap()
                .unwrap();
            let (want_x, want_y, want_z, want_h) = if flipped {
                (-a, b, 0.152, heading)
            } else {
                (-a, -b, -0.152, -heading)
            };
            assert!(
                close(u.x_m, want_x) && close(u.y_m, want_y) && close(u.z_m, want_z),
                "{u:?}"
            );
            assert!(close(angle_diff(u.heading_rad, want_h), 0.0), "{u:?}");
            assert_eq!(u.upside_down, flipped);
            assert_eq!(u.chain, ["laser", "base_scan", "base_link"]);

            // A link only /tf has: its first value.
            let l2 = static_transform(&bag, "base_link", "laser2")
                .unwrap()
                .unwrap();
            assert!(close(l2.x_m, -0.064) && close(l2.y_m, 0.3) && close(l2.z_m, 0.122));
            assert!(close(l2.heading_rad, FRAC_PI_2 + 0.25) && l2.from_tf);

            // Not connected, or not there.
            assert_eq!(static_transform(&bag, "base_link", "camera").unwrap(), None);
            assert_eq!(
                static_transform(&bag, "base_link", "nowhere").unwrap(),
                None
            );
            assert_eq!(base_frame_guess(&bag).as_deref(), Some("base_link"));
        }
    }
}

#[test]
fn the_base_frame_is_guessed_from_the_tree() {
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), Kind::Sqlite3(Distro::Humble), |w| {
        let tf = w.topic::<TFMessage>("/tf", Qos::DEFAULT).unwrap();
        w.write(
            tf,
            S,
            &TFMessage {
                transforms: vec![TransformStamped::planar(
                    S,
                    "odom",
                    "/base_footprint",
                    0.0,
                    0.0,
                    0.0,
                )],
            },
        )
        .unwrap();
    });
    assert_eq!(base_frame_guess(&bag).as_deref(), Some("base_footprint"));
    assert_eq!(tf_frames(&bag).unwrap(), ["base_footprint", "odom"]);
}

/// A mission log with a lidar and a gyro, exported as `twindrive rosbag`
/// does, reads back as the log has it.
#[test]
fn an_exported_log_reads_back_as_logged() {
    use twindrive_kinematics::{DiffDriveParams, Pose};
    let mount = Pose::new(0.12, -0.03, 0.4);
    let mut log = twindrive_log::MissionLog::new(twindrive_log::LogHeader {
        format: twindrive_log::LOG_FORMAT.into(),
        version: twindrive_log::LOG_VERSION,
        scenario: "scan".into(),
        seed: 1,
        dt_s: 0.01,
        ticks_per_rev: 512,
        nominal: DiffDriveParams::new(0.066, 0.066, 0.26),
        footprint_radius_m: 0.15,
        max_wheel_speed_rad_s: 12.0,
        max_wheel_accel_rad_s2: 30.0,
        start: Pose::new(1.0, 2.0, 0.5),
        range_sensors: vec![twindrive_log::RangeSensorInfo {
            name: "lidar".into(),
            kind: twindrive_log::SensorKind::Lidar,
            mount,
            beams: 8,
            fov_rad: TAU,
            min_range_m: 0.1,
            max_range_m: 4.0,
        }],
        gyro: Some(twindrive_log::GyroInfo {
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
            gyro_z_rad_s: (k % 2 == 0).then_some(1.0 / 3.0 - k as f64 * 1e-3),
        });
        for b in 0..8 {
            log.ranges.push(match (k % 3, b) {
                (1, _) => f64::NAN, // not sampled at this step
                (_, 5) => 4.0,      // a miss, at max range
                _ => 0.5 + 0.1 * b as f64 + 1.0 / (3.0 + k as f64),
            });
        }
    }
    let start_ns = 1_700_000_000 * S;
    for sqlite3 in [false, true] {
        let dir = tempfile::tempdir().unwrap();
        let options = crate::export::ExportOptions {
            start_ns,
            ..Default::default()
        };
        let summary = if sqlite3 {
            let w =
                BagWriter::sqlite3(&dir.path().join("x_0.db3"), "x_0.db3", Distro::Jazzy).unwrap();
            crate::export::write_log_bag(&log, &options, w).unwrap()
        } else {
            let f = std::fs::File::create(dir.path().join("x_0.mcap")).unwrap();
            let w = BagWriter::mcap(std::io::BufWriter::new(f), "x_0.mcap", Distro::Jazzy).unwrap();
            crate::export::write_log_bag(&log, &options, w).unwrap()
        };
        std::fs::write(dir.path().join("metadata.yaml"), summary.metadata_yaml).unwrap();
        let bag = Bag::open(dir.path()).unwrap();

        let info = &log.header.range_sensors[0];
        let (angle_min, increment) = info.angle_min_and_increment();
        let want: Vec<ScanData> = (0..log.steps.len())
            .filter_map(|k| {
                let r = log.range_reading(k, 0)?;
                Some(ScanData {
                    t_s: seconds_of(start_ns + log.steps[k].t_ns),
                    angle_min_rad: f64::from(angle_min as f32),
                    increment_rad: f64::from(increment as f32),
                    range_min_m: f64::from(info.min_range_m as f32),
                    range_max_m: f64::from(info.max_range_m as f32),
                    ranges_m: r.iter().map(|x| *x as f32).collect(),
                })
            })
            .collect();
        assert_eq!(want.len(), 7);
        for stamps in [Stamps::Header, Stamps::LogTime] {
            let scans = scan_track(&bag, "/lidar", stamps).unwrap();
            assert_eq!(scans.scans, want);
            assert_eq!(scans.frame_id, "lidar_link");
            assert_eq!(
                (scans.malformed, scans.other_frame, scans.repeated),
                (0, 0, 0)
            );
            let imu = imu_rate_track(&bag, "/imu", stamps).unwrap();
            let rates: Vec<(f64, f64)> = log
                .steps
                .iter()
                .filter_map(|s| Some((seconds_of(start_ns + s.t_ns), s.gyro_z_rad_s?)))
                .collect();
            assert_eq!(imu.samples, rates);
            assert_eq!(imu.frame_id, crate::export::IMU_FRAME);
        }

        let base = base_frame_guess(&bag).unwrap();
        let m = static_transform(&bag, &base, "lidar_link")
            .unwrap()
            .unwrap();
        assert!(close(m.x_m, mount.x_m) && close(m.y_m, mount.y_m) && m.z_m == 0.0);
        assert!(close(m.heading_rad, mount.heading_rad) && !m.upside_down);
        let g = static_transform(&bag, &base, crate::export::IMU_FRAME)
            .unwrap()
            .unwrap();
        assert!(g.x_m == 0.0 && g.heading_rad == 0.0 && !g.upside_down);
    }
}
