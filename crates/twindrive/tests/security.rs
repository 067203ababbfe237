//! Every message authenticated, both ways, against an attacker on the same
//! zenoh network: an independent client (Python `eclipse-zenoh`,
//! `scripts/forger.py`) that publishes forged messages (the right robot
//! id, growing sequence numbers, fresh time stamps; in the clear, sealed
//! with a key nobody trusts, or with a made-up tag) and genuine ones it
//! captured and replays. Real `twindrive robot`, `master` and `router`
//! processes on loopback; every wait bounded, every child killed by its
//! process id.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{Proc, finish, fixture, port, python, repo, text, twindrive};
use twindrive_link::envelope::read_private_key_pem;
use twindrive_link::secure::{Channel, MemoryEpochs, Role};
use twindrive_link::wire::{self, Body, Handback, Offer, Stamper, Status};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Router, robot `rover` and masters, all zenoh clients of the router.
struct Site {
    tmp: tempfile::TempDir,
    router: String,
    _router: Proc,
}

impl Site {
    fn new() -> Self {
        let tmp = tempfile::tempdir().unwrap();
        let router = format!("tcp/127.0.0.1:{}", port());
        std::fs::write(
            tmp.path().join("client.json5"),
            "{ mode: \"client\", scouting: { multicast: { enabled: false } } }\n",
        )
        .unwrap();
        let proc = Proc(
            Command::new(env!("CARGO_BIN_EXE_twindrive"))
                .args(["router", "--listen", &router])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap(),
        );
        std::thread::sleep(Duration::from_millis(500));
        Self {
            tmp,
            router,
            _router: proc,
        }
    }

    fn path(&self, p: &str) -> PathBuf {
        self.tmp.path().join(p)
    }

