//! A userspace link emulator: one-way latency, jitter, loss, a bandwidth
//! cap and scheduled outages, deterministic under a seed.
//!
//! One [`LinkEmulator`] models one direction. A message handed to it at
//! time `t` waits for the transmitter (messages leave one after another at
//! the bandwidth cap, each taking `8 · bytes / bandwidth`), then flies for
//! the latency plus a jitter drawn uniformly from `±jitter`; it is lost
//! with the loss probability, or when it would leave during an outage. The
//! emulator only computes *when* a message arrives: the caller (a virtual
//! time loop, or a transport that sleeps until then) delivers it. Time is
//! an argument everywhere, in nanoseconds.

use std::fmt;
use std::str::FromStr;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Link characteristics, one direction (both directions use the same).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkProfile {
    pub name: String,
    /// One-way propagation delay.
    pub latency_s: f64,
    /// Half-width of the uniform jitter added to the latency.
    pub jitter_s: f64,
    /// Probability that a message is lost.
    pub loss: f64,
    /// Transmit rate; `None`: unlimited.
    pub bandwidth_bit_s: Option<f64>,
    /// Times (from the start of the run) when nothing gets through.
    pub outages: Vec<Outage>,
    /// Probability that a message arrives with a byte changed (bit errors
    /// the link layer did not catch).
    #[serde(default)]
    pub corrupt: f64,
}

/// `[start_s, end_s)`: messages that would leave then are lost.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Outage {
    pub start_s: f64,
    pub end_s: f64,
}

/// Why a link description was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProfileError {
    #[error(
        "unknown link profile `{0}`: expected lan, wifi, satellite-lossy, lunar, mars-relay or key=value pairs (latency_s, jitter_s, loss, bandwidth_bit_s, corrupt, outage=START..END)"
    )]
    Unknown(String),
    #[error("link profile field `{field}`: {message}")]
    Field { field: String, message: String },
}

impl LinkProfile {
    /// A perfect link: no delay, no loss, no cap.
    pub fn ideal() -> Self {
        Self::new("ideal", 0.0, 0.0, 0.0, None)
    }

    fn new(name: &str, latency_s: f64, jitter_s: f64, loss: f64, bandwidth: Option<f64>) -> Self {
        Self {
            name: name.into(),
            latency_s,
            jitter_s,
            loss,
            bandwidth_bit_s: bandwidth,
            outages: Vec::new(),
            corrupt: 0.0,
        }
    }

    /// The named profiles.
    pub fn named(name: &str) -> Option<Self> {
        Some(match name {
            // Wired LAN: sub-millisecond, clean, 100 Mbit/s.
            "lan" => Self::new(name, 0.0005, 0.0001, 0.0, Some(100e6)),
            // Wi-Fi at the edge of its range.
            "wifi" => Self::new(name, 0.005, 0.003, 0.01, Some(20e6)),
            // A GEO satellite hop: ~300 ms one way, a few % loss, 1 Mbit/s.
            "satellite-lossy" => Self::new(name, 0.3, 0.02, 0.03, Some(1e6)),
            // Earth-Moon: 1.28 s one way, 256 kbit/s, some loss.
            "lunar" => Self::new(name, 1.28, 0.01, 0.02, Some(256e3)),
            // Earth-Mars through a relay orbiter: minutes one way, kbit/s.
            "mars-relay" => Self::new(name, 720.0, 1.0, 0.05, Some(8e3)),
            _ => return None,
        })
    }

    /// Checks every value; the error names the field.
    pub fn validate(&self) -> Result<(), ProfileError> {
        let bad = |field: &str, message: String| ProfileError::Field {
            field: field.into(),
            message,
        };
        for (field, v) in [("latency_s", self.latency_s), ("jitter_s", self.jitter_s)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(field, format!("must be a finite number >= 0, got {v}")));
            }
        }
        if self.jitter_s > self.latency_s {
            return Err(bad(
                "jitter_s",
                format!(
                    "must not exceed latency_s ({}), got {}",
                    self.latency_s, self.jitter_s
                ),
            ));
        }
        if !(0.0..1.0).contains(&self.corrupt) {
            return Err(bad(
                "corrupt",
                format!("must be in [0, 1), got {}", self.corrupt),
            ));
        }
        if !(0.0..1.0).contains(&self.loss) {
            return Err(bad("loss", format!("must be in [0, 1), got {}", self.loss)));
        }
        if let Some(b) = self.bandwidth_bit_s
            && !(b.is_finite() && b > 0.0)
        {
            return Err(bad(
                "bandwidth_bit_s",
                format!("must be a finite number > 0, got {b}"),
            ));
        }
        for (k, o) in self.outages.iter().enumerate() {
            if !(o.start_s.is_finite() && o.end_s.is_finite() && o.start_s < o.end_s) {
                return Err(bad(
                    &format!("outages[{k}]"),
                    format!("needs start_s < end_s, got {}..{}", o.start_s, o.end_s),
                ));
            }
        }
        Ok(())
    }
}

