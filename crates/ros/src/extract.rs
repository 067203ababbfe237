//! What calibration needs from a recording: cumulative wheel angles and a
//! reference pose track, each on its own clock; for self-calibration
//! without a pose reference, lidar scans ([`scan_track`]), gyro yaw rates
//! ([`imu_rate_track`]) and sensor mounts from the TF tree
//! ([`static_transform`]).
//!
//! Times are seconds on the clock [`Stamps`] picks, as the recording has
//! them (Unix time for a robot's bag; nothing is subtracted), the same for
//! every track.
//!
//! Wheels come from `sensor_msgs/msg/JointState` (two named joints; the
//! position in radians, or the velocity integrated), from any message
//! with two integer tick fields, or from wheel speeds published as plain
//! numbers (a `std_msgs/msg/Float64` per wheel, or two elements of an
//! array), integrated. Poses come from
//! `geometry_msgs/msg/PoseStamped`, `geometry_msgs/msg/PoseWithCovarianceStamped`,
//! `nav_msgs/msg/Odometry` or a `tf2_msgs/msg/TFMessage` child frame. Fields
//! are found by name in the definition stored in the file, so a message only
//! has to have the fields, not a particular version of the type.

mod description;
mod imu;
mod scan;
#[cfg(test)]
mod sensor_tests;
mod speeds;
mod tf;

pub use description::{ROBOT_DESCRIPTION, robot_description};
pub use imu::{IMU, ImuRateTrack, imu_rate_track};
pub use scan::{LASER_SCAN, ScanData, ScanTrack, scan_track};
pub use speeds::{NumberField, number_track};
pub use tf::{PlanarMount, TF_MESSAGE, base_frame_guess, static_transform, tf_frames};

use crate::bag::{Bag, BagError};
use crate::live::{JointPaths, Joints};
use crate::schema::{Arity, Base, FieldPath, Primitive, Schema, normalize_type_name};
use crate::value::Value;

/// Where message times come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stamps {
    /// `header.stamp` (the sensor's clock); the log time for types without a header.
    Header,
    /// The time the recorder received the message.
    LogTime,
}

/// Which JointState field carries the wheels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointSignal {
    /// Position when the messages carry it, else velocity.
    Auto,
    Position,
    Velocity,
}

#[derive(Debug, Clone, PartialEq)]
pub enum WheelSource {
    Joints {
        topic: String,
        left: String,
        right: String,
        signal: JointSignal,
    },
    /// Two integer fields (`a.b`, or `data[0]` for an array element).
    Ticks {
        topic: String,
        left_field: String,
        right_field: String,
        ticks_per_rev: u32,
    },
    /// Wheel speeds as plain numbers, integrated: a `std_msgs/msg/Float64`
    /// topic per wheel (field `data`), or two elements of one array topic
    /// (`std_msgs/msg/Float64MultiArray`'s `data[0]` and `data[1]`).
    Speeds {
        left: NumberField,
        right: NumberField,
        /// Radians per unit of the published number (1 for rad/s, 2π for
        /// revolutions per second).
        rad_per_unit: f64,
    },
}

#[derive(Debug, Clone, PartialEq)]
pub struct PoseSource {
    pub topic: String,
    /// The child frame of a TF topic (required there); for Odometry, checked
    /// against `child_frame_id` when given.
    pub frame: Option<String>,
    /// The parent frame of a TF topic, when several parents publish the child.
    pub parent: Option<String>,
}

/// `(t_s, left_rad, right_rad)`, time-ordered.
pub type WheelTrack = Vec<(f64, f64, f64)>;
/// `(t_s, x_m, y_m, heading_rad)`, time-ordered.
pub type PoseTrack = Vec<(f64, f64, f64, f64)>;

/// What came out of a topic besides the samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Extracted<T> {
    pub samples: T,
    /// Messages on the topic that did not carry what was asked for (other
    /// joints, other TF frames).
    pub skipped: u64,
    /// `position` or `velocity` for joints; the type for poses.
    pub used: String,
}

