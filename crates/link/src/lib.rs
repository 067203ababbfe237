//! The link between master and robot: what crosses it and how, without
//! I/O. Everything here takes time as an argument and runs the same over
//! zenoh and in virtual time.
//!
//! - [`emulator`]: a userspace link emulator (latency, jitter, loss,
//!   bandwidth, outages; named profiles), deterministic under a seed;
//! - [`envelope`]: signed plans (ed25519) and the robot's rules for accepting one;
//! - [`plan_codec`]: the compact, lossless form plans travel in;
//! - [`secure`]: every message sealed (ChaCha20-Poly1305 from the two ends'
//!   static keys), replays refused across restarts;
//! - [`wire`]: the versioned messages and their bytes (any bytes decode to a
//!   message or an error, never a panic);
//! - [`upload`]: chunked, resumable upload with NAKs (sender and receiver
//!   state machines, repair shards, the chunk-store trait);
//! - [`vtime`]: two endpoints joined by emulated links in virtual time;
//! - [`efficiency`]: an upload's time against the ideal the link allows.

pub mod efficiency;
pub mod emulator;
pub mod envelope;
pub mod plan_codec;
pub mod secure;
pub mod upload;
pub mod vtime;
pub mod wire;

pub use emulator::{LinkEmulator, LinkProfile, LinkStats, Outage};
