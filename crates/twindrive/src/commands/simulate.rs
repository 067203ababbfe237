use std::path::Path;

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
        if !(d.is_finite() && d > 0.0) {
            bail!("--duration-s must be a finite number > 0, got {d}");
        }
        scenario.steps = ((d / scenario.dt_s()).round() as u64).max(1);
    }
    let summary = simulate_into(scenario, out)?;
    print_summary(&summary, out);
    Ok(())
}

/// Simulates `scenario` and writes every artefact into `out`, atomically per file.
pub fn simulate_into(scenario: Scenario, out: &Path) -> anyhow::Result<MissionSummary> {
    let staging = Staging::new(out)?;
    let world = scenario.world.clone();
    let bar = progress::bar(scenario.steps, &format!("simulating {}", scenario.name));
    let log = Simulator::new(scenario).run(|done, _| bar.set_position(done));
    bar.finish_and_clear();

    let summary = MissionSummary::new(&log, &world);
    staging.write_with("log.csv", |w| {
        twindrive_log::write_csv(&log, w).map_err(Into::into)
    })?;
    staging.write_with("log.meta.json", |w| {
        serde_json::to_writer_pretty(w, &log.header).map_err(Into::into)
    })?;
    staging.write_with("log.mcap", |w| {
        twindrive_log::write_mcap(&log, w).map_err(Into::into)
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
    Ok(summary)
}

pub fn print_summary(s: &MissionSummary, out: &Path) {
    println!(
        "{}: {:.1} s, {:.2} m driven, {} bump episode(s), min clearance {:.3} m",
        s.scenario, s.duration_s, s.distance_m, s.bumps, s.min_clearance_m
    );
    println!(
        "results in {}/ (log.csv, log.mcap, ground_truth.tum, summary.json, figures)",
        out.display()
    );
}
