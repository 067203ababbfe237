//! Two protocol endpoints joined by an emulated link, in virtual time: the
//! same state machines as over zenoh, deterministic under the emulator's
//! seed, as fast as the machine runs them.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use crate::emulator::{LinkEmulator, LinkProfile};
use crate::secure::{Peers, Refusal};
use crate::upload::{ChunkStore, Receiver, Sender};
use crate::wire::{self, Message};

/// A protocol state machine: messages in and out, time passed in.
pub trait Endpoint {
    fn poll_transmit(&mut self, now_ns: u64) -> Option<Message>;
    fn handle(&mut self, message: &Message, now_ns: u64);
    fn poll_timeout(&self) -> Option<u64>;
    /// A payload arrived that was refused before it was read (not
    /// authentic, a replay): nothing of it reached [`Self::handle`]. An
    /// endpoint that reports counts it.
    fn refused(&mut self, _refusal: &Refusal, _now_ns: u64) {}
}

impl Endpoint for Sender {
    fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        Sender::poll_transmit(self, now_ns)
    }
    fn handle(&mut self, message: &Message, now_ns: u64) {
        Sender::handle(self, message, now_ns)
    }
    fn poll_timeout(&self) -> Option<u64> {
        Sender::poll_timeout(self)
    }
}

impl<S: ChunkStore> Endpoint for Receiver<S> {
    fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        Receiver::poll_transmit(self, now_ns)
    }
    fn handle(&mut self, message: &Message, now_ns: u64) {
        Receiver::handle(self, message, now_ns)
    }
    fn poll_timeout(&self) -> Option<u64> {
        Receiver::poll_timeout(self)
    }
}

/// A message on its way: arrival time, order of sending (ties), whether it
/// goes A → B (or, at one end of a real connection, out), and its bytes.
pub type InFlight = Reverse<(u64, u64, bool, Vec<u8>)>;

/// Changes a message's bytes in flight.
pub type Tamper = Box<dyn FnMut(&mut Vec<u8>)>;

/// Messages in flight both ways between endpoint A (the master) and B (the
/// robot).
pub struct VirtualLink {
    /// A → B.
    pub up: LinkEmulator,
    /// B → A.
    pub down: LinkEmulator,
    in_flight: BinaryHeap<InFlight>,
    order: u64,
    pub now_ns: u64,
    /// Applied to every message's bytes in flight A → B (tests corrupt
    /// chunks with it).
    pub tamper_up: Option<Tamper>,
    /// Bytes that did not decode, per direction (A → B, B → A).
    pub undecodable: [u64; 2],
    /// Every message sealed by its sender's end and opened by its
    /// receiver's (A's, B's), as over zenoh; `None`: plain messages (the
    /// protocol's own tests).
    pub sealed: Option<[Peers; 2]>,
}

impl VirtualLink {
    /// Both directions over `profile`, each with its own random stream of
    /// `seed` (stream 0 up, A → B; stream 1 down).
    pub fn symmetric(profile: &LinkProfile, seed: u64) -> Self {
        Self::new(
            LinkEmulator::new(profile.clone(), seed, 0),
            LinkEmulator::new(profile.clone(), seed, 1),
        )
    }

    pub fn new(up: LinkEmulator, down: LinkEmulator) -> Self {
        Self {
            up,
            down,
            in_flight: BinaryHeap::new(),
            order: 0,
            now_ns: 0,
            tamper_up: None,
            undecodable: [0; 2],
            sealed: None,
        }
    }

    /// Seals every message: `a` is A's end of the link (the master's), `b`
    /// B's.
    pub fn sealed(mut self, a: Peers, b: Peers) -> Self {
        self.sealed = Some([a, b]);
        self
    }

    fn send(&mut self, to_b: bool, message: &Message) {
        let mut bytes = wire::encode(message);
        if let Some(ends) = &mut self.sealed {
            let end = &mut ends[usize::from(!to_b)];
            bytes = end.seal(&bytes).expect("memory epochs never fail");
        }
        let link = if to_b { &mut self.up } else { &mut self.down };
        if let Some(at) = link.send_bytes(self.now_ns, &mut bytes) {
            if to_b && let Some(tamper) = &mut self.tamper_up {
                tamper(&mut bytes);
            }
            self.order += 1;
            self.in_flight.push(Reverse((at, self.order, to_b, bytes)));
        }
    }

    /// Runs both endpoints until `done` says so, nothing is left to happen,
    /// or `until_ns`; returns whether `done` was reached.
    pub fn run<A: Endpoint, B: Endpoint>(
        &mut self,
        a: &mut A,
        b: &mut B,
        until_ns: u64,
        mut done: impl FnMut(&A, &B) -> bool,
    ) -> bool {
        loop {
            while let Some(m) = a.poll_transmit(self.now_ns) {
                self.send(true, &m);
            }
            while let Some(m) = b.poll_transmit(self.now_ns) {
                self.send(false, &m);
            }
            if done(a, b) {
                return true;
            }
            let now = self.now_ns;
            let next = [
                self.in_flight.peek().map(|Reverse(e)| e.0),
                a.poll_timeout().filter(|&t| t > now),
                b.poll_timeout().filter(|&t| t > now),
            ]
            .into_iter()
            .flatten()
            .min();
            let Some(next) = next else {
                return false;
            };
            if next > until_ns {
                self.now_ns = until_ns;
                return false;
            }
            self.now_ns = next.max(now);
            while self
                .in_flight
                .peek()
                .is_some_and(|Reverse(e)| e.0 <= self.now_ns)
            {
                let Reverse((_, _, to_b, bytes)) = self.in_flight.pop().expect("peeked");
                let now = self.now_ns;
                let opened = match &mut self.sealed {
                    Some(ends) => ends[usize::from(to_b)].open(&bytes),
                    None => Ok(bytes),
                };
                match opened.map(|plain| wire::decode(&plain)) {
                    Ok(Ok(m)) if to_b => b.handle(&m, now),
                    Ok(Ok(m)) => a.handle(&m, now),
                    Ok(Err(_)) => self.undecodable[usize::from(!to_b)] += 1,
                    Err(refusal) if to_b => b.refused(&refusal, now),
                    Err(refusal) => a.refused(&refusal, now),
                }
            }
        }
    }

    /// Forgets what is in flight (a process that restarts loses its socket).
    pub fn drop_in_flight(&mut self) {
        self.in_flight.clear();
    }
}
