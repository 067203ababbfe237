//! Localization on the robot, on held-out-style sites: the executive driven
//! from the navigator's estimate, on a site whose true kinematics differ
//! from the twin's by a random few percent and that has no motion-capture
//! tracker. A lidar robot localizes against the plan's map and stays on
//! its plan; a one-IR robot is never worse than odometry alone.

mod common;

use std::sync::{Arc, OnceLock};

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twindrive_agent::backend::{RobotBackend, SimBackend};
use twindrive_agent::executive::{Executive, Stop, Tolerances};
use twindrive_agent::localize::{LocalizeSettings, Mode};
use twindrive_agent::navigator::{Navigator, initial_estimate};
use twindrive_mission::plan::{MissionPlan, SiteMapGeometry};
use twindrive_sim::Scenario;

fn office() -> Scenario {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/office_drive.toml");
    Scenario::load(&path).unwrap()
}

/// The office drive's plan (a 181-beam lidar), made on its twin.
fn office_plan() -> &'static Arc<MissionPlan> {
    static PLAN: OnceLock<Arc<MissionPlan>> = OnceLock::new();
    PLAN.get_or_init(|| {
        let scenario = office();
        Arc::new(common::plan_of(&scenario, &scenario.robot.true_params))
    })
}

/// `twin` as a remote site: no tracker, true kinematics off by `error`
/// (each parameter scaled by 1 ± error, signs at random), its own noise.
fn site(twin: &Scenario, error: f64, rng: &mut ChaCha8Rng) -> Scenario {
    let mut s = twin.clone();
    s.tracker = None;
    let t = &mut s.robot.true_params;
    let mut sign = || if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    t.left_diameter_m *= 1.0 + sign() * error;
    t.right_diameter_m *= 1.0 + sign() * error;
    t.wheelbase_m *= 1.0 + sign() * error;
    s.seed = rng.random_range(0..1_000_000);
    s
}

struct Trial {
    stop: Option<Stop>,
    /// Whether the bumper was ever pressed.
    bumped: bool,
    /// Largest distance from the true position to the plan's path (m).
    path_error_m: f64,
    collisions: u32,
    localized_fixes: u64,
    /// The true pose at every step.
    track: Vec<twindrive_kinematics::Pose>,
    events: Vec<twindrive_agent::executive::Event>,
    /// The robot's time when it stopped (s).
    stopped_s: f64,
}

