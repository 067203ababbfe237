//! `twindrive experiment fleet`: one master supervising N robot agents
//! through a zenoh router, all real processes on loopback; and, in virtual
//! time in one process, the master's protocol cost per robot as N grows.
//!
//! The processes: `twindrive router`, N × `twindrive robot` (each its own
//! id, site, state directory, zenoh client of the router) and one
//! `twindrive master --robot r001 --robot r002 …` (a client too). Each site
//! is the case study with its own true kinematics (as the latency
//! experiment's) and seed, and the robots go by odometry alone
//! (`--localization off`), so each hands back once and finishes on a
//! continuation: what is measured is the protocol, not the robot's autonomy
//! (a robot that localizes against its map does not hand back for this
//! mismatch at all). Measured: the master's CPU time and peak memory (it reports
//! them itself), the time until every robot held its plan, the hand-back
//! reaction time (the robot's stop, from its journal, to the master's
//! receipt, from its report: one clock, one machine), and telemetry: bytes
//! per second delivered from each robot, and each log's back-fill rate
//! against the pace the robot's budget allows it.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use serde::Serialize;
use twindrive_agent::backend::SimBackend;
use twindrive_link::emulator::LinkProfile;
use twindrive_link::envelope::SigningKey;

use twindrive_files::Staging;

use crate::mission::Mission;
use crate::rehearsal::{Rehearsal, site_like};

/// A child process killed (by its id) when dropped.
struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn free_port() -> anyhow::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")
        .context("finding a free port on 127.0.0.1")?
        .local_addr()?
        .port())
}

/// The case study's scenario text with robot `k`'s seed and true kinematics.
fn site_toml(k: usize) -> anyhow::Result<String> {
    let text = twindrive_sim::builtin::WALL_FOLLOWING;
    let twin = twindrive_sim::builtin::load("wall_following")
        .expect("built in")
        .context("the built-in wall_following scenario")?;
    // The site the latency experiment uses, with robot `k`'s seed.
    let site = site_like(&twin);
    let t = site.robot.true_params;
    let old_params = "true_params = { left_diameter_m = 0.0652, right_diameter_m = 0.0665, wheelbase_m = 0.2678 }";
    let old_seed = "seed = 2012";
    if !text.contains(old_params) || !text.contains(old_seed) {
        bail!("the built-in wall_following scenario changed: update the fleet's site maker");
    }
    Ok(text
        .replace(
            old_params,
            &format!(
                "true_params = {{ left_diameter_m = {}, right_diameter_m = {}, wheelbase_m = {} }}",
                t.left_diameter_m, t.right_diameter_m, t.wheelbase_m
            ),
        )
        .replace(
            old_seed,
            &format!("seed = {}", site.seed.wrapping_add(k as u64)),
        ))
}

/// What one fleet run measured.
#[derive(Debug, Clone, Serialize)]
pub struct FleetResult {
    pub robots: usize,
    pub completed: usize,
    pub wall_clock_s: f64,
    pub master_cpu_s: Option<f64>,
    pub master_peak_rss_mb: Option<f64>,
    /// Until the last robot held its first plan (master's clock), s.
    pub upload_to_all_s: Option<f64>,
    /// Robot stop to master notified: median and largest, s.
    pub handback_reaction_median_s: Option<f64>,
    pub handback_reaction_max_s: Option<f64>,
    pub handbacks: usize,
    /// Mean bytes per second received from each robot over its mission:
    /// the lowest and the highest robot.
    pub telemetry_bytes_s_min: f64,
    pub telemetry_bytes_s_max: f64,
    pub telemetry_budget_bytes_s: f64,
    /// Each log's back-fill rate against the pace the budget allows (0.7
    /// of it): the lowest over the fleet.
    pub backfill_vs_pace_min: Option<f64>,
    pub logs_backfilled: usize,
    pub logs_expected: usize,
}

fn read_json(path: &Path) -> anyhow::Result<serde_json::Value> {
    twindrive_files::json::read(path, "a JSON document")
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied()
}

