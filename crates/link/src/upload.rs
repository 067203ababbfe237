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

use std::collections::VecDeque;

use sha2::{Digest, Sha256};

use crate::wire::{Body, MAX_NAK_RANGES, Message, Offer, Stamper, TransferId};

/// Default chunk payload: small enough for any link's MTU budget.
pub const DEFAULT_CHUNK_BYTES: u32 = 1024;

/// The SHA-256 of a file: its transfer id.
pub fn transfer_id(file: &[u8]) -> TransferId {
    Sha256::digest(file).into()
}

/// Sender settings.
#[derive(Debug, Clone, Copy)]
pub struct SenderConfig {
    pub chunk_bytes: u32,
    /// Send no faster than this (the link's rate, if known); `None`: as fast
    /// as asked.
    pub pace_bit_s: Option<f64>,
    /// A first guess of the round trip, until one is measured.
    pub rtt_hint_ns: u64,
    /// The link's expected loss (0 to 1): sizes the repair shards that
    /// protect the tail of the file, so its last chunks need no round trip
    /// to be asked again. 0: no repair shards.
    pub loss_hint: f64,
}

impl Default for SenderConfig {
    fn default() -> Self {
        Self {
            chunk_bytes: DEFAULT_CHUNK_BYTES,
            pace_bit_s: None,
            rtt_hint_ns: 1_000_000_000,
            loss_hint: 0.0,
        }
    }
}

/// Progress and cost of an upload.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct SenderStats {
    pub chunks: u32,
    pub chunks_sent: u64,
    pub chunks_resent: u64,
    /// Chunks the receiver reported holding.
    pub chunks_confirmed: u32,
    pub naks_received: u64,
    /// Reed-Solomon repair shards sent for the tail block.
    pub repairs_sent: u64,
    /// Offers sent again because an end-of-file went unanswered (a
    /// receiver that restarted, or a link that was down).
    pub reoffers: u64,
}

/// The master's side of one upload.
#[derive(Debug, Clone)]
pub struct Sender {
    stamper: Stamper,
    file: Vec<u8>,
    offer: Offer,
    config: SenderConfig,
    /// When each chunk was last sent (`None`: never).
    sent_at: Vec<Option<u64>>,
    confirmed: Vec<bool>,
    queued: Vec<bool>,
    queue: VecDeque<u32>,
    /// Stream chunks before the receiver has answered the offer.
    optimistic: bool,
    offer_sent_at: Option<u64>,
    answered: bool,
    eof_sent_at: Option<u64>,
    /// The offer went again in place of an end-of-file: the end-of-file
    /// follows at once.
    eof_now: bool,
    /// The offer went again, unanswered so far: the next NAK answers it
    /// and is the receiver's whole truth (one that restarted holds less
    /// than an earlier NAK confirmed).
    reoffered: bool,
    /// End-of-files sent since the receiver last answered (a NAK).
    eofs_unanswered: u32,
    next_send_ns: u64,
    rtt_ns: u64,
    finished: bool,
    refused: Option<String>,
    /// Repair shards still to send (built when the first pass ends).
    repairs: VecDeque<(u32, Vec<u8>)>,
    repairs_built: bool,
    pub stats: SenderStats,
}

/// The tail block a sender protects, and how many repair shards. The
/// block spans four round trips of chunks: a chunk lost before it is
/// NAKed and resent (twice, if need be) before the first pass ends (at
/// least 64 chunks: on a fast link a round trip is a few chunks). A repair
/// shard costs one chunk's time on the link; a shortfall costs about two
/// round trips after the end: shards are added while the chance of a
/// shortfall, times that, outweighs one more shard.
fn tail_block(chunks: u32, chunk_bytes: u32, config: &SenderConfig) -> (u32, u32) {
    let p = config.loss_hint;
    if !(p > 0.0 && p < 1.0) || chunks == 0 {
        return (chunks, 0);
    }
    let per_chunk_bits = 8.0 * (f64::from(chunk_bytes) + 64.0);
    let rtt_s = config.rtt_hint_ns as f64 * 1e-9;
    let (in_four_rtt, chunk_s) = match config.pace_bit_s {
        Some(rate) => (
            (4.0 * rtt_s * rate / per_chunk_bits).ceil() as u32,
            per_chunk_bits / rate,
        ),
        None => (256, 0.0),
    };
    let block = chunks.min(in_four_rtt.clamp(64, 4096));
    let n = f64::from(block);
    let mut repairs = (n * p / (1.0 - p)).ceil() as u32;
    // A shortfall is found at the end of the file, asked for and resent:
    // about two round trips.
    while repairs < 4096 && shortfall_probability(block, repairs, p) * 2.0 * rtt_s > chunk_s {
        repairs += 1;
    }
    (chunks - block, repairs.max(1))
}

