//! The robot's executive: runs an accepted plan on its own, at the control
//! rate, and decides every stop locally.
//!
//! Each tick takes what the robot sensed and where it believes it is (its
//! filter's estimate: odometry fused with localization against the plan's
//! map, in the site's frame) and gives the wheel commands for the next
//! period. The plan's trajectory is tracked from that estimate (the
//! tracker `verify-plan` uses on the twin). It stops, with zero wheel
//! speeds from then on:
//! - when the plan is done;
//! - on a bump the plan did not predict;
//! - when reality departs from the twin's prediction: the estimate farther
//!   from the plan's pose at that time than `max_deviation_m` (a robot held
//!   back by something the twin lacks), or range readings whose mean
//!   absolute difference from what the map predicts has a median over the
//!   last `residual_window` ticks above `max_range_residual_m` (a wall or
//!   box where the twin saw none; the median lets a reading that jumps at
//!   a wall's edge a tick early pass). The prediction is the robot's own,
//!   from the map the plan carries, bit for bit the twin's, and the best of
//!   several counts: at the estimate and at poses within its uncertainty
//!   (when the robot localizes; a beam that skims a wall's end flips on a
//!   millimetre), and at the plan's poses within `range_match_s` of now. A
//!   localized robot's residual means the world changed, not that the
//!   robot is lost. A reading that ends past a block the twin learnt but
//!   not past what stands behind it is no departure: the twin guesses a
//!   block's extent from a contact, and a smaller obstacle endangers
//!   nothing;
//! - on an obstacle on the path ahead: a range reading well shorter than
//!   anything the map explains (at every pose the residual tries, by more
//!   than the estimate's uncertainty could make it) whose end lies in the
//!   corridor the plan sweeps over its next metre, in several fresh
//!   readings of that sensor in a row. The mean residual over a lidar's
//!   beams barely moves for a box in a few of them; this stops the robot
//!   before it touches what its sensors could see.
//!   These (bump, deviation, residual, obstacle ahead) are hand-backs:
//!   control returns to the operator;
//! - when a supervised plan has heard nothing from the master for longer
//!   than its dead-man timeout.
//!
//! None of these waits for a message: the link is never in the loop.

use std::collections::VecDeque;
use std::sync::Arc;

use serde::Serialize;
use twindrive_kinematics::Pose;
use twindrive_mission::PipelineError;
use twindrive_mission::plan::{MissionPlan, PlanGeometry};
use twindrive_mission::verify::{Criteria, Tracker, TrackerSettings};
use twindrive_sim::RangeModel;

use crate::backend::Reading;
use crate::localize::{Beam, beams};
pub use twindrive_link::envelope::Tolerances;

/// What a plan must meet on the twin before it is sent to a robot that
/// hands back on `tolerances`.
pub fn criteria(tolerances: &Tolerances) -> Criteria {
    Criteria {
        max_deviation_m: tolerances.max_deviation_m,
    }
}

/// Why the robot stopped.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "reason", rename_all = "snake_case")]
pub enum Stop {
    /// The plan ran to its end.
    Finished,
    /// Hand-back: a bump the plan did not predict.
    UnexpectedBump,
    /// Hand-back: odometry this far from where the plan is at this time.
    Deviation { deviation_m: f64 },
    /// Hand-back: range readings this far (the median over the window)
    /// from the predicted.
    RangeResidual { median_residual_m: f64 },
    /// Hand-back: something the map lacks on the plan's path ahead, seen
    /// this far off, its end at (`x_m`, `y_m`) in the site's frame.
    ObstacleAhead { range_m: f64, x_m: f64, y_m: f64 },
    /// Nothing heard from the master for this long.
    DeadMan { silent_s: f64 },
    /// Hand-back: the robot lost a sensor it steers by (a silent
    /// `/joint_states`); the backend has already stopped the wheels.
    SensorFault { what: String },
}

/// The reasons (as [`Stop::reason`] names them) that hand control back.
pub const HANDBACK_REASONS: [&str; 5] = [
    "unexpected_bump",
    "deviation",
    "range_residual",
    "obstacle_ahead",
    "sensor_fault",
];

impl Stop {
    /// Whether control goes back to the operator (reality departed from
    /// the twin, or the robot lost a sensor it steers by).
    pub fn is_handback(&self) -> bool {
        HANDBACK_REASONS.contains(&self.reason())
    }

