//! The mission plan: what is uploaded to the real robot. Data only (like
//! `geo-types` beside `geo`): the document, its hash and its checks, for
//! the protocol and the robot, with no simulator or pipeline behind it;
//! `twindrive-mission` makes plans and adds what needs the simulator (the
//! range model, the map as a world).
//!
//! A versioned JSON document: a header (robot, calibrated parameters,
//! limits, time step, the site's map, pipeline settings, the SHA-256 of the
//! source log, the pipeline's summary) and one sample per plan step: time,
//! pose, body velocities, each wheel's angular speed, and whether the twin's
//! bumper touched there. The robot predicts its range readings itself from
//! the map (`twindrive_mission::plan::PlanGeometry::range_model`: the same
//! code and the same walls as the twin, so the same bits), localizes against it, and can tell when
//! the world departs from it. `sha256` is the SHA-256 of the plan's canonical content: the
//! document itself serialised compactly with the `sha256` field empty, as
//! serde_json writes it (fields in their declared order, object keys of the
//! free-form settings sorted, floats in their shortest round-trip form as
//! `ryu` prints them). A reader in another language must print numbers the
//! same way to reproduce the bytes; twindrive re-reads and re-hashes.
//!
//! A CSV export carries the samples for other tools.

use std::io::Write;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use twindrive_kinematics::{DiffDriveParams, Pose};
pub use twindrive_kinematics::{RangeSensorInfo, SensorKind};

mod freedom;
pub mod goals;
pub use freedom::{CorridorStretch, Freedom, KeepOutZone, check_polygon};
pub use goals::{GoalArea, GoalWaypoint, PlanGoals};

/// A plan that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    #[error("{what} at sample {index} is not a finite number")]
    NonFinite { what: &'static str, index: usize },
    #[error("sample {index}: time {t_s} s does not increase (previous {previous_s} s)")]
    TimeNotIncreasing {
        index: usize,
        t_s: f64,
        previous_s: f64,
    },
    #[error("{field} must be a finite number > 0, got {value}")]
    BadSetting { field: &'static str, value: f64 },
    #[error("{0}")]
    Invalid(String),
}

/// Wheel limits of the robot.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WheelLimits {
    pub max_speed_rad_s: f64,
    pub max_accel_rad_s2: f64,
}

impl WheelLimits {
    pub fn validate(&self) -> Result<(), PlanError> {
        for (field, value) in [
            ("max_wheel_speed_rad_s", self.max_speed_rad_s),
            ("max_wheel_accel_rad_s2", self.max_accel_rad_s2),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(PlanError::BadSetting { field, value });
            }
        }
        Ok(())
    }

    /// These limits scaled by `factor` (a planning margin).
    pub fn scaled(&self, factor: f64) -> WheelLimits {
        WheelLimits {
            max_speed_rad_s: self.max_speed_rad_s * factor,
            max_accel_rad_s2: self.max_accel_rad_s2 * factor,
        }
    }
}

/// Identifies a plan document.
pub const PLAN_FORMAT: &str = "twindrive-mission-plan";
/// Bumped whenever the meaning of a field changes (3: each range sensor
/// says its kind, which the plan's hash covers, so a version-2 plan is
/// refused by version rather than read as damaged; the header carries the
/// robot's [`Freedom`]; 4: the header carries the operator's [`PlanGoals`]).
pub const PLAN_VERSION: u32 = 4;

/// The robot the plan is for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotInfo {
    /// The scenario (twin) the mission was rehearsed in.
    pub scenario: String,
    pub footprint_radius_m: f64,
    pub ticks_per_rev: u32,
    /// The robot's range sensors, in the order its readings come.
    pub range_sensors: Vec<RangeSensorInfo>,
}

