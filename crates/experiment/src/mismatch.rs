//! `twindrive experiment mismatch`: decoupled operation as the site's
//! kinematics depart from the twin's, for a robot with the paper's one side
//! IR and for the same robot with a 2D lidar, with the robot localizing
//! against the plan's map and without (dead reckoning, as before issue 21).
//!
//! The twin rehearses the case study; the plan is made with the twin's
//! parameters. Each site is the twin with no motion-capture tracker (a
//! remote site has none), its true wheel diameters and wheelbase each
//! scaled by 1 ± the error (signs drawn per seed), its own noise, and,
//! with `box`, the demo's box on the route that the twin lacks. The plan
//! is signed and uploaded over the link profile and the robot runs it on
//! its own, with hand-back and continuation, in virtual time. Per run:
//! completed or not, completion time (upload included), hand-backs,
//! contacts with what the twin knew (its walls) and with what it did not
//! (the box), each contact counted once however many plans it spans, and
//! the largest distance of the true path from the plan's.

use std::io::Write;
use std::path::Path;

use anyhow::Context;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use twindrive_agent::backend::{Reading, RobotBackend, SimBackend};
use twindrive_agent::localize::LocalizeSettings;
use twindrive_agent::operator::Outcome;
use twindrive_kinematics::Pose;
use twindrive_link::emulator::LinkProfile;
use twindrive_link::envelope::SigningKey;
use twindrive_log::LogHeader;
use twindrive_sim::{Scenario, World};

use twindrive_files::Staging;
use twindrive_mission::redundancy::RouteProgress;

use crate::mission::Mission;
use crate::rehearsal::{Rehearsal, SITE_BOX, score};

/// The lidar added to the case study's robot for the lidar rows (a site
/// file's `[[range_sensors]]` table).
pub const LIDAR: &str = r#"
[[range_sensors]]
name = "lidar"
kind = "lidar"
mount = { x_m = 0.0, y_m = 0.0, heading_rad = 0.0 }
beams = 181
fov_rad = 3.141592653589793
max_range_m = 4.0
noise_std_m = 0.01
rate_hz = 10.0
"#;

/// The robot's range sensors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Sensors {
    /// The paper's one side IR.
    Ir,
    /// The side IR and a 181-beam, 4 m lidar.
    Lidar,
}

impl Sensors {
    pub fn name(self) -> &'static str {
        match self {
            Sensors::Ir => "ir",
            Sensors::Lidar => "lidar",
        }
    }

    /// The case study's twin with these sensors.
    pub fn twin(self) -> anyhow::Result<Scenario> {
        let mut text = twindrive_sim::builtin::WALL_FOLLOWING.to_string();
        if self == Sensors::Lidar {
            text.push_str(LIDAR);
        }
        Scenario::from_toml(
            &text,
            std::path::Path::new("<built-in>/wall_following.toml"),
        )
        .map_err(|e| anyhow::anyhow!("the case study with {}: {e}", self.name()))
    }
}

/// What the robot may do about an obstacle the twin lacks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Autonomy {
    /// The plan gives no corridor: the robot stops and hands back.
    Handback,
    /// The plan's corridor from the twin's clearance: a robot that can see
    /// ahead goes around inside it.
    Detour,
}

impl Autonomy {
    pub fn name(self) -> &'static str {
        match self {
            Autonomy::Handback => "handback",
            Autonomy::Detour => "detour",
        }
    }
}

/// One run's cell and seed.
#[derive(Debug, Clone, Copy)]
pub struct Job {
    pub sensors: Sensors,
    pub autonomy: Autonomy,
    pub error: f64,
    pub obstacle: bool,
    pub localization: bool,
    pub seed: u64,
}

/// One run.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub sensors: &'static str,
    pub autonomy: &'static str,
    pub kinematic_error: f64,
    pub obstacle: bool,
    pub localization: bool,
    pub seed: u64,
    pub completed: bool,
    pub completion_s: Option<f64>,
    pub handbacks: usize,
    /// Why, in order, `;`-separated.
    pub handback_reasons: String,
    /// Detours the robot went on by itself and came back from.
    pub detours: usize,
    /// Whether the twin learnt a block where the box is from what the
    /// robot saw on its detours (no hand-back needed).
    pub box_learnt_from_detours: bool,
    pub contacts_known: u32,
    pub contacts_unknown: u32,
    pub path_error_max_m: f64,
    /// Why the mission did not complete.
    pub failure: Option<String>,
}

