//! `twindrive experiment latency`: direct tele-operation against decoupled
//! operation on the same robot site, seeds and link, over a grid of one-way
//! latencies and losses, in virtual time with the project's own link
//! emulator and protocol code.
//!
//! The mission is the twin's scenario (the paper's wall-following case
//! study unless `--scenario`): rehearsed on the twin, it gives the intended
//! route (the plan's path) and the plan decoupled operation uploads. The
//! robot's site is the twin with other true kinematics (`--site` for one's
//! own). Each method drives the site until the route is covered:
//! - direct (a) hold-last, (b) watchdog and (c) move-and-wait run the twin's
//!   own controller at the master on delayed sensor data
//!   ([`twindrive_agent::direct`]); a run is complete when the robot's true
//!   path has passed within the coverage radius of `--complete-at` of the
//!   route (as if the operator knew its pose exactly: generous to direct
//!   operation), and the operator learns so one latency later;
//! - decoupled signs the plan, uploads it, and the robot runs it on its
//!   own with hand-back and continuation ([`super::super::demo_decoupled`]);
//!   complete when the master learns the last plan finished.

use std::io::Write;
use std::path::Path;

use anyhow::{Context, bail};
use serde::Serialize;
use twindrive_agent::backend::{Reading, RobotBackend, SimBackend};
use twindrive_agent::direct::{self, DirectConfig, DirectMethod};
use twindrive_agent::operator::Outcome;
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_link::emulator::{LinkEmulator, LinkProfile};
use twindrive_link::envelope::SigningKey;
use twindrive_log::LogHeader;
use twindrive_mission::pipeline::PipelineSettings;
use twindrive_mission::plan::{MissionPlan, sha256_hex};
use twindrive_mission::redundancy::RedundancyConfig;
use twindrive_plot::{Markers, Series, TimeFigure, WorldFigure, palette};
use twindrive_sim::{Contacts, Scenario, Simulator};

use super::route::Route;
use crate::cli::LatencyExperimentArgs;
use crate::commands::demo_decoupled::Mission;
use crate::figures::walls;
use crate::output::Staging;
use crate::usage::usage;

/// The default site: the twin's true wheel diameters and wheelbase scaled
/// by these (tyres worn unevenly, a heavier payload).
pub const SITE_SCALE: [f64; 3] = [1.004, 0.996, 1.01];

/// The methods, in the order of the tables.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    Direct(DirectMethod),
    Decoupled,
}

impl Method {
    pub fn name(&self) -> &'static str {
        match self {
            Method::Direct(DirectMethod::HoldLast) => "direct (a) hold-last",
            Method::Direct(DirectMethod::Watchdog { .. }) => "direct (b) watchdog",
            Method::Direct(DirectMethod::MoveAndWait { .. }) => "direct (c) move-and-wait",
            Method::Decoupled => "decoupled",
        }
    }

    fn color(&self) -> twindrive_plot::RGBColor {
        match self {
            Method::Direct(DirectMethod::HoldLast) => palette::BAD,
            Method::Direct(DirectMethod::Watchdog { .. }) => palette::ALT,
            Method::Direct(DirectMethod::MoveAndWait { .. }) => palette::PURPLE,
            Method::Decoupled => palette::GOOD,
        }
    }
}

/// The experiment's settings, checked.
#[derive(Debug, Clone)]
pub struct Settings {
    pub latencies_s: Vec<f64>,
    pub losses: Vec<f64>,
    pub seeds: u64,
    pub bandwidth_bit_s: f64,
    pub watchdog_timeout_s: f64,
    pub move_s: f64,
    pub coverage_radius_m: f64,
    pub complete_at: f64,
    pub max_duration_s: f64,
}

impl Settings {
    /// The demo's short version: 0, 0.5 and 2 s one way at 10 % loss, one
    /// seed.
    fn demo() -> Self {
        Settings {
            latencies_s: vec![0.0, 0.5, 2.0],
            losses: vec![0.1],
            seeds: 1,
            bandwidth_bit_s: 256_000.0,
            watchdog_timeout_s: 0.5,
            move_s: 0.5,
            coverage_radius_m: 0.15,
            complete_at: 0.9,
            max_duration_s: 1_800.0,
        }
    }

