//! The `twindrive` binary end to end: outputs, determinism and bad input.

mod common;

use std::path::Path;
use std::process::Output;

use common::{repo, text, twindrive_in as twindrive};
use twindrive_mission::detour::distance_to_block;

fn files(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

fn simulate(scenario: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "simulate",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    twindrive(&args, &repo())
}

#[test]
fn simulate_writes_every_artefact_and_is_deterministic() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = repo().join("scenarios/wall_following.toml");
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    for dir in [&a, &b] {
        let out = simulate(&scenario, dir, &["--duration-s", "40"]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        assert!(text(&out.stdout).contains("bump episode"));
    }
    let names = files(&a);
    for want in [
        "log.csv",
        "log.meta.json",
        "log.mcap",
        "ground_truth.tum",
        "summary.json",
        "path.svg",
        "path.png",
        "wheel_speeds.svg",
        "wheel_speeds.png",
        "side_ir.svg",
        "side_ir.png",
    ] {
        assert!(
            names.iter().any(|n| n == want),
            "missing {want} in {names:?}"
        );
    }
    for name in &names {
        assert_eq!(
            std::fs::read(a.join(name)).unwrap(),
            std::fs::read(b.join(name)).unwrap(),
            "{name} differs between runs"
        );
    }
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(a.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["duration_s"], 40.0);
    assert!(summary["distance_m"].as_f64().unwrap() > 5.0);
    assert!(summary["bumps"].as_u64().unwrap() >= 2);
    assert!(summary["min_clearance_m"].as_f64().unwrap() >= 0.0);
    // The TUM file has one pose per step.
    let tum = std::fs::read_to_string(a.join("ground_truth.tum")).unwrap();
    assert_eq!(tum.lines().count(), 4000);

    // Another seed changes the noise, hence the log.
    let c = tmp.path().join("c");
    assert!(
        simulate(&scenario, &c, &["--duration-s", "40", "--seed", "3"])
            .status
            .success()
    );
    assert_ne!(
        std::fs::read(a.join("log.csv")).unwrap(),
        std::fs::read(c.join("log.csv")).unwrap()
    );
}

#[test]
fn existing_output_directory_keeps_other_files() {
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    std::fs::write(out_dir.join("notes.txt"), "mine").unwrap();
    let out = simulate(
        &repo().join("scenarios/office_drive.toml"),
        &out_dir,
        &["--duration-s", "5"],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(
        std::fs::read_to_string(out_dir.join("notes.txt")).unwrap(),
        "mine"
    );
    assert!(out_dir.join("log.mcap").is_file());
    // No staging directory is left behind.
    assert_eq!(files(tmp.path()), vec!["out".to_string()]);
}

#[test]
fn demo_runs_from_any_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let out = twindrive(&["demo"], tmp.path());
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("twindrive-out/wall_following"), "{stdout}");
    assert!(
        tmp.path()
            .join("twindrive-out/wall_following/path.png")
            .is_file()
    );
    // Decoupled operation: the box the twin lacked is handed back and
    // learnt, the continuations go around it and the mission completes, with
    // every hand-back the box's doing and every robot log home; the robot's
    // plans are the master's.
    let d = tmp.path().join("twindrive-out/decoupled");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["outcome"], "completed", "{report}");
    assert_eq!(
        report["robot_logs"].as_array().unwrap().len(),
        report["uploads"].as_array().unwrap().len(),
        "{report}"
    );
    let handbacks = report["handbacks"].as_array().unwrap();
    assert!(!handbacks.is_empty());
    for h in handbacks {
        // The box is [1.9, 2.1] x [0.9, 1.2]; its side IR sees 0.8 m at most.
        let p: Vec<f64> = serde_json::from_value(h["pose"].clone()).unwrap();
        let d = distance_to_block([p[0], p[1]], &([1.9, 0.9], [2.1, 1.2]));
        assert!(d < 0.5, "a hand-back away from the box: {h}");
    }
    assert!(
        report["twin_updates"]
            .as_array()
            .unwrap()
            .iter()
            .any(|u| !u["obstacles_added"].as_array().unwrap().is_empty())
    );
    for f in ["twin.svg", "timeline.svg", "robot_journal.jsonl"] {
        assert!(d.join(f).is_file(), "{f}");
    }
    // The robot localizes against the plan's map and the twin guesses the
    // box's extent from the contact: at most two hand-backs (issue 21).
    assert!(handbacks.len() <= 2, "{} hand-backs", handbacks.len());
    let robot_logs = report["robot_logs"].as_array().unwrap();
    assert!(!robot_logs.is_empty());
    // Every contact is with the box: the robot's true footprint never
    // touches a wall the twin knew.
    let known = twindrive_sim::builtin::load("wall_following")
        .unwrap()
        .unwrap();
    let footprint = known.robot.footprint_radius_m;
    for l in robot_logs {
        let csv = std::fs::read_to_string(d.join(l.as_str().unwrap()).join("log.csv")).unwrap();
        let mut lines = csv.lines();
        let head: Vec<&str> = lines.next().unwrap().split(',').collect();
        let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
        let (x, y) = (col("gt_x"), col("gt_y"));
        for line in lines {
            let f: Vec<&str> = line.split(',').collect();
            let (px, py) = (f[x].parse::<f64>().unwrap(), f[y].parse::<f64>().unwrap());
            let clear = known.world.clearance_m(px, py, 1.0) - footprint;
            assert!(clear > 0.0, "{l}: touches a known wall at ({px}, {py})");
        }
    }
    assert!(stdout.contains("outcome Completed"), "{stdout}");

    // The report links figures that exist, as PNGs, among them the
    // calibration's and the experiment's collisions.
    let out_dir = tmp.path().join("twindrive-out");
    let md = std::fs::read_to_string(out_dir.join("report.md")).unwrap();
    let links: Vec<&str> = md
        .split("](")
        .skip(1)
        .map(|rest| &rest[..rest.find(')').unwrap()])
        .collect();
    assert!(links.len() >= 18, "{links:?}");
    for l in &links {
        assert!(l.ends_with(".png"), "{l} is not a PNG");
        assert!(
            out_dir.join(l).is_file(),
            "report.md links {l}, which is missing"
        );
    }
    for f in [
        "calibration/calib_left_diameter.png",
        "calibration/calib_right_diameter.png",
        "calibration/calib_wheelbase.png",
        "calibration/calib_innovations.png",
        "experiment/collisions.png",
        "experiment/completion_time.png",
        "decoupled/twin.png",
        "decoupled/timeline.png",
        "plan/plan_wheel_speeds.png",
        "mapped_site/map_vs_truth.png",
        "mapped_site/decoupled/twin.png",
    ] {
        assert!(links.contains(&f), "report.md leaves out {f}");
    }

    // The twin from the robot's own sensors: the hidden site's drive
    // self-calibrated, mapped into a site the twin runs on, and the plan
    // made there completed on the true site without a collision.
    let m = out_dir.join("mapped_site");
    let cal: serde_json::Value =
        serde_json::from_slice(&std::fs::read(m.join("calibration/calib.json")).unwrap()).unwrap();
    assert_eq!(cal["reference"], "scans");
    for f in ["site/map.pgm", "site/map.yaml", "site/site.toml"] {
        assert!(m.join(f).is_file(), "{f}");
    }
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(m.join("decoupled/report.json")).unwrap()).unwrap();
    assert_eq!(report["outcome"], "completed", "{report}");
    assert_eq!(report["collisions"], 0, "{report}");
    assert!(stdout.contains("of wall the lidar saw drawn"), "{stdout}");
}

