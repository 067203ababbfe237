//! The robots the console supervises: one master end per robot (its own
//! upload, heartbeats, pings and log assembly), an operator per mission
//! that waits for the person at the page on a hand-back, and what the page
//! shows of each: upload progress, link state, the age of every stream,
//! reported against predicted pose, residuals, the twin's updates.
//!
//! A [`RobotSlot`] is shared between its zenoh driver task (through
//! [`SharedSlot`], a `twindrive_link::vtime::Endpoint`) and the console;
//! nothing in it does network I/O, and time comes in as nanoseconds of the
//! console's clock.

use std::collections::VecDeque;
use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard};

use serde_json::{Value, json};
use twindrive_agent::master::{Master, MasterConfig, MasterEvent};
use twindrive_agent::operator::{OnHandback, Operator, OperatorConfig, Outcome, TimelineEntry};
use twindrive_agent::twin::Twin;
use twindrive_link::envelope::{Envelope, SigningKey, Supervision, Tolerances, sign_plan};
use twindrive_link::vtime::Endpoint;
use twindrive_link::wire::{Body, Handback, Message, PlanPhase, Status, TransferId};
use twindrive_mission::plan::{MissionPlan, PlanGeometry, hex};
use twindrive_sim::Scenario;
use twindrive_store::{DirStore, MasterArchive};

use crate::planning::{columns, freedom_view};

/// Statuses kept for the page's time series (an hour at one a second).
const SERIES_LEN: usize = 3600;

/// A stream is stale when nothing came for this long and this many of its
/// expected periods.
const STALE_S: f64 = 3.0;

/// Everything the page needs to sign a plan for a robot.
pub struct Signing<'a> {
    pub key: &'a SigningKey,
    pub world_sha256: &'a str,
    pub unix_now_s: f64,
    /// Unix time at the console clock's zero.
    pub unix_at_zero_s: f64,
    pub expires_in_s: u64,
    pub supervision: Supervision,
}

enum Link {
    Idle(Box<Master<DirStore>>),
    Operating(Box<Operator<DirStore>>),
}

/// One robot.
pub struct RobotSlot {
    pub id: String,
    /// Its files: plans, robot logs, the report.
    archive: MasterArchive,
    link: Option<Link>,
    /// Console time of the last message from the robot.
    last_rx_ns: Option<u64>,
    last_status_ns: Option<u64>,
    /// Arrival times and encoded sizes of recent messages (for rates).
    rx_times: VecDeque<(u64, usize)>,
    pub messages_received: u64,
    /// Payloads on the robot's key expression refused before they were
    /// read (not authentic, replays).
    pub refused_messages: u64,
    /// (console s, plan s, deviation m, range residual m).
    series: VecDeque<[f64; 4]>,
    series_rev: u64,
    /// Changes when the mission's picture changes (plans, hand-backs, twin
    /// updates, logs).
    mission_rev: u64,
    /// Tracks of the robot's back-filled logs (columns t, x, y).
    logs: Vec<Value>,
    /// A hand-back that arrived while no mission of this console ran (the
    /// robot ran a plan of an earlier master).
    orphan_handback: Option<Handback>,
    /// The latest status of a running plan: its transfer, plan time (s)
    /// and samples passed (where it stopped, once it stops).
    last_run: Option<(TransferId, f64, u32)>,
    /// Entries of the mission's timeline already told to the operator.
    timeline_told: usize,
    /// Lines for the console's event list, not yet taken.
    events: VecDeque<(&'static str, String)>,
    report_written: bool,
    /// Problems worth telling the operator (writing files, say).
    pub notices: VecDeque<String>,
}

/// A robot slot shared by its driver and the console.
#[derive(Clone)]
pub struct SharedSlot(pub Arc<Mutex<RobotSlot>>);

impl SharedSlot {
    pub fn lock(&self) -> MutexGuard<'_, RobotSlot> {
        // A panic elsewhere must not take the console down with it.
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Endpoint for SharedSlot {
    fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        self.lock().poll_transmit(now_ns)
    }
    fn handle(&mut self, message: &Message, now_ns: u64) {
        self.lock().handle(message, now_ns)
    }
    fn poll_timeout(&self) -> Option<u64> {
        self.lock().poll_timeout()
    }
    fn refused(&mut self, _refusal: &twindrive_link::secure::Refusal, _now_ns: u64) {
        self.lock().refused_messages += 1;
    }
}

impl RobotSlot {
    /// A robot `id` whose files go to `out`, laid out as the master's
    /// ([`MasterArchive`]).
    pub fn new(id: &str, out: &Path, config: MasterConfig) -> Self {
        let archive = MasterArchive::new(out);
        let master = Master::new(id, config, archive.log_chunks());
        Self {
            id: id.into(),
            archive,
            link: Some(Link::Idle(Box::new(master))),
            last_rx_ns: None,
            last_status_ns: None,
            rx_times: VecDeque::new(),
            messages_received: 0,
            refused_messages: 0,
            series: VecDeque::new(),
            series_rev: 0,
            mission_rev: 0,
            logs: Vec::new(),
            orphan_handback: None,
            last_run: None,
            timeline_told: 0,
            events: VecDeque::new(),
            report_written: false,
            notices: VecDeque::new(),
        }
    }

