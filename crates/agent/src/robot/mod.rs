//! The robot agent as one state machine: messages and a clock in, messages
//! and wheel commands out.
//!
//! It assembles uploads (durably, so a restart resumes them), accepts a
//! plan only through the [`PlanGate`], drives an accepted plan with the
//! [`Executive`] at the backend's control rate, runs the online augmented
//! EKF on its encoders and absolute poses, sends live [`Status`] summaries
//! within a telemetry budget, hands control back with what it knows when
//! reality departs from the plan, and back-fills its mission log (MCAP) to
//! the master with the same chunked upload the plans travel by, paced to
//! what the budget leaves.
//!
//! Everything it must not forget goes to its [`RobotStore`]: the journal
//! (one JSON object per line: `t`, `event`, details, `wheel_travel_rad`),
//! the last plan counter accepted (replays stay closed), uploads in
//! progress, every accepted plan document (byte for byte the master's
//! `plan.json`, named by its content hash) and its own log of each plan it
//! drove, kept until the master acknowledges it.
//!
//! A restart reads the journal: an upload resumes where it stood; a plan
//! that was executing is marked stopped and is never driven again (no plan
//! step runs twice); logs not yet acknowledged are offered again.
//!
//! - `journal`: what a restart reads from the journal;
//! - `acceptance`: whether a plan that arrived whole is driven;
//! - `run`: driving it, and the hand-back;
//! - `backfill`: the robot's logs home.

mod acceptance;
mod backfill;
mod journal;
mod run;

use std::collections::{HashMap, VecDeque};

use ed25519_dalek::VerifyingKey;
use serde_json::json;
use twindrive_link::envelope::PlanGate;
use twindrive_link::upload::{Receiver, ReceiverConfig, ReceiverEvent, Sender};
use twindrive_link::wire::{
    Body, DetourReport, Handback, Message, PlanPhase, Stamper, Status, TransferId, WindowSample,
};
use twindrive_log::MissionLog;
use twindrive_mission::plan::hex;

use crate::backend::RobotBackend;
use crate::executive::Executive;
use crate::localize::LocalizeSettings;
use crate::navigator::Navigator;
use crate::store::RobotStore;

/// How the agent runs.
#[derive(Debug, Clone)]
pub struct AgentConfig {
    pub robot_id: String,
    /// Keys whose plans this robot accepts.
    pub trusted: Vec<VerifyingKey>,
    /// Unix time (s) at `now_ns = 0` of the clock the agent is driven by.
    pub unix_time_at_zero_s: f64,
    /// Bytes per second the robot may spend on what it sends while it
    /// drives a plan (status, hand-back, log back-fill).
    pub telemetry_budget_bytes_s: f64,
    /// What a plan's log may cost on the link: bytes per second of mission
    /// (`twindrive_log::digest`; the full log stays on the robot).
    pub log_budget_bytes_s: f64,
    /// Shortest time between two status summaries (s).
    pub status_period_s: f64,
    /// Backend seconds per second of the driving clock (1 for a real robot;
    /// more runs a simulated site faster than real time).
    pub time_scale: f64,
    /// Largest signed plan file accepted.
    pub max_plan_file_bytes: u64,
    /// How the robot localizes against each plan's map.
    pub localization: LocalizeSettings,
}

impl AgentConfig {
    pub fn new(robot_id: &str, trusted: Vec<VerifyingKey>) -> Self {
        Self {
            robot_id: robot_id.into(),
            trusted,
            unix_time_at_zero_s: 0.0,
            telemetry_budget_bytes_s: 8_000.0,
            log_budget_bytes_s: twindrive_log::digest::DEFAULT_BUDGET_BYTES_PER_S,
            status_period_s: 1.0,
            time_scale: 1.0,
            max_plan_file_bytes: 16 << 20,
            localization: LocalizeSettings::default(),
        }
    }
}

