//! `twindrive console`: checks the command line, loads the twin, the key
//! and a rehearsal, and hands over to `twindrive-console`.

use anyhow::{Context, bail};
use twindrive_console::ConsoleConfig;
use twindrive_link::envelope::Supervision;
use twindrive_net::SessionOptions;
use twindrive_sim::Scenario;

use crate::cli::ConsoleArgs;
use crate::usage::usage;

pub fn run(args: &ConsoleArgs) -> anyhow::Result<()> {
    crate::flags::check_distinct_robots(&args.robot)?;
    for o in &args.allow_origin {
        if !(o.starts_with("http://") || o.starts_with("https://")) {
            return Err(usage(format!(
                "--allow-origin {o}: an origin is scheme://host[:port], e.g. https://ops.example"
            )));
        }
    }
    let (scenario, scenario_bytes) = match &args.scenario {
        Some(p) => {
            let bytes =
                std::fs::read(p).with_context(|| format!("--scenario: reading {}", p.display()))?;
            let s = Scenario::load(p).map_err(|e| anyhow::anyhow!("--scenario: {e}"))?;
            (s, bytes)
        }
        None => {
            let s = twindrive_sim::builtin::load("wall_following")
                .expect("built in")
                .map_err(|e| anyhow::anyhow!("the built-in scenario: {e}"))?;
            (
                s,
                twindrive_sim::builtin::WALL_FOLLOWING.as_bytes().to_vec(),
            )
        }
    };
    let link = crate::flags::link_profile(args.link.as_deref())?;
    let key = args
        .key
        .as_deref()
        .map(crate::flags::signing_key)
        .transpose()?;
    let mut robot_links = Vec::new();
    if !args.robot.is_empty() {
        let (Some(key), Some(key_path)) = (&key, &args.key) else {
            return Err(usage(
                "--robot: talking to a robot needs the master's --key (it seals every message)",
            ));
        };
        let robot_keys = crate::flags::robot_keys(&args.trust_robot)?;
        crate::flags::check_robot_keys(&args.robot, &robot_keys)?;
        let dir = crate::flags::link_state_dir(args.link_state.as_deref(), key_path);
        for id in &args.robot {
            robot_links.push(twindrive_store::link_state::master_end(
                &dir,
                id,
                key,
                &robot_keys[id],
            )?);
        }
    }
    let rehearsal = args
        .rehearsal
        .as_deref()
        .map(|p| {
            twindrive_log::read_mission_log(p)
                .with_context(|| format!("--rehearsal {}", p.display()))
        })
        .transpose()?;
    if let Some(log) = &rehearsal
        && log.steps.len() < 20
    {
        bail!(
            "--rehearsal: {} steps; a rehearsal needs at least 20",
            log.steps.len()
        );
    }
    twindrive_console::run(ConsoleConfig {
        scenario,
        scenario_bytes,
        listen: args.listen,
        allow_origins: args.allow_origin.clone(),
        key,
        params: args
            .calibration
            .as_deref()
            .map(crate::flags::read_calibration)
            .transpose()?,
        robots: args.robot.clone(),
        robot_links,
        session: SessionOptions {
            listen: args.zenoh_listen.clone(),
            connect: args.connect.clone(),
            config_file: args.zenoh_config.clone(),
            mode: None,
            // The console serves the twin without its robots too: it keeps
            // trying while no router answers, and says so on its log.
            patience: std::time::Duration::from_secs(365 * 86_400),
        },
        link,
        seed: args.seed,
        telemetry_budget_bytes_s: args.telemetry_budget,
        supervision: Supervision {
            dead_man_timeout_s: args.supervise,
        },
        expires_in_s: args.expires_in,
        out: args.out.clone(),
        rehearsal,
        foxglove: args.foxglove,
    })
}
