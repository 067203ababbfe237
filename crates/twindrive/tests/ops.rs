//! Decoupled operation with two real processes on loopback and zenoh in
//! between: `twindrive robot` (a simulated site, run faster than real time)
//! and `twindrive master`. Faults: an outage mid-upload, the robot killed
//! mid-upload and mid-execution, the master killed, plans the robot must
//! refuse, corrupted messages, and an obstacle the twin lacks. Every wait is
//! bounded and every child is killed by its process id.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{Proc, finish, fixture, port, repo, text, twindrive};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

struct Mission {
    tmp: tempfile::TempDir,
    port: u16,
    site: PathBuf,
    trust: PathBuf,
    time_scale: f64,
    /// The robot's and the master's --telemetry-budget (bytes/s): high by
    /// default, so a robot log comes home in a second rather than the
    /// minute the lunar default takes; a test of the back-fill itself sets
    /// the default back.
    telemetry_budget: &'static str,
}

impl Mission {
    fn new(site: &str, trust: &str, time_scale: f64) -> Self {
        let f = fixture();
        Self {
            tmp: tempfile::tempdir().unwrap(),
            port: port(),
            site: if site.is_empty() {
                repo().join("scenarios/wall_following.toml")
            } else {
                f.path(site)
            },
            trust: f.path(trust).join("master.pub"),
            time_scale,
            telemetry_budget: "1000000",
        }
    }

    fn robot_dir(&self) -> PathBuf {
        self.tmp.path().join("robot")
    }

    fn out(&self) -> PathBuf {
        self.tmp.path().join("master")
    }

    /// The master's link state: its own, kept across the master's restarts
    /// within the test.
    fn master_link_state(&self) -> PathBuf {
        self.tmp.path().join("master-link")
    }

