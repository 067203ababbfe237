//! `twindrive robot`, `twindrive master` and `twindrive router`: the two
//! ends of decoupled operation as processes over zenoh, and a router for a
//! fleet. The protocol is twindrive-agent's state machines; this file reads
//! inputs, opens the session, drives them and writes what they produce.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, bail};
use twindrive_agent::backend::SimBackend;
use twindrive_agent::master::{Master, MasterConfig};
use twindrive_agent::narrate::{Narrator, Verbosity};
use twindrive_agent::operator::{OnHandback, Operator, OperatorConfig, Outcome};
use twindrive_agent::robot::{AgentConfig, RobotAgent};
use twindrive_agent::twin::Twin;
use twindrive_files::write_durably;
use twindrive_link::emulator::LinkEmulator;
use twindrive_link::envelope::{
    Envelope, Supervision, Tolerances, peek_envelope, read_public_key_pem, sha256_hex, sign_plan,
};
use twindrive_mission::plan::MissionPlan;
use twindrive_net::{Emulation, SessionOptions, down_key, open_session, up_key};
use twindrive_sim::Scenario;
use twindrive_store::{DirStore, MasterArchive, RobotDir};

use crate::cli::{MasterArgs, OnHandbackArg, RobotArgs, ZenohArgs};
use crate::usage::usage;

fn session_options(z: &ZenohArgs, mode: Option<&str>) -> SessionOptions {
    SessionOptions {
        listen: z.listen.clone(),
        connect: z.connect.clone(),
        config_file: z.zenoh_config.clone(),
        mode: mode.map(str::to_owned),
    }
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")
}

fn unix_now_s() -> anyhow::Result<f64> {
    Ok(crate::flags::since_epoch()?.as_secs_f64())
}

/// `twindrive robot`.
pub fn robot(args: &RobotArgs) -> anyhow::Result<()> {
    let mut trusted = Vec::new();
    for path in &args.trust {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("--trust: reading {}", path.display()))?;
        trusted.push(
            read_public_key_pem(&text)
                .map_err(|e| anyhow::anyhow!("--trust {}: {e}", path.display()))?,
        );
    }
    let site = Scenario::load(&args.site).map_err(|e| anyhow::anyhow!("--site: {e}"))?;
    let ros = read_ros_section(&args.site)?;
    let mut config = AgentConfig::new(&args.id, trusted);
    // The agent's clock: zero now, in Unix time and for the driver alike.
    let zero = std::time::Instant::now();
    config.unix_time_at_zero_s = unix_now_s()?;
    config.telemetry_budget_bytes_s = args.telemetry_budget;
    config.time_scale = args.time_scale;
    if args.localization == "off" {
        config.localization = twindrive_agent::localize::LocalizeSettings::odometry_only();
    }
    let rt = runtime()?;
    match ros {
        None => {
            let start = site.robot.start;
            // The site runs as long as the robot does.
            let backend =
                SimBackend::new(site, start, 1e6).map_err(|e| anyhow::anyhow!("--site: {e}"))?;
            run_agent(args, config, backend, zero, &rt)
        }
        Some(ros) => {
            if args.time_scale != 1.0 {
                return Err(usage(format!(
                    "--time-scale: a ROS 2 robot runs in real time (1), got {}",
                    args.time_scale
                )));
            }
            let bridge = twindrive_agent::ros::RosBridge::new(ros, &site, 0.0)
                .map_err(|e| anyhow::anyhow!("--site {}: {e}", args.site.display()))?;
            let options = SessionOptions {
                listen: Vec::new(),
                connect: bridge.config().connect.clone(),
                config_file: None,
                mode: None,
            };
            let deadline = Duration::from_secs_f64(args.run_for.unwrap_or(1e9));
            let (backend, ros_session) = rt.block_on(async {
                let session = twindrive_net::open_session_patiently(&options, deadline).await?;
                let backend = twindrive_net::ros::RosBackend::open(
                    &session,
                    bridge,
                    zero,
                    Some(site.world.log_map()),
                )
                .await?;
                anyhow::Ok((backend, session))
            })?;
            eprintln!(
                "robot {}: driving a ROS 2 robot through rmw_zenoh at {}",
                args.id,
                options.connect.join(", ")
            );
            let result = run_agent(args, config, backend, zero, &rt);
            rt.block_on(async {
                let _ = ros_session.close().await;
            });
            result
        }
    }
}

