//! The master-robot link over a network: zenoh in the field, an
//! in-process bus in tests.
//!
//! [`Network`] is the transport seam ([`transport`]): a link sends on one
//! key expression and receives on another, and that is all the processes
//! and [`drive`] ask of the network; none of them holds a zenoh type.
//! [`Network::open`] opens zenoh as [`SessionOptions`] say (peer mode with
//! multicast scouting off by default: loopback, or `--listen` /
//! `--connect` endpoints for two machines; or any standard zenoh JSON5
//! configuration: TLS, QUIC, client mode through a router), within a
//! bounded time ([`session`]'s one place where flags and a configuration
//! file become endpoints); [`MemoryBus`] is the same seam in one process.
//! [`drive`] runs one of `twindrive-link`'s state machines over a network:
//! it sends what the machine wants sent on one key expression, feeds it
//! what arrives on another, and wakes it when it asks; with a
//! [`twindrive_link::LinkEmulator`] pair it puts the emulated link on every
//! message both ways. The protocol code knows nothing of the network: time
//! goes in as nanoseconds since the driver started.
//!
//! Key expressions, per robot id `ID`: `twindrive/ID/up` (master → robot)
//! and `twindrive/ID/down` (robot → master). Every payload is one
//! `twindrive_link::wire` message (protocol version, robot id, sequence
//! number, time stamp); chunking is the protocol's own, so zenoh never
//! fragments a large message.

pub mod ros;
pub mod session;
pub mod tls_check;
pub mod tls_log;
pub mod transport;

pub use session::{SessionOptions, plain_error};
pub use tls_log::TlsRefusals;
pub use transport::{MemoryBus, Network};

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::time::{Duration, Instant};

use twindrive_link::LinkEmulator;
use twindrive_link::secure::{Peers, Refusal};
use twindrive_link::vtime::{Endpoint, InFlight};
use twindrive_link::wire;

/// Log directives (`tracing_subscriber::EnvFilter` syntax) that keep the
/// network's routine chatter out of a process's log: zenoh's "scouting
/// delay elapsed" says nothing a user can act on.
pub const QUIET_LOG_DIRECTIVES: &str = "zenoh::net::runtime::orchestrator=error";

/// Master → robot messages for robot `id`.
pub fn up_key(robot_id: &str) -> String {
    format!("twindrive/{robot_id}/up")
}

/// Robot → master messages for robot `id`.
pub fn down_key(robot_id: &str) -> String {
    format!("twindrive/{robot_id}/down")
}

/// How long [`drive`] waits for the other side's subscriber before it
/// starts anyway.
pub const STARTUP_WAIT: Duration = Duration::from_secs(3);

/// What the driver saw on the way.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DriveStats {
    pub messages_sent: u64,
    pub messages_received: u64,
    /// Bytes of the messages received for this robot.
    pub bytes_received: u64,
    /// Authentic payloads that were not messages, or not for this robot:
    /// logged and dropped.
    pub garbage: u64,
    /// Payloads refused before they were read (not sealed, not authentic,
    /// replays): logged (a line at most every [`REFUSAL_LOG_PERIOD`]) and
    /// dropped.
    pub refused: u64,
}

/// At most one log line per this while about refused payloads (with how
/// many since the last).
pub const REFUSAL_LOG_PERIOD: Duration = Duration::from_secs(10);

/// One robot's link at this end: where it sends and listens, and the
/// sealing every message goes through.
pub struct LinkEnd {
    pub robot_id: String,
    pub tx_key: String,
    pub rx_key: String,
    pub peers: Peers,
    last_refusal_log: Option<Instant>,
    refused_unlogged: u64,
}

impl LinkEnd {
    /// The master's end of robot `robot_id`'s link.
    pub fn master(robot_id: &str, peers: Peers) -> Self {
        Self::new(robot_id, up_key(robot_id), down_key(robot_id), peers)
    }

    /// The robot's end.
    pub fn robot(robot_id: &str, peers: Peers) -> Self {
        Self::new(robot_id, down_key(robot_id), up_key(robot_id), peers)
    }

    fn new(robot_id: &str, tx_key: String, rx_key: String, peers: Peers) -> Self {
        Self {
            robot_id: robot_id.into(),
            tx_key,
            rx_key,
            peers,
            last_refusal_log: None,
            refused_unlogged: 0,
        }
    }

    /// Logs a refusal: the first at once, then a line at most every
    /// [`REFUSAL_LOG_PERIOD`] with the count since.
    fn log_refusal(&mut self, refusal: &Refusal, bytes: usize) {
        self.refused_unlogged += 1;
        let due = self
            .last_refusal_log
            .is_none_or(|at| at.elapsed() >= REFUSAL_LOG_PERIOD);
        if due {
            tracing::warn!(
                key = %self.rx_key,
                bytes,
                refused = self.refused_unlogged,
                kind = refusal.kind(),
                "refused a payload before reading it: {refusal}"
            );
            self.last_refusal_log = Some(Instant::now());
            self.refused_unlogged = 0;
        }
    }
}

/// The emulated link both ways, applied at this end of the connection.
pub struct Emulation {
    /// On what this end sends.
    pub outgoing: LinkEmulator,
    /// On what this end receives.
    pub incoming: LinkEmulator,
}

/// Runs `endpoint` over `network` on `link` (sealing what it sends on
/// `link.tx_key`, opening what arrives on `link.rx_key`), until `done`
/// says so or `deadline` passes (an error). Payloads that do not open are
/// refused before anything reads them; messages not for the link's robot
/// are dropped as garbage.
pub async fn drive<E: Endpoint>(
    endpoint: &mut E,
    network: &Network,
    link: &mut LinkEnd,
    emulation: Option<Emulation>,
    deadline: Duration,
    done: impl FnMut(&mut E) -> bool,
) -> anyhow::Result<DriveStats> {
    let mut stats = DriveStats::default();
    let zero = Instant::now();
    drive_counting(
        endpoint, network, link, emulation, deadline, zero, &mut stats, done,
    )
    .await
    .map(|()| stats)
}

