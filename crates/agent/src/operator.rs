//! The master's decisions, around its [`Master`] end: what to upload, what
//! a hand-back changes in the twin, whether to continue, and when the
//! mission is over. Drives in real processes and in virtual time alike:
//! call [`Operator::react`] after messages are handled, and stop when
//! [`Operator::is_done`].

use std::collections::VecDeque;
use std::sync::Arc;

use ed25519_dalek::SigningKey;
use serde::Serialize;
use twindrive_link::envelope::{Envelope, Supervision, Tolerances, sign_plan};
use twindrive_link::upload::ChunkStore;
use twindrive_link::wire::{Message, PlanPhase, TransferId};
use twindrive_mission::plan::{MissionPlan, hex, sha256_hex};

use crate::master::{Master, MasterEvent};
use crate::twin::{ContinuationSettings, LearnSettings, Twin, TwinUpdate};

/// What the operator does when the robot hands control back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OnHandback {
    /// Update the twin and end the mission there.
    Stop,
    /// Update the twin, rehearse a continuation on it from the hand-back
    /// pose, sign it and upload it; until the mission completes.
    Replan,
    /// Update the twin, then wait for the operator (a console): they
    /// continue with [`Operator::replan`] or end with
    /// [`Operator::end_mission`].
    Ask,
}

/// How the mission ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    Completed,
    HandedBack,
    Rejected,
    Failed,
}

/// Operator settings.
#[derive(Debug, Clone)]
pub struct OperatorConfig {
    pub robot_id: String,
    pub on_handback: OnHandback,
    /// Signed plans expire this long after signing (s).
    pub expires_in_s: u64,
    pub supervision: Supervision,
    pub tolerances: Tolerances,
    /// Unix time (s) at `now_ns = 0`.
    pub unix_time_at_zero_s: f64,
    /// The counter of the first continuation is one above the first plan's.
    pub first_counter: u64,
    /// SHA-256 of the twin's world the first plan was rehearsed in.
    pub world_sha256: String,
    /// How long to wait for the robot's next log once the mission is
    /// decided (s; the wait starts again with each log received).
    pub log_wait_s: f64,
    /// At most this many continuations.
    pub max_continuations: usize,
    /// How continuations go around what the twin learnt.
    pub continuation: ContinuationSettings,
    /// Once the digests are in, ask the robot for every executed plan's
    /// full-rate log too (the whole MCAP it keeps), and wait for them.
    pub full_rate_logs: bool,
}

impl OperatorConfig {
    /// An operator that replans on a hand-back (up to ten continuations,
    /// with the default detour clearance and pace), for plans
    /// valid a day and unsupervised, with the default tolerances, waiting
    /// two minutes for the robot's logs. The mission's first plan is
    /// signed with `first_counter` for the world whose hash is `world_sha256`.
    pub fn replanning(
        robot_id: &str,
        first_counter: u64,
        world_sha256: String,
        unix_time_at_zero_s: f64,
    ) -> Self {
        Self {
            robot_id: robot_id.into(),
            on_handback: OnHandback::Replan,
            expires_in_s: 86_400,
            supervision: Supervision {
                dead_man_timeout_s: None,
            },
            tolerances: Tolerances::default(),
            unix_time_at_zero_s,
            first_counter,
            world_sha256,
            log_wait_s: 120.0,
            max_continuations: 10,
            continuation: ContinuationSettings::default(),
            full_rate_logs: false,
        }
    }
}

/// The report's record of one plan sent.
#[derive(Debug, Clone, Serialize)]
pub struct UploadEntry {
    pub plan_sha256: String,
    pub transfer: String,
    pub counter: u64,
    pub bytes: u64,
    pub duration_s: f64,
    pub chunks: u32,
    pub chunks_resent: u64,
    /// The plan's own duration (s).
    pub plan_duration_s: f64,
}

/// The report's record of one hand-back.
#[derive(Debug, Clone, Serialize)]
pub struct HandbackEntry {
    pub plan_sha256: String,
    pub reason: String,
    /// When it arrived (s of the master's clock).
    pub t_s: f64,
    /// How far into its plan the robot was (s).
    pub plan_t_s: f64,
    pub pose: [f64; 3],
    pub params: [f64; 3],
    pub params_std: [f64; 3],
}

