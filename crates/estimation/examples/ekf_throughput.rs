//! The EKF side of `bench/ekf_vs_filterpy.sh`.
//!
//! `--write-input FILE`: simulates the calibration drive and writes one row
//! per tracker pose: the wheel rotations since the previous pose and the pose
//! (`left_rad,right_rad,x,y,theta`; the first row only initialises).
//! `--run FILE [--repeat N]`: one predict + one update per row, N times over,
//! single-threaded; prints `steps_per_s <v>` and `final <dL> <dR> <b>`.
//!
//! Filter settings (the Python peer uses the same): initial state from the
//! first row's pose and (0.066, 0.066, 0.26); P0 = diag(1e-6, 1e-6, 4e-6,
//! (0.1·p)²); wheel noise 1e-6·|φ| + 1e-9 rad²; R = diag(1e-6, 1e-6, 4e-6);
//! gating off.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use twindrive_estimation::{
    AugmentedEkf, GateConfig, Mat6, NoiseModel, StateAndCovariance, StateVec,
};

const NOMINAL: [f64; 3] = [0.066, 0.066, 0.26];

fn write_input(path: &Path) -> std::io::Result<()> {
    let scenario = twindrive_sim::Scenario::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/calibration_drive.toml"),
    )
    .expect("scenario loads");
    let rad = std::f64::consts::TAU / f64::from(scenario.robot.encoder.ticks_per_rev);
    let log = twindrive_sim::Simulator::new(scenario).run(|_, _| {});
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(out, "left_rad,right_rad,x,y,theta")?;
    // Wheel angles at each step from the last encoder sample (zero-order hold
    // keeps both implementations on exactly the same numbers).
    let mut angles = [0.0, 0.0];
    let mut last = [0.0, 0.0];
    for s in &log.steps {
        if let Some([l, r]) = s.encoder_ticks {
            angles = [l as f64 * rad, r as f64 * rad];
        }
        if let Some(p) = s.tracker {
            writeln!(
                out,
                "{},{},{},{},{}",
                angles[0] - last[0],
                angles[1] - last[1],
                p.x_m,
                p.y_m,
                p.heading_rad
            )?;
            last = angles;
        }
    }
    out.flush()
}

fn read_rows(path: &Path) -> Vec<[f64; 5]> {
    let text = std::fs::read_to_string(path).expect("input readable");
    text.lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().expect("number")).collect();
            [v[0], v[1], v[2], v[3], v[4]]
        })
        .collect()
}

fn filter(first: &[f64; 5]) -> AugmentedEkf {
    let mut p = Mat6::zeros();
    for (i, v) in [1e-6, 1e-6, 4e-6].iter().enumerate() {
        p[(i, i)] = *v;
    }
    for i in 0..3 {
        p[(3 + i, 3 + i)] = (0.1 * NOMINAL[i]).powi(2);
    }
    let init = StateAndCovariance {
        state: StateVec::new(
            first[2], first[3], first[4], NOMINAL[0], NOMINAL[1], NOMINAL[2],
        ),
        covariance: p,
    };
    let noise = NoiseModel {
        wheel_rad2_per_rad: 1e-6,
        wheel_floor_rad2: 1e-9,
        param_random_walk_m2_per_s: None,
        position_std_m: 1e-3,
        heading_std_rad: 2e-3,
    };
    let gate = GateConfig {
        probability: 1.0 - 1e-15,
        max_consecutive_rejections: usize::MAX,
        reanchor: false,
    };
    AugmentedEkf::new(init, noise, gate)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("--write-input") => write_input(Path::new(&args[1])).expect("input written"),
        Some("--run") => {
            let rows = read_rows(Path::new(&args[1]));
            let repeat: usize = args
                .iter()
                .position(|a| a == "--repeat")
                .map_or(20, |i| args[i + 1].parse().expect("count"));
            let mut ekf = filter(&rows[0]);
            let start = Instant::now();
            for _ in 0..repeat {
                ekf = filter(&rows[0]);
                for r in &rows[1..] {
                    ekf.predict(r[0], r[1], 0.0);
                    ekf.update_pose(0.0, r[2], r[3], r[4])
                        .expect("healthy filter");
                }
            }
            let secs = start.elapsed().as_secs_f64();
            let steps = (repeat * (rows.len() - 1)) as f64;
            let s = ekf.estimate().state;
            println!("steps_per_s {:.1}", steps / secs);
            println!("final {} {} {}", s[3], s[4], s[5]);
        }
        _ => eprintln!("usage: ekf_throughput --write-input FILE | --run FILE [--repeat N]"),
    }
}
