//! `twindrive bag info`: what `ros2 bag info` prints about a recording, any
//! damage, which topics a calibration can use (wheels, references, scans,
//! IMU) and a suggested `calibrate --bag` command line.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;
use twindrive_ros::extract::{NumberField, Stamps, number_track};
use twindrive_ros::{Bag, MessageRef, Value};

/// Names that mark an external reference (motion capture, a tracker, a
/// simulator's truth).
const REFERENCE_HINTS: &[&str] = &[
    "mocap",
    "vicon",
    "optitrack",
    "qualisys",
    "tracker",
    "ground_truth",
    "groundtruth",
    "gt",
];

/// A topic or TF frame that can serve as calibration's pose reference.
#[derive(Debug, Clone, PartialEq)]
struct Reference {
    topic: String,
    /// TF: the child frame (and its parent).
    frame: Option<(String, String)>,
    what: String,
    count: u64,
    /// Named like an external reference.
    hinted: bool,
}

/// What a JointState topic carries.
#[derive(Debug, Default)]
struct Joints {
    names: Vec<String>,
    position: bool,
    velocity: bool,
}

/// The report on `path`.
pub fn describe(path: &Path) -> anyhow::Result<String> {
    let bag = Bag::open(path)?;
    let mut o = String::new();
    summary(&bag, &mut o);
    for d in bag.damage() {
        let _ = writeln!(o, "\nwarning: {d}");
    }
    usable(&bag, path, &mut o).context("reading the topics")?;
    Ok(o)
}

fn seconds(ns: u64) -> String {
    format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000)
}

fn utc(ns: u64) -> String {
    let t = std::time::UNIX_EPOCH + std::time::Duration::from_nanos(ns);
    humantime::format_rfc3339_nanos(t).to_string()
}

fn size(bytes: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = bytes as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < units.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{bytes} B")
    } else {
        format!("{v:.1} {}", units[u])
    }
}

/// `ros2 bag info`'s block.
fn summary(bag: &Bag, o: &mut String) {
    let files = bag.files();
    let names: Vec<String> = files
        .iter()
        .map(|f| {
            f.path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        })
        .collect();
    let _ = writeln!(
        o,
        "Files:             {}",
        names.join("\n                   ")
    );
    let _ = writeln!(
        o,
        "Bag size:          {}",
        size(files.iter().map(|f| f.size_bytes).sum())
    );
    let compression = if files.iter().any(|f| f.compressed) {
        " (files compressed with zstd)"
    } else {
        ""
    };
    let _ = writeln!(
        o,
        "Storage id:        {}{compression}",
        bag.storage().identifier()
    );
    if let Some(m) = bag.metadata() {
        let _ = writeln!(o, "Metadata version:  {}", m.version);
    } else {
        let _ = writeln!(
            o,
            "Metadata version:  none (no metadata.yaml: files in the order of their first message)"
        );
    }
    if let Some(d) = bag.ros_distro() {
        let _ = writeln!(o, "ROS distro:        {d}");
    }
    match bag.time_range_ns() {
        Some((a, b)) => {
            let _ = writeln!(o, "Duration:          {}s", seconds(b - a));
            let _ = writeln!(o, "Start:             {} ({})", utc(a), seconds(a));
            let _ = writeln!(o, "End:               {} ({})", utc(b), seconds(b));
        }
        None => {
            let _ = writeln!(o, "Duration:          0s (no messages)");
        }
    }
    let _ = writeln!(o, "Messages:          {}", bag.message_count());
    let width = bag.topics().iter().map(|t| t.name.len()).max().unwrap_or(0);
    for (i, t) in bag.topics().iter().enumerate() {
        let _ = writeln!(
            o,
            "{}Topic: {:<width$} | Type: {} | Count: {} | Serialization Format: {}",
            if i == 0 {
                "Topic information: "
            } else {
                "                   "
            },
            t.name,
            t.type_name,
            t.message_count,
            t.message_encoding,
        );
    }
}

fn is_wheel_odometry(topic: &str, frames: Option<(&str, &str)>) -> bool {
    match frames {
        Some((parent, child)) => {
            parent.trim_start_matches('/') == "odom"
                && matches!(
                    child.trim_start_matches('/'),
                    "base_link" | "base_footprint"
                )
        }
        None => {
            let last = topic.rsplit('/').next().unwrap_or(topic);
            last == "odom" || last.starts_with("odom") || topic.contains("wheel_odom")
        }
    }
}

