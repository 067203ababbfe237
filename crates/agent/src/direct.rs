//! Direct tele-operation over a delayed link: the baseline decoupled
//! operation is measured against.
//!
//! The operator's controller runs at the master on the sensor data the link
//! brings it, and its wheel commands reach the robot over the same link.
//! Three ways an operator really drives over delay:
//! - [`DirectMethod::HoldLast`]: a continuous stream both ways; the robot
//!   holds the last command it received;
//! - [`DirectMethod::Watchdog`]: the same, with the robot zeroing its wheels
//!   when no command arrived within a timeout (the usual safety net);
//! - [`DirectMethod::MoveAndWait`]: Ferrell's move-and-wait (1965): the
//!   operator commands one short move, the robot makes it and stops, and the
//!   operator waits for the feedback of that move before the next one.
//!
//! Messages are sized by their real encoding (postcard, with the header
//! every twindrive message carries) and go through the project's
//! [`LinkEmulator`], one per direction, in virtual time: the robot steps at
//! the site's period, so each arrival is seen at the first step at or after
//! it (at most one step late).

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use serde::Serialize;
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_link::emulator::{LinkEmulator, LinkStats};
use twindrive_link::wire::PROTOCOL_VERSION;
use twindrive_sim::controller::{Controller, Observation};
use twindrive_sim::{Contacts, ControllerConfig, Scenario, Sensed, Simulator, StepOutput};

/// How the operator drives.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DirectMethod {
    /// The robot holds the last command it received.
    HoldLast,
    /// The robot zeroes its wheels when no command arrived for `timeout_s`.
    Watchdog { timeout_s: f64 },
    /// One move of `move_s` at a time, each after the feedback of the last.
    MoveAndWait { move_s: f64 },
}

/// A direct run.
#[derive(Debug, Clone)]
pub struct DirectConfig {
    pub method: DirectMethod,
    /// The operator's control period, and the robot's sensor stream period
    /// (s).
    pub control_period_s: f64,
    /// Give up after this long (s).
    pub max_duration_s: f64,
    pub robot_id: String,
}

/// What a direct run did.
#[derive(Debug, Clone, Default)]
pub struct DirectRun {
    /// The robot's true pose at each step.
    pub path: Vec<(f64, Pose)>,
    /// When `done` first said so (robot time, s).
    pub done_at_s: Option<f64>,
    /// Robot time at the end of the run (s).
    pub end_s: f64,
    /// Bumper presses (rising edges).
    pub bumps: u32,
    /// Periods of contact that stopped the robot (rising edges).
    pub collisions: u32,
    /// Time spent stopped by contact (s).
    pub contact_s: f64,
    /// Master → robot.
    pub up: LinkStats,
    /// Robot → master.
    pub down: LinkStats,
    /// Moves made (move-and-wait) or commands applied (streams).
    pub commands_applied: u64,
}

/// The robot's sensor report, as it goes over the link.
#[derive(Debug, Clone, Serialize)]
struct Frame<'a> {
    version: u16,
    robot_id: &'a str,
    seq: u64,
    t_ns: u64,
    /// The move this frame closes (move-and-wait), 0 otherwise.
    move_id: u64,
    bump: bool,
    encoder_ticks: Option<[i64; 2]>,
    ranges_m: Vec<f32>,
}

/// The operator's command, as it goes over the link.
#[derive(Debug, Clone, Serialize)]
struct Command<'a> {
    version: u16,
    robot_id: &'a str,
    seq: u64,
    t_ns: u64,
    /// Move-and-wait: the move's id and duration (s); 0 for a stream.
    move_id: u64,
    move_s: f32,
    wheels_rad_s: [f32; 2],
}

fn encoded_len(value: &impl Serialize) -> usize {
    postcard::to_allocvec(value)
        .expect("plain structs serialise")
        .len()
}

/// What the master holds of a frame.
#[derive(Debug, Clone)]
struct Seen {
    seq: u64,
    move_id: u64,
    bump: bool,
    ranges_m: Vec<f64>,
}

/// A command as the robot receives it.
#[derive(Debug, Clone, Copy)]
struct Order {
    seq: u64,
    move_id: u64,
    move_s: f64,
    wheels: [f64; 2],
}

/// Messages in flight one way: (arrival, order of sending) → payload.
struct Flight<T> {
    heap: BinaryHeap<Reverse<(u64, u64)>>,
    payloads: std::collections::HashMap<u64, T>,
    order: u64,
}

