//! Any bytes decode to a message or an error, never a panic: 100,000 random
//! byte strings and 100,000 mutations of real messages of every kind. And
//! any bytes given to a receiving end are opened or refused, never a panic
//! and never accepted unless genuine: the same again, sealed.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twindrive_link::secure::{key_from_seed, memory_pair};
use twindrive_link::wire::{
    self, Body, DetourReport, Handback, Offer, PlanPhase, Stamper, Status, WindowSample,
};

fn samples() -> Vec<Vec<u8>> {
    let mut s = Stamper::new("rover-7");
    let t = [9u8; 32];
    let bodies = vec![
        Body::Offer(Offer {
            transfer: t,
            size: 450_000,
            chunk_size: 1024,
            fec_from: 0,
            fec_repairs: 0,
        }),
        Body::Chunk {
            transfer: t,
            index: 17,
            crc32: 0xdead_beef,
            data: (0..1024).map(|k| k as u8).collect(),
        },
        Body::EndOfFile { transfer: t },
        Body::Nak {
            transfer: t,
            received: 100,
            upto: 300,
            missing: vec![(3, 9), (200, 250)],
        },
        Body::Finished { transfer: t },
        Body::Refused {
            transfer: t,
            reason: "too large".into(),
        },
        Body::Heartbeat {
            telemetry_budget_bytes_s: 8_000,
            backfill_bytes_s: 32_000,
        },
        Body::Ping { nonce: 77 },
        Body::Pong { nonce: 77 },
        Body::Status(Box::new(Status {
            plan: Some((
                t,
                PlanPhase::Stopped {
                    reason: "dead_man".into(),
                },
            )),
            progress: (10, 20),
            plan_t_s: 3.5,
            pose: [1.0, 2.0, 0.5],
            params: [0.065, 0.066, 0.27],
            params_std: [1e-4; 3],
            deviation_m: 0.02,
            range_residual_m: f64::NAN,
            wheel_travel_rad: 12.0,
            logs_pending: 1,
            handback_pending: false,
            bumps: 2,
            collisions: 0,
            refused: 3,
            deviation_now_m: 0.01,
            max_deviation_on_detour: true,
            on_detour: false,
        })),
        Body::Handback(Box::new(Handback {
            plan: t,
            reason: "range_residual".into(),
            plan_t_s: 8.0,
            progress: 700,
            pose: [1.7, 0.7, -2.0],
            pose_covariance: [1e-4; 9],
            params: [0.065, 0.066, 0.27],
            params_covariance: [1e-8; 9],
            window: vec![
                WindowSample {
                    plan_t_s: 7.9,
                    pose: [1.7, 0.7, -2.0],
                    ranges_m: vec![0.3, f32::NAN],
                    bump: false,
                };
                20
            ],
        })),
        Body::HandbackAck { plan: t },
        Body::Detour(Box::new(DetourReport {
            plan: t,
            index: 2,
            plan_t_s: 31.5,
            from: [1.2, 0.9, 3.1],
            from_sample: 3150,
            waypoints: vec![[1.2, 0.9], [1.6, 0.6], [2.4, 0.6]],
            rejoin: 3600,
            obstacle: vec![[1.9, 1.0]; 40],
            rejoined: true,
            extra_s: 7.5,
            extra_m: 0.4,
        })),
        Body::DetourAck {
            plan: t,
            index: 2,
            rejoined: true,
        },
    ];
    bodies
        .into_iter()
        .enumerate()
        .map(|(k, b)| wire::encode(&s.stamp(b, k as u64 * 1_000)))
        .collect()
}

#[test]
fn random_and_mutated_bytes_never_panic_the_decoder() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x7717);
    let real = samples();
    for m in &real {
        assert!(wire::decode(m).is_ok());
    }
    let mut decoded = 0;
    for _ in 0..100_000 {
        let len = rng.random_range(0..300);
        let bytes: Vec<u8> = (0..len).map(|_| rng.random()).collect();
        decoded += usize::from(wire::decode(&bytes).is_ok());
    }
    for k in 0..100_000 {
        let bytes = mutated(&mut rng, &real[k % real.len()]);
        decoded += usize::from(wire::decode(&bytes).is_ok());
    }
    // Most garbage is refused; what decodes is a well-formed message.
    assert!(decoded < 100_000, "{decoded} of 200,000 decoded");
}

/// `real`, changed: bytes flipped, cut short, garbage inserted, or huge
/// varint lengths where lengths live.
fn mutated(rng: &mut ChaCha8Rng, real: &[u8]) -> Vec<u8> {
    let mut bytes = real.to_vec();
    {
        match rng.random_range(0..4) {
            // Flip bytes.
            0 => {
                for _ in 0..rng.random_range(1..8) {
                    let i = rng.random_range(0..bytes.len());
                    bytes[i] ^= rng.random::<u8>() | 1;
                }
            }
            // Cut short.
            1 => bytes.truncate(rng.random_range(0..bytes.len())),
            // Insert garbage.
            2 => {
                let i = rng.random_range(0..=bytes.len());
                let extra: Vec<u8> = (0..rng.random_range(1..16)).map(|_| rng.random()).collect();
                bytes.splice(i..i, extra);
            }
            // Huge varint lengths where lengths live.
            _ => {
                let i = rng.random_range(0..bytes.len());
                bytes[i] = 0xff;
                if i + 1 < bytes.len() {
                    bytes[i + 1] = 0xff;
                }
            }
        }
    }
    bytes
}

#[test]
fn random_and_altered_sealed_bytes_never_panic_the_receiver_and_none_is_accepted() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5ea1);
    let (master, robot) = (key_from_seed(3, 0), key_from_seed(3, 1));
    let (mut master_end, mut robot_end) = memory_pair(&master, &robot, "rover-7");
    let sealed: Vec<Vec<u8>> = samples()
        .iter()
        .map(|m| master_end.seal(m).unwrap())
        .collect();
    let mut accepted = 0;
    for _ in 0..100_000 {
        let len = rng.random_range(0..300);
        let bytes: Vec<u8> = (0..len).map(|_| rng.random()).collect();
        accepted += usize::from(robot_end.open(&bytes).is_ok());
    }
    for k in 0..100_000 {
        let original = &sealed[k % sealed.len()];
        let bytes = mutated(&mut rng, original);
        if bytes != *original {
            accepted += usize::from(robot_end.open(&bytes).is_ok());
        }
    }
    assert_eq!(accepted, 0, "forged or altered payloads accepted");
    // None of it touched the receiver: the genuine ones open, once, and
    // decode to what was sent.
    for (s, plain) in sealed.iter().zip(samples()) {
        assert_eq!(robot_end.open(s).unwrap(), plain);
        assert!(robot_end.open(s).is_err());
    }
}
