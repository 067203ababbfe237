//! Simulating a scenario into an output directory: the log (CSV, its
//! header, MCAP with the site map), the ground truth (TUM), the summary and
//! the figures.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, bail};
use twindrive_files::Staging;
use twindrive_sim::{MissionSummary, Scenario, Simulator};

use crate::figures;

/// In-memory logs larger than this are refused up front.
const LOG_BUDGET_BYTES: u64 = 4 << 30;

/// Simulates `scenario` and writes every artefact into `out`, atomically per file.
pub fn simulate_into(
    scenario: Scenario,
    out: &Path,
) -> anyhow::Result<(MissionSummary, twindrive_log::MissionLog)> {
    let needed = scenario.log_size_bytes();
    if needed > LOG_BUDGET_BYTES {
        bail!(
            "{}: {} steps would need about {:.1} GiB for the log (limit {} GiB); shorten the run, lengthen dt_s or lower the range sensor rates",
            scenario.name,
            scenario.steps,
            needed as f64 / (1u64 << 30) as f64,
            LOG_BUDGET_BYTES >> 30
        );
    }
    let staging = Staging::new(out, "simulate")?;
    let world = scenario.world.clone();
    tracing::info!(scenario = %scenario.name, steps = scenario.steps, "simulating");
    let started = Instant::now();
    let bar = twindrive_progress::bar(scenario.steps, &format!("simulating {}", scenario.name));
    let log = Simulator::new(scenario).run(|done, _| bar.set_position(done));
    bar.finish_and_clear();
    tracing::info!(elapsed_s = started.elapsed().as_secs_f64(), "simulated");
    let summary = write_run(&staging, &log, &world)?;
    staging.commit()?;
    tracing::info!(dir = %out.display(), elapsed_s = started.elapsed().as_secs_f64(), "wrote results");
    Ok((summary, log))
}

/// Stages what a run on the twin writes (the log as CSV, its header, MCAP
/// with the site map, the ground truth as TUM, the summary and the
/// figures); the caller commits. Its summary.
pub fn write_run(
    staging: &Staging,
    log: &twindrive_log::MissionLog,
    world: &twindrive_sim::World,
) -> anyhow::Result<MissionSummary> {
    let summary = MissionSummary::new(log, world);
    staging.write_with("log.csv", |w| {
        twindrive_log::write_csv(log, w).map_err(Into::into)
    })?;
    staging.write_with("log.meta.json", |w| {
        serde_json::to_writer_pretty(w, &log.header).map_err(Into::into)
    })?;
    staging.write_with("log.mcap", |w| {
        twindrive_log::write_mcap_with_map(log, Some(&world.log_map()), w).map_err(Into::into)
    })?;
    staging.write_with("ground_truth.tum", |w| {
        twindrive_log::write_tum(log.steps.iter().map(|s| (s.t_ns, s.ground_truth)), w)
            .map_err(Into::into)
    })?;
    staging.write_with("summary.json", |w| {
        serde_json::to_writer_pretty(w, &summary).map_err(Into::into)
    })?;
    figures::mission_figures(log, world, staging.dir()).context("drawing figures")?;
    Ok(summary)
}

/// The summary as two lines for a terminal; `out` is where the files went.
pub fn print_summary(
    s: &MissionSummary,
    out: &Path,
    stdout: &mut impl Write,
) -> std::io::Result<()> {
    writeln!(
        stdout,
        "{}: {:.1} s, {:.2} m driven, {} bump episode(s), min clearance {:.3} m",
        s.scenario, s.duration_s, s.distance_m, s.bumps, s.min_clearance_m
    )?;
    writeln!(
        stdout,
        "results in {}/ (log.csv, log.mcap, ground_truth.tum, summary.json, figures)",
        out.display()
    )?;
    Ok(())
}
