//! The master's end of the link as one state machine: it uploads signed
//! plans, keeps a supervised robot's dead-man quiet with heartbeats, reads
//! the robot's status summaries, acknowledges hand-backs and assembles the
//! robot's back-filled logs. What to do about any of it is the owner's
//! business ([`crate::operator`]): the master reports [`MasterEvent`]s.

use std::collections::{HashMap, HashSet, VecDeque};

use twindrive_link::emulator::LinkProfile;
use twindrive_link::upload::{
    ChunkStore, Receiver, ReceiverConfig, ReceiverEvent, Sender, SenderConfig,
};
use twindrive_link::wire::{
    Body, DetourReport, Handback, Message, PlanPhase, Stamper, Status, TransferId,
};

/// What the master reports to its owner.
#[derive(Debug, Clone, PartialEq)]
pub enum MasterEvent {
    /// Chunks of the plan file the robot has confirmed.
    UploadProgress {
        transfer: TransferId,
        confirmed: u32,
        chunks: u32,
    },
    /// The robot holds the whole plan file.
    Uploaded(UploadRecord),
    /// The robot refused the upload itself (too large, say).
    UploadRefused {
        transfer: TransferId,
        reason: String,
    },
    /// A plan file's phase on the robot changed.
    Phase {
        transfer: TransferId,
        phase: PlanPhase,
    },
    /// The robot handed control back (reported once per plan).
    Handback(Box<Handback>),
    /// The robot went around something on its own (begun, or back on the
    /// plan).
    Detour(Box<DetourReport>),
    /// A robot log arrived whole (a digest, or a full-rate MCAP asked for
    /// with [`Master::request_log`]).
    RobotLog { transfer: TransferId, file: Vec<u8> },
    /// The robot keeps no log of a plan asked for (by its document hash).
    LogRefused {
        plan_sha256: [u8; 32],
        reason: String,
    },
    /// A status summary.
    Status(Box<Status>),
}

/// One finished upload.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct UploadRecord {
    #[serde(serialize_with = "ser_hex")]
    pub transfer: TransferId,
    pub bytes: u64,
    pub duration_s: f64,
    pub chunks: u32,
    pub chunks_resent: u64,
}

fn ser_hex<S: serde::Serializer>(t: &TransferId, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(&twindrive_mission::plan::hex(t))
}

struct Upload {
    sender: Sender,
    bytes: u64,
    started_ns: u64,
    /// When the robot held it whole, or refused it.
    finished_ns: Option<u64>,
    last_confirmed: u32,
    done: bool,
}

/// Master settings.
#[derive(Debug, Clone, Copy)]
pub struct MasterConfig {
    pub upload: SenderConfig,
    /// A heartbeat this often (s).
    pub heartbeat_period_s: f64,
    /// Bytes per second the robot may send (it keeps to the lower of this
    /// and its own limit).
    pub telemetry_budget_bytes_s: f64,
}

impl MasterConfig {
    /// Settings for a master whose traffic crosses `link` (`None`: a link
    /// of unknown character): the upload paced a little below the link's
    /// rate (heartbeats, pings and the NAKs of the robot's log share the
    /// way up, and a queue that never drains stretches the round trip
    /// until chunks are sent twice), its round trip and repair shards sized
    /// for the link's delay and loss.
    pub fn for_link(link: Option<&LinkProfile>, telemetry_budget_bytes_s: f64) -> Self {
        Self {
            upload: SenderConfig {
                pace_bit_s: link.and_then(|p| p.bandwidth_bit_s).map(|b| 0.95 * b),
                rtt_hint_ns: link.map_or(1_000_000_000, |p| {
                    ((2.0 * p.latency_s).max(0.05) * 1e9) as u64
                }),
                loss_hint: link.map_or(0.0, |p| p.loss),
                ..SenderConfig::default()
            },
            heartbeat_period_s: 1.0,
            telemetry_budget_bytes_s,
        }
    }
}

