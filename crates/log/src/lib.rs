//! Mission logs: what the twin recorded at every simulation step, and their
//! CSV, MCAP and TUM readers and writers.
//!
//! A [`MissionLog`] is a header plus one [`StepRecord`] per simulation step.
//! Sensors that sample slower than the simulation leave their fields empty
//! (`None`, or NaN for range readings) on the steps they did not sample.

pub mod calib_csv;
pub mod carmen;
mod csv_io;
pub mod digest;
mod error;
pub mod goals;
pub mod map_topic;
mod mcap_io;
mod time;
mod tum;

pub use csv_io::{read_csv, read_csv_from, write_csv};
pub use error::LogError;
pub use goals::{ReachedWaypoint, RehearsedGoals, SweptArea};
pub use map_topic::{MapGrid, WorldMap};
pub use mcap_io::{
    Track, is_mcap, read_mcap, read_mcap_bytes, write_mcap, write_mcap_with_map, write_tracks_mcap,
};
pub use time::{format_seconds, ns_from_seconds, push_seconds, seconds_from_ns};
pub use tum::{read_tum, write_tum};

use serde::{Deserialize, Serialize};
use twindrive_kinematics::{DiffDriveParams, Pose};

/// Identifies the header of a mission log.
pub const LOG_FORMAT: &str = "twindrive-mission-log";
/// Bumped whenever the meaning of a field or column changes.
pub const LOG_VERSION: u32 = 2;

/// Reads a log header written as JSON (`log.meta.json`).
pub fn read_header_json(path: &std::path::Path) -> Result<LogHeader, LogError> {
    let text = std::fs::read_to_string(path).map_err(|e| LogError::Io {
        path: path.into(),
        source: e,
    })?;
    let header: LogHeader = serde_json::from_str(&text).map_err(|e| LogError::Line {
        path: path.into(),
        line: e.line() as u64,
        message: e.to_string(),
    })?;
    if header.format != LOG_FORMAT || header.version != LOG_VERSION {
        return Err(LogError::Format {
            path: path.into(),
            message: format!(
                "is `{}` version {}, expected `{LOG_FORMAT}` version {LOG_VERSION}",
                header.format, header.version
            ),
        });
    }
    Ok(header)
}

/// Reads a simulator output directory: `log.meta.json` and `log.csv`.
pub fn read_log_dir(dir: &std::path::Path) -> Result<MissionLog, LogError> {
    let header = read_header_json(&dir.join("log.meta.json"))?;
    read_csv(&dir.join("log.csv"), &header)
}

/// A mission log: a directory `simulate` wrote, or a log MCAP (robot logs,
/// rehearsals).
pub fn read_mission_log(path: &std::path::Path) -> Result<MissionLog, LogError> {
    if path.is_dir() {
        read_log_dir(path)
    } else {
        read_mcap(path)
    }
}

/// What a reader needs to interpret the per-step records.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogHeader {
    pub format: String,
    pub version: u32,
    pub scenario: String,
    pub seed: u64,
    pub dt_s: f64,
    pub ticks_per_rev: u32,
    /// The parameters the operator believes (not the twin's hidden truth).
    pub nominal: DiffDriveParams,
    pub footprint_radius_m: f64,
    /// Wheel limits of the robot (the pipeline's plans must respect them).
    pub max_wheel_speed_rad_s: f64,
    pub max_wheel_accel_rad_s2: f64,
    /// Where the mission started: the operator places the robot, so this is
    /// known, unlike the path that followed.
    pub start: Pose,
    pub range_sensors: Vec<RangeSensorInfo>,
    /// The robot's gyro, if it has one; its readings are
    /// [`StepRecord::gyro_z_rad_s`]. Absent from headers without one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gyro: Option<GyroInfo>,
    /// The goals a rehearsal from goals reached, and when (absent from a
    /// manual rehearsal's header): the plan keeps them.
    #[serde(default, skip_serializing_if = "RehearsedGoals::is_empty")]
    pub goals: RehearsedGoals,
}