impl FromStr for LinkProfile {
    type Err = ProfileError;

    /// A named profile, optionally followed by overrides, or overrides
    /// alone: `lunar`, `lunar,loss=0.1,outage=30..90`,
    /// `latency_s=0.05,bandwidth_bit_s=1e6`.
    fn from_str(text: &str) -> Result<Self, ProfileError> {
        let mut parts = text.split(',').map(str::trim).filter(|p| !p.is_empty());
        let mut profile = LinkProfile::ideal();
        profile.name = "custom".into();
        let mut first = true;
        for part in parts.by_ref() {
            let Some((key, value)) = part.split_once('=') else {
                if first && let Some(named) = LinkProfile::named(part) {
                    profile = named;
                    first = false;
                    continue;
                }
                return Err(ProfileError::Unknown(part.into()));
            };
            first = false;
            let number = |v: &str| {
                v.trim().parse::<f64>().map_err(|e| ProfileError::Field {
                    field: key.into(),
                    message: format!("`{v}` is not a number: {e}"),
                })
            };
            match key.trim() {
                "latency_s" => profile.latency_s = number(value)?,
                "jitter_s" => profile.jitter_s = number(value)?,
                "loss" => profile.loss = number(value)?,
                "bandwidth_bit_s" => profile.bandwidth_bit_s = Some(number(value)?),
                "corrupt" => profile.corrupt = number(value)?,
                "outage" => {
                    let (a, b) = value.split_once("..").ok_or_else(|| ProfileError::Field {
                        field: "outage".into(),
                        message: format!("expected START..END in seconds, got `{value}`"),
                    })?;
                    profile.outages.push(Outage {
                        start_s: number(a)?,
                        end_s: number(b)?,
                    });
                }
                other => return Err(ProfileError::Unknown(other.into())),
            }
        }
        profile.validate()?;
        Ok(profile)
    }
}

impl fmt::Display for LinkProfile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: {} ms ± {} ms one way, {} % loss, {}",
            self.name,
            self.latency_s * 1e3,
            self.jitter_s * 1e3,
            self.loss * 100.0,
            match self.bandwidth_bit_s {
                Some(b) => format!("{} kbit/s", b / 1e3),
                None => "no bandwidth cap".into(),
            }
        )?;
        for o in &self.outages {
            write!(f, ", outage {}..{} s", o.start_s, o.end_s)?;
        }
        if self.corrupt > 0.0 {
            write!(f, ", {} % corrupted", self.corrupt * 100.0)?;
        }
        Ok(())
    }
}

/// One direction of an emulated link.
#[derive(Debug, Clone)]
pub struct LinkEmulator {
    profile: LinkProfile,
    rng: ChaCha8Rng,
    /// When the transmitter is free again.
    tx_free_ns: u64,
    pub stats: LinkStats,
}

/// What went through one direction.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct LinkStats {
    pub messages_sent: u64,
    pub bytes_sent: u64,
    pub messages_lost: u64,
    pub messages_in_outage: u64,
    pub messages_corrupted: u64,
}

impl LinkEmulator {
    /// `stream` separates the random streams of the two directions (and of
    /// several robots) under one seed.
    pub fn new(profile: LinkProfile, seed: u64, stream: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(stream);
        Self {
            profile,
            rng,
            tx_free_ns: 0,
            stats: LinkStats::default(),
        }
    }

    pub fn profile(&self) -> &LinkProfile {
        &self.profile
    }

