//! Decoding what a robot's ROS 2 drivers publish, one message at a time:
//! joint states, range readings, laser scans, hazards and poses, each from
//! the type a site file names. The definitions are the built-in (Jazzy)
//! ones; fields are found by name, so a decoder is built once per topic and
//! each message costs one CDR walk.

use crate::msgs::{self, Distro};
use crate::schema::{Base, FieldPath, Schema};
use crate::value::Value;

/// What one message said.
#[derive(Debug, Clone, PartialEq)]
pub enum Sample {
    /// The two wheel joints: angle (rad) and speed (rad/s), where given.
    Joints {
        position: Option<[f64; 2]>,
        velocity: Option<[f64; 2]>,
    },
    /// A JointState without both wheel joints (another joint group).
    OtherJoints,
    /// One range (m); `+inf` for no return, as REP-117 has it.
    Range(f64),
    /// The beams of a scan (m).
    Scan(Vec<f64>),
    /// The bumper pressed, and the wheels stalled, as far as the type tells.
    Hazard { bump: bool, stall: bool },
    /// x, y (m), heading (rad).
    Pose([f64; 3]),
}

#[derive(Debug, Clone)]
enum Kind {
    Joints {
        paths: JointPaths,
        left: String,
        right: String,
    },
    Range(FieldPath),
    Scan(FieldPath),
    HazardVector {
        detections: FieldPath,
        /// `type` inside one detection.
        kind: FieldPath,
    },
    Bool(FieldPath),
    Pose([FieldPath; 6]),
}

/// A decoder for one topic.
#[derive(Debug, Clone)]
pub struct Decoder {
    schema: Schema,
    kind: Kind,
}

/// `irobot_create_msgs/msg/HazardDetection` types.
const BUMP: i64 = 1;
const STALL: i64 = 3;

impl Decoder {
    fn schema(type_name: &str) -> Result<Schema, String> {
        let text = msgs::definition(type_name, Distro::Jazzy)
            .ok_or_else(|| format!("twindrive has no definition of {type_name}"))?;
        Schema::parse(type_name, &text).map_err(|e| e.to_string())
    }

    /// `sensor_msgs/msg/JointState` with the two wheel joints' names.
    pub fn joints(left: &str, right: &str) -> Result<Self, String> {
        let schema = Self::schema("sensor_msgs/msg/JointState")?;
        let kind = Kind::Joints {
            paths: JointPaths::new(&schema)?,
            left: left.into(),
            right: right.into(),
        };
        Ok(Self { schema, kind })
    }

    /// A range sensor: `sensor_msgs/msg/Range` or `sensor_msgs/msg/LaserScan`.
    pub fn range(type_name: &str) -> Result<Self, String> {
        let schema = Self::schema(type_name)?;
        let kind = match type_name {
            "sensor_msgs/msg/Range" => Kind::Range(schema.path("range")?),
            "sensor_msgs/msg/LaserScan" => Kind::Scan(schema.path("ranges")?),
            other => {
                return Err(format!(
                    "a range sensor publishes sensor_msgs/msg/Range or sensor_msgs/msg/LaserScan, not {other}"
                ));
            }
        };
        Ok(Self { schema, kind })
    }

    /// A bumper: `irobot_create_msgs/msg/HazardDetectionVector` (BUMP and
    /// STALL detections) or `std_msgs/msg/Bool` (pressed).
    pub fn hazard(type_name: &str) -> Result<Self, String> {
        let schema = Self::schema(type_name)?;
        let kind = match type_name {
            "irobot_create_msgs/msg/HazardDetectionVector" => {
                let detections = schema.path("detections")?;
                let Base::Message(t) = detections.ty.base else {
                    return Err("`detections` is not a list of messages".into());
                };
                let kind = schema.path_from(t, "type")?;
                Kind::HazardVector { detections, kind }
            }
            "std_msgs/msg/Bool" => Kind::Bool(schema.path("data")?),
            other => {
                return Err(format!(
                    "a bumper publishes irobot_create_msgs/msg/HazardDetectionVector or std_msgs/msg/Bool, not {other}"
                ));
            }
        };
        Ok(Self { schema, kind })
    }