/// A yaw-rate gyro as the operator knows it: its name and rate. A simulated
/// gyro's bias, scale error and noise are the twin's hidden truth (like its
/// true wheel parameters) and stay in the scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GyroInfo {
    pub name: String,
    /// Sampling rate (Hz).
    pub rate_hz: f64,
}

impl LogHeader {
    /// Total beams over all range sensors.
    pub fn beams_per_step(&self) -> usize {
        self.range_sensors.iter().map(|s| s.beams as usize).sum()
    }

    /// Offset of each sensor's first beam within a step's readings.
    pub fn beam_offsets(&self) -> Vec<usize> {
        self.range_sensors
            .iter()
            .scan(0usize, |acc, s| {
                let start = *acc;
                *acc += s.beams as usize;
                Some(start)
            })
            .collect()
    }

    /// Index of the range sensor called `name`.
    pub fn sensor_index(&self, name: &str) -> Option<usize> {
        self.range_sensors.iter().position(|s| s.name == name)
    }
}

pub use twindrive_kinematics::{RangeSensorInfo, SensorKind};

/// Everything recorded at one simulation step.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepRecord {
    /// Simulation time; integer nanoseconds so that every format round-trips it exactly.
    pub t_ns: u64,
    /// Wheel angular speeds asked for by the controller, [left, right].
    pub cmd_wheel_rad_s: [f64; 2],
    /// Wheel angular speeds actually reached (after speed and acceleration limits).
    pub wheel_rad_s: [f64; 2],
    /// Cumulative encoder counts [left, right]; `None` when the encoders did not sample.
    pub encoder_ticks: Option<[i64; 2]>,
    pub bump: bool,
    /// External tracker pose; `None` when it did not sample or dropped out.
    pub tracker: Option<Pose>,
    pub ground_truth: Pose,
    /// Gyro reading of the yaw rate (rad/s, counter-clockwise positive);
    /// `None` when there is no gyro or it did not sample.
    pub gyro_z_rad_s: Option<f64>,
}

impl StepRecord {
    pub fn t_s(&self) -> f64 {
        seconds_from_ns(self.t_ns)
    }
}

/// A whole mission as recorded by the twin.
#[derive(Debug, Clone, PartialEq)]
pub struct MissionLog {
    pub header: LogHeader,
    pub steps: Vec<StepRecord>,
    /// Range readings, [`MissionLog::beams_per_step`] values per step in
    /// sensor order; NaN where that sensor did not sample at that step.
    pub ranges: Vec<f64>,
}

impl MissionLog {
    pub fn new(header: LogHeader) -> Self {
        Self {
            header,
            steps: Vec::new(),
            ranges: Vec::new(),
        }
    }

    /// Total beams over all range sensors.
    pub fn beams_per_step(&self) -> usize {
        self.header.beams_per_step()
    }

    /// Offset of each sensor's first beam within a step's readings.
    pub fn beam_offsets(&self) -> Vec<usize> {
        self.header.beam_offsets()
    }

    /// The readings of `sensor` at `step`, or `None` if it did not sample then.
    pub fn range_reading(&self, step: usize, sensor: usize) -> Option<&[f64]> {
        let per_step = self.beams_per_step();
        let start = step * per_step + self.beam_offsets()[sensor];
        let beams = self.header.range_sensors[sensor].beams as usize;
        let slice = &self.ranges[start..start + beams];
        if slice.first().is_some_and(|r| r.is_nan()) {
            None
        } else {
            Some(slice)
        }
    }

    /// Index of the range sensor called `name`.
    pub fn sensor_index(&self, name: &str) -> Option<usize> {
        self.header.sensor_index(name)
    }

