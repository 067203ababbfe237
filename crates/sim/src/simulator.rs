//! The stepping code. All scenario data lives in [`Scenario`]; the simulator
//! holds only the evolving state, random streams and scratch buffers.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use twindrive_kinematics::{Pose, arc_step, body_increment, wrap_angle};
use twindrive_log::{MissionLog, StepRecord};

use crate::controller::{Controller, Observation, WallMode};
use crate::scan::{Fan, ScanKernel};
use crate::{Scenario, Vector};

/// Iterations of the contact bisection: resolves the stopping point to
/// 2^-30 of one step's travel.
const CONTACT_BISECTIONS: u32 = 30;

/// Random streams, one per noise source so that adding a sensor does not
/// change the noise of the others. Range sensors use a stream named after
/// the sensor, so their order in the file does not matter either, and their
/// dropouts one named after the sensor too (`<name>.dropout`: no sensor
/// name has a dot), so dropouts leave the range noise as it was.
const STREAM_SLIP: u64 = 1;
const STREAM_TRACKER: u64 = 2;
const STREAM_GYRO: u64 = 3;

/// FNV-1a of the sensor name, with the top bit set to stay clear of the
/// fixed streams above.
fn named_stream(name: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in name.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h | (1 << 63)
}

/// One step's outputs, reused from step to step.
#[derive(Debug, Clone)]
pub struct StepOutput {
    pub record: StepRecord,
    /// Every beam of every range sensor; NaN where a sensor did not sample.
    pub ranges: Vec<f64>,
    pub wall_mode: Option<WallMode>,
    /// A wall stopped the robot during this step (a collision).
    pub blocked: bool,
}

/// Contact over a run, step by step: bump presses and periods of contact
/// that stopped the robot (each counted once, at its start), and the time
/// spent stopped by contact.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Contacts {
    pub bumps: u32,
    pub collisions: u32,
    pub contact_s: f64,
    was_bumped: bool,
    was_blocked: bool,
}

impl Contacts {
    /// One step of `dt_s`: the bumper's state and whether contact stopped
    /// the robot.
    pub fn record(&mut self, bump: bool, blocked: bool, dt_s: f64) {
        if bump && !self.was_bumped {
            self.bumps += 1;
        }
        if blocked && !self.was_blocked {
            self.collisions += 1;
        }
        if blocked {
            self.contact_s += dt_s;
        }
        (self.was_bumped, self.was_blocked) = (bump, blocked);
    }
}

/// A controller outside the simulator: sensor readings in, wheel commands
/// [left, right] (rad/s) out.
pub type ExternalControl<'c> = dyn FnMut(&Sensed) -> [f64; 2] + 'c;

/// What an external controller sees at a step ([`Simulator::step_with`]):
/// the robot's own sensors, never the true pose.
#[derive(Debug, Clone, Copy)]
pub struct Sensed<'a> {
    pub t_ns: u64,
    pub bump: bool,
    /// Cumulative encoder counts, when the encoders sampled.
    pub encoder_ticks: Option<[i64; 2]>,
    /// The external tracker's pose, when it sampled.
    pub tracker: Option<Pose>,
    /// The latest first-beam reading of each range sensor.
    pub latest_range_m: &'a [f64],
    /// Every beam read at this step (NaN where a sensor did not sample).
    pub ranges_m: &'a [f64],
}

impl StepOutput {
    pub fn new(beams: usize) -> Self {
        Self {
            record: StepRecord {
                t_ns: 0,
                cmd_wheel_rad_s: [0.0; 2],
                wheel_rad_s: [0.0; 2],
                encoder_ticks: None,
                bump: false,
                tracker: None,
                ground_truth: Pose::default(),
                gyro_z_rad_s: None,
            },
            ranges: vec![f64::NAN; beams],
            wall_mode: None,
            blocked: false,
        }
    }
}

struct RangeState {
    kernel: Option<ScanKernel>,
    rng: ChaCha8Rng,
    dropout_rng: ChaCha8Rng,
    next_ns: u64,
    offset: usize,
}

/// The kernel for a sensor's beams (`None` for a single beam: one ray).
fn range_kernel(info: &twindrive_log::RangeSensorInfo) -> Option<ScanKernel> {
    let (angle_min_rad, increment_rad) = info.angle_min_and_increment();
    (info.beams > 1).then(|| {
        ScanKernel::new(Fan {
            angle_min_rad,
            increment_rad,
            beams: info.beams as usize,
        })
    })
}

