//! ROS 2 interop, checked against independent implementations (the Python
//! packages `rosbags` and `mcap-ros2-support`, installed by
//! `scripts/ros-deps.sh`):
//!
//! - recordings *they* write from a simulated drive calibrate to the true
//!   parameters, with the clock offset between the robot's and the capture
//!   system's stamps found;
//! - every topic `twindrive rosbag` writes decodes with their decoders
//!   (rosbags with the distribution's own definitions, mcap-ros2-support with
//!   the ones stored in the file) to the log's values;
//! - bad recordings and wrong names get errors that name the topic and the
//!   message.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{SIM_NOISE, TRUTH, fixture, python, repo, text, twindrive};
use serde_json::Value;

const NOMINAL: &str = "0.066,0.066,0.26";
const LAG_S: f64 = 0.25;
const JOINTS: [&str; 4] = [
    "--left-joint",
    "wheel_left_joint",
    "--right-joint",
    "wheel_right_joint",
];

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn py(script: &str, args: &[&str]) -> String {
    let o = Command::new(python())
        .arg(repo().join("scripts/ros").join(script))
        .args(args)
        .output()
        .unwrap();
    assert!(o.status.success(), "{script} {args:?}: {}", text(&o.stderr));
    text(&o.stdout)
}

/// A 130 s calibration drive (the same as tests/calibrate.rs uses).
fn calibration_drive() -> &'static Path {
    static D: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    D.get_or_init(|| {
        common::shared_fixture("ros-calibration-drive", |dir| {
            let o = twindrive(&[
                "simulate",
                "scenarios/calibration_drive.toml",
                "--duration-s",
                "130",
                "--out",
                s(&dir.join("sim")),
            ]);
            assert!(o.status.success(), "{}", text(&o.stderr));
        })
    })
}

/// The calibration drive as `twindrive rosbag` writes it.
fn calibration_bag() -> &'static Path {
    static D: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    D.get_or_init(|| {
        common::shared_fixture("ros-calibration-bag", |dir| {
            let o = twindrive(&[
                "rosbag",
                s(&calibration_drive().join("sim")),
                "--out",
                s(&dir.join("drive")),
            ]);
            assert!(o.status.success(), "{}", text(&o.stderr));
        })
        .join("drive")
    })
}

fn calibrate(bag: &Path, out: &Path, extra: &[&str]) -> (std::process::Output, Option<Value>) {
    let mut args = vec![
        "calibrate",
        "--bag",
        s(bag),
        "--initial",
        NOMINAL,
        "--time-offset",
        "auto",
        "--out",
        s(out),
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&SIM_NOISE);
    let o = twindrive(&args);
    let json = std::fs::read(out)
        .ok()
        .map(|b| serde_json::from_slice(&b).unwrap());
    (o, json)
}

fn assert_recovered(j: &Value, offset_s: f64) {
    let p = ["left_diameter_m", "right_diameter_m", "wheelbase_m"].map(|k| j[k].as_f64().unwrap());
    for i in 0..3 {
        assert!((p[i] / TRUTH[i] - 1.0).abs() < 1e-3, "{p:?} vs {TRUTH:?}");
    }
    let found = j["clock_offset_s"].as_f64().unwrap();
    assert!(
        (found - offset_s).abs() < 0.01,
        "clock offset {found} vs {offset_s}"
    );
    assert_eq!(j["identifiability"]["well_determined"], true);
}

#[test]
fn recordings_written_by_rosbags_and_mcap_ros2_calibrate_to_the_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = calibration_drive().join("sim");
    let lag = LAG_S.to_string();

    // rosbags: a bag directory (metadata v9), joint positions, TF reference.
    let bag = tmp.path().join("tf_bag");
    py(
        "make_bag.py",
        &[
            s(&sim),
            s(&bag),
            "--writer",
            "rosbags",
            "--robot-clock-lag-s",
            &lag,
        ],
    );
    let out = tmp.path().join("a/calib.json");
    let mut extra = JOINTS.to_vec();
    extra.extend(["--pose-topic", "/tf", "--pose-frame", "robot"]);
    let (o, j) = calibrate(&bag, &out, &extra);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let j = j.unwrap();
    assert_recovered(&j, LAG_S);
    assert_eq!(j["data"]["time_origin_s"], 1.7e9);

    // mcap-ros2-support: one file, joint velocities only, PoseStamped.
    let file = tmp.path().join("pose.mcap");
    py(
        "make_bag.py",
        &[
            s(&sim),
            s(&file),
            "--writer",
            "mcap_ros2",
            "--robot-clock-lag-s",
            &lag,
        ],
    );
    let out = tmp.path().join("b/calib.json");
    let mut extra = JOINTS.to_vec();
    extra.extend(["--pose-topic", "/mocap/pose"]);
    let (o, j) = calibrate(&file, &out, &extra);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_recovered(&j.unwrap(), LAG_S);

    // Without the offset search the lag puts the poses at odds with the
    // wheels: the gate rejects most of them and the calibration is refused.
    let out = tmp.path().join("c/calib.json");
    let mut args = vec![
        "calibrate",
        "--bag",
        s(&file),
        "--initial",
        NOMINAL,
        "--out",
        s(&out),
        "--pose-topic",
        "/mocap/pose",
    ];
    args.extend(JOINTS);
    args.extend(SIM_NOISE);
    let o = twindrive(&args);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stdout));
    let e = text(&o.stderr);
    assert!(
        e.contains("calibration refused, nothing written") && e.contains("--time-offset auto"),
        "{e}"
    );
    assert!(!out.exists());
}

