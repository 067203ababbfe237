//! The mission log as MCAP with JSON-schema channels that open in Foxglove.
//!
//! Topics: `/ground_truth` and `/tracker` (`foxglove.PoseInFrame`, plus an
//! exact `heading_rad`), `/tf` (`foxglove.FrameTransform`, world -> base_link),
//! `/range/<name>` (`foxglove.LaserScan` in frame `base_link`), `/wheels`,
//! `/encoders` and `/bump` (twindrive schemas), `/gyro` (`twindrive.Gyro`)
//! when the robot has a gyro, and with a map the world's
//! walls on `/map` ([`crate::map_topic`]). The log header is the metadata
//! record `twindrive.log_header`.

use std::collections::{BTreeMap, HashMap};
use std::io::{Seek, Write};
use std::path::Path;

use serde::{Deserialize, Serialize};
use serde_json::json;
use twindrive_kinematics::Pose;

use crate::{LogError, LogHeader, MissionLog, StepRecord};

const HEADER_METADATA: &str = "twindrive.log_header";

#[derive(Serialize, Deserialize, Clone, Copy)]
struct Stamp {
    sec: u64,
    nsec: u32,
}

impl Stamp {
    fn new(t_ns: u64) -> Self {
        Self {
            sec: t_ns / 1_000_000_000,
            nsec: (t_ns % 1_000_000_000) as u32,
        }
    }
}

