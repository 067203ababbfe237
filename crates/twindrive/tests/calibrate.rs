//! `twindrive calibrate` end to end: simulator logs, generic CSVs with an
//! unknown clock offset, the degenerate-drive warning and bad input.

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{SIM_NOISE, TRUTH, repo, text, twindrive};

fn simulate(scenario: &Path, out: &Path, duration: &str) {
    let o = twindrive(&[
        "simulate",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--duration-s",
        duration,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
}

fn calibrate(args: &[&str]) -> (Output, Option<serde_json::Value>, PathBuf) {
    let out = args
        .iter()
        .position(|a| *a == "--out")
        .map(|i| PathBuf::from(args[i + 1]))
        .unwrap();
    let mut all = vec!["calibrate"];
    all.extend_from_slice(args);
    let o = twindrive(&all);
    let json = std::fs::read(&out)
        .ok()
        .map(|b| serde_json::from_slice(&b).unwrap());
    (o, json, out)
}

fn params(v: &serde_json::Value) -> [f64; 3] {
    ["left_diameter_m", "right_diameter_m", "wheelbase_m"].map(|k| v[k].as_f64().unwrap())
}

#[test]
fn a_simulated_log_directory_is_calibrated() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    simulate(
        &repo().join("scenarios/calibration_drive.toml"),
        &sim,
        "130",
    );
    let out = tmp.path().join("res/calib.json");
    let mut args = vec![sim.to_str().unwrap(), "--out", out.to_str().unwrap()];
    args.extend_from_slice(&SIM_NOISE);
    let (o, json, _) = calibrate(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let j = json.unwrap();
    let p = params(&j);
    for i in 0..3 {
        assert!((p[i] / TRUTH[i] - 1.0).abs() < 1e-3, "{p:?}");
    }
    assert_eq!(j["method"], "smoother");
    assert_eq!(j["identifiability"]["well_determined"], true);
    assert!(
        j["cross_check"]["max_relative_difference"]
            .as_f64()
            .unwrap()
            < 1e-3
    );
    assert!(j["wheelbase_std_m"].as_f64().unwrap() > 0.0);
    // The log carries the true pose, so pose NEES is reported.
    let nees = j["residuals"]["pose_nees_mean"].as_f64().unwrap();
    let inside = j["residuals"]["pose_nees_inside_95_fraction"]
        .as_f64()
        .unwrap();
    assert!(
        nees.is_finite() && nees > 0.0 && (0.0..=1.0).contains(&inside),
        "pose NEES {nees}, {inside}"
    );
    let dir = tmp.path().join("res");
    for f in [
        "calib_left_diameter.svg",
        "calib_right_diameter.png",
        "calib_wheelbase.svg",
        "calib_innovations.png",
        "calib_reference.tum",
        "calib_dead_reckoning_initial.tum",
        "calib_dead_reckoning_calibrated.tum",
    ] {
        assert!(dir.join(f).is_file(), "missing {f}");
    }
    // The calibrated dead reckoning ends nearer the reference than the initial one.
    let last = |f: &str| -> (f64, f64) {
        let t = std::fs::read_to_string(dir.join(f)).unwrap();
        let v: Vec<f64> = t
            .lines()
            .last()
            .unwrap()
            .split(' ')
            .map(|x| x.parse().unwrap())
            .collect();
        (v[1], v[2])
    };
    let (r, i, c) = (
        last("calib_reference.tum"),
        last("calib_dead_reckoning_initial.tum"),
        last("calib_dead_reckoning_calibrated.tum"),
    );
    let d = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).hypot(a.1 - b.1);
    assert!(
        d(c, r) * 10.0 < d(i, r),
        "calibrated {} vs initial {}",
        d(c, r),
        d(i, r)
    );
}

/// Writes the log's encoders (ticks, or wheel speeds) and tracker poses as
/// generic CSVs, the encoder clock shifted by `shift` seconds.
fn export_csv(sim: &Path, dir: &Path, shift: f64, speeds: bool) -> (PathBuf, PathBuf) {
    let log = twindrive_log::read_log_dir(sim).unwrap();
    let mut enc = String::from(if speeds {
        "t,left_rad_s,right_rad_s\n"
    } else {
        "t,left_ticks,right_ticks\n"
    });
    let mut pose = String::from("t,x,y,theta\n");
    for s in &log.steps {
        if speeds {
            enc.push_str(&format!(
                "{},{},{}\n",
                s.t_s() - shift,
                s.wheel_rad_s[0],
                -s.wheel_rad_s[1]
            ));
        } else if let Some([l, r]) = s.encoder_ticks {
            enc.push_str(&format!("{},{l},{}\n", s.t_s() - shift, -r));
        }
        if let Some(p) = s.tracker {
            pose.push_str(&format!(
                "{},{},{},{}\n",
                s.t_s(),
                p.x_m,
                p.y_m,
                p.heading_rad
            ));
        }
    }
    let (e, p) = (dir.join("enc.csv"), dir.join("pose.csv"));
    std::fs::write(&e, enc).unwrap();
    std::fs::write(&p, pose).unwrap();
    (e, p)
}

#[test]
fn generic_csvs_with_an_unknown_clock_offset_and_a_backwards_counter() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    simulate(
        &repo().join("scenarios/calibration_drive.toml"),
        &sim,
        "130",
    );
    for speeds in [false, true] {
        let (e, p) = export_csv(&sim, tmp.path(), 1234.5, speeds);
        let out = tmp.path().join("calib.json");
        let mut args = vec![
            "--encoders",
            e.to_str().unwrap(),
            "--poses",
            p.to_str().unwrap(),
            "--initial",
            "0.066,0.066,0.26",
            "--right-sign",
            "-1",
            "--time-offset",
            "auto",
            "--out",
            out.to_str().unwrap(),
        ];
        if !speeds {
            args.extend_from_slice(&["--ticks-per-rev", "512"]);
        }
        args.extend_from_slice(&SIM_NOISE);
        let (o, json, _) = calibrate(&args);
        assert!(o.status.success(), "{}", text(&o.stderr));
        let j = json.unwrap();
        assert!(
            (j["clock_offset_s"].as_f64().unwrap() - 1234.5).abs() < 0.02,
            "{}",
            j["clock_offset_s"]
        );
        assert_eq!(j["clock_offset_source"], "auto");
        let p = params(&j);
        for i in 0..3 {
            assert!(
                (p[i] / TRUTH[i] - 1.0).abs() < 2e-3,
                "speeds {speeds}: {p:?}"
            );
        }
    }
}

