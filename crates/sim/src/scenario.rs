//! Scenario files: TOML as written by people, parsed strictly (unknown keys
//! are errors), then resolved into checked values before any simulation runs.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use twindrive_kinematics::{DiffDriveParams, Pose};

use crate::SimError;

/// A scenario as written in its TOML file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    pub name: String,
    #[serde(default)]
    pub description: String,
    pub simulation: SimulationSection,
    pub world: WorldSection,
    pub robot: RobotSection,
    #[serde(default)]
    pub encoders: EncoderSection,
    #[serde(default)]
    pub range_sensors: Vec<RangeSensorSection>,
    #[serde(default)]
    pub bump: BumpSection,
    pub tracker: Option<TrackerSection>,
    pub gyro: Option<GyroSection>,
    pub controller: ControllerSection,
    /// A robot site's ROS 2 drivers (`twindrive robot` reads this section
    /// itself; the simulator ignores it).
    pub ros: Option<toml::Table>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationSection {
    pub duration_s: f64,
    pub dt_s: f64,
    pub seed: u64,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldSection {
    /// Single wall segments `[[x0, y0], [x1, y1]]`.
    #[serde(default)]
    pub segments: Vec<[[f64; 2]; 2]>,
    #[serde(default)]
    pub polylines: Vec<PolylineSpec>,
    /// Solid axis-aligned blocks.
    #[serde(default)]
    pub rectangles: Vec<RectangleSpec>,
    /// A ROS map_server YAML file, relative to the scenario file.
    pub map: Option<PathBuf>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolylineSpec {
    pub points: Vec<[f64; 2]>,
    #[serde(default)]
    pub closed: bool,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RectangleSpec {
    pub min: [f64; 2],
    pub max: [f64; 2],
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSection {
    pub start: Pose,
    pub footprint_radius_m: f64,
    /// The hidden truth the twin simulates.
    pub true_params: DiffDriveParams,
    /// What the operator believes; controllers use these.
    pub nominal_params: DiffDriveParams,
    pub max_wheel_speed_rad_s: f64,
    pub max_wheel_accel_rad_s2: f64,
    /// Relative standard deviation of each wheel's ground travel per step.
    #[serde(default)]
    pub slip_std: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncoderSection {
    #[serde(default = "default_ticks")]
    pub ticks_per_rev: u32,
    /// Sampling rate; absent means every simulation step.
    pub rate_hz: Option<f64>,
}

fn default_ticks() -> u32 {
    512
}

impl Default for EncoderSection {
    fn default() -> Self {
        Self {
            ticks_per_rev: default_ticks(),
            rate_hz: None,
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RangeSensorSection {
    pub name: String,
    /// `"ranger"` (one beam: IR, ultrasound, time of flight) or `"lidar"`
    /// (a fan of beams). Absent: a ranger for one beam, a lidar for more
    /// (what sites written before `kind` existed meant).
    pub kind: Option<twindrive_log::SensorKind>,
    /// Mount pose in the body frame.
    pub mount: Pose,
    #[serde(default = "one")]
    pub beams: u32,
    #[serde(default)]
    pub fov_rad: f64,
    #[serde(default)]
    pub min_range_m: f64,
    pub max_range_m: f64,
    #[serde(default)]
    pub noise_std_m: f64,
    /// Sampling rate; absent means every simulation step.
    pub rate_hz: Option<f64>,
    /// Probability that any one beam returns nothing (read as `max_range_m`).
    #[serde(default)]
    pub dropout_probability: f64,
}

fn one() -> u32 {
    1
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BumpSection {
    /// Angular width of the bumper, centred on the robot's front.
    #[serde(default = "default_bump_arc")]
    pub arc_rad: f64,
    /// Contact is reported within this distance of the footprint edge.
    #[serde(default = "default_contact_margin")]
    pub contact_margin_m: f64,
}

/// A bumper all round by default.
fn default_bump_arc() -> f64 {
    std::f64::consts::TAU
}

fn default_contact_margin() -> f64 {
    0.002
}

impl Default for BumpSection {
    fn default() -> Self {
        Self {
            arc_rad: default_bump_arc(),
            contact_margin_m: default_contact_margin(),
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackerSection {
    pub rate_hz: f64,
    #[serde(default)]
    pub position_noise_std_m: f64,
    #[serde(default)]
    pub heading_noise_std_rad: f64,
    /// Probability that any one sample is lost.
    #[serde(default)]
    pub dropout_probability: f64,
}

/// A yaw-rate gyro: measured = (1 + `scale_error`) · true + `bias_rad_s` + noise.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GyroSection {
    #[serde(default = "default_gyro_name")]
    pub name: String,
    pub rate_hz: f64,
    #[serde(default)]
    pub noise_std_rad_s: f64,
    #[serde(default)]
    pub bias_rad_s: f64,
    /// Relative error of the rate scale (0.01: reads 1 % high).
    #[serde(default)]
    pub scale_error: f64,
}

fn default_gyro_name() -> String {
    "gyro".into()
}

#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ControllerSection {
    /// The paper's wall follower: bump -> reverse -> turn left -> P control
    /// on the side range sensor.
    WallFollower(WallFollowerSpec),
    /// Fixed wheel-speed segments (calibration drives).
    Scripted(ScriptedSpec),
    /// Timed (v, ω) commands from a CSV file, as an operator's keys produce.
    Manual(ManualSpec),
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallFollowerSpec {
    pub side_sensor: String,
    pub target_range_m: f64,
    pub cruise_speed_m_s: f64,
    pub gain_rad_s_per_m: f64,
    pub max_turn_rate_rad_s: f64,
    pub reverse_speed_m_s: f64,
    pub reverse_duration_s: f64,
    pub turn_rate_rad_s: f64,
    pub turn_duration_s: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptedSpec {
    pub segments: Vec<WheelSegment>,
    #[serde(default)]
    pub repeat: bool,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WheelSegment {
    pub duration_s: f64,
    pub left_rad_s: f64,
    pub right_rad_s: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ManualSpec {
    /// CSV with header `t_s,v_m_s,omega_rad_s`, relative to the scenario file.
    pub commands: PathBuf,
}

impl ScenarioFile {
    /// Parses TOML text; `path` labels errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, SimError> {
        toml::from_str(text).map_err(|e| SimError::Scenario {
            path: path.to_path_buf(),
            message: e.to_string().trim_end().to_string(),
        })
    }
}

/// Checks that a value is finite and > 0, naming the field otherwise.
pub(crate) fn require_positive(path: &Path, field: &str, value: f64) -> Result<(), SimError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SimError::field(
            path,
            field,
            format!("must be a finite number > 0, got {value}"),
        ))
    }
}

/// Checks that a value is finite and >= 0, naming the field otherwise.
pub(crate) fn require_non_negative(path: &Path, field: &str, value: f64) -> Result<(), SimError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(SimError::field(
            path,
            field,
            format!("must be a finite number >= 0, got {value}"),
        ))
    }
}

pub(crate) fn require_finite(path: &Path, field: &str, values: &[f64]) -> Result<(), SimError> {
    match values.iter().find(|v| !v.is_finite()) {
        None => Ok(()),
        Some(v) => Err(SimError::field(
            path,
            field,
            format!("must be finite, got {v}"),
        )),
    }
}

pub(crate) fn validate_params(
    path: &Path,
    section: &str,
    p: &DiffDriveParams,
) -> Result<(), SimError> {
    p.validate().map_err(|e| {
        SimError::field(
            path,
            &format!("{section}.{}", e.field),
            format!("must be a finite number > 0, got {}", e.value),
        )
    })
}