/// Everything a reader needs besides the samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanHeader {
    pub robot: RobotInfo,
    pub calibrated: DiffDriveParams,
    pub limits: WheelLimits,
    /// The control period the plan was made at (the source log's encoder
    /// period); sample times may be further apart where the plan slows down.
    pub time_step_s: f64,
    pub start: Pose,
    /// The covariance of `start` (x, y, heading; row-major 3 x 3) when the
    /// twin refined where the robot stands against its map (a
    /// continuation): a robot that stands at `start` takes it, with this,
    /// as its estimate, since it already holds the robot's own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_covariance: Option<[f64; 9]>,
    /// The site as the twin knows it: what the robot localizes against and
    /// predicts its readings from.
    pub site_map: SiteMap,
    /// Where the robot may go on its own (its corridor), where never
    /// (keep-out zones), and how much a detour may cost; see [`Freedom`].
    pub freedom: Freedom,
    /// The operator's goals the plan keeps (a plan from a rehearsal from
    /// goals; empty for a manual one).
    #[serde(default, skip_serializing_if = "PlanGoals::is_empty")]
    pub goals: PlanGoals,
    /// SHA-256 (hex) of the source log files.
    pub source_log_sha256: String,
    /// The pipeline's settings, as given.
    pub settings: serde_json::Value,
    /// What the pipeline did (deletions, durations), for people.
    pub summary: serde_json::Value,
}

/// The site's map in a plan: the twin's walls (two-sided segments, metres,
/// `[x0, y0, x1, y1]`) in the twin's order, and its solid blocks
/// (`[min_x, min_y, max_x, max_y]`; their outlines are among the walls).
/// A map_server map travels as the boundary segments of its occupied cells,
/// merged into straight runs: the office map is 36 segments.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SiteMap {
    pub segments: Vec<[f64; 4]>,
    pub boxes: Vec<[f64; 4]>,
}

impl SiteMap {
    /// The map's walls without its blocks' outlines. Blocks are what the
    /// twin learnt from the robot, their extent partly a guess; what stands
    /// behind one is among these.
    pub fn walls_without_boxes(&self) -> Vec<[f64; 4]> {
        let on_outline = |w: &[f64; 4]| {
            self.boxes.iter().any(|b| {
                let along_x = w[1] == w[3]
                    && (w[1] == b[1] || w[1] == b[3])
                    && w[0].min(w[2]) >= b[0]
                    && w[0].max(w[2]) <= b[2];
                let along_y = w[0] == w[2]
                    && (w[0] == b[0] || w[0] == b[2])
                    && w[1].min(w[3]) >= b[1]
                    && w[1].max(w[3]) <= b[3];
                along_x || along_y
            })
        };
        self.segments
            .iter()
            .filter(|w| !on_outline(w))
            .copied()
            .collect()
    }

    fn validate(&self) -> Result<(), PlanError> {
        for (what, rows) in [
            ("header.site_map.segments", &self.segments),
            ("header.site_map.boxes", &self.boxes),
        ] {
            if let Some(index) = rows.iter().position(|r| r.iter().any(|v| !v.is_finite())) {
                return Err(PlanError::NonFinite { what, index });
            }
        }
        if let Some(index) = self
            .boxes
            .iter()
            .position(|b| !(b[0] <= b[2] && b[1] <= b[3]))
        {
            return Err(PlanError::Invalid(format!(
                "header.site_map.boxes[{index}]: min must not exceed max, got {:?}",
                self.boxes[index]
            )));
        }
        Ok(())
    }
}

/// One step of the plan: hold the wheel speeds from `t_s` to the next sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanSample {
    pub t_s: f64,
    pub x_m: f64,
    pub y_m: f64,
    pub heading_rad: f64,
    pub v_m_s: f64,
    pub omega_rad_s: f64,
    pub left_rad_s: f64,
    pub right_rad_s: f64,
    /// The twin's bumper touches a wall here (the plan drives into contact
    /// on purpose, as the wall follower does).
    pub expected_bump: bool,
}

impl PlanSample {
    pub fn pose(&self) -> Pose {
        Pose::new(self.x_m, self.y_m, self.heading_rad)
    }
}

/// The plan document.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MissionPlan {
    pub format: String,
    pub version: u32,
    pub header: PlanHeader,
    pub samples: Vec<PlanSample>,
    /// SHA-256 (hex) of the canonical content; see the module docs.
    pub sha256: String,
}

/// Bytes in lower-case hex.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// SHA-256 of some bytes, in hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