/// The report's record of a detour the robot decided on its own.
#[derive(Debug, Clone, Serialize)]
pub struct DetourEntry {
    pub plan_sha256: String,
    pub index: u32,
    /// When the report arrived (s of the master's clock), and how far into
    /// its plan the robot was when it began (s).
    pub t_s: f64,
    pub plan_t_s: f64,
    pub from: [f64; 3],
    pub waypoints: Vec<[f32; 2]>,
    /// Back on the plan, and what it added (s, m).
    pub rejoined: bool,
    pub extra_s: f64,
    pub extra_m: f64,
    /// Points where its readings ended on what the map lacks, and the
    /// blocks the twin learnt from them (`(min, max)` corners, m).
    pub obstacle_points: usize,
    pub learnt: Vec<twindrive_mission::detour::Block>,
}

/// A robot log as it arrived, as an MCAP file.
#[derive(Debug, Clone)]
pub struct ArrivedLog {
    /// The plan it is the log of, when known.
    pub plan: Option<Arc<MissionPlan>>,
    pub mcap: Vec<u8>,
    /// The robot's full-rate log, asked for; else made from its digest.
    pub full_rate: bool,
}

/// How often the full-rate log asked for is asked again while neither it
/// nor a refusal has come (the link may have lost the request), ns.
const FULL_LOG_ASK_EVERY_NS: u64 = 10_000_000_000;

/// One moment of the mission, for the timeline.
#[derive(Debug, Clone, Serialize)]
pub struct TimelineEntry {
    pub t_s: f64,
    pub event: String,
    pub detail: String,
}

/// `report.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub outcome: Option<Outcome>,
    pub robot_id: String,
    pub on_handback: OnHandback,
    pub uploads: Vec<UploadEntry>,
    pub handbacks: Vec<HandbackEntry>,
    /// Detours the robot went on by itself (each reported when begun and
    /// when back on the plan).
    pub detours: Vec<DetourEntry>,
    pub twin_updates: Vec<TwinUpdate>,
    pub rejections: Vec<String>,
    pub failure: Option<String>,
    pub collisions: u32,
    pub bumps: u32,
    /// The robot's distance from the plan's pose in its latest status
    /// while a plan ran (m) ...
    pub last_deviation_m: Option<f64>,
    /// ... the largest any status reported (m; every plan's, continuations'
    /// too), and whether the robot was on a detour then.
    pub max_deviation_m: Option<f64>,
    pub max_deviation_on_detour: bool,
    /// Directories of the robot's logs as received (filled by the owner).
    pub robot_logs: Vec<String>,
    pub status_messages: u64,
    /// Payloads on the robot's key expression this master refused before
    /// reading them (not authentic, replays): nothing of them was used.
    pub refused_messages: u64,
    /// The robot's own count of payloads it refused, from its latest status.
    pub robot_refused_messages: u32,
    /// The link's round trip (median of the pings answered, s).
    pub link_rtt_median_s: Option<f64>,
    pub pings_answered: usize,
    /// Unix time (s) at the timeline's zero.
    pub unix_time_at_zero_s: f64,
    pub timeline: Vec<TimelineEntry>,
}

struct SentPlan {
    transfer: TransferId,
    plan: Arc<MissionPlan>,
    counter: u64,
    executed: bool,
}

