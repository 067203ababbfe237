//! A self-calibration's inputs from a simulator log: the wheels, the
//! scans of one lidar in its own frame and the gyro's rates.

use anyhow::bail;
use twindrive_estimation::WheelSample;
use twindrive_estimation::localize::Scan;
use twindrive_log::{MissionLog, RangeSensorInfo};

use crate::inputs;

/// Fewest beams a range sensor needs to be matched scan to scan.
pub const MIN_SCAN_BEAMS: u32 = 30;

/// What a self-calibration reads from a recording.
#[derive(Debug, Clone)]
pub struct ScanRecording {
    pub wheels: Vec<WheelSample>,
    pub scans: Vec<Scan>,
    pub gyro: Vec<(f64, f64)>,
    /// The lidar as the recording describes it (its mount is a guess).
    pub lidar: RangeSensorInfo,
    pub nominal: Option<[f64; 3]>,
    pub ticks_per_rev: Option<u32>,
    pub time_origin_s: f64,
}

/// The range sensor called `name`, or the first with at least
/// [`MIN_SCAN_BEAMS`] beams; an error names the sensors the log has.
pub fn lidar_of<'a>(log: &'a MissionLog, name: Option<&str>) -> anyhow::Result<(usize, &'a RangeSensorInfo)> {
    let sensors = &log.header.range_sensors;
    let found = match name {
        Some(n) => sensors.iter().position(|s| s.name == n),
        None => sensors.iter().position(|s| s.beams >= MIN_SCAN_BEAMS),
    };
    match found {
        Some(i) if sensors[i].beams >= MIN_SCAN_BEAMS => Ok((i, &sensors[i])),
        _ => {
            let have: Vec<String> = sensors
                .iter()
                .map(|s| format!("{} ({} beams)", s.name, s.beams))
                .collect();
            let have = if have.is_empty() { "none".to_string() } else { have.join(", ") };
            match name {
                Some(n) => bail!(
                    "--scan-sensor {n}: the log has no range sensor of that name with at least {MIN_SCAN_BEAMS} beams; \
                     its range sensors: {have}"
                ),
                None => bail!(
                    "the log has no range sensor with at least {MIN_SCAN_BEAMS} beams to match scan to scan; \
                     its range sensors: {have}"
                ),
            }
        }
    }
}

/// Whether a calibration of `log` with `--reference auto` uses its scans:
/// it has a lidar and no tracker sample.
pub fn prefers_scans(log: &MissionLog) -> bool {
    lidar_of(log, None).is_ok() && log.tracker_poses().next().is_none()
}

/// The scans of range sensor `sensor` of `log`, in its own frame.
pub fn scans_from_log(log: &MissionLog, sensor: usize) -> Vec<Scan> {
    let info = &log.header.range_sensors[sensor];
    let (angle_min_rad, increment_rad) = info.angle_min_and_increment();
    (0..log.steps.len())
        .filter_map(|i| {
            let ranges = log.range_reading(i, sensor)?;
            Some(Scan {
                t_s: log.steps[i].t_s(),
                angle_min_rad,
                increment_rad,
                range_min_m: info.min_range_m,
                range_max_m: info.max_range_m,
                ranges_m: ranges.iter().map(|r| *r as f32).collect(),
            })
        })
        .collect()
}

impl ScanRecording {
    /// A simulator log's wheels (`signs` flip counters that run
    /// backwards), the scans of its lidar `sensor` (or the first with
    /// enough beams) and its gyro. Never its true track.
    pub fn from_log(log: &MissionLog, sensor: Option<&str>, signs: [f64; 2]) -> anyhow::Result<Self> {
        let (index, lidar) = lidar_of(log, sensor)?;
        let n = log.header.nominal;
        Ok(Self {
            wheels: inputs::signed_wheels_from_log(log, signs),
            scans: scans_from_log(log, index),
            gyro: log.gyro_rates().collect(),
            lidar: lidar.clone(),
            nominal: Some([n.left_diameter_m, n.right_diameter_m, n.wheelbase_m]),
            ticks_per_rev: Some(log.header.ticks_per_rev),
            time_origin_s: 0.0,
        })
    }
}
