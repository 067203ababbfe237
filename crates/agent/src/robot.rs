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
//! Everything it must not forget lives in its state directory:
//! - `journal.jsonl`: one JSON object per line (`t`, `event`, details,
//!   `wheel_travel_rad`), synced on every line;
//! - `counter`: the last plan counter accepted (replays stay closed);
//! - `chunks/`: uploads in progress;
//! - `plans/<sha256>.json`: every accepted plan document, byte for byte the
//!   master's `plan.json` (named by its content hash);
//! - `logs/<sha256>/`: the robot's own log of each plan it drove
//!   (`log.mcap`, `log.csv`, `log.meta.json`), kept until the master
//!   acknowledges it.
//!
//! A restart reads the journal: an upload resumes where it stood; a plan
//! that was executing is marked stopped and is never driven again (no plan
//! step runs twice); logs not yet acknowledged are offered again.

use std::collections::{HashMap, VecDeque};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use ed25519_dalek::VerifyingKey;
use serde_json::json;
use twindrive_link::envelope::{CounterFile, PlanGate};
use twindrive_link::upload::{
    DirStore, Receiver, ReceiverConfig, ReceiverEvent, Sender, SenderConfig,
};
use twindrive_link::wire::{
    Body, Handback, Message, PlanPhase, Stamper, Status, TransferId, WindowSample,
};
use twindrive_log::{MissionLog, StepRecord};
use twindrive_mission::plan::{MissionPlan, hex};

use crate::backend::RobotBackend;
use crate::executive::{Executive, Stop};
use crate::localize::{LocalizeSettings, Mode};
use crate::navigator::{Navigator, initial_estimate, with_learnt_params};

/// How the agent runs.
#[derive(Debug, Clone)]
pub struct AgentConfig {
    pub robot_id: String,
    pub state_dir: PathBuf,
    /// Keys whose plans this robot accepts.
    pub trusted: Vec<VerifyingKey>,
    /// Unix time (s) at `now_ns = 0` of the clock the agent is driven by.
    pub unix_time_at_zero_s: f64,
    /// Bytes per second the robot may spend on what it sends (status,
    /// hand-back, log back-fill).
    pub telemetry_budget_bytes_s: f64,
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
    pub fn new(robot_id: &str, state_dir: impl Into<PathBuf>, trusted: Vec<VerifyingKey>) -> Self {
        Self {
            robot_id: robot_id.into(),
            state_dir: state_dir.into(),
            trusted,
            unix_time_at_zero_s: 0.0,
            telemetry_budget_bytes_s: 8_000.0,
            status_period_s: 1.0,
            time_scale: 1.0,
            max_plan_file_bytes: 16 << 20,
            localization: LocalizeSettings::default(),
        }
    }
}

/// The journal: one JSON object per line, synced as written.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
}

impl Journal {
    pub fn new(path: PathBuf) -> Self {
        Self { path }
    }

    /// Appends one line; a failure is reported to the caller's log, and the
    /// robot carries on (its safety never depends on the journal).
    pub fn append(&self, line: &serde_json::Value) -> std::io::Result<()> {
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.path)?;
        let mut bytes = serde_json::to_vec(line).expect("JSON values serialise");
        bytes.push(b'\n');
        f.write_all(&bytes)?;
        f.sync_data()
    }

    /// Every line that parses (a torn last line from a power cut is skipped).
    pub fn read(path: &Path) -> std::io::Result<Vec<serde_json::Value>> {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(e) => return Err(e),
        };
        Ok(text
            .lines()
            .filter_map(|l| serde_json::from_str(l).ok())
            .collect())
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
    wheels: [f64; 2],
    max_deviation_m: f64,
    window: VecDeque<WindowSample>,
    tick: u64,
}

/// A robot log on its way to the master.
struct Backfill {
    plan_sha256: String,
    sender: Sender,
}

/// A plan is driven only by a robot facing its first heading within this (rad).
pub const START_HEADING_RAD: f64 = 0.35;

