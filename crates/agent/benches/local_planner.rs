//! One local planning step of the robot's detour: a 360-beam scan (8 m
//! lidar) integrated into its occupancy grid over an 8 m window at 5 cm,
//! the distance transform, and the way around a box the map lacks on a
//! 20 m x 20 m site (an outer wall, inner walls and 40 boxes) back onto the
//! plan, inside a 1.2 m corridor. The target is 2 ms on one core, so a
//! 50 Hz control loop on a small robot computer keeps its period when it
//! replans at every scan. Also the planner's set-up, once a detour.
//! `cargo bench -p twindrive-agent --bench local_planner`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twindrive_agent::local_planner::{LocalPlanner, LocalPlannerSettings};
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_mission::plan::{
    CorridorStretch, Freedom, MissionPlan, PlanHeader, PlanSample, RobotInfo, SiteMap, WheelLimits,
};
use twindrive_sim::{Vector, World};

fn site(rng: &mut ChaCha8Rng) -> Vec<[f64; 4]> {
    let mut walls = vec![
        [0.0, 0.0, 20.0, 0.0],
        [20.0, 0.0, 20.0, 20.0],
        [20.0, 20.0, 0.0, 20.0],
        [0.0, 20.0, 0.0, 0.0],
        [10.0, 0.0, 10.0, 8.0],
        [10.0, 12.0, 10.0, 20.0],
        [0.0, 14.0, 6.0, 14.0],
    ];
    for _ in 0..40 {
        let (x, y): (f64, f64) = (rng.random_range(1.0..18.0), rng.random_range(1.0..18.0));
        // Clear of the route along y = 10.
        if (y - 10.0).abs() < 2.0 {
            continue;
        }
        let (w, h) = (rng.random_range(0.2..1.0), rng.random_range(0.2..1.0));
        walls.extend([
            [x, y, x + w, y],
            [x + w, y, x + w, y + h],
            [x + w, y + h, x, y + h],
            [x, y + h, x, y],
        ]);
    }
    walls
}

/// A plan along y = 10 from x = 1 to 19 at 0.3 m/s, 1 cm apart.
fn plan(walls: Vec<[f64; 4]>) -> MissionPlan {
    let samples = (0..=1800)
        .map(|k| PlanSample {
            t_s: k as f64 / 30.0,
            x_m: 1.0 + k as f64 * 0.01,
            y_m: 10.0,
            heading_rad: 0.0,
            v_m_s: 0.3,
            omega_rad_s: 0.0,
            left_rad_s: 9.2,
            right_rad_s: 9.2,
            expected_bump: false,
        })
        .collect();
    MissionPlan::new(
        PlanHeader {
            robot: RobotInfo {
                scenario: "bench".into(),
                footprint_radius_m: 0.15,
                ticks_per_rev: 512,
                range_sensors: Vec::new(),
            },
            calibrated: DiffDriveParams::new(0.065, 0.065, 0.27),
            limits: WheelLimits {
                max_speed_rad_s: 12.0,
                max_accel_rad_s2: 30.0,
            },
            time_step_s: 0.01,
            start: Pose::new(1.0, 10.0, 0.0),
            start_covariance: None,
            site_map: SiteMap {
                segments: walls,
                boxes: Vec::new(),
            },
            freedom: Freedom {
                corridor: vec![CorridorStretch {
                    from_m: 0.0,
                    half_width_m: 1.2,
                }],
                keep_out: Vec::new(),
                max_extra_time_s: 60.0,
                max_extra_distance_m: 5.0,
            },
            goals: Default::default(),
            source_log_sha256: "0".repeat(64),
            settings: serde_json::json!({}),
            summary: serde_json::json!({}),
        },
        samples,
    )
}

fn benches(c: &mut Criterion) {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let walls = site(&mut rng);
    let plan = plan(walls.clone());
    // The site as it is: a 0.4 m box on the route at x = 8.
    let mut real = walls;
    real.extend([
        [7.8, 9.8, 8.2, 9.8],
        [8.2, 9.8, 8.2, 10.2],
        [8.2, 10.2, 7.8, 10.2],
        [7.8, 10.2, 7.8, 9.8],
    ]);
    let world = World::from_walls(&real, &[]);
    let pose = Pose::new(6.8, 10.0, 0.0);
    let k = 580;
    let scan: Vec<([f64; 2], bool)> = (0..360)
        .map(|b| {
            let a = pose.heading_rad + (b as f64 - 180.0).to_radians();
            let d = Vector::new(a.cos(), a.sin());
            let r = world.cast_ray(Vector::new(pose.x_m, pose.y_m), d, 8.0);
            ([pose.x_m + r * d.x, pose.y_m + r * d.y], r < 8.0)
        })
        .collect();
    let settings = LocalPlannerSettings::default();
    let along_m: std::sync::Arc<[f64]> =
        twindrive_mission::freedom::sample_arc_lengths(&plan.samples).into();
    let mut planner = LocalPlanner::new(
        &plan,
        along_m.clone(),
        k,
        [pose.x_m, pose.y_m],
        settings,
        None,
    );
    planner.integrate([pose.x_m, pose.y_m], &scan);
    let detour = planner
        .plan(&plan, k, pose, 0.03, None)
        .expect("a way around");
    assert!(detour.length_m > 1.0, "{detour:?}");
    c.bench_function(
        "local planner: set up over an 8 m window (once a detour)",
        |b| {
            b.iter(|| {
                black_box(LocalPlanner::new(
                    black_box(&plan),
                    along_m.clone(),
                    k,
                    [pose.x_m, pose.y_m],
                    settings,
                    None,
                ))
            })
        },
    );
    c.bench_function(
        "local planner: one step (360-beam scan in, distance transform, way around)",
        |b| {
            b.iter(|| {
                planner.integrate(black_box([pose.x_m, pose.y_m]), black_box(&scan));
                black_box(planner.plan(&plan, k, pose, 0.03, None).ok())
            })
        },
    );
}

criterion_group!(local_planner, benches);
criterion_main!(local_planner);
