//! Decoupled operation end to end in virtual time: the operator's master
//! and the robot agent, the same state machines the two processes run,
//! joined by the emulated link. Each case runs under several seeds.

mod common;

use std::path::Path;

use ed25519_dalek::SigningKey;
use twindrive_agent::backend::{RobotBackend, SimBackend};
use twindrive_agent::master::{Master, MasterConfig};
use twindrive_agent::operator::{OnHandback, Operator, OperatorConfig, Outcome};
use twindrive_agent::robot::{AgentConfig, RobotAgent};
use twindrive_agent::store::MemoryRobotStore;
use twindrive_agent::twin::Twin;
use twindrive_link::emulator::LinkProfile;
use twindrive_link::envelope::{Envelope, Supervision, sign_plan};
use twindrive_link::upload::{MemoryStore, SenderConfig};
use twindrive_link::vtime::VirtualLink;

const S: u64 = 1_000_000_000;
const UNIX0: f64 = 1.8e9;
const BOX: &str = "rectangles = [{ min = [1.9, 0.9], max = [2.1, 1.2] }]";

fn envelope(counter: u64, expires_unix_s: u64, dead_man: Option<f64>) -> Envelope {
    Envelope {
        format: String::new(),
        version: 0,
        plan_sha256: String::new(),
        plan_file_sha256: String::new(),
        plan_bytes: 0,
        plan_encoding: String::new(),
        robot_id: "rover".into(),
        counter,
        not_before_unix_s: 0,
        expires_unix_s,
        world_sha256: "0".repeat(64),
        supervision: Supervision {
            dead_man_timeout_s: dead_man,
        },
        tolerances: Default::default(),
    }
}

fn plan_json() -> Vec<u8> {
    serde_json::to_vec_pretty(&**common::plan()).unwrap()
}

struct Harness {
    link: VirtualLink,
    op: Operator<MemoryStore>,
    agent: RobotAgent<Site, MemoryRobotStore>,
}

/// The site's simulator as a robot whose motor drivers hold the last
/// command they heard (as many do): it counts the zero commands the agent
/// sends it while no plan runs.
struct Site {
    sim: SimBackend,
    holds: u64,
}

impl RobotBackend for Site {
    fn period_s(&self) -> f64 {
        self.sim.period_s()
    }
    fn step(
        &mut self,
        decide: &mut dyn FnMut(&twindrive_agent::backend::Reading) -> [f64; 2],
    ) -> Option<twindrive_agent::backend::Reading> {
        self.sim.step(decide)
    }
    fn hold(&mut self) -> bool {
        self.holds += 1;
        true
    }
    fn wheel_travel_rad(&self) -> f64 {
        self.sim.wheel_travel_rad()
    }
    fn log_header(&self) -> twindrive_log::LogHeader {
        self.sim.log_header()
    }
    fn map(&self) -> Option<twindrive_log::WorldMap> {
        self.sim.map()
    }
}

fn site_backend(extra: &str) -> Site {
    Site {
        sim: SimBackend::new(common::site(extra), common::plan().samples[0].pose(), 400.0).unwrap(),
        holds: 0,
    }
}

/// A robot on `store` (a clone of one that an earlier agent used is that
/// robot restarted).
fn agent(
    store: &MemoryRobotStore,
    trusted: &SigningKey,
    extra: &str,
) -> RobotAgent<Site, MemoryRobotStore> {
    let mut config = AgentConfig::new("rover", vec![trusted.verifying_key()]);
    config.unix_time_at_zero_s = UNIX0;
    RobotAgent::new(config, site_backend(extra), store.clone()).unwrap()
}

/// A key of its own for each seed (tests need no randomness).
fn test_key(seed: u8) -> SigningKey {
    SigningKey::from_bytes(&[seed; 32])
}

fn harness(
    store: &MemoryRobotStore,
    profile: &str,
    seed: u64,
    master_key: &SigningKey,
    robot_trusts: &SigningKey,
    extra: &str,
    on_handback: OnHandback,
) -> Harness {
    harness_with_budget(
        store,
        profile,
        seed,
        master_key,
        robot_trusts,
        extra,
        on_handback,
        8_000.0,
    )
}

