//! The standard ROS 2 messages twindrive reads and writes, as Rust types
//! that serialize to CDR with `cdr-encoding`, and their `ros2msg`
//! definitions (what rosbag2 stores as an MCAP schema).
//!
//! Definitions are those of ROS 2 Jazzy; [`Distro::Humble`] differs only in
//! `sensor_msgs/msg/Range`, which gained `variance` in Jazzy.

use serde::ser::SerializeTuple;
use serde::{Deserialize, Serialize, Serializer};

/// The ROS 2 distribution whose message definitions a file follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Distro {
    Humble,
    #[default]
    Jazzy,
}

impl Distro {
    pub fn name(self) -> &'static str {
        match self {
            Distro::Humble => "humble",
            Distro::Jazzy => "jazzy",
        }
    }

    pub fn parse(text: &str) -> Option<Self> {
        match text {
            "humble" => Some(Distro::Humble),
            "jazzy" => Some(Distro::Jazzy),
            _ => None,
        }
    }

    /// The definitions a release's messages follow, by the release's name
    /// as a bag records it: Humble's up to Iron (`sensor_msgs/msg/Range`
    /// without `variance`), Jazzy's from Jazzy on.
    pub fn of_release(name: &str) -> Option<Self> {
        match name.to_ascii_lowercase().as_str() {
            "foxy" | "galactic" | "humble" | "iron" => Some(Distro::Humble),
            "jazzy" | "kilted" | "rolling" => Some(Distro::Jazzy),
            _ => None,
        }
    }
}

/// A message type with its definition.
pub trait RosMessage: Serialize {
    /// `pkg/msg/Type`.
    const TYPE: &'static str;
}

