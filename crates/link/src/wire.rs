//! Messages between master and robot, and their bytes.
//!
//! Every message carries the protocol version, the robot id, a sequence
//! number (per sender, growing) and the sender's time stamp. On the link
//! each is sealed ([`crate::secure`]): these bytes are what a receiver
//! reads once the message has proven where it came from. The encoding is
//! `postcard` (serde, compact varints); [`decode`] takes any bytes and
//! answers with a message or an error, never a panic, and refuses anything
//! longer than [`MAX_MESSAGE_BYTES`] before looking inside.

use serde::{Deserialize, Serialize};

/// Version of this message set; a message of another version is refused
/// (4: the robot reports its detours; 5: its status says its deviation now
/// beside the largest).
pub const PROTOCOL_VERSION: u16 = 5;
/// Nothing longer is decoded.
pub const MAX_MESSAGE_BYTES: usize = 64 * 1024;
/// Longest robot id.
pub const MAX_ROBOT_ID_BYTES: usize = 64;

/// SHA-256 of a transfer's whole file: what identifies it on both sides.
pub type TransferId = [u8; 32];

/// The SHA-256 of a file: its transfer id.
pub fn transfer_id(file: &[u8]) -> TransferId {
    use sha2::{Digest, Sha256};
    Sha256::digest(file).into()
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Message {
    pub version: u16,
    pub robot_id: String,
    /// Per sender, one more for every message it sends.
    pub seq: u64,
    /// The sender's clock when it sent the message, nanoseconds.
    pub t_ns: u64,
    pub body: Body,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Body {
    /// Master → robot: a file is on offer (a new upload, or one resumed).
    Offer(Offer),
    /// Master → robot: one piece of the file.
    Chunk {
        transfer: TransferId,
        index: u32,
        /// CRC-32 of `data`: a corrupted chunk is dropped and asked again.
        crc32: u32,
        data: Vec<u8>,
    },
    /// Master → robot: every chunk has been sent at least once.
    EndOfFile {
        transfer: TransferId,
    },
    /// Robot → master: what it holds and what it still needs: of the
    /// chunks below `upto`, those in `missing` (inclusive index ranges, at
    /// most [`MAX_NAK_RANGES`]; more follow in later NAKs).
    Nak {
        transfer: TransferId,
        received: u32,
        upto: u32,
        missing: Vec<(u32, u32)>,
    },
    /// Robot → master: the whole file arrived and its SHA-256 matches.
    Finished {
        transfer: TransferId,
    },
    /// Master → robot: Reed-Solomon repair shard `index` of the offer's tail
    /// block (any `fec_from..chunks` originals can be rebuilt from as many
    /// shards, originals and repairs together). Sent once, after the block.
    Repair {
        transfer: TransferId,
        index: u32,
        crc32: u32,
        data: Vec<u8>,
    },
    /// Robot → master: the offer is refused (too large, say).
    Refused {
        transfer: TransferId,
        reason: String,
    },
    /// Master → robot: the master is there (a supervised plan's dead-man
    /// counts from the last message heard, of any kind), and the bytes per
    /// second the robot may send it (the robot keeps to the lower of this
    /// and its own limit), and the rate it may back-fill its logs at while
    /// it drives no plan: the link's, as the master paces its own uploads
    /// (0: the master knows no rate; as fast as the link takes them).
    Heartbeat {
        telemetry_budget_bytes_s: u32,
        backfill_bytes_s: u32,
    },
    /// Either way: answer with `Pong` at once (round-trip time).
    Ping {
        nonce: u64,
    },
    Pong {
        nonce: u64,
    },
    /// Robot → master: a live summary, at a low rate.
    Status(Box<Status>),
    /// Robot → master: reality departed from the plan; the robot stopped
    /// and control returns to the operator. Repeated until acknowledged.
    Handback(Box<Handback>),
    /// Master → robot: the hand-back of this plan arrived.
    HandbackAck {
        plan: TransferId,
    },
    /// Master → robot: send the full-rate log (its MCAP as the robot keeps
    /// it, not the digest) of the plan whose document hash is
    /// `plan_sha256` (`MissionPlan::sha256`), after any log already on its
    /// way. Answered by a transfer of it, or by `Refused` with `transfer`
    /// set to `plan_sha256` when the robot keeps none. Sent again until
    /// one of them comes.
    LogRequest {
        plan_sha256: [u8; 32],
    },
    /// Robot → master: the robot went around something the plan's map
    /// lacks, on its own, inside the plan's corridor (when it began, and
    /// when it was back on the plan). Repeated until acknowledged.
    Detour(Box<DetourReport>),
    /// Master → robot: this detour report arrived.
    DetourAck {
        plan: TransferId,
        index: u32,
        rejoined: bool,
    },
}

/// A detour the robot decided on its own.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DetourReport {
    pub plan: TransferId,
    /// Which detour: the robot counts them from 1 since its agent started
    /// (with `plan`, it names one).
    pub index: u32,
    /// Time since the plan started when it began (s), the robot's pose
    /// there (x, y m; heading rad) and the plan sample it left at.
    pub plan_t_s: f64,
    pub from: [f64; 3],
    pub from_sample: u32,
    /// The way it planned (x, y), back onto the plan at sample `rejoin`.
    pub waypoints: Vec<[f32; 2]>,
    pub rejoin: u32,
    /// Where its readings ended on what the map lacks (x, y in the site's
    /// frame), seen from `from` and along the way.
    pub obstacle: Vec<[f32; 2]>,
    /// Back on the plan: what the detour added (s, m).
    pub rejoined: bool,
    pub extra_s: f64,
    pub extra_m: f64,
}

/// Where the robot stands with one plan file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum PlanPhase {
    /// Arriving: chunks held of all.
    Receiving { received: u32, chunks: u32 },
    /// Refused at the gate; no wheel moved.
    Rejected { reason: String },
    /// Accepted and running.
    Executing,
    /// Ran to its end.
    Finished,
    /// Stopped before its end: hand-back, dead-man, or a restart mid-run.
    Stopped { reason: String },
}