/// The operator at the master.
pub struct Operator<S: ChunkStore> {
    pub master: Master<S>,
    twin: Option<Twin>,
    key: Option<SigningKey>,
    config: OperatorConfig,
    pub report: Report,
    plans: Vec<SentPlan>,
    decided_at_ns: Option<u64>,
    /// When the latest robot log came in.
    last_log_at_ns: Option<u64>,
    logs_received: usize,
    /// Logs pending on the robot, by its latest status since the decision.
    status_after_decision: Option<u32>,
    /// The robot's latest status says a hand-back waits for acknowledgement.
    handback_pending: bool,
    /// Robot logs for the owner to write.
    pub new_logs: VecDeque<ArrivedLog>,
    /// With `full_rate_logs`, once asked: the plans whose full-rate logs
    /// are still to come, the first asked for (and when, last).
    full_logs: Option<VecDeque<Arc<MissionPlan>>>,
    full_log_asked_ns: Option<u64>,
    /// Continuation plans signed (document bytes, signed file) for the
    /// owner to keep.
    pub new_plans: VecDeque<(Arc<MissionPlan>, Vec<u8>, Vec<u8>)>,
    /// With [`OnHandback::Ask`]: the hand-back waiting for the operator's
    /// decision, with the plan it interrupted and where (plan time, s).
    awaiting: Option<(HandbackEntry, Arc<MissionPlan>, f64)>,
    /// The latest hand-back as the robot sent it (its sensor window).
    last_handback: Option<Box<twindrive_link::wire::Handback>>,
    now_ns: u64,
}

impl<S: ChunkStore> Operator<S> {
    /// An operator for `master`; `twin` is needed to replan.
    pub fn new(
        master: Master<S>,
        twin: Option<Twin>,
        key: Option<SigningKey>,
        config: OperatorConfig,
    ) -> Self {
        Self {
            report: Report {
                outcome: None,
                robot_id: config.robot_id.clone(),
                on_handback: config.on_handback,
                uploads: Vec::new(),
                handbacks: Vec::new(),
                detours: Vec::new(),
                twin_updates: Vec::new(),
                rejections: Vec::new(),
                failure: None,
                collisions: 0,
                bumps: 0,
                last_deviation_m: None,
                max_deviation_m: None,
                max_deviation_on_detour: false,
                robot_logs: Vec::new(),
                status_messages: 0,
                refused_messages: 0,
                robot_refused_messages: 0,
                link_rtt_median_s: None,
                pings_answered: 0,
                unix_time_at_zero_s: config.unix_time_at_zero_s,
                timeline: Vec::new(),
            },
            master,
            twin,
            key,
            config,
            plans: Vec::new(),
            decided_at_ns: None,
            last_log_at_ns: None,
            logs_received: 0,
            status_after_decision: None,
            handback_pending: false,
            new_logs: VecDeque::new(),
            full_logs: None,
            full_log_asked_ns: None,
            new_plans: VecDeque::new(),
            awaiting: None,
            last_handback: None,
            now_ns: 0,
        }
    }

    /// The settings, to change before the mission starts (what to do on
    /// a hand-back is fixed at construction: the report records it).
    pub fn config_mut(&mut self) -> &mut OperatorConfig {
        &mut self.config
    }

    pub fn twin(&self) -> Option<&Twin> {
        self.twin.as_ref()
    }

    fn note(&mut self, event: &str, detail: String) {
        tracing::info!(target: "twindrive::master", event, "{detail}");
        self.report.timeline.push(TimelineEntry {
            t_s: self.now_ns as f64 * 1e-9,
            event: event.into(),
            detail,
        });
    }

    /// Starts the mission with a signed plan file (`resume`: this master
    /// restarted and the robot may hold part of it).
    pub fn start(
        &mut self,
        plan: Arc<MissionPlan>,
        signed: Vec<u8>,
        counter: u64,
        resume: bool,
        now_ns: u64,
    ) {
        self.now_ns = now_ns;
        let bytes = signed.len();
        let transfer = self.master.upload(signed, resume, now_ns);
        self.note(
            "upload_started",
            format!("plan {} ({bytes} bytes signed)", &plan.sha256[..12]),
        );
        self.plans.push(SentPlan {
            transfer,
            plan,
            counter,
            executed: false,
        });
    }

    fn decide(&mut self, outcome: Outcome) {
        if self.report.outcome.is_none() {
            self.report.outcome = Some(outcome);
            self.decided_at_ns = Some(self.now_ns);
            self.note("outcome", format!("{outcome:?}"));
        }
    }

    /// The mission is decided, and the robot's logs are in (with
    /// `full_rate_logs`, the full-rate ones too), or the next one was
    /// waited for long enough.
    pub fn is_done(&self) -> bool {
        let Some(at) = self.waiting_since_ns() else {
            return false;
        };
        let full_in =
            !self.config.full_rate_logs || self.full_logs.as_ref().is_some_and(VecDeque::is_empty);
        (self.digests_in() && full_in) || self.now_ns >= at + (self.config.log_wait_s * 1e9) as u64
    }

