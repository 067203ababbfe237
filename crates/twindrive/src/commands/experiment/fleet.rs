//! `twindrive experiment fleet`: flags into the fleet experiment's
//! configuration.

use anyhow::Context;
use twindrive_experiment::fleet::{self, Config};
use twindrive_link::emulator::LinkProfile;

use crate::cli::FleetExperimentArgs;
use crate::usage::usage;

pub fn run(args: &FleetExperimentArgs) -> anyhow::Result<()> {
    if let Some(link) = &args.link {
        link.parse::<LinkProfile>()
            .map_err(|e| usage(format!("--link {link}: {e}")))?;
    }
    let config = Config {
        exe: std::env::current_exe().context("finding the twindrive executable")?,
        out: args.out.clone(),
        robots: args.robots.clone(),
        time_scale: args.time_scale,
        telemetry_budget: args.telemetry_budget,
        timeout: args.timeout,
        link: args.link.clone(),
        cost: args.cost.clone(),
    };
    fleet::run(&config, &mut std::io::stdout().lock())
}