fn seconds(ns: i64) -> f64 {
    ns as f64 * 1e-9
}

/// `header.stamp` of a message whose type has a standard header.
/// `header.stamp` of type `ty` (0: the top-level message), if it has a header.
fn header_stamp(schema: &Schema, ty: usize) -> Option<(FieldPath, FieldPath)> {
    Some((
        schema.path_from(ty, "header.stamp.sec").ok()?,
        schema.path_from(ty, "header.stamp.nanosec").ok()?,
    ))
}

fn stamp_ns(v: &Value, paths: &(FieldPath, FieldPath)) -> Result<i64, String> {
    let sec = v
        .at(&paths.0)
        .and_then(Value::as_i64)
        .ok_or("no header.stamp.sec")?;
    let nsec = v
        .at(&paths.1)
        .and_then(Value::as_i64)
        .ok_or("no header.stamp.nanosec")?;
    Ok(sec * 1_000_000_000 + nsec)
}

/// The message time by `stamps`.
fn message_time(
    v: &Value,
    log_time_ns: u64,
    stamps: Stamps,
    header: Option<&(FieldPath, FieldPath)>,
) -> Result<f64, String> {
    match (stamps, header) {
        (Stamps::Header, Some(h)) => Ok(seconds(stamp_ns(v, h)?)),
        _ => Ok(seconds(log_time_ns as i64)),
    }
}

/// Header stamps that are all zero were never filled in by the publisher.
fn check_stamped(
    bag: &Bag,
    topic: &str,
    times: impl IntoIterator<Item = f64>,
    stamps: Stamps,
) -> Result<(), BagError> {
    let (mut n, mut all_zero) = (0usize, true);
    for t in times {
        n += 1;
        all_zero &= t == 0.0;
    }
    if stamps == Stamps::Header && n > 1 && all_zero {
        return Err(topic_error(
            bag,
            topic,
            "every header.stamp is zero (the publisher does not stamp its messages); pass --stamps log to use the recording time".into(),
        ));
    }
    Ok(())
}

/// Sorts by time and drops repeated times (a republished sample), keeping the first.
fn ordered<T: Copy>(mut v: Vec<(f64, T)>) -> Vec<(f64, T)> {
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    v.dedup_by(|b, a| a.0 == b.0);
    v
}

/// Cumulative wheel angles from `source`.
pub fn wheel_track(
    bag: &Bag,
    source: &WheelSource,
    stamps: Stamps,
) -> Result<Extracted<WheelTrack>, BagError> {
    match source {
        WheelSource::Joints {
            topic,
            left,
            right,
            signal,
        } => joints(bag, topic, left, right, *signal, stamps),
        WheelSource::Ticks {
            topic,
            left_field,
            right_field,
            ticks_per_rev,
        } => ticks(bag, topic, left_field, right_field, *ticks_per_rev, stamps),
        WheelSource::Speeds {
            left,
            right,
            rad_per_unit,
        } => speeds::speeds(bag, left, right, *rad_per_unit, stamps),
    }
}

fn topic_error(bag: &Bag, topic: &str, message: String) -> BagError {
    BagError::Topic {
        path: bag.path().to_path_buf(),
        topic: topic.to_string(),
        message,
    }
}

/// The schema of `topic`, which must have type `want` (`pkg/msg/Type`);
/// otherwise an error that says what the topic is (missing, or its type)
/// and lists the bag's topics of type `want`.
fn typed_schema(bag: &Bag, topic: &str, want: &str) -> Result<Schema, BagError> {
    let found = bag.topic(topic).map(|t| normalize_type_name(&t.type_name));
    if found.as_deref() == Some(want) {
        return bag.schema(topic);
    }
    let same: Vec<String> = bag
        .topics()
        .iter()
        .filter(|t| normalize_type_name(&t.type_name) == want)
        .map(|t| format!("{} ({} messages)", t.name, t.message_count))
        .collect();
    let what = match found.as_deref() {
        None => "not in the bag".to_string(),
        Some("") => format!("has no type in the file, and {want} is wanted"),
        Some(other) => format!("is {other}, not {want}"),
    };
    let have = if same.is_empty() {
        format!(
            "the bag has no {want} topic; its topics: {}",
            match bag.describe_topics() {
                d if d.is_empty() => "none".to_string(),
                d => d,
            }
        )
    } else {
        format!("the {want} topics are: {}", same.join(", "))
    };
    Err(topic_error(bag, topic, format!("{what}; {have}")))
}