impl<T> Flight<T> {
    fn new() -> Self {
        Self {
            heap: BinaryHeap::new(),
            payloads: Default::default(),
            order: 0,
        }
    }

    fn send(&mut self, link: &mut LinkEmulator, now_ns: u64, bytes: usize, payload: T) {
        if let Some(at) = link.send(now_ns, bytes) {
            self.order += 1;
            self.heap.push(Reverse((at, self.order)));
            self.payloads.insert(self.order, payload);
        }
    }

    fn arrived(&mut self, now_ns: u64) -> Option<T> {
        if self
            .heap
            .peek()
            .is_some_and(|Reverse((at, _))| *at <= now_ns)
        {
            let Reverse((_, order)) = self.heap.pop().expect("peeked");
            return self.payloads.remove(&order);
        }
        None
    }
}

/// Runs the site under direct tele-operation by `controller` (the
/// operator's, with the operator's `nominal` parameters) until `done` says
/// so after a step (given the robot time and its true pose) or the time is
/// up.
pub fn run(
    site: &Scenario,
    controller: &ControllerConfig,
    nominal: &DiffDriveParams,
    up: LinkEmulator,
    down: LinkEmulator,
    config: &DirectConfig,
    mut done: impl FnMut(f64, &Pose) -> bool,
) -> Result<DirectRun, String> {
    let mut site = site.clone();
    site.set_duration_s(config.max_duration_s)
        .map_err(|e| format!("max_duration_s: {e}"))?;
    let dt_ns = site.dt_ns;
    let period_ns = ((config.control_period_s * 1e9).round() as u64).max(dt_ns);
    let latency_s = up.profile().latency_s + up.profile().jitter_s;
    let mut sim = Simulator::new(site);
    let mut out = StepOutput::new(sim.beams());
    let mut operator = Controller::new(controller);
    let (mut up, mut down) = (up, down);
    let mut to_robot: Flight<Order> = Flight::new();
    let mut to_master: Flight<Seen> = Flight::new();
    let id = config.robot_id.as_str();

    // The robot's side.
    let mut applied: Option<Order> = None;
    let mut applied_at_ns = 0u64;
    let mut move_until_ns: Option<u64> = None;
    let mut last_move_done = 0u64;
    let mut frame_seq = 0u64;
    let mut feedback_due: Option<u64> = Some(0);
    let mut feedback_sent_ns = 0u64;
    // The master's side.
    let mut latest: Option<Seen> = None;
    let mut command_seq = 0u64;
    let mut awaiting: Option<(u64, u64, Order)> = None;
    let mut motion_ns = 0u64;
    let resend_ns = |move_s: f64| ((2.0 * latency_s + move_s + 0.5) * 1e9) as u64;

    let mut run = DirectRun::default();
    let mut contacts = Contacts::default();
    let mut sensed_bump = false;
    let mut sensed_ticks = None;
    let mut sensed_ranges: Vec<f64> = Vec::new();
    let mut step = 0u64;
    loop {
        let now = step * dt_ns;
        // The robot takes in what arrived.
        while let Some(order) = to_robot.arrived(now) {
            match config.method {
                DirectMethod::MoveAndWait { .. } => {
                    if order.move_id <= last_move_done {
                        // A repeat of a move made: its feedback was lost.
                        if order.move_id == last_move_done {
                            feedback_due = Some(last_move_done);
                        }
                    } else if move_until_ns.is_none() {
                        applied = Some(order);
                        move_until_ns = Some(now + (order.move_s * 1e9).round() as u64);
                        run.commands_applied += 1;
                    }
                }
                _ => {
                    if applied.is_none_or(|a| order.seq > a.seq) {
                        applied = Some(order);
                        applied_at_ns = now;
                        run.commands_applied += 1;
                    }
                }
            }
        }
        // The wheels for this step.
        let wheels = match (config.method, applied) {
            (_, None) => [0.0, 0.0],
            (DirectMethod::HoldLast, Some(a)) => a.wheels,
            (DirectMethod::Watchdog { timeout_s }, Some(a)) => {
                if now.saturating_sub(applied_at_ns) as f64 * 1e-9 > timeout_s {
                    [0.0, 0.0]
                } else {
                    a.wheels
                }
            }
            (DirectMethod::MoveAndWait { .. }, Some(a)) => match move_until_ns {
                Some(until) if now < until => a.wheels,
                Some(_) => {
                    move_until_ns = None;
                    last_move_done = a.move_id;
                    feedback_due = Some(a.move_id);
                    [0.0, 0.0]
                }
                None => [0.0, 0.0],
            },
        };
        let stepped = sim.step_with(&mut out, &mut |s: &Sensed| {
            sensed_bump = s.bump;
            sensed_ticks = s.encoder_ticks.or(sensed_ticks);
            sensed_ranges.clear();
            sensed_ranges.extend_from_slice(s.latest_range_m);
            wheels
        });
        if !stepped {
            break;
        }
        let t_s = now as f64 * 1e-9;
        let r = &out.record;
        run.path.push((t_s, r.ground_truth));
        contacts.record(r.bump, out.blocked, dt_ns as f64 * 1e-9);

        // The robot reports what it sensed at the start of this step.
        let stream = !matches!(config.method, DirectMethod::MoveAndWait { .. });
        let report = if stream {
            now.is_multiple_of(period_ns).then_some(0)
        } else {
            if let DirectMethod::MoveAndWait { move_s } = config.method
                && last_move_done == 0
                && applied.is_none()
                && now >= feedback_sent_ns + resend_ns(move_s)
            {
                // Nothing came of the first report: it may have been lost.
                feedback_due = Some(0);
            }
            feedback_due.take()
        };
        if let Some(move_id) = report {
            frame_seq += 1;
            feedback_sent_ns = now;
            let frame = Frame {
                version: PROTOCOL_VERSION,
                robot_id: id,
                seq: frame_seq,
                t_ns: now,
                move_id,
                bump: sensed_bump,
                encoder_ticks: sensed_ticks,
                ranges_m: sensed_ranges.iter().map(|&r| r as f32).collect(),
            };
            let bytes = encoded_len(&frame);
            to_master.send(
                &mut down,
                now,
                bytes,
                Seen {
                    seq: frame_seq,
                    move_id,
                    bump: sensed_bump,
                    ranges_m: sensed_ranges.clone(),
                },
            );
        }

        // The master.
        let mut fresh_feedback = None;
        while let Some(seen) = to_master.arrived(now) {
            if !stream && awaiting.is_some_and(|(m, _, _)| m == seen.move_id) {
                fresh_feedback = Some(seen.clone());
            }
            if !stream && seen.move_id == 0 && command_seq == 0 {
                fresh_feedback = Some(seen.clone());
            }
            if latest.as_ref().is_none_or(|l| seen.seq > l.seq) {
                latest = Some(seen);
            }
        }
        let send = |order: Order, up: &mut LinkEmulator, to_robot: &mut Flight<Order>| {
            let command = Command {
                version: PROTOCOL_VERSION,
                robot_id: id,
                seq: order.seq,
                t_ns: now,
                move_id: order.move_id,
                move_s: order.move_s as f32,
                wheels_rad_s: order.wheels.map(|w| w as f32),
            };
            to_robot.send(up, now, encoded_len(&command), order);
        };
        match config.method {
            DirectMethod::HoldLast | DirectMethod::Watchdog { .. } => {
                if now.is_multiple_of(period_ns)
                    && let Some(seen) = &latest
                {
                    let obs = Observation {
                        t_ns: now,
                        bump: seen.bump,
                        latest_range_m: &seen.ranges_m,
                    };
                    command_seq += 1;
                    let order = Order {
                        seq: command_seq,
                        move_id: 0,
                        move_s: 0.0,
                        wheels: operator.command(&obs, nominal),
                    };
                    send(order, &mut up, &mut to_robot);
                }
            }
            DirectMethod::MoveAndWait { move_s } => {
                if let Some(seen) = fresh_feedback {
                    // The move's result is in: plan the next one on it, on
                    // the clock of motion (the controller's timers count
                    // the robot's moving time).
                    let obs = Observation {
                        t_ns: motion_ns,
                        bump: seen.bump,
                        latest_range_m: &seen.ranges_m,
                    };
                    command_seq += 1;
                    let order = Order {
                        seq: command_seq,
                        move_id: command_seq,
                        move_s,
                        wheels: operator.command(&obs, nominal),
                    };
                    motion_ns += (move_s * 1e9).round() as u64;
                    awaiting = Some((order.move_id, now, order));
                    send(order, &mut up, &mut to_robot);
                } else if let Some((m, sent, order)) = awaiting
                    && now >= sent + resend_ns(move_s)
                {
                    // No feedback: the move or its feedback was lost.
                    awaiting = Some((m, now, order));
                    send(order, &mut up, &mut to_robot);
                }
            }
        }

        step += 1;
        run.end_s = step as f64 * dt_ns as f64 * 1e-9;
        if done(run.end_s, &sim.pose()) {
            run.done_at_s = Some(run.end_s);
            break;
        }
    }
    (run.bumps, run.collisions, run.contact_s) =
        (contacts.bumps, contacts.collisions, contacts.contact_s);
    run.up = up.stats;
    run.down = down.stats;
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;
    use twindrive_link::emulator::LinkProfile;

    fn case_study() -> Scenario {
        twindrive_sim::builtin::load("wall_following")
            .expect("built in")
            .expect("valid")
    }

    fn drive(method: DirectMethod, latency_s: f64, seconds: f64) -> DirectRun {
        let site = case_study();
        let profile: LinkProfile = format!("latency_s={latency_s}").parse().unwrap();
        run(
            &site,
            &site.controller,
            &site.robot.nominal_params,
            LinkEmulator::new(profile.clone(), 1, 0),
            LinkEmulator::new(profile, 1, 1),
            &DirectConfig {
                method,
                control_period_s: 0.02,
                max_duration_s: seconds,
                robot_id: "rover".into(),
            },
            |_, _| false,
        )
        .unwrap()
    }

    #[test]
    fn without_delay_the_stream_drives_like_the_twin_itself() {
        // The same controller on board (the scenario's own run) and at the
        // master over a link with no delay: the paths agree closely (the
        // master's command is one control period behind).
        let site = case_study();
        let mut own = site.clone();
        own.set_duration_s(20.0).unwrap();
        let log = Simulator::new(own).run(|_, _| {});
        let direct = drive(DirectMethod::HoldLast, 0.0, 20.0);
        let end = log.steps.last().unwrap().ground_truth;
        let (_, last) = direct.path.last().unwrap();
        let gap = (end.x_m - last.x_m).hypot(end.y_m - last.y_m);
        assert!(gap < 0.1, "{gap} m apart after 20 s");
        assert!(direct.commands_applied > 900);
    }

    #[test]
    fn the_robot_holds_still_until_a_command_arrives() {
        let run = drive(DirectMethod::HoldLast, 2.0, 4.5);
        // Sensor data reaches the master at 2 s, the first command the
        // robot at 4 s: before that the wheels are still.
        let start = run.path[0].1;
        for (t, p) in &run.path {
            if *t < 3.99 {
                assert_eq!((p.x_m, p.y_m), (start.x_m, start.y_m), "moved at {t} s");
            }
        }
        let (_, end) = run.path.last().unwrap();
        assert!((end.x_m - start.x_m).abs() > 0.01, "never moved");
        assert!(run.up.bytes_sent > 0 && run.down.bytes_sent > 0);
    }

    #[test]
    fn move_and_wait_pays_a_round_trip_per_move() {
        let run = drive(DirectMethod::MoveAndWait { move_s: 0.5 }, 1.0, 30.0);
        // Each move takes 0.5 s and its round trip 2 s.
        let moves = run.commands_applied;
        assert!((11..=13).contains(&moves), "{moves} moves in 30 s");
        // Feedback only after each move: far fewer frames than a stream.
        assert!(run.down.messages_sent < 20, "{:?}", run.down);
    }

    #[test]
    fn the_watchdog_stops_the_wheels_in_an_outage() {
        let site = case_study();
        let mut profile: LinkProfile = "latency_s=0.1".parse().unwrap();
        profile.outages.push(twindrive_link::emulator::Outage {
            start_s: 5.0,
            end_s: 15.0,
        });
        let go = |method| {
            run(
                &site,
                &site.controller,
                &site.robot.nominal_params,
                LinkEmulator::new(profile.clone(), 1, 0),
                LinkEmulator::new(profile.clone(), 1, 1),
                &DirectConfig {
                    method,
                    control_period_s: 0.02,
                    max_duration_s: 14.0,
                    robot_id: "rover".into(),
                },
                |_, _| false,
            )
            .unwrap()
        };
        let moved = |r: &DirectRun, from: f64, to: f64| {
            let at = |t: f64| r.path.iter().find(|(s, _)| *s >= t).unwrap().1;
            let (a, b) = (at(from), at(to));
            (a.x_m - b.x_m).hypot(a.y_m - b.y_m)
        };
        let held = go(DirectMethod::HoldLast);
        let watched = go(DirectMethod::Watchdog { timeout_s: 0.5 });
        assert!(moved(&held, 7.0, 13.0) > 0.5, "holding drives on blind");
        assert!(moved(&watched, 7.0, 13.0) < 1e-9, "the watchdog stops");
    }
}