impl Default for MasterConfig {
    fn default() -> Self {
        Self {
            upload: SenderConfig::default(),
            heartbeat_period_s: 1.0,
            telemetry_budget_bytes_s: 8_000.0,
        }
    }
}

/// The master's end.
pub struct Master<S: ChunkStore> {
    stamper: Stamper,
    config: MasterConfig,
    upload: Option<Upload>,
    logs: Receiver<S>,
    next_heartbeat_ns: u64,
    outbox: VecDeque<Body>,
    handbacks_seen: HashSet<TransferId>,
    /// Detour reports heard: plan, index, whether back on the plan.
    detours_seen: HashSet<(TransferId, u32, bool)>,
    phases: HashMap<TransferId, PlanPhase>,
    latest: Option<Status>,
    events: VecDeque<MasterEvent>,
    /// When the robot was last heard (the driving clock).
    pub last_heard_ns: Option<u64>,
    pings: HashMap<u64, u64>,
    next_nonce: u64,
    /// Round trips measured (s).
    pub rtt_s: Vec<f64>,
}

impl<S: ChunkStore> Master<S> {
    /// A master for `robot_id`; robot logs are assembled in `log_store`.
    pub fn new(robot_id: &str, config: MasterConfig, log_store: S) -> Self {
        Self {
            stamper: Stamper::new(robot_id),
            config,
            upload: None,
            logs: Receiver::new(
                robot_id,
                log_store,
                ReceiverConfig {
                    max_file_bytes: 1 << 30,
                    ..ReceiverConfig::default()
                },
            ),
            next_heartbeat_ns: 0,
            outbox: VecDeque::new(),
            handbacks_seen: HashSet::new(),
            detours_seen: HashSet::new(),
            phases: HashMap::new(),
            latest: None,
            events: VecDeque::new(),
            last_heard_ns: None,
            pings: HashMap::new(),
            next_nonce: 0,
            rtt_s: Vec::new(),
        }
    }

    /// Starts uploading a signed plan file. `resume`: it may be partly on
    /// the robot already (this master restarted), so only what the robot's
    /// answer lists as missing is sent.
    pub fn upload(&mut self, file: Vec<u8>, resume: bool, now_ns: u64) -> TransferId {
        let bytes = file.len() as u64;
        let robot = self.stamper.robot_id.clone();
        let sender = if resume {
            Sender::resume(&robot, file, self.config.upload)
        } else {
            Sender::new(&robot, file, self.config.upload)
        };
        let transfer = sender.transfer();
        self.upload = Some(Upload {
            sender,
            bytes,
            started_ns: now_ns,
            finished_ns: None,
            last_confirmed: 0,
            done: false,
        });
        transfer
    }

    /// The upload under way or last finished.
    /// Asks the robot for the full-rate log of the plan whose document
    /// hash is `plan_sha256` (it comes as a [`MasterEvent::RobotLog`] after
    /// the logs already on their way, or a [`MasterEvent::LogRefused`]).
    /// The link may lose the request: the owner asks again until one of
    /// them comes.
    pub fn request_log(&mut self, plan_sha256: [u8; 32]) {
        self.outbox.push_back(Body::LogRequest { plan_sha256 });
    }

    pub fn uploading(&self) -> Option<TransferId> {
        self.upload.as_ref().map(|u| u.sender.transfer())
    }

    /// Chunks of the current upload the robot has confirmed, of all.
    pub fn upload_progress(&self) -> Option<(u32, u32)> {
        self.upload
            .as_ref()
            .map(|u| (u.sender.stats.chunks_confirmed, u.sender.stats.chunks))
    }

    /// The current (or last) upload's counts: chunks sent, resent,
    /// confirmed, repair shards; its size in bytes and when it began.
    pub fn upload_stats(&self) -> Option<(twindrive_link::upload::SenderStats, u64, u64)> {
        self.upload
            .as_ref()
            .map(|u| (u.sender.stats, u.bytes, u.started_ns))
    }

