//! How close an upload comes to what the link allows: the time until the
//! robot holds the whole file, in virtual time over the emulator, against
//! the ideal `D + S(1+h)/(B(1-p))` (one-way delay D, size S, the chunk
//! header's overhead h, bandwidth B, loss p).

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::emulator::LinkProfile;
use crate::upload::{MemoryStore, Receiver, ReceiverConfig, Sender, SenderConfig};
use crate::vtime::VirtualLink;
use crate::wire;

/// One upload.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trial {
    /// Until the robot held the whole file (s).
    pub time_s: f64,
    /// The ideal for the profile, ignoring its outages (s).
    pub ideal_s: f64,
    pub chunks_resent: u64,
}

/// The ideal upload time of `size` bytes over `profile`, without its
/// outages (s).
pub fn ideal_s(profile: &LinkProfile, size: usize, config: &SenderConfig) -> f64 {
    // Header overhead: a full chunk message, sealed (the header every chunk
    // carries on the link), against its payload.
    let chunk_bytes = wire::link_bytes(&wire::Message {
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
    let h = chunk_bytes as f64 / f64::from(config.chunk_bytes) - 1.0;
    let b = profile.bandwidth_bit_s.unwrap_or(f64::INFINITY);
    profile.latency_s + 8.0 * size as f64 * (1.0 + h) / (b * (1.0 - profile.loss))
}

/// The sender's settings for `profile`: paced at its rate, its round trip
/// and loss as hints.
pub fn sender_config(profile: &LinkProfile) -> SenderConfig {
    SenderConfig {
        pace_bit_s: profile.bandwidth_bit_s,
        rtt_hint_ns: (2.0 * profile.latency_s * 1e9) as u64 + 1,
        loss_hint: profile.loss,
        ..SenderConfig::default()
    }
}

/// Uploads `size` random bytes (from `seed`) over `profile`; `None` if the
/// robot did not hold the file within `give_up_s`.
pub fn upload(profile: &LinkProfile, size: usize, seed: u64, give_up_s: f64) -> Option<Trial> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let file: Vec<u8> = (0..size).map(|_| rng.random::<u8>()).collect();
    let config = sender_config(profile);
    let mut sender = Sender::new("rover", file, config);
    // The robot's own receiver settings.
    let mut receiver = Receiver::new("rover", MemoryStore::default(), ReceiverConfig::default());
    // Sealed as over zenoh.
    let (master_end, robot_end) = crate::secure::memory_pair(
        &crate::secure::key_from_seed(seed, 0),
        &crate::secure::key_from_seed(seed, 1),
        "rover",
    );
    let mut net = VirtualLink::symmetric(profile, seed).sealed(master_end, robot_end);
    let until = (give_up_s * 1e9) as u64;
    // Done when the robot holds the whole file (the master hears so one
    // delay later).
    if !net.run(&mut sender, &mut receiver, until, |_, r| r.is_complete()) {
        return None;
    }
    Some(Trial {
        time_s: net.now_ns as f64 * 1e-9,
        ideal_s: ideal_s(profile, size, &config),
        chunks_resent: sender.stats.chunks_resent,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lossless_upload_is_close_to_the_ideal() {
        let profile = LinkProfile::named("satellite-lossy").unwrap();
        let mut clean = profile.clone();
        clean.loss = 0.0;
        let t = upload(&clean, 100_000, 1, 1e4).unwrap();
        assert!(t.time_s >= t.ideal_s * 0.97, "{t:?}");
        assert!(t.time_s <= t.ideal_s * 1.1, "{t:?}");
        assert_eq!(t.chunks_resent, 0);
    }
}

#[cfg(test)]
mod targets {
    use super::*;
    use crate::emulator::Outage;

    fn mean_ratio(profile: &LinkProfile, size: usize) -> f64 {
        (0..3)
            .map(|seed| {
                let t = upload(profile, size, seed, 1e5).expect("completes");
                t.time_s / t.ideal_s
            })
            .sum::<f64>()
            / 3.0
    }

    #[test]
    fn the_case_study_plan_uploads_within_a_tenth_of_the_ideal_at_ten_percent_loss() {
        for name in ["satellite-lossy", "lunar"] {
            let mut p = LinkProfile::named(name).unwrap();
            p.loss = 0.1;
            let r = mean_ratio(&p, 140_339);
            assert!(r <= 1.1, "{name}: {r:.3}x the ideal");
        }
    }

    #[test]
    fn an_upload_completes_at_thirty_percent_loss_and_through_an_outage() {
        let mut p = LinkProfile::named("lunar").unwrap();
        p.loss = 0.3;
        assert!(upload(&p, 140_339, 1, 1e4).is_some());
        p.loss = 0.1;
        let ideal = ideal_s(&p, 140_339, &sender_config(&p));
        p.outages.push(Outage {
            start_s: 0.5 * ideal,
            end_s: 0.5 * ideal + 60.0,
        });
        let t = upload(&p, 140_339, 1, 1e4).expect("completes after the outage");
        assert!(t.time_s > ideal + 60.0 - 1.0, "{t:?}");
        assert!(t.time_s < ideal + 60.0 + 3.0 * 2.56 + 5.0, "{t:?}");
    }
}
