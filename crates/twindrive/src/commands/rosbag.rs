//! `twindrive rosbag`: a mission log as a rosbag2 recording.

use std::io::Write;

use anyhow::Context;
use twindrive_ros::BagWriter;
use twindrive_ros::export::{ExportOptions, write_log_bag};
use twindrive_ros::msgs::Distro;

use crate::cli::{DistroArg, RosbagArgs, StorageArg};
use twindrive_files::Staging;

pub fn run(args: &RosbagArgs) -> anyhow::Result<()> {
    let log = twindrive_log::read_mission_log(&args.log)?;
    let map = match &args.scenario {
        Some(p) => Some(
            twindrive_sim::Scenario::load(p)
                .with_context(|| format!("--scenario {}", p.display()))?
                .world
                .log_map(),
        ),
        None => match twindrive_sim::builtin::load(&log.header.scenario) {
            Some(s) => Some(s?.world.log_map()),
            None => {
                tracing::warn!(
                    scenario = %log.header.scenario,
                    "the log's scenario is not built in and no --scenario was given: the bag has no /map"
                );
                None
            }
        },
    };
    let plan: Option<Vec<(u64, twindrive_kinematics::Pose)>> = match &args.plan {
        Some(p) => {
            let plan = twindrive_workflow::inputs::read_plan(p)?;
            let poses = plan
                .samples
                .iter()
                .map(|s| twindrive_log::ns_from_seconds(s.t_s).map(|t| (t, s.pose())))
                .collect::<Option<Vec<_>>>()
                .with_context(|| {
                    format!("{}: a sample time is negative or not finite", p.display())
                })?;
            Some(poses)
        }
        None => None,
    };
    let distro = match args.distro {
        DistroArg::Humble => Distro::Humble,
        DistroArg::Jazzy => Distro::Jazzy,
    };
    let options = ExportOptions {
        start_ns: (args.start_time * 1e9).round() as u64,
        map: map.as_ref(),
        plan: plan.as_deref(),
    };
    let name = args
        .out
        .file_name()
        .and_then(|n| n.to_str())
        .filter(|n| !n.is_empty() && *n != "..")
        .with_context(|| format!("--out {}: name a bag directory", args.out.display()))?;
    let staging = Staging::new(&args.out, "rosbag")?;
    let (file_name, summary) = match args.storage {
        StorageArg::Mcap => {
            let file_name = format!("{name}_0.mcap");
            let mut summary = None;
            staging.write_with(&file_name, |w| {
                let bag = BagWriter::mcap(w, &file_name, distro)?;
                summary = Some(write_log_bag(&log, &options, bag)?);
                Ok(())
            })?;
            (file_name, summary.expect("written"))
        }
        StorageArg::Sqlite3 => {
            let file_name = format!("{name}_0.db3");
            let written = BagWriter::sqlite3(&staging.path(&file_name), &file_name, distro)
                .and_then(|bag| write_log_bag(&log, &options, bag))
                .with_context(|| format!("writing {}/{file_name}", args.out.display()))?;
            (file_name, written)
        }
    };
    staging.write_with("metadata.yaml", |w| {
        w.write_all(summary.metadata_yaml.as_bytes())?;
        Ok(())
    })?;
    staging.commit()?;
    let mut o = std::io::stdout().lock();
    writeln!(
        o,
        "wrote {}/ ({file_name}, metadata.yaml):",
        args.out.display()
    )?;
    for (topic, ty, n) in &summary.topics {
        writeln!(o, "  {topic:<24} {ty:<45} {n:>8}")?;
    }
    Ok(())
}
