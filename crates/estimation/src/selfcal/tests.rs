//! Synthetic drives: random robots, mounts and motions, with and without
//! noise.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::*;
use crate::NoiseModel;

/// A random robot: wheels 4-20 cm (the two within 2 %), wheelbase 8-60 cm,
/// lidar anywhere within ±10 cm and at any heading.
fn random_truth(rng: &mut ChaCha8Rng) -> [f64; 6] {
    let d = rng.random_range(0.04..0.2);
    [
        d * (1.0 + rng.random_range(-0.02..0.02)),
        d * (1.0 + rng.random_range(-0.02..0.02)),
        rng.random_range(0.08..0.6),
        rng.random_range(-0.1..0.1),
        rng.random_range(-0.1..0.1),
        rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
    ]
}

#[derive(Clone, Copy, PartialEq)]
enum Drive {
    /// Spins in place, arcs of many curvatures, straight stretches.
    Rich,
    /// Straight lines only (forwards and backwards).
    Straight,
    /// Arcs of one curvature only.
    OneCurvature,
}

/// Noise of a synthetic drive.
#[derive(Clone, Copy)]
struct Noise {
    /// Laser [σx (m), σy (m), σθ (rad)].
    laser: [f64; 3],
    /// Wheel noise per step (as the fit's `NoiseModel`).
    wheel_rad2_per_rad: f64,
    /// Gyro: (bias rad/s, scale error, σ_g rad/√s).
    gyro: Option<(f64, f64, f64)>,
}

const NOISE_FREE: Noise = Noise {
    laser: [0.0; 3],
    wheel_rad2_per_rad: 0.0,
    gyro: None,
};

/// `n` motions of about a second, each 1-8 encoder steps at varying
/// speeds (one step when `single_step`).
fn drive(
    rng: &mut ChaCha8Rng,
    truth: [f64; 6],
    kind: Drive,
    n: usize,
    noise: Noise,
    single_step: bool,
) -> Vec<RelativeMotion> {
    let [dl, dr, b, ..] = truth;
    let gauss = |rng: &mut ChaCha8Rng, s: f64| {
        if s > 0.0 {
            Normal::new(0.0, s).unwrap().sample(rng)
        } else {
            0.0
        }
    };
    let one_curvature = rng.random_range(-3.0..3.0);
    let mut t = 0.0;
    (0..n)
        .map(|k| {
            // Body travel (m) and turn (rad) over the motion.
            let (travel, turn) = match kind {
                Drive::Straight => (rng.random_range(-0.3..0.3), 0.0),
                Drive::OneCurvature => {
                    let s = rng.random_range(0.05..0.3);
                    (s, one_curvature * s)
                }
                Drive::Rich => match k % 4 {
                    0 => (0.0, rng.random_range(-1.2..1.2)),
                    1 => (rng.random_range(-0.3..0.3), 0.0),
                    _ => {
                        let s = rng.random_range(-0.3..0.3);
                        (s, s * rng.random_range(-6.0..6.0))
                    }
                },
            };
            let steps = if single_step {
                1
            } else {
                rng.random_range(1..9)
            };
            let weights: Vec<f64> = (0..steps).map(|_| rng.random_range(0.2..1.0)).collect();
            let total: f64 = weights.iter().sum();
            let true_steps: Vec<[f64; 2]> = weights
                .iter()
                .map(|w| {
                    let (s, a) = (travel * w / total, turn * w / total);
                    // s = (sL + sR)/2, a = (sR − sL)/b, s_i = d_i φ_i / 2.
                    let (sl, sr) = (s - 0.5 * a * b, s + 0.5 * a * b);
                    [2.0 * sl / dl, 2.0 * sr / dr]
                })
                .collect();
            let mut laser = predict_laser_motion(&true_steps, truth);
            for (v, s) in laser.iter_mut().zip(noise.laser) {
                *v += gauss(rng, s);
            }
            let measured: Vec<[f64; 2]> = true_steps
                .iter()
                .map(|s| s.map(|w| w + gauss(rng, (noise.wheel_rad2_per_rad * w.abs()).sqrt())))
                .collect();
            let duration = rng.random_range(0.5..1.5);
            let gyro_rad = noise.gyro.map(|(bias, scale, sigma)| {
                (1.0 + scale) * turn + bias * duration + gauss(rng, sigma * duration.sqrt())
            });
            let m = RelativeMotion {
                t0_s: t,
                t1_s: t + duration,
                wheel_steps: measured,
                laser,
                laser_cov: None,
                gyro_rad,
            };
            t += duration;
            m
        })
        .collect()
}