/// Noise-free ranges of one sensor's beams from the robot at `pose`.
fn cast_beams(
    world: &crate::World,
    info: &twindrive_log::RangeSensorInfo,
    kernel: Option<&mut ScanKernel>,
    pose: &Pose,
    beams: &mut [f64],
) {
    let m = &info.mount;
    let (ox, oy) = pose.transform_point(m.x_m, m.y_m);
    let origin = Vector::new(ox, oy);
    let heading = pose.heading_rad + m.heading_rad;
    let max = info.max_range_m;
    match kernel {
        None => {
            let dir = Vector::new(heading.cos(), heading.sin());
            beams[0] = world.cast_ray(origin, dir, max);
        }
        Some(kernel) => kernel.scan(world, origin, heading, max, beams),
    }
}

/// Whether the bumper of the scenario's robot touches a wall at `pose`.
fn bumper_pressed(scenario: &Scenario, pose: &Pose) -> bool {
    let robot = &scenario.robot;
    let bump = &scenario.bump;
    let p = Vector::new(pose.x_m, pose.y_m);
    match scenario
        .world
        .nearest_within(p, robot.footprint_radius_m + bump.contact_margin_m)
    {
        None => false,
        Some(n) => {
            let d = n.point - p;
            let bearing = wrap_angle(d.y.atan2(d.x) - pose.heading_rad);
            bearing.abs() <= 0.5 * bump.arc_rad
        }
    }
}

/// Noise-free readings of every beam of `sensors` from the robot at `pose`
/// in `world`: the maximum range where nothing is in reach, the minimum
/// where something is closer. The one implementation the twin's
/// [`SensorModel`] and the robot's [`RangeModel`] share, so the two predict
/// the same bits.
fn predict_ranges<'s>(
    world: &crate::World,
    sensors: impl Iterator<Item = &'s twindrive_log::RangeSensorInfo>,
    kernels: &mut [Option<ScanKernel>],
    pose: &Pose,
    ranges: &mut [f64],
) {
    let mut offset = 0;
    for (info, kernel) in sensors.zip(kernels) {
        let n = info.beams as usize;
        let beams = &mut ranges[offset..offset + n];
        offset += n;
        cast_beams(world, info, kernel.as_mut(), pose, beams);
        let max = info.max_range_m;
        for r in beams.iter_mut() {
            if *r < max {
                *r = r.max(info.min_range_m);
            }
        }
    }
}

/// Noise-free readings of a scenario's sensors at any pose: what the twin
/// expects the robot to read there.
pub struct SensorModel<'a> {
    scenario: &'a Scenario,
    kernels: Vec<Option<ScanKernel>>,
    beams: usize,
}

impl<'a> SensorModel<'a> {
    pub fn new(scenario: &'a Scenario) -> Self {
        let kernels = scenario
            .range_sensors
            .iter()
            .map(|s| range_kernel(&s.info))
            .collect();
        Self {
            scenario,
            kernels,
            beams: scenario
                .range_sensors
                .iter()
                .map(|s| s.info.beams as usize)
                .sum(),
        }
    }

    /// Beams over all range sensors (the length `read` fills).
    pub fn beams(&self) -> usize {
        self.beams
    }

    /// Fills `ranges` (every beam of every sensor; the maximum range where
    /// nothing is in reach, the minimum where something is closer) and
    /// returns whether the bumper is pressed.
    pub fn read(&mut self, pose: &Pose, ranges: &mut [f64]) -> bool {
        predict_ranges(
            &self.scenario.world,
            self.scenario.range_sensors.iter().map(|s| &s.info),
            &mut self.kernels,
            pose,
            ranges,
        );
        bumper_pressed(self.scenario, pose)
    }

    /// Whether the bumper is pressed at `pose`.
    pub fn bump(&self, pose: &Pose) -> bool {
        bumper_pressed(self.scenario, pose)
    }
}

/// Noise-free range readings from a world and the robot's sensors alone
/// (no scenario): what a robot carrying its site's map predicts it will
/// read. Built from the same walls as the twin's world it gives the twin's
/// [`SensorModel`] readings bit for bit.
#[derive(Debug, Clone)]
pub struct RangeModel {
    world: crate::World,
    sensors: Vec<twindrive_log::RangeSensorInfo>,
    kernels: Vec<Option<ScanKernel>>,
    beams: usize,
}

