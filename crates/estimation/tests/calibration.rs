//! Calibration on simulated drives: recovered parameters near the truth,
//! consistent covariance, every path agrees, bad data is handled.

mod common;

use twindrive_estimation::batch::{self, BatchConfig};
use twindrive_estimation::{
    FilterConfig, FilterRun, OnlineCalibrator, PoseSample, StateAndCovariance, StateVec,
    WheelSample, clock, initial_estimate, nees, run_filter, smooth,
};
use twindrive_log::MissionLog;

/// The twin's tracker noise, and wheel noise for its slip and quantisation.
fn sim_config() -> FilterConfig {
    let mut cfg = FilterConfig::default();
    cfg.noise.position_std_m = 0.001;
    cfg.noise.heading_std_rad = 0.002;
    cfg.noise.wheel_rad2_per_rad = 1e-6;
    cfg.noise.wheel_floor_rad2 = 1e-9;
    cfg
}

/// The filter from the nominal guess with 10 % parameter uncertainty.
fn filter(
    wheels: &[WheelSample],
    poses: &[PoseSample],
    cfg: FilterConfig,
    history: bool,
) -> FilterRun {
    run_filter(wheels, poses, common::NOMINAL, 0.1, cfg, history, |_, _| {}).unwrap()
}

/// The batch fit from the nominal guess with the twin's noise.
fn batch_fit(wheels: &[WheelSample], poses: &[PoseSample]) -> batch::BatchResult {
    let cfg = BatchConfig {
        noise: sim_config().noise,
        ..BatchConfig::default()
    };
    batch::fit(wheels, poses, common::NOMINAL, &cfg).unwrap()
}

fn rel_err(est: f64, truth: f64) -> f64 {
    (est / truth - 1.0).abs()
}

fn calibration_log() -> MissionLog {
    common::simulate(common::scenario("calibration_drive.toml"), None, None)
}

fn truth_at(log: &MissionLog, t_s: f64) -> StateVec {
    let k = (t_s / log.header.dt_s).round() as usize;
    let g = log.steps[k].ground_truth;
    assert!((log.steps[k].t_s() - t_s).abs() < 1e-9);
    StateVec::new(
        g.x_m,
        g.y_m,
        g.heading_rad,
        common::TRUTH[0],
        common::TRUTH[1],
        common::TRUTH[2],
    )
}

#[test]
fn all_methods_recover_the_parameters_within_a_tenth_of_a_percent() {
    let log = calibration_log();
    let (wheels, poses) = common::samples(&log);
    let run = filter(&wheels, &poses, sim_config(), true);
    let smoothed = smooth(&run).unwrap();
    let b = batch_fit(&wheels, &poses);
    for i in 0..3 {
        let ekf = run.estimate.state[3 + i];
        let smo = smoothed[0].state[3 + i];
        let truth = common::TRUTH[i];
        assert!(
            rel_err(ekf, truth) < 1e-3,
            "EKF parameter {i}: {ekf} vs {truth}"
        );
        assert!(
            rel_err(smo, truth) < 1e-3,
            "smoother parameter {i}: {smo} vs {truth}"
        );
        assert!(
            rel_err(b.params[i], truth) < 1e-3,
            "batch parameter {i}: {} vs {truth}",
            b.params[i]
        );
        // The nominal guess was a few percent off: the filter really moved.
        assert!(rel_err(common::NOMINAL[i], truth) > 5e-3);
        // EKF and batch agree with each other.
        assert!(
            rel_err(ekf, b.params[i]) < 1e-3,
            "EKF {ekf} vs batch {}",
            b.params[i]
        );
    }
    assert!(
        b.identifiability.well_determined,
        "{}",
        b.identifiability.verdict
    );
    // Innovations consistent with the tracker noise: mean NIS near 3.
    let nis = run.stats.mean_nis();
    assert!((2.5..3.5).contains(&nis), "mean NIS {nis}");
}