/// A backend that records the robot's true path and classifies each
/// contact by what it touched.
struct Recorder {
    inner: SimBackend,
    known: World,
    touch_m: f64,
    /// Time (s) and true pose of every step.
    path: Vec<(f64, Pose)>,
    was_bumped: bool,
    known_contacts: u32,
    unknown_contacts: u32,
}

impl RobotBackend for Recorder {
    fn period_s(&self) -> f64 {
        self.inner.period_s()
    }
    fn step(&mut self, decide: &mut dyn FnMut(&Reading) -> [f64; 2]) -> Option<Reading> {
        let r = self.inner.step(decide)?;
        let p = r.record.ground_truth;
        self.path.push((r.t_s, p));
        let touching = r.record.bump || r.blocked;
        if touching && !self.was_bumped {
            if self.known.clearance_m(p.x_m, p.y_m, 1.0) <= self.touch_m {
                self.known_contacts += 1;
            } else {
                self.unknown_contacts += 1;
            }
        }
        self.was_bumped = touching;
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

/// The site of one run: no tracker, the kinematic error with signs drawn
/// from the seed, the box when asked, its own noise.
pub fn site(twin: &Scenario, job: &Job) -> Scenario {
    let mut s = twin.clone();
    s.tracker = None;
    let mut rng = ChaCha8Rng::seed_from_u64(job.seed.wrapping_mul(7919).wrapping_add(21));
    let mut sign = || if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    let t = &mut s.robot.true_params;
    t.left_diameter_m *= 1.0 + sign() * job.error;
    t.right_diameter_m *= 1.0 + sign() * job.error;
    t.wheelbase_m *= 1.0 + sign() * job.error;
    s.seed = twin.seed.wrapping_add(1_000 + job.seed);
    if job.obstacle {
        s.world = s.world.with_blocks(&[SITE_BOX]);
    }
    s
}

/// Runs one job on `mission` (its twin's sensors are the job's).
pub fn run_one(
    mission: &Rehearsal,
    job: Job,
    profile: &LinkProfile,
    max_duration_s: f64,
    key: &SigningKey,
) -> anyhow::Result<Row> {
    let twin = &mission.twin;
    let site = site(twin, &job);
    let plan = &mission.plan;
    let backend = SimBackend::new(site, plan.samples[0].pose(), max_duration_s)
        .map_err(|e| anyhow::anyhow!("the site: {e}"))?;
    let recorder = Recorder {
        inner: backend,
        known: twin.world.clone(),
        touch_m: twin.robot.footprint_radius_m + twin.bump.contact_margin_m + 0.01,
        path: Vec::new(),
        was_bumped: false,
        known_contacts: 0,
        unknown_contacts: 0,
    };
    let mut m = Mission::new(
        plan,
        &mission.plan_json,
        twin,
        &mission.world_toml,
        key,
        profile,
        job.seed,
        recorder,
    )?;
    m.op.config_mut().max_continuations = 8;
    if !job.localization {
        m.robot.set_localization(LocalizeSettings::odometry_only());
    }
    let until = (max_duration_s * 1e9) as u64;
    let Mission {
        op, robot, link, ..
    } = &mut m;
    link.run(op, robot, until, |op, _| op.report.outcome.is_some());
    let report = &op.report;
    let completed = report.outcome == Some(Outcome::Completed);
    let rec = robot.backend();
    // The route counts as covered within 0.15 m (as the latency
    // experiment's default); only the path error is reported here.
    let (_, _, path_error_max_m) =
        score(&mut RouteProgress::new(&mission.route(), 0.15), &rec.path);
    Ok(Row {
        sensors: job.sensors.name(),
        autonomy: job.autonomy.name(),
        kinematic_error: job.error,
        obstacle: job.obstacle,
        localization: job.localization,
        seed: job.seed,
        completed,
        completion_s: completed
            .then(|| {
                report
                    .timeline
                    .iter()
                    .find(|e| e.event == "outcome")
                    .map(|e| e.t_s)
            })
            .flatten(),
        handbacks: report.handbacks.len(),
        detours: report.detours.iter().filter(|d| d.rejoined).count(),
        box_learnt_from_detours: report.detours.iter().flat_map(|d| &d.learnt).any(|b| {
            let (lo, hi) = SITE_BOX;
            b.0[0] <= hi[0] && b.1[0] >= lo[0] && b.0[1] <= hi[1] && b.1[1] >= lo[1]
        }),
        handback_reasons: report
            .handbacks
            .iter()
            .map(|h| h.reason.as_str())
            .collect::<Vec<_>>()
            .join(";"),
        contacts_known: rec.known_contacts,
        contacts_unknown: rec.unknown_contacts,
        path_error_max_m,
        failure: (!completed).then(|| {
            report
                .failure
                .clone()
                .unwrap_or_else(|| format!("{:?}", report.outcome))
        }),
    })
}

/// Every job, on every core, results in the jobs' order.
fn run_all(
    missions: &[((Sensors, Autonomy), Rehearsal)],
    jobs: &[Job],
    profile: &LinkProfile,
    max_duration_s: f64,
) -> anyhow::Result<Vec<Row>> {
    let key = SigningKey::from_bytes(&[7; 32]);
    crate::pool::run_all(jobs, |job| {
        let mission = &missions
            .iter()
            .find(|(s, _)| *s == (job.sensors, job.autonomy))
            .expect("a mission per sensor set and autonomy")
            .1;
        run_one(mission, *job, profile, max_duration_s, &key).with_context(|| format!("{job:?}"))
    })
}

/// results.csv: one row per run.
pub fn csv(rows: &[Row]) -> String {
    let mut out = String::from(
        "sensors,autonomy,kinematic_error,obstacle,localization,seed,completed,completion_s,handbacks,handback_reasons,detours,box_learnt_from_detours,contacts_known,contacts_unknown,path_error_max_m,failure\n",
    );
    for r in rows {
        out.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.4},\"{}\"\n",
            r.sensors,
            r.autonomy,
            r.kinematic_error,
            r.obstacle,
            r.localization,
            r.seed,
            r.completed,
            r.completion_s.map_or(String::new(), |t| format!("{t:.1}")),
            r.handbacks,
            r.handback_reasons,
            r.detours,
            r.box_learnt_from_detours,
            r.contacts_known,
            r.contacts_unknown,
            r.path_error_max_m,
            r.failure.as_deref().unwrap_or("").replace('"', "\"\"")
        ));
    }
    out
}