#[derive(Serialize, Deserialize)]
struct Vec3 {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Serialize, Deserialize)]
struct Quat {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

fn yaw_quat(heading_rad: f64) -> Quat {
    let (z, w) = (0.5 * heading_rad).sin_cos();
    Quat {
        x: 0.0,
        y: 0.0,
        z,
        w,
    }
}

#[derive(Serialize, Deserialize)]
struct PoseMsg {
    position: Vec3,
    orientation: Quat,
}

impl PoseMsg {
    fn planar(p: &Pose) -> Self {
        Self {
            position: Vec3 {
                x: p.x_m,
                y: p.y_m,
                z: 0.0,
            },
            orientation: yaw_quat(p.heading_rad),
        }
    }
}

#[derive(Serialize, Deserialize)]
struct PoseInFrame {
    timestamp: Stamp,
    frame_id: String,
    pose: PoseMsg,
    heading_rad: f64,
}

#[derive(Serialize)]
struct FrameTransform {
    timestamp: Stamp,
    parent_frame_id: &'static str,
    child_frame_id: &'static str,
    translation: Vec3,
    rotation: Quat,
}

#[derive(Serialize, Deserialize)]
struct LaserScan {
    timestamp: Stamp,
    frame_id: String,
    pose: PoseMsg,
    start_angle: f64,
    end_angle: f64,
    ranges: Vec<f64>,
    intensities: Vec<f64>,
}

#[derive(Serialize, Deserialize)]
struct Wheels {
    timestamp: Stamp,
    cmd_left_rad_s: f64,
    cmd_right_rad_s: f64,
    left_rad_s: f64,
    right_rad_s: f64,
}

#[derive(Serialize, Deserialize)]
struct Encoders {
    timestamp: Stamp,
    left_ticks: i64,
    right_ticks: i64,
}

#[derive(Serialize, Deserialize)]
struct Bump {
    timestamp: Stamp,
    pressed: bool,
}

#[derive(Serialize, Deserialize)]
struct Gyro {
    timestamp: Stamp,
    z_rad_s: f64,
}

fn time_schema() -> serde_json::Value {
    json!({"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}})
}

fn vec3_schema() -> serde_json::Value {
    json!({"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}})
}

fn quat_schema() -> serde_json::Value {
    json!({"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}}})
}

fn pose_schema() -> serde_json::Value {
    json!({"type": "object", "properties": {"position": vec3_schema(), "orientation": quat_schema()}})
}

fn object_schema(title: &str, props: serde_json::Value) -> Vec<u8> {
    let mut props = props;
    props["timestamp"] = time_schema();
    serde_json::to_vec(&json!({"title": title, "type": "object", "properties": props}))
        .expect("static schema serialises")
}

/// A writer with the project's options: zstd chunks, no profile, the
/// library named; no wall-clock time recorded.
fn writer<W: Write + Seek>(out: W) -> mcap::McapResult<mcap::Writer<W>> {
    mcap::WriteOptions::new()
        .profile("")
        .library(concat!("twindrive-log ", env!("CARGO_PKG_VERSION")))
        .compression(Some(mcap::Compression::Zstd))
        .create(out)
}

/// Writes a JSON metadata record `name` holding `{"json": json}`.
fn write_json_metadata<W: Write + Seek>(
    w: &mut mcap::Writer<W>,
    name: &str,
    json: String,
) -> mcap::McapResult<()> {
    w.write_metadata(&mcap::records::Metadata {
        name: name.into(),
        metadata: BTreeMap::from([("json".to_string(), json)]),
    })
}

/// The `foxglove.PoseInFrame` schema (plus an exact `heading_rad`).
fn add_pose_in_frame_schema<W: Write + Seek>(w: &mut mcap::Writer<W>) -> mcap::McapResult<u16> {
    w.add_schema(
        "foxglove.PoseInFrame",
        "jsonschema",
        &object_schema(
            "foxglove.PoseInFrame",
            json!({"frame_id": {"type": "string"}, "pose": pose_schema(), "heading_rad": {"type": "number"}}),
        ),
    )
}

/// Writes JSON messages with one running sequence number and one reused buffer.
struct Emitter {
    sequence: u32,
    buf: Vec<u8>,
}

impl Emitter {
    fn new() -> Self {
        Self {
            sequence: 0,
            buf: Vec::with_capacity(1024),
        }
    }

    fn emit<W: Write + Seek>(
        &mut self,
        w: &mut mcap::Writer<W>,
        channel_id: u16,
        t_ns: u64,
        msg: &dyn erased::Json,
    ) -> mcap::McapResult<()> {
        self.buf.clear();
        msg.write_json(&mut self.buf);
        self.sequence = self.sequence.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: t_ns,
            publish_time: t_ns,
        };
        w.write_to_known_channel(&header, &self.buf)
    }
}

struct Channels {
    ground_truth: u16,
    tracker: u16,
    tf: u16,
    wheels: u16,
    encoders: u16,
    bump: u16,
    ranges: Vec<u16>,
    gyro: Option<u16>,
}

fn add_channels<W: Write + Seek>(
    w: &mut mcap::Writer<W>,
    header: &LogHeader,
) -> mcap::McapResult<Channels> {
    let none = BTreeMap::new();
    let pose_in_frame = add_pose_in_frame_schema(w)?;
    let frame_transform = w.add_schema(
        "foxglove.FrameTransform",
        "jsonschema",
        &object_schema(
            "foxglove.FrameTransform",
            json!({"parent_frame_id": {"type": "string"}, "child_frame_id": {"type": "string"},
                   "translation": vec3_schema(), "rotation": quat_schema()}),
        ),
    )?;
    let laser_scan = w.add_schema(
        "foxglove.LaserScan",
        "jsonschema",
        &object_schema(
            "foxglove.LaserScan",
            json!({"frame_id": {"type": "string"}, "pose": pose_schema(),
                   "start_angle": {"type": "number"}, "end_angle": {"type": "number"},
                   "ranges": {"type": "array", "items": {"type": "number"}},
                   "intensities": {"type": "array", "items": {"type": "number"}}}),
        ),
    )?;
    let num = json!({"type": "number"});
    let wheels = w.add_schema(
        "twindrive.Wheels",
        "jsonschema",
        &object_schema(
            "twindrive.Wheels",
            json!({"cmd_left_rad_s": num, "cmd_right_rad_s": num, "left_rad_s": num, "right_rad_s": num}),
        ),
    )?;
    let int = json!({"type": "integer"});
    let encoders = w.add_schema(
        "twindrive.Encoders",
        "jsonschema",
        &object_schema(
            "twindrive.Encoders",
            json!({"left_ticks": int, "right_ticks": int}),
        ),
    )?;
    let bump = w.add_schema(
        "twindrive.Bump",
        "jsonschema",
        &object_schema("twindrive.Bump", json!({"pressed": {"type": "boolean"}})),
    )?;
    // Added last, and only with a gyro, so logs without one keep their bytes.
    let gyro = match &header.gyro {
        None => None,
        Some(_) => {
            let schema = w.add_schema(
                "twindrive.Gyro",
                "jsonschema",
                &object_schema("twindrive.Gyro", json!({"z_rad_s": num})),
            )?;
            Some(w.add_channel(schema, "/gyro", "json", &none)?)
        }
    };
    Ok(Channels {
        ground_truth: w.add_channel(pose_in_frame, "/ground_truth", "json", &none)?,
        tracker: w.add_channel(pose_in_frame, "/tracker", "json", &none)?,
        tf: w.add_channel(frame_transform, "/tf", "json", &none)?,
        wheels: w.add_channel(wheels, "/wheels", "json", &none)?,
        encoders: w.add_channel(encoders, "/encoders", "json", &none)?,
        bump: w.add_channel(bump, "/bump", "json", &none)?,
        ranges: header
            .range_sensors
            .iter()
            .map(|s| w.add_channel(laser_scan, &format!("/range/{}", s.name), "json", &none))
            .collect::<Result<_, _>>()?,
        gyro,
    })
}

/// Writes the log as MCAP (zstd-compressed chunks). No wall-clock time is
/// recorded, so the same log gives the same bytes.
pub fn write_mcap<W: Write + Seek>(log: &MissionLog, out: W) -> Result<(), mcap::McapError> {
    write_mcap_with_map(log, None, out)
}

/// [`write_mcap`] with the world the log was made in on `/map` (see
/// [`crate::map_topic`]), so the log opens in Foxglove with its walls.
pub fn write_mcap_with_map<W: Write + Seek>(
    log: &MissionLog,
    map: Option<&crate::WorldMap>,
    out: W,
) -> Result<(), mcap::McapError> {
    let mut w = writer(out)?;
    let header_json = serde_json::to_string(&log.header).expect("header serialises");
    write_json_metadata(&mut w, HEADER_METADATA, header_json)?;
    if let Some(map) = map {
        crate::map_topic::write_map(&mut w, map)?;
    }
    let ch = add_channels(&mut w, &log.header)?;
    let per_step = log.beams_per_step();
    let offsets = log.beam_offsets();
    let mut emitter = Emitter::new();

    for (k, s) in log.steps.iter().enumerate() {
        let t = s.t_ns;
        let stamp = Stamp::new(t);
        let gt = &s.ground_truth;
        emitter.emit(
            &mut w,
            ch.ground_truth,
            t,
            &PoseInFrame {
                timestamp: stamp,
                frame_id: "world".into(),
                pose: PoseMsg::planar(gt),
                heading_rad: gt.heading_rad,
            },
        )?;
        emitter.emit(
            &mut w,
            ch.tf,
            t,
            &FrameTransform {
                timestamp: stamp,
                parent_frame_id: "world",
                child_frame_id: "base_link",
                translation: Vec3 {
                    x: gt.x_m,
                    y: gt.y_m,
                    z: 0.0,
                },
                rotation: yaw_quat(gt.heading_rad),
            },
        )?;
        emitter.emit(
            &mut w,
            ch.wheels,
            t,
            &Wheels {
                timestamp: stamp,
                cmd_left_rad_s: s.cmd_wheel_rad_s[0],
                cmd_right_rad_s: s.cmd_wheel_rad_s[1],
                left_rad_s: s.wheel_rad_s[0],
                right_rad_s: s.wheel_rad_s[1],
            },
        )?;
        emitter.emit(
            &mut w,
            ch.bump,
            t,
            &Bump {
                timestamp: stamp,
                pressed: s.bump,
            },
        )?;
        if let Some([l, r]) = s.encoder_ticks {
            emitter.emit(
                &mut w,
                ch.encoders,
                t,
                &Encoders {
                    timestamp: stamp,
                    left_ticks: l,
                    right_ticks: r,
                },
            )?;
        }
        if let Some(p) = &s.tracker {
            emitter.emit(
                &mut w,
                ch.tracker,
                t,
                &PoseInFrame {
                    timestamp: stamp,
                    frame_id: "world".into(),
                    pose: PoseMsg::planar(p),
                    heading_rad: p.heading_rad,
                },
            )?;
        }
        if let (Some(channel), Some(z)) = (ch.gyro, s.gyro_z_rad_s) {
            emitter.emit(
                &mut w,
                channel,
                t,
                &Gyro {
                    timestamp: stamp,
                    z_rad_s: z,
                },
            )?;
        }
        for (i, sensor) in log.header.range_sensors.iter().enumerate() {
            let start = k * per_step + offsets[i];
            let ranges = &log.ranges[start..start + sensor.beams as usize];
            if ranges[0].is_nan() {
                continue;
            }
            let (angle_min, inc) = sensor.angle_min_and_increment();
            emitter.emit(
                &mut w,
                ch.ranges[i],
                t,
                &LaserScan {
                    timestamp: stamp,
                    frame_id: "base_link".into(),
                    pose: PoseMsg::planar(&sensor.mount),
                    start_angle: angle_min,
                    end_angle: angle_min + inc * f64::from(sensor.beams.saturating_sub(1)),
                    ranges: ranges.to_vec(),
                    intensities: Vec::new(),
                },
            )?;
        }
    }
    w.finish()?;
    Ok(())
}

/// One named pose track with optional wheel speeds, for [`write_tracks_mcap`].
pub struct Track<'a> {
    /// Topic prefix, e.g. `/executed`.
    pub topic: &'a str,
    /// (t_ns, pose) in time order.
    pub poses: &'a [(u64, Pose)],
    /// (t_ns, [left, right] rad/s), or empty.
    pub wheels: &'a [(u64, [f64; 2])],
}

/// Writes several pose tracks (`<topic>` as `foxglove.PoseInFrame` in frame
/// `world`, `<topic>/wheels` as `twindrive.WheelSpeeds`) into one MCAP file,
/// so stages of a pipeline can be scrubbed side by side in Foxglove. No
/// wall-clock time is recorded: the same tracks give the same bytes.
pub fn write_tracks_mcap<W: Write + Seek>(
    tracks: &[Track],
    metadata: &[(&str, String)],
    map: Option<&crate::WorldMap>,
    out: W,
) -> Result<(), mcap::McapError> {
    let mut w = writer(out)?;
    for (name, json) in metadata {
        write_json_metadata(&mut w, name, json.clone())?;
    }
    if let Some(map) = map {
        crate::map_topic::write_map(&mut w, map)?;
    }
    let none = BTreeMap::new();
    let pose_in_frame = add_pose_in_frame_schema(&mut w)?;
    let num = json!({"type": "number"});
    let wheel_speeds = w.add_schema(
        "twindrive.WheelSpeeds",
        "jsonschema",
        &object_schema(
            "twindrive.WheelSpeeds",
            json!({"left_rad_s": num, "right_rad_s": num}),
        ),
    )?;
    #[derive(Serialize)]
    struct WheelSpeeds {
        timestamp: Stamp,
        left_rad_s: f64,
        right_rad_s: f64,
    }
    let mut emitter = Emitter::new();
    for track in tracks {
        let poses = w.add_channel(pose_in_frame, track.topic, "json", &none)?;
        for (t, p) in track.poses {
            let msg = PoseInFrame {
                timestamp: Stamp::new(*t),
                frame_id: "world".into(),
                pose: PoseMsg::planar(p),
                heading_rad: p.heading_rad,
            };
            emitter.emit(&mut w, poses, *t, &msg)?;
        }
        if track.wheels.is_empty() {
            continue;
        }
        let wheels = w.add_channel(
            wheel_speeds,
            &format!("{}/wheels", track.topic),
            "json",
            &none,
        )?;
        for (t, [l, r]) in track.wheels {
            let msg = WheelSpeeds {
                timestamp: Stamp::new(*t),
                left_rad_s: *l,
                right_rad_s: *r,
            };
            emitter.emit(&mut w, wheels, *t, &msg)?;
        }
    }
    w.finish()?;
    Ok(())
}

/// Object-safe JSON serialisation for the message structs above.
mod erased {
    pub trait Json {
        fn write_json(&self, out: &mut Vec<u8>);
    }
    impl<T: serde::Serialize> Json for T {
        fn write_json(&self, out: &mut Vec<u8>) {
            serde_json::to_writer(out, self).expect("message serialises");
        }
    }
}

/// Reads a log written by [`write_mcap`].
pub fn read_mcap(path: &Path) -> Result<MissionLog, LogError> {
    let bytes = std::fs::read(path).map_err(|e| LogError::io(path, e))?;
    read_mcap_bytes(&bytes, path)
}

/// Whether `bytes` begin as an MCAP file does (its magic).
pub fn is_mcap(bytes: &[u8]) -> bool {
    bytes.starts_with(mcap::MAGIC)
}

/// Reads a log written by [`write_mcap`] from its bytes; `path` names them
/// in errors.
pub fn read_mcap_bytes(bytes: &[u8], path: &Path) -> Result<MissionLog, LogError> {
    let bad = |m: String| LogError::format(path, m);
    let summary = mcap::Summary::read(bytes)
        .map_err(|e| bad(format!("not a readable MCAP file: {e}")))?
        .ok_or_else(|| bad("MCAP file has no summary section".into()))?;
    let index = summary
        .metadata_indexes
        .iter()
        .find(|m| m.name == HEADER_METADATA)
        .ok_or_else(|| bad(format!("no `{HEADER_METADATA}` metadata record")))?;
    let meta = mcap::read::metadata(bytes, index).map_err(|e| bad(e.to_string()))?;
    let header: LogHeader = meta
        .metadata
        .get("json")
        .ok_or_else(|| bad("log header metadata has no `json` entry".into()))
        .and_then(|j| serde_json::from_str(j).map_err(|e| bad(format!("log header: {e}"))))?;

    let mut log = MissionLog::new(header);
    let per_step = log.beams_per_step();
    let offsets = log.beam_offsets();
    let range_topics: HashMap<String, usize> = log
        .header
        .range_sensors
        .iter()
        .enumerate()
        .map(|(i, s)| (format!("/range/{}", s.name), i))
        .collect();
    let mut step_of_time: HashMap<u64, usize> = HashMap::new();
    let stream = mcap::MessageStream::new(bytes).map_err(|e| bad(e.to_string()))?;
    for message in stream {
        let message = message.map_err(|e| bad(e.to_string()))?;
        let topic = message.channel.topic.as_str();
        let t = message.log_time;
        let parse_err =
            |e: serde_json::Error| bad(format!("message on {topic} at t = {t} ns: {e}"));
        if topic == "/ground_truth" {
            let msg: PoseInFrame = serde_json::from_slice(&message.data).map_err(parse_err)?;
            step_of_time.insert(t, log.steps.len());
            log.steps.push(StepRecord {
                t_ns: t,
                cmd_wheel_rad_s: [0.0; 2],
                wheel_rad_s: [0.0; 2],
                encoder_ticks: None,
                bump: false,
                tracker: None,
                ground_truth: Pose::new(msg.pose.position.x, msg.pose.position.y, msg.heading_rad),
                gyro_z_rad_s: None,
            });
            log.ranges.resize(log.ranges.len() + per_step, f64::NAN);
            continue;
        }
        // The transform repeats the ground truth; the map is the world's.
        if matches!(topic, "/tf" | "/map" | "/map/grid") {
            continue;
        }
        let &k = step_of_time
            .get(&t)
            .ok_or_else(|| bad(format!("message on {topic} at t = {t} ns has no /ground_truth message at that time before it")))?;
        let step = &mut log.steps[k];
        match topic {
            "/wheels" => {
                let m: Wheels = serde_json::from_slice(&message.data).map_err(parse_err)?;
                step.cmd_wheel_rad_s = [m.cmd_left_rad_s, m.cmd_right_rad_s];
                step.wheel_rad_s = [m.left_rad_s, m.right_rad_s];
            }
            "/bump" => {
                let m: Bump = serde_json::from_slice(&message.data).map_err(parse_err)?;
                step.bump = m.pressed;
            }
            "/encoders" => {
                let m: Encoders = serde_json::from_slice(&message.data).map_err(parse_err)?;
                step.encoder_ticks = Some([m.left_ticks, m.right_ticks]);
            }
            "/tracker" => {
                let m: PoseInFrame = serde_json::from_slice(&message.data).map_err(parse_err)?;
                step.tracker = Some(Pose::new(
                    m.pose.position.x,
                    m.pose.position.y,
                    m.heading_rad,
                ));
            }
            "/gyro" if log.header.gyro.is_some() => {
                let m: Gyro = serde_json::from_slice(&message.data).map_err(parse_err)?;
                step.gyro_z_rad_s = Some(m.z_rad_s);
            }
            other => {
                let &i = range_topics
                    .get(other)
                    .ok_or_else(|| bad(format!("unexpected topic {other}")))?;
                let m: LaserScan = serde_json::from_slice(&message.data).map_err(parse_err)?;
                let beams = log.header.range_sensors[i].beams as usize;
                if m.ranges.len() != beams {
                    return Err(bad(format!(
                        "{other} at t = {t} ns has {} ranges, expected {beams}",
                        m.ranges.len()
                    )));
                }
                let start = k * per_step + offsets[i];
                log.ranges[start..start + beams].copy_from_slice(&m.ranges);
            }
        }
    }
    Ok(log)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{assert_same, sample_log};

    #[test]
    fn round_trip_is_exact_and_deterministic() {
        let log = sample_log();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("log.mcap");
        write_mcap(&log, std::fs::File::create(&path).unwrap()).unwrap();
        let back = read_mcap(&path).unwrap();
        assert_same(&log, &back);

        let mut again = std::io::Cursor::new(Vec::new());
        write_mcap(&log, &mut again).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), again.into_inner());
    }

    #[test]
    fn a_gyro_round_trips_on_its_own_channel() {
        let log = crate::testutil::sample_log_with_gyro();
        let mut bytes = std::io::Cursor::new(Vec::new());
        write_mcap(&log, &mut bytes).unwrap();
        let bytes = bytes.into_inner();
        assert_same(&log, &read_mcap_bytes(&bytes, Path::new("g.mcap")).unwrap());
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let gyro: Vec<_> = summary
            .channels
            .values()
            .filter(|c| c.topic == "/gyro")
            .collect();
        assert_eq!(gyro.len(), 1);
        assert_eq!(gyro[0].schema.as_ref().unwrap().name, "twindrive.Gyro");

        // Without a gyro there is no channel, and a stray one is refused.
        let plain = sample_log();
        let mut plain_bytes = std::io::Cursor::new(Vec::new());
        write_mcap(&plain, &mut plain_bytes).unwrap();
        let plain_summary = mcap::Summary::read(plain_bytes.get_ref()).unwrap().unwrap();
        assert!(plain_summary.channels.values().all(|c| c.topic != "/gyro"));
        let mut stray = log.clone();
        stray.header.gyro = None;
        let mut stray_bytes = std::io::Cursor::new(Vec::new());
        let json = serde_json::to_string(&stray.header).unwrap();
        let mut w = writer(&mut stray_bytes).unwrap();
        write_json_metadata(&mut w, HEADER_METADATA, json).unwrap();
        let ch = add_channels(&mut w, &log.header).unwrap();
        let mut emitter = Emitter::new();
        let stamp = Stamp::new(0);
        let gt = PoseInFrame {
            timestamp: stamp,
            frame_id: "world".into(),
            pose: PoseMsg::planar(&Pose::default()),
            heading_rad: 0.0,
        };
        emitter.emit(&mut w, ch.ground_truth, 0, &gt).unwrap();
        let z = Gyro {
            timestamp: stamp,
            z_rad_s: 0.5,
        };
        emitter.emit(&mut w, ch.gyro.unwrap(), 0, &z).unwrap();
        w.finish().unwrap();
        drop(w);
        let err = read_mcap_bytes(stray_bytes.get_ref(), Path::new("s.mcap"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("unexpected topic /gyro"), "{err}");
    }

    #[test]
    fn garbage_is_a_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.mcap");
        std::fs::write(&path, b"not an mcap").unwrap();
        let err = read_mcap(&path).unwrap_err().to_string();
        assert!(err.contains("bad.mcap") && err.contains("MCAP"), "{err}");
    }
}