    /// The robot has said, since the decision, that no log of its waits
    /// for the master (and no hand-back: the master acknowledges it first).
    fn digests_in(&self) -> bool {
        self.status_after_decision == Some(0) && !self.handback_pending
    }

    /// With `full_rate_logs`: once the digests are in, the executed plans'
    /// full-rate logs are asked for, one at a time, each again every
    /// [`FULL_LOG_ASK_EVERY_NS`] until it (or a refusal) comes.
    fn ask_for_full_logs(&mut self, now_ns: u64) {
        if !self.config.full_rate_logs || self.decided_at_ns.is_none() {
            return;
        }
        if self.full_logs.is_none() {
            if !self.digests_in() {
                return;
            }
            let plans: VecDeque<Arc<MissionPlan>> = self
                .plans
                .iter()
                .filter(|p| p.executed)
                .map(|p| p.plan.clone())
                .collect();
            self.note(
                "full_rate_logs_asked",
                format!("{} plan(s)' full-rate logs", plans.len()),
            );
            self.full_logs = Some(plans);
        }
        let Some(next) = self.full_logs.as_ref().and_then(|q| q.front()) else {
            return;
        };
        let due = self
            .full_log_asked_ns
            .is_none_or(|t| now_ns.saturating_sub(t) >= FULL_LOG_ASK_EVERY_NS);
        match next.sha256_bytes() {
            Some(sha) if due => {
                self.master.request_log(sha);
                self.full_log_asked_ns = Some(now_ns);
            }
            Some(_) => {}
            None => {
                let sha = next.sha256.clone();
                self.full_logs.as_mut().map(VecDeque::pop_front);
                self.note(
                    "robot_log_refused",
                    format!("plan {sha:?} has no SHA-256 to ask by"),
                );
            }
        }
    }

    /// Once the mission is decided, the wait for the robot's next log runs
    /// from the decision or the latest log received, whichever is later: a
    /// slow link that keeps delivering logs is waited for.
    fn waiting_since_ns(&self) -> Option<u64> {
        let at = self.decided_at_ns?;
        Some(self.last_log_at_ns.map_or(at, |l| l.max(at)))
    }

    /// Once the mission is decided: the robot's logs still pending by its
    /// latest status since (unknown before one arrives), the seconds waited
    /// for the next one and the seconds the operator waits for it at most.
    pub fn waiting_for_logs(&self, now_ns: u64) -> Option<(Option<u32>, f64, f64)> {
        let at = self.waiting_since_ns()?;
        Some((
            self.status_after_decision,
            now_ns.saturating_sub(at) as f64 * 1e-9,
            self.config.log_wait_s,
        ))
    }

    /// Gives up: the mission failed for `why` (the link never came back, say).
    pub fn fail(&mut self, why: String, now_ns: u64) {
        self.now_ns = now_ns;
        if self.report.outcome.is_none() {
            self.report.failure = Some(why);
            self.decide(Outcome::Failed);
        }
    }

    fn plan_of(&self, transfer: &TransferId) -> Option<&SentPlan> {
        self.plans.iter().find(|p| p.transfer == *transfer)
    }

    fn is_current(&self, transfer: &TransferId) -> bool {
        self.plans.last().is_some_and(|p| p.transfer == *transfer)
    }

