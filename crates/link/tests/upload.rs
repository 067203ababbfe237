//! The upload in virtual time over emulated links: bytes identical after
//! loss, an outage, corrupted chunks and restarts of either side; and the
//! decoder against random and mutated bytes.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twindrive_link::emulator::{LinkProfile, Outage};
use twindrive_link::upload::{
    ChunkStore, MemoryStore, Receiver, ReceiverConfig, ReceiverEvent, Sender, SenderConfig,
};
use twindrive_link::vtime::VirtualLink;
use twindrive_link::wire::{self, Body, Stamper};

const S: u64 = 1_000_000_000;

fn file(len: usize, seed: u64) -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..len).map(|_| rng.random::<u8>()).collect()
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
fn a_lossy_upload_with_an_outage_arrives_byte_identical() {
    for seed in 0..4 {
        let mut profile: LinkProfile = "lunar,loss=0.1".parse().unwrap();
        profile.outages.push(Outage {
            start_s: 3.0,
            end_s: 9.0,
        });
        let data = file(200_000, seed);
        let mut sender = Sender::new("rover", data.clone(), sender_config(&profile));
        let mut receiver =
            Receiver::new("rover", MemoryStore::default(), ReceiverConfig::default());
        let mut net = VirtualLink::symmetric(&profile, seed);
        let mut got = None;
        let done = net.run(&mut sender, &mut receiver, 3_600 * S, |s, _| {
            s.is_finished()
        });
        completed(&mut receiver, &mut got);
        assert!(done, "seed {seed}: not finished by {} s", net.now_ns / S);
        assert_eq!(got.as_deref(), Some(&data[..]), "seed {seed}");
        assert!(
            sender.stats.chunks_resent > 0,
            "seed {seed}: {:?}",
            sender.stats
        );
        // 200 kB at 256 kbit/s is 6.3 s on the wire; with 10 % loss, a six
        // second outage and 1.28 s each way it still ends within a minute.
        assert!(
            net.now_ns < 60 * S,
            "seed {seed}: {} s",
            net.now_ns as f64 / 1e9
        );
    }
}

#[test]
fn restarts_of_either_side_resume_without_losing_or_repeating() {
    let profile: LinkProfile = "satellite-lossy,loss=0.1".parse().unwrap();
    let data = file(150_000, 9);
    // Clones share what the store holds: a restarted receiver finds it.
    let kept = MemoryStore::default();
    let store = || kept.clone();
    let mut net = VirtualLink::symmetric(&profile, 3);
    let mut got = None;

    let mut sender = Sender::new("rover", data.clone(), sender_config(&profile));
    let mut receiver = Receiver::new("rover", store(), ReceiverConfig::default());
    // Part of the way, then the robot process dies and comes back.
    assert!(!net.run(&mut sender, &mut receiver, S / 2, |s, _| s.is_finished()));
    let offer = store().pending().unwrap().expect("a transfer in progress");
    let held_before = store().open(&offer).unwrap().iter().filter(|&&h| h).count();
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
    assert_eq!(store().pending().unwrap(), None);
}

#[test]
fn a_receiver_that_forgot_the_transfer_still_gets_the_whole_file() {
    // The sender has been answered and streams chunks when its receiver is
    // replaced by one that never heard the offer (a master started again
    // with another output directory while a robot back-fills its log):
    // chunks and end-of-files alone would go unheard forever. The sender
    // offers again when an end-of-file goes unanswered.
    for (profile, seed) in [("lan", 1), ("satellite-lossy,loss=0.2", 2), ("lunar", 3)] {
        let profile: LinkProfile = profile.parse().unwrap();
        let data = file(120_000, seed);
        let mut net = VirtualLink::symmetric(&profile, seed);
        let mut sender = Sender::resume("rover", data.clone(), sender_config(&profile));
        let mut first = Receiver::new("rover", MemoryStore::default(), ReceiverConfig::default());
        // A quarter of the way.
        assert!(net.run(&mut sender, &mut first, 600 * S, |s, _| {
            s.stats.chunks_confirmed > s.stats.chunks / 4
        }));
        assert!(!sender.is_finished(), "{profile:?}: {:?}", sender.stats);
        drop(first);
        net.drop_in_flight();
        let mut second = Receiver::new("rover", MemoryStore::default(), ReceiverConfig::default());
        let mut got = None;
        assert!(
            net.run(&mut sender, &mut second, 600 * S, |s, _| s.is_finished()),
            "{profile:?}: {:?}",
            sender.stats
        );
        completed(&mut second, &mut got);
        assert_eq!(got.as_deref(), Some(&data[..]), "{profile:?}");
        assert!(sender.stats.reoffers > 0, "{profile:?}: {:?}", sender.stats);
    }
}

#[test]
fn corrupted_chunks_are_dropped_and_asked_for_again() {
    let profile: LinkProfile = "wifi".parse().unwrap();
    let data = file(80_000, 5);
    let mut sender = Sender::new("rover", data.clone(), sender_config(&profile));
    let mut receiver = Receiver::new("rover", MemoryStore::default(), ReceiverConfig::default());
    let mut net = VirtualLink::symmetric(&profile, 11);
    // Flip a byte in every 7th message's tail on the way up.
    let mut n = 0u64;
    net.tamper_up = Some(Box::new(move |bytes: &mut Vec<u8>| {
        n += 1;
        if n.is_multiple_of(7) {
            let last = bytes.len() - 1;
            bytes[last] ^= 0x5a;
        }
    }));
    let mut corrupted = 0;
    let mut got = None;
    assert!(net.run(&mut sender, &mut receiver, 600 * S, |s, _| s.is_finished()));
    while let Some(e) = receiver.poll_event() {
        match e {
            ReceiverEvent::Corrupted { .. } => corrupted += 1,
            ReceiverEvent::Completed { file, .. } => got = Some(file),
            _ => {}
        }
    }
    assert!(corrupted > 5, "{corrupted} corrupted chunks seen");
    assert_eq!(got.as_deref(), Some(&data[..]));
}

