//! Driving an accepted plan: the executive at the backend's control rate,
//! the navigator's estimate, the robot's log, and the hand-back when
//! reality departs from the plan.

use std::collections::VecDeque;
use std::sync::Arc;

use serde_json::json;
use twindrive_link::wire::{DetourReport, Handback, PlanPhase, TransferId, WindowSample};
use twindrive_log::{MissionLog, StepRecord};
use twindrive_mission::plan::{MissionPlan, hex};

use super::{MAX_DETOUR_REPORTS, RobotAgent, Running, WINDOW_EVERY, WINDOW_TICKS, pose3};
use crate::backend::RobotBackend;
use crate::executive::{Event, Executive, Stop};
use crate::localize::Mode;
use crate::navigator::{Navigator, initial_estimate, with_learnt_params};
use crate::store::RobotStore;
use twindrive_link::wire::MAX_MESSAGE_BYTES;

impl<B: RobotBackend, S: RobotStore> RobotAgent<B, S> {
    pub(super) fn start(
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
            deviation_now_m: 0.0,
            max_deviation_m: 0.0,
            max_deviation_on_detour: false,
            window: VecDeque::new(),
            pace: WindowPace::default(),
            tick: 0,
        });
        self.next_tick_ns = now_ns;
    }

    fn tick_period_ns(&self) -> u64 {
        ((self.backend.period_s() / self.config.time_scale.max(1e-6)) * 1e9).max(1.0) as u64
    }

    /// Runs every control tick due by `now_ns` (a process that fell behind
    /// catches up, a bounded number of ticks at a time).
    ///
    /// While no plan runs, the wheels are commanded zero once a period for
    /// as long as the backend needs to hear it ([`RobotBackend::hold`]): a
    /// stopped robot stays stopped on drivers that hold their last command.
    pub(super) fn run_ticks(&mut self, now_ns: u64) {
        let period = self.tick_period_ns();
        let mut budget = 1_000;
        while self.running.is_some() && self.next_tick_ns <= now_ns && budget > 0 {
            budget -= 1;
            self.next_tick_ns += period;
            self.tick(now_ns);
        }
        if self.running.is_none() && self.holding && self.next_tick_ns <= now_ns {
            self.holding = self.backend.hold();
            // No catching up on zeros: one now, the next a period on.
            self.next_tick_ns += period;
            if self.next_tick_ns <= now_ns {
                self.next_tick_ns = now_ns + period;
            }
        }
    }

    fn tick(&mut self, now_ns: u64) {
        let Some(r) = &mut self.running else {
            return;
        };
        // Where the robot is (encoders, any absolute pose, and its range
        // readings matched against the plan's map), and what the wheels do
        // this period: decided on the period's reading and sent in the same
        // period, so a stop is the very command of the tick that decides it.
        let decided = self.backend.step(&mut |reading| {
            let belief = r.nav.update(reading);
            r.exec.tick(reading, &belief)
        });
        let Some(reading) = decided else {
            let reason = "the robot's backend stopped".to_string();
            self.end(Some(Stop::DeadMan { silent_s: 0.0 }), Some(reason), now_ns);
            return;
        };
        self.backend_t_s = reading.t_s;
        let t0 = *r.t0_s.get_or_insert(reading.t_s - self.backend.period_s());
        let pose = pose3(&r.nav.pose());
        let covariance = r.nav.pose_covariance();
        r.tick += 1;
        // The robot's own log of this period.
        let mut record: StepRecord = reading.record;
        record.t_ns = ((reading.t_s - t0).max(0.0) * 1e9).round() as u64;
        r.log.steps.push(record);
        r.log.ranges.extend_from_slice(&reading.fresh_ranges_m);
        let reference = r.exec.reference();
        let deviation = (pose[0] - reference.x_m).hypot(pose[1] - reference.y_m);
        r.deviation_now_m = deviation;
        if deviation > r.max_deviation_m {
            r.max_deviation_m = deviation;
            r.max_deviation_on_detour = r.exec.on_a_detour();
        }
        let localizer = r.nav.localizer();
        let localized = localizer.localized(reading.t_s);
        let localization_changed = (localized != r.localized && localizer.mode() != Mode::None)
            .then(|| {
                r.localized = localized;
                (hex(&r.transfer), localizer.fixes, localizer.failures)
            });
        // A sample holds only the readings taken at its pose: a beam read
        // periods earlier, paired with this pose, would put what it saw
        // where the robot no longer looked from (a turning robot's walls
        // would come home bent, as obstacles the twin lacks).
        let beams = reading.fresh_ranges_m.len();
        let force = reading.bump || r.exec.stopped().is_some();
        if r.pace.take(r.tick, &reading.fresh_ranges_m, force) {
            r.window.push_back(WindowSample {
                // On the plan's clock (detours move it on).
                plan_t_s: reading.t_s - t0 - r.exec.plan_lag_s(reading.t_s),
                pose,
                ranges_m: reading.fresh_ranges_m.iter().map(|&v| v as f32).collect(),
                bump: reading.bump,
            });
            // As many samples as fit the hand-back message: a lidar's
            // hundreds of beams a sample would otherwise make it too long
            // to send, and the hand-back would never arrive.
            if r.window.len() > window_samples(beams) {
                r.window.pop_front();
            }
        }
        self.params = r.nav.params();
        self.params_covariance = r.nav.params_covariance();
        self.pose = pose;
        self.pose_covariance = covariance;
        // Each press and each contact counted once, however many periods
        // or plans it lasts (a continuation can start against the box the
        // plan before it met).
        if reading.bump && !self.last_bump {
            self.bumps += 1;
        }
        self.last_bump = reading.bump;
        if reading.blocked && !self.last_blocked {
            self.collisions += 1;
        }
        self.last_blocked = reading.blocked;
        let stopped = r.exec.stopped().cloned();
        let plan_id = r.transfer;
        let transfer = hex(&plan_id);
        let events = r.exec.take_events();
        for event in events {
            self.queue_detour_report(plan_id, &event);
            // Detours the robot decided on its own: the master hears them
            // (and the twin learns what it saw) without a round trip.
            let mut details = serde_json::to_value(&event).expect("events serialise");
            let name = details
                .as_object_mut()
                .and_then(|m| m.remove("event"))
                .and_then(|v| v.as_str().map(str::to_owned))
                .unwrap_or_else(|| "detour".into());
            if let Some(m) = details.as_object_mut() {
                m.insert("transfer".into(), json!(transfer));
            }
            self.record(now_ns, &name, details);
        }
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

    /// A detour begun or ended goes to the master (repeated until
    /// acknowledged; at most [`MAX_DETOUR_REPORTS`] wait, the oldest
    /// dropped).
    fn queue_detour_report(&mut self, plan: twindrive_link::wire::TransferId, event: &Event) {
        let f32s = |v: &[[f64; 2]]| -> Vec<[f32; 2]> {
            v.iter().map(|p| [p[0] as f32, p[1] as f32]).collect()
        };
        let report = match event {
            Event::Detour {
                plan_t_s,
                from,
                from_sample,
                rejoin,
                waypoints,
                obstacle,
                ..
            } => {
                self.detour_index = self.detour_index.wrapping_add(1);
                DetourReport {
                    plan,
                    index: self.detour_index,
                    plan_t_s: *plan_t_s,
                    from: *from,
                    from_sample: *from_sample as u32,
                    waypoints: f32s(waypoints),
                    rejoin: *rejoin as u32,
                    obstacle: f32s(obstacle),
                    rejoined: false,
                    extra_s: 0.0,
                    extra_m: 0.0,
                }
            }
            Event::Rejoined {
                sample,
                extra_s,
                extra_m,
                obstacle,
                ..
            } => {
                // The report of the same detour when it began.
                let Some(begun) = self
                    .last_detour
                    .clone()
                    .filter(|d| d.plan == plan && d.index == self.detour_index)
                else {
                    return;
                };
                DetourReport {
                    rejoin: *sample as u32,
                    obstacle: f32s(obstacle),
                    rejoined: true,
                    extra_s: *extra_s,
                    extra_m: *extra_m,
                    ..begun
                }
            }
        };
        self.last_detour = Some(report.clone());
        if self.detours.len() == MAX_DETOUR_REPORTS {
            self.detours.pop_front();
        }
        self.detours.push_back((report, 0));
    }

    /// The plan ended (or the backend did): record it, write the log, hand
    /// back if reality departed from the plan.
    fn end(&mut self, stop: Option<Stop>, note: Option<String>, now_ns: u64) {
        let Some(r) = self.running.take() else {
            return;
        };
        // The stop's own tick commanded zero; from the next period on the
        // agent holds it for as long as the robot needs to hear it.
        self.holding = true;
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
}

/// When the hand-back's window takes a sample: on a tick with a range
/// reading, at most every [`WINDOW_EVERY`] ticks, but at every sweep of a
/// sensor that reads less often than that (a lidar's); and at every tick
/// with a contact or a stop.
#[derive(Debug, Default)]
pub(super) struct WindowPace {
    /// The tick each range beam last read on.
    last_read: Vec<Option<u64>>,
    last_sample: Option<u64>,
}

impl WindowPace {
    /// Whether tick `tick`, whose fresh readings are `fresh_ranges_m` (NaN:
    /// the beam did not read), is sampled; `force` for a contact or a stop.
    pub(super) fn take(&mut self, tick: u64, fresh_ranges_m: &[f64], force: bool) -> bool {
        self.last_read.resize(fresh_ranges_m.len(), None);
        let (mut any_read, mut slow_sweep) = (false, false);
        for (last, v) in self.last_read.iter_mut().zip(fresh_ranges_m) {
            if v.is_finite() {
                any_read = true;
                slow_sweep |= last.is_none_or(|t| tick - t >= WINDOW_EVERY);
                *last = Some(tick);
            }
        }
        let due = self.last_sample.is_none_or(|t| tick - t >= WINDOW_EVERY);
        let take = force || (any_read && (due || slow_sweep));
        if take {
            self.last_sample = Some(tick);
        }
        take
    }
}

/// Samples of `beams` readings the hand-back's window keeps: at most
/// [`WINDOW_TICKS`] / [`WINDOW_EVERY`], and no more than fill three
/// quarters of a message (4 bytes a beam, about 40 more a sample).
fn window_samples(beams: usize) -> usize {
    let per_sample = 4 * beams + 48;
    (MAX_MESSAGE_BYTES * 3 / 4 / per_sample).clamp(2, WINDOW_TICKS / WINDOW_EVERY as usize)
}

#[cfg(test)]
mod window_tests {
    use super::*;
    use twindrive_link::wire::{Body, Handback, Stamper, WindowSample, decode, encode};

    /// A 50 Hz side IR (every second tick, either phase) and a 10 Hz lidar
    /// (every tenth tick, any phase), at 100 Hz: every lidar sweep is
    /// sampled, the IR every fourth tick, and nothing between readings
    /// unless forced.
    #[test]
    fn the_window_samples_every_slow_sweep_and_fast_readings_at_its_pace() {
        for (ir_phase, lidar_phase) in [(0, 0), (1, 0), (1, 3), (0, 7)] {
            let mut pace = WindowPace::default();
            let mut taken = Vec::new();
            for tick in 0..200u64 {
                let ir = (tick + ir_phase) % 2 == 0;
                let lidar = (tick + lidar_phase) % 10 == 0;
                let fresh = [
                    if ir { 0.5 } else { f64::NAN },
                    if lidar { 2.0 } else { f64::NAN },
                    if lidar { 2.5 } else { f64::NAN },
                ];
                if pace.take(tick, &fresh, tick == 101) {
                    taken.push((tick, ir, lidar));
                }
            }
            let sweeps = taken.iter().filter(|t| t.2).count();
            assert_eq!(sweeps, 20, "{taken:?}");
            let ir_only: Vec<u64> = taken.iter().filter(|t| t.1 && !t.2).map(|t| t.0).collect();
            assert!(ir_only.len() >= 200 / 4 - 20 - 2, "{taken:?}");
            // (A beam's very first reading is a sweep of its own.)
            for w in taken.windows(2).filter(|w| w[0].0 >= 10) {
                let (a, b) = (w[0], w[1]);
                assert!(b.2 || b.0 == 101 || b.0 - a.0 >= WINDOW_EVERY, "{taken:?}");
                assert!(
                    b.0 == 101 || b.1 || b.2,
                    "a sample with nothing read: {taken:?}"
                );
            }
            assert!(taken.iter().any(|t| t.0 == 101), "forced");
        }
    }

    #[test]
    fn a_full_window_fits_a_hand_back_message_for_any_sensor() {
        for beams in [1usize, 3, 181, 361, 720, 1081, 2000] {
            let n = window_samples(beams);
            assert!(n >= 2 && n <= WINDOW_TICKS / WINDOW_EVERY as usize);
            let window = vec![
                WindowSample {
                    plan_t_s: 1.0,
                    pose: [1.0, 2.0, 3.0],
                    ranges_m: vec![1.5; beams],
                    bump: false,
                };
                n + 1
            ];
            let h = Handback {
                plan: [7; 32],
                reason: "range_residual".into(),
                plan_t_s: 1.0,
                progress: 3,
                pose: [0.0; 3],
                pose_covariance: [0.0; 9],
                params: [0.066, 0.066, 0.26],
                params_covariance: [0.0; 9],
                window,
            };
            // The window as the robot keeps it: `n` samples.
            let mut h = h;
            h.window.truncate(n);
            let bytes = encode(&Stamper::new("rover").stamp(Body::Handback(Box::new(h)), 0));
            assert!(
                decode(&bytes).is_ok(),
                "{beams} beams: {} bytes",
                bytes.len()
            );
        }
    }
}
