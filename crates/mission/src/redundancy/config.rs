//! The user's definition of redundancy (TOML or flags).

use serde::{Deserialize, Serialize};

use super::RedundancyError;

/// `min_loop_length_m` when not given, in pinch distances.
pub const DEFAULT_LOOP_LENGTH_IN_PINCH_DISTANCES: f64 = 3.0;

/// What counts as redundant. A TOML file with only `pinch_distance_m = 0.1`
/// is complete.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RedundancyConfig {
    /// Samples closer than this (strictly) pinch the path.
    pub pinch_distance_m: f64,
    /// Shortest path between the two samples of a pinch; `None`:
    /// [`DEFAULT_LOOP_LENGTH_IN_PINCH_DISTANCES`] pinch distances.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_loop_length_m: Option<f64>,
    /// Shortest time between the two samples of a pinch.
    #[serde(default)]
    pub min_loop_duration_s: f64,
    /// Whether "bump and back up" kinks are cut; when not, reversing samples
    /// are protected.
    #[serde(default = "yes")]
    pub reversing_is_redundant: bool,
    /// Places worth looking at twice: samples inside are never deleted.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub keep_regions: Vec<KeepRegion>,
    /// Times worth keeping: samples inside are never deleted.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub keep_windows: Vec<TimeWindow>,
    /// A deleted sample must stay within this distance of the path that
    /// remains (the route's coverage); `None`: the pinch distance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage_radius_m: Option<f64>,
    /// Whether the plan also reaches the mission's final pose (along the
    /// recorded route); by default it ends where the last new ground was
    /// covered.
    #[serde(default)]
    pub keep_end: bool,
}

fn yes() -> bool {
    true
}

/// A closed region of the plane (`kind = "circle"` or `kind = "rectangle"`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum KeepRegion {
    Circle {
        x_m: f64,
        y_m: f64,
        radius_m: f64,
    },
    Rectangle {
        min_x_m: f64,
        min_y_m: f64,
        max_x_m: f64,
        max_y_m: f64,
    },
}

/// A closed time interval, in the path's clock.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeWindow {
    pub start_s: f64,
    pub end_s: f64,
}

impl RedundancyConfig {
    /// Defaults for everything but the pinch distance.
    pub fn with_pinch_distance(pinch_distance_m: f64) -> Self {
        Self {
            pinch_distance_m,
            min_loop_length_m: None,
            min_loop_duration_s: 0.0,
            reversing_is_redundant: true,
            keep_regions: Vec::new(),
            keep_windows: Vec::new(),
            coverage_radius_m: None,
            keep_end: false,
        }
    }

    /// `coverage_radius_m`, or its default (the pinch distance).
    pub fn effective_coverage_radius_m(&self) -> f64 {
        self.coverage_radius_m.unwrap_or(self.pinch_distance_m)
    }

    /// `min_loop_length_m`, or its default.
    pub fn effective_min_loop_length_m(&self) -> f64 {
        self.min_loop_length_m
            .unwrap_or(DEFAULT_LOOP_LENGTH_IN_PINCH_DISTANCES * self.pinch_distance_m)
    }

    /// Checks every value; the error names the first bad field.
    pub fn validate(&self) -> Result<(), RedundancyError> {
        positive("pinch_distance_m", self.pinch_distance_m)?;
        if let Some(l) = self.min_loop_length_m {
            non_negative("min_loop_length_m", l)?;
        }
        non_negative("min_loop_duration_s", self.min_loop_duration_s)?;
        if let Some(r) = self.coverage_radius_m {
            positive("coverage_radius_m", r)?;
        }
        for (k, region) in self.keep_regions.iter().enumerate() {
            region.validate(&format!("keep_regions[{k}]"))?;
        }
        for (k, window) in self.keep_windows.iter().enumerate() {
            window.validate(&format!("keep_windows[{k}]"))?;
        }
        Ok(())
    }

    /// Whether a sample at this place and time must survive.
    pub fn keeps(&self, position: [f64; 2], t_s: f64) -> bool {
        self.keep_regions.iter().any(|r| r.contains(position))
            || self.keep_windows.iter().any(|w| w.contains(t_s))
    }
}

impl KeepRegion {
    /// Whether the point lies inside or on the boundary.
    pub fn contains(&self, [x, y]: [f64; 2]) -> bool {
        match *self {
            KeepRegion::Circle { x_m, y_m, radius_m } => {
                let (dx, dy) = (x - x_m, y - y_m);
                dx * dx + dy * dy <= radius_m * radius_m
            }
            KeepRegion::Rectangle {
                min_x_m,
                min_y_m,
                max_x_m,
                max_y_m,
            } => (min_x_m..=max_x_m).contains(&x) && (min_y_m..=max_y_m).contains(&y),
        }
    }

