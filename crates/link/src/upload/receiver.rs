//! The robot's side of uploads: chunks kept durably as they come, NAKs
//! for what is missing, the tail rebuilt from repair shards, the file
//! checked against its hash.

use std::collections::VecDeque;

use super::store::ChunkStore;
use crate::wire::{Body, MAX_NAK_RANGES, Message, Offer, Stamper, TransferId, transfer_id};

/// Receiver settings.
#[derive(Debug, Clone, Copy)]
pub struct ReceiverConfig {
    /// Largest file accepted, checked on the offer.
    pub max_file_bytes: u64,
    /// How often to NAK while chunks are missing.
    pub nak_interval_ns: u64,
}

impl Default for ReceiverConfig {
    fn default() -> Self {
        Self {
            max_file_bytes: 64 * 1024 * 1024,
            nak_interval_ns: 500_000_000,
        }
    }
}

/// What the receiver reports to its owner.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ReceiverEvent {
    /// Upload progress: chunks held of all.
    Progress { received: u32, chunks: u32 },
    /// A chunk whose CRC did not match was dropped.
    Corrupted { index: u32 },
    /// The file is complete and hashes to its transfer id.
    Completed { transfer: TransferId, file: Vec<u8> },
    /// The offer was refused.
    Refused { reason: String },
    /// Storage failed; the chunk will be asked for again.
    StorageError(String),
}

#[derive(Debug)]
struct Transfer {
    offer: Offer,
    have: Vec<bool>,
    received: u32,
    highest: Option<u32>,
    eof_seen: bool,
    last_nak_ns: Option<u64>,
    /// Chunks held when the last NAK went.
    received_at_last_nak: u32,
    /// Every chunk below this one is held.
    low_water: u32,
    nak_now: bool,
    /// The next NAK lists every chunk (an answer to an offer).
    full: bool,
    done: bool,
    /// Repair shards of the tail block held (kept in memory: after a
    /// restart the NAKs ask for the originals instead).
    repairs: std::collections::BTreeMap<u32, Vec<u8>>,
}

/// The robot's side of uploads.
#[derive(Debug)]
pub struct Receiver<S: ChunkStore> {
    stamper: Stamper,
    store: S,
    config: ReceiverConfig,
    current: Option<Transfer>,
    outbox: VecDeque<Body>,
    events: VecDeque<ReceiverEvent>,
    /// Chunks and repair shards that came before their offer (lost, or
    /// overtaken), kept a while in memory: (transfer, repair?, index, data).
    orphans: VecDeque<(TransferId, bool, u32, Vec<u8>)>,
}

/// At most this many chunks wait for their offer.
const MAX_ORPHANS: usize = 4_096;

impl<S: ChunkStore> Receiver<S> {
    /// A receiver; one that finds an unfinished transfer in its store (a
    /// restart) resumes it at once and says where it stands.
    pub fn new(robot_id: &str, store: S, config: ReceiverConfig) -> Self {
        let mut receiver = Self {
            stamper: Stamper::new(robot_id),
            store,
            config,
            current: None,
            outbox: VecDeque::new(),
            events: VecDeque::new(),
            orphans: VecDeque::new(),
        };
        match receiver.store.pending() {
            Ok(Some(offer)) => receiver.offer(offer),
            Ok(None) => {}
            Err(e) => receiver
                .events
                .push_back(ReceiverEvent::StorageError(e.to_string())),
        }
        receiver
    }

    /// The next thing to tell the owner.
    pub fn poll_event(&mut self) -> Option<ReceiverEvent> {
        self.events.pop_front()
    }

    pub fn store(&self) -> &S {
        &self.store
    }

    /// The transfer under way (or the last one completed).
    pub fn current_transfer(&self) -> Option<TransferId> {
        self.current.as_ref().map(|t| t.offer.transfer)
    }

    /// Whether the current transfer is complete (its file handed out).
    pub fn is_complete(&self) -> bool {
        self.current.as_ref().is_some_and(|t| t.done)
    }