#[test]
fn a_single_circle_is_refused_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let text_in = std::fs::read_to_string(repo().join("scenarios/calibration_drive.toml")).unwrap();
    let start = text_in.find("segments = [").unwrap();
    let one = format!(
        "{}segments = [{{ duration_s = 60.0, left_rad_s = 6.0, right_rad_s = 4.0 }}]\n",
        &text_in[..start]
    );
    let scenario = tmp.path().join("circle.toml");
    std::fs::write(&scenario, one).unwrap();
    let sim = tmp.path().join("sim");
    simulate(&scenario, &sim, "60");
    let out = tmp.path().join("out/calib.json");
    let mut args = vec![sim.to_str().unwrap(), "--out", out.to_str().unwrap()];
    args.extend_from_slice(&SIM_NOISE);
    let (o, json, _) = calibrate(&args);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stderr));
    let stderr = text(&o.stderr);
    assert!(
        stderr.contains("calibration refused, nothing written")
            && stderr.contains("cannot separate the parameters")
            && stderr.contains("reference poses accepted"),
        "{stderr}"
    );
    assert!(json.is_none());
    assert!(!tmp.path().join("out").exists(), "nothing is written");
}

/// An AMCL-like reference (2 Hz, 5 cm of error) is refused either way, for
/// the reason that holds: calibrated as if it were a 2 mm tracker, the gate
/// rejects most poses; with its real noise stated, the poses are accepted
/// but do not pin the wheels' scale. Nothing is written.
#[test]
fn a_sparse_noisy_reference_is_refused_for_the_right_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    simulate(
        &repo().join("scenarios/calibration_drive.toml"),
        &sim,
        "130",
    );
    // Every 60th tracker sample (the tracker runs at 120 Hz), with noise
    // from a fixed-seed generator.
    let log = std::fs::read_to_string(sim.join("log.csv")).unwrap();
    let mut rows = log.lines();
    let head: Vec<&str> = rows.next().unwrap().split(',').collect();
    let col = |n: &str| head.iter().position(|h| *h == n).unwrap();
    let (t, x, y, th) = (
        col("t"),
        col("tracker_x"),
        col("tracker_y"),
        col("tracker_theta"),
    );
    let (l, r) = (col("left_ticks"), col("right_ticks"));
    let mut enc = String::from("t,left_ticks,right_ticks\n");
    let mut poses = String::from("t,x,y,theta\n");
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut noise = |scale: f64| {
        // xorshift, then a sum of uniforms: roughly normal, deterministic.
        let mut sum = 0.0;
        for _ in 0..12 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            sum += (seed >> 11) as f64 / (1u64 << 53) as f64;
        }
        (sum - 6.0) * scale
    };
    let mut k = 0;
    for row in rows {
        let v: Vec<&str> = row.split(',').collect();
        if !v[l].is_empty() {
            enc.push_str(&format!("{},{},{}\n", v[t], v[l], v[r]));
        }
        if !v[x].is_empty() {
            if k % 60 == 0 {
                let f = |i: usize| v[i].parse::<f64>().unwrap();
                poses.push_str(&format!(
                    "{},{},{},{}\n",
                    v[t],
                    f(x) + noise(0.05),
                    f(y) + noise(0.05),
                    f(th) + noise(0.05)
                ));
            }
            k += 1;
        }
    }
    let (e, p) = (tmp.path().join("enc.csv"), tmp.path().join("amcl.csv"));
    std::fs::write(&e, enc).unwrap();
    std::fs::write(&p, poses).unwrap();
    let ticks = std::fs::read_to_string(sim.join("log.meta.json")).unwrap();
    let ticks: serde_json::Value = serde_json::from_str(&ticks).unwrap();
    let ticks = ticks["ticks_per_rev"].to_string();
    // Calibrates with the reference's stated noise; checks the refusal
    // (exit 1, nothing written) and returns what it said.
    let refused = |name: &str, position_std_m: &str, heading_std_rad: &str| {
        let out = tmp.path().join(name).join("calib.json");
        let (e, p, out_s) = (
            e.display().to_string(),
            p.display().to_string(),
            out.display().to_string(),
        );
        let args = [
            "--encoders",
            &e,
            "--poses",
            &p,
            "--ticks-per-rev",
            &ticks,
            "--initial",
            "0.07,0.07,0.23",
            "--out",
            &out_s,
            "--position-std-m",
            position_std_m,
            "--heading-std-rad",
            heading_std_rad,
        ];
        let (o, json, _) = calibrate(&args);
        assert_eq!(o.status.code(), Some(1), "{}", text(&o.stdout));
        assert!(json.is_none() && !tmp.path().join(name).exists());
        text(&o.stderr)
    };
    let stderr = refused("tight", "0.002", "0.005");
    assert!(
        stderr.contains("calibration refused, nothing written")
            && stderr.contains("the filter's gate rejected"),
        "{stderr}"
    );
    let stderr = refused("stated", "0.05", "0.05");
    assert!(
        stderr.contains("does not pin every parameter")
            && !stderr.contains("gate rejected")
            && stderr.contains(", 0 rejected ("),
        "{stderr}"
    );
}

