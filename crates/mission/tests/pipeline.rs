//! The pipeline stages on the paper's case study (the wall-following
//! mission on the twin), checked against the forward model and the limits.

use std::sync::OnceLock;
use twindrive_mission::freedom::FreedomMap;

use twindrive_kinematics::DiffDriveParams;
use twindrive_log::MissionLog;
use twindrive_mission::PipelineError;
use twindrive_mission::control::{forward, recompute};
use twindrive_mission::planner::{PlannerSettings, executed_path};
use twindrive_mission::retime::WheelLimits;
use twindrive_mission::spikes::{FilterSettings, filter_spikes, find_spikes, time_optimal};

/// The twin's hidden truth (what calibration recovers to 0.01 %).
const CALIBRATED: DiffDriveParams = DiffDriveParams {
    left_diameter_m: 0.0652,
    right_diameter_m: 0.0665,
    wheelbase_m: 0.2678,
};

/// The wall-following log's encoder period (the control period of its plans).
const PERIOD_S: f64 = 0.01;

fn scenario() -> twindrive_sim::Scenario {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenarios/wall_following.toml");
    twindrive_sim::Scenario::load(&path).expect("scenario loads")
}

fn wall_following() -> &'static MissionLog {
    static LOG: OnceLock<MissionLog> = OnceLock::new();
    LOG.get_or_init(|| twindrive_sim::Simulator::new(scenario()).run(|_, _| {}))
}

/// The mission's executed path with its spikes filtered (no redundancy removal).
fn filtered() -> twindrive_mission::spikes::Filtered {
    let log = wall_following();
    let path = executed_path(log, &CALIBRATED, &PlannerSettings::default()).unwrap();
    filter_spikes(
        &path,
        &CALIBRATED,
        &limits(log),
        PERIOD_S,
        &FilterSettings::default(),
    )
    .unwrap()
}

fn limits(log: &MissionLog) -> WheelLimits {
    WheelLimits {
        max_speed_rad_s: log.header.max_wheel_speed_rad_s,
        max_accel_rad_s2: log.header.max_wheel_accel_rad_s2,
    }
}

#[test]
fn the_planner_recreates_the_path_from_encoders_and_calibrated_parameters() {
    let log = wall_following();
    let end_error = |params: &DiffDriveParams| {
        let path = executed_path(log, params, &PlannerSettings::default()).unwrap();
        let last = path.last().unwrap();
        let truth = log
            .steps
            .iter()
            .rev()
            .find(|s| s.encoder_ticks.is_some())
            .unwrap()
            .ground_truth;
        (path.len(), last.pose.distance_to(&truth))
    };
    let (n, calibrated) = end_error(&CALIBRATED);
    let (_, nominal) = end_error(&log.header.nominal);
    assert_eq!(
        n,
        log.steps
            .iter()
            .filter(|s| s.encoder_ticks.is_some())
            .count()
    );
    // Over 120 s and ~24 m with slip noise: calibrated odometry ends within
    // a few centimetres, far closer than the hand-measured parameters.
    assert!(calibrated < 0.05, "calibrated end error {calibrated} m");
    assert!(
        nominal > 5.0 * calibrated,
        "nominal {nominal} vs calibrated {calibrated}"
    );
}

#[test]
fn recomputed_wheel_speeds_reproduce_the_path_through_the_forward_model() {
    let log = wall_following();
    let mut path = executed_path(log, &CALIBRATED, &PlannerSettings::default()).unwrap();
    let commands = recompute(&mut path, &CALIBRATED);
    let reached = forward(&path, &commands, &CALIBRATED);
    let worst = path
        .iter()
        .zip(&reached)
        .map(|(p, q)| {
            p.pose
                .distance_to(q)
                .max((p.pose.heading_rad - q.heading_rad).abs())
        })
        .fold(0.0, f64::max);
    assert!(worst < 1e-9, "forward model departs by {worst}");
}