#[allow(clippy::too_many_arguments)]
fn harness_with_budget(
    store: &MemoryRobotStore,
    profile: &str,
    seed: u64,
    master_key: &SigningKey,
    robot_trusts: &SigningKey,
    extra: &str,
    on_handback: OnHandback,
    budget: f64,
) -> Harness {
    let profile: LinkProfile = profile.parse().unwrap();
    let link = VirtualLink::symmetric(&profile, seed);
    let master = Master::new(
        "rover",
        MasterConfig {
            upload: SenderConfig {
                pace_bit_s: profile.bandwidth_bit_s,
                rtt_hint_ns: (2.0 * profile.latency_s * 1e9) as u64,
                loss_hint: profile.loss,
                ..SenderConfig::default()
            },
            heartbeat_period_s: 1.0,
            telemetry_budget_bytes_s: budget,
        },
        MemoryStore::default(),
    );
    let twin = Twin::new(common::twin(), common::CALIBRATED);
    let op = Operator::new(
        master,
        Some(twin),
        Some(master_key.clone()),
        OperatorConfig {
            robot_id: "rover".into(),
            on_handback,
            expires_in_s: 3_600,
            supervision: Supervision {
                dead_man_timeout_s: None,
            },
            tolerances: Default::default(),
            unix_time_at_zero_s: UNIX0,
            first_counter: 1,
            world_sha256: "0".repeat(64),
            log_wait_s: 1_200.0,
            max_continuations: 6,
            continuation: Default::default(),
            full_rate_logs: false,
        },
    );
    Harness {
        link,
        op,
        agent: agent(store, robot_trusts, extra),
    }
}

impl Harness {
    fn send(&mut self, signed: Vec<u8>, counter: u64) {
        self.op.start(
            common::plan().clone(),
            signed,
            counter,
            false,
            self.link.now_ns,
        );
    }

    /// Runs until the robot drives a plan (`executing`) or drives none,
    /// for at most `t_s` of link time.
    fn run_until_executing(&mut self, executing: bool, t_s: f64) -> bool {
        let (op, agent) = (&mut self.op, &mut self.agent);
        self.link.run(op, agent, (t_s * 1e9) as u64, |_, agent| {
            agent.is_executing() == executing
        })
    }

    fn run_until(&mut self, t_s: f64) -> bool {
        let (op, agent) = (&mut self.op, &mut self.agent);
        self.link
            .run(op, agent, (t_s * 1e9) as u64, |op, _| op.is_done())
    }
}

fn journal(store: &MemoryRobotStore) -> Vec<serde_json::Value> {
    store.journal_lines()
}

fn events(store: &MemoryRobotStore, event: &str) -> Vec<serde_json::Value> {
    journal(store)
        .into_iter()
        .filter(|l| l["event"] == event)
        .collect()
}

