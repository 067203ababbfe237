//! A topic's quality of service as ROS 2 writes it in the two places
//! twindrive does: a rosbag2 bag's `offered_qos_profiles` and an rmw_zenoh
//! liveliness token.

/// The rmw QoS policies twindrive sets; the rest are rmw's defaults
/// (keep-last history, infinite deadline, lifespan and lease, automatic
/// liveliness).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Reliable, or best effort.
    pub reliable: bool,
    /// Late joiners get the last messages (latched: `/map`, `/tf_static`).
    pub transient_local: bool,
    pub depth: u32,
}

impl Qos {
    /// rclcpp's default: reliable, volatile, keep last 10.
    pub const DEFAULT: Qos = Qos {
        reliable: true,
        transient_local: false,
        depth: 10,
    };
    /// `rclcpp::SensorDataQoS`: best effort, keep last 5.
    pub const SENSOR_DATA: Qos = Qos {
        reliable: false,
        transient_local: false,
        depth: 5,
    };
    /// A latched topic: reliable, transient local, keep last 1.
    pub const LATCHED: Qos = Qos {
        reliable: true,
        transient_local: true,
        depth: 1,
    };

    /// rosbag2's `offered_qos_profiles` (metadata version 8): a YAML list of
    /// one profile.
    pub fn yaml(&self) -> String {
        // rmw enums: history 1 keep-last; reliability 1 reliable, 2 best
        // effort; durability 1 transient local, 2 volatile; liveliness 1
        // automatic. Durations 0 are the rmw defaults (infinite).
        format!(
            "- history: 1\n  depth: {}\n  reliability: {}\n  durability: {}\n  deadline:\n    sec: 0\n    nsec: 0\n  lifespan:\n    sec: 0\n    nsec: 0\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 0\n    nsec: 0\n  avoid_ros_namespace_conventions: false",
            self.depth,
            if self.reliable { 1 } else { 2 },
            if self.transient_local { 1 } else { 2 },
        )
    }

    /// rmw_zenoh's token part
    /// `<reliability>:<durability>:<history>,<depth>:<deadline>:<lifespan>:<liveliness>`,
    /// each empty where it is rmw_zenoh's default (reliable, volatile, keep
    /// last, infinite durations, automatic liveliness).
    pub fn keyexpr(&self) -> String {
        format!(
            "{}:{}:,{}:,:,:,,",
            if self.reliable { "" } else { "2" },
            if self.transient_local { "1" } else { "" },
            self.depth
        )
    }
}
