//! `twindrive robot`: the robot agent as a process, on a simulated site or
//! a ROS 2 robot through rmw_zenoh, keeping its state in its directory.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use twindrive_agent::backend::SimBackend;
use twindrive_agent::robot::{AgentConfig, RobotAgent};
use twindrive_agent::ros::RosConfig;
use twindrive_link::envelope::{SigningKey, VerifyingKey};
use twindrive_net::{SessionOptions, up_key};
use twindrive_sim::Scenario;
use twindrive_store::RobotDir;

use crate::{runtime, unix_now_s};

/// A robot process, checked: who it is, whom it trusts, where it drives
/// and keeps its state, how it reaches the master.
pub struct RobotConfig {
    pub id: String,
    /// The site file (for messages) and the site it describes.
    pub site_path: PathBuf,
    pub site: Scenario,
    /// The site's `[ros]` section: drive a ROS 2 robot, not the simulation.
    pub ros: Option<RosConfig>,
    pub trusted: Vec<VerifyingKey>,
    /// The robot's own key: seals every message to the master.
    pub key: SigningKey,
    pub state_dir: PathBuf,
    pub zenoh: SessionOptions,
    pub telemetry_budget: f64,
    /// The simulated site runs this many times faster than real time (a
    /// ROS 2 robot runs in real time: 1).
    pub time_scale: f64,
    /// Stop after this many seconds (tests, experiments).
    pub run_for: Option<f64>,
    /// Localize against the plan's map (else odometry alone).
    pub localization: bool,
}

/// Runs the robot agent until stopped (Ctrl-C, or `run_for`).
pub fn run(args: &RobotConfig) -> anyhow::Result<()> {
    let site = args.site.clone();
    let mut config = AgentConfig::new(&args.id, args.trusted.clone());
    // The agent's clock: zero now, in Unix time and for the driver alike.
    let zero = std::time::Instant::now();
    config.unix_time_at_zero_s = unix_now_s()?;
    config.telemetry_budget_bytes_s = args.telemetry_budget;
    config.time_scale = args.time_scale;
    if !args.localization {
        config.localization = twindrive_agent::localize::LocalizeSettings::odometry_only();
    }
    let rt = runtime()?;
    match args.ros.clone() {
        None => {
            let start = site.robot.start;
            // The site runs as long as the robot does.
            let backend =
                SimBackend::new(site, start, 1e6).map_err(|e| anyhow::anyhow!("--site: {e}"))?;
            run_agent(args, config, backend, zero, &rt)
        }
        Some(ros) => {
            let bridge = twindrive_agent::ros::RosBridge::new(ros, &site, 0.0)
                .map_err(|e| anyhow::anyhow!("--site {}: {e}", args.site_path.display()))?;
            let options = SessionOptions {
                connect: bridge.config().connect.clone(),
                patience: args.zenoh.patience,
                ..SessionOptions::default()
            };
            let (backend, ros_network) = rt.block_on(async {
                let network = twindrive_net::Network::open(&options)
                    .await
                    .context("the robot's ROS 2 network (the site's [ros] connect)")?;
                let backend = twindrive_net::ros::RosBackend::open(
                    &network,
                    bridge,
                    zero,
                    Some(site.world.log_map()),
                )
                .await?;
                anyhow::Ok((backend, network))
            })?;
            eprintln!(
                "robot {}: driving a ROS 2 robot through rmw_zenoh at {}",
                args.id,
                options.connect.join(", ")
            );
            let result = run_agent(args, config, backend, zero, &rt);
            rt.block_on(ros_network.close());
            result
        }
    }
}

/// The `[ros]` section of a site file, if it has one, with errors that
/// name its line.
pub fn read_ros_section(site: &Path) -> anyhow::Result<Option<twindrive_agent::ros::RosConfig>> {
    #[derive(serde::Deserialize)]
    struct RosOnly {
        ros: Option<twindrive_agent::ros::RosConfig>,
        #[serde(flatten)]
        _rest: toml::Table,
    }
    let text = std::fs::read_to_string(site)
        .with_context(|| format!("--site: reading {}", site.display()))?;
    let parsed: RosOnly =
        toml::from_str(&text).map_err(|e| anyhow::anyhow!("--site {}: {e}", site.display()))?;
    Ok(parsed.ros)
}

/// Runs the agent with `backend` until stopped.
fn run_agent<B: twindrive_agent::backend::RobotBackend>(
    args: &RobotConfig,
    config: AgentConfig,
    backend: B,
    zero: std::time::Instant,
    rt: &tokio::runtime::Runtime,
) -> anyhow::Result<()> {
    let mut agent = RobotDir::open(&args.state_dir)
        .and_then(|store| RobotAgent::new(config, backend, store))
        .with_context(|| format!("--state-dir {}", args.state_dir.display()))?;
    let peers =
        twindrive_store::link_state::robot_end(&args.state_dir, &args.id, &args.key, &args.trusted)
            .with_context(|| format!("--state-dir {}", args.state_dir.display()))?;
    let mut link = twindrive_net::LinkEnd::robot(&args.id, peers);
    let options = args.zenoh.clone();
    let deadline = Duration::from_secs_f64(args.run_for.unwrap_or(1e9));
    rt.block_on(async {
        // A robot that boots before its router or its network keeps trying
        // (for --connect-timeout), and one that cannot listen stops at once.
        let network = twindrive_net::Network::open(&options)
            .await
            .context("the link to the master")?;
        eprintln!(
            "robot {}: listening on {} for plans signed by {} trusted key(s); every message sealed with key {}",
            args.id,
            up_key(&args.id),
            args.trusted.len(),
            twindrive_store::link_state::fingerprint(&args.key.verifying_key()),
        );
        let mut stats = twindrive_net::DriveStats::default();
        let mut voice = twindrive_progress::Voice::new();
        let drive = twindrive_net::drive_counting(
            &mut agent,
            &network,
            &mut link,
            None,
            deadline,
            zero,
            &mut stats,
            |agent| {
                // Every journal line as it happens, and what the robot is
                // doing when nothing happened for a while.
                for line in agent.take_said() {
                    voice.say(&line);
                }
                voice.status(|| agent.doing());
                false
            },
        );
        tokio::select! {
            r = drive => {
                if args.run_for.is_none() {
                    r?;
                }
            }
            _ = tokio::signal::ctrl_c() => eprintln!("robot {}: stopping", args.id),
        }
        network.close().await;
        anyhow::Ok(())
    })
}