#[test]
fn a_box_the_twin_lacks_is_handed_back_learnt_and_the_continuation_completes() {
    for seed in [1, 2, 3] {
        let store = MemoryRobotStore::default();
        let key = test_key(1);
        let mut h = harness(
            &store,
            "lunar,loss=0.1",
            seed,
            &key,
            &key,
            BOX,
            OnHandback::Replan,
        );
        let signed = sign_plan(&key, &plan_json(), envelope(1, u64::MAX, None)).unwrap();
        h.send(signed, 1);
        assert!(
            h.run_until(1_800.0),
            "seed {seed}: not done: {:?}",
            h.op.report.timeline
        );
        let r = &h.op.report;
        assert_eq!(
            r.outcome,
            Some(Outcome::Completed),
            "seed {seed}: {:?} {:#?}",
            r.failure,
            r.timeline
        );
        assert!(!r.handbacks.is_empty());
        // Contact happens only where the robot met the box the twin lacked
        // (the bumper closes within a tick or two of touching).
        let bumps = r
            .handbacks
            .iter()
            .filter(|h| h.reason == "unexpected_bump")
            .count();
        assert!(
            r.collisions as usize <= 2 * bumps,
            "seed {seed}: {} collisions",
            r.collisions
        );
        // The twin learnt a block where the site's box is.
        let learnt = &h.op.twin().unwrap().learnt;
        assert!(
            learnt
                .iter()
                .any(|(min, max)| min[0] < 2.1 && max[0] > 1.9 && min[1] < 1.2 && max[1] > 0.9),
            "seed {seed}: {learnt:?}"
        );
        // Every plan the robot accepted is stored byte for byte as signed.
        assert_eq!(r.uploads.len(), r.handbacks.len() + 1);
        assert_eq!(store.plan(&common::plan().sha256), Some(plan_json()));
        for (plan, json, _) in &h.op.new_plans {
            assert_eq!(store.plan(&plan.sha256).as_ref(), Some(json));
        }
        // The robot's logs came back, one per plan driven, and read as logs.
        assert_eq!(
            h.op.new_logs.len(),
            r.uploads.len(),
            "seed {seed}: {:#?}",
            r.timeline
        );
        for (k, arrived) in h.op.new_logs.iter().enumerate() {
            assert!(!arrived.full_rate);
            let log =
                twindrive_log::read_mcap_bytes(&arrived.mcap, Path::new("received.mcap")).unwrap();
            assert!(log.steps.len() > 100);
            // The period whose reading ended the plan (a hand-back or the
            // plan's end) commanded zero itself; the plan was driving just
            // before a hand-back.
            let last = log.steps.last().unwrap();
            assert_eq!(last.cmd_wheel_rad_s, [0.0, 0.0], "seed {seed}, log {k}");
            if k < r.handbacks.len() {
                let before = log.steps[log.steps.len() - 2].cmd_wheel_rad_s;
                assert!(before != [0.0, 0.0], "seed {seed}, log {k}");
            }
        }
        assert_eq!(events(&store, "execution_started").len(), r.uploads.len());
        assert_eq!(events(&store, "handback").len(), r.handbacks.len());
        // The first plan starts from the robot's own estimate; every
        // continuation from the pose the twin refined, as its header says.
        let starts = events(&store, "localization");
        assert_eq!(starts.len(), r.uploads.len());
        assert_eq!(starts[0]["start"], "the robot's own");
        for (start, (plan, _, _)) in starts[1..].iter().zip(&h.op.new_plans) {
            assert_eq!(start["start"], "refined by the twin", "seed {seed}");
            let p = plan.header.start;
            assert_eq!(
                start["start_pose"],
                serde_json::json!([p.x_m, p.y_m, p.heading_rad]),
                "seed {seed}"
            );
            assert!(plan.header.start_covariance.is_some());
        }
    }
}

#[test]
fn on_handback_ask_waits_for_the_operator_who_continues_or_ends() {
    let key = test_key(2);
    for continue_it in [true, false] {
        let store = MemoryRobotStore::default();
        let mut h = harness(&store, "lan", 5, &key, &key, BOX, OnHandback::Ask);
        let signed = sign_plan(&key, &plan_json(), envelope(1, u64::MAX, None)).unwrap();
        h.send(signed, 1);
        let limit = (600.0 * 1e9) as u64;
        let waiting = {
            let (op, agent) = (&mut h.op, &mut h.agent);
            h.link
                .run(op, agent, limit, |op, _| op.awaiting_decision().is_some())
        };
        assert!(waiting, "no hand-back: {:#?}", h.op.report.timeline);
        // Nothing is decided, nothing else is sent, until the operator acts.
        assert_eq!(h.op.report.outcome, None);
        assert_eq!(h.op.report.uploads.len(), 1);
        assert!(!h.op.twin().unwrap().learnt.is_empty());
        let reason = h.op.awaiting_decision().unwrap().reason.clone();
        assert_eq!(reason, "unexpected_bump");
        assert!(h.op.last_handback().is_some_and(|w| !w.window.is_empty()));
        let now = h.link.now_ns;
        {
            let (op, agent) = (&mut h.op, &mut h.agent);
            h.link.run(op, agent, now + 5_000_000_000, |_, _| false);
        }
        assert_eq!(h.op.report.outcome, None, "still waiting");
        let now = h.link.now_ns;
        // The upload's clock stopped when the robot held it whole.
        let took = h.op.report.uploads[0].duration_s;
        assert!(took > 0.0);
        assert_eq!(h.op.master.upload_duration_s(now), Some(took));
        if continue_it {
            h.op.replan(now).unwrap();
            assert!(h.op.awaiting_decision().is_none());
            assert!(h.op.replan(now).is_err(), "nothing waits any more");
            // The continuation goes out; this test stops at the next
            // hand-back or the end.
            let (op, agent) = (&mut h.op, &mut h.agent);
            let decided = h.link.run(op, agent, limit * 2, |op, _| {
                op.awaiting_decision().is_some() || op.report.outcome.is_some()
            });
            assert!(decided);
            assert!(
                h.op.report.uploads.len() >= 2,
                "{:#?}",
                h.op.report.timeline
            );
        } else {
            h.op.end_mission(now);
            assert_eq!(h.op.report.outcome, Some(Outcome::HandedBack));
            assert!(h.run_until(900.0), "the logs come back");
            assert_eq!(h.op.report.uploads.len(), 1);
        }
    }
}