/// A plan being driven.
struct Running {
    transfer: TransferId,
    exec: Executive,
    /// The augmented EKF and the localizer.
    nav: Navigator,
    /// Whether the localizer has a recent fix (as last journaled).
    localized: bool,
    log: MissionLog,
    /// Backend time of the plan's first tick.
    t0_s: Option<f64>,
    /// Distance from the plan's pose at the latest tick, and the largest
    /// since the plan started, with whether it came on a detour.
    deviation_now_m: f64,
    max_deviation_m: f64,
    max_deviation_on_detour: bool,
    window: VecDeque<WindowSample>,
    pace: run::WindowPace,
    tick: u64,
}

/// A robot log on its way to the master.
struct Backfill {
    plan_sha256: String,
    /// The full-rate MCAP, asked for by the master; else the digest.
    full_rate: bool,
    sender: Sender,
}

/// A plan is driven only by a robot facing its first heading within this (rad).
pub const START_HEADING_RAD: f64 = 0.35;

/// Sent this many times a second at most while a hand-back is unacknowledged.
const HANDBACK_RESEND_S: f64 = 5.0;
/// At most this many detour reports wait for their acknowledgement.
const MAX_DETOUR_REPORTS: usize = 16;
/// Ticks in the hand-back's sensor window, and a sample at most every this
/// many ticks (and at every sweep of a sensor that reads less often).
const WINDOW_TICKS: usize = 200;
const WINDOW_EVERY: u64 = 4;

/// The robot agent.
pub struct RobotAgent<B: RobotBackend, S: RobotStore> {
    config: AgentConfig,
    backend: B,
    store: S,
    last_counter: u64,
    gate: PlanGate,
    stamper: Stamper,
    receiver: Receiver<S::Chunks>,
    /// What became of every plan file seen (from the journal on start).
    known: HashMap<TransferId, PlanPhase>,
    current: Option<(TransferId, PlanPhase)>,
    running: Option<Running>,
    /// Backend time at the last tick.
    backend_t_s: f64,
    /// The next control period: a tick while a plan runs, a hold (zero
    /// commanded) while none does and the backend asks for it.
    next_tick_ns: u64,
    /// The backend wants zero commanded every period while no plan runs.
    holding: bool,
    next_status_ns: u64,
    handback: Option<(Handback, u64)>,
    /// Detour reports not yet acknowledged, each with when it was last
    /// sent (0: not yet).
    detours: VecDeque<(DetourReport, u64)>,
    /// The latest detour report made, and the count of detours so far.
    last_detour: Option<DetourReport>,
    detour_index: u32,
    backfills: VecDeque<Backfill>,
    /// Logs of plans that just ended, written once the hand-back (if any)
    /// has gone: a log takes a while to encode and sync, the hand-back
    /// must not wait for it.
    unwritten: VecDeque<(String, MissionLog)>,
    outbox: VecDeque<Body>,
    last_progress_journaled: u32,
    /// Latest EKF estimate of the wheel parameters and their 3 x 3
    /// covariance (row major; NaN before any).
    params: [f64; 3],
    params_covariance: [f64; 9],
    pose: [f64; 3],
    /// The pose's 3 x 3 covariance (row major; infinite before any estimate).
    pose_covariance: [f64; 9],
    bumps: u32,
    collisions: u32,
    last_bump: bool,
    last_blocked: bool,
    /// Payloads refused before they were read (see [`Self::refused`]).
    refused: u32,
    /// Journal writes that failed (reported in the process log).
    pub journal_errors: u64,
    /// The telemetry budget in force (the master may lower it).
    budget_bytes_s: f64,
    /// The rate logs may come home at while no plan runs, as the master
    /// last said (0: as fast as the link takes them; `None`: not heard yet,
    /// so the telemetry budget).
    backfill_bytes_s: Option<f64>,
    /// When an authentic message from a master last arrived.
    last_heard_master_ns: Option<u64>,
    /// Journal lines not yet taken by [`RobotAgent::take_said`].
    said: VecDeque<String>,
}