    fn link(&mut self) -> &mut Link {
        self.link.as_mut().expect("a link, except inside upload")
    }

    fn master(&self) -> &Master<DirStore> {
        match self.link.as_ref().expect("a link") {
            Link::Idle(m) => m,
            Link::Operating(op) => &op.master,
        }
    }

    fn operator(&self) -> Option<&Operator<DirStore>> {
        match self.link.as_ref().expect("a link") {
            Link::Idle(_) => None,
            Link::Operating(op) => Some(op),
        }
    }

    pub fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        match self.link() {
            Link::Idle(m) => m.poll_transmit(now_ns),
            Link::Operating(op) => op.poll_transmit(now_ns),
        }
    }

    pub fn poll_timeout(&self) -> Option<u64> {
        match self.link.as_ref().expect("a link") {
            Link::Idle(m) => m.poll_timeout(),
            Link::Operating(op) => op.poll_timeout(),
        }
    }

    pub fn handle(&mut self, message: &Message, now_ns: u64) {
        self.messages_received += 1;
        self.last_rx_ns = Some(now_ns);
        self.rx_times
            .push_back((now_ns, twindrive_link::wire::encode(message).len()));
        while self
            .rx_times
            .front()
            .is_some_and(|&(t, _)| t + 10_000_000_000 < now_ns)
        {
            self.rx_times.pop_front();
        }
        if let Body::Status(s) = &message.body {
            self.last_status_ns = Some(now_ns);
            if let Some((t, PlanPhase::Executing)) = &s.plan {
                self.last_run = Some((*t, s.plan_t_s, s.progress.0));
            }
            self.series.push_back([
                now_ns as f64 * 1e-9,
                s.plan_t_s,
                s.deviation_m,
                s.range_residual_m,
            ]);
            if self.series.len() > SERIES_LEN {
                self.series.pop_front();
            }
            self.series_rev += 1;
        }
        match self.link() {
            Link::Idle(m) => {
                m.handle(message, now_ns);
                let mut orphan = None;
                while let Some(event) = m.poll_event() {
                    if let MasterEvent::Handback(h) = event {
                        orphan = Some(*h);
                    }
                }
                if let Some(h) = orphan {
                    self.events.push_back((
                        "warn",
                        format!(
                            "robot {}: hand-back: {} at {:.1} s into a plan of an earlier master",
                            self.id,
                            h.reason.replace('_', " "),
                            h.plan_t_s
                        ),
                    ));
                    self.orphan_handback = Some(h);
                    self.mission_rev += 1;
                }
            }
            Link::Operating(op) => {
                let counts = |op: &Operator<DirStore>| {
                    let r = &op.report;
                    (r.handbacks.len(), r.twin_updates.len(), r.detours.len())
                };
                let before = counts(op);
                op.handle(message, now_ns);
                let after = counts(op);
                if before != after {
                    self.mission_rev += 1;
                }
                self.collect(now_ns);
            }
        }
    }

    /// Writes what the operator produced (continuation plans, robot logs,
    /// the report once the mission is done).
    fn collect(&mut self, _now_ns: u64) {
        let Some(Link::Operating(op)) = self.link.as_mut() else {
            return;
        };
        // Plans by transfer: those uploaded, and the one uploading.
        let mut plans: Vec<(String, &str)> = op
            .report
            .uploads
            .iter()
            .map(|u| (u.transfer.clone(), u.plan_sha256.as_str()))
            .collect();
        if let (Some(t), Some(p)) = (op.master.uploading(), op.current_plan()) {
            plans.push((hex(&t), p.sha256.as_str()));
        }
        for entry in &op.report.timeline[self.timeline_told..] {
            if let Some(line) = event_line(&self.id, entry, &plans) {
                self.events.push_back(line);
            }
        }
        self.timeline_told = op.report.timeline.len();
        let plans: Vec<_> = op.new_plans.drain(..).collect();
        let logs: Vec<_> = op.new_logs.drain(..).collect();
        let done = op.is_done();
        for (plan, json, signed) in &plans {
            let written = self.archive.write_plan(plan, json, Some(signed));
            self.noted("writing a plan", written);
        }
        // Logs come home after the mission is decided: the report lists
        // each as it arrives (written again when one comes after it).
        let mut arrived = Vec::new();
        for log in logs {
            match self
                .archive
                .write_robot_log(log.plan.as_deref(), &log.mcap, log.full_rate)
            {
                Ok(written) => {
                    arrived.push(written.name.clone());
                    let log = written.log;
                    let every = (log.steps.len() / 20_000).max(1);
                    self.logs
                        .push(columns(log.steps.iter().step_by(every).map(|s| {
                            (s.t_ns as f64 * 1e-9, s.ground_truth.x_m, s.ground_truth.y_m)
                        })));
                }
                Err(e) => self.notice(format!("the robot's log: {e:#}")),
            }
        }
        let logs_arrived = !arrived.is_empty();
        let first_report = !self.report_written;
        let report = match self.link.as_mut() {
            Some(Link::Operating(op)) => {
                op.report.robot_logs.extend(arrived);
                (done && (first_report || logs_arrived)).then(|| {
                    if first_report {
                        op.finish_report();
                    }
                    serde_json::to_vec_pretty(&op.report).unwrap_or_default()
                })
            }
            _ => None,
        };
        let changed = !plans.is_empty() || logs_arrived || report.is_some();
        if let Some(report) = report {
            self.report_written = true;
            let written = self.archive.write_report(&report);
            self.noted("writing report.json", written);
        }
        if changed {
            self.mission_rev += 1;
        }
    }

