//! The master's side of a hand-back: the pose refined against the twin's
//! map from the hand-back's window, and continuations that keep three of
//! its standard deviations clear of everything the twin knows.

mod common;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use twindrive_agent::refine::{RefineSettings, refine};
use twindrive_agent::twin::{ContinuationSettings, LearnSettings, SETTLE_M, Twin};
use twindrive_kinematics::Pose;
use twindrive_link::envelope::Tolerances;
use twindrive_link::wire::{Handback, WindowSample};
use twindrive_sim::{Scenario, SensorModel, Simulator};

fn office() -> Scenario {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/office_drive.toml");
    Scenario::load(&path).unwrap()
}

/// A hand-back at `believed` (the robot's estimate) with `std` on each of
/// x, y and heading, and a window of what the site's sensors read at the
/// `true_poses`, each believed off by the same rigid error as the last.
fn handback(site: &Scenario, true_poses: &[Pose], believed: Pose, std: [f64; 3]) -> Handback {
    let mut model = SensorModel::new(site);
    let mut ranges = vec![0.0; model.beams()];
    let last = *true_poses.last().unwrap();
    let dh = believed.heading_rad - last.heading_rad;
    let (s, c) = dh.sin_cos();
    let window = true_poses
        .iter()
        .map(|p| {
            let bump = model.read(p, &mut ranges);
            let (dx, dy) = (p.x_m - last.x_m, p.y_m - last.y_m);
            WindowSample {
                plan_t_s: 0.0,
                pose: [
                    believed.x_m + c * dx - s * dy,
                    believed.y_m + s * dx + c * dy,
                    p.heading_rad + dh,
                ],
                ranges_m: ranges.iter().map(|&r| r as f32).collect(),
                bump,
            }
        })
        .collect();
    let mut pose_covariance = [0.0; 9];
    for i in 0..3 {
        pose_covariance[4 * i] = std[i] * std[i];
    }
    Handback {
        plan: [0; 32],
        reason: "range_residual".into(),
        plan_t_s: 0.0,
        progress: 0,
        pose: [believed.x_m, believed.y_m, believed.heading_rad],
        pose_covariance,
        params: [0.0; 3],
        params_covariance: [1.0; 9],
        window,
    }
}

/// Random moments of the office drive (a 181-beam lidar), the robot's
/// estimate off by a random error drawn from the covariance it reports:
/// the twin's refined pose is within 3 cm and 0.02 rad of the truth, closer
/// than the robot's own, and its covariance is smaller and consistent with
/// the error left (squared Mahalanobis distance within chi-square(3) at
/// 99.9 %).
#[test]
fn the_twin_refines_a_handback_pose_against_its_map() {
    let site = office();
    let log = Simulator::new(site.clone()).run(|_, _| {});
    let sensors: Vec<_> = site.range_sensors.iter().map(|s| s.info.clone()).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let std = [0.05, 0.05, 0.03];
    for _ in 0..12 {
        let end = rng.random_range(300..log.steps.len());
        let poses: Vec<Pose> = log.steps[end - 200..end]
            .iter()
            .step_by(4)
            .map(|s| s.ground_truth)
            .collect();
        let truth = *poses.last().unwrap();
        let noise = |s: f64| Normal::new(0.0, s).unwrap();
        let mut draw = |i: usize| noise(std[i]).sample(&mut rng);
        let (ex, ey, eh) = (draw(0), draw(1), draw(2));
        let believed = Pose::new(truth.x_m + ex, truth.y_m + ey, truth.heading_rad + eh);
        let h = handback(&site, &poses, believed, std);
        let r = refine(
            &site.world,
            &sensors,
            &site.robot.true_params,
            &h,
            &RefineSettings::default(),
        );
        let e = [
            r.pose[0] - truth.x_m,
            r.pose[1] - truth.y_m,
            twindrive_kinematics::wrap_angle(r.pose[2] - truth.heading_rad),
        ];
        let before = ex.hypot(ey);
        let after = e[0].hypot(e[1]);
        assert!(r.directions >= 2, "{r:?}");
        assert!(after < 0.03 && e[2].abs() < 0.02, "error {e:?} from {r:?}");
        assert!(after < before.max(0.01), "{after} after, {before} before");
        let c = nalgebra::Matrix3::from_row_slice(&r.covariance);
        assert!(c.trace() < 3.0 * std[0] * std[0], "{r:?}");
        let v = nalgebra::Vector3::from(e);
        let d2 = (v.transpose() * c.try_inverse().unwrap() * v)[(0, 0)];
        assert!(d2 < 16.27, "Mahalanobis² {d2} for {e:?}, {r:?}");
    }
}

/// Random hand-backs along the case-study plan: a continuation from a pose
/// known to a few millimetres is planned and verified; the same hand-back
/// with a position uncertainty whose three sigma exceed the plan's
/// clearance from the walls is refused, and the reason says how near it
/// comes, to what and why.
#[test]
fn a_continuation_from_an_uncertain_pose_near_a_wall_is_refused() {
    let plan = common::plan();
    let twin_site = common::twin();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let criteria = twindrive_agent::executive::criteria(&Tolerances::default());
    let t0 = plan.samples[0].t_s;
    let footprint = twin_site.robot.footprint_radius_m;
    let (mut tried, mut checked) = (0, 0);
    while checked < 4 {
        tried += 1;
        assert!(tried < 1_000, "no hand-back point ahead of a wall");
        let k = rng.random_range(plan.samples.len() / 10..plan.samples.len() * 8 / 10);
        let at = plan.samples[k].pose();
        let plan_t_s = plan.samples[k].t_s - t0;
        // The plan's least clearance from the walls over the metre ahead,
        // where the robot has not localized again yet.
        let mut travel_m = 0.0;
        let least = plan.samples[k..]
            .windows(2)
            .take_while(|w| {
                travel_m += (w[1].x_m - w[0].x_m).hypot(w[1].y_m - w[0].y_m);
                travel_m < SETTLE_M
            })
            .map(|w| twin_site.world.clearance_m(w[1].x_m, w[1].y_m, 2.0) - footprint)
            .fold(f64::INFINITY, f64::min);
        // Where the plan comes nearer a wall ahead than where the robot
        // stands (a continuation may start near a wall and move away).
        let here = twin_site.world.clearance_m(at.x_m, at.y_m, 2.0) - footprint;
        if least > here - 0.03 || least < 0.02 {
            continue;
        }
        checked += 1;
        for (std, refused) in [(0.003, false), ((least + 0.02) / 3.0, true)] {
            let mut twin = Twin::new(twin_site.clone(), common::CALIBRATED);
            let mut h = handback(&twin_site, &[at], at, [std, std, 0.01]);
            h.window.clear();
            h.plan_t_s = plan_t_s;
            twin.apply(&h, &LearnSettings::default());
            let sigma = twin.refined.unwrap().position_std_m();
            assert!(
                (sigma - std).abs() < 1e-3 * std.max(0.003),
                "{sigma} for {std}"
            );
            let result =
                twin.continuation(plan, plan_t_s, &ContinuationSettings::default(), &criteria);
            match (refused, result) {
                (false, Ok(c)) => assert!(c.samples.len() > 10),
                (true, Err(e)) => {
                    let why = e.to_string();
                    assert!(
                        why.contains("a wall the twin knew") && why.contains("three of them"),
                        "{why}"
                    );
                }
                (false, Err(e)) => panic!("refused at {at:?} with {std} m: {e}"),
                (true, Ok(_)) => panic!(
                    "sent from {at:?} ({here:.3} m clear) known to {std:.3} m although the plan passes {least:.3} m from a wall"
                ),
            }
        }
    }
}