/// `(type, own definition, types it uses directly)`.
const DEFINITIONS: &[(&str, &str, &[&str])] = &[
    (
        "builtin_interfaces/msg/Time",
        "int32 sec\nuint32 nanosec\n",
        &[],
    ),
    (
        "std_msgs/msg/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
        &["builtin_interfaces/msg/Time"],
    ),
    ("std_msgs/msg/String", "string data\n", &[]),
    ("std_msgs/msg/Bool", "bool data\n", &[]),
    ("std_msgs/msg/Float64", "float64 data\n", &[]),
    (
        "std_msgs/msg/MultiArrayDimension",
        "string label\nuint32 size\nuint32 stride\n",
        &[],
    ),
    (
        "std_msgs/msg/MultiArrayLayout",
        "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset\n",
        &["std_msgs/msg/MultiArrayDimension"],
    ),
    (
        "std_msgs/msg/Float64MultiArray",
        "std_msgs/MultiArrayLayout layout\nfloat64[] data\n",
        &["std_msgs/msg/MultiArrayLayout"],
    ),
    (
        "geometry_msgs/msg/Point",
        "float64 x\nfloat64 y\nfloat64 z\n",
        &[],
    ),
    (
        "geometry_msgs/msg/Vector3",
        "float64 x\nfloat64 y\nfloat64 z\n",
        &[],
    ),
    (
        "geometry_msgs/msg/Quaternion",
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
        &[],
    ),
    (
        "geometry_msgs/msg/Pose",
        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
        &["geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion"],
    ),
    (
        "geometry_msgs/msg/PoseStamped",
        "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
        &["std_msgs/msg/Header", "geometry_msgs/msg/Pose"],
    ),
    (
        "geometry_msgs/msg/PoseWithCovariance",
        "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
        &["geometry_msgs/msg/Pose"],
    ),
    (
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        "std_msgs/Header header\ngeometry_msgs/PoseWithCovariance pose\n",
        &[
            "std_msgs/msg/Header",
            "geometry_msgs/msg/PoseWithCovariance",
        ],
    ),
    (
        "geometry_msgs/msg/Twist",
        "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
        &["geometry_msgs/msg/Vector3"],
    ),
    (
        "geometry_msgs/msg/TwistStamped",
        "std_msgs/Header header\ngeometry_msgs/Twist twist\n",
        &["std_msgs/msg/Header", "geometry_msgs/msg/Twist"],
    ),
    (
        "geometry_msgs/msg/TwistWithCovariance",
        "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
        &["geometry_msgs/msg/Twist"],
    ),
    (
        "geometry_msgs/msg/Transform",
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
        &["geometry_msgs/msg/Vector3", "geometry_msgs/msg/Quaternion"],
    ),
    (
        "geometry_msgs/msg/TransformStamped",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
        &["std_msgs/msg/Header", "geometry_msgs/msg/Transform"],
    ),
    (
        "tf2_msgs/msg/TFMessage",
        "geometry_msgs/TransformStamped[] transforms\n",
        &["geometry_msgs/msg/TransformStamped"],
    ),
    (
        "nav_msgs/msg/Odometry",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n\
         geometry_msgs/TwistWithCovariance twist\n",
        &[
            "std_msgs/msg/Header",
            "geometry_msgs/msg/PoseWithCovariance",
            "geometry_msgs/msg/TwistWithCovariance",
        ],
    ),
    (
        "nav_msgs/msg/MapMetaData",
        "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\n\
         geometry_msgs/Pose origin\n",
        &["builtin_interfaces/msg/Time", "geometry_msgs/msg/Pose"],
    ),
    (
        "nav_msgs/msg/OccupancyGrid",
        "std_msgs/Header header\nnav_msgs/MapMetaData info\nint8[] data\n",
        &["std_msgs/msg/Header", "nav_msgs/msg/MapMetaData"],
    ),
    (
        "nav_msgs/msg/Path",
        "std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n",
        &["std_msgs/msg/Header", "geometry_msgs/msg/PoseStamped"],
    ),
    (
        "sensor_msgs/msg/JointState",
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
        &["std_msgs/msg/Header"],
    ),
    (
        "sensor_msgs/msg/Imu",
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n\
         geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n\
         geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n",
        &[
            "std_msgs/msg/Header",
            "geometry_msgs/msg/Quaternion",
            "geometry_msgs/msg/Vector3",
        ],
    ),
    (
        "sensor_msgs/msg/LaserScan",
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n\
         float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n\
         float32[] ranges\nfloat32[] intensities\n",
        &["std_msgs/msg/Header"],
    ),
    (
        "irobot_create_msgs/msg/HazardDetection",
        "uint8 BACKUP_LIMIT=0\nuint8 BUMP=1\nuint8 CLIFF=2\nuint8 STALL=3\nuint8 WHEEL_DROP=4\n\
         uint8 OBJECT_PROXIMITY=5\nstd_msgs/Header header\nuint8 type\n",
        &["std_msgs/msg/Header"],
    ),
    (
        "irobot_create_msgs/msg/HazardDetectionVector",
        "std_msgs/Header header\nirobot_create_msgs/HazardDetection[] detections\n",
        &[
            "std_msgs/msg/Header",
            "irobot_create_msgs/msg/HazardDetection",
        ],
    ),
];

const RANGE: &str = "sensor_msgs/msg/Range";
const RANGE_HUMBLE: &str = "uint8 ULTRASOUND=0\nuint8 INFRARED=1\nstd_msgs/Header header\nuint8 radiation_type\n\
float32 field_of_view\nfloat32 min_range\nfloat32 max_range\nfloat32 range\n";
const RANGE_JAZZY: &str = "uint8 ULTRASOUND=0\nuint8 INFRARED=1\nstd_msgs/Header header\nuint8 radiation_type\n\
float32 field_of_view\nfloat32 min_range\nfloat32 max_range\nfloat32 range\nfloat32 variance\n";

fn own(type_name: &str, distro: Distro) -> Option<(&'static str, &'static [&'static str])> {
    if type_name == RANGE {
        let text = match distro {
            Distro::Humble => RANGE_HUMBLE,
            Distro::Jazzy => RANGE_JAZZY,
        };
        return Some((text, &["std_msgs/msg/Header"]));
    }
    DEFINITIONS
        .iter()
        .find(|(n, _, _)| *n == type_name)
        .map(|(_, t, d)| (*t, *d))
}

/// Every type this module knows.
pub fn known_types() -> impl Iterator<Item = &'static str> {
    DEFINITIONS
        .iter()
        .map(|(n, _, _)| *n)
        .chain(std::iter::once(RANGE))
}