    /// A write's result: a failure becomes a notice for the operator.
    fn noted<T>(&mut self, what: &str, result: std::io::Result<T>) -> Option<T> {
        match result {
            Ok(t) => Some(t),
            Err(e) => {
                let dir = self.archive.dir().display().to_string();
                self.notice(format!("{what} into {dir}: {e}"));
                None
            }
        }
    }

    fn notice(&mut self, text: String) {
        tracing::warn!(robot = %self.id, "{text}");
        self.notices.push_back(text);
        if self.notices.len() > 20 {
            self.notices.pop_front();
        }
        self.mission_rev += 1;
    }

    /// Whether a mission of this console is under way (not yet decided).
    pub fn busy(&self) -> bool {
        self.operator()
            .is_some_and(|op| op.report.outcome.is_none())
    }

    /// Signs `plan` for this robot and starts uploading it; the operator
    /// waits for the person on a hand-back.
    pub fn upload(
        &mut self,
        plan: Arc<MissionPlan>,
        plan_json: &[u8],
        twin: &Scenario,
        signing: &Signing,
        now_ns: u64,
    ) -> Result<String, String> {
        if self.busy() {
            return Err(format!(
                "robot {}: a mission is under way; end it (or let it finish) first",
                self.id
            ));
        }
        // Counters only grow: milliseconds of Unix time.
        let counter = (signing.unix_now_s * 1e3) as u64;
        let envelope = Envelope::new(
            &self.id,
            counter,
            signing.unix_now_s as u64,
            signing.expires_in_s,
            signing.world_sha256.to_owned(),
            signing.supervision,
            Tolerances::default(),
        );
        let signed = sign_plan(signing.key, plan_json, envelope)
            .map_err(|e| format!("signing the plan: {e}"))?;
        let master = match self.link.take().expect("a link") {
            Link::Idle(m) => *m,
            Link::Operating(op) => op.into_master(),
        };
        let mut op = Operator::new(
            master,
            Some(Twin::new(twin.clone(), plan.header.calibrated)),
            Some(signing.key.clone()),
            OperatorConfig {
                on_handback: OnHandback::Ask,
                expires_in_s: signing.expires_in_s,
                supervision: signing.supervision,
                ..OperatorConfig::replanning(
                    &self.id,
                    counter,
                    signing.world_sha256.to_owned(),
                    signing.unix_at_zero_s,
                )
            },
        );
        let stem = plan.sha256[..12].to_owned();
        let written = self.archive.write_plan(&plan, plan_json, Some(&signed));
        self.noted("writing the plan", written);
        let bytes = signed.len();
        op.start(plan, signed, counter, false, now_ns);
        self.link = Some(Link::Operating(Box::new(op)));
        self.orphan_handback = None;
        self.timeline_told = 0;
        self.logs.clear();
        self.report_written = false;
        self.mission_rev += 1;
        Ok(format!(
            "robot {}: uploading plan {stem} ({bytes} bytes signed)",
            self.id
        ))
    }

    /// Continues after a hand-back: the rest of the plan from the hand-back
    /// pose around what the twin learnt, verified, signed and uploaded.
    pub fn replan(&mut self, now_ns: u64) -> Result<String, String> {
        let Some(Link::Operating(op)) = self.link.as_mut() else {
            return Err(format!("robot {}: no mission to continue", self.id));
        };
        op.replan(now_ns)
            .map_err(|e| format!("robot {}: {e:#}", self.id))?;
        self.collect(now_ns);
        self.mission_rev += 1;
        Ok(format!("robot {}: continuation uploading", self.id))
    }

    /// Ends the mission at a hand-back.
    pub fn end_mission(&mut self, now_ns: u64) -> Result<String, String> {
        let Some(Link::Operating(op)) = self.link.as_mut() else {
            self.orphan_handback = None;
            self.mission_rev += 1;
            return Ok(format!("robot {}: nothing to end", self.id));
        };
        op.end_mission(now_ns);
        self.collect(now_ns);
        self.mission_rev += 1;
        Ok(format!("robot {}: mission ended", self.id))
    }