/// The `[ros]` section of a site file, if it has one, with errors that
/// name its line.
fn read_ros_section(site: &Path) -> anyhow::Result<Option<twindrive_agent::ros::RosConfig>> {
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
    args: &RobotArgs,
    config: AgentConfig,
    backend: B,
    zero: std::time::Instant,
    rt: &tokio::runtime::Runtime,
) -> anyhow::Result<()> {
    let mut agent = RobotDir::open(&args.state_dir)
        .and_then(|store| RobotAgent::new(config, backend, store))
        .with_context(|| format!("--state-dir {}", args.state_dir.display()))?;
    let options = session_options(&args.zenoh, None);
    let deadline = Duration::from_secs_f64(args.run_for.unwrap_or(1e9));
    rt.block_on(async {
        // A robot that boots before its router or its network keeps trying.
        let session = twindrive_net::open_session_patiently(&options, deadline).await?;
        eprintln!(
            "robot {}: listening on {} for plans signed by {} trusted key(s)",
            args.id,
            up_key(&args.id),
            args.trust.len()
        );
        let (tx, rx) = (down_key(&args.id), up_key(&args.id));
        let mut stats = twindrive_net::DriveStats::default();
        let mut voice = twindrive_progress::Voice::new();
        let drive = twindrive_net::drive_counting(
            &mut agent,
            &session,
            &args.id,
            &tx,
            &rx,
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
        let _ = session.close().await;
        anyhow::Ok(())
    })
}

/// `twindrive router`.
pub fn router(listen: Vec<String>, zenoh_config: Option<PathBuf>) -> anyhow::Result<()> {
    let options = SessionOptions {
        listen: listen.clone(),
        connect: Vec::new(),
        config_file: zenoh_config,
        mode: Some("router".into()),
    };
    runtime()?.block_on(async {
        let session = open_session(&options).await?;
        eprintln!("router: listening on {}", listen.join(", "));
        tokio::signal::ctrl_c().await.ok();
        let _ = session.close().await;
        anyhow::Ok(())
    })
}

/// The signed plan the master starts with, the plan inside it, and whether
/// it resumes an upload an earlier run of this master began.
struct FirstPlan {
    plan: Arc<MissionPlan>,
    plan_json: Vec<u8>,
    signed: Vec<u8>,
    counter: u64,
    /// The hash of the twin's world in its envelope.
    world_sha256: String,
    resume: bool,
}

fn first_plan(
    args: &MasterArgs,
    robot: &str,
    archive: &MasterArchive,
    key: Option<&twindrive_link::envelope::SigningKey>,
) -> anyhow::Result<FirstPlan> {
    // An upload this master began and did not finish is resumed when it
    // carries the same plan (a self-signed plan signs to new bytes each run).
    let pending = archive.upload_path();
    let unfinished = archive.unfinished_upload();
    let (signed, resume) = if let Some(path) = &args.signed {
        let bytes =
            std::fs::read(path).with_context(|| format!("--signed: reading {}", path.display()))?;
        let resume = unfinished.as_deref() == Some(&bytes[..]);
        (bytes, resume)
    } else {
        let path = args.plan.as_ref().expect("clap: --plan or --signed");
        let plan_json =
            std::fs::read(path).with_context(|| format!("--plan: reading {}", path.display()))?;
        let same = unfinished.as_deref().is_some_and(|u| {
            twindrive_link::envelope::open_unchecked(u).is_ok_and(|j| j == plan_json)
                && peek_envelope(u).is_ok_and(|e| e.robot_id == robot)
        });
        if same {
            (unfinished.clone().expect("checked"), true)
        } else {
            let plan = crate::flags::parse_plan(&plan_json, path)?;
            let world =
                crate::flags::world_bytes(&plan.header.robot.scenario, args.scenario.as_deref())?;
            let key = key.expect("clap: --plan requires --key");
            let now = crate::flags::since_epoch()?;
            let envelope = Envelope::new(
                robot,
                now.as_millis() as u64,
                now.as_secs(),
                args.expires_in,
                sha256_hex(&world),
                Supervision {
                    dead_man_timeout_s: args.supervise,
                },
                Tolerances::default(),
            );
            let signed = sign_plan(key, &plan_json, envelope)
                .map_err(|e| anyhow::anyhow!("--plan {}: {e}", path.display()))?;
            (signed, false)
        }
    };
    if resume {
        eprintln!("master: resuming the upload in {}", pending.display());
    } else if unfinished.is_some() {
        eprintln!(
            "master: {} held an unfinished upload of another plan; starting this one",
            pending.display()
        );
    }
    let envelope = peek_envelope(&signed).map_err(|e| anyhow::anyhow!("the signed plan: {e}"))?;
    if envelope.robot_id != robot {
        bail!(
            "the signed plan is for robot `{}`, not --robot {robot}",
            envelope.robot_id,
        );
    }
    // The plan inside, for the report and for continuations.
    let plan_json = twindrive_link::envelope::open_unchecked(&signed)
        .map_err(|e| anyhow::anyhow!("the signed plan: {e}"))?;
    let plan: MissionPlan =
        serde_json::from_slice(&plan_json).context("the signed plan's document")?;
    Ok(FirstPlan {
        plan: Arc::new(plan),
        plan_json,
        signed,
        counter: envelope.counter,
        world_sha256: envelope.world_sha256,
        resume,
    })
}

/// One robot the master supervises.
struct Supervised {
    robot: String,
    /// Its output directory (`--out`, or `--out/<id>` in a fleet).
    archive: MasterArchive,
    op: Operator<DirStore>,
    stats: twindrive_net::DriveStats,
}

/// `twindrive master`: one robot, or a fleet (`--robot` repeated) over one
/// zenoh session, each robot with its own operator, twin and output
/// directory.
pub fn master(args: &MasterArgs) -> anyhow::Result<()> {
    crate::flags::check_distinct_robots(&args.robot)?;
    let fleet = args.robot.len() > 1;
    if fleet && args.signed.is_some() {
        return Err(usage(
            "--signed holds a plan signed for one robot; a fleet needs --plan and --key (each robot gets its own signature)",
        ));
    }
    let profile = crate::flags::link_profile(args.link.as_deref())?;
    let key = crate::flags::signing_key(args.key.as_deref())?;
    let verbosity = if args.quiet {
        Verbosity::Quiet
    } else if args.verbose {
        Verbosity::Verbose
    } else {
        Verbosity::Normal
    };
    if args.on_handback == OnHandbackArg::Replan && key.is_none() {
        return Err(usage(
            "--on-handback replan signs continuations: it needs --key",
        ));
    }
    let unix_at_zero = unix_now_s()?;
    let mut members = Vec::new();
    for robot in &args.robot {
        let out = if fleet {
            args.out.join(robot)
        } else {
            args.out.clone()
        };
        let archive = MasterArchive::new(out);
        let first = first_plan(args, robot, &archive, key.as_ref())?;
        // The twin: the scenario the plan was rehearsed in.
        let twin_scenario = match twindrive_workflow::verification::twin_of(
            &first.plan,
            args.scenario.as_deref(),
        ) {
            Ok(twin) => Some(twin),
            Err(e)
                if args.allow_failed_verification && args.on_handback != OnHandbackArg::Replan =>
            {
                eprintln!(
                    "warning: the plan cannot be verified ({e:#}); sending it unverified because of --allow-failed-verification"
                );
                None
            }
            Err(e) => {
                return Err(e.context(
                    "the master verifies every plan on its twin before sending it (and replans on it)",
                ));
            }
        };
        // Nothing that fails on the twin goes to the robot.
        if let Some(twin) = &twin_scenario {
            twindrive_workflow::verification::check_before_sending(
                &first.plan,
                twin,
                args.allow_failed_verification,
            )?;
        }
        // Keep what is being uploaded, so a restarted master resumes it.
        archive.keep_upload(&first.signed).with_context(|| {
            format!("keeping the upload's state in {}", archive.dir().display())
        })?;
        archive
            .write_plan(&first.plan, &first.plan_json, Some(&first.signed))
            .with_context(|| format!("writing the plan into {}", archive.dir().display()))?;
        let master = Master::new(
            robot,
            MasterConfig::for_link(profile.as_ref(), args.telemetry_budget),
            archive.log_chunks(),
        );
        let calibrated = first.plan.header.calibrated;
        let mut op = Operator::new(
            master,
            twin_scenario.map(|s| Twin::new(s, calibrated)),
            key.clone(),
            OperatorConfig {
                on_handback: match args.on_handback {
                    OnHandbackArg::Stop => OnHandback::Stop,
                    OnHandbackArg::Replan => OnHandback::Replan,
                },
                expires_in_s: args.expires_in,
                supervision: Supervision {
                    dead_man_timeout_s: args.supervise,
                },
                log_wait_s: args.log_wait,
                // Continuations build on the world the first plan was signed for.
                ..OperatorConfig::replanning(
                    robot,
                    first.counter,
                    first.world_sha256.clone(),
                    unix_at_zero,
                )
            },
        );
        op.start(
            first.plan.clone(),
            first.signed.clone(),
            first.counter,
            first.resume,
            0,
        );
        if !args.quiet {
            eprintln!(
                "master: uploading plan {} ({} bytes) to robot {robot}",
                &first.plan.sha256[..12],
                first.signed.len(),
            );
        }
        members.push(Supervised {
            robot: robot.clone(),
            archive,
            op,
            stats: Default::default(),
        });
    }
    // The master's clock: zero now (every plan is ready), in Unix time and
    // for the driver alike.
    let zero = std::time::Instant::now();
    let unix_at_zero = unix_now_s()?;
    for m in &mut members {
        m.op.config_mut().unix_time_at_zero_s = unix_at_zero;
        m.op.report.unix_time_at_zero_s = unix_at_zero;
    }
    let rt = runtime()?;
    let options = session_options(&args.zenoh, None);
    let deadline = Duration::from_secs_f64(args.timeout);
    let results: Vec<anyhow::Result<()>> = rt.block_on(async {
        let session = match open_session(&options).await {
            Ok(s) => s,
            Err(e) => return vec![Err(e)],
        };
        let runs = members.iter_mut().enumerate().map(|(k, m)| {
            // One emulator pair per robot, each its own random streams.
            let emulation = profile.clone().map(|p| Emulation {
                outgoing: LinkEmulator::new(p.clone(), args.seed, 2 * k as u64),
                incoming: LinkEmulator::new(p, args.seed, 2 * k as u64 + 1),
            });
            supervise(m, &session, emulation, deadline, zero, !fleet, verbosity)
        });
        let results = futures::future::join_all(runs).await;
        let _ = session.close().await;
        results
    });
    let mut first_error = None;
    if results.len() != members.len() {
        // The session did not open.
        for m in &mut members {
            m.op.fail(
                format!("{:#}", results[0].as_ref().expect_err("an error")),
                0,
            );
        }
    } else {
        for (m, r) in members.iter_mut().zip(results) {
            match r {
                Err(e) if e.is::<WriteError>() => {
                    first_error.get_or_insert(e);
                }
                Err(e) => m.op.fail(format!("{e:#}"), 0),
                Ok(()) => {}
            }
        }
    }
    let usage = process_usage();
    let mut stdout = std::io::stdout().lock();
    let mut worst = Outcome::Completed;
    let mut summary = Vec::new();
    for m in &mut members {
        m.op.finish_report();
        let report = serde_json::to_vec_pretty(&m.op.report)?;
        m.archive
            .write_report(&report)
            .context("writing report.json")?;
        let outcome = m.op.report.outcome.unwrap_or(Outcome::Failed);
        worst = worse(worst, outcome);
        writeln!(
            stdout,
            "{}outcome: {outcome:?}{}; {} upload(s), {} hand-back(s), {} robot log(s); report: {}",
            if fleet {
                format!("{}: ", m.robot)
            } else {
                String::new()
            },
            m.op.report
                .failure
                .as_ref()
                .map_or(String::new(), |f| format!(" ({f})")),
            m.op.report.uploads.len(),
            m.op.report.handbacks.len(),
            m.op.report.robot_logs.len(),
            m.archive.report_path().display()
        )?;
        summary.push(serde_json::json!({
            "robot": m.robot,
            "outcome": outcome,
            "uploads": m.op.report.uploads.len(),
            "handbacks": m.op.report.handbacks.len(),
            "robot_logs": m.op.report.robot_logs.len(),
            "status_messages": m.op.report.status_messages,
            "messages_received": m.stats.messages_received,
            "bytes_received": m.stats.bytes_received,
            "garbage": m.stats.garbage,
        }));
    }
    {
        let fleet_json = serde_json::json!({
            "robots": summary,
            "unix_time_at_zero_s": unix_at_zero,
            "telemetry_budget_bytes_s": args.telemetry_budget,
            "process_cpu_s": usage.map(|u| u.0),
            "process_peak_rss_bytes": usage.map(|u| u.1),
        });
        write_durably(
            &args.out.join("fleet.json"),
            &serde_json::to_vec_pretty(&fleet_json)?,
        )
        .context("writing fleet.json")?;
        if fleet {
            writeln!(
                stdout,
                "fleet: {} robot(s); worst outcome {worst:?}; {}",
                members.len(),
                args.out.join("fleet.json").display()
            )?;
        }
    }
    if let Some(e) = first_error {
        return Err(e);
    }
    match worst {
        Outcome::Completed => Ok(()),
        Outcome::HandedBack => std::process::exit(3),
        Outcome::Rejected => std::process::exit(4),
        Outcome::Failed => bail!(
            "the mission failed: {}",
            members
                .iter()
                .find_map(|m| m.op.report.failure.clone())
                .unwrap_or_else(|| "see report.json".into())
        ),
    }
}

/// The worse of two outcomes: failed, then rejected, then handed back.
fn worse(a: Outcome, b: Outcome) -> Outcome {
    let rank = |o: Outcome| match o {
        Outcome::Completed => 0,
        Outcome::HandedBack => 1,
        Outcome::Rejected => 2,
        Outcome::Failed => 3,
    };
    if rank(b) > rank(a) { b } else { a }
}

/// A file the master could not write (its mission may have gone well).
#[derive(Debug)]
struct WriteError(anyhow::Error);

impl std::fmt::Display for WriteError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:#}", self.0)
    }
}