    /// The reason's name on the wire and in journals.
    pub fn reason(&self) -> &'static str {
        match self {
            Stop::Finished => "finished",
            Stop::UnexpectedBump => "unexpected_bump",
            Stop::Deviation { .. } => "deviation",
            Stop::RangeResidual { .. } => "range_residual",
            Stop::ObstacleAhead { .. } => "obstacle_ahead",
            Stop::DeadMan { .. } => "dead_man",
            Stop::SensorFault { .. } => "sensor_fault",
        }
    }
}

/// Where the robot believes it is, for one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Belief {
    /// The pose to steer by, in the site's frame.
    pub pose: Pose,
    /// Its standard deviations (x, y m; heading rad).
    pub pose_std: [f64; 3],
    /// Whether the pose comes from localization against the plan's map
    /// (else from odometry alone).
    pub localizing: bool,
}

/// One plan being driven.
pub struct Executive {
    plan: Arc<MissionPlan>,
    tracker: Tracker,
    tolerances: Tolerances,
    dead_man_timeout_s: Option<f64>,
    /// What the robot's range sensors should read, from the plan's map.
    model: RangeModel,
    predicted: Vec<f64>,
    /// The map without its learnt blocks, when it has some, and its
    /// predictions.
    behind: Option<RangeModel>,
    predicted_behind: Vec<f64>,
    /// The shortest prediction of each beam over the poses tried.
    nearest: Vec<f64>,
    /// The robot's beams, for where a reading ends.
    beams: Vec<Beam>,
    /// Per sensor, its fresh readings in a row that saw something on the
    /// path ahead.
    ahead_count: Vec<usize>,
    /// The residual of the latest fresh readings (repeated until the next).
    last_residual: Option<f64>,
    /// Time of the first tick (the plan's time zero).
    t0_s: Option<f64>,
    last_heard_s: f64,
    residuals: VecDeque<f64>,
    last_median: Option<f64>,
    stopped: Option<(f64, Stop)>,
}

impl Executive {
    /// Ready to drive `plan` from its first pose.
    pub fn new(
        plan: Arc<MissionPlan>,
        tolerances: Tolerances,
        dead_man_timeout_s: Option<f64>,
        max_wheel_rad_s: f64,
    ) -> Result<Self, PipelineError> {
        let tracker = Tracker::new(
            &plan.samples,
            &plan.header.calibrated,
            &TrackerSettings::default(),
            plan.header.robot.ticks_per_rev,
            max_wheel_rad_s.min(plan.header.limits.max_speed_rad_s),
        )?;
        let model = plan.range_model();
        let behind = plan.range_model_without_boxes();
        Ok(Self {
            predicted: vec![0.0; model.beams()],
            nearest: vec![0.0; model.beams()],
            beams: beams(&plan.header.robot.range_sensors),
            ahead_count: vec![0; plan.header.robot.range_sensors.len()],
            predicted_behind: vec![0.0; behind.as_ref().map_or(0, |m| m.beams())],
            behind,
            model,
            last_residual: None,
            plan,
            tracker,
            tolerances,
            dead_man_timeout_s,
            t0_s: None,
            last_heard_s: f64::NEG_INFINITY,
            residuals: VecDeque::new(),
            last_median: None,
            stopped: None,
        })
    }

    /// A message from the master arrived at `t_s` (the backend's clock).
    pub fn heard_from_master(&mut self, t_s: f64) {
        self.last_heard_s = self.last_heard_s.max(t_s);
    }

    /// Why and when the robot stopped, once it has.
    pub fn stopped(&self) -> Option<&(f64, Stop)> {
        self.stopped.as_ref()
    }

    /// The pose the plan was last tracked from.
    pub fn estimate(&self) -> Pose {
        self.tracker.estimate()
    }

    /// Plan samples passed.
    pub fn progress(&self) -> usize {
        self.tracker.progress()
    }

    pub fn plan(&self) -> &Arc<MissionPlan> {
        &self.plan
    }

    /// The plan's pose now.
    pub fn reference(&self) -> Pose {
        self.tracker.reference()
    }

    /// The latest median range residual (m), once the window is full.
    pub fn range_residual_m(&self) -> Option<f64> {
        self.last_median
    }

    /// What the robot sensed at the start of this period and where it
    /// believes it is now in; the wheel commands for this period out (zero
    /// from the period that decides a stop on).
    pub fn tick(&mut self, reading: &Reading, belief: &Belief) -> [f64; 2] {
        if self.stopped.is_some() {
            return [0.0, 0.0];
        }
        let t0 = *self.t0_s.get_or_insert(reading.t_s);
        if self.last_heard_s == f64::NEG_INFINITY {
            // Supervision starts with the plan.
            self.last_heard_s = reading.t_s;
        }
        let t = reading.t_s - t0;
        let command = self
            .tracker
            .command_from(&self.plan.samples, t, belief.pose);
        if let Some(stop) = self.check(reading, t, belief) {
            self.stopped = Some((reading.t_s, stop));
            return [0.0, 0.0];
        }
        match command {
            Some(wheels) => wheels,
            None => {
                self.stopped = Some((reading.t_s, Stop::Finished));
                [0.0, 0.0]
            }
        }
    }