    fn methods(&self) -> [Method; 4] {
        [
            Method::Direct(DirectMethod::HoldLast),
            Method::Direct(DirectMethod::Watchdog {
                timeout_s: self.watchdog_timeout_s,
            }),
            Method::Direct(DirectMethod::MoveAndWait {
                move_s: self.move_s,
            }),
            Method::Decoupled,
        ]
    }

    /// The link of one cell: the same both ways and for every method.
    fn link(&self, latency_s: f64, loss: f64) -> LinkProfile {
        let mut p: LinkProfile = "latency_s=0".parse().expect("a valid profile");
        p.name = format!("latency {latency_s} s, loss {loss}");
        p.latency_s = latency_s;
        // A little jitter, so messages of a stream can arrive out of order.
        p.jitter_s = 0.02 * latency_s;
        p.loss = loss;
        p.bandwidth_bit_s = Some(self.bandwidth_bit_s);
        p
    }
}

/// What one run measured (one row of `results.csv`).
#[derive(Debug, Clone, Serialize)]
pub struct RunRow {
    pub method: &'static str,
    pub latency_s: f64,
    pub loss: f64,
    pub seed: u64,
    pub completed: bool,
    /// Until the operator knew the mission was done (upload included), s.
    pub completion_s: Option<f64>,
    pub collisions: u32,
    pub bumps: u32,
    pub contact_s: f64,
    pub coverage_percent: f64,
    pub path_error_mean_m: f64,
    pub path_error_max_m: f64,
    pub bytes_up: u64,
    pub bytes_down: u64,
    pub handbacks: usize,
    pub uploads: usize,
    #[serde(skip)]
    pub path: Vec<(f64, f64)>,
}

/// The mission as rehearsed on the twin, and the site it runs on.
pub struct Mission0 {
    pub twin: Scenario,
    pub world_toml: Vec<u8>,
    pub site: Scenario,
    pub plan: MissionPlan,
    pub plan_json: Vec<u8>,
}

impl Mission0 {
    /// Rehearses `twin`'s mission (its own controller, its full duration)
    /// and makes the plan with `calibrated` parameters.
    pub fn rehearse(
        twin: Scenario,
        world_toml: Vec<u8>,
        site: Scenario,
        calibrated: DiffDriveParams,
    ) -> anyhow::Result<Self> {
        let log = Simulator::new(twin.clone()).run(|_, _| {});
        let mut csv = Vec::new();
        twindrive_log::write_csv(&log, &mut csv)?;
        let settings = PipelineSettings {
            planner: Default::default(),
            redundancy: RedundancyConfig::with_pinch_distance(twin.robot.footprint_radius_m),
            filter: Default::default(),
        };
        let (plan, _) = twindrive_mission::pipeline::plan_from_log(
            &log,
            &sha256_hex(&csv),
            &calibrated,
            &twin,
            &settings,
            false,
        )
        .context("planning the rehearsal")?;
        let mut plan_json = serde_json::to_vec_pretty(&plan)?;
        plan_json.push(b'\n');
        Ok(Self {
            twin,
            world_toml,
            site,
            plan,
            plan_json,
        })
    }

    pub(super) fn route(&self) -> Vec<[f64; 2]> {
        self.plan.samples.iter().map(|s| [s.x_m, s.y_m]).collect()
    }
}

/// A backend that records the robot's true path and contacts.
struct Recorder<B> {
    inner: B,
    path: Vec<(f64, Pose)>,
    contacts: Contacts,
}

impl<B: RobotBackend> RobotBackend for Recorder<B> {
    fn period_s(&self) -> f64 {
        self.inner.period_s()
    }
    fn step(&mut self, wheels: [f64; 2]) -> Option<Reading> {
        let r = self.inner.step(wheels)?;
        self.path.push((r.t_s, r.record.ground_truth));
        let dt_s = self.period_s();
        self.contacts.record(r.record.bump, r.blocked, dt_s);
        Some(r)
    }
    fn wheel_travel_rad(&self) -> f64 {
        self.inner.wheel_travel_rad()
    }
    fn log_header(&self) -> LogHeader {
        self.inner.log_header()
    }
}

/// The site for one seed.
fn site_for(site: &Scenario, seed: u64) -> Scenario {
    let mut s = site.clone();
    s.seed = site.seed.wrapping_add(seed);
    s
}

