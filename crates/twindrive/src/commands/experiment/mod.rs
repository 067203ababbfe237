//! `twindrive experiment`: the measurements behind the claim that
//! decoupling wins.
//!
//! - `latency`: direct tele-operation against decoupled operation over a
//!   grid of latencies and losses;
//! - `upload`: the plan upload against the ideal the link allows;
//! - `fleet`: one master, N robot processes, a zenoh router.

pub mod fleet;
pub mod latency;
mod route;
pub mod upload;

use crate::cli::ExperimentCommand;

pub fn run(command: &ExperimentCommand) -> anyhow::Result<()> {
    match command {
        ExperimentCommand::Latency(a) => latency::run(a),
        ExperimentCommand::Upload(a) => upload::run(a),
        ExperimentCommand::Fleet(a) => fleet::run(a),
    }
}