    /// Acts on everything the master reported.
    pub fn react(&mut self, now_ns: u64) {
        self.now_ns = now_ns;
        while let Some(event) = self.master.poll_event() {
            match event {
                MasterEvent::UploadProgress { .. } => {}
                MasterEvent::Uploaded(rec) => {
                    let (sha, counter, duration) = self
                        .plan_of(&rec.transfer)
                        .map(|p| (p.plan.sha256.clone(), p.counter, p.plan.duration_s()))
                        .unwrap_or_default();
                    self.note(
                        "upload_finished",
                        format!(
                            "{} bytes in {:.1} s, {} chunks resent",
                            rec.bytes, rec.duration_s, rec.chunks_resent
                        ),
                    );
                    self.report.uploads.push(UploadEntry {
                        plan_sha256: sha,
                        transfer: hex(&rec.transfer),
                        counter,
                        bytes: rec.bytes,
                        duration_s: rec.duration_s,
                        chunks: rec.chunks,
                        chunks_resent: rec.chunks_resent,
                        plan_duration_s: duration,
                    });
                }
                MasterEvent::UploadRefused { reason, .. } => {
                    self.report.rejections.push(reason.clone());
                    self.note("upload_refused", reason);
                    self.decide(Outcome::Rejected);
                }
                MasterEvent::Phase { transfer, phase } => self.phase(transfer, phase),
                MasterEvent::Handback(h) => self.handback(&h),
                MasterEvent::Detour(d) => self.detour(&d),
                MasterEvent::RobotLog { file, .. } if twindrive_log::is_mcap(&file) => {
                    // A full-rate log: the one asked for (one at a time).
                    self.last_log_at_ns = Some(now_ns);
                    let plan = self.full_logs.as_mut().and_then(VecDeque::pop_front);
                    self.full_log_asked_ns = None;
                    self.note(
                        "robot_log_full_rate",
                        format!(
                            "{} bytes, plan {}",
                            file.len(),
                            plan.as_ref().map_or("?", |p| &p.sha256[..12])
                        ),
                    );
                    self.new_logs.push_back(ArrivedLog {
                        plan,
                        mcap: file,
                        full_rate: true,
                    });
                }
                MasterEvent::LogRefused {
                    plan_sha256,
                    reason,
                } => {
                    let asked = self
                        .full_logs
                        .as_ref()
                        .and_then(|q| q.front())
                        .is_some_and(|p| p.sha256_bytes() == Some(plan_sha256));
                    if asked {
                        self.full_logs.as_mut().map(VecDeque::pop_front);
                        self.full_log_asked_ns = None;
                        self.note("robot_log_refused", reason);
                    }
                }
                MasterEvent::RobotLog { file, .. } => {
                    self.logs_received += 1;
                    self.last_log_at_ns = Some(now_ns);
                    // What came is the log's digest: as a log file again.
                    let digest_bytes = file.len();
                    let file = match log_file_of_digest(&file) {
                        Ok(mcap) => mcap,
                        Err(e) => {
                            self.note("robot_log_unreadable", e.to_string());
                            continue;
                        }
                    };
                    // Logs come back in the order the plans ran.
                    let plan = self
                        .plans
                        .iter()
                        .filter(|p| p.executed)
                        .nth(self.logs_received - 1)
                        .map(|p| p.plan.clone());
                    self.note("robot_log", format!("{digest_bytes} bytes on the link"));
                    self.new_logs.push_back(ArrivedLog {
                        plan,
                        mcap: file,
                        full_rate: false,
                    });
                }
                MasterEvent::Status(s) => {
                    self.report.status_messages += 1;
                    // A status the robot sent while still driving (one that
                    // crossed the hand-back on the way) does not yet count
                    // the log of the plan it drove.
                    let driving = matches!(s.plan, Some((_, PlanPhase::Executing)));
                    if self.decided_at_ns.is_some() && !driving {
                        self.status_after_decision = Some(s.logs_pending);
                    }
                    self.handback_pending = s.handback_pending;
                    self.report.collisions = s.collisions;
                    self.report.bumps = s.bumps;
                    if driving && s.deviation_now_m.is_finite() {
                        self.report.last_deviation_m = Some(s.deviation_now_m);
                    }
                    if s.deviation_m.is_finite()
                        && self
                            .report
                            .max_deviation_m
                            .is_none_or(|m| s.deviation_m > m)
                    {
                        self.report.max_deviation_m = Some(s.deviation_m);
                        self.report.max_deviation_on_detour = s.max_deviation_on_detour;
                    }
                    self.report.robot_refused_messages = s.refused;
                }
            }
        }
        self.ask_for_full_logs(now_ns);
    }

