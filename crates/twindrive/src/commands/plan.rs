//! `twindrive plan`: a mission log and a calibration in, a verified-format,
//! hashed mission plan out, with the pipeline's figures and an MCAP of every
//! stage (the work is `twindrive-workflow`'s).

use anyhow::Context;
use twindrive_mission::freedom::FreedomSettings;
use twindrive_mission::pipeline::PipelineSettings;
use twindrive_mission::redundancy::RedundancyConfig;
use twindrive_workflow::plan::{
    Job, log_dir_sha256, make_plan, print_summary, scenario_for, write_outputs,
};

use crate::cli::PlanArgs;

pub fn run(args: &PlanArgs) -> anyhow::Result<()> {
    let job = resolve(args)?;
    let (plan, stages) = make_plan(&job)?;
    write_outputs(&plan, &stages, &job.scenario, &args.out)?;
    print_summary(
        &stages.summary(),
        &plan,
        &args.out,
        &mut std::io::stdout().lock(),
    )?;
    Ok(())
}

fn resolve(args: &PlanArgs) -> anyhow::Result<Job> {
    let log = twindrive_log::read_log_dir(&args.log_dir)?;
    let log_sha256 = log_dir_sha256(&args.log_dir)?;
    let params = crate::flags::read_calibration(&args.calibration).context("--calibration")?;
    let mut redundancy = match &args.redundancy {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            toml::from_str::<RedundancyConfig>(&text)
                .with_context(|| format!("{}", path.display()))?
        }
        None => RedundancyConfig::with_pinch_distance(
            args.pinch_distance.unwrap_or(log.header.footprint_radius_m),
        ),
    };
    if let Some(d) = args.pinch_distance {
        redundancy.pinch_distance_m = d;
    }
    args.flags.apply(&mut redundancy);
    redundancy.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    let scenario = scenario_for(&log, args.scenario.as_deref())?;
    let freedom = match &args.freedom {
        Some(path) => crate::flags::read_freedom(path, log.header.footprint_radius_m)?,
        None => FreedomSettings::default(),
    };
    Ok(Job {
        log,
        log_sha256,
        params,
        scenario,
        settings: PipelineSettings {
            planner: Default::default(),
            redundancy,
            filter: Default::default(),
            freedom,
        },
        time_optimal: args.time_optimal,
    })
}