impl std::error::Error for WriteError {}

/// This process's CPU time (s, user and system) and peak resident memory
/// (bytes), where the system tells (Linux's /proc).
pub(crate) fn process_usage() -> Option<(f64, u64)> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) in parentheses.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the line, in clock ticks
    // (USER_HZ, 100 on Linux).
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let hwm_kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some((ticks / 100.0, hwm_kb * 1024))
}

/// What the master says about one robot: its events, and what it waits
/// for (a live line on a terminal, a line after a quiet while on a pipe),
/// as `-q`/`-v` ask.
struct Speaker {
    narrator: Narrator,
    /// `None` when quiet.
    voice: Option<twindrive_progress::Voice>,
}

impl Speaker {
    /// `live`: a live line on a terminal (one robot; a fleet's robots say
    /// plain lines).
    fn new(robot: &str, verbosity: Verbosity, live: bool) -> Self {
        let voice = if live {
            twindrive_progress::Voice::new
        } else {
            twindrive_progress::Voice::plain
        };
        Self {
            narrator: Narrator::new(robot, verbosity),
            voice: (verbosity != Verbosity::Quiet).then(voice),
        }
    }

    fn say(&mut self, line: &str) {
        if let Some(voice) = &mut self.voice {
            voice.say(line);
        }
    }