/// The full `ros2msg` definition of `type_name` as rosbag2 stores it: the
/// type's own text, then each type it uses (depth first, once each) after a
/// separator line and `MSG: pkg/Type`.
pub fn definition(type_name: &str, distro: Distro) -> Option<String> {
    let (text, _) = own(type_name, distro)?;
    let mut out = text.to_string();
    let mut seen = vec![type_name];
    let mut order = Vec::new();
    fn walk<'a>(t: &'a str, distro: Distro, seen: &mut Vec<&'a str>, order: &mut Vec<&'a str>) {
        let (_, deps) = own(t, distro).expect("dependencies are defined");
        for d in deps {
            if !seen.contains(d) {
                seen.push(d);
                order.push(*d);
                walk(d, distro, seen, order);
            }
        }
    }
    walk(type_name, distro, &mut seen, &mut order);
    for d in order {
        let (text, _) = own(d, distro).expect("defined");
        let short = d.replace("/msg/", "/");
        out.push_str(&"=".repeat(80));
        out.push_str("\nMSG: ");
        out.push_str(&short);
        out.push('\n');
        out.push_str(text);
    }
    Some(out)
}

/// Serializes a message as ROS 2 does: the little-endian CDR encapsulation
/// header, then the CDR body.
pub fn encode<T: RosMessage>(msg: &T) -> Vec<u8> {
    let mut out = Vec::new();
    encode_into(&mut out, msg);
    out
}

/// [`encode`] into `out` (cleared first), reusing its allocation.
pub fn encode_into<T: RosMessage>(out: &mut Vec<u8>, msg: &T) {
    out.clear();
    out.extend_from_slice(&[0, 1, 0, 0]);
    cdr_encoding::to_writer::<T, byteorder::LittleEndian, _>(out, msg)
        .expect("CDR serialization of a plain struct into a Vec cannot fail");
}

/// The RIHS01 hash of `type_name` with its Jazzy definition (the one
/// rmw_zenoh keys and Jazzy bags carry), if twindrive knows the type.
pub fn type_hash(type_name: &str) -> Option<String> {
    let text = definition(type_name, Distro::Jazzy)?;
    Some(crate::Schema::parse(type_name, &text).ok()?.type_hash())
}

macro_rules! message {
    ($t:ident, $name:literal) => {
        impl RosMessage for $t {
            const TYPE: &'static str = $name;
        }
    };
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// From nanoseconds since the epoch (or since the log's start).
    pub fn from_ns(t_ns: u64) -> Self {
        Self {
            sec: i32::try_from(t_ns / 1_000_000_000).unwrap_or(i32::MAX),
            nanosec: (t_ns % 1_000_000_000) as u32,
        }
    }

    pub fn as_ns(self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

impl Header {
    pub fn new(t_ns: u64, frame_id: &str) -> Self {
        Self {
            stamp: Time::from_ns(t_ns),
            frame_id: frame_id.to_string(),
        }
    }
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StringMsg {
    pub data: String,
}
message!(StringMsg, "std_msgs/msg/String");

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Bool {
    pub data: bool,
}
message!(Bool, "std_msgs/msg/Bool");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiArrayDimension {
    pub label: String,
    pub size: u32,
    pub stride: u32,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiArrayLayout {
    pub dim: Vec<MultiArrayDimension>,
    pub data_offset: u32,
}

/// One number, as a motor controller publishes a wheel's speed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Float64 {
    pub data: f64,
}
message!(Float64, "std_msgs/msg/Float64");

/// What a ros2_control `JointGroupVelocityController` takes: one velocity
/// per joint, in the controller's joint order.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Float64MultiArray {
    pub layout: MultiArrayLayout,
    pub data: Vec<f64>,
}
message!(Float64MultiArray, "std_msgs/msg/Float64MultiArray");

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self::from_yaw(0.0)
    }
}