    /// Lets the operator act on what the master reported (called by the
    /// console's tick: time passing decides things too).
    pub fn tick(&mut self, now_ns: u64) {
        if let Some(Link::Operating(op)) = self.link.as_mut() {
            op.react(now_ns);
            self.collect(now_ns);
        }
    }

    /// Writes the report now (the console is closing).
    pub fn finish(&mut self) {
        if let Some(Link::Operating(op)) = self.link.as_mut() {
            op.finish_report();
            if let Ok(bytes) = serde_json::to_vec_pretty(&op.report) {
                let written = self.archive.write_report(&bytes);
                self.noted("writing report.json", written);
            }
        }
    }

    /// Lines for the console's event list since the last call: the
    /// mission's hand-backs, continuations, completion and end.
    pub fn take_events(&mut self) -> Vec<(&'static str, String)> {
        self.events.drain(..).collect()
    }

    pub fn mission_rev(&self) -> u64 {
        self.mission_rev
    }

    pub fn series_rev(&self) -> u64 {
        self.series_rev
    }

    /// The robot's reported pose, the twin's prediction for the same plan
    /// time (while a plan runs), and the blocks the twin learnt from it.
    #[allow(clippy::type_complexity)]
    pub fn poses(
        &self,
    ) -> (
        Option<[f64; 3]>,
        Option<[f64; 3]>,
        Vec<([f64; 2], [f64; 2])>,
    ) {
        let master = self.master();
        let status = master.latest_status();
        let op = self.operator();
        let predicted = match (op.and_then(|o| o.current_plan()), status) {
            (Some(p), Some(s)) if matches!(s.plan, Some((_, PlanPhase::Executing))) => {
                Some(predicted_pose(p, s.plan_t_s))
            }
            _ => None,
        };
        (
            status.and_then(|s| known_pose(s.pose)),
            predicted,
            op.and_then(|o| o.twin())
                .map(|t| t.learnt.clone())
                .unwrap_or_default(),
        )
    }

