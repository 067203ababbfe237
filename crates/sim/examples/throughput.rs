//! Simulation throughput on one scenario, single-threaded, no logging:
//! `cargo run --release -p twindrive-sim --example throughput -- SCENARIO.toml --steps N`.
//! Prints `steps_per_s <value>` (read by `bench/sim_vs_irsim.sh`).

use std::time::Instant;

use twindrive_sim::{Scenario, Simulator, StepOutput};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or("usage: throughput SCENARIO.toml [--steps N]")?;
    let mut steps: u64 = 200_000;
    while let Some(flag) = args.next() {
        match flag.as_str() {
            "--steps" => steps = args.next().ok_or("--steps needs a value")?.parse()?,
            other => return Err(format!("unknown argument `{other}`").into()),
        }
    }
    let mut scenario = Scenario::load(path.as_ref())?;
    scenario.steps = steps;
    let mut sim = Simulator::new(scenario);
    let mut out = StepOutput::new(sim.beams());
    let start = Instant::now();
    let mut bumps = 0u64;
    while sim.step(&mut out) {
        bumps += u64::from(out.record.bump);
    }
    let elapsed = start.elapsed().as_secs_f64();
    eprintln!("{steps} steps in {elapsed:.3} s ({bumps} steps with the bumper pressed)");
    println!("steps_per_s {:.1}", steps as f64 / elapsed);
    Ok(())
}