    /// Cumulative wheel rotation `(t_s, left_rad, right_rad)` at every
    /// encoder sample (counts times 2π / ticks_per_rev).
    pub fn wheel_angles(&self) -> impl Iterator<Item = (f64, f64, f64)> + '_ {
        let rad_per_tick = std::f64::consts::TAU / f64::from(self.header.ticks_per_rev);
        self.steps.iter().filter_map(move |s| {
            s.encoder_ticks
                .map(|[l, r]| (s.t_s(), l as f64 * rad_per_tick, r as f64 * rad_per_tick))
        })
    }

    /// `(t_s, pose)` of every tracker sample.
    pub fn tracker_poses(&self) -> impl Iterator<Item = (f64, Pose)> + '_ {
        self.steps
            .iter()
            .filter_map(|s| s.tracker.map(|p| (s.t_s(), p)))
    }

    /// `(t_s, rad_s)` of every gyro sample.
    pub fn gyro_rates(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.steps
            .iter()
            .filter_map(|s| s.gyro_z_rad_s.map(|w| (s.t_s(), w)))
    }

    /// Ground-truth path length in metres.
    pub fn ground_truth_distance_m(&self) -> f64 {
        self.steps
            .windows(2)
            .map(|w| w[0].ground_truth.distance_to(&w[1].ground_truth))
            .sum()
    }
}

#[cfg(test)]
pub(crate) mod testutil {
    use super::*;

    /// A small log that exercises every optional field.
    pub fn sample_log() -> MissionLog {
        let header = LogHeader {
            format: LOG_FORMAT.into(),
            version: LOG_VERSION,
            scenario: "unit".into(),
            seed: 3,
            dt_s: 0.01,
            ticks_per_rev: 512,
            nominal: DiffDriveParams::new(0.064, 0.064, 0.26),
            footprint_radius_m: 0.17,
            max_wheel_speed_rad_s: 12.0,
            max_wheel_accel_rad_s2: 40.0,
            start: Pose::new(0.5, 0.25, 0.1),
            range_sensors: vec![
                RangeSensorInfo {
                    name: "side_ir".into(),
                    kind: SensorKind::Ranger,
                    mount: Pose::new(0.1, -0.1, -0.7),
                    beams: 1,
                    fov_rad: 0.0,
                    min_range_m: 0.04,
                    max_range_m: 0.8,
                },
                RangeSensorInfo {
                    name: "scan".into(),
                    kind: SensorKind::Lidar,
                    mount: Pose::new(0.0, 0.0, 0.0),
                    beams: 4,
                    fov_rad: std::f64::consts::TAU,
                    min_range_m: 0.0,
                    max_range_m: 5.0,
                },
            ],
            gyro: None,
            goals: Default::default(),
        };
        let mut log = MissionLog::new(header);
        for k in 0..7u64 {
            let x = k as f64 * 0.1 + 1.0 / 3.0;
            log.steps.push(StepRecord {
                t_ns: k * 10_000_000,
                cmd_wheel_rad_s: [1.0 / 7.0, -2.5],
                wheel_rad_s: [0.1 * k as f64, -1e-300],
                encoder_ticks: (k % 2 == 0).then_some([k as i64 * 3, -(k as i64)]),
                bump: k == 4,
                tracker: (k % 3 == 0).then_some(Pose::new(x, -x, 3.0)),
                ground_truth: Pose::new(x, 2.0 * x, -0.1 * k as f64),
                gyro_z_rad_s: None,
            });
            let sampled = k % 2 == 1;
            log.ranges.push(if sampled {
                0.123456789 * k as f64
            } else {
                f64::NAN
            });
            for b in 0..4 {
                log.ranges.push(if k != 5 {
                    4.0 + b as f64 / 3.0
                } else {
                    f64::NAN
                });
            }
        }
        log
    }

    /// [`sample_log`] with a gyro that samples on some steps.
    pub fn sample_log_with_gyro() -> MissionLog {
        let mut log = sample_log();
        log.header.gyro = Some(GyroInfo {
            name: "gyro".into(),
            rate_hz: 50.0,
        });
        for (k, s) in log.steps.iter_mut().enumerate() {
            s.gyro_z_rad_s = (k % 2 == 0).then_some(-0.1 / 3.0 + k as f64 * 1e-7);
        }
        log
    }