    /// The state in one word for the fleet list.
    fn state_word(&self) -> &'static str {
        let Some(op) = self.operator() else {
            return if self.orphan_handback.is_some() {
                "handed_back"
            } else {
                "idle"
            };
        };
        if op.awaiting_decision().is_some() {
            return "awaiting_decision";
        }
        if let Some(outcome) = op.report.outcome {
            return match outcome {
                Outcome::Completed => "completed",
                Outcome::HandedBack => "handed_back",
                Outcome::Rejected => "rejected",
                Outcome::Failed => "failed",
            };
        }
        let m = &op.master;
        match m.uploading().and_then(|t| m.phase(&t)) {
            Some(PlanPhase::Executing) => "executing",
            Some(PlanPhase::Finished) => "completed",
            Some(PlanPhase::Stopped { .. }) => "stopped",
            Some(PlanPhase::Rejected { .. }) => "rejected",
            _ if m.upload_finished() => "uploaded",
            _ => "uploading",
        }
    }

    /// What the page shows of this robot now (a few hundred bytes).
    pub fn view(&self, now_ns: u64) -> Value {
        let master = self.master();
        let age = |t: Option<u64>| t.map(|t| now_ns.saturating_sub(t) as f64 * 1e-9);
        let rtt = {
            let r = &master.rtt_s;
            let recent = &r[r.len().saturating_sub(5)..];
            let mut v = recent.to_vec();
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied()
        };
        let rx_age = age(self.last_rx_ns);
        // A ping is late past three round trips (at least 5 s).
        let late_ns = (3.0 * rtt.unwrap_or(1.0) * 1e9).max(5e9) as u64;
        let (answered, lost) = master.ping_counts(now_ns, late_ns);
        let rtt_allow = rtt.unwrap_or(0.0);
        let outage = rx_age.is_none_or(|a| a > STALE_S + rtt_allow);
        let rate = self.rx_times.len() as f64 / 10.0;
        let bytes_rate = self.rx_times.iter().map(|&(_, n)| n).sum::<usize>() as f64 / 10.0;
        let upload = master.upload_stats().map(|(s, bytes, _)| {
            json!({
                "chunks": s.chunks,
                "confirmed": s.chunks_confirmed,
                "sent": s.chunks_sent,
                "resent": s.chunks_resent,
                "repairs": s.repairs_sent,
                "bytes": bytes,
                "elapsed_s": master.upload_duration_s(now_ns),
                "done": master.upload_finished(),
            })
        });
        let status_age = age(self.last_status_ns);
        let status = master.latest_status().map(|s| status_view(s, status_age));
        let op = self.operator();
        // The twin's prediction only means something while a plan runs.
        let (_, predicted, learnt) = self.poses();
        let awaiting = op.and_then(|o| o.awaiting_decision()).map(|h| {
            json!({ "reason": h.reason, "plan_t_s": h.plan_t_s, "pose": h.pose, "decision": true })
        });
        let awaiting = awaiting.or_else(|| {
            self.orphan_handback.as_ref().map(|h| {
                json!({ "reason": h.reason, "plan_t_s": h.plan_t_s, "pose": h.pose, "decision": false })
            })
        });
        let tol = Tolerances::default();
        json!({
            "id": self.id,
            "state": self.state_word(),
            "upload": upload,
            "link": {
                "rtt_s": rtt,
                "last_rx_age_s": rx_age,
                "rx_msgs_s": rate,
                "rx_bytes_s": bytes_rate,
                "pings_answered": answered,
                "pings_lost": lost,
                "messages": self.messages_received,
                "refused": self.refused_messages,
                "outage": outage,
            },
            "status": status,
            "plan": self.plan_view(),
            "predicted": predicted,
            "awaiting": awaiting,
            "outcome": op.and_then(|o| o.report.outcome),
            "failure": op.and_then(|o| o.report.failure.clone()),
            "uploads": op.map_or(0, |o| o.report.uploads.len()),
            "handbacks": op.map_or(0, |o| o.report.handbacks.len()),
            "learnt": learnt,
            "tolerances": { "deviation_m": tol.max_deviation_m, "range_residual_m": tol.max_range_residual_m },
            "notices": self.notices,
            "mission_rev": self.mission_rev,
            "series_rev": self.series_rev,
        })
    }

    /// The plan the robot is executing, or else the one sent to it last (or
    /// the one its status speaks of, a plan of an earlier master), with
    /// where the robot stands in it: from its statuses while it runs, from
    /// its hand-back once it handed back, from its last status while
    /// running once it stopped otherwise or finished.
    fn plan_view(&self) -> Option<Value> {
        let master = self.master();
        let op = self.operator();
        let reported = master.latest_status().and_then(|s| s.plan.as_ref());
        let transfer = match reported {
            Some((t, PlanPhase::Executing)) => Some(*t),
            _ => master.uploading().or(reported.map(|(t, _)| *t)),
        }?;
        let plan = op.and_then(|o| o.plan_for(&transfer));
        let phase = match master.phase(&transfer) {
            Some(PlanPhase::Receiving { .. }) | None if master.uploading() == Some(transfer) => {
                if master.upload_finished() {
                    "uploaded"
                } else {
                    "uploading"
                }
            }
            Some(p) => phase_word(p),
            None => "unknown",
        };
        let handback = op
            .and_then(|o| o.last_handback())
            .or(self.orphan_handback.as_ref())
            .filter(|h| h.plan == transfer);
        let position = match (handback, self.last_run) {
            (Some(h), _) => Some((h.plan_t_s, h.progress)),
            (None, Some((t, plan_t_s, passed))) if t == transfer => Some((plan_t_s, passed)),
            _ => None,
        };
        Some(json!({
            "sha256": plan.map(|p| p.sha256.clone()),
            "transfer": hex(&transfer),
            "phase": phase,
            "duration_s": plan.map(|p| p.duration_s()),
            "samples": plan.map(|p| p.samples.len()),
            "plan_t_s": position.map(|p| p.0),
            "passed": position.map(|p| p.1),
        }))
    }

    /// The heavier picture, sent when it changes: time series, the plan,
    /// the hand-back's readings against the prediction, the twin's updates,
    /// the robot's logs, the timeline.
    pub fn detail(&self) -> Value {
        let op = self.operator();
        let plan = op.and_then(|o| o.current_plan());
        let series = {
            let col = |k: usize| self.series.iter().map(|s| s[k]).collect::<Vec<_>>();
            json!({ "t": col(0), "plan_t": col(1), "deviation": col(2), "residual": col(3) })
        };
        let window = op
            .and_then(|o| o.report.handbacks.last().map(|h| (o, h)))
            .and_then(|(o, _)| handback_window(o));
        json!({
            "type": "robot",
            "id": self.id,
            "series": series,
            "plan": plan.map(|p| columns(p.samples.iter().map(|s| (s.t_s - p.samples[0].t_s, s.x_m, s.y_m)))),
            "plan_sha256": plan.map(|p| p.sha256.clone()),
            "freedom": plan.map(|p| freedom_view(p)),
            "detours": op.map(|o| &o.report.detours),
            "window": window,
            "twin_updates": op.map(|o| &o.report.twin_updates),
            "handbacks": op.map(|o| &o.report.handbacks),
            "logs": self.logs,
            "timeline": op.map(|o| &o.report.timeline),
            "mission_rev": self.mission_rev,
            "series_rev": self.series_rev,
        })
    }
}

/// A robot's pose estimate, unless it has none yet (NaN before its first
/// plan runs).
fn known_pose(pose: [f64; 3]) -> Option<[f64; 3]> {
    pose.iter().all(|v| v.is_finite()).then_some(pose)
}

fn phase_word(phase: &PlanPhase) -> &'static str {
    match phase {
        PlanPhase::Receiving { .. } => "receiving",
        PlanPhase::Rejected { .. } => "rejected",
        PlanPhase::Executing => "executing",
        PlanPhase::Finished => "finished",
        PlanPhase::Stopped { .. } => "stopped",
    }
}