    /// A message of `bytes` handed over at `now_ns`: when it arrives, or
    /// `None` if it is lost.
    pub fn send(&mut self, now_ns: u64, bytes: usize) -> Option<u64> {
        let p = &self.profile;
        self.stats.messages_sent += 1;
        self.stats.bytes_sent += bytes as u64;
        let start = now_ns.max(self.tx_free_ns);
        let tx_ns = match p.bandwidth_bit_s {
            Some(b) => (8.0 * bytes as f64 / b * 1e9).round() as u64,
            None => 0,
        };
        let leaves = start + tx_ns;
        self.tx_free_ns = leaves;
        // Draw both numbers whatever happens, so one message's fate does not
        // shift the next one's.
        let lost = self.rng.random::<f64>() < p.loss;
        let jitter = (self.rng.random::<f64>() * 2.0 - 1.0) * p.jitter_s;
        let leaves_s = leaves as f64 * 1e-9;
        if p.outages
            .iter()
            .any(|o| (o.start_s..o.end_s).contains(&leaves_s))
        {
            self.stats.messages_in_outage += 1;
            return None;
        }
        if lost {
            self.stats.messages_lost += 1;
            return None;
        }
        let flight = ((p.latency_s + jitter).max(0.0) * 1e9).round() as u64;
        Some(leaves + flight)
    }

    /// Like [`LinkEmulator::send`], for the message's bytes: with the
    /// profile's `corrupt` probability one byte arrives changed.
    pub fn send_bytes(&mut self, now_ns: u64, bytes: &mut [u8]) -> Option<u64> {
        let at = self.send(now_ns, bytes.len())?;
        if self.profile.corrupt > 0.0 && !bytes.is_empty() {
            let hit = self.rng.random::<f64>() < self.profile.corrupt;
            let at_byte = self.rng.random_range(0..bytes.len());
            let flip = self.rng.random_range(1..=255u8);
            if hit {
                bytes[at_byte] ^= flip;
                self.stats.messages_corrupted += 1;
            }
        }
        Some(at)
    }

    /// When the transmitter will be free: a sender that paces itself waits
    /// until then.
    pub fn tx_free_ns(&self) -> u64 {
        self.tx_free_ns
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profiles_parse_and_check_their_fields() {
        let lunar: LinkProfile = "lunar".parse().unwrap();
        assert_eq!(lunar.latency_s, 1.28);
        let custom: LinkProfile = "lunar,loss=0.1,outage=30..90".parse().unwrap();
        assert_eq!(custom.loss, 0.1);
        assert_eq!(custom.outages.len(), 1);
        let own: LinkProfile = "latency_s=0.05,bandwidth_bit_s=1e6".parse().unwrap();
        assert_eq!(own.bandwidth_bit_s, Some(1e6));
        assert!(matches!(
            "moon".parse::<LinkProfile>(),
            Err(ProfileError::Unknown(_))
        ));
        let err = "lan,loss=1.5".parse::<LinkProfile>().unwrap_err();
        assert!(err.to_string().contains("loss"), "{err}");
        assert!("lan,outage=5..1".parse::<LinkProfile>().is_err());
    }

    #[test]
    fn bandwidth_latency_loss_and_outages_are_what_the_profile_says() {
        let mut p = LinkProfile::new("t", 0.5, 0.0, 0.0, Some(8_000.0));
        p.outages.push(Outage {
            start_s: 10.0,
            end_s: 20.0,
        });
        let mut link = LinkEmulator::new(p, 1, 0);
        // 1000 bytes at 8 kbit/s: one second on the wire, then 0.5 s flight.
        assert_eq!(link.send(0, 1000), Some(1_500_000_000));
        // Queued behind the first.
        assert_eq!(link.send(0, 1000), Some(2_500_000_000));
        // Leaves during the outage: lost.
        assert_eq!(link.send(10_000_000_000, 1000), None);
        assert_eq!(link.stats.messages_in_outage, 1);

        let lossy = LinkProfile::new("l", 0.0, 0.0, 0.1, None);
        let mut link = LinkEmulator::new(lossy.clone(), 7, 0);
        let lost = (0..100_000).filter(|_| link.send(0, 10).is_none()).count();
        assert!((9_000..11_000).contains(&lost), "{lost}");
        // Same seed, same fate.
        let mut a = LinkEmulator::new(lossy.clone(), 7, 3);
        let mut b = LinkEmulator::new(lossy, 7, 3);
        for k in 0..1000 {
            assert_eq!(a.send(k, 10), b.send(k, 10));
        }
    }
}
