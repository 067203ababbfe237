//! A lidar's scans: every `sensor_msgs/msg/LaserScan` of a topic as plain
//! data, in time order.

use super::{Stamps, check_stamped, header_stamp, message_time, one_sensor, topic_error};
use crate::bag::{Bag, BagError};
use crate::value::Value;

pub const LASER_SCAN: &str = "sensor_msgs/msg/LaserScan";

/// One scan, field for field what a scan matcher needs.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanData {
    /// Time of the scan (s) on the chosen clock; by the LaserScan
    /// convention, the time of the first beam.
    pub t_s: f64,
    /// Bearing of the first beam in the scan's frame (rad).
    pub angle_min_rad: f64,
    /// Bearing step between beams (rad; negative for a clockwise scanner).
    pub increment_rad: f64,
    pub range_min_m: f64,
    pub range_max_m: f64,
    /// One range per beam (m), as recorded: a reading outside
    /// `[range_min_m, range_max_m]`, NaN or ±inf is not a return (REP-117).
    pub ranges_m: Vec<f32>,
}

/// The scans of a topic.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanTrack {
    /// Time-ordered, one per time, all in `frame_id`.
    pub scans: Vec<ScanData>,
    /// `header.frame_id` of the earliest well-formed scan.
    pub frame_id: String,
    /// Scans left out as malformed: no ranges, an angle or a range limit
    /// that is not a number, `range_max` not above `range_min`, or a count
    /// of ranges that does not fit `angle_min`..`angle_max` at
    /// `angle_increment`.
    pub malformed: u64,
    /// Well-formed scans left out for another `frame_id` (another sensor).
    pub other_frame: u64,
    /// Scans left out for repeating an earlier scan's time.
    pub repeated: u64,
}

/// Every `sensor_msgs/msg/LaserScan` on `topic`, times by `stamps` (as
/// [`super::wheel_track`] has them: seconds, as recorded). A topic that is
/// missing or of another type is an error naming its type and the bag's
/// LaserScan topics; so is one without a single well-formed scan.
pub fn scan_track(bag: &Bag, topic: &str, stamps: Stamps) -> Result<ScanTrack, BagError> {
    let schema = super::typed_schema(bag, topic, LASER_SCAN)?;
    let terr = |m: String| topic_error(bag, topic, m);
    let path = |p: &str| schema.path(p).map_err(terr);
    let frame = path("header.frame_id")?;
    let nums = [
        path("angle_min")?,
        path("angle_max")?,
        path("angle_increment")?,
        path("range_min")?,
        path("range_max")?,
    ];
    let ranges = path("ranges")?;
    let header = header_stamp(&schema, 0);
    let mut raw = Vec::new();
    let mut malformed = 0;
    let mut first_malformed: Option<String> = None;
    bag.for_each(topic, |m| {
        let t = message_time(m.value, m.log_time_ns, stamps, header.as_ref())?;
        let f = m.value.at(&frame).and_then(Value::as_str).unwrap_or("");
        let [angle_min, angle_max, increment, range_min, range_max] = nums
            .each_ref()
            .map(|p| m.value.at(p).and_then(Value::as_f64).unwrap_or(f64::NAN));
        let values = m
            .value
            .at(&ranges)
            .and_then(Value::as_array)
            .ok_or("`ranges` is not an array")?;
        let ranges_m: Option<Vec<f32>> = values
            .iter()
            .map(|v| v.as_f64().map(|r| r as f32))
            .collect();
        let ranges_m = ranges_m.ok_or("`ranges` holds something other than numbers")?;
        let scan = ScanData {
            t_s: t,
            angle_min_rad: angle_min,
            increment_rad: increment,
            range_min_m: range_min,
            range_max_m: range_max,
            ranges_m,
        };
        match flaw(&scan, angle_max) {
            Some(why) => {
                malformed += 1;
                first_malformed.get_or_insert_with(|| format!("message {}: {why}", m.index));
            }
            None => raw.push((t, f.to_string(), scan)),
        }
        Ok(())
    })?;
    if raw.is_empty() {
        return Err(terr(match first_malformed {
            None => "has no messages".into(),
            Some(first) => {
                format!("no well-formed scan: all {malformed} are malformed (the first, {first})")
            }
        }));
    }
    check_stamped(bag, topic, raw.iter().map(|s| s.0), stamps)?;
    let one = one_sensor(raw);
    Ok(ScanTrack {
        scans: one.readings.into_iter().map(|(_, s)| s).collect(),
        frame_id: one.frame_id,
        malformed,
        other_frame: one.other_frame,
        repeated: one.repeated,
    })
}

/// Why `scan` (whose last beam is at `angle_max`) cannot be used, if it
/// cannot.
fn flaw(scan: &ScanData, angle_max: f64) -> Option<String> {
    let n = scan.ranges_m.len();
    let (a0, step) = (scan.angle_min_rad, scan.increment_rad);
    if n == 0 {
        return Some("no ranges".into());
    }
    if !(a0.is_finite() && angle_max.is_finite() && step.is_finite()) {
        return Some(format!(
            "an angle is not a finite number (angle_min {a0}, angle_max {angle_max}, angle_increment {step})"
        ));
    }
    if scan.range_min_m.is_nan()
        || scan.range_max_m.is_nan()
        || scan.range_max_m <= scan.range_min_m
    {
        return Some(format!(
            "range_max {} is not above range_min {}",
            scan.range_max_m, scan.range_min_m
        ));
    }
    if n == 1 {
        return None;
    }
    // Drivers put the last beam at angle_max, or one step short of it (a
    // full turn that does not repeat its first beam): n − 1 or n steps,
    // give or take float32 rounding.
    let steps = (angle_max - a0) / step;
    if step == 0.0 || !steps.is_finite() || (steps - (n - 1) as f64).abs() > 1.0 + 1e-3 {
        return Some(format!(
            "{n} ranges, but angle_min {a0} to angle_max {angle_max} at angle_increment {step} makes {} beams",
            if step == 0.0 || !steps.is_finite() {
                "no whole number of".to_string()
            } else {
                format!("{:.0}", steps + 1.0)
            }
        ));
    }
    None
}