fn noise_model(wheel_rad2_per_rad: f64) -> NoiseModel {
    NoiseModel {
        wheel_rad2_per_rad,
        wheel_floor_rad2: 0.0,
        ..NoiseModel::default()
    }
}

/// |a − b| per parameter: relative for dL, dR, b; metres and radians
/// (wrapped) for the mount.
fn errors(est: [f64; 6], truth: [f64; 6]) -> [f64; 6] {
    std::array::from_fn(|i| match i {
        0..=2 => (est[i] / truth[i] - 1.0).abs(),
        5 => twindrive_kinematics::wrap_angle(est[i] - truth[i]).abs(),
        _ => (est[i] - truth[i]).abs(),
    })
}

fn six(r: &SelfCalResult) -> ([f64; 6], [f64; 6]) {
    let p = [
        r.params[0],
        r.params[1],
        r.params[2],
        r.mount[0],
        r.mount[1],
        r.mount[2],
    ];
    let s = [
        r.std[0],
        r.std[1],
        r.std[2],
        r.mount_std[0],
        r.mount_std[1],
        r.mount_std[2],
    ];
    (p, s)
}

#[test]
fn noise_free_motions_are_recovered_exactly_from_no_guess() {
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    for case in 0..20 {
        let mut truth = random_truth(&mut rng);
        if case < 4 {
            // Lidars mounted backwards, either side of ±180°.
            truth[5] = [170f64, -170.0, 179.0, -179.5][case].to_radians();
        }
        // One arc per motion: Censi's closed form is exact.
        let motions = drive(&mut rng, truth, Drive::Rich, 60, NOISE_FREE, true);
        let cf = closed_form(&motions).expect("closed form");
        let e = errors(cf.params, truth);
        assert!(
            e.iter().all(|v| *v < 1e-9),
            "case {case}: closed form {e:?}"
        );
        // Several steps per motion at varying speeds: the closed form is
        // close, the fit over every step exact.
        let motions = drive(&mut rng, truth, Drive::Rich, 60, NOISE_FREE, false);
        let cf = closed_form(&motions).expect("closed form");
        let e = errors(cf.params, truth);
        assert!(e.iter().all(|v| *v < 0.2), "case {case}: closed form {e:?}");
        let ml = fit(&motions, cf.params, &SelfCalConfig::default()).unwrap();
        let e = errors(six(&ml).0, truth);
        assert!(e.iter().all(|v| *v < 1e-9), "case {case}: fit {e:?}");
    }
}

#[test]
fn noisy_estimates_are_within_three_reported_standard_deviations() {
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    let (mut checks, mut within_one) = (0, 0);
    for case in 0..12 {
        let truth = random_truth(&mut rng);
        let noise = Noise {
            laser: [0.002, 0.002, 0.3f64.to_radians()],
            wheel_rad2_per_rad: 1e-5,
            gyro: None,
        };
        let motions = drive(&mut rng, truth, Drive::Rich, 400, noise, false);
        let cf = closed_form(&motions).expect("closed form");
        let cfg = SelfCalConfig {
            noise: noise_model(noise.wheel_rad2_per_rad),
            ..SelfCalConfig::default()
        };
        let ml = fit(&motions, cf.params, &cfg).unwrap();
        let (p, s) = six(&ml);
        for i in 0..6 {
            let err = if i == 5 {
                twindrive_kinematics::wrap_angle(p[i] - truth[i])
            } else {
                p[i] - truth[i]
            };
            assert!(
                err.abs() <= 3.0 * s[i],
                "case {case}, parameter {i}: error {err:.3e} against σ {:.3e}",
                s[i]
            );
            checks += 1;
            within_one += usize::from(err.abs() <= s[i]);
        }
        // The fitted laser noise is the simulated one.
        let fitted = ml.laser_noise.axis_std.unwrap();
        for (f, t) in fitted.iter().zip(noise.laser) {
            assert!((f / t - 1.0).abs() < 0.2, "case {case}: laser σ {fitted:?}");
        }
        assert!(
            ml.identifiability.separable(),
            "{}",
            ml.identifiability.verdict
        );
    }
    // About 68 % within one σ: the standard deviations are not inflated.
    let share = within_one as f64 / checks as f64;
    assert!((0.5..0.85).contains(&share), "{share} within 1σ");
}

