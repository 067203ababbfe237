//! `twindrive map` end to end: a drive's log and its self-calibration into
//! a ROS map_server map and a site the twin runs on; the same inputs give
//! the same bytes; bad input is a clear error and writes nothing.

mod common;

use std::path::Path;

use common::{repo, text, twindrive, twindrive_in};

fn run(args: &[&str]) -> std::process::Output {
    twindrive(args)
}

fn simulate(scenario: &Path, out: &Path, duration: &str) {
    let o = run(&[
        "simulate",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--duration-s",
        duration,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
}

/// A calibration with the drive's true wheels and mount, as a
/// self-calibration within its tolerance would give them.
fn calibration(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("calib.json");
    std::fs::write(
        &path,
        r#"{"left_diameter_m": 0.0652, "right_diameter_m": 0.0671, "wheelbase_m": 0.2655,
            "lidar": "lidar", "lidar_mount": {"x_m": -0.03, "y_m": 0.02, "heading_rad": 0.4}}"#,
    )
    .unwrap();
    path
}

#[test]
fn a_drive_is_mapped_into_a_site_the_twin_runs_on() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    simulate(
        &repo().join("scenarios/self_calibration_drive.toml"),
        &sim,
        "40",
    );
    let cal = calibration(tmp.path());
    let site = tmp.path().join("site");
    let map = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "map",
            sim.to_str().unwrap(),
            "--calibration",
            cal.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let o = map(&site, &[]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let stdout = text(&o.stdout);
    assert!(stdout.contains("matched to the map"), "{stdout}");
    for f in [
        "map.pgm",
        "map.yaml",
        "map.png",
        "site.toml",
        "poses.tum",
        "map_report.json",
    ] {
        assert!(site.join(f).is_file(), "{f}");
    }
    picture_shows_the_map(&site);
    let yaml = std::fs::read_to_string(site.join("map.yaml")).unwrap();
    assert!(
        yaml.contains("image: map.pgm") && yaml.contains("resolution: 0.05"),
        "{yaml}"
    );
    let pgm = std::fs::read(site.join("map.pgm")).unwrap();
    assert!(pgm.starts_with(b"P5\n"));
    // Free (254 at most), occupied (0 at least) and unknown (205) cells.
    assert!(pgm.contains(&205), "no unknown pixel");
    assert!(pgm.iter().any(|v| *v >= 206) && pgm.iter().skip(15).any(|v| *v <= 89));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(site.join("map_report.json")).unwrap()).unwrap();
    let scans = report["scans"].as_u64().unwrap();
    assert!(scans >= 350, "{report}");
    assert!(
        report["scans_matched"].as_u64().unwrap() * 100 >= scans * 95,
        "{report}"
    );
    for k in ["free_cells", "occupied_cells", "unknown_cells"] {
        assert!(report[k].as_u64().unwrap() > 0, "{k}: {report}");
    }
    // The site is a scenario on the map: the twin runs on it.
    let toml = std::fs::read_to_string(site.join("site.toml")).unwrap();
    assert!(toml.contains("map = \"map.yaml\""), "{toml}");
    let o = run(&[
        "simulate",
        site.join("site.toml").to_str().unwrap(),
        "--out",
        tmp.path().join("on_map").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    // Same inputs, same bytes (the site's name is its directory's).
    let again = tmp.path().join("again");
    assert!(map(&again, &[]).status.success());
    for f in [
        "map.pgm",
        "map.yaml",
        "map.png",
        "poses.tum",
        "map_report.json",
    ] {
        assert!(
            std::fs::read(site.join(f)).unwrap() == std::fs::read(again.join(f)).unwrap(),
            "{f} differs"
        );
    }
    assert_eq!(
        std::fs::read_to_string(again.join("site.toml"))
            .unwrap()
            .replace("name = \"again\"", "name = \"site\""),
        toml
    );
    // A mission moved onto the map: its commands file comes along.
    let with_mission = tmp.path().join("mission");
    let o = map(
        &with_mission,
        &[
            "--mission",
            repo().join("scenarios/office_drive.toml").to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(with_mission.join("office_drive_commands.csv").is_file());
    let toml = std::fs::read_to_string(with_mission.join("site.toml")).unwrap();
    assert!(toml.contains("office_drive_on_mission"), "{toml}");
    assert!(toml.contains("left_diameter_m = 0.0652"), "{toml}");
}

#[test]
fn bad_input_is_a_clear_error_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let cal = calibration(tmp.path());
    // A log without a lidar.
    let sim = tmp.path().join("sim");
    simulate(&repo().join("scenarios/wall_following.toml"), &sim, "5");
    let out = tmp.path().join("site");
    let o = run(&[
        "map",
        sim.to_str().unwrap(),
        "--calibration",
        cal.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = text(&o.stderr);
    assert!(
        err.contains("no lidar to match scan to scan; its range sensors: side_ir (a ranger)"),
        "{err}"
    );
    assert!(!out.exists());
    // A calibration that is not one names the file.
    let bad = tmp.path().join("bad.json");
    std::fs::write(&bad, "{\"wheelbase_m\": 0.26}").unwrap();
    let o = run(&[
        "map",
        sim.to_str().unwrap(),
        "--calibration",
        bad.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o.stderr).contains("bad.json"), "{}", text(&o.stderr));
    // Usage errors exit 2.
    let o = run(&["map", sim.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    let o = run(&[
        "map",
        "--calibration",
        cal.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(!out.exists());
    // A master keeps maps only of a site on a map, given with --scenario.
    let maps = tmp.path().join("maps");
    let keys = tmp.path().join("keys");
    for extra in [&[][..], &["--robot", "rover"]] {
        let mut args = vec!["keygen", "--out", keys.to_str().unwrap()];
        args.extend_from_slice(extra);
        assert!(run(&args).status.success());
    }
    let key = keys.join("master.key");
    let robot_key = keys.join("rover.pub");
    let master = |extra: &[&str]| {
        let mut args = vec![
            "master",
            "--plan",
            "plan.json",
            "--key",
            key.to_str().unwrap(),
            "--trust-robot",
            robot_key.to_str().unwrap(),
            "--robot",
            "rover",
            "--out",
            out.to_str().unwrap(),
            "--site-maps",
            maps.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let o = master(&[]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(
        text(&o.stderr).contains("--scenario"),
        "{}",
        text(&o.stderr)
    );
    let hand_drawn = repo().join("scenarios/wall_following.toml");
    let o = master(&["--scenario", hand_drawn.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stderr));
    assert!(
        text(&o.stderr).contains("has no map"),
        "{}",
        text(&o.stderr)
    );
    assert!(!maps.exists() && !out.exists());
}

/// The mission of the process test below: the self-calibration drive's
/// room and robot, spinning, then one arc.
fn short_drive() -> String {
    let text =
        std::fs::read_to_string(repo().join("scenarios/self_calibration_drive.toml")).unwrap();
    let controller = text.find("[controller]").unwrap();
    text[..controller].replacen("duration_s = 120.0", "duration_s = 18.0", 1)
        + "[controller]\nkind = \"scripted\"\nsegments = [\n  \
           { duration_s = 8.0, left_rad_s = -1.5, right_rad_s = 1.5 },\n  \
           { duration_s = 10.0, left_rad_s = 8.0, right_rad_s = 5.5 },\n]\n"
}

/// `twindrive master --site-maps`: the twin's map is drawn from a first
/// look while a partition hid half the room; a mission planned on it runs
/// on the robot (`twindrive robot`, the room without the partition), and
/// its log extends the map into version 1 (the far side known, the
/// partition cleared); the next mission's twin runs on version 1 and
/// makes version 2.
#[test]
fn the_master_keeps_the_twins_map_of_the_site_across_missions() {
    use common::{Proc, finish, port};
    use std::process::{Command, Stdio};
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let mission = short_drive();
    std::fs::write(d.join("mission.toml"), &mission).unwrap();
    // The first look: standing still (the boxes hide what is behind them).
    let look = mission.replacen("duration_s = 18.0", "duration_s = 3.0", 1);
    std::fs::write(d.join("look.toml"), look).unwrap();
    simulate(&d.join("look.toml"), &d.join("look"), "3");
    let cal = calibration(d);
    let site = d.join("site");
    let o = run(&[
        "map",
        &s(&d.join("look")),
        "--calibration",
        &s(&cal),
        "--mission",
        &s(&d.join("mission.toml")),
        "--resolution-m",
        "0.025",
        "--out",
        &s(&site),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    // The mission rehearsed on the twin and planned; keys.
    simulate(&site.join("site.toml"), &d.join("rehearsal"), "18");
    let plan = d.join("plan/plan.json");
    let o = run(&[
        "plan",
        &s(&d.join("rehearsal")),
        "--calibration",
        &s(&cal),
        "--scenario",
        &s(&site.join("site.toml")),
        "--out",
        &s(&plan),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let o = run(&["keygen", "--out", &s(&d.join("keys"))]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let o = run(&["keygen", "--out", &s(&d.join("keys")), "--robot", "rover"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    // The robot's site: the room, under the name the twin knows it by (a
    // robot refuses a plan for another site), its lidar without dropouts
    // (the robot's range check counts a dropped return as a discrepancy).
    let name = "self_calibration_drive_on_site";
    std::fs::write(
        d.join("true.toml"),
        mission
            .replacen(
                "name = \"self_calibration_drive\"",
                &format!("name = \"{name}\""),
                1,
            )
            .replacen("dropout_probability = 0.01", "dropout_probability = 0.0", 1),
    )
    .unwrap();

    // A robot at the mission's start, its own state, on its own port.
    let robot = |state: &str| {
        let robot_port = port();
        let p = Proc(
            Command::new(env!("CARGO_BIN_EXE_twindrive"))
                .args([
                    "robot",
                    "--id",
                    "rover",
                    "--site",
                    &s(&d.join("true.toml")),
                    "--trust",
                    &s(&d.join("keys/master.pub")),
                    "--key",
                    &s(&d.join("keys/rover.key")),
                    "--state-dir",
                    &s(&d.join(state)),
                    "--listen",
                    &format!("tcp/127.0.0.1:{robot_port}"),
                    "--time-scale",
                    "4",
                    "--telemetry-budget",
                    "1000000",
                    "--run-for",
                    "240",
                ])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap(),
        );
        (p, robot_port)
    };
    let maps = d.join("maps");
    let master = |out: &str, robot_port: u16| {
        let stdout = d.join(format!("{out}.stdout"));
        let p = Proc(
            Command::new(env!("CARGO_BIN_EXE_twindrive"))
                .args([
                    "master",
                    "--plan",
                    &s(&plan),
                    "--key",
                    &s(&d.join("keys/master.key")),
                    "--trust-robot",
                    &s(&d.join("keys/rover.pub")),
                    "--robot",
                    "rover",
                    "--connect",
                    &format!("tcp/127.0.0.1:{robot_port}"),
                    "--out",
                    &s(&d.join(out)),
                    "--scenario",
                    &s(&site.join("site.toml")),
                    "--site-maps",
                    &s(&maps),
                    "--telemetry-budget",
                    "1000000",
                    "--timeout",
                    "120",
                    "--log-wait",
                    "60",
                ])
                .stdout(std::fs::File::create(&stdout).unwrap())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        );
        let (code, err) = finish(p, 180.0);
        let said = std::fs::read_to_string(&stdout).unwrap();
        assert_eq!(code, Some(0), "{said}\n{err}");
        (said, err)
    };
    let update = |version: &str| -> serde_json::Value {
        let dir = maps.join(name).join(version);
        for f in ["site.toml", "map.yaml", "map.pgm"] {
            assert!(dir.join(f).is_file(), "{}", dir.join(f).display());
        }
        serde_json::from_slice(&std::fs::read(dir.join("update.json")).unwrap()).unwrap()
    };

    let (first_robot, robot_port) = robot("robot1");
    let (said, err) = master("first", robot_port);
    drop(first_robot);
    assert!(err.contains("no map of site"), "{err}");
    assert!(said.contains(&format!("site `{name}` version 1")), "{said}");
    let first = update("0001");
    assert_eq!(first["previous"], serde_json::Value::Null);
    assert_eq!(first["logs"][0]["drawn"], true, "{first}");
    let known = |u: &serde_json::Value, k: &str| {
        u[k]["free"].as_u64().unwrap() + u[k]["occupied"].as_u64().unwrap()
    };
    // It matched the map, and what the boxes hid from the first look is
    // known now.
    let log = &first["logs"][0];
    assert!(
        log["scans_matched"].as_u64().unwrap() * 20 >= log["scans"].as_u64().unwrap() * 19,
        "{first}"
    );
    assert!(
        known(&first, "cells_after") > known(&first, "cells_before") + 200,
        "{first}"
    );
    assert!(
        first["changes"]["unknown_to_occupied"].as_u64().unwrap() > 50,
        "{first}"
    );

    // The next mission, by a robot back at the start.
    let (_second_robot, robot_port) = robot("robot2");
    let (said, err) = master("second", robot_port);
    assert!(err.contains("(version 1)"), "{err}");
    assert!(said.contains(&format!("site `{name}` version 2")), "{said}");
    let second = update("0002");
    assert_eq!(second["previous"], 1);
    // Version 1 was the twin: it knew the room already.
    assert_eq!(known(&second, "cells_before"), known(&first, "cells_after"));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("second/report.json")).unwrap()).unwrap();
    assert_eq!(report["outcome"], "completed", "{report}");
}

/// The poses of a `poses.tum`: `(t_s, x_m, y_m)` per line.
fn tum(path: &Path) -> Vec<(f64, f64, f64)> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<f64> = l
                .split_whitespace()
                .take(3)
                .map(|x| x.parse().unwrap())
                .collect();
            (v[0], v[1], v[2])
        })
        .collect()
}

/// A real robot's recording with only `/odom`, `/tf` and `/scan` (a Neato
/// on a building's first floor, `../shared/data/rosbag2_recordings/`): it
/// is mapped from the robot's odometry with no calibration, from its
/// Odometry topic and from TF alike. Nearly every scan matches the map, the
/// matches' residual is the lidar's centimetre, and the two mappings put
/// the robot at the same places. Without a motion source it is a usage
/// error that writes nothing.
#[test]
fn a_real_recording_with_odometry_and_no_wheel_joints_is_mapped() {
    let bag =
        repo().join("../shared/data/rosbag2_recordings/comprobo22_neato_macfirst_floor_take_2");
    let bag = bag.to_str().unwrap();
    let dir = tempfile::tempdir().unwrap();
    // The bag mapped from `topic`'s odometry into `out`, with `more` flags.
    let map_from = |topic: &str, more: &[&str], out: &Path| {
        let mut args = vec![
            "map",
            "--bag",
            bag,
            "--scan-topic",
            "/scan",
            "--odom-topic",
            topic,
            "--wheel-diameter-m",
            "0.07",
            "--wheelbase-m",
            "0.24",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(more);
        run(&args)
    };
    let mut tracks = Vec::new();
    for topic in ["/odom", "/tf"] {
        let out = dir.path().join(topic.trim_start_matches('/'));
        let o = map_from(topic, &[], &out);
        assert!(o.status.success(), "{topic}: {}", text(&o.stderr));
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("map_report.json")).unwrap()).unwrap();
        let scans = report["scans"].as_f64().unwrap();
        assert!(scans > 300.0, "{report}");
        assert!(
            report["scans_matched"].as_f64().unwrap() >= 0.95 * scans,
            "{report}"
        );
        let noise = report["range_noise_m"].as_f64().unwrap();
        assert!(noise < 0.03, "{topic}: residual {noise} m");
        let occupied = report["occupied_cells"].as_f64().unwrap();
        assert!(occupied > 500.0, "{report}");
        tracks.push(tum(&out.join("poses.tum")));
    }
    // The same drive through two topics: at every time both mapped, within
    // a few centimetres of each other. Each pose is stamped with its scan's
    // header time, on the bag's clock (its recording ran 1663967375.5 to
    // 1663967421.8, Unix time).
    let (a, b) = (&tracks[0], &tracks[1]);
    for track in [a, b] {
        assert!(
            track
                .iter()
                .all(|p| (1_663_967_375.5..1_663_967_421.8).contains(&p.0))
        );
    }
    let mut compared = 0;
    for &(t, x, y) in a {
        if let Some(&(_, u, v)) = b.iter().find(|p| (p.0 - t).abs() < 1e-6) {
            assert!(
                (x - u).hypot(y - v) < 0.15,
                "at {t} s: ({x}, {y}) and ({u}, {v})"
            );
            compared += 1;
        }
    }
    assert!(compared > 300, "{compared} poses at common times");
    // A robot too wide to stand where the drive started starts further on;
    // one too wide for anywhere still gets its map, and is told what to
    // change.
    for (radius, fits) in [("0.8", true), ("3", false)] {
        let out = dir.path().join(format!("wide{radius}"));
        let o = map_from("/odom", &["--footprint-radius-m", radius], &out);
        let err = text(&o.stderr);
        for kept in [
            "map.pgm",
            "map.yaml",
            "map.png",
            "poses.tum",
            "map_report.json",
        ] {
            assert!(out.join(kept).exists(), "{radius}: {kept}: {err}");
        }
        assert!(!err.contains(".twindrive-staging"), "{err}");
        if fits {
            assert!(o.status.success(), "{err}");
            let site = twindrive_sim::Scenario::load(&out.join("site.toml")).unwrap();
            let s = site.robot.start;
            assert!(s.x_m.hypot(s.y_m) > 0.2, "{s:?}");
            assert!(err.contains("starts it at"), "{err}");
        } else {
            assert_eq!(o.status.code(), Some(1), "{err}");
            assert!(!out.join("site.toml").exists());
            assert!(
                err.contains("--footprint-radius-m") && err.contains("map is written"),
                "{err}"
            );
        }
    }
    // No motion named (with or without a calibration).
    let calib = calibration(dir.path());
    for (args, says) in [
        (
            vec!["--wheel-diameter-m", "0.07", "--wheelbase-m", "0.24"],
            "--odom-topic",
        ),
        (
            vec!["--calibration", calib.to_str().unwrap()],
            "--odom-topic",
        ),
    ] {
        let out = dir.path().join("refused");
        let mut all = vec!["map", "--bag", bag, "--scan-topic", "/scan"];
        all.extend(args);
        all.extend(["--out", out.to_str().unwrap()]);
        let o = run(&all);
        assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
        assert!(text(&o.stderr).contains(says), "{}", text(&o.stderr));
        assert!(!out.exists());
    }
}

/// A real robot that publishes its wheels' speeds as two
/// `std_msgs/msg/Float64` topics and has a 360° lidar and no odometry
/// (`challenge_handin_esc_wheel_vel_db3` in
/// `../shared/data/rosbag2_recordings/`, 23.7 s, one motor mounted
/// mirrored). `bag info` names the two topics and the mirrored one; its
/// suggested self-calibration finds a wheelbase within 3 % of the 0.67 m
/// the robot's own controller configuration publishes (nothing here knew
/// it), and the bag maps from the calibration and from the nominal wheels
/// alike. Wheels with no size to turn angles into metres are a usage
/// error that writes nothing.
#[test]
fn a_real_robot_that_publishes_its_wheel_speeds_is_calibrated_and_mapped() {
    let bag = repo().join("../shared/data/rosbag2_recordings/challenge_handin_esc_wheel_vel_db3");
    let bag = bag.to_str().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let info = run(&["bag", "info", bag]);
    let out = text(&info.stdout);
    assert!(info.status.success(), "{}", text(&info.stderr));
    let wheels = "--left-speed-topic /actuators/esc/wheel_velocity_axis0 \
                  --right-speed-topic /actuators/esc/wheel_velocity_axis1 --right-sign -1";
    assert!(out.contains(wheels), "{out}");
    // The suggested self-calibration, with the nominal wheels as the guess.
    let line = out
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with("twindrive calibrate"))
        .unwrap_or_else(|| panic!("no calibrate line: {out}"));
    let calib = dir.path().join("calib.json");
    let args: Vec<String> = line
        .split_whitespace()
        .skip(1)
        .map(|w| match w {
            "DL,DR,B" => "0.27,0.27,0.67".to_string(),
            "calib.json" => calib.to_str().unwrap().to_string(),
            w => w.to_string(),
        })
        .collect();
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = run(&args);
    assert!(o.status.success(), "{line}: {}", text(&o.stderr));
    let c: serde_json::Value = serde_json::from_slice(&std::fs::read(&calib).unwrap()).unwrap();
    let get = |k: &str| c[k].as_f64().unwrap();
    let b = get("wheelbase_m");
    assert!((b - 0.67).abs() < 0.03 * 0.67, "wheelbase {b} m");
    let (dl, dr) = (get("left_diameter_m"), get("right_diameter_m"));
    assert!((dl - dr).abs() < 0.03 * dl, "diameters {dl} {dr}");
    let wheel_flags: Vec<&str> = wheels.split_whitespace().collect();
    let map = |size: &[&str], out: &Path| {
        let mut args = vec!["map", "--bag", bag, "--scan-topic", "/sensors/scan"];
        args.extend(&wheel_flags);
        args.extend(size);
        args.extend(["--out", out.to_str().unwrap()]);
        run(&args)
    };
    let nominal = ["--wheel-diameter-m", "0.27", "--wheelbase-m", "0.67"];
    for (size, name) in [
        (vec!["--calibration", calib.to_str().unwrap()], "calibrated"),
        (nominal.to_vec(), "nominal"),
    ] {
        let out = dir.path().join(name);
        let o = map(&size, &out);
        assert!(o.status.success(), "{name}: {}", text(&o.stderr));
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("map_report.json")).unwrap()).unwrap();
        let scans = report["scans"].as_f64().unwrap();
        assert!(scans > 200.0, "{report}");
        assert!(
            report["scans_matched"].as_f64().unwrap() >= 0.95 * scans,
            "{name}: {report}"
        );
        let noise = report["range_noise_m"].as_f64().unwrap();
        assert!(noise < 0.03, "{name}: residual {noise} m");
        // Stamped on the bag's clock (recorded 1650902101.4 to 1650902125.1).
        let poses = tum(&out.join("poses.tum"));
        assert!(poses.len() as f64 == scans, "{}", poses.len());
        assert!(
            poses
                .iter()
                .all(|p| (1_650_902_101.3..1_650_902_125.2).contains(&p.0))
        );
    }
    let refused = dir.path().join("refused");
    let o = map(&[], &refused);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    assert!(
        err.contains("--wheel-diameter-m")
            && err.contains(
                "the bag records no /robot_description (the robot's URDF) to read them from"
            ),
        "{err}"
    );
    assert!(!refused.exists());
}

/// `(t_s, [x_m, y_m, heading_rad])` of a TUM file, through the library.
fn tum_track(path: &Path) -> Vec<(f64, [f64; 3])> {
    twindrive_log::read_tum(path)
        .unwrap()
        .into_iter()
        .map(|(t, p)| {
            (
                twindrive_log::seconds_from_ns(t),
                [p.x_m, p.y_m, p.heading_rad],
            )
        })
        .collect()
}

/// A CARMEN log of the public 2D SLAM benchmark (Freiburg building 079,
/// `../shared/data/slam2d_benchmark/`, Kümmerle et al. 2009) is mapped as
/// it is: its first two minutes, from the robot's ODOM lines. (Not MIT
/// CSAIL: nearly half its relations reproduce the logged odometry's
/// translation, see its SOURCE.md.) Every relation inside that window finds its two
/// poses in poses.tum (stamped with the scans' ipc_timestamp), and the
/// map's poses are closer to the relations than the raw odometry, in
/// translation and in rotation. `twindrive relations` scores poses.tum as
/// the library does. A broken log line is an error naming its file, line
/// and field, and writes nothing.
#[test]
fn a_carmen_log_is_mapped_and_scored_on_the_benchmarks_relations() {
    use twindrive_estimation::relations;
    let dir = repo().join("../shared/data/slam2d_benchmark/fr079");
    if !dir.is_dir() {
        eprintln!("SKIPPED: ../shared/data/slam2d_benchmark is absent");
        return;
    }
    let log_path = dir.join("fr079.rebuilt.clf.gz");
    let relations_path = dir.join("fr079.relations");
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("site");
    let window_s = 120.0;
    let o = run(&[
        "map",
        "--carmen",
        log_path.to_str().unwrap(),
        "--until-s",
        &window_s.to_string(),
        "--wheel-diameter-m",
        "0.2",
        "--wheelbase-m",
        "0.4",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let log = twindrive_log::carmen::CarmenLog::read(&log_path).unwrap();
    let (start_s, end_s) = (log.lasers[0].t_s, log.lasers[0].t_s + window_s);
    let all =
        relations::parse_relations(&std::fs::read_to_string(&relations_path).unwrap()).unwrap();
    let inside: Vec<_> = all
        .iter()
        .copied()
        .filter(|r| {
            [r.t1_s, r.t2_s]
                .iter()
                .all(|t| (start_s..=end_s).contains(t))
        })
        .collect();
    assert!(
        inside.len() > 100,
        "{} relations in the window",
        inside.len()
    );
    let mapped = tum_track(&out.join("poses.tum"));
    assert!(
        mapped
            .iter()
            .all(|(t, _)| (start_s - 1e-3..=end_s + 1e-3).contains(t)),
        "poses.tum runs past the window"
    );
    let ours = relations::score(&inside, &mapped);
    assert_eq!(
        ours.matched,
        inside.len(),
        "relations matched in the window"
    );
    let odometry: Vec<(f64, [f64; 3])> = log
        .odometry_at_lasers()
        .into_iter()
        .map(|(t, p)| (t, [p.x_m, p.y_m, p.heading_rad]))
        .collect();
    let raw = relations::score(&inside, &odometry);
    let (ours, raw) = (ours.errors.unwrap(), raw.errors.unwrap());
    assert!(
        ours.abs_trans_m.mean < raw.abs_trans_m.mean,
        "mapped translational error {:.4} m is not below the raw odometry's {:.4} m on the {} relations",
        ours.abs_trans_m.mean,
        raw.abs_trans_m.mean,
        inside.len()
    );
    assert!(
        ours.abs_rot_deg.mean < raw.abs_rot_deg.mean,
        "mapped rotational error {:.3} deg is not below the raw odometry's {:.3} deg on the {} relations",
        ours.abs_rot_deg.mean,
        raw.abs_rot_deg.mean,
        inside.len()
    );
    // Cartographer's published means on the whole of fr079 (Hess et al.
    // 2016, Table II; ../shared/data/slam2d_benchmark/PUBLISHED.md).
    assert!(
        ours.abs_trans_m.mean <= 0.0452 && ours.abs_rot_deg.mean <= 0.538,
        "mapped {:.4} m, {:.3} deg: above Cartographer's 0.0452 m, 0.538 deg",
        ours.abs_trans_m.mean,
        ours.abs_rot_deg.mean
    );
    // The command scores all the set's relations: those of the window
    // match, and their errors are the library's.
    let o = run(&[
        "relations",
        "--relations",
        relations_path.to_str().unwrap(),
        out.join("poses.tum").to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let whole = relations::score(&all, &mapped);
    assert_eq!(json["relations"].as_u64(), Some(all.len() as u64), "{json}");
    assert_eq!(
        json["matched"].as_u64(),
        Some(whole.matched as u64),
        "{json}"
    );
    assert!(whole.matched >= inside.len());
    let mean = json["errors"]["abs_trans_m"]["mean"].as_f64().unwrap();
    assert!((mean - whole.errors.unwrap().abs_trans_m.mean).abs() < 1e-12);
    let o = run(&[
        "relations",
        "--relations",
        relations_path.to_str().unwrap(),
        out.join("poses.tum").to_str().unwrap(),
    ]);
    let stdout = text(&o.stdout);
    assert!(
        stdout.contains(&format!(
            "relations matched: {} of {}",
            whole.matched,
            all.len()
        )) && stdout.contains("absolute translational error: "),
        "{stdout}"
    );
    // Bad input: a log line cut short, a relations line with a word.
    let bad = tmp.path().join("bad.clf");
    std::fs::write(&bad, "# c\nODOM 0 0 0 0 0 0 1 h 1\nFLASER 3 1 2\n").unwrap();
    let bad_out = tmp.path().join("bad_site");
    let o = run(&[
        "map",
        "--carmen",
        bad.to_str().unwrap(),
        "--wheel-diameter-m",
        "0.2",
        "--wheelbase-m",
        "0.4",
        "--out",
        bad_out.to_str().unwrap(),
    ]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("bad.clf, line 3, column `range 3`: the line ends"),
        "{err}"
    );
    assert!(!bad_out.exists());
    let bad_rel = tmp.path().join("bad.relations");
    std::fs::write(&bad_rel, "1 2 0 0 0 0 0 0\n1 2 0 0 0 0 zero 0\n").unwrap();
    let o = run(&[
        "relations",
        "--relations",
        bad_rel.to_str().unwrap(),
        out.join("poses.tum").to_str().unwrap(),
    ]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("bad.relations") && err.contains("line 2: `pitch`: `zero`"),
        "{err}"
    );
}

/// `map.png` in `site` is a PNG of `map.pgm`'s cells: each a square of
/// whole pixels (as many as keep the longer side within 1200, 1 to 8),
/// in the PGM's grey where nothing is drawn over it, with the drive's
/// path and its ends drawn in colour.
fn picture_shows_the_map(site: &Path) {
    let pgm = std::fs::read(site.join("map.pgm")).unwrap();
    let head = String::from_utf8_lossy(&pgm[..pgm.len().min(40)]).into_owned();
    let mut fields = head.split_ascii_whitespace();
    assert_eq!(fields.next(), Some("P5"));
    let w: usize = fields.next().unwrap().parse().unwrap();
    let h: usize = fields.next().unwrap().parse().unwrap();
    assert!(
        w.max(h) <= 4000,
        "{w} x {h}: shrunk pictures are not checked here"
    );
    let greys = &pgm[pgm.len() - w * h..];
    let png = image::open(site.join("map.png")).unwrap();
    assert_eq!(
        image::ImageFormat::from_path(site.join("map.png")).unwrap(),
        image::ImageFormat::Png
    );
    let png = png.to_rgb8();
    let zoom = (1200 / w.max(h)).clamp(1, 8);
    assert_eq!(
        (png.width() as usize, png.height() as usize),
        (w * zoom, h * zoom),
        "a map of {w} x {h} cells"
    );
    let (mut same, mut coloured, mut cells) = (0, 0, 0);
    for row in 0..h {
        for col in 0..w {
            let p = png.get_pixel(
                (col * zoom + zoom / 2) as u32,
                (row * zoom + zoom / 2) as u32,
            );
            cells += 1;
            if p.0 == [greys[row * w + col]; 3] {
                same += 1;
            } else if p.0[0] != p.0[1] || p.0[1] != p.0[2] {
                coloured += 1;
            }
        }
    }
    assert!(
        same * 100 >= cells * 95,
        "{same} of {cells} cells in the map's grey"
    );
    assert!(
        coloured > 20 && same + coloured == cells,
        "{coloured} coloured cells of {cells}"
    );
}

/// The Neato's recording keeps the robot's URDF on /robot_description:
/// mapped with the plain command line and no wheel flag, the twin's robot
/// takes its wheels from it, and the terminal says so. (The URDF is a
/// TurtleBot 4's, on an iRobot Create 3 base: the wheels are within 1 %
/// of the 0.03575 m radius and 0.233 m separation the Create 3's own
/// drive controller is configured with, iRobotEducation/create3_sim
/// irobot_create_control/config/control.yaml; not the Neato's.) Flags
/// still win, one by one.
#[test]
fn a_recordings_robot_description_gives_the_site_its_wheels() {
    let bag =
        repo().join("../shared/data/rosbag2_recordings/comprobo22_neato_macfirst_floor_take_2");
    if !bag.exists() {
        eprintln!("SKIPPED: ../shared/data/rosbag2_recordings is absent");
        return;
    }
    let bag = bag.canonicalize().unwrap();
    let bag = bag.to_str().unwrap();
    let dir = tempfile::tempdir().unwrap();
    // `bag info` names the description and suggests the plain command line.
    let info = twindrive(&["bag", "info", bag]);
    assert!(info.status.success(), "{}", text(&info.stderr));
    let said = text(&info.stdout);
    assert!(
        said.contains("robot description: wheels from /robot_description (robot `turtlebot4`)")
            && said.contains(&format!(
                "twindrive map --bag {bag} --scan-topic /scan --odom-topic /odom --out site"
            )),
        "{said}"
    );
    // The literal command, in a fresh directory.
    let literal = [
        "map",
        "--bag",
        bag,
        "--scan-topic",
        "/scan",
        "--odom-topic",
        "/odom",
        "--out",
        "site",
    ];
    let o = twindrive_in(&literal, dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    let stdout = text(&o.stdout);
    let line = stdout
        .lines()
        .find(|l| l.starts_with("wheels from /robot_description (robot `turtlebot4`): diameter "))
        .unwrap_or_else(|| panic!("not said where the wheels came from: {stdout}"));
    assert!(
        line.ends_with("(joints left_wheel_joint, right_wheel_joint)"),
        "{line}"
    );
    // "diameter L m / R m, wheelbase B m": the numbers said.
    let said: Vec<f64> = line
        .split([' ', ','])
        .filter_map(|w| w.parse().ok())
        .collect();
    let [left, right, base] = said[..] else {
        panic!("{line}")
    };
    let site = dir.path().join("site");
    assert!(site.join("site.toml").is_file() && site.join("map.png").is_file());
    picture_shows_the_map(&site);
    let scenario = twindrive_sim::Scenario::load(&site.join("site.toml")).unwrap();
    for p in [scenario.robot.true_params, scenario.robot.nominal_params] {
        assert!(
            (p.left_diameter_m - left).abs() < 1e-4
                && (p.right_diameter_m - right).abs() < 1e-4
                && (p.wheelbase_m - base).abs() < 1e-4,
            "{p:?} against {line}"
        );
    }
    assert!((left / 0.0715 - 1.0).abs() < 0.01 && (right / 0.0715 - 1.0).abs() < 0.01);
    assert!((base / 0.233 - 1.0).abs() < 0.01, "{base}");
    // A flag wins over its part of the description.
    let o = twindrive_in(
        &[
            &literal[..7],
            &["--wheelbase-m", "0.248", "--out", "site_b"],
        ]
        .concat(),
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stdout).contains("--wheelbase-m 0.248 given"));
    let p = twindrive_sim::Scenario::load(&dir.path().join("site_b/site.toml"))
        .unwrap()
        .robot
        .true_params;
    assert!(
        p.wheelbase_m == 0.248 && (p.left_diameter_m - left).abs() < 1e-4,
        "{p:?}"
    );
    // Both flags: the description is not read.
    let o = twindrive_in(
        &[
            &literal[..7],
            &[
                "--wheel-diameter-m",
                "0.07",
                "--wheelbase-m",
                "0.248",
                "--out",
                "site_c",
            ],
        ]
        .concat(),
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        !text(&o.stdout).contains("wheels from"),
        "{}",
        text(&o.stdout)
    );
}

/// A recording whose description cannot give the wheels: the refusal says
/// what the URDF lacks, and the flags that give them; nothing is written.
#[test]
fn a_description_without_wheels_is_refused_with_what_it_lacks() {
    use twindrive_ros::msgs::StringMsg;
    use twindrive_ros::{BagWriter, Distro, Qos};
    let dir = tempfile::tempdir().unwrap();
    for (name, urdf, says) in [
        (
            "bare",
            "<robot name=\"bare\"><link name=\"base_link\"/></robot>",
            "robot `bare` has no continuous or revolute joint",
        ),
        (
            "meshes",
            "<robot name=\"m\"><link name=\"base_link\"/><link name=\"w\"><visual><geometry>\
             <mesh filename=\"w.dae\"/></geometry></visual></link>\
             <joint name=\"wj\" type=\"continuous\"><parent link=\"base_link\"/><child link=\"w\"/>\
             <origin xyz=\"0 0.1 0\" rpy=\"-1.5708 0 0\"/><axis xyz=\"0 0 1\"/></joint></robot>",
            "wj (link `w` has no <cylinder> about its axis)",
        ),
        ("broken", "<robot name=\"b\"><link>", "not well-formed XML"),
    ] {
        let path = dir.path().join(name);
        std::fs::create_dir(&path).unwrap();
        let mut w = BagWriter::sqlite3(&path.join("b_0.db3"), "b_0.db3", Distro::Humble).unwrap();
        let topic = w
            .topic::<StringMsg>("/robot_description", Qos::LATCHED)
            .unwrap();
        w.write(
            topic,
            1_700_000_000_000_000_000,
            &StringMsg { data: urdf.into() },
        )
        .unwrap();
        let metadata = w.finish().unwrap();
        std::fs::write(path.join("metadata.yaml"), metadata).unwrap();
        let out = dir.path().join(format!("{name}_site"));
        let o = twindrive(&[
            "map",
            "--bag",
            path.to_str().unwrap(),
            "--scan-topic",
            "/scan",
            "--odom-topic",
            "/odom",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(2), "{name}: {}", text(&o.stderr));
        let err = text(&o.stderr);
        assert!(
            err.contains("--wheel-diameter-m and --wheelbase-m")
                && err.contains("the bag's /robot_description gives no wheels")
                && err.contains(says),
            "{name}: {err}"
        );
        assert!(!out.exists());
    }
}

/// A drive exported by `twindrive rosbag` carries the robot's URDF (the
/// nominal wheels): self-calibrating it needs no --initial, mapping it
/// from its wheel joints no wheel flag, and each says where the wheels
/// came from.
#[test]
fn an_exported_drive_calibrates_and_maps_from_its_description() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = repo().join("scenarios/self_calibration_drive.toml");
    let sim = tmp.path().join("sim");
    simulate(&scenario, &sim, "60");
    let bag = tmp.path().join("bag");
    let o = run(&[
        "rosbag",
        sim.to_str().unwrap(),
        "--out",
        bag.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let nominal = twindrive_sim::Scenario::load(&scenario)
        .unwrap()
        .robot
        .nominal_params;
    let said = format!(
        "diameter {:.4} m / {:.4} m, wheelbase {:.4} m (joints wheel_left_joint, wheel_right_joint)",
        nominal.left_diameter_m, nominal.right_diameter_m, nominal.wheelbase_m
    );
    let info = text(&run(&["bag", "info", bag.to_str().unwrap()]).stdout);
    let line = info
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with("twindrive calibrate") && l.contains("--scan-topic"))
        .unwrap_or_else(|| panic!("no self-calibration line: {info}"));
    assert!(
        !line.contains("--initial") && info.contains(&said),
        "{info}"
    );
    let calib = tmp.path().join("cal/calib.json");
    let joints = [
        "--left-joint",
        "wheel_left_joint",
        "--right-joint",
        "wheel_right_joint",
    ];
    let site = tmp.path().join("site");
    // calibrate and map alike take the wheels from the description.
    for (command, out) in [("calibrate", &calib), ("map", &site)] {
        let mut args = vec![
            command,
            "--bag",
            bag.to_str().unwrap(),
            "--scan-topic",
            "/lidar",
        ];
        args.extend(joints);
        args.extend(["--out", out.to_str().unwrap()]);
        let o = run(&args);
        assert!(o.status.success(), "{command}: {}", text(&o.stderr));
        assert!(
            text(&o.stdout).contains(&said),
            "{command}: {}",
            text(&o.stdout)
        );
    }
    let robot = twindrive_sim::Scenario::load(&site.join("site.toml"))
        .unwrap()
        .robot;
    assert_eq!(robot.true_params, nominal);
    picture_shows_the_map(&site);
}
