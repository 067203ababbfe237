//! Driving a [`Route`] on the twin: the twin's robot turns in place at
//! each corner to face the next leg, drives the leg straight (the heading
//! and the sideways offset from the leg corrected, slowing to stop at the
//! leg's end), and at a waypoint turns to its heading and stands its dwell.
//! No I/O and no clock: the pose and the time come in at each step, the
//! body speeds go out.

use twindrive_kinematics::{Pose, wrap_angle};

use crate::goals::Goals;
use crate::route::Route;

/// How the follower drives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowerSettings {
    /// Turning in place, at most (rad/s), and its gain (1/s).
    pub max_turn_rad_s: f64,
    pub turn_gain_per_s: f64,
    /// Facing within this, a turn is done (rad).
    pub aligned_rad: f64,
    /// Braking towards a leg's end (m/s²).
    pub decel_m_s2: f64,
    /// Gains on the heading (1/s) and the sideways offset (rad/s per m)
    /// while driving a leg.
    pub heading_gain_per_s: f64,
    pub offset_gain: f64,
    /// The leg's end within this along it, it is done (m).
    pub reached_m: f64,
}

impl Default for FollowerSettings {
    fn default() -> Self {
        Self {
            max_turn_rad_s: 1.0,
            turn_gain_per_s: 3.0,
            aligned_rad: 0.02,
            decel_m_s2: 0.3,
            heading_gain_per_s: 2.0,
            offset_gain: 4.0,
            reached_m: 0.005,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// Turning to face leg `k`.
    Face,
    /// Driving leg `k`.
    Drive,
    /// At a waypoint: turning to its heading.
    Heading,
    /// At a waypoint: standing until this time (s).
    Dwell {
        until_s: f64,
    },
    Done,
}

#[derive(Debug, Clone)]
struct Leg {
    from: [f64; 2],
    to: [f64; 2],
    speed_m_s: f64,
    /// At its end, the waypoint it reaches (index into the goals).
    waypoint: Option<usize>,
}

/// How long driving `route` through `goals`' waypoints takes (s): the
/// follower driven on `robot` (its nominal wheels, their speed and
/// acceleration limits, at the control period `dt_s`) from `start`, as the
/// twin drives it but without noise or slip. Gives up (and says so with
/// `f64::INFINITY`) after an hour of driving.
pub fn expected_duration_s(
    route: &Route,
    goals: &Goals,
    settings: &FollowerSettings,
    robot: &twindrive_sim::RobotConfig,
    start: Pose,
    dt_s: f64,
) -> f64 {
    const GIVE_UP_S: f64 = 3600.0;
    let params = &robot.nominal_params;
    let mut follower = Follower::new(route, goals, *settings);
    let mut pose = start;
    let mut wheels = [0.0f64; 2];
    let max_change = robot.max_wheel_accel_rad_s2 * dt_s;
    let mut t_s = 0.0;
    while !follower.done() {
        if t_s > GIVE_UP_S {
            return f64::INFINITY;
        }
        let (v, omega) = follower.command(&pose, t_s);
        let (l, r) = twindrive_kinematics::wheel_speeds(params, v, omega);
        // The simulator's limits: both wheels scaled to the top speed
        // (keeping the curvature), then each towards it at the acceleration.
        let peak = l.abs().max(r.abs());
        let scale = if peak > robot.max_wheel_speed_rad_s {
            robot.max_wheel_speed_rad_s / peak
        } else {
            1.0
        };
        for (w, cmd) in wheels.iter_mut().zip([l * scale, r * scale]) {
            *w += (cmd - *w).clamp(-max_change, max_change);
        }
        pose = twindrive_kinematics::arc_step_wheels(
            &pose,
            params,
            wheels[0] * dt_s,
            wheels[1] * dt_s,
        );
        t_s += dt_s;
    }
    t_s
}

/// When the robot met a waypoint: it stood there at `reached_t_s`, then
/// turned to the waypoint's heading and stood its dwell, and left at
/// `left_t_s` (the times the follower was given).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arrival {
    /// Index into the goals' waypoints.
    pub waypoint: usize,
    pub reached_t_s: f64,
    pub left_t_s: f64,
}

/// Drives a route through the goals' waypoints.
#[derive(Debug, Clone)]
pub struct Follower {
    legs: Vec<Leg>,
    goals: Goals,
    settings: FollowerSettings,
    k: usize,
    phase: Phase,
    /// Waypoints reached so far.
    reached: usize,
    /// When the robot stood at the waypoint it is at now.
    standing_since_s: Option<f64>,
    arrivals: Vec<Arrival>,
}

impl Follower {
    pub fn new(route: &Route, goals: &Goals, settings: FollowerSettings) -> Self {
        let mut legs = Vec::new();
        let mut waypoint = 0;
        for (i, w) in route.points.windows(2).enumerate() {
            let ends_at = route.stops.get(waypoint) == Some(&(i + 1));
            if w[0] != w[1] {
                legs.push(Leg {
                    from: w[0],
                    to: w[1],
                    speed_m_s: goals.leg_speed_m_s(waypoint.min(goals.waypoints.len() - 1)),
                    waypoint: None,
                });
            }
            if ends_at {
                // A waypoint on the start, or twice in a row, is a leg of
                // no length: it still turns and dwells.
                if legs.is_empty() || legs.last().and_then(|l| l.waypoint).is_some() {
                    legs.push(Leg {
                        from: w[1],
                        to: w[1],
                        speed_m_s: goals.speed_m_s,
                        waypoint: None,
                    });
                }
                legs.last_mut().expect("one at least").waypoint = Some(waypoint);
                waypoint += 1;
            }
        }
        let phase = if legs.is_empty() {
            Phase::Done
        } else {
            Phase::Face
        };
        Self {
            legs,
            goals: goals.clone(),
            settings,
            k: 0,
            phase,
            reached: 0,
            standing_since_s: None,
            arrivals: Vec::new(),
        }
    }