/// A sensor topic's readings `(t, frame_id, reading)`, as read, put in
/// time order (stable) and narrowed to one sensor: the frame of the
/// earliest reading, and one reading per time (the first; a later one at
/// the same time is a republished copy).
struct OneSensor<T> {
    readings: Vec<(f64, T)>,
    frame_id: String,
    other_frame: u64,
    repeated: u64,
}

fn one_sensor<T>(mut raw: Vec<(f64, String, T)>) -> OneSensor<T> {
    raw.sort_by(|a, b| a.0.total_cmp(&b.0));
    let frame_id = raw.first().map(|r| r.1.clone()).unwrap_or_default();
    let same = |f: &str| f.trim_start_matches('/') == frame_id.trim_start_matches('/');
    let (mut other_frame, mut repeated) = (0, 0);
    let mut readings: Vec<(f64, T)> = Vec::with_capacity(raw.len());
    for (t, f, r) in raw {
        if !same(&f) {
            other_frame += 1;
        } else if readings.last().is_some_and(|(last, _)| *last == t) {
            repeated += 1;
        } else {
            readings.push((t, r));
        }
    }
    OneSensor {
        readings,
        frame_id,
        other_frame,
        repeated,
    }
}

fn joints(
    bag: &Bag,
    topic: &str,
    left: &str,
    right: &str,
    signal: JointSignal,
    stamps: Stamps,
) -> Result<Extracted<WheelTrack>, BagError> {
    let schema = bag.schema(topic)?;
    let paths = JointPaths::new(&schema).map_err(|e| {
        topic_error(
            bag,
            topic,
            format!("{e}; wheel joints are read from sensor_msgs/msg/JointState"),
        )
    })?;
    let header = header_stamp(&schema, 0);
    // (t, position, velocity) of every message that names both joints.
    type Pair = Option<[f64; 2]>;
    let mut raw: Vec<(f64, (Pair, Pair))> = Vec::new();
    let mut seen_names: Vec<String> = Vec::new();
    let mut skipped = 0;
    bag.for_each(topic, |m| {
        match paths.read(m.value, left, right)? {
            Joints::Other(list) => {
                for n in list.iter().filter_map(Value::as_str) {
                    if !seen_names.iter().any(|s| s == n) && seen_names.len() < 32 {
                        seen_names.push(n.to_string());
                    }
                }
                skipped += 1;
            }
            Joints::Both { position, velocity } => {
                let t = message_time(m.value, m.log_time_ns, stamps, header.as_ref())?;
                raw.push((t, (position, velocity)));
            }
        }
        Ok(())
    })?;
    if raw.is_empty() {
        return Err(topic_error(
            bag,
            topic,
            format!(
                "no message names both joints `{left}` and `{right}`; the joints named are: {}",
                if seen_names.is_empty() {
                    "none".to_string()
                } else {
                    seen_names.join(", ")
                }
            ),
        ));
    }
    check_stamped(bag, topic, raw.iter().map(|s| s.0), stamps)?;
    let raw = ordered(raw);
    let has_position = raw.iter().all(|(_, (p, _))| p.is_some());
    let has_velocity = raw.iter().all(|(_, (_, v))| v.is_some());
    let use_position = match signal {
        JointSignal::Position | JointSignal::Auto if has_position => true,
        JointSignal::Velocity | JointSignal::Auto if has_velocity => false,
        _ => {
            return Err(topic_error(
                bag,
                topic,
                format!(
                    "the joints have no {} in every message (position in all: {has_position}, velocity in all: {has_velocity})",
                    match signal {
                        JointSignal::Position => "position",
                        JointSignal::Velocity => "velocity",
                        JointSignal::Auto => "position or velocity",
                    }
                ),
            ));
        }
    };
    let samples = if use_position {
        raw.iter()
            .map(|(t, (p, _))| {
                let [l, r] = p.expect("checked");
                (*t, l, r)
            })
            .collect()
    } else {
        let speeds = raw.iter().map(|(t, (_, v))| (*t, v.expect("checked")));
        twindrive_kinematics::wheel_angles_from_speeds(speeds)
            .into_iter()
            .map(|(t, [l, r])| (t, l, r))
            .collect()
    };
    Ok(Extracted {
        samples,
        skipped,
        used: if use_position { "position" } else { "velocity" }.into(),
    })
}

