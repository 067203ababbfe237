//! `twindrive experiment mismatch`: flags into the mismatch experiment's
//! configuration.

use twindrive_experiment::mismatch::{self, Autonomy, Config, Sensors};

use crate::cli::{AutonomyArg, MismatchExperimentArgs, ObstacleArg, OnOff, SensorsArg};
use crate::usage::usage;

pub fn run(args: &MismatchExperimentArgs) -> anyhow::Result<()> {
    let config = Config {
        errors: args.errors.clone(),
        sensors: args
            .sensors
            .iter()
            .map(|s| match s {
                SensorsArg::Ir => Sensors::Ir,
                SensorsArg::Lidar => Sensors::Lidar,
            })
            .collect(),
        autonomy: args
            .autonomy
            .iter()
            .map(|a| match a {
                AutonomyArg::Handback => Autonomy::Handback,
                AutonomyArg::Detour => Autonomy::Detour,
            })
            .collect(),
        obstacle: args
            .obstacle
            .iter()
            .map(|o| *o == ObstacleArg::Box)
            .collect(),
        localization: args.localization.iter().map(|l| *l == OnOff::On).collect(),
        seeds: args.seeds,
        profile: args
            .profile
            .parse()
            .map_err(|e| usage(format!("--profile: {e}")))?,
        profile_text: args.profile.clone(),
        max_duration_s: args.max_duration,
    };
    mismatch::run(&config, &args.out, &mut std::io::stdout().lock())
}
