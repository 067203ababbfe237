//! The operator's twin: a simulator they drive by hand (a dead-man command
//! that lapses unless renewed), hand to the wall follower or send along a
//! way to their goals, at real time or faster, recording a run as a
//! rehearsal. No I/O: time comes in as
//! nanoseconds of the console's clock, so tests step it as they like.

use std::collections::VecDeque;

use twindrive_kinematics::{Pose, wheel_speeds};
use twindrive_log::MissionLog;
use twindrive_mission::follower::Follower;
use twindrive_mission::itinerary::Itinerary;
use twindrive_sim::ControllerConfig;
use twindrive_sim::controller::{Controller, Observation};
use twindrive_sim::scenario::WallFollowerSpec;
use twindrive_sim::{Scenario, Sensed, Simulator, StepOutput};

/// A manual command lapses this long after it was sent (the dead-man): a
/// page that stops sending (a released key, a lost connection) stops the
/// robot.
pub const DEAD_MAN_NS: u64 = 400_000_000;

/// The most real time one [`Workspace::advance`] catches up, so a stalled
/// console does not try to simulate minutes at once.
const MAX_CATCH_UP_NS: u64 = 1_000_000_000;

/// The longest rehearsal kept (s of simulated time).
pub const MAX_REHEARSAL_S: f64 = 4.0 * 3600.0;

/// Fastest speed-up of simulated over real time.
pub const MAX_SPEED: f64 = 64.0;

/// What drives the twin.
#[derive(Debug, Clone)]
enum Drive {
    Idle,
    /// Body velocities from the page, valid until `expires_ns` (console
    /// clock).
    Manual {
        v_m_s: f64,
        omega_rad_s: f64,
        expires_ns: u64,
    },
    WallFollower(Box<Controller>),
    /// Along a way through the operator's waypoints; a recording going on
    /// ends when the last is reached, and records the goals met.
    Route(Box<(Follower, Itinerary)>),
}

/// A bump the twin's robot felt (for the map).
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct BumpEvent {
    pub t_s: f64,
    pub x_m: f64,
    pub y_m: f64,
}

/// The twin the operator drives.
pub struct Workspace {
    /// The twin as loaded (its start pose is where a reset puts the robot).
    base: Scenario,
    /// Where the robot starts after a reset (placed by the operator).
    start: Pose,
    sim: Simulator,
    out: StepOutput,
    /// The latest reading of every beam (NaN: none yet).
    latest_ranges: Vec<f64>,
    drive: Drive,
    speed: f64,
    /// Console time up to which the twin has been simulated.
    simulated_to_ns: u64,
    /// Real nanoseconds owed to the simulation (fractions of a step).
    owed_ns: f64,
    recording: Option<MissionLog>,
    /// The last finished recording.
    rehearsal: Option<MissionLog>,
    rehearsal_rev: u64,
    bumps: VecDeque<BumpEvent>,
    was_bumped: bool,
    wall_spec: (WallFollowerSpec, usize),
    /// Simulated time since the last reset or recording start.
    t_ns: u64,
}

/// A wall follower for scenarios that do not configure one: the paper's
/// gains on the first range sensor.
fn wall_follower_of(scenario: &Scenario) -> (WallFollowerSpec, usize) {
    if let ControllerConfig::WallFollower { spec, sensor } = &scenario.controller {
        return (spec.clone(), *sensor);
    }
    let builtin = twindrive_sim::builtin::load("wall_following")
        .expect("built in")
        .expect("the built-in scenario is valid");
    match builtin.controller {
        ControllerConfig::WallFollower { spec, .. } => (spec, 0),
        _ => unreachable!("the case study follows a wall"),
    }
}