/// Runs calibrate on hand-written CSVs and checks the clean failure (exit 1).
fn rejected(enc: &str, pose: &str, extra: &[&str], expect: &[&str]) {
    rejected_with(1, enc, pose, extra, expect);
}

/// Runs calibrate on hand-written CSVs and checks the clean failure with
/// exit status `code` (2: a usage error).
fn rejected_with(code: i32, enc: &str, pose: &str, extra: &[&str], expect: &[&str]) {
    let tmp = tempfile::tempdir().unwrap();
    let (e, p) = (tmp.path().join("enc.csv"), tmp.path().join("pose.csv"));
    std::fs::write(&e, enc).unwrap();
    std::fs::write(&p, pose).unwrap();
    let out = tmp.path().join("calib.json");
    let mut args = vec![
        "--encoders",
        e.to_str().unwrap(),
        "--poses",
        p.to_str().unwrap(),
        "--ticks-per-rev",
        "512",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    if !extra.contains(&"--initial") {
        args.extend_from_slice(&["--initial", "0.066,0.066,0.26"]);
    }
    let (o, json, _) = calibrate(&args);
    let stderr = text(&o.stderr);
    assert_eq!(o.status.code(), Some(code), "{stderr}");
    for x in expect {
        assert!(stderr.contains(x), "expected `{x}` in {stderr}");
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(json.is_none(), "an output file was written");
    let left: Vec<String> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left.len(), 2, "{left:?}");
}

fn good_encoders() -> String {
    let mut s = String::from("t,left_ticks,right_ticks\n");
    for k in 0..500 {
        s.push_str(&format!("{},{},{}\n", k as f64 * 0.02, k * 3, k * 4));
    }
    s
}

fn good_poses() -> String {
    let mut s = String::from("t,x,y,theta\n");
    for k in 0..500 {
        s.push_str(&format!("{},{},0,0\n", k as f64 * 0.02, k as f64 * 0.001));
    }
    s
}

#[test]
fn bad_inputs_fail_cleanly() {
    let (enc, pose) = (good_encoders(), good_poses());
    rejected(
        &enc.replace("\n0.04,6,8\n", "\n0.02,6,8\n"),
        &pose,
        &[],
        &["enc.csv, line 4, column `t`: duplicate timestamp 0.02 (also on line 3)"],
    );
    rejected(
        &enc.replace("\n0.04,6,8\n", "\n0.01,6,8\n"),
        &pose,
        &[],
        &["enc.csv, line 4, column `t`: time 0.01 goes back"],
    );
    rejected(
        &enc,
        &pose.replace("\n0.04,0.002,0,0\n", "\n0.04,NaN,0,0\n"),
        &[],
        &["pose.csv, line 4, column `x`: expected a finite number, found `NaN`"],
    );
    rejected(
        &enc.replace("\n0.04,6,8\n", "\n0.04,six,8\n"),
        &pose,
        &[],
        &["enc.csv, line 4, column `left_ticks`: expected an integer tick count, found `six`"],
    );
    rejected(
        &enc.replace("right_ticks", "rite_ticks"),
        &pose,
        &[],
        &["enc.csv, line 1: missing column `right_ticks`"],
    );
    rejected("", &pose, &[], &["enc.csv: is empty"]);
    rejected(&enc, "", &[], &["pose.csv: is empty"]);
    rejected(
        &enc,
        &pose,
        &["--time-offset", "1000"],
        &["do not overlap in time", "--time-offset auto"],
    );
    rejected_with(
        2,
        &enc,
        &pose,
        &["--initial", "0.066,-0.066,0.26"],
        &["--initial: the right diameter must be a finite number > 0"],
    );
    rejected_with(
        2,
        &enc,
        &pose,
        &["--initial", "0.066,0.066"],
        &["--initial: expected three numbers DL,DR,B"],
    );
    rejected_with(
        2,
        &enc,
        &pose,
        &["--left-sign", "2"],
        &["--left-sign <LEFT_SIGN>': 1 or -1, got 2"],
    );
}

#[test]
fn a_log_with_a_lidar_and_no_tracker_self_calibrates_with_the_lidar_mount() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    simulate(
        &repo().join("scenarios/self_calibration_drive.toml"),
        &sim,
        "120",
    );
    let out = tmp.path().join("res/calib.json");
    // No --reference: the log has a lidar and no tracker, so its scans are
    // used; the mount guess says nothing of the true one.
    let (o, json, _) = calibrate(&[
        sim.to_str().unwrap(),
        "--mount",
        "0,0,0",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let j = json.unwrap();
    assert_eq!(j["reference"], "scans");
    let truth = [0.0652, 0.0671, 0.2655];
    let p = params(&j);
    for i in 0..3 {
        assert!((p[i] / truth[i] - 1.0).abs() < 0.003, "{p:?}");
    }
    let m = &j["lidar_mount"];
    let (x, y, h) = (
        m["x_m"].as_f64().unwrap(),
        m["y_m"].as_f64().unwrap(),
        m["heading_rad"].as_f64().unwrap(),
    );
    assert!(
        (x + 0.03).hypot(y - 0.02) < 0.01 && (h - 0.4).abs() < 0.5f64.to_radians(),
        "{m}"
    );
    assert!(j["lidar_mount_std"]["x_m"].as_f64().unwrap() > 0.0);
    assert_eq!(j["lidar_mount_guess_source"], "--mount");
    let g = &j["gyro"];
    assert!(
        (g["bias_rad_s"].as_f64().unwrap() - 0.004).abs() < 0.001,
        "{g}"
    );
    assert!(
        (g["scale_error"].as_f64().unwrap() - 0.01).abs() < 0.002,
        "{g}"
    );
    let stdout = text(&o.stdout);
    assert!(stdout.contains("lidar mount"), "{stdout}");
    for f in [
        "calib_laser_residuals.svg",
        "calib_laser_residuals.png",
        "calib_dead_reckoning_calibrated.tum",
    ] {
        assert!(tmp.path().join("res").join(f).is_file(), "{f}");
    }
    // Asking for the poses the log does not have is an error, not a guess.
    let out2 = tmp.path().join("res2/calib.json");
    let (o, json, _) = calibrate(&[
        sim.to_str().unwrap(),
        "--reference",
        "poses",
        "--out",
        out2.to_str().unwrap(),
    ]);
    assert!(!o.status.success() && json.is_none());
    assert!(
        text(&o.stderr).contains("no samples"),
        "{}",
        text(&o.stderr)
    );
    // A sensor the log does not have is named with those it has.
    let (o, _, _) = calibrate(&[
        sim.to_str().unwrap(),
        "--reference",
        "scans",
        "--scan-sensor",
        "laser",
        "--out",
        out2.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("lidar (a lidar of 360 beams)"),
        "{}",
        text(&o.stderr)
    );
}
