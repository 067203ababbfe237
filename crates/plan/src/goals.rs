//! The operator's goals a plan keeps: the waypoints (with the heading to
//! face and the time to stand there) and areas of the rehearsal from goals
//! the plan was made from, and the check that the plan's own path still
//! meets every waypoint, in order.

use serde::{Deserialize, Serialize};
use twindrive_kinematics::{Pose, wrap_angle};

/// A plan passes within this of each waypoint (m).
pub const GOAL_REACH_M: f64 = 0.05;
/// ... faces each heading within this (rad) ...
pub const GOAL_HEADING_RAD: f64 = 0.05;
/// ... and stands there at least its dwell less this (s).
pub const GOAL_DWELL_SLACK_S: f64 = 0.5;

/// Slower than this (m/s, rad/s) the plan stands.
const STANDING_M_S: f64 = 2e-3;
const STANDING_RAD_S: f64 = 1e-2;

/// The goals a plan keeps.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanGoals {
    /// In the order the plan meets them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub waypoints: Vec<GoalWaypoint>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub areas: Vec<GoalArea>,
    /// The rehearsal ended at its last waypoint, so the plan does too.
    #[serde(default)]
    pub ends_at_last_waypoint: bool,
}

/// A waypoint the plan passes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GoalWaypoint {
    /// `waypoint 2`, `home`.
    pub name: String,
    pub x_m: f64,
    pub y_m: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading_rad: Option<f64>,
    pub dwell_s: f64,
}

/// An area the plan sweeps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GoalArea {
    /// `area 1`.
    pub name: String,
    pub polygon: Vec<[f64; 2]>,
    pub sweep_radius_m: f64,
    /// The share of its free ground the rehearsal swept (%).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub swept_percent: Option<f64>,
}

/// How the plan meets one waypoint.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WaypointMet {
    pub name: String,
    /// The nearest the plan passes (m), after the waypoints before it.
    pub passed_m: f64,
    /// The plan's time there (s from its start).
    pub at_t_s: f64,
    /// How far the plan's heading there is from the one asked for (rad).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heading_error_rad: Option<f64>,
    /// How long it stands there (s), and how long it was to.
    pub stood_s: f64,
    pub dwell_s: f64,
    /// What is wrong, in the operator's words; `None` when it is kept.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub missed: Option<String>,
}

impl PlanGoals {
    pub fn is_empty(&self) -> bool {
        self.waypoints.is_empty() && self.areas.is_empty()
    }

    /// How the path (time s, pose) meets each waypoint in order, and
    /// whether it ends at the last (when it is to): the last entry is the
    /// end's check when `ends_at_last_waypoint`.
    pub fn check_waypoints(&self, path: &[(f64, Pose)]) -> Vec<WaypointMet> {
        let mut out = Vec::with_capacity(self.waypoints.len() + 1);
        let t0 = path.first().map_or(0.0, |p| p.0);
        let mut from = 0;
        for w in &self.waypoints {
            let (met, next) = meet(w, path, from, t0);
            out.push(met);
            from = next;
        }
        if self.ends_at_last_waypoint
            && let (Some(w), Some(&(t, end))) = (self.waypoints.last(), path.last())
        {
            let d = (end.x_m - w.x_m).hypot(end.y_m - w.y_m);
            out.push(WaypointMet {
                name: format!("the end at {}", w.name),
                passed_m: d,
                at_t_s: t - t0,
                heading_error_rad: w
                    .heading_rad
                    .map(|h| wrap_angle(end.heading_rad - h).abs()),
                stood_s: 0.0,
                dwell_s: 0.0,
                missed: (d > GOAL_REACH_M).then(|| {
                    format!(
                        "the plan ends {d:.3} m from {} at ({:.2}, {:.2}), not within {GOAL_REACH_M} m",
                        w.name, w.x_m, w.y_m
                    )
                }),
            });
        }
        out
    }
}