#[test]
fn on_handback_stop_ends_the_mission_handed_back_with_the_twin_updated() {
    let store = MemoryRobotStore::default();
    let key = test_key(3);
    let mut h = harness(
        &store,
        "satellite-lossy",
        7,
        &key,
        &key,
        BOX,
        OnHandback::Stop,
    );
    h.send(
        sign_plan(&key, &plan_json(), envelope(1, u64::MAX, None)).unwrap(),
        1,
    );
    assert!(h.run_until(600.0));
    let r = &h.op.report;
    assert_eq!(r.outcome, Some(Outcome::HandedBack));
    assert_eq!(r.handbacks.len(), 1);
    assert_eq!(r.twin_updates.len(), 1);
    assert!(!r.twin_updates[0].obstacles_added.is_empty());
    // Stopped, the robot is told zero every control period for as long as
    // no plan runs: drivers that hold their last command stay stopped.
    let period_s = h.agent.backend().period_s();
    let before = h.agent.backend().holds;
    let from_ns = h.link.now_ns;
    let (op, agent) = (&mut h.op, &mut h.agent);
    h.link.run(op, agent, from_ns + 10 * S, |_, _| false);
    let holds = h.agent.backend().holds - before;
    let expected = 10.0 / period_s;
    assert!(
        (holds as f64 - expected).abs() <= 2.0,
        "{holds} zero commands in 10 s, one a period is {expected}"
    );
}

/// A plan the gate must refuse: it crosses the link whole, is rejected with
/// its reason, and no wheel moves.
fn refused(
    signed: impl Fn(&SigningKey) -> Vec<u8>,
    prepare: impl Fn(&MemoryRobotStore),
    expect: &str,
) {
    for seed in [11, 12, 13] {
        let store = MemoryRobotStore::default();
        prepare(&store);
        let key = test_key(4);
        let mut h = harness(
            &store,
            "lunar,loss=0.1",
            seed,
            &key,
            &key,
            "",
            OnHandback::Stop,
        );
        h.send(signed(&key), 1);
        assert!(h.run_until(600.0), "seed {seed}");
        assert_eq!(h.op.report.outcome, Some(Outcome::Rejected), "seed {seed}");
        let rejected = events(&store, "plan_rejected");
        assert_eq!(rejected.len(), 1, "seed {seed}");
        let reason = rejected[0]["reason"].as_str().unwrap();
        assert!(reason.contains(expect), "seed {seed}: {reason}");
        assert_eq!(h.agent.backend().wheel_travel_rad(), 0.0);
        assert!(events(&store, "execution_started").is_empty());
        assert!(
            journal(&store)
                .iter()
                .all(|l| l["wheel_travel_rad"].as_f64() == Some(0.0))
        );
    }
}

#[test]
fn a_plan_signed_by_an_unknown_key_is_refused_and_no_wheel_moves() {
    refused(
        |_| {
            let forger = test_key(5);
            sign_plan(&forger, &plan_json(), envelope(5, u64::MAX, None)).unwrap()
        },
        |_| {},
        "signature",
    );
}

#[test]
fn a_replayed_plan_is_refused_even_after_a_restart() {
    refused(
        |key| sign_plan(key, &plan_json(), envelope(5, u64::MAX, None)).unwrap(),
        // The robot accepted counter 9 before it restarted.
        |store| store.set_counter(9),
        "replay",
    );
}

#[test]
fn an_expired_plan_is_refused() {
    refused(
        |key| sign_plan(key, &plan_json(), envelope(5, UNIX0 as u64 + 5, None)).unwrap(),
        |_| {},
        "expired",
    );
}

#[test]
fn a_plan_corrupted_after_signing_is_refused() {
    refused(
        |key| {
            let mut s = sign_plan(key, &plan_json(), envelope(5, u64::MAX, None)).unwrap();
            let n = s.len();
            s[n - 100] ^= 0x40;
            s
        },
        |_| {},
        "plan",
    );
}

