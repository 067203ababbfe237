//! A scenario resolved into checked, typed values: the world built, the map
//! and command files loaded, rates turned into sample periods.

use std::path::{Path, PathBuf};

use parry2d_f64::bounding_volume::Aabb;
use parry2d_f64::math::Vector;
use twindrive_kinematics::{DiffDriveParams, EncoderSpec, Pose, SensorKind};
use twindrive_log::{
    GyroInfo, LOG_FORMAT, LOG_VERSION, LogHeader, RangeSensorInfo, ns_from_seconds,
};

use crate::manual::{ManualCommand, read_manual_commands};
use crate::scenario::{
    BumpSection, ControllerSection, GyroSection, ScenarioFile, ScriptedSpec, TrackerSection,
    WallFollowerSpec, require_finite, require_non_negative, require_positive, validate_params,
};
use crate::world::{World, polyline_segments, rectangle_segments};
use crate::{SimError, map};

/// A scenario ready to simulate.
#[derive(Debug, Clone)]
pub struct Scenario {
    pub name: String,
    pub description: String,
    pub seed: u64,
    pub dt_ns: u64,
    pub steps: u64,
    pub world: World,
    pub robot: RobotConfig,
    pub encoder_period_ns: u64,
    pub range_sensors: Vec<RangeSensorConfig>,
    pub bump: BumpSection,
    pub tracker: Option<TrackerConfig>,
    pub gyro: Option<GyroConfig>,
    pub controller: ControllerConfig,
}

#[derive(Debug, Clone)]
pub struct RobotConfig {
    pub start: Pose,
    pub footprint_radius_m: f64,
    pub true_params: DiffDriveParams,
    pub nominal_params: DiffDriveParams,
    pub encoder: EncoderSpec,
    pub max_wheel_speed_rad_s: f64,
    pub max_wheel_accel_rad_s2: f64,
    pub slip_std: f64,
}

#[derive(Debug, Clone)]
pub struct RangeSensorConfig {
    pub info: RangeSensorInfo,
    pub noise_std_m: f64,
    pub period_ns: u64,
    /// Probability that a beam returns nothing (read as the maximum range).
    pub dropout_probability: f64,
}

#[derive(Debug, Clone)]
pub struct TrackerConfig {
    pub period_ns: u64,
    pub position_noise_std_m: f64,
    pub heading_noise_std_rad: f64,
    pub dropout_probability: f64,
}

/// A simulated gyro: what the log tells of it (`info`) and its hidden
/// errors, which stay with the twin like the true wheel parameters.
#[derive(Debug, Clone)]
pub struct GyroConfig {
    pub info: GyroInfo,
    pub period_ns: u64,
    pub noise_std_rad_s: f64,
    pub bias_rad_s: f64,
    pub scale_error: f64,
}

#[derive(Debug, Clone)]
pub enum ControllerConfig {
    WallFollower {
        spec: WallFollowerSpec,
        sensor: usize,
    },
    Scripted(ScriptedSpec),
    Manual(Vec<ManualCommand>),
}

impl Scenario {
    /// Reads, parses and resolves a scenario file.
    pub fn load(path: &Path) -> Result<Self, SimError> {
        let text = std::fs::read_to_string(path).map_err(|e| SimError::Io {
            path: path.to_path_buf(),
            source: e,
        })?;
        Self::from_toml(&text, path)
    }

    /// Parses and resolves TOML text; `path` labels errors and anchors
    /// relative file names (map, commands).
    pub fn from_toml(text: &str, path: &Path) -> Result<Self, SimError> {
        let file = ScenarioFile::parse(text, path)?;
        Self::resolve(file, path)
    }

