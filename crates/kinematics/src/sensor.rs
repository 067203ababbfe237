//! The robot's range sensors as mounted: what a log header and a plan say
//! of them.

use serde::{Deserialize, Serialize};

use crate::Pose;

/// What a range sensor is. The simulator, the agent, the logs and ROS ask
/// this, never the beam count: the localizer, the map builders and the
/// hand-back rules treat the two differently.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SensorKind {
    /// One beam along the mount's heading: an infrared, ultrasonic or
    /// time-of-flight ranger, such as the paper's side IR sensors (ROS
    /// `sensor_msgs/msg/Range`). It sees only what its beam crosses: a
    /// robot with rangers alone cannot look ahead along its path, and one
    /// reading says little of where it is.
    Ranger,
    /// A scanning 2D lidar: a fan of beams in one sweep (ROS
    /// `sensor_msgs/msg/LaserScan`), matched scan by scan, and enough to
    /// map with.
    Lidar,
}

impl SensorKind {
    /// The kind of a sensor described before sensors said what they are
    /// (logs, plans and sites written before `kind` existed): one beam is a
    /// ranger, a fan a lidar. Nothing else infers the kind.
    pub fn of_unlabelled(beams: u32) -> Self {
        if beams == 1 {
            Self::Ranger
        } else {
            Self::Lidar
        }
    }

    /// The name a site file, a log and `--help` use.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Ranger => "ranger",
            Self::Lidar => "lidar",
        }
    }

    /// Why `beams` beams do not make a sensor of this kind, if they do not.
    pub fn check_beams(self, beams: u32) -> Result<(), String> {
        match self {
            Self::Ranger if beams != 1 => Err(format!(
                "a ranger has one beam, got {beams} (a fan of beams is kind = \"lidar\")"
            )),
            Self::Lidar if beams < 2 => Err(format!(
                "a lidar sweeps a fan of at least 2 beams, got {beams} (one beam is kind = \"ranger\")"
            )),
            _ => Ok(()),
        }
    }
}

impl std::fmt::Display for SensorKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Fewest beams a lidar needs to be matched scan to scan, or to map and
/// plan with.
pub const MIN_SCAN_BEAMS: u32 = 30;

/// A range sensor as mounted on the robot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "LabelledOrNot")]
pub struct RangeSensorInfo {
    pub name: String,
    pub kind: SensorKind,
    /// Mount pose in the robot body frame.
    pub mount: Pose,
    pub beams: u32,
    /// Angular field of view spanned by the beams (ignored for one beam).
    pub fov_rad: f64,
    pub min_range_m: f64,
    pub max_range_m: f64,
}

/// A sensor as written, with or without its kind (older files have none).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LabelledOrNot {
    name: String,
    kind: Option<SensorKind>,
    mount: Pose,
    beams: u32,
    fov_rad: f64,
    min_range_m: f64,
    max_range_m: f64,
}

impl TryFrom<LabelledOrNot> for RangeSensorInfo {
    type Error = String;

    fn try_from(s: LabelledOrNot) -> Result<Self, String> {
        let name = s.name.clone();
        Self::labelled_or_not(
            s.name,
            s.kind,
            s.mount,
            s.beams,
            s.fov_rad,
            [s.min_range_m, s.max_range_m],
        )
        .map_err(|e| format!("range sensor `{name}`: {e}"))
    }
}

impl RangeSensorInfo {
    /// A sensor as a file describes it: its `kind` if the file says it,
    /// else [`SensorKind::of_unlabelled`]; an error (without the sensor's
    /// name) when the beams contradict the kind.
    pub fn labelled_or_not(
        name: String,
        kind: Option<SensorKind>,
        mount: Pose,
        beams: u32,
        fov_rad: f64,
        [min_range_m, max_range_m]: [f64; 2],
    ) -> Result<Self, String> {
        let labelled = kind.is_some();
        let kind = kind.unwrap_or(SensorKind::of_unlabelled(beams));
        kind.check_beams(beams).map_err(|e| {
            if labelled {
                format!("is \"{kind}\": {e}")
            } else {
                format!("has no `kind` and {beams} beams: {e}")
            }
        })?;
        Ok(Self {
            name,
            kind,
            mount,
            beams,
            fov_rad,
            min_range_m,
            max_range_m,
        })
    }