impl RangeModel {
    pub fn new(world: crate::World, sensors: &[twindrive_log::RangeSensorInfo]) -> Self {
        Self {
            world,
            kernels: sensors.iter().map(range_kernel).collect(),
            beams: sensors.iter().map(|s| s.beams as usize).sum(),
            sensors: sensors.to_vec(),
        }
    }

    pub fn world(&self) -> &crate::World {
        &self.world
    }

    pub fn sensors(&self) -> &[twindrive_log::RangeSensorInfo] {
        &self.sensors
    }

    /// Beams over all range sensors (the length `read` fills).
    pub fn beams(&self) -> usize {
        self.beams
    }

    /// Fills `ranges` with every beam's noise-free reading at `pose`.
    pub fn read(&mut self, pose: &Pose, ranges: &mut [f64]) {
        predict_ranges(
            &self.world,
            self.sensors.iter(),
            &mut self.kernels,
            pose,
            ranges,
        );
    }
}

/// Steps a [`Scenario`] forward in time.
pub struct Simulator {
    scenario: Scenario,
    step: u64,
    pose: Pose,
    wheel_rad_s: [f64; 2],
    wheel_angle_rad: [f64; 2],
    controller: Controller,
    slip_rng: ChaCha8Rng,
    tracker_rng: ChaCha8Rng,
    gyro_rng: ChaCha8Rng,
    ranges: Vec<RangeState>,
    latest_range_m: Vec<f64>,
    next_encoder_ns: u64,
    next_tracker_ns: u64,
    next_gyro_ns: u64,
    /// The true yaw rate over the last step (heading change / dt).
    yaw_rate_rad_s: f64,
    beams: usize,
}

fn stream(seed: u64, id: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(id);
    rng
}

/// Advances a sample schedule past `t_ns`; true if a sample is due at `t_ns`.
#[inline]
fn due(next_ns: &mut u64, period_ns: u64, t_ns: u64) -> bool {
    if t_ns < *next_ns {
        return false;
    }
    while *next_ns <= t_ns {
        *next_ns += period_ns;
    }
    true
}

impl Simulator {
    pub fn new(scenario: Scenario) -> Self {
        let mut offset = 0;
        let ranges = scenario
            .range_sensors
            .iter()
            .map(|s| {
                let state = RangeState {
                    kernel: range_kernel(&s.info),
                    rng: stream(scenario.seed, named_stream(&s.info.name)),
                    dropout_rng: stream(
                        scenario.seed,
                        named_stream(&format!("{}.dropout", s.info.name)),
                    ),
                    next_ns: 0,
                    offset,
                };
                offset += s.info.beams as usize;
                state
            })
            .collect();
        Self {
            step: 0,
            pose: scenario.robot.start,
            wheel_rad_s: [0.0; 2],
            wheel_angle_rad: [0.0; 2],
            controller: Controller::new(&scenario.controller),
            slip_rng: stream(scenario.seed, STREAM_SLIP),
            tracker_rng: stream(scenario.seed, STREAM_TRACKER),
            gyro_rng: stream(scenario.seed, STREAM_GYRO),
            latest_range_m: scenario
                .range_sensors
                .iter()
                .map(|s| s.info.max_range_m)
                .collect(),
            ranges,
            next_encoder_ns: 0,
            next_tracker_ns: 0,
            next_gyro_ns: 0,
            yaw_rate_rad_s: 0.0,
            beams: offset,
            scenario,
        }
    }

    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// True pose now.
    pub fn pose(&self) -> Pose {
        self.pose
    }

    /// Total beams over all range sensors (the length of [`StepOutput::ranges`]).
    pub fn beams(&self) -> usize {
        self.beams
    }

    pub fn finished(&self) -> bool {
        self.step >= self.scenario.steps
    }

    /// Cumulative true wheel rotation [left, right] in radians.
    pub fn wheel_angle_rad(&self) -> [f64; 2] {
        self.wheel_angle_rad
    }

    /// Senses at the current time, runs the controller, then moves the robot
    /// over one time step. Returns false (and does nothing) once the
    /// scenario's duration is reached.
    pub fn step(&mut self, out: &mut StepOutput) -> bool {
        self.step_inner(out, None)
    }

