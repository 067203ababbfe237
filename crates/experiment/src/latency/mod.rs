//! `twindrive experiment latency`: direct tele-operation against decoupled
//! operation on the same robot site, seeds and link, over a grid of one-way
//! latencies and losses, in virtual time with the project's own link
//! emulator and protocol code.
//!
//! The mission is the twin's scenario (the paper's wall-following case
//! study unless `--scenario`): rehearsed on the twin, it gives the intended
//! route (the plan's path) and the plan decoupled operation uploads. The
//! robot's site is the twin with other true kinematics (`--site` for one's
//! own). Each method drives the site until the route is covered:
//! - direct (a) hold-last, (b) watchdog and (c) move-and-wait run the twin's
//!   own controller at the master on delayed sensor data
//!   ([`twindrive_agent::direct`]); a run is complete when the robot's true
//!   path has passed within the coverage radius of `--complete-at` of the
//!   route (as if the operator knew its pose exactly: generous to direct
//!   operation), and the operator learns so one latency later;
//! - decoupled signs the plan, uploads it, and the robot runs it on its
//!   own with hand-back and continuation ([`crate::mission`]);
//!   complete when the master learns the last plan finished.

mod model;
mod report;
mod runner;

use std::io::Write;
use std::path::Path;

use anyhow::{Context, bail};
use twindrive_files::Staging;
use twindrive_kinematics::DiffDriveParams;
use twindrive_sim::Scenario;

pub use model::{Method, Settings};
pub use report::{Cell, cells, csv, figures, intro, markdown, paths_figure};
pub use runner::{Job, RunRow, run_grid, run_one};

use crate::rehearsal::{Rehearsal, site_like};

/// The demo's short version: latencies 0, 0.5 and 2 s at 10 % loss, one
/// seed, on the demo's own plan; `results.md`, `results.csv` and the
/// figures into `out`.
pub fn demo_section(mission: &Rehearsal, out: &Path) -> anyhow::Result<(Settings, Vec<Cell>)> {
    let settings = Settings::demo();
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let rows = run_grid(mission, &settings)?;
    let cells = cells(&rows, &settings);
    let md = markdown(&cells, &settings, &intro(mission, &settings));
    let staging = Staging::new(out, "demo-experiment")?;
    staging.write_with("results.csv", |w| Ok(w.write_all(csv(&rows).as_bytes())?))?;
    staging.write_with("results.md", |w| Ok(w.write_all(md.as_bytes())?))?;
    figures(&cells, &settings, staging.dir())?;
    paths_figure(
        &rows,
        mission,
        &settings,
        0.5,
        0.1,
        &staging.dir().join("paths"),
    )?;
    staging.commit()?;
    Ok((settings, cells))
}

/// The twin (`scenario`, else the case study) and its world file, the site
/// (`site`, else [`site_like`] the twin) and the calibrated parameters
/// (`calibration`, else the built-in calibration drive's).
pub fn inputs(
    scenario: Option<&Path>,
    site: Option<&Path>,
    calibration: Option<DiffDriveParams>,
) -> anyhow::Result<(Scenario, Vec<u8>, Scenario, DiffDriveParams)> {
    let (twin, world_toml) = match scenario {
        Some(path) => (
            Scenario::load(path)?,
            std::fs::read(path).with_context(|| format!("reading {}", path.display()))?,
        ),
        None => (
            twindrive_sim::builtin::load("wall_following")
                .expect("built in")
                .context("the built-in wall_following scenario")?,
            twindrive_sim::builtin::WALL_FOLLOWING.as_bytes().to_vec(),
        ),
    };
    if !matches!(
        twin.controller,
        twindrive_sim::ControllerConfig::WallFollower { .. }
    ) {
        bail!(
            "--scenario: the mission's controller must be a wall follower (the operator's controller in direct operation)"
        );
    }
    let site = match site {
        Some(path) => Scenario::load(path).map_err(|e| anyhow::anyhow!("--site: {e}"))?,
        None => site_like(&twin),
    };
    let calibrated = match calibration {
        Some(c) => c,
        None => twindrive_calibrate::calibrate_like(&twin)?,
    };
    Ok((twin, world_toml, site, calibrated))
}

/// Runs the experiment on `mission` with `settings`; `results.csv`,
/// `results.md` and the figures into `dir`, the tables to `out`.
pub fn run(
    mission: &Rehearsal,
    settings: &Settings,
    dir: &Path,
    out: &mut impl Write,
) -> anyhow::Result<()> {
    writeln!(
        out,
        "rehearsal: plan of {:.1} s ({} samples); {} runs",
        mission.plan.duration_s(),
        mission.plan.samples.len(),
        settings.latencies_s.len() * settings.losses.len() * 4 * settings.seeds as usize
    )?;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let rows = run_grid(mission, settings)?;
    let cells = cells(&rows, settings);
    let intro = intro(mission, settings);
    let md = markdown(&cells, settings, &intro);
    let staging = Staging::new(dir, "experiment-latency")?;
    staging.write_with("results.csv", |w| Ok(w.write_all(csv(&rows).as_bytes())?))?;
    staging.write_with("results.md", |w| Ok(w.write_all(md.as_bytes())?))?;
    figures(&cells, settings, staging.dir())?;
    let mid = settings.latencies_s[settings.latencies_s.len() / 2];
    paths_figure(
        &rows,
        mission,
        settings,
        mid,
        settings.losses[0],
        &staging.dir().join("paths"),
    )?;
    staging.commit()?;
    out.write_all(md.as_bytes())?;
    writeln!(
        out,
        "-> {}/ (results.csv, results.md, completion_time, collisions, paths)",
        dir.display()
    )?;
    Ok(())
}
