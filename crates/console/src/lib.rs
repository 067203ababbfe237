//! The operator's console: an interactive master with a web page.
//!
//! The operator drives the twin (keys, an on-screen joystick that stops the
//! robot when released, or the wall follower), records a rehearsal, runs
//! the mission pipeline on it and sees every stage on the map, verifies the
//! plan on the twin, signs and uploads it to a robot agent over zenoh, and
//! supervises it: the robot's reported pose against the twin's prediction,
//! residuals against the hand-back tolerances, the link and the age of
//! every stream, the hand-back banner and the decision after it (a
//! continuation around what the updated twin learnt, or the end of the
//! mission).
//!
//! Modules: [`workspace`] (the twin, no I/O), [`planning`] (pipeline and
//! verification), [`corridor`] (a plan's corridor clipped to the map, as
//! drawn), [`fleet`] (one master end and operator per robot), [`core`]
//! (commands in, frames out), [`words`] (refusals in the operator's
//! words), [`protocol`] (the page's commands),
//! [`auth`] (token and origin), [`server`] (axum, WebSockets, zenoh
//! drivers). The page itself is `web/` (plain modules, uPlot), embedded in
//! the binary.

pub mod auth;
pub mod core;
pub mod corridor;
pub mod fleet;
pub mod foxglove_bridge;
pub mod planning;
pub mod protocol;
pub mod server;
pub mod words;
pub mod workspace;

use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context;
use twindrive_agent::master::MasterConfig;
use twindrive_link::LinkEmulator;
use twindrive_link::emulator::LinkProfile;
use twindrive_link::envelope::{SigningKey, Supervision};
use twindrive_log::MissionLog;
use twindrive_net::{Emulation, SessionOptions};
use twindrive_sim::Scenario;

use crate::fleet::{RobotSlot, SharedSlot};

/// Everything `twindrive console` is started with.
pub struct ConsoleConfig {
    /// The twin.
    pub scenario: Scenario,
    /// The scenario file's bytes: plans are signed for their SHA-256.
    pub scenario_bytes: Vec<u8>,
    pub listen: SocketAddr,
    /// Further origins allowed to open the WebSocket.
    pub allow_origins: Vec<String>,
    pub key: Option<SigningKey>,
    /// The robot's calibrated parameters (default: the twin's nominal ones).
    pub params: Option<twindrive_kinematics::DiffDriveParams>,
    pub robots: Vec<String>,
    /// The console's end of each robot's link (sealing), in `robots`' order.
    pub robot_links: Vec<twindrive_link::secure::Peers>,
    pub session: SessionOptions,
    /// The emulated link on every robot's traffic, at this end.
    pub link: Option<LinkProfile>,
    pub seed: u64,
    pub telemetry_budget_bytes_s: f64,
    pub supervision: Supervision,
    pub expires_in_s: u64,
    /// Plans, rehearsals, robot logs, reports, the access token.
    pub out: PathBuf,
    /// A rehearsal to start with (a mission log made in this twin).
    pub rehearsal: Option<MissionLog>,
    /// Also serve the live streams to Foxglove / Lichtblick here.
    pub foxglove: Option<SocketAddr>,
}

/// The twin the operator rehearses on: the site's scenario with its robot
/// moving as the calibrated `params` say, the same parameters plans are
/// made with (one robot model per rehearsal). Without a calibration the
/// console does not plan ([`core::NO_MODEL`]).
pub fn twin_model(
    mut scenario: Scenario,
    params: Option<twindrive_kinematics::DiffDriveParams>,
) -> Scenario {
    if let Some(p) = params {
        scenario.robot.true_params = p;
    }
    scenario
}

/// Runs the console until interrupted (Ctrl-C or SIGTERM).
pub fn run(config: ConsoleConfig) -> anyhow::Result<()> {
    // The address first: a console that cannot listen writes nothing.
    let listener = std::net::TcpListener::bind(config.listen).with_context(|| {
        format!(
            "--listen {}: cannot listen there (another console or program holds it?); choose another address with --listen",
            config.listen
        )
    })?;
    listener.set_nonblocking(true)?;
    std::fs::create_dir_all(&config.out)
        .with_context(|| format!("creating {}", config.out.display()))?;
    let token = auth::token_in(&config.out.join("console.token"))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(serve(config, token, listener))
}

fn unix_now_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