    /// Equality that treats NaN == NaN (the "not sampled" marker).
    pub fn assert_same(a: &MissionLog, b: &MissionLog) {
        assert_eq!(a.header, b.header);
        assert_eq!(a.steps, b.steps);
        assert_eq!(a.ranges.len(), b.ranges.len());
        for (i, (x, y)) in a.ranges.iter().zip(&b.ranges).enumerate() {
            assert!(
                x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()),
                "range {i}: {x} vs {y}"
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_directory_round_trip() {
        let log = testutil::sample_log();
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("log.meta.json"),
            serde_json::to_string(&log.header).unwrap(),
        )
        .unwrap();
        write_csv(
            &log,
            std::fs::File::create(dir.path().join("log.csv")).unwrap(),
        )
        .unwrap();
        testutil::assert_same(&log, &read_log_dir(dir.path()).unwrap());
        let with_gyro = testutil::sample_log_with_gyro();
        let gyro_dir = tempfile::tempdir().unwrap();
        std::fs::write(
            gyro_dir.path().join("log.meta.json"),
            serde_json::to_string(&with_gyro.header).unwrap(),
        )
        .unwrap();
        write_csv(
            &with_gyro,
            std::fs::File::create(gyro_dir.path().join("log.csv")).unwrap(),
        )
        .unwrap();
        testutil::assert_same(&with_gyro, &read_log_dir(gyro_dir.path()).unwrap());
        std::fs::write(dir.path().join("log.meta.json"), "{\"format\": 3}").unwrap();
        let err = read_log_dir(dir.path()).unwrap_err().to_string();
        assert!(err.contains("log.meta.json, line 1"), "{err}");
    }

    #[test]
    fn range_reading_respects_not_sampled() {
        let log = testutil::sample_log();
        assert!(log.range_reading(0, 0).is_none());
        assert_eq!(log.range_reading(1, 0).unwrap(), &[0.123456789]);
        assert_eq!(log.range_reading(1, 1).unwrap().len(), 4);
        assert!(log.range_reading(5, 1).is_none());
    }

    #[test]
    fn the_gyro_is_in_the_header_only_when_there_is_one() {
        let plain = serde_json::to_string(&testutil::sample_log().header).unwrap();
        assert!(!plain.contains("gyro"), "{plain}");
        let log = testutil::sample_log_with_gyro();
        let json = serde_json::to_string(&log.header).unwrap();
        assert!(
            json.ends_with(r#""gyro":{"name":"gyro","rate_hz":50.0}}"#),
            "{json}"
        );
        assert_eq!(
            serde_json::from_str::<LogHeader>(&json).unwrap(),
            log.header
        );
        let hidden = json.replace(r#""rate_hz":50.0"#, r#""rate_hz":50.0,"bias_rad_s":0.01"#);
        let err = serde_json::from_str::<LogHeader>(&hidden).unwrap_err();
        assert!(
            err.to_string().contains("unknown field `bias_rad_s`"),
            "{err}"
        );
        let rates: Vec<(f64, f64)> = log.gyro_rates().collect();
        assert_eq!(rates.len(), 4);
        assert_eq!(rates[1], (0.02, -0.1 / 3.0 + 2e-7));
    }

    #[test]
    fn beam_angles() {
        let log = testutil::sample_log();
        let scan = &log.header.range_sensors[1];
        assert_eq!(scan.beam_angle_rad(0), -std::f64::consts::PI);
        assert!((scan.beam_angle_rad(2)).abs() < 1e-15);
        let mut narrow = scan.clone();
        narrow.fov_rad = 1.0;
        narrow.beams = 3;
        assert_eq!(narrow.beam_angle_rad(0), -0.5);
        assert_eq!(narrow.beam_angle_rad(2), 0.5);
    }
}
