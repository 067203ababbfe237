//! `twindrive site-sim`: a site's simulator behind a pipe.

use std::io::{BufRead, Write};
use std::path::Path;

use anyhow::{Context, bail};
use twindrive_agent::backend::{RobotBackend, SimBackend};
use twindrive_sim::Scenario;

/// Most steps one line may ask for (a minute at 1 kHz).
const MAX_STEPS: u64 = 60_000;

pub fn run(site: &Path) -> anyhow::Result<()> {
    let scenario = Scenario::load(site).with_context(|| format!("--site {}", site.display()))?;
    let start = scenario.robot.start;
    let rad_per_tick = std::f64::consts::TAU / f64::from(scenario.log_header().ticks_per_rev);
    let mut backend =
        SimBackend::new(scenario, start, 1e6).map_err(|e| anyhow::anyhow!("--site: {e}"))?;
    let stdin = std::io::stdin().lock();
    let mut out = std::io::stdout().lock();
    let mut ticks = [0i64; 2];
    for (n, line) in stdin.lines().enumerate() {
        let line = line.context("reading stdin")?;
        let fields: Vec<&str> = line.split_whitespace().collect();
        let parse = |i: usize| -> anyhow::Result<f64> {
            fields
                .get(i)
                .and_then(|f| f.parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .with_context(|| {
                    format!(
                        "stdin line {}: expected `LEFT_RAD_S RIGHT_RAD_S STEPS`, got `{line}`",
                        n + 1
                    )
                })
        };
        if fields.len() != 3 {
            bail!(
                "stdin line {}: expected `LEFT_RAD_S RIGHT_RAD_S STEPS`, got `{line}`",
                n + 1
            );
        }
        let wheels = [parse(0)?, parse(1)?];
        let steps = parse(2)?;
        if !(steps >= 1.0 && steps <= MAX_STEPS as f64 && steps.fract() == 0.0) {
            bail!(
                "stdin line {}: STEPS must be a whole number from 1 to {MAX_STEPS}",
                n + 1
            );
        }
        let (mut bump, mut blocked) = (false, false);
        let mut last = None;
        for _ in 0..steps as u64 {
            let Some(r) = backend.step(&mut |_| wheels) else {
                bail!("the site's simulation ended");
            };
            if let Some(t) = r.encoder_ticks {
                ticks = t;
            }
            bump |= r.bump;
            blocked |= r.blocked;
            last = Some(r);
        }
        let r = last.expect("at least one step");
        let pose = backend.true_pose();
        let ranges: Vec<Option<f64>> = r
            .ranges_m
            .iter()
            .map(|v| v.is_finite().then_some(*v))
            .collect();
        serde_json::to_writer(
            &mut out,
            &serde_json::json!({
                "t_s": r.t_s,
                "wheel_rad": [ticks[0] as f64 * rad_per_tick, ticks[1] as f64 * rad_per_tick],
                "wheel_rad_s": r.record.wheel_rad_s,
                "bump": bump,
                "blocked": blocked,
                "ranges_m": ranges,
                "pose": [pose.x_m, pose.y_m, pose.heading_rad],
            }),
        )?;
        out.write_all(b"\n")?;
        out.flush()?;
    }
    Ok(())
}