    /// Like [`Simulator::step`], with the wheel commands coming from `control`
    /// instead of the scenario's controller (plans, path trackers).
    pub fn step_with(&mut self, out: &mut StepOutput, control: &mut ExternalControl) -> bool {
        self.step_inner(out, Some(control))
    }

    fn step_inner(&mut self, out: &mut StepOutput, external: Option<&mut ExternalControl>) -> bool {
        if self.finished() {
            return false;
        }
        let t_ns = self.step * self.scenario.dt_ns;
        let bump = self.bumper_pressed();
        self.sense_ranges(t_ns, &mut out.ranges);

        let sc = &self.scenario;
        let encoder_ticks = due(&mut self.next_encoder_ns, sc.encoder_period_ns, t_ns).then(|| {
            [
                sc.robot.encoder.ticks_for_angle(self.wheel_angle_rad[0]),
                sc.robot.encoder.ticks_for_angle(self.wheel_angle_rad[1]),
            ]
        });
        let tracker = self.sense_tracker(t_ns);
        let gyro_z_rad_s = self.sense_gyro(t_ns);

        let external_control = external.is_some();
        let mut cmd = match external {
            Some(control) => control(&Sensed {
                t_ns,
                bump,
                encoder_ticks,
                tracker,
                latest_range_m: &self.latest_range_m,
                ranges_m: &out.ranges,
            }),
            None => {
                let obs = Observation {
                    t_ns,
                    bump,
                    latest_range_m: &self.latest_range_m,
                };
                self.controller
                    .command(&obs, &self.scenario.robot.nominal_params)
            }
        };
        // Saturate by scaling both wheels, which keeps the commanded curvature.
        let max = self.scenario.robot.max_wheel_speed_rad_s;
        let peak = cmd[0].abs().max(cmd[1].abs());
        if peak > max {
            cmd = [cmd[0] * max / peak, cmd[1] * max / peak];
        }

        out.record = StepRecord {
            t_ns,
            cmd_wheel_rad_s: cmd,
            wheel_rad_s: [0.0; 2],
            encoder_ticks,
            bump,
            tracker,
            ground_truth: self.pose,
            gyro_z_rad_s,
        };
        let (reached, blocked) = self.advance(cmd);
        out.record.wheel_rad_s = reached;
        out.blocked = blocked;
        out.wall_mode = if external_control {
            None
        } else {
            self.controller.wall_mode()
        };
        self.step += 1;
        true
    }

    /// Runs to the end, calling `progress(step, total)` now and then.
    pub fn run(mut self, mut progress: impl FnMut(u64, u64)) -> MissionLog {
        let total = self.scenario.steps;
        let mut log = MissionLog::new(self.scenario.log_header());
        log.steps.reserve(total as usize);
        log.ranges.reserve(total as usize * self.beams);
        let mut out = StepOutput::new(self.beams);
        while self.step(&mut out) {
            log.steps.push(out.record);
            log.ranges.extend_from_slice(&out.ranges);
            if self.step.is_multiple_of(8192) {
                progress(self.step, total);
            }
        }
        progress(total, total);
        log
    }

    fn bumper_pressed(&self) -> bool {
        bumper_pressed(&self.scenario, &self.pose)
    }

    fn sense_ranges(&mut self, t_ns: u64, out: &mut [f64]) {
        let world = &self.scenario.world;
        for (i, (cfg, st)) in self
            .scenario
            .range_sensors
            .iter()
            .zip(&mut self.ranges)
            .enumerate()
        {
            let beams = &mut out[st.offset..st.offset + cfg.info.beams as usize];
            if !due(&mut st.next_ns, cfg.period_ns, t_ns) {
                beams.fill(f64::NAN);
                continue;
            }
            cast_beams(world, &cfg.info, st.kernel.as_mut(), &self.pose, beams);
            let max = cfg.info.max_range_m;
            for r in beams.iter_mut() {
                if *r < max {
                    let noise = if cfg.noise_std_m > 0.0 {
                        cfg.noise_std_m * st.rng.sample::<f64, _>(StandardNormal)
                    } else {
                        0.0
                    };
                    *r = (*r + noise).clamp(cfg.info.min_range_m, max);
                }
                // Every beam draws, hit or miss, so the dropouts do not
                // depend on what the sensor sees.
                if cfg.dropout_probability > 0.0
                    && st.dropout_rng.random::<f64>() < cfg.dropout_probability
                {
                    *r = max;
                }
            }
            self.latest_range_m[i] = beams[0];
        }
    }