#[test]
fn gyro_bias_and_scale_are_fitted() {
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    for case in 0..6 {
        let truth = random_truth(&mut rng);
        let (bias, scale) = (rng.random_range(-0.01..0.01), rng.random_range(-0.03..0.03));
        // Noise-free first: exact, gyro included.
        let gyro = Noise {
            gyro: Some((bias, scale, 0.0)),
            ..NOISE_FREE
        };
        let motions = drive(&mut rng, truth, Drive::Rich, 80, gyro, false);
        let cf = closed_form(&motions).unwrap();
        let ml = fit(&motions, cf.params, &SelfCalConfig::default()).unwrap();
        let g = ml.gyro.unwrap();
        assert!(
            (g.bias_rad_s - bias).abs() < 1e-9 && (g.scale_error - scale).abs() < 1e-9,
            "case {case}: {g:?} against {bias}, {scale}"
        );
        assert!(errors(six(&ml).0, truth).iter().all(|v| *v < 1e-9));
        assert_eq!(ml.identifiability.parameters.len(), 8);
        // Noisy: within 3σ.
        let noise = Noise {
            laser: [0.002, 0.002, 0.3f64.to_radians()],
            wheel_rad2_per_rad: 1e-5,
            gyro: Some((bias, scale, 0.002)),
        };
        let motions = drive(&mut rng, truth, Drive::Rich, 400, noise, false);
        let cf = closed_form(&motions).unwrap();
        let cfg = SelfCalConfig {
            noise: noise_model(noise.wheel_rad2_per_rad),
            ..SelfCalConfig::default()
        };
        let ml = fit(&motions, cf.params, &cfg).unwrap();
        let g = ml.gyro.unwrap();
        assert!(
            (g.bias_rad_s - bias).abs() <= 3.0 * g.bias_std_rad_s,
            "case {case}: {g:?} against bias {bias}"
        );
        assert!(
            (g.scale_error - scale).abs() <= 3.0 * g.scale_error_std,
            "case {case}: {g:?} against scale {scale}"
        );
        assert!((g.noise_rad_per_sqrt_s / 0.002 - 1.0).abs() < 0.25, "{g:?}");
    }
}

#[test]
fn matcher_covariances_are_scaled_to_the_residuals() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let truth = random_truth(&mut rng);
    let noise = Noise {
        laser: [0.003, 0.001, 0.2f64.to_radians()],
        ..NOISE_FREE
    };
    let mut motions = drive(&mut rng, truth, Drive::Rich, 300, noise, false);
    // The matcher reports half the true standard deviations: α ≈ 4.
    let half = noise.laser.map(|s| 0.25 * s * s);
    for m in &mut motions {
        m.laser_cov = Some([
            [half[0], 0.0, 0.0],
            [0.0, half[1], 0.0],
            [0.0, 0.0, half[2]],
        ]);
    }
    let cf = closed_form(&motions).unwrap();
    let cfg = SelfCalConfig {
        noise: noise_model(0.0),
        ..SelfCalConfig::default()
    };
    let ml = fit(&motions, cf.params, &cfg).unwrap();
    let alpha = ml.laser_noise.covariance_scale.unwrap();
    assert!((alpha / 4.0 - 1.0).abs() < 0.2, "α = {alpha}");
    assert!(ml.laser_noise.axis_std.is_none());
    let (p, s) = six(&ml);
    for i in 0..6 {
        let err = twindrive_kinematics::wrap_angle(p[i] - truth[i]);
        assert!(
            err.abs() <= 3.0 * s[i],
            "parameter {i}: {err:.2e} vs σ {:.2e}",
            s[i]
        );
    }
}

#[test]
fn a_drive_of_straight_lines_cannot_pin_the_wheelbase_or_the_mount() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let truth = random_truth(&mut rng);
    let noise = Noise {
        laser: [0.002, 0.002, 0.005],
        ..NOISE_FREE
    };
    let motions = drive(&mut rng, truth, Drive::Straight, 200, noise, false);
    // Censi's first step refuses (the wheels always turn in one ratio).
    assert!(closed_form(&motions).is_none());
    // From a rough guess the fit runs, but says what it cannot pin.
    let guess = [
        truth[0] * 1.02,
        truth[1] * 0.98,
        truth[2] * 1.1,
        0.0,
        0.0,
        truth[5] + 0.1,
    ];
    let ml = fit(&motions, guess, &SelfCalConfig::default()).unwrap();
    let id = &ml.identifiability;
    assert!(!id.separable() && !id.well_determined, "{id:?}");
    assert!(!id.pins_every_parameter(0.05));
    // b, ℓx and ℓy are unobserved: with no turn, neither the wheelbase nor
    // the lidar's position changes anything.
    assert!(
        id.verdict
            .contains("cannot separate the lidar's mount from the wheelbase")
            && id.verdict.contains("combinations of b, lx, ly are"),
        "{}",
        id.verdict
    );
    assert!(id.verdict.contains("turn in place"), "{}", id.verdict);
    println!("straight lines: {}", id.verdict);
    // The fit's own standard deviations agree: b and the lidar's position
    // are free, the wheel diameters and the lidar's heading are not.
    assert!(
        ml.std[2].is_infinite() && ml.mount_std[0].is_infinite() && ml.mount_std[1].is_infinite()
    );
    assert!(ml.std[0].is_finite() && ml.std[1].is_finite() && ml.mount_std[2].is_finite());
    assert!((ml.mount[2] - truth[5]).abs() < 0.01, "{:?}", ml.mount);
}