/// The visits of the path to `w` from sample `from`: runs of samples
/// within [`GOAL_REACH_M`]. The first visit that keeps the heading and the
/// dwell meets it; else the best one says what is missing. Returns the
/// check and the sample the next waypoint is looked for from.
fn meet(w: &GoalWaypoint, path: &[(f64, Pose)], from: usize, t0: f64) -> (WaypointMet, usize) {
    let at = |k: usize| {
        let p = &path[k].1;
        (p.x_m - w.x_m).hypot(p.y_m - w.y_m)
    };
    let mut best: Option<(WaypointMet, usize)> = None;
    let mut nearest = (f64::INFINITY, from);
    let mut k = from;
    while k < path.len() {
        let d = at(k);
        if d < nearest.0 {
            nearest = (d, k);
        }
        if d > GOAL_REACH_M {
            k += 1;
            continue;
        }
        // A visit: from k while within reach.
        let start = k;
        while k + 1 < path.len() && at(k + 1) <= GOAL_REACH_M {
            k += 1;
        }
        let end = k;
        let visit = visit(w, path, start, end, t0);
        let kept = visit.missed.is_none();
        let better = best
            .as_ref()
            .is_none_or(|(b, _)| shortfall(&visit, w) < shortfall(b, w));
        if better {
            best = Some((visit, end));
        }
        if kept {
            break;
        }
        k += 1;
    }
    best.unwrap_or_else(|| {
        let (d, k) = nearest;
        let t = path.get(k).map_or(0.0, |p| p.0 - t0);
        let missed = if d.is_finite() {
            format!(
                "{} at ({:.2}, {:.2}): the plan passes {d:.3} m from it at best (at {t:.1} s), not within {GOAL_REACH_M} m",
                w.name, w.x_m, w.y_m
            )
        } else {
            format!(
                "{} at ({:.2}, {:.2}): the plan ends before it",
                w.name, w.x_m, w.y_m
            )
        };
        (
            WaypointMet {
                name: w.name.clone(),
                passed_m: d,
                at_t_s: t,
                heading_error_rad: None,
                stood_s: 0.0,
                dwell_s: w.dwell_s,
                missed: Some(missed),
            },
            from,
        )
    })
}

/// How a visit (samples `start..=end`, all within reach) meets `w`.
fn visit(w: &GoalWaypoint, path: &[(f64, Pose)], start: usize, end: usize, t0: f64) -> WaypointMet {
    let mut closest = (f64::INFINITY, start);
    for (k, (_, p)) in path.iter().enumerate().take(end + 1).skip(start) {
        let d = (p.x_m - w.x_m).hypot(p.y_m - w.y_m);
        if d < closest.0 {
            closest = (d, k);
        }
    }
    // Standing: segments that hardly move. Facing: the heading of the
    // visit nearest the one asked for (the plan turns to it in place,
    // then stands or turns on to its next leg).
    let mut stood_s = 0.0;
    let facing = match w.heading_rad {
        Some(h) => (start..=end)
            .map(|k| path[k].1.heading_rad)
            .min_by(|a, b| wrap_angle(a - h).abs().total_cmp(&wrap_angle(b - h).abs()))
            .unwrap_or(path[closest.1].1.heading_rad),
        None => path[closest.1].1.heading_rad,
    };
    let facing = wrap_angle(facing);
    for k in start..end {
        let (a, b) = (&path[k], &path[k + 1]);
        let dt = b.0 - a.0;
        if dt <= 0.0 {
            continue;
        }
        let moved = (b.1.x_m - a.1.x_m).hypot(b.1.y_m - a.1.y_m) / dt;
        let turned = wrap_angle(b.1.heading_rad - a.1.heading_rad).abs() / dt;
        if moved < STANDING_M_S && turned < STANDING_RAD_S {
            stood_s += dt;
        }
    }
    let heading_error_rad = w.heading_rad.map(|h| wrap_angle(facing - h).abs());
    let mut missed = Vec::new();
    if let Some(e) = heading_error_rad
        && e > GOAL_HEADING_RAD
    {
        missed.push(format!(
            "faces {facing:.3} rad there, {e:.3} rad from the {:.3} rad asked for (within {GOAL_HEADING_RAD} rad)",
            w.heading_rad.unwrap_or_default()
        ));
    }
    if stood_s < w.dwell_s - GOAL_DWELL_SLACK_S {
        missed.push(format!(
            "stands there {stood_s:.1} s of the {:.1} s asked for",
            w.dwell_s
        ));
    }
    WaypointMet {
        name: w.name.clone(),
        passed_m: closest.0,
        at_t_s: path[closest.1].0 - t0,
        heading_error_rad,
        stood_s,
        dwell_s: w.dwell_s,
        missed: (!missed.is_empty()).then(|| {
            format!(
                "{} at ({:.2}, {:.2}): the plan {}",
                w.name,
                w.x_m,
                w.y_m,
                missed.join(" and ")
            )
        }),
    }
}