/// A field path with an optional trailing array index: `data[1]`.
fn element_path(schema: &Schema, text: &str) -> Result<(FieldPath, Option<usize>), String> {
    let (path, index) = match text.strip_suffix(']').and_then(|t| t.rsplit_once('[')) {
        Some((p, i)) => (
            p,
            Some(
                i.parse::<usize>()
                    .map_err(|_| format!("`{text}`: `{i}` is not an array index"))?,
            ),
        ),
        None => (text, None),
    };
    let fp = schema.path(path)?;
    let numeric = matches!(fp.ty.base, Base::Primitive(p) if p != Primitive::Bool);
    let shape_ok = match (fp.ty.arity, index) {
        (Arity::Single, None) => true,
        (Arity::Fixed(n), Some(i)) => i < n,
        (Arity::Sequence(_), Some(_)) => true,
        _ => false,
    };
    if !numeric || !shape_ok {
        return Err(format!(
            "`{text}` is not a number field{}",
            if index.is_none() && fp.ty.arity != Arity::Single {
                " (it is an array: add an index such as `[0]`)"
            } else {
                ""
            }
        ));
    }
    Ok((fp, index))
}

/// The finite number at `path` (an [`element_path`]) of `value`; `name`
/// is the field as the user wrote it.
fn number_at(
    value: &Value,
    (path, index): &(FieldPath, Option<usize>),
    name: &str,
) -> Result<f64, String> {
    let v = value.at(path).ok_or_else(|| format!("no field `{name}`"))?;
    let v = match (v, index) {
        (Value::Array(a), Some(i)) => a.get(*i),
        (Value::Bytes(b), Some(i)) => {
            return b
                .get(*i)
                .map(|b| f64::from(*b))
                .ok_or_else(|| format!("`{name}`: the array is shorter"));
        }
        (v, None) => Some(v),
        _ => None,
    };
    v.and_then(Value::as_f64)
        .filter(|x| x.is_finite())
        .ok_or_else(|| format!("`{name}` is missing or not a finite number"))
}

fn ticks(
    bag: &Bag,
    topic: &str,
    left_field: &str,
    right_field: &str,
    ticks_per_rev: u32,
    stamps: Stamps,
) -> Result<Extracted<WheelTrack>, BagError> {
    if ticks_per_rev == 0 {
        return Err(topic_error(
            bag,
            topic,
            "ticks per revolution must be > 0".into(),
        ));
    }
    let schema = bag.schema(topic)?;
    let (l, r) = (
        element_path(&schema, left_field).map_err(|e| topic_error(bag, topic, e))?,
        element_path(&schema, right_field).map_err(|e| topic_error(bag, topic, e))?,
    );
    let header = header_stamp(&schema, 0);
    let k = std::f64::consts::TAU / f64::from(ticks_per_rev);
    let mut raw = Vec::new();
    bag.for_each(topic, |m| {
        let t = message_time(m.value, m.log_time_ns, stamps, header.as_ref())?;
        raw.push((
            t,
            (
                number_at(m.value, &l, left_field)? * k,
                number_at(m.value, &r, right_field)? * k,
            ),
        ));
        Ok(())
    })?;
    Ok(Extracted {
        samples: ordered(raw)
            .into_iter()
            .map(|(t, (a, b))| (t, a, b))
            .collect(),
        skipped: 0,
        used: "ticks".into(),
    })
}