/// Writes a broken variant of the wall-following scenario and checks that
/// simulate fails cleanly: non-zero exit, one message naming the file and
/// `expect` (the field), no output directory.
fn assert_rejected(edit: impl Fn(String) -> String, expect: &[&str]) {
    let tmp = tempfile::tempdir().unwrap();
    let text_in = std::fs::read_to_string(repo().join("scenarios/wall_following.toml")).unwrap();
    let edited = edit(text_in.clone());
    assert_ne!(edited, text_in, "the edit changed nothing");
    let path = tmp.path().join("broken.toml");
    std::fs::write(&path, edited).unwrap();
    let out_dir = tmp.path().join("out");
    let out = simulate(&path, &out_dir, &[]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.starts_with("error: ") && stderr.contains("broken.toml"),
        "{stderr}"
    );
    for e in expect {
        assert!(stderr.contains(e), "expected `{e}` in: {stderr}");
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!out_dir.exists(), "output directory was created");
    assert_eq!(
        files(tmp.path()),
        vec!["broken.toml".to_string()],
        "something was left behind"
    );
}

#[test]
fn bad_scenarios_fail_cleanly() {
    assert_rejected(
        |t| t.replace("seed = 2012", "seed = 2012\ncolour = \"red\""),
        &["unknown field `colour`", "line 11"],
    );
    assert_rejected(
        |t| t.replace("polylines = [", "map = \"missing.yaml\"\npolylines = ["),
        &["field `world.map`", "missing.yaml", "does not exist"],
    );
    assert_rejected(
        |t| t.replace("right_diameter_m = 0.0665", "right_diameter_m = 0.0"),
        &["field `robot.true_params.right_diameter_m` must be a finite number > 0, got 0"],
    );
    assert_rejected(
        |t| t.replace("dt_s = 0.01", "dt_s = -0.01"),
        &["field `simulation.dt_s` must be a finite number > 0"],
    );
    assert_rejected(
        |t| t.replace("x_m = 3.0, y_m = 1.05", "x_m = 3.0, y_m = 1.45"),
        &["field `robot.start`", "overlaps a wall"],
    );
}