/// Coverage (percent of the route's points within the radius of the path)
/// and path error (mean and largest distance from the path to the route, m)
/// of a true path.
pub(super) fn score(route: &mut Route, path: &[(f64, Pose)]) -> (f64, f64, f64) {
    let (mut sum, mut max, mut n) = (0.0, 0.0f64, 0usize);
    for (k, (_, p)) in path.iter().enumerate() {
        route.visit([p.x_m, p.y_m]);
        // The error changes little within ten steps.
        if k % 10 == 0 {
            let d = route.distance_m([p.x_m, p.y_m]);
            sum += d;
            max = max.max(d);
            n += 1;
        }
    }
    (100.0 * route.covered_fraction(), sum / n.max(1) as f64, max)
}

/// One run of one method in one cell.
/// One run: a method in a cell, with a seed.
#[derive(Debug, Clone, Copy)]
pub struct Job {
    pub method: Method,
    pub latency_s: f64,
    pub loss: f64,
    pub seed: u64,
}

pub fn run_one(
    m: &Mission0,
    settings: &Settings,
    job: Job,
    key: &SigningKey,
) -> anyhow::Result<RunRow> {
    let Job {
        method,
        latency_s,
        loss,
        seed,
    } = job;
    let profile = settings.link(latency_s, loss);
    let site = site_for(&m.site, seed);
    let mut route = Route::new(&m.route(), settings.coverage_radius_m);
    let mut row = RunRow {
        method: method.name(),
        latency_s,
        loss,
        seed,
        completed: false,
        completion_s: None,
        collisions: 0,
        bumps: 0,
        contact_s: 0.0,
        coverage_percent: 0.0,
        path_error_mean_m: 0.0,
        path_error_max_m: 0.0,
        bytes_up: 0,
        bytes_down: 0,
        handbacks: 0,
        uploads: 0,
        path: Vec::new(),
    };
    let path = match method {
        Method::Direct(d) => {
            let complete_at = settings.complete_at;
            let run = direct::run(
                &site,
                &m.twin.controller,
                &m.twin.robot.nominal_params,
                LinkEmulator::new(profile.clone(), seed, 0),
                LinkEmulator::new(profile.clone(), seed, 1),
                &DirectConfig {
                    method: d,
                    control_period_s: 0.02,
                    max_duration_s: settings.max_duration_s,
                    robot_id: "rover".into(),
                },
                |_, p| {
                    route.visit([p.x_m, p.y_m]);
                    route.covered_fraction() >= complete_at
                },
            )
            .map_err(|e| anyhow::anyhow!("{}: {e}", method.name()))?;
            row.completed = run.done_at_s.is_some();
            row.completion_s = run.done_at_s.map(|t| t + latency_s);
            (row.collisions, row.bumps, row.contact_s) = (run.collisions, run.bumps, run.contact_s);
            (row.bytes_up, row.bytes_down) = (run.up.bytes_sent, run.down.bytes_sent);
            run.path
        }
        Method::Decoupled => {
            let backend = SimBackend::new(site, m.plan.samples[0].pose(), settings.max_duration_s)
                .map_err(|e| anyhow::anyhow!("the site: {e}"))?;
            let recorder = Recorder {
                inner: backend,
                path: Vec::new(),
                contacts: Contacts::default(),
            };
            let mut mission = Mission::new(
                &m.plan,
                &m.plan_json,
                &m.twin,
                &m.world_toml,
                key,
                &profile,
                seed,
                recorder,
            )?;
            let until = (settings.max_duration_s * 1e9) as u64;
            let Mission {
                op, robot, link, ..
            } = &mut mission;
            link.run(op, robot, until, |op, _| op.report.outcome.is_some());
            let report = &op.report;
            if report.outcome == Some(Outcome::Completed) {
                row.completed = true;
                row.completion_s = report
                    .timeline
                    .iter()
                    .find(|e| e.event == "outcome")
                    .map(|e| e.t_s);
            }
            row.handbacks = report.handbacks.len();
            row.uploads = report.uploads.len();
            (row.bytes_up, row.bytes_down) = (link.up.stats.bytes_sent, link.down.stats.bytes_sent);
            let rec = robot.backend();
            let c = &rec.contacts;
            (row.collisions, row.bumps, row.contact_s) = (c.collisions, c.bumps, c.contact_s);
            rec.path.clone()
        }
    };
    let mut fresh = Route::new(&m.route(), settings.coverage_radius_m);
    let (coverage, mean, max) = score(&mut fresh, &path);
    row.coverage_percent = coverage;
    row.path_error_mean_m = mean;
    row.path_error_max_m = max;
    let points: Vec<(f64, f64)> = path.iter().map(|(_, p)| (p.x_m, p.y_m)).collect();
    row.path = twindrive_plot::decimate(&points, 0.01);
    Ok(row)
}