    fn check(&mut self, reading: &Reading, t: f64, belief: &Belief) -> Option<Stop> {
        // The plan's samples within `range_match_s` of now. A bump is
        // expected when the plan predicts one among them (contact starts and
        // ends a little early or late on a real robot).
        let now = t + self.plan.samples[0].t_s;
        let m = self.tolerances.range_match_s;
        let lo = self.plan.samples.partition_point(|s| s.t_s < now - m);
        let hi = self.plan.samples.partition_point(|s| s.t_s <= now + m);
        let near = &self.plan.samples[lo..hi.max(lo)];
        let k = self.tracker.progress().min(self.plan.samples.len() - 1);
        let predicted = self.plan.samples[k].expected_bump || near.iter().any(|s| s.expected_bump);
        if let Some(what) = &reading.fault {
            return Some(Stop::SensorFault { what: what.clone() });
        }
        if reading.bump && !predicted {
            return Some(Stop::UnexpectedBump);
        }
        if let Some(timeout) = self.dead_man_timeout_s {
            let silent = reading.t_s - self.last_heard_s;
            if silent > timeout {
                return Some(Stop::DeadMan { silent_s: silent });
            }
        }
        // Where the plan is at this time, against where the robot believes
        // it is.
        let reference = self.tracker.reference();
        let estimate = belief.pose;
        let deviation_m = (reference.x_m - estimate.x_m).hypot(reference.y_m - estimate.y_m);
        if deviation_m > self.tolerances.max_deviation_m {
            return Some(Stop::Deviation { deviation_m });
        }
        // Measured against predicted ranges, on fresh readings; the latest
        // stands until the next. A beam that skims a wall's end flips
        // between the wall and the distance on a millimetre of pose: the
        // best of the predictions at the estimate and at poses a little off
        // it (within the estimate's uncertainty, at least 1 cm and 0.01 rad,
        // at most 3 cm and 0.03 rad) counts, when the robot localizes.
        if reading.fresh_ranges_m.iter().any(|r| r.is_finite()) {
            let std = belief.pose_std;
            let d = [
                (2.0 * std[0].max(std[1])).clamp(0.01, 0.03),
                (2.0 * std[2]).clamp(0.01, 0.03),
            ];
            let (s, c) = estimate.heading_rad.sin_cos();
            // And the plan's poses within `range_match_s` of now (every
            // fifth), as when plans carried the twin's predictions: a
            // reading the map explains near the estimate or along the plan
            // is no discrepancy.
            let along_plan = near.iter().step_by(5).map(|s| s.pose());
            let near_estimate = [
                (0.0, 0.0, 0.0),
                (d[0] * c, d[0] * s, 0.0),
                (-d[0] * c, -d[0] * s, 0.0),
                (-d[0] * s, d[0] * c, 0.0),
                (d[0] * s, -d[0] * c, 0.0),
                (0.0, 0.0, d[1]),
                (0.0, 0.0, -d[1]),
            ]
            .into_iter()
            .filter(|_| belief.localizing)
            .map(|(dx, dy, dh)| {
                Pose::new(
                    estimate.x_m + dx,
                    estimate.y_m + dy,
                    estimate.heading_rad + dh,
                )
            });
            let mut best: Option<f64> = None;
            self.nearest.fill(f64::INFINITY);
            for pose in near_estimate.chain(along_plan) {
                self.model.read(&pose, &mut self.predicted);
                for (n, e) in self.nearest.iter_mut().zip(&self.predicted) {
                    *n = n.min(*e);
                }
                if let Some(behind) = &mut self.behind {
                    behind.read(&pose, &mut self.predicted_behind);
                }
                let (mut sum, mut count) = (0.0, 0usize);
                for (i, (m, e)) in reading
                    .fresh_ranges_m
                    .iter()
                    .zip(&self.predicted)
                    .enumerate()
                {
                    if m.is_finite() && e.is_finite() {
                        // A reading past a learnt block's face, but not past
                        // what stands behind it, says the block is smaller
                        // than the twin guessed: no departure.
                        let far = self.predicted_behind.get(i).copied().unwrap_or(*e);
                        sum += if *m > *e {
                            (m - far).max(0.0).min(m - e)
                        } else {
                            e - m
                        };
                        count += 1;
                    }
                }
                if count > 0 {
                    let r = sum / count as f64;
                    best = Some(best.map_or(r, |b: f64| b.min(r)));
                }
            }
            if best.is_some() {
                self.last_residual = best;
            }
            if let Some(seen) = self.ahead(reading, belief, k) {
                return Some(seen);
            }
        }
        let best = self.last_residual;
        if let Some(residual) = best {
            self.residuals.push_back(residual);
            if self.residuals.len() > self.tolerances.residual_window {
                self.residuals.pop_front();
            }
            if self.residuals.len() == self.tolerances.residual_window {
                // The median: a range that jumps at a wall's edge a tick
                // before or after the twin said is no discrepancy; a
                // wall where the twin saw none stays.
                let mut sorted: Vec<f64> = self.residuals.iter().copied().collect();
                sorted.sort_by(f64::total_cmp);
                let median = sorted[sorted.len() / 2];
                self.last_median = Some(median);
                if median > self.tolerances.max_range_residual_m {
                    return Some(Stop::RangeResidual {
                        median_residual_m: median,
                    });
                }
            }
        }
        None
    }

