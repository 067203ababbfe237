//! `twindrive experiment`: the latency experiment end to end on a reduced
//! grid, and the upload experiment in smoke mode.

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

fn twindrive() -> Command {
    Command::new(env!("CARGO_BIN_EXE_twindrive"))
}

/// `results.csv` as one map per row, by column name.
fn read_csv(path: &Path) -> Vec<HashMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    lines
        .map(|l| {
            header
                .iter()
                .cloned()
                .zip(l.split(',').map(String::from))
                .collect()
        })
        .collect()
}

/// Runs `twindrive experiment ARGS --out DIR`, which must succeed, and
/// reads the `results.csv` it wrote.
fn results(args: &[&str], dir: &Path) -> Vec<HashMap<String, String>> {
    let out = twindrive()
        .arg("experiment")
        .args(args)
        .arg("--out")
        .arg(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    read_csv(&dir.join("results.csv"))
}

fn num(row: &HashMap<String, String>, column: &str) -> f64 {
    row[column]
        .parse()
        .unwrap_or_else(|_| panic!("{column} = {:?}", row[column]))
}

#[test]
fn the_latency_experiment_fills_every_cell_and_decoupled_operation_never_collides() {
    let dir = tempfile::tempdir().unwrap();
    let rows = results(
        &[
            "latency",
            "--latencies",
            "0,2",
            "--losses",
            "0,0.1",
            "--seeds",
            "1",
            "--max-duration",
            "900",
        ],
        dir.path(),
    );
    let methods = [
        "direct (a) hold-last",
        "direct (b) watchdog",
        "direct (c) move-and-wait",
        "decoupled",
    ];
    assert_eq!(rows.len(), methods.len() * 2 * 2);
    let find = |method: &str, latency: f64, loss: f64| {
        rows.iter()
            .find(|r| {
                r["method"] == method && num(r, "latency_s") == latency && num(r, "loss") == loss
            })
            .unwrap_or_else(|| panic!("no row for {method} at {latency} s, loss {loss}"))
    };
    for loss in [0.0, 0.1] {
        for latency in [0.0, 2.0] {
            for m in methods {
                find(m, latency, loss);
            }
            // Decoupled: no contact at all, the mission completed and the
            // route covered, whatever the link.
            let d = find("decoupled", latency, loss);
            assert_eq!(d["completed"], "true", "{d:?}");
            assert_eq!(num(d, "collisions"), 0.0, "{d:?}");
            assert_eq!(num(d, "bumps"), 0.0, "{d:?}");
            assert!(num(d, "coverage_percent") > 95.0, "{d:?}");
            assert!(num(d, "bytes_up") > 100_000.0, "the plan went up: {d:?}");
        }
        // Direct (a): the same controller, delayed, runs into walls more.
        let contacts = |latency: f64| {
            let r = find("direct (a) hold-last", latency, loss);
            num(r, "collisions") + num(r, "bumps")
        };
        assert!(
            contacts(2.0) > contacts(0.0),
            "loss {loss}: {} contacts at 2 s against {} at 0 s",
            contacts(2.0),
            contacts(0.0)
        );
        // Move-and-wait completes, but pays a round trip per move.
        let mw = |latency: f64| {
            num(
                find("direct (c) move-and-wait", latency, loss),
                "completion_s",
            )
        };
        assert!(
            mw(2.0) > 3.0 * mw(0.0),
            "{} s against {} s",
            mw(2.0),
            mw(0.0)
        );
    }
    let md = std::fs::read_to_string(dir.path().join("results.md")).unwrap();
    assert!(md.contains("Completion time (s), loss 10 %"), "{md}");
    for f in [
        "completion_time.svg",
        "completion_time.png",
        "collisions.svg",
        "paths.png",
    ] {
        assert!(dir.path().join(f).is_file(), "{f} missing");
    }
}

#[test]
fn the_latency_experiment_refuses_a_bad_grid_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = twindrive()
        .args(["experiment", "latency", "--latencies", "0,fast", "--out"])
        .arg(dir.path().join("x"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--latencies") && err.contains("fast"), "{err}");
    assert!(!dir.path().join("x").exists(), "nothing written");
}

#[test]
fn the_upload_experiment_completes_every_row() {
    let dir = tempfile::tempdir().unwrap();
    let out = twindrive()
        .args(["experiment", "upload", "--smoke", "--seeds", "1", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows = read_csv(&dir.path().join("results.csv"));
    assert_eq!(rows.len(), 4 * 4, "four profiles, four losses");
    for r in &rows {
        assert!(num(r, "mean_time_s") > 0.0, "{r:?}");
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("60 s outage"), "{stdout}");
}

#[test]
fn a_fleet_of_three_robot_processes_completes_through_a_router_with_every_log_back() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = twindrive()
        .args([
            "experiment",
            "fleet",
            "--robots",
            "3",
            "--time-scale",
            "4",
            // Each robot's two logs (~1.8 MB each) home in seconds, not
            // the minutes the default budget takes.
            "--telemetry-budget",
            "200000",
            "--timeout",
            "400",
            "--cost",
            "1,2",
            "--out",
        ])
        .arg(dir.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Bounded: the experiment's own master gives up after --timeout.
    let started = std::time::Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if started.elapsed() > std::time::Duration::from_secs(600) {
            let _ = child.kill();
            panic!("the fleet experiment did not end within 600 s");
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
    };
    let mut err = String::new();
    use std::io::Read;
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    assert!(status.success(), "{err}");
    let results: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("results.json")).unwrap()).unwrap();
    let run = &results["fleet"][0];
    // On failure, the robots' journals say where each log got to.
    let journals = || -> String {
        ["r001", "r002", "r003"]
            .iter()
            .map(|id| {
                let j = std::fs::read_to_string(
                    dir.path()
                        .join("runs/n3/robots")
                        .join(id)
                        .join("journal.jsonl"),
                )
                .unwrap_or_default();
                let events: Vec<String> = j
                    .lines()
                    .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
                    .filter(|v| v["event"] != "upload_progress")
                    .map(|v| format!("{:.1} {}", v["t"].as_f64().unwrap_or(0.0), v["event"]))
                    .collect();
                format!("{id}: {}", events.join(", "))
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(run["robots"], 3);
    assert_eq!(run["completed"], 3, "{run}");
    // Each robot handed back once (its site's kinematics are not the
    // twin's) and ran a continuation: two logs each, all back-filled.
    assert!(run["handbacks"].as_u64().unwrap() >= 3, "{run}");
    assert_eq!(
        run["logs_expected"],
        run["logs_backfilled"],
        "{run}\n{}\nmaster: {err}",
        journals()
    );
    assert!(run["logs_backfilled"].as_u64().unwrap() >= 6, "{run}");
    assert!(run["master_cpu_s"].as_f64().unwrap() > 0.0, "{run}");
    assert!(
        run["handback_reaction_max_s"].as_f64().unwrap() < 5.0,
        "{run}"
    );
    // Every robot's plan ran to its end on the robot.
    for id in ["r001", "r002", "r003"] {
        let journal = std::fs::read_to_string(
            dir.path()
                .join("runs/n3/robots")
                .join(id)
                .join("journal.jsonl"),
        )
        .unwrap();
        assert!(
            journal.contains("\"execution_finished\""),
            "{id}: {journal}"
        );
    }
    let cost = results["master_cost"].as_array().unwrap();
    assert_eq!(cost.len(), 2);
    assert!(cost[1]["messages"].as_u64().unwrap() > cost[0]["messages"].as_u64().unwrap());
}

/// The kinematic-mismatch experiment on two random errors of up to 3 %
/// (random signs per seed), no tracker: the lidar robot localizing
/// against the plan's map completes with no hand-back and stays within
/// 5 cm of its plan, where dead reckoning hands back; localizing, with or
/// without the box the twin lacks, it never touches what the twin knew.
/// With the box, a robot whose plan gives it no corridor hands back before
/// it; one with the twin's corridor goes around it with no hand-back and
/// no contact, finishing within 15 % of the time it takes without the box.
#[test]
fn the_mismatch_experiment_keeps_a_localizing_lidar_robot_on_its_plan() {
    let dir = tempfile::tempdir().unwrap();
    let errors = format!(
        "{:.4},{:.4}",
        0.01 + 0.02 * (std::process::id() % 97) as f64 / 97.0,
        0.005 + 0.015 * (std::process::id() % 89) as f64 / 89.0
    );
    let rows = results(
        &[
            "mismatch",
            "--errors",
            &errors,
            "--sensors",
            "lidar",
            "--autonomy",
            "handback,detour",
            "--seeds",
            "1",
        ],
        dir.path(),
    );
    assert_eq!(rows.len(), 2 * 2 * 2 * 2, "{rows:?}");
    for r in &rows {
        if r["localization"] == "true" {
            assert_eq!(num(r, "contacts_known"), 0.0, "{r:?}");
        }
        if r["obstacle"] == "false" && r["localization"] == "true" {
            assert_eq!(r["completed"], "true", "{r:?}");
            assert_eq!(num(r, "handbacks"), 0.0, "{r:?}");
            assert!(num(r, "path_error_max_m") < 0.05, "{r:?}");
        }
        if r["obstacle"] == "false" && r["localization"] == "false" {
            assert!(num(r, "handbacks") >= 1.0, "{r:?}");
        }
        // The box the twin lacks: seen on the path ahead and never
        // touched, learnt, gone around.
        if r["obstacle"] == "true" && r["localization"] == "true" {
            assert_eq!(num(r, "contacts_unknown"), 0.0, "{r:?}");
            assert_eq!(r["completed"], "true", "{r:?}");
            if r["autonomy"] == "handback" {
                assert!(num(r, "handbacks") <= 2.0, "{r:?}");
                assert!(r["handback_reasons"].starts_with("obstacle_ahead"), "{r:?}");
            } else {
                assert_eq!(num(r, "handbacks"), 0.0, "{r:?}");
                // The master heard of the detour and the twin learnt the
                // box from what the robot saw, with no round trip.
                assert!(num(r, "detours") >= 1.0, "{r:?}");
                assert_eq!(r["box_learnt_from_detours"], "true", "{r:?}");
                let without = rows
                    .iter()
                    .find(|w| {
                        w["obstacle"] == "false"
                            && ["autonomy", "localization", "kinematic_error", "seed"]
                                .iter()
                                .all(|c| w[*c] == r[*c])
                    })
                    .unwrap();
                assert!(
                    num(r, "completion_s") <= 1.15 * num(without, "completion_s"),
                    "{r:?} against {without:?}"
                );
            }
        }
    }
}
