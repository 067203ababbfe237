//! The operator's goals for a rehearsal on the twin (`mission.toml`): an
//! ordered list of waypoints the twin's robot is to drive through, each
//! with an optional heading to turn to there, a time to stand, and a speed
//! limit for the leg that ends there; the clearance the way keeps and the
//! speed it drives at.
//!
//! ```toml
//! clearance_m = 0.1   # the footprint kept clear of everything by this
//! speed_m_s = 0.2     # the drive's speed, unless a leg says otherwise
//!
//! [[waypoints]]
//! x_m = 2.0
//! y_m = 1.0
//!
//! [[waypoints]]       # the last is the goal
//! x_m = 4.5
//! y_m = 3.0
//! heading_rad = 1.57  # turn to face this there
//! dwell_s = 5.0       # and stand this long
//! speed_m_s = 0.1     # the leg to here at most this fast
//!
//! [[areas]]           # then sweep this, after the waypoints
//! polygon = [[1.0, 3.0], [3.0, 3.0], [3.0, 4.5], [1.0, 4.5]]
//! sweep_radius_m = 0.15  # the sweep about the robot's centre (default: its footprint)
//! overlap = 0.1       # lanes overlap by this share of the sweep's width
//! ```
//!
//! With `return_home = true` the robot comes back, after the waypoints and
//! areas, to where it started and turns to face as it did. The goals are
//! the operator's intent: a plan made from their rehearsal keeps every one
//! (see [`crate::itinerary`]).

use serde::{Deserialize, Serialize};

/// A mission file as written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Goals {
    #[serde(default = "default_clearance")]
    pub clearance_m: f64,
    #[serde(default = "default_speed")]
    pub speed_m_s: f64,
    #[serde(default)]
    pub waypoints: Vec<Waypoint>,
    /// Areas to sweep, in order, after the waypoints.
    #[serde(default)]
    pub areas: Vec<Area>,
    /// Come back to the start (and face as there) after everything else.
    #[serde(default)]
    pub return_home: bool,
}

/// An area to sweep ([`crate::coverage`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Area {
    /// A simple polygon (x, y in the site's frame, m).
    pub polygon: Vec<[f64; 2]>,
    /// The sweep's radius about the robot's centre (m; default: the
    /// robot's footprint radius).
    #[serde(default)]
    pub sweep_radius_m: Option<f64>,
    #[serde(default = "default_overlap")]
    pub overlap: f64,
}

fn default_overlap() -> f64 {
    0.1
}

fn default_clearance() -> f64 {
    0.1
}
fn default_speed() -> f64 {
    0.2
}

/// One waypoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Waypoint {
    pub x_m: f64,
    pub y_m: f64,
    /// Turn to face this there (rad, counter-clockwise from x).
    #[serde(default)]
    pub heading_rad: Option<f64>,
    /// Stand still this long there (s).
    #[serde(default)]
    pub dwell_s: f64,
    /// The leg that ends here at most this fast (m/s).
    #[serde(default)]
    pub speed_m_s: Option<f64>,
}

impl Waypoint {
    pub fn at(&self) -> [f64; 2] {
        [self.x_m, self.y_m]
    }
}

impl Goals {
    /// Parses and checks a mission file's text; errors say the line (TOML)
    /// or the field (`waypoints[2].x_m`) and what was expected.
    pub fn parse(text: &str) -> Result<Self, String> {
        let goals: Self = toml::from_str(text).map_err(|e| e.to_string())?;
        goals.validate()?;
        Ok(goals)
    }