    fn validate(&self, name: &str) -> Result<(), RedundancyError> {
        match *self {
            KeepRegion::Circle { x_m, y_m, radius_m } => {
                finite(&format!("{name}.x_m"), x_m)?;
                finite(&format!("{name}.y_m"), y_m)?;
                positive(&format!("{name}.radius_m"), radius_m)
            }
            KeepRegion::Rectangle {
                min_x_m,
                min_y_m,
                max_x_m,
                max_y_m,
            } => {
                for (field, v) in [
                    ("min_x_m", min_x_m),
                    ("min_y_m", min_y_m),
                    ("max_x_m", max_x_m),
                    ("max_y_m", max_y_m),
                ] {
                    finite(&format!("{name}.{field}"), v)?;
                }
                if max_x_m <= min_x_m || max_y_m <= min_y_m {
                    return Err(RedundancyError::Config {
                        field: name.to_owned(),
                        requirement: "must have max_x_m > min_x_m and max_y_m > min_y_m",
                        got: format!("x {min_x_m}..{max_x_m}, y {min_y_m}..{max_y_m}"),
                    });
                }
                Ok(())
            }
        }
    }
}

impl TimeWindow {
    /// Whether the time lies inside or on the boundary.
    pub fn contains(&self, t_s: f64) -> bool {
        (self.start_s..=self.end_s).contains(&t_s)
    }

    fn validate(&self, name: &str) -> Result<(), RedundancyError> {
        finite(&format!("{name}.start_s"), self.start_s)?;
        finite(&format!("{name}.end_s"), self.end_s)?;
        if self.end_s <= self.start_s {
            return Err(RedundancyError::Config {
                field: name.to_owned(),
                requirement: "must have end_s > start_s",
                got: format!("start_s = {}, end_s = {}", self.start_s, self.end_s),
            });
        }
        Ok(())
    }
}

fn bad(field: &str, requirement: &'static str, value: f64) -> RedundancyError {
    RedundancyError::Config {
        field: field.to_owned(),
        requirement,
        got: value.to_string(),
    }
}

fn finite(field: &str, value: f64) -> Result<(), RedundancyError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(bad(field, "must be finite", value))
    }
}

fn positive(field: &str, value: f64) -> Result<(), RedundancyError> {
    if value.is_nan() || value <= 0.0 {
        return Err(bad(field, "must be > 0", value));
    }
    finite(field, value)
}

fn non_negative(field: &str, value: f64) -> Result<(), RedundancyError> {
    if value.is_nan() || value < 0.0 {
        return Err(bad(field, "must be >= 0", value));
    }
    finite(field, value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimal_json_gets_defaults() {
        let cfg: RedundancyConfig = serde_json::from_str(r#"{"pinch_distance_m": 0.1}"#).unwrap();
        assert_eq!(cfg, RedundancyConfig::with_pinch_distance(0.1));
        assert!((cfg.effective_min_loop_length_m() - 0.3).abs() < 1e-12);
    }

    #[test]
    fn regions_are_tagged_and_strict() {
        let cfg: RedundancyConfig = serde_json::from_str(
            r#"{"pinch_distance_m": 0.1,
                "keep_regions": [{"kind": "circle", "x_m": 1, "y_m": 2, "radius_m": 0.5},
                                 {"kind": "rectangle", "min_x_m": 0, "min_y_m": 0, "max_x_m": 1, "max_y_m": 1}],
                "keep_windows": [{"start_s": 3, "end_s": 4}]}"#,
        )
        .unwrap();
        assert!(cfg.keep_regions[0].contains([1.3, 2.4]));
        assert!(!cfg.keep_regions[0].contains([1.4, 2.4]));
        assert!(cfg.keeps([0.5, 1.0], 0.0));
        assert!(cfg.keeps([9.0, 9.0], 4.0));
        assert!(!cfg.keeps([9.0, 9.0], 4.5));
        let typo = r#"{"pinch_distance_m": 0.1, "keep_regions": [{"kind": "circle", "x_m": 1, "y_m": 2, "r": 0.5}]}"#;
        assert!(serde_json::from_str::<RedundancyConfig>(typo).is_err());
        assert!(serde_json::from_str::<RedundancyConfig>(r#"{"pinch_m": 0.1}"#).is_err());
    }

    #[test]
    fn validation_names_the_field() {
        let msg = |cfg: RedundancyConfig| cfg.validate().unwrap_err().to_string();
        assert_eq!(
            msg(RedundancyConfig::with_pinch_distance(-1.0)),
            "pinch_distance_m must be > 0, got -1"
        );
        assert_eq!(
            msg(RedundancyConfig::with_pinch_distance(f64::INFINITY)),
            "pinch_distance_m must be finite, got inf"
        );
        let mut cfg = RedundancyConfig::with_pinch_distance(0.1);
        cfg.keep_windows.push(TimeWindow {
            start_s: 5.0,
            end_s: 3.0,
        });
        assert_eq!(
            msg(cfg),
            "keep_windows[0] must have end_s > start_s, got start_s = 5, end_s = 3"
        );
        let mut cfg = RedundancyConfig::with_pinch_distance(0.1);
        cfg.coverage_radius_m = Some(0.0);
        assert_eq!(msg(cfg), "coverage_radius_m must be > 0, got 0");
    }
}
