//! What the master says while it works, for people: one line per event of
//! the mission (upload done, execution started, progress every tenth of the
//! plan, a hand-back with its reason and where, the twin's update, a
//! continuation verified and sent, completion, each robot log) and, when
//! nothing happened for a while, what it is waiting for and for how long.
//! No I/O and time as an argument: the process prints the events, and
//! [`Narrator::waiting_line`] as a live line on a terminal or after a quiet
//! while on a pipe.

use twindrive_link::upload::ChunkStore;
use twindrive_link::wire::{PlanPhase, TransferId};

use crate::operator::Operator;

/// How much the master says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verbosity {
    /// The outcome only (and errors).
    Quiet,
    /// Every event, progress every 10 %, and what it waits for when
    /// nothing happened for a while.
    Normal,
    /// Also every status summary the robot sends.
    Verbose,
}

/// Turns an operator's record into lines for people.
#[derive(Debug, Clone)]
pub struct Narrator {
    robot_id: String,
    verbosity: Verbosity,
    timeline_said: usize,
    statuses_said: u64,
    upload_tenth: Option<(TransferId, u32)>,
    plan_tenth: Option<(TransferId, u32)>,
}

impl Narrator {
    pub fn new(robot_id: &str, verbosity: Verbosity) -> Self {
        Self {
            robot_id: robot_id.into(),
            verbosity,
            timeline_said: 0,
            statuses_said: 0,
            upload_tenth: None,
            plan_tenth: None,
        }
    }

    pub fn verbosity(&self) -> Verbosity {
        self.verbosity
    }

    /// The events to print at `now_ns` (the operator's clock).
    pub fn lines<S: ChunkStore>(&mut self, op: &Operator<S>, now_ns: u64) -> Vec<String> {
        let mut out = Vec::new();
        if self.verbosity == Verbosity::Quiet {
            return out;
        }
        let at = |t_s: f64| format!("{t_s:7.1} s  {}", self.robot_id);
        // The mission's events, as the operator recorded them.
        for e in &op.report.timeline[self.timeline_said..] {
            // Executions are recorded by transfer: say the plan.
            let detail = match e.event.as_str() {
                "execution_started" | "execution_finished" => op
                    .plan_sha_of_transfer(&e.detail)
                    .map_or(e.detail.clone(), |sha| sha[..12].to_string()),
                _ => e.detail.clone(),
            };
            out.push(format!("{}  {}", at(e.t_s), event_text(&e.event, &detail)));
        }
        self.timeline_said = op.report.timeline.len();
        let now_s = now_ns as f64 * 1e-9;
        // The upload, every tenth of the way.
        if let (Some(transfer), Some((confirmed, chunks))) =
            (op.master.uploading(), op.master.upload_progress())
            && chunks > 0
            && !op.master.upload_finished()
        {
            let tenth = 10 * confirmed / chunks;
            if crossed(&mut self.upload_tenth, transfer, tenth) && tenth > 0 {
                out.push(format!(
                    "{}  upload {} %: {confirmed} of {chunks} chunks confirmed",
                    at(now_s),
                    10 * tenth
                ));
            }
        }
        // The plan's execution, every tenth of the way.
        if let Some(s) = op.master.latest_status()
            && let Some((transfer, PlanPhase::Executing)) = &s.plan
            && s.progress.1 > 0
        {
            let tenth = 10 * s.progress.0 / s.progress.1;
            if crossed(&mut self.plan_tenth, *transfer, tenth) && tenth > 0 {
                out.push(format!("{}  executing: {}", at(now_s), execution(s)));
            }
        }
        if self.verbosity == Verbosity::Verbose {
            while self.statuses_said < op.report.status_messages {
                self.statuses_said += 1;
                if let Some(s) = op.master.latest_status() {
                    out.push(format!("{}  status: {}", at(now_s), status_text(s)));
                }
            }
        }
        out
    }

    /// [`Narrator::waiting`] as a line like the events', stamped with the
    /// time.
    pub fn waiting_line<S: ChunkStore>(&self, op: &Operator<S>, now_ns: u64) -> String {
        format!(
            "{:7.1} s  {}  {}",
            now_ns as f64 * 1e-9,
            self.robot_id,
            self.waiting(op, now_ns)
        )
    }