/// The reference poses from `source`.
pub fn pose_track(
    bag: &Bag,
    source: &PoseSource,
    stamps: Stamps,
) -> Result<Extracted<PoseTrack>, BagError> {
    let topic = source.topic.as_str();
    let schema = bag.schema(topic)?;
    let type_name = schema.root().name.clone();
    let terr = |m: String| topic_error(bag, topic, m);
    if type_name == "tf2_msgs/msg/TFMessage" {
        let child = source.frame.as_deref().ok_or_else(|| {
            terr("a TF topic holds many frames: name the robot's with --pose-frame".into())
        })?;
        return tf_track(bag, &schema, topic, child, source.parent.as_deref(), stamps);
    }
    let pose_prefix = match type_name.as_str() {
        "geometry_msgs/msg/PoseStamped" => "pose",
        "geometry_msgs/msg/PoseWithCovarianceStamped" | "nav_msgs/msg/Odometry" => "pose.pose",
        other => {
            return Err(terr(format!(
                "is {other}; a reference pose is read from geometry_msgs/msg/PoseStamped, \
                 geometry_msgs/msg/PoseWithCovarianceStamped, nav_msgs/msg/Odometry or tf2_msgs/msg/TFMessage"
            )));
        }
    };
    if source.parent.is_some() {
        return Err(terr("--pose-parent applies to TF topics only".into()));
    }
    let child_check = match (&source.frame, type_name.as_str()) {
        (Some(f), "nav_msgs/msg/Odometry") => {
            Some((schema.path("child_frame_id").map_err(terr)?, f.clone()))
        }
        (Some(_), _) => {
            return Err(terr(format!(
                "--pose-frame selects a TF child frame or checks an Odometry child frame; {type_name} has neither"
            )));
        }
        (None, _) => None,
    };
    let fields = crate::live::pose_paths(&schema, pose_prefix).map_err(terr)?;
    let header = header_stamp(&schema, 0);
    let mut raw = Vec::new();
    let mut skipped = 0;
    bag.for_each(topic, |m| {
        if let Some((path, want)) = &child_check
            && m.value.at(path).and_then(Value::as_str) != Some(want.as_str())
        {
            skipped += 1;
            return Ok(());
        }
        let t = message_time(m.value, m.log_time_ns, stamps, header.as_ref())?;
        let v: Vec<f64> = fields
            .iter()
            .map(|f| m.value.at(f).and_then(Value::as_f64).unwrap_or(f64::NAN))
            .collect();
        raw.push((t, crate::live::planar_pose(&v)?));
        Ok(())
    })?;
    check_stamped(bag, topic, raw.iter().map(|s| s.0), stamps)?;
    finish_poses(bag, topic, raw, skipped, type_name)
}