    pub fn resolve(file: ScenarioFile, path: &Path) -> Result<Self, SimError> {
        let base = path.parent().unwrap_or(Path::new("."));
        let sim = &file.simulation;
        require_positive(path, "simulation.dt_s", sim.dt_s)?;
        require_positive(path, "simulation.duration_s", sim.duration_s)?;
        let dt_ns = ns_from_seconds(sim.dt_s)
            .filter(|&n| n >= 1000)
            .ok_or_else(|| {
                SimError::field(
                    path,
                    "simulation.dt_s",
                    format!("must be at least 1 µs, got {}", sim.dt_s),
                )
            })?;
        let steps = (sim.duration_s * 1e9 / dt_ns as f64).round() as u64;
        if steps == 0 || steps > 2_000_000_000 {
            return Err(SimError::field(
                path,
                "simulation.duration_s",
                format!("gives {steps} steps of dt_s; need 1 to 2e9"),
            ));
        }
        let period = |field: &str, rate: Option<f64>| -> Result<u64, SimError> {
            match rate {
                None => Ok(dt_ns),
                Some(hz) => {
                    require_positive(path, field, hz)?;
                    Ok(((1e9 / hz).round() as u64).max(1))
                }
            }
        };

        let robot = resolve_robot(&file, path)?;
        let encoder_period_ns = period("encoders.rate_hz", file.encoders.rate_hz)?;

        let mut range_sensors = Vec::new();
        for (i, s) in file.range_sensors.iter().enumerate() {
            let f = |name: &str| format!("range_sensors[{i}].{name}");
            if !valid_sensor_name(&s.name) {
                return Err(SimError::field(
                    path,
                    &f("name"),
                    format!("must be non-empty letters, digits or `_`, got `{}`", s.name),
                ));
            }
            if file.range_sensors[..i].iter().any(|o| o.name == s.name) {
                return Err(SimError::field(
                    path,
                    &f("name"),
                    format!("`{}` is used twice", s.name),
                ));
            }
            require_positive(path, &f("max_range_m"), s.max_range_m)?;
            require_non_negative(path, &f("min_range_m"), s.min_range_m)?;
            if s.min_range_m >= s.max_range_m {
                return Err(SimError::field(
                    path,
                    &f("min_range_m"),
                    "must be below max_range_m".into(),
                ));
            }
            require_non_negative(path, &f("noise_std_m"), s.noise_std_m)?;
            require_probability(path, &f("dropout_probability"), s.dropout_probability)?;
            require_finite(
                path,
                &f("mount"),
                &[s.mount.x_m, s.mount.y_m, s.mount.heading_rad],
            )?;
            if s.beams == 0 || s.beams > 100_000 {
                return Err(SimError::field(
                    path,
                    &f("beams"),
                    format!("must be 1 to 100000, got {}", s.beams),
                ));
            }
            if s.beams > 1 && !(s.fov_rad > 0.0 && s.fov_rad <= std::f64::consts::TAU) {
                return Err(SimError::field(
                    path,
                    &f("fov_rad"),
                    format!(
                        "must be in (0, 2π] for a multi-beam sensor, got {}",
                        s.fov_rad
                    ),
                ));
            }
            let info = RangeSensorInfo::labelled_or_not(
                s.name.clone(),
                s.kind,
                s.mount,
                s.beams,
                s.fov_rad,
                [s.min_range_m, s.max_range_m],
            )
            .map_err(|e| SimError::field(path, &f("kind"), e))?;
            range_sensors.push(RangeSensorConfig {
                info,
                noise_std_m: s.noise_std_m,
                period_ns: period(&f("rate_hz"), s.rate_hz)?,
                dropout_probability: s.dropout_probability,
            });
        }

        require_positive(path, "bump.arc_rad", file.bump.arc_rad)?;
        if file.bump.arc_rad > std::f64::consts::TAU + 1e-9 {
            return Err(SimError::field(
                path,
                "bump.arc_rad",
                format!("must be at most 2π, got {}", file.bump.arc_rad),
            ));
        }
        // Contact leaves the footprint a hair outside the wall; a zero margin
        // would never see it.
        require_positive(path, "bump.contact_margin_m", file.bump.contact_margin_m)?;
        if file.bump.contact_margin_m >= robot.footprint_radius_m {
            return Err(SimError::field(
                path,
                "bump.contact_margin_m",
                "must be below robot.footprint_radius_m".into(),
            ));
        }
        // Walls are checked at the end of each step; a step shorter than half
        // the footprint radius cannot jump over one.
        let p = &robot.true_params;
        let max_step_m = robot.max_wheel_speed_rad_s
            * sim.dt_s
            * 0.5
            * p.left_diameter_m.max(p.right_diameter_m)
            * (1.0 + 5.0 * robot.slip_std);
        if max_step_m >= 0.5 * robot.footprint_radius_m {
            return Err(SimError::field(
                path,
                "simulation.dt_s",
                format!(
                    "is too long: at robot.max_wheel_speed_rad_s a wheel moves {max_step_m:.3} m per step, \
                 which must stay below half the footprint radius ({:.3} m)",
                    0.5 * robot.footprint_radius_m
                ),
            ));
        }

        let tracker = match &file.tracker {
            None => None,
            Some(t) => Some(resolve_tracker(
                t,
                path,
                period("tracker.rate_hz", Some(t.rate_hz))?,
            )?),
        };

        let gyro = match &file.gyro {
            None => None,
            Some(g) => Some(resolve_gyro(
                g,
                path,
                period("gyro.rate_hz", Some(g.rate_hz))?,
            )?),
        };

        let controller = match &file.controller {
            ControllerSection::WallFollower(spec) => {
                let sensor = range_sensors
                    .iter()
                    .position(|s| s.info.name == spec.side_sensor)
                    .ok_or_else(|| {
                        SimError::field(
                            path,
                            "controller.side_sensor",
                            format!("no range sensor is named `{}`", spec.side_sensor),
                        )
                    })?;
                let info = &range_sensors[sensor].info;
                if info.kind != SensorKind::Ranger {
                    return Err(SimError::field(
                        path,
                        "controller.side_sensor",
                        format!(
                            "`{}` is a {}; the wall follower holds its distance with a ranger (kind = \"ranger\")",
                            spec.side_sensor, info.kind
                        ),
                    ));
                }
                for (name, v) in [
                    ("target_range_m", spec.target_range_m),
                    ("cruise_speed_m_s", spec.cruise_speed_m_s),
                    ("gain_rad_s_per_m", spec.gain_rad_s_per_m),
                    ("max_turn_rate_rad_s", spec.max_turn_rate_rad_s),
                    ("reverse_speed_m_s", spec.reverse_speed_m_s),
                    ("reverse_duration_s", spec.reverse_duration_s),
                    ("turn_rate_rad_s", spec.turn_rate_rad_s),
                    ("turn_duration_s", spec.turn_duration_s),
                ] {
                    require_positive(path, &format!("controller.{name}"), v)?;
                }
                ControllerConfig::WallFollower {
                    spec: spec.clone(),
                    sensor,
                }
            }
            ControllerSection::Scripted(spec) => {
                if spec.segments.is_empty() {
                    return Err(SimError::field(
                        path,
                        "controller.segments",
                        "needs at least one segment".into(),
                    ));
                }
                for (i, seg) in spec.segments.iter().enumerate() {
                    require_positive(
                        path,
                        &format!("controller.segments[{i}].duration_s"),
                        seg.duration_s,
                    )?;
                    if seg.duration_s < sim.dt_s {
                        return Err(SimError::field(
                            path,
                            &format!("controller.segments[{i}].duration_s"),
                            format!(
                                "must be at least one time step ({} s), got {}",
                                sim.dt_s, seg.duration_s
                            ),
                        ));
                    }
                    require_finite(
                        path,
                        &format!("controller.segments[{i}]"),
                        &[seg.left_rad_s, seg.right_rad_s],
                    )?;
                }
                ControllerConfig::Scripted(spec.clone())
            }
            ControllerSection::Manual(spec) => {
                let commands_path = base.join(&spec.commands);
                ControllerConfig::Manual(read_manual_commands(&commands_path)?)
            }
        };

        let world = build_world(&file, path, base)?;
        let start = Vector::new(robot.start.x_m, robot.start.y_m);
        if world.inside_obstacle(start) {
            return Err(SimError::field(
                path,
                "robot.start",
                format!(
                    "({}, {}) is inside an obstacle",
                    robot.start.x_m, robot.start.y_m
                ),
            ));
        }
        if let Some(n) = world.nearest_within(start, robot.footprint_radius_m) {
            return Err(SimError::field(
                path,
                "robot.start",
                format!(
                    "the footprint (radius {} m) at ({}, {}) overlaps a wall: nearest wall point ({:.3}, {:.3}) is {:.3} m away",
                    robot.footprint_radius_m,
                    robot.start.x_m,
                    robot.start.y_m,
                    n.point.x,
                    n.point.y,
                    n.distance_m
                ),
            ));
        }

        Ok(Scenario {
            name: file.name,
            description: file.description,
            seed: sim.seed,
            dt_ns,
            steps,
            world,
            robot,
            encoder_period_ns,
            range_sensors,
            bump: file.bump,
            tracker,
            gyro,
            controller,
        })
    }