    /// Takes in a message from the sender.
    /// (The receiver acts on messages alone; its NAK timing is by
    /// `poll_transmit`'s clock.)
    pub fn handle(&mut self, message: &Message, _now_ns: u64) {
        match &message.body {
            Body::Offer(offer) => self.offer(*offer),
            Body::Chunk {
                transfer,
                index,
                crc32,
                data,
            } => self.chunk(*transfer, *index, *crc32, data),
            Body::Repair {
                transfer,
                index,
                crc32,
                data,
            } => self.repair(*transfer, *index, *crc32, data),
            Body::EndOfFile { transfer } => {
                if let Some(t) = &mut self.current
                    && t.offer.transfer == *transfer
                {
                    if t.done {
                        self.outbox.push_back(Body::Finished {
                            transfer: *transfer,
                        });
                    } else {
                        t.eof_seen = true;
                        t.nak_now = true;
                    }
                }
            }
            _ => {}
        }
    }

    fn offer(&mut self, offer: Offer) {
        if let Some(t) = &mut self.current
            && t.offer == offer
        {
            // The same upload again (the sender restarted): say where it stands.
            if t.done {
                self.outbox.push_back(Body::Finished {
                    transfer: offer.transfer,
                });
            } else {
                t.nak_now = true;
                t.full = true;
            }
            return;
        }
        if offer.size > self.config.max_file_bytes || offer.chunk_size == 0 {
            let reason = if offer.chunk_size == 0 {
                "chunk size 0".to_string()
            } else {
                format!(
                    "{} bytes, more than the {} accepted",
                    offer.size, self.config.max_file_bytes
                )
            };
            self.events.push_back(ReceiverEvent::Refused {
                reason: reason.clone(),
            });
            self.outbox.push_back(Body::Refused {
                transfer: offer.transfer,
                reason,
            });
            return;
        }
        let have = match self.store.open(&offer) {
            Ok(have) if have.len() == offer.chunks() as usize => have,
            Ok(_) => vec![false; offer.chunks() as usize],
            Err(e) => {
                self.events
                    .push_back(ReceiverEvent::StorageError(e.to_string()));
                vec![false; offer.chunks() as usize]
            }
        };
        let received = have.iter().filter(|&&h| h).count() as u32;
        let highest = have.iter().rposition(|&h| h).map(|k| k as u32);
        self.current = Some(Transfer {
            offer,
            have,
            received,
            highest,
            eof_seen: false,
            last_nak_ns: None,
            received_at_last_nak: 0,
            low_water: 0,
            nak_now: true,
            full: true,
            done: false,
            repairs: std::collections::BTreeMap::new(),
        });
        self.events.push_back(ReceiverEvent::Progress {
            received,
            chunks: offer.chunks(),
        });
        self.adopt_orphans();
        self.check_complete();
    }

    /// Keeps a good chunk (or repair shard) of a transfer not on offer yet.
    fn orphan(&mut self, transfer: TransferId, repair: bool, index: u32, crc32: u32, data: &[u8]) {
        if self
            .current
            .as_ref()
            .is_some_and(|t| t.offer.transfer == transfer)
            || crc32fast::hash(data) != crc32
        {
            return;
        }
        if self.orphans.len() == MAX_ORPHANS {
            self.orphans.pop_front();
        }
        self.orphans
            .push_back((transfer, repair, index, data.to_vec()));
    }

    /// Feeds the current transfer what came before its offer.
    fn adopt_orphans(&mut self) {
        let Some(transfer) = self.current.as_ref().map(|t| t.offer.transfer) else {
            return;
        };
        let (mine, others): (VecDeque<_>, VecDeque<_>) = std::mem::take(&mut self.orphans)
            .into_iter()
            .partition(|o| o.0 == transfer);
        self.orphans = others;
        for (_, repair, index, data) in mine {
            let crc = crc32fast::hash(&data);
            if repair {
                self.repair(transfer, index, crc, &data);
            } else {
                self.chunk(transfer, index, crc, &data);
            }
        }
    }