/// Runs router, master and `n` robots in `dir`; waits for the master.
pub fn run_fleet(
    n: usize,
    dir: &Path,
    plan_json: &Path,
    args: &Config,
) -> anyhow::Result<FleetResult> {
    let exe = &args.exe;
    std::fs::create_dir_all(dir)?;
    let keys = dir.join("keys");
    if !keys.join("master.key").exists() {
        twindrive_store::keys::write_key_pair(&keys)?;
    }
    let client = dir.join("client.json5");
    std::fs::write(
        &client,
        "{ mode: \"client\", scouting: { multicast: { enabled: false } } }\n",
    )?;
    let router = format!("tcp/127.0.0.1:{}", free_port()?);
    let quiet = |c: &mut Command| {
        c.stdout(Stdio::null()).stderr(Stdio::null());
    };
    let mut cmd = Command::new(exe);
    cmd.args(["router", "--listen", &router]);
    quiet(&mut cmd);
    let _router = Proc(cmd.spawn().context("starting the router")?);
    std::thread::sleep(Duration::from_millis(300));
    let ids: Vec<String> = (1..=n).map(|k| format!("r{k:03}")).collect();
    // Each run's robots start from empty state directories: new robot keys
    // too (a key's link epochs live with its state), and a fresh link
    // state at the master.
    let robot_keys = dir.join("robot_keys");
    let master_link = dir.join("master_link");
    for d in [&robot_keys, &master_link] {
        let _ = std::fs::remove_dir_all(d);
    }
    for id in &ids {
        twindrive_store::keys::write_named_key_pair(&robot_keys, id)?;
    }
    let mut robots = Vec::new();
    for (k, id) in ids.iter().enumerate() {
        let site = dir.join(format!("site_{id}.toml"));
        std::fs::write(&site, site_toml(k)?)?;
        let state = dir.join("robots").join(id);
        let _ = std::fs::remove_dir_all(&state);
        let mut cmd = Command::new(exe);
        cmd.args(["robot", "--id", id, "--site"])
            .arg(&site)
            .arg("--trust")
            .arg(keys.join("master.pub"))
            .arg("--key")
            .arg(robot_keys.join(format!("{id}.key")))
            .arg("--state-dir")
            .arg(&state)
            .args(["--connect", &router, "--zenoh-config"])
            .arg(&client)
            .args([
                "--localization",
                "off",
                "--time-scale",
                &args.time_scale.to_string(),
                "--telemetry-budget",
                &args.telemetry_budget.to_string(),
                "--run-for",
                &(args.timeout + 30.0).to_string(),
            ]);
        quiet(&mut cmd);
        robots.push(Proc(
            cmd.spawn()
                .with_context(|| format!("starting robot {id}"))?,
        ));
    }
    let out = dir.join("master");
    let _ = std::fs::remove_dir_all(&out);
    let mut cmd = Command::new(exe);
    cmd.arg("master").arg("--plan").arg(plan_json);
    cmd.arg("--key").arg(keys.join("master.key"));
    cmd.arg("--trust-robot").arg(&robot_keys);
    cmd.arg("--link-state").arg(&master_link);
    for id in &ids {
        cmd.args(["--robot", id]);
    }
    cmd.arg("--out")
        .arg(&out)
        .args(["--connect", &router, "--zenoh-config"])
        .arg(&client)
        .args([
            "--on-handback",
            "replan",
            "--timeout",
            &args.timeout.to_string(),
            "--log-wait",
            &(0.8 * args.timeout).to_string(),
            "--telemetry-budget",
            &args.telemetry_budget.to_string(),
        ]);
    if let Some(link) = &args.link {
        cmd.args(["--link", link]);
    }
    // What the master says goes to a file: a pipe nobody reads until the
    // end would fill and stall it.
    let said = out.join("master.stderr");
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let said_file =
        std::fs::File::create(&said).with_context(|| format!("creating {}", said.display()))?;
    cmd.stdout(Stdio::null()).stderr(said_file);
    let started = Instant::now();
    let mut master = Proc(cmd.spawn().context("starting the master")?);
    // Bounded: the master gives up by itself after --timeout; this is the
    // net under it.
    let limit = Duration::from_secs_f64(args.timeout + 60.0);
    let status = loop {
        if let Some(status) = master.0.try_wait()? {
            break status;
        }
        if started.elapsed() > limit {
            bail!(
                "the master did not exit within {:.0} s",
                limit.as_secs_f64()
            );
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let wall_clock_s = started.elapsed().as_secs_f64();
    let stderr = std::fs::read_to_string(&said).unwrap_or_default();
    drop(robots);
    let fleet_path = out.join("fleet.json");
    if !fleet_path.exists() {
        bail!(
            "the master exited with {status} and wrote no {}: {}",
            fleet_path.display(),
            // Its last words.
            {
                let said = stderr.trim();
                &said[said.char_indices().rev().nth(4_000).map_or(0, |(i, _)| i)..]
            }
        );
    }
    measure(n, &ids, dir, &out, wall_clock_s, args.telemetry_budget)
}

/// The figures of one run, from the master's reports and the robots'
/// journals.
fn measure(
    n: usize,
    ids: &[String],
    dir: &Path,
    out: &Path,
    wall_clock_s: f64,
    budget: f64,
) -> anyhow::Result<FleetResult> {
    let fleet = read_json(&out.join("fleet.json"))?;
    let (cpu, rss) = (
        fleet["process_cpu_s"].as_f64(),
        fleet["process_peak_rss_bytes"].as_f64(),
    );
    let mut completed = 0;
    let mut uploads_done = Vec::new();
    let mut reactions = Vec::new();
    let mut rates = Vec::new();
    let mut backfill = Vec::new();
    let (mut logs_backfilled, mut logs_expected, mut handbacks) = (0, 0, 0);
    for id in ids {
        let robot_out: PathBuf = if n > 1 {
            out.join(id)
        } else {
            out.to_path_buf()
        };
        let report = read_json(&robot_out.join("report.json"))?;
        if report["outcome"] == "completed" {
            completed += 1;
        }
        let zero = report["unix_time_at_zero_s"].as_f64().unwrap_or(0.0);
        let timeline = report["timeline"].as_array().cloned().unwrap_or_default();
        let at = |event: &str| -> Vec<f64> {
            timeline
                .iter()
                .filter(|e| e["event"] == event)
                .filter_map(|e| e["t_s"].as_f64())
                .collect()
        };
        if let Some(t) = at("upload_finished").first() {
            uploads_done.push(*t);
        }
        let end = timeline
            .last()
            .and_then(|e| e["t_s"].as_f64())
            .unwrap_or(1.0);
        // The robot's journal: stops (hand-backs) and log back-fills, on
        // the same Unix clock.
        let journal = twindrive_store::RobotDir::journal(&dir.join("robots").join(id))?;
        let stops: Vec<f64> = journal
            .iter()
            .filter(|l| {
                l["event"] == "stopped"
                    && matches!(
                        l["reason"].as_str(),
                        Some(r) if twindrive_agent::executive::HANDBACK_REASONS.contains(&r)
                    )
            })
            .filter_map(|l| l["unix_s"].as_f64())
            .collect();
        let received: Vec<f64> = at("handback").iter().map(|t| zero + t).collect();
        handbacks += received.len();
        for (stop, got) in stops.iter().zip(&received) {
            reactions.push(got - stop);
        }
        let bytes = fleet["robots"]
            .as_array()
            .and_then(|a| a.iter().find(|r| r["robot"] == id.as_str()))
            .and_then(|r| r["bytes_received"].as_f64())
            .unwrap_or(0.0);
        rates.push(bytes / end.max(1.0));
        // Back-fills: each log from its writing (or the end of the one
        // before) to its acknowledgement.
        let mut free_at = f64::NEG_INFINITY;
        let mut written: std::collections::HashMap<String, f64> = Default::default();
        for l in &journal {
            let (Some(t), Some(sha)) = (l["unix_s"].as_f64(), l["plan_sha256"].as_str()) else {
                continue;
            };
            match l["event"].as_str() {
                Some("log_written") => {
                    logs_expected += 1;
                    written.insert(sha.to_string(), t);
                }
                Some("log_acknowledged") => {
                    logs_backfilled += 1;
                    let from = written.get(sha).copied().unwrap_or(t).max(free_at);
                    free_at = t;
                    let path = dir
                        .join("robots")
                        .join(id)
                        .join("logs")
                        .join(sha)
                        .join("log.mcap");
                    if let Ok(meta) = std::fs::metadata(&path)
                        && t > from
                    {
                        backfill.push(meta.len() as f64 / (t - from) / (0.7 * budget));
                    }
                }
                _ => {}
            }
        }
    }
    let upload_to_all_s =
        (uploads_done.len() == n).then(|| uploads_done.iter().copied().fold(0.0, f64::max));
    Ok(FleetResult {
        robots: n,
        completed,
        wall_clock_s,
        master_cpu_s: cpu,
        master_peak_rss_mb: rss.map(|b| b / 1e6),
        upload_to_all_s,
        handback_reaction_median_s: median(reactions.clone()),
        handback_reaction_max_s: reactions.iter().copied().reduce(f64::max),
        handbacks,
        telemetry_bytes_s_min: rates.iter().copied().fold(f64::INFINITY, f64::min),
        telemetry_bytes_s_max: rates.iter().copied().fold(0.0, f64::max),
        telemetry_budget_bytes_s: budget,
        backfill_vs_pace_min: backfill.iter().copied().reduce(f64::min),
        logs_backfilled,
        logs_expected,
    })
}

/// The master's protocol cost in virtual time: `n` robots each running the
/// plan against its own operator, the master side's calls timed.
#[derive(Debug, Clone, Serialize)]
pub struct CostRow {
    pub robots: usize,
    /// Time in the master's protocol state machines (upload, heartbeats,
    /// pings, statuses, logs), all robots, s.
    pub master_s: f64,
    pub master_us_per_robot: f64,
    /// The operator's own time (continuations planned on the twin after
    /// hand-backs), all robots, s; and the hand-backs.
    pub operator_s: f64,
    pub handbacks: usize,
    /// Messages the master handled and sent, all robots.
    pub messages: u64,
}

/// An operator whose calls are timed.
struct Timed<'a> {
    op: &'a mut twindrive_agent::operator::Operator<twindrive_link::upload::MemoryStore>,
    spent: Duration,
    operator: Duration,
    messages: u64,
}

impl twindrive_link::vtime::Endpoint for Timed<'_> {
    fn refused(&mut self, refusal: &twindrive_link::secure::Refusal, now_ns: u64) {
        self.op.refused(refusal, now_ns);
    }
    fn poll_transmit(&mut self, now_ns: u64) -> Option<twindrive_link::wire::Message> {
        let t = Instant::now();
        let m = self.op.poll_transmit(now_ns);
        self.spent += t.elapsed();
        self.messages += u64::from(m.is_some());
        m
    }
    fn handle(&mut self, message: &twindrive_link::wire::Message, now_ns: u64) {
        let t = Instant::now();
        self.op.master.handle(message, now_ns);
        self.spent += t.elapsed();
        self.messages += 1;
        // The operator's decisions (a hand-back's continuation is planned
        // on the twin) are not the protocol's cost.
        let t = Instant::now();
        self.op.react(now_ns);
        self.operator += t.elapsed();
    }
    fn poll_timeout(&self) -> Option<u64> {
        self.op.poll_timeout()
    }
}