    /// Changes the duration, with the same checks as the scenario file's.
    pub fn set_duration_s(&mut self, duration_s: f64) -> Result<(), String> {
        self.steps = steps_for(duration_s, self.dt_ns)?;
        Ok(())
    }

    /// Bytes the in-memory log of this scenario needs, roughly.
    pub fn log_size_bytes(&self) -> u64 {
        let beams: u64 = self
            .range_sensors
            .iter()
            .map(|s| u64::from(s.info.beams))
            .sum();
        let per_step = std::mem::size_of::<twindrive_log::StepRecord>() as u64 + 8 * beams;
        self.steps.saturating_mul(per_step)
    }

    pub fn dt_s(&self) -> f64 {
        self.dt_ns as f64 * 1e-9
    }

    pub fn duration_s(&self) -> f64 {
        self.steps as f64 * self.dt_s()
    }

    /// The header of the log this scenario produces.
    pub fn log_header(&self) -> LogHeader {
        LogHeader {
            format: LOG_FORMAT.into(),
            version: LOG_VERSION,
            scenario: self.name.clone(),
            seed: self.seed,
            dt_s: self.dt_s(),
            ticks_per_rev: self.robot.encoder.ticks_per_rev,
            nominal: self.robot.nominal_params,
            footprint_radius_m: self.robot.footprint_radius_m,
            max_wheel_speed_rad_s: self.robot.max_wheel_speed_rad_s,
            max_wheel_accel_rad_s2: self.robot.max_wheel_accel_rad_s2,
            start: self.robot.start,
            range_sensors: self.range_sensors.iter().map(|s| s.info.clone()).collect(),
            gyro: self.gyro.as_ref().map(|g| g.info.clone()),
            goals: Default::default(),
        }
    }
}