/// The chance that more than `repairs` of `block + repairs` shards are
/// lost, each with probability `p`.
fn shortfall_probability(block: u32, repairs: u32, p: f64) -> f64 {
    let n = block + repairs;
    // P(X <= repairs) for X ~ Binomial(n, p), term by term in logs.
    let (ln_p, ln_q) = (p.ln(), (1.0 - p).ln());
    let mut ln_term = f64::from(n) * ln_q;
    let mut held = ln_term.exp();
    for k in 1..=repairs.min(n) {
        ln_term += (f64::from(n - k + 1) / f64::from(k)).ln() + ln_p - ln_q;
        held += ln_term.exp();
    }
    (1.0 - held).max(0.0)
}

impl Sender {
    /// A fresh upload: the chunks stream right after the offer.
    pub fn new(robot_id: &str, file: Vec<u8>, config: SenderConfig) -> Self {
        Self::start(robot_id, file, config, true)
    }

    /// An upload that may be partly done (after a restart): offer, then send
    /// only what the receiver's answer says is missing.
    pub fn resume(robot_id: &str, file: Vec<u8>, config: SenderConfig) -> Self {
        Self::start(robot_id, file, config, false)
    }

    fn start(robot_id: &str, file: Vec<u8>, config: SenderConfig, optimistic: bool) -> Self {
        // Repair shards need an even size.
        let chunk_bytes = config.chunk_bytes.max(2).next_multiple_of(2);
        let chunks = (file.len() as u64).div_ceil(u64::from(chunk_bytes)) as u32;
        let (fec_from, fec_repairs) = tail_block(chunks, chunk_bytes, &config);
        let offer = Offer {
            transfer: transfer_id(&file),
            size: file.len() as u64,
            chunk_size: chunk_bytes,
            fec_from,
            fec_repairs,
        };
        let n = offer.chunks() as usize;
        let mut sender = Self {
            stamper: Stamper::new(robot_id),
            file,
            offer,
            config: SenderConfig {
                chunk_bytes,
                ..config
            },
            sent_at: vec![None; n],
            confirmed: vec![false; n],
            queued: vec![false; n],
            queue: VecDeque::with_capacity(n),
            optimistic,
            offer_sent_at: None,
            answered: false,
            eof_sent_at: None,
            eof_now: false,
            reoffered: false,
            eofs_unanswered: 0,
            next_send_ns: 0,
            rtt_ns: config.rtt_hint_ns.max(1),
            finished: false,
            refused: None,
            repairs: VecDeque::new(),
            // A resumed upload asks again for what is missing instead.
            repairs_built: !optimistic,
            stats: SenderStats {
                chunks: n as u32,
                ..SenderStats::default()
            },
        };
        if optimistic {
            for k in 0..n as u32 {
                sender.enqueue(k);
            }
        }
        sender
    }

    pub fn transfer(&self) -> TransferId {
        self.offer.transfer
    }

    /// The receiver has the whole file.
    pub fn is_finished(&self) -> bool {
        self.finished
    }

    /// Why the receiver refused the offer, if it did.
    pub fn refused(&self) -> Option<&str> {
        self.refused.as_deref()
    }

    fn enqueue(&mut self, k: u32) {
        if !self.queued[k as usize] && !self.confirmed[k as usize] {
            self.queued[k as usize] = true;
            self.queue.push_back(k);
        }
    }

