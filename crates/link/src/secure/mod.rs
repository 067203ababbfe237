//! Every message between master and robot sealed: authenticated,
//! encrypted, and refused when replayed.
//!
//! Each master-robot pair shares two ChaCha20-Poly1305 keys, one per
//! direction, derived from their static ed25519 keys ([`keys`]): no
//! handshake, nothing to set up before the first chunk of an upload, and
//! no session state a lost or reordered message can break. A sealed
//! message is
//!
//! ```text
//! suite (1 byte: 0x01, bit 0x80: a resync request follows)
//! epoch (u32, big-endian)   the sender's boot epoch: kept durably, one more
//!                           at every start, so no nonce is used twice
//! counter (u48, big-endian) per epoch, one more per message
//! [resync (u32)]            "I refuse your epochs up to this one: move past it"
//! ciphertext (the wire message) and the 16-byte Poly1305 tag
//! ```
//!
//! with the nonce `epoch ‖ counter` and the header as associated data:
//! [`OVERHEAD_BYTES`] (27) per message, 31 with a resync request.
//!
//! The receiver opens a message before anything else reads it, then
//! refuses a counter seen before in the sender's epoch ([`window`]) and
//! every earlier epoch. It keeps the highest epoch it accepted durably
//! ([`epochs::EpochStore`]) before accepting a message of it, so after a
//! restart it accepts only epochs above: the peer's current epoch too,
//! since what was sent in it before the restart could be replayed. It then
//! asks, in every message it sends, for a newer epoch (the resync request,
//! authenticated like the rest), and the peer moves to one on hearing it.
//! A restart of either end costs a one-way trip of refused messages, no
//! round trip and no state that a lost message leaves inconsistent.

pub mod epochs;
pub mod keys;
pub mod window;

use chacha20poly1305::{AeadInOut, Nonce, Tag};
use ed25519_dalek::{SigningKey, VerifyingKey};

pub use epochs::{EpochStore, MemoryEpochs};
pub use keys::{KeyError, PairKeys, Role};
use window::{ReplayWindow, Seen};

/// The first byte of a sealed message (low 7 bits).
pub const SUITE: u8 = 0x01;
/// Set in the first byte: a resync request follows the counter.
const RESYNC: u8 = 0x80;
/// Suite, epoch and counter.
pub const HEADER_BYTES: usize = 1 + 4 + 6;
pub const TAG_BYTES: usize = 16;
/// What sealing adds to a message.
pub const OVERHEAD_BYTES: usize = HEADER_BYTES + TAG_BYTES;
/// ... and with a resync request (only after a restart).
pub const MAX_OVERHEAD_BYTES: usize = OVERHEAD_BYTES + 4;
/// The largest counter of an epoch (48 bits); the next message moves to a
/// new epoch.
const MAX_COUNTER: u64 = (1 << 48) - 1;

/// Why a payload is not accepted. Nothing a refused payload says reaches
/// the protocol.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    #[error("not a sealed message ({0})")]
    NotSealed(&'static str),
    #[error(
        "not authentic: not sealed by a trusted key for this robot (forged, altered, or a key this end does not trust)"
    )]
    NotAuthentic,
    #[error("a replay: counter {counter} of epoch {epoch} was accepted before")]
    Replayed { epoch: u32, counter: u64 },
    #[error("too old: counter {counter} of epoch {epoch} is below the replay window")]
    TooOld { epoch: u32, counter: u64 },
    #[error(
        "from an earlier epoch ({epoch}, the sender is at {current}): a replay from before its restart"
    )]
    OldEpoch { epoch: u32, current: u32 },
    #[error(
        "epoch {epoch} was accepted before this end restarted: refused (a replay could hide in it), a newer one asked for"
    )]
    StaleEpoch { epoch: u32 },
    #[error("could not keep the link's state: {0}")]
    Storage(String),
}

impl Refusal {
    /// A short name for counting and logs.
    pub fn kind(&self) -> &'static str {
        match self {
            Refusal::NotSealed(_) => "not_sealed",
            Refusal::NotAuthentic => "not_authentic",
            Refusal::Replayed { .. } | Refusal::TooOld { .. } => "replayed",
            Refusal::OldEpoch { .. } | Refusal::StaleEpoch { .. } => "stale_epoch",
            Refusal::Storage(_) => "storage",
        }
    }
}

/// Why a channel cannot be made.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ChannelError {
    #[error(transparent)]
    Key(#[from] KeyError),
    #[error("the link's state: {0}")]
    Storage(String),
}