    /// Checks the values; errors name the field.
    pub fn validate(&self) -> Result<(), String> {
        let positive = |field: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("field `{field}`: expected a number > 0, got {v}"))
            }
        };
        if !(self.clearance_m.is_finite() && self.clearance_m >= 0.0) {
            return Err(format!(
                "field `clearance_m`: expected a number >= 0, got {}",
                self.clearance_m
            ));
        }
        positive("speed_m_s", self.speed_m_s)?;
        if self.waypoints.is_empty() && self.areas.is_empty() {
            return Err(
                "no `[[waypoints]]` and no `[[areas]]`: expected at least one waypoint (the last is the goal) or an area to sweep".to_string(),
            );
        }
        for (i, a) in self.areas.iter().enumerate() {
            crate::plan::check_polygon(&a.polygon)
                .map_err(|e| format!("field `areas[{i}].polygon`: {e}"))?;
            if let Some(r) = a.sweep_radius_m {
                positive(&format!("areas[{i}].sweep_radius_m"), r)?;
            }
            if !(a.overlap.is_finite() && (0.0..0.9).contains(&a.overlap)) {
                return Err(format!(
                    "field `areas[{i}].overlap`: expected a share in [0, 0.9), got {}",
                    a.overlap
                ));
            }
        }
        for (i, w) in self.waypoints.iter().enumerate() {
            let field = |f: &str| format!("waypoints[{i}].{f}");
            for (f, v) in [("x_m", w.x_m), ("y_m", w.y_m)] {
                if !v.is_finite() {
                    return Err(format!(
                        "field `{}`: expected a finite number, got {v}",
                        field(f)
                    ));
                }
            }
            if let Some(h) = w.heading_rad
                && !(h.is_finite() && h.abs() <= std::f64::consts::TAU)
            {
                return Err(format!(
                    "field `{}`: expected an angle in radians within ±2π (±6.283), got {h}{}",
                    field("heading_rad"),
                    if h.is_finite() {
                        format!(
                            " (if you meant {h} degrees, that is {:.4} rad)",
                            h.to_radians()
                        )
                    } else {
                        String::new()
                    }
                ));
            }
            if !(w.dwell_s.is_finite() && w.dwell_s >= 0.0) {
                return Err(format!(
                    "field `{}`: expected a number >= 0, got {}",
                    field("dwell_s"),
                    w.dwell_s
                ));
            }
            if let Some(v) = w.speed_m_s {
                positive(&field("speed_m_s"), v)?;
            }
        }
        Ok(())
    }

    /// The speed limit of the leg that ends at waypoint `k` (m/s).
    pub fn leg_speed_m_s(&self, k: usize) -> f64 {
        self.waypoints[k].speed_m_s.unwrap_or(self.speed_m_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mission_file_parses_with_its_defaults() {
        let g = Goals::parse(
            "[[waypoints]]\nx_m = 1\ny_m = 2\n\n[[waypoints]]\nx_m = 3\ny_m = 4\nheading_rad = 1.5\ndwell_s = 2\nspeed_m_s = 0.1\n",
        )
        .unwrap();
        assert_eq!(g.clearance_m, 0.1);
        assert_eq!(g.speed_m_s, 0.2);
        assert_eq!(g.waypoints.len(), 2);
        assert_eq!(g.waypoints[1].heading_rad, Some(1.5));
        assert_eq!(g.leg_speed_m_s(0), 0.2);
        assert_eq!(g.leg_speed_m_s(1), 0.1);
    }

    #[test]
    fn bad_mission_files_name_the_line_or_the_field() {
        for (text, says) in [
            ("[[waypoints]]\nx_m = 1\n", "y_m"),
            ("[[waypoints]]\nx_m = 1\ny_m = 2\nz_m = 3\n", "line 4"),
            ("[[waypoints]]\nx_m = \"one\"\ny_m = 2\n", "line 2"),
            (
                "speed_m_s = 0\n[[waypoints]]\nx_m = 1\ny_m = 2\n",
                "speed_m_s",
            ),
            (
                "clearance_m = -1\n[[waypoints]]\nx_m = 1\ny_m = 2\n",
                "clearance_m",
            ),
            ("", "no `[[waypoints]]`"),
            (
                "[[areas]]\npolygon = [[0, 0], [1, 0]]\n",
                "areas[0].polygon",
            ),
            (
                "[[areas]]\npolygon = [[0, 0], [1, 0], [1, 1]]\noverlap = 1.5\n",
                "areas[0].overlap",
            ),
            (
                "[[waypoints]]\nx_m = 1\ny_m = 2\n[[waypoints]]\nx_m = 1\ny_m = 2\ndwell_s = -1\n",
                "waypoints[1].dwell_s",
            ),
            (
                "[[waypoints]]\nx_m = 1\ny_m = 2\nspeed_m_s = -0.1\n",
                "waypoints[0].speed_m_s",
            ),
            ("[[waypoints]]\nx_m = nan\ny_m = 2\n", "waypoints[0].x_m"),
            (
                "[[waypoints]]\nx_m = 1\ny_m = 2\nheading_rad = 90\n",
                "waypoints[0].heading_rad`: expected an angle in radians within ±2π",
            ),
            (
                "[[waypoints]]\nx_m = 1\ny_m = 2\nheading_rad = -7\n",
                "waypoints[0].heading_rad",
            ),
            (
                "return_home = 1\n[[waypoints]]\nx_m = 1\ny_m = 2\n",
                "line 1",
            ),
        ] {
            let e = Goals::parse(text).unwrap_err();
            assert!(e.contains(says), "{text:?}: {e}");
        }
    }
}
