//! The master-robot link over zenoh.
//!
//! [`open_session`] opens a zenoh session: peer mode with multicast
//! scouting off by default (loopback, or `--listen` / `--connect` endpoints
//! for two machines), or any standard zenoh JSON5 configuration (TLS, QUIC,
//! client mode through a router). [`drive`] runs one of `twindrive-link`'s
//! state machines over a session: it publishes what the machine wants sent
//! on one key expression, feeds it what arrives on another, and wakes it
//! when it asks; with a [`twindrive_link::LinkEmulator`] pair it puts the
//! emulated link on every message both ways. The protocol code knows nothing
//! of zenoh: time goes in as nanoseconds since the driver started.
//!
//! Key expressions, per robot id `ID`: `twindrive/ID/up` (master → robot)
//! and `twindrive/ID/down` (robot → master). Every payload is one
//! `twindrive_link::wire` message (protocol version, robot id, sequence
//! number, time stamp); chunking is the protocol's own, so zenoh never
//! fragments a large message.

pub mod ros;

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::path::Path;
use std::time::{Duration, Instant};
pub use zenoh::Session;

use twindrive_link::LinkEmulator;
use twindrive_link::vtime::{Endpoint, InFlight};
use twindrive_link::wire;

/// Master → robot messages for robot `id`.
pub fn up_key(robot_id: &str) -> String {
    format!("twindrive/{robot_id}/up")
}

/// Robot → master messages for robot `id`.
pub fn down_key(robot_id: &str) -> String {
    format!("twindrive/{robot_id}/down")
}

/// How to open a session.
#[derive(Debug, Clone, Default)]
pub struct SessionOptions {
    /// Endpoints to listen on (`tcp/127.0.0.1:7447`).
    pub listen: Vec<String>,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// A zenoh JSON5 configuration file; when given, it decides everything
    /// (`listen` and `connect` are added to it).
    pub config_file: Option<std::path::PathBuf>,
    /// `peer` (default), `client` (through a router) or `router`.
    pub mode: Option<String>,
}

/// Opens a zenoh session as `options` say: by default peer mode, multicast
/// scouting off.
pub async fn open_session(options: &SessionOptions) -> anyhow::Result<zenoh::Session> {
    let mut config = match &options.config_file {
        Some(path) => load_config(path)?,
        None => {
            let mut c = zenoh::Config::default();
            set(&mut c, "mode", "\"peer\"")?;
            set(&mut c, "scouting/multicast/enabled", "false")?;
            c
        }
    };
    if let Some(mode) = &options.mode {
        set(&mut config, "mode", &format!("{mode:?}"))?;
    }
    if !options.listen.is_empty() {
        set(&mut config, "listen/endpoints", &json_list(&options.listen))?;
    }
    if !options.connect.is_empty() {
        set(
            &mut config,
            "connect/endpoints",
            &json_list(&options.connect),
        )?;
    }
    zenoh::open(config)
        .await
        .map_err(|e| anyhow::anyhow!("opening the zenoh session: {e}"))
}

