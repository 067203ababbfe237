//! The `twindrive` binary end to end: outputs, determinism and bad input.

mod common;

use std::path::Path;
use std::process::Output;

use common::{repo, text, twindrive_in as twindrive};

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
    // Decoupled operation: the box the twin lacked is handed back, learnt,
    // and the continuation completes; the robot's plans are the master's.
    let d = tmp.path().join("twindrive-out/decoupled");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["outcome"], "completed", "{report}");
    assert!(!report["handbacks"].as_array().unwrap().is_empty());
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
    let robot_logs = report["robot_logs"].as_array().unwrap();
    assert!(!robot_logs.is_empty());
    for l in robot_logs {
        assert!(d.join(l.as_str().unwrap()).join("log.csv").is_file());
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
    ] {
        assert!(links.contains(&f), "report.md leaves out {f}");
    }
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
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out.stderr).contains("--duration-s must be a finite number > 0"));
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