/// At most this many journal lines wait for [`RobotAgent::take_said`].
const MAX_SAID: usize = 1_000;

fn pose3(p: &twindrive_kinematics::Pose) -> [f64; 3] {
    [p.x_m, p.y_m, p.heading_rad]
}

impl<B: RobotBackend, S: RobotStore> RobotAgent<B, S> {
    /// Starts (or restarts) the agent on what its store holds.
    pub fn new(config: AgentConfig, backend: B, mut store: S) -> std::io::Result<Self> {
        let last_counter = store.load_counter()?;
        let receiver = Receiver::new(
            &config.robot_id,
            store.chunks()?,
            ReceiverConfig {
                max_file_bytes: config.max_plan_file_bytes,
                ..ReceiverConfig::default()
            },
        );
        let gate = PlanGate {
            robot_id: config.robot_id.clone(),
            trusted: config.trusted.clone(),
            max_signed_bytes: config.max_plan_file_bytes as usize,
            max_plan_bytes: 64 << 20,
        };
        let mut agent = Self {
            stamper: Stamper::new(&config.robot_id),
            store,
            last_counter,
            gate,
            receiver,
            known: HashMap::new(),
            current: None,
            running: None,
            backend_t_s: 0.0,
            next_tick_ns: 0,
            // Zero at once on start, and every period after if the robot
            // needs to hear it.
            holding: true,
            next_status_ns: 0,
            handback: None,
            detours: VecDeque::new(),
            last_detour: None,
            detour_index: 0,
            backfills: VecDeque::new(),
            unwritten: VecDeque::new(),
            outbox: VecDeque::new(),
            last_progress_journaled: 0,
            params: [f64::NAN; 3],
            params_covariance: [f64::NAN; 9],
            pose: [f64::NAN; 3],
            pose_covariance: [f64::INFINITY; 9],
            bumps: 0,
            collisions: 0,
            refused: 0,
            last_bump: false,
            last_blocked: false,
            journal_errors: 0,
            budget_bytes_s: config.telemetry_budget_bytes_s,
            backfill_bytes_s: None,
            last_heard_master_ns: None,
            said: VecDeque::new(),
            config,
            backend,
        };
        agent.recover()?;
        agent.record(
            0,
            "agent_started",
            json!({ "robot_id": agent.config.robot_id }),
        );
        Ok(agent)
    }

    /// How the robot localizes the plans it starts from now on.
    pub fn set_localization(&mut self, settings: LocalizeSettings) {
        self.config.localization = settings;
    }

    pub fn backend(&self) -> &B {
        &self.backend
    }

    pub fn store(&self) -> &S {
        &self.store
    }

    /// Where the current plan stands.
    pub fn current(&self) -> Option<&(TransferId, PlanPhase)> {
        self.current.as_ref()
    }

    /// Whether a plan is being driven.
    pub fn is_executing(&self) -> bool {
        self.running.is_some()
    }

    /// Logs not yet acknowledged by the master.
    pub fn logs_pending(&self) -> usize {
        self.backfills.len() + self.unwritten.len()
    }

    fn unix_now_s(&self, now_ns: u64) -> u64 {
        (self.config.unix_time_at_zero_s + now_ns as f64 * 1e-9).max(0.0) as u64
    }