    /// How long the current (or last) upload took: until the robot held
    /// it whole or refused it, or until `now_ns` while it goes on (s).
    pub fn upload_duration_s(&self, now_ns: u64) -> Option<f64> {
        self.upload
            .as_ref()
            .map(|u| u.finished_ns.unwrap_or(now_ns).saturating_sub(u.started_ns) as f64 * 1e-9)
    }

    /// Pings answered, and pings unanswered for longer than `late_ns` (lost
    /// one way or the other; an unanswered ping is forgotten after ten
    /// minutes).
    pub fn ping_counts(&self, now_ns: u64, late_ns: u64) -> (usize, usize) {
        let lost = self
            .pings
            .values()
            .filter(|&&sent| now_ns.saturating_sub(sent) > late_ns)
            .count();
        (self.rtt_s.len(), lost)
    }

    /// Whether the current upload is on the robot whole.
    pub fn upload_finished(&self) -> bool {
        self.upload.as_ref().is_some_and(|u| u.done)
    }

    pub fn phase(&self, transfer: &TransferId) -> Option<&PlanPhase> {
        self.phases.get(transfer)
    }

    pub fn latest_status(&self) -> Option<&Status> {
        self.latest.as_ref()
    }

    pub fn poll_event(&mut self) -> Option<MasterEvent> {
        self.events.pop_front()
    }

    /// Takes in a message from the robot.
    pub fn handle(&mut self, message: &Message, now_ns: u64) {
        self.last_heard_ns = Some(now_ns);
        match &message.body {
            Body::Nak { transfer, .. }
            | Body::Finished { transfer }
            | Body::Refused { transfer, .. } => {
                if let Some(u) = &mut self.upload
                    && u.sender.transfer() == *transfer
                {
                    u.sender.handle(message, now_ns);
                    self.upload_events(now_ns);
                } else if let Body::Refused { reason, .. } = &message.body {
                    self.events.push_back(MasterEvent::LogRefused {
                        plan_sha256: *transfer,
                        reason: reason.clone(),
                    });
                }
            }
            Body::Offer(_) | Body::Chunk { .. } | Body::Repair { .. } | Body::EndOfFile { .. } => {
                self.logs.handle(message, now_ns);
                while let Some(e) = self.logs.poll_event() {
                    match e {
                        ReceiverEvent::Completed { transfer, file } => self
                            .events
                            .push_back(MasterEvent::RobotLog { transfer, file }),
                        ReceiverEvent::StorageError(e) => {
                            tracing::error!(error = %e, "storing a robot log chunk")
                        }
                        _ => {}
                    }
                }
            }
            Body::Status(status) => {
                if let Some((t, phase)) = &status.plan {
                    self.phase_seen(*t, phase.clone());
                }
                self.latest = Some((**status).clone());
                self.events.push_back(MasterEvent::Status(status.clone()));
            }
            Body::Handback(h) => {
                self.outbox.push_back(Body::HandbackAck { plan: h.plan });
                if self.handbacks_seen.insert(h.plan) {
                    self.phase_seen(
                        h.plan,
                        PlanPhase::Stopped {
                            reason: h.reason.clone(),
                        },
                    );
                    self.events.push_back(MasterEvent::Handback(h.clone()));
                }
            }
            Body::Detour(d) => {
                self.outbox.push_back(Body::DetourAck {
                    plan: d.plan,
                    index: d.index,
                    rejoined: d.rejoined,
                });
                if self.detours_seen.insert((d.plan, d.index, d.rejoined)) {
                    self.events.push_back(MasterEvent::Detour(d.clone()));
                }
            }
            Body::Ping { nonce } => self.outbox.push_back(Body::Pong { nonce: *nonce }),
            Body::Pong { nonce } => {
                if let Some(sent) = self.pings.remove(nonce) {
                    let rtt_s = now_ns.saturating_sub(sent) as f64 * 1e-9;
                    self.rtt_s.push(rtt_s);
                }
            }
            Body::Heartbeat { .. }
            | Body::HandbackAck { .. }
            | Body::DetourAck { .. }
            | Body::LogRequest { .. } => {}
        }
    }