impl Quaternion {
    /// A rotation about z by `yaw_rad` (counter-clockwise positive, REP-103).
    pub fn from_yaw(yaw_rad: f64) -> Self {
        let (s, c) = (0.5 * yaw_rad).sin_cos();
        Self {
            x: 0.0,
            y: 0.0,
            z: s,
            w: c,
        }
    }

    /// The heading of this rotation about z (rad, in (−π, π]).
    pub fn yaw_rad(&self) -> f64 {
        (2.0 * (self.w * self.z + self.x * self.y))
            .atan2(1.0 - 2.0 * (self.y * self.y + self.z * self.z))
    }
}

/// `geometry_msgs/msg/Point`.
pub type Point = Vector3;

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}

impl Pose {
    /// A planar pose at height 0.
    pub fn planar(x_m: f64, y_m: f64, heading_rad: f64) -> Self {
        Self {
            position: Vector3 {
                x: x_m,
                y: y_m,
                z: 0.0,
            },
            orientation: Quaternion::from_yaw(heading_rad),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    pub header: Header,
    pub pose: Pose,
}
message!(PoseStamped, "geometry_msgs/msg/PoseStamped");

/// A row-major 6×6 covariance (x, y, z, roll, pitch, yaw).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Covariance(pub [f64; 36]);

impl Default for Covariance {
    fn default() -> Self {
        Self([0.0; 36])
    }
}

impl Covariance {
    /// Diagonal entries in the order x, y, z, roll, pitch, yaw.
    pub fn diagonal(d: [f64; 6]) -> Self {
        let mut c = [0.0; 36];
        for (i, v) in d.into_iter().enumerate() {
            c[i * 7] = v;
        }
        Self(c)
    }
}

impl Serialize for Covariance {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(36)?;
        for v in &self.0 {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for Covariance {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = Covariance;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("36 float64")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut a: A,
            ) -> Result<Covariance, A::Error> {
                let mut c = [0.0; 36];
                for (i, v) in c.iter_mut().enumerate() {
                    *v = a
                        .next_element()?
                        .ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
                }
                Ok(Covariance(c))
            }
        }
        d.deserialize_tuple(36, V)
    }
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    pub covariance: Covariance,
}

/// A localizer's pose (nav2's `/amcl_pose`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovarianceStamped {
    pub header: Header,
    pub pose: PoseWithCovariance,
}
message!(
    PoseWithCovarianceStamped,
    "geometry_msgs/msg/PoseWithCovarianceStamped"
);

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}
message!(Twist, "geometry_msgs/msg/Twist");

