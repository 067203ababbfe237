//! `twindrive robot`, `twindrive master` and `twindrive router`: flags into
//! the processes' checked configurations (the processes are
//! `twindrive-ops`').

use std::path::PathBuf;

use twindrive_agent::narrate::Verbosity;
use twindrive_agent::operator::{OnHandback, Outcome};
use twindrive_net::SessionOptions;
use twindrive_ops::MasterSettings;
use twindrive_ops::robot::RobotConfig;
use twindrive_sim::Scenario;

use crate::cli::{MasterArgs, OnHandbackArg, RobotArgs, ZenohArgs};
use crate::usage::usage;

fn session_options(z: &ZenohArgs) -> SessionOptions {
    SessionOptions {
        listen: z.listen.clone(),
        connect: z.connect.clone(),
        config_file: z.zenoh_config.clone(),
        mode: None,
        patience: std::time::Duration::from_secs_f64(z.connect_timeout),
    }
}

/// `twindrive robot`.
pub fn robot(args: &RobotArgs) -> anyhow::Result<()> {
    let trusted = args
        .trust
        .iter()
        .map(|path| crate::flags::public_key("--trust", path))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let key = crate::flags::signing_key(&args.key)?;
    let site = Scenario::load(&args.site).map_err(|e| anyhow::anyhow!("--site: {e}"))?;
    let ros = twindrive_ops::robot::read_ros_section(&args.site)?;
    if ros.is_some() && args.time_scale != 1.0 {
        return Err(usage(format!(
            "--time-scale: a ROS 2 robot runs in real time (1), got {}",
            args.time_scale
        )));
    }
    twindrive_ops::robot::run(&RobotConfig {
        id: args.id.clone(),
        site_path: args.site.clone(),
        site,
        ros,
        trusted,
        key,
        state_dir: args.state_dir.clone(),
        zenoh: session_options(&args.zenoh),
        telemetry_budget: args.telemetry_budget,
        time_scale: args.time_scale,
        run_for: args.run_for,
        localization: args.localization != "off",
    })
}

/// `twindrive router`.
pub fn router(listen: Vec<String>, zenoh_config: Option<PathBuf>) -> anyhow::Result<()> {
    twindrive_ops::router::run(listen, zenoh_config)
}

/// `twindrive master`: exits 3 when a robot handed back, 4 when one
/// rejected its plan.
pub fn master(args: &MasterArgs) -> anyhow::Result<()> {
    crate::flags::check_distinct_robots(&args.robot)?;
    if args.robot.len() > 1 && args.signed.is_some() {
        return Err(usage(
            "--signed holds a plan signed for one robot; a fleet needs --plan and --key (each robot gets its own signature)",
        ));
    }
    let robot_keys = crate::flags::robot_keys(&args.trust_robot)?;
    crate::flags::check_robot_keys(&args.robot, &robot_keys)?;
    let key = crate::flags::master_key(&args.key, &args.robot, Some(&robot_keys))?;
    let settings = MasterSettings {
        plan: args.plan.clone(),
        signed: args.signed.clone(),
        key,
        robot_keys,
        link_state: crate::flags::link_state_dir(args.link_state.as_deref(), &args.key),
        robots: args.robot.clone(),
        out: args.out.clone(),
        zenoh: session_options(&args.zenoh),
        profile: crate::flags::link_profile(args.link.as_deref())?,
        seed: args.seed,
        expires_in: args.expires_in,
        supervise: args.supervise,
        on_handback: match args.on_handback {
            OnHandbackArg::Stop => OnHandback::Stop,
            OnHandbackArg::Replan => OnHandback::Replan,
        },
        scenario: args.scenario.clone(),
        site_maps: args.site_maps.clone(),
        timeout: args.timeout,
        telemetry_budget: args.telemetry_budget,
        log_wait: args.log_wait,
        full_logs: args.full_logs,
        allow_failed_verification: args.allow_failed_verification,
        verbosity: if args.quiet {
            Verbosity::Quiet
        } else if args.verbose {
            Verbosity::Verbose
        } else {
            Verbosity::Normal
        },
    };
    let outcome = twindrive_ops::master::run(&settings, &mut std::io::stdout().lock())?;
    match outcome {
        Outcome::HandedBack => std::process::exit(3),
        Outcome::Rejected => std::process::exit(4),
        _ => Ok(()),
    }
}