impl MissionPlan {
    /// `sha256` as bytes (`None` if it is not 64 hex digits).
    pub fn sha256_bytes(&self) -> Option<[u8; 32]> {
        let text = self.sha256.as_bytes();
        if text.len() != 64 {
            return None;
        }
        let mut out = [0u8; 32];
        for (k, pair) in text.chunks(2).enumerate() {
            let pair = std::str::from_utf8(pair).ok()?;
            out[k] = u8::from_str_radix(pair, 16).ok()?;
        }
        Some(out)
    }

    /// A plan with its hash filled in.
    pub fn new(header: PlanHeader, samples: Vec<PlanSample>) -> Self {
        let mut plan = Self {
            format: PLAN_FORMAT.into(),
            version: PLAN_VERSION,
            header,
            samples,
            sha256: String::new(),
        };
        plan.sha256 = plan.content_hash();
        plan
    }

    /// This plan starting from a pose known to `covariance` (its hash
    /// renewed).
    pub fn with_start_covariance(mut self, covariance: [f64; 9]) -> Self {
        self.header.start_covariance = Some(covariance);
        self.sha256 = self.content_hash();
        self
    }

    /// The SHA-256 of the canonical content (this plan with `sha256` empty).
    pub fn content_hash(&self) -> String {
        let mut hasher = Sha256::new();
        let canonical = MissionPlan {
            sha256: String::new(),
            ..self.clone()
        };
        serde_json::to_writer(HashWriter(&mut hasher), &canonical)
            .expect("a plan of finite numbers serialises");
        hex(&hasher.finalize())
    }

    /// Checks format, version, hash and contents.
    pub fn validate(&self) -> Result<(), PlanError> {
        if self.format != PLAN_FORMAT || self.version != PLAN_VERSION {
            return Err(PlanError::Invalid(format!(
                "is `{}` version {}, expected `{PLAN_FORMAT}` version {PLAN_VERSION}",
                self.format, self.version
            )));
        }
        let h = &self.header;
        h.calibrated
            .validate()
            .map_err(|e| PlanError::Invalid(format!("header.calibrated: {e}")))?;
        h.limits.validate()?;
        if !(h.time_step_s.is_finite() && h.time_step_s > 0.0) {
            return Err(PlanError::BadSetting {
                field: "header.time_step_s",
                value: h.time_step_s,
            });
        }
        if ![h.start.x_m, h.start.y_m, h.start.heading_rad]
            .iter()
            .all(|v| v.is_finite())
        {
            return Err(PlanError::NonFinite {
                what: "header.start",
                index: 0,
            });
        }
        if let Some(c) = &h.start_covariance {
            // Finite, symmetric, with a positive variance on the diagonal
            // and correlations within one.
            let fine = c.iter().all(|v| v.is_finite())
                && (0..3).all(|i| c[4 * i] > 0.0)
                && (0..3).all(|i| {
                    (0..3).all(|j| {
                        let (a, b) = (c[3 * i + j], c[3 * j + i]);
                        (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-12)
                            && a * a <= c[4 * i] * c[4 * j] * (1.0 + 1e-9)
                    })
                });
            if !fine {
                return Err(PlanError::Invalid(format!(
                    "header.start_covariance: expected a 3 x 3 covariance (finite, symmetric, positive variances), got {c:?}"
                )));
            }
        }
        h.site_map.validate()?;
        h.freedom.validate(h.robot.footprint_radius_m)?;
        let mut previous = f64::NEG_INFINITY;
        for (index, s) in self.samples.iter().enumerate() {
            let numbers = [
                ("t_s", s.t_s),
                ("x_m", s.x_m),
                ("y_m", s.y_m),
                ("heading_rad", s.heading_rad),
                ("v_m_s", s.v_m_s),
                ("omega_rad_s", s.omega_rad_s),
                ("left_rad_s", s.left_rad_s),
                ("right_rad_s", s.right_rad_s),
            ];
            if let Some((what, _)) = numbers.iter().find(|(_, v)| !v.is_finite()) {
                return Err(PlanError::NonFinite { what, index });
            }
            if s.t_s <= previous {
                return Err(PlanError::TimeNotIncreasing {
                    index,
                    t_s: s.t_s,
                    previous_s: previous,
                });
            }
            previous = s.t_s;
        }
        let actual = self.content_hash();
        if actual != self.sha256 {
            return Err(PlanError::Invalid(format!(
                "the plan's content does not match its sha256 (recorded {}, content {actual}): it was changed or damaged",
                self.sha256
            )));
        }
        Ok(())
    }