    /// What the mission waits for now, with how long: the live status line
    /// on a terminal, and the line said on a pipe after a quiet while.
    pub fn waiting<S: ChunkStore>(&self, op: &Operator<S>, now_ns: u64) -> String {
        let now_s = now_ns as f64 * 1e-9;
        let heard = op
            .master
            .last_heard_ns
            .map(|t| now_ns.saturating_sub(t) as f64 * 1e-9);
        let silent = match heard {
            None => format!(", nothing heard from the robot in {now_s:.0} s"),
            Some(s) if s > 3.0 => format!(", nothing heard from the robot for {s:.0} s"),
            Some(_) => String::new(),
        };
        if let Some((pending, waited_s, limit_s)) = op.waiting_for_logs(now_ns) {
            let pending = pending.map_or("the robot has not said how many".into(), |n| {
                format!("{n} pending on the robot")
            });
            return format!(
                "waiting for the robot's next log ({pending}): {waited_s:.0} s of at most {limit_s:.0} s{silent}"
            );
        }
        if op.awaiting_decision().is_some() {
            return format!("waiting for the operator's decision on the hand-back{silent}");
        }
        if let Some((confirmed, chunks)) = op.master.upload_progress()
            && !op.master.upload_finished()
        {
            let started = op
                .master
                .upload_stats()
                .map_or(0.0, |(_, _, t)| now_ns.saturating_sub(t) as f64 * 1e-9);
            return format!(
                "uploading: {confirmed} of {chunks} chunks confirmed, {started:.0} s so far{silent}"
            );
        }
        match op.master.latest_status() {
            Some(s) => match &s.plan {
                Some((_, PlanPhase::Executing)) => {
                    format!("executing: {}{silent}", execution(s))
                }
                _ => format!("waiting for the robot to start the plan (it holds it whole){silent}"),
            },
            None => format!("waiting for the robot's first status{silent}"),
        }
    }
}

/// Whether `tenth` is a new tenth of `transfer` (and remembers it).
fn crossed(seen: &mut Option<(TransferId, u32)>, transfer: TransferId, tenth: u32) -> bool {
    match seen {
        Some((t, k)) if *t == transfer && *k >= tenth => false,
        _ => {
            *seen = Some((transfer, tenth));
            true
        }
    }
}

fn execution(s: &twindrive_link::wire::Status) -> String {
    let pct = 100.0 * f64::from(s.progress.0) / f64::from(s.progress.1.max(1));
    format!(
        "{pct:.0} % of the plan, {:.1} s in, {}, range residual {}",
        s.plan_t_s,
        deviation(s),
        if s.range_residual_m.is_finite() {
            format!("{:.3} m", s.range_residual_m)
        } else {
            "-".into()
        }
    )
}

/// The robot's distance from the plan's pose now and the largest since
/// the plan started, each labelled, with the detour each came on:
/// `deviation now 0.03 m, worst 1.95 m (during a detour)`.
fn deviation(s: &twindrive_link::wire::Status) -> String {
    let metres = |v: f64| {
        if v.is_finite() {
            format!("{v:.2} m")
        } else {
            "-".into()
        }
    };
    format!(
        "deviation now {}{}, worst {}{}",
        metres(s.deviation_now_m),
        if s.on_detour { " (on a detour)" } else { "" },
        metres(s.deviation_m),
        if s.max_deviation_on_detour {
            " (during a detour)"
        } else {
            ""
        }
    )
}

fn status_text(s: &twindrive_link::wire::Status) -> String {
    let phase = match &s.plan {
        None => "no plan".to_string(),
        Some((_, PlanPhase::Receiving { received, chunks })) => {
            format!("receiving {received}/{chunks}")
        }
        Some((_, PlanPhase::Rejected { reason })) => format!("rejected ({reason})"),
        Some((_, PlanPhase::Executing)) => format!("executing, {}", execution(s)),
        Some((_, PlanPhase::Finished)) => "finished".into(),
        Some((_, PlanPhase::Stopped { reason })) => format!("stopped ({reason})"),
    };
    format!(
        "{phase}; pose ({:.2}, {:.2}, {:.0} deg); {} log(s) pending; {} bump(s), {} collision(s)",
        s.pose[0],
        s.pose[1],
        s.pose[2].to_degrees(),
        s.logs_pending,
        s.bumps,
        s.collisions
    )
}