#[test]
fn chunks_corrupted_in_flight_are_asked_again_and_the_plan_arrives_whole() {
    let store = MemoryRobotStore::default();
    let key = test_key(6);
    let mut h = harness(
        &store,
        "lunar,loss=0.05",
        5,
        &key,
        &key,
        "",
        OnHandback::Stop,
    );
    let mut k = 0u64;
    h.link.tamper_up = Some(Box::new(move |bytes: &mut Vec<u8>| {
        k += 1;
        if k.is_multiple_of(7) && bytes.len() > 500 {
            let n = bytes.len();
            bytes[n - 10] ^= 0xff;
        }
    }));
    h.send(
        sign_plan(&key, &plan_json(), envelope(1, u64::MAX, None)).unwrap(),
        1,
    );
    assert!(h.run_until(900.0));
    assert_eq!(h.op.report.outcome, Some(Outcome::Completed));
    assert!(!events(&store, "chunk_corrupted").is_empty());
    assert!(h.op.report.uploads[0].chunks_resent > 0);
}

#[test]
fn a_robot_restarted_mid_upload_resumes_and_the_plan_arrives_byte_identical() {
    for seed in [21, 22, 23] {
        let store = MemoryRobotStore::default();
        let key = test_key(7);
        let mut h = harness(
            &store,
            "lunar,loss=0.1",
            seed,
            &key,
            &key,
            "",
            OnHandback::Stop,
        );
        h.send(
            sign_plan(&key, &plan_json(), envelope(1, u64::MAX, None)).unwrap(),
            1,
        );
        // Part of the way (the first progress the robot journals), then the
        // robot's process dies and comes back.
        let mut t = 0.0;
        while events(&store, "upload_progress").is_empty() {
            t += 0.05;
            assert!(!h.run_until(t));
            assert!(t < 60.0, "no upload progress in a minute");
        }
        assert!(
            events(&store, "execution_started").is_empty(),
            "still uploading"
        );
        let before = events(&store, "upload_progress");
        let held = before.last().unwrap()["received"].as_u64().unwrap();
        assert!(held > 0);
        h.link.drop_in_flight();
        h.agent = agent(&store, &key, "");
        assert!(h.run_until(900.0), "seed {seed}");
        assert_eq!(h.op.report.outcome, Some(Outcome::Completed), "seed {seed}");
        assert_eq!(store.plan(&common::plan().sha256), Some(plan_json()));
        // Resumed: the restarted robot still held what it had, and said so.
        let lines = journal(&store);
        let restart = lines
            .iter()
            .rposition(|l| l["event"] == "agent_started")
            .unwrap();
        let first = lines[restart..]
            .iter()
            .find(|l| l["event"] == "upload_progress")
            .unwrap();
        assert!(first["received"].as_u64().unwrap() >= held, "seed {seed}");
    }
}

#[test]
fn a_robot_restarted_mid_execution_stays_stopped_and_never_drives_the_plan_again() {
    for seed in [31, 32, 33] {
        let store = MemoryRobotStore::default();
        let key = test_key(8);
        let mut h = harness(&store, "lan", seed, &key, &key, "", OnHandback::Replan);
        h.send(
            sign_plan(&key, &plan_json(), envelope(1, u64::MAX, None)).unwrap(),
            1,
        );
        assert!(!h.run_until(10.0));
        assert!(
            h.agent.is_executing(),
            "seed {seed}: {:#?}",
            h.op.report.timeline
        );
        h.link.drop_in_flight();
        h.agent = agent(&store, &key, "");
        assert!(h.run_until(300.0), "seed {seed}");
        assert_eq!(h.op.report.outcome, Some(Outcome::Failed), "seed {seed}");
        assert_eq!(h.agent.backend().wheel_travel_rad(), 0.0);
        assert_eq!(events(&store, "execution_started").len(), 1);
        let stopped = events(&store, "stopped");
        assert_eq!(stopped[0]["reason"], "restarted_mid_execution");
    }
}