impl Twist {
    /// Forward speed and turn rate of a ground robot.
    pub fn planar(v_m_s: f64, omega_rad_s: f64) -> Self {
        Self {
            linear: Vector3 {
                x: v_m_s,
                ..Vector3::default()
            },
            angular: Vector3 {
                z: omega_rad_s,
                ..Vector3::default()
            },
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TwistStamped {
    pub header: Header,
    pub twist: Twist,
}
message!(TwistStamped, "geometry_msgs/msg/TwistStamped");

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    pub covariance: Covariance,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}
message!(Odometry, "nav_msgs/msg/Odometry");

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}

impl TransformStamped {
    /// `parent` → `child` for a planar pose of the child in the parent.
    pub fn planar(t_ns: u64, parent: &str, child: &str, x_m: f64, y_m: f64, yaw_rad: f64) -> Self {
        Self {
            header: Header::new(t_ns, parent),
            child_frame_id: child.to_string(),
            transform: Transform {
                translation: Vector3 {
                    x: x_m,
                    y: y_m,
                    z: 0.0,
                },
                rotation: Quaternion::from_yaw(yaw_rad),
            },
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TFMessage {
    pub transforms: Vec<TransformStamped>,
}
message!(TFMessage, "tf2_msgs/msg/TFMessage");

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JointState {
    pub header: Header,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}
message!(JointState, "sensor_msgs/msg/JointState");

/// `sensor_msgs/msg/Range`; `variance` exists from Jazzy on and is written
/// only when `Some`.
#[derive(Debug, Clone, PartialEq)]
pub struct Range {
    pub header: Header,
    pub radiation_type: u8,
    pub field_of_view: f32,
    pub min_range: f32,
    pub max_range: f32,
    pub range: f32,
    pub variance: Option<f32>,
}
message!(Range, "sensor_msgs/msg/Range");

impl Range {
    pub const ULTRASOUND: u8 = 0;
    pub const INFRARED: u8 = 1;
}

impl Serialize for Range {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut st = s.serialize_struct("Range", 7)?;
        st.serialize_field("header", &self.header)?;
        st.serialize_field("radiation_type", &self.radiation_type)?;
        st.serialize_field("field_of_view", &self.field_of_view)?;
        st.serialize_field("min_range", &self.min_range)?;
        st.serialize_field("max_range", &self.max_range)?;
        st.serialize_field("range", &self.range)?;
        if let Some(v) = &self.variance {
            st.serialize_field("variance", v)?;
        }
        st.end()
    }
}

/// `sensor_msgs/msg/Imu`. A covariance whose first element is −1 marks
/// its quantity as not measured; all zeros, as measured with an unknown
/// covariance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Imu {
    pub header: Header,
    pub orientation: Quaternion,
    pub orientation_covariance: [f64; 9],
    pub angular_velocity: Vector3,
    pub angular_velocity_covariance: [f64; 9],
    pub linear_acceleration: Vector3,
    pub linear_acceleration_covariance: [f64; 9],
}
message!(Imu, "sensor_msgs/msg/Imu");

impl Imu {
    /// `[-1, 0, …]`: the quantity is not measured.
    pub const NOT_MEASURED: [f64; 9] = [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];

