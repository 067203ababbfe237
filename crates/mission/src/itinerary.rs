//! The operator's goals as the twin drives them: every stop of the way in
//! order (the operator's waypoints, each area's sweep, home), the way
//! through them, and, once driven, the record of what was met and when,
//! which the log carries so that the plan keeps it.
//!
//! The waypoints are routed first, on their own, so a waypoint that cannot
//! be reached is refused by its own name before any area is swept from it.

use twindrive_kinematics::Pose;
use twindrive_log::{ReachedWaypoint, RehearsedGoals, SweptArea};

use crate::coverage::{Sweep, SweepSettings, sweep};
use crate::follower::Arrival;
use crate::goals::{Goals, Waypoint};
use crate::route::{Route, RoutePlanner, Unreachable};

/// Why the goals cannot be driven.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ItineraryError {
    /// A value of the goals (the field named), or an area that cannot be
    /// swept.
    #[error("{0}")]
    Goals(String),
    /// A stop cannot be reached: `why` (its waypoint counted in the way's
    /// stops), told with the stop's own name.
    #[error("{reason}")]
    Unreachable { reason: String, why: Unreachable },
}

/// What a stop of the way stands for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    /// The operator's waypoint (index into [`Goals::waypoints`]).
    Waypoint(usize),
    /// A stop of the sweep of area `area` (index into [`Goals::areas`]).
    Sweep { area: usize },
    /// Back where the mission started.
    Home,
}

/// The goals as stops, and the way through them.
#[derive(Debug, Clone)]
pub struct Itinerary {
    /// The goals as given.
    pub goals: Goals,
    /// Every stop of the way as a waypoint, in order (the operator's, each
    /// sweep's, home), with the goals' speeds: what the follower drives.
    pub driven: Goals,
    /// What each of `driven`'s waypoints stands for.
    pub stops: Vec<Stop>,
    /// Each area's sweep.
    pub sweeps: Vec<(SweepSettings, Sweep)>,
    /// The way from the start through every stop.
    pub route: Route,
    /// Where the robot started.
    pub start: Pose,
}

impl Stop {
    /// The operator's name for it.
    pub fn name(&self) -> String {
        match self {
            Stop::Waypoint(i) => format!("waypoint {}", i + 1),
            Stop::Sweep { area } => format!("the sweep of area {}", area + 1),
            Stop::Home => "home".to_string(),
        }
    }
}

/// The fastest a robot drives straight: its wheels' speed limit (rad/s)
/// on its smaller nominal wheel (m/s).
pub fn top_speed_m_s(robot: &twindrive_sim::RobotConfig) -> f64 {
    let p = &robot.nominal_params;
    robot.max_wheel_speed_rad_s * 0.5 * p.left_diameter_m.min(p.right_diameter_m)
}

