//! Flag resolution the commands share: files named on the command line
//! read and checked (a plan, a calibration, a key, the twin's world), and
//! values parsed, each error naming its flag or file.

use std::path::Path;

use anyhow::{Context, bail};
use serde::Deserialize;
use twindrive_kinematics::DiffDriveParams;
use twindrive_link::LinkProfile;
use twindrive_link::envelope::read_private_key_pem;
use twindrive_mission::plan::MissionPlan;

use crate::usage::usage;

/// The three parameters of a `calib.json` (other fields are ignored).
#[derive(Debug, Deserialize)]
struct Calibration {
    left_diameter_m: f64,
    right_diameter_m: f64,
    wheelbase_m: f64,
}

/// Reads the calibrated parameters from a `twindrive calibrate` output.
pub fn read_calibration(path: &Path) -> anyhow::Result<DiffDriveParams> {
    let c: Calibration = twindrive_files::json::read(
        path,
        "a calibration (calib.json from `twindrive calibrate`, with left_diameter_m, right_diameter_m and wheelbase_m)",
    )?;
    let params = DiffDriveParams::new(c.left_diameter_m, c.right_diameter_m, c.wheelbase_m);
    params
        .validate()
        .with_context(|| format!("{}", path.display()))?;
    Ok(params)
}

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

/// The robots a master or the console supervises are distinct (each id is
/// checked when parsed).
pub fn check_distinct_robots(robots: &[String]) -> anyhow::Result<()> {
    let mut seen = std::collections::HashSet::new();
    for id in robots {
        if !seen.insert(id) {
            return Err(usage(format!("--robot {id} is given twice")));
        }
    }
    Ok(())
}

/// `--link PROFILE`, parsed.
pub fn link_profile(arg: Option<&str>) -> anyhow::Result<Option<LinkProfile>> {
    arg.map(|p| p.parse().map_err(|e| usage(format!("--link {p}: {e}"))))
        .transpose()
}

/// `--key master.key`, read.
pub fn signing_key(
    path: Option<&Path>,
) -> anyhow::Result<Option<twindrive_link::envelope::SigningKey>> {
    let Some(path) = path else {
        return Ok(None);
    };
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("--key: reading {}", path.display()))?;
    read_private_key_pem(&text)
        .map(Some)
        .map_err(|e| anyhow::anyhow!("--key {}: {e}", path.display()))
}