/// Largest distance of `p` to the polyline of the plan's positions.
fn distance_to_path(plan: &MissionPlan, x: f64, y: f64) -> f64 {
    plan.samples
        .windows(2)
        .map(|w| {
            let (ax, ay, bx, by) = (w[0].x_m, w[0].y_m, w[1].x_m, w[1].y_m);
            let (dx, dy) = (bx - ax, by - ay);
            let l2 = dx * dx + dy * dy;
            let t = if l2 > 0.0 {
                (((x - ax) * dx + (y - ay) * dy) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (x - ax - t * dx).hypot(y - ay - t * dy)
        })
        .fold(f64::INFINITY, f64::min)
}

fn drive(plan: &Arc<MissionPlan>, site: Scenario, localize: bool) -> Trial {
    drive_with(plan, site, localize, Tolerances::default())
}

fn drive_with(
    plan: &Arc<MissionPlan>,
    site: Scenario,
    localize: bool,
    tolerances: Tolerances,
) -> Trial {
    let max_wheel = site.robot.max_wheel_speed_rad_s;
    let duration = plan.duration_s();
    let mut backend = SimBackend::new(site, plan.samples[0].pose(), duration + 30.0).unwrap();
    let mut exec = Executive::new(plan.clone(), tolerances, None, max_wheel).unwrap();
    let start = plan.samples[0].pose();
    let initial = initial_estimate(
        [start.x_m, start.y_m, start.heading_rad],
        None,
        &plan.header.calibrated,
    );
    let settings = if localize {
        LocalizeSettings::default()
    } else {
        LocalizeSettings::odometry_only()
    };
    let mut nav = Navigator::new(plan, initial, plan.header.robot.ticks_per_rev, settings);
    let (mut path_error_m, mut collisions, mut k) = (0.0f64, 0, 0u64);
    let mut bumped = false;
    let mut track = Vec::new();
    let mut events = Vec::new();
    let mut stopped_s = f64::NAN;
    while let Some(reading) = backend.step(&mut |reading| {
        let belief = nav.update(reading);
        exec.tick(reading, &belief)
    }) {
        track.push(backend.true_pose());
        events.extend(exec.take_events());
        stopped_s = reading.t_s;
        if backend.blocked() {
            collisions += 1;
        }
        bumped |= reading.bump;
        k += 1;
        if k % 10 == 0 {
            let p = backend.true_pose();
            path_error_m = path_error_m.max(distance_to_path(plan, p.x_m, p.y_m));
        }
        if exec.stopped().is_some() || reading.t_s > duration + 25.0 {
            break;
        }
    }
    Trial {
        stop: exec.stopped().map(|(_, s)| s.clone()),
        bumped,
        path_error_m,
        collisions,
        localized_fixes: nav.localizer().fixes,
        track,
        events,
        stopped_s,
    }
}

/// `plan` with its freedom replaced by `change`'s, its hash renewed.
fn with_freedom(
    plan: &MissionPlan,
    change: impl FnOnce(&mut twindrive_mission::plan::Freedom),
) -> Arc<MissionPlan> {
    let mut header = plan.header.clone();
    change(&mut header.freedom);
    Arc::new(MissionPlan::new(header, plan.samples.clone()))
}

#[test]
fn a_lidar_robot_with_up_to_two_percent_kinematic_error_stays_on_its_plan() {
    let plan = office_plan();
    let twin = office();
    let mut rng = ChaCha8Rng::seed_from_u64(2026);
    for error in [0.0, 0.005, 0.01, 0.02, 0.02] {
        let site = site(&twin, error, &mut rng);
        let t = drive(plan, site.clone(), true);
        assert_eq!(t.stop, Some(Stop::Finished), "error {error}");
        assert!(t.path_error_m < 0.05, "error {error}: {} m", t.path_error_m);
        assert_eq!(t.collisions, 0, "error {error}");
        // About one fix per scan (10 Hz).
        assert!(
            t.localized_fixes as f64 > 8.0 * plan.duration_s(),
            "{}",
            t.localized_fixes
        );
        if error >= 0.01 {
            // Without the map the same robot does not finish on its plan.
            let blind = drive(plan, site, false);
            assert_ne!(
                blind.stop,
                Some(Stop::Finished),
                "error {error}: odometry alone finished"
            );
        }
    }
}

/// A box the twin lacks, dropped on the plan's path at a random moment on
/// sites with random kinematic errors, and a plan that gives the robot no
/// corridor (directed driving): the lidar robot, localizing, hands back
/// before it touches it (the range residual may see it first, a box
/// shadowing far walls). With the residual out of the way, the
/// obstacle-ahead stop alone does it and says where the box is.
#[test]
fn a_lidar_robot_without_a_corridor_stops_before_a_box_it_can_see_on_its_path() {
    let plan = &with_freedom(office_plan(), |f| f.corridor.clear());
    let twin = office();
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    let footprint = twin.robot.footprint_radius_m;
    let without_residual = Tolerances {
        max_range_residual_m: f64::INFINITY,
        ..Tolerances::default()
    };
    let mut trials = 0;
    while trials < 4 {
        // A plan sample well inside the mission, away from the walls.
        let k = rng.random_range(plan.samples.len() / 5..4 * plan.samples.len() / 5);
        let s = &plan.samples[k];
        if twin.world.clearance_m(s.x_m, s.y_m, 1.0) < 0.6 {
            continue;
        }
        let half = [rng.random_range(0.08..0.2), rng.random_range(0.08..0.2)];
        let block = (
            [s.x_m - half[0], s.y_m - half[1]],
            [s.x_m + half[0], s.y_m + half[1]],
        );
        let mut site = site(&twin, rng.random_range(0.0..0.02), &mut rng);
        site.world = site.world.with_blocks(&[block]);
        let t = drive(plan, site.clone(), true);
        assert!(
            matches!(
                t.stop,
                Some(Stop::ObstacleAhead { .. } | Stop::RangeResidual { .. })
            ),
            "{block:?}: stopped {:?}",
            t.stop
        );
        assert!(!t.bumped && t.collisions == 0, "{block:?}: touched it");
        let t = drive_with(plan, site, true, without_residual);
        let Some(Stop::ObstacleAhead { x_m, y_m, range_m }) = t.stop else {
            panic!("{block:?}: stopped {:?}", t.stop);
        };
        assert!(!t.bumped && t.collisions == 0, "{block:?}: touched it");
        // What it saw is on the box (within the lidar's noise and the
        // estimate's error), and farther than the footprint.
        let out = (block.0[0] - x_m)
            .max(x_m - block.1[0])
            .max(block.0[1] - y_m)
            .max(y_m - block.1[1]);
        assert!(out < 0.05, "{block:?}: saw ({x_m}, {y_m})");
        assert!(range_m > footprint, "{range_m} m");
        trials += 1;
    }
}

/// A box the twin lacks on the plan's path, at a random place with room
/// on both sides, on sites with random kinematic errors, and in half the
/// trials a keep-out zone of random size beside it on a random side: the
/// lidar robot goes around the box on its own (a detour event, then back
/// on the plan) and finishes the plan without touching anything, its true
/// footprint never in the zone and its centre inside the plan's corridor,
/// within the plan's time and extra-time bound.
#[test]
fn a_lidar_robot_goes_around_a_box_inside_its_corridor_and_out_of_a_zone() {
    use twindrive_agent::executive::Event;
    use twindrive_mission::freedom::FreedomMap;
    use twindrive_mission::plan::KeepOutZone;
    let twin = office();
    let base = office_plan();
    let mut rng = ChaCha8Rng::seed_from_u64(40);
    let footprint = twin.robot.footprint_radius_m;
    let mut trials = 0;
    while trials < 6 {
        let k = rng.random_range(base.samples.len() / 5..4 * base.samples.len() / 5);
        let s = base.samples[k].clone();
        if twin.world.clearance_m(s.x_m, s.y_m, 2.0) < 1.0 || s.v_m_s < 0.05 {
            continue;
        }
        let half = [rng.random_range(0.08..0.2), rng.random_range(0.08..0.2)];
        let block = (
            [s.x_m - half[0], s.y_m - half[1]],
            [s.x_m + half[0], s.y_m + half[1]],
        );
        let zone = rng.random_bool(0.5).then(|| {
            // Beside the path on one side: from 0.4 m out to 0.6-1.2 m,
            // 0.3-0.8 m either way along it.
            let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let (sn, cs) = s.heading_rad.sin_cos();
            let (near, far) = (0.4, rng.random_range(0.6..1.2));
            let along = rng.random_range(0.3..0.8);
            let at = |a: f64, c: f64| {
                [
                    s.x_m + a * cs - side * c * sn,
                    s.y_m + a * sn + side * c * cs,
                ]
            };
            KeepOutZone {
                name: "flowers".into(),
                polygon: vec![
                    at(-along, near),
                    at(along, near),
                    at(along, far),
                    at(-along, far),
                ],
            }
        });
        let plan = with_freedom(base, |f| f.keep_out = zone.clone().into_iter().collect());
        let mut site = site(&twin, rng.random_range(0.0..0.02), &mut rng);
        site.world = site.world.with_blocks(&[block]);
        let t = drive(&plan, site, true);
        assert_eq!(t.stop, Some(Stop::Finished), "{block:?} {zone:?}");
        assert!(!t.bumped && t.collisions == 0, "{block:?}: touched it");
        assert!(
            matches!(t.events.first(), Some(Event::Detour { .. }))
                && matches!(t.events.last(), Some(Event::Rejoined { .. })),
            "{block:?}: {:?}",
            t.events
        );
        let map = FreedomMap::of_plan(&plan);
        let along = twindrive_mission::freedom::sample_arc_lengths(&plan.samples);
        for p in &t.track {
            assert!(
                map.zone_hit([p.x_m, p.y_m]).is_none(),
                "{block:?}: in the zone at {p:?}"
            );
            let inside = plan.samples.iter().zip(&along).any(|(s, a)| {
                let hw = plan.header.freedom.half_width_at(*a).unwrap();
                (s.x_m - p.x_m).hypot(s.y_m - p.y_m) <= hw - footprint + 0.02
            });
            assert!(inside, "{block:?}: out of the corridor at {p:?}");
        }
        assert!(
            t.stopped_s <= plan.duration_s() + plan.header.freedom.max_extra_time_s,
            "{} s",
            t.stopped_s
        );
        trials += 1;
    }
}

/// A box that fills the corridor at a random place on the plan: no way
/// around exists inside it, and the lidar robot hands back (`blocked`,
/// where it saw the box) without touching anything.
#[test]
fn a_box_filling_the_corridor_is_one_hand_back_and_no_contact() {
    let twin = office();
    let plan = office_plan();
    let along = twindrive_mission::freedom::sample_arc_lengths(&plan.samples);
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    let mut trials = 0;
    while trials < 3 {
        let k = rng.random_range(plan.samples.len() / 5..4 * plan.samples.len() / 5);
        let s = &plan.samples[k];
        if twin.world.clearance_m(s.x_m, s.y_m, 1.0) < 0.6 {
            continue;
        }
        let hw = plan.header.freedom.half_width_at(along[k]).unwrap();
        let half = hw + 0.1;
        let block = ([s.x_m - half, s.y_m - half], [s.x_m + half, s.y_m + half]);
        let mut site = site(&twin, rng.random_range(0.0..0.02), &mut rng);
        site.world = site.world.with_blocks(&[block]);
        let t = drive(plan, site, true);
        let Some(Stop::Blocked { x_m, y_m, .. }) = t.stop else {
            panic!("{block:?}: stopped {:?}", t.stop);
        };
        assert!(t.stop.as_ref().unwrap().is_handback());
        assert!(!t.bumped && t.collisions == 0, "{block:?}: touched it");
        let out = (block.0[0] - x_m)
            .max(x_m - block.1[0])
            .max(block.0[1] - y_m)
            .max(y_m - block.1[1]);
        assert!(out < 0.05, "{block:?}: saw ({x_m}, {y_m})");
        trials += 1;
    }
}

#[test]
fn a_one_ir_robot_is_never_worse_than_odometry_alone() {
    let plan = common::plan();
    let twin = common::twin();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let start = initial_estimate([0.0; 3], None, &plan.header.calibrated);
    let nav = Navigator::new(plan, start, 512, LocalizeSettings::default());
    assert_eq!(nav.localizer().mode(), Mode::Window);
    for error in [0.0, 0.005, 0.01, 0.01, 0.02] {
        let site = site(&twin, error, &mut rng);
        let t = drive(plan, site.clone(), true);
        let blind = drive(plan, site, false);
        assert_eq!(t.collisions, 0, "error {error}");
        if blind.stop == Some(Stop::Finished) {
            assert_eq!(t.stop, Some(Stop::Finished), "error {error}");
            assert!(t.path_error_m <= blind.path_error_m + 0.01, "error {error}");
        }
        // On this plan (along walls the beam keeps seeing) it does better.
        assert_eq!(t.stop, Some(Stop::Finished), "error {error}");
        assert!(t.path_error_m < 0.05, "error {error}: {} m", t.path_error_m);
        assert!(t.localized_fixes > 30, "error {error}");
    }
}

#[test]
fn one_beam_in_an_open_room_cannot_localize_and_goes_by_odometry() {
    // The case-study plan in a room four times larger: the side IR reads
    // nothing on most of it.
    let plan = common::plan();
    let mut twin = common::twin();
    twin.world = twindrive_sim::World::from_walls(
        &[
            [-10.0, -10.0, 20.0, -10.0],
            [20.0, -10.0, 20.0, 20.0],
            [20.0, 20.0, -10.0, 20.0],
            [-10.0, 20.0, -10.0, -10.0],
        ],
        &[],
    );
    let mut plan_in_open = (**plan).clone();
    plan_in_open.header.site_map = twindrive_mission::plan::SiteMap::of(&twin.world);
    let plan_in_open = Arc::new(plan_in_open);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let site = site(&twin, 0.0, &mut rng);
    let t = drive(&plan_in_open, site, true);
    assert_eq!(t.localized_fixes, 0, "no wall in reach, no fix");
    assert_eq!(t.stop, Some(Stop::Finished), "odometry alone, as before");
}

#[test]
fn the_localizer_asks_each_sensor_its_kind_not_its_beam_count() {
    use twindrive_agent::localize::Localizer;
    use twindrive_log::SensorKind;
    let lidar = office_plan().as_ref().clone();
    let mode = |plan: &MissionPlan| Localizer::new(plan, LocalizeSettings::default()).mode();
    assert_eq!(lidar.header.robot.range_sensors[0].kind, SensorKind::Lidar);
    assert_eq!(mode(&lidar), Mode::Scan);
    // A sparse lidar (a dozen beams) is still a lidar: matched scan by scan.
    let mut sparse = lidar.clone();
    let s = &mut sparse.header.robot.range_sensors[0];
    s.beams = 12;
    s.fov_rad = 3.0;
    assert_eq!(mode(&sparse), Mode::Scan);
    // Rangers alone gather their readings over a window of driving, however
    // many there are.
    let mut rangers = lidar.clone();
    let one = &lidar.header.robot.range_sensors[0];
    rangers.header.robot.range_sensors = (0..40)
        .map(|i| twindrive_log::RangeSensorInfo {
            name: format!("ir{i}"),
            kind: SensorKind::Ranger,
            mount: twindrive_kinematics::Pose::new(0.0, 0.0, f64::from(i) * 0.15),
            beams: 1,
            fov_rad: 0.0,
            ..one.clone()
        })
        .collect();
    assert_eq!(mode(&rangers), Mode::Window);
}
