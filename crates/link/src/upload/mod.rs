//! Chunked, resumable file upload with negative acknowledgements (the
//! pattern of CCSDS CFDP class 2), as two state machines without I/O.
//!
//! The sender offers the file (its SHA-256 names the transfer), streams
//! every chunk once at its pacing rate, then says so (`EndOfFile`). The
//! receiver stores each good chunk durably the moment it arrives and answers
//! with NAKs: right after an offer (so a resumed upload only sends what is
//! missing), every `nak_interval` while chunks below the highest one
//! received are missing, and at the end of the file. The sender sends again
//! what a NAK lists, unless it sent it less than a round trip ago. When the
//! last chunk is in and the whole file hashes to the transfer id, the
//! receiver says `Finished`; the sender repeats `EndOfFile` until it hears
//! that.
//!
//! Both sides take the time as an argument (`now_ns`) and hand out the
//! messages they want sent (`poll_transmit`) and when they next want to be
//! woken (`poll_timeout`), so the same code runs over zenoh and in virtual
//! time. A restart of either side loses nothing: the receiver's chunks are
//! in its [`ChunkStore`]; a sender that restarts offers again and waits for
//! the receiver's NAK before sending.
//!
//! - [`sender`]: the master's side, paced, with repair shards for the tail;
//! - [`receiver`]: the robot's side, NAKs, repair and assembly;
//! - [`fec`]: how large a tail block to protect and with how many shards;
//! - [`store`]: where a receiver keeps its chunks ([`ChunkStore`]), and a
//!   store in memory (the durable one on disk is `twindrive-store`'s).

pub mod fec;
pub mod receiver;
pub mod sender;
pub mod store;

pub use crate::wire::transfer_id;
pub use receiver::{Receiver, ReceiverConfig, ReceiverEvent};
pub use sender::{DEFAULT_CHUNK_BYTES, Sender, SenderConfig, SenderStats};
pub use store::{ChunkStore, MemoryStore};