    /// The robot on `site` (a fixture path or the case study), its log in
    /// robot.log (appended: a restart keeps the first run's lines).
    fn robot(&self, site: Option<&str>, time_scale: &str) -> Proc {
        let f = fixture();
        let site = site.map_or(repo().join("scenarios/wall_following.toml"), |p| f.path(p));
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.path("robot.log"))
            .unwrap();
        Proc(
            Command::new(env!("CARGO_BIN_EXE_twindrive"))
                .args([
                    "robot",
                    "--id",
                    "rover",
                    "--site",
                    s(&site),
                    "--trust",
                    s(&f.path("keys/master.pub")),
                    "--key",
                    s(&f.path("keys/rover.key")),
                    "--state-dir",
                    s(&self.path("robot")),
                    "--connect",
                    &self.router,
                    "--zenoh-config",
                    s(&self.path("client.json5")),
                    "--time-scale",
                    time_scale,
                    "--telemetry-budget",
                    "1000000",
                    "--run-for",
                    "240",
                ])
                .stdout(Stdio::null())
                .stderr(log)
                .spawn()
                .unwrap(),
        )
    }

    /// A master sending the fixture's plan to `rover` (or `signed`).
    fn master(&self, out: &str, extra: &[&str]) -> Proc {
        let f = fixture();
        let mut args = vec![
            "master".to_string(),
            "--key".into(),
            s(&f.path("keys/master.key")).into(),
            "--trust-robot".into(),
            s(&f.path("keys/rover.pub")).into(),
            "--link-state".into(),
            s(&self.path("master-link")).into(),
            "--robot".into(),
            "rover".into(),
            "--out".into(),
            s(&self.path(out)).into(),
            "--connect".into(),
            self.router.clone(),
            "--zenoh-config".into(),
            s(&self.path("client.json5")).into(),
            "--timeout".into(),
            "150".into(),
            "--log-wait".into(),
            "5".into(),
            "--telemetry-budget".into(),
            "1000000".into(),
        ];
        if !extra.contains(&"--signed") {
            args.extend(["--plan".into(), s(&f.path("plan/plan.json")).into()]);
        }
        args.extend(extra.iter().map(|a| a.to_string()));
        Proc(
            Command::new(env!("CARGO_BIN_EXE_twindrive"))
                .args(&args)
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        )
    }

    fn journal(&self) -> Vec<serde_json::Value> {
        std::fs::read_to_string(self.path("robot/journal.jsonl"))
            .unwrap_or_default()
            .lines()
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
    fn wait_for(&self, event: &str, limit_s: f64) -> serde_json::Value {
        let start = Instant::now();
        loop {
            if let Some(e) = self.events(event).pop() {
                return e;
            }
            assert!(
                start.elapsed().as_secs_f64() < limit_s,
                "no `{event}` in the robot's journal after {limit_s} s; robot log:\n{}",
                self.robot_log()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn robot_log(&self) -> String {
        std::fs::read_to_string(self.path("robot.log")).unwrap_or_default()
    }

    /// The forger publishing `payloads` on `key` every 0.25 s for
    /// `for_s` (or each once).
    fn forge(&self, key: &str, name: &str, payloads: &[Vec<u8>], for_s: Option<f64>) -> Proc {
        let file = self.path(name);
        write_payloads(&file, payloads);
        let mut args = vec![
            s(&repo().join("scripts/forger.py")).to_string(),
            "publish".into(),
            self.router.clone(),
            key.into(),
            s(&file).into(),
        ];
        if let Some(t) = for_s {
            args.extend(["--for".into(), t.to_string()]);
        }
        Proc(
            Command::new(python())
                .args(&args)
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        )
    }

    /// The forger capturing what is published on `key` for `for_s`.
    fn capture(&self, key: &str, name: &str, for_s: f64) -> Proc {
        Proc(
            Command::new(python())
                .args([
                    s(&repo().join("scripts/forger.py")),
                    "capture",
                    &self.router,
                    key,
                    s(&self.path(name)),
                    "--for",
                    &for_s.to_string(),
                ])
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        )
    }
}

fn write_payloads(path: &Path, payloads: &[Vec<u8>]) {
    let mut bytes = Vec::new();
    for p in payloads {
        bytes.extend_from_slice(&(p.len() as u32).to_be_bytes());
        bytes.extend_from_slice(p);
    }
    std::fs::write(path, bytes).unwrap();
}

fn read_payloads(path: &Path) -> Vec<Vec<u8>> {
    let data = std::fs::read(path).unwrap_or_default();
    let mut out = Vec::new();
    let mut i = 0;
    while i + 4 <= data.len() {
        let n = u32::from_be_bytes(data[i..i + 4].try_into().unwrap()) as usize;
        out.push(data[i + 4..i + 4 + n].to_vec());
        i += 4 + n;
    }
    out
}

/// Every body in three forged forms, with robot id `rover`, growing
/// sequence numbers and fresh time stamps: in the clear (the protocol's
/// bytes as they were before sealing), sealed with a key the other end
/// does not trust (the attacker's own master or robot key, `other/`), and
/// with a sealed header whose tag is made up. `role` is whom the forger
/// pretends to be.
fn forged(role: Role, bodies: &[Body], copies: usize) -> Vec<Vec<u8>> {
    forged_for("rover", role, bodies, copies)
}

/// [`forged`], for robot `id` (a fixture robot).
fn forged_for(id: &str, role: Role, bodies: &[Body], copies: usize) -> Vec<Vec<u8>> {
    let f = fixture();
    let read =
        |p: &str| read_private_key_pem(&std::fs::read_to_string(f.path(p)).unwrap()).unwrap();
    let (own, peer) = match role {
        Role::Master => (read("other/master.key"), read(&format!("keys/{id}.key"))),
        Role::Robot => (read(&format!("other/{id}.key")), read("keys/master.key")),
    };
    let mut attacker = Channel::new(
        role,
        &own,
        &peer.verifying_key(),
        id,
        Box::new(MemoryEpochs::default()),
    )
    .unwrap();
    let mut stamper = Stamper::new(id);
    let unix_ns = || {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos() as u64
    };
    let mut out = Vec::new();
    for k in 0..copies {
        for body in bodies {
            let plain = wire::encode(&stamper.stamp(body.clone(), unix_ns()));
            let mut made_up = vec![0x01];
            made_up.extend_from_slice(&(k as u32 + 1).to_be_bytes());
            made_up.extend_from_slice(&(k as u64).to_be_bytes()[2..]);
            made_up.extend_from_slice(&plain);
            made_up.extend_from_slice(&[0x5a; 16]);
            out.push(attacker.seal(&plain).unwrap());
            out.push(made_up);
            out.push(plain);
        }
    }
    out
}

fn hex_transfer(v: &serde_json::Value) -> [u8; 32] {
    let h = v["transfer"].as_str().expect("a transfer id");
    let mut t = [0u8; 32];
    for (i, b) in t.iter_mut().enumerate() {
        *b = u8::from_str_radix(&h[2 * i..2 * i + 2], 16).unwrap();
    }
    t
}

#[test]
fn forged_pings_do_not_keep_a_supervised_robot_driving_after_its_master_died() {
    let site = Site::new();
    let _robot = site.robot(None, "1");
    let mut master = site.master("m", &["--supervise", "3"]);
    site.wait_for("execution_started", 90.0);
    // The attacker keeps the robot company: pings, heartbeats, every 0.25 s.
    // ... and every other message a master sends: a forged upload (offer,
    // chunks, a repair shard, its end), answers about the robot's logs,
    // a pong and a hand-back acknowledgement.
    let fake = [5u8; 32];
    let forged_up = forged(
        Role::Master,
        &[
            Body::Ping { nonce: 1 },
            Body::Heartbeat {
                telemetry_budget_bytes_s: 100,
                backfill_bytes_s: 100,
            },
            Body::Offer(Offer {
                transfer: fake,
                size: 2048,
                chunk_size: 1024,
                fec_from: 2,
                fec_repairs: 0,
            }),
            Body::Chunk {
                transfer: fake,
                index: 0,
                crc32: crc32(&[1; 1024]),
                data: vec![1; 1024],
            },
            Body::Repair {
                transfer: fake,
                index: 2,
                crc32: crc32(&[2; 1024]),
                data: vec![2; 1024],
            },
            Body::EndOfFile { transfer: fake },
            Body::Nak {
                transfer: fake,
                received: 0,
                upto: 10,
                missing: vec![(0, 9)],
            },
            Body::Finished { transfer: fake },
            Body::Refused {
                transfer: fake,
                reason: "forged".into(),
            },
            Body::Pong { nonce: 1 },
            Body::HandbackAck { plan: fake },
        ],
        10,
    );
    let _forger = site.forge("twindrive/rover/up", "pings.bin", &forged_up, Some(15.0));
    std::thread::sleep(Duration::from_millis(1500));
    let killed_unix_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs_f64();
    master.0.kill().unwrap();
    let _ = master.0.wait();
    let stopped = site.wait_for("stopped", 20.0);
    assert_eq!(stopped["reason"], "dead_man", "{stopped}");
    let after_s = stopped["unix_s"].as_f64().unwrap() - killed_unix_s;
    assert!(
        after_s <= 3.0 + 2.0,
        "stopped {after_s:.1} s after the master died (dead-man 3 s)"
    );
    // The forged heartbeats did not touch the telemetry budget either, and
    // the forged upload never began.
    let fake_hex: String = fake.iter().map(|b| format!("{b:02x}")).collect();
    assert!(
        site.journal()
            .iter()
            .all(|e| e["transfer"].as_str() != Some(fake_hex.as_str())),
        "the forged upload reached the robot"
    );
    assert!(
        site.events("telemetry_budget")
            .iter()
            .all(|e| e["bytes_per_s"] != 100.0),
        "{:?}",
        site.events("telemetry_budget")
    );
    let log = site.robot_log();
    assert!(log.contains("refused a payload before reading it"), "{log}");
    assert!(log.contains("twindrive/rover/up"), "{log}");
}

#[test]
fn a_forged_handback_ack_leaves_the_handback_repeating_until_the_real_master_answers() {
    let site = Site::new();
    let _robot = site.robot(Some("site_box.toml"), "5");
    let mut master = site.master("m", &[]);
    site.wait_for("execution_started", 90.0);
    master.0.kill().unwrap();
    let _ = master.0.wait();
    // The robot meets the box the twin lacks and hands back, to nobody.
    let handback = site.wait_for("handback", 120.0);
    let plan = hex_transfer(&handback);
    let acks = forged(Role::Master, &[Body::HandbackAck { plan }], 20);
    let forger = site.forge("twindrive/rover/up", "acks.bin", &acks, Some(6.0));
    let (code, err) = finish(forger, 30.0);
    assert_eq!(code, Some(0), "the forger: {err}");
    assert!(
        site.events("handback_acknowledged").is_empty(),
        "a forged acknowledgement was taken"
    );
    // The real master, restarted, hears the hand-back and acknowledges it
    // (the new plan it brings is refused: the robot stands at the box, not
    // at the plan's start; exit 4, the worse outcome).
    let (code, err) = finish(site.master("m", &[]), 150.0);
    assert!(matches!(code, Some(3 | 4)), "{err}");
    assert!(err.contains("HAND-BACK"), "{err}");
    let ack = site.wait_for("handback_acknowledged", 10.0);
    assert_eq!(hex_transfer(&ack), plan);
}

#[test]
fn forged_and_replayed_messages_change_nothing_at_the_master_or_the_robot() {
    let site = Site::new();
    let robot = site.robot(None, "10");
    let signed = site.path("plan.signed");
    let f = fixture();
    let o = twindrive(&[
        "sign",
        s(&f.path("plan/plan.json")),
        "--key",
        s(&f.path("keys/master.key")),
        "--robot",
        "rover",
        "--out",
        s(&signed),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let transfer = wire::transfer_id(&std::fs::read(&signed).unwrap());
    // What a robot could say, forged: a pose far off, other wheels, a
    // hand-back the twin would learn from, and the upload's end.
    let status = Status {
        plan: None,
        progress: (0, 0),
        plan_t_s: 0.0,
        pose: [9.0, -9.0, 3.0],
        params: [0.2, 0.01, 0.9],
        params_std: [1e-4; 3],
        deviation_m: 0.0,
        range_residual_m: 0.0,
        wheel_travel_rad: 0.0,
        logs_pending: 0,
        handback_pending: false,
        bumps: 7,
        collisions: 7,
        refused: 0,
        deviation_now_m: 0.0,
        max_deviation_on_detour: false,
        on_detour: false,
    };
    let handback = Handback {
        plan: transfer,
        reason: "unexpected_bump".into(),
        plan_t_s: 1.0,
        progress: 10,
        pose: [1.0, 1.0, 0.0],
        pose_covariance: [0.0; 9],
        params: [0.2, 0.01, 0.9],
        params_covariance: [0.0; 9],
        window: Vec::new(),
    };
    let down = forged(
        Role::Robot,
        &[
            Body::Status(Box::new(status)),
            Body::Handback(Box::new(handback)),
            Body::Refused {
                transfer,
                reason: "forged".into(),
            },
            Body::Finished { transfer },
            Body::Offer(Offer {
                transfer: [7; 32],
                size: 4096,
                chunk_size: 1024,
                fec_from: 4,
                fec_repairs: 0,
            }),
            Body::Chunk {
                transfer: [7; 32],
                index: 0,
                crc32: crc32(&[3; 1024]),
                data: vec![3; 1024],
            },
            Body::Repair {
                transfer: [7; 32],
                index: 4,
                crc32: crc32(&[4; 1024]),
                data: vec![4; 1024],
            },
            Body::EndOfFile { transfer: [7; 32] },
            Body::Nak {
                transfer,
                received: 0,
                upto: 100,
                missing: vec![(0, 99)],
            },
            Body::Ping { nonce: 3 },
            Body::Pong { nonce: 3 },
        ],
        10,
    );
    let capture_up = site.capture("twindrive/rover/up", "up.bin", 25.0);
    let capture_down = site.capture("twindrive/rover/down", "down.bin", 25.0);
    std::thread::sleep(Duration::from_millis(1000));
    let _forger = site.forge("twindrive/rover/down", "down-forged.bin", &down, Some(20.0));
    let (code, err) = finish(site.master("m", &["--signed", s(&signed)]), 150.0);
    assert_eq!(code, Some(0), "{err}");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(site.path("m/report.json")).unwrap()).unwrap();
    assert_eq!(report["outcome"], "completed", "{report}");
    assert!(
        report["handbacks"].as_array().unwrap().is_empty(),
        "{report}"
    );
    assert!(
        report["twin_updates"].as_array().unwrap().is_empty(),
        "{report}"
    );
    assert_eq!(report["bumps"], 0, "{report}");
    assert_eq!(report["collisions"], 0, "{report}");
    assert!(report["refused_messages"].as_u64().unwrap() > 0, "{report}");
    assert!(err.contains("refused a payload before reading it"), "{err}");
    let robot_plan = std::fs::read(
        site.path("robot/plans")
            .join(format!("{}.json", plan_sha(&f.path("plan/plan.json")))),
    )
    .unwrap();
    assert_eq!(robot_plan, std::fs::read(f.path("plan/plan.json")).unwrap());

    // Replays: what the master sent, to the robot, now and after its
    // restart; what the robot sent, to a new master on a new mission.
    let _ = finish(capture_up, 60.0);
    let up = read_payloads(&site.path("up.bin"));
    assert!(up.len() > 50, "{} messages captured", up.len());
    replay_to_robot(&site, "replay-up.bin", &up, "a replay");

    // The robot restarted: the same bytes again, refused (their epoch was
    // accepted before the restart).
    drop(robot);
    let _robot = site.robot(None, "10");
    let start = Instant::now();
    while site.events("agent_started").len() < 2 {
        assert!(start.elapsed().as_secs() < 30, "the robot did not restart");
        std::thread::sleep(Duration::from_millis(50));
    }
    replay_to_robot(
        &site,
        "replay-up-2.bin",
        &up,
        "accepted before this end restarted",
    );

    // The master restarted (a new process, its link state kept): what the
    // robot sent before, replayed to it, is refused; the twin learns
    // nothing from the replayed hand-backs or statuses. (Its new plan is
    // refused by the robot, which stands at the old plan's end: exit 4.)
    let _ = finish(capture_down, 60.0);
    let captured_down: Vec<Vec<u8>> = read_payloads(&site.path("down.bin"))
        .into_iter()
        .filter(|p| !down.contains(p))
        .collect();
    assert!(captured_down.len() > 5, "{} captured", captured_down.len());
    let _replay = site.forge(
        "twindrive/rover/down",
        "replay-down.bin",
        &captured_down,
        Some(10.0),
    );
    let (code, err) = finish(site.master("m2", &[]), 150.0);
    assert!(matches!(code, Some(0 | 4)), "{err}");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(site.path("m2/report.json")).unwrap()).unwrap();
    assert!(report["refused_messages"].as_u64().unwrap() > 0, "{report}");
    assert!(
        report["handbacks"].as_array().unwrap().is_empty(),
        "{report}"
    );
    assert!(
        report["twin_updates"].as_array().unwrap().is_empty(),
        "{report}"
    );
}

fn crc32(data: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(data);
    h.finalize()
}

/// Replays `captured` to the robot: nothing of a plan happens, and the
/// robot's log says `why`.
fn replay_to_robot(site: &Site, name: &str, captured: &[Vec<u8>], why: &str) {
    let before = site.journal().len();
    let replay = site.forge("twindrive/rover/up", name, captured, None);
    let _ = finish(replay, 60.0);
    std::thread::sleep(Duration::from_millis(1000));
    let new: Vec<_> = site.journal()[before..].to_vec();
    let moved = [
        "upload_progress",
        "plan_accepted",
        "execution_started",
        "plan_rejected",
    ];
    assert!(
        new.iter()
            .all(|e| !moved.contains(&e["event"].as_str().unwrap_or(""))),
        "a replay moved the robot: {new:?}"
    );
    assert!(site.robot_log().contains(why), "{}", site.robot_log());
}

fn plan_sha(plan: &Path) -> String {
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(plan).unwrap()).unwrap();
    v["sha256"].as_str().unwrap().to_string()
}

#[test]
fn with_the_wrong_keys_nothing_moves_and_both_sides_say_why() {
    for (robot_trusts, master_trusts) in [
        ("other/master.pub", "keys/rover.pub"),
        ("keys/master.pub", "other/rover.pub"),
    ] {
        let f = fixture();
        let tmp = tempfile::tempdir().unwrap();
        let zport = port();
        let robot_log = tmp.path().join("robot.log");
        let _robot = Proc(
            Command::new(env!("CARGO_BIN_EXE_twindrive"))
                .args([
                    "robot",
                    "--id",
                    "rover",
                    "--site",
                    s(&repo().join("scenarios/wall_following.toml")),
                    "--trust",
                    s(&f.path(robot_trusts)),
                    "--key",
                    s(&f.path("keys/rover.key")),
                    "--state-dir",
                    s(&tmp.path().join("robot")),
                    "--listen",
                    &format!("tcp/127.0.0.1:{zport}"),
                    "--run-for",
                    "60",
                ])
                .stdout(Stdio::null())
                .stderr(std::fs::File::create(&robot_log).unwrap())
                .spawn()
                .unwrap(),
        );
        let master = Proc(
            Command::new(env!("CARGO_BIN_EXE_twindrive"))
                .args([
                    "master",
                    "--plan",
                    s(&f.path("plan/plan.json")),
                    "--key",
                    s(&f.path("keys/master.key")),
                    "--trust-robot",
                    s(&f.path(master_trusts)),
                    "--link-state",
                    s(&tmp.path().join("master-link")),
                    "--robot",
                    "rover",
                    "--out",
                    s(&tmp.path().join("m")),
                    "--connect",
                    &format!("tcp/127.0.0.1:{zport}"),
                    "--timeout",
                    "12",
                ])
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        );
        let (code, err) = finish(master, 60.0);
        assert_ne!(code, Some(0), "{err}");
        assert!(err.contains("not authentic"), "the master: {err}");
        let log = std::fs::read_to_string(&robot_log).unwrap();
        assert!(log.contains("not authentic"), "the robot: {log}");
        let journal =
            std::fs::read_to_string(tmp.path().join("robot/journal.jsonl")).unwrap_or_default();
        assert!(!journal.contains("upload_progress"), "{journal}");
        assert!(!journal.contains("execution_started"), "{journal}");
    }
}

#[test]
fn a_fleet_over_tls_with_mutual_authentication_completes_and_each_robot_keeps_to_its_keys() {
    let f = fixture();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let tls_port = port().to_string();
    let certs = d.join("certs");
    let o = twindrive(&[
        "certs",
        "--out",
        s(&certs),
        "--robot",
        "r1",
        "--robot",
        "r2",
        "--port",
        &tls_port,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let cert = |name: &str| s(&certs.join(name)).to_string();
    let _router = Proc(
        Command::new(env!("CARGO_BIN_EXE_twindrive"))
            .args([
                "router",
                "--zenoh-config",
                &cert("router.json5"),
                "--listen",
                &format!("tls/127.0.0.1:{tls_port}"),
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    std::thread::sleep(Duration::from_millis(1000));
    let endpoint = format!("tls/localhost:{tls_port}");
    let forger = |args: &[&str]| {
        Command::new(python())
            .arg(repo().join("scripts/forger.py"))
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    // A client that trusts the router but shows no certificate: refused.
    let (code, err) = finish(
        Proc(forger(&[
            "capture",
            &endpoint,
            "twindrive/r1/up",
            s(&d.join("nothing.bin")),
            "--for",
            "1",
            "--ca",
            &cert("ca.pem"),
        ])),
        60.0,
    );
    assert_eq!(
        code,
        Some(3),
        "a client without a certificate got in: {err}"
    );

    let robots: Vec<Proc> = ["r1", "r2"]
        .iter()
        .map(|id| {
            Proc(
                Command::new(env!("CARGO_BIN_EXE_twindrive"))
                    .args([
                        "robot",
                        "--id",
                        id,
                        "--site",
                        s(&repo().join("scenarios/wall_following.toml")),
                        "--trust",
                        s(&f.path("keys/master.pub")),
                        "--key",
                        s(&f.path(&format!("keys/{id}.key"))),
                        "--state-dir",
                        s(&d.join(id)),
                        "--zenoh-config",
                        &cert(&format!("{id}.json5")),
                        "--time-scale",
                        "10",
                        "--telemetry-budget",
                        "200000",
                        "--run-for",
                        "240",
                    ])
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .unwrap(),
            )
        })
        .collect();
    // Robot r1's certificate, misused: forged statuses on r2's key (the
    // router's access control drops them) and on its own (they reach the
    // master, which refuses them: not sealed by r1's key).
    let status = |id: &str| forged_for(id, Role::Robot, &[Body::Ping { nonce: 9 }], 30);
    let mut attacks = Vec::new();
    for (id, name) in [("r2", "as-r2.bin"), ("r1", "as-r1.bin")] {
        let file = d.join(name);
        write_payloads(&file, &status(id));
        attacks.push(Proc(forger(&[
            "publish",
            &endpoint,
            &format!("twindrive/{id}/down"),
            s(&file),
            "--for",
            "20",
            "--ca",
            &cert("ca.pem"),
            "--cert",
            &cert("r1.pem"),
            "--private-key",
            &cert("r1.key"),
        ])));
    }
    let master = Proc(
        Command::new(env!("CARGO_BIN_EXE_twindrive"))
            .args([
                "master",
                "--plan",
                s(&f.path("plan/plan.json")),
                "--key",
                s(&f.path("keys/master.key")),
                "--trust-robot",
                s(&f.path("keys/r1.pub")),
                "--trust-robot",
                s(&f.path("keys/r2.pub")),
                "--link-state",
                s(&d.join("master-link")),
                "--robot",
                "r1",
                "--robot",
                "r2",
                "--out",
                s(&d.join("m")),
                "--zenoh-config",
                &cert("master.json5"),
                "--timeout",
                "200",
                "--log-wait",
                "5",
                "--telemetry-budget",
                "200000",
            ])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let (code, err) = finish(master, 240.0);
    assert_eq!(code, Some(0), "{err}");
    let report = |id: &str| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(d.join("m").join(id).join("report.json")).unwrap())
            .unwrap()
    };
    for id in ["r1", "r2"] {
        assert_eq!(report(id)["outcome"], "completed", "{}", report(id));
    }
    assert!(
        report("r1")["refused_messages"].as_u64().unwrap() > 0,
        "r1's own key expression: the forgeries arrive, and are refused"
    );
    assert_eq!(
        report("r2")["refused_messages"],
        0,
        "r2's key expression: the router let r1's certificate publish on it"
    );
    drop(attacks);
    drop(robots);
}