    /// An absolute pose: `geometry_msgs/msg/PoseStamped`,
    /// `geometry_msgs/msg/PoseWithCovarianceStamped` or `nav_msgs/msg/Odometry`.
    pub fn pose(type_name: &str) -> Result<Self, String> {
        let schema = Self::schema(type_name)?;
        let prefix = match type_name {
            "geometry_msgs/msg/PoseStamped" => "pose",
            "geometry_msgs/msg/PoseWithCovarianceStamped" | "nav_msgs/msg/Odometry" => "pose.pose",
            other => {
                return Err(format!(
                    "a pose comes as geometry_msgs/msg/PoseStamped, PoseWithCovarianceStamped or nav_msgs/msg/Odometry, not {other}"
                ));
            }
        };
        let kind = Kind::Pose(pose_paths(&schema, prefix)?);
        Ok(Self { schema, kind })
    }

    /// The type this decoder reads.
    pub fn type_name(&self) -> &str {
        &self.schema.root().name
    }

    /// Decodes one serialized message.
    pub fn decode(&self, bytes: &[u8]) -> Result<Sample, String> {
        let v = self.schema.decode(bytes).map_err(|e| e.message)?;
        let num = |p: &FieldPath| v.at(p).and_then(Value::as_f64);
        match &self.kind {
            Kind::Joints { paths, left, right } => Ok(match paths.read(&v, left, right)? {
                Joints::Both { position, velocity } => Sample::Joints { position, velocity },
                Joints::Other(_) => Sample::OtherJoints,
            }),
            Kind::Range(p) => Ok(Sample::Range(num(p).ok_or("no `range`")?)),
            Kind::Scan(p) => Ok(Sample::Scan(
                v.at(p)
                    .and_then(Value::as_array)
                    .ok_or("no `ranges`")?
                    .iter()
                    .map(|r| r.as_f64().unwrap_or(f64::NAN))
                    .collect(),
            )),
            Kind::HazardVector { detections, kind } => {
                let mut bump = false;
                let mut stall = false;
                for d in v.at(detections).and_then(Value::as_array).unwrap_or(&[]) {
                    match d.at(kind).and_then(Value::as_i64) {
                        Some(BUMP) => bump = true,
                        Some(STALL) => stall = true,
                        _ => {}
                    }
                }
                Ok(Sample::Hazard { bump, stall })
            }
            Kind::Bool(p) => Ok(Sample::Hazard {
                bump: matches!(v.at(p), Some(Value::Bool(true))),
                stall: false,
            }),
            Kind::Pose(fields) => {
                let f: Vec<f64> = fields.iter().map(|p| num(p).unwrap_or(f64::NAN)).collect();
                let (x, y, h) = planar_pose(&f)?;
                Ok(Sample::Pose([x, y, h]))
            }
        }
    }
}

/// The fields of a `sensor_msgs/msg/JointState` two wheel joints are read from.
#[derive(Debug, Clone)]
pub(crate) struct JointPaths {
    names: FieldPath,
    position: FieldPath,
    velocity: FieldPath,
}

/// What one JointState says of two joints.
pub(crate) enum Joints<'v> {
    /// It names both: their angles and speeds, where it gives both.
    Both {
        position: Option<[f64; 2]>,
        velocity: Option<[f64; 2]>,
    },
    /// It does not name both (another joint group): the names it has.
    Other(&'v [Value]),
}

impl JointPaths {
    pub(crate) fn new(schema: &Schema) -> Result<Self, String> {
        Ok(Self {
            names: schema.path("name")?,
            position: schema.path("position")?,
            velocity: schema.path("velocity")?,
        })
    }

    /// Joints `left` and `right` of message `v`; a value given but not
    /// finite is an error.
    pub(crate) fn read<'v>(
        &self,
        v: &'v Value,
        left: &str,
        right: &str,
    ) -> Result<Joints<'v>, String> {
        let list = v
            .at(&self.names)
            .and_then(Value::as_array)
            .ok_or("no `name` list")?;
        let idx = |j: &str| list.iter().position(|n| n.as_str() == Some(j));
        let (Some(l), Some(r)) = (idx(left), idx(right)) else {
            return Ok(Joints::Other(list));
        };
        let pair = |p: &FieldPath| -> Result<Option<[f64; 2]>, String> {
            let a = v.at(p).and_then(Value::as_array).unwrap_or(&[]);
            let (x, y) = (
                a.get(l).and_then(Value::as_f64),
                a.get(r).and_then(Value::as_f64),
            );
            if let Some(bad) = [x, y].into_iter().flatten().find(|x| !x.is_finite()) {
                return Err(format!("joint value {bad} is not finite"));
            }
            Ok(x.zip(y).map(|(x, y)| [x, y]))
        };
        Ok(Joints::Both {
            position: pair(&self.position)?,
            velocity: pair(&self.velocity)?,
        })
    }
}

