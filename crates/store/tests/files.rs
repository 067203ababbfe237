//! The files at the process edge: upload chunks that survive restarts of
//! either side, the plan counter, the robot's state directory.

use twindrive_agent::store::{LogFiles, RobotStore};
use twindrive_link::emulator::LinkProfile;
use twindrive_link::upload::{
    ChunkStore, Receiver, ReceiverConfig, ReceiverEvent, Sender, SenderConfig,
};
use twindrive_link::vtime::VirtualLink;
use twindrive_store::{CounterFile, DirStore, RobotDir};

const S: u64 = 1_000_000_000;

fn file(len: usize, seed: u64) -> Vec<u8> {
    // xorshift: bytes no compressor or chunk boundary favours.
    let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

fn sender_config(profile: &LinkProfile) -> SenderConfig {
    SenderConfig {
        pace_bit_s: profile.bandwidth_bit_s,
        rtt_hint_ns: (2.0 * profile.latency_s * 1e9) as u64 + 1,
        ..SenderConfig::default()
    }
}

/// The completed file, if the receiver has said so.
fn completed<St: ChunkStore>(receiver: &mut Receiver<St>, got: &mut Option<Vec<u8>>) {
    while let Some(e) = receiver.poll_event() {
        if let ReceiverEvent::Completed { file, .. } = e {
            *got = Some(file);
        }
    }
}

#[test]
fn restarts_of_either_side_resume_without_losing_or_repeating() {
    let profile: LinkProfile = "satellite-lossy,loss=0.1".parse().unwrap();
    let data = file(150_000, 9);
    let tmp = tempfile::tempdir().unwrap();
    let store = || DirStore::new(tmp.path().join("chunks"));
    let mut net = VirtualLink::symmetric(&profile, 3);
    let mut got = None;

    let mut sender = Sender::new("rover", data.clone(), sender_config(&profile));
    let mut receiver = Receiver::new("rover", store(), ReceiverConfig::default());
    // Part of the way, then the robot process dies and comes back.
    assert!(!net.run(&mut sender, &mut receiver, S / 2, |s, _| s.is_finished()));
    let held_before = std::fs::read_dir(tmp.path().join("chunks"))
        .unwrap()
        .next()
        .map(|d| std::fs::read_dir(d.unwrap().path()).unwrap().count())
        .unwrap_or(0);
    assert!(
        held_before > 10,
        "{held_before} chunks held before the restart"
    );
    drop(receiver);
    net.drop_in_flight();
    let mut receiver = Receiver::new("rover", store(), ReceiverConfig::default());
    // Then the master dies too, and resumes.
    assert!(!net.run(&mut sender, &mut receiver, S, |s, _| s.is_finished()));
    let sent_before = sender.stats.chunks_sent;
    drop(sender);
    net.drop_in_flight();
    let mut sender = Sender::resume("rover", data.clone(), sender_config(&profile));
    assert!(net.run(&mut sender, &mut receiver, 600 * S, |s, _| s.is_finished()));
    completed(&mut receiver, &mut got);
    assert_eq!(got.as_deref(), Some(&data[..]));
    // The resumed sender sent what was missing, not the whole file again.
    let chunks = u64::from(sender.stats.chunks);
    assert!(
        sender.stats.chunks_sent < chunks - held_before as u64 / 2,
        "resumed sender sent {} of {chunks} chunks ({sent_before} before)",
        sender.stats.chunks_sent
    );
    // The store is cleaned up once the file is complete.
    assert_eq!(
        std::fs::read_dir(tmp.path().join("chunks"))
            .unwrap()
            .count(),
        0
    );
}

#[test]
fn the_counter_survives_a_restart() {
    let tmp = tempfile::tempdir().unwrap();
    let file = CounterFile::new(tmp.path().join("accepted_counter"));
    assert_eq!(file.load().unwrap(), 0);
    file.store(41).unwrap();
    assert_eq!(
        CounterFile::new(tmp.path().join("accepted_counter"))
            .load()
            .unwrap(),
        41
    );
    std::fs::write(tmp.path().join("accepted_counter"), "x").unwrap();
    assert!(file.load().is_err());
}

#[test]
fn the_robot_dir_keeps_its_layout_and_survives_a_reopen() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("state");
    let mut store = RobotDir::open(&dir).unwrap();
    for sub in ["chunks", "plans", "logs"] {
        assert!(dir.join(sub).is_dir(), "{sub}/");
    }
    assert!(store.read_journal().unwrap().is_empty());
    assert!(RobotDir::journal(&dir).unwrap().is_empty());
    store.append_journal(b"{\"event\":\"a\"}\n").unwrap();
    store.append_journal(b"{\"event\":\"b\"}\n").unwrap();
    store.store_counter(7).unwrap();
    store.store_plan("ab12", b"{}").unwrap();
    let log = LogFiles {
        digest: b"digest".to_vec(),
        mcap: b"mcap".to_vec(),
        csv: b"csv".to_vec(),
        meta_json: b"meta".to_vec(),
    };
    store.store_log("ab12", &log).unwrap();
    // A power cut mid-line leaves a torn last line: it is skipped.
    std::fs::OpenOptions::new()
        .append(true)
        .open(dir.join("journal.jsonl"))
        .and_then(|mut f| std::io::Write::write_all(&mut f, b"{\"event\":\"c"))
        .unwrap();

    let mut again = RobotDir::open(&dir).unwrap();
    let events: Vec<_> = RobotDir::journal(&dir)
        .unwrap()
        .iter()
        .map(|l| l["event"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(events, ["a", "b"]);
    assert_eq!(again.load_counter().unwrap(), 7);
    assert_eq!(std::fs::read(dir.join("plans/ab12.json")).unwrap(), b"{}");
    assert_eq!(again.log_mcap("ab12").unwrap(), b"mcap");
    assert_eq!(again.log_digest("ab12").unwrap(), b"digest");
    assert_eq!(
        std::fs::read(dir.join("logs/ab12/log.csv")).unwrap(),
        b"csv"
    );
    assert_eq!(
        std::fs::read(dir.join("logs/ab12/log.meta.json")).unwrap(),
        b"meta"
    );
    let missing = again.log_mcap("cd34").unwrap_err();
    assert!(missing.to_string().contains("cd34"), "{missing}");
}
