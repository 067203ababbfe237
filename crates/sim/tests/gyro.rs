//! The gyro and range dropouts: readings with the configured errors, logs
//! that carry them exactly, and every other sensor's output left as it was.

mod common;

use std::path::Path;

use twindrive_log::{MissionLog, read_csv_from, read_mcap_bytes, write_csv, write_mcap};
use twindrive_sim::{Simulator, StepOutput};

const BIAS_RAD_S: f64 = 0.02;
const SCALE_ERROR: f64 = 0.03;
const NOISE_RAD_S: f64 = 0.01;

/// The gyro the statistics are checked against, at half the step rate.
fn gyro() -> String {
    format!(
        "[gyro]\nrate_hz = 50.0\nbias_rad_s = {BIAS_RAD_S}\nscale_error = {SCALE_ERROR}\nnoise_std_rad_s = {NOISE_RAD_S}\n"
    )
}

/// Spins in place at three rates each way for 300 s (ten 30 s cycles, so
/// the true rate averages near zero), with slip, a noisy tracker that drops
/// out, a noisy lidar that reaches every wall, and `sensors` added.
fn spin(sensors: &str, lidar_dropout: f64) -> String {
    let segments = [2.0, 5.0, 8.0]
        .iter()
        .flat_map(|w| {
            [
                format!(
                    "{{ duration_s = 5.0, left_rad_s = {}, right_rad_s = {w} }}",
                    -w
                ),
                format!(
                    "{{ duration_s = 5.0, left_rad_s = {w}, right_rad_s = {} }}",
                    -w
                ),
            ]
        })
        .collect::<Vec<_>>()
        .join(", ");
    let controller = format!("kind = \"scripted\"\nrepeat = true\nsegments = [{segments}]");
    common::scenario_toml("", &controller, 300.0, 0.01).replace(
        "[controller]",
        &format!(
            "[tracker]\nrate_hz = 20.0\nposition_noise_std_m = 0.01\nheading_noise_std_rad = 0.01\ndropout_probability = 0.1\n\
             [[range_sensors]]\nname = \"lidar\"\nmount = {{ x_m = 0.1, y_m = 0.0, heading_rad = 0.0 }}\nbeams = 90\n\
             fov_rad = 6.283185307179586\nmax_range_m = 20.0\nnoise_std_m = 0.01\nrate_hz = 10.0\n\
             dropout_probability = {lidar_dropout}\n{sensors}\n[controller]"
        ),
    )
}

fn run(text: &str) -> MissionLog {
    Simulator::new(common::parse(text).unwrap()).run(|_, _| {})
}

/// (true yaw rate over the step before, reading) of every gyro sample but
/// the first, the true rate from the ground-truth headings.
fn gyro_pairs(log: &MissionLog) -> Vec<(f64, f64)> {
    let dt = log.header.dt_s;
    log.steps
        .windows(2)
        .filter_map(|w| {
            let truth = (w[1].ground_truth.heading_rad - w[0].ground_truth.heading_rad) / dt;
            w[1].gyro_z_rad_s.map(|z| (truth, z))
        })
        .collect()
}

fn mean(v: impl Iterator<Item = f64> + Clone) -> f64 {
    let n = v.clone().count() as f64;
    v.sum::<f64>() / n
}

#[test]
fn the_gyro_reads_the_true_rate_with_its_bias_scale_and_noise() {
    let log = run(&spin(&gyro(), 0.0));
    let info = log.header.gyro.as_ref().expect("the header names the gyro");
    assert_eq!((info.name.as_str(), info.rate_hz), ("gyro", 50.0));
    assert_eq!(log.gyro_rates().count(), log.steps.len() / 2);
    let pairs = gyro_pairs(&log);

    // Over the spin, both ways alike, the mean error is the bias.
    let mean_true = mean(pairs.iter().map(|p| p.0));
    assert!(mean_true.abs() < 0.01, "mean true rate {mean_true}");
    let max_true = pairs.iter().map(|p| p.0.abs()).fold(0.0, f64::max);
    assert!(max_true > 1.5, "spun at most {max_true} rad/s");
    let mean_error = mean(pairs.iter().map(|(t, z)| z - t));
    assert!(
        (mean_error - BIAS_RAD_S).abs() < 1e-3,
        "mean error {mean_error}, bias {BIAS_RAD_S}"
    );

    // The regression of reading on truth recovers the scale and the bias ...
    let mean_z = mean(pairs.iter().map(|p| p.1));
    let cov = mean(pairs.iter().map(|(t, z)| (t - mean_true) * (z - mean_z)));
    let var = mean(pairs.iter().map(|(t, _)| (t - mean_true).powi(2)));
    let slope = cov / var;
    let intercept = mean_z - slope * mean_true;
    assert!(
        (slope - (1.0 + SCALE_ERROR)).abs() < 1e-3,
        "slope {slope}, expected {}",
        1.0 + SCALE_ERROR
    );
    assert!(
        (intercept - BIAS_RAD_S).abs() < 5e-4,
        "intercept {intercept}"
    );
    // ... and what is left is the noise.
    let residual_std = mean(
        pairs
            .iter()
            .map(|(t, z)| (z - slope * t - intercept).powi(2)),
    )
    .sqrt();
    assert!(
        (residual_std / NOISE_RAD_S - 1.0).abs() < 0.03,
        "residual std {residual_std}, noise {NOISE_RAD_S}"
    );
}

