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
//! **Bounded autonomy.** A robot with a lidar whose plan gives it a
//! corridor wider than its footprint (and three standard deviations of its
//! position) does not hand back on an obstacle ahead: it goes around it
//! ([`crate::local_planner`]: its own occupancy grid of the plan's map and
//! fresh scans, inside the corridor, out of the keep-out zones, the
//! footprint clear by three standard deviations of its position), at a
//! speed that falls near obstacles, replanning at every scan, and rejoins
//! the plan past the obstacle, the plan's clock moved on by the time the
//! detour took. On a detour it hands back when no way exists
//! ([`Stop::Blocked`]), when the way would add more time or distance than
//! the plan's freedom allows ([`Stop::DetourBound`]), on any unexpected
//! bump, when its estimate leaves the corridor ([`Stop::LeftCorridor`]),
//! or on a sensor fault or the dead man. After it, range readings that end
//! on what it saw are explained (the twin learns it from the detour
//! event). A robot with rangers alone cannot see ahead and behaves as
//! before.
//!
//! None of these waits for a message: the link is never in the loop.

use std::collections::VecDeque;
use std::sync::Arc;

use serde::Serialize;
use twindrive_kinematics::Pose;
use twindrive_mission::PipelineError;
use twindrive_mission::plan::{MissionPlan, PlanGeometry};
use twindrive_mission::verify::{Criteria, Tracker, TrackerSettings, capped_wheel_speeds};
use twindrive_sim::RangeModel;

use crate::backend::Reading;
use crate::local_planner::{Detour, LocalPlanner, LocalPlannerSettings, NoWay};
use crate::localize::{Beam, beams};
use twindrive_estimation::mapping::{CellState, LogOddsGrid};
use twindrive_kinematics::wrap_angle;
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
    /// Hand-back: something the map lacks blocks the plan, and no way
    /// around it exists inside the corridor and out of the keep-out zones
    /// (`why`); it was last seen ending at (`x_m`, `y_m`).
    Blocked { why: String, x_m: f64, y_m: f64 },
    /// Hand-back: the way around would cost more than the operator
    /// allowed (`why`: which bound, by how much).
    DetourBound { why: String },
    /// Hand-back: on a detour the robot's estimate left its corridor, at
    /// (`x_m`, `y_m`).
    LeftCorridor { x_m: f64, y_m: f64 },
}

/// The reasons (as [`Stop::reason`] names them) that hand control back.
pub const HANDBACK_REASONS: [&str; 8] = [
    "unexpected_bump",
    "deviation",
    "range_residual",
    "obstacle_ahead",
    "sensor_fault",
    "blocked",
    "detour_bound",
    "left_corridor",
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
            Stop::Blocked { .. } => "blocked",
            Stop::DetourBound { .. } => "detour_bound",
            Stop::LeftCorridor { .. } => "left_corridor",
        }
    }
}

/// On a detour: a waypoint within this is reached (m), as is one the
/// robot has gone past (beyond the line through it square to the way).
const WAYPOINT_REACHED_M: f64 = 0.05;
/// The detour's last point (on the plan) within this is reached: from
/// there the robot turns to the plan's heading and the tracker takes the
/// rest up (a bearing to a point a few centimetres off swings with every
/// fix, and a robot chasing it circles).
const REJOIN_REACHED_M: f64 = 0.1;
/// Driving to a waypoint, at least this fast (m/s): slower, a real
/// robot's motors may not turn the wheels against friction at all.
const MIN_APPROACH_M_S: f64 = 0.03;
/// The detour ends at the plan's sample nearest the robot within this,
/// along the plan, of the planned rejoin point (m): twice the distance at
/// which that point is reached.
const REJOIN_WINDOW_M: f64 = 2.0 * REJOIN_REACHED_M;
/// Facing the rejoin sample's heading within this, the detour ends (rad).
const ALIGNED_RAD: f64 = 0.05;
/// Heading errors beyond this are turned in place (rad).
const TURN_IN_PLACE_RAD: f64 = 0.4;
const TURN_GAIN_PER_S: f64 = 2.5;
const MAX_TURN_RAD_S: f64 = 1.5;
/// Within this of its clearance limit the robot slows, to this fraction
/// of its detour speed at the limit.
const SLOW_WITHIN_M: f64 = 0.3;
const MIN_SPEED_FRACTION: f64 = 0.3;
/// A detour event carries at most this many points of what it saw, this
/// far apart at least (m).
const MAX_OBSTACLE_POINTS: usize = 200;
const OBSTACLE_POINT_SPACING_M: f64 = 0.05;
/// On a detour, at most this long without a lidar scan (s).
const MAX_DETOUR_SCAN_GAP_S: f64 = 1.0;

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
    /// The robot's beams that belong to a lidar (it can see ahead and
    /// plan around what it sees).
    lidar_beams: Vec<bool>,
    /// The plan's clock runs this far behind the robot's (s): the time the
    /// detours took.
    time_shift_s: f64,
    /// The detour in progress.
    detour: Option<Going>,
    /// What the lidar saw on earlier detours.
    seen: Option<LogOddsGrid>,
    planner_settings: LocalPlannerSettings,
    max_wheel_rad_s: f64,
    events: Vec<Event>,
    /// Arc length of the plan at each sample (m), shared with each
    /// detour's planner.
    along_m: Arc<[f64]>,
    /// Whether the last obstacle ahead was confirmed by a lidar.
    ahead_by_lidar: bool,
}

