//! The paper's case study: the wall follower keeps its set distance in
//! steady state and backs up and turns left after each bump.

mod common;

use twindrive_sim::controller::WallMode;
use twindrive_sim::{Simulator, StepOutput};

#[test]
fn keeps_its_set_distance_and_backs_up_after_bumps() {
    let sc = common::load("wall_following.toml");
    let twindrive_sim::ControllerConfig::WallFollower { spec, sensor } = sc.controller.clone()
    else {
        panic!("wall_following.toml uses the wall follower");
    };
    let max_range = sc.range_sensors[sensor].info.max_range_m;
    let mut sim = Simulator::new(sc);
    let mut out = StepOutput::new(sim.beams());

    let settle_ns = 4_000_000_000;
    let mut last_disturbance_ns = 0; // last bump manoeuvre or lost wall
    let mut steady = Vec::new();
    let mut modes = Vec::new();
    while sim.step(&mut out) {
        let t = out.record.t_ns;
        let mode = out.wall_mode.unwrap();
        modes.push((mode, out.record.bump, out.record.cmd_wheel_rad_s));
        if let Some(r) = out.ranges.first().copied().filter(|r| !r.is_nan()) {
            if mode != WallMode::Follow || r >= max_range {
                last_disturbance_ns = t;
            } else if t >= last_disturbance_ns + settle_ns {
                steady.push(r - spec.target_range_m);
            }
        } else if mode != WallMode::Follow {
            last_disturbance_ns = t;
        }
    }
    // Steady state covers a good part of the mission.
    assert!(steady.len() > 1500, "{} steady-state samples", steady.len());
    let mean = steady.iter().sum::<f64>() / steady.len() as f64;
    let rms = (steady.iter().map(|e| e * e).sum::<f64>() / steady.len() as f64).sqrt();
    assert!(mean.abs() < 0.02, "mean error {mean} m");
    assert!(rms < 0.03, "rms error {rms} m");

    // Every bump in Follow starts reverse -> turn-left, as in the paper.
    let mut episodes = 0;
    for k in 1..modes.len() {
        if modes[k].0 != WallMode::Follow && modes[k - 1].0 == WallMode::Follow {
            assert!(modes[k].1, "step {k}: left Follow without a bump");
            assert!(matches!(modes[k].0, WallMode::Reverse { .. }));
            let [l, r] = modes[k].2;
            assert!(l < 0.0 && r < 0.0, "reversing commands {l}, {r}");
            let turn = modes[k..]
                .iter()
                .find(|m| matches!(m.0, WallMode::Turn { .. }))
                .expect("a turn follows");
            assert!(turn.2[1] > turn.2[0], "turns left");
            episodes += 1;
        }
    }
    assert!(
        episodes >= 2,
        "{episodes} bump-and-back-up episodes, the paper has at least two"
    );
}