#[test]
fn missing_scenario_file_and_bad_flags() {
    let tmp = tempfile::tempdir().unwrap();
    let out = simulate(&tmp.path().join("nope.toml"), &tmp.path().join("o"), &[]);
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out.stderr).contains("nope.toml"));
    let out = simulate(
        &repo().join("scenarios/wall_following.toml"),
        &tmp.path().join("o"),
        &["--duration-s=-1"],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("a duration > 0 s, got -1"));
    assert!(!tmp.path().join("o").exists());
    // Usage errors are clap's (exit code 2).
    assert_eq!(twindrive(&["simulate"], tmp.path()).status.code(), Some(2));
}

#[test]
fn help_lists_the_commands() {
    let out = twindrive(&["--help"], &repo());
    let help = text(&out.stdout);
    for cmd in ["simulate", "demo", "draw-map"] {
        assert!(help.contains(cmd), "{help}");
    }
}

/// Each command's --help names every kind of input it accepts (and, where
/// it has them, what it refuses and its exit statuses): a newcomer reads
/// it before the book.
#[test]
fn every_commands_help_names_each_input_it_takes() {
    // Help wraps lines; compare with white space folded.
    let help = |args: &[&str]| {
        let out = twindrive(args, &repo());
        assert!(out.status.success(), "{args:?}");
        text(&out.stdout)
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ")
    };
    let top = help(&["--help"]);
    assert!(
        top.contains("calibrate") && top.contains("self-calibration"),
        "{top}"
    );
    for (command, names) in [
        (
            &["calibrate", "--help"][..],
            &[
                "simulator output directory",
                "--encoders",
                "--poses",
                "--bag",
                "self-calibration",
                "--scan-topic",
                "--imu-topic",
            ][..],
        ),
        (
            &["map", "--help"],
            &[
                "simulator output directory",
                "--bag",
                "LaserScan",
                "JointState",
                "std_msgs/msg/Float64",
                "--left-speed-topic",
                "/odom",
                "--carmen",
                "CARMEN log",
                "read directly",
                "--until-s",
                "Not mapped",
            ],
        ),
        (
            &["relations", "--help"],
            &[
                "TUM",
                "--relations",
                "T(t1)⁻¹ T(t2)",
                "within 1 ms",
                "Exit status 1",
            ],
        ),
        (
            &["verify-plan", "--help"],
            &[
                "Exit status 0",
                "3: it failed verification",
                "2: a usage error",
            ],
        ),
        (
            &["router", "--help"],
            &[
                "--listen",
                "--zenoh-config",
                "tcp/127.0.0.1:7447",
                "listen.endpoints",
            ],
        ),
        (
            &["robot", "--help"],
            &[
                "--zenoh-config",
                "--listen",
                "--connect",
                "--connect-timeout",
                "[ros]",
            ],
        ),
        (
            &["master", "--help"],
            &["--plan", "--signed", "--zenoh-config", "--connect-timeout"],
        ),
        (&["bag", "info", "--help"], &["MCAP", "sqlite3"]),
        (&["rosbag", "--help"], &["MCAP", "sqlite3"]),
    ] {
        let text = help(command);
        for name in names {
            assert!(
                text.contains(name),
                "{command:?} --help does not say {name:?}:\n{text}"
            );
        }
    }
}

