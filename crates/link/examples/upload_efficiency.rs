//! Upload completion time in virtual time against the ideal
//! `D + S(1+h)/(B(1-p))` (one-way delay D, size S, header overhead h,
//! bandwidth B, loss p), over each named profile and a grid of losses.
//!
//! `cargo run --release -p twindrive-link --example upload_efficiency -- [--smoke] [--seeds N]`
//!
//! Sizes: 140 kB (the signed case-study plan, 2.1 kB per second of
//! mission), 450 kB (the same plan as compressed JSON) and 24 MB (a one-hour
//! plan at 6.6 kB/s, the JSON rate: a bound). Prints one row per profile, loss and size:
//! the mean time until the robot holds the whole file, over the seeds; the
//! ideal; and their ratio.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twindrive_link::emulator::{LinkEmulator, LinkProfile, Outage};
use twindrive_link::upload::{MemoryStore, Receiver, ReceiverConfig, Sender, SenderConfig};
use twindrive_link::vtime::VirtualLink;
use twindrive_link::wire;

fn run(profile: &LinkProfile, size: usize, seed: u64) -> Option<(f64, f64)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let file: Vec<u8> = (0..size).map(|_| rng.random::<u8>()).collect();
    let config = SenderConfig {
        pace_bit_s: profile.bandwidth_bit_s,
        rtt_hint_ns: (2.0 * profile.latency_s * 1e9) as u64 + 1,
        loss_hint: profile.loss,
        ..SenderConfig::default()
    };
    let mut sender = Sender::new("rover", file, config);
    let mut receiver = Receiver::new(
        "rover",
        MemoryStore::default(),
        ReceiverConfig {
            // NAK gaps about once a round trip.
            nak_interval_ns: ((2.0 * profile.latency_s * 1e9) as u64).max(50_000_000),
            ..ReceiverConfig::default()
        },
    );
    let mut net = VirtualLink::new(
        LinkEmulator::new(profile.clone(), seed, 0),
        LinkEmulator::new(profile.clone(), seed, 1),
    );
    let until = 100_000 * 1_000_000_000u64;
    // Done when the robot holds the whole file (the master hears so one
    // delay later).
    if !net.run(&mut sender, &mut receiver, until, |_, r| r.is_complete()) {
        return None;
    }
    // Header overhead: a full chunk message against its payload.
    let chunk = wire::encode(&wire::Message {
        version: wire::PROTOCOL_VERSION,
        robot_id: "rover".into(),
        seq: 1 << 20,
        t_ns: 1 << 40,
        body: wire::Body::Chunk {
            transfer: [0; 32],
            index: 1 << 14,
            crc32: u32::MAX,
            data: vec![0; config.chunk_bytes as usize],
        },
    });
    let h = chunk.len() as f64 / f64::from(config.chunk_bytes) - 1.0;
    let b = profile.bandwidth_bit_s.unwrap_or(f64::INFINITY);
    let ideal = profile.latency_s + 8.0 * size as f64 * (1.0 + h) / (b * (1.0 - profile.loss));
    Some((net.now_ns as f64 * 1e-9, ideal))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let smoke = args.iter().any(|a| a == "--smoke");
    let seeds: u64 = args
        .iter()
        .position(|a| a == "--seeds")
        .and_then(|k| args.get(k + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(if smoke { 1 } else { 3 });
    let sizes: &[(usize, &str)] = if smoke {
        &[(20_000, "20 kB")]
    } else {
        &[
            (140_000, "case study 140 kB"),
            (450_000, "450 kB"),
            (24_000_000, "one hour 24 MB"),
        ]
    };
    let profiles = ["lan", "wifi", "satellite-lossy", "lunar"];
    println!(
        "{:<18} {:>6} {:<18} {:>12} {:>12} {:>7}",
        "profile", "loss", "size", "time (s)", "ideal (s)", "ratio"
    );
    for name in profiles {
        for loss in [0.0, 0.01, 0.1, 0.3] {
            let mut profile = LinkProfile::named(name).expect("named profile");
            profile.loss = loss;
            for &(size, label) in sizes {
                if smoke && loss > 0.1 {
                    continue;
                }
                let mut total = (0.0, 0.0);
                for seed in 0..seeds {
                    match run(&profile, size, seed) {
                        Some((t, ideal)) => {
                            total.0 += t;
                            total.1 += ideal;
                        }
                        None => {
                            eprintln!("{name} loss {loss} {label} seed {seed}: did not complete");
                            std::process::exit(1);
                        }
                    }
                }
                let (t, ideal) = (total.0 / seeds as f64, total.1 / seeds as f64);
                println!(
                    "{name:<18} {:>5.0}% {label:<18} {t:>12.2} {ideal:>12.2} {:>6.2}x",
                    loss * 100.0,
                    t / ideal
                );
            }
        }
    }
    // Through a 60 s outage in the middle of a lunar upload.
    let mut profile = LinkProfile::named("lunar").expect("named profile");
    profile.loss = 0.1;
    profile.outages.push(Outage {
        start_s: 5.0,
        end_s: 65.0,
    });
    let size = if smoke { 20_000 } else { 450_000 };
    match run(&profile, size, 0) {
        Some((t, ideal)) => println!(
            "lunar, 10 % loss, 60 s outage from 5 s, {size} bytes: {t:.2} s (ideal without the outage {ideal:.2} s)"
        ),
        None => {
            eprintln!("the upload through the outage did not complete");
            std::process::exit(1);
        }
    }
}
