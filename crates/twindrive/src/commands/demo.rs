use std::io::Write;
use std::path::Path;

use anyhow::Context;

use super::simulate::{print_summary, simulate_into};

pub fn run(out: &Path) -> anyhow::Result<()> {
    let scenario = twindrive_sim::builtin::load("wall_following")
        .expect("wall_following is built in")
        .context("the built-in wall-following scenario")?;
    let dir = out.join("wall_following");
    let summary = simulate_into(scenario, &dir)?;
    print_summary(&summary, &dir)?;
    writeln!(
        std::io::stdout().lock(),
        "open {}/path.png for the driven path and bump points",
        dir.display()
    )?;
    Ok(())
}