    fn sense_tracker(&mut self, t_ns: u64) -> Option<Pose> {
        let cfg = self.scenario.tracker.as_ref()?;
        if !due(&mut self.next_tracker_ns, cfg.period_ns, t_ns) {
            return None;
        }
        let rng = &mut self.tracker_rng;
        let mut n = || rng.sample::<f64, _>(StandardNormal);
        let noisy = Pose::new(
            self.pose.x_m + cfg.position_noise_std_m * n(),
            self.pose.y_m + cfg.position_noise_std_m * n(),
            wrap_angle(self.pose.heading_rad + cfg.heading_noise_std_rad * n()),
        );
        // Draw the dropout after the noise so the noise sequence does not
        // depend on the dropout rate.
        let dropped =
            cfg.dropout_probability > 0.0 && rng.random::<f64>() < cfg.dropout_probability;
        (!dropped).then_some(noisy)
    }

    /// The gyro's reading of the true yaw rate over the last step, when it
    /// samples at `t_ns`.
    fn sense_gyro(&mut self, t_ns: u64) -> Option<f64> {
        let cfg = self.scenario.gyro.as_ref()?;
        if !due(&mut self.next_gyro_ns, cfg.period_ns, t_ns) {
            return None;
        }
        let noise = if cfg.noise_std_rad_s > 0.0 {
            cfg.noise_std_rad_s * self.gyro_rng.sample::<f64, _>(StandardNormal)
        } else {
            0.0
        };
        Some((1.0 + cfg.scale_error) * self.yaw_rate_rad_s + cfg.bias_rad_s + noise)
    }

    /// Applies the wheel limits, moves the robot along the exact arc and stops
    /// it at first contact with a wall. Returns the wheel speeds reached and
    /// whether a wall stopped the robot.
    fn advance(&mut self, cmd: [f64; 2]) -> ([f64; 2], bool) {
        let robot = &self.scenario.robot;
        let dt_s = self.scenario.dt_s();
        let max_change = robot.max_wheel_accel_rad_s2 * dt_s;
        let mut w = [0.0; 2];
        for i in 0..2 {
            w[i] =
                self.wheel_rad_s[i] + (cmd[i] - self.wheel_rad_s[i]).clamp(-max_change, max_change);
        }
        let rotation = [w[0] * dt_s, w[1] * dt_s];
        let (mut slip_l, mut slip_r) = (1.0, 1.0);
        if robot.slip_std > 0.0 {
            slip_l += robot.slip_std * self.slip_rng.sample::<f64, _>(StandardNormal);
            slip_r += robot.slip_std * self.slip_rng.sample::<f64, _>(StandardNormal);
        }
        let p = &robot.true_params;
        let left_m = 0.5 * p.left_diameter_m * rotation[0] * slip_l;
        let right_m = 0.5 * p.right_diameter_m * rotation[1] * slip_r;
        let (ds, dtheta) = body_increment(left_m, right_m, p.wheelbase_m);

        let radius = robot.footprint_radius_m;
        let world = &self.scenario.world;
        let clear = |pose: &Pose| {
            world
                .nearest_within(Vector::new(pose.x_m, pose.y_m), radius)
                .is_none_or(|n| n.distance_m >= radius)
        };
        let target = arc_step(&self.pose, ds, dtheta);
        let fraction = if clear(&target) {
            1.0
        } else {
            // Largest fraction of the step that keeps the footprint clear.
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..CONTACT_BISECTIONS {
                let mid = 0.5 * (lo + hi);
                if clear(&arc_step(&self.pose, mid * ds, mid * dtheta)) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            lo
        };
        self.pose = if fraction == 1.0 {
            target
        } else {
            // Blocked: the wheels stall where the body stopped.
            w = [w[0] * fraction, w[1] * fraction];
            arc_step(&self.pose, fraction * ds, fraction * dtheta)
        };
        self.wheel_angle_rad[0] += rotation[0] * fraction;
        self.wheel_angle_rad[1] += rotation[1] * fraction;
        self.wheel_rad_s = w;
        self.yaw_rate_rad_s = fraction * dtheta / dt_s;
        (w, fraction < 1.0)
    }
}
