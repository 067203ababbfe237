//! The boundary between the agent and the robot it drives: wheel commands
//! out; encoder counts, range readings, the bumper and any absolute pose in.
//!
//! A control period is one call of [`RobotBackend::step`]: the backend reads
//! the robot's sensors, the agent decides from that reading, and the
//! backend sends the decision **in the same period**. A stop decided on a
//! reading is the command of that very period, never of the next.
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
    /// Contact stopped the robot this period, where the backend can tell
    /// (in the reading handed to `decide`, as far as the robot knows at the
    /// period's start).
    pub blocked: bool,
    /// A sensor the robot steers by went silent: the backend has stopped
    /// the wheels, and the executive hands back.
    pub fault: Option<String>,
}

/// A robot the agent can drive.
pub trait RobotBackend {
    /// The control period (s).
    fn period_s(&self) -> f64;
    /// One control period: reads what the robot sensed, asks `decide` for
    /// the wheel speeds (left, right, rad/s) on that reading, and sends them
    /// at once. A fault the backend detects itself (`Reading::fault`) sends
    /// zero whatever `decide` says. Returns the period's reading, its
    /// `record.cmd_wheel_rad_s` the command sent; `None` when the backend
    /// can run no longer.
    fn step(&mut self, decide: &mut dyn FnMut(&Reading) -> [f64; 2]) -> Option<Reading>;
    /// Commands the wheels to stand still for one period in which the agent
    /// drives no plan (after a stop, between plans). Returns whether the
    /// robot needs to go on hearing it every period: a robot's motor
    /// drivers that hold their last command (or keep it until their own
    /// timeout) must be told zero again and again; a simulated site, which
    /// does not move between steps, needs nothing (the default).
    fn hold(&mut self) -> bool {
        false
    }
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
    /// Whether contact stopped the robot in the last period.
    blocked: bool,
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
            blocked: false,
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

    fn step(&mut self, decide: &mut dyn FnMut(&Reading) -> [f64; 2]) -> Option<Reading> {
        // The simulator senses at the period's start, then asks for the
        // period's command: the reading is made there, handed to `decide`,
        // and its answer drives this same period.
        let Self {
            sim,
            out,
            latest,
            blocked,
            ..
        } = self;
        let mut reading = None;
        let stepped = sim.step_with(out, &mut |s: &Sensed| {
            for (latest, &now) in latest.iter_mut().zip(s.ranges_m) {
                if !now.is_nan() {
                    *latest = now;
                }
            }
            let r = Reading {
                t_s: s.t_ns as f64 * 1e-9,
                encoder_ticks: s.encoder_ticks,
                bump: s.bump,
                ranges_m: latest.clone(),
                pose: s.tracker,
                // Completed once the period has run.
                record: StepRecord::default(),
                fresh_ranges_m: s.ranges_m.to_vec(),
                blocked: *blocked,
                fault: None,
            };
            let wheels = decide(&r);
            reading = Some(r);
            wheels
        });
        if !stepped {
            return None;
        }
        let mut reading = reading.expect("the simulator asks for every step's command");
        let record = &self.out.record;
        self.travel_rad += (record.wheel_rad_s[0].abs() + record.wheel_rad_s[1].abs())
            * self.sim.scenario().dt_s();
        self.blocked = self.out.blocked;
        reading.record = *record;
        reading.blocked = self.out.blocked;
        Some(reading)
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
