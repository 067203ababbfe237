//! What a rehearsal from goals reached, and when: the operator's intent as
//! the log records it. The mission pipeline keeps these goals in the plan
//! (it cuts, re-times and smooths only between them), and verification
//! checks that the plan still reaches them.

use serde::{Deserialize, Serialize};

/// The goals a rehearsal drove to, in the order it reached them.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RehearsedGoals {
    /// Every waypoint the operator gave (and home, when the mission comes
    /// back), in order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub waypoints: Vec<ReachedWaypoint>,
    /// Every area the operator had swept.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub areas: Vec<SweptArea>,
}

impl RehearsedGoals {
    pub fn is_empty(&self) -> bool {
        self.waypoints.is_empty() && self.areas.is_empty()
    }

    /// The log time windows in which the goals were met (a waypoint from
    /// the moment the robot stood there until it left, an area from its
    /// first lane to its last), in time order.
    pub fn windows_s(&self) -> Vec<(f64, f64)> {
        let mut windows: Vec<(f64, f64)> = self
            .waypoints
            .iter()
            .map(|w| (w.reached_t_s, w.left_t_s))
            .chain(self.areas.iter().map(|a| (a.start_t_s, a.end_t_s)))
            .collect();
        windows.sort_by(|a, b| a.0.total_cmp(&b.0));
        windows
    }
}

/// A waypoint the rehearsal reached.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReachedWaypoint {
    /// How the operator knows it: `waypoint 2`, or `home`.
    pub name: String,
    pub x_m: f64,
    pub y_m: f64,
    /// The heading the robot turned to there (rad), if one was asked for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading_rad: Option<f64>,
    /// How long it was to stand there (s).
    pub dwell_s: f64,
    /// Log time at which the robot stood there (before it turned and
    /// dwelt), and at which it left.
    pub reached_t_s: f64,
    pub left_t_s: f64,
}

/// An area the rehearsal swept.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweptArea {
    /// `area 1`, ...
    pub name: String,
    pub polygon: Vec<[f64; 2]>,
    /// The sweep about the robot's centre (m).
    pub sweep_radius_m: f64,
    /// Log time of the sweep's first lane and of its last touch-up.
    pub start_t_s: f64,
    pub end_t_s: f64,
    /// The share of the area's free ground the twin swept (%), once
    /// measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub swept_percent: Option<f64>,
}