    fn chunk(&mut self, transfer: TransferId, index: u32, crc32: u32, data: &[u8]) {
        let Some(t) = &mut self.current else {
            self.orphan(transfer, false, index, crc32, data);
            return;
        };
        if t.offer.transfer != transfer {
            self.orphan(transfer, false, index, crc32, data);
            return;
        }
        if t.done || index >= t.offer.chunks() {
            return;
        }
        let expected_len = if index + 1 == t.offer.chunks() {
            (t.offer.size - u64::from(index) * u64::from(t.offer.chunk_size)) as usize
        } else {
            t.offer.chunk_size as usize
        };
        if crc32fast::hash(data) != crc32 || data.len() != expected_len {
            self.events.push_back(ReceiverEvent::Corrupted { index });
            return;
        }
        if t.have[index as usize] {
            return;
        }
        if let Err(e) = self.store.put(&t.offer, index, data) {
            self.events
                .push_back(ReceiverEvent::StorageError(e.to_string()));
            return;
        }
        t.have[index as usize] = true;
        t.received += 1;
        // A new gap below this chunk: NAK at once, so that the loss is
        // repaired during the pass and not after its end (gaps in the tail
        // block wait for its repair shards).
        let gap_from = t.highest.map_or(0, |h| h + 1);
        let protected_from = if t.offer.fec_repairs > 0 {
            t.offer.fec_from
        } else {
            t.offer.chunks()
        };
        if index > gap_from && gap_from < protected_from {
            t.nak_now = true;
        }
        // Gaps below the tail block still open after another 16 chunks (a
        // resent chunk lost again): NAK again, at a pace set by the link's
        // own rate, not a timer.
        while t.low_water < t.offer.chunks() && t.have[t.low_water as usize] {
            t.low_water += 1;
        }
        let open_gap = t.low_water < protected_from.min(t.highest.map_or(0, |h| h.max(index)));
        if open_gap && t.received >= t.received_at_last_nak + 16 {
            t.nak_now = true;
        }
        t.highest = Some(t.highest.map_or(index, |h| h.max(index)));
        self.events.push_back(ReceiverEvent::Progress {
            received: t.received,
            chunks: t.offer.chunks(),
        });
        self.try_repair();
        self.check_complete();
    }

    fn repair(&mut self, transfer: TransferId, index: u32, crc32: u32, data: &[u8]) {
        let Some(t) = &mut self.current else {
            self.orphan(transfer, true, index, crc32, data);
            return;
        };
        if t.offer.transfer != transfer {
            self.orphan(transfer, true, index, crc32, data);
            return;
        }
        if t.done || index >= t.offer.fec_repairs {
            return;
        }
        if crc32fast::hash(data) != crc32 || data.len() != t.offer.chunk_size as usize {
            self.events.push_back(ReceiverEvent::Corrupted {
                index: t.offer.chunks() + index,
            });
            return;
        }
        t.repairs.insert(index, data.to_vec());
        self.try_repair();
        self.check_complete();
    }

    /// Rebuilds the tail block's missing chunks once as many repair shards
    /// as missing chunks are in.
    fn try_repair(&mut self) {
        let Some(t) = &mut self.current else {
            return;
        };
        let o = t.offer;
        let (from, chunks) = (o.fec_from, o.chunks());
        if t.done || o.fec_repairs == 0 || from >= chunks {
            return;
        }
        let missing: Vec<u32> = (from..chunks).filter(|&k| !t.have[k as usize]).collect();
        if missing.is_empty() || t.repairs.len() < missing.len() {
            return;
        }
        let size = o.chunk_size as usize;
        let mut originals = Vec::with_capacity((chunks - from) as usize);
        for k in from..chunks {
            if t.have[k as usize] {
                match self.store.get(&o, k) {
                    Ok(mut c) => {
                        c.resize(size, 0);
                        originals.push(((k - from) as usize, c));
                    }
                    Err(e) => {
                        self.events
                            .push_back(ReceiverEvent::StorageError(e.to_string()));
                        return;
                    }
                }
            }
        }
        let restored = match super::fec::restore(&o, originals, &t.repairs) {
            Ok(r) => r,
            Err(e) => {
                self.events.push_back(ReceiverEvent::StorageError(format!(
                    "repairing the tail block: {e}"
                )));
                t.repairs.clear();
                return;
            }
        };
        for (i, mut data) in restored {
            let k = from + i as u32;
            if t.have[k as usize] {
                continue;
            }
            if k + 1 == chunks {
                data.truncate((o.size - u64::from(k) * u64::from(o.chunk_size)) as usize);
            }
            if let Err(e) = self.store.put(&o, k, &data) {
                self.events
                    .push_back(ReceiverEvent::StorageError(e.to_string()));
                return;
            }
            t.have[k as usize] = true;
            t.received += 1;
        }
        t.highest = Some(chunks - 1);
        self.events.push_back(ReceiverEvent::Progress {
            received: t.received,
            chunks,
        });
    }