    fn robot(&self) -> Proc {
        let child = Command::new(env!("CARGO_BIN_EXE_twindrive"))
            .args([
                "robot",
                "--id",
                "rover",
                "--site",
                s(&self.site),
                "--trust",
                s(&self.trust),
                "--key",
                s(&fixture().path("keys/rover.key")),
                "--state-dir",
                s(&self.robot_dir()),
                "--listen",
                &format!("tcp/127.0.0.1:{}", self.port),
                "--time-scale",
                &self.time_scale.to_string(),
                "--telemetry-budget",
                self.telemetry_budget,
                "--run-for",
                "300",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        Proc(child)
    }

    fn master(&self, extra: &[&str]) -> Proc {
        self.master_in(&self.out(), extra)
    }

    /// A master writing to `out`.
    fn master_in(&self, out: &Path, extra: &[&str]) -> Proc {
        let f = fixture();
        let mut args = vec![
            "master".to_string(),
            "--robot".into(),
            "rover".into(),
            "--out".into(),
            s(out).into(),
            "--connect".into(),
            format!("tcp/127.0.0.1:{}", self.port),
            "--timeout".into(),
            "240".into(),
        ];
        if !extra.contains(&"--log-wait") {
            args.extend(["--log-wait".into(), "60".into()]);
        }
        args.extend(["--telemetry-budget".into(), self.telemetry_budget.into()]);
        args.extend([
            "--key".into(),
            s(&f.path("keys/master.key")).into(),
            "--trust-robot".into(),
            s(&f.path("keys/rover.pub")).into(),
            "--link-state".into(),
            s(&self.master_link_state()).into(),
        ]);
        if !extra.contains(&"--signed") {
            args.extend(["--plan".into(), s(&f.path("plan/plan.json")).into()]);
        }
        args.extend(extra.iter().map(|a| a.to_string()));
        let child = Command::new(env!("CARGO_BIN_EXE_twindrive"))
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        Proc(child)
    }

    fn journal(&self) -> Vec<serde_json::Value> {
        let text =
            std::fs::read_to_string(self.robot_dir().join("journal.jsonl")).unwrap_or_default();
        text.lines()
            .filter_map(|l| serde_json::from_str(l).ok())
            .collect()
    }

    fn events(&self, event: &str) -> Vec<serde_json::Value> {
        self.journal()
            .into_iter()
            .filter(|l| l["event"] == event)
            .collect()
    }

    /// Waits (at most `limit_s`) until the journal has `event`.
    fn wait_for(&self, event: &str, limit_s: f64) {
        let start = Instant::now();
        while self.events(event).is_empty() {
            assert!(
                start.elapsed().as_secs_f64() < limit_s,
                "no `{event}` in the robot's journal after {limit_s} s"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn report(&self) -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(self.out().join("report.json")).unwrap()).unwrap()
    }
}

fn plan_sha() -> String {
    let plan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(fixture().path("plan/plan.json")).unwrap()).unwrap();
    plan["sha256"].as_str().unwrap().to_string()
}

fn assert_plan_identical(m: &Mission) {
    let sha = plan_sha();
    let robot = std::fs::read(m.robot_dir().join("plans").join(format!("{sha}.json"))).unwrap();
    assert_eq!(
        robot,
        std::fs::read(fixture().path("plan/plan.json")).unwrap()
    );
}

fn assert_no_wheel_moved(m: &Mission) {
    assert!(m.events("execution_started").is_empty());
    for line in m.journal() {
        assert_eq!(line["wheel_travel_rad"].as_f64(), Some(0.0), "{line}");
    }
}

#[test]
fn an_obstacle_the_twin_lacks_is_handed_back_and_the_continuation_completes() {
    let m = Mission::new("site_box.toml", "keys", 10.0);
    let _robot = m.robot();
    let (code, err) = finish(m.master(&["--on-handback", "replan", "--full-logs"]), 240.0);
    assert_eq!(code, Some(0), "{err}");
    let r = m.report();
    assert_eq!(r["outcome"], "completed");
    assert_master_speaks(
        &err,
        &["HAND-BACK", "continuation verified", "OUTCOME: Completed"],
    );
    assert!(!r["handbacks"].as_array().unwrap().is_empty());
    let updates = r["twin_updates"].as_array().unwrap();
    assert!(
        updates
            .iter()
            .any(|u| !u["obstacles_added"].as_array().unwrap().is_empty())
    );
    assert_plan_identical(&m);
    // Every continuation the robot holds is the master's, byte for byte.
    for u in r["uploads"].as_array().unwrap() {
        let sha = u["plan_sha256"].as_str().unwrap();
        let name = format!("{sha}.json");
        assert_eq!(
            std::fs::read(m.robot_dir().join("plans").join(&name)).unwrap(),
            std::fs::read(m.out().join("plans").join(&name)).unwrap()
        );
        // Asked for (--full-logs), each plan's full-rate log came home as
        // the robot keeps it, beside the one made from its digest.
        let suffix = format!("_{}_full", &sha[..12]);
        let full = std::fs::read_dir(m.out().join("robot_logs"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.to_string_lossy().ends_with(&suffix))
            .unwrap_or_else(|| panic!("no robot_logs/NN{suffix}: {:#?}", r["robot_logs"]));
        assert_eq!(
            std::fs::read(full.join("log.mcap")).unwrap(),
            std::fs::read(m.robot_dir().join("logs").join(sha).join("log.mcap")).unwrap()
        );
    }
    assert!(!r["robot_logs"].as_array().unwrap().is_empty());
}

#[test]
fn an_outage_mid_upload_delays_it_and_the_plan_arrives_byte_identical() {
    let m = Mission::new("", "keys", 10.0);
    let _robot = m.robot();
    // ~250 kB at 1 Mbit/s takes ~2 s; nothing gets through from 0.5 s to 4 s.
    let (code, err) = finish(
        m.master(&["--link", "lan,bandwidth_bit_s=1e6,outage=0.5..4"]),
        240.0,
    );
    assert_eq!(code, Some(0), "{err}");
    assert_plan_identical(&m);
    let r = m.report();
    assert!(r["uploads"][0]["duration_s"].as_f64().unwrap() > 4.0);
}

#[test]
fn a_robot_killed_mid_upload_resumes_where_it_stood() {
    let m = Mission::new("", "keys", 10.0);
    let robot = m.robot();
    let master = m.master(&["--link", "lan,bandwidth_bit_s=4e5"]);
    m.wait_for("upload_progress", 60.0);
    let held_before = m.events("upload_progress").last().unwrap()["received"]
        .as_u64()
        .unwrap();
    drop(robot);
    std::thread::sleep(Duration::from_millis(500));
    let _robot = m.robot();
    let (code, err) = finish(master, 240.0);
    assert_eq!(code, Some(0), "{err}");
    assert_plan_identical(&m);
    // The restarted robot still held its chunks.
    let lines = m.journal();
    let restart = lines
        .iter()
        .rposition(|l| l["event"] == "agent_started")
        .unwrap();
    assert!(restart > 0);
    let first = lines[restart..]
        .iter()
        .find(|l| l["event"] == "upload_progress")
        .unwrap();
    assert!(first["received"].as_u64().unwrap() >= held_before);
}

#[test]
fn a_robot_killed_mid_execution_stays_stopped_and_reports() {
    let m = Mission::new("", "keys", 2.0);
    let robot = m.robot();
    let master = m.master(&[]);
    m.wait_for("execution_started", 60.0);
    std::thread::sleep(Duration::from_millis(1500));
    drop(robot);
    let _robot = m.robot();
    let (code, err) = finish(master, 240.0);
    assert_eq!(code, Some(1), "{err}");
    let r = m.report();
    assert_eq!(r["outcome"], "failed");
    assert!(
        r["failure"]
            .as_str()
            .unwrap()
            .contains("restarted_mid_execution"),
        "{r}"
    );
    assert_eq!(m.events("execution_started").len(), 1);
}

#[test]
fn when_the_master_is_killed_a_supervised_plan_stops_on_its_dead_man() {
    let m = Mission::new("", "keys", 1.0);
    let _robot = m.robot();
    let master = m.master(&["--supervise", "2"]);
    m.wait_for("execution_started", 60.0);
    std::thread::sleep(Duration::from_millis(1000));
    drop(master);
    m.wait_for("stopped", 30.0);
    assert_eq!(m.events("stopped")[0]["reason"], "dead_man");
    assert!(m.events("execution_finished").is_empty());
}

#[test]
fn when_the_master_is_killed_an_unsupervised_plan_runs_to_its_end() {
    let m = Mission::new("", "keys", 10.0);
    let _robot = m.robot();
    let master = m.master(&[]);
    m.wait_for("execution_started", 60.0);
    drop(master);
    m.wait_for("execution_finished", 60.0);
    assert!(m.events("stopped").is_empty());
}

#[test]
fn a_plan_signed_by_an_unknown_key_is_rejected_and_no_wheel_moves() {
    // The master is the robot's, the plan signed by another key.
    let m = Mission::new("", "keys", 10.0);
    let _robot = m.robot();
    let foreign = sign_with(&m, "foreign.signed", "other/master.key", &[]);
    let (code, err) = finish(m.master(&["--signed", s(&foreign)]), 120.0);
    assert_eq!(code, Some(4), "{err}");
    assert_eq!(m.report()["outcome"], "rejected");
    assert!(
        m.events("plan_rejected")[0]["reason"]
            .as_str()
            .unwrap()
            .contains("signature")
    );
    assert_no_wheel_moved(&m);
}

fn sign(m: &Mission, name: &str, extra: &[&str]) -> PathBuf {
    sign_with(m, name, "keys/master.key", extra)
}

/// The fixture's plan signed for robot `rover` with `key` (a fixture path).
fn sign_with(m: &Mission, name: &str, key: &str, extra: &[&str]) -> PathBuf {
    let f = fixture();
    let out = m.tmp.path().join(name);
    let (plan, key) = (f.path("plan/plan.json"), f.path(key));
    let mut args = vec![
        "sign",
        s(&plan),
        "--key",
        s(&key),
        "--robot",
        "rover",
        "--out",
        s(&out),
    ];
    args.extend_from_slice(extra);
    let o = twindrive(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    out
}

#[test]
fn a_replayed_or_expired_plan_is_rejected_and_no_wheel_moves() {
    let m = Mission::new("", "keys", 10.0);
    // The robot once accepted counter 10 (its state survives restarts).
    std::fs::create_dir_all(m.robot_dir()).unwrap();
    twindrive_store::CounterFile::new(m.robot_dir().join("counter"))
        .store(10)
        .unwrap();
    let _robot = m.robot();
    let old = sign(&m, "old.signed", &["--counter", "5"]);
    let expired = sign(
        &m,
        "expired.signed",
        &["--counter", "50", "--expires-in", "0"],
    );
    for (file, expect) in [(&old, "replay"), (&expired, "expired")] {
        let _ = std::fs::remove_dir_all(m.out());
        let (code, err) = finish(m.master(&["--signed", s(file)]), 120.0);
        assert_eq!(code, Some(4), "{err}");
        let rejected = m.events("plan_rejected");
        let last = rejected.last().unwrap()["reason"]
            .as_str()
            .unwrap()
            .to_string();
        assert!(last.contains(expect), "{last}");
    }
    assert_no_wheel_moved(&m);
}

#[test]
fn corrupted_messages_are_dropped_and_asked_again_and_the_plan_arrives_whole() {
    let m = Mission::new("", "keys", 10.0);
    let _robot = m.robot();
    let (code, err) = finish(m.master(&["--link", "lan,corrupt=0.2"]), 240.0);
    assert_eq!(code, Some(0), "{err}");
    assert_plan_identical(&m);
    // Corrupted messages no longer authenticate: refused at either end
    // before anything reads them, and the chunks asked again.
    let report = m.report();
    let refused = report["refused_messages"].as_u64().unwrap()
        + report["robot_refused_messages"].as_u64().unwrap();
    assert!(refused > 0, "{report}");
}

#[test]
fn bad_input_is_a_clear_error() {
    let f = fixture();
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(
        tmp.path().join("bad.toml"),
        "[simulation]\nduration_s = -1\n",
    )
    .unwrap();
    let out = twindrive(&[
        "robot",
        "--id",
        "rover",
        "--site",
        s(&tmp.path().join("bad.toml")),
        "--trust",
        s(&f.path("keys/master.pub")),
        "--key",
        s(&f.path("keys/rover.key")),
        "--state-dir",
        s(&tmp.path().join("r")),
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("--site"),
        "{}",
        text(&out.stderr)
    );
    let out = twindrive(&[
        "robot",
        "--id",
        "rover",
        "--site",
        "scenarios/wall_following.toml",
        "--trust",
        s(&f.path("keys/master.key")),
        "--key",
        s(&f.path("keys/rover.key")),
        "--state-dir",
        s(&tmp.path().join("r")),
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("--trust"),
        "{}",
        text(&out.stderr)
    );
    let out = twindrive(&[
        "master",
        "--plan",
        s(&f.path("plan/plan.json")),
        "--key",
        s(&tmp.path().join("missing.key")),
        "--trust-robot",
        s(&f.path("keys/rover.pub")),
        "--robot",
        "rover",
        "--out",
        s(&tmp.path().join("m")),
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("missing.key"),
        "{}",
        text(&out.stderr)
    );
    let out = twindrive(&[
        "master",
        "--signed",
        s(&f.path("plan/plan.json")),
        "--key",
        s(&f.path("keys/master.key")),
        "--trust-robot",
        s(&f.path("keys/rover.pub")),
        "--link-state",
        s(&tmp.path().join("link")),
        "--robot",
        "rover",
        "--out",
        s(&tmp.path().join("m")),
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("signed plan"),
        "{}",
        text(&out.stderr)
    );
    let out = twindrive(&[
        "master",
        "--signed",
        s(&f.path("plan/plan.json")),
        "--key",
        s(&f.path("keys/master.key")),
        "--trust-robot",
        s(&f.path("keys/rover.pub")),
        "--robot",
        "rover",
        "--link",
        "moon",
        "--out",
        s(&tmp.path().join("m")),
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("--link"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn a_master_killed_mid_upload_resumes_it_when_restarted() {
    let m = Mission::new("", "keys", 10.0);
    let _robot = m.robot();
    let link = ["--link", "lan,bandwidth_bit_s=1e5"];
    let master = m.master(&link);
    m.wait_for("upload_progress", 60.0);
    std::thread::sleep(Duration::from_millis(1500));
    drop(master);
    let held = m.events("upload_progress").last().unwrap()["received"]
        .as_u64()
        .unwrap();
    assert!(m.out().join("state/uploading.signed").is_file());
    let (code, err) = finish(m.master(&link), 240.0);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("resuming the upload"), "{err}");
    assert_plan_identical(&m);
    // Resumed, not started over: the robot's count never went back.
    let counts: Vec<u64> = m
        .events("upload_progress")
        .iter()
        .map(|l| l["received"].as_u64().unwrap())
        .collect();
    assert!(
        held > 0 && counts.windows(2).all(|w| w[1] >= w[0]),
        "{counts:?}"
    );
    assert!(!m.out().join("state/uploading.signed").exists());
}

#[test]
fn robot_and_master_meet_through_a_zenoh_router() {
    let m = Mission::new("", "keys", 10.0);
    let router_port = port();
    let router = format!("tcp/127.0.0.1:{router_port}");
    // The robot is a zenoh client and boots before its router: it keeps
    // trying until the router is there.
    let client = m.tmp.path().join("client.json5");
    std::fs::write(
        &client,
        "{ mode: \"client\", scouting: { multicast: { enabled: false } } }\n",
    )
    .unwrap();
    let f = fixture();
    let mut robot = Proc(
        Command::new(env!("CARGO_BIN_EXE_twindrive"))
            .args([
                "robot",
                "--id",
                "rover",
                "--site",
                s(&m.site),
                "--trust",
                s(&f.path("keys").join("master.pub")),
                "--key",
                s(&f.path("keys/rover.key")),
                "--state-dir",
                s(&m.robot_dir()),
                "--connect",
                &router,
                "--zenoh-config",
                s(&client),
                "--time-scale",
                "10",
                "--telemetry-budget",
                m.telemetry_budget,
                "--run-for",
                "300",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    std::thread::sleep(Duration::from_millis(2500));
    assert!(
        robot.0.try_wait().unwrap().is_none(),
        "the robot gave up before its router came"
    );
    let _router = Proc(
        Command::new(env!("CARGO_BIN_EXE_twindrive"))
            .args(["router", "--listen", &router])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    std::thread::sleep(Duration::from_millis(500));
    let master = Proc(
        Command::new(env!("CARGO_BIN_EXE_twindrive"))
            .args([
                "master",
                "--plan",
                s(&f.path("plan/plan.json")),
                "--key",
                s(&f.path("keys/master.key")),
                "--trust-robot",
                s(&f.path("keys/rover.pub")),
                "--link-state",
                s(&m.master_link_state()),
                "--robot",
                "rover",
                "--out",
                s(&m.out()),
                "--connect",
                &router,
                "--timeout",
                "240",
                "--log-wait",
                "60",
                "--telemetry-budget",
                m.telemetry_budget,
            ])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let (code, err) = finish(master, 240.0);
    assert_eq!(code, Some(0), "{err}");
    assert_plan_identical(&m);
    assert_eq!(m.report()["outcome"], "completed");
}

/// Files (chunks) a master holds of robot logs still arriving.
fn log_chunks_held(out: &Path) -> usize {
    let Ok(dirs) = std::fs::read_dir(out.join("state/log_chunks")) else {
        return 0;
    };
    dirs.filter_map(Result::ok)
        .filter_map(|d| std::fs::read_dir(d.path()).ok())
        .map(|files| files.count())
        .sum()
}

#[test]
fn every_robot_log_comes_home_through_a_dead_master_a_dead_link_and_a_robot_restart() {
    let mut m = Mission::new("site_box.toml", "keys", 10.0);
    // The log back-filled over a slow link (2 kB/s, the rate the masters
    // give the robot): the masters are killed and the link cut while it
    // arrives.
    m.telemetry_budget = "8000";
    let robot = m.robot();
    // Master A: the robot hands back at the box; A waits two seconds for
    // the log and exits while the robot back-fills it.
    let (code, err) = finish(
        m.master(&["--link", "lan,bandwidth_bit_s=16000", "--log-wait", "2"]),
        120.0,
    );
    assert_eq!(code, Some(3), "{err}");
    assert!(err.contains("HAND-BACK"), "{err}");
    assert!(!m.events("log_written").is_empty());
    assert!(
        m.events("log_acknowledged").is_empty(),
        "A took the log whole"
    );
    // Master B, another output directory, the link dead for its first
    // four seconds, then slow. The robot is killed mid back-fill and
    // started again: its simulated site starts over at the plan's start, so
    // B's plan may be driven (and handed back at the box again) or refused.
    let b = m.tmp.path().join("master_b");
    let master_b = m.master_in(
        &b,
        &[
            "--link",
            "lan,outage=0..4,bandwidth_bit_s=16000",
            "--log-wait",
            "120",
        ],
    );
    let start = Instant::now();
    while log_chunks_held(&b) < 2 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "B holds no chunk of the log after 60 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    drop(robot);
    let _robot = m.robot();
    let (code, err) = finish(master_b, 240.0);
    assert!(matches!(code, Some(3 | 4)), "{err}");
    assert!(err.contains("robot log received"), "{err}");
    // Every log the robot wrote is home, every step of it, and
    // acknowledged: A's cut short by A's exit, the link's outage and the
    // robot's restart.
    let written = m.events("log_written");
    assert!(!written.is_empty());
    assert_eq!(m.events("log_acknowledged").len(), written.len());
    // (B's plan, driven again from the start after the restart, is A's
    // plan on the same simulated site: the same log, which comes once.)
    let mut written: Vec<_> = written
        .into_iter()
        .map(|w| w["plan_sha256"].as_str().unwrap().to_string())
        .collect();
    written.dedup();
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(b.join("report.json")).unwrap()).unwrap();
    let logs = r["robot_logs"].as_array().unwrap();
    assert_eq!(logs.len(), written.len(), "{r}");
    let read = |p: PathBuf| twindrive_log::read_mcap(&p).unwrap();
    for (home, sha) in logs.iter().zip(&written) {
        let home = read(Path::new(home.as_str().unwrap()).join("log.mcap"));
        let kept = read(m.robot_dir().join("logs").join(sha).join("log.mcap"));
        assert_eq!(home.steps.len(), kept.steps.len());
        for (a, b) in home.steps.iter().zip(&kept.steps) {
            assert_eq!((a.t_ns, a.encoder_ticks), (b.t_ns, b.encoder_ticks));
        }
    }
}

/// The master's stderr on a pipe: one line per event, `what` among them,
/// and never long without a line: it says what it waits for after 4 s of
/// quiet; 6 s is allowed between two lines, because a continuation planned
/// in between holds the loop (a second or more on a loaded machine).
fn assert_master_speaks(err: &str, what: &[&str]) {
    for w in what.iter().chain(&[
        "upload done",
        "the robot started plan",
        "robot log received",
    ]) {
        assert!(err.contains(w), "no `{w}` in:\n{err}");
    }
    let times: Vec<f64> = err
        .lines()
        .filter_map(|l| l.trim_start().split_once(" s  rover  "))
        .filter_map(|(t, _)| t.trim().parse().ok())
        .collect();
    assert!(times.len() > 5, "{err}");
    for w in times.windows(2) {
        assert!(w[1] >= w[0], "{err}");
        assert!(
            w[1] - w[0] <= 6.0,
            "silent from {} s to {} s:\n{err}",
            w[0],
            w[1]
        );
    }
}
