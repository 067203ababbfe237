//! Robot logs home: each plan's log kept in the store once the hand-back
//! has gone (in full, and as the digest that comes home:
//! `twindrive_log::digest`, at most `log_budget_bytes_s` per second of
//! mission), then the digest uploaded to the master, oldest first, until it
//! acknowledges it: paced to what the telemetry budget leaves while a plan
//! runs, at the link's rate (as the master says) once none does. A plan's
//! full-rate log goes the same way when the master asks for it
//! (`Body::LogRequest`), after what is already on its way.

use serde_json::json;
use twindrive_link::upload::{Sender, SenderConfig};
use twindrive_link::wire::{Body, Message};
use twindrive_log::MissionLog;
use twindrive_mission::plan::hex;

use super::{Backfill, RobotAgent};
use crate::backend::RobotBackend;
use crate::store::{LogFiles, RobotStore};

impl<B: RobotBackend, S: RobotStore> RobotAgent<B, S> {
    /// Writes the logs of plans that ended, then the next message of the
    /// oldest log on its way (one at a time).
    pub(super) fn poll_backfill(&mut self, now_ns: u64) -> Option<Message> {
        while let Some((sha, log)) = self.unwritten.pop_front() {
            self.write_log(&sha, &log, now_ns);
        }
        while let Some(b) = self.backfills.front_mut() {
            if b.sender.is_finished() || b.sender.refused().is_some() {
                let b = self.backfills.pop_front().expect("front");
                let event = if b.sender.is_finished() {
                    "log_acknowledged"
                } else {
                    "log_refused"
                };
                self.record(
                    now_ns,
                    event,
                    json!({ "plan_sha256": b.plan_sha256, "full_rate": b.full_rate }),
                );
                continue;
            }
            let pace = self.backfill_pace_bit_s();
            let b = self.backfills.front_mut().expect("front");
            b.sender.set_pace(pace);
            return b.sender.poll_transmit(now_ns);
        }
        None
    }

    /// How fast logs go home now (bit/s; `None`: as fast as the link
    /// takes them).
    fn backfill_pace_bit_s(&self) -> Option<f64> {
        let budget = Some((8.0 * 0.7 * self.budget_bytes_s).max(800.0));
        if self.running.is_some() {
            return budget;
        }
        match self.backfill_bytes_s {
            None => budget,
            Some(r) if r <= 0.0 => None,
            Some(r) => Some((8.0 * r).max(800.0)),
        }
    }

    pub(super) fn backfill_timeout(&self) -> Option<u64> {
        self.backfills.front().and_then(|b| {
            if b.sender.is_finished() || b.sender.refused().is_some() {
                Some(0)
            } else {
                b.sender.poll_timeout()
            }
        })
    }

    fn write_log(&mut self, plan_sha256: &str, log: &MissionLog, now_ns: u64) {
        let mut digest_note = None;
        let result = (|| -> anyhow::Result<()> {
            let mut mcap = std::io::Cursor::new(Vec::new());
            let map = self.backend.map();
            twindrive_log::write_mcap_with_map(log, map.as_ref(), &mut mcap)?;
            let mut csv = Vec::new();
            twindrive_log::write_csv(log, &mut csv)?;
            let (digest, kept) = twindrive_log::digest::encode(log, self.config.log_budget_bytes_s);
            digest_note = Some((digest.len(), kept));
            let files = LogFiles {
                digest,
                mcap: mcap.into_inner(),
                csv,
                meta_json: serde_json::to_vec_pretty(&log.header)?,
            };
            self.store.store_log(plan_sha256, &files)?;
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
                        "digest_bytes": digest_note.map(|(n, _)| n),
                        "sweeps_kept": digest_note.map(|(_, k)| k),
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

    pub(super) fn queue_backfill(&mut self, plan_sha256: &str) {
        if self.queued(plan_sha256, false) {
            return;
        }
        // A log kept before digests existed: its digest from its MCAP.
        let digest = self.store.log_digest(plan_sha256).or_else(|e| {
            if e.kind() != std::io::ErrorKind::NotFound {
                return Err(e);
            }
            let mcap = self.store.log_mcap(plan_sha256)?;
            let log = twindrive_log::read_mcap_bytes(&mcap, std::path::Path::new("log.mcap"))
                .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))?;
            Ok(twindrive_log::digest::encode(&log, self.config.log_budget_bytes_s).0)
        });
        match digest {
            Ok(file) => self.push_backfill(plan_sha256, false, file),
            Err(e) => {
                tracing::error!(plan_sha256, error = %e, "a robot log to back-fill")
            }
        }
    }

    /// The master asks for the full-rate log of the plan whose document
    /// hash is `plan`: its MCAP joins the logs on their way (once: a
    /// request heard again while it is queued changes nothing), or the
    /// master hears that none is kept here.
    pub(super) fn queue_full_log(&mut self, plan: &[u8; 32], now_ns: u64) {
        let plan_sha256 = hex(plan);
        if self.queued(&plan_sha256, true) {
            return;
        }
        match self.store.log_mcap(&plan_sha256) {
            Ok(file) => {
                let bytes = file.len();
                self.push_backfill(&plan_sha256, true, file);
                self.record(
                    now_ns,
                    "log_requested",
                    json!({ "plan_sha256": plan_sha256, "bytes": bytes }),
                );
            }
            Err(e) => {
                let reason = format!("no log of plan {plan_sha256} is kept on this robot ({e})");
                self.record(
                    now_ns,
                    "log_request_refused",
                    json!({ "plan_sha256": plan_sha256, "reason": reason }),
                );
                self.outbox.push_back(Body::Refused {
                    transfer: *plan,
                    reason,
                });
            }
        }
    }

    /// Whether `plan_sha256`'s log (full-rate or digest) is on its way.
    fn queued(&self, plan_sha256: &str, full_rate: bool) -> bool {
        self.backfills
            .iter()
            .any(|b| b.plan_sha256 == plan_sha256 && b.full_rate == full_rate)
    }

    /// Puts `file`, `plan_sha256`'s log, last among the logs on their way.
    fn push_backfill(&mut self, plan_sha256: &str, full_rate: bool, file: Vec<u8>) {
        let sender = Sender::resume(
            &self.config.robot_id,
            file,
            SenderConfig {
                pace_bit_s: self.backfill_pace_bit_s(),
                ..SenderConfig::default()
            },
        );
        self.backfills.push_back(Backfill {
            plan_sha256: plan_sha256.into(),
            full_rate,
            sender,
        });
    }
}
