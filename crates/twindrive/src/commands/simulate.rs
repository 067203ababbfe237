use std::io::Write;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, bail};
use twindrive_sim::{MissionSummary, Scenario, Simulator};

use crate::output::Staging;
use crate::{figures, progress};

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
    print_summary(&summary, out)
}

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
    let bar = progress::bar(scenario.steps, &format!("simulating {}", scenario.name));
    let log = Simulator::new(scenario).run(|done, _| bar.set_position(done));
    bar.finish_and_clear();
    tracing::info!(elapsed_s = started.elapsed().as_secs_f64(), "simulated");

    let summary = MissionSummary::new(&log, &world);
    staging.write_with("log.csv", |w| {
        twindrive_log::write_csv(&log, w).map_err(Into::into)
    })?;
    staging.write_with("log.meta.json", |w| {
        serde_json::to_writer_pretty(w, &log.header).map_err(Into::into)
    })?;
    staging.write_with("log.mcap", |w| {
        twindrive_log::write_mcap_with_map(&log, Some(&world.log_map()), w).map_err(Into::into)
    })?;
    staging.write_with("ground_truth.tum", |w| {
        twindrive_log::write_tum(log.steps.iter().map(|s| (s.t_ns, s.ground_truth)), w)
            .map_err(Into::into)
    })?;
    staging.write_with("summary.json", |w| {
        serde_json::to_writer_pretty(w, &summary).map_err(Into::into)
    })?;
    figures::mission_figures(&log, &world, staging.dir()).context("drawing figures")?;
    staging.commit()?;
    tracing::info!(dir = %out.display(), elapsed_s = started.elapsed().as_secs_f64(), "wrote results");
    Ok((summary, log))
}

pub fn print_summary(s: &MissionSummary, out: &Path) -> anyhow::Result<()> {
    let mut stdout = std::io::stdout().lock();
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
