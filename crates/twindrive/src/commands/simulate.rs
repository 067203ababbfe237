//! `twindrive simulate`: run a scenario on the twin and write its log,
//! ground truth, summary and figures.

use std::path::Path;

use twindrive_sim::Scenario;
use twindrive_workflow::simulate::{print_summary, simulate_into};

pub fn run(
    scenario_path: &Path,
    out: &Path,
    seed: Option<u64>,
    duration_s: Option<f64>,
) -> anyhow::Result<()> {
    let mut scenario = Scenario::load(scenario_path)?;
    if let Some(seed) = seed {
        scenario.seed = seed;
    }
    if let Some(d) = duration_s {
        scenario
            .set_duration_s(d)
            .map_err(|m| crate::usage::usage(format!("--duration-s {m}")))?;
    }
    let (summary, _) = simulate_into(scenario, out)?;
    print_summary(&summary, out, &mut std::io::stdout().lock())?;
    Ok(())
}