/// Every run of the grid, on every core, in a fixed order of results.
pub fn run_grid(m: &Mission0, settings: &Settings) -> anyhow::Result<Vec<RunRow>> {
    let key = SigningKey::from_bytes(&[7; 32]);
    let mut jobs = Vec::new();
    for &latency in &settings.latencies_s {
        for &loss in &settings.losses {
            for method in settings.methods() {
                for seed in 0..settings.seeds {
                    jobs.push(Job {
                        method,
                        latency_s: latency,
                        loss,
                        seed,
                    });
                }
            }
        }
    }
    super::pool::run_all(&jobs, |&job| {
        run_one(m, settings, job, &key).with_context(|| {
            format!(
                "{} at latency {} s, loss {}, seed {}",
                job.method.name(),
                job.latency_s,
                job.loss,
                job.seed
            )
        })
    })
}

/// The mean of the rows of one method in one cell.
#[derive(Debug, Clone)]
pub struct Cell {
    pub method: Method,
    pub latency_s: f64,
    pub loss: f64,
    pub runs: usize,
    pub completed: usize,
    /// Mean over completed runs.
    pub completion_s: Option<f64>,
    pub collisions: f64,
    pub bumps: f64,
    pub contact_s: f64,
    pub coverage_percent: f64,
    pub path_error_mean_m: f64,
    pub bytes_up: f64,
    pub bytes_down: f64,
    pub handbacks: f64,
}

pub fn cells(rows: &[RunRow], settings: &Settings) -> Vec<Cell> {
    let mut out = Vec::new();
    for &latency_s in &settings.latencies_s {
        for &loss in &settings.losses {
            for method in settings.methods() {
                let these: Vec<&RunRow> = rows
                    .iter()
                    .filter(|r| {
                        r.method == method.name() && r.latency_s == latency_s && r.loss == loss
                    })
                    .collect();
                let n = these.len().max(1) as f64;
                let mean = |f: &dyn Fn(&RunRow) -> f64| these.iter().map(|r| f(r)).sum::<f64>() / n;
                let done: Vec<f64> = these.iter().filter_map(|r| r.completion_s).collect();
                out.push(Cell {
                    method,
                    latency_s,
                    loss,
                    runs: these.len(),
                    completed: done.len(),
                    completion_s: (!done.is_empty())
                        .then(|| done.iter().sum::<f64>() / done.len() as f64),
                    collisions: mean(&|r| f64::from(r.collisions)),
                    bumps: mean(&|r| f64::from(r.bumps)),
                    contact_s: mean(&|r| r.contact_s),
                    coverage_percent: mean(&|r| r.coverage_percent),
                    path_error_mean_m: mean(&|r| r.path_error_mean_m),
                    bytes_up: mean(&|r| r.bytes_up as f64),
                    bytes_down: mean(&|r| r.bytes_down as f64),
                    handbacks: mean(&|r| r.handbacks as f64),
                });
            }
        }
    }
    out
}

fn pct(loss: f64) -> String {
    format!(
        "{} %",
        ryu::Buffer::new()
            .format(loss * 100.0)
            .trim_end_matches(".0")
    )
}

fn secs(latency: f64) -> String {
    ryu::Buffer::new()
        .format(latency)
        .trim_end_matches(".0")
        .to_string()
}