    /// An obstacle on the path ahead: a sensor whose last
    /// `obstacle_confirm` fresh readings each had a reading well shorter
    /// than anything the map explains (`self.nearest`, over the poses the
    /// residual tried) ending in the corridor the plan sweeps from sample
    /// `k` over its next `obstacle_ahead_m`. The nearest such reading is
    /// reported.
    fn ahead(&mut self, reading: &Reading, belief: &Belief, k: usize) -> Option<Stop> {
        let tol = &self.tolerances;
        let estimate = &belief.pose;
        // Shorter than the map explains by more than the estimate's
        // uncertainty could make it (three standard deviations of the
        // position, and of the heading at the reading's range).
        let [sx, sy, sh] = belief.pose_std;
        let position_3std = 3.0 * sx.max(sy);
        let reach = self.plan.header.robot.footprint_radius_m + tol.obstacle_margin_m;
        // The plan's samples over its next `obstacle_ahead_m`, found when a
        // reading first needs them.
        let samples = &self.plan.samples[k..];
        let mut corridor: Option<&[_]> = None;
        let mut in_corridor = |x_m: f64, y_m: f64| {
            let corridor = corridor.get_or_insert_with(|| {
                let mut travel_m = 0.0;
                let ahead = samples
                    .windows(2)
                    .take_while(|w| {
                        travel_m += (w[1].x_m - w[0].x_m).hypot(w[1].y_m - w[0].y_m);
                        travel_m <= tol.obstacle_ahead_m
                    })
                    .count();
                &samples[..=ahead]
            });
            corridor
                .iter()
                .any(|p| (p.x_m - x_m).hypot(p.y_m - y_m) < reach)
        };
        let mut nearest: Option<Stop> = None;
        let mut confirmed = false;
        // Sensor by sensor (a sensor's beams come together).
        let mut first = 0;
        for beams in self.beams.chunk_by(|a, b| a.sensor == b.sensor) {
            let these = first..first + beams.len();
            first = these.end;
            // A reading with fewer ranges than beams has none of the rest.
            let (Some(ranges), Some(nearest_predicted)) = (
                reading.fresh_ranges_m.get(these.clone()),
                self.nearest.get(these),
            ) else {
                break;
            };
            let mut fresh = false;
            let mut seen = false;
            for ((m, n), beam) in ranges.iter().zip(nearest_predicted).zip(beams) {
                if !m.is_finite() {
                    continue;
                }
                fresh = true;
                let shorter_by = tol.obstacle_shorter_by_m.max(position_3std + 3.0 * sh * m);
                if *m <= beam.min_m || *m >= beam.max_m || *m > n - shorter_by {
                    continue;
                }
                let (bx, by) = beam.endpoint(*m);
                let (x_m, y_m) = estimate.transform_point(bx, by);
                if in_corridor(x_m, y_m) {
                    seen = true;
                    if !matches!(nearest, Some(Stop::ObstacleAhead { range_m, .. }) if range_m <= *m)
                    {
                        nearest = Some(Stop::ObstacleAhead {
                            range_m: *m,
                            x_m,
                            y_m,
                        });
                    }
                }
            }
            let count = &mut self.ahead_count[beams[0].sensor];
            if fresh {
                *count = if seen { *count + 1 } else { 0 };
            }
            confirmed |= *count >= tol.obstacle_confirm;
        }
        if confirmed { nearest } else { None }
    }
}