#[test]
fn filtering_leaves_no_speed_or_acceleration_above_the_limits() {
    let log = wall_following();
    let lim = limits(log);
    let path = executed_path(log, &CALIBRATED, &PlannerSettings::default()).unwrap();
    let f = filtered();
    assert!(!f.spikes.is_empty(), "the bumps make spikes to remove");
    assert!(find_spikes(&f.samples, &f.commands, &lim).is_empty());
    // Executable at the control period: no command held much longer.
    let longest = twindrive_mission::spikes::longest_hold_s(&f.samples);
    assert!(longest <= 3.0 * PERIOD_S, "held {longest} s");
    // Every command within the limits, checked directly.
    let mut previous = ([0.0f64; 2], 0.0f64);
    for (k, c) in f.commands.iter().enumerate() {
        let dt = f
            .samples
            .get(k + 1)
            .map_or(0.0, |q| q.t_s - f.samples[k].t_s);
        let span = 0.5 * (previous.1 + dt);
        for w in 0..2 {
            assert!(c.wheels()[w].abs() <= lim.max_speed_rad_s * (1.0 + 1e-6));
            if span > 0.0 {
                let accel = (c.wheels()[w] - previous.0[w]).abs() / span;
                assert!(
                    accel <= lim.max_accel_rad_s2 * (1.0 + 1e-6),
                    "segment {k}: {accel}"
                );
            }
        }
        previous = (c.wheels(), dt);
    }
    // Slower where needed, never faster; the filtered plan still follows
    // the path through the forward model.
    let (t0, t1) = (path.last().unwrap().t_s, f.samples.last().unwrap().t_s);
    assert!(t1 >= t0, "{t1} < {t0}");
    let reached = forward(&f.samples, &f.commands, &CALIBRATED);
    let worst = f
        .samples
        .iter()
        .zip(&reached)
        .map(|(p, q)| p.pose.distance_to(q))
        .fold(0.0, f64::max);
    assert!(worst < 0.01, "filtered plan departs by {worst} m");
    // The time-optimal re-timing of the same path is no slower.
    let (fastest, commands) = time_optimal(&f.samples, &CALIBRATED, &lim, PERIOD_S).unwrap();
    assert!(find_spikes(&fastest, &commands, &lim).is_empty());
    let t2 = fastest.last().unwrap().t_s;
    assert!(twindrive_mission::spikes::longest_hold_s(&fastest) <= 3.0 * PERIOD_S);
    eprintln!(
        "mission {t0:.2} s, filtered {t1:.2} s ({} spikes, {} windows), time-optimal {t2:.2} s",
        f.spikes.len(),
        f.windows.len()
    );
    assert!(t2 <= t1, "time-optimal {t2} s vs filtered {t1} s");
}

#[test]
fn bad_inputs_are_clear_errors() {
    let log = wall_following();
    let mut empty = log.clone();
    empty.steps.clear();
    assert_eq!(
        executed_path(&empty, &CALIBRATED, &PlannerSettings::default()),
        Err(PipelineError::EmptyLog)
    );
    let mut blind = log.clone();
    blind.steps.iter_mut().for_each(|s| s.encoder_ticks = None);
    assert_eq!(
        executed_path(&blind, &CALIBRATED, &PlannerSettings::default()),
        Err(PipelineError::NoEncoderData(0))
    );
    let path = executed_path(log, &CALIBRATED, &PlannerSettings::default()).unwrap();
    let zero = WheelLimits {
        max_speed_rad_s: 12.0,
        max_accel_rad_s2: 0.0,
    };
    let err = filter_spikes(
        &path,
        &CALIBRATED,
        &zero,
        PERIOD_S,
        &FilterSettings::default(),
    )
    .unwrap_err();
    assert_eq!(
        err.to_string(),
        "max_wheel_accel_rad_s2 must be a finite number > 0, got 0"
    );
}

/// Plan samples of the filtered mission (no sensor predictions).
fn plan_samples() -> Vec<twindrive_mission::plan::PlanSample> {
    let f = filtered();
    f.samples
        .iter()
        .zip(&f.commands)
        .map(|(p, c)| twindrive_mission::plan::plan_sample(p, c, false))
        .collect()
}

#[test]
fn closed_loop_tracking_reaches_the_goal_even_when_the_plan_ends_standing_still() {
    let mut samples = plan_samples();
    // Two seconds of standing still at the end (a manual drive's last stop).
    let last = samples.last().unwrap().clone();
    for k in 1..=200 {
        samples.push(twindrive_mission::plan::PlanSample {
            t_s: last.t_s + 0.01 * k as f64,
            ..last.clone()
        });
    }
    let settings = twindrive_mission::verify::TrackerSettings::default();
    let r = twindrive_mission::verify::closed_loop(
        &samples,
        scenario(),
        &CALIBRATED,
        &settings,
        &FreedomMap::unconstrained(),
    )
    .unwrap()
    .report;
    let plan_duration = samples.last().unwrap().t_s - samples[0].t_s;
    assert!(r.final_error_m < 0.03, "{r:?}");
    assert!(
        r.duration_s < plan_duration + 1.0,
        "stopped at the goal, not at the timeout: {r:?}"
    );
    // This path still has its bump-and-back-ups (no redundancy removal):
    // tracked faithfully, the bumper closes there as it did, but nothing
    // drives into a wall.
    assert_eq!(r.collisions, 0, "{r:?}");
    assert!(r.mean_deviation_m < 0.01, "{r:?}");
    assert!(r.max_deviation_m < 0.15, "{r:?}");
}