fn tf_track(
    bag: &Bag,
    schema: &Schema,
    topic: &str,
    child: &str,
    parent: Option<&str>,
    stamps: Stamps,
) -> Result<Extracted<PoseTrack>, BagError> {
    let terr = |m: String| topic_error(bag, topic, m);
    let transforms = schema.path("transforms").map_err(terr)?;
    let Base::Message(ts) = transforms.ty.base else {
        return Err(terr("`transforms` is not a list of messages".into()));
    };
    // Paths inside one TransformStamped.
    let inner = |dotted: &str| schema.path_from(ts, dotted).map_err(terr);
    let child_path = inner("child_frame_id")?;
    let parent_path = inner("header.frame_id")?;
    let stamp = header_stamp(schema, ts)
        .ok_or_else(|| terr("a TransformStamped without header.stamp".into()))?;
    let nums = [
        inner("transform.translation.x")?,
        inner("transform.translation.y")?,
        inner("transform.rotation.x")?,
        inner("transform.rotation.y")?,
        inner("transform.rotation.z")?,
        inner("transform.rotation.w")?,
    ];
    let mut raw = Vec::new();
    let mut frames: Vec<String> = Vec::new();
    let mut skipped = 0;
    bag.for_each(topic, |m| {
        let list = m
            .value
            .at(&transforms)
            .and_then(Value::as_array)
            .ok_or("no `transforms` list")?;
        let mut found = false;
        for tr in list {
            let (Some(c), Some(p)) = (
                tr.at(&child_path).and_then(Value::as_str),
                tr.at(&parent_path).and_then(Value::as_str),
            ) else {
                continue;
            };
            let c = c.trim_start_matches('/');
            let p = p.trim_start_matches('/');
            if c != child.trim_start_matches('/')
                || parent.is_some_and(|want| want.trim_start_matches('/') != p)
            {
                let name = format!("{p} -> {c}");
                if frames.len() < 32 && !frames.contains(&name) {
                    frames.push(name);
                }
                continue;
            }
            let t = message_time(tr, m.log_time_ns, stamps, Some(&stamp))?;
            let v: Vec<f64> = nums
                .iter()
                .map(|p| tr.at(p).and_then(Value::as_f64).unwrap_or(f64::NAN))
                .collect();
            raw.push((t, crate::live::planar_pose(&v)?));
            found = true;
        }
        if !found {
            skipped += 1;
        }
        Ok(())
    })?;
    if raw.is_empty() {
        return Err(terr(format!(
            "no transform to child frame `{child}`{}; the transforms are: {}",
            parent.map(|p| format!(" from `{p}`")).unwrap_or_default(),
            if frames.is_empty() {
                "none".to_string()
            } else {
                frames.join(", ")
            }
        )));
    }
    check_stamped(bag, topic, raw.iter().map(|s| s.0), stamps)?;
    finish_poses(bag, topic, raw, skipped, "tf2_msgs/msg/TFMessage".into())
}