#[test]
fn draw_map_reproduces_the_shipped_map() {
    let tmp = tempfile::tempdir().unwrap();
    let out = twindrive(
        &["draw-map", tmp.path().join("maps").to_str().unwrap()],
        &repo(),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    for f in ["office.pgm", "office.yaml"] {
        assert_eq!(
            std::fs::read(tmp.path().join("maps").join(f)).unwrap(),
            std::fs::read(repo().join("scenarios/maps").join(f)).unwrap()
        );
    }
}

/// Runs `args` and checks a usage error: exit 2, a message naming `flag`
/// and `expected`, no panic, nothing written.
fn assert_usage_error(args: &[&str], flag: &str, expected: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let out = twindrive(args, tmp.path());
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
    assert!(
        stderr.contains(flag) && stderr.contains(expected),
        "{args:?}: expected `{flag}` and `{expected}` in: {stderr}"
    );
    assert!(
        !stderr.contains("unexpected argument") && !stderr.contains("panicked"),
        "{args:?}: {stderr}"
    );
    assert!(files(tmp.path()).is_empty(), "{args:?} wrote something");
}

/// The command before the flag, the flag, a bad value, what is expected,
/// the rest of the command.
type FlagCase = (
    &'static [&'static str],
    &'static str,
    &'static str,
    &'static str,
    &'static [&'static str],
);

/// `twindrive robot` with its required flags.
const ROBOT: &[&str] = &[
    "robot",
    "--id",
    "r",
    "--site",
    "s.toml",
    "--trust",
    "k",
    "--key",
    "r.key",
    "--state-dir",
    "d",
];