#[test]
fn covariance_is_consistent_nees_inside_chi_square_bounds() {
    // Monte Carlo over seeds, with wheel slip dominating quantisation so the
    // filter's wheel-noise model is the true one: slip σ = 5 % per 1 ms step
    // gives a rotation variance of σ² ω dt ≈ 1e-5 rad² per rad at ~4 rad/s.
    let runs = 12;
    let (mut param_nees, mut pose_nees) = (0.0, 0.0);
    for seed in 0..runs {
        let mut sc = common::scenario("calibration_drive.toml");
        sc.robot.slip_std = 0.05;
        sc.robot.encoder.ticks_per_rev = 4096;
        let log = common::simulate(sc, Some(500 + seed), Some(100.0));
        let (wheels, poses) = common::samples(&log);
        let mut cfg = sim_config();
        cfg.noise.wheel_rad2_per_rad = 1e-5;
        cfg.noise.wheel_floor_rad2 = 1e-10;
        let run = filter(&wheels, &poses, cfg, false);
        let est = StateAndCovariance {
            state: run.estimate.state,
            covariance: run.estimate.covariance,
        };
        let truth = truth_at(&log, run.estimate.t_s);
        param_nees += nees(&est, &truth, &[3, 4, 5]) / runs as f64;
        pose_nees += nees(&est, &truth, &[0, 1, 2]) / runs as f64;
    }
    // Two-sided 99 % bounds of the mean of `runs` chi-square(3) variables.
    let dof = 3 * runs as usize;
    let lo = twindrive_estimation::chi2_quantile(dof, 0.005) / runs as f64;
    let hi = twindrive_estimation::chi2_quantile(dof, 0.995) / runs as f64;
    assert!(
        (lo..hi).contains(&param_nees),
        "parameter NEES {param_nees} outside [{lo}, {hi}]"
    );
    assert!(
        (lo..hi).contains(&pose_nees),
        "pose NEES {pose_nees} outside [{lo}, {hi}]"
    );
}

/// Merges both streams in time order, as a live robot would deliver them.
fn live_order(
    wheels: &[WheelSample],
    poses: &[PoseSample],
) -> Vec<Result<WheelSample, PoseSample>> {
    let mut all: Vec<(f64, u8, Result<WheelSample, PoseSample>)> = wheels
        .iter()
        .map(|w| (w.t_s, 1, Ok(*w)))
        .chain(poses.iter().map(|p| (p.t_s, 0, Err(*p))))
        .collect();
    all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    all.into_iter().map(|x| x.2).collect()
}

#[test]
fn online_and_offline_give_the_same_estimate() {
    let log = common::simulate(common::scenario("calibration_drive.toml"), None, Some(40.0));
    let (wheels, poses) = common::samples(&log);
    let cfg = sim_config();
    let offline = filter(&wheels, &poses, cfg, false);

    let first = *poses.iter().find(|p| p.t_s >= wheels[0].t_s).unwrap();
    let init = initial_estimate(&first, common::NOMINAL, &cfg.noise, 0.1);
    let mut online = OnlineCalibrator::new(init, first.t_s, cfg, false);
    for sample in live_order(&wheels, &poses) {
        match sample {
            Ok(w) => online.push_wheels(w).unwrap(),
            Err(p) if p.t_s > first.t_s && p.t_s <= wheels.last().unwrap().t_s => {
                online.push_pose(p).unwrap()
            }
            Err(_) => {}
        }
    }
    let on = online.estimate();
    assert_eq!(on.t_s, offline.estimate.t_s);
    assert_eq!(
        on.state, offline.estimate.state,
        "online and offline differ"
    );
    assert_eq!(on.covariance, offline.estimate.covariance);
}

#[test]
fn a_pose_between_encoder_samples_is_fused_at_its_own_time() {
    // Encoders at 50 Hz, tracker at 120 Hz: most poses fall between encoder
    // samples. Splitting the increment at the pose time matters: fusing each
    // pose at the next encoder sample instead is clearly worse.
    let log = calibration_log();
    let (wheels, poses) = common::samples(&log);
    let exact = filter(&wheels, &poses, sim_config(), false);
    let snapped: Vec<PoseSample> = poses
        .iter()
        .map(|p| {
            let k = wheels
                .partition_point(|w| w.t_s < p.t_s)
                .min(wheels.len() - 1);
            PoseSample {
                t_s: wheels[k].t_s,
                ..*p
            }
        })
        .collect();
    let mut dedup = snapped.clone();
    dedup.dedup_by(|a, b| a.t_s == b.t_s);
    let late = filter(&wheels, &dedup, sim_config(), false);
    let err = |s: &StateVec| {
        (0..3)
            .map(|i| rel_err(s[3 + i], common::TRUTH[i]))
            .fold(0.0, f64::max)
    };
    assert!(err(&exact.estimate.state) < 1e-3);
    assert!(
        err(&late.estimate.state) > 2.0 * err(&exact.estimate.state),
        "exact {} vs snapped {}",
        err(&exact.estimate.state),
        err(&late.estimate.state)
    );
}

