//! Running the grid: one run is one method in one cell with one seed, on
//! the site, in virtual time; every run on every core.

use anyhow::Context;
use serde::Serialize;
use twindrive_agent::backend::{Reading, RobotBackend, SimBackend};
use twindrive_agent::direct::{self, DirectConfig};
use twindrive_agent::operator::Outcome;
use twindrive_kinematics::Pose;
use twindrive_link::emulator::LinkEmulator;
use twindrive_link::envelope::SigningKey;
use twindrive_log::LogHeader;
use twindrive_mission::redundancy::RouteProgress;
use twindrive_sim::{Contacts, Scenario};

use super::model::{Method, Settings};
use crate::mission::Mission;
use crate::rehearsal::{Rehearsal, score};

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
    fn step(&mut self, decide: &mut dyn FnMut(&Reading) -> [f64; 2]) -> Option<Reading> {
        let r = self.inner.step(decide)?;
        self.path.push((r.t_s, r.record.ground_truth));
        let dt_s = self.period_s();
        self.contacts.record(r.record.bump, r.blocked, dt_s);
        Some(r)
    }
    fn hold(&mut self) -> bool {
        self.inner.hold()
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

/// One run: a method in a cell, with a seed.
#[derive(Debug, Clone, Copy)]
pub struct Job {
    pub method: Method,
    pub latency_s: f64,
    pub loss: f64,
    pub seed: u64,
}

pub fn run_one(
    m: &Rehearsal,
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
    let mut route = RouteProgress::new(&m.route(), settings.coverage_radius_m);
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
    let mut fresh = RouteProgress::new(&m.route(), settings.coverage_radius_m);
    let (coverage, mean, max) = score(&mut fresh, &path);
    row.coverage_percent = coverage;
    row.path_error_mean_m = mean;
    row.path_error_max_m = max;
    let points: Vec<(f64, f64)> = path.iter().map(|(_, p)| (p.x_m, p.y_m)).collect();
    row.path = twindrive_plot::decimate(&points, 0.01);
    Ok(row)
}

/// Every run of the grid, on every core, in a fixed order of results.
pub fn run_grid(m: &Rehearsal, settings: &Settings) -> anyhow::Result<Vec<RunRow>> {
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
    crate::pool::run_all(&jobs, |&job| {
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