/// One table of methods (columns) against latency (rows) at one loss.
fn pivot(
    md: &mut String,
    title: &str,
    cells: &[Cell],
    settings: &Settings,
    loss: f64,
    entry: impl Fn(&Cell) -> String,
) {
    let methods = settings.methods();
    md.push_str(&format!("\n{title}\n\n| one-way latency (s) |"));
    for m in &methods {
        md.push_str(&format!(" {} |", m.name()));
    }
    md.push_str("\n|---:|");
    md.push_str(&"---:|".repeat(methods.len()));
    md.push('\n');
    for &lat in &settings.latencies_s {
        md.push_str(&format!("| {} |", secs(lat)));
        for m in &methods {
            let c = cells
                .iter()
                .find(|c| c.method == *m && c.latency_s == lat && c.loss == loss)
                .expect("every cell");
            md.push_str(&format!(" {} |", entry(c)));
        }
        md.push('\n');
    }
}

/// The tables of `results.md`: completion time and contacts pivoted by
/// latency, then every cell.
pub fn markdown(cells: &[Cell], settings: &Settings, intro: &str) -> String {
    let mut md = String::new();
    md.push_str(intro);
    for &loss in &settings.losses {
        pivot(
            &mut md,
            &format!(
                "**Completion time (s), loss {}** (mean over completed runs; `—`: none completed; completed/runs in brackets where not all)",
                pct(loss)
            ),
            cells,
            settings,
            loss,
            |c| {
                let t = c.completion_s.map_or("—".into(), |t| format!("{t:.0}"));
                if c.completed < c.runs {
                    format!("{t} ({}/{})", c.completed, c.runs)
                } else {
                    t
                }
            },
        );
        pivot(
            &mut md,
            &format!("**Collisions / bumps per run, loss {}**", pct(loss)),
            cells,
            settings,
            loss,
            |c| format!("{:.1} / {:.1}", c.collisions, c.bumps),
        );
    }
    md.push_str("\n**Every cell** (means over seeds)\n\n| method | latency (s) | loss | completed | completion (s) | collisions | bumps | in contact (s) | route covered | path error (m) | kB up | kB down | hand-backs |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for c in cells {
        md.push_str(&format!(
            "| {} | {} | {} | {}/{} | {} | {:.1} | {:.1} | {:.1} | {:.1} % | {:.3} | {:.1} | {:.1} | {:.1} |\n",
            c.method.name(),
            secs(c.latency_s),
            pct(c.loss),
            c.completed,
            c.runs,
            c.completion_s.map_or("—".into(), |t| format!("{t:.1}")),
            c.collisions,
            c.bumps,
            c.contact_s,
            c.coverage_percent,
            c.path_error_mean_m,
            c.bytes_up / 1e3,
            c.bytes_down / 1e3,
            c.handbacks,
        ));
    }
    md
}

/// `results.csv`, one row per run.
pub fn csv(rows: &[RunRow]) -> String {
    let mut s = String::from(
        "method,latency_s,loss,seed,completed,completion_s,collisions,bumps,contact_s,coverage_percent,path_error_mean_m,path_error_max_m,bytes_up,bytes_down,handbacks,uploads\n",
    );
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{:.2},{:.2},{:.4},{:.4},{},{},{},{}\n",
            r.method,
            r.latency_s,
            r.loss,
            r.seed,
            r.completed,
            r.completion_s.map_or(String::new(), |t| format!("{t:.3}")),
            r.collisions,
            r.bumps,
            r.contact_s,
            r.coverage_percent,
            r.path_error_mean_m,
            r.path_error_max_m,
            r.bytes_up,
            r.bytes_down,
            r.handbacks,
            r.uploads
        ));
    }
    s
}