    /// The waypoints met so far, in order, and when.
    pub fn arrivals(&self) -> &[Arrival] {
        &self.arrivals
    }

    /// Whether the last waypoint is reached (and its dwell stood).
    pub fn done(&self) -> bool {
        self.phase == Phase::Done
    }

    /// How many waypoints the robot reached.
    pub fn reached(&self) -> usize {
        self.reached
    }

    /// The body speeds (m/s, rad/s) for the robot at `pose` at time `t_s`.
    pub fn command(&mut self, pose: &Pose, t_s: f64) -> (f64, f64) {
        let s = self.settings;
        let turn = |e: f64| (s.turn_gain_per_s * e).clamp(-s.max_turn_rad_s, s.max_turn_rad_s);
        loop {
            let Some(leg) = self.legs.get(self.k) else {
                self.phase = Phase::Done;
                return (0.0, 0.0);
            };
            let d = [leg.to[0] - leg.from[0], leg.to[1] - leg.from[1]];
            let length = d[0].hypot(d[1]);
            match self.phase {
                Phase::Done => return (0.0, 0.0),
                Phase::Face => {
                    if length < 1e-9 {
                        self.phase = Phase::Drive;
                        continue;
                    }
                    let e = wrap_angle(d[1].atan2(d[0]) - pose.heading_rad);
                    if e.abs() <= s.aligned_rad {
                        self.phase = Phase::Drive;
                        continue;
                    }
                    return (0.0, turn(e));
                }
                Phase::Drive => {
                    let (along, offset) = if length < 1e-9 {
                        (0.0, 0.0)
                    } else {
                        let u = [d[0] / length, d[1] / length];
                        let r = [pose.x_m - leg.from[0], pose.y_m - leg.from[1]];
                        (r[0] * u[0] + r[1] * u[1], u[0] * r[1] - u[1] * r[0])
                    };
                    let left = length - along;
                    if left <= s.reached_m {
                        self.phase = if leg.waypoint.is_some() {
                            self.standing_since_s = Some(t_s);
                            Phase::Heading
                        } else {
                            self.k += 1;
                            Phase::Face
                        };
                        continue;
                    }
                    let e = wrap_angle(d[1].atan2(d[0]) - pose.heading_rad);
                    if e.abs() > 0.3 {
                        // Knocked off the leg's heading: face it again.
                        return (0.0, turn(e));
                    }
                    let v = leg
                        .speed_m_s
                        .min((2.0 * s.decel_m_s2 * left).sqrt())
                        .max(0.01);
                    let omega = (s.heading_gain_per_s * e - s.offset_gain * offset * v.signum())
                        .clamp(-s.max_turn_rad_s, s.max_turn_rad_s);
                    return (v * e.cos(), omega);
                }
                Phase::Heading => {
                    let w = leg.waypoint.expect("a waypoint's leg");
                    if let Some(h) = self.goals.waypoints[w].heading_rad {
                        let e = wrap_angle(h - pose.heading_rad);
                        if e.abs() > s.aligned_rad {
                            return (0.0, turn(e));
                        }
                    }
                    self.reached += 1;
                    self.phase = Phase::Dwell {
                        until_s: t_s + self.goals.waypoints[w].dwell_s,
                    };
                    continue;
                }
                Phase::Dwell { until_s } => {
                    if t_s < until_s {
                        return (0.0, 0.0);
                    }
                    self.arrivals.push(Arrival {
                        waypoint: leg.waypoint.expect("a waypoint's leg"),
                        reached_t_s: self.standing_since_s.take().unwrap_or(t_s),
                        left_t_s: t_s,
                    });
                    self.k += 1;
                    self.phase = if self.k < self.legs.len() {
                        Phase::Face
                    } else {
                        Phase::Done
                    };
                    if self.phase == Phase::Done {
                        return (0.0, 0.0);
                    }
                }
            }
        }
    }
}
