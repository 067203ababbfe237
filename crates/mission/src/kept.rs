//! Whether a path keeps the operator's goals: every waypoint met in order,
//! facing its heading and standing its dwell
//! ([`twindrive_plan::goals`]), the end where the rehearsal ended, and
//! every area swept as the rehearsal swept it (on the twin's site).

use serde::Serialize;
use twindrive_kinematics::Pose;
use twindrive_plan::PlanGoals;
pub use twindrive_plan::goals::{GOAL_DWELL_SLACK_S, GOAL_HEADING_RAD, GOAL_REACH_M, WaypointMet};

use crate::coverage::covered_share;
use crate::plan::KeepOutZone;
use crate::route::{RoutePlanner, RouteSettings};

/// A plan sweeps each area at least the rehearsal's share less this
/// (percentage points).
pub const AREA_SLACK_PERCENT: f64 = 2.0;

/// How a path sweeps one area.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AreaMet {
    pub name: String,
    /// The share of the area's free ground the path sweeps (%).
    pub swept_percent: f64,
    /// The share the rehearsal swept (%), when it was measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rehearsed_percent: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub missed: Option<String>,
}

/// How a path keeps the goals.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct GoalsKept {
    pub waypoints: Vec<WaypointMet>,
    pub areas: Vec<AreaMet>,
}

impl GoalsKept {
    /// Every goal missed, in the operator's words.
    pub fn missed(&self) -> Vec<String> {
        self.waypoints
            .iter()
            .filter_map(|w| w.missed.clone())
            .chain(self.areas.iter().filter_map(|a| a.missed.clone()))
            .collect()
    }

    pub fn is_empty(&self) -> bool {
        self.waypoints.is_empty() && self.areas.is_empty()
    }
}

/// How `path` (time s, pose) keeps `goals` on the twin's `world`, for a
/// robot of `footprint_m` kept out of `zones`.
pub fn goals_kept(
    goals: &PlanGoals,
    path: &[(f64, Pose)],
    world: &twindrive_sim::World,
    footprint_m: f64,
    zones: &[KeepOutZone],
) -> GoalsKept {
    let waypoints = goals.check_waypoints(path);
    let areas = if goals.areas.is_empty() {
        Vec::new()
    } else {
        let planner = RoutePlanner::new(world, zones, footprint_m, RouteSettings::default());
        let track: Vec<[f64; 2]> = path.iter().map(|(_, p)| [p.x_m, p.y_m]).collect();
        goals
            .areas
            .iter()
            .map(|a| {
                let swept = planner
                    .as_ref()
                    .map_or(0.0, |pl| covered_share(pl, &a.polygon, &track, a.sweep_radius_m).1);
                let missed = a.swept_percent.and_then(|r| {
                    (swept < r - AREA_SLACK_PERCENT).then(|| {
                        format!(
                            "{}: the plan sweeps {swept:.1} % of its free ground, the rehearsal {r:.1} % (at most {AREA_SLACK_PERCENT} points less)",
                            a.name
                        )
                    })
                });
                AreaMet {
                    name: a.name.clone(),
                    swept_percent: swept,
                    rehearsed_percent: a.swept_percent,
                    missed,
                }
            })
            .collect()
    };
    GoalsKept { waypoints, areas }
}