/// Completion time and collisions against latency, one line per method,
/// one panel per loss. A method's cells that did not complete are marked in
/// a row of their own above the completion times (never drawn as if they
/// completed); lines that coincide are told apart by the plot.
pub fn figures(cells: &[Cell], settings: &Settings, dir: &Path) -> anyhow::Result<()> {
    let methods = settings.methods();
    for (base, title, y_label, value) in [
        (
            "completion_time",
            "mission completion time",
            "completion time (s)",
            (&|c: &Cell| c.completion_s) as &dyn Fn(&Cell) -> Option<f64>,
        ),
        (
            "collisions",
            "collision periods per run",
            "collisions",
            &|c: &Cell| Some(c.collisions),
        ),
    ] {
        let titles: Vec<String> = settings
            .losses
            .iter()
            .map(|l| format!("{title}, loss {}", pct(*l)))
            .collect();
        let of = |m: Method, loss: f64| {
            cells
                .iter()
                .filter(move |c| c.method == m && c.loss == loss)
        };
        let lines: Vec<Vec<Vec<(f64, f64)>>> = settings
            .losses
            .iter()
            .map(|&loss| {
                methods
                    .iter()
                    .map(|m| {
                        of(*m, loss)
                            .filter_map(|c| value(c).map(|v| (c.latency_s, v)))
                            .collect()
                    })
                    .collect()
            })
            .collect();
        // Not completed: method k's row at the top of its panel.
        let missing: Vec<Vec<Vec<(f64, f64)>>> = settings
            .losses
            .iter()
            .zip(&lines)
            .map(|(&loss, per_method)| {
                let top = per_method
                    .iter()
                    .flatten()
                    .map(|p| p.1)
                    .fold(0.0f64, f64::max);
                let step = 0.06 * top.max(1.0);
                methods
                    .iter()
                    .enumerate()
                    .map(|(k, m)| {
                        of(*m, loss)
                            .filter(|c| value(c).is_none())
                            .map(|c| (c.latency_s, top + step * (k + 1) as f64))
                            .collect()
                    })
                    .collect()
            })
            .collect();
        let missing_labels: Vec<String> = methods
            .iter()
            .map(|m| format!("{}: not completed (top rows)", m.name()))
            .collect();
        let series: Vec<Vec<Series>> = lines
            .iter()
            .map(|per_method| {
                per_method
                    .iter()
                    .zip(&methods)
                    .map(|(points, m)| Series {
                        label: m.name(),
                        points,
                        color: m.color(),
                    })
                    .collect()
            })
            .collect();
        let markers: Vec<Vec<Markers>> = missing
            .iter()
            .map(|per_method| {
                per_method
                    .iter()
                    .zip(&methods)
                    .zip(&missing_labels)
                    .filter(|((points, _), _)| !points.is_empty())
                    .map(|((points, m), label)| Markers {
                        label,
                        points,
                        color: m.color(),
                    })
                    .collect()
            })
            .collect();
        let panels: Vec<TimeFigure> = series
            .iter()
            .zip(&markers)
            .zip(&titles)
            .map(|((s, m), t)| TimeFigure {
                title: t,
                x_label: "one-way latency (s)",
                y_label,
                series: s,
                markers: m,
                bands: &[],
            })
            .collect();
        twindrive_plot::Panels { panels: &panels }.write(&dir.join(base))?;
    }
    Ok(())
}

/// The true paths of every method in one cell (seed 0), over the route.
pub fn paths_figure(
    rows: &[RunRow],
    m: &Mission0,
    settings: &Settings,
    latency_s: f64,
    loss: f64,
    base: &Path,
) -> anyhow::Result<()> {
    let route: Vec<(f64, f64)> = m.plan.samples.iter().map(|s| (s.x_m, s.y_m)).collect();
    let mut series = vec![Series {
        label: "intended route (the rehearsal's plan)",
        points: &route,
        color: palette::TRUTH,
    }];
    for method in settings.methods() {
        if let Some(r) = rows.iter().find(|r| {
            r.method == method.name() && r.latency_s == latency_s && r.loss == loss && r.seed == 0
        }) {
            series.push(Series {
                label: method.name(),
                points: &r.path,
                color: method.color(),
            });
        }
    }
    let title = format!(
        "true paths at {} s one way, loss {} (seed 0)",
        secs(latency_s),
        pct(loss)
    );
    WorldFigure {
        title: &title,
        walls: &walls(&m.site.world),
        paths: &series,
        markers: &[],
        outlines: &[],
    }
    .write(base)?;
    Ok(())
}

fn parse_list(
    text: &str,
    flag: &str,
    check: impl Fn(f64) -> bool,
    what: &str,
) -> anyhow::Result<Vec<f64>> {
    let mut out = Vec::new();
    for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let v: f64 = part
            .parse()
            .map_err(|_| usage(format!("{flag}: {what}, got `{part}`")))?;
        if !check(v) {
            return Err(usage(format!("{flag}: {what}, got {v}")));
        }
        if !out.contains(&v) {
            out.push(v);
        }
    }
    if out.is_empty() {
        return Err(usage(format!("{flag}: {what}, at least one")));
    }
    Ok(out)
}

