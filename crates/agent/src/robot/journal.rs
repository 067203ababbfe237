//! The journal: one JSON object per line, and what a restart reads from it.

use serde_json::json;
use twindrive_link::wire::{PlanPhase, TransferId};
use twindrive_mission::plan::hex;

use super::RobotAgent;
use crate::backend::RobotBackend;
use crate::store::{RobotStore, parse_journal};

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

impl<B: RobotBackend, S: RobotStore> RobotAgent<B, S> {
    /// Reads the journal of an earlier run: what each plan file became, a
    /// plan interrupted mid-run (now stopped for good), logs to offer again.
    pub(super) fn recover(&mut self) -> std::io::Result<()> {
        let lines = parse_journal(&self.store.read_journal()?);
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
}
