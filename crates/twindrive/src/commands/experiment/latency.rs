//! `twindrive experiment latency`: flags into the latency experiment's
//! settings and inputs.

use twindrive_experiment::latency::{self, Settings};
use twindrive_experiment::rehearsal::Rehearsal;

use crate::cli::LatencyExperimentArgs;
use crate::usage::usage;

pub fn run(args: &LatencyExperimentArgs) -> anyhow::Result<()> {
    let settings = settings(args)?;
    let calibration = match &args.calibration {
        Some(path) => Some(crate::flags::read_calibration(path)?),
        None => None,
    };
    let (twin, world_toml, site, calibrated) =
        latency::inputs(args.scenario.as_deref(), args.site.as_deref(), calibration)?;
    let mission = Rehearsal::rehearse(twin, world_toml, site, calibrated)?;
    latency::run(
        &mission,
        &settings,
        &args.out,
        &mut std::io::stdout().lock(),
    )
}

fn parse_list(
    text: &str,
    flag: &str,
    check: impl Fn(f64) -> bool,
    what: &str,
) -> anyhow::Result<Vec<f64>> {
    let mut out = Vec::new();
    for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let v: f64 = part
            .parse()
            .map_err(|_| usage(format!("{flag}: {what}, got `{part}`")))?;
        if !check(v) {
            return Err(usage(format!("{flag}: {what}, got {v}")));
        }
        if !out.contains(&v) {
            out.push(v);
        }
    }
    if out.is_empty() {
        return Err(usage(format!("{flag}: {what}, at least one")));
    }
    Ok(out)
}

/// The settings the flags give (each scalar is checked when parsed; the
/// lists here, as usage errors).
fn settings(args: &LatencyExperimentArgs) -> anyhow::Result<Settings> {
    Ok(Settings {
        latencies_s: parse_list(
            &args.latencies,
            "--latencies",
            |v| v.is_finite() && (0.0..=600.0).contains(&v),
            "one-way latencies from 0 to 600 s",
        )?,
        losses: parse_list(
            &args.losses,
            "--losses",
            |v| (0.0..0.9).contains(&v),
            "losses from 0 to 0.9 (a fraction)",
        )?,
        seeds: args.seeds,
        bandwidth_bit_s: args.bandwidth,
        watchdog_timeout_s: args.watchdog_timeout,
        move_s: args.move_s,
        coverage_radius_m: args.coverage_radius,
        complete_at: args.complete_at,
        max_duration_s: args.max_duration,
    })
}