#[test]
fn a_perfect_gyro_sees_slip_and_contact_as_the_ground_truth_does() {
    // Pushing into a block on an arc: contact stops the turn part-way.
    let text = common::scenario_toml(
        "rectangles = [{ min = [5.6, 3.0], max = [6.0, 7.0] }]",
        "kind = \"scripted\"\nsegments = [{ duration_s = 20.0, left_rad_s = 5.0, right_rad_s = 6.0 }]",
        20.0,
        0.05,
    )
    .replace("[controller]", "[gyro]\nrate_hz = 100.0\n[controller]");
    let mut sim = Simulator::new(common::parse(&text).unwrap());
    let mut out = StepOutput::new(sim.beams());
    let mut steps = Vec::new();
    let mut blocked_turns = 0;
    while sim.step(&mut out) {
        let before = out.record.ground_truth.heading_rad;
        if out.blocked && sim.pose().heading_rad != before {
            blocked_turns += 1;
        }
        steps.push(out.record);
    }
    assert!(blocked_turns > 0, "the robot never turned into contact");
    let dt = sim.scenario().dt_s();
    for w in steps.windows(2) {
        let truth = (w[1].ground_truth.heading_rad - w[0].ground_truth.heading_rad) / dt;
        let z = w[1].gyro_z_rad_s.expect("samples every step");
        assert!(
            (z - truth).abs() < 1e-9,
            "t = {}: {z} vs {truth}",
            w[1].t_s()
        );
    }
    assert_eq!(steps[0].gyro_z_rad_s, Some(0.0));
}

#[test]
fn a_gyro_or_dropouts_leave_the_other_streams_as_they_were() {
    let plain = run(&spin("", 0.0));
    let with_gyro = run(&spin(&gyro(), 0.0));
    assert_eq!(plain.header.gyro, None);
    assert!(plain.steps.iter().all(|s| s.gyro_z_rad_s.is_none()));
    let mut stripped = with_gyro.clone();
    stripped.header.gyro = None;
    for s in &mut stripped.steps {
        s.gyro_z_rad_s = None;
    }
    assert_eq!(stripped.header, plain.header);
    assert_eq!(stripped.steps, plain.steps);
    let bits = |log: &MissionLog| log.ranges.iter().map(|r| r.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&stripped), bits(&plain));
    assert!(plain.tracker_poses().count() > 0);

    // Dropouts: about the given fraction of beams read the maximum range,
    // and every other beam reads exactly what it read without dropouts.
    let p = 0.2;
    let dropped = run(&spin("", p));
    assert_eq!(dropped.steps, plain.steps);
    let max = plain.header.range_sensors[0].max_range_m;
    let (mut sampled, mut lost) = (0usize, 0usize);
    for (a, b) in plain.ranges.iter().zip(&dropped.ranges) {
        if a.is_nan() {
            assert!(b.is_nan());
            continue;
        }
        sampled += 1;
        assert!(*a < max, "a beam missed every wall");
        if *b == max {
            lost += 1;
        } else {
            assert_eq!(a.to_bits(), b.to_bits());
        }
    }
    let fraction = lost as f64 / sampled as f64;
    assert!(sampled > 200_000, "{sampled} beams");
    assert!((fraction - p).abs() < 0.005, "dropout fraction {fraction}");
}

#[test]
fn logs_with_a_gyro_round_trip_exactly_and_repeat_byte_for_byte() {
    let log = run(&spin(&gyro(), 0.1));
    let bytes = |log: &MissionLog| {
        let mut csv = Vec::new();
        write_csv(log, &mut csv).unwrap();
        let mut mcap = std::io::Cursor::new(Vec::new());
        write_mcap(log, &mut mcap).unwrap();
        (csv, mcap.into_inner())
    };
    let (csv, mcap) = bytes(&log);
    assert!(String::from_utf8_lossy(&csv[..200]).contains(",gt_theta,gyro_z_rad_s,range_lidar_0,"));
    let same = |back: &MissionLog| {
        assert_eq!(back.header, log.header);
        assert_eq!(back.steps, log.steps);
        assert!(
            back.ranges
                .iter()
                .zip(&log.ranges)
                .all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
        );
    };
    same(&read_csv_from(csv.as_slice(), Path::new("log.csv"), &log.header).unwrap());
    same(&read_mcap_bytes(&mcap, Path::new("log.mcap")).unwrap());
    assert_eq!(bytes(&run(&spin(&gyro(), 0.1))), (csv, mcap));
}