/// [`open_session`], tried again every second while it fails (a client
/// whose router is not up yet, a network still coming up), for at most
/// `patience`. A robot that boots before its link must not give up.
pub async fn open_session_patiently(
    options: &SessionOptions,
    patience: Duration,
) -> anyhow::Result<zenoh::Session> {
    let started = Instant::now();
    loop {
        match open_session(options).await {
            Ok(s) => return Ok(s),
            Err(e) if started.elapsed() < patience => {
                tracing::warn!("{e:#}; trying again in 1 s");
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
            Err(e) => {
                return Err(e.context(format!(
                    "gave up after {:.0} s",
                    started.elapsed().as_secs_f64()
                )));
            }
        }
    }
}

fn load_config(path: &Path) -> anyhow::Result<zenoh::Config> {
    zenoh::Config::from_file(path)
        .map_err(|e| anyhow::anyhow!("{}: not a zenoh configuration: {e}", path.display()))
}

fn set(config: &mut zenoh::Config, key: &str, value: &str) -> anyhow::Result<()> {
    config
        .insert_json5(key, value)
        .map_err(|e| anyhow::anyhow!("zenoh configuration `{key}` = {value}: {e}"))
}

fn json_list(items: &[String]) -> String {
    let quoted: Vec<String> = items.iter().map(|e| format!("{e:?}")).collect();
    format!("[{}]", quoted.join(","))
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
    /// Payloads that were not messages, or not for this robot: logged and
    /// dropped.
    pub garbage: u64,
}

/// The emulated link both ways, applied at this end of the connection.
pub struct Emulation {
    /// On what this end sends.
    pub outgoing: LinkEmulator,
    /// On what this end receives.
    pub incoming: LinkEmulator,
}

/// Runs `endpoint` over `session`: publishes on `tx_key`, listens on
/// `rx_key`, until `done` says so or `deadline` passes (an error). Messages
/// not for `robot_id` are dropped as garbage.
#[allow(clippy::too_many_arguments)]
pub async fn drive<E: Endpoint>(
    endpoint: &mut E,
    session: &zenoh::Session,
    robot_id: &str,
    tx_key: &str,
    rx_key: &str,
    emulation: Option<Emulation>,
    deadline: Duration,
    done: impl FnMut(&mut E) -> bool,
) -> anyhow::Result<DriveStats> {
    let mut stats = DriveStats::default();
    let zero = Instant::now();
    drive_counting(
        endpoint, session, robot_id, tx_key, rx_key, emulation, deadline, zero, &mut stats, done,
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
    session: &zenoh::Session,
    robot_id: &str,
    tx_key: &str,
    rx_key: &str,
    mut emulation: Option<Emulation>,
    deadline: Duration,
    zero: Instant,
    stats: &mut DriveStats,
    mut done: impl FnMut(&mut E) -> bool,
) -> anyhow::Result<()> {
    let publisher = session
        .declare_publisher(tx_key.to_owned())
        .await
        .map_err(|e| anyhow::anyhow!("declaring the publisher on {tx_key}: {e}"))?;
    let subscriber = session
        .declare_subscriber(rx_key.to_owned())
        .await
        .map_err(|e| anyhow::anyhow!("declaring the subscriber on {rx_key}: {e}"))?;
    // Messages put before zenoh has a route to the other side are lost:
    // wait (a bounded while) until a subscriber matches. The protocol
    // copes either way; this keeps a fresh upload's first pass whole.
    let waiting = Instant::now();
    while waiting.elapsed() < STARTUP_WAIT {
        match publisher.matching_status().await {
            Ok(m) if m.matching() => break,
            Ok(_) => tokio::time::sleep(Duration::from_millis(20)).await,
            Err(e) => {
                tracing::warn!(error = %e, "the publisher's matching status");
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
                publisher
                    .put(bytes)
                    .await
                    .map_err(|e| anyhow::anyhow!("publishing on {tx_key}: {e}"))?;
            } else {
                deliver(endpoint, &bytes, robot_id, now, stats);
            }
        }
        while let Some(message) = endpoint.poll_transmit(now) {
            let mut bytes = wire::encode(&message);
            stats.messages_sent += 1;
            match &mut emulation {
                Some(e) => {
                    if let Some(at) = e.outgoing.send_bytes(now, &mut bytes) {
                        order += 1;
                        delayed.push(Reverse((at, order, true, bytes)));
                    }
                }
                None => publisher
                    .put(bytes)
                    .await
                    .map_err(|e| anyhow::anyhow!("publishing on {tx_key}: {e}"))?,
            }
        }
        if done(endpoint) {
            return Ok(());
        }
        if start.elapsed() > deadline {
            anyhow::bail!(
                "gave up after {:.1} s ({} messages sent, {} received)",
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
            sample = subscriber.recv_async() => {
                let sample = sample.map_err(|e| anyhow::anyhow!("the subscriber on {rx_key} closed: {e}"))?;
                let mut bytes = sample.payload().to_bytes().into_owned();
                let now = now_ns();
                match &mut emulation {
                    Some(e) => {
                        if let Some(at) = e.incoming.send_bytes(now, &mut bytes) {
                            order += 1;
                            delayed.push(Reverse((at, order, false, bytes)));
                        }
                    }
                    None => deliver(endpoint, &bytes, robot_id, now, stats),
                }
            }
            _ = tokio::time::sleep(wake) => {}
        }
    }
}

fn deliver<E: Endpoint>(
    endpoint: &mut E,
    bytes: &[u8],
    robot_id: &str,
    now_ns: u64,
    stats: &mut DriveStats,
) {
    match wire::decode(bytes) {
        Ok(m) if m.robot_id == robot_id => {
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