/// One end of one master-robot pair's sealed link.
pub struct Channel {
    keys: PairKeys,
    store: Box<dyn EpochStore>,
    /// This end's sending epoch and next counter.
    epoch: u32,
    next_counter: u64,
    /// The peer's epoch accepted in this run, and its counters seen.
    peer: Option<(u32, ReplayWindow)>,
    /// Asked of the peer in every message until it moves past this epoch.
    resync: Option<u32>,
}

impl std::fmt::Debug for Channel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Channel")
            .field("epoch", &self.epoch)
            .field("next_counter", &self.next_counter)
            .field("peer_epoch", &self.peer.as_ref().map(|p| p.0))
            .field("resync", &self.resync)
            .finish_non_exhaustive()
    }
}

impl Channel {
    /// The channel of robot `robot_id`'s link at this end: `own` is this
    /// end's key, `peer` the other's public key. Starts a new sending
    /// epoch (kept in `store` first).
    pub fn new(
        role: Role,
        own: &SigningKey,
        peer: &VerifyingKey,
        robot_id: &str,
        mut store: Box<dyn EpochStore>,
    ) -> Result<Self, ChannelError> {
        let keys = PairKeys::derive(role, own, peer, robot_id)?;
        let epoch = store.next_epoch(1).map_err(ChannelError::Storage)?;
        Ok(Self {
            keys,
            store,
            epoch,
            next_counter: 0,
            peer: None,
            resync: None,
        })
    }

    /// This end's sending epoch.
    pub fn epoch(&self) -> u32 {
        self.epoch
    }

    /// Whether this end is asking the peer for a newer epoch.
    pub fn asks_resync(&self) -> bool {
        self.resync.is_some()
    }

    /// `plaintext` sealed for the peer.
    pub fn seal(&mut self, plaintext: &[u8]) -> Result<Vec<u8>, String> {
        if self.next_counter > MAX_COUNTER {
            self.epoch = self.store.next_epoch(self.epoch.saturating_add(1))?;
            self.next_counter = 0;
        }
        let counter = self.next_counter;
        self.next_counter += 1;
        let mut out = Vec::with_capacity(plaintext.len() + MAX_OVERHEAD_BYTES);
        out.push(SUITE | if self.resync.is_some() { RESYNC } else { 0 });
        out.extend_from_slice(&self.epoch.to_be_bytes());
        out.extend_from_slice(&counter.to_be_bytes()[2..]);
        if let Some(floor) = self.resync {
            out.extend_from_slice(&floor.to_be_bytes());
        }
        let header_len = out.len();
        out.extend_from_slice(plaintext);
        let (header, body) = out.split_at_mut(header_len);
        let tag = self
            .keys
            .seal
            .encrypt_inout_detached(&nonce(self.epoch, counter), header, body.into())
            .map_err(|_| "a message too long to seal".to_string())?;
        out.extend_from_slice(&tag);
        Ok(out)
    }

    /// The plaintext of a sealed message from the peer, or why it is
    /// refused. Authenticates before it looks at anything else.
    pub fn open(&mut self, sealed: &[u8]) -> Result<Vec<u8>, Refusal> {
        let header = Header::parse(sealed)?;
        let (head, rest) = sealed.split_at(header.len);
        let (ciphertext, tag) = rest.split_at(rest.len() - TAG_BYTES);
        let mut plaintext = ciphertext.to_vec();
        let tag = Tag::try_from(tag).expect("16 bytes");
        self.keys
            .open
            .decrypt_inout_detached(
                &nonce(header.epoch, header.counter),
                head,
                plaintext.as_mut_slice().into(),
                &tag,
            )
            .map_err(|_| Refusal::NotAuthentic)?;
        self.accept(&header)?;
        Ok(plaintext)
    }

    /// The replay rules, on an authentic header; keeps what must be kept.
    fn accept(&mut self, h: &Header) -> Result<(), Refusal> {
        match &mut self.peer {
            Some((current, window)) if h.epoch == *current => {
                window.check(h.counter).map_err(|seen| match seen {
                    Seen::Replayed => Refusal::Replayed {
                        epoch: h.epoch,
                        counter: h.counter,
                    },
                    Seen::TooOld => Refusal::TooOld {
                        epoch: h.epoch,
                        counter: h.counter,
                    },
                })?;
                window.accept(h.counter);
            }
            Some((current, _)) if h.epoch < *current => {
                return Err(Refusal::OldEpoch {
                    epoch: h.epoch,
                    current: *current,
                });
            }
            _ => {
                // An epoch this run has not seen: newer than the one it
                // has, or the first since this end started.
                let floor = self.store.peer_floor();
                if h.epoch <= floor {
                    // Accepted before this end restarted (or a replay from
                    // even earlier): ask the peer to move on.
                    self.resync = Some(self.resync.unwrap_or(0).max(floor));
                    return Err(Refusal::StaleEpoch { epoch: h.epoch });
                }
                self.store
                    .raise_peer_floor(h.epoch)
                    .map_err(Refusal::Storage)?;
                let mut window = ReplayWindow::default();
                window.accept(h.counter);
                self.peer = Some((h.epoch, window));
                self.resync = None;
            }
        }
        if let Some(floor) = h.resync
            && self.epoch <= floor
        {
            // The peer restarted and refuses this epoch: move past it. If
            // the new epoch cannot be kept, the peer asks again.
            if let Ok(epoch) = self.store.next_epoch(floor.saturating_add(1)) {
                self.epoch = epoch;
                self.next_counter = 0;
            }
        }
        Ok(())
    }
}