/// How far a visit is from meeting `w` (for the best of several misses).
fn shortfall(m: &WaypointMet, w: &GoalWaypoint) -> f64 {
    m.heading_error_rad
        .map_or(0.0, |e| (e - GOAL_HEADING_RAD).max(0.0))
        + (w.dwell_s - GOAL_DWELL_SLACK_S - m.stood_s).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight drive along x at 0.2 m/s sampled at 0.01 s, standing
    /// `dwell_s` at `stop_x` (turned to `face`) on the way.
    fn drive(stop_x: f64, dwell_s: f64, face: f64) -> Vec<(f64, Pose)> {
        let mut out = Vec::new();
        let mut t = 0.0;
        let mut x = 0.0;
        while x < stop_x {
            out.push((t, Pose::new(x, 0.0, 0.0)));
            x += 0.002;
            t += 0.01;
        }
        // Turn, then stand.
        let turn_steps = (face.abs() / 0.01).ceil() as usize;
        for k in 0..=turn_steps {
            let h = face * k as f64 / turn_steps.max(1) as f64;
            out.push((t, Pose::new(stop_x, 0.0, h)));
            t += 0.01;
        }
        let stand = (dwell_s / 0.01).round() as usize;
        for _ in 0..stand {
            out.push((t, Pose::new(stop_x, 0.0, face)));
            t += 0.01;
        }
        for k in 1..200 {
            let d = 0.002 * k as f64;
            out.push((t, Pose::new(stop_x + d * face.cos(), d * face.sin(), face)));
            t += 0.01;
        }
        out
    }

    fn waypoint(x: f64, y: f64, heading: Option<f64>, dwell_s: f64) -> GoalWaypoint {
        GoalWaypoint {
            name: "waypoint 1".into(),
            x_m: x,
            y_m: y,
            heading_rad: heading,
            dwell_s,
        }
    }

    #[test]
    fn a_path_that_stops_faces_and_stands_meets_the_waypoint() {
        let path = drive(1.0, 3.0, 0.8);
        let goals = PlanGoals {
            waypoints: vec![waypoint(1.0, 0.01, Some(0.8), 3.0)],
            ..PlanGoals::default()
        };
        let met = goals.check_waypoints(&path);
        assert_eq!(met.len(), 1);
        assert!(met[0].missed.is_none(), "{met:?}");
        assert!(met[0].passed_m <= 0.01 + 1e-9, "{met:?}");
        assert!(met[0].stood_s >= 2.9, "{met:?}");
    }

    #[test]
    fn misses_name_the_waypoint_and_what_is_missing() {
        let path = drive(1.0, 1.0, 0.0);
        let far = PlanGoals {
            waypoints: vec![waypoint(1.0, 0.16, None, 0.0)],
            ..PlanGoals::default()
        };
        let m = &far.check_waypoints(&path)[0];
        let why = m.missed.as_deref().unwrap();
        assert!(
            why.contains("waypoint 1") && why.contains("0.160 m from it"),
            "{why}"
        );
        let short = PlanGoals {
            waypoints: vec![waypoint(1.0, 0.0, Some(1.2), 3.0)],
            ..PlanGoals::default()
        };
        let why = short.check_waypoints(&drive(1.0, 1.0, 0.3))[0]
            .missed
            .clone()
            .unwrap();
        assert!(
            why.contains("rad asked for") && why.contains("of the 3.0 s asked for"),
            "{why}"
        );
    }

    #[test]
    fn waypoints_are_met_in_order_and_the_end_is_checked() {
        // Out to x = 1 and back: a waypoint at the start is met on the way
        // back only when it comes after the far one.
        let mut path = drive(1.0, 0.0, std::f64::consts::PI);
        let t_end = path.last().unwrap().0;
        path.retain(|(_, p)| p.x_m >= 0.0);
        let goals = PlanGoals {
            waypoints: vec![
                GoalWaypoint {
                    name: "waypoint 1".into(),
                    ..waypoint(1.0, 0.0, None, 0.0)
                },
                GoalWaypoint {
                    name: "home".into(),
                    ..waypoint(0.7, 0.0, None, 0.0)
                },
            ],
            areas: Vec::new(),
            ends_at_last_waypoint: true,
        };
        let met = goals.check_waypoints(&path);
        assert_eq!(met.len(), 3, "{met:?}");
        assert!(
            met[0].missed.is_none() && met[1].missed.is_none(),
            "{met:?}"
        );
        assert!(met[1].at_t_s > met[0].at_t_s);
        // The path ends 0.1 m beyond "home".
        let end = met[2].missed.as_deref().unwrap();
        assert!(end.contains("the plan ends 0.09"), "{end} ({t_end})");
    }
}