    /// A yaw-rate gyro's reading: angular velocity about z (covariance
    /// unknown), no orientation, no linear acceleration.
    pub fn yaw_rate(header: Header, z_rad_s: f64) -> Self {
        Self {
            header,
            orientation: Quaternion::default(),
            orientation_covariance: Self::NOT_MEASURED,
            angular_velocity: Vector3 {
                z: z_rad_s,
                ..Vector3::default()
            },
            angular_velocity_covariance: [0.0; 9],
            linear_acceleration: Vector3::default(),
            linear_acceleration_covariance: Self::NOT_MEASURED,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LaserScan {
    pub header: Header,
    pub angle_min: f32,
    pub angle_max: f32,
    pub angle_increment: f32,
    pub time_increment: f32,
    pub scan_time: f32,
    pub range_min: f32,
    pub range_max: f32,
    pub ranges: Vec<f32>,
    pub intensities: Vec<f32>,
}
message!(LaserScan, "sensor_msgs/msg/LaserScan");

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct MapMetaData {
    pub map_load_time: Time,
    pub resolution: f32,
    pub width: u32,
    pub height: u32,
    pub origin: Pose,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OccupancyGrid {
    pub header: Header,
    pub info: MapMetaData,
    /// Row-major from the bottom row: −1 unknown, 0 free … 100 occupied.
    pub data: Vec<i8>,
}
message!(OccupancyGrid, "nav_msgs/msg/OccupancyGrid");

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Path {
    pub header: Header,
    pub poses: Vec<PoseStamped>,
}
message!(Path, "nav_msgs/msg/Path");

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HazardDetection {
    pub header: Header,
    #[serde(rename = "type")]
    pub kind: u8,
}

impl HazardDetection {
    pub const BACKUP_LIMIT: u8 = 0;
    pub const BUMP: u8 = 1;
    pub const CLIFF: u8 = 2;
    pub const STALL: u8 = 3;
    pub const WHEEL_DROP: u8 = 4;
    pub const OBJECT_PROXIMITY: u8 = 5;
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HazardDetectionVector {
    pub header: Header,
    pub detections: Vec<HazardDetection>,
}
message!(
    HazardDetectionVector,
    "irobot_create_msgs/msg/HazardDetectionVector"
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Schema;

    #[test]
    fn every_definition_parses_and_decodes_what_encode_writes() {
        for distro in [Distro::Humble, Distro::Jazzy] {
            for t in known_types() {
                let text = definition(t, distro).unwrap();
                Schema::parse(t, &text).unwrap_or_else(|e| panic!("{t}: {e}\n{text}"));
            }
        }
        let odom = Odometry {
            header: Header::new(1_500_000_000, "odom"),
            child_frame_id: "base_link".into(),
            pose: PoseWithCovariance {
                pose: Pose::planar(1.0, -2.0, 0.5),
                covariance: Covariance::diagonal([1e-4, 1e-4, 1e6, 1e6, 1e6, 1e-3]),
            },
            twist: TwistWithCovariance {
                twist: Twist::planar(0.3, -0.1),
                covariance: Covariance::default(),
            },
        };
        let bytes = encode(&odom);
        let s = Schema::parse(
            Odometry::TYPE,
            &definition(Odometry::TYPE, Distro::Jazzy).unwrap(),
        )
        .unwrap();
        let v = s.decode(&bytes).unwrap();
        let get = |p: &str| v.at(&s.path(p).unwrap()).unwrap().clone();
        assert_eq!(get("header.stamp.sec").as_i64(), Some(1));
        assert_eq!(get("header.stamp.nanosec").as_i64(), Some(500_000_000));
        assert_eq!(get("header.frame_id").as_str(), Some("odom"));
        assert_eq!(get("pose.pose.position.y").as_f64(), Some(-2.0));
        assert_eq!(get("twist.twist.angular.z").as_f64(), Some(-0.1));
        let cov = get("pose.covariance");
        assert_eq!(cov.as_array().unwrap()[35].as_f64(), Some(1e-3));
        let (back, _) =
            cdr_encoding::from_bytes::<Odometry, byteorder::LittleEndian>(&bytes[4..]).unwrap();
        assert_eq!(back, odom);
    }

    #[test]
    fn range_follows_the_distro() {
        let r = Range {
            header: Header::new(0, "ir"),
            radiation_type: Range::INFRARED,
            field_of_view: 0.05,
            min_range: 0.04,
            max_range: 0.8,
            range: 0.3,
            variance: Some(1e-4),
        };
        let jazzy = Schema::parse(RANGE, &definition(RANGE, Distro::Jazzy).unwrap()).unwrap();
        let humble = Schema::parse(RANGE, &definition(RANGE, Distro::Humble).unwrap()).unwrap();
        assert!(jazzy.decode(&encode(&r)).is_ok());
        let old = Range {
            variance: None,
            ..r
        };
        assert!(humble.decode(&encode(&old)).is_ok());
    }

    #[test]
    fn imu_encodes_as_its_definition_and_back() {
        let imu = Imu::yaw_rate(Header::new(2_250_000_000, "imu_link"), -0.375);
        let bytes = encode(&imu);
        let s = Schema::parse(Imu::TYPE, &definition(Imu::TYPE, Distro::Jazzy).unwrap()).unwrap();
        let v = s.decode(&bytes).unwrap();
        let get = |p: &str| v.at(&s.path(p).unwrap()).unwrap().clone();
        assert_eq!(get("header.frame_id").as_str(), Some("imu_link"));
        assert_eq!(get("angular_velocity.z").as_f64(), Some(-0.375));
        assert_eq!(get("orientation.w").as_f64(), Some(1.0));
        let first = |p: &str| get(p).as_array().unwrap()[0].as_f64();
        assert_eq!(first("orientation_covariance"), Some(-1.0));
        assert_eq!(first("angular_velocity_covariance"), Some(0.0));
        assert_eq!(first("linear_acceleration_covariance"), Some(-1.0));
        let (back, _) =
            cdr_encoding::from_bytes::<Imu, byteorder::LittleEndian>(&bytes[4..]).unwrap();
        assert_eq!(back, imu);
    }

    #[test]
    fn yaw_round_trips() {
        for yaw in [-3.0, -1.0, 0.0, 0.7, 3.1] {
            assert!((Quaternion::from_yaw(yaw).yaw_rad() - yaw).abs() < 1e-12);
        }
    }
}