    fn record(&mut self, now_ns: u64, event: &str, details: serde_json::Value) {
        let mut line = json!({
            "t": now_ns as f64 * 1e-9,
            "unix_s": self.config.unix_time_at_zero_s + now_ns as f64 * 1e-9,
            "event": event,
            "wheel_travel_rad": self.backend.wheel_travel_rad(),
        });
        if let (Some(map), serde_json::Value::Object(d)) = (line.as_object_mut(), details) {
            map.extend(d);
        }
        let mut bytes = serde_json::to_vec(&line).expect("JSON values serialise");
        bytes.push(b'\n');
        if let Err(e) = self.store.append_journal(&bytes) {
            self.journal_errors += 1;
            tracing::error!(error = %e, event, "writing the journal");
        }
        tracing::info!(target: "twindrive::robot", "{line}");
        // For people: the event and its details, without the clock fields.
        let mut details = line.clone();
        if let Some(map) = details.as_object_mut() {
            for k in ["t", "unix_s", "event", "wheel_travel_rad"] {
                map.remove(k);
            }
        }
        if self.said.len() == MAX_SAID {
            self.said.pop_front();
        }
        self.said.push_back(format!(
            "{:7.1} s  {}  {}: {}",
            now_ns as f64 * 1e-9,
            self.config.robot_id,
            event.replace('_', " "),
            details
        ));
    }

    /// The journal's lines since the last call, for people (the process
    /// prints them).
    pub fn take_said(&mut self) -> Vec<String> {
        self.said.drain(..).collect()
    }

    /// What the robot is doing now, in one line.
    pub fn doing(&self) -> String {
        let [x, y, h] = self.believed_pose();
        let what = match (&self.running, &self.current) {
            (Some(r), _) => format!(
                "executing {} % of the plan, {:.1} s in",
                100 * r.exec.progress() / r.exec.plan().samples.len().max(1),
                r.window.back().map_or(0.0, |w| w.plan_t_s)
            ),
            (None, Some((_, PlanPhase::Receiving { received, chunks }))) => {
                format!("receiving a plan, {received} of {chunks} chunks")
            }
            (None, _) => "idle, waiting for a plan".into(),
        };
        format!(
            "robot {}: {what}; at ({x:.2}, {y:.2}) m, {:.0} deg; {} log(s) to send{}",
            self.config.robot_id,
            h.to_degrees(),
            self.logs_pending(),
            if self.handback.is_some() {
                "; hand-back not yet acknowledged"
            } else {
                ""
            }
        )
    }

    fn set_phase(&mut self, transfer: TransferId, phase: PlanPhase) {
        self.known.insert(transfer, phase.clone());
        self.current = Some((transfer, phase));
    }

