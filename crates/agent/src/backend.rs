//! The boundary between the agent and the robot it drives: wheel commands
//! out; encoder counts, range readings, the bumper and any absolute pose in.
//! Two backends: a simulator running the robot's **site** (its own
//! scenario, which the master never sees), and a ROS 2 robot
//! (`crate::ros`, carried over zenoh by `twindrive_net::ros`); both
//! implement the same trait and nothing else changes.

use twindrive_kinematics::Pose;
use twindrive_log::{LogHeader, StepRecord};
use twindrive_sim::{Scenario, Sensed, Simulator, StepOutput};

/// What the robot sensed over one control period.
#[derive(Debug, Clone, PartialEq)]
pub struct Reading {
    /// Time since the backend started (s).
    pub t_s: f64,
    /// Cumulative encoder counts, when they sampled.
    pub encoder_ticks: Option<[i64; 2]>,
    pub bump: bool,
    /// The latest reading of each range beam (NaN: no reading yet).
    pub ranges_m: Vec<f64>,
    /// An absolute pose (a tracker, GNSS), when one sampled.
    pub pose: Option<Pose>,
    /// The period as the project's logs record it (wheel speeds asked for
    /// and reached, and the true pose where the backend knows it: a
    /// simulator does, a real robot logs its best estimate there).
    pub record: StepRecord,
    /// Every beam read this period (NaN where a sensor did not sample).
    pub fresh_ranges_m: Vec<f64>,
    /// Contact stopped the robot this period, where the backend can tell.
    pub blocked: bool,
    /// A sensor the robot steers by went silent: the backend has stopped
    /// the wheels, and the executive hands back.
    pub fault: Option<String>,
}

/// A robot the agent can drive.
pub trait RobotBackend {
    /// The control period (s).
    fn period_s(&self) -> f64;
    /// Sends `wheels` (left, right, rad/s) for one period and returns what
    /// the robot sensed; `None` when the backend can run no longer.
    fn step(&mut self, wheels: [f64; 2]) -> Option<Reading>;
    /// Total wheel rotation commanded and performed so far (rad), both
    /// wheels: a robot that never moved has zero.
    fn wheel_travel_rad(&self) -> f64;
    /// What the robot's logs say of it (sensors, limits, where it is now).
    fn log_header(&self) -> LogHeader;
    /// The world the robot knows, for its logs' `/map` (none by default).
    fn map(&self) -> Option<twindrive_log::WorldMap> {
        None
    }
}

/// The site as a simulator: the robot's true kinematics, noise, slip and
/// any obstacle the twin lacks.
pub struct SimBackend {
    sim: Simulator,
    out: StepOutput,
    travel_rad: f64,
    latest: Vec<f64>,
}

impl SimBackend {
    /// Runs `site` from `start`, for at most `max_duration_s`.
    pub fn new(mut site: Scenario, start: Pose, max_duration_s: f64) -> Result<Self, String> {
        site.robot.start = start;
        site.set_duration_s(max_duration_s)
            .map_err(|e| format!("site duration: {e}"))?;
        let sim = Simulator::new(site);
        let out = StepOutput::new(sim.beams());
        let beams = sim.beams();
        Ok(Self {
            sim,
            out,
            travel_rad: 0.0,
            latest: vec![f64::NAN; beams],
        })
    }

    /// The robot's true pose (what no real robot knows; for tests and logs).
    pub fn true_pose(&self) -> Pose {
        self.sim.pose()
    }

    /// Whether a wall stopped the robot in the last step.
    pub fn blocked(&self) -> bool {
        self.out.blocked
    }
}

impl RobotBackend for SimBackend {
    fn period_s(&self) -> f64 {
        self.sim.scenario().dt_s()
    }

    fn step(&mut self, wheels: [f64; 2]) -> Option<Reading> {
        if !self.sim.step_with(&mut self.out, &mut |_: &Sensed| wheels) {
            return None;
        }
        let r = &self.out.record;
        let dt = self.period_s();
        self.travel_rad += (r.wheel_rad_s[0].abs() + r.wheel_rad_s[1].abs()) * dt;
        for (latest, &now) in self.latest.iter_mut().zip(&self.out.ranges) {
            if !now.is_nan() {
                *latest = now;
            }
        }
        Some(Reading {
            t_s: r.t_s() + dt,
            encoder_ticks: r.encoder_ticks,
            bump: r.bump,
            ranges_m: self.latest.clone(),
            pose: r.tracker,
            record: *r,
            fresh_ranges_m: self.out.ranges.clone(),
            blocked: self.out.blocked,
            fault: None,
        })
    }

    fn wheel_travel_rad(&self) -> f64 {
        self.travel_rad
    }

    fn log_header(&self) -> LogHeader {
        let mut header = self.sim.scenario().log_header();
        header.start = self.sim.pose();
        header
    }

    /// The site's world: a simulated site knows it.
    fn map(&self) -> Option<twindrive_log::WorldMap> {
        Some(self.sim.scenario().world.log_map())
    }
}