    /// Takes in a message from the receiver.
    pub fn handle(&mut self, message: &Message, now_ns: u64) {
        match &message.body {
            Body::Nak {
                transfer,
                received,
                upto,
                missing,
            } if *transfer == self.offer.transfer => {
                self.stats.naks_received += 1;
                self.eofs_unanswered = 0;
                if std::mem::take(&mut self.reoffered) {
                    // What this receiver lists as missing is missing, even
                    // if an earlier receiver held it.
                    for &(a, b) in missing {
                        for k in a..=b.min(self.stats.chunks.saturating_sub(1)) {
                            self.confirmed[k as usize] = false;
                        }
                    }
                }
                let first = !self.answered;
                if first {
                    self.answered = true;
                    // The first NAK answers the offer, unless that answer
                    // was lost and this one reports a gap much later: a
                    // round trip above the hint is not believed.
                    if let Some(t) = self.offer_sent_at {
                        self.rtt_ns = now_ns.saturating_sub(t).min(self.config.rtt_hint_ns).max(1);
                    }
                }
                // The answer to a fresh upload's offer lists every chunk not
                // yet in, and the first pass is bringing them: it only
                // confirms what the receiver held already.
                let listed: &[(u32, u32)] = if first && self.optimistic {
                    &[]
                } else {
                    missing
                };
                let upto = if first && self.optimistic {
                    missing.first().map_or(*upto, |&(a, _)| a.min(*upto))
                } else {
                    *upto
                };
                self.apply_nak(*received, upto, listed, now_ns);
            }
            Body::Finished { transfer } if *transfer == self.offer.transfer => {
                self.finished = true;
                self.confirmed.fill(true);
                self.stats.chunks_confirmed = self.stats.chunks;
                self.queue.clear();
            }
            Body::Refused { transfer, reason } if *transfer == self.offer.transfer => {
                self.refused = Some(reason.clone());
                self.queue.clear();
            }
            _ => {}
        }
    }

    fn apply_nak(&mut self, received: u32, upto: u32, missing: &[(u32, u32)], now_ns: u64) {
        let n = self.stats.chunks;
        // The NAK speaks for chunks below `upto`: those not listed are held.
        let listed_to = upto.min(n);
        let mut is_missing = vec![false; listed_to as usize];
        for &(a, b) in missing {
            for k in a..=b.min(listed_to.saturating_sub(1)) {
                is_missing[k as usize] = true;
            }
        }
        for (confirmed, &gone) in self.confirmed.iter_mut().zip(&is_missing) {
            if !gone {
                *confirmed = true;
            }
        }
        self.stats.chunks_confirmed = received.min(n);
        // Chunks sent before and lost go ahead of the first pass, lowest
        // first: a loss repaired early costs no round trip at the end.
        let mut again = Vec::new();
        for (k, &gone) in is_missing.iter().enumerate() {
            // Not again if it may still be on its way, or the NAK left the
            // receiver before it could have arrived.
            let in_flight = self.sent_at[k].is_some_and(|t| now_ns < t + self.in_flight_ns());
            if gone && !in_flight {
                if self.sent_at[k].is_some() && !self.queued[k] && !self.confirmed[k] {
                    again.push(k as u32);
                } else {
                    self.enqueue(k as u32);
                }
            }
        }
        for &k in again.iter().rev() {
            self.queued[k as usize] = true;
            self.queue.push_front(k);
        }
    }