async fn serve(
    config: ConsoleConfig,
    token: String,
    listener: std::net::TcpListener,
) -> anyhow::Result<()> {
    let listener = tokio::net::TcpListener::from_std(listener)
        .with_context(|| format!("--listen {}", config.listen))?;
    let bound = listener.local_addr()?;
    let access = Arc::new(auth::Access::new(token, bound, &config.allow_origins));
    let zero = Instant::now();
    let unix_at_zero_s = unix_now_s();
    let master_config =
        MasterConfig::for_link(config.link.as_ref(), config.telemetry_budget_bytes_s);
    let robots: Vec<SharedSlot> = config
        .robots
        .iter()
        .map(|id| {
            SharedSlot(Arc::new(Mutex::new(RobotSlot::new(
                id,
                &config.out.join(id),
                master_config,
            ))))
        })
        .collect();
    let mut ws = workspace::Workspace::new(twin_model(config.scenario.clone(), config.params));
    if let Some(log) = config.rehearsal {
        ws.set_rehearsal(log);
    }
    let instance = auth::new_token()?[..12].to_owned();
    let mut core = core::Core::new(
        ws,
        robots.clone(),
        core::Settings {
            key: config.key,
            params: config
                .params
                .unwrap_or(config.scenario.robot.nominal_params),
            calibrated: config.params.is_some(),
            world_sha256: twindrive_mission::plan::sha256_hex(&config.scenario_bytes),
            unix_at_zero_s,
            supervision: config.supervision,
            expires_in_s: config.expires_in_s,
            out: config.out.clone(),
            instance,
        },
    );
    let mut bridge = match config.foxglove {
        Some(addr) => {
            Some(foxglove_bridge::Bridge::start(addr, &config.scenario, &config.robots).await?)
        }
        None => None,
    };
    let (frames_tx, frames_rx) = watch::channel(Arc::new(core.frame(0)));
    let core = Arc::new(Mutex::new(core));
    let stop = Arc::new(AtomicBool::new(false));

    // The robots' links, on one network (zenoh), opened in the background:
    // the page serves at once, and the robots show an outage until the
    // network (a router not up yet, a network coming up) is there.
    let (network_tx, network_rx) = tokio::sync::oneshot::channel::<twindrive_net::Network>();
    let links = if robots.is_empty() {
        None
    } else {
        let robots = robots.clone();
        let robot_links = config.robot_links;
        let options = config.session.clone();
        let link = config.link.clone();
        let seed = config.seed;
        let stop = stop.clone();
        Some(tokio::spawn(async move {
            let network = match twindrive_net::Network::open(&options).await {
                Ok(n) => n,
                Err(e) => {
                    tracing::error!("no network to the robots: {e:#}");
                    return;
                }
            };
            let mut drivers = Vec::new();
            for (k, (slot, peers)) in robots.iter().zip(robot_links).enumerate() {
                let id = slot.lock().id.clone();
                let mut link_end = twindrive_net::LinkEnd::master(&id, peers);
                let network = network.clone();
                let mut endpoint = slot.clone();
                let stop = stop.clone();
                let emulation = link.clone().map(|p| Emulation {
                    outgoing: LinkEmulator::new(p.clone(), seed, 2 * k as u64),
                    incoming: LinkEmulator::new(p, seed, 2 * k as u64 + 1),
                });
                drivers.push(tokio::spawn(async move {
                    let mut stats = twindrive_net::DriveStats::default();
                    let result = twindrive_net::drive_counting(
                        &mut endpoint,
                        &network,
                        &mut link_end,
                        emulation,
                        Duration::from_secs(100 * 365 * 86_400),
                        zero,
                        &mut stats,
                        |_| stop.load(Ordering::Relaxed),
                    )
                    .await;
                    if let Err(e) = result {
                        tracing::error!(robot = %id, "the link driver stopped: {e:#}");
                    }
                }));
            }
            for d in drivers {
                let _ = d.await;
            }
            let _ = network_tx.send(network);
        }))
    };

    // The tick: the twin at 50 Hz, frames at 25 Hz.
    let foxglove_port = bridge.as_ref().map(foxglove_bridge::Bridge::port);
    let ticker = {
        let core = core.clone();
        let stop = stop.clone();
        tokio::spawn(async move {
            let mut interval = tokio::time::interval(Duration::from_millis(20));
            interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
            let mut n = 0u64;
            let mut said = 0u64;
            while !stop.load(Ordering::Relaxed) {
                interval.tick().await;
                n += 1;
                let now = zero.elapsed().as_nanos() as u64;
                let frame = {
                    let mut c = core.lock().unwrap_or_else(|e| e.into_inner());
                    c.tick(now);
                    // The page's events, on stderr too (one line each).
                    for (seq, level, text) in c.events_since(said) {
                        said = seq;
                        eprintln!("console: {level}: {text}");
                    }
                    if n.is_multiple_of(2)
                        && let Some(b) = &mut bridge
                    {
                        let unix_ns = ((unix_at_zero_s + now as f64 * 1e-9) * 1e9) as u64;
                        b.publish(&c, unix_ns);
                    }
                    n.is_multiple_of(2).then(|| c.frame(now))
                };
                if let Some(f) = frame {
                    frames_tx.send_replace(Arc::new(f));
                }
            }
        })
    };

    let app = server::App {
        core: core.clone(),
        frames: frames_rx,
        access: access.clone(),
        zero,
    };
    let url = format!("http://{bound}/?token={}", access.token());
    {
        // A closed stdout (a launcher that read the address and left) must
        // not stop the console.
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "console: open {url}");
        if let (Some(addr), Some(port)) = (config.foxglove, foxglove_port) {
            let _ = writeln!(
                out,
                "console: Foxglove WebSocket at ws://{}:{port}",
                addr.ip()
            );
        }
        let _ = writeln!(
            out,
            "console: twin `{}`, robots {:?}, files in {}",
            config.scenario.name,
            config.robots,
            config.out.display()
        );
        let _ = out.flush();
    }
    let shutdown = {
        let stop = stop.clone();
        async move {
            wait_for_signal().await;
            stop.store(true, Ordering::Relaxed);
        }
    };
    axum::serve(listener, server::router(app))
        .with_graceful_shutdown(shutdown)
        .await
        .context("serving the console")?;
    stop.store(true, Ordering::Relaxed);
    let _ = ticker.await;
    if let Some(links) = links {
        // The drivers see `stop` within 50 ms; a network still being
        // opened is given up.
        match tokio::time::timeout(Duration::from_secs(2), links).await {
            Ok(_) => {
                if let Ok(n) = network_rx.await {
                    n.close().await;
                }
            }
            Err(_) => tracing::warn!("the robots' links did not stop within 2 s"),
        }
    }
    core.lock().unwrap_or_else(|e| e.into_inner()).finish_all();
    eprintln!("console: stopped; reports in {}", config.out.display());
    Ok(())
}

use tokio::sync::watch;

async fn wait_for_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = tokio::signal::ctrl_c() => {}
                    _ = term.recv() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}