/// results.md: one line per cell (sensors, obstacle, localization, error),
/// over its seeds.
pub fn markdown(rows: &[Row], profile: &str) -> String {
    let mut out = format!(
        "# Kinematic mismatch: decoupled operation over `{profile}`\n\n\
         The case study's plan on sites whose true wheel diameters and wheelbase each differ \
         from the twin's by the error (random signs), with no tracker; `box`: the demo's box \
         the twin lacks on the route. Autonomy `handback`: the plan gives the robot no corridor, \
         it stops and hands back; `detour`: the plan's corridor from the twin's clearance, a \
         robot that can see ahead (the lidar) goes around inside it. Means over seeds; contacts \
         are counted once each, by what was touched; completion is the mission's end (upload, \
         hand-backs and continuations included).\n\n\
         | sensors | autonomy | obstacle | localization | error % | completed | hand-backs per mission | contacts, known | contacts, unknown | completion s | path error max m |\n\
         |---|---|---|---|---:|---:|---:|---:|---:|---:|---:|\n"
    );
    type Key<'a> = (&'a str, &'a str, bool, bool, f64);
    let key = |r: &Row| -> Key<'_> {
        (
            r.sensors,
            r.autonomy,
            r.obstacle,
            r.localization,
            r.kinematic_error,
        )
    };
    let mut keys: Vec<Key<'_>> = Vec::new();
    for r in rows {
        if !keys.contains(&key(r)) {
            keys.push(key(r));
        }
    }
    for k in keys {
        let (sensors, autonomy, obstacle, localization, error) = k;
        let cell: Vec<&Row> = rows.iter().filter(|r| key(r) == k).collect();
        let n = cell.len() as f64;
        let mean = |f: &dyn Fn(&Row) -> f64| cell.iter().map(|r| f(r)).sum::<f64>() / n;
        let done: Vec<f64> = cell.iter().filter_map(|r| r.completion_s).collect();
        out.push_str(&format!(
            "| {sensors} | {autonomy} | {} | {} | {:.1} | {}/{} | {:.1} | {:.1} | {:.1} | {} | {:.3} |\n",
            if obstacle { "box" } else { "none" },
            if localization { "on" } else { "off" },
            100.0 * error,
            done.len(),
            cell.len(),
            mean(&|r| r.handbacks as f64),
            mean(&|r| f64::from(r.contacts_known)),
            mean(&|r| f64::from(r.contacts_unknown)),
            if done.is_empty() {
                "-".into()
            } else {
                format!("{:.0}", done.iter().sum::<f64>() / done.len() as f64)
            },
            mean(&|r| r.path_error_max_m),
        ));
    }
    out
}