impl Itinerary {
    /// Plans the way from `start` through `goals` for `robot` on
    /// `planner`'s site. Errors name the waypoint or area and why.
    pub fn plan(
        planner: &RoutePlanner,
        goals: &Goals,
        start: Pose,
        robot: &twindrive_sim::RobotConfig,
    ) -> Result<Self, ItineraryError> {
        goals.validate().map_err(ItineraryError::Goals)?;
        let top = top_speed_m_s(robot);
        let fast = |field: String, v: f64| {
            if v > top {
                Err(ItineraryError::Goals(format!(
                    "field `{field}`: {v} m/s is above the robot's top speed of {top:.2} m/s (its wheels turn at most {:.1} rad/s, nominal diameters {:.3} and {:.3} m)",
                    robot.max_wheel_speed_rad_s,
                    robot.nominal_params.left_diameter_m,
                    robot.nominal_params.right_diameter_m
                )))
            } else {
                Ok(())
            }
        };
        fast("speed_m_s".into(), goals.speed_m_s)?;
        for (i, w) in goals.waypoints.iter().enumerate() {
            if let Some(v) = w.speed_m_s {
                fast(format!("waypoints[{i}].speed_m_s"), v)?;
            }
        }
        let from = [start.x_m, start.y_m];
        let own: Vec<[f64; 2]> = goals.waypoints.iter().map(Waypoint::at).collect();
        let mut route = planner
            .route(from, &own)
            .map_err(|why| ItineraryError::Unreachable {
                reason: why.to_string(),
                why,
            })?;
        let mut driven = goals.clone();
        driven.areas.clear();
        let mut stops: Vec<Stop> = (0..own.len()).map(Stop::Waypoint).collect();
        let mut sweeps = Vec::new();
        let footprint_m = robot.footprint_radius_m;
        for (i, area) in goals.areas.iter().enumerate() {
            let here = driven.waypoints.last().map_or(from, Waypoint::at);
            let settings = SweepSettings {
                sweep_radius_m: area.sweep_radius_m.unwrap_or(footprint_m),
                overlap: area.overlap,
            };
            let swept = sweep(planner, &area.polygon, here, &settings).map_err(|e| {
                ItineraryError::Goals(format!("area {} (`areas[{i}]`): {e}", i + 1))
            })?;
            driven
                .waypoints
                .extend(swept.waypoints.iter().map(|p| plain(*p)));
            stops.extend(std::iter::repeat_n(
                Stop::Sweep { area: i },
                swept.waypoints.len(),
            ));
            sweeps.push((settings, swept));
        }
        if goals.return_home {
            driven.waypoints.push(Waypoint {
                heading_rad: Some(start.heading_rad),
                ..plain(from)
            });
            stops.push(Stop::Home);
        }
        // On from the last waypoint through the sweeps and home.
        let rest: Vec<[f64; 2]> = driven.waypoints[own.len()..]
            .iter()
            .map(Waypoint::at)
            .collect();
        if !rest.is_empty() {
            let here = own.last().copied().unwrap_or(from);
            let more = planner.route(here, &rest).map_err(|why: Unreachable| {
                // The way on starts at the last waypoint (0 here).
                let name = match why.waypoint() {
                    0 => own
                        .len()
                        .checked_sub(1)
                        .map_or("the start".to_string(), |k| Stop::Waypoint(k).name()),
                    k => stops[own.len() + k - 1].name(),
                };
                ItineraryError::Unreachable {
                    reason: why.naming(&name),
                    why,
                }
            })?;
            let offset = route.points.len() - 1;
            route.points.extend_from_slice(&more.points[1..]);
            route.stops.extend(more.stops.iter().map(|&k| k + offset));
            route.length_m += more.length_m;
            route.min_clearance_m = route.min_clearance_m.min(more.min_clearance_m);
        }
        Ok(Self {
            goals: goals.clone(),
            driven,
            stops,
            sweeps,
            route,
            start,
        })
    }

    /// What the drive met, as the log records it: each of the operator's
    /// waypoints (and home) with when the robot stood there and left, each
    /// area from its sweep's first stop to its last. `arrivals` are the
    /// follower's (indices into `driven`); stops not met are left out.
    pub fn record(&self, arrivals: &[Arrival]) -> RehearsedGoals {
        let mut record = RehearsedGoals::default();
        for a in arrivals {
            let Some(&stop) = self.stops.get(a.waypoint) else {
                continue;
            };
            let w = &self.driven.waypoints[a.waypoint];
            match stop {
                Stop::Waypoint(_) | Stop::Home => record.waypoints.push(ReachedWaypoint {
                    name: stop.name(),
                    x_m: w.x_m,
                    y_m: w.y_m,
                    heading_rad: w.heading_rad,
                    dwell_s: w.dwell_s,
                    reached_t_s: a.reached_t_s,
                    left_t_s: a.left_t_s,
                }),
                Stop::Sweep { area } => {
                    let name = format!("area {}", area + 1);
                    match record.areas.last_mut() {
                        Some(last) if last.name == name => last.end_t_s = a.left_t_s,
                        _ => record.areas.push(SweptArea {
                            name,
                            polygon: self.goals.areas[area].polygon.clone(),
                            sweep_radius_m: self.sweeps[area].0.sweep_radius_m,
                            start_t_s: a.reached_t_s,
                            end_t_s: a.left_t_s,
                            swept_percent: None,
                        }),
                    }
                }
            }
        }
        record
    }
}

/// A waypoint at `p` with nothing asked there.
fn plain(p: [f64; 2]) -> Waypoint {
    Waypoint {
        x_m: p[0],
        y_m: p[1],
        heading_rad: None,
        dwell_s: 0.0,
        speed_m_s: None,
    }
}