#[test]
fn twindrive_calibrates_from_its_own_exported_bag() {
    let tmp = tempfile::tempdir().unwrap();
    let bag = calibration_bag();
    let out = tmp.path().join("calib.json");
    let mut args = JOINTS.to_vec();
    args.extend(["--pose-topic", "/tracker/pose"]);
    let (o, j) = calibrate(bag, &out, &args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_recovered(&j.unwrap(), 0.0);
}

fn close(a: &Value, b: f64, tol: f64) -> bool {
    a.as_f64().is_some_and(|a| (a - b).abs() <= tol)
}

fn yaw(q: &Value) -> f64 {
    let f = |k: &str| q[k].as_f64().unwrap();
    (2.0 * (f("w") * f("z") + f("x") * f("y"))).atan2(1.0 - 2.0 * (f("y").powi(2) + f("z").powi(2)))
}

#[test]
fn exported_bags_decode_with_independent_decoders_to_the_log() {
    let f = fixture();
    let log = twindrive_log::read_log_dir(&f.path("wf")).unwrap();
    let plan: Value =
        serde_json::from_slice(&std::fs::read(f.path("plan/plan.json")).unwrap()).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    for distro in ["jazzy", "humble"] {
        let bag = tmp.path().join(format!("wf_{distro}"));
        let o = twindrive(&[
            "rosbag",
            s(&f.path("wf")),
            "--out",
            s(&bag),
            "--plan",
            s(&f.path("plan/plan.json")),
            "--distro",
            distro,
            "--start-time",
            "1700000000.5",
        ]);
        assert!(o.status.success(), "{}", text(&o.stderr));
        assert!(bag.join(format!("wf_{distro}_0.mcap")).is_file());
        let found: Value = serde_json::from_str(&py("check_bag.py", &[s(&bag), distro])).unwrap();
        let topic = |t: &str| -> &Value {
            let v = &found[t];
            assert!(
                v.is_object(),
                "no topic {t} in {:?}",
                found.as_object().unwrap().keys()
            );
            v
        };
        let count = |t: &str| topic(t)["count"].as_u64().unwrap() as usize;

        let encoder_steps: Vec<&twindrive_log::StepRecord> = log
            .steps
            .iter()
            .filter(|s| s.encoder_ticks.is_some())
            .collect();
        let last_enc = encoder_steps.last().unwrap();
        let tracker_steps = log.steps.iter().filter(|s| s.tracker.is_some()).count();
        for t in [
            "/joint_states",
            "/odom",
            "/ground_truth",
            "/cmd_vel",
            "/bump",
        ] {
            assert_eq!(count(t), encoder_steps.len(), "{t}");
        }
        assert_eq!(count("/tracker/pose"), tracker_steps);
        assert_eq!(count("/tf"), encoder_steps.len() + tracker_steps);

        // Stamps: the log's time plus --start-time.
        let js = &topic("/joint_states")["last"];
        let stamp = js["header"]["stamp"]["sec"].as_f64().unwrap()
            + js["header"]["stamp"]["nanosec"].as_f64().unwrap() * 1e-9;
        assert!(
            (stamp - (1_700_000_000.5 + last_enc.t_s())).abs() < 1e-6,
            "{stamp}"
        );
        assert_eq!(
            js["name"],
            serde_json::json!(["wheel_left_joint", "wheel_right_joint"])
        );
        let k = std::f64::consts::TAU / f64::from(log.header.ticks_per_rev);
        let [l, r] = last_enc.encoder_ticks.unwrap();
        assert!(close(&js["position"][0], l as f64 * k, 1e-12));
        assert!(close(&js["position"][1], r as f64 * k, 1e-12));

        let gt = &topic("/ground_truth")["last"]["pose"]["pose"];
        assert!(close(
            &gt["position"]["x"],
            last_enc.ground_truth.x_m,
            1e-12
        ));
        assert!(close(
            &gt["position"]["y"],
            last_enc.ground_truth.y_m,
            1e-12
        ));
        let dh = twindrive_kinematics::wrap_angle(
            yaw(&gt["orientation"]) - last_enc.ground_truth.heading_rad,
        );
        assert!(dh.abs() < 1e-9, "{dh}");

        // Dead reckoning with the nominal parameters stays near the truth
        // on a 30 s drive (in the odom frame, which starts at the start pose).
        let od = &topic("/odom")["last"];
        assert_eq!(od["header"]["frame_id"], "odom");
        assert_eq!(od["child_frame_id"], "base_link");

        // Every bump sample has one BUMP detection.
        let bumps = encoder_steps.iter().filter(|s| s.bump).count();
        assert!(bumps > 0, "the case study bumps");
        let bump_last = &topic("/bump")["last"];
        assert_eq!(
            bump_last["detections"].as_array().unwrap().len(),
            usize::from(last_enc.bump)
        );

        // One Range topic per ranger, INFRARED, with the log's readings.
        for (i, sensor) in log.header.range_sensors.iter().enumerate() {
            let name = format!("/{}", sensor.name);
            let readings: Vec<f64> = (0..log.steps.len())
                .filter_map(|k| log.range_reading(k, i).map(|r| r[0]))
                .collect();
            assert_eq!(count(&name), readings.len(), "{name}");
            let last = &topic(&name)["last"];
            if sensor.kind == twindrive_log::SensorKind::Ranger {
                assert_eq!(topic(&name)["type"], "sensor_msgs/msg/Range");
                assert_eq!(last["radiation_type"], 1);
                assert!(close(
                    &last["range"],
                    f64::from(*readings.last().unwrap() as f32),
                    0.0
                ));
                assert_eq!(last["header"]["frame_id"], format!("{}_link", sensor.name));
                assert_eq!(last.get("variance").is_some(), distro == "jazzy", "{last}");
            } else {
                assert_eq!(topic(&name)["type"], "sensor_msgs/msg/LaserScan");
            }
        }
        let statics = topic("/tf_static")["first"]["transforms"]
            .as_array()
            .unwrap()
            .clone();
        assert_eq!(statics.len(), log.header.range_sensors.len());
        for (t, sensor) in statics.iter().zip(&log.header.range_sensors) {
            assert_eq!(t["header"]["frame_id"], "base_link");
            assert!(close(
                &t["transform"]["translation"]["x"],
                sensor.mount.x_m,
                1e-12
            ));
            assert!((yaw(&t["transform"]["rotation"]) - sensor.mount.heading_rad).abs() < 1e-9);
        }

        // The map: walls drawn as occupied cells, the rest free.
        let map = &topic("/map")["first"];
        let cells = &map["data"];
        let n = cells["len"].as_u64().unwrap();
        assert_eq!(
            n,
            map["info"]["width"].as_u64().unwrap() * map["info"]["height"].as_u64().unwrap()
        );
        let occupied = cells["counts"]["100"].as_u64().unwrap_or(0);
        assert!(occupied > 100 && occupied < n / 2, "{occupied} of {n}");

        // The plan, latched, with the plan's poses.
        let path = &topic("/plan")["first"];
        let poses = path["poses"].as_array().unwrap();
        let samples = plan["samples"].as_array().unwrap();
        assert_eq!(poses.len(), samples.len());
        let lp = &poses.last().unwrap()["pose"]["position"];
        assert!(close(
            &lp["x"],
            samples.last().unwrap()["x_m"].as_f64().unwrap(),
            1e-12
        ));
    }
    // The metadata says which distribution's definitions were used.
    let yaml = std::fs::read_to_string(tmp.path().join("wf_humble/metadata.yaml")).unwrap();
    assert!(yaml.contains("ros_distro: humble"), "{yaml}");
}

#[test]
fn bad_recordings_and_wrong_names_say_which_topic_and_message() {
    let tmp = tempfile::tempdir().unwrap();
    let bag = calibration_bag();
    let out = tmp.path().join("res/calib.json");
    let run = |extra: &[&str]| {
        let (o, j) = calibrate(bag, &out, extra);
        assert!(!o.status.success(), "{extra:?} should fail");
        assert!(j.is_none(), "no output on failure");
        text(&o.stderr)
    };
    let run_joints = |pose: &[&str]| {
        let mut args = JOINTS.to_vec();
        args.extend_from_slice(pose);
        run(&args)
    };
    let e = run(&[
        "--left-joint",
        "left",
        "--right-joint",
        "right",
        "--pose-topic",
        "/tracker/pose",
    ]);
    assert!(
        e.contains("topic `/joint_states`") && e.contains("wheel_left_joint, wheel_right_joint"),
        "{e}"
    );
    let e = run_joints(&["--pose-topic", "/mocap"]);
    assert!(
        e.contains("topic `/mocap`: not in the bag")
            && e.contains("/tracker/pose (geometry_msgs/msg/PoseStamped"),
        "{e}"
    );
    let e = run_joints(&["--pose-topic", "/tf"]);
    assert!(e.contains("--pose-frame"), "{e}");
    let e = run_joints(&["--pose-topic", "/tf", "--pose-frame", "robot"]);
    assert!(
        e.contains("odom -> base_link") && e.contains("map -> odom"),
        "{e}"
    );
    let e = run(&[
        "--ticks-topic",
        "/joint_states",
        "--left-field",
        "name[0]",
        "--right-field",
        "position[1]",
        "--ticks-per-rev",
        "512",
        "--pose-topic",
        "/tracker/pose",
    ]);
    assert!(e.contains("`name[0]` is not a number field"), "{e}");

    // A recording cut short (no summary, no footer): read up to the cut,
    // said on stderr, and calibrated from what was read.
    let file = tmp.path().join("pose.mcap");
    py(
        "make_bag.py",
        &[
            s(&calibration_drive().join("sim")),
            s(&file),
            "--writer",
            "mcap_ros2",
        ],
    );
    let bytes = std::fs::read(&file).unwrap();
    let broken = tmp.path().join("cut.mcap");
    std::fs::write(&broken, &bytes[..bytes.len() / 2]).unwrap();
    let mut args = JOINTS.to_vec();
    args.extend(["--pose-topic", "/mocap/pose"]);
    let cut_out = tmp.path().join("cut/calib.json");
    let (o, j) = calibrate(&broken, &cut_out, &args);
    let e = text(&o.stderr);
    assert!(o.status.success() && j.is_some(), "{e}");
    assert!(
        e.contains("cut.mcap: cut short or damaged") && e.contains("whole messages"),
        "{e}"
    );

    // A message whose bytes end early: named by topic and index.
    let bad = tmp.path().join("bad.mcap");
    write_truncated_joint_state(&bad, 7);
    let (o, j) = calibrate(&bad, &out, &args);
    assert!(!o.status.success() && j.is_none());
    let e = text(&o.stderr);
    assert!(
        e.contains("topic `/joint_states`, message 7") && e.contains("ends before"),
        "{e}"
    );
    assert!(!e.contains("panicked"), "{e}");
    // `bag info` still reports the rest, and names what it cannot read.
    let (total, topics, out) = bag_info(&bad);
    assert!(total > 10 && topics.contains_key("/joint_states"), "{out}");
    assert!(
        out.contains("cannot read:") && out.contains("topic `/joint_states`, message 7"),
        "{out}"
    );
}

/// Ten JointState messages and a pose stream, message `bad` cut short.
fn write_truncated_joint_state(path: &Path, bad: usize) {
    use twindrive_ros::msgs::{self, Distro, Header, JointState, PoseStamped, RosMessage};
    let mut w = mcap::Writer::new(std::io::BufWriter::new(
        std::fs::File::create(path).unwrap(),
    ))
    .unwrap();
    let channel = |w: &mut mcap::Writer<_>, topic: &str, ty: &str| {
        let def = msgs::definition(ty, Distro::Jazzy).unwrap();
        let schema = w.add_schema(ty, "ros2msg", def.as_bytes()).unwrap();
        w.add_channel(schema, topic, "cdr", &Default::default())
            .unwrap()
    };
    let js = channel(&mut w, "/joint_states", JointState::TYPE);
    let ps = channel(&mut w, "/mocap/pose", PoseStamped::TYPE);
    for k in 0..10u64 {
        let t = 1_000_000_000 + k * 100_000_000;
        let mut bytes = msgs::encode(&JointState {
            header: Header::new(t, ""),
            name: vec!["wheel_left_joint".into(), "wheel_right_joint".into()],
            position: vec![k as f64, k as f64],
            velocity: vec![],
            effort: vec![],
        });
        if k as usize == bad {
            bytes.truncate(bytes.len() - 20);
        }
        let header = |channel_id| mcap::records::MessageHeader {
            channel_id,
            sequence: k as u32,
            log_time: t,
            publish_time: t,
        };
        w.write_to_known_channel(&header(js), &bytes).unwrap();
        let pose = msgs::encode(&PoseStamped {
            header: Header::new(t, "world"),
            pose: msgs::Pose::planar(0.1 * k as f64, 0.0, 0.0),
        });
        w.write_to_known_channel(&header(ps), &pose).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn type_hashes_match_rosbags_for_every_message_twindrive_knows() {
    let types: Vec<&str> = twindrive_ros::msgs::known_types().collect();
    let theirs: Value = serde_json::from_str(&py("type_hashes.py", &types)).unwrap();
    for t in types {
        assert_eq!(
            twindrive_ros::rmw_zenoh::type_hash(t).as_deref(),
            theirs[t].as_str(),
            "{t}"
        );
    }
}

/// A ROS 2 robot for the agent: a router for its ROS network, the fake
/// driver (the site simulator behind rmw_zenoh, bytes by rosbags and
/// eclipse-zenoh), the robot agent with a `[ros]` site, and a master.
struct RosRobot {
    dir: tempfile::TempDir,
    _router: common::Proc,
    driver: Option<common::Proc>,
    robot: common::Proc,
    robot_port: u16,
    /// The plan its master sends.
    plan: PathBuf,
}

const ROS_SECTION: &str = r#"
[ros]
connect = ["tcp/127.0.0.1:PORT"]

[ros.command]

[ros.joint_states]
left_joint = "wheel_left_joint"
right_joint = "wheel_right_joint"
timeout_s = 0.5

[[ros.ranges]]
topic = "side_ir"
sensor = "side_ir"

[ros.hazard]
topic = "hazard_detection"
type = "irobot_create_msgs/msg/HazardDetectionVector"

[ros.odom]
topic = "odom"
type = "nav_msgs/msg/Odometry"
"#;

impl RosRobot {
    fn start(driver_extra: &[&str]) -> Self {
        Self::start_at("", driver_extra)
    }

    /// The robot on the twin's site, its driver's site with `world_extra`
    /// added to the world (what the twin does not know).
    fn start_at(world_extra: &str, driver_extra: &[&str]) -> Self {
        let site = std::fs::read_to_string(repo().join("scenarios/wall_following.toml")).unwrap();
        Self::start_site(
            &site,
            world_extra,
            driver_extra,
            &fixture().path("plan/plan.json"),
        )
    }

    /// The robot at `site` (a site file without its `[ros]` section) with
    /// `plan` for its master.
    fn start_site(site: &str, world_extra: &str, driver_extra: &[&str], plan: &Path) -> Self {
        use std::process::Stdio;
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let ros_port = common::port();
        let mut ros = ROS_SECTION.replace("PORT", &ros_port.to_string());
        if site.contains("name = \"lidar\"") {
            ros.push_str("\n[[ros.ranges]]\ntopic = \"lidar\"\nsensor = \"lidar\"\n");
        }
        let site = site.to_owned() + &ros;
        std::fs::write(d.join("site.toml"), &site).unwrap();
        std::fs::write(
            d.join("driver_site.toml"),
            site.replace("[world]\n", &format!("[world]\n{world_extra}\n")),
        )
        .unwrap();
        let bin = env!("CARGO_BIN_EXE_twindrive");
        let router = common::Proc(
            Command::new(bin)
                .args(["router", "--listen", &format!("tcp/127.0.0.1:{ros_port}")])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap(),
        );
        let mut args: Vec<String> = [
            repo().join("scripts/ros/fake_driver.py").to_str().unwrap(),
            "--connect",
            &format!("tcp/127.0.0.1:{ros_port}"),
            "--site",
            s(&d.join("driver_site.toml")),
            "--twindrive",
            bin,
            "--stats",
            s(&d.join("driver.json")),
            "--run-for",
            "150",
        ]
        .iter()
        .map(|a| a.to_string())
        .collect();
        args.extend(driver_extra.iter().map(|a| a.to_string()));
        let driver = common::Proc(
            Command::new(python())
                .args(&args)
                .stdout(Stdio::null())
                .stderr(std::fs::File::create(d.join("driver.log")).unwrap())
                .spawn()
                .unwrap(),
        );
        let robot_port = common::port();
        let robot = common::Proc(
            Command::new(bin)
                .args([
                    "robot",
                    "--id",
                    "tb1",
                    "--site",
                    s(&d.join("site.toml")),
                    "--trust",
                    s(&fixture().path("keys/master.pub")),
                    "--key",
                    s(&fixture().path("keys/tb1.key")),
                    "--state-dir",
                    s(&d.join("robot")),
                    "--listen",
                    &format!("tcp/127.0.0.1:{robot_port}"),
                    "--run-for",
                    "150",
                ])
                // Says when it first hears each of the robot's topics.
                .env("RUST_LOG", "warn,twindrive_net::ros=info")
                .stdout(Stdio::null())
                .stderr(std::fs::File::create(d.join("robot.log")).unwrap())
                .spawn()
                .unwrap(),
        );
        Self {
            dir,
            _router: router,
            driver: Some(driver),
            robot,
            robot_port,
            plan: plan.to_owned(),
        }
    }

    /// Runs a master to the end: its exit code and report. The mission
    /// starts once the agent has heard the driver's joint states, as an
    /// operator starts one once the robot is up (a robot whose joints never
    /// reported stops on a sensor fault at the plan's first step, which a
    /// slow start on a loaded machine would otherwise cause).
    fn master(&self) -> (Option<i32>, Value) {
        let started = std::time::Instant::now();
        let heard = |log: &str| {
            log.lines()
                .any(|l| l.contains("first message from the robot") && l.contains("joint_states"))
        };
        while !heard(&self.log("robot.log")) {
            assert!(
                started.elapsed().as_secs() < 60,
                "the agent heard no joint states in 60 s\ndriver: {}\nrobot: {}",
                self.log("driver.log"),
                self.log("robot.log")
            );
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
        let out = self.dir.path().join("master");
        let m = common::Proc(
            Command::new(env!("CARGO_BIN_EXE_twindrive"))
                .args([
                    "master",
                    "--plan",
                    s(&self.plan),
                    "--key",
                    s(&fixture().path("keys/master.key")),
                    "--trust-robot",
                    s(&fixture().path("keys/tb1.pub")),
                    "--link-state",
                    s(&self.dir.path().join("master-link")),
                    "--robot",
                    "tb1",
                    "--connect",
                    &format!("tcp/127.0.0.1:{}", self.robot_port),
                    "--out",
                    s(&out),
                    "--timeout",
                    "90",
                    "--log-wait",
                    "5",
                ])
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap(),
        );
        let (code, err) = common::finish(m, 120.0);
        let report = std::fs::read(out.join("report.json"))
            .map(|b| serde_json::from_slice(&b).unwrap())
            .unwrap_or_else(|_| {
                panic!("no report; master: {err}\nrobot: {}", self.log("robot.log"))
            });
        (code, report)
    }

    fn log(&self, name: &str) -> String {
        std::fs::read_to_string(self.dir.path().join(name)).unwrap_or_default()
    }

    /// Stops the driver (SIGTERM: it writes its statistics) and reads them.
    fn driver_stats(&mut self) -> Value {
        let d = self.driver.take().unwrap();
        let pid = d.0.id().to_string();
        let _ = Command::new("kill").args(["-TERM", &pid]).status();
        let path = self.dir.path().join("driver.json");
        let start = std::time::Instant::now();
        while !path.exists() {
            // The driver asks the graph for up to 30 s before it writes.
            assert!(
                start.elapsed().as_secs() < 60,
                "the fake driver wrote no statistics: {}",
                self.log("driver.log")
            );
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
        drop(d);
        serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
    }
}

#[test]
fn a_plan_runs_on_a_ros2_robot_through_rmw_zenoh() {
    let mut r = RosRobot::start(&[]);
    let (code, report) = r.master();
    assert_eq!(code, Some(0), "{report}\nrobot: {}", r.log("robot.log"));
    assert_eq!(report["outcome"], "completed");
    assert_eq!(report["collisions"], 0);
    let _ = &r.robot;
    let stats = r.driver_stats();
    // The agent drove the robot through /cmd_vel, every sample with an
    // rmw_zenoh attachment, numbered from 1.
    let commands = stats["commands"].as_u64().unwrap();
    assert!(commands > 200, "{stats}");
    assert!(stats["moving_commands"].as_u64().unwrap() > 100, "{stats}");
    assert_eq!(stats["bad_attachments"], 0);
    assert_eq!(stats["decode_errors"], 0);
    let seq: Vec<i64> = stats["sequence_numbers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_i64().unwrap())
        .collect();
    // Numbered from 1, one more each command. The agent commands zero
    // from its start, maybe before the driver listens, and zenoh drops a
    // put whose route is still settling (its default congestion control):
    // the driver may miss the first few.
    assert!(seq[0] >= 1, "{:?}", &seq[..seq.len().min(20)]);
    assert!(seq.windows(2).all(|w| w[1] > w[0]));
    let steps_of_one = seq.windows(2).filter(|w| w[1] == w[0] + 1).count();
    assert!(
        steps_of_one as f64 >= 0.99 * (seq.len() - 1) as f64,
        "{steps_of_one} of {} commands follow the one before",
        seq.len()
    );
    // rosbags' RIHS01 hashes are twindrive's.
    for (t, h) in stats["type_hashes"].as_object().unwrap() {
        assert_eq!(
            twindrive_ros::rmw_zenoh::type_hash(t).as_deref(),
            h.as_str(),
            "{t}"
        );
    }
    // The ROS graph sees the agent: its node, subscriptions and publisher.
    let tokens: Vec<&str> = stats["liveliness"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    let js_hash = twindrive_ros::rmw_zenoh::type_hash("sensor_msgs/msg/JointState").unwrap();
    let twist_hash = twindrive_ros::rmw_zenoh::type_hash("geometry_msgs/msg/Twist").unwrap();
    for want in [
        "/NN/%/%/twindrive_agent".to_string(),
        format!("/MS/%/%/twindrive_agent/%joint_states/sensor_msgs::msg::dds_::JointState_/{js_hash}/"),
        format!("/MP/%/%/twindrive_agent/%cmd_vel/geometry_msgs::msg::dds_::Twist_/{twist_hash}/"),
        "/MS/%/%/twindrive_agent/%side_ir/sensor_msgs::msg::dds_::Range_/".to_string(),
        "/MS/%/%/twindrive_agent/%hazard_detection/irobot_create_msgs::msg::dds_::HazardDetectionVector_/".to_string(),
    ] {
        assert!(
            tokens.iter().any(|t| t.starts_with("@ros2_lv/0/") && t.contains(&want)),
            "no token with {want} in {tokens:#?}"
        );
    }
    // The robot's own log of the plan, as a rosbag2 bag ROS tools read.
    let logs = r.dir.path().join("robot/logs");
    let log = std::fs::read_dir(&logs)
        .unwrap()
        .next()
        .expect("the robot logged the plan")
        .unwrap()
        .path()
        .join("log.mcap");
    let bag = r.dir.path().join("robot_bag");
    let o = twindrive(&["rosbag", s(&log), "--out", s(&bag)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let found: Value = serde_json::from_str(&py("check_bag.py", &[s(&bag), "jazzy"])).unwrap();
    assert!(
        found["/joint_states"]["count"].as_u64().unwrap() > 100,
        "{found}"
    );
    assert!(found["/side_ir"]["count"].as_u64().unwrap() > 100);
}

#[test]
fn silent_joint_states_stop_the_wheels_and_hand_back() {
    let mut r = RosRobot::start(&["--stall-joints-after", "3"]);
    let (code, report) = r.master();
    assert_eq!(code, Some(3), "{report}\nrobot: {}", r.log("robot.log"));
    assert_eq!(report["outcome"], "handed_back", "{report}");
    let handback = &report["handbacks"][0];
    assert!(handback.to_string().contains("sensor_fault"), "{handback}");
    let stats = r.driver_stats();
    assert!(stats["stalled_at_s"].as_f64().is_some(), "{stats}");
    // After the driver hung, the agent commanded zero within the timeout
    // (0.5 s) plus a few periods, and never moved the robot again.
    let after: Vec<(f64, f64, f64)> = stats["after_stall"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| {
            (
                v[0].as_f64().unwrap(),
                v[1].as_f64().unwrap(),
                v[2].as_f64().unwrap(),
            )
        })
        .collect();
    let first_zero = after
        .iter()
        .find(|(_, v, w)| *v == 0.0 && *w == 0.0)
        .unwrap_or_else(|| panic!("no zero command after the stall: {after:?}"));
    assert!(first_zero.0 < 0.5 + 0.2, "{after:?}");
    assert!(
        after
            .iter()
            .all(|(t, v, w)| *t <= first_zero.0 || (*v == 0.0 && *w == 0.0)),
        "{after:?}"
    );
}

/// What the fake driver saw of a stop: when the last moving command came,
/// when the first zero after it did, the longest silence from then to the
/// driver's end, and how far the robot went after the last moving command.
struct StopSeen {
    stopped_at_s: f64,
    first_zero_s: f64,
    longest_gap_s: f64,
    travelled_m: f64,
    /// The wheel speeds driven at the driver's last tick.
    last_wheels: (f64, f64),
}

fn stop_seen(stats: &Value) -> StopSeen {
    let rows = |key: &str| -> Vec<Vec<f64>> {
        stats[key]
            .as_array()
            .unwrap()
            .iter()
            .map(|row| {
                row.as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap())
                    .collect()
            })
            .collect()
    };
    let received = rows("received");
    let ticks = rows("ticks");
    let moving = |c: &Vec<f64>| c[1] != 0.0 || c[2] != 0.0;
    let last_moving = received
        .iter()
        .rposition(moving)
        .unwrap_or_else(|| panic!("the robot was never driven: {stats}"));
    let stopped_at_s = received[last_moving][0];
    // After the last moving command, zero and only zero, every period
    // until the driver stopped listening.
    let zeros = &received[last_moving + 1..];
    assert!(!zeros.is_empty(), "no zero command after the stop");
    let end_s = ticks.last().unwrap()[0];
    let mut heard = vec![stopped_at_s];
    heard.extend(zeros.iter().map(|c| c[0]));
    heard.push(end_s);
    let longest_gap_s = heard.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
    let at = |t: f64| {
        let k = ticks.partition_point(|row| row[0] < t).min(ticks.len() - 1);
        (ticks[k][3], ticks[k][4])
    };
    let (x0, y0) = at(stopped_at_s);
    let last = ticks.last().unwrap();
    StopSeen {
        stopped_at_s,
        first_zero_s: zeros[0][0],
        longest_gap_s,
        travelled_m: (last[3] - x0).hypot(last[4] - y0),
        last_wheels: (last[1], last[2]),
    }
}

/// The box the twin lacks, in the plan's way.
const BOX: &str = "rectangles = [{ min = [1.9, 0.9], max = [2.1, 1.2] }]";

/// A motor controller that holds the last command it heard (no command
/// timeout), on a site with a box the twin lacks: when the agent hands back,
/// the period that decides it commands zero, the agent goes on commanding
/// zero every period, and the robot halts within its braking distance.
#[test]
fn a_hand_back_stops_a_robot_whose_driver_holds_its_last_command() {
    let mut r = RosRobot::start_at(BOX, &["--cmd-timeout", "0"]);
    let (code, report) = r.master();
    assert_eq!(code, Some(3), "{report}\nrobot: {}", r.log("robot.log"));
    assert_eq!(report["outcome"], "handed_back", "{report}");
    let seen = stop_seen(&r.driver_stats());
    assert!(
        seen.longest_gap_s < 0.25,
        "the zero command paused for {:.3} s (one period is 0.02 s)",
        seen.longest_gap_s
    );
    // 7.7 rad/s at 30 rad/s^2 on 33 mm wheels is 3.3 cm of braking, plus a
    // period or two of latency.
    assert!(
        seen.travelled_m < 0.06,
        "{:.3} m travelled after the stop was commanded",
        seen.travelled_m
    );
    assert_eq!(seen.last_wheels, (0.0, 0.0), "the wheels still turn");
}

/// The case study's plan, made on the twin, on a robot nobody here wrote:
/// MuJoCo behind the driver (velocity-controlled motors with a torque
/// limit, inertia, tyre and caster friction, ray-cast range sensor,
/// bumper from contacts). It completes with no contact.
#[test]
fn a_plan_made_on_the_twin_completes_on_a_physics_engines_robot() {
    let mut r = RosRobot::start(&["--physics", "mujoco"]);
    let (code, report) = r.master();
    assert_eq!(
        code,
        Some(0),
        "{report}\nrobot: {}\njournal: {}",
        r.log("robot.log"),
        r.log("robot/journal.jsonl")
    );
    assert_eq!(report["outcome"], "completed", "{report}");
    assert_eq!(report["collisions"], 0, "{report}");
    assert_eq!(report["bumps"], 0, "{report}");
    let stats = r.driver_stats();
    assert_eq!(stats["physics"], "mujoco");
    assert_eq!(stats["contact_ticks"], 0, "MuJoCo saw a contact");
}

/// The same robot in MuJoCo with a box the twin lacks and a motor
/// controller that holds its last command: the hand-back's zero reaches the
/// motors within a control period or two of the last moving command, and
/// the robot rolls no further than the physics' own braking distance from
/// its speed then (an experiment on the same model) plus that latency.
#[test]
fn a_hand_back_halts_a_physics_engines_robot_within_its_braking_distance() {
    let mut r = RosRobot::start_at(BOX, &["--physics", "mujoco", "--cmd-timeout", "0"]);
    let (code, report) = r.master();
    assert_eq!(code, Some(3), "{report}\nrobot: {}", r.log("robot.log"));
    assert_eq!(report["outcome"], "handed_back", "{report}");
    let stats = r.driver_stats();
    let seen = stop_seen(&stats);
    let braking = &stats["braking"];
    let speed_m_s = braking["speed_m_s"].as_f64().unwrap();
    let braking_m = braking["distance_m"].as_f64().unwrap();
    assert!(speed_m_s > 0.05, "the robot was not moving: {braking}");
    let latency_s = seen.first_zero_s - seen.stopped_at_s;
    assert!(
        latency_s < 0.1,
        "the zero came {latency_s:.3} s after the last moving command (one period is 0.02 s)"
    );
    assert!(seen.longest_gap_s < 0.25, "{:.3} s", seen.longest_gap_s);
    // The driver applies a command at its next tick (0.02 s).
    let bound_m = braking_m + speed_m_s * (latency_s + 0.02) + 0.005;
    assert!(
        seen.travelled_m <= bound_m,
        "{:.4} m after the last moving command; braking from {speed_m_s:.3} m/s is {braking_m:.4} m, bound {bound_m:.4} m",
        seen.travelled_m
    );
    assert_eq!(seen.last_wheels, (0.0, 0.0), "the wheels still turn");
}

/// An LDS-like scanner on the paper's robot: 360 beams at 5 Hz.
const LIDAR: &str = r#"
[[range_sensors]]
name = "lidar"
kind = "lidar"
mount = { x_m = 0.0, y_m = 0.0, heading_rad = 0.0 }
beams = 360
fov_rad = 6.283185307179586
min_range_m = 0.12
max_range_m = 3.5
noise_std_m = 0.01
rate_hz = 5.0
"#;

/// The paper's site with the lidar robot, and a wall-following rehearsal
/// of 30 s on it (its directory).
fn lidar_rehearsal() -> &'static (tempfile::TempDir, String) {
    static R: std::sync::OnceLock<(tempfile::TempDir, String)> = std::sync::OnceLock::new();
    R.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let site =
            std::fs::read_to_string(repo().join("scenarios/wall_following.toml")).unwrap() + LIDAR;
        std::fs::write(dir.path().join("site.toml"), &site).unwrap();
        let out = twindrive(&[
            "simulate",
            s(&dir.path().join("site.toml")),
            "--duration-s",
            "30",
            "--out",
            s(&dir.path().join("wf")),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        (dir, site)
    })
}

/// Distance from `p` to the rectangle `r` (`[min, max]` corners), 0 inside.
fn to_rect(p: [f64; 2], r: [[f64; 2]; 2]) -> f64 {
    let dx = (r[0][0] - p[0]).max(p[0] - r[1][0]).max(0.0);
    let dy = (r[0][1] - p[1]).max(p[1] - r[1][1]).max(0.0);
    dx.hypot(dy)
}

/// The lidar robot in MuJoCo (motor torque limits, inertia, friction) with
/// a box the twin lacks on its route, at a random place and of a random
/// size, and a keep-out zone the operator drew at random beside the route:
/// the robot goes around the box on its own (a detour, back on the plan)
/// and completes, with no contact in the physics engine and its true
/// footprint never in the zone. `TWINDRIVE_TRIALS=N` runs N random sites
/// (CI runs one).
#[test]
fn a_lidar_robot_on_a_physics_engine_goes_around_a_box_and_keeps_out_of_a_zone() {
    use rand::{RngExt, SeedableRng};
    let trials: u64 = std::env::var("TWINDRIVE_TRIALS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1);
    let (rehearsal, site) = lidar_rehearsal();
    let footprint_m = 0.15;
    for seed in 0..trials {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(400 + seed);
        // The box on the first leg (the route runs west at y = 1.05-1.1).
        let (bx, by) = (
            rng.random_range(1.9..2.5),
            1.07 + rng.random_range(-0.08..0.08),
        );
        let half = [rng.random_range(0.05..0.12), rng.random_range(0.05..0.12)];
        let block = [[bx - half[0], by - half[1]], [bx + half[0], by + half[1]]];
        // The zone south of the route, from the room's wall up.
        let (zx, zl) = (rng.random_range(1.2..3.2), rng.random_range(0.15..0.4));
        let zone = [[zx - zl, 0.0], [zx + zl, rng.random_range(0.2..0.45)]];
        let trial = tempfile::tempdir().unwrap();
        let freedom = trial.path().join("freedom.toml");
        std::fs::write(
            &freedom,
            format!(
                "[[keep_out]]\nname = \"flowers\"\npolygon = [[{a}, {b}], [{c}, {b}], [{c}, {d}], [{a}, {d}]]\n",
                a = zone[0][0],
                b = zone[0][1],
                c = zone[1][0],
                d = zone[1][1]
            ),
        )
        .unwrap();
        let plan = trial.path().join("plan.json");
        let out = twindrive(&[
            "plan",
            s(&rehearsal.path().join("wf")),
            "--calibration",
            s(&fixture().path("calib.json")),
            "--scenario",
            s(&rehearsal.path().join("site.toml")),
            "--freedom",
            s(&freedom),
            "--out",
            s(&plan),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let world = format!(
            "rectangles = [{{ min = [{}, {}], max = [{}, {}] }}]",
            block[0][0], block[0][1], block[1][0], block[1][1]
        );
        let mut r = RosRobot::start_site(site, &world, &["--physics", "mujoco"], &plan);
        let (code, report) = r.master();
        let journal = r.log("robot/journal.jsonl");
        assert_eq!(
            code,
            Some(0),
            "box {block:?}, zone {zone:?}: {report}\nrobot: {}\njournal: {journal}",
            r.log("robot.log")
        );
        assert_eq!(report["outcome"], "completed", "{report}");
        assert!(
            report["handbacks"].as_array().unwrap().is_empty(),
            "{report}"
        );
        assert_eq!(
            (&report["collisions"], &report["bumps"]),
            (&0.into(), &0.into())
        );
        let detours = report["detours"].as_array().unwrap();
        let done = detours.iter().find(|d| d["rejoined"] == true);
        let done = done.unwrap_or_else(|| panic!("no detour back on the plan: {report}"));
        let stats = r.driver_stats();
        assert_eq!(stats["physics"], "mujoco");
        assert_eq!(
            stats["contact_ticks"], 0,
            "MuJoCo saw a contact: box {block:?}"
        );
        // The driver's ticks carry MuJoCo's true position (x, y last).
        let track: Vec<[f64; 2]> = stats["ticks"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| [t[3].as_f64().unwrap(), t[4].as_f64().unwrap()])
            .collect();
        let nearest = |r: [[f64; 2]; 2]| {
            track
                .iter()
                .map(|p| to_rect(*p, r))
                .fold(f64::INFINITY, f64::min)
        };
        let (to_zone, to_box) = (nearest(zone), nearest(block));
        eprintln!(
            "trial {seed}: box {block:?}, zone {zone:?}: detour +{:.1} s, +{:.2} m; closest to the box {to_box:.3} m, to the zone {to_zone:.3} m (centre; footprint {footprint_m} m)",
            done["extra_s"].as_f64().unwrap(),
            done["extra_m"].as_f64().unwrap()
        );
        assert!(to_box > footprint_m, "{to_box} m from the box");
        assert!(
            to_zone > footprint_m,
            "the footprint entered the zone: {to_zone} m"
        );
    }
}

/// `twindrive bag info`'s message count and per-topic (type, count).
fn bag_info(
    bag: &Path,
) -> (
    u64,
    std::collections::BTreeMap<String, (String, u64)>,
    String,
) {
    let o = twindrive(&["bag", "info", s(bag)]);
    assert!(
        o.status.success(),
        "bag info {}: {}",
        bag.display(),
        text(&o.stderr)
    );
    let out = text(&o.stdout);
    let total = out
        .lines()
        .find_map(|l| l.strip_prefix("Messages:"))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("{out}"));
    let topics = out
        .lines()
        .filter_map(|l| l.split_once("Topic: ").map(|(_, r)| r))
        .map(|r| {
            let parts: Vec<&str> = r.split(" | ").map(str::trim).collect();
            let ty = parts[1].trim_start_matches("Type: ").to_string();
            let count = parts[2].trim_start_matches("Count: ").parse().unwrap();
            (parts[0].to_string(), (ty, count))
        })
        .collect();
    (total, topics, out)
}

/// What `rosbags` counts in each of `bags` (scripts/ros/bag_counts.py).
fn rosbags_counts(bags: &[PathBuf]) -> Vec<Value> {
    let args: Vec<&str> = bags.iter().map(|b| s(b)).collect();
    let v: Value = serde_json::from_str(&py("bag_counts.py", &args)).unwrap();
    v.as_array().unwrap().clone()
}

fn assert_same_counts(bag: &Path, theirs: &Value) {
    let (total, topics, out) = bag_info(bag);
    assert_eq!(
        total,
        theirs["message_count"].as_u64().unwrap(),
        "{}\n{out}",
        bag.display()
    );
    let their_topics = theirs["topics"].as_object().unwrap();
    assert_eq!(topics.len(), their_topics.len(), "{}\n{out}", bag.display());
    for (name, t) in their_topics {
        let (ty, count) = &topics[name];
        assert_eq!(ty, t["type"].as_str().unwrap(), "{name}");
        assert_eq!(
            *count,
            t["count"].as_u64().unwrap(),
            "{}: {name}\n{out}",
            bag.display()
        );
    }
}

/// The calibration drive rewritten by `rosbags` in every storage, split,
/// compressed and metadata layout (scripts/ros/bag_variants.py).
fn variants() -> &'static Path {
    static D: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    D.get_or_init(|| {
        common::shared_fixture("ros-bag-variants", |dir| {
            py("bag_variants.py", &[s(calibration_bag()), s(dir)]);
        })
    })
}

#[test]
fn every_storage_and_layout_rosbags_writes_opens_with_its_counts() {
    let mut bags: Vec<PathBuf> = std::fs::read_dir(variants())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir())
        .collect();
    bags.sort();
    for want in [
        "sqlite3_v8",
        "sqlite3_v9",
        "mcap_v9",
        "sqlite3_file_zstd",
        "mcap_file_zstd",
        "sqlite3_message_zstd",
        "sqlite3_split",
        "mcap_split",
        "sqlite3_split_no_metadata",
        "mcap_split_no_metadata",
        "sqlite3_v4",
        "sqlite3_v5",
        "sqlite3_v6",
        "sqlite3_v7",
        "sqlite3_foxy",
        "sqlite3_humble",
    ] {
        assert!(
            bags.iter().any(|b| b.ends_with(want)),
            "bag_variants.py wrote no {want}: {bags:?}"
        );
    }
    // rosbag2's own test bags, read in place from the shared data sets
    // (../shared/data/rosbag2_test_bags/SOURCE.md).
    let fixtures = repo().join("../shared/data/rosbag2_test_bags");
    assert!(
        fixtures.is_dir(),
        "{} is absent: the shared data sets sit beside the repository",
        fixtures.display()
    );
    for name in [
        "foxy_sqlite3_cdr_test",
        "sqlite3_cdr_test",
        "mcap_cdr_test",
        "mcap_wbag",
        "mcap_multiple_files_no_metadata",
        "galactic_sqlite3_file_compression_no_metadata",
    ] {
        bags.push(fixtures.join(name));
    }
    let theirs = rosbags_counts(&bags);
    for (bag, theirs) in bags.iter().zip(&theirs) {
        assert!(theirs.get("error").is_none(), "{theirs}");
        assert_same_counts(bag, theirs);
    }
    // The Foxy and Humble layouts store no definitions: the built-in ones
    // decode them, and calibration reads the sqlite3 copies like the MCAP.
    for name in [
        "sqlite3_foxy",
        "sqlite3_split_no_metadata",
        "sqlite3_file_zstd",
    ] {
        let (_, _, out) = bag_info(&variants().join(name));
        assert!(
            out.contains("--left-joint wheel_left_joint --right-joint wheel_right_joint --pose-topic /tracker/pose"),
            "{name}: {out}"
        );
    }
}

#[test]
fn the_sqlite3_copy_calibrates_exactly_as_the_mcap_one() {
    let tmp = tempfile::tempdir().unwrap();
    let mut args = JOINTS.to_vec();
    args.extend(["--pose-topic", "/tracker/pose"]);
    let run = |bag: &Path, name: &str| {
        let out = tmp.path().join(name).join("calib.json");
        let (o, j) = calibrate(bag, &out, &args);
        assert!(o.status.success(), "{name}: {}", text(&o.stderr));
        let j = j.unwrap();
        ["left_diameter_m", "right_diameter_m", "wheelbase_m"].map(|k| j[k].as_f64().unwrap())
    };
    let mcap = run(calibration_bag(), "mcap");
    for name in [
        "sqlite3_v9",
        "sqlite3_humble",
        "sqlite3_split_no_metadata",
        "mcap_file_zstd",
    ] {
        let p = run(&variants().join(name), name);
        for i in 0..3 {
            assert!((p[i] - mcap[i]).abs() < 1e-9, "{name}: {p:?} vs {mcap:?}");
        }
    }
    for i in 0..3 {
        assert!((mcap[i] / TRUTH[i] - 1.0).abs() < 1e-3, "{mcap:?}");
    }
}

#[test]
fn sqlite3_bags_twindrive_writes_read_back_in_rosbags_message_for_message() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = calibration_drive().join("sim");
    for distro in ["humble", "jazzy"] {
        let mut lists = Vec::new();
        for storage in ["mcap", "sqlite3"] {
            let bag = tmp.path().join(format!("{distro}_{storage}"));
            let o = twindrive(&[
                "rosbag",
                s(&sim),
                "--out",
                s(&bag),
                "--distro",
                distro,
                "--storage",
                storage,
            ]);
            assert!(o.status.success(), "{}", text(&o.stderr));
            let read: Value =
                serde_json::from_str(&py("read_bag_messages.py", &[s(&bag), "--distro", distro]))
                    .unwrap();
            assert_eq!(read["distro"], distro, "{storage}");
            let (total, _, _) = bag_info(&bag);
            assert_eq!(total as usize, read["messages"].as_array().unwrap().len());
            lists.push(read["messages"].clone());
        }
        // The same topics, times and bytes in both storages.
        assert_eq!(lists[0], lists[1], "{distro}");
    }
}

#[test]
fn recordings_cut_short_read_up_to_the_damage_and_calibrate() {
    let tmp = tempfile::tempdir().unwrap();
    let src = calibration_bag();
    let file = std::fs::read_dir(src)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .unwrap();
    let whole = std::fs::read(&file).unwrap();
    let (total, _, _) = bag_info(src);
    let cut = |name: &str, bytes: &[u8]| {
        let dir = tmp.path().join(name);
        std::fs::create_dir_all(&dir).unwrap();
        // A recorder that lost power writes no metadata.yaml either.
        std::fs::write(dir.join(file.file_name().unwrap()), bytes).unwrap();
        dir
    };
    let mut counts = Vec::new();
    for percent in [50, 70, 90] {
        let dir = cut(
            &format!("cut{percent}"),
            &whole[..whole.len() * percent / 100],
        );
        let (n, _, out) = bag_info(&dir);
        assert!(
            n < total && out.contains("the file ends in the middle of a record"),
            "{percent} %: {n} of {total}\n{out}"
        );
        counts.push(n);
        if percent == 70 {
            let out_json = tmp.path().join("cal70/calib.json");
            let mut args = JOINTS.to_vec();
            args.extend(["--pose-topic", "/tracker/pose"]);
            let (o, j) = calibrate(&dir, &out_json, &args);
            assert!(o.status.success(), "{}", text(&o.stderr));
            let stderr = text(&o.stderr);
            assert!(
                stderr.contains("cut short") && stderr.contains("whole messages"),
                "{stderr}"
            );
            let j = j.unwrap();
            let p = ["left_diameter_m", "right_diameter_m", "wheelbase_m"]
                .map(|k| j[k].as_f64().unwrap());
            for i in 0..3 {
                assert!((p[i] / TRUTH[i] - 1.0).abs() < 1e-3, "{p:?} vs {TRUTH:?}");
            }
        }
    }
    assert!(counts.windows(2).all(|w| w[0] < w[1]), "{counts:?}");
    // The last chunk's bytes scrambled: everything before it reads.
    let summary = mcap::Summary::read(&whole).unwrap().unwrap();
    let last = summary.chunk_indexes.last().unwrap();
    let at = (last.chunk_start_offset + last.chunk_length / 2) as usize;
    let mut bad = whole.clone();
    for b in &mut bad[at..at + 256] {
        *b ^= 0x5a;
    }
    let dir = cut("scrambled", &bad);
    let (n, _, out) = bag_info(&dir);
    assert!(
        n < total && n > total / 2 && out.contains("a chunk is damaged"),
        "{n} of {total}\n{out}"
    );
    // Nothing whole: a clear error, not a panic.
    let dir = cut("empty", &whole[..64]);
    let o = twindrive(&["bag", "info", s(&dir)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o.stderr).contains("no whole message"),
        "{}",
        text(&o.stderr)
    );
}

#[test]
fn calibrations_the_bag_does_not_support_fail_and_write_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    // The left wheel's sign flipped: the gate rejects most poses.
    let out = tmp.path().join("sign/calib.json");
    let mut args = JOINTS.to_vec();
    args.extend(["--pose-topic", "/tracker/pose", "--left-sign", "-1"]);
    let (o, j) = calibrate(calibration_bag(), &out, &args);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stdout));
    let e = text(&o.stderr);
    assert!(
        e.contains("calibration refused, nothing written")
            && (e.contains("the filter's gate rejected") || e.contains("failed the gate"))
            && e.contains("--left-sign"),
        "{e}"
    );
    assert!(j.is_none() && !tmp.path().join("sign").exists());
    // Asking for what the bag lacks lists what it has.
    let out = tmp.path().join("missing/calib.json");
    let mut args = JOINTS.to_vec();
    args.extend(["--pose-topic", "/amcl_pose"]);
    let (o, _) = calibrate(&variants().join("sqlite3_v9"), &out, &args);
    assert_eq!(o.status.code(), Some(1));
    let e = text(&o.stderr);
    assert!(
        e.contains("/amcl_pose") && e.contains("not in the bag") && e.contains("/tracker/pose"),
        "{e}"
    );
}

/// Self-calibration from a bag with no pose topic: the self-calibration
/// drive exported by `twindrive rosbag` (joint states, /lidar scans, /imu,
/// /tf_static with the lidar's mount), rewritten by rosbags in sqlite3 (its
/// v9 writer and Humble's layout), and written by rosbags from the log
/// (`make_bag.py --scans`: rosbags' own CDR serializer) calibrates as its
/// log directory does; a wrong topic names those the bag has.
#[test]
fn a_bag_self_calibrates_from_its_scans_as_its_log_does() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    let scenario = "scenarios/self_calibration_drive.toml";
    let o = twindrive(&["simulate", scenario, "--out", s(&sim)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let bag = tmp.path().join("bag");
    let o = twindrive(&["rosbag", s(&sim), "--scenario", scenario, "--out", s(&bag)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let read = |out: &Path| -> [f64; 9] {
        let j: Value = serde_json::from_slice(&std::fs::read(out).unwrap()).unwrap();
        assert_eq!(j["reference"], "scans");
        let m = &j["lidar_mount"];
        let g = &j["gyro"];
        [
            j["left_diameter_m"].as_f64().unwrap(),
            j["right_diameter_m"].as_f64().unwrap(),
            j["wheelbase_m"].as_f64().unwrap(),
            m["x_m"].as_f64().unwrap(),
            m["y_m"].as_f64().unwrap(),
            m["heading_rad"].as_f64().unwrap(),
            g["bias_rad_s"].as_f64().unwrap(),
            g["scale_error"].as_f64().unwrap(),
            j["lidar_mount_guess"]["heading_rad"].as_f64().unwrap(),
        ]
    };
    let log_out = tmp.path().join("log/calib.json");
    let o = twindrive(&["calibrate", s(&sim), "--out", s(&log_out)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let from_log = read(&log_out);
    let by_bag = |bag: &Path, name: &str, scan_topic: &str| -> [f64; 9] {
        let out = tmp.path().join(name).join("calib.json");
        let mut args = vec![
            "calibrate",
            "--bag",
            s(bag),
            "--scan-topic",
            scan_topic,
            "--imu-topic",
            "/imu",
        ];
        args.extend(JOINTS);
        args.extend(["--initial", NOMINAL, "--out", s(&out)]);
        let o = twindrive(&args);
        assert!(o.status.success(), "{name}: {}", text(&o.stderr));
        assert!(
            text(&o.stdout).contains("guess from /tf_static"),
            "{name}: {}",
            text(&o.stdout)
        );
        read(&out)
    };
    let variants = tmp.path().join("variants");
    py("bag_variants.py", &[s(&bag), s(&variants)]);
    // And the same log recorded by rosbags' own writer and serializer: the
    // scans in frame `laser` under a two-link /tf_static chain, the
    // stamps in Unix time.
    let rosbags = tmp.path().join("rosbags");
    py(
        "make_bag.py",
        &[s(&sim), s(&rosbags), "--writer", "rosbags", "--scans"],
    );
    for (name, path, topic) in [
        ("mcap", bag.clone(), "/lidar"),
        ("sqlite3_v9", variants.join("sqlite3_v9"), "/lidar"),
        ("sqlite3_humble", variants.join("sqlite3_humble"), "/lidar"),
        ("rosbags", rosbags.clone(), "/scan"),
    ] {
        // The same numbers up to the matcher's convergence (10 µm steps):
        // the mount guess from /tf_static's quaternion differs from the log
        // header's in the last bit, so the priors do.
        let p = by_bag(&path, name, topic);
        for i in 0..9 {
            assert!(
                (p[i] - from_log[i]).abs() < 1e-6,
                "{name}: {p:?} against the log's {from_log:?}"
            );
        }
    }
    // The site mapped from the rosbags-written bag is the log's, in the
    // bag's frame (the robot's first pose): the same poses, moved by the
    // log's start pose.
    let site_log = tmp.path().join("site_log");
    let o = twindrive(&[
        "map",
        s(&sim),
        "--calibration",
        s(&log_out),
        "--out",
        s(&site_log),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let site_bag = tmp.path().join("site_bag");
    let mut args = vec!["map", "--bag", s(&rosbags), "--scan-topic", "/scan"];
    args.extend(JOINTS);
    args.extend(["--calibration", s(&log_out), "--out", s(&site_bag)]);
    let o = twindrive(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let poses = |dir: &Path| -> Vec<[f64; 3]> {
        std::fs::read_to_string(dir.join("poses.tum"))
            .unwrap()
            .lines()
            .map(|l| {
                let v: Vec<f64> = l.split(' ').map(|x| x.parse().unwrap()).collect();
                [v[1], v[2], 2.0 * v[6].atan2(v[7])]
            })
            .collect()
    };
    let (from_log, from_bag) = (poses(&site_log), poses(&site_bag));
    assert_eq!(from_log.len(), from_bag.len());
    let start = from_log[0];
    let (sn, cs) = start[2].sin_cos();
    let apart: Vec<f64> = from_log
        .iter()
        .zip(&from_bag)
        .map(|(l, b)| {
            let moved = [
                start[0] + cs * b[0] - sn * b[1],
                start[1] + sn * b[0] + cs * b[1],
            ];
            (l[0] - moved[0]).hypot(l[1] - moved[1])
        })
        .collect();
    let worst = apart.iter().copied().fold(0.0, f64::max);
    let mean = apart.iter().sum::<f64>() / apart.len() as f64;
    // The SLAM's choices are discrete (which scans become nodes, the
    // correlative search's lattice, which loops close): inputs that differ
    // in the last bit (the mount from /tf_static's quaternion) can tip one,
    // and the poses then differ by the matcher's precision, not more.
    eprintln!("the bag's map poses: mean {mean:.5} m, worst {worst:.5} m from the log's");
    assert!(
        worst < 0.02 && mean < 0.005,
        "the bag's map poses differ by {worst} m at worst, {mean} m on average"
    );
    let report = |dir: &Path| -> Value {
        serde_json::from_slice(&std::fs::read(dir.join("map_report.json")).unwrap()).unwrap()
    };
    let (a, b) = (report(&site_log), report(&site_bag));
    let occupied = |v: &Value| v["occupied_cells"].as_f64().unwrap();
    // The two grids lie in frames turned by the log's start heading: a
    // wall square to one runs slantwise across the other's cells, which
    // rasterises it into up to √2 as many; the same walls give about as
    // many cells, not exactly as many.
    assert!(
        (occupied(&a) / occupied(&b) - 1.0).abs() < 0.2,
        "{a} against {b}"
    );
    // A topic that is not a scan names the scans there are.
    let out = tmp.path().join("wrong/calib.json");
    let mut args = vec!["calibrate", "--bag", s(&bag), "--scan-topic", "/imu"];
    args.extend(JOINTS);
    args.extend(["--initial", NOMINAL, "--out", s(&out)]);
    let o = twindrive(&args);
    assert!(!o.status.success() && !out.exists());
    let err = text(&o.stderr);
    assert!(
        err.contains("/lidar") && err.contains("sensor_msgs/msg/Imu"),
        "{err}"
    );
    // Without a pose or a scan topic the command says what it needs.
    let mut args = vec!["calibrate", "--bag", s(&bag)];
    args.extend(JOINTS);
    let o = twindrive(&args);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
}