    fn tell(&mut self, op: &Operator<DirStore>, now_ns: u64) {
        let Some(voice) = &mut self.voice else {
            return;
        };
        for line in self.narrator.lines(op, now_ns) {
            voice.say(&line);
        }
        voice.status(|| self.narrator.waiting_line(op, now_ns));
    }
}

/// Drives one robot's operator over the session until its mission is
/// decided and its logs are in; writes its plans and logs as they come.
async fn supervise(
    m: &mut Supervised,
    session: &twindrive_net::Session,
    emulation: Option<Emulation>,
    deadline: Duration,
    zero: std::time::Instant,
    show_progress: bool,
    verbosity: Verbosity,
) -> anyhow::Result<()> {
    let robot = m.robot.clone();
    let archive = &mut m.archive;
    let mut speaker = Speaker::new(&robot, verbosity, show_progress);
    let mut write_error: Option<anyhow::Error> = None;
    let r = twindrive_net::drive_counting(
        &mut m.op,
        session,
        &robot,
        &up_key(&robot),
        &down_key(&robot),
        emulation,
        deadline,
        zero,
        &mut m.stats,
        |op| {
            let now_ns = zero.elapsed().as_nanos() as u64;
            if op.master.upload_finished() {
                archive.upload_finished();
            }
            while let Some((plan, json, signed)) = op.new_plans.pop_front() {
                if let Err(e) = archive.write_plan(&plan, &json, Some(&signed)) {
                    write_error.get_or_insert(
                        anyhow::Error::new(e)
                            .context(format!("writing a plan into {}", archive.dir().display())),
                    );
                }
            }
            while let Some((plan, mcap)) = op.new_logs.pop_front() {
                match archive.write_robot_log(plan.as_deref(), &mcap) {
                    Ok(written) => {
                        let dir = written.dir.display().to_string();
                        speaker.say(&format!("{robot}: robot log written to {dir}"));
                        op.report.robot_logs.push(dir);
                    }
                    Err(e) => {
                        write_error.get_or_insert(e);
                    }
                }
            }
            speaker.tell(op, now_ns);
            op.is_done()
        },
    )
    .await;
    if let Some(e) = write_error {
        return Err(WriteError(e).into());
    }
    r
}