fn hinted(name: &str) -> bool {
    let lower = name.to_ascii_lowercase();
    lower
        .split(|c: char| !c.is_ascii_alphanumeric() && c != '_')
        .any(|part| REFERENCE_HINTS.contains(&part))
        || REFERENCE_HINTS
            .iter()
            .filter(|h| h.len() > 2)
            .any(|h| lower.contains(h))
}

/// What the joint-state, odometry and TF topics hold.
#[derive(Default)]
struct Seen {
    joints: BTreeMap<String, Joints>,
    /// (topic, parent, child) → transforms.
    tf_pairs: BTreeMap<(String, String, String), u64>,
    /// topic → (child frame, messages).
    odom_children: BTreeMap<String, (String, u64)>,
}

impl Seen {
    fn absorb(&mut self, topic: &str, m: &MessageRef<'_>) -> Result<(), String> {
        let schema = m.schema;
        match schema.root().name.as_str() {
            "sensor_msgs/msg/JointState" => {
                let j = self.joints.entry(topic.to_string()).or_default();
                let names = schema.path("name").map_err(|e| e.to_string())?;
                if let Some(list) = m.value.at(&names).and_then(Value::as_array) {
                    for n in list.iter().filter_map(Value::as_str) {
                        if j.names.len() < 64 && !j.names.iter().any(|x| x == n) {
                            j.names.push(n.to_string());
                        }
                    }
                    let len = |f: &str| {
                        schema
                            .path(f)
                            .ok()
                            .and_then(|p| m.value.at(&p).and_then(Value::as_array).map(<[_]>::len))
                            .unwrap_or(0)
                    };
                    j.position |= len("position") == list.len() && !list.is_empty();
                    j.velocity |= len("velocity") == list.len() && !list.is_empty();
                }
            }
            "nav_msgs/msg/Odometry" => {
                let child = schema
                    .path("child_frame_id")
                    .ok()
                    .and_then(|p| m.value.at(&p).and_then(Value::as_str).map(str::to_string))
                    .unwrap_or_default();
                let e = self
                    .odom_children
                    .entry(topic.to_string())
                    .or_insert((child, 0));
                e.1 += 1;
            }
            _ => {
                let list = schema.path("transforms").map_err(|e| e.to_string())?;
                let twindrive_ros::Base::Message(ts) = list.ty.base else {
                    return Ok(());
                };
                let child = schema
                    .path_from(ts, "child_frame_id")
                    .map_err(|e| e.to_string())?;
                let parent = schema
                    .path_from(ts, "header.frame_id")
                    .map_err(|e| e.to_string())?;
                for tr in m.value.at(&list).and_then(Value::as_array).unwrap_or(&[]) {
                    if let (Some(c), Some(p)) = (
                        tr.at(&child).and_then(Value::as_str),
                        tr.at(&parent).and_then(Value::as_str),
                    ) {
                        *self
                            .tf_pairs
                            .entry((
                                topic.to_string(),
                                p.trim_start_matches('/').to_string(),
                                c.trim_start_matches('/').to_string(),
                            ))
                            .or_default() += 1;
                    }
                }
            }
        }
        Ok(())
    }

    fn forget(&mut self, topic: &str) {
        self.joints.remove(topic);
        self.odom_children.remove(topic);
        self.tf_pairs.retain(|(t, _, _), _| t != topic);
    }
}