/// [`drive`] on a clock whose zero is `zero` (the endpoint's `now_ns`
/// counts from it; an owner that also stamps Unix time takes both at one
/// moment), counting into `stats` as it goes (they hold what happened when
/// it fails too).
#[allow(clippy::too_many_arguments)]
pub async fn drive_counting<E: Endpoint>(
    endpoint: &mut E,
    network: &Network,
    link: &mut LinkEnd,
    mut emulation: Option<Emulation>,
    deadline: Duration,
    zero: Instant,
    stats: &mut DriveStats,
    mut done: impl FnMut(&mut E) -> bool,
) -> anyhow::Result<()> {
    let (tx_key, rx_key) = (link.tx_key.clone(), link.rx_key.clone());
    let mut channel = network.channel(&tx_key, &rx_key).await?;
    // Messages put before the network has a route to the other side are
    // lost: wait (a bounded while) until someone listens. The protocol
    // copes either way; this keeps a fresh upload's first pass whole.
    let waiting = Instant::now();
    while waiting.elapsed() < STARTUP_WAIT {
        match channel.listened().await {
            Ok(true) => break,
            Ok(false) => tokio::time::sleep(Duration::from_millis(20)).await,
            Err(e) => {
                tracing::warn!(error = %e, "whether anyone listens");
                break;
            }
        }
    }
    let start = zero;
    let now_ns = || start.elapsed().as_nanos() as u64;
    // Emulated delays: (due time, order, outgoing?, bytes).
    let mut delayed: BinaryHeap<InFlight> = BinaryHeap::new();
    let mut order = 0u64;
    loop {
        let now = now_ns();
        // Emulated messages that are due.
        while delayed.peek().is_some_and(|Reverse(d)| d.0 <= now) {
            let Reverse((_, _, outgoing, bytes)) = delayed.pop().expect("peeked");
            if outgoing {
                channel.send(bytes).await?;
            } else {
                deliver(endpoint, link, &bytes, now, stats);
            }
        }
        while let Some(message) = endpoint.poll_transmit(now) {
            let mut bytes = link
                .peers
                .seal(&wire::encode(&message))
                .map_err(|e| anyhow::anyhow!("sealing a message on {tx_key}: {e}"))?;
            stats.messages_sent += 1;
            match &mut emulation {
                Some(e) => {
                    if let Some(at) = e.outgoing.send_bytes(now, &mut bytes) {
                        order += 1;
                        delayed.push(Reverse((at, order, true, bytes)));
                    }
                }
                None => channel.send(bytes).await?,
            }
        }
        if done(endpoint) {
            return Ok(());
        }
        if start.elapsed() > deadline {
            // Heard from the other end, but nothing that authenticated:
            // the keys do not match, and the message says which to check.
            let keys = if stats.messages_received == 0 && stats.refused > 0 {
                format!(
                    "; all {} message(s) heard on {rx_key} were refused as not authentic: the two ends' keys do not match (each end must trust the other's public key: the robot's --trust, the master's --trust-robot {}.pub)",
                    stats.refused, link.robot_id
                )
            } else {
                String::new()
            };
            anyhow::bail!(
                "gave up after {:.1} s ({} messages sent, {} received){keys}",
                deadline.as_secs_f64(),
                stats.messages_sent,
                stats.messages_received
            );
        }
        let now = now_ns();
        let wake = [
            endpoint.poll_timeout(),
            delayed.peek().map(|Reverse(d)| d.0),
        ]
        .into_iter()
        .flatten()
        .min()
        .map_or(Duration::from_millis(50), |t| {
            Duration::from_nanos(t.saturating_sub(now)).min(Duration::from_millis(50))
        });
        tokio::select! {
            bytes = channel.recv() => {
                let mut bytes = bytes?;
                let now = now_ns();
                match &mut emulation {
                    Some(e) => {
                        if let Some(at) = e.incoming.send_bytes(now, &mut bytes) {
                            order += 1;
                            delayed.push(Reverse((at, order, false, bytes)));
                        }
                    }
                    None => deliver(endpoint, link, &bytes, now, stats),
                }
            }
            _ = tokio::time::sleep(wake) => {}
        }
    }
}

/// Opens a payload and hands its message in; refuses (and counts) what
/// does not open before anything reads it.
fn deliver<E: Endpoint>(
    endpoint: &mut E,
    link: &mut LinkEnd,
    bytes: &[u8],
    now_ns: u64,
    stats: &mut DriveStats,
) {
    let plain = match link.peers.open(bytes) {
        Ok(plain) => plain,
        Err(refusal) => {
            stats.refused += 1;
            link.log_refusal(&refusal, bytes.len());
            endpoint.refused(&refusal, now_ns);
            return;
        }
    };
    match wire::decode(&plain) {
        Ok(m) if m.robot_id == link.robot_id => {
            stats.messages_received += 1;
            stats.bytes_received += bytes.len() as u64;
            endpoint.handle(&m, now_ns);
        }
        Ok(m) => {
            stats.garbage += 1;
            tracing::warn!(robot = %m.robot_id, "dropped a message for another robot");
        }
        Err(e) => {
            stats.garbage += 1;
            tracing::warn!(bytes = bytes.len(), error = %e, "dropped a payload that is not a message");
        }
    }
}
