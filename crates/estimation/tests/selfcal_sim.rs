//! Self-calibration on the simulator: held-out random rooms with clutter,
//! random true kinematics, lidar mounts and gyro errors, a drive of spins
//! and arcs of two curvatures both ways with the lidar's scans and the
//! gyro's rates only (no pose reference). The estimate must come within
//! 0.3 % of the truth on each of dL, dR, b and within 1 cm and 0.5 degrees
//! on the mount.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twindrive_estimation::WheelSample;
use twindrive_estimation::localize::Scan;
use twindrive_estimation::selfcal::{
    LaserOdometrySettings, SelfCalConfig, closed_form, fit, laser_odometry,
};
use twindrive_log::MissionLog;

struct Site {
    toml: String,
    truth: [f64; 6],
    nominal: [f64; 3],
}

fn site(seed: u64) -> Site {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (w, h) = (rng.random_range(6.0..10.0), rng.random_range(6.0..10.0));
    let nominal = [0.066, 0.066, 0.26];
    let truth_w = [
        nominal[0] * (1.0 + rng.random_range(-0.03..0.03)),
        nominal[1] * (1.0 + rng.random_range(-0.03..0.03)),
        nominal[2] * (1.0 + rng.random_range(-0.03..0.03)),
    ];
    let mount = [
        rng.random_range(-0.05..0.05),
        rng.random_range(-0.05..0.05),
        rng.random_range(-3.1..3.1),
    ];
    // Clutter along the walls, clear of the robot's circles around the
    // middle.
    let mut rects = Vec::new();
    for _ in 0..rng.random_range(3..7) {
        let (bw, bh) = (rng.random_range(0.2..0.6), rng.random_range(0.2..0.6));
        let side = rng.random_range(0..4);
        let (x, y) = match side {
            0 => (rng.random_range(0.2..w - 0.8), 0.2),
            1 => (rng.random_range(0.2..w - 0.8), h - 0.8),
            2 => (0.2, rng.random_range(0.2..h - 0.8)),
            _ => (w - 0.8, rng.random_range(0.2..h - 0.8)),
        };
        rects.push(format!(
            "{{ min = [{x:.3}, {y:.3}], max = [{:.3}, {:.3}] }}",
            x + bw,
            y + bh
        ));
    }
    let noise = rng.random_range(0.01..0.03);
    let toml = format!(
        r#"name = "selfcal_{seed}"
[simulation]
duration_s = 120.0
dt_s = 0.005
seed = {seed}
[world]
polylines = [ {{ points = [[0.0, 0.0], [{w:.3}, 0.0], [{w:.3}, {h:.3}], [0.0, {h:.3}]], closed = true }} ]
rectangles = [ {rects} ]
[robot]
start = {{ x_m = {cx:.3}, y_m = {cy:.3}, heading_rad = 0.3 }}
footprint_radius_m = 0.15
max_wheel_speed_rad_s = 12.0
max_wheel_accel_rad_s2 = 30.0
slip_std = 0.001
true_params = {{ left_diameter_m = {:.6}, right_diameter_m = {:.6}, wheelbase_m = {:.6} }}
nominal_params = {{ left_diameter_m = 0.066, right_diameter_m = 0.066, wheelbase_m = 0.26 }}
[encoders]
ticks_per_rev = 2048
rate_hz = 50.0
[[range_sensors]]
name = "lidar"
mount = {{ x_m = {:.4}, y_m = {:.4}, heading_rad = {:.4} }}
beams = 360
fov_rad = 6.283185307179586
max_range_m = 12.0
noise_std_m = {noise:.4}
dropout_probability = 0.01
rate_hz = 10.0
[gyro]
rate_hz = 100.0
noise_std_rad_s = 0.002
bias_rad_s = 0.004
scale_error = 0.01
[controller]
kind = "scripted"
segments = [
  {{ duration_s = 15.0, left_rad_s = -1.5, right_rad_s = 1.5 }},
  {{ duration_s = 25.0, left_rad_s = 8.0, right_rad_s = 5.5 }},
  {{ duration_s = 25.0, left_rad_s = 5.5, right_rad_s = 8.0 }},
  {{ duration_s = 20.0, left_rad_s = 7.0, right_rad_s = 2.0 }},
  {{ duration_s = 20.0, left_rad_s = 2.0, right_rad_s = 7.0 }},
  {{ duration_s = 15.0, left_rad_s = 1.5, right_rad_s = -1.5 }},
]
"#,
        truth_w[0],
        truth_w[1],
        truth_w[2],
        mount[0],
        mount[1],
        mount[2],
        rects = rects.join(", "),
        cx = w / 2.0,
        cy = h / 2.0,
    );
    Site {
        toml,
        truth: [truth_w[0], truth_w[1], truth_w[2], mount[0], mount[1], mount[2]],
        nominal,
    }
}