/// Which topics calibration can use, and a command line.
fn usable(bag: &Bag, path: &Path, o: &mut String) -> anyhow::Result<()> {
    let mut refs: Vec<Reference> = Vec::new();
    let mut wheel_odometry: Vec<String> = Vec::new();
    // Odometry a map can be drawn from: `(topic, is TF)`, Odometry first.
    let mut map_odometry: Vec<(String, bool)> = Vec::new();
    let mut scans = Vec::new();
    let mut imus = Vec::new();
    let mut scan_topics: Vec<String> = Vec::new();
    let mut imu_topics: Vec<String> = Vec::new();
    let mut ticks: Vec<(String, String, Vec<String>)> = Vec::new();
    // Plain-number topics that may carry wheel speeds: one number per
    // topic, or an array.
    let mut speed_topics: Vec<String> = Vec::new();
    let mut speed_arrays: Vec<String> = Vec::new();
    let mut unreadable: Vec<String> = Vec::new();
    let mut decode: Vec<&str> = Vec::new();
    for t in bag.topics() {
        let ty = t.type_name.as_str();
        match ty {
            "sensor_msgs/msg/JointState" | "nav_msgs/msg/Odometry" | "tf2_msgs/msg/TFMessage" => {
                decode.push(&t.name)
            }
            "geometry_msgs/msg/PoseStamped" | "geometry_msgs/msg/PoseWithCovarianceStamped" => refs
                .push(Reference {
                    topic: t.name.clone(),
                    frame: None,
                    what: ty.to_string(),
                    count: t.message_count,
                    hinted: hinted(&t.name),
                }),
            "sensor_msgs/msg/LaserScan" => {
                scans.push(format!("{} ({ty})", t.name));
                if t.message_count > 0 {
                    scan_topics.push(t.name.clone());
                }
            }
            "sensor_msgs/msg/Imu" => {
                imus.push(format!("{} ({ty})", t.name));
                if t.message_count > 0 {
                    imu_topics.push(t.name.clone());
                }
            }
            "std_msgs/msg/Float64" | "std_msgs/msg/Float32" if t.message_count > 1 => {
                speed_topics.push(t.name.clone())
            }
            "std_msgs/msg/Float64MultiArray" | "std_msgs/msg/Float32MultiArray"
                if t.message_count > 1 =>
            {
                speed_arrays.push(t.name.clone())
            }
            _ if t.message_count > 0 && !standard_non_tick(ty) => {
                if let Ok(schema) = bag.schema(&t.name) {
                    let fields: Vec<String> = schema
                        .integer_fields()
                        .into_iter()
                        .filter(|f| !f.ends_with(".sec") && !f.ends_with(".nanosec"))
                        .collect();
                    if fields.len() >= 2 {
                        ticks.push((t.name.clone(), ty.to_string(), fields));
                    }
                }
            }
            _ => {}
        }
    }
    // The topics whose messages are read, if their definitions parse.
    let mut readable: Vec<&str> = Vec::new();
    for t in &decode {
        match bag.schema(t) {
            Ok(_) => readable.push(t),
            Err(e) => unreadable.push(e.to_string()),
        }
    }
    // One pass over every topic; if a message does not decode, topic by
    // topic, so it costs only its topic.
    let mut seen = Seen::default();
    if bag
        .for_each_of(&readable, |k, m| seen.absorb(readable[k], &m))
        .is_err()
    {
        seen = Seen::default();
        for topic in &readable {
            if let Err(e) = bag.for_each(topic, |m| seen.absorb(topic, &m)) {
                seen.forget(topic);
                unreadable.push(e.to_string());
            }
        }
    }
    let Seen {
        joints,
        tf_pairs,
        odom_children,
    } = seen;
    // Frames on the robot (the base and everything mounted on it): an edge
    // from one of them, or into `odom`, is not the robot's pose in the world.
    let mut on_robot: Vec<String> = vec!["base_link".into(), "base_footprint".into()];
    loop {
        let more: Vec<String> = tf_pairs
            .keys()
            .filter(|(_, p, c)| on_robot.contains(p) && !on_robot.contains(c))
            .map(|(_, _, c)| c.clone())
            .collect();
        if more.is_empty() {
            break;
        }
        on_robot.extend(more);
    }
    for (topic, (child, count)) in &odom_children {
        if is_wheel_odometry(topic, None) && !hinted(topic) {
            wheel_odometry.push(format!(
                "{topic} (nav_msgs/msg/Odometry, child frame `{child}`)"
            ));
            map_odometry.push((topic.clone(), false));
        } else {
            refs.push(Reference {
                topic: topic.clone(),
                frame: None,
                what: format!("nav_msgs/msg/Odometry, child frame `{child}`"),
                count: *count,
                hinted: hinted(topic),
            });
        }
    }
    for ((topic, parent, child), count) in &tf_pairs {
        if topic.ends_with("tf_static") || on_robot.contains(parent) || child == "odom" {
            continue;
        }
        if is_wheel_odometry(topic, Some((parent, child))) {
            wheel_odometry.push(format!("{topic}: {parent} -> {child}"));
            if !map_odometry.iter().any(|(t, _)| t == topic) {
                map_odometry.push((topic.clone(), true));
            }
        } else {
            refs.push(Reference {
                topic: topic.clone(),
                frame: Some((parent.clone(), child.clone())),
                what: format!("TF {parent} -> {child}"),
                count: *count,
                hinted: hinted(child) || hinted(parent),
            });
        }
    }
    let duration_s = bag
        .time_range_ns()
        .map(|(a, b)| (b - a) as f64 * 1e-9)
        .unwrap_or(0.0);
    let rate = |n: u64| {
        if duration_s > 0.0 {
            format!("{:.1} Hz", n as f64 / duration_s)
        } else {
            "-".into()
        }
    };

    let _ = writeln!(o, "\nFor calibration (`twindrive calibrate --bag`):");
    let _ = writeln!(o, "  wheels (joint states):");
    if joints.is_empty() {
        let _ = writeln!(o, "    none");
    }
    for (topic, j) in &joints {
        let signals = match (j.position, j.velocity) {
            (true, true) => "position and velocity",
            (true, false) => "position",
            (false, true) => "velocity",
            (false, false) => "neither position nor velocity for every joint",
        };
        let _ = writeln!(o, "    {topic}: joints {} ({signals})", j.names.join(", "));
    }
    let _ = writeln!(o, "  wheels (two integer fields, encoder ticks):");
    if ticks.is_empty() {
        let _ = writeln!(o, "    none");
    }
    for (topic, ty, fields) in &ticks {
        let _ = writeln!(o, "    {topic} ({ty}): {}", fields.join(", "));
    }
    let speeds = wheel_speeds(bag, &speed_topics, &speed_arrays);
    let _ = writeln!(o, "  wheels (speeds as plain numbers, integrated):");
    match &speeds {
        Some(s) => {
            let _ = writeln!(o, "    {}", s.describe());
        }
        None if speed_topics.is_empty() && speed_arrays.is_empty() => {
            let _ = writeln!(o, "    none");
        }
        None => {
            let _ = writeln!(
                o,
                "    cannot tell the two wheels among {}",
                speed_topics
                    .iter()
                    .chain(&speed_arrays)
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
    }
    refs.sort_by(|a, b| b.hinted.cmp(&a.hinted).then(b.count.cmp(&a.count)));
    let _ = writeln!(o, "  pose references (best first):");
    if refs.is_empty() {
        let _ = writeln!(o, "    none");
    }
    for r in &refs {
        let _ = writeln!(
            o,
            "    {} ({}, {} messages, {})",
            r.topic,
            r.what,
            r.count,
            rate(r.count)
        );
    }
    if !wheel_odometry.is_empty() {
        let _ = writeln!(
            o,
            "  wheel odometry (computed from the wheels, so not a reference):"
        );
        for w in &wheel_odometry {
            let _ = writeln!(o, "    {w}");
        }
    }
    let _ = writeln!(o, "  scans: {}", list_or_none(&scans));
    let _ = writeln!(o, "  IMU: {}", list_or_none(&imus));
    for u in &unreadable {
        let _ = writeln!(o, "  cannot read: {u}");
    }
    // The robot's description: the nominal wheels `map` and `calibrate`
    // take when no flag gives them.
    let described = crate::described_wheels::of_bag(bag);
    match &described {
        Ok(d) => {
            let _ = writeln!(o, "  robot description: {}", d.summary());
        }
        Err(why)
            if bag
                .topics()
                .iter()
                .any(|t| t.name.ends_with("robot_description")) =>
        {
            let _ = writeln!(o, "  robot description: {why}");
        }
        Err(_) => {
            let _ = writeln!(o, "  robot description: none");
        }
    }
    let described = described.ok().map(|d| d.topic);
    // Without a description, the wheels' nominal sizes are the user's to give.
    let initial = if described.is_some() {
        ""
    } else {
        " --initial DL,DR,B"
    };

    let wheel_flags = match joints
        .iter()
        .find_map(|(t, j)| wheel_pair(&j.names).map(|(l, r)| (t, l, r)))
    {
        Some((topic, l, r)) => {
            let mut f = String::new();
            if topic != "/joint_states" {
                let _ = write!(f, " --joint-topic {topic}");
            }
            let _ = write!(f, " --left-joint {l} --right-joint {r}");
            Some(f)
        }
        None => ticks
            .first()
            .map(|(topic, _, fields)| {
                format!(
                    " --ticks-topic {topic} --left-field {} --right-field {} --ticks-per-rev TICKS",
                    fields[0], fields[1]
                )
            })
            .or_else(|| speeds.as_ref().map(WheelSpeeds::flags)),
    };
    let reference = refs.first().map(|r| match &r.frame {
        Some((parent, child)) => format!(
            " --pose-topic {} --pose-frame {child} --pose-parent {parent}",
            r.topic
        ),
        None => format!(" --pose-topic {}", r.topic),
    });
    // Without a pose reference: the wheels and the lidar's mount (and the
    // gyro) from the scans.
    let self_cal = match (&wheel_flags, scan_topics.first()) {
        (Some(w), Some(scan)) => {
            let imu = imu_topics
                .first()
                .map(|t| format!(" --imu-topic {t}"))
                .unwrap_or_default();
            // Self-calibration needs 30 matched intervals: a short drive
            // gets shorter ones.
            let interval = if duration_s < 60.0 {
                " --interval-s 0.5"
            } else {
                ""
            };
            Some(format!(
                "twindrive calibrate --bag {}{w} --scan-topic {scan}{imu}{interval}{initial} --out calib.json",
                shell_quote(&path.display().to_string())
            ))
        }
        _ => None,
    };
    // The map: from the robot's odometry, else from the wheels with a
    // calibration.
    if let Some(scan) = scan_topics.first() {
        let bag = shell_quote(&path.display().to_string());
        map_odometry.sort_by_key(|(_, tf)| *tf);
        let map = match (map_odometry.first(), &wheel_flags) {
            (Some((topic, _)), _) if described.is_some() => Some(format!(
                "twindrive map --bag {bag} --scan-topic {scan} --odom-topic {topic} --out site\n  \
                 (the twin's robot takes its wheels from {}; or give them with --wheel-diameter-m D --wheelbase-m B, \
                 or --calibration calib.json)",
                described.as_deref().unwrap_or_default()
            )),
            (None, Some(w)) if described.is_some() => Some(format!(
                "twindrive map --bag {bag}{w} --scan-topic {scan} --calibration calib.json --out site\n  \
                 (calib.json: from the calibrate command line below; or, with the nominal wheels of {}, \
                 leave out --calibration)",
                described.as_deref().unwrap_or_default()
            )),
            (Some((topic, _)), _) => Some(format!(
                "twindrive map --bag {bag} --scan-topic {scan} --odom-topic {topic} --wheel-diameter-m D --wheelbase-m B --out site\n  \
                 (D, B: the robot's wheel diameter and wheelbase in metres, for the twin's robot; or --calibration calib.json)"
            )),
            (None, Some(w)) => Some(format!(
                "twindrive map --bag {bag}{w} --scan-topic {scan} --calibration calib.json --out site\n  \
                 (calib.json: from the calibrate command line below; or, with the nominal wheels, \
                 --wheel-diameter-m D --wheelbase-m B instead of --calibration)"
            )),
            (None, None) => None,
        };
        match map {
            Some(m) => {
                let _ = writeln!(o, "\nFor the site's map:\n  {m}");
            }
            None => {
                let _ = writeln!(
                    o,
                    "\nNo map command line to suggest: the bag has scans but neither odometry nor wheel data."
                );
            }
        }
    }
    let guess = match &described {
        Some(d) => format!("the wheels' first guess from {d}"),
        None => "DL,DR,B: your robot's nominal wheel diameters and wheelbase in metres".to_string(),
    };
    match (wheel_flags, reference) {
        (Some(w), Some(p)) => {
            let _ = writeln!(
                o,
                "\nSuggested ({guess}):\n  twindrive calibrate --bag {}{w}{p} --time-offset auto{initial} --out calib.json",
                shell_quote(&path.display().to_string())
            );
            if let Some(c) = &self_cal {
                let _ = writeln!(
                    o,
                    "Without the pose reference (self-calibration, the lidar's mount too):\n  {c}"
                );
            }
        }
        (Some(_), None) if self_cal.is_some() => {
            let _ = writeln!(
                o,
                "\nSuggested, with no pose reference (self-calibration of the wheels and the lidar's mount; \
                 {guess}):\n  {}",
                self_cal.as_deref().unwrap_or_default()
            );
        }
        (w, p) => {
            let _ = writeln!(
                o,
                "\nNo calibrate command line to suggest: {}.",
                match (w, p) {
                    (None, None) => "the bag has neither wheel data nor a pose reference",
                    (None, _) =>
                        "the bag has no wheel data (two wheel joints, two integer tick fields, or two wheel speeds)",
                    _ => "the bag has no pose reference besides wheel odometry",
                }
            );
        }
    }
    Ok(())
}

/// Standard packages whose messages never carry wheel ticks (std_msgs'
/// integer arrays and robot vendors' packages may).
fn standard_non_tick(type_name: &str) -> bool {
    const PACKAGES: &[&str] = &[
        "action_msgs",
        "builtin_interfaces",
        "diagnostic_msgs",
        "geometry_msgs",
        "lifecycle_msgs",
        "map_msgs",
        "nav_msgs",
        "rcl_interfaces",
        "rosgraph_msgs",
        "sensor_msgs",
        "shape_msgs",
        "statistics_msgs",
        "stereo_msgs",
        "tf2_msgs",
        "trajectory_msgs",
        "unique_identifier_msgs",
        "visualization_msgs",
    ];
    PACKAGES.contains(&type_name.split('/').next().unwrap_or(""))
}

fn list_or_none(v: &[String]) -> String {
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

/// Two wheel speeds as plain numbers: two topics, or two elements of one
/// array topic; with the sign a wheel's numbers need.
#[derive(Debug, Clone, PartialEq)]
struct WheelSpeeds {
    left: NumberField,
    right: NumberField,
    /// Which wheel's numbers run backwards when the robot drives (the one
    /// whose mean is negative while the other's is positive: a motor
    /// mounted mirrored), if one does.
    backwards: Option<&'static str>,
}

impl WheelSpeeds {
    fn describe(&self) -> String {
        let side = |n: &NumberField| {
            if n.field == "data" {
                n.topic.clone()
            } else {
                format!("{} {}", n.topic, n.field)
            }
        };
        format!(
            "left {}, right {}{}; taken as rad/s (--speed-unit rev-per-s if they are turns)",
            side(&self.left),
            side(&self.right),
            match self.backwards {
                Some(w) => format!(
                    "; the {w} one's mean is negative while the other's is positive (a mirrored motor): --{w}-sign -1"
                ),
                None => String::new(),
            }
        )
    }

    fn flags(&self) -> String {
        let mut f = String::new();
        for (side, n) in [("left", &self.left), ("right", &self.right)] {
            let _ = write!(f, " --{side}-speed-topic {}", n.topic);
            if n.field != "data" {
                let _ = write!(f, " --{side}-speed-field '{}'", n.field);
            }
        }
        if let Some(w) = self.backwards {
            let _ = write!(f, " --{w}-sign -1");
        }
        f
    }
}

/// The wheel speeds among the plain-number topics, if two can be told
/// apart: by `left`/`right` in their names, else the only two (in name
/// order: `axis0` is the left); else an array topic's first two elements.
fn wheel_speeds(bag: &Bag, topics: &[String], arrays: &[String]) -> Option<WheelSpeeds> {
    let field = |t: &String, f: &str| NumberField {
        topic: t.clone(),
        field: f.to_string(),
    };
    let by_side = |side: &str| {
        let mut m = topics
            .iter()
            .filter(|t| t.to_ascii_lowercase().contains(side));
        let first = m.next()?;
        m.next().is_none().then_some(first)
    };
    let (left, right) = match (by_side("left"), by_side("right")) {
        (Some(l), Some(r)) => (field(l, "data"), field(r, "data")),
        _ if topics.len() == 2 => {
            let mut two = [&topics[0], &topics[1]];
            two.sort();
            (field(two[0], "data"), field(two[1], "data"))
        }
        _ if arrays.len() == 1 => (field(&arrays[0], "data[0]"), field(&arrays[0], "data[1]")),
        _ => return None,
    };
    let backwards = match (mean_of(bag, &left), mean_of(bag, &right)) {
        (Some(l), Some(r)) if l < 0.0 && r > 0.0 => Some("left"),
        (Some(l), Some(r)) if r < 0.0 && l > 0.0 => Some("right"),
        _ => None,
    };
    Some(WheelSpeeds {
        left,
        right,
        backwards,
    })
}

/// The mean of a number field over a topic's messages, if every message
/// has it (read as `map` and `calibrate` read it).
fn mean_of(bag: &Bag, field: &NumberField) -> Option<f64> {
    let track = number_track(bag, field, Stamps::LogTime).ok()?;
    (!track.is_empty()).then(|| track.iter().map(|(_, v)| v).sum::<f64>() / track.len() as f64)
}

/// The left and right wheel joints among `names`, if they can be told.
fn wheel_pair(names: &[String]) -> Option<(&str, &str)> {
    let find = |side: &str| {
        let mut m = names.iter().filter(|n| {
            let l = n.to_ascii_lowercase();
            l.contains(side) && l.contains("wheel")
        });
        let first = m.next()?;
        m.next().is_none().then_some(first.as_str())
    };
    match (find("left"), find("right")) {
        (Some(l), Some(r)) => Some((l, r)),
        _ if names.len() == 2 => Some((&names[0], &names[1])),
        _ => None,
    }
}

fn shell_quote(s: &str) -> String {
    if s.chars()
        .all(|c| c.is_ascii_alphanumeric() || "/._-+:@%".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn references_and_wheel_odometry_are_told_apart() {
        assert!(hinted("/mocap/pose") && hinted("/vicon/robot_1") && hinted("/ground_truth"));
        assert!(!hinted("/amcl_pose") && !hinted("/odom"));
        assert!(is_wheel_odometry("/odom", None));
        assert!(is_wheel_odometry("/tf", Some(("odom", "base_link"))));
        assert!(!is_wheel_odometry("/tf", Some(("world", "robot"))));
    }

    /// A robot without motion capture: nav2's `/amcl_pose`, and a `/tf`
    /// full of edges that are not the robot's pose in the world (the wheels
    /// on the base, `map -> odom`, wheel odometry).
    #[test]
    fn the_suggested_reference_is_a_pose_of_the_robot_in_the_world() {
        use twindrive_ros::msgs::{
            Distro, Header, JointState, Pose, PoseWithCovariance, PoseWithCovarianceStamped,
            TFMessage, TransformStamped,
        };
        use twindrive_ros::{BagWriter, Qos};
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b_0.db3");
        let mut w = BagWriter::sqlite3(&path, "b_0.db3", Distro::Humble).unwrap();
        let js = w
            .topic::<JointState>("/joint_states", Qos::DEFAULT)
            .unwrap();
        let tf = w.topic::<TFMessage>("/tf", Qos::DEFAULT).unwrap();
        let amcl = w
            .topic::<PoseWithCovarianceStamped>("/amcl_pose", Qos::DEFAULT)
            .unwrap();
        for k in 0..200u64 {
            let t = 1_000_000_000 + k * 20_000_000;
            let a = k as f64 * 0.01;
            w.write(
                js,
                t,
                &JointState {
                    header: Header::new(t, ""),
                    name: vec!["wheel_left_joint".into(), "wheel_right_joint".into()],
                    position: vec![a, a],
                    velocity: vec![],
                    effort: vec![],
                },
            )
            .unwrap();
            let transforms = vec![
                TransformStamped::planar(t, "base_link", "wheel_left_link", 0.0, 0.08, a),
                TransformStamped::planar(t, "base_link", "wheel_right_link", 0.0, -0.08, a),
                TransformStamped::planar(t, "wheel_left_link", "left_tyre", 0.0, 0.0, 0.0),
                TransformStamped::planar(t, "odom", "base_link", a, 0.0, 0.0),
            ];
            w.write(tf, t, &TFMessage { transforms }).unwrap();
            if k % 25 == 0 {
                let map_odom = TransformStamped::planar(t, "map", "odom", 0.1, 0.0, 0.0);
                w.write(
                    tf,
                    t,
                    &TFMessage {
                        transforms: vec![map_odom],
                    },
                )
                .unwrap();
                let pose = PoseWithCovarianceStamped {
                    header: Header::new(t, "map"),
                    pose: PoseWithCovariance {
                        pose: Pose::planar(a, 0.0, 0.0),
                        ..Default::default()
                    },
                };
                w.write(amcl, t, &pose).unwrap();
            }
        }
        std::fs::write(dir.path().join("metadata.yaml"), w.finish().unwrap()).unwrap();
        let text = describe(dir.path()).unwrap();
        let suggested = text.lines().last().unwrap();
        assert!(
            suggested.contains("--pose-topic /amcl_pose")
                && suggested
                    .contains("--left-joint wheel_left_joint --right-joint wheel_right_joint"),
            "{text}"
        );
        for not_a_reference in ["wheel_left_link", "left_tyre", "TF map -> odom"] {
            assert!(!text.contains(not_a_reference), "{not_a_reference}: {text}");
        }
        assert!(text.contains("/tf: odom -> base_link"), "{text}");
    }

    /// Wheel speeds in one array topic (a ros2_control forward
    /// controller's), the left motor mirrored; two named topics beside it
    /// are told apart by name.
    #[test]
    fn wheel_speed_topics_are_suggested_with_the_mirrored_wheel() {
        use twindrive_ros::msgs::{Distro, Float64, Float64MultiArray};
        use twindrive_ros::{BagWriter, Qos};
        let write = |dir: &Path, two_topics: bool| {
            let path = dir.join("b_0.db3");
            let mut w = BagWriter::sqlite3(&path, "b_0.db3", Distro::Humble).unwrap();
            let array = w
                .topic::<Float64MultiArray>("/wheel_speeds", Qos::DEFAULT)
                .unwrap();
            let sides = two_topics.then(|| {
                (
                    w.topic::<Float64>("/right_wheel/speed", Qos::DEFAULT)
                        .unwrap(),
                    w.topic::<Float64>("/left_wheel/speed", Qos::DEFAULT)
                        .unwrap(),
                )
            });
            for k in 0..50u64 {
                let t = 1_000_000_000 + k * 20_000_000;
                let msg = Float64MultiArray {
                    data: vec![-3.0, 2.5],
                    ..Default::default()
                };
                w.write(array, t, &msg).unwrap();
                if let Some((r, l)) = sides {
                    w.write(r, t, &Float64 { data: 2.5 }).unwrap();
                    w.write(l, t, &Float64 { data: -3.0 }).unwrap();
                }
            }
            std::fs::write(dir.join("metadata.yaml"), w.finish().unwrap()).unwrap();
            let bag = Bag::open(dir).unwrap();
            let arrays = ["/wheel_speeds".to_string()];
            let topics: Vec<String> = if two_topics {
                vec!["/right_wheel/speed".into(), "/left_wheel/speed".into()]
            } else {
                vec![]
            };
            (describe(dir).unwrap(), wheel_speeds(&bag, &topics, &arrays))
        };
        let dir = tempfile::tempdir().unwrap();
        let (text, found) = write(dir.path(), false);
        assert!(
            text.contains("left /wheel_speeds data[0], right /wheel_speeds data[1]; the left one's mean is negative"),
            "{text}"
        );
        assert_eq!(
            found.unwrap().flags(),
            " --left-speed-topic /wheel_speeds --left-speed-field 'data[0]' \
             --right-speed-topic /wheel_speeds --right-speed-field 'data[1]' --left-sign -1"
        );
        let dir = tempfile::tempdir().unwrap();
        let (text, found) = write(dir.path(), true);
        assert!(
            text.contains("left /left_wheel/speed, right /right_wheel/speed"),
            "{text}"
        );
        assert_eq!(
            found.unwrap().flags(),
            " --left-speed-topic /left_wheel/speed --right-speed-topic /right_wheel/speed --left-sign -1"
        );
    }

    #[test]
    fn wheel_joints_are_found_by_name() {
        let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(
            wheel_pair(&names(&[
                "arm_joint",
                "wheel_right_joint",
                "wheel_left_joint"
            ])),
            Some(("wheel_left_joint", "wheel_right_joint"))
        );
        assert_eq!(wheel_pair(&names(&["a", "b"])), Some(("a", "b")));
        assert_eq!(wheel_pair(&names(&["a", "b", "c"])), None);
    }
}