/// The master goes away for good after the upload: a supervised plan stops
/// on its dead-man, an unsupervised one runs to its end.
#[test]
fn when_the_master_dies_the_plans_policy_decides() {
    for (dead_man, expect) in [(Some(3.0), "dead_man"), (None, "finished")] {
        let store = MemoryRobotStore::default();
        let key = test_key(9);
        let mut h = harness(&store, "wifi", 41, &key, &key, "", OnHandback::Stop);
        h.send(
            sign_plan(&key, &plan_json(), envelope(1, u64::MAX, dead_man)).unwrap(),
            1,
        );
        assert!(!h.run_until(5.0));
        assert!(h.agent.is_executing());
        // Only the robot runs from here.
        let mut silent = Silent;
        h.link.drop_in_flight();
        let agent = &mut h.agent;
        h.link
            .run(&mut silent, agent, 200 * S, |_, a| !a.is_executing());
        let ended: Vec<_> = journal(&store)
            .into_iter()
            .filter(|l| l["event"] == "stopped" || l["event"] == "execution_finished")
            .collect();
        assert_eq!(ended.len(), 1);
        if expect == "finished" {
            assert_eq!(ended[0]["event"], "execution_finished");
        } else {
            assert_eq!(ended[0]["reason"], expect);
            // Stopped within the timeout and a tick of the last word heard.
            assert!(ended[0]["plan_t_s"].as_f64().unwrap() < 5.0 + 3.0 + 0.5);
        }
    }
}

/// A master that is gone.
struct Silent;

impl twindrive_link::vtime::Endpoint for Silent {
    fn poll_transmit(&mut self, _: u64) -> Option<twindrive_link::wire::Message> {
        None
    }
    fn handle(&mut self, _: &twindrive_link::wire::Message, _: u64) {}
    fn poll_timeout(&self) -> Option<u64> {
        None
    }
}

/// What the robot sends (status, hand-backs, NAKs, its logs) keeps to the
/// master's budget, and every log still arrives.
#[test]
fn telemetry_keeps_to_its_budget_and_every_log_arrives() {
    for budget in [1_000.0, 4_000.0] {
        let store = MemoryRobotStore::default();
        let key = test_key(10);
        let mut h = harness_with_budget(
            &store,
            "lunar",
            51,
            &key,
            &key,
            BOX,
            OnHandback::Stop,
            budget,
        );
        h.send(
            sign_plan(&key, &plan_json(), envelope(1, u64::MAX, None)).unwrap(),
            1,
        );
        // While the plan runs, the robot keeps to its budget.
        assert!(h.run_until_executing(true, 600.0));
        let (sent0, t0) = (h.link.down.stats.bytes_sent, h.link.now_ns);
        assert!(h.run_until_executing(false, 1_200.0));
        let sent = (h.link.down.stats.bytes_sent - sent0) as f64;
        let took = (h.link.now_ns - t0) as f64 * 1e-9;
        assert!(
            sent / took <= budget * 1.1,
            "{budget}: {} B/s while driving",
            sent / took
        );
        assert!(h.run_until(3_600.0));
        assert_eq!(h.op.new_logs.len(), 1, "{budget}");
        assert!(h.op.report.status_messages > 10);
        h.op.finish_report();
        let rtt = h.op.report.link_rtt_median_s.unwrap();
        assert!((2.5..2.7).contains(&rtt), "{rtt}");
    }
}

/// At default settings over the lunar profile, the case study's log costs
/// at most 4 kB per second of mission on the link and is home within a
/// minute of the mission's end; the robot keeps the full log.
#[test]
fn the_case_study_log_comes_home_over_lunar_within_a_minute() {
    for seed in [61, 62] {
        let store = MemoryRobotStore::default();
        let key = test_key(12);
        let mut h = harness(&store, "lunar", seed, &key, &key, "", OnHandback::Stop);
        h.send(
            sign_plan(&key, &plan_json(), envelope(1, u64::MAX, None)).unwrap(),
            1,
        );
        assert!(h.run_until_executing(true, 600.0));
        assert!(h.run_until_executing(false, 1_200.0));
        let ended_ns = h.link.now_ns;
        let (op, agent) = (&mut h.op, &mut h.agent);
        assert!(
            h.link.run(op, agent, ended_ns + 600 * S, |op, _| !op
                .new_logs
                .is_empty()),
            "seed {seed}: no log in 10 minutes"
        );
        let home_s = (h.link.now_ns - ended_ns) as f64 * 1e-9;
        assert!(
            home_s <= 60.0,
            "seed {seed}: the log came {home_s:.1} s after the end"
        );
        let written = events(&store, "log_written");
        let digest_bytes = written[0]["digest_bytes"].as_f64().unwrap();
        let mission_s = common::plan().samples.last().unwrap().t_s - common::plan().samples[0].t_s;
        assert!(
            digest_bytes <= 4_000.0 * mission_s,
            "seed {seed}: {digest_bytes} bytes for {mission_s:.0} s"
        );
        // The log that came is the robot's, every step of it.
        let mcap = &h.op.new_logs[0].mcap;
        let home = twindrive_log::read_mcap_bytes(mcap, Path::new("home.mcap")).unwrap();
        let full = store.log(&common::plan().sha256).unwrap();
        let kept = twindrive_log::read_mcap_bytes(&full.mcap, Path::new("kept.mcap")).unwrap();
        assert_eq!(home.steps.len(), kept.steps.len());
        assert_eq!(
            home.steps
                .iter()
                .map(|s| s.encoder_ticks)
                .collect::<Vec<_>>(),
            kept.steps
                .iter()
                .map(|s| s.encoder_ticks)
                .collect::<Vec<_>>()
        );
        eprintln!(
            "seed {seed}: {digest_bytes} bytes ({:.0} B per mission second, full MCAP {} bytes), home {home_s:.1} s after the end",
            digest_bytes / mission_s,
            full.mcap.len()
        );
    }
}