/// The cost for each N in `ns`: N missions on the same plan over
/// `profile`, each robot on the twin's own world and kinematics (its own
/// noise seed): no hand-back, so no replanning, the protocol alone
/// (upload, heartbeats, pings, statuses, the log's receipt).
pub fn master_cost(
    mission: &Rehearsal,
    ns: &[usize],
    profile: &LinkProfile,
) -> anyhow::Result<Vec<CostRow>> {
    let key = SigningKey::from_bytes(&[7; 32]);
    let total: usize = ns.iter().sum();
    let bar = twindrive_progress::bar(total as u64, "robots (virtual time)");
    let mut rows = Vec::new();
    for &n in ns {
        let (mut spent, mut operator, mut messages, mut handbacks) =
            (Duration::ZERO, Duration::ZERO, 0u64, 0usize);
        for k in 0..n {
            let mut site = mission.twin.clone();
            site.seed = mission.twin.seed.wrapping_add(1 + k as u64);
            let backend = SimBackend::new(site, mission.plan.samples[0].pose(), 3_600.0)
                .map_err(|e| anyhow::anyhow!("the site: {e}"))?;
            let mut m = Mission::new(
                &mission.plan,
                &mission.plan_json,
                &mission.twin,
                &mission.world_toml,
                &key,
                profile,
                k as u64,
                backend,
            )?;
            let Mission {
                op, robot, link, ..
            } = &mut m;
            let mut timed = Timed {
                op,
                spent: Duration::ZERO,
                operator: Duration::ZERO,
                messages: 0,
            };
            link.run(&mut timed, robot, 3_600_000_000_000, |t, _| t.op.is_done());
            spent += timed.spent;
            operator += timed.operator;
            handbacks += timed.op.report.handbacks.len();
            messages += timed.messages;
            bar.inc(1);
        }
        rows.push(CostRow {
            robots: n,
            master_s: spent.as_secs_f64(),
            master_us_per_robot: spent.as_secs_f64() * 1e6 / n as f64,
            operator_s: operator.as_secs_f64(),
            handbacks,
            messages,
        });
    }
    bar.finish_and_clear();
    Ok(rows)
}

