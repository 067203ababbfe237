//! One predict + update of the augmented EKF, and a whole offline run.
//! `cargo bench -p twindrive-estimation --bench ekf`

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};

#[path = "../tests/common.rs"]
mod common;
use twindrive_estimation::{
    AugmentedEkf, FilterConfig, GateConfig, PoseSample, StateAndCovariance, WheelSample, run_filter,
};

fn calibration_drive() -> (Vec<WheelSample>, Vec<PoseSample>) {
    common::samples(&common::simulate(
        common::scenario("calibration_drive.toml"),
        None,
        None,
    ))
}

fn config() -> FilterConfig {
    let mut c = FilterConfig::default();
    c.noise.position_std_m = 0.001;
    c.noise.heading_std_rad = 0.002;
    c.noise.wheel_rad2_per_rad = 1e-6;
    c.gate = GateConfig {
        max_consecutive_rejections: usize::MAX,
        ..GateConfig::default()
    };
    c
}

fn benches(c: &mut Criterion) {
    let (wheels, poses) = calibration_drive();
    let nominal = [0.066, 0.066, 0.26];

    // Steady state: start from the converged run's estimate, then cycle
    // through real increments and poses.
    let run =
        run_filter(&wheels, &poses, nominal, 0.1, config(), false, |_, _| {}).expect("filter runs");
    let steady = StateAndCovariance {
        state: run.estimate.state,
        covariance: run.estimate.covariance,
    };
    let rows: Vec<(f64, f64, PoseSample)> = poses
        .windows(2)
        .filter_map(|w| {
            let a = twindrive_estimation::dead_reckoning::wheel_angles_at(&wheels, w[0].t_s)?;
            let b = twindrive_estimation::dead_reckoning::wheel_angles_at(&wheels, w[1].t_s)?;
            Some((b.0 - a.0, b.1 - a.1, w[1]))
        })
        .collect();
    let mut group = c.benchmark_group("ekf");
    group.throughput(Throughput::Elements(1));
    group.bench_function("predict_update", |b| {
        let mut ekf = AugmentedEkf::new(steady, config().noise, config().gate);
        let mut k = 0;
        b.iter(|| {
            let (l, r, p) = rows[k];
            k = if k + 1 == rows.len() { 0 } else { k + 1 };
            ekf.predict(l, r, 0.008);
            // Re-anchor the pose on the sample so the cycle stays consistent.
            black_box(
                ekf.update_pose(p.t_s, p.x_m, p.y_m, p.heading_rad.unwrap_or(0.0))
                    .ok(),
            );
        })
    });
    group.finish();

    let mut group = c.benchmark_group("offline");
    group.sample_size(20);
    group.throughput(Throughput::Elements((wheels.len() + poses.len()) as u64));
    group.bench_function("calibration_drive_130s", |b| {
        b.iter(|| {
            black_box(
                run_filter(&wheels, &poses, nominal, 0.1, config(), false, |_, _| {})
                    .expect("runs"),
            )
        })
    });
    group.bench_function("calibration_drive_130s_with_history_and_smoother", |b| {
        b.iter(|| {
            let run =
                run_filter(&wheels, &poses, nominal, 0.1, config(), true, |_, _| {}).expect("runs");
            black_box(twindrive_estimation::smooth(&run).expect("smooths"))
        })
    });
    group.finish();
}

criterion_group!(ekf, benches);
criterion_main!(ekf);
