//! The operator's inputs read and checked: a plan file (format, hash,
//! contents) and the bytes of the twin's world a plan was rehearsed in;
//! and now, as the time since the Unix epoch (plans are signed with it).

use std::path::Path;

use anyhow::{Context, bail};
use twindrive_mission::plan::MissionPlan;

/// Reads and checks a plan file (format, hash, contents).
pub fn read_plan(path: &Path) -> anyhow::Result<MissionPlan> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    parse_plan(&bytes, path)
}

/// Checks the bytes of the plan file `path` (format, hash, contents).
pub fn parse_plan(bytes: &[u8], path: &Path) -> anyhow::Result<MissionPlan> {
    let plan: MissionPlan = twindrive_files::json::parse(bytes, path, twindrive_files::json::PLAN)?;
    plan.validate()
        .with_context(|| format!("{}", path.display()))?;
    Ok(plan)
}

/// The bytes of the twin's world a plan was rehearsed in: `scenario` if
/// given, else the built-in scenario the plan names (`scenario_name`).
pub fn world_bytes(scenario_name: &str, scenario: Option<&Path>) -> anyhow::Result<Vec<u8>> {
    Ok(match scenario {
        Some(path) => std::fs::read(path)
            .with_context(|| format!("--scenario: reading {}", path.display()))?,
        None => match twindrive_sim::builtin::ALL
            .iter()
            .find(|(n, _)| *n == scenario_name)
        {
            Some((_, text)) => text.as_bytes().to_vec(),
            None => bail!(
                "the plan's scenario `{scenario_name}` is not built in; pass --scenario with the TOML it was rehearsed in"
            ),
        },
    })
}

/// Now, as the time since the Unix epoch.
pub fn since_epoch() -> anyhow::Result<std::time::Duration> {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .context("the system clock is before 1970")
}
