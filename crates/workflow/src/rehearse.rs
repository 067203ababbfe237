//! A rehearsal from goals: the way through the operator's waypoints on the
//! twin's map ([`twindrive_mission::route`]), driven by the twin's robot
//! ([`twindrive_mission::follower`], on the twin's true pose), logged as a
//! manual rehearsal is: what `simulate` writes, and the route beside it.
//! Nothing is written when a waypoint cannot be reached or the twin does
//! not get there.

use std::path::Path;
use std::time::Instant;

use anyhow::bail;
use serde::Serialize;
use twindrive_files::Staging;
use twindrive_kinematics::wheel_speeds;
use twindrive_log::MissionLog;
use twindrive_mission::coverage::{covered_share, with_sweeps};
use twindrive_mission::follower::{Follower, FollowerSettings, expected_duration_s};
use twindrive_mission::goals::Goals;
use twindrive_mission::plan::KeepOutZone;
use twindrive_mission::route::{Route, RoutePlanner, RouteSettings, Unreachable};
use twindrive_sim::{MissionSummary, Scenario, Simulator, StepOutput};

use crate::simulate::write_run;

/// The way planned for the goals, and what it took.
#[derive(Debug, Clone, Serialize)]
pub struct PlannedRoute {
    pub route: Route,
    /// At the goals' speeds, turning at the follower's rate (s).
    pub duration_s: f64,
    pub planning_ms: f64,
    /// The waypoints driven: the goals' own, then each area's sweep.
    pub goals: Goals,
    /// Each area's sweep.
    pub areas: Vec<AreaSweep>,
}

/// An area's sweep: its lanes and touch-ups, its free ground, the share
/// planned to be swept and (once driven) the share the twin swept.
#[derive(Debug, Clone, Serialize)]
pub struct AreaSweep {
    pub lanes: usize,
    pub touch_ups: usize,
    pub free_m2: f64,
    pub planned_percent: f64,
    pub swept_percent: Option<f64>,
    pub sweep_radius_m: f64,
}

/// Plans the way from the scenario's start through the goals' waypoints,
/// `zones` kept out of.
pub fn plan_route(
    scenario: &Scenario,
    goals: &Goals,
    zones: &[KeepOutZone],
) -> Result<PlannedRoute, anyhow::Error> {
    let started = Instant::now();
    let settings = RouteSettings {
        clearance_m: goals.clearance_m,
        ..RouteSettings::default()
    };
    let Some(planner) = RoutePlanner::new(
        &scenario.world,
        zones,
        scenario.robot.footprint_radius_m,
        settings,
    ) else {
        bail!(
            "{}: the twin's site has no walls or map to plan on",
            scenario.name
        );
    };
    let s = scenario.robot.start;
    // Each area's sweep after the waypoints, from where the robot is then.
    let (driven, sweeps) = with_sweeps(
        &planner,
        goals,
        [s.x_m, s.y_m],
        scenario.robot.footprint_radius_m,
    )
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    let areas = sweeps
        .iter()
        .map(|(settings, sweep)| AreaSweep {
            lanes: sweep.lanes,
            touch_ups: sweep.touch_ups,
            free_m2: sweep.free_m2,
            planned_percent: sweep.planned_percent,
            swept_percent: None,
            sweep_radius_m: settings.sweep_radius_m,
        })
        .collect();
    let waypoints: Vec<[f64; 2]> = driven.waypoints.iter().map(|w| w.at()).collect();
    let route = planner
        .route([s.x_m, s.y_m], &waypoints)
        .map_err(|why: Unreachable| anyhow::anyhow!("{why}"))?;
    let planning_ms = started.elapsed().as_secs_f64() * 1e3;
    let duration_s = expected_duration_s(&route, &driven, &FollowerSettings::default());
    Ok(PlannedRoute {
        route,
        duration_s,
        planning_ms,
        goals: driven,
        areas,
    })
}

/// Drives `planned` on the twin from the scenario's start: the log, once
/// the robot stood at the last waypoint. Errors (nothing written) when the
/// robot touches anything or does not get there in twice the route's time
/// and a minute.
pub fn drive_route(mut scenario: Scenario, planned: &PlannedRoute) -> anyhow::Result<MissionLog> {
    let goals = &planned.goals;
    let limit_s = 2.0 * planned.duration_s + 60.0;
    scenario
        .set_duration_s(limit_s)
        .map_err(|e| anyhow::anyhow!("the rehearsal's length: {e}"))?;
    let nominal = scenario.robot.nominal_params;
    let dt_s = scenario.dt_ns as f64 * 1e-9;
    let total = scenario.steps;
    let mut sim = Simulator::new(scenario);
    let mut follower = Follower::new(&planned.route, goals, FollowerSettings::default());
    let mut log = MissionLog::new(sim.scenario().log_header());
    let mut out = StepOutput::new(sim.beams());
    let bar = twindrive_progress::bar(total, "driving the route on the twin");
    let mut step = 0u64;
    while !follower.done() {
        let pose = sim.pose();
        let (v, omega) = follower.command(&pose, step as f64 * dt_s);
        let (l, r) = wheel_speeds(&nominal, v, omega);
        if !sim.step_with(&mut out, &mut |_| [l, r]) {
            bail!(
                "the twin's robot reached {} of {} waypoint(s) in {limit_s:.0} s and stood at ({:.2}, {:.2}): it did not get there",
                follower.reached(),
                goals.waypoints.len(),
                pose.x_m,
                pose.y_m
            );
        }
        log.steps.push(out.record);
        log.ranges.extend_from_slice(&out.ranges);
        if out.record.bump || out.blocked {
            bail!(
                "the twin's robot touched something at ({:.2}, {:.2}), {:.1} s in: the route is not clear",
                pose.x_m,
                pose.y_m,
                step as f64 * dt_s
            );
        }
        step += 1;
        if step.is_multiple_of(4096) {
            bar.set_position(step);
        }
    }
    bar.finish_and_clear();
    Ok(log)
}