/// Sent this many times a second at most while a hand-back is unacknowledged.
const HANDBACK_RESEND_S: f64 = 5.0;
/// Ticks in the hand-back's sensor window, and one kept in this many.
const WINDOW_TICKS: usize = 200;
const WINDOW_EVERY: u64 = 4;

/// The robot agent.
pub struct RobotAgent<B: RobotBackend> {
    config: AgentConfig,
    backend: B,
    journal: Journal,
    counter: CounterFile,
    last_counter: u64,
    gate: PlanGate,
    stamper: Stamper,
    receiver: Receiver<DirStore>,
    /// What became of every plan file seen (from the journal on start).
    known: HashMap<TransferId, PlanPhase>,
    current: Option<(TransferId, PlanPhase)>,
    running: Option<Running>,
    /// Backend time at the last tick.
    backend_t_s: f64,
    next_tick_ns: u64,
    next_status_ns: u64,
    handback: Option<(Handback, u64)>,
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
    /// Journal writes that failed (reported in the process log).
    pub journal_errors: u64,
    /// The telemetry budget in force (the master may lower it).
    budget_bytes_s: f64,
    /// Journal lines not yet taken by [`RobotAgent::take_said`].
    said: VecDeque<String>,
}

/// At most this many journal lines wait for [`RobotAgent::take_said`].
const MAX_SAID: usize = 1_000;

fn pose3(p: &twindrive_kinematics::Pose) -> [f64; 3] {
    [p.x_m, p.y_m, p.heading_rad]
}

fn transfer_from_hex(s: &str) -> Option<TransferId> {
    if s.len() != 64 {
        return None;
    }
    let mut out = [0u8; 32];
    for (k, byte) in out.iter_mut().enumerate() {
        *byte = u8::from_str_radix(s.get(2 * k..2 * k + 2)?, 16).ok()?;
    }
    Some(out)
}