/// The line in the console's event list for an entry of a mission's
/// timeline (with its level), or none for an upload's start (the upload
/// command reports the first, `continuation_planned` the others).
fn event_line(
    robot: &str,
    entry: &TimelineEntry,
    plans: &[(String, &str)],
) -> Option<(&'static str, String)> {
    let d = &entry.detail;
    // Phases name the transfer (its first 12 hex digits); `plans` has the
    // plan sent as each transfer (hex, plan SHA-256).
    let plan_of = |transfer: &str| {
        plans
            .iter()
            .find(|(t, _)| !transfer.is_empty() && t.starts_with(transfer))
            .map_or_else(
                || format!("transfer {transfer}"),
                |(_, sha)| format!("plan {}", &sha[..sha.len().min(12)]),
            )
    };
    let (level, text) = match entry.event.as_str() {
        "upload_finished" => ("info", format!("upload finished: {d}")),
        "upload_refused" => ("error", format!("upload refused: {d}")),
        "plan_rejected" => ("error", format!("plan rejected: {d}")),
        "execution_started" => ("info", format!("executing {}", plan_of(d))),
        "execution_finished" => ("info", format!("{} finished", plan_of(d))),
        "stopped" => ("warn", format!("stopped: {}", d.replace('_', " "))),
        "handback" => {
            // "<reason> at <t> s into the plan, pose (…)"
            let (reason, rest) = d.split_once(' ').unwrap_or((d, ""));
            (
                "warn",
                format!("hand-back: {} {rest}", reason.replace('_', " ")),
            )
        }
        "twin_updated" => ("info", format!("the twin updated from the hand-back: {d}")),
        "detour" => ("info", format!("detour: {d}")),
        "detour_done" => ("info", format!("detour done: {d}")),
        "awaiting_operator" => (
            "warn",
            "waiting for you: continue or end the mission".into(),
        ),
        "continuation_planned" => ("info", format!("continuation uploading: {d}")),
        "continuation_refused" => ("error", format!("no continuation: {d}")),
        "operator_ended" => ("info", format!("mission ended by the operator: {d}")),
        "outcome" => {
            let (level, word) = match d.as_str() {
                "Completed" => ("ok", "completed"),
                "HandedBack" => ("warn", "handed back"),
                "Rejected" => ("error", "rejected"),
                _ => ("error", "failed"),
            };
            (level, format!("mission over: {word}"))
        }
        "robot_log" => ("info", format!("the robot's log arrived ({d})")),
        _ => return None,
    };
    Some((level, format!("robot {robot}: {text}")))
}

fn status_view(s: &Status, age_s: Option<f64>) -> Value {
    json!({
        "age_s": age_s,
        "stale": age_s.is_none_or(|a| a > STALE_S),
        "pose": known_pose(s.pose),
        "phase": s.plan.as_ref().map(|(_, p)| phase_word(p)),
        "deviation_m": s.deviation_m,
        "range_residual_m": s.range_residual_m,
        "params": s.params,
        "params_std": s.params_std,
        "bumps": s.bumps,
        "collisions": s.collisions,
        "refused": s.refused,
        "logs_pending": s.logs_pending,
    })
}

/// The plan's pose `plan_t_s` into it (the twin's prediction for the time
/// the robot reports), interpolated.
pub fn predicted_pose(plan: &MissionPlan, plan_t_s: f64) -> [f64; 3] {
    let s = &plan.samples;
    let t = s[0].t_s + plan_t_s.max(0.0);
    let k = s.partition_point(|p| p.t_s <= t);
    if k == 0 {
        return [s[0].x_m, s[0].y_m, s[0].heading_rad];
    }
    if k >= s.len() {
        let l = &s[s.len() - 1];
        return [l.x_m, l.y_m, l.heading_rad];
    }
    let (a, b) = (&s[k - 1], &s[k]);
    let f = ((t - a.t_s) / (b.t_s - a.t_s)).clamp(0.0, 1.0);
    let dh = (b.heading_rad - a.heading_rad + std::f64::consts::PI)
        .rem_euclid(2.0 * std::f64::consts::PI)
        - std::f64::consts::PI;
    [
        a.x_m + f * (b.x_m - a.x_m),
        a.y_m + f * (b.y_m - a.y_m),
        a.heading_rad + f * dh,
    ]
}

