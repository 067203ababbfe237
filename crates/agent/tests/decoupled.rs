//! The story in virtual time: the master signs the case-study plan and
//! uploads it over the emulated lunar link; the robot assembles it, accepts
//! it only if every check passes, and drives it on its own site. A forged
//! plan crosses the same link and is refused.

mod common;

use twindrive_agent::backend::{RobotBackend, SimBackend};
use twindrive_agent::executive::{Executive, Stop, Tolerances};

use twindrive_link::emulator::{LinkEmulator, LinkProfile};
use twindrive_link::envelope::{Envelope, PlanGate, Supervision, generate_key, sign_plan};
use twindrive_link::upload::{
    MemoryStore, Receiver, ReceiverConfig, ReceiverEvent, Sender, SenderConfig,
};
use twindrive_link::vtime::VirtualLink;

const S: u64 = 1_000_000_000;

fn envelope(counter: u64) -> Envelope {
    Envelope {
        format: String::new(),
        version: 0,
        plan_sha256: String::new(),
        plan_file_sha256: String::new(),
        plan_bytes: 0,
        robot_id: "rover".into(),
        counter,
        not_before_unix_s: 0,
        expires_unix_s: u64::MAX,
        world_sha256: "0".repeat(64),
        supervision: Supervision {
            dead_man_timeout_s: None,
        },
    }
}

/// Uploads `signed` over lunar with 10 % loss; returns the bytes the robot
/// assembled and the virtual time it took.
fn upload(signed: Vec<u8>, seed: u64) -> (Vec<u8>, f64) {
    let profile: LinkProfile = "lunar,loss=0.1".parse().unwrap();
    let mut net = VirtualLink::new(
        LinkEmulator::new(profile.clone(), seed, 0),
        LinkEmulator::new(profile.clone(), seed, 1),
    );
    let mut sender = Sender::new(
        "rover",
        signed,
        SenderConfig {
            pace_bit_s: profile.bandwidth_bit_s,
            rtt_hint_ns: (2.0 * profile.latency_s * 1e9) as u64,
            ..SenderConfig::default()
        },
    );
    let mut receiver = Receiver::new("rover", MemoryStore::default(), ReceiverConfig::default());
    assert!(net.run(&mut sender, &mut receiver, 3_600 * S, |s, _| {
        s.is_finished()
    }));
    let mut file = None;
    while let Some(e) = receiver.poll_event() {
        if let ReceiverEvent::Completed { file: f, .. } = e {
            file = Some(f);
        }
    }
    (file.expect("completed"), net.now_ns as f64 * 1e-9)
}

#[test]
fn a_signed_plan_crosses_the_lunar_link_and_runs_and_a_forged_one_is_refused() {
    let plan = common::plan();
    let plan_json = serde_json::to_vec_pretty(plan).unwrap();
    let master = generate_key().unwrap();
    let gate = PlanGate {
        robot_id: "rover".into(),
        trusted: vec![master.verifying_key()],
        max_signed_bytes: 16 << 20,
        max_plan_bytes: 64 << 20,
    };

    // The genuine plan: arrives byte-identical, is accepted, and runs on a
    // site with a box the twin lacks until the robot hands control back.
    let signed = sign_plan(&master, &plan_json, envelope(1)).unwrap();
    let (received, upload_s) = upload(signed.clone(), 1);
    assert_eq!(received, signed);
    let accepted = gate.check(&received, 0, 1_000).unwrap();
    assert_eq!(accepted.plan_json, plan_json);
    let site = common::site("rectangles = [{ min = [1.9, 0.9], max = [2.1, 1.2] }]");
    let max_wheel = site.robot.max_wheel_speed_rad_s;
    let mut backend = SimBackend::new(site, accepted.plan.samples[0].pose(), 120.0).unwrap();
    let mut exec = Executive::new(&accepted.plan, Tolerances::default(), None, max_wheel).unwrap();
    let mut wheels = [0.0, 0.0];
    while let Some(reading) = backend.step(wheels) {
        wheels = exec.tick(&reading);
        if exec.stopped().is_some() {
            break;
        }
    }
    let (t, stop) = exec.stopped().cloned().expect("stopped");
    assert!(stop.is_handback(), "{stop:?} at {t} s");
    assert_ne!(stop, Stop::Finished);
    assert!(backend.wheel_travel_rad() > 10.0);
    // The upload took seconds of link time, not the mission's.
    assert!(upload_s < 120.0, "{upload_s} s");

    // A plan signed by another key crosses the same link intact and is
    // refused, so no executive is ever made for it.
    let forger = generate_key().unwrap();
    let forged = sign_plan(&forger, &plan_json, envelope(2)).unwrap();
    let (received, _) = upload(forged.clone(), 2);
    assert_eq!(received, forged);
    assert!(matches!(
        gate.check(&received, 1, 1_000),
        Err(twindrive_link::envelope::Rejection::BadSignature)
    ));
}