#[test]
fn smoother_is_at_least_as_good_as_the_filter() {
    let log = common::simulate(common::scenario("calibration_drive.toml"), None, Some(60.0));
    let (wheels, poses) = common::samples(&log);
    let run = filter(&wheels, &poses, sim_config(), true);
    let history = run.history.as_ref().unwrap();
    let smoothed = smooth(&run).unwrap();
    let (mut filt_sq, mut smooth_sq) = (0.0, 0.0);
    for (k, t) in history.t_s.iter().enumerate() {
        let truth = truth_at(&log, *t);
        let f = &history.filtered[k].state;
        let s = &smoothed[k].state;
        filt_sq += (f[0] - truth[0]).powi(2) + (f[1] - truth[1]).powi(2);
        smooth_sq += (s[0] - truth[0]).powi(2) + (s[1] - truth[1]).powi(2);
    }
    // Constant parameters: every smoothed node carries the final filtered
    // parameters (all the data), which the filter only reaches at the end.
    for i in 3..6 {
        let fin = run.estimate.state[i];
        assert!(
            smoothed
                .iter()
                .all(|s| (s.state[i] / fin - 1.0).abs() < 1e-9),
            "parameter {i}"
        );
    }
    assert!(
        smooth_sq < filt_sq,
        "smoothed position error {smooth_sq} vs filtered {filt_sq}"
    );
    // Smoothed covariances are no larger than filtered ones.
    for (f, s) in history.filtered.iter().zip(&smoothed) {
        for i in 0..6 {
            assert!(s.covariance[(i, i)] <= f.covariance[(i, i)] * (1.0 + 1e-6) + 1e-18);
        }
    }
}

#[test]
fn a_single_circle_cannot_separate_the_parameters() {
    let mut sc = common::scenario("calibration_drive.toml");
    let twindrive_sim::ControllerConfig::Scripted(spec) = &mut sc.controller else {
        panic!()
    };
    spec.segments.truncate(1); // one constant wheel-speed ratio: one curvature
    spec.segments[0].duration_s = 60.0;
    let log = common::simulate(sc, None, Some(60.0));
    let (wheels, poses) = common::samples(&log);
    let b = batch_fit(&wheels, &poses);
    let id = &b.identifiability;
    assert!(!id.well_determined, "{id:?}");
    assert!(
        id.verdict.contains("cannot separate") && id.verdict.contains("curvature"),
        "{}",
        id.verdict
    );
    assert!(id.condition_number > 1e4, "{}", id.condition_number);
}

#[test]
fn an_outlier_burst_is_rejected() {
    let log = calibration_log();
    let (wheels, mut poses) = common::samples(&log);
    // A tracker glitch: 40 consecutive poses (a third of a second) 0.4 m off.
    let start = poses.len() / 2;
    for p in &mut poses[start..start + 40] {
        p.x_m += 0.4;
    }
    let run = filter(&wheels, &poses, sim_config(), true);
    assert!(run.stats.rejected >= 40, "{} rejected", run.stats.rejected);
    let glitch: Vec<_> = run
        .history
        .as_ref()
        .unwrap()
        .innovations
        .iter()
        .filter(|r| r.innovation[0] > 0.3)
        .collect();
    assert_eq!(glitch.len(), 40);
    assert!(glitch.iter().all(|r| !r.accepted));
    for i in 0..3 {
        assert!(rel_err(run.estimate.state[3 + i], common::TRUTH[i]) < 1e-3);
    }
}

#[test]
fn the_clock_offset_is_recovered() {
    let log = common::simulate(
        common::scenario("calibration_drive.toml"),
        None,
        Some(100.0),
    );
    let (wheels, poses) = common::samples(&log);
    let shift = -1_520_000_000.337;
    let shifted: Vec<PoseSample> = poses
        .iter()
        .map(|p| PoseSample {
            t_s: p.t_s + shift,
            ..*p
        })
        .collect();
    let found = clock::estimate_offset(&wheels, &shifted, common::NOMINAL, 30.0).unwrap();
    assert!(
        (found.offset_s - shift).abs() < 0.02,
        "found {} for {shift}",
        found.offset_s
    );
    assert!(found.correlation > 0.5);
}

#[test]
fn gated_outcome_is_reported() {
    let log = common::simulate(common::scenario("calibration_drive.toml"), None, Some(5.0));
    let (wheels, poses) = common::samples(&log);
    let init = initial_estimate(&poses[0], common::NOMINAL, &sim_config().noise, 0.1);
    let mut cal = OnlineCalibrator::new(init, poses[0].t_s, sim_config(), false);
    cal.push_wheels(wheels[0]).unwrap();
    let far = PoseSample {
        t_s: wheels[0].t_s,
        x_m: 100.0,
        y_m: 0.0,
        heading_rad: Some(0.0),
    };
    cal.push_pose(far).unwrap();
    assert_eq!(cal.stats().rejected, 1);
    assert_eq!(cal.stats().accepted, 0);
    assert_eq!(
        cal.estimate().state[0],
        init.state[0],
        "the far pose moved nothing"
    );
}