    /// The next message to send at `now_ns`, if any.
    pub fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        if self.finished || self.refused.is_some() {
            return None;
        }
        let offer_due = match self.offer_sent_at {
            None => true,
            Some(t) => !self.answered && now_ns >= t + 2 * self.rtt_ns,
        };
        if offer_due {
            self.offer_sent_at = Some(now_ns);
            return Some(self.stamper.stamp(Body::Offer(self.offer), now_ns));
        }
        if !(self.optimistic || self.answered) {
            return None;
        }
        if now_ns < self.next_send_ns {
            return None;
        }
        while let Some(k) = self.queue.pop_front() {
            self.queued[k as usize] = false;
            if self.confirmed[k as usize] {
                continue;
            }
            let from = k as usize * self.offer.chunk_size as usize;
            let to = (from + self.offer.chunk_size as usize).min(self.file.len());
            let data = self.file[from..to].to_vec();
            if self.sent_at[k as usize].is_some() {
                self.stats.chunks_resent += 1;
            }
            self.sent_at[k as usize] = Some(now_ns);
            self.stats.chunks_sent += 1;
            let message = self.stamper.stamp(
                Body::Chunk {
                    transfer: self.offer.transfer,
                    index: k,
                    crc32: crc32fast::hash(&data),
                    data,
                },
                now_ns,
            );
            self.pace(now_ns, crate::wire::encode(&message).len());
            return Some(message);
        }
        // The first pass is over: the tail block's repair shards, once.
        if !self.repairs_built {
            self.repairs_built = true;
            self.build_repairs();
        }
        if let Some((index, data)) = self.repairs.pop_front() {
            self.stats.repairs_sent += 1;
            let message = self.stamper.stamp(
                Body::Repair {
                    transfer: self.offer.transfer,
                    index,
                    crc32: crc32fast::hash(&data),
                    data,
                },
                now_ns,
            );
            self.pace(now_ns, crate::wire::encode(&message).len());
            return Some(message);
        }
        // Everything sent: say so, and again each round trip until done.
        let eof_due = self.eof_now
            || self
                .eof_sent_at
                .is_none_or(|t| now_ns >= t + self.rtt_ns + self.rtt_ns / 4);
        if eof_due {
            // No answer to two end-of-files in a row: the receiver may have
            // restarted and forgotten this transfer (its chunks and
            // end-of-files then go unheard). The offer goes again first; a
            // receiver answers it with where it stands, so the transfer
            // resumes with whoever listens now instead of stalling.
            if self.eofs_unanswered >= 2 && !self.eof_now {
                self.eofs_unanswered = 0;
                self.eof_now = true;
                self.reoffered = true;
                self.stats.reoffers += 1;
                return Some(self.stamper.stamp(Body::Offer(self.offer), now_ns));
            }
            self.eof_now = false;
            self.eof_sent_at = Some(now_ns);
            self.eofs_unanswered += 1;
            let message = self.stamper.stamp(
                Body::EndOfFile {
                    transfer: self.offer.transfer,
                },
                now_ns,
            );
            self.pace(now_ns, crate::wire::encode(&message).len());
            return Some(message);
        }
        None
    }

    fn build_repairs(&mut self) {
        let o = self.offer;
        if o.fec_repairs == 0 || o.fec_from >= o.chunks() {
            return;
        }
        let size = o.chunk_size as usize;
        let originals = (o.fec_from..o.chunks()).map(|k| {
            let from = k as usize * size;
            let mut shard = self.file[from..(from + size).min(self.file.len())].to_vec();
            shard.resize(size, 0);
            shard
        });
        match reed_solomon_simd::encode(
            (o.chunks() - o.fec_from) as usize,
            o.fec_repairs as usize,
            originals,
        ) {
            Ok(shards) => {
                self.repairs = (0..).zip(shards).collect();
            }
            // Without repairs the NAKs still bring every chunk.
            Err(_) => self.repairs.clear(),
        }
    }

    /// How long after sending a chunk a NAK that lists it may be stale:
    /// the round trip with a quarter of it for jitter, and the chunk's own
    /// time on the link.
    fn in_flight_ns(&self) -> u64 {
        let tx_ns = self.config.pace_bit_s.map_or(0, |rate| {
            (8.0 * (f64::from(self.offer.chunk_size) + 64.0) / rate * 1e9) as u64
        });
        // The hint, when the one sample taken is shorter: a sample caught
        // two lucky draws of jitter.
        let rtt = self.rtt_ns.max(self.config.rtt_hint_ns);
        rtt + rtt / 4 + tx_ns
    }

    fn pace(&mut self, now_ns: u64, bytes: usize) {
        if let Some(rate) = self.config.pace_bit_s {
            self.next_send_ns = now_ns + (8.0 * bytes as f64 / rate * 1e9).ceil() as u64;
        }
    }

    /// When the sender next wants `poll_transmit` called, if ever.
    pub fn poll_timeout(&self) -> Option<u64> {
        if self.finished || self.refused.is_some() {
            return None;
        }
        match self.offer_sent_at {
            None => return Some(0),
            Some(t) if !self.answered => {
                let retry = t + 2 * self.rtt_ns;
                if !self.optimistic {
                    return Some(retry);
                }
                if self.queue.is_empty() && self.repairs_built && self.repairs.is_empty() {
                    return Some(retry.min(self.eof_due_at()));
                }
                return Some(retry.min(self.next_send_ns));
            }
            _ => {}
        }
        if !self.queue.is_empty() || !self.repairs_built || !self.repairs.is_empty() {
            return Some(self.next_send_ns);
        }
        Some(self.eof_due_at().max(self.next_send_ns))
    }

    fn eof_due_at(&self) -> u64 {
        if self.eof_now {
            return 0;
        }
        self.eof_sent_at
            .map_or(0, |t| t + self.rtt_ns + self.rtt_ns / 4)
    }
}