/// Number of steps of `dt_ns` in `duration_s`, at most 2e9.
fn steps_for(duration_s: f64, dt_ns: u64) -> Result<u64, String> {
    if !(duration_s.is_finite() && duration_s > 0.0) {
        return Err(format!("must be a finite number > 0, got {duration_s}"));
    }
    let steps = (duration_s * 1e9 / dt_ns as f64).round();
    if !(1.0..=2e9).contains(&steps) {
        return Err(format!("gives {steps} steps of dt_s; need 1 to 2e9"));
    }
    Ok(steps as u64)
}

fn resolve_robot(file: &ScenarioFile, path: &Path) -> Result<RobotConfig, SimError> {
    let r = &file.robot;
    validate_params(path, "robot.true_params", &r.true_params)?;
    validate_params(path, "robot.nominal_params", &r.nominal_params)?;
    require_finite(
        path,
        "robot.start",
        &[r.start.x_m, r.start.y_m, r.start.heading_rad],
    )?;
    require_positive(path, "robot.footprint_radius_m", r.footprint_radius_m)?;
    require_positive(path, "robot.max_wheel_speed_rad_s", r.max_wheel_speed_rad_s)?;
    require_positive(
        path,
        "robot.max_wheel_accel_rad_s2",
        r.max_wheel_accel_rad_s2,
    )?;
    require_non_negative(path, "robot.slip_std", r.slip_std)?;
    if r.slip_std >= 0.5 {
        return Err(SimError::field(
            path,
            "robot.slip_std",
            format!("must be below 0.5, got {}", r.slip_std),
        ));
    }
    if file.encoders.ticks_per_rev == 0 {
        return Err(SimError::field(
            path,
            "encoders.ticks_per_rev",
            "must be > 0".into(),
        ));
    }
    Ok(RobotConfig {
        start: r.start,
        footprint_radius_m: r.footprint_radius_m,
        true_params: r.true_params,
        nominal_params: r.nominal_params,
        encoder: EncoderSpec {
            ticks_per_rev: file.encoders.ticks_per_rev,
        },
        max_wheel_speed_rad_s: r.max_wheel_speed_rad_s,
        max_wheel_accel_rad_s2: r.max_wheel_accel_rad_s2,
        slip_std: r.slip_std,
    })
}

