//! A ROS 2 robot behind the agent, without I/O: what the robot's drivers
//! publish goes in ([`RosBridge::on_message`]), the agent's wheel command
//! comes out as the bytes of the robot's command topic
//! ([`RosBridge::step`]), with time as an argument. `twindrive_net::ros`
//! carries both over zenoh with rmw_zenoh's key expressions.
//!
//! The site file's `[ros]` section ([`RosConfig`]) names the topics and
//! types. The safety rules stay on the robot: the executive's stops are
//! unchanged, and a `/joint_states` older than its timeout is a fault that
//! stops the wheels at once and hands back.

use serde::Deserialize;
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_log::{LogHeader, StepRecord};
use twindrive_ros::live::{Decoder, Sample};
use twindrive_ros::msgs::{self, Float64MultiArray, Header, Twist, TwistStamped};
use twindrive_ros::rmw_zenoh::fully_qualified;
use twindrive_sim::Scenario;

use crate::backend::Reading;

fn default_node() -> String {
    "twindrive_agent".into()
}
fn default_connect() -> Vec<String> {
    vec!["tcp/127.0.0.1:7447".into()]
}
fn default_period() -> f64 {
    0.02
}
fn default_cmd_vel() -> String {
    "cmd_vel".into()
}
fn default_twist() -> String {
    "geometry_msgs/msg/Twist".into()
}
fn default_base_link() -> String {
    "base_link".into()
}
fn default_joint_states() -> String {
    "joint_states".into()
}
fn default_timeout() -> f64 {
    0.5
}

/// The `[ros]` section of a site file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RosConfig {
    /// `ROS_DOMAIN_ID`.
    #[serde(default)]
    pub domain_id: u32,
    /// The robot's namespace (`/tb3`); relative topic names go under it.
    #[serde(default)]
    pub namespace: String,
    /// The agent's node name in the ROS graph.
    #[serde(default = "default_node")]
    pub node_name: String,
    /// zenoh endpoints of the robot's rmw_zenoh router (`rmw_zenohd`).
    #[serde(default = "default_connect")]
    pub connect: Vec<String>,
    /// The control period (s).
    #[serde(default = "default_period")]
    pub period_s: f64,
    pub command: CommandConfig,
    pub joint_states: JointStatesConfig,
    /// Range sensors of the site's robot, by topic.
    #[serde(default)]
    pub ranges: Vec<RangeConfig>,
    /// The bumper.
    pub hazard: Option<TopicConfig>,
    /// An absolute pose (motion capture, a localizer), for the online EKF.
    pub pose: Option<TopicConfig>,
    /// The robot's own odometry, logged as its best estimate where no
    /// absolute pose is given.
    pub odom: Option<TopicConfig>,
}

/// Where wheel commands go.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CommandConfig {
    #[serde(default = "default_cmd_vel")]
    pub topic: String,
    /// `geometry_msgs/msg/Twist`, `geometry_msgs/msg/TwistStamped` (a
    /// diff_drive_controller), or `std_msgs/msg/Float64MultiArray` (a
    /// ros2_control velocity controller: `[left, right]` in rad/s).
    #[serde(rename = "type", default = "default_twist")]
    pub type_name: String,
    /// The wheel radius the robot's controller turns a twist into wheel
    /// speeds with (default: half the site's nominal mean diameter).
    pub wheel_radius_m: Option<f64>,
    /// Its wheel separation (default: the site's nominal wheelbase).
    pub wheel_separation_m: Option<f64>,
    /// `header.frame_id` of a TwistStamped.
    #[serde(default = "default_base_link")]
    pub frame_id: String,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointStatesConfig {
    #[serde(default = "default_joint_states")]
    pub topic: String,
    pub left_joint: String,
    pub right_joint: String,
    /// No wheel joints for this long stops the robot and hands back (s).
    #[serde(default = "default_timeout")]
    pub timeout_s: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RangeConfig {
    pub topic: String,
    /// `sensor_msgs/msg/Range` or `sensor_msgs/msg/LaserScan`; unsaid,
    /// the one of the sensor's kind (a scan for a lidar).
    #[serde(rename = "type", default)]
    pub type_name: Option<String>,
    /// The `[[range_sensors]]` entry of the site file it is.
    pub sensor: String,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TopicConfig {
    pub topic: String,
    #[serde(rename = "type")]
    pub type_name: String,
}

/// What a subscription feeds.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Role {
    Joints,
    Range { offset: usize, beams: usize },
    Hazard,
    Pose,
    Odom,
}

/// A topic the bridge subscribes to.
#[derive(Debug, Clone)]
pub struct Subscription {
    /// Fully qualified (`/tb3/joint_states`).
    pub topic: String,
    pub type_name: String,
    role: Role,
    decoder: Decoder,
}

/// Counters for the robot's journal and tests.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BridgeStats {
    /// Messages received, per subscription.
    pub received: Vec<u64>,
    /// Messages that did not decode (logged and dropped).
    pub rejected: u64,
    /// Wheel commands published, zeros while no plan ran included.
    pub commands_sent: u64,
    /// Periods the wheels were stopped because `/joint_states` was stale.
    pub stale_periods: u64,
}