/// Plans, drives and writes a rehearsal from goals into `out`: the run's
/// files as `simulate` writes them and `route.json` (the way planned).
pub fn rehearse_into(
    scenario: Scenario,
    goals: &Goals,
    zones: &[KeepOutZone],
    out: &Path,
) -> anyhow::Result<(PlannedRoute, MissionSummary)> {
    let planned = plan_route(&scenario, goals, zones)?;
    tracing::info!(
        length_m = planned.route.length_m,
        corners = planned.route.points.len(),
        planning_ms = planned.planning_ms,
        "route planned"
    );
    let mut planned = planned;
    let world = scenario.world.clone();
    let footprint_m = scenario.robot.footprint_radius_m;
    let log = drive_route(scenario, &planned)?;
    if !goals.areas.is_empty() {
        // What the twin swept of each area, by its true track.
        let settings = RouteSettings {
            clearance_m: goals.clearance_m,
            ..RouteSettings::default()
        };
        let planner = RoutePlanner::new(&world, zones, footprint_m, settings)
            .expect("planned on the same site");
        let track: Vec<[f64; 2]> = log
            .steps
            .iter()
            .map(|s| [s.ground_truth.x_m, s.ground_truth.y_m])
            .collect();
        for (area, sweep) in goals.areas.iter().zip(&mut planned.areas) {
            let (_, percent) = covered_share(&planner, &area.polygon, &track, sweep.sweep_radius_m);
            sweep.swept_percent = Some(percent);
        }
    }
    let staging = Staging::new(out, "rehearse")?;
    let summary = write_run(&staging, &log, &world)?;
    staging.write_with("route.json", |w| {
        serde_json::to_writer_pretty(w, &planned).map_err(Into::into)
    })?;
    staging.commit()?;
    Ok((planned, summary))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use twindrive_kinematics::wrap_angle;
    use twindrive_mission::goals::Waypoint;
    use twindrive_sim::World;

    /// The paper's robot in random rooms with clutter, a start and two
    /// waypoints at random (the last with a heading and a dwell): the twin
    /// drives the way without touching anything (`drive_route` fails on a
    /// contact) and stands at each waypoint within 3 cm, at the goal's
    /// heading, for its dwell.
    #[test]
    fn the_twin_drives_random_routes_to_their_goals_without_contact() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4101);
        let base = twindrive_sim::builtin::load("wall_following")
            .unwrap()
            .unwrap();
        let mut driven = 0;
        while driven < 6 {
            let (w, h) = (rng.random_range(4.0..9.0), rng.random_range(4.0..9.0));
            let walls = [
                [0.0, 0.0, w, 0.0],
                [w, 0.0, w, h],
                [w, h, 0.0, h],
                [0.0, h, 0.0, 0.0],
            ];
            let blocks: Vec<([f64; 2], [f64; 2])> = (0..rng.random_range(2..8))
                .map(|_| {
                    let (x, y) = (
                        rng.random_range(0.5..w - 1.0),
                        rng.random_range(0.5..h - 1.0),
                    );
                    (
                        [x, y],
                        [
                            x + rng.random_range(0.1..0.7),
                            y + rng.random_range(0.1..0.7),
                        ],
                    )
                })
                .collect();
            let mut scenario = base.clone();
            scenario.world = World::from_walls(&walls, &[]).with_blocks(&blocks);
            let planner =
                RoutePlanner::new(&scenario.world, &[], 0.15, RouteSettings::default()).unwrap();
            let mut free = || loop {
                let p = [
                    rng.random_range(0.3..w - 0.3),
                    rng.random_range(0.3..h - 0.3),
                ];
                if planner.clearance_at(p) > 0.15 {
                    return p;
                }
            };
            let (s, a, b) = (free(), free(), free());
            scenario.robot.start.x_m = s[0];
            scenario.robot.start.y_m = s[1];
            scenario.robot.start.heading_rad = rng.random_range(-3.0..3.0);
            let heading = rng.random_range(-3.0..3.0);
            let goals = Goals {
                areas: Vec::new(),
                clearance_m: 0.1,
                speed_m_s: rng.random_range(0.1..0.3),
                waypoints: vec![
                    Waypoint {
                        x_m: a[0],
                        y_m: a[1],
                        heading_rad: None,
                        dwell_s: 0.0,
                        speed_m_s: None,
                    },
                    Waypoint {
                        x_m: b[0],
                        y_m: b[1],
                        heading_rad: Some(heading),
                        dwell_s: 1.5,
                        speed_m_s: Some(0.1),
                    },
                ],
            };
            let Ok(planned) = plan_route(&scenario, &goals, &[]) else {
                continue; // Shut off by the clutter: refusals are route's tests.
            };
            let log = drive_route(scenario.clone(), &planned).unwrap();
            let truth: Vec<_> = log.steps.iter().map(|s| s.ground_truth).collect();
            let near = |p: [f64; 2]| {
                truth
                    .iter()
                    .map(|q| (q.x_m - p[0]).hypot(q.y_m - p[1]))
                    .fold(f64::INFINITY, f64::min)
            };
            assert!(near(a) < 0.03, "waypoint 1: {} m", near(a));
            let end = truth.last().unwrap();
            assert!(
                (end.x_m - b[0]).hypot(end.y_m - b[1]) < 0.03,
                "{end:?} for {b:?}"
            );
            assert!(
                wrap_angle(end.heading_rad - heading).abs() < 0.05,
                "{end:?} for {heading}"
            );
            // It stood its dwell at the goal.
            let dt = scenario.dt_ns as f64 * 1e-9;
            let standing = truth
                .iter()
                .rev()
                .take_while(|q| {
                    (q.x_m - end.x_m).hypot(q.y_m - end.y_m) < 1e-3
                        && wrap_angle(q.heading_rad - end.heading_rad).abs() < 1e-3
                })
                .count() as f64
                * dt;
            assert!(standing >= 1.4, "stood {standing} s");
            driven += 1;
        }
    }

    /// Random rooms with clutter and a random quadrilateral drawn in them:
    /// the twin sweeps it (lanes, then touch-ups) without touching
    /// anything and covers at least 95 % of its free ground with its
    /// footprint, by its true track.
    #[test]
    fn the_twin_sweeps_random_areas_covering_95_percent_of_their_free_ground() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4102);
        let base = twindrive_sim::builtin::load("wall_following")
            .unwrap()
            .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let mut swept = Vec::new();
        while swept.len() < 4 {
            let (w, h) = (rng.random_range(4.0..7.0), rng.random_range(4.0..7.0));
            let walls = [
                [0.0, 0.0, w, 0.0],
                [w, 0.0, w, h],
                [w, h, 0.0, h],
                [0.0, h, 0.0, 0.0],
            ];
            let blocks: Vec<([f64; 2], [f64; 2])> = (0..rng.random_range(1..5))
                .map(|_| {
                    let (x, y) = (
                        rng.random_range(1.0..w - 1.5),
                        rng.random_range(1.0..h - 1.5),
                    );
                    (
                        [x, y],
                        [
                            x + rng.random_range(0.1..0.5),
                            y + rng.random_range(0.1..0.5),
                        ],
                    )
                })
                .collect();
            let mut scenario = base.clone();
            scenario.world = World::from_walls(&walls, &[]).with_blocks(&blocks);
            scenario.robot.start.x_m = 0.4;
            scenario.robot.start.y_m = 0.4;
            // A quadrilateral of corners jittered about a rectangle.
            let (x0, y0) = (rng.random_range(0.2..1.0), rng.random_range(0.2..1.0));
            let (x1, y1) = (
                rng.random_range(w - 2.0..w - 0.2),
                rng.random_range(h - 2.0..h - 0.2),
            );
            let mut j = || rng.random_range(-0.3..0.3);
            let polygon = vec![
                [x0 + j(), y0 + j()],
                [x1 + j(), y0 + j()],
                [x1 + j(), y1 + j()],
                [x0 + j(), y1 + j()],
            ];
            let goals = Goals::parse(&format!(
                "clearance_m = 0.02\nspeed_m_s = 0.3\n[[areas]]\npolygon = {polygon:?}\n"
            ))
            .unwrap();
            let out = dir.path().join(format!("sweep{}", swept.len()));
            let (planned, summary) = rehearse_into(scenario, &goals, &[], &out).unwrap();
            assert_eq!(summary.bumps, 0);
            let area = &planned.areas[0];
            let percent = area.swept_percent.unwrap();
            assert!(percent >= 95.0, "{area:?} on {polygon:?} with {blocks:?}");
            swept.push(percent);
        }
        eprintln!("swept {swept:?} %");
    }

    /// A goal it cannot reach writes nothing.
    #[test]
    fn an_unreachable_goal_writes_nothing() {
        let scenario = twindrive_sim::builtin::load("wall_following")
            .unwrap()
            .unwrap();
        let goals = Goals::parse("[[waypoints]]\nx_m = 30.0\ny_m = 1.0\n").unwrap();
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let e = rehearse_into(scenario, &goals, &[], &out).unwrap_err();
        assert!(e.to_string().contains("off the twin's site"), "{e}");
        assert!(!out.exists());
    }
}