fn scans(log: &MissionLog) -> Vec<Scan> {
    let info = &log.header.range_sensors[0];
    let (angle_min_rad, increment_rad) = info.angle_min_and_increment();
    (0..log.steps.len())
        .filter_map(|i| {
            let r = log.range_reading(i, 0)?;
            Some(Scan {
                t_s: log.steps[i].t_s(),
                angle_min_rad,
                increment_rad,
                range_min_m: info.min_range_m,
                range_max_m: info.max_range_m,
                ranges_m: r.iter().map(|v| *v as f32).collect(),
            })
        })
        .collect()
}

#[test]
fn self_calibration_on_held_out_rooms() {
    for seed in [90_001u64, 90_002, 90_003] {
        let s = site(seed);
        let scenario = twindrive_sim::Scenario::from_toml(&s.toml, std::path::Path::new("selfcal.toml"))
            .expect("the scenario is valid");
        let log = twindrive_sim::Simulator::new(scenario).run(|_, _| {});
        let wheels: Vec<WheelSample> = log
            .wheel_angles()
            .map(|(t_s, left_rad, right_rad)| WheelSample { t_s, left_rad, right_rad })
            .collect();
        let gyro: Vec<(f64, f64)> = log.gyro_rates().collect();
        let scans = scans(&log);
        let guess = [s.nominal[0], s.nominal[1], s.nominal[2], 0.0, 0.0, 0.0];
        let t = std::time::Instant::now();
        let interval_s: f64 = std::env::var("IV").ok().and_then(|v| v.parse().ok()).unwrap_or(0.5);
        let settings = LaserOdometrySettings { interval_s, ..LaserOdometrySettings::default() };
        let odo = laser_odometry(&scans, &wheels, &gyro, guess, &settings, |_, _| {});
        let t_odo = t.elapsed();
        let cf = closed_form(&odo.motions);
        let start = cf.as_ref().map_or(guess, |c| c.params);
        let r = fit(&odo.motions, start, &SelfCalConfig::default()).expect("a fit");
        let est = [r.params[0], r.params[1], r.params[2], r.mount[0], r.mount[1], r.mount[2]];
        let rel: Vec<f64> = (0..3).map(|i| 100.0 * (est[i] / s.truth[i] - 1.0)).collect();
        eprintln!(
            "seed {seed}: {} scans, {} consecutive ({:?} refused), {} intervals ({:?}), {} standstills; odo {:.2?}\n  params % {rel:.3?}  mount err mm {:.2} {:.2} deg {:.3}  cf {:?}\n  gyro {:?}\n  {}",
            odo.scans, odo.consecutive_matched, odo.consecutive_refused, odo.intervals, odo.refused, odo.standstills, t_odo,
            1e3 * (est[3] - s.truth[3]), 1e3 * (est[4] - s.truth[4]),
            twindrive_kinematics::wrap_angle(est[5] - s.truth[5]).to_degrees(),
            cf.map(|c| { let p = c.params; [100.0*(p[0]/s.truth[0]-1.0), 100.0*(p[1]/s.truth[1]-1.0), 100.0*(p[2]/s.truth[2]-1.0), 1e3*(p[3]-s.truth[3]), 1e3*(p[4]-s.truth[4]), twindrive_kinematics::wrap_angle(p[5]-s.truth[5]).to_degrees()] }),
            r.gyro, r.identifiability.verdict
        );
    }
}
