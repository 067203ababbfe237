//! `twindrive rehearse`: a rehearsal from goals on the twin.

use std::path::PathBuf;

use anyhow::Context;
use twindrive_mission::goals::Goals;
use twindrive_sim::Scenario;
use twindrive_workflow::rehearse::{plan_route, rehearse_into};
use twindrive_workflow::simulate::print_summary;

pub struct Args {
    pub scenario: PathBuf,
    pub goals: PathBuf,
    pub freedom: Option<PathBuf>,
    pub route_only: bool,
    pub out: Option<PathBuf>,
    pub seed: Option<u64>,
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    let mut scenario = Scenario::load(&args.scenario)?;
    if let Some(seed) = args.seed {
        scenario.seed = seed;
    }
    let text = std::fs::read_to_string(&args.goals)
        .with_context(|| format!("--goals: reading {}", args.goals.display()))?;
    let goals = Goals::parse(&text)
        .map_err(|e| anyhow::anyhow!("--goals: {}: {e}", args.goals.display()))?;
    let zones = match &args.freedom {
        Some(path) => crate::flags::read_freedom(path, scenario.robot.footprint_radius_m)?.keep_out,
        None => Vec::new(),
    };
    if args.route_only {
        let planned = plan_route(&scenario, &goals, &zones)?;
        println!("{}", serde_json::to_string_pretty(&planned)?);
        return Ok(());
    }
    let out = args.out.as_deref().expect("clap requires --out");
    let (planned, summary) = rehearse_into(scenario, &goals, &zones, out)?;
    println!(
        "route: {} waypoint(s){}, {:.2} m in {} leg(s), about {:.0} s, the footprint at least {:.3} m clear; planned in {:.1} ms",
        goals.waypoints.len(),
        if goals.return_home { " and home" } else { "" },
        planned.route.length_m,
        planned.route.points.len() - 1,
        planned.duration_s,
        planned.route.min_clearance_m,
        planned.planning_ms
    );
    for (i, a) in planned.areas.iter().enumerate() {
        println!(
            "area {}: {:.2} m² of free ground, {} lane(s) and {} touch-up(s): the twin swept {:.1} % (planned {:.1} %)",
            i + 1,
            a.free_m2,
            a.lanes,
            a.touch_ups,
            a.swept_percent.unwrap_or(f64::NAN),
            a.planned_percent
        );
    }
    print_summary(&summary, out, &mut std::io::stdout().lock())?;
    Ok(())
}