    /// Takes in a message from the master.
    pub fn handle(&mut self, message: &Message, now_ns: u64) {
        if let Some(r) = &mut self.running {
            r.exec.heard_from_master(self.backend_t_s);
        }
        // A master heard after a silence (a restarted one, a link back from
        // an outage) gets an unacknowledged hand-back at once, not at the
        // next resend.
        let silent_ns = self
            .last_heard_master_ns
            .map_or(u64::MAX, |t| now_ns.saturating_sub(t));
        if silent_ns > (HANDBACK_RESEND_S * 1e9) as u64 {
            if let Some((_, last)) = &mut self.handback {
                *last = 0;
            }
            for (_, last) in &mut self.detours {
                *last = 0;
            }
        }
        self.last_heard_master_ns = Some(now_ns);
        match &message.body {
            Body::Offer(offer) => {
                if let Some(phase) = self.known.get(&offer.transfer) {
                    // Already whole here (the master restarted): say so
                    // again, and where it stands.
                    self.outbox.push_back(Body::Finished {
                        transfer: offer.transfer,
                    });
                    let phase = phase.clone();
                    if self.current.as_ref().is_none_or(|c| c.0 != offer.transfer) {
                        self.current = Some((offer.transfer, phase));
                    }
                    self.next_status_ns = now_ns;
                    return;
                }
                if self.running.is_some() {
                    // One plan at a time: the offer is heard again once
                    // this one ends.
                    return;
                }
                self.receiver.handle(message, now_ns);
            }
            Body::Chunk { .. } | Body::Repair { .. } | Body::EndOfFile { .. } => {
                self.receiver.handle(message, now_ns)
            }
            Body::Nak { transfer, .. }
            | Body::Finished { transfer }
            | Body::Refused { transfer, .. } => {
                if let Some(b) = self
                    .backfills
                    .iter_mut()
                    .find(|b| b.sender.transfer() == *transfer)
                {
                    b.sender.handle(message, now_ns);
                }
            }
            Body::HandbackAck { plan } => {
                if self.handback.as_ref().is_some_and(|(h, _)| h.plan == *plan) {
                    self.handback = None;
                    self.record(
                        now_ns,
                        "handback_acknowledged",
                        json!({ "transfer": hex(plan) }),
                    );
                }
            }
            Body::Heartbeat {
                telemetry_budget_bytes_s,
                backfill_bytes_s,
            } => {
                self.backfill_bytes_s = Some(f64::from(*backfill_bytes_s));
                let budget = f64::from(*telemetry_budget_bytes_s)
                    .clamp(100.0, self.config.telemetry_budget_bytes_s);
                if budget != self.budget_bytes_s {
                    self.budget_bytes_s = budget;
                    self.record(now_ns, "telemetry_budget", json!({ "bytes_per_s": budget }));
                }
            }
            Body::Ping { nonce } => self.outbox.push_back(Body::Pong { nonce: *nonce }),
            Body::LogRequest { plan_sha256 } => self.queue_full_log(plan_sha256, now_ns),
            Body::DetourAck {
                plan,
                index,
                rejoined,
            } => {
                let before = self.detours.len();
                self.detours
                    .retain(|(d, _)| (d.plan, d.index, d.rejoined) != (*plan, *index, *rejoined));
                if self.detours.len() < before {
                    self.record(
                        now_ns,
                        "detour_acknowledged",
                        json!({ "transfer": hex(plan), "index": index, "rejoined": rejoined }),
                    );
                }
            }
            Body::Pong { .. } | Body::Status(_) | Body::Handback(_) | Body::Detour(_) => {}
        }
        self.receiver_events(now_ns);
    }

    fn receiver_events(&mut self, now_ns: u64) {
        while let Some(event) = self.receiver.poll_event() {
            match event {
                ReceiverEvent::Progress { received, chunks } => {
                    // The journal notes every tenth of the way.
                    let step = (chunks / 10).max(1);
                    if received == chunks
                        || received >= self.last_progress_journaled + step
                        || received < self.last_progress_journaled
                    {
                        self.last_progress_journaled = received;
                        self.record(
                            now_ns,
                            "upload_progress",
                            json!({ "received": received, "chunks": chunks }),
                        );
                    }
                    if let Some(t) = self.receiver_transfer() {
                        self.current = Some((t, PlanPhase::Receiving { received, chunks }));
                    }
                }
                ReceiverEvent::Corrupted { index } => {
                    self.record(now_ns, "chunk_corrupted", json!({ "index": index }));
                }
                ReceiverEvent::Refused { reason } => {
                    self.record(now_ns, "upload_refused", json!({ "reason": reason }));
                }
                ReceiverEvent::StorageError(e) => {
                    self.record(now_ns, "storage_error", json!({ "error": e }));
                }
                ReceiverEvent::Completed { transfer, file } => {
                    self.consider(transfer, file, now_ns)
                }
            }
        }
    }

    fn receiver_transfer(&self) -> Option<TransferId> {
        self.current
            .as_ref()
            .filter(|c| matches!(c.1, PlanPhase::Receiving { .. }))
            .map(|c| c.0)
            .or_else(|| self.receiver.current_transfer())
    }

