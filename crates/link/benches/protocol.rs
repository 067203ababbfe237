//! The protocol's state machines without a network: a whole upload through
//! an ideal virtual link (chunks per second through sender and receiver
//! together), and one chunk message encoded and decoded, and also sealed
//! and opened as on the link.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use twindrive_link::emulator::{LinkEmulator, LinkProfile};
use twindrive_link::secure::{key_from_seed, memory_pair};
use twindrive_link::upload::{MemoryStore, Receiver, ReceiverConfig, Sender, SenderConfig};
use twindrive_link::vtime::VirtualLink;
use twindrive_link::wire::{self, Body, Stamper};

fn upload(c: &mut Criterion) {
    let file: Vec<u8> = (0..4_000_000u32).map(|k| (k * 31 % 253) as u8).collect();
    let chunks = file.len().div_ceil(1024) as u64;
    let mut g = c.benchmark_group("upload");
    g.throughput(Throughput::Elements(chunks));
    g.sample_size(10);
    for (name, loss) in [("4 MB, ideal link", 0.0), ("4 MB, 10 % loss", 0.1)] {
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut profile = LinkProfile::ideal();
                profile.loss = loss;
                profile.latency_s = 0.01;
                let mut net = VirtualLink::new(
                    LinkEmulator::new(profile.clone(), 1, 0),
                    LinkEmulator::new(profile, 1, 1),
                );
                let mut sender = Sender::new(
                    "rover",
                    file.clone(),
                    SenderConfig {
                        rtt_hint_ns: 20_000_000,
                        loss_hint: loss,
                        ..SenderConfig::default()
                    },
                );
                let mut receiver =
                    Receiver::new("rover", MemoryStore::default(), ReceiverConfig::default());
                assert!(
                    net.run(&mut sender, &mut receiver, 3_600_000_000_000, |s, _| s
                        .is_finished())
                );
                black_box(sender.stats.chunks_sent)
            })
        });
    }
    g.finish();
}

fn wire_codec(c: &mut Criterion) {
    let mut stamper = Stamper::new("rover");
    let message = stamper.stamp(
        Body::Chunk {
            transfer: [3; 32],
            index: 1234,
            crc32: 99,
            data: vec![7; 1024],
        },
        42,
    );
    let mut g = c.benchmark_group("wire");
    g.throughput(Throughput::Elements(1));
    g.bench_function("encode + decode a 1 KiB chunk", |b| {
        b.iter(|| {
            let bytes = wire::encode(black_box(&message));
            black_box(wire::decode(&bytes).unwrap())
        })
    });
    // As on the link: encoded, sealed by the master, opened by the robot
    // (which refuses a replay: each sealing is new).
    let (mut master, mut robot) =
        memory_pair(&key_from_seed(1, 0), &key_from_seed(1, 1), "rover-1");
    g.bench_function("encode, seal, open + decode a 1 KiB chunk", |b| {
        b.iter(|| {
            let sealed = master.seal(&wire::encode(black_box(&message))).unwrap();
            black_box(wire::decode(&robot.open(&sealed).unwrap()).unwrap())
        })
    });
    g.finish();
}

criterion_group!(benches, upload, wire_codec);
criterion_main!(benches);