/// Where a receiver keeps the chunks it has, across restarts.
pub trait ChunkStore {
    /// Starts or resumes `offer`'s transfer: which chunks are already held.
    fn open(&mut self, offer: &Offer) -> std::io::Result<Vec<bool>>;
    /// Keeps one chunk; once this returns, a restart still has it.
    fn put(&mut self, offer: &Offer, index: u32, data: &[u8]) -> std::io::Result<()>;
    /// One chunk held.
    fn get(&mut self, offer: &Offer, index: u32) -> std::io::Result<Vec<u8>>;
    /// The whole file, chunks in order.
    fn assemble(&mut self, offer: &Offer) -> std::io::Result<Vec<u8>>;
    /// Drops what is kept for the transfer (done, or to start over).
    fn discard(&mut self, offer: &Offer) -> std::io::Result<()>;
    /// A transfer opened and not yet discarded (after a restart: the one to
    /// resume before the sender offers it again).
    fn pending(&mut self) -> std::io::Result<Option<Offer>>;
}

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
        let restored = match reed_solomon_simd::decode(
            (chunks - from) as usize,
            o.fec_repairs as usize,
            originals,
            t.repairs.iter().map(|(&i, d)| (i as usize, d)),
        ) {
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

/// Chunks in memory. Clones share one store, so a test can "restart" a
/// receiver and keep what it had durably.
#[derive(Debug, Clone, Default)]
pub struct MemoryStore {
    inner: std::sync::Arc<std::sync::Mutex<MemoryInner>>,
}

#[derive(Debug, Default)]
struct MemoryInner {
    chunks: std::collections::HashMap<TransferId, Vec<Option<Vec<u8>>>>,
    pending: Option<Offer>,
}

impl ChunkStore for MemoryStore {
    fn open(&mut self, offer: &Offer) -> std::io::Result<Vec<bool>> {
        let mut inner = self.inner.lock().expect("store lock");
        inner.pending = Some(*offer);
        let chunks = inner
            .chunks
            .entry(offer.transfer)
            .or_insert_with(|| vec![None; offer.chunks() as usize]);
        Ok(chunks.iter().map(Option::is_some).collect())
    }

    fn put(&mut self, offer: &Offer, index: u32, data: &[u8]) -> std::io::Result<()> {
        let mut inner = self.inner.lock().expect("store lock");
        let chunks = inner
            .chunks
            .entry(offer.transfer)
            .or_insert_with(|| vec![None; offer.chunks() as usize]);
        chunks[index as usize] = Some(data.to_vec());
        Ok(())
    }

    fn get(&mut self, offer: &Offer, index: u32) -> std::io::Result<Vec<u8>> {
        let inner = self.inner.lock().expect("store lock");
        inner
            .chunks
            .get(&offer.transfer)
            .and_then(|c| c.get(index as usize)?.clone())
            .ok_or_else(|| std::io::Error::other("no such chunk"))
    }

    fn assemble(&mut self, offer: &Offer) -> std::io::Result<Vec<u8>> {
        let inner = self.inner.lock().expect("store lock");
        let chunks = inner
            .chunks
            .get(&offer.transfer)
            .ok_or_else(|| std::io::Error::other("no such transfer"))?;
        let mut file = Vec::with_capacity(offer.size as usize);
        for c in chunks {
            let c = c
                .as_ref()
                .ok_or_else(|| std::io::Error::other("a chunk is missing"))?;
            file.extend_from_slice(c);
        }
        Ok(file)
    }

    fn discard(&mut self, offer: &Offer) -> std::io::Result<()> {
        let mut inner = self.inner.lock().expect("store lock");
        inner.chunks.remove(&offer.transfer);
        if inner.pending.is_some_and(|p| p.transfer == offer.transfer) {
            inner.pending = None;
        }
        Ok(())
    }

    fn pending(&mut self) -> std::io::Result<Option<Offer>> {
        Ok(self.inner.lock().expect("store lock").pending)
    }
}

/// Chunks on disk: `DIR/<transfer hex>/<index>.chunk`, each written to a
/// temporary file, synced and renamed, so a chunk is either whole or absent.
#[derive(Debug, Clone)]
pub struct DirStore {
    dir: std::path::PathBuf,
}

impl DirStore {
    pub fn new(dir: impl Into<std::path::PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    fn transfer_dir(&self, offer: &Offer) -> std::path::PathBuf {
        self.dir.join(twindrive_plan::hex(&offer.transfer))
    }
}

impl ChunkStore for DirStore {
    fn open(&mut self, offer: &Offer) -> std::io::Result<Vec<bool>> {
        let dir = self.transfer_dir(offer);
        std::fs::create_dir_all(&dir)?;
        let offer_bytes = postcard::to_allocvec(offer).map_err(std::io::Error::other)?;
        write_durably(&dir.join("offer"), &offer_bytes)?;
        let mut have = vec![false; offer.chunks() as usize];
        for entry in std::fs::read_dir(&dir)? {
            let name = entry?.file_name().to_string_lossy().into_owned();
            if let Some(k) = name
                .strip_suffix(".chunk")
                .and_then(|k| k.parse::<usize>().ok())
                && k < have.len()
            {
                have[k] = true;
            }
        }
        Ok(have)
    }

    fn put(&mut self, offer: &Offer, index: u32, data: &[u8]) -> std::io::Result<()> {
        write_durably(
            &self.transfer_dir(offer).join(format!("{index}.chunk")),
            data,
        )
    }

    fn get(&mut self, offer: &Offer, index: u32) -> std::io::Result<Vec<u8>> {
        std::fs::read(self.transfer_dir(offer).join(format!("{index}.chunk")))
    }

    fn assemble(&mut self, offer: &Offer) -> std::io::Result<Vec<u8>> {
        let dir = self.transfer_dir(offer);
        let mut file = Vec::with_capacity(offer.size as usize);
        for k in 0..offer.chunks() {
            file.extend(std::fs::read(dir.join(format!("{k}.chunk")))?);
        }
        Ok(file)
    }

    fn discard(&mut self, offer: &Offer) -> std::io::Result<()> {
        match std::fs::remove_dir_all(self.transfer_dir(offer)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
            _ => Ok(()),
        }
    }

    fn pending(&mut self) -> std::io::Result<Option<Offer>> {
        let entries = match std::fs::read_dir(&self.dir) {
            Ok(entries) => entries,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(e),
        };
        // The most recently touched transfer with a readable offer.
        let mut best: Option<(std::time::SystemTime, Offer)> = None;
        for entry in entries {
            let path = entry?.path().join("offer");
            let Ok(bytes) = std::fs::read(&path) else {
                continue;
            };
            let Ok(offer) = postcard::from_bytes::<Offer>(&bytes) else {
                continue;
            };
            let modified = std::fs::metadata(&path)?.modified()?;
            if best.as_ref().is_none_or(|(t, _)| modified > *t) {
                best = Some((modified, offer));
            }
        }
        Ok(best.map(|(_, offer)| offer))
    }
}

/// Writes `data` to a temporary file beside `path`, syncs it and renames it
/// into place: the file is whole or absent, even across a crash.
pub fn write_durably(path: &std::path::Path, data: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = std::path::PathBuf::from(tmp);
    let mut f = std::fs::File::create(&tmp)?;
    f.write_all(data)?;
    f.sync_all()?;
    std::fs::rename(&tmp, path)?;
    if let Some(dir) = path.parent()
        && let Ok(d) = std::fs::File::open(dir)
    {
        // The rename itself survives a power cut once the directory is synced.
        let _ = d.sync_all();
    }
    Ok(())
}