fn finish_poses(
    bag: &Bag,
    topic: &str,
    raw: Vec<(f64, (f64, f64, f64))>,
    skipped: u64,
    used: String,
) -> Result<Extracted<PoseTrack>, BagError> {
    if raw.is_empty() {
        return Err(topic_error(bag, topic, "no poses".into()));
    }
    Ok(Extracted {
        samples: ordered(raw)
            .into_iter()
            .map(|(t, (x, y, h))| (t, x, y, h))
            .collect(),
        skipped,
        used,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bag::BagWriter;
    use crate::msgs::*;
    use crate::qos::Qos;

    fn bag(dir: &std::path::Path) -> Bag {
        let path = dir.join("t.mcap");
        let f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut w = BagWriter::mcap(f, "t.mcap", Distro::Jazzy).unwrap();
        let js = w
            .topic::<JointState>("/joint_states", Qos::DEFAULT)
            .unwrap();
        let tf = w.topic::<TFMessage>("/tf", Qos::DEFAULT).unwrap();
        let od = w.topic::<Odometry>("/odom", Qos::DEFAULT).unwrap();
        for k in 0..20u64 {
            let t = 5_000_000_000 + k * 100_000_000;
            // Stamps 1 s behind the recorder's clock.
            let stamp = t - 1_000_000_000;
            // An arm's joint state in between.
            w.write(
                js,
                t,
                &JointState {
                    header: Header::new(stamp, ""),
                    name: vec!["arm".into()],
                    position: vec![0.0],
                    velocity: vec![],
                    effort: vec![],
                },
            )
            .unwrap();
            w.write(
                js,
                t,
                &JointState {
                    header: Header::new(stamp, ""),
                    name: vec!["r".into(), "l".into()],
                    position: vec![2.0 * k as f64, k as f64],
                    velocity: vec![20.0, 10.0],
                    effort: vec![],
                },
            )
            .unwrap();
            w.write(
                tf,
                t,
                &TFMessage {
                    transforms: vec![
                        TransformStamped::planar(stamp, "odom", "base_link", 9.0, 9.0, 0.0),
                        TransformStamped::planar(
                            stamp,
                            "world",
                            "robot",
                            0.1 * k as f64,
                            1.0,
                            0.25,
                        ),
                    ],
                },
            )
            .unwrap();
            w.write(
                od,
                t,
                &Odometry {
                    header: Header::new(stamp, "odom"),
                    child_frame_id: "base_link".into(),
                    pose: PoseWithCovariance {
                        pose: crate::msgs::Pose::planar(k as f64, 0.0, -0.5),
                        covariance: Covariance::default(),
                    },
                    twist: TwistWithCovariance::default(),
                },
            )
            .unwrap();
        }
        w.finish().unwrap();
        Bag::open(&path).unwrap()
    }

    #[test]
    fn joints_ticks_and_poses_come_out_on_the_chosen_clock() {
        let dir = tempfile::tempdir().unwrap();
        let b = bag(dir.path());
        let src = |signal| WheelSource::Joints {
            topic: "/joint_states".into(),
            left: "l".into(),
            right: "r".into(),
            signal,
        };
        let w = wheel_track(&b, &src(JointSignal::Auto), Stamps::Header).unwrap();
        assert_eq!(w.used, "position");
        assert_eq!(w.skipped, 20);
        assert_eq!(w.samples.len(), 20);
        let (t, l, r) = w.samples[3];
        assert!((t - 4.3).abs() < 1e-9 && (l, r) == (3.0, 6.0));
        let v = wheel_track(&b, &src(JointSignal::Velocity), Stamps::LogTime).unwrap();
        assert_eq!(v.used, "velocity");
        assert!((v.samples[10].0 - 6.0).abs() < 1e-9);
        assert!((v.samples[10].1 - 10.0).abs() < 1e-9 && (v.samples[10].2 - 20.0).abs() < 1e-9);

        let ticks = WheelSource::Ticks {
            topic: "/joint_states".into(),
            left_field: "position[1]".into(),
            right_field: "velocity[0]".into(),
            ticks_per_rev: 4,
        };
        let e = wheel_track(&b, &ticks, Stamps::Header)
            .unwrap_err()
            .to_string();
        assert!(e.contains("message 0") && e.contains("position[1]"), "{e}");

        let tf = PoseSource {
            topic: "/tf".into(),
            frame: Some("robot".into()),
            parent: None,
        };
        let p = pose_track(&b, &tf, Stamps::Header).unwrap();
        assert_eq!(p.samples.len(), 20);
        let (t, x, y, h) = p.samples[5];
        assert!(
            (t - 4.5).abs() < 1e-9
                && (x - 0.5).abs() < 1e-12
                && y == 1.0
                && (h - 0.25).abs() < 1e-12
        );
        let odom = PoseSource {
            topic: "/odom".into(),
            frame: Some("base_link".into()),
            parent: None,
        };
        let p = pose_track(&b, &odom, Stamps::LogTime).unwrap();
        assert!((p.samples[2].0 - 5.2).abs() < 1e-9 && (p.samples[2].3 + 0.5).abs() < 1e-12);
    }

    #[test]
    fn wrong_names_are_listed() {
        let dir = tempfile::tempdir().unwrap();
        let b = bag(dir.path());
        let e = wheel_track(
            &b,
            &WheelSource::Joints {
                topic: "/joint_states".into(),
                left: "wheel_left_joint".into(),
                right: "r".into(),
                signal: JointSignal::Auto,
            },
            Stamps::Header,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("the joints named are: arm, r, l"), "{e}");
        let e = pose_track(
            &b,
            &PoseSource {
                topic: "/tf".into(),
                frame: Some("base_footprint".into()),
                parent: None,
            },
            Stamps::Header,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("odom -> base_link") && e.contains("world -> robot"),
            "{e}"
        );
        let e = pose_track(
            &b,
            &PoseSource {
                topic: "/tf".into(),
                frame: None,
                parent: None,
            },
            Stamps::Header,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("--pose-frame"), "{e}");
        let e = pose_track(
            &b,
            &PoseSource {
                topic: "/joint_states".into(),
                frame: None,
                parent: None,
            },
            Stamps::Header,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("is sensor_msgs/msg/JointState; a reference pose"),
            "{e}"
        );
    }
}