/// The experiment's grid: every combination of its lists, each seed.
#[derive(Debug, Clone)]
pub struct Config {
    /// Kinematic errors (fractions: 0.01 is 1 %).
    pub errors: Vec<f64>,
    pub sensors: Vec<Sensors>,
    /// Hand back, go around inside the corridor, or both.
    pub autonomy: Vec<Autonomy>,
    /// With the box on the route, without, or both.
    pub obstacle: Vec<bool>,
    /// Localization against the plan's map on, off, or both.
    pub localization: Vec<bool>,
    pub seeds: u64,
    /// The link, and its text as given (for the tables).
    pub profile: LinkProfile,
    pub profile_text: String,
    /// Give a run up after this long, seconds of mission time.
    pub max_duration_s: f64,
}

/// Runs the grid; `results.csv` and `results.md` into `dir`, the table to
/// `out`.
pub fn run(config: &Config, dir: &Path, out: &mut impl Write) -> anyhow::Result<()> {
    let profile = config.profile.clone();
    let mut missions = Vec::new();
    let sensor_sets = config.sensors.clone();
    for &sensors in &sensor_sets {
        let twin = sensors.twin()?;
        let calibrated = twin.robot.true_params;
        let world_toml = twindrive_sim::builtin::WALL_FOLLOWING.as_bytes().to_vec();
        let mission = Rehearsal::rehearse(twin.clone(), world_toml, twin, calibrated)
            .with_context(|| format!("rehearsing with {}", sensors.name()))?;
        writeln!(
            out,
            "rehearsal ({}): plan of {:.1} s",
            sensors.name(),
            mission.plan.duration_s()
        )?;
        for &autonomy in &config.autonomy {
            let plan = match autonomy {
                Autonomy::Detour => mission.with_freedom(|_| {})?,
                Autonomy::Handback => mission.with_freedom(|f| f.corridor.clear())?,
            };
            missions.push(((sensors, autonomy), plan));
        }
    }
    let mut jobs = Vec::new();
    for (&sensors, &autonomy) in sensor_sets
        .iter()
        .flat_map(|s| config.autonomy.iter().map(move |a| (s, a)))
    {
        for &obstacle in &config.obstacle {
            for &localization in &config.localization {
                for &error in &config.errors {
                    for seed in 0..config.seeds {
                        jobs.push(Job {
                            sensors,
                            autonomy,
                            error,
                            obstacle,
                            localization,
                            seed,
                        });
                    }
                }
            }
        }
    }
    writeln!(out, "{} runs over {}", jobs.len(), config.profile_text)?;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let rows = run_all(&missions, &jobs, &profile, config.max_duration_s)?;
    let md = markdown(&rows, &config.profile_text);
    let staging = Staging::new(dir, "experiment-mismatch")?;
    staging.write_with("results.csv", |w| Ok(w.write_all(csv(&rows).as_bytes())?))?;
    staging.write_with("results.md", |w| Ok(w.write_all(md.as_bytes())?))?;
    staging.commit()?;
    out.write_all(md.as_bytes())?;
    writeln!(out, "-> {}/ (results.csv, results.md)", dir.display())?;
    Ok(())
}