    fn phase_seen(&mut self, transfer: TransferId, phase: PlanPhase) {
        // Receiving progress is reported as upload progress.
        if matches!(phase, PlanPhase::Receiving { .. }) {
            return;
        }
        if self.phases.get(&transfer) != Some(&phase) {
            // A stop the hand-back already reported keeps its reason.
            if matches!(self.phases.get(&transfer), Some(PlanPhase::Stopped { .. }))
                && matches!(phase, PlanPhase::Stopped { .. })
            {
                return;
            }
            self.phases.insert(transfer, phase.clone());
            self.events
                .push_back(MasterEvent::Phase { transfer, phase });
        }
    }

    fn upload_events(&mut self, now_ns: u64) {
        let Some(u) = &mut self.upload else {
            return;
        };
        let transfer = u.sender.transfer();
        let confirmed = u.sender.stats.chunks_confirmed;
        if confirmed != u.last_confirmed {
            u.last_confirmed = confirmed;
            self.events.push_back(MasterEvent::UploadProgress {
                transfer,
                confirmed,
                chunks: u.sender.stats.chunks,
            });
        }
        if u.done {
            return;
        }
        if u.sender.is_finished() {
            u.done = true;
            u.finished_ns = Some(now_ns);
            self.events.push_back(MasterEvent::Uploaded(UploadRecord {
                transfer,
                bytes: u.bytes,
                duration_s: now_ns.saturating_sub(u.started_ns) as f64 * 1e-9,
                chunks: u.sender.stats.chunks,
                chunks_resent: u.sender.stats.chunks_resent,
            }));
        } else if let Some(reason) = u.sender.refused() {
            u.done = true;
            u.finished_ns = Some(now_ns);
            self.events.push_back(MasterEvent::UploadRefused {
                transfer,
                reason: reason.to_string(),
            });
        }
    }

    /// The next message to send at `now_ns`.
    pub fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        if let Some(body) = self.outbox.pop_front() {
            return Some(self.stamper.stamp(body, now_ns));
        }
        if let Some(u) = &mut self.upload
            && let Some(m) = u.sender.poll_transmit(now_ns)
        {
            return Some(m);
        }
        if let Some(m) = self.logs.poll_transmit(now_ns) {
            return Some(m);
        }
        if now_ns >= self.next_heartbeat_ns {
            self.next_heartbeat_ns = now_ns + (self.config.heartbeat_period_s * 1e9) as u64;
            let budget = self
                .config
                .telemetry_budget_bytes_s
                .clamp(0.0, f64::from(u32::MAX)) as u32;
            // Every heartbeat carries a ping: the link's round trip, measured.
            // (A ping unanswered for ten minutes is forgotten.)
            self.pings
                .retain(|_, sent| now_ns.saturating_sub(*sent) < 600_000_000_000);
            if self.pings.len() < 1_024 {
                self.next_nonce += 1;
                self.pings.insert(self.next_nonce, now_ns);
                self.outbox.push_back(Body::Ping {
                    nonce: self.next_nonce,
                });
            }
            // The robot's logs come home at the rate this master's own
            // uploads go out at, once it drives nothing.
            let backfill_bytes_s = self.config.upload.pace_bit_s.map_or(0, |bit_s| {
                (bit_s / 8.0).clamp(1.0, f64::from(u32::MAX)) as u32
            });
            return Some(self.stamper.stamp(
                Body::Heartbeat {
                    telemetry_budget_bytes_s: budget,
                    backfill_bytes_s,
                },
                now_ns,
            ));
        }
        None
    }

    /// When the master next wants `poll_transmit` called.
    pub fn poll_timeout(&self) -> Option<u64> {
        if !self.outbox.is_empty() {
            return Some(0);
        }
        [
            self.upload.as_ref().and_then(|u| u.sender.poll_timeout()),
            self.logs.poll_timeout(),
            Some(self.next_heartbeat_ns),
        ]
        .into_iter()
        .flatten()
        .min()
    }
}