    /// Mission duration (first to last sample).
    pub fn duration_s(&self) -> f64 {
        match (self.samples.first(), self.samples.last()) {
            (Some(a), Some(b)) => b.t_s - a.t_s,
            _ => 0.0,
        }
    }

    /// `t,x,y,theta,v,omega,left_rad_s,right_rad_s` rows.
    pub fn write_csv(&self, mut out: impl Write) -> std::io::Result<()> {
        let mut buf = ryu::Buffer::new();
        writeln!(out, "t,x,y,theta,v,omega,left_rad_s,right_rad_s")?;
        for s in &self.samples {
            let row = [
                s.t_s,
                s.x_m,
                s.y_m,
                s.heading_rad,
                s.v_m_s,
                s.omega_rad_s,
                s.left_rad_s,
                s.right_rad_s,
            ];
            for (k, v) in row.iter().enumerate() {
                if k > 0 {
                    out.write_all(b",")?;
                }
                out.write_all(buf.format(*v).as_bytes())?;
            }
            out.write_all(b"\n")?;
        }
        out.flush()
    }
}

/// Feeds serialised bytes straight into the hasher.
struct HashWriter<'a>(&'a mut Sha256);

impl Write for HashWriter<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.update(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan() -> MissionPlan {
        let header = PlanHeader {
            robot: RobotInfo {
                scenario: "unit".into(),
                footprint_radius_m: 0.15,
                ticks_per_rev: 512,
                range_sensors: vec![RangeSensorInfo {
                    name: "side_ir".into(),
                    kind: SensorKind::Ranger,
                    mount: Pose::new(0.05, -0.12, -1.047),
                    beams: 1,
                    fov_rad: 0.0,
                    min_range_m: 0.1,
                    max_range_m: 0.8,
                }],
            },
            calibrated: DiffDriveParams::new(0.0652, 0.0665, 0.2678),
            limits: WheelLimits {
                max_speed_rad_s: 12.0,
                max_accel_rad_s2: 30.0,
            },
            time_step_s: 0.01,
            start: Pose::new(3.0, 1.05, std::f64::consts::PI),
            start_covariance: None,
            site_map: SiteMap {
                segments: vec![[0.0, 0.0, 6.0, 0.0], [1.5, 1.5, 4.5, 1.5]],
                boxes: vec![],
            },
            freedom: Freedom {
                corridor: vec![CorridorStretch {
                    from_m: 0.0,
                    half_width_m: 0.5,
                }],
                keep_out: vec![KeepOutZone {
                    name: "rock".into(),
                    polygon: vec![[5.0, 5.0], [6.0, 5.0], [5.5, 6.0]],
                }],
                max_extra_time_s: 20.0,
                max_extra_distance_m: 3.0,
            },
            goals: Default::default(),
            source_log_sha256: sha256_hex(b"log"),
            settings: serde_json::json!({ "pinch_distance_m": 0.1 }),
            summary: serde_json::json!({ "loops_removed": 2 }),
        };
        let samples = (0..50)
            .map(|k| PlanSample {
                t_s: k as f64 * 0.01,
                x_m: 3.0 - 0.002 * k as f64,
                y_m: 1.05,
                heading_rad: std::f64::consts::PI,
                v_m_s: 0.2,
                omega_rad_s: 0.0,
                left_rad_s: 6.13,
                right_rad_s: 6.01,
                expected_bump: false,
            })
            .collect();
        MissionPlan::new(header, samples)
    }

    #[test]
    fn the_hash_is_stable_and_survives_a_json_round_trip() {
        let a = plan();
        assert_eq!(a.sha256, plan().sha256, "same content, same hash");
        assert_eq!(a.sha256.len(), 64);
        let text = serde_json::to_string_pretty(&a).unwrap();
        let b: MissionPlan = serde_json::from_str(&text).unwrap();
        assert_eq!(b, a);
        b.validate().unwrap();
    }

    #[test]
    fn changing_any_sample_changes_the_hash() {
        let a = plan();
        for k in [0, 17, 49] {
            for field in 0..4 {
                let mut b = a.clone();
                let s = &mut b.samples[k];
                match field {
                    0 => s.x_m = f64::from_bits(s.x_m.to_bits() + 1),
                    1 => s.left_rad_s += 1e-9,
                    2 => s.heading_rad += 1e-6,
                    _ => s.expected_bump = !s.expected_bump,
                }
                assert_ne!(b.content_hash(), a.sha256, "sample {k} field {field}");
                assert!(b.validate().is_err(), "a changed plan fails validation");
            }
        }
    }

    #[test]
    fn a_start_covariance_is_carried_hashed_and_checked() {
        let a = plan();
        let json = serde_json::to_string(&a).unwrap();
        assert!(!json.contains("start_covariance"), "absent when unknown");
        let c = [4e-4, 1e-5, 0.0, 1e-5, 9e-4, 2e-5, 0.0, 2e-5, 1e-4];
        let b = a.clone().with_start_covariance(c);
        assert_ne!(a.sha256, b.sha256);
        assert_eq!(b.sha256, b.content_hash());
        b.validate().unwrap();
        let back: MissionPlan = serde_json::from_str(&serde_json::to_string(&b).unwrap()).unwrap();
        assert_eq!(back, b);
        for bad in [
            [-4e-4, 0.0, 0.0, 0.0, 9e-4, 0.0, 0.0, 0.0, 1e-4],
            [4e-4, 1e-5, 0.0, 0.0, 9e-4, 0.0, 0.0, 0.0, 1e-4],
            [4e-4, 0.0, 0.0, 0.0, 9e-4, 0.0, 0.0, 0.0, f64::NAN],
            [1e-4, 1e-3, 0.0, 1e-3, 1e-4, 0.0, 0.0, 0.0, 1e-4],
        ] {
            let err = a.clone().with_start_covariance(bad).validate().unwrap_err();
            assert!(err.to_string().contains("header.start_covariance"), "{err}");
        }
    }

    #[test]
    fn a_plan_of_an_older_version_is_refused_by_its_version_not_as_damaged() {
        let mut old = plan();
        old.version = 2;
        old.sha256 = old.content_hash();
        let err = old.validate().unwrap_err().to_string();
        assert!(
            err.contains(&format!(
                "version 2, expected `twindrive-mission-plan` version {PLAN_VERSION}"
            )),
            "{err}"
        );
    }

    #[test]
    fn bad_samples_are_named() {
        let mut b = plan();
        b.samples[3].v_m_s = f64::NAN;
        assert_eq!(
            b.validate(),
            Err(PlanError::NonFinite {
                what: "v_m_s",
                index: 3
            })
        );
        let mut d = plan();
        d.header.calibrated.wheelbase_m = -0.2;
        d.sha256 = d.content_hash();
        assert!(
            d.validate()
                .unwrap_err()
                .to_string()
                .contains("header.calibrated")
        );
        let mut m = plan();
        m.header.site_map.segments[1][2] = f64::INFINITY;
        m.sha256 = m.content_hash();
        assert_eq!(
            m.validate(),
            Err(PlanError::NonFinite {
                what: "header.site_map.segments",
                index: 1
            })
        );
        let mut f = plan();
        f.header.freedom.keep_out[0].polygon.pop();
        f.sha256 = f.content_hash();
        assert!(
            f.validate()
                .unwrap_err()
                .to_string()
                .contains("header.freedom.keep_out[0].polygon"),
        );
        let mut z = plan();
        z.header.freedom.keep_out[0].polygon[0][1] += 1e-9;
        assert!(z.validate().is_err(), "the zones are hashed");
        let mut c = plan();
        c.samples[5].t_s = c.samples[4].t_s;
        c.sha256 = c.content_hash();
        assert!(matches!(
            c.validate(),
            Err(PlanError::TimeNotIncreasing { index: 5, .. })
        ));
    }
}