impl<B: RobotBackend> RobotAgent<B> {
    /// Starts (or restarts) the agent on its state directory.
    pub fn new(config: AgentConfig, backend: B) -> std::io::Result<Self> {
        let dir = &config.state_dir;
        for sub in ["chunks", "plans", "logs"] {
            std::fs::create_dir_all(dir.join(sub))?;
        }
        let journal = Journal::new(dir.join("journal.jsonl"));
        let counter = CounterFile::new(dir.join("counter"));
        let last_counter = counter.load()?;
        let receiver = Receiver::new(
            &config.robot_id,
            DirStore::new(dir.join("chunks")),
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
            journal,
            counter,
            last_counter,
            gate,
            receiver,
            known: HashMap::new(),
            current: None,
            running: None,
            backend_t_s: 0.0,
            next_tick_ns: 0,
            next_status_ns: 0,
            handback: None,
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
            last_bump: false,
            journal_errors: 0,
            budget_bytes_s: config.telemetry_budget_bytes_s,
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

    /// Reads the journal of an earlier run: what each plan file became, a
    /// plan interrupted mid-run (now stopped for good), logs to offer again.
    fn recover(&mut self) -> std::io::Result<()> {
        let lines = Journal::read(&self.journal.path)?;
        let mut executing: Option<TransferId> = None;
        let mut logs: Vec<(String, bool)> = Vec::new();
        for line in &lines {
            let event = line["event"].as_str().unwrap_or_default();
            let transfer = line["transfer"].as_str().and_then(transfer_from_hex);
            let reason = line["reason"].as_str().unwrap_or_default().to_string();
            match (event, transfer) {
                ("plan_accepted", Some(t)) => {
                    self.known.insert(t, PlanPhase::Executing);
                }
                ("plan_rejected", Some(t)) => {
                    self.known.insert(t, PlanPhase::Rejected { reason });
                }
                ("execution_started", Some(t)) => executing = Some(t),
                ("execution_finished", Some(t)) => {
                    self.known.insert(t, PlanPhase::Finished);
                    executing = None;
                }
                ("stopped", Some(t)) => {
                    self.known.insert(t, PlanPhase::Stopped { reason });
                    executing = None;
                }
                ("log_written", _) => {
                    if let Some(p) = line["plan_sha256"].as_str() {
                        logs.push((p.to_string(), false));
                    }
                }
                ("log_acknowledged", _) => {
                    if let Some(p) = line["plan_sha256"].as_str() {
                        for l in logs.iter_mut().filter(|l| l.0 == p) {
                            l.1 = true;
                        }
                    }
                }
                _ => {}
            }
        }
        // Any plan accepted and never started, or started and never ended,
        // is stopped: a restart never drives a plan (or a step of one) again.
        let unfinished: Vec<TransferId> = self
            .known
            .iter()
            .filter(|(_, p)| matches!(p, PlanPhase::Executing))
            .map(|(t, _)| *t)
            .collect();
        for t in unfinished {
            let reason = if executing == Some(t) {
                "restarted_mid_execution"
            } else {
                "restarted_before_execution"
            };
            self.known.insert(
                t,
                PlanPhase::Stopped {
                    reason: reason.into(),
                },
            );
            self.record(
                0,
                "stopped",
                json!({ "transfer": hex(&t), "reason": reason }),
            );
            self.current = Some((
                t,
                PlanPhase::Stopped {
                    reason: reason.into(),
                },
            ));
        }
        for (plan, acked) in logs {
            if !acked {
                self.queue_backfill(&plan);
            }
        }
        Ok(())
    }

    /// How the robot localizes the plans it starts from now on.
    pub fn set_localization(&mut self, settings: LocalizeSettings) {
        self.config.localization = settings;
    }

    pub fn backend(&self) -> &B {
        &self.backend
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
        if let Err(e) = self.journal.append(&line) {
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
            } => {
                let budget = f64::from(*telemetry_budget_bytes_s)
                    .clamp(100.0, self.config.telemetry_budget_bytes_s);
                if budget != self.budget_bytes_s {
                    self.budget_bytes_s = budget;
                    self.record(now_ns, "telemetry_budget", json!({ "bytes_per_s": budget }));
                }
            }
            Body::Ping { nonce } => self.outbox.push_back(Body::Pong { nonce: *nonce }),
            Body::Pong { .. } | Body::Status(_) | Body::Handback(_) => {}
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

    /// A whole plan file arrived: through the gate, or refused.
    fn consider(&mut self, transfer: TransferId, file: Vec<u8>, now_ns: u64) {
        let now_unix = self.unix_now_s(now_ns);
        let checked = self
            .gate
            .check(&file, self.last_counter, now_unix)
            .map_err(|r| r.to_string())
            .and_then(|accepted| {
                self.fits(&accepted.plan)?;
                self.at_start(&accepted.plan, &accepted.envelope.tolerances)?;
                Ok(accepted)
            });
        match checked {
            Err(reason) => {
                self.record(
                    now_ns,
                    "plan_rejected",
                    json!({ "transfer": hex(&transfer), "reason": reason }),
                );
                self.set_phase(transfer, PlanPhase::Rejected { reason });
            }
            Ok(accepted) => {
                let sha = accepted.plan.sha256.clone();
                let path = self
                    .config
                    .state_dir
                    .join("plans")
                    .join(format!("{sha}.json"));
                let stored = twindrive_link::upload::write_durably(&path, &accepted.plan_json)
                    .and_then(|()| self.counter.store(accepted.envelope.counter));
                if let Err(e) = stored {
                    let reason = format!("storing the plan: {e}");
                    self.record(
                        now_ns,
                        "plan_rejected",
                        json!({ "transfer": hex(&transfer), "reason": reason }),
                    );
                    self.set_phase(transfer, PlanPhase::Rejected { reason });
                    return;
                }
                self.last_counter = accepted.envelope.counter;
                self.record(
                    now_ns,
                    "plan_accepted",
                    json!({
                        "transfer": hex(&transfer),
                        "plan_sha256": sha,
                        "counter": accepted.envelope.counter,
                        "samples": accepted.plan.samples.len(),
                        "path": format!("plans/{sha}.json"),
                    }),
                );
                let env = accepted.envelope;
                self.start(transfer, Arc::new(accepted.plan), &env, now_ns);
            }
        }
        self.next_status_ns = now_ns;
    }

    /// Whether a plan was made for this robot at this site: the site its
    /// twin copies, the encoder resolution and the range beams it predicts.
    fn fits(&self, plan: &MissionPlan) -> Result<(), String> {
        let me = self.backend.log_header();
        let robot = &plan.header.robot;
        if robot.scenario != me.scenario {
            return Err(format!(
                "the plan was rehearsed for site `{}`, this robot is at `{}`",
                robot.scenario, me.scenario
            ));
        }
        if robot.ticks_per_rev != me.ticks_per_rev {
            return Err(format!(
                "the plan is for encoders of {} ticks per revolution, this robot's have {}",
                robot.ticks_per_rev, me.ticks_per_rev
            ));
        }
        let beams = |s: &[twindrive_log::RangeSensorInfo]| -> Vec<(String, u32)> {
            s.iter().map(|r| (r.name.clone(), r.beams)).collect()
        };
        if beams(&robot.range_sensors) != beams(&me.range_sensors) {
            return Err(format!(
                "the plan predicts range sensors {:?}, this robot has {:?}",
                beams(&robot.range_sensors),
                beams(&me.range_sensors)
            ));
        }
        Ok(())
    }

    /// Where the robot believes it is: its estimate at the end of the last
    /// plan it drove, or (before any) what its backend says (a simulated
    /// site's start, a ROS robot's pose or odometry).
    pub fn believed_pose(&self) -> [f64; 3] {
        if self.pose.iter().all(|v| v.is_finite()) {
            self.pose
        } else {
            pose3(&self.backend.log_header().start)
        }
    }

    /// Whether the robot stands where the plan starts: within the plan's
    /// deviation tolerance, and facing its way within [`START_HEADING_RAD`].
    /// A plan that starts elsewhere would be driven from the wrong place,
    /// every step off by the same offset: it is refused before anything
    /// moves, with what to do.
    fn at_start(
        &self,
        plan: &MissionPlan,
        tolerances: &crate::executive::Tolerances,
    ) -> Result<(), String> {
        let [x, y, heading] = self.believed_pose();
        let s = plan.header.start;
        let away_m = (x - s.x_m).hypot(y - s.y_m);
        let turn_rad = twindrive_kinematics::wrap_angle(heading - s.heading_rad).abs();
        if away_m <= tolerances.max_deviation_m && turn_rad <= START_HEADING_RAD {
            return Ok(());
        }
        Err(format!(
            "not at the plan's start: the robot is at ({x:.2}, {y:.2}) m heading {:.0} deg, the plan starts at ({:.2}, {:.2}) m heading {:.0} deg, {away_m:.2} m and {:.0} deg away (at most {:.2} m and {:.0} deg). Nothing moved. Bring the robot to the plan's start, or plan from where it stands (rehearse on the twin from this pose)",
            heading.to_degrees(),
            s.x_m,
            s.y_m,
            s.heading_rad.to_degrees(),
            turn_rad.to_degrees(),
            tolerances.max_deviation_m,
            START_HEADING_RAD.to_degrees(),
        ))
    }

    fn start(
        &mut self,
        transfer: TransferId,
        plan: Arc<MissionPlan>,
        envelope: &twindrive_link::envelope::Envelope,
        now_ns: u64,
    ) {
        let max_wheel = self.backend.log_header().max_wheel_speed_rad_s;
        let exec = match Executive::new(
            plan.clone(),
            envelope.tolerances,
            envelope.supervision.dead_man_timeout_s,
            max_wheel,
        ) {
            Ok(e) => e,
            Err(e) => {
                let reason = format!("the plan cannot be driven: {e}");
                self.record(
                    now_ns,
                    "stopped",
                    json!({ "transfer": hex(&transfer), "reason": reason }),
                );
                self.set_phase(transfer, PlanPhase::Stopped { reason });
                return;
            }
        };
        let mut header = self.backend.log_header();
        header.nominal = plan.header.calibrated;
        self.record(
            now_ns,
            "execution_started",
            json!({ "transfer": hex(&transfer), "plan_sha256": plan.sha256 }),
        );
        self.set_phase(transfer, PlanPhase::Executing);
        // A continuation starts from where the twin refined the robot's
        // pose against its map (from the robot's own estimate and its
        // readings): the robot stands there (`at_start` held) and takes it.
        let (pose, covariance, start) = match plan.header.start_covariance {
            Some(c) => (pose3(&plan.header.start), c, "refined by the twin"),
            None => (
                self.believed_pose(),
                self.pose_covariance,
                "the robot's own",
            ),
        };
        self.pose = pose;
        self.pose_covariance = covariance;
        // The wheel parameters it learnt on earlier plans, when it has.
        let initial = with_learnt_params(
            initial_estimate(pose, Some(&covariance), &plan.header.calibrated),
            self.params,
            &self.params_covariance,
        );
        let nav = Navigator::new(
            &plan,
            initial,
            header.ticks_per_rev,
            self.config.localization,
        );
        let localizer = nav.localizer();
        let how = match localizer.mode() {
            Mode::Scan => format!(
                "matching each scan ({} beams) against the plan's map",
                localizer.beams()
            ),
            Mode::Window => format!(
                "matching {} beam(s) against the plan's map over windows of driving",
                localizer.beams()
            ),
            Mode::None => {
                "no range sensor or no map: odometry only, as without localization".into()
            }
        };
        self.record(
            now_ns,
            "localization",
            json!({ "transfer": hex(&transfer), "how": how, "start": start, "start_pose": pose }),
        );
        self.running = Some(Running {
            transfer,
            exec,
            nav,
            localized: false,
            log: MissionLog::new(header),
            t0_s: None,
            wheels: [0.0, 0.0],
            max_deviation_m: 0.0,
            window: VecDeque::new(),
            tick: 0,
        });
        self.next_tick_ns = now_ns;
    }

    fn tick_period_ns(&self) -> u64 {
        ((self.backend.period_s() / self.config.time_scale.max(1e-6)) * 1e9).max(1.0) as u64
    }

    /// Runs every control tick due by `now_ns` (a process that fell behind
    /// catches up, a bounded number of ticks at a time).
    fn run_ticks(&mut self, now_ns: u64) {
        let period = self.tick_period_ns();
        let mut budget = 1_000;
        while self.running.is_some() && self.next_tick_ns <= now_ns && budget > 0 {
            budget -= 1;
            self.next_tick_ns += period;
            self.tick(now_ns);
        }
    }

    fn tick(&mut self, now_ns: u64) {
        let Some(r) = &mut self.running else {
            return;
        };
        let Some(reading) = self.backend.step(r.wheels) else {
            let reason = "the robot's backend stopped".to_string();
            self.end(Some(Stop::DeadMan { silent_s: 0.0 }), Some(reason), now_ns);
            return;
        };
        self.backend_t_s = reading.t_s;
        let r = self.running.as_mut().expect("running");
        let t0 = *r.t0_s.get_or_insert(reading.t_s - self.backend.period_s());
        // Where the robot is: encoders, any absolute pose, and its range
        // readings matched against the plan's map.
        let belief = r.nav.update(&reading);
        let pose = pose3(&r.nav.pose());
        let covariance = r.nav.pose_covariance();
        r.wheels = r.exec.tick(&reading, &belief);
        r.tick += 1;
        // The robot's own log of this period.
        let mut record: StepRecord = reading.record;
        record.t_ns = ((reading.t_s - t0).max(0.0) * 1e9).round() as u64;
        r.log.steps.push(record);
        r.log.ranges.extend_from_slice(&reading.fresh_ranges_m);
        let reference = r.exec.reference();
        let deviation = (pose[0] - reference.x_m).hypot(pose[1] - reference.y_m);
        r.max_deviation_m = r.max_deviation_m.max(deviation);
        let localizer = r.nav.localizer();
        let localized = localizer.localized(reading.t_s);
        let localization_changed = (localized != r.localized && localizer.mode() != Mode::None)
            .then(|| {
                r.localized = localized;
                (hex(&r.transfer), localizer.fixes, localizer.failures)
            });
        // Every few ticks, and every tick with a contact or a stop.
        if r.tick % WINDOW_EVERY == 0 || reading.bump || r.exec.stopped().is_some() {
            r.window.push_back(WindowSample {
                plan_t_s: reading.t_s - t0,
                pose,
                ranges_m: reading.ranges_m.iter().map(|&v| v as f32).collect(),
                bump: reading.bump,
            });
            if r.window.len() > WINDOW_TICKS / WINDOW_EVERY as usize {
                r.window.pop_front();
            }
        }
        self.params = r.nav.params();
        self.params_covariance = r.nav.params_covariance();
        self.pose = pose;
        self.pose_covariance = covariance;
        if reading.bump && !self.last_bump {
            self.bumps += 1;
        }
        self.last_bump = reading.bump;
        if reading.blocked {
            self.collisions += 1;
        }
        let stopped = r.exec.stopped().cloned();
        if let Some((transfer, fixes, failures)) = localization_changed {
            let event = if localized {
                "localized"
            } else {
                "not_localized"
            };
            let note = if localized {
                "the range readings match the plan's map: tracking in the site's frame"
            } else {
                "no match with the plan's map for a while: going on by odometry, as without a map"
            };
            self.record(
                now_ns,
                event,
                json!({ "transfer": transfer, "fixes": fixes, "failed_matches": failures, "note": note }),
            );
        }
        if let Some((_, stop)) = stopped {
            self.end(Some(stop), None, now_ns);
        }
    }

    /// The plan ended (or the backend did): record it, write the log, hand
    /// back if reality departed from the plan.
    fn end(&mut self, stop: Option<Stop>, note: Option<String>, now_ns: u64) {
        let Some(r) = self.running.take() else {
            return;
        };
        let plan = r.exec.plan().clone();
        let t = hex(&r.transfer);
        let plan_t_s = r.window.back().map_or(0.0, |w| w.plan_t_s);
        let reason = match (&stop, &note) {
            (_, Some(n)) => n.clone(),
            (Some(s), None) => s.reason().to_string(),
            (None, None) => "stopped".into(),
        };
        if matches!(stop, Some(Stop::Finished)) && note.is_none() {
            self.record(
                now_ns,
                "execution_finished",
                json!({ "transfer": t, "plan_t_s": plan_t_s, "max_deviation_m": r.max_deviation_m }),
            );
            self.set_phase(r.transfer, PlanPhase::Finished);
        } else {
            self.record(
                now_ns,
                "stopped",
                json!({ "transfer": t, "reason": reason, "plan_t_s": plan_t_s, "stop": stop }),
            );
            self.set_phase(
                r.transfer,
                PlanPhase::Stopped {
                    reason: reason.clone(),
                },
            );
        }
        if let Some(s) = stop.as_ref().filter(|s| s.is_handback()) {
            let (params, covariance) = (r.nav.params(), r.nav.params_covariance());
            let handback = Handback {
                plan: r.transfer,
                reason: s.reason().to_string(),
                plan_t_s,
                progress: r.exec.progress() as u32,
                pose: self.pose,
                pose_covariance: self.pose_covariance,
                params,
                params_covariance: covariance,
                window: r.window.iter().cloned().collect(),
            };
            self.record(
                now_ns,
                "handback",
                json!({
                    "transfer": t,
                    "reason": handback.reason,
                    "plan_t_s": plan_t_s,
                    "pose": handback.pose,
                    "params": handback.params,
                }),
            );
            self.handback = Some((handback, 0));
        }
        self.unwritten.push_back((plan.sha256.clone(), r.log));
        self.next_status_ns = now_ns;
    }

    fn write_log(&mut self, plan_sha256: &str, log: &MissionLog, now_ns: u64) {
        let dir = self.config.state_dir.join("logs").join(plan_sha256);
        let result = (|| -> anyhow::Result<()> {
            std::fs::create_dir_all(&dir)?;
            let mut mcap = std::io::Cursor::new(Vec::new());
            let map = self.backend.map();
            twindrive_log::write_mcap_with_map(log, map.as_ref(), &mut mcap)?;
            let mut csv = Vec::new();
            twindrive_log::write_csv(log, &mut csv)?;
            let meta = serde_json::to_vec_pretty(&log.header)?;
            twindrive_link::upload::write_durably(&dir.join("log.csv"), &csv)?;
            twindrive_link::upload::write_durably(&dir.join("log.meta.json"), &meta)?;
            twindrive_link::upload::write_durably(&dir.join("log.mcap"), mcap.get_ref())?;
            Ok(())
        })();
        match result {
            Ok(()) => {
                self.record(
                    now_ns,
                    "log_written",
                    json!({
                        "plan_sha256": plan_sha256,
                        "steps": log.steps.len(),
                        "dir": format!("logs/{plan_sha256}"),
                    }),
                );
                self.queue_backfill(plan_sha256);
            }
            Err(e) => {
                self.record(
                    now_ns,
                    "log_error",
                    json!({ "plan_sha256": plan_sha256, "error": e.to_string() }),
                );
            }
        }
    }

    fn queue_backfill(&mut self, plan_sha256: &str) {
        if self.backfills.iter().any(|b| b.plan_sha256 == plan_sha256) {
            return;
        }
        let path = self
            .config
            .state_dir
            .join("logs")
            .join(plan_sha256)
            .join("log.mcap");
        match std::fs::read(&path) {
            Ok(file) => {
                let pace = 8.0 * 0.7 * self.budget_bytes_s;
                let sender = Sender::resume(
                    &self.config.robot_id,
                    file,
                    SenderConfig {
                        pace_bit_s: Some(pace.max(800.0)),
                        ..SenderConfig::default()
                    },
                );
                self.backfills.push_back(Backfill {
                    plan_sha256: plan_sha256.into(),
                    sender,
                });
            }
            Err(e) => {
                tracing::error!(path = %path.display(), error = %e, "a robot log to back-fill")
            }
        }
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
            bumps: self.bumps,
            collisions: self.collisions,
        }
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
        if now_ns >= self.next_status_ns {
            let message = self
                .stamper
                .stamp(Body::Status(Box::new(self.status())), now_ns);
            let bytes = twindrive_link::wire::encode(&message).len() as f64;
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
        // Everything urgent has gone: write the logs of plans that ended.
        while let Some((sha, log)) = self.unwritten.pop_front() {
            self.write_log(&sha, &log, now_ns);
        }
        // Logs back-fill one at a time, oldest first.
        while let Some(b) = self.backfills.front_mut() {
            if b.sender.is_finished() || b.sender.refused().is_some() {
                let b = self.backfills.pop_front().expect("front");
                let event = if b.sender.is_finished() {
                    "log_acknowledged"
                } else {
                    "log_refused"
                };
                self.record(now_ns, event, json!({ "plan_sha256": b.plan_sha256 }));
                continue;
            }
            return b.sender.poll_transmit(now_ns);
        }
        None
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
        let backfill = self.backfills.front().and_then(|b| {
            if b.sender.is_finished() || b.sender.refused().is_some() {
                Some(0)
            } else {
                b.sender.poll_timeout()
            }
        });
        [
            self.running.as_ref().map(|_| self.next_tick_ns),
            Some(self.next_status_ns),
            handback,
            self.receiver.poll_timeout(),
            backfill,
        ]
        .into_iter()
        .flatten()
        .min()
    }
}