    fn check_complete(&mut self) {
        let Some(t) = &mut self.current else {
            return;
        };
        if t.done || t.received != t.offer.chunks() {
            return;
        }
        let offer = t.offer;
        match self.store.assemble(&offer) {
            Ok(file) if transfer_id(&file) == offer.transfer => {
                t.done = true;
                let _ = self.store.discard(&offer);
                self.outbox.push_back(Body::Finished {
                    transfer: offer.transfer,
                });
                self.events.push_back(ReceiverEvent::Completed {
                    transfer: offer.transfer,
                    file,
                });
            }
            Ok(_) => {
                // Every chunk passed its CRC yet the whole does not hash
                // right: start this transfer over.
                let _ = self.store.discard(&offer);
                t.have.fill(false);
                t.received = 0;
                t.highest = None;
                t.nak_now = true;
                self.events.push_back(ReceiverEvent::StorageError(
                    "the assembled file does not match its SHA-256; starting over".into(),
                ));
            }
            Err(e) => self
                .events
                .push_back(ReceiverEvent::StorageError(e.to_string())),
        }
    }

    /// The next message to send at `now_ns`, if any.
    pub fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        if let Some(body) = self.outbox.pop_front() {
            return Some(self.stamper.stamp(body, now_ns));
        }
        let t = self.current.as_mut()?;
        if t.done {
            return None;
        }
        let gaps = t.eof_seen || t.highest.is_some_and(|h| h + 1 > t.received);
        let periodic = gaps
            && t.last_nak_ns
                .is_none_or(|last| now_ns >= last + self.config.nak_interval_ns);
        if !(t.nak_now || periodic) {
            return None;
        }
        t.nak_now = false;
        t.last_nak_ns = Some(now_ns);
        t.received_at_last_nak = t.received;
        // Missing ranges up to the highest chunk seen (all of them after
        // the end of the file), lowest first.
        let upto = if t.eof_seen || t.full || t.highest.is_none() {
            t.full = false;
            t.offer.chunks()
        } else {
            t.highest.map_or(0, |h| h + 1)
        };
        // The tail block's gaps are for its repair shards to fill: none
        // asked before the end of the file, then only as many as the
        // shards held cannot cover (the lowest).
        let from = t.offer.fec_from.min(t.offer.chunks());
        let upto = if t.offer.fec_repairs > 0 && upto > from {
            if t.eof_seen {
                let held = t.have[from as usize..].iter().filter(|&&h| h).count();
                let deficit = (t.offer.chunks() - from) as usize
                    - held
                    - t.repairs
                        .len()
                        .min((t.offer.chunks() - from) as usize - held);
                // Speak up to just past the `deficit`-th missing chunk.
                let mut seen = 0;
                let mut end = from;
                for k in from..t.offer.chunks() {
                    if seen == deficit {
                        break;
                    }
                    if !t.have[k as usize] {
                        seen += 1;
                    }
                    end = k + 1;
                }
                end
            } else {
                from
            }
        } else {
            upto
        };
        let mut missing = Vec::new();
        let mut k = 0;
        while k < upto && missing.len() < MAX_NAK_RANGES {
            if t.have[k as usize] {
                k += 1;
                continue;
            }
            let a = k;
            while k + 1 < upto && !t.have[k as usize + 1] {
                k += 1;
            }
            missing.push((a, k));
            k += 1;
        }
        // A full list speaks only up to where it stopped.
        let upto = if missing.len() == MAX_NAK_RANGES {
            k
        } else {
            upto
        };
        let body = Body::Nak {
            transfer: t.offer.transfer,
            received: t.received,
            upto,
            missing,
        };
        Some(self.stamper.stamp(body, now_ns))
    }

    /// When the receiver next wants `poll_transmit` called, if ever.
    pub fn poll_timeout(&self) -> Option<u64> {
        if !self.outbox.is_empty() {
            return Some(0);
        }
        let t = self.current.as_ref()?;
        if t.done {
            return None;
        }
        if t.nak_now {
            return Some(0);
        }
        let gaps = t.eof_seen || t.highest.is_some_and(|h| h + 1 > t.received);
        gaps.then(|| {
            t.last_nak_ns
                .map_or(0, |last| last + self.config.nak_interval_ns)
        })
    }
}