#[test]
fn a_drive_of_one_curvature_cannot_pin_every_parameter() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for _ in 0..5 {
        let truth = random_truth(&mut rng);
        let noise = Noise {
            laser: [0.002, 0.002, 0.005],
            ..NOISE_FREE
        };
        let motions = drive(&mut rng, truth, Drive::OneCurvature, 200, noise, false);
        let guess = [
            truth[0] * 1.01,
            truth[1],
            truth[2] * 0.95,
            0.0,
            0.0,
            truth[5],
        ];
        let ml = fit(&motions, guess, &SelfCalConfig::default()).unwrap();
        let id = &ml.identifiability;
        assert!(!id.separable() && !id.pins_every_parameter(0.05), "{id:?}");
        assert!(id.verdict.contains("cannot separate"), "{}", id.verdict);
        assert!(
            id.verdict.contains("two different curvatures"),
            "{}",
            id.verdict
        );
        println!("one curvature: {}", id.verdict);
    }
}

#[test]
fn too_few_or_unusable_motions_are_errors() {
    let mut rng = ChaCha8Rng::seed_from_u64(10);
    let truth = random_truth(&mut rng);
    let motions = drive(&mut rng, truth, Drive::Rich, 40, NOISE_FREE, false);
    let few = &motions[..MIN_MOTIONS - 1];
    assert!(closed_form(few).is_none());
    let err = fit(few, truth, &SelfCalConfig::default()).unwrap_err();
    assert!(err.to_string().contains("at least"), "{err}");
    assert!(fit(&[], truth, &SelfCalConfig::default()).is_err());

    let mut bad = motions.clone();
    bad[3].laser[1] = f64::NAN;
    assert!(closed_form(&bad).is_none());
    let err = fit(&bad, truth, &SelfCalConfig::default()).unwrap_err();
    assert!(err.to_string().contains("motion 3"), "{err}");

    let mut bad = motions.clone();
    bad[5].laser_cov = Some([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]);
    assert!(fit(&bad, truth, &SelfCalConfig::default()).is_err());

    let mut bad = motions.clone();
    bad[7].t1_s = bad[7].t0_s - 1.0;
    assert!(fit(&bad, truth, &SelfCalConfig::default()).is_err());

    let mut bad_guess = truth;
    bad_guess[2] = -0.3;
    assert!(fit(&motions, bad_guess, &SelfCalConfig::default()).is_err());
    bad_guess[2] = f64::INFINITY;
    assert!(fit(&motions, bad_guess, &SelfCalConfig::default()).is_err());
    let cfg = SelfCalConfig {
        trim_probability: 0.3,
        ..SelfCalConfig::default()
    };
    assert!(fit(&motions, truth, &cfg).is_err());
    let cfg = ClosedFormConfig {
        outlier_fraction: 0.0,
        ..ClosedFormConfig::default()
    };
    assert!(closed_form_with(&motions, &cfg).is_none());
    // Standing still everywhere: nothing to calibrate, no panic.
    let still: Vec<RelativeMotion> = (0..20)
        .map(|k| RelativeMotion::constant_speed(k as f64, k as f64 + 1.0, [0.0; 2], [0.0; 3]))
        .collect();
    assert!(closed_form(&still).is_none());
    if let Ok(r) = fit(&still, truth, &SelfCalConfig::default()) {
        assert!(!r.identifiability.separable());
    }
}

#[test]
fn the_fit_is_deterministic_and_fast_enough() {
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let truth = random_truth(&mut rng);
    let noise = Noise {
        laser: [0.001, 0.001, 0.003],
        wheel_rad2_per_rad: 1e-5,
        gyro: Some((0.002, 0.01, 0.001)),
    };
    let motions = drive(&mut rng, truth, Drive::Rich, 4000, noise, false);
    let cf = closed_form(&motions).unwrap();
    let started = std::time::Instant::now();
    let a = fit(&motions, cf.params, &SelfCalConfig::default()).unwrap();
    let elapsed = started.elapsed();
    let b = fit(&motions, cf.params, &SelfCalConfig::default()).unwrap();
    assert_eq!(a, b);
    // Well under a second in the (optimised) dev profile; generous here
    // for a loaded machine.
    assert!(elapsed.as_secs_f64() < 2.0, "{elapsed:?}");
}