    fn phase(&mut self, transfer: TransferId, phase: PlanPhase) {
        let current = self.is_current(&transfer);
        match phase {
            PlanPhase::Receiving { .. } => {}
            PlanPhase::Rejected { reason } => {
                self.report.rejections.push(reason.clone());
                self.note("plan_rejected", reason);
                if current {
                    self.decide(Outcome::Rejected);
                }
            }
            PlanPhase::Executing => {
                if let Some(p) = self.plans.iter_mut().find(|p| p.transfer == transfer) {
                    p.executed = true;
                }
                self.note("execution_started", hex(&transfer)[..12].to_string());
            }
            PlanPhase::Finished => {
                self.mark_executed(transfer);
                self.note("execution_finished", hex(&transfer)[..12].to_string());
                if current {
                    self.decide(Outcome::Completed);
                }
            }
            PlanPhase::Stopped { reason } => {
                self.mark_executed(transfer);
                let handback = crate::executive::HANDBACK_REASONS.contains(&reason.as_str());
                self.note("stopped", reason.clone());
                if current && !handback {
                    self.report.failure = Some(format!("the robot stopped: {reason}"));
                    self.decide(Outcome::Failed);
                }
            }
        }
    }

    /// A detour report: said, recorded, and once the robot is back on the
    /// plan the twin learns what it saw (no continuation: the robot went
    /// on by itself).
    fn detour(&mut self, d: &twindrive_link::wire::DetourReport) {
        let sha = self
            .plan_of(&d.plan)
            .map(|p| p.plan.sha256.clone())
            .unwrap_or_default();
        let points: Vec<[f64; 2]> = d
            .obstacle
            .iter()
            .map(|p| [f64::from(p[0]), f64::from(p[1])])
            .collect();
        let learnt = match (&mut self.twin, d.rejoined) {
            (Some(twin), true) => {
                twin.learn_seen(&points, [d.from[0], d.from[1]], &LearnSettings::default())
            }
            _ => Vec::new(),
        };
        if d.rejoined {
            self.note(
                "detour_done",
                format!(
                    "back on the plan at sample {}: {:.1} s and {:.2} m more than the plan; the twin learnt {} block(s) from {} point(s)",
                    d.rejoin,
                    d.extra_s,
                    d.extra_m,
                    learnt.len(),
                    points.len()
                ),
            );
        } else {
            self.note(
                "detour",
                format!(
                    "going around something the map lacks, {:.1} s into the plan at ({:.2}, {:.2}), back onto it at sample {}",
                    d.plan_t_s, d.from[0], d.from[1], d.rejoin
                ),
            );
        }
        self.report.detours.push(DetourEntry {
            plan_sha256: sha,
            index: d.index,
            t_s: self.now_ns as f64 * 1e-9,
            plan_t_s: d.plan_t_s,
            from: d.from,
            waypoints: d.waypoints.clone(),
            rejoined: d.rejoined,
            extra_s: d.extra_s,
            extra_m: d.extra_m,
            obstacle_points: points.len(),
            learnt,
        });
    }

    fn mark_executed(&mut self, transfer: TransferId) {
        if let Some(p) = self.plans.iter_mut().find(|p| p.transfer == transfer) {
            p.executed = true;
        }
    }