#[test]
fn closed_loop_tracking_corrects_a_sideways_start_error() {
    let mut samples = plan_samples();
    samples.truncate(2000); // the first 20 s
    // The robot starts where the plan starts; the rest of the plan lies
    // 3 cm to the side (the robot heads along -x there, so y is sideways).
    for s in &mut samples[1..] {
        s.y_m += 0.03;
    }
    let replay = twindrive_mission::verify::closed_loop(
        &samples,
        scenario(),
        &CALIBRATED,
        &twindrive_mission::verify::TrackerSettings::default(),
        &FreedomMap::unconstrained(),
    )
    .unwrap();
    // Converged within the first few seconds and on track to the end.
    let late: Vec<f64> = replay
        .track
        .iter()
        .filter(|(t, _)| (5.0..15.0).contains(t))
        .map(|(t, p)| {
            let k = samples.partition_point(|s| s.t_s <= *t).max(1) - 1;
            (p.x_m - samples[k].x_m).hypot(p.y_m - samples[k].y_m)
        })
        .collect();
    let worst_late = late.iter().cloned().fold(0.0, f64::max);
    assert!(worst_late < 0.01, "still {worst_late} m off after 5 s");
    assert!(replay.report.final_error_m < 0.02, "{:?}", replay.report);
}

/// The whole pipeline at the robot's own size: pinch distance and coverage
/// radius one footprint radius (0.15 m).
fn case_study_settings() -> twindrive_mission::pipeline::PipelineSettings {
    twindrive_mission::pipeline::PipelineSettings {
        planner: PlannerSettings::default(),
        redundancy: twindrive_mission::redundancy::RedundancyConfig::with_pinch_distance(
            scenario().robot.footprint_radius_m,
        ),
        filter: FilterSettings::default(),
        freedom: Default::default(),
    }
}

#[test]
fn the_case_study_plan_keeps_the_explored_route_and_drops_the_second_lap() {
    let log = wall_following();
    let stages =
        twindrive_mission::pipeline::run(log, &CALIBRATED, &limits(log), &case_study_settings())
            .unwrap();
    let s = stages.summary();
    // Coverage of the route as driven, at 0.15 m, by the plan itself.
    let c = twindrive_mission::redundancy::route_coverage(
        &stages.executed,
        &stages.filtered.samples,
        0.15,
    )
    .unwrap();
    assert!(c.covered_percent >= 99.0, "{c:?}");
    assert_eq!(s.coverage, stages.coverage);
    assert!(
        c.plan_length_m <= 0.65 * c.route_length_m,
        "the second lap is gone: plan {} m of {} m",
        c.plan_length_m,
        c.route_length_m
    );
    assert!(s.reversing_m < 0.05, "backwards {} m", s.reversing_m);
    assert!(s.kinks_removed >= 2 && s.trailing_retrace_m > 5.0, "{s:?}");
    assert!(s.deletion_list.iter().all(|d| d.uncovered_m == 0.0));
    // The refused cut is the old answer: the first lap, with the ~3.5 m
    // of route only it explored.
    assert!(
        s.refused_cuts
            .iter()
            .any(|r| r.length_m > 12.0 && (2.5..4.5).contains(&r.would_drop_m)),
        "{:?}",
        s.refused_cuts
    );

    // Replayed on the twin's true robot: no wall touched.
    let samples: Vec<_> = stages
        .filtered
        .samples
        .iter()
        .zip(&stages.filtered.commands)
        .map(|(p, c)| twindrive_mission::plan::plan_sample(p, c, false))
        .collect();
    let open = twindrive_mission::verify::open_loop(
        &samples,
        scenario(),
        None,
        &FreedomMap::unconstrained(),
    )
    .unwrap();
    let closed = twindrive_mission::verify::closed_loop(
        &samples,
        scenario(),
        &CALIBRATED,
        &twindrive_mission::verify::TrackerSettings::default(),
        &FreedomMap::unconstrained(),
    )
    .unwrap();
    for r in [&open.report, &closed.report] {
        assert_eq!((r.collisions, r.bumps), (0, 0), "{r:?}");
    }
}

#[test]
fn a_two_lap_mission_stopped_anywhere_in_its_second_lap_keeps_its_coverage() {
    // The wall follower's lap takes about 70 s: stop early, half way and
    // nearly at the end of the second lap.
    for duration_s in [80.0, 100.0, 120.0, 135.0] {
        let mut sc = scenario();
        sc.steps = (duration_s * 1e9 / sc.dt_ns as f64).round() as u64;
        let log = twindrive_sim::Simulator::new(sc).run(|_, _| {});
        let stages = twindrive_mission::pipeline::run(
            &log,
            &CALIBRATED,
            &limits(&log),
            &case_study_settings(),
        )
        .unwrap();
        let c = &stages.coverage;
        assert!(
            c.covered_percent >= 99.0,
            "stopped at {duration_s} s: {c:?}"
        );
        assert!(
            c.plan_length_m < 0.9 * c.route_length_m,
            "stopped at {duration_s} s: the retrace is cut ({} of {} m)",
            c.plan_length_m,
            c.route_length_m
        );
    }
}