/// Asked for, the full-rate log of every plan driven comes home after its
/// digest, byte for byte as the robot keeps it, over a link that loses a
/// fifth of the messages (requests included: they are asked again); a
/// plan the robot has no log of is refused, and the robot says so.
#[test]
fn full_rate_logs_come_home_whole_when_asked_for() {
    let store = MemoryRobotStore::default();
    let key = test_key(13);
    let mut h = harness(
        &store,
        "lan,loss=0.2",
        63,
        &key,
        &key,
        BOX,
        OnHandback::Stop,
    );
    h.op.config_mut().full_rate_logs = true;
    h.send(
        sign_plan(&key, &plan_json(), envelope(1, u64::MAX, None)).unwrap(),
        1,
    );
    assert!(h.run_until(3_600.0), "{:#?}", h.op.report.timeline);
    assert_eq!(h.op.report.handbacks.len(), 1);
    let logs: Vec<_> = h.op.new_logs.iter().collect();
    assert_eq!(logs.len(), 2, "{:#?}", h.op.report.timeline);
    assert!(!logs[0].full_rate && logs[1].full_rate);
    let plan = logs[1].plan.as_ref().expect("the plan it is the log of");
    assert_eq!(plan.sha256, common::plan().sha256);
    let kept = store.log(&plan.sha256).unwrap();
    assert_eq!(logs[1].mcap, kept.mcap, "byte for byte");
    assert!(events(&store, "log_requested").len() == 1);
    // A plan this robot never drove.
    h.op.master.request_log([9; 32]);
    let until = h.link.now_ns + 30 * S;
    let (op, agent) = (&mut h.op, &mut h.agent);
    h.link.run(op, agent, until, |_, _| false);
    let refused = events(&store, "log_request_refused");
    assert!(!refused.is_empty());
    assert!(
        refused[0]["reason"]
            .as_str()
            .unwrap()
            .contains(&"09".repeat(32))
    );
}

/// A plan rehearsed for another site is refused after its signature
/// checks, and no wheel moves.
#[test]
fn a_plan_for_another_site_is_refused() {
    let store = MemoryRobotStore::default();
    let key = test_key(11);
    let mut h = harness(&store, "lan", 61, &key, &key, "", OnHandback::Stop);
    let text = twindrive_sim::builtin::WALL_FOLLOWING
        .replace("name = \"wall_following\"", "name = \"quarry\"");
    let site = twindrive_sim::Scenario::from_toml(&text, Path::new("<quarry>.toml")).unwrap();
    let backend = Site {
        sim: SimBackend::new(site, common::plan().samples[0].pose(), 100.0).unwrap(),
        holds: 0,
    };
    let mut config = AgentConfig::new("rover", vec![key.verifying_key()]);
    config.unix_time_at_zero_s = UNIX0;
    h.agent = RobotAgent::new(config, backend, store.clone()).unwrap();
    h.send(
        sign_plan(&key, &plan_json(), envelope(1, u64::MAX, None)).unwrap(),
        1,
    );
    assert!(h.run_until(600.0));
    assert_eq!(h.op.report.outcome, Some(Outcome::Rejected));
    let reason = events(&store, "plan_rejected")[0]["reason"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(
        reason.contains("site `wall_following`") && reason.contains("quarry"),
        "{reason}"
    );
    assert_eq!(h.agent.backend().wheel_travel_rad(), 0.0);
}