#[test]
fn an_offer_above_the_size_cap_is_refused_before_any_chunk() {
    let profile = LinkProfile::ideal();
    let data = file(10_000, 1);
    let mut sender = Sender::new("rover", data, sender_config(&profile));
    let config = ReceiverConfig {
        max_file_bytes: 5_000,
        ..ReceiverConfig::default()
    };
    let store = MemoryStore::default();
    let mut receiver = Receiver::new("rover", store, config);
    let mut net = VirtualLink::symmetric(&profile, 1);
    net.run(&mut sender, &mut receiver, 10 * S, |s, _| {
        s.refused().is_some()
    });
    assert!(
        sender
            .refused()
            .unwrap()
            .contains("more than the 5000 accepted")
    );
    assert!(matches!(
        receiver.poll_event(),
        Some(ReceiverEvent::Refused { .. })
    ));
}

#[test]
fn random_and_mutated_bytes_never_panic_the_decoder_or_the_endpoints() {
    let mut rng = ChaCha8Rng::seed_from_u64(2026);
    let mut stamper = Stamper::new("rover");
    let valid: Vec<Vec<u8>> = [
        Body::Offer(wire::Offer {
            transfer: [1; 32],
            size: 5_000,
            chunk_size: 1024,
            fec_from: 0,
            fec_repairs: 0,
        }),
        Body::Chunk {
            transfer: [1; 32],
            index: 2,
            crc32: crc(&[9; 1024]),
            data: vec![9; 1024],
        },
        Body::EndOfFile { transfer: [1; 32] },
        Body::Nak {
            transfer: [1; 32],
            received: 3,
            upto: 5,
            missing: vec![(0, 1), (4, 4)],
        },
        Body::Finished { transfer: [1; 32] },
        Body::Refused {
            transfer: [1; 32],
            reason: "no".into(),
        },
    ]
    .into_iter()
    .map(|b| wire::encode(&stamper.stamp(b, 5)))
    .collect();
    let mut sender = Sender::new("rover", file(5_000, 1), SenderConfig::default());
    let mut receiver = Receiver::new("rover", MemoryStore::default(), ReceiverConfig::default());
    let (mut decoded, mut refused) = (0, 0);
    for k in 0..120_000u64 {
        let bytes: Vec<u8> = match k % 3 {
            0 => {
                let len = rng.random_range(0..200);
                (0..len).map(|_| rng.random::<u8>()).collect()
            }
            1 => {
                let mut b = valid[rng.random_range(0..valid.len())].clone();
                for _ in 0..rng.random_range(1..6) {
                    let i = rng.random_range(0..b.len());
                    b[i] = rng.random::<u8>();
                }
                b
            }
            _ => {
                let mut b = valid[rng.random_range(0..valid.len())].clone();
                let cut = rng.random_range(0..b.len());
                b.truncate(cut);
                b.extend((0..rng.random_range(0..20)).map(|_| rng.random::<u8>()));
                b
            }
        };
        match wire::decode(&bytes) {
            Ok(m) => {
                decoded += 1;
                sender.handle(&m, k);
                receiver.handle(&m, k);
                while sender.poll_transmit(k).is_some() {}
                while receiver.poll_transmit(k).is_some() {}
                while receiver.poll_event().is_some() {}
            }
            Err(_) => refused += 1,
        }
    }
    assert!(
        decoded > 1_000 && refused > 50_000,
        "{decoded} decoded, {refused} refused"
    );
}

fn crc(data: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(data);
    h.finalize()
}

/// Chunks lost at the end of the file are rebuilt from the repair shards
/// that follow them: no chunk is sent twice, no round trip is waited for.
#[test]
fn repair_shards_rebuild_a_lost_tail_without_a_round_trip() {
    let profile: LinkProfile = "lunar,loss=0".parse().unwrap();
    let data = file(140_000, 9);
    let mut net = VirtualLink::symmetric(&profile, 3);
    // Every fifth chunk of the last forty is corrupted in flight (dropped).
    net.tamper_up = Some(Box::new(|bytes: &mut Vec<u8>| {
        if let Ok(m) = wire::decode(bytes)
            && let Body::Chunk { index, .. } = m.body
            && index >= 97
            && index % 5 == 0
        {
            let n = bytes.len();
            bytes[n - 1] ^= 0xff;
        }
    }));
    let config = SenderConfig {
        loss_hint: 0.1,
        ..sender_config(&profile)
    };
    let mut sender = Sender::new("rover", data.clone(), config);
    let mut receiver = Receiver::new("rover", MemoryStore::default(), ReceiverConfig::default());
    assert!(net.run(&mut sender, &mut receiver, 600 * S, |_, r| r.is_complete()));
    let mut got = None;
    completed(&mut receiver, &mut got);
    assert_eq!(got.unwrap(), data);
    assert!(sender.stats.repairs_sent > 8);
    assert_eq!(sender.stats.chunks_resent, 0);
    // The stream and its repairs, one way: well under a round trip more.
    let stream_s = 8.0 * (140_000.0 + 1_100.0 * sender.stats.repairs_sent as f64) * 1.07
        / profile.bandwidth_bit_s.unwrap();
    let took = net.now_ns as f64 * 1e-9;
    assert!(
        took < stream_s + profile.latency_s + 0.5,
        "{took} s against {stream_s} s"
    );
}