/// The fleets to run, and how.
#[derive(Debug, Clone)]
pub struct Config {
    /// The `twindrive` executable the processes run.
    pub exe: PathBuf,
    /// Output directory (results.json; runs/ holds each run's processes'
    /// files).
    pub out: PathBuf,
    /// Fleet sizes to run.
    pub robots: Vec<usize>,
    /// Each robot's simulated site runs this many times faster than real time.
    pub time_scale: f64,
    /// Bytes per second each robot may send.
    pub telemetry_budget: f64,
    /// Give a run up after this many seconds.
    pub timeout: f64,
    /// Emulate this link (a profile's text, already checked) at the master
    /// on every robot's traffic.
    pub link: Option<String>,
    /// Also measure the master's protocol cost in virtual time for these
    /// fleet sizes.
    pub cost: Vec<usize>,
}

/// Runs each fleet, then the virtual-time cost; `results.json` into
/// `args.out`, a line per fleet to `stdout`.
pub fn run(args: &Config, stdout: &mut impl Write) -> anyhow::Result<()> {
    let twin = twindrive_sim::builtin::load("wall_following")
        .expect("built in")
        .context("the built-in wall_following scenario")?;
    let calibrated = twindrive_calibrate::calibrate_like(&twin)?;
    let site = site_like(&twin);
    let mission = Rehearsal::rehearse(
        twin,
        twindrive_sim::builtin::WALL_FOLLOWING.as_bytes().to_vec(),
        site,
        calibrated,
    )?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let work = args.out.join("runs");
    std::fs::create_dir_all(&work)?;
    let plan_path = work.join("plan.json");
    std::fs::write(&plan_path, &mission.plan_json)?;
    let mut results = Vec::new();
    for &n in &args.robots {
        writeln!(
            stdout,
            "fleet of {n}: router, master and {n} robot process(es)…"
        )?;
        stdout.flush()?;
        let r = run_fleet(n, &work.join(format!("n{n}")), &plan_path, args)?;
        writeln!(
            stdout,
            "  {}/{} completed in {:.0} s; master CPU {} s, peak RSS {} MB; upload to all {} s; hand-back reaction median {} s (max {}); telemetry {:.0}-{:.0} B/s per robot (budget {:.0}); back-fill at {} of its pace (lowest); logs {}/{}",
            r.completed,
            r.robots,
            r.wall_clock_s,
            opt(r.master_cpu_s, 2),
            opt(r.master_peak_rss_mb, 0),
            opt(r.upload_to_all_s, 1),
            opt(r.handback_reaction_median_s, 3),
            opt(r.handback_reaction_max_s, 3),
            r.telemetry_bytes_s_min,
            r.telemetry_bytes_s_max,
            r.telemetry_budget_bytes_s,
            opt(r.backfill_vs_pace_min, 2),
            r.logs_backfilled,
            r.logs_expected,
        )?;
        results.push(r);
    }
    let cost = if args.cost.is_empty() {
        Vec::new()
    } else {
        let profile: LinkProfile = args
            .link
            .as_deref()
            .unwrap_or("lan")
            .parse()
            .map_err(|e| anyhow::anyhow!("--link: {e}"))?;
        let rows = master_cost(&mission, &args.cost, &profile)?;
        for r in &rows {
            writeln!(
                stdout,
                "virtual time, {} robot(s): master protocol {:.3} s, {:.0} µs per robot, {} messages; operator {:.2} s for {} hand-back(s)",
                r.robots, r.master_s, r.master_us_per_robot, r.messages, r.operator_s, r.handbacks
            )?;
        }
        rows
    };
    let staging = Staging::new(&args.out, "experiment-fleet")?;
    staging.write_with("results.json", |w| {
        serde_json::to_writer_pretty(
            w,
            &serde_json::json!({ "fleet": results, "master_cost": cost }),
        )
        .map_err(Into::into)
    })?;
    staging.commit()?;
    writeln!(stdout, "-> {}/results.json", args.out.display())?;
    for r in results.iter().filter(|r| r.completed < r.robots) {
        // An outcome, not an error of the experiment: each robot's
        // report.json says why (a hand-back the operator could not plan a
        // safe continuation for, say).
        writeln!(
            stdout,
            "fleet of {}: {} robot(s) did not complete; their report.json in {}/n{}/master says why",
            r.robots,
            r.robots - r.completed,
            work.display(),
            r.robots
        )?;
    }
    Ok(())
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}