/// The paths of x, y and the quaternion of the `geometry_msgs/msg/Pose`
/// at `prefix` (`pose`, `pose.pose`), in [`planar_pose`]'s order.
pub(crate) fn pose_paths(schema: &Schema, prefix: &str) -> Result<[FieldPath; 6], String> {
    let p = |s: &str| schema.path(&format!("{prefix}.{s}"));
    Ok([
        p("position.x")?,
        p("position.y")?,
        p("orientation.x")?,
        p("orientation.y")?,
        p("orientation.z")?,
        p("orientation.w")?,
    ])
}

/// x, y and heading from `[x, y, qx, qy, qz, qw]`; refuses a missing
/// number or a quaternion that is not a rotation (an unset orientation).
pub(crate) fn planar_pose(v: &[f64]) -> Result<(f64, f64, f64), String> {
    if v.len() != 6 || v.iter().any(|x| !x.is_finite()) {
        return Err("the pose has a missing or non-finite number".into());
    }
    let q = msgs::Quaternion {
        x: v[2],
        y: v[3],
        z: v[4],
        w: v[5],
    };
    let norm = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
    if (norm - 1.0).abs() > 1e-3 {
        return Err(format!(
            "the orientation quaternion has norm {norm:.4}, not 1 (an unset orientation?)"
        ));
    }
    Ok((v[0], v[1], q.yaw_rad()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::*;

    #[test]
    fn each_kind_decodes() {
        let j = Decoder::joints("wl", "wr").unwrap();
        let msg = encode(&JointState {
            header: Header::new(5, ""),
            name: vec!["wr".into(), "arm".into(), "wl".into()],
            position: vec![2.0, 0.0, 1.0],
            velocity: vec![],
            effort: vec![],
        });
        assert_eq!(
            j.decode(&msg).unwrap(),
            Sample::Joints {
                position: Some([1.0, 2.0]),
                velocity: None
            }
        );
        let other = encode(&JointState {
            header: Header::new(5, ""),
            name: vec!["arm".into()],
            position: vec![0.0],
            velocity: vec![],
            effort: vec![],
        });
        assert_eq!(j.decode(&other).unwrap(), Sample::OtherJoints);
        assert!(j.decode(&msg[..msg.len() - 9]).is_err());

        let h = Decoder::hazard("irobot_create_msgs/msg/HazardDetectionVector").unwrap();
        let hz = encode(&HazardDetectionVector {
            header: Header::new(0, "base_link"),
            detections: vec![HazardDetection {
                header: Header::new(0, "bump_front"),
                kind: HazardDetection::BUMP,
            }],
        });
        assert_eq!(
            h.decode(&hz).unwrap(),
            Sample::Hazard {
                bump: true,
                stall: false
            }
        );
        let b = Decoder::hazard("std_msgs/msg/Bool").unwrap();
        assert_eq!(
            b.decode(&encode(&Bool { data: true })).unwrap(),
            Sample::Hazard {
                bump: true,
                stall: false
            }
        );
        let p = Decoder::pose("nav_msgs/msg/Odometry").unwrap();
        let odom = encode(&Odometry {
            header: Header::new(0, "map"),
            child_frame_id: "base_link".into(),
            pose: PoseWithCovariance {
                pose: crate::msgs::Pose::planar(1.0, 2.0, 0.5),
                covariance: Covariance::default(),
            },
            twist: TwistWithCovariance::default(),
        });
        let Sample::Pose([x, y, h]) = p.decode(&odom).unwrap() else {
            panic!()
        };
        assert!((x - 1.0).abs() < 1e-12 && (y - 2.0).abs() < 1e-12 && (h - 0.5).abs() < 1e-12);
        assert!(Decoder::range("sensor_msgs/msg/Image").is_err());
        assert!(Decoder::hazard("std_msgs/msg/String").is_err());
    }
}