/// The last hand-back's sensor window against the plan's predicted
/// readings at the same plan times: per beam, measured and predicted.
fn handback_window(op: &Operator<DirStore>) -> Option<Value> {
    let h = op.last_handback()?;
    let plan = op.plan_for(&h.plan)?;
    let beams = h.window.first()?.ranges_m.len();
    let t: Vec<f64> = h.window.iter().map(|w| w.plan_t_s).collect();
    let measured: Vec<Vec<Option<f64>>> = (0..beams)
        .map(|b| {
            h.window
                .iter()
                .map(|w| {
                    let r = w.ranges_m[b] as f64;
                    r.is_finite().then_some(r)
                })
                .collect()
        })
        .collect();
    // What the plan's map predicts at the pose the robot believed it had:
    // the robot's own comparison.
    let mut model = plan.range_model();
    let mut ranges = vec![0.0; model.beams()];
    let per_sample: Vec<Vec<f64>> = h
        .window
        .iter()
        .map(|w| {
            model.read(
                &twindrive_kinematics::Pose::new(w.pose[0], w.pose[1], w.pose[2]),
                &mut ranges,
            );
            ranges.clone()
        })
        .collect();
    let predicted: Vec<Vec<Option<f64>>> = (0..beams)
        .map(|b| per_sample.iter().map(|r| r.get(b).copied()).collect())
        .collect();
    Some(json!({
        "reason": h.reason,
        "t": t,
        "measured": measured,
        "predicted": predicted,
        "tolerance_m": Tolerances::default().max_range_residual_m,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use twindrive_link::wire::Stamper;

    fn status(plan: Option<(TransferId, PlanPhase)>, plan_t_s: f64, pose: [f64; 3]) -> Body {
        Body::Status(Box::new(Status {
            plan,
            progress: (40, 100),
            plan_t_s,
            pose,
            params: [0.1; 3],
            params_std: [0.01; 3],
            deviation_m: 0.01,
            range_residual_m: 0.02,
            wheel_travel_rad: 0.0,
            logs_pending: 0,
            handback_pending: false,
            bumps: 0,
            collisions: 0,
            refused: 0,
            deviation_now_m: 0.01,
            max_deviation_on_detour: false,
            on_detour: false,
        }))
    }

    #[test]
    fn a_robot_without_a_pose_has_none_and_a_stopped_plan_keeps_its_time() {
        let dir = tempfile::tempdir().unwrap();
        let mut slot = RobotSlot::new("r1", dir.path(), MasterConfig::default());
        let mut robot = Stamper::new("r1");
        let mut send = |slot: &mut RobotSlot, body: Body, t_s: u64| {
            let now = t_s * 1_000_000_000;
            let m = robot.stamp(body, now);
            slot.handle(&m, now);
            slot.tick(now);
        };
        // Before its first plan the robot's estimate is NaN: no pose.
        send(&mut slot, status(None, 0.0, [f64::NAN; 3]), 1);
        let v = slot.view(1_000_000_000);
        assert_eq!(v["status"]["pose"], Value::Null, "{v}");
        assert_eq!(v["plan"], Value::Null, "{v}");
        assert_eq!(slot.poses().0, None);
        // A plan (of an earlier master) runs: its pose, its time.
        let t = [7u8; 32];
        send(
            &mut slot,
            status(Some((t, PlanPhase::Executing)), 15.5, [1.0, 2.0, 0.5]),
            2,
        );
        let v = slot.view(2_000_000_000);
        assert_eq!(v["status"]["pose"], json!([1.0, 2.0, 0.5]));
        assert_eq!(slot.poses().0, Some([1.0, 2.0, 0.5]));
        assert_eq!(v["plan"]["phase"], "executing");
        assert_eq!(v["plan"]["plan_t_s"], 15.5);
        assert_eq!(v["plan"]["transfer"], hex(&t));
        // Stopped, its statuses say 0 s: the plan stays where it stopped.
        let stopped = PlanPhase::Stopped {
            reason: "dead_man".into(),
        };
        send(
            &mut slot,
            status(Some((t, stopped.clone())), 0.0, [1.1, 2.0, 0.5]),
            3,
        );
        let v = slot.view(3_000_000_000);
        assert_eq!(v["plan"]["phase"], "stopped");
        assert_eq!(v["plan"]["plan_t_s"], 15.5, "{v}");
        // A hand-back: where it says it stopped, with a line for the events.
        let h = Handback {
            plan: t,
            reason: "unexpected_bump".into(),
            plan_t_s: 15.75,
            progress: 41,
            pose: [1.1, 2.0, 0.5],
            pose_covariance: [0.0; 9],
            params: [0.1; 3],
            params_covariance: [0.0; 9],
            window: Vec::new(),
        };
        send(&mut slot, Body::Handback(Box::new(h)), 4);
        let v = slot.view(4_000_000_000);
        assert_eq!(v["plan"]["plan_t_s"], 15.75, "{v}");
        assert_eq!(v["awaiting"]["plan_t_s"], 15.75, "{v}");
        assert_eq!(v["plan"]["passed"], 41);
        let events = slot.take_events();
        assert_eq!(events.len(), 1, "{events:?}");
        assert!(
            events[0].1.contains("hand-back: unexpected bump at 15.8 s"),
            "{events:?}"
        );
        assert!(slot.take_events().is_empty(), "taken once");
    }

    /// A detour the robot reports (begun, then back on the plan) reaches
    /// the page: the detail lists both with the plan's corridor, the
    /// mission's revision moves on, the event list tells each.
    #[test]
    fn a_detour_the_robot_reports_reaches_the_page() {
        use twindrive_link::wire::DetourReport;
        let scenario = twindrive_sim::builtin::load("wall_following")
            .unwrap()
            .unwrap();
        let mut w = crate::workspace::Workspace::new(scenario.clone());
        w.wall_follow(0);
        w.set_speed(32.0, 0).unwrap();
        w.record_start(0);
        w.advance(1_000_000_000);
        let log = w.record_stop(1_000_000_000).unwrap().clone();
        let made = crate::planning::make_plan(
            &log,
            &scenario,
            &scenario.robot.nominal_params,
            crate::planning::default_redundancy(&scenario),
            Default::default(),
        )
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let mut slot = RobotSlot::new("r1", dir.path(), MasterConfig::default());
        let key = SigningKey::from_bytes(&[7; 32]);
        let world = "00".repeat(32);
        let signing = Signing {
            key: &key,
            world_sha256: &world,
            unix_now_s: 1.8e9,
            unix_at_zero_s: 1.8e9,
            expires_in_s: 60,
            supervision: Supervision {
                dead_man_timeout_s: None,
            },
        };
        slot.upload(made.plan.clone(), &made.plan_json, &scenario, &signing, 0)
            .unwrap();
        let transfer = slot.master().uploading().unwrap();
        let rev = slot.mission_rev();
        let mut robot = Stamper::new("r1");
        for (k, rejoined) in [false, true].into_iter().enumerate() {
            let body = Body::Detour(Box::new(DetourReport {
                plan: transfer,
                index: 1,
                plan_t_s: 3.0,
                from: [1.0, 1.0, 0.0],
                from_sample: 300,
                waypoints: vec![[1.0, 1.0], [1.5, 0.7], [2.0, 1.0]],
                rejoin: 500,
                obstacle: vec![[1.4, 1.0], [1.45, 1.05]],
                rejoined,
                extra_s: if rejoined { 2.5 } else { 0.0 },
                extra_m: if rejoined { 0.4 } else { 0.0 },
            }));
            let now = (k as u64 + 1) * 1_000_000_000;
            let m = robot.stamp(body, now);
            slot.handle(&m, now);
        }
        assert!(slot.mission_rev() > rev);
        let d = slot.detail();
        let detours = d["detours"].as_array().unwrap();
        assert_eq!(detours.len(), 2, "{d}");
        assert_eq!(detours[1]["rejoined"], true);
        assert_eq!(detours[1]["waypoints"].as_array().unwrap().len(), 3);
        assert_eq!(
            d["freedom"]["corridor_half_width_m"]
                .as_array()
                .unwrap()
                .len(),
            made.plan.samples.len()
        );
        let events = slot.take_events();
        let told = |s: &str| events.iter().any(|(_, t)| t.contains(s));
        assert!(told("robot r1: detour: going around"), "{events:?}");
        assert!(
            told("robot r1: detour done: back on the plan at sample 500"),
            "{events:?}"
        );
    }

    fn entry(event: &str, detail: &str) -> TimelineEntry {
        TimelineEntry {
            t_s: 1.0,
            event: event.into(),
            detail: detail.into(),
        }
    }

    #[test]
    fn the_missions_timeline_becomes_event_lines() {
        let transfer = "ab".repeat(32);
        let sha = "cd".repeat(32);
        let plans = [(transfer.clone(), sha.as_str())];
        let line = |e: &str, d: &str| event_line("r1", &entry(e, d), &plans);
        let (level, text) = line(
            "handback",
            "unexpected_bump at 15.5 s into the plan, pose (1.00, 2.00, 0.50)",
        )
        .unwrap();
        assert_eq!(level, "warn");
        assert_eq!(
            text,
            "robot r1: hand-back: unexpected bump at 15.5 s into the plan, pose (1.00, 2.00, 0.50)"
        );
        let (_, text) = line("execution_started", &transfer[..12]).unwrap();
        assert_eq!(text, format!("robot r1: executing plan {}", &sha[..12]));
        let (_, text) = line("execution_finished", "0123456789ab").unwrap();
        assert_eq!(text, "robot r1: transfer 0123456789ab finished");
        let (_, text) = line(
            "continuation_planned",
            "12.0 s rehearsed on the updated twin, plan 0123456789ab (120 samples)",
        )
        .unwrap();
        assert!(text.starts_with("robot r1: continuation uploading: 12.0 s"));
        assert_eq!(
            line("outcome", "Completed").unwrap(),
            ("ok", "robot r1: mission over: completed".into())
        );
        assert_eq!(
            line("outcome", "HandedBack").unwrap(),
            ("warn", "robot r1: mission over: handed back".into())
        );
        assert_eq!(line("outcome", "Failed").unwrap().0, "error");
        assert!(
            line("operator_ended", "the mission ends at the hand-back")
                .unwrap()
                .1
                .contains("mission ended by the operator")
        );
        assert_eq!(line("upload_started", "plan x (10 bytes signed)"), None);
        let (level, text) = line("detour", "going around something the map lacks").unwrap();
        assert_eq!(level, "info");
        assert!(text.starts_with("robot r1: detour: going around"), "{text}");
        assert!(
            line("detour_done", "back on the plan at sample 40")
                .unwrap()
                .1
                .contains("detour done: back on the plan")
        );
    }
}