#[test]
fn invalid_flag_values_are_usage_errors_in_both_forms() {
    let cases: &[FlagCase] = &[
        (
            &["simulate", "s.toml"],
            "--duration-s",
            "-5",
            "a duration > 0 s, got -5",
            &["--out", "o"],
        ),
        (
            &["calibrate", "d"],
            "--batch-window-s",
            "-1",
            "a duration > 0 s",
            &[],
        ),
        (
            &["calibrate", "d"],
            "--left-sign",
            "-2",
            "1 or -1, got -2",
            &[],
        ),
        (
            &["calibrate", "d"],
            "--ticks-per-rev",
            "0",
            "ticks per revolution",
            &[],
        ),
        (
            &["prune", "p.csv"],
            "--pinch-distance",
            "-0.1",
            "a distance > 0 m",
            &["--out", "o.csv"],
        ),
        (
            &["prune", "p.csv", "--pinch-distance", "0.1"],
            "--min-loop-duration",
            "-3",
            "a duration ≥ 0 s",
            &["--out", "o.csv"],
        ),
        (
            &["sign", "p.json", "--key", "k", "--robot", "r"],
            "--supervise",
            "-1",
            "a duration > 0 s",
            &["--out", "o"],
        ),
        (
            &["sign", "p.json", "--key", "k", "--supervise", "5"],
            "--robot",
            "a/b",
            "a robot id",
            &["--out", "o"],
        ),
        (ROBOT, "--time-scale", "-2", "a time scale > 0", &[]),
        (
            ROBOT,
            "--telemetry-budget",
            "50",
            "at least 100 bytes per second",
            &[],
        ),
        (
            &[
                "master",
                "--signed",
                "x",
                "--key",
                "k",
                "--trust-robot",
                "r.pub",
                "--robot",
                "r",
                "--out",
                "o",
            ],
            "--timeout",
            "-5",
            "a duration > 0 s",
            &[],
        ),
        (
            &["rosbag", "l", "--out", "o"],
            "--start-time",
            "-1",
            "Unix seconds",
            &[],
        ),
        (
            &["experiment", "latency"],
            "--complete-at",
            "-0.5",
            "a fraction in (0, 1]",
            &[],
        ),
        (
            &["experiment", "latency"],
            "--seeds",
            "0",
            "a whole number ≥ 1",
            &[],
        ),
        (
            &["experiment", "fleet"],
            "--robots",
            "-3",
            "a fleet size from 1 to 200",
            &[],
        ),
        (
            &["experiment", "upload"],
            "--seeds",
            "-1",
            "a whole number ≥ 1",
            &[],
        ),
    ];
    for (before, flag, value, expected, after) in cases {
        let joined = format!("{flag}={value}");
        for form in [vec![*flag, *value], vec![joined.as_str()]] {
            let mut args: Vec<&str> = before.to_vec();
            args.extend(form);
            args.extend_from_slice(after);
            assert_usage_error(&args, flag, expected);
        }
    }
    // Checks clap cannot make are usage errors too.
    assert_usage_error(
        &[
            "master",
            "--signed",
            "x",
            "--key",
            "k",
            "--trust-robot",
            "a.pub",
            "--robot",
            "a",
            "--robot",
            "a",
            "--out",
            "o",
        ],
        "--robot a",
        "given twice",
    );
    assert_usage_error(
        &["experiment", "latency", "--losses", "0,-0.1"],
        "--losses",
        "losses from 0 to 0.9",
    );
    assert_usage_error(&["calibrate", "--out", "c.json"], "--encoders", "--bag");
    // A negative value that is valid is taken as a value.
    let tmp = tempfile::tempdir().unwrap();
    let out = twindrive(&["calibrate", "nope", "--left-sign", "-1"], tmp.path());
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("nope: does not exist"));
}

#[test]
fn a_missing_file_is_named_with_the_os_error_once() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let runs: &[&[&str]] = &[
        &["simulate", "nope.toml", "--out", "o"],
        &["verify-plan", "nope.json", "--out", "o"],
        &[
            "prune",
            "nope.csv",
            "--pinch-distance",
            "0.1",
            "--out",
            "o.csv",
        ],
        &[
            "calibrate",
            "--encoders",
            "nope.csv",
            "--poses",
            "nope2.csv",
            "--initial",
            "0.06,0.06,0.2",
        ],
        &["rosbag", "nope.mcap", "--out", "o"],
    ];
    for args in runs {
        let out = twindrive(args, d);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains("nope"), "{args:?}: {stderr}");
        assert_eq!(
            stderr.matches("No such file or directory").count(),
            1,
            "{args:?}: {stderr}"
        );
    }
    assert_eq!(files(d), Vec::<String>::new());
}

#[test]
fn calibrate_says_what_input_it_expects() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::create_dir(tmp.path().join("photos")).unwrap();
    std::fs::write(tmp.path().join("photos/a.jpg"), "x").unwrap();
    let out = twindrive(&["calibrate", "photos"], tmp.path());
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    for want in [
        "photos: is not a simulator log",
        "log.csv + log.meta.json from `twindrive simulate`",
        "--encoders E.csv and --poses P.csv",
        "--bag BAG (a rosbag2 directory or one .mcap/.db3 file)",
    ] {
        assert!(stderr.contains(want), "expected `{want}` in: {stderr}");
    }
    assert!(!tmp.path().join("calib.json").exists());
}

