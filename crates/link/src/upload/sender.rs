//! The master's side of one upload: offer, paced chunks, repair shards
//! for the tail, answers to NAKs, end-of-file until the receiver finishes.

use std::collections::VecDeque;

use super::fec::tail_block;
use crate::wire::{Body, Message, Offer, Stamper, TransferId, transfer_id};

/// Default chunk payload: small enough for any link's MTU budget.
pub const DEFAULT_CHUNK_BYTES: u32 = 1024;

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
        let (fec_from, fec_repairs) = tail_block(
            chunks,
            chunk_bytes,
            config.loss_hint,
            config.rtt_hint_ns,
            config.pace_bit_s,
        );
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
            self.pace(now_ns, crate::wire::link_bytes(&message));
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
            self.pace(now_ns, crate::wire::link_bytes(&message));
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
            self.pace(now_ns, crate::wire::link_bytes(&message));
            return Some(message);
        }
        None
    }

    fn build_repairs(&mut self) {
        let o = self.offer;
        if o.fec_repairs == 0 || o.fec_from >= o.chunks() {
            return;
        }
        match super::fec::repair_shards(&self.file, &o) {
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

    /// Sends no faster than `pace_bit_s` from now on (`None`: as fast as
    /// asked): a robot's log goes at the telemetry budget while a plan runs
    /// and at the link's rate once none does.
    pub fn set_pace(&mut self, pace_bit_s: Option<f64>) {
        self.config.pace_bit_s = pace_bit_s;
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