fn nonce(epoch: u32, counter: u64) -> Nonce {
    let mut n = [0u8; 12];
    n[..4].copy_from_slice(&epoch.to_be_bytes());
    n[4..].copy_from_slice(&counter.to_be_bytes());
    Nonce::from(n)
}

/// A sealed message's clear header.
struct Header {
    epoch: u32,
    counter: u64,
    resync: Option<u32>,
    /// Its length in bytes.
    len: usize,
}

impl Header {
    fn parse(bytes: &[u8]) -> Result<Self, Refusal> {
        let Some(&first) = bytes.first() else {
            return Err(Refusal::NotSealed("empty"));
        };
        if first & !RESYNC != SUITE {
            return Err(Refusal::NotSealed("unknown suite byte"));
        }
        let len = HEADER_BYTES + if first & RESYNC != 0 { 4 } else { 0 };
        if bytes.len() < len + TAG_BYTES {
            return Err(Refusal::NotSealed("shorter than a sealed message"));
        }
        let epoch = u32::from_be_bytes(bytes[1..5].try_into().expect("4 bytes"));
        let mut counter = [0u8; 8];
        counter[2..].copy_from_slice(&bytes[5..11]);
        let resync = (first & RESYNC != 0)
            .then(|| u32::from_be_bytes(bytes[11..15].try_into().expect("4 bytes")));
        Ok(Self {
            epoch,
            counter: u64::from_be_bytes(counter),
            resync,
            len,
        })
    }
}

/// The channels of one end with every peer key it trusts for one robot's
/// link (a robot that trusts several masters): a message is opened by the
/// channel whose key sealed it, and this end answers on the channel that
/// last opened one (the first until then).
#[derive(Debug)]
pub struct Peers {
    channels: Vec<Channel>,
    active: usize,
}

impl Peers {
    /// # Panics
    /// If `channels` is empty.
    pub fn new(channels: Vec<Channel>) -> Self {
        assert!(!channels.is_empty(), "a link needs a trusted key");
        Self {
            channels,
            active: 0,
        }
    }

    pub fn one(channel: Channel) -> Self {
        Self::new(vec![channel])
    }

    /// `plaintext` sealed for the peer heard last.
    pub fn seal(&mut self, plaintext: &[u8]) -> Result<Vec<u8>, String> {
        self.channels[self.active].seal(plaintext)
    }

    /// The plaintext of `sealed`, opened by whichever trusted key sealed it.
    pub fn open(&mut self, sealed: &[u8]) -> Result<Vec<u8>, Refusal> {
        let mut refusal = Refusal::NotAuthentic;
        for (i, channel) in self.channels.iter_mut().enumerate() {
            match channel.open(sealed) {
                Ok(plain) => {
                    self.active = i;
                    return Ok(plain);
                }
                Err(Refusal::NotAuthentic) => {}
                Err(other) => refusal = other,
            }
        }
        Err(refusal)
    }
}

/// Both ends of robot `robot_id`'s link in one process (the demo, the
/// experiments, tests in virtual time), their epochs in memory: the
/// master's end and the robot's.
pub fn memory_pair(master: &SigningKey, robot: &SigningKey, robot_id: &str) -> (Peers, Peers) {
    let end = |role, own: &SigningKey, peer: &SigningKey| {
        Peers::one(
            Channel::new(
                role,
                own,
                &peer.verifying_key(),
                robot_id,
                Box::new(MemoryEpochs::default()),
            )
            .expect("keys made here are valid and memory epochs never fail"),
        )
    };
    (
        end(Role::Master, master, robot),
        end(Role::Robot, robot, master),
    )
}

/// A key pair from a seed: the same seed, the same key (runs in virtual
/// time are reproducible byte for byte). Never for a real robot.
pub fn key_from_seed(seed: u64, stream: u64) -> SigningKey {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    SigningKey::from_bytes(&rng.random())
}

#[cfg(test)]
mod tests;
