//! `twindrive master`: one robot or a fleet, each with its operator, twin
//! and output folder, over one network.

use std::io::Write;
use std::time::Duration;

use anyhow::{Context, bail};
use twindrive_agent::master::{Master, MasterConfig};
use twindrive_agent::narrate::Verbosity;
use twindrive_agent::operator::{OnHandback, Operator, OperatorConfig, Outcome};
use twindrive_agent::twin::Twin;
use twindrive_files::write_durably;
use twindrive_link::emulator::LinkEmulator;
use twindrive_link::envelope::Supervision;
use twindrive_net::{Emulation, Network};
use twindrive_store::MasterArchive;

use crate::first_plan::first_plan;
use crate::settings::MasterSettings;
use crate::site_maps::{KeptSite, ReturnedLogs};
use crate::supervise::{Supervised, WriteError, supervise};
use crate::{runtime, unix_now_s};

/// Runs the master: one robot, or a fleet over one network, each
/// robot with its own operator, twin and output directory. Says one line
/// per robot (and one for the fleet) on `stdout`, writes each
/// `report.json` and `fleet.json`, and returns the worst outcome.
pub fn run(args: &MasterSettings, stdout: &mut impl Write) -> anyhow::Result<Outcome> {
    let fleet = args.robots.len() > 1;
    let verbosity = args.verbosity;
    let quiet = verbosity == Verbosity::Quiet;
    let unix_at_zero = unix_now_s()?;
    // The twin's site: --scenario, or its latest version kept in --site-maps.
    let kept = match (&args.site_maps, &args.scenario) {
        (Some(dir), Some(scenario)) => Some(KeptSite::resolve(dir, scenario)?),
        (Some(_), None) => bail!("--site-maps needs --scenario: the twin's site on a map"),
        _ => None,
    };
    if let Some(k) = &kept
        && !quiet
    {
        eprintln!("master: {}", k.describe());
    }
    let twin_site = kept
        .as_ref()
        .map(|k| k.path.clone())
        .or_else(|| args.scenario.clone());
    let mut members = Vec::new();
    for robot in &args.robots {
        let out = if fleet {
            args.out.join(robot)
        } else {
            args.out.clone()
        };
        let archive = MasterArchive::new(out);
        let first = first_plan(args, robot, &archive, twin_site.as_deref())?;
        // The twin: the scenario the plan was rehearsed in (its latest map).
        let twin_scenario = match twindrive_workflow::verification::twin_of(
            &first.plan,
            twin_site.as_deref(),
        ) {
            Ok(twin) => Some(twin),
            Err(e) if args.allow_failed_verification && args.on_handback != OnHandback::Replan => {
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
            MasterConfig::for_link(args.profile.as_ref(), args.telemetry_budget),
            archive.log_chunks(),
        );
        let calibrated = first.plan.header.calibrated;
        let mut op = Operator::new(
            master,
            twin_scenario.map(|s| Twin::new(s, calibrated)),
            Some(args.key.clone()),
            OperatorConfig {
                on_handback: args.on_handback,
                expires_in_s: args.expires_in,
                supervision: Supervision {
                    dead_man_timeout_s: args.supervise,
                },
                log_wait_s: args.log_wait,
                full_rate_logs: args.full_logs,
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
        if !quiet {
            eprintln!(
                "master: uploading plan {} ({} bytes) to robot {robot}",
                &first.plan.sha256[..12],
                first.signed.len(),
            );
        }
        let robot_key = args
            .robot_keys
            .get(robot)
            .with_context(|| format!("no trusted key for robot {robot}"))?;
        let peers =
            twindrive_store::link_state::master_end(&args.link_state, robot, &args.key, robot_key)?;
        members.push(Supervised {
            robot: robot.clone(),
            archive,
            op,
            stats: Default::default(),
            link: twindrive_net::LinkEnd::master(robot, peers),
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
    let options = args.zenoh.clone();
    let deadline = Duration::from_secs_f64(args.timeout);
    let results: Vec<anyhow::Result<()>> = rt.block_on(async {
        let network = match Network::open(&options).await {
            Ok(n) => n,
            Err(e) => return vec![Err(e)],
        };
        let runs = members.iter_mut().enumerate().map(|(k, m)| {
            // One emulator pair per robot, each its own random streams.
            let emulation = args.profile.clone().map(|p| Emulation {
                outgoing: LinkEmulator::new(p.clone(), args.seed, 2 * k as u64),
                incoming: LinkEmulator::new(p, args.seed, 2 * k as u64 + 1),
            });
            supervise(m, &network, emulation, deadline, zero, !fleet, verbosity)
        });
        let results = futures::future::join_all(runs).await;
        network.close().await;
        results
    });
    let mut first_error = None;
    if results.len() != members.len() {
        // The network did not open.
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
            "refused": m.stats.refused,
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
    // The twin keeps learning its site: the robot logs that came back
    // extend its map into the next version.
    if let Some(k) = &kept {
        // Each robot's wheels as its twin knows them last (a hand-back may
        // have changed them), else as its plan says.
        let returned: Vec<ReturnedLogs<'_>> = members
            .iter()
            .filter_map(|m| {
                let params =
                    m.op.twin()
                        .map(|t| t.calibrated)
                        .or_else(|| m.op.current_plan().map(|p| p.header.calibrated))?;
                Some(ReturnedLogs {
                    dirs: &m.op.report.robot_logs,
                    params,
                })
            })
            .collect();
        k.update(&returned, stdout, quiet)
            .context("updating the site's map (the mission's reports are written)")?;
    }
    match worst {
        Outcome::Failed => bail!(
            "the mission failed: {}",
            members
                .iter()
                .find_map(|m| m.op.report.failure.clone())
                .unwrap_or_else(|| "see report.json".into())
        ),
        outcome => Ok(outcome),
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

/// This process's CPU time (s, user and system) and peak resident memory
/// (bytes), where the system tells (Linux's /proc).
fn process_usage() -> Option<(f64, u64)> {
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