/// The robot's live summary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// The plan file (its transfer id) this speaks of, and where it stands.
    pub plan: Option<(TransferId, PlanPhase)>,
    /// Plan samples passed, of all.
    pub progress: (u32, u32),
    /// The robot's time since its plan started (s).
    pub plan_t_s: f64,
    /// Pose estimate: x, y (m), heading (rad).
    pub pose: [f64; 3],
    /// Kinematic estimate: left and right wheel diameters, wheelbase (m),
    /// and their standard deviations.
    pub params: [f64; 3],
    pub params_std: [f64; 3],
    /// The largest distance from the plan's pose since the plan started
    /// (m; NaN while no plan runs).
    pub deviation_m: f64,
    /// The latest median range residual (m).
    pub range_residual_m: f64,
    /// Wheel rotation since the agent started (rad, both wheels).
    pub wheel_travel_rad: f64,
    /// Robot logs not yet acknowledged by the master.
    pub logs_pending: u32,
    /// A hand-back not yet acknowledged (a master that came after it, or
    /// whose first copies were refused, waits to hear it).
    pub handback_pending: bool,
    /// Bumper presses, and contacts that held the robot (where the backend
    /// can tell), since the agent started: each counted once, however many
    /// control periods or plans it lasts.
    pub bumps: u32,
    pub collisions: u32,
    /// Payloads refused before they were read (not authentic, replays)
    /// since the agent started.
    pub refused: u32,
    /// Distance from the plan's pose now (m; NaN while no plan runs).
    pub deviation_now_m: f64,
    /// Whether the robot was on a detour when it was farthest from the plan
    /// (`deviation_m`), and whether it is on one now.
    pub max_deviation_on_detour: bool,
    pub on_detour: bool,
}

/// Why and where the robot handed control back, with what it knows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Handback {
    pub plan: TransferId,
    pub reason: String,
    /// Time since the plan started (s), and plan samples passed.
    pub plan_t_s: f64,
    pub progress: u32,
    /// Pose estimate: x, y (m), heading (rad), in the site's frame (odometry
    /// fused with localization against the plan's map) ...
    pub pose: [f64; 3],
    /// ... and its 3 x 3 covariance (row major).
    pub pose_covariance: [f64; 9],
    /// Wheel diameters and wheelbase (m) with their 3 × 3 covariance (row
    /// major).
    pub params: [f64; 3],
    pub params_covariance: [f64; 9],
    /// The recent sensor window, oldest first.
    pub window: Vec<WindowSample>,
}

