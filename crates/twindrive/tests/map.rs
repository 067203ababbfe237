//! `twindrive map` end to end: a drive's log and its self-calibration into
//! a ROS map_server map and a site the twin runs on; the same inputs give
//! the same bytes; bad input is a clear error and writes nothing.

mod common;

use std::path::Path;

use common::{repo, text, twindrive};

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
        "site.toml",
        "poses.tum",
        "map_report.json",
    ] {
        assert!(site.join(f).is_file(), "{f}");
    }
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
    for f in ["map.pgm", "map.yaml", "poses.tum", "map_report.json"] {
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
    assert!(err.contains("side_ir (1 beams)"), "{err}");
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
}
