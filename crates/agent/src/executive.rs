//! The robot's executive: runs an accepted plan on its own, at the control
//! rate, and decides every stop locally.
//!
//! Each tick takes what the robot sensed and gives the wheel commands for
//! the next period. The plan's trajectory is tracked on the robot's own
//! odometry (the tracker `verify-plan` uses on the twin). It stops, with
//! zero wheel speeds from then on:
//! - when the plan is done;
//! - on a bump the plan did not predict;
//! - when reality departs from the twin's prediction: odometry farther
//!   from the plan's pose at that time than `max_deviation_m` (a robot held
//!   back by something the twin lacks), or range readings whose absolute
//!   difference from the plan's predicted ones has a median over the last
//!   `residual_window` ticks above `max_range_residual_m` (a wall or box
//!   where the twin saw none; the median lets a reading that jumps at a
//!   wall's edge a tick early pass). These are hand-backs: control returns to the
//!   operator;
//! - when a supervised plan has heard nothing from the master for longer
//!   than its dead-man timeout.
//!
//! None of these waits for a message: the link is never in the loop.

use std::collections::VecDeque;
use std::sync::Arc;

use serde::Serialize;
use twindrive_kinematics::Pose;
use twindrive_mission::PipelineError;
use twindrive_mission::plan::MissionPlan;
use twindrive_mission::verify::{Tracker, TrackerSettings};

use crate::backend::Reading;
pub use twindrive_link::envelope::Tolerances;

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
    /// Nothing heard from the master for this long.
    DeadMan { silent_s: f64 },
    /// Hand-back: the robot lost a sensor it steers by (a silent
    /// `/joint_states`); the backend has already stopped the wheels.
    SensorFault { what: String },
}

/// The reasons (as [`Stop::reason`] names them) that hand control back.
pub const HANDBACK_REASONS: [&str; 4] = [
    "unexpected_bump",
    "deviation",
    "range_residual",
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
            Stop::DeadMan { .. } => "dead_man",
            Stop::SensorFault { .. } => "sensor_fault",
        }
    }
}

/// One plan being driven.
pub struct Executive {
    plan: Arc<MissionPlan>,
    tracker: Tracker,
    tolerances: Tolerances,
    dead_man_timeout_s: Option<f64>,
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
        Ok(Self {
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

    /// Odometry's pose estimate.
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

    /// What the robot sensed over the last period in; the wheel commands for
    /// the next one out.
    pub fn tick(&mut self, reading: &Reading) -> [f64; 2] {
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
            .command(&self.plan.samples, t, reading.encoder_ticks);
        if let Some(stop) = self.check(reading, t) {
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

    fn check(&mut self, reading: &Reading, t: f64) -> Option<Stop> {
        // A bump is expected when the plan predicts one within
        // `range_match_s` of now (contact starts and ends a little early or
        // late on a real robot).
        let now = t + self.plan.samples[0].t_s;
        let m = self.tolerances.range_match_s;
        let lo = self.plan.samples.partition_point(|s| s.t_s < now - m);
        let hi = self.plan.samples.partition_point(|s| s.t_s <= now + m);
        let k = self.tracker.progress().min(self.plan.samples.len() - 1);
        let predicted = self.plan.samples[k].expected_bump
            || self.plan.samples[lo..hi.max(lo)]
                .iter()
                .any(|s| s.expected_bump);
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
        // Where the plan is at this time, against where odometry says the
        // robot is.
        let reference = self.tracker.reference();
        let estimate = self.tracker.estimate();
        let deviation_m = (reference.x_m - estimate.x_m).hypot(reference.y_m - estimate.y_m);
        if deviation_m > self.tolerances.max_deviation_m {
            return Some(Stop::Deviation { deviation_m });
        }
        // Predicted against measured ranges: the best match among the plan's
        // samples within `range_match_s` of now (a reading that flips at a
        // wall's edge a little early or late is explained by a neighbour; a
        // box the twin lacks is explained by none).
        let lo = self
            .plan
            .samples
            .partition_point(|s| s.t_s < now - self.tolerances.range_match_s);
        let hi = self
            .plan
            .samples
            .partition_point(|s| s.t_s <= now + self.tolerances.range_match_s);
        let mut best: Option<f64> = None;
        for s in &self.plan.samples[lo..hi.max(lo)] {
            let (mut sum, mut count) = (0.0, 0usize);
            for (m, e) in reading.ranges_m.iter().zip(&s.expected_ranges_m) {
                if m.is_finite() && e.is_finite() {
                    sum += (m - e).abs();
                    count += 1;
                }
            }
            if count > 0 {
                let r = sum / count as f64;
                best = Some(best.map_or(r, |b: f64| b.min(r)));
            }
        }
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
}