impl Workspace {
    /// A twin of `scenario`, without end, its robot at the scenario's start.
    pub fn new(scenario: Scenario) -> Self {
        let start = scenario.robot.start;
        let wall_spec = wall_follower_of(&scenario);
        let mut base = scenario;
        // The operator decides when a run ends.
        base.steps = u64::MAX;
        let sim = Simulator::new(base.clone());
        let out = StepOutput::new(sim.beams());
        Self {
            base,
            start,
            latest_ranges: vec![f64::NAN; out.ranges.len()],
            out,
            sim,
            drive: Drive::Idle,
            speed: 1.0,
            simulated_to_ns: 0,
            owed_ns: 0.0,
            recording: None,
            rehearsal: None,
            rehearsal_rev: 0,
            bumps: VecDeque::new(),
            was_bumped: false,
            wall_spec,
            t_ns: 0,
        }
    }

    pub fn scenario(&self) -> &Scenario {
        &self.base
    }

    pub fn pose(&self) -> Pose {
        self.sim.pose()
    }

    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// Simulated seconds since the last reset or recording start.
    pub fn t_s(&self) -> f64 {
        self.t_ns as f64 * 1e-9
    }

    pub fn drive_name(&self) -> &'static str {
        match self.drive {
            Drive::Idle => "idle",
            Drive::Manual { .. } => "manual",
            Drive::WallFollower(_) => "wall_follower",
            Drive::Route(_) => "route",
        }
    }

    /// The latest range reading of every beam (NaN: not sampled yet).
    pub fn ranges(&self) -> &[f64] {
        &self.latest_ranges
    }

    pub fn bumped(&self) -> bool {
        self.out.record.bump
    }

    pub fn bumps(&self) -> impl DoubleEndedIterator<Item = &BumpEvent> {
        self.bumps.iter()
    }

    /// Seconds recorded so far, when recording.
    pub fn recording_s(&self) -> Option<f64> {
        self.recording.as_ref().map(|l| {
            l.steps
                .last()
                .map_or(0.0, |s| s.t_ns as f64 * 1e-9 + l.header.dt_s)
        })
    }

    pub fn rehearsal(&self) -> Option<&MissionLog> {
        self.rehearsal.as_ref()
    }

    /// The goals the rehearsal met (to add what was measured of them).
    pub fn rehearsal_goals_mut(&mut self) -> Option<&mut twindrive_log::RehearsedGoals> {
        self.rehearsal.as_mut().map(|log| &mut log.header.goals)
    }

    /// Changes whenever a new rehearsal is recorded.
    pub fn rehearsal_rev(&self) -> u64 {
        self.rehearsal_rev
    }

    /// Body velocity limits of the twin's robot with its nominal parameters
    /// (what a full stick deflection asks for).
    pub fn velocity_limits(&self) -> (f64, f64) {
        let p = &self.base.robot.nominal_params;
        let w = self.base.robot.max_wheel_speed_rad_s;
        let r = 0.25 * (p.left_diameter_m + p.right_diameter_m);
        (w * r, 2.0 * w * r / p.wheelbase_m)
    }

    /// Manual driving: `forward` and `turn` in [-1, 1] of the robot's
    /// limits, until `now_ns` + [`DEAD_MAN_NS`] unless renewed.
    pub fn drive(&mut self, forward: f64, turn: f64, now_ns: u64) -> Result<(), String> {
        for (name, v) in [("forward", forward), ("turn", turn)] {
            if !(v.is_finite() && (-1.0..=1.0).contains(&v)) {
                return Err(format!("{name}: a number in [-1, 1], got {v}"));
            }
        }
        self.advance(now_ns);
        let (v_max, omega_max) = self.velocity_limits();
        // Both at full deflection would saturate a wheel: share the range.
        let (v, omega) = (0.7 * forward * v_max, 0.5 * turn * omega_max);
        self.set_drive(Drive::Manual {
            v_m_s: v,
            omega_rad_s: omega,
            expires_ns: now_ns + DEAD_MAN_NS,
        });
        Ok(())
    }

    pub fn stop(&mut self, now_ns: u64) {
        self.advance(now_ns);
        self.set_drive(Drive::Idle);
    }

    /// Drives the twin by `drive` from now on; the goals a way met so far
    /// go into the recording going on.
    fn set_drive(&mut self, drive: Drive) {
        if let Drive::Route(route) = &self.drive
            && let Some(log) = &mut self.recording
        {
            let (follower, itinerary) = route.as_ref();
            let met = itinerary.record(follower.arrivals());
            let goals = &mut log.header.goals;
            goals.waypoints.extend(met.waypoints);
            goals.areas.extend(met.areas);
        }
        self.drive = drive;
    }

    /// Hands the robot to the wall follower (the scenario's, or the paper's
    /// on the first range sensor).
    pub fn wall_follow(&mut self, now_ns: u64) {
        self.advance(now_ns);
        let (spec, sensor) = self.wall_spec.clone();
        self.set_drive(Drive::WallFollower(Box::new(Controller::new(
            &ControllerConfig::WallFollower { spec, sensor },
        ))));
    }

    /// Sends the robot along a way (planned from where it stands now).
    pub fn follow(&mut self, follower: Follower, itinerary: Itinerary, now_ns: u64) {
        self.advance(now_ns);
        self.set_drive(Drive::Route(Box::new((follower, itinerary))));
    }

    pub fn set_speed(&mut self, factor: f64, now_ns: u64) -> Result<(), String> {
        if !(factor.is_finite() && (0.1..=MAX_SPEED).contains(&factor)) {
            return Err(format!(
                "speed: a factor of real time in [0.1, {MAX_SPEED}], got {factor}"
            ));
        }
        self.advance(now_ns);
        self.speed = factor;
        Ok(())
    }

    /// Puts the robot at `pose` (which must be free) and makes it the start
    /// of later resets.
    pub fn place(&mut self, pose: Pose, now_ns: u64) -> Result<(), String> {
        if ![pose.x_m, pose.y_m, pose.heading_rad]
            .iter()
            .all(|v| v.is_finite())
        {
            return Err("place: x_m, y_m and heading_rad must be finite".into());
        }
        let mut probe = self.base.clone();
        probe.robot.start = pose;
        let p = twindrive_sim::Vector::new(pose.x_m, pose.y_m);
        if probe.world.inside_obstacle(p)
            || probe
                .world
                .nearest_within(p, probe.robot.footprint_radius_m)
                .is_some()
        {
            return Err(format!(
                "place: ({:.2}, {:.2}) is inside an obstacle or closer than the footprint to a wall",
                pose.x_m, pose.y_m
            ));
        }
        self.start = pose;
        self.restart_at(pose, now_ns);
        Ok(())
    }

    /// Back to the start pose, idle; a recording in progress is dropped.
    pub fn reset(&mut self, now_ns: u64) {
        self.recording = None;
        self.drive = Drive::Idle;
        let start = self.start;
        self.restart_at(start, now_ns);
    }

    fn restart_at(&mut self, pose: Pose, now_ns: u64) {
        let mut scenario = self.base.clone();
        scenario.robot.start = pose;
        self.sim = Simulator::new(scenario);
        self.out = StepOutput::new(self.sim.beams());
        self.latest_ranges = vec![f64::NAN; self.out.ranges.len()];
        self.simulated_to_ns = now_ns;
        self.owed_ns = 0.0;
        self.t_ns = 0;
        self.bumps.clear();
        self.was_bumped = false;
        if let Drive::WallFollower(_) = self.drive {
            self.wall_follow(now_ns);
        }
    }

    /// Starts recording a rehearsal from where the robot is: the twin
    /// restarts there (its clock and encoders from zero), as a mission log
    /// would begin.
    pub fn record_start(&mut self, now_ns: u64) {
        self.advance(now_ns);
        let here = self.sim.pose();
        self.restart_at(here, now_ns);
        let mut header = self.sim.scenario().log_header();
        header.scenario = self.base.name.clone();
        self.recording = Some(MissionLog::new(header));
    }

    /// Ends the recording; it becomes the rehearsal the pipeline works on.
    pub fn record_stop(&mut self, now_ns: u64) -> Result<&MissionLog, String> {
        self.advance(now_ns);
        let log = self
            .recording
            .take()
            .ok_or_else(|| "record_stop: not recording".to_owned())?;
        if log.steps.len() < 20 {
            return Err(format!(
                "record_stop: the rehearsal has {} steps; drive for a while first",
                log.steps.len()
            ));
        }
        self.rehearsal = Some(log);
        self.rehearsal_rev += 1;
        Ok(self.rehearsal.as_ref().expect("just set"))
    }

    /// Makes `log` the rehearsal (one loaded from a file).
    pub fn set_rehearsal(&mut self, log: MissionLog) {
        self.rehearsal = Some(log);
        self.rehearsal_rev += 1;
    }

    /// Simulates up to `now_ns` of the console's clock at the set speed.
    pub fn advance(&mut self, now_ns: u64) {
        let elapsed = now_ns
            .saturating_sub(self.simulated_to_ns)
            .min(MAX_CATCH_UP_NS);
        self.simulated_to_ns = self.simulated_to_ns.max(now_ns);
        let dt = self.base.dt_ns;
        self.owed_ns += elapsed as f64 * self.speed;
        // The console time each step stands for, to expire a manual command
        // at the right step.
        let mut step_console_ns = now_ns as f64 - self.owed_ns / self.speed;
        while self.owed_ns >= dt as f64 {
            self.owed_ns -= dt as f64;
            step_console_ns += dt as f64 / self.speed;
            if let Drive::Manual { expires_ns, .. } = self.drive
                && step_console_ns as u64 > expires_ns
            {
                self.drive = Drive::Idle;
            }
            self.step_once();
        }
    }

    fn step_once(&mut self) {
        let nominal = self.base.robot.nominal_params;
        let (pose, t_s) = (self.sim.pose(), self.t_s());
        let drive = &mut self.drive;
        let mut control = |s: &Sensed| -> [f64; 2] {
            match drive {
                Drive::Idle => [0.0, 0.0],
                Drive::Manual {
                    v_m_s, omega_rad_s, ..
                } => {
                    let (l, r) = wheel_speeds(&nominal, *v_m_s, *omega_rad_s);
                    [l, r]
                }
                Drive::WallFollower(c) => c.command(
                    &Observation {
                        t_ns: s.t_ns,
                        bump: s.bump,
                        latest_range_m: s.latest_range_m,
                    },
                    &nominal,
                ),
                Drive::Route(route) => {
                    let (v, omega) = route.0.command(&pose, t_s);
                    let (l, r) = wheel_speeds(&nominal, v, omega);
                    [l, r]
                }
            }
        };
        if !self.sim.step_with(&mut self.out, &mut control) {
            return;
        }
        self.t_ns = self.out.record.t_ns + self.base.dt_ns;
        for (latest, &now) in self.latest_ranges.iter_mut().zip(&self.out.ranges) {
            if now.is_finite() {
                *latest = now;
            }
        }
        let bump = self.out.record.bump;
        if bump && !self.was_bumped {
            let p = self.out.record.ground_truth;
            self.bumps.push_back(BumpEvent {
                t_s: self.t_s(),
                x_m: p.x_m,
                y_m: p.y_m,
            });
            if self.bumps.len() > 200 {
                self.bumps.pop_front();
            }
        }
        self.was_bumped = bump;
        if let Some(log) = &mut self.recording {
            log.steps.push(self.out.record);
            log.ranges.extend_from_slice(&self.out.ranges);
            if self.out.record.t_ns as f64 * 1e-9 >= MAX_REHEARSAL_S {
                let log = self.recording.take().expect("recording");
                tracing::warn!("the rehearsal reached {MAX_REHEARSAL_S} s; recording stopped");
                self.rehearsal = Some(log);
                self.rehearsal_rev += 1;
            }
        }
        // At the last waypoint: the robot stands, and the drive there is
        // the rehearsal (a bump on the way ends it too: the way was not
        // clear, and the operator sees where).
        let arrived = matches!(&self.drive, Drive::Route(route) if route.0.done());
        if arrived || (bump && matches!(self.drive, Drive::Route(_))) {
            self.set_drive(Drive::Idle);
            if let Some(log) = self.recording.take() {
                self.rehearsal = Some(log);
                self.rehearsal_rev += 1;
            }
        }
    }

    /// Where a range sensor is now: x, y (m) and heading (rad) in the world.
    pub fn mount_in_world(&self, info: &twindrive_log::RangeSensorInfo) -> [f64; 3] {
        let pose = self.sim.pose();
        let (sin, cos) = pose.heading_rad.sin_cos();
        [
            pose.x_m + cos * info.mount.x_m - sin * info.mount.y_m,
            pose.y_m + sin * info.mount.x_m + cos * info.mount.y_m,
            pose.heading_rad + info.mount.heading_rad,
        ]
    }

    /// Every beam now: origin and end in the world frame, and its range.
    pub fn beams(&self) -> Vec<[f64; 5]> {
        let pose = self.sim.pose();
        let mut out = Vec::new();
        let mut k = 0;
        for s in &self.base.range_sensors {
            let info = &s.info;
            let [ox, oy, _] = self.mount_in_world(info);
            for b in 0..info.beams {
                let range = self.latest_ranges.get(k).copied().unwrap_or(f64::NAN);
                k += 1;
                let a = pose.heading_rad + info.mount.heading_rad + info.beam_angle_rad(b);
                let r = if range.is_finite() {
                    range
                } else {
                    info.max_range_m
                };
                out.push([ox, oy, ox + r * a.cos(), oy + r * a.sin(), range]);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn twin() -> Workspace {
        let s = twindrive_sim::builtin::load("wall_following")
            .unwrap()
            .unwrap();
        Workspace::new(s)
    }

    const S: u64 = 1_000_000_000;

    #[test]
    fn a_manual_command_drives_then_lapses() {
        let mut w = twin();
        let start = w.pose();
        w.drive(1.0, 0.0, 0).unwrap();
        w.advance(S / 4);
        let moved = w.pose();
        let dist = |p: Pose| (p.x_m - start.x_m).hypot(p.y_m - start.y_m);
        assert!(dist(moved) > 0.01, "{start:?} -> {moved:?}");
        // No renewal: the dead-man stops the robot, which then stays put.
        w.advance(2 * S);
        let stopped = w.pose();
        w.advance(3 * S);
        assert_eq!(w.pose(), stopped);
        assert_eq!(w.drive_name(), "idle");
        // It coasted at most the dead-man time past the command.
        let (v_max, _) = w.velocity_limits();
        assert!(dist(stopped) < 0.7 * v_max * 0.6);
    }

    #[test]
    fn renewed_commands_keep_driving_and_turning_turns_left() {
        let mut w = twin();
        let start = w.pose();
        for k in 0..20 {
            w.drive(0.0, 1.0, k * S / 10).unwrap();
        }
        w.advance(2 * S);
        let heading = w.pose().heading_rad - start.heading_rad;
        assert!(heading > 0.5, "counter-clockwise is positive: {heading}");
    }

    #[test]
    fn bad_commands_are_refused() {
        let mut w = twin();
        assert!(w.drive(f64::NAN, 0.0, 0).is_err());
        assert!(w.drive(0.0, 1.5, 0).is_err());
        assert!(w.set_speed(0.0, 0).is_err());
        assert!(w.set_speed(1e9, 0).is_err());
        assert!(w.place(Pose::new(f64::NAN, 0.0, 0.0), 0).is_err());
        assert!(w.record_stop(0).is_err());
    }

    #[test]
    fn a_recording_is_a_mission_log_from_the_robot_s_pose() {
        let mut w = twin();
        w.wall_follow(0);
        w.set_speed(8.0, 0).unwrap();
        w.advance(S);
        let here = w.pose();
        w.record_start(S);
        assert_eq!(w.t_s(), 0.0);
        for k in 1..=20 {
            w.advance(S + k * S / 10);
        }
        let log = w.record_stop(3 * S).unwrap();
        assert_eq!(log.header.start, here);
        assert_eq!(log.steps[0].t_ns, 0);
        // 2 s of real time at 8x.
        let secs = log.steps.len() as f64 * log.header.dt_s;
        assert!((secs - 16.0).abs() < 0.1, "{secs}");
        assert_eq!(log.ranges.len(), log.steps.len() * log.beams_per_step());
        assert_eq!(w.rehearsal_rev(), 1);
    }
}