/// The default site: `twin` with its true kinematics scaled by
/// [`SITE_SCALE`] and its own seed.
pub fn site_like(twin: &Scenario) -> Scenario {
    let mut site = twin.clone();
    let t = &mut site.robot.true_params;
    t.left_diameter_m *= SITE_SCALE[0];
    t.right_diameter_m *= SITE_SCALE[1];
    t.wheelbase_m *= SITE_SCALE[2];
    site.seed = twin.seed.wrapping_add(1_000);
    site
}

/// The demo's short version: latencies 0, 0.5 and 2 s at 10 % loss, one
/// seed, on the demo's own plan; `results.md`, `results.csv` and the
/// figures into `out`.
pub fn demo_section(mission: &Mission0, out: &Path) -> anyhow::Result<(Settings, Vec<Cell>)> {
    let settings = Settings::demo();
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let rows = run_grid(mission, &settings)?;
    let cells = cells(&rows, &settings);
    let md = markdown(&cells, &settings, &intro(mission, &settings));
    let staging = Staging::new(out, "demo-experiment")?;
    staging.write_with("results.csv", |w| Ok(w.write_all(csv(&rows).as_bytes())?))?;
    staging.write_with("results.md", |w| Ok(w.write_all(md.as_bytes())?))?;
    figures(&cells, &settings, staging.dir())?;
    paths_figure(
        &rows,
        mission,
        &settings,
        0.5,
        0.1,
        &staging.dir().join("paths"),
    )?;
    staging.commit()?;
    Ok((settings, cells))
}

/// The twin, the site and the calibrated parameters from the arguments.
pub fn inputs(
    args: &LatencyExperimentArgs,
) -> anyhow::Result<(Scenario, Vec<u8>, Scenario, DiffDriveParams)> {
    let (twin, world_toml) = match &args.scenario {
        Some(path) => (
            Scenario::load(path)?,
            std::fs::read(path).with_context(|| format!("reading {}", path.display()))?,
        ),
        None => (
            twindrive_sim::builtin::load("wall_following")
                .expect("built in")
                .context("the built-in wall_following scenario")?,
            twindrive_sim::builtin::WALL_FOLLOWING.as_bytes().to_vec(),
        ),
    };
    if !matches!(
        twin.controller,
        twindrive_sim::ControllerConfig::WallFollower { .. }
    ) {
        bail!(
            "--scenario: the mission's controller must be a wall follower (the operator's controller in direct operation)"
        );
    }
    let site = match &args.site {
        Some(path) => Scenario::load(path).map_err(|e| anyhow::anyhow!("--site: {e}"))?,
        None => site_like(&twin),
    };
    let calibrated = match &args.calibration {
        Some(path) => crate::flags::read_calibration(path)?,
        None => crate::commands::calibrate::calibrate_like(&twin)?,
    };
    Ok((twin, world_toml, site, calibrated))
}

/// The settings the flags give (each scalar is checked when parsed; the
/// lists here, as usage errors).
pub fn settings(args: &LatencyExperimentArgs) -> anyhow::Result<Settings> {
    Ok(Settings {
        latencies_s: parse_list(
            &args.latencies,
            "--latencies",
            |v| v.is_finite() && (0.0..=600.0).contains(&v),
            "one-way latencies from 0 to 600 s",
        )?,
        losses: parse_list(
            &args.losses,
            "--losses",
            |v| (0.0..0.9).contains(&v),
            "losses from 0 to 0.9 (a fraction)",
        )?,
        seeds: args.seeds,
        bandwidth_bit_s: args.bandwidth,
        watchdog_timeout_s: args.watchdog_timeout,
        move_s: args.move_s,
        coverage_radius_m: args.coverage_radius,
        complete_at: args.complete_at,
        max_duration_s: args.max_duration,
    })
}