/// What the executive did that the master hears of (besides stopping).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    /// It saw something the map lacks on the plan ahead and is going
    /// around it: from `from` (x, y, heading), at plan sample `from_sample`,
    /// along `waypoints`, back onto the plan at sample `rejoin`;
    /// `obstacle` the readings that ended on it (x, y in the site's frame).
    Detour {
        t_s: f64,
        plan_t_s: f64,
        from: [f64; 3],
        from_sample: usize,
        rejoin: usize,
        waypoints: Vec<[f64; 2]>,
        length_m: f64,
        obstacle: Vec<[f64; 2]>,
    },
    /// Back on the plan at sample `sample`, `extra_s` later and `extra_m`
    /// further than the plan; `obstacle` what it saw on the way.
    Rejoined {
        t_s: f64,
        sample: usize,
        extra_s: f64,
        extra_m: f64,
        obstacle: Vec<[f64; 2]>,
    },
}

/// A detour being driven.
struct Going {
    planner: LocalPlanner,
    route: Detour,
    /// The waypoint being driven to.
    next: usize,
    from_sample: usize,
    /// The robot's time (since the plan started) and the plan's when it
    /// began.
    started_s: f64,
    plan_t_s: f64,
    driven_m: f64,
    last: Pose,
    /// Speed limit on the detour (m/s).
    max_speed_m_s: f64,
    /// Where readings ended on what the map lacks (x, y), for the twin.
    obstacle: Vec<[f64; 2]>,
    /// The robot's time of the last lidar scan (s).
    last_scan_s: f64,
    /// At the rejoin point, turning to the plan's heading.
    aligning: bool,
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
        let beams = beams(&plan.header.robot.range_sensors);
        // Only a lidar with enough beams to plan with: a sparse fan would
        // leave the grid nearly empty, and unknown cells count as free.
        let lidar_beams = beams
            .iter()
            .map(|b| plan.header.robot.range_sensors[b.sensor].is_scanning_lidar())
            .collect();
        Ok(Self {
            along_m: twindrive_mission::freedom::sample_arc_lengths(&plan.samples).into(),
            ahead_by_lidar: false,
            lidar_beams,
            time_shift_s: 0.0,
            detour: None,
            seen: None,
            planner_settings: LocalPlannerSettings::default(),
            max_wheel_rad_s: max_wheel_rad_s.min(plan.header.limits.max_speed_rad_s),
            events: Vec::new(),
            predicted: vec![0.0; model.beams()],
            nearest: vec![0.0; model.beams()],
            beams,
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

    /// How far the plan's clock is behind the robot's at backend time
    /// `t_s` (s): the time detours took; on a detour the plan's clock
    /// stands where it left the plan. A hand-back's plan time is the
    /// robot's time since the plan started less this.
    pub fn plan_lag_s(&self, t_s: f64) -> f64 {
        match (&self.detour, self.t0_s) {
            (Some(g), Some(t0)) => (t_s - t0) - g.plan_t_s,
            _ => self.time_shift_s,
        }
    }

    /// What happened since the last call (detours begun and ended).
    pub fn take_events(&mut self) -> Vec<Event> {
        std::mem::take(&mut self.events)
    }

    /// Whether a detour is being driven.
    pub fn on_a_detour(&self) -> bool {
        self.detour.is_some()
    }

    /// How the robot plans its detours.
    pub fn set_planner_settings(&mut self, settings: LocalPlannerSettings) {
        self.planner_settings = settings;
    }

    /// Whether the robot may go around an obstacle here: it has a lidar,
    /// and the corridor at its progress leaves room beside the path beyond
    /// its footprint and three standard deviations of its position.
    fn may_detour(&self, belief: &Belief) -> bool {
        if !self.lidar_beams.iter().any(|&l| l) {
            return false;
        }
        let k = self.tracker.progress().min(self.along_m.len() - 1);
        let along = self.along_m[k];
        let keep = 3.0 * belief.pose_std[0].max(belief.pose_std[1]);
        let room = self.plan.header.robot.footprint_radius_m
            + keep
            + self.planner_settings.corridor_margin_m
            + 2.0 * self.planner_settings.cell_m;
        self.plan
            .header
            .freedom
            .half_width_at(along)
            .is_some_and(|hw| hw > room)
    }

    fn start_detour(&mut self, belief: &Belief, t: f64, plan_t: f64) {
        let k = self.tracker.progress().min(self.plan.samples.len() - 1);
        let pose = belief.pose;
        let planner = LocalPlanner::new(
            &self.plan,
            self.along_m.clone(),
            k,
            [pose.x_m, pose.y_m],
            self.planner_settings,
            self.seen.take(),
        );
        // As fast as the plan drives around here, a slow walk at least.
        let ahead = planner.along_m(k) + self.planner_settings.look_ahead_m;
        let max_speed_m_s = self.plan.samples[k..]
            .iter()
            .enumerate()
            .take_while(|(i, _)| planner.along_m(k + i) <= ahead)
            .map(|(_, s)| s.v_m_s.abs())
            .fold(0.1f64, f64::max)
            .min(0.5);
        self.detour = Some(Going {
            planner,
            route: Detour {
                waypoints: Vec::new(),
                rejoin: k,
                length_m: 0.0,
            },
            next: 0,
            from_sample: k,
            started_s: t,
            plan_t_s: plan_t,
            driven_m: 0.0,
            last: pose,
            max_speed_m_s,
            obstacle: Vec::new(),
            last_scan_s: t,
            aligning: false,
        });
    }

    /// One tick on a detour: the wheel commands, or zero and a stop.
    fn on_detour(&mut self, reading: &Reading, belief: &Belief, t: f64) -> [f64; 2] {
        match self.detour_tick(reading, belief, t) {
            Ok(wheels) => wheels,
            Err(stop) => {
                if let Some(g) = self.detour.take() {
                    // The plan's clock stays where the detour left the
                    // plan: a continuation starts from there.
                    self.time_shift_s = t - g.plan_t_s;
                    self.seen = Some(g.planner.into_seen());
                }
                self.stopped = Some((reading.t_s, stop));
                [0.0, 0.0]
            }
        }
    }

    fn detour_tick(
        &mut self,
        reading: &Reading,
        belief: &Belief,
        t: f64,
    ) -> Result<[f64; 2], Stop> {
        if let Some(what) = &reading.fault {
            return Err(Stop::SensorFault { what: what.clone() });
        }
        // A detour plans no contact: any bump hands back.
        if reading.bump {
            return Err(Stop::UnexpectedBump);
        }
        if let Some(timeout) = self.dead_man_timeout_s {
            let silent = reading.t_s - self.last_heard_s;
            if silent > timeout {
                return Err(Stop::DeadMan { silent_s: silent });
            }
        }
        let pose = belief.pose;
        let keep = 3.0 * belief.pose_std[0].max(belief.pose_std[1]);
        let fresh_scan = reading
            .fresh_ranges_m
            .iter()
            .zip(&self.lidar_beams)
            .any(|(m, &lidar)| lidar && m.is_finite());
        if fresh_scan {
            self.model.read(&pose, &mut self.predicted);
        }
        let plan = self.plan.clone();
        let freedom = &plan.header.freedom;
        let shorter_by = self.tolerances.obstacle_shorter_by_m;
        let g = self.detour.as_mut().expect("on a detour");
        // Distance driven, counted in steps of 2 cm so the estimate's
        // jitter while turning in place adds nothing.
        let step = pose.distance_to(&g.last);
        if step >= 0.02 {
            g.driven_m += step;
            g.last = pose;
        }
        if !g.planner.in_corridor([pose.x_m, pose.y_m]) {
            return Err(Stop::LeftCorridor {
                x_m: pose.x_m,
                y_m: pose.y_m,
            });
        }
        // A detour drives on what the lidar sees: without scans it stops.
        if fresh_scan {
            g.last_scan_s = t;
        } else if t - g.last_scan_s > MAX_DETOUR_SCAN_GAP_S {
            return Err(Stop::SensorFault {
                what: format!("no lidar scan for {:.1} s on a detour", t - g.last_scan_s),
            });
        }
        if fresh_scan {
            // The scan, sensor by sensor, into the robot's grid; where it
            // ended short of the map, for the twin.
            let mut first = 0;
            for beams in self.beams.chunk_by(|a, b| a.sensor == b.sensor) {
                let these = first..first + beams.len();
                first = these.end;
                if !self.lidar_beams[these.start] {
                    continue;
                }
                let Some(ranges) = reading.fresh_ranges_m.get(these.clone()) else {
                    break;
                };
                let origin = pose.transform_point(beams[0].origin[0], beams[0].origin[1]);
                let mut scan = Vec::with_capacity(beams.len());
                for ((m, beam), i) in ranges.iter().zip(beams).zip(these) {
                    if !m.is_finite() || *m <= beam.min_m {
                        continue;
                    }
                    let hit = *m < beam.max_m;
                    let (bx, by) = beam.endpoint(m.min(beam.max_m));
                    let end = pose.transform_point(bx, by);
                    scan.push(([end.0, end.1], hit));
                    let unexplained = self.predicted.get(i).is_some_and(|e| *m < e - shorter_by);
                    if hit && unexplained && g.obstacle.len() < MAX_OBSTACLE_POINTS {
                        let p = [end.0, end.1];
                        if g.obstacle
                            .iter()
                            .all(|q| (q[0] - p[0]).hypot(q[1] - p[1]) >= OBSTACLE_POINT_SPACING_M)
                        {
                            g.obstacle.push(p);
                        }
                    }
                }
                g.planner.integrate([origin.0, origin.1], &scan);
            }
            let nearest_seen = || {
                g.obstacle
                    .iter()
                    .min_by(|a, b| {
                        let d = |p: &[f64; 2]| (p[0] - pose.x_m).hypot(p[1] - pose.y_m);
                        d(a).total_cmp(&d(b))
                    })
                    .copied()
                    .unwrap_or([pose.x_m, pose.y_m])
            };
            let announced = !g.route.waypoints.is_empty();
            let rejoined = announced.then_some(g.route.rejoin);
            g.route = match g.planner.plan(&plan, g.from_sample, pose, keep, rejoined) {
                Ok(route) => route,
                Err(no_way) => {
                    let [x_m, y_m] = nearest_seen();
                    let why = match no_way {
                        NoWay::NoRejoin => format!(
                            "the plan is blocked for {:.1} m ahead: nothing clear to rejoin it at",
                            self.planner_settings.look_ahead_m
                        ),
                        NoWay::NotSeen => "the lidar does not show what stopped the robot on the plan's path: it cannot plan around it".to_string(),
                        NoWay::Enclosed { .. } => "no way around inside the corridor and out of the keep-out zones with the footprint clear".to_string(),
                    };
                    return Err(Stop::Blocked { why, x_m, y_m });
                }
            };
            g.next = 1.min(g.route.waypoints.len() - 1);
            // What the rest would cost, against the operator's bounds.
            let samples = &plan.samples;
            let gain_m = g.planner.along_m(g.route.rejoin) - g.planner.along_m(g.from_sample);
            let extra_m = g.driven_m + g.route.length_m - gain_m;
            if extra_m > freedom.max_extra_distance_m {
                return Err(Stop::DetourBound {
                    why: format!(
                        "the way around adds {extra_m:.2} m, more than the {:.2} m allowed",
                        freedom.max_extra_distance_m
                    ),
                });
            }
            let gain_s = samples[g.route.rejoin].t_s - samples[0].t_s - g.plan_t_s;
            let extra_s =
                self.time_shift_s + (t - g.started_s) + g.route.length_m / g.max_speed_m_s - gain_s;
            if extra_s > freedom.max_extra_time_s {
                return Err(Stop::DetourBound {
                    why: format!(
                        "the way around makes the mission {extra_s:.1} s later, more than the {:.1} s allowed",
                        freedom.max_extra_time_s
                    ),
                });
            }
            if !announced {
                self.events.push(Event::Detour {
                    t_s: reading.t_s,
                    plan_t_s: g.plan_t_s,
                    from: [pose.x_m, pose.y_m, pose.heading_rad],
                    from_sample: g.from_sample,
                    rejoin: g.route.rejoin,
                    waypoints: g.route.waypoints.clone(),
                    length_m: g.route.length_m,
                    obstacle: g.obstacle.clone(),
                });
            }
        }
        if g.route.waypoints.is_empty() {
            // No scan yet since the obstacle was seen: stand.
            return Ok([0.0, 0.0]);
        }
        // Drive the waypoints: turn towards the next, then go, slower as
        // obstacles come near; at the last, turn to the plan's heading.
        let wp = &g.route.waypoints;
        let here = [pose.x_m, pose.y_m];
        let reached = |k: usize, within_m: f64| {
            let (a, b) = (wp[k.saturating_sub(1)], wp[k]);
            let d = (b[0] - here[0]).hypot(b[1] - here[1]);
            let past =
                k > 0 && (here[0] - b[0]) * (b[0] - a[0]) + (here[1] - b[1]) * (b[1] - a[1]) > 0.0;
            d < within_m || past
        };
        while g.next + 1 < wp.len() && reached(g.next, WAYPOINT_REACHED_M) {
            g.next += 1;
        }
        let target = wp[g.next];
        let to_target = (target[0] - pose.x_m).hypot(target[1] - pose.y_m);
        let last = g.next + 1 == wp.len();
        // Once at the rejoin point the robot turns there, unless it has
        // drifted well off it.
        g.aligning = last
            && if g.aligning {
                to_target < 2.0 * REJOIN_REACHED_M
            } else {
                reached(g.next, REJOIN_REACHED_M)
            };
        let (v, omega) = if g.aligning {
            let rejoin = &plan.samples[g.route.rejoin];
            let e = wrap_angle(rejoin.heading_rad - pose.heading_rad);
            if e.abs() < ALIGNED_RAD {
                return Ok(self.rejoin(belief, t));
            }
            (
                0.0,
                (TURN_GAIN_PER_S * e).clamp(-MAX_TURN_RAD_S, MAX_TURN_RAD_S),
            )
        } else {
            let e =
                wrap_angle((target[1] - pose.y_m).atan2(target[0] - pose.x_m) - pose.heading_rad);
            let omega = (TURN_GAIN_PER_S * e).clamp(-MAX_TURN_RAD_S, MAX_TURN_RAD_S);
            if e.abs() > TURN_IN_PLACE_RAD {
                (0.0, omega)
            } else {
                let clearance = g.planner.clearance_at([pose.x_m, pose.y_m]);
                let slow = (clearance / SLOW_WITHIN_M).clamp(MIN_SPEED_FRACTION, 1.0);
                let v = (g.max_speed_m_s * slow * e.cos())
                    .min(to_target / 0.5)
                    .max(MIN_APPROACH_M_S);
                (v, omega)
            }
        };
        Ok(capped_wheel_speeds(
            &plan.header.calibrated,
            v,
            omega,
            self.max_wheel_rad_s,
        ))
    }

    /// Back on the plan near the detour's rejoin sample: at the sample
    /// nearest the robot within [`REJOIN_WINDOW_M`] along the plan of it
    /// (a robot that turned in place beside the point, under a slow
    /// control loop, stands a few centimetres before or after it; the
    /// plan's clock set to the planned sample would start the tracker that
    /// far behind or ahead). The plan's clock moves on to that sample, the
    /// residual starts afresh, and tracking resumes.
    fn rejoin(&mut self, belief: &Belief, t: f64) -> [f64; 2] {
        let mut g = self.detour.take().expect("on a detour");
        let samples = &self.plan.samples;
        let planned_m = g.planner.along_m(g.route.rejoin);
        let near = |k: usize| (g.planner.along_m(k) - planned_m).abs() <= REJOIN_WINDOW_M;
        let first = (0..g.route.rejoin)
            .rev()
            .take_while(|&k| k >= g.from_sample && near(k))
            .last()
            .unwrap_or(g.route.rejoin);
        let last = (g.route.rejoin..samples.len())
            .take_while(|&k| near(k))
            .last()
            .unwrap_or(g.route.rejoin);
        let here = belief.pose;
        g.route.rejoin = (first..=last)
            .min_by(|&a, &b| {
                let d = |k: usize| {
                    let s = &samples[k];
                    (s.x_m - here.x_m).hypot(s.y_m - here.y_m)
                };
                d(a).total_cmp(&d(b)).then(a.cmp(&b))
            })
            .unwrap_or(g.route.rejoin);
        let plan_t = samples[g.route.rejoin].t_s - samples[0].t_s;
        let gain_m = g.planner.along_m(g.route.rejoin) - g.planner.along_m(g.from_sample);
        self.events.push(Event::Rejoined {
            t_s: t + self.t0_s.unwrap_or(0.0),
            sample: g.route.rejoin,
            extra_s: (t - g.started_s) - (plan_t - g.plan_t_s),
            extra_m: g.driven_m - gain_m,
            obstacle: g.obstacle,
        });
        self.time_shift_s = t - plan_t;
        self.seen = Some(g.planner.into_seen());
        self.residuals.clear();
        self.last_residual = None;
        self.last_median = None;
        self.ahead_count.fill(0);
        match self
            .tracker
            .command_from(&self.plan.samples, plan_t, belief.pose)
        {
            Some(wheels) => wheels,
            None => {
                self.stopped = Some((t + self.t0_s.unwrap_or(0.0), Stop::Finished));
                [0.0, 0.0]
            }
        }
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
        if self.detour.is_some() {
            return self.on_detour(reading, belief, t);
        }
        let plan_t = t - self.time_shift_s;
        let command = self
            .tracker
            .command_from(&self.plan.samples, plan_t, belief.pose);
        match self.check(reading, plan_t, belief) {
            // What the lidar saw it can plan around; what only a ranger saw
            // it cannot see on the way round.
            Some(Stop::ObstacleAhead { .. }) if self.ahead_by_lidar && self.may_detour(belief) => {
                self.start_detour(belief, t, plan_t);
                return self.on_detour(reading, belief, t);
            }
            Some(stop) => {
                self.stopped = Some((reading.t_s, stop));
                return [0.0, 0.0];
            }
            None => {}
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
            // Readings that end on what a detour saw the map lacks are
            // explained: the robot knows it is there.
            // (Built only once a detour has seen something.)
            let explained: Vec<bool> = match &self.seen {
                None => Vec::new(),
                Some(seen) => reading
                    .fresh_ranges_m
                    .iter()
                    .zip(&self.beams)
                    .map(|(m, beam)| {
                        m.is_finite() && *m > beam.min_m && *m < beam.max_m && {
                            let (bx, by) = beam.endpoint(*m);
                            let (x, y) = estimate.transform_point(bx, by);
                            seen.state_at([x, y]) == CellState::Occupied
                        }
                    })
                    .collect(),
            };
            // A localized robot that may go around what blocks its path
            // takes a reading shorter than the map explains for something
            // standing there: the obstacle-ahead check (and the detour)
            // judges it where it matters, on the path; elsewhere it does
            // not stop the mission. Readings longer than the map explains
            // (a wall gone, a robot lost) still count.
            let short_is_obstacle = belief.localizing && self.may_detour(belief);
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
                    if explained.get(i).copied().unwrap_or(false) {
                        count += 1;
                    } else if m.is_finite() && e.is_finite() {
                        // A reading past a learnt block's face, but not past
                        // what stands behind it, says the block is smaller
                        // than the twin guessed: no departure.
                        let far = self.predicted_behind.get(i).copied().unwrap_or(*e);
                        sum += if *m > *e {
                            (m - far).max(0.0).min(m - e)
                        } else if short_is_obstacle {
                            0.0
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
        let mut by_lidar = false;
        // Sensor by sensor (a sensor's beams come together).
        let mut first = 0;
        for beams in self.beams.chunk_by(|a, b| a.sensor == b.sensor) {
            let these = first..first + beams.len();
            let these_start = these.start;
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
            let this = *count >= tol.obstacle_confirm;
            confirmed |= this;
            by_lidar |= this && self.lidar_beams[these_start];
        }
        self.ahead_by_lidar = by_lidar;
        if confirmed { nearest } else { None }
    }
}