    fn status(&self) -> Status {
        let (progress, plan_t_s, deviation_m, range_residual_m) = match &self.running {
            Some(r) => (
                (r.exec.progress() as u32, r.exec.plan().samples.len() as u32),
                r.window.back().map_or(0.0, |w| w.plan_t_s),
                r.max_deviation_m,
                r.exec.range_residual_m().unwrap_or(f64::NAN),
            ),
            None => ((0, 0), 0.0, f64::NAN, f64::NAN),
        };
        let (deviation_now_m, max_deviation_on_detour, on_detour) = match &self.running {
            Some(r) => (
                r.deviation_now_m,
                r.max_deviation_on_detour,
                r.exec.on_a_detour(),
            ),
            None => (f64::NAN, false, false),
        };
        Status {
            plan: self.current.clone(),
            progress,
            plan_t_s,
            pose: self.believed_pose(),
            params: self.params,
            params_std: [0, 4, 8].map(|i| self.params_covariance[i].sqrt()),
            deviation_m,
            range_residual_m,
            wheel_travel_rad: self.backend.wheel_travel_rad(),
            logs_pending: self.logs_pending() as u32,
            handback_pending: self.handback.is_some(),
            bumps: self.bumps,
            collisions: self.collisions,
            refused: self.refused,
            deviation_now_m,
            max_deviation_on_detour,
            on_detour,
        }
    }

    /// A payload refused before it was read (forged, altered, replayed):
    /// counted, reported in every status, and nothing else. It is not
    /// heard: a supervised plan's dead-man keeps counting.
    pub fn refused(&mut self, _refusal: &twindrive_link::secure::Refusal, _now_ns: u64) {
        self.refused = self.refused.saturating_add(1);
    }

    /// The next message to send at `now_ns`; runs the control ticks due by
    /// then first.
    pub fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        self.run_ticks(now_ns);
        if let Some(body) = self.outbox.pop_front() {
            return Some(self.stamper.stamp(body, now_ns));
        }
        if let Some((h, last)) = &mut self.handback
            && (*last == 0 || now_ns >= *last + (HANDBACK_RESEND_S * 1e9) as u64)
        {
            *last = now_ns.max(1);
            let body = Body::Handback(Box::new(h.clone()));
            return Some(self.stamper.stamp(body, now_ns));
        }
        if let Some((d, last)) = self
            .detours
            .iter_mut()
            .find(|(_, last)| *last == 0 || now_ns >= *last + (HANDBACK_RESEND_S * 1e9) as u64)
        {
            *last = now_ns.max(1);
            let body = Body::Detour(Box::new(d.clone()));
            return Some(self.stamper.stamp(body, now_ns));
        }
        if now_ns >= self.next_status_ns {
            let message = self
                .stamper
                .stamp(Body::Status(Box::new(self.status())), now_ns);
            let bytes = twindrive_link::wire::link_bytes(&message) as f64;
            // A status at most every `status_period_s`, and within a third
            // of the budget.
            let period_s = self
                .config
                .status_period_s
                .max(bytes / (self.budget_bytes_s / 3.0).max(1.0));
            self.next_status_ns = now_ns + (period_s * 1e9) as u64;
            return Some(message);
        }
        if let Some(m) = self.receiver.poll_transmit(now_ns) {
            return Some(m);
        }
        // Everything urgent has gone: the robot's logs.
        self.poll_backfill(now_ns)
    }

    /// When the agent next wants `poll_transmit` called.
    pub fn poll_timeout(&self) -> Option<u64> {
        if !self.outbox.is_empty() || !self.unwritten.is_empty() {
            return Some(0);
        }
        let handback = self.handback.as_ref().map(|(_, last)| {
            if *last == 0 {
                0
            } else {
                last + (HANDBACK_RESEND_S * 1e9) as u64
            }
        });
        let detour = self
            .detours
            .iter()
            .map(|(_, last)| {
                if *last == 0 {
                    0
                } else {
                    last + (HANDBACK_RESEND_S * 1e9) as u64
                }
            })
            .min();
        [
            (self.running.is_some() || self.holding).then_some(self.next_tick_ns),
            Some(self.next_status_ns),
            handback,
            detour,
            self.receiver.poll_timeout(),
            self.backfill_timeout(),
        ]
        .into_iter()
        .flatten()
        .min()
    }
}