/// One moment of the hand-back's sensor window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WindowSample {
    pub plan_t_s: f64,
    pub pose: [f64; 3],
    /// Each range beam's reading taken at this pose (m; NaN: the beam did
    /// not read this period).
    pub ranges_m: Vec<f32>,
    pub bump: bool,
}

/// A transfer on offer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Offer {
    pub transfer: TransferId,
    pub size: u64,
    pub chunk_size: u32,
    /// The chunks from this index to the end form the tail block, which
    /// Reed-Solomon repair shards protect (the number of chunks: none).
    pub fec_from: u32,
    /// Repair shards the sender sends after the tail block, once.
    pub fec_repairs: u32,
}

/// At most this many missing ranges in one NAK.
pub const MAX_NAK_RANGES: usize = 256;

impl Offer {
    /// How many chunks the file has.
    pub fn chunks(&self) -> u32 {
        if self.chunk_size == 0 {
            return 0;
        }
        self.size.div_ceil(u64::from(self.chunk_size)) as u32
    }
}

/// Why bytes are not a message.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    #[error("message of {0} bytes, longer than the {MAX_MESSAGE_BYTES}-byte limit")]
    TooLong(usize),
    #[error("not a twindrive message: {0}")]
    Malformed(String),
    #[error("protocol version {0}, this build speaks {PROTOCOL_VERSION}")]
    Version(u16),
    #[error("robot id of {0} bytes, longer than {MAX_ROBOT_ID_BYTES}")]
    RobotId(usize),
    #[error("{0} trailing bytes after the message")]
    Trailing(usize),
}

/// The bytes of a message.
pub fn encode(message: &Message) -> Vec<u8> {
    postcard::to_allocvec(message).expect("messages always serialise")
}

/// A message's bytes on the link: encoded and sealed
/// ([`crate::secure::OVERHEAD_BYTES`] more). What pacing and budgets count.
pub fn link_bytes(message: &Message) -> usize {
    encode(message).len() + crate::secure::OVERHEAD_BYTES
}

/// A message from any bytes.
pub fn decode(bytes: &[u8]) -> Result<Message, DecodeError> {
    if bytes.len() > MAX_MESSAGE_BYTES {
        return Err(DecodeError::TooLong(bytes.len()));
    }
    let (message, rest): (Message, _) =
        postcard::take_from_bytes(bytes).map_err(|e| DecodeError::Malformed(e.to_string()))?;
    if !rest.is_empty() {
        return Err(DecodeError::Trailing(rest.len()));
    }
    if message.version != PROTOCOL_VERSION {
        return Err(DecodeError::Version(message.version));
    }
    if message.robot_id.len() > MAX_ROBOT_ID_BYTES {
        return Err(DecodeError::RobotId(message.robot_id.len()));
    }
    Ok(message)
}

/// Stamps bodies with one sender's robot id, sequence numbers and times.
#[derive(Debug, Clone)]
pub struct Stamper {
    pub robot_id: String,
    next_seq: u64,
}

impl Stamper {
    pub fn new(robot_id: &str) -> Self {
        Self {
            robot_id: robot_id.into(),
            next_seq: 0,
        }
    }

    pub fn stamp(&mut self, body: Body, now_ns: u64) -> Message {
        let seq = self.next_seq;
        self.next_seq += 1;
        Message {
            version: PROTOCOL_VERSION,
            robot_id: self.robot_id.clone(),
            seq,
            t_ns: now_ns,
            body,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_round_trip_and_garbage_is_an_error() {
        let mut s = Stamper::new("rover-1");
        let m = s.stamp(
            Body::Chunk {
                transfer: [7; 32],
                index: 3,
                crc32: 99,
                data: vec![1, 2, 3],
            },
            42,
        );
        let bytes = encode(&m);
        assert_eq!(decode(&bytes).unwrap(), m);
        assert!(decode(&bytes[..bytes.len() - 1]).is_err());
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(decode(&longer), Err(DecodeError::Trailing(1)));
        let mut other = m.clone();
        other.version = 9;
        assert_eq!(decode(&encode(&other)), Err(DecodeError::Version(9)));
        assert!(matches!(
            decode(&vec![0u8; MAX_MESSAGE_BYTES + 1]),
            Err(DecodeError::TooLong(_))
        ));
    }
}