fn resolve_tracker(
    t: &TrackerSection,
    path: &Path,
    period_ns: u64,
) -> Result<TrackerConfig, SimError> {
    require_non_negative(path, "tracker.position_noise_std_m", t.position_noise_std_m)?;
    require_non_negative(
        path,
        "tracker.heading_noise_std_rad",
        t.heading_noise_std_rad,
    )?;
    require_probability(path, "tracker.dropout_probability", t.dropout_probability)?;
    Ok(TrackerConfig {
        period_ns,
        position_noise_std_m: t.position_noise_std_m,
        heading_noise_std_rad: t.heading_noise_std_rad,
        dropout_probability: t.dropout_probability,
    })
}

/// Checks a dropout probability: in [0, 1).
fn require_probability(path: &Path, field: &str, p: f64) -> Result<(), SimError> {
    if (0.0..1.0).contains(&p) {
        Ok(())
    } else {
        Err(SimError::field(
            path,
            field,
            format!("must be in [0, 1), got {p}"),
        ))
    }
}

fn resolve_gyro(g: &GyroSection, path: &Path, period_ns: u64) -> Result<GyroConfig, SimError> {
    if !valid_sensor_name(&g.name) {
        return Err(SimError::field(
            path,
            "gyro.name",
            format!("must be non-empty letters, digits or `_`, got `{}`", g.name),
        ));
    }
    require_non_negative(path, "gyro.noise_std_rad_s", g.noise_std_rad_s)?;
    require_finite(path, "gyro.bias_rad_s", &[g.bias_rad_s])?;
    if !(g.scale_error.is_finite() && g.scale_error.abs() < 1.0) {
        return Err(SimError::field(
            path,
            "gyro.scale_error",
            format!(
                "must be a fraction in (-1, 1) (0.01 reads 1 % high), got {}",
                g.scale_error
            ),
        ));
    }
    Ok(GyroConfig {
        info: GyroInfo {
            name: g.name.clone(),
            rate_hz: g.rate_hz,
        },
        period_ns,
        noise_std_rad_s: g.noise_std_rad_s,
        bias_rad_s: g.bias_rad_s,
        scale_error: g.scale_error,
    })
}

/// Names of sensors (they become column, topic and frame names).
fn valid_sensor_name(name: &str) -> bool {
    !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

fn build_world(file: &ScenarioFile, path: &Path, base: &Path) -> Result<World, SimError> {
    let w = &file.world;
    let mut segments = Vec::new();
    let mut solids = Vec::new();
    for (i, s) in w.segments.iter().enumerate() {
        require_finite(
            path,
            &format!("world.segments[{i}]"),
            &[s[0][0], s[0][1], s[1][0], s[1][1]],
        )?;
        segments.extend(polyline_segments(s, false));
    }
    for (i, p) in w.polylines.iter().enumerate() {
        if p.points.len() < 2 {
            return Err(SimError::field(
                path,
                &format!("world.polylines[{i}].points"),
                "needs at least two points".into(),
            ));
        }
        let flat: Vec<f64> = p.points.iter().flatten().copied().collect();
        require_finite(path, &format!("world.polylines[{i}].points"), &flat)?;
        segments.extend(polyline_segments(&p.points, p.closed));
    }
    for (i, r) in w.rectangles.iter().enumerate() {
        require_finite(
            path,
            &format!("world.rectangles[{i}]"),
            &[r.min[0], r.min[1], r.max[0], r.max[1]],
        )?;
        if r.min[0] >= r.max[0] || r.min[1] >= r.max[1] {
            return Err(SimError::field(
                path,
                &format!("world.rectangles[{i}]"),
                "min must be below max in x and y".into(),
            ));
        }
        segments.extend(rectangle_segments(r.min, r.max));
        solids.push(Aabb::new(
            Vector::new(r.min[0], r.min[1]),
            Vector::new(r.max[0], r.max[1]),
        ));
    }
    let grid = match &w.map {
        None => None,
        Some(rel) => {
            let map_path: PathBuf = base.join(rel);
            if !map_path.is_file() {
                return Err(SimError::field(
                    path,
                    "world.map",
                    format!("map file `{}` does not exist", map_path.display()),
                ));
            }
            let grid = map::load_map(&map_path)?;
            segments.extend(grid.boundary_segments());
            Some(grid)
        }
    };
    if segments.is_empty() {
        return Err(SimError::field(
            path,
            "world",
            "has no walls: give segments, polylines, rectangles or a map".into(),
        ));
    }
    Ok(World::new(segments, solids, grid))
}