pub fn run(args: &LatencyExperimentArgs) -> anyhow::Result<()> {
    let settings = settings(args)?;
    let (twin, world_toml, site, calibrated) = inputs(args)?;
    let mission = Mission0::rehearse(twin, world_toml, site, calibrated)?;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "rehearsal: plan of {:.1} s ({} samples); {} runs",
        mission.plan.duration_s(),
        mission.plan.samples.len(),
        settings.latencies_s.len() * settings.losses.len() * 4 * settings.seeds as usize
    )?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let rows = run_grid(&mission, &settings)?;
    let cells = cells(&rows, &settings);
    let intro = intro(&mission, &settings);
    let md = markdown(&cells, &settings, &intro);
    let staging = Staging::new(&args.out, "experiment-latency")?;
    staging.write_with("results.csv", |w| Ok(w.write_all(csv(&rows).as_bytes())?))?;
    staging.write_with("results.md", |w| Ok(w.write_all(md.as_bytes())?))?;
    figures(&cells, &settings, staging.dir())?;
    let mid = settings.latencies_s[settings.latencies_s.len() / 2];
    paths_figure(
        &rows,
        &mission,
        &settings,
        mid,
        settings.losses[0],
        &staging.dir().join("paths"),
    )?;
    staging.commit()?;
    out.write_all(md.as_bytes())?;
    writeln!(
        out,
        "-> {}/ (results.csv, results.md, completion_time, collisions, paths)",
        args.out.display()
    )?;
    Ok(())
}

/// What the experiment did, for the top of `results.md`.
pub fn intro(m: &Mission0, s: &Settings) -> String {
    let t = &m.twin.robot.true_params;
    let r = &m.site.robot.true_params;
    format!(
        "Mission: `{}` rehearsed on the twin, plan of {:.1} s. Site: true wheel diameters {:.4} / {:.4} m and \
         wheelbase {:.4} m (the twin's: {:.4} / {:.4} / {:.4}). Link both ways: the one-way latency, 2 % of it \
         as jitter, the loss, {:.0} kbit/s. Direct operation runs the twin's controller at the master at 50 Hz \
         ((b): wheels zeroed after {} s without a command; (c): moves of {} s); a run is complete when the \
         robot has passed within {} m of {:.0} % of the route, plus one latency for the operator to see it. \
         Decoupled: signed upload, autonomous execution, hand-back and continuation; complete when the master \
         learns the last plan finished. {} seed(s) per cell; runs cut at {:.0} s.\n",
        m.twin.name,
        m.plan.duration_s(),
        r.left_diameter_m,
        r.right_diameter_m,
        r.wheelbase_m,
        t.left_diameter_m,
        t.right_diameter_m,
        t.wheelbase_m,
        s.bandwidth_bit_s / 1e3,
        s.watchdog_timeout_s,
        s.move_s,
        s.coverage_radius_m,
        s.complete_at * 100.0,
        s.seeds,
        s.max_duration_s,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cell(method: Method, latency_s: f64, completion_s: Option<f64>) -> Cell {
        Cell {
            method,
            latency_s,
            loss: 0.1,
            runs: 1,
            completed: usize::from(completion_s.is_some()),
            completion_s,
            collisions: 0.0,
            bumps: 0.0,
            contact_s: 0.0,
            coverage_percent: 90.0,
            path_error_mean_m: 0.0,
            bytes_up: 0.0,
            bytes_down: 0.0,
            handbacks: 0.0,
        }
    }

    #[test]
    fn completion_figure_marks_runs_that_did_not_complete_and_coinciding_lines() {
        let settings = Settings::demo();
        let [hold, watchdog, move_wait, decoupled] = settings.methods();
        let mut cells = Vec::new();
        for (lat, direct, mw, dec) in [
            (0.0, Some(57.0), 77.0, 79.0),
            (0.5, None, 170.0, 80.0),
            (2.0, None, 504.0, 84.0),
        ] {
            cells.push(cell(hold, lat, direct));
            cells.push(cell(watchdog, lat, direct));
            cells.push(cell(move_wait, lat, Some(mw)));
            cells.push(cell(decoupled, lat, Some(dec)));
        }
        let dir = tempfile::tempdir().unwrap();
        figures(&cells, &settings, dir.path()).unwrap();
        let svg = std::fs::read_to_string(dir.path().join("completion_time.svg")).unwrap();
        for text in [
            "direct (a) hold-last: not completed (top rows)",
            "direct (b) watchdog: not completed (top rows)",
            "direct (b) watchdog (dashed: same points as direct (a) hold-last)",
        ] {
            assert!(svg.contains(text), "no `{text}` in the figure");
        }
        assert!(!svg.contains("move-and-wait: not completed"));
        assert!(dir.path().join("completion_time.png").is_file());
        assert!(dir.path().join("collisions.png").is_file());
    }
}