/// The agent's side of a ROS 2 robot.
pub struct RosBridge {
    config: RosConfig,
    header: LogHeader,
    subscriptions: Vec<Subscription>,
    command_topic: String,
    /// The robot controller's wheel radius and separation (m).
    controller: (f64, f64),
    origin_s: f64,
    ticks_per_rad: f64,
    // What the robot said last.
    wheel_angles: Option<[f64; 2]>,
    wheel_speeds: [f64; 2],
    joints_at_s: Option<f64>,
    fresh_ticks: Option<[i64; 2]>,
    ranges: Vec<f64>,
    fresh_ranges: Vec<f64>,
    bump: bool,
    stall: bool,
    fresh_pose: Option<Pose>,
    best_pose: Pose,
    stats: BridgeStats,
}

impl RosBridge {
    /// Checks `config` against the site's robot (its sensors, its
    /// parameters) and starts the bridge's clock at `now_s`.
    pub fn new(config: RosConfig, site: &Scenario, now_s: f64) -> Result<Self, String> {
        if !(config.period_s.is_finite() && config.period_s > 0.0 && config.period_s <= 1.0) {
            return Err(format!(
                "ros.period_s: between 0 and 1 s, got {}",
                config.period_s
            ));
        }
        let j = &config.joint_states;
        if !(j.timeout_s.is_finite() && j.timeout_s > 0.0) {
            return Err(format!(
                "ros.joint_states.timeout_s: a number > 0, got {}",
                j.timeout_s
            ));
        }
        let header = site.log_header();
        let ns = config.namespace.as_str();
        let mut subscriptions = vec![Subscription {
            topic: fully_qualified(ns, &j.topic),
            type_name: "sensor_msgs/msg/JointState".into(),
            role: Role::Joints,
            decoder: Decoder::joints(&j.left_joint, &j.right_joint)?,
        }];
        let offsets = header.beam_offsets();
        for (i, r) in config.ranges.iter().enumerate() {
            let k = header.sensor_index(&r.sensor).ok_or_else(|| {
                format!(
                    "ros.ranges[{i}].sensor: the site has no range sensor `{}` (it has: {})",
                    r.sensor,
                    header
                        .range_sensors
                        .iter()
                        .map(|s| s.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })?;
            let kind = header.range_sensors[k].kind;
            let beams = header.range_sensors[k].beams as usize;
            let ranger = kind == twindrive_log::SensorKind::Ranger;
            let expected = if ranger {
                "sensor_msgs/msg/Range"
            } else {
                "sensor_msgs/msg/LaserScan"
            };
            let type_name = r.type_name.as_deref().unwrap_or(expected);
            if type_name != expected {
                return Err(format!(
                    "ros.ranges[{i}]: sensor `{}` is a {kind}, so its type is {expected}",
                    r.sensor
                ));
            }
            subscriptions.push(Subscription {
                topic: fully_qualified(ns, &r.topic),
                type_name: type_name.to_owned(),
                role: Role::Range {
                    offset: offsets[k],
                    beams,
                },
                decoder: Decoder::range(type_name).map_err(|e| format!("ros.ranges[{i}]: {e}"))?,
            });
        }
        for (name, t, role) in [
            ("hazard", &config.hazard, Role::Hazard),
            ("pose", &config.pose, Role::Pose),
            ("odom", &config.odom, Role::Odom),
        ] {
            let Some(t) = t else { continue };
            let decoder = match role {
                Role::Hazard => Decoder::hazard(&t.type_name),
                _ => Decoder::pose(&t.type_name),
            }
            .map_err(|e| format!("ros.{name}: {e}"))?;
            subscriptions.push(Subscription {
                topic: fully_qualified(ns, &t.topic),
                type_name: t.type_name.clone(),
                role,
                decoder,
            });
        }
        let c = &config.command;
        if !matches!(
            c.type_name.as_str(),
            "geometry_msgs/msg/Twist"
                | "geometry_msgs/msg/TwistStamped"
                | "std_msgs/msg/Float64MultiArray"
        ) {
            return Err(format!(
                "ros.command.type: geometry_msgs/msg/Twist, geometry_msgs/msg/TwistStamped or std_msgs/msg/Float64MultiArray, not {}",
                c.type_name
            ));
        }
        let n: DiffDriveParams = header.nominal;
        let controller = (
            c.wheel_radius_m
                .unwrap_or(0.25 * (n.left_diameter_m + n.right_diameter_m)),
            c.wheel_separation_m.unwrap_or(n.wheelbase_m),
        );
        if !(controller.0 > 0.0 && controller.1 > 0.0) {
            return Err("ros.command: wheel_radius_m and wheel_separation_m must be > 0".into());
        }
        let beams = header.beams_per_step();
        let start = header.start;
        Ok(Self {
            command_topic: fully_qualified(ns, &c.topic),
            controller,
            origin_s: now_s,
            ticks_per_rad: f64::from(header.ticks_per_rev) / std::f64::consts::TAU,
            stats: BridgeStats {
                received: vec![0; subscriptions.len()],
                ..BridgeStats::default()
            },
            subscriptions,
            config,
            header,
            wheel_angles: None,
            wheel_speeds: [0.0; 2],
            joints_at_s: None,
            fresh_ticks: None,
            ranges: vec![f64::NAN; beams],
            fresh_ranges: vec![f64::NAN; beams],
            bump: false,
            stall: false,
            fresh_pose: None,
            best_pose: start,
        })
    }

    pub fn config(&self) -> &RosConfig {
        &self.config
    }

    pub fn subscriptions(&self) -> &[Subscription] {
        &self.subscriptions
    }

    /// The command topic (fully qualified) and its type.
    pub fn command_topic(&self) -> (&str, &str) {
        (&self.command_topic, &self.config.command.type_name)
    }

    pub fn stats(&self) -> &BridgeStats {
        &self.stats
    }

    /// What the robot's logs say of it; `start` is where it is now.
    pub fn log_header(&self) -> LogHeader {
        let mut h = self.header.clone();
        h.start = self.best_pose;
        h
    }

    /// A message on subscription `index` at `now_s`. A message that does
    /// not decode is counted and refused; the bridge carries on.
    pub fn on_message(&mut self, index: usize, bytes: &[u8], now_s: f64) -> Result<(), String> {
        let sub = self
            .subscriptions
            .get(index)
            .ok_or_else(|| format!("no subscription {index}"))?;
        let sample = match sub.decoder.decode(bytes) {
            Ok(s) => s,
            Err(e) => {
                self.stats.rejected += 1;
                return Err(format!("{} ({}): {e}", sub.topic, sub.type_name));
            }
        };
        self.stats.received[index] += 1;
        match (sub.role, sample) {
            (Role::Joints, Sample::Joints { position, velocity }) => {
                let dt = self.joints_at_s.map(|t| now_s - t).unwrap_or(0.0);
                let angles = match (position, velocity, self.wheel_angles) {
                    (Some(p), _, _) => p,
                    // Speeds only: integrate them.
                    (None, Some(v), Some(a)) => [a[0] + v[0] * dt, a[1] + v[1] * dt],
                    (None, Some(_), None) => [0.0, 0.0],
                    (None, None, _) => {
                        return Err(format!(
                            "{}: the wheel joints have neither position nor velocity",
                            sub.topic
                        ));
                    }
                };
                self.wheel_speeds = match (velocity, self.wheel_angles) {
                    (Some(v), _) => v,
                    (None, Some(a)) if dt > 0.0 => {
                        [(angles[0] - a[0]) / dt, (angles[1] - a[1]) / dt]
                    }
                    _ => self.wheel_speeds,
                };
                self.wheel_angles = Some(angles);
                self.fresh_ticks = Some(angles.map(|a| (a * self.ticks_per_rad).round() as i64));
                self.joints_at_s = Some(now_s);
            }
            (Role::Joints, Sample::OtherJoints) => {}
            (Role::Range { offset, .. }, Sample::Range(r)) => {
                self.ranges[offset] = r;
                self.fresh_ranges[offset] = r;
            }
            (Role::Range { offset, beams }, Sample::Scan(rs)) => {
                if rs.len() != beams {
                    self.stats.rejected += 1;
                    return Err(format!(
                        "{}: a scan of {} beams, the site's sensor has {beams}",
                        sub.topic,
                        rs.len()
                    ));
                }
                self.ranges[offset..offset + beams].copy_from_slice(&rs);
                self.fresh_ranges[offset..offset + beams].copy_from_slice(&rs);
            }
            (Role::Hazard, Sample::Hazard { bump, stall }) => {
                self.bump = bump;
                self.stall = stall;
            }
            (Role::Pose, Sample::Pose([x, y, h])) => {
                let p = Pose::new(x, y, h);
                self.fresh_pose = Some(p);
                self.best_pose = p;
            }
            (Role::Odom, Sample::Pose([x, y, h])) => {
                if self.config.pose.is_none() {
                    self.best_pose = Pose::new(x, y, h);
                }
            }
            (_, other) => {
                return Err(format!("{}: unexpected {other:?}", sub.topic));
            }
        }
        Ok(())
    }

    /// How long `/joint_states` has been silent at `now_s`.
    pub fn joints_silent_s(&self, now_s: f64) -> f64 {
        now_s - self.joints_at_s.unwrap_or(self.origin_s)
    }

    /// One control period at `now_s`: the reading of what the robot said
    /// since the last, the agent's decision on it (`decide`), and the
    /// command message to publish now. Stale joint states make the reading
    /// a fault and command zero, whatever `decide` asked.
    pub fn step(
        &mut self,
        now_s: f64,
        decide: &mut dyn FnMut(&Reading) -> [f64; 2],
    ) -> (Reading, Vec<u8>) {
        let silent = self.joints_silent_s(now_s);
        let timeout = self.config.joint_states.timeout_s;
        let fault = (silent > timeout).then(|| {
            format!(
                "no wheel joints on {} for {silent:.2} s (timeout {timeout} s)",
                self.subscriptions[0].topic
            )
        });
        let t_s = now_s - self.origin_s;
        let encoder_ticks = self.fresh_ticks.take();
        let pose = self.fresh_pose.take();
        let fresh = std::mem::replace(&mut self.fresh_ranges, vec![f64::NAN; self.ranges.len()]);
        let mut reading = Reading {
            t_s,
            encoder_ticks,
            bump: self.bump,
            ranges_m: self.ranges.clone(),
            pose,
            record: StepRecord {
                t_ns: 0,
                cmd_wheel_rad_s: [0.0; 2],
                wheel_rad_s: self.wheel_speeds,
                encoder_ticks,
                bump: self.bump,
                tracker: pose,
                ground_truth: self.best_pose,
                gyro_z_rad_s: None,
            },
            fresh_ranges_m: fresh,
            blocked: self.stall,
            fault,
        };
        let asked = decide(&reading);
        let wheels = if reading.fault.is_some() {
            self.stats.stale_periods += 1;
            [0.0, 0.0]
        } else {
            asked
        };
        reading.record.cmd_wheel_rad_s = wheels;
        self.stats.commands_sent += 1;
        (reading, self.command_bytes(wheels, now_s))
    }

    /// The command of a period in which the agent drives no plan: zero.
    pub fn hold(&mut self, now_s: f64) -> Vec<u8> {
        self.stats.commands_sent += 1;
        self.command_bytes([0.0, 0.0], now_s)
    }

    /// The command message for `wheels` (left, right, rad/s).
    pub fn command_bytes(&self, wheels: [f64; 2], now_s: f64) -> Vec<u8> {
        let (r, b) = self.controller;
        let v = 0.5 * r * (wheels[0] + wheels[1]);
        let w = r * (wheels[1] - wheels[0]) / b;
        match self.config.command.type_name.as_str() {
            "geometry_msgs/msg/TwistStamped" => msgs::encode(&TwistStamped {
                header: Header::new((now_s.max(0.0) * 1e9) as u64, &self.config.command.frame_id),
                twist: Twist::planar(v, w),
            }),
            "std_msgs/msg/Float64MultiArray" => msgs::encode(&Float64MultiArray {
                data: wheels.to_vec(),
                ..Float64MultiArray::default()
            }),
            _ => msgs::encode(&Twist::planar(v, w)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use twindrive_ros::msgs::{HazardDetection, HazardDetectionVector, JointState, LaserScan};

    fn site() -> Scenario {
        twindrive_sim::builtin::load("wall_following")
            .unwrap()
            .unwrap()
    }

    fn config(extra: &str) -> RosConfig {
        toml::from_str(&format!(
            "[command]\n[joint_states]\nleft_joint = \"wl\"\nright_joint = \"wr\"\n{extra}"
        ))
        .unwrap()
    }

    fn joints(pos: [f64; 2]) -> Vec<u8> {
        msgs::encode(&JointState {
            header: Header::new(0, ""),
            name: vec!["wl".into(), "wr".into()],
            position: pos.to_vec(),
            velocity: vec![],
            effort: vec![],
        })
    }

    #[test]
    fn joints_become_ticks_and_stale_joints_stop_the_wheels() {
        let site = site();
        let mut b = RosBridge::new(config(""), &site, 100.0).unwrap();
        let tpr = f64::from(site.log_header().ticks_per_rev);
        b.on_message(0, &joints([std::f64::consts::PI, 0.0]), 100.01)
            .unwrap();
        let (r, cmd) = b.step(100.02, &mut |_| [2.0, 2.0]);
        assert_eq!(r.encoder_ticks, Some([(tpr / 2.0).round() as i64, 0]));
        assert!(r.fault.is_none());
        let (twist, _) =
            cdr_encoding::from_bytes::<Twist, byteorder::LittleEndian>(&cmd[4..]).unwrap();
        let n = site.log_header().nominal;
        let radius = 0.25 * (n.left_diameter_m + n.right_diameter_m);
        assert!((twist.linear.x - 2.0 * radius).abs() < 1e-12 && twist.angular.z.abs() < 1e-12);
        // No new joint state: no new ticks this period.
        let (r, _) = b.step(100.04, &mut |_| [2.0, 2.0]);
        assert_eq!(r.encoder_ticks, None);
        // Silent past the timeout: zero, whatever is asked, and a fault.
        let (r, cmd) = b.step(100.6, &mut |_| [2.0, -2.0]);
        assert!(
            r.fault.as_deref().unwrap().contains("/joint_states"),
            "{:?}",
            r.fault
        );
        assert_eq!(r.record.cmd_wheel_rad_s, [0.0, 0.0]);
        let (twist, _) =
            cdr_encoding::from_bytes::<Twist, byteorder::LittleEndian>(&cmd[4..]).unwrap();
        assert_eq!((twist.linear.x, twist.angular.z), (0.0, 0.0));
        // Garbage is refused and counted; the bridge carries on.
        assert!(b.on_message(0, &[0, 1, 0, 0, 9], 100.7).is_err());
        assert_eq!(b.stats().rejected, 1);
        b.on_message(0, &joints([0.0, 0.0]), 100.8).unwrap();
        assert!(b.step(100.81, &mut |_| [1.0, 1.0]).0.fault.is_none());
    }

    #[test]
    fn sensors_hazards_and_config_errors() {
        let site = site();
        let sensor = &site.log_header().range_sensors[0];
        let extra = format!(
            "[[ranges]]\ntopic = \"ir\"\nsensor = \"{}\"\n[hazard]\ntopic = \"/hazard_detection\"\ntype = \"irobot_create_msgs/msg/HazardDetectionVector\"\n",
            sensor.name
        );
        let mut b = RosBridge::new(
            RosConfig {
                namespace: "/tb".into(),
                ..config(&extra)
            },
            &site,
            0.0,
        )
        .unwrap();
        assert_eq!(b.subscriptions()[1].topic, "/tb/ir");
        assert_eq!(b.subscriptions()[2].topic, "/hazard_detection");
        assert_eq!(b.command_topic().0, "/tb/cmd_vel");
        let range = msgs::encode(&msgs::Range {
            header: Header::new(0, "ir"),
            radiation_type: msgs::Range::INFRARED,
            field_of_view: 0.0,
            min_range: 0.1,
            max_range: 0.8,
            range: 0.25,
            variance: Some(0.0),
        });
        b.on_message(1, &range, 0.01).unwrap();
        let hz = msgs::encode(&HazardDetectionVector {
            header: Header::new(0, ""),
            detections: vec![HazardDetection {
                header: Header::new(0, ""),
                kind: HazardDetection::BUMP,
            }],
        });
        b.on_message(2, &hz, 0.01).unwrap();
        let (r, _) = b.step(0.02, &mut |_| [0.0, 0.0]);
        assert!(r.bump);
        assert_eq!(r.ranges_m[0], 0.25_f32 as f64);
        assert_eq!(r.fresh_ranges_m[0], 0.25_f32 as f64);
        let (r, _) = b.step(0.04, &mut |_| [0.0, 0.0]);
        assert!(r.fresh_ranges_m[0].is_nan() && r.ranges_m[0] > 0.0);

        let scan = msgs::encode(&LaserScan {
            header: Header::new(0, ""),
            angle_min: 0.0,
            angle_max: 0.0,
            angle_increment: 0.0,
            time_increment: 0.0,
            scan_time: 0.0,
            range_min: 0.0,
            range_max: 1.0,
            ranges: vec![1.0; 3],
            intensities: vec![],
        });
        assert!(
            b.on_message(1, &scan, 0.05).is_err(),
            "a scan on a Range topic"
        );

        let bad = "[[ranges]]\ntopic = \"ir\"\nsensor = \"sonar\"\n";
        let e = RosBridge::new(config(bad), &site, 0.0).err().unwrap();
        assert!(e.contains("no range sensor `sonar`"), "{e}");
        let e = RosBridge::new(
            config(&format!("[[ranges]]\ntopic = \"ir\"\ntype = \"sensor_msgs/msg/LaserScan\"\nsensor = \"{}\"\n", sensor.name)),
            &site,
            0.0,
        )
        .err()
        .unwrap();
        assert!(e.contains("so its type is sensor_msgs/msg/Range"), "{e}");
        let mut c = config("");
        c.command.type_name = "std_msgs/msg/Float64MultiArray".into();
        let b = RosBridge::new(c, &site, 0.0).unwrap();
        let (arr, _) = cdr_encoding::from_bytes::<Float64MultiArray, byteorder::LittleEndian>(
            &b.command_bytes([1.5, -0.5], 0.0)[4..],
        )
        .unwrap();
        assert_eq!(arr.data, vec![1.5, -0.5]);
    }
}
