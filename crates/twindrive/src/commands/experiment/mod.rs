//! `twindrive experiment`: the measurements behind the claim that
//! decoupling wins (the work is `twindrive-experiment`'s; these files turn
//! flags into its configurations).
//!
//! - `latency`: direct tele-operation against decoupled operation over a
//!   grid of latencies and losses;
//! - `upload`: the plan upload against the ideal the link allows;
//! - `fleet`: one master, N robot processes, a zenoh router;
//! - `mismatch`: decoupled operation as the site's kinematics depart from
//!   the twin's, per range sensor, with and without localization.

mod fleet;
mod latency;
mod mismatch;

use crate::cli::{ExperimentCommand, UploadExperimentArgs};

pub fn run(command: &ExperimentCommand) -> anyhow::Result<()> {
    match command {
        ExperimentCommand::Latency(a) => latency::run(a),
        ExperimentCommand::Upload(a) => upload(a),
        ExperimentCommand::Fleet(a) => fleet::run(a),
        ExperimentCommand::Mismatch(a) => mismatch::run(a),
    }
}

fn upload(args: &UploadExperimentArgs) -> anyhow::Result<()> {
    let config = twindrive_experiment::upload::Config {
        out: args.out.clone(),
        seeds: args.seeds,
        smoke: args.smoke,
    };
    twindrive_experiment::upload::run(&config, &mut std::io::stdout().lock())
}