    /// Whether this is a lidar with enough beams ([`MIN_SCAN_BEAMS`]) to
    /// be matched scan to scan, mapped and planned with.
    pub fn is_scanning_lidar(&self) -> bool {
        self.kind == SensorKind::Lidar && self.beams >= MIN_SCAN_BEAMS
    }

    /// Beam angle relative to the mount heading. A full circle spreads the
    /// beams over [-π, π); a narrower field spans [-fov/2, fov/2] inclusive.
    pub fn beam_angle_rad(&self, beam: u32) -> f64 {
        let (start, step) = self.angle_min_and_increment();
        start + step * f64::from(beam)
    }

    /// `(angle_min, angle_increment)` as in a ROS `LaserScan`.
    pub fn angle_min_and_increment(&self) -> (f64, f64) {
        use std::f64::consts::{PI, TAU};
        if self.beams <= 1 {
            (0.0, 0.0)
        } else if self.fov_rad >= TAU - 1e-9 {
            (-PI, TAU / f64::from(self.beams))
        } else {
            (
                -0.5 * self.fov_rad,
                self.fov_rad / f64::from(self.beams - 1),
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn json(kind: Option<&str>, beams: u32) -> String {
        let kind = kind.map_or(String::new(), |k| format!(r#""kind":"{k}","#));
        format!(
            r#"{{"name":"s",{kind}"mount":{{"x_m":0.1,"y_m":0.0,"heading_rad":0.0}},"beams":{beams},"fov_rad":1.0,"min_range_m":0.0,"max_range_m":4.0}}"#
        )
    }

    #[test]
    fn a_sensor_written_without_its_kind_reads_as_a_ranger_for_one_beam_and_a_lidar_for_a_fan() {
        for (beams, kind) in [
            (1, SensorKind::Ranger),
            (2, SensorKind::Lidar),
            (8, SensorKind::Lidar),
            (360, SensorKind::Lidar),
        ] {
            let s: RangeSensorInfo = serde_json::from_str(&json(None, beams)).unwrap();
            assert_eq!(s.kind, kind, "{beams} beams");
        }
    }

    #[test]
    fn the_kind_is_written_and_read_back() {
        for (beams, kind) in [(1, "ranger"), (5, "lidar"), (720, "lidar")] {
            let s: RangeSensorInfo = serde_json::from_str(&json(Some(kind), beams)).unwrap();
            assert_eq!(s.kind.as_str(), kind);
            let text = serde_json::to_string(&s).unwrap();
            assert!(text.contains(&format!(r#""kind":"{kind}""#)), "{text}");
            let back: RangeSensorInfo = serde_json::from_str(&text).unwrap();
            assert_eq!(back, s);
        }
    }

    #[test]
    fn a_kind_its_beams_contradict_and_an_unknown_field_are_refused_by_name() {
        let e = serde_json::from_str::<RangeSensorInfo>(&json(Some("ranger"), 360))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("range sensor `s`") && e.contains("a ranger has one beam, got 360"),
            "{e}"
        );
        let e = serde_json::from_str::<RangeSensorInfo>(&json(Some("lidar"), 1))
            .unwrap_err()
            .to_string();
        assert!(e.contains("at least 2 beams, got 1"), "{e}");
        let e = serde_json::from_str::<RangeSensorInfo>(&json(Some("sonar"), 1))
            .unwrap_err()
            .to_string();
        assert!(e.contains("sonar"), "{e}");
        let e = serde_json::from_str::<RangeSensorInfo>(&json(None, 0))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("has no `kind` and 0 beams") && !e.contains(r#"is "lidar""#),
            "{e}"
        );
        let extra = json(None, 1).replace(r#""beams""#, r#""colour":1,"beams""#);
        let e = serde_json::from_str::<RangeSensorInfo>(&extra)
            .unwrap_err()
            .to_string();
        assert!(e.contains("colour"), "{e}");
    }
}