#[test]
fn a_plan_that_is_not_a_plan_is_named_as_such() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let keygen = twindrive(&["keygen", "--out", "keys"], d);
    assert!(keygen.status.success(), "{}", text(&keygen.stderr));
    std::fs::write(d.join("path.json"), "t,x,y,theta\n0,0,0,0\n").unwrap();
    std::fs::write(
        d.join("calib.json"),
        r#"{"left_diameter_m": 0.0652, "right_diameter_m": 0.0665, "wheelbase_m": 0.2678}"#,
    )
    .unwrap();
    for (file, want) in [
        (
            "path.json",
            "path.json is not a twindrive mission plan: not JSON (line 1, column 2: expected ident)",
        ),
        (
            "calib.json",
            "calib.json is not a twindrive mission plan: a JSON document, but not a twindrive mission plan (unknown field `left_diameter_m`",
        ),
    ] {
        let runs: [&[&str]; 2] = [
            &["verify-plan", file, "--out", "v"],
            &[
                "sign",
                file,
                "--key",
                "keys/master.key",
                "--robot",
                "r1",
                "--out",
                "p.signed",
            ],
        ];
        for args in runs {
            let out = twindrive(args, d);
            let stderr = text(&out.stderr);
            assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
            assert!(
                stderr.contains(want),
                "{args:?}: expected `{want}` in: {stderr}"
            );
            assert!(!stderr.contains("header.robot.scenario"), "{stderr}");
        }
    }
    assert!(!d.join("v").exists() && !d.join("p.signed").exists());
}

/// A long path that drives straight and, every 3 m, around a petal of
/// random radius on a random side and back to the line: each petal is a
/// loop whose cut would drop ground (refused), and every fourth is driven
/// twice (its second lap is removed).
fn petal_path_csv(path: &Path, petals: usize) {
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut csv = String::from("t,x,y,theta\n");
    let mut t = 0usize;
    let mut emit = |x: f64, y: f64, heading: f64| {
        csv.push_str(&format!("{},{x},{y},{heading}\n", t as f64 * 0.1));
        t += 1;
    };
    let mut x = 0.0;
    for k in 0..petals {
        for _ in 0..60 {
            emit(x, 0.0, 0.0);
            x += 0.05;
        }
        let r = 0.3 + 0.5 * next();
        let side = if next() < 0.5 { 1.0 } else { -1.0 };
        let m = (std::f64::consts::TAU * r / 0.05) as usize;
        let laps = if k % 4 == 0 { 2 } else { 1 };
        for i in 0..m * laps {
            let a = std::f64::consts::TAU * i as f64 / m as f64;
            emit(x + r * a.sin(), side * r * (1.0 - a.cos()), side * a);
        }
    }
    std::fs::write(path, csv).unwrap();
}

#[test]
fn prune_prints_a_summary_and_writes_the_details() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    petal_path_csv(&d.join("walk.csv"), 200);
    let base = [
        "prune",
        "walk.csv",
        "--pinch-distance",
        "0.1",
        "--coverage-radius",
        "0.1",
        "--out",
        "out/pruned.csv",
    ];
    let mut args = base.to_vec();
    args.extend(["--details", "out/details.txt"]);
    let out = twindrive(&args, d);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(stdout.lines().count() < 20, "{stdout}");
    let details = std::fs::read_to_string(d.join("out/details.txt")).unwrap();
    let refused = details
        .lines()
        .filter(|l| l.starts_with("refused: "))
        .count();
    let removed = details
        .lines()
        .filter(|l| l.starts_with("removed: "))
        .count();
    // Each petal driven once is refused; each second lap is removed (and
    // the last samples, a trailing retrace).
    assert_eq!(refused, 200, "{details}");
    assert_eq!(removed, 50 + 1, "{details}");
    assert!(stdout.contains("removed 50 loop(s)"), "{stdout}");
    assert_eq!(refused + removed, details.lines().count());
    assert!(
        stdout.contains(&format!("refused {refused} cut(s)")),
        "{stdout}"
    );
    assert!(stdout.contains("out/details.txt"), "{stdout}");
    assert!(d.join("out/pruned.csv").is_file());
    // -v prints the same lines after the summary.
    let mut args = base.to_vec();
    args.push("-v");
    let verbose = text(&twindrive(&args, d).stdout);
    assert!(verbose.ends_with(&details), "{verbose}");
    assert_eq!(
        verbose.lines().count(),
        stdout.lines().count() + details.lines().count()
    );
    // Without either, the summary points to them.
    let plain = text(&twindrive(&base, d).stdout);
    assert!(plain.contains("-v or --details FILE"), "{plain}");
    assert!(!plain.contains("refused: "), "{plain}");
}