    fn handback(&mut self, h: &twindrive_link::wire::Handback) {
        self.mark_executed(h.plan);
        self.last_handback = Some(Box::new(h.clone()));
        let std = |i: usize| h.params_covariance[4 * i].max(0.0).sqrt();
        let sha = self
            .plan_of(&h.plan)
            .map(|p| p.plan.sha256.clone())
            .unwrap_or_default();
        self.report.handbacks.push(HandbackEntry {
            plan_sha256: sha,
            reason: h.reason.clone(),
            t_s: self.now_ns as f64 * 1e-9,
            plan_t_s: h.plan_t_s,
            pose: h.pose,
            params: h.params,
            params_std: [std(0), std(1), std(2)],
        });
        self.note(
            "handback",
            format!(
                "{} at {:.1} s into the plan, pose ({:.2}, {:.2}, {:.2})",
                h.reason, h.plan_t_s, h.pose[0], h.pose[1], h.pose[2]
            ),
        );
        if !self.is_current(&h.plan) {
            return;
        }
        let Some(twin) = &mut self.twin else {
            self.decide(Outcome::HandedBack);
            return;
        };
        let update = twin.apply(h, &LearnSettings::default());
        self.note(
            "twin_updated",
            format!(
                "pose; {} block(s) added from {} point(s); parameters {}",
                update.obstacles_added.len(),
                update.evidence_points,
                if update.params.is_some() {
                    "updated"
                } else {
                    "kept"
                }
            ),
        );
        let learnt_nothing = !update.changed() && h.reason == "range_residual";
        self.report.twin_updates.push(update);
        if learnt_nothing {
            // Readings departed from the twin's, yet none of them is short
            // of or beyond its prediction by enough to say where: the same
            // continuation would hand back the same way.
            let why = "the robot's readings departed from the twin's, but the twin could not \
                       learn where from them; a continuation would hand back the same way";
            self.report.failure = Some(format!("the continuation: {why}"));
            self.note(
                "continuation_refused",
                format!("{why}; the mission ends here"),
            );
            self.decide(Outcome::HandedBack);
            return;
        }
        let continuations = self.plans.len() - 1;
        if self.config.on_handback == OnHandback::Stop
            || continuations >= self.config.max_continuations
        {
            self.decide(Outcome::HandedBack);
            return;
        }
        let interrupted = self
            .plan_of(&h.plan)
            .map(|p| p.plan.clone())
            .expect("the current plan is one sent");
        if self.config.on_handback == OnHandback::Ask {
            let entry = self.report.handbacks.last().expect("pushed above").clone();
            self.awaiting = Some((entry, interrupted, h.plan_t_s));
            self.note("awaiting_operator", "continue or end the mission".into());
            return;
        }
        match self.continue_from(&interrupted, h.plan_t_s) {
            Ok(()) => {}
            Err(e) => {
                self.report.failure = Some(format!("the continuation: {e}"));
                self.note(
                    "continuation_refused",
                    format!("{e}; it is not sent, the mission ends here"),
                );
                self.decide(Outcome::HandedBack);
            }
        }
    }

    /// The plan sent last (the one the robot runs or will run).
    pub fn current_plan(&self) -> Option<&Arc<MissionPlan>> {
        self.plans.last().map(|p| &p.plan)
    }

    /// The latest hand-back as the robot sent it, with its sensor window.
    pub fn last_handback(&self) -> Option<&twindrive_link::wire::Handback> {
        self.last_handback.as_deref()
    }

    /// The SHA-256 of the plan sent as the transfer whose hex id starts
    /// with `prefix` (the timeline names transfers so).
    pub fn plan_sha_of_transfer(&self, prefix: &str) -> Option<&str> {
        self.plans
            .iter()
            .find(|p| hex(&p.transfer).starts_with(prefix))
            .map(|p| p.plan.sha256.as_str())
    }

    /// The plan sent as `transfer`.
    pub fn plan_for(&self, transfer: &TransferId) -> Option<&Arc<MissionPlan>> {
        self.plan_of(transfer).map(|p| &p.plan)
    }

    /// The hand-back waiting for a decision ([`OnHandback::Ask`]).
    pub fn awaiting_decision(&self) -> Option<&HandbackEntry> {
        self.awaiting.as_ref().map(|(h, _, _)| h)
    }

    /// The operator's decision on a waiting hand-back: rehearse the rest of
    /// the plan on the updated twin from the hand-back pose, sign it and
    /// upload it. On failure the hand-back stays waiting.
    pub fn replan(&mut self, now_ns: u64) -> anyhow::Result<()> {
        self.now_ns = now_ns;
        let Some((_, interrupted, plan_t_s)) = &self.awaiting else {
            anyhow::bail!("no hand-back is waiting for a decision");
        };
        if self.twin.is_none() {
            anyhow::bail!("this operator has no twin to rehearse a continuation on");
        }
        let (interrupted, plan_t_s) = (interrupted.clone(), *plan_t_s);
        self.continue_from(&interrupted, plan_t_s)?;
        self.awaiting = None;
        Ok(())
    }

