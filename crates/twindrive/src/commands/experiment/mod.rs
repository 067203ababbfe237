//! `twindrive experiment`: the measurements behind the claim that
//! decoupling wins.
//!
//! - `latency`: direct tele-operation against decoupled operation over a
//!   grid of latencies and losses;
//! - `upload`: the plan upload against the ideal the link allows;
//! - `fleet`: one master, N robot processes, a zenoh router;
//! - `mismatch`: decoupled operation as the site's kinematics depart from
//!   the twin's, per range sensor, with and without localization.

pub mod fleet;
pub mod latency;
pub mod mismatch;
mod pool;
mod route;
pub mod upload;

use crate::cli::ExperimentCommand;

pub fn run(command: &ExperimentCommand) -> anyhow::Result<()> {
    match command {
        ExperimentCommand::Latency(a) => latency::run(a),
        ExperimentCommand::Upload(a) => upload::run(a),
        ExperimentCommand::Fleet(a) => fleet::run(a),
        ExperimentCommand::Mismatch(a) => mismatch::run(a),
    }
}