/// One of the operator's timeline events in words.
fn event_text(event: &str, detail: &str) -> String {
    let what = match event {
        "upload_started" => "uploading",
        "upload_finished" => "upload done:",
        "upload_refused" => "the robot REFUSED the upload:",
        "plan_rejected" => "the robot REJECTED the plan:",
        "execution_started" => "the robot started plan",
        "execution_finished" => "the robot finished plan",
        "stopped" => "the robot stopped:",
        "handback" => "HAND-BACK:",
        "twin_updated" => "the twin learnt from it:",
        "awaiting_operator" => "waiting for the operator:",
        "continuation_planned" => "continuation verified on the twin and signed:",
        "continuation_refused" => "NO CONTINUATION:",
        "robot_log" => "robot log received:",
        "operator_ended" => "the operator ended the mission:",
        "outcome" => "OUTCOME:",
        other => return format!("{}: {detail}", other.replace('_', " ")),
    };
    format!("{what} {detail}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use twindrive_link::wire::Status;

    fn executing(deviation_now_m: f64, on_detour: bool, worst: (f64, bool)) -> Status {
        Status {
            plan: Some(([7; 32], PlanPhase::Executing)),
            progress: (40, 100),
            plan_t_s: 12.0,
            pose: [1.0, 2.0, 0.3],
            params: [0.065, 0.066, 0.27],
            params_std: [1e-4; 3],
            deviation_m: worst.0,
            range_residual_m: 0.01,
            wheel_travel_rad: 50.0,
            logs_pending: 0,
            handback_pending: false,
            bumps: 0,
            collisions: 0,
            refused: 0,
            deviation_now_m,
            max_deviation_on_detour: worst.1,
            on_detour,
        }
    }

    /// A robot's deviation through random plans, each with a detour that
    /// leaves the plan and rejoins it: every line says the deviation now
    /// and the worst so far, each under its name, the worst marked as a
    /// detour's exactly when it came on one; back on the plan, the line says
    /// the small deviation now, not the detour's.
    #[test]
    fn the_deviation_is_said_now_and_at_its_worst_labelled() {
        let mut rng = ChaCha8Rng::seed_from_u64(54);
        for _ in 0..50 {
            let n = rng.random_range(20..80);
            let from = rng.random_range(2..n / 2);
            let to = rng.random_range(from + 5..n - 1);
            let peak = rng.random_range(0.3..2.5);
            let (mut worst, mut worst_on_detour) = (0.0f64, false);
            let mut last = String::new();
            for k in 0..n {
                let on_detour = (from..to).contains(&k);
                let now = if on_detour {
                    // Out to the peak and back.
                    let x = (k - from) as f64 / (to - from) as f64;
                    peak * (std::f64::consts::PI * x).sin() + rng.random_range(0.0..0.02)
                } else {
                    rng.random_range(0.0..0.05)
                };
                if now > worst {
                    (worst, worst_on_detour) = (now, on_detour);
                }
                let line = execution(&executing(now, on_detour, (worst, worst_on_detour)));
                let said_now = format!("deviation now {now:.2} m");
                assert!(line.contains(&said_now), "{line}");
                assert_eq!(line.contains("(on a detour)"), on_detour, "{line}");
                let said_worst = format!("worst {worst:.2} m");
                assert!(line.contains(&said_worst), "{line}");
                assert_eq!(
                    line.contains("(during a detour)"),
                    worst_on_detour,
                    "{line}"
                );
                assert!(
                    !line.contains("deviation 0") && !line.contains("deviation 1"),
                    "{line}"
                );
                last = line;
            }
            // Back on the plan after the detour: now is small, the worst the
            // detour's, said as such.
            assert!(worst_on_detour, "{last}");
            let now: f64 = last
                .split("deviation now ")
                .nth(1)
                .and_then(|t| t.split(' ').next())
                .and_then(|v| v.parse().ok())
                .unwrap();
            assert!(now < 0.06 && worst > 0.3, "{last}");
            assert!(last.contains(" (during a detour)"), "{last}");
        }
        // No plan running: no numbers to say.
        let idle = execution(&executing(f64::NAN, false, (f64::NAN, false)));
        assert!(idle.contains("deviation now -, worst -"), "{idle}");
    }

    #[test]
    fn a_tenth_is_said_once_per_transfer() {
        let mut seen = None;
        let (a, b) = ([1u8; 32], [2u8; 32]);
        assert!(crossed(&mut seen, a, 0));
        assert!(!crossed(&mut seen, a, 0));
        assert!(crossed(&mut seen, a, 3));
        assert!(!crossed(&mut seen, a, 2));
        assert!(crossed(&mut seen, b, 1));
    }

    #[test]
    fn every_timeline_event_has_words() {
        for e in [
            "upload_started",
            "handback",
            "continuation_planned",
            "robot_log",
            "outcome",
        ] {
            let t = event_text(e, "x");
            assert!(!t.contains('_'), "{t}");
            assert!(t.ends_with('x'), "{t}");
        }
        assert_eq!(event_text("new_thing", "d"), "new thing: d");
    }
}