    /// The operator's decision on a waiting hand-back: the mission ends
    /// there (handed back).
    pub fn end_mission(&mut self, now_ns: u64) {
        self.now_ns = now_ns;
        if self.awaiting.take().is_some() {
            self.note("operator_ended", "the mission ends at the hand-back".into());
        }
        self.decide(Outcome::HandedBack);
    }

    /// Gives the master back (a new mission on the same link keeps its
    /// sequence numbers and round-trip times).
    pub fn into_master(self) -> Master<S> {
        self.master
    }

    /// Plans, verifies, signs and uploads the continuation of `interrupted`
    /// from `plan_t_s` on.
    fn continue_from(&mut self, interrupted: &MissionPlan, plan_t_s: f64) -> anyhow::Result<()> {
        let twin = self.twin.as_ref().expect("replanning needs the twin");
        let plan = twin.continuation(
            interrupted,
            plan_t_s,
            &self.config.continuation,
            &crate::executive::criteria(&self.config.tolerances),
        )?;
        let learnt = serde_json::to_string(&twin.learnt)?;
        let plan_json = serde_json::to_vec_pretty(&plan)?;
        let counter = self
            .plans
            .iter()
            .map(|p| p.counter)
            .max()
            .unwrap_or(self.config.first_counter)
            + 1;
        let now_unix = (self.config.unix_time_at_zero_s + self.now_ns as f64 * 1e-9) as u64;
        let envelope = Envelope::new(
            &self.config.robot_id,
            counter,
            now_unix,
            self.config.expires_in_s,
            sha256_hex(format!("{}{learnt}", self.config.world_sha256).as_bytes()),
            self.config.supervision,
            self.config.tolerances,
        );
        let key = self
            .key
            .as_ref()
            .ok_or_else(|| anyhow::anyhow!("no signing key to sign a continuation with"))?;
        let signed = sign_plan(key, &plan_json, envelope)?;
        self.note(
            "continuation_planned",
            format!(
                "the rest of plan {} from {:.1} s on, around {} learnt block(s): {:.1} s, plan {} ({} samples)",
                &interrupted.sha256[..12],
                plan_t_s,
                twin.learnt.len(),
                plan.duration_s(),
                &plan.sha256[..12],
                plan.samples.len()
            ),
        );
        let plan = Arc::new(plan);
        self.new_plans
            .push_back((plan.clone(), plan_json, signed.clone()));
        let now = self.now_ns;
        self.start(plan, signed, counter, false, now);
        Ok(())
    }

    /// Fills in the report's link figures (call before writing it).
    pub fn finish_report(&mut self) {
        let mut rtt = self.master.rtt_s.clone();
        rtt.sort_by(f64::total_cmp);
        self.report.pings_answered = rtt.len();
        self.report.link_rtt_median_s = rtt.get(rtt.len() / 2).copied();
    }

    /// A payload refused before it was read: counted, nothing else.
    pub fn refused(&mut self, _refusal: &twindrive_link::secure::Refusal, _now_ns: u64) {
        self.report.refused_messages += 1;
    }

    /// Takes in a message from the robot.
    pub fn handle(&mut self, message: &Message, now_ns: u64) {
        self.master.handle(message, now_ns);
        self.react(now_ns);
    }

    pub fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        self.now_ns = now_ns;
        self.master.poll_transmit(now_ns)
    }

    pub fn poll_timeout(&self) -> Option<u64> {
        let wait = self
            .waiting_since_ns()
            .map(|at| at + (self.config.log_wait_s * 1e9) as u64);
        let ask_again = self
            .full_log_asked_ns
            .map(|t| t.saturating_add(FULL_LOG_ASK_EVERY_NS));
        [self.master.poll_timeout(), wait, ask_again]
            .into_iter()
            .flatten()
            .min()
    }
}

/// A robot log's digest as it came over the link, as an MCAP log file again.
fn log_file_of_digest(digest: &[u8]) -> anyhow::Result<Vec<u8>> {
    let log = twindrive_log::digest::decode(digest)?;
    let mut mcap = std::io::Cursor::new(Vec::new());
    twindrive_log::write_mcap(&log, &mut mcap)?;
    Ok(mcap.into_inner())
}
