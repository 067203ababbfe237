//! The console's state behind the web server: the twin workspace, the plan
//! and its verification, the robots; commands in, frames out. No I/O but
//! the files a plan leaves behind (rehearsals), and time as an argument.

use std::collections::{BTreeMap, VecDeque};
use std::path::PathBuf;
use std::sync::Arc;

use serde_json::{Value, json};
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_link::envelope::{SigningKey, Supervision};
use twindrive_log::MissionLog;
use twindrive_mission::coverage::covered_share;
use twindrive_mission::follower::{Follower, FollowerSettings, expected_duration_s};
use twindrive_mission::freedom::FreedomSettings;
use twindrive_mission::goals::Goals;
use twindrive_mission::itinerary::{Itinerary, ItineraryError};
use twindrive_mission::plan::KeepOutZone;
use twindrive_mission::plan::MissionPlan;
use twindrive_mission::redundancy::RedundancyConfig;
use twindrive_mission::route::{RoutePlanner, RouteSettings};
use twindrive_sim::Scenario;

use crate::fleet::{SharedSlot, Signing};
use crate::planning::{self, PlanResult, Verification};
use crate::protocol::Command;
use crate::words::in_operator_words;
use crate::workspace::Workspace;

/// Areas the twin is sweeping, to measure once the drive's rehearsal (the
/// one after `rehearsal_rev`) ends.
struct Sweeping {
    rehearsal_rev: u64,
    /// Each area's polygon and sweep radius (m).
    areas: Vec<(Vec<[f64; 2]>, f64)>,
    zones: Vec<KeepOutZone>,
    settings: RouteSettings,
}

/// Work too slow for the console's tick, run on a blocking thread.
pub enum Job {
    Plan {
        log: Box<MissionLog>,
        scenario: Box<Scenario>,
        params: DiffDriveParams,
        redundancy: RedundancyConfig,
        freedom: Box<FreedomSettings>,
    },
    Verify {
        plan: Arc<MissionPlan>,
        scenario: Box<Scenario>,
    },
}

pub enum JobResult {
    /// A plan, verified on the twin as soon as it is made.
    Plan(Result<(PlanResult, (Verification, Value)), String>),
    Verify(Result<(Verification, Value), String>),
}

impl Job {
    pub fn run(self) -> JobResult {
        match self {
            Job::Plan {
                log,
                scenario,
                params,
                redundancy,
                freedom,
            } => JobResult::Plan(
                planning::make_plan(&log, &scenario, &params, redundancy, *freedom).and_then(|p| {
                    let v = planning::verify(&p.plan, &scenario)?;
                    Ok((p, v))
                }),
            ),
            Job::Verify { plan, scenario } => JobResult::Verify(planning::verify(&plan, &scenario)),
        }
    }
}

/// What a command did.
pub enum Applied {
    /// Done; a line for the operator, if worth one.
    Done(Option<String>),
    /// Run this job, then hand its result to [`Core::finish`].
    Job(Job),
}

/// One published picture: the state (small, every frame) and the heavy
/// parts with the revision they belong to (sent when a page lacks them).
pub struct Frame {
    pub state: Arc<str>,
    pub world: Arc<str>,
    pub plan: Option<(u64, Arc<str>)>,
    pub verify: Option<(u64, Arc<str>)>,
    pub rehearsal: Option<(u64, Arc<str>)>,
}

/// Why the console will not plan without a robot model.
pub const NO_MODEL: &str = "plan: no robot model. Plans are made with the robot's calibrated wheel diameters and wheelbase, and the twin rehearses with the same ones; without them the plan's path is dead reckoning with parameters the robot does not have, and it fails on the robot. Calibrate the robot (`twindrive calibrate`) and start the console with --calibration calib.json";

/// What the console was started with.
pub struct Settings {
    pub key: Option<SigningKey>,
    /// The robot's calibrated parameters, which plans are made with.
    pub params: DiffDriveParams,
    /// Whether they came from a calibration (or are the twin's nominal ones).
    pub calibrated: bool,
    /// SHA-256 of the twin's scenario file: plans are signed for it.
    pub world_sha256: String,
    pub unix_at_zero_s: f64,
    pub supervision: Supervision,
    pub expires_in_s: u64,
    /// Where rehearsals and plans are kept.
    pub out: PathBuf,
    /// Tells a page that the console behind it restarted.
    pub instance: String,
}

pub struct Core {
    pub ws: Workspace,
    pub robots: Vec<SharedSlot>,
    settings: Settings,
    redundancy: RedundancyConfig,
    freedom: FreedomSettings,
    plan: Option<PlanResult>,
    plan_rev: u64,
    verification: Option<(Verification, Value)>,
    verify_rev: u64,
    /// The way to the operator's goals (or why there is none), as the
    /// page draws it, with the goals as given (a page opened later takes
    /// them up).
    route: Option<Value>,
    /// The last refusal of each part of the page ([`spot`]), in the
    /// operator's words, until a command there succeeds.
    refusals: BTreeMap<&'static str, String>,
    /// A sweep being driven: what the twin swept of each area is measured
    /// once its rehearsal ends.
    sweeping: Option<Sweeping>,
    job: Option<&'static str>,
    events: VecDeque<Value>,
    event_seq: u64,
    world: Arc<str>,
    plan_cache: Option<(u64, Arc<str>)>,
    verify_cache: Option<(u64, Arc<str>)>,
    rehearsal_cache: Option<(u64, Arc<str>)>,
}

/// The part of the page a command comes from, where its refusal shows:
/// `goals` (Show the way, Drive it), `plan` (Make plan, Verify; `freedom`
/// when the robot's freedom is refused), `twin` (the twin's controls),
/// `robot` (upload, and the decision after a hand-back). Driving, stopping
/// and focusing have none: they are refused only for a broken page.
pub fn spot(cmd: &Command) -> Option<&'static str> {
    match cmd {
        Command::Goals { .. } | Command::GoalsClear => Some("goals"),
        Command::Plan { .. } | Command::Verify => Some("plan"),
        Command::Upload { .. } | Command::Replan { .. } | Command::EndMission { .. } => {
            Some("robot")
        }
        Command::WallFollow
        | Command::Speed { .. }
        | Command::Reset
        | Command::Place { .. }
        | Command::RecordStart
        | Command::RecordStop => Some("twin"),
        Command::Drive { .. } | Command::Stop | Command::Focus { .. } => None,
    }
}

/// The map as the page draws it: walls, solids, the occupancy grid (row 0
/// at the bottom), the robot's footprint and sensors.
pub fn world_json(scenario: &Scenario) -> Value {
    let w = &scenario.world;
    let segments: Vec<[f64; 4]> = w
        .segments()
        .iter()
        .map(|s| [s.a.x, s.a.y, s.b.x, s.b.y])
        .collect();
    let solids: Vec<[f64; 4]> = w
        .solids()
        .iter()
        .map(|a| [a.mins.x, a.mins.y, a.maxs.x, a.maxs.y])
        .collect();
    let grid = w.grid().map(|g| {
        let cells: String = g
            .cells
            .iter()
            .map(|c| match c {
                twindrive_sim::map::Cell::Free => '0',
                twindrive_sim::map::Cell::Occupied => '1',
                twindrive_sim::map::Cell::Unknown => '2',
            })
            .collect();
        json!({
            "width": g.width, "height": g.height, "resolution_m": g.resolution_m,
            "origin": [g.origin_x_m, g.origin_y_m, g.origin_yaw_rad], "cells": cells,
        })
    });
    let bounds = w.bounds().map(|b| [b.mins.x, b.mins.y, b.maxs.x, b.maxs.y]);
    json!({
        "type": "world",
        "scenario": scenario.name,
        "segments": segments,
        "solids": solids,
        "grid": grid,
        "bounds": bounds,
        "start": [scenario.robot.start.x_m, scenario.robot.start.y_m, scenario.robot.start.heading_rad],
        "footprint_radius_m": scenario.robot.footprint_radius_m,
        "dt_s": scenario.dt_ns as f64 * 1e-9,
    })
}

impl Core {
    pub fn new(ws: Workspace, robots: Vec<SharedSlot>, settings: Settings) -> Self {
        let world = world_json(ws.scenario()).to_string().into();
        let redundancy = planning::default_redundancy(ws.scenario());
        Self {
            ws,
            robots,
            settings,
            redundancy,
            freedom: FreedomSettings::default(),
            plan: None,
            plan_rev: 0,
            verification: None,
            verify_rev: 0,
            route: None,
            refusals: BTreeMap::new(),
            sweeping: None,
            job: None,
            events: VecDeque::new(),
            event_seq: 0,
            world,
            plan_cache: None,
            verify_cache: None,
            rehearsal_cache: None,
        }
    }

    /// A line in the page's event list.
    pub fn event(&mut self, level: &str, text: String) {
        match level {
            "error" | "warn" => tracing::warn!("{text}"),
            _ => tracing::info!("{text}"),
        }
        self.event_seq += 1;
        self.events
            .push_back(json!({ "seq": self.event_seq, "level": level, "text": text }));
        if self.events.len() > 30 {
            self.events.pop_front();
        }
    }

    /// The events after sequence number `seq`: (seq, level, text).
    pub fn events_since(&self, seq: u64) -> Vec<(u64, String, String)> {
        self.events
            .iter()
            .filter_map(|e| {
                let n = e["seq"].as_u64()?;
                (n > seq).then(|| {
                    (
                        n,
                        e["level"].as_str().unwrap_or("info").to_owned(),
                        e["text"].as_str().unwrap_or_default().to_owned(),
                    )
                })
            })
            .collect()
    }

    fn robot(&self, id: &str) -> Result<&SharedSlot, String> {
        self.robots
            .iter()
            .find(|r| r.lock().id == id)
            .ok_or_else(|| {
                let ids: Vec<String> = self.robots.iter().map(|r| r.lock().id.clone()).collect();
                format!("no robot `{id}`; this console has {ids:?}")
            })
    }

    /// Carries out a command from a page at console time `now_ns`.
    /// Plans the way to `goals` from where the twin's robot stands, out of
    /// the keep-out zones of the freedom last set; with `drive`, sends the
    /// robot along it recording a rehearsal.
    fn goals(
        &mut self,
        goals: &Goals,
        drive: bool,
        keep_out: Option<Vec<KeepOutZone>>,
        now_ns: u64,
    ) -> Result<Applied, String> {
        goals.validate().map_err(|e| format!("goals: {e}"))?;
        let zones = keep_out.unwrap_or_else(|| self.freedom.keep_out.clone());
        let probe = FreedomSettings {
            keep_out: zones.clone(),
            ..FreedomSettings::default()
        };
        probe
            .validate(self.ws.scenario().robot.footprint_radius_m)
            .map_err(|e| format!("goals: the keep-out zones, {e}"))?;
        if drive && let Some(job) = self.job {
            return Err(format!("busy {job}; wait for it"));
        }
        self.ws.advance(now_ns);
        let pose = self.ws.pose();
        let scenario = self.ws.scenario();
        let settings = RouteSettings {
            clearance_m: goals.clearance_m,
            ..RouteSettings::default()
        };
        let planner = RoutePlanner::new(
            &scenario.world,
            &zones,
            scenario.robot.footprint_radius_m,
            settings,
        )
        .ok_or("goals: the twin's site has no walls or map to plan on")?;
        let itinerary = match Itinerary::plan(&planner, goals, pose, &scenario.robot) {
            Ok(itinerary) => itinerary,
            Err(ItineraryError::Unreachable { reason, why }) => {
                let waypoints: Vec<[f64; 2]> = goals.waypoints.iter().map(|w| w.at()).collect();
                self.route = Some(json!({
                    "waypoints": waypoints,
                    "unreachable": why,
                    "reason": reason,
                }));
                return Err(format!("goals: {reason}"));
            }
            Err(e) => return Err(format!("goals: {e}")),
        };
        let sweeps = &itinerary.sweeps;
        let areas: Vec<Value> = sweeps
            .iter()
            .map(|(_, s)| {
                json!({
                    "lanes": s.lanes,
                    "touch_ups": s.touch_ups,
                    "free_m2": s.free_m2,
                    "planned_percent": s.planned_percent,
                })
            })
            .collect();
        let goals = &itinerary.driven;
        let waypoints: Vec<[f64; 2]> = goals.waypoints.iter().map(|w| w.at()).collect();
        let route = itinerary.route.clone();
        let settings = FollowerSettings::default();
        let duration_s = expected_duration_s(
            &route,
            goals,
            &settings,
            &scenario.robot,
            pose,
            scenario.dt_ns as f64 * 1e-9,
        );
        let line = format!(
            "twin: a way of {:.2} m to {} waypoint(s), about {duration_s:.0} s, the footprint at least {:.3} m clear",
            route.length_m,
            goals.waypoints.len(),
            route.min_clearance_m
        );
        self.route = Some(json!({
            "waypoints": waypoints,
            "points": route.points,
            "stops": route.stops,
            "length_m": route.length_m,
            "min_clearance_m": route.min_clearance_m,
            "duration_s": duration_s,
            "areas": areas,
            "unreachable": Value::Null,
        }));
        if drive {
            if self.ws.recording_s().is_none() {
                self.ws.record_start(now_ns);
            }
            self.sweeping = (!sweeps.is_empty()).then(|| Sweeping {
                rehearsal_rev: self.ws.rehearsal_rev(),
                areas: itinerary
                    .goals
                    .areas
                    .iter()
                    .zip(sweeps)
                    .map(|(a, (s, _))| (a.polygon.clone(), s.sweep_radius_m))
                    .collect(),
                zones: zones.clone(),
                settings: *planner.settings(),
            });
            let follower = Follower::new(&route, goals, settings);
            self.ws.follow(follower, itinerary, now_ns);
            return Ok(Applied::Done(Some(format!(
                "{line}: driving it, recording the rehearsal"
            ))));
        }
        Ok(Applied::Done(Some(line)))
    }

    /// Carries out `cmd` at console time `now_ns`. A refusal comes back in
    /// the operator's words and stays in the state beside the part of the
    /// page that sent it ([`spot`]) until a command there succeeds; new
    /// goals replace the way shown.
    pub fn apply(&mut self, cmd: Command, now_ns: u64) -> Result<Applied, String> {
        let zones = match &cmd {
            Command::Goals {
                keep_out: Some(z), ..
            } => z.clone(),
            Command::Plan {
                freedom: Some(f), ..
            } => f.keep_out.clone(),
            _ => self.freedom.keep_out.clone(),
        };
        let given = match &cmd {
            Command::Goals { goals, .. } => Some(goals.clone()),
            _ => None,
        };
        if given.is_some() {
            self.route = None;
        }
        let place = spot(&cmd);
        let result = self.carry_out(cmd, now_ns);
        if let (Some(goals), Some(route)) = (given, self.route.as_mut()) {
            route["goals"] = json!(goals);
        }
        match result {
            Ok(applied) => {
                if let Some(place) = place {
                    self.refusals.remove(place);
                    if place == "plan" {
                        self.refusals.remove("freedom");
                    }
                }
                Ok(applied)
            }
            Err(e) => {
                let words = in_operator_words(&e, &zones);
                if let Some(place) = place {
                    let place = if place == "plan" && e.starts_with("plan: the robot's freedom") {
                        "freedom"
                    } else {
                        place
                    };
                    self.refusals.insert(place, words.clone());
                }
                Err(words)
            }
        }
    }

    fn carry_out(&mut self, cmd: Command, now_ns: u64) -> Result<Applied, String> {
        let done = |s: &str| Ok(Applied::Done(Some(s.to_owned())));
        match cmd {
            Command::Drive { forward, turn } => {
                self.ws.drive(forward, turn, now_ns)?;
                Ok(Applied::Done(None))
            }
            Command::Stop => {
                self.ws.stop(now_ns);
                Ok(Applied::Done(None))
            }
            Command::WallFollow => {
                self.ws.wall_follow(now_ns);
                done("twin: wall follower on")
            }
            Command::Goals {
                goals,
                drive,
                keep_out,
            } => self.goals(&goals, drive, keep_out, now_ns),
            Command::GoalsClear => {
                self.route = None;
                Ok(Applied::Done(None))
            }
            Command::Speed { factor } => {
                self.ws.set_speed(factor, now_ns)?;
                Ok(Applied::Done(Some(format!("twin: {factor}x real time"))))
            }
            Command::Reset => {
                self.ws.reset(now_ns);
                done("twin: reset to the start pose")
            }
            Command::Place {
                x_m,
                y_m,
                heading_rad,
            } => {
                self.ws.place(Pose::new(x_m, y_m, heading_rad), now_ns)?;
                Ok(Applied::Done(Some(format!(
                    "twin: robot placed at ({x_m:.2}, {y_m:.2})"
                ))))
            }
            Command::RecordStart => {
                self.ws.record_start(now_ns);
                done("twin: recording a rehearsal")
            }
            Command::RecordStop => {
                let log = self.ws.record_stop(now_ns)?;
                let secs = log.steps.len() as f64 * log.header.dt_s;
                Ok(Applied::Done(Some(format!(
                    "twin: rehearsal of {secs:.1} s recorded"
                ))))
            }
            Command::Plan {
                redundancy,
                freedom,
            } => {
                if let Some(job) = self.job {
                    return Err(format!("busy {job}; wait for it"));
                }
                if !self.settings.calibrated {
                    return Err(NO_MODEL.into());
                }
                let log = self
                    .ws
                    .rehearsal()
                    .ok_or("plan: record a rehearsal first")?
                    .clone();
                if let Some(f) = freedom {
                    f.validate(self.ws.scenario().robot.footprint_radius_m)
                        .map_err(|e| format!("plan: the robot's freedom, {e}"))?;
                    self.freedom = f;
                }
                if let Some(r) = redundancy {
                    self.redundancy = r;
                }
                self.job = Some("planning");
                Ok(Applied::Job(Job::Plan {
                    log: Box::new(log),
                    scenario: Box::new(self.ws.scenario().clone()),
                    params: self.settings.params,
                    redundancy: self.redundancy.clone(),
                    freedom: Box::new(self.freedom.clone()),
                }))
            }
            Command::Verify => {
                if let Some(job) = self.job {
                    return Err(format!("busy {job}; wait for it"));
                }
                let plan = self
                    .plan
                    .as_ref()
                    .ok_or("verify: make a plan first")?
                    .plan
                    .clone();
                self.job = Some("verifying");
                Ok(Applied::Job(Job::Verify {
                    plan,
                    scenario: Box::new(self.ws.scenario().clone()),
                }))
            }
            Command::Upload { robot, force } => {
                if self.settings.key.is_none() {
                    return Err(
                        "upload: this console has no signing key (start it with --key)".into(),
                    );
                }
                let p = self.plan.as_ref().ok_or("upload: make a plan first")?;
                let short = p.plan.sha256[..12].to_owned();
                let verdict = self
                    .verification
                    .as_ref()
                    .filter(|(v, _)| v.plan_sha256 == p.plan.sha256)
                    .map(|(v, _)| v.verdict.clone());
                match verdict {
                    Some(v) if v.passed => {}
                    Some(v) if force => {
                        let reasons = v.reasons.join("; ");
                        tracing::warn!(plan = %p.plan.sha256, reasons, "operator override: sending a plan that failed verification");
                        self.event(
                            "error",
                            format!("upload: plan {short} FAILED verification ({reasons}); sent anyway at the operator's insistence"),
                        );
                    }
                    Some(v) => {
                        return Err(format!(
                            "upload: plan {short} failed verification on the twin ({}); it is not sent. Fix the rehearsal or the calibration, or tick \"send even if verification failed\"",
                            v.reasons.join("; ")
                        ));
                    }
                    None => {
                        return Err(format!(
                            "upload: plan {short} is not verified yet; verify it first"
                        ));
                    }
                }
                let p = self.plan.as_ref().expect("checked above");
                let key = self.settings.key.as_ref().expect("checked above");
                let unix_now_s = self.settings.unix_at_zero_s + now_ns as f64 * 1e-9;
                let signing = Signing {
                    key,
                    world_sha256: &self.settings.world_sha256,
                    unix_now_s,
                    unix_at_zero_s: self.settings.unix_at_zero_s,
                    expires_in_s: self.settings.expires_in_s,
                    supervision: self.settings.supervision,
                };
                let slot = self.robot(&robot)?;
                let line = slot.lock().upload(
                    p.plan.clone(),
                    &p.plan_json,
                    self.ws.scenario(),
                    &signing,
                    now_ns,
                )?;
                Ok(Applied::Done(Some(line)))
            }
            Command::Replan { robot } => {
                let line = self.robot(&robot)?.lock().replan(now_ns)?;
                Ok(Applied::Done(Some(line)))
            }
            Command::EndMission { robot } => {
                let line = self.robot(&robot)?.lock().end_mission(now_ns)?;
                Ok(Applied::Done(Some(line)))
            }
            Command::Focus { robot } => {
                if let Some(id) = robot {
                    self.robot(&id)?;
                }
                Ok(Applied::Done(None))
            }
        }
    }

    /// Takes a job's result in.
    pub fn finish(&mut self, result: JobResult) -> Result<String, String> {
        self.job = None;
        match result {
            JobResult::Plan(Ok((p, verified))) => {
                // Plans made here, laid out as the master's: the document
                // and the twin's run it was made from.
                let archive = twindrive_store::MasterArchive::new(&self.settings.out);
                let stem = p.plan.sha256[..12].to_owned();
                let written = archive
                    .write_rehearsal(&p.plan.sha256, &p.rehearsal_mcap)
                    .and_then(|_| archive.write_plan(&p.plan, &p.plan_json, None));
                let plan_path = written.map_err(|e| {
                    format!("writing plan {stem} into {}: {e}", archive.dir().display())
                })?;
                let s = &p.view["summary"];
                let line = format!(
                    "plan {stem}: {:.2} m in {:.1} s from {:.2} m rehearsed, {:.2} % covered; {}; verification {}",
                    s["plan_length_m"].as_f64().unwrap_or(0.0),
                    s["plan_duration_s"].as_f64().unwrap_or(0.0),
                    s["executed_length_m"].as_f64().unwrap_or(0.0),
                    s["coverage_percent"].as_f64().unwrap_or(0.0),
                    plan_path.display(),
                    verified.0.verdict.summary(),
                );
                self.plan = Some(p);
                self.plan_rev += 1;
                self.verification = Some(verified);
                self.verify_rev += 1;
                Ok(line)
            }
            JobResult::Plan(Err(e)) => {
                let words = in_operator_words(&e, &self.freedom.keep_out);
                self.refusals.insert("plan", words.clone());
                Err(words)
            }
            JobResult::Verify(Ok(v)) => {
                let line = format!(
                    "verification of {}: {}",
                    &v.0.plan_sha256[..12],
                    v.0.verdict.summary()
                );
                self.verification = Some(v);
                self.verify_rev += 1;
                Ok(line)
            }
            JobResult::Verify(Err(e)) => {
                self.refusals.insert("plan", e.clone());
                Err(e)
            }
        }
    }

    /// Time passes: the twin moves, the operators react.
    pub fn tick(&mut self, now_ns: u64) {
        self.ws.advance(now_ns);
        self.measure_sweep();
        let mut lines = Vec::new();
        for r in &self.robots {
            let mut slot = r.lock();
            slot.tick(now_ns);
            lines.extend(slot.take_events());
        }
        for (level, text) in lines {
            self.event(level, text);
        }
    }

    /// Once a sweep's rehearsal has ended: what the twin swept of each
    /// area, by its true track, into the way's view and the event list.
    fn measure_sweep(&mut self) {
        let Some(sw) = &self.sweeping else {
            return;
        };
        if self.ws.rehearsal_rev() <= sw.rehearsal_rev {
            return;
        }
        let sw = self.sweeping.take().expect("checked");
        let Some(log) = self.ws.rehearsal() else {
            return;
        };
        let track: Vec<[f64; 2]> = log
            .steps
            .iter()
            .map(|s| [s.ground_truth.x_m, s.ground_truth.y_m])
            .collect();
        let scenario = self.ws.scenario();
        let Some(planner) = RoutePlanner::new(
            &scenario.world,
            &sw.zones,
            scenario.robot.footprint_radius_m,
            sw.settings,
        ) else {
            return;
        };
        let mut lines = Vec::new();
        let mut percents = Vec::new();
        for (i, (polygon, radius)) in sw.areas.iter().enumerate() {
            let (free_m2, percent) = covered_share(&planner, polygon, &track, *radius);
            percents.push((polygon, percent));
            if let Some(area) = self
                .route
                .as_mut()
                .and_then(|r| r.get_mut("areas"))
                .and_then(|a| a.get_mut(i))
            {
                area["swept_percent"] = json!(percent);
            }
            lines.push(format!(
                "twin: area {} swept {percent:.1} % of its {free_m2:.2} m² of free ground",
                i + 1
            ));
        }
        // The rehearsal records them with its areas (the last ones it met).
        if let Some(goals) = self.ws.rehearsal_goals_mut() {
            for (record, (polygon, percent)) in
                goals.areas.iter_mut().rev().zip(percents.into_iter().rev())
            {
                if &record.polygon == polygon {
                    record.swept_percent = Some(percent);
                }
            }
        }
        for line in lines {
            self.event("info", line);
        }
    }

    /// The heavy detail of robot `id` (for a page that focuses it).
    pub fn robot_detail(&self, id: &str) -> Option<Arc<str>> {
        let slot = self.robot(id).ok()?;
        Some(slot.lock().detail().to_string().into())
    }

    /// The revisions of robot `id`'s detail.
    pub fn robot_revs(&self, id: &str) -> Option<(u64, u64)> {
        let slot = self.robot(id).ok()?;
        let s = slot.lock();
        Some((s.mission_rev(), s.series_rev()))
    }

    /// Writes every robot's report (the console is closing).
    pub fn finish_all(&mut self) {
        for r in &self.robots {
            r.lock().finish();
        }
    }

    /// The picture now.
    pub fn frame(&mut self, now_ns: u64) -> Frame {
        let ws = &self.ws;
        let pose = ws.pose();
        let bumps: Vec<[f64; 2]> = ws.bumps().rev().take(20).map(|b| [b.x_m, b.y_m]).collect();
        let verdict = self.verification.as_ref().map(|(v, _)| {
            json!({
                "passed": v.passed,
                "reasons": v.verdict.reasons,
                "max_deviation_tolerance_m": v.verdict.max_deviation_m,
                "open_loop": { "collisions": v.open_loop.collisions, "bumps": v.open_loop.bumps, "max_deviation_m": v.open_loop.max_deviation_m },
                "closed_loop": { "collisions": v.closed_loop.collisions, "bumps": v.closed_loop.bumps, "max_deviation_m": v.closed_loop.max_deviation_m },
            })
        });
        let robots: Vec<Value> = self.robots.iter().map(|r| r.lock().view(now_ns)).collect();
        let state = json!({
            "type": "state",
            "instance": self.settings.instance,
            "t_s": now_ns as f64 * 1e-9,
            "twin": {
                "t_s": ws.t_s(),
                "pose": [pose.x_m, pose.y_m, pose.heading_rad],
                "beams": ws.beams(),
                "bump": ws.bumped(),
                "bumps": bumps,
                "drive": ws.drive_name(),
                "speed": ws.speed(),
                "recording_s": ws.recording_s(),
                "rehearsal_rev": ws.rehearsal_rev(),
                "has_rehearsal": ws.rehearsal().is_some(),
            },
            "job": self.job,
            "plan_rev": self.plan_rev,
            "plan": self.plan.as_ref().map(|p| json!({
                "sha256": p.plan.sha256,
                "summary": p.view["summary"],
                "duration_s": p.plan.duration_s(),
            })),
            "verify_rev": self.verify_rev,
            "route": self.route,
            "refusals": self.refusals,
            "verdict": verdict,
            "redundancy": self.redundancy,
            "freedom": self.freedom,
            "can_sign": self.settings.key.is_some(),
            "params": {
                "left_diameter_m": self.settings.params.left_diameter_m,
                "right_diameter_m": self.settings.params.right_diameter_m,
                "wheelbase_m": self.settings.params.wheelbase_m,
                "calibrated": self.settings.calibrated,
            },
            "robots": robots,
            "events": self.events,
        });
        if let Some(p) = &self.plan
            && self
                .plan_cache
                .as_ref()
                .is_none_or(|c| c.0 != self.plan_rev)
        {
            let mut v = p.view.clone();
            v["type"] = json!("plan");
            v["rev"] = json!(self.plan_rev);
            self.plan_cache = Some((self.plan_rev, v.to_string().into()));
        }
        if self.plan.is_none() {
            self.plan_cache = None;
        }
        match &self.verification {
            Some((_, view))
                if self
                    .verify_cache
                    .as_ref()
                    .is_none_or(|c| c.0 != self.verify_rev) =>
            {
                let mut v = view.clone();
                v["type"] = json!("verify");
                v["rev"] = json!(self.verify_rev);
                self.verify_cache = Some((self.verify_rev, v.to_string().into()));
            }
            None => self.verify_cache = None,
            _ => {}
        }
        let rev = self.ws.rehearsal_rev();
        if let Some(log) = self.ws.rehearsal()
            && self.rehearsal_cache.as_ref().is_none_or(|c| c.0 != rev)
        {
            let every = (log.steps.len() / 50_000).max(1);
            let track = planning::columns(
                log.steps
                    .iter()
                    .step_by(every)
                    .map(|s| (s.t_ns as f64 * 1e-9, s.ground_truth.x_m, s.ground_truth.y_m)),
            );
            let v = json!({ "type": "rehearsal", "rev": rev, "track": track });
            self.rehearsal_cache = Some((rev, v.to_string().into()));
        }
        Frame {
            state: state.to_string().into(),
            world: self.world.clone(),
            plan: self.plan_cache.clone(),
            verify: self.verify_cache.clone(),
            rehearsal: self.rehearsal_cache.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::parse;

    fn core(key: bool) -> Core {
        core_with(key, true)
    }

    /// A console on the case study's twin; `calibrated`: started with a
    /// calibration (the twin's nominal parameters stand in for it).
    fn core_with(key: bool, calibrated: bool) -> Core {
        let scenario = twindrive_sim::builtin::load("wall_following")
            .unwrap()
            .unwrap();
        let out =
            std::env::temp_dir().join(format!("twindrive-console-core-{}", std::process::id()));
        let params = scenario.robot.nominal_params;
        Core::new(
            Workspace::new(crate::twin_model(scenario, calibrated.then_some(params))),
            Vec::new(),
            Settings {
                key: key.then(|| twindrive_store::generate_key().unwrap()),
                params,
                calibrated,
                world_sha256: "00".repeat(32),
                unix_at_zero_s: 1.8e9,
                supervision: Supervision {
                    dead_man_timeout_s: None,
                },
                expires_in_s: 60,
                out,
                instance: "test".into(),
            },
        )
    }

    fn apply(c: &mut Core, text: &str, now_ns: u64) -> Result<Applied, String> {
        c.apply(parse(text)?, now_ns)
    }

    fn state(c: &mut Core, now_ns: u64) -> Value {
        serde_json::from_str(&c.frame(now_ns).state).unwrap()
    }

    #[test]
    fn commands_out_of_order_are_refused_with_a_reason() {
        let mut c = core(false);
        let e = |r: Result<Applied, String>| r.err().expect("refused");
        assert!(e(apply(&mut c, r#"{"cmd":"plan"}"#, 0)).contains("record a rehearsal first"));
        assert!(e(apply(&mut c, r#"{"cmd":"verify"}"#, 0)).contains("make a plan first"));
        assert!(e(apply(&mut c, r#"{"cmd":"record_stop"}"#, 0)).contains("not recording"));
        assert!(e(apply(&mut c, r#"{"cmd":"upload","robot":"r1"}"#, 0)).contains("no signing key"));
        assert!(e(apply(&mut c, r#"{"cmd":"replan","robot":"r1"}"#, 0)).contains("no robot `r1`"));
        assert!(e(apply(&mut c, r#"{"cmd":"focus","robot":"r9"}"#, 0)).contains("no robot"));
        assert!(e(apply(&mut c, r#"{"cmd":"speed","factor":-1}"#, 0)).contains("speed: a factor"));
        let mut k = core(true);
        assert!(e(apply(&mut k, r#"{"cmd":"upload","robot":"r1"}"#, 0)).contains("make a plan"));
        // Refusals change nothing.
        let s = state(&mut c, 0);
        assert_eq!(s["twin"]["drive"], "idle");
        assert_eq!(s["plan"], Value::Null);
    }

    #[test]
    fn a_recorded_drive_is_planned_verified_and_published() {
        let mut c = core(true);
        let s = 1_000_000_000u64;
        for cmd in [
            r#"{"cmd":"wall_follow"}"#,
            r#"{"cmd":"speed","factor":32}"#,
            r#"{"cmd":"record_start"}"#,
        ] {
            assert!(apply(&mut c, cmd, 0).is_ok());
        }
        c.tick(s);
        let st = state(&mut c, s);
        assert!(st["twin"]["recording_s"].as_f64().unwrap() > 30.0, "{st}");
        assert!(apply(&mut c, r#"{"cmd":"record_stop"}"#, s).is_ok());
        let Ok(Applied::Job(job)) = apply(
            &mut c,
            r#"{"cmd":"plan","redundancy":{"pinch_distance_m":0.15,"keep_end":true}}"#,
            s,
        ) else {
            panic!("a planning job")
        };
        // One job at a time.
        assert!(apply(&mut c, r#"{"cmd":"verify"}"#, s).is_err());
        assert_eq!(state(&mut c, s)["job"], "planning");
        let line = c.finish(job.run()).unwrap();
        assert!(line.contains("covered"), "{line}");
        let frame = c.frame(s);
        let plan: Value = serde_json::from_str(&frame.plan.unwrap().1).unwrap();
        assert_eq!(plan["type"], "plan");
        assert_eq!(plan["settings"]["keep_end"], true);
        let Ok(Applied::Job(job)) = apply(&mut c, r#"{"cmd":"verify"}"#, s) else {
            panic!("a verification job")
        };
        let line = c.finish(job.run()).unwrap();
        assert!(line.contains("passed"), "{line}");
        let st = state(&mut c, s);
        assert_eq!(st["verdict"]["passed"], true);
        assert!(
            st["events"].as_array().unwrap().is_empty(),
            "events are the server's to add"
        );
        assert!(c.frame(s).verify.is_some());
        assert!(c.frame(s).rehearsal.is_some());
    }

    /// Records a 32x wall-following rehearsal of `secs` console seconds.
    fn rehearse(c: &mut Core, secs: u64) -> u64 {
        let s = secs * 1_000_000_000;
        for cmd in [
            r#"{"cmd":"wall_follow"}"#,
            r#"{"cmd":"speed","factor":32}"#,
            r#"{"cmd":"record_start"}"#,
        ] {
            assert!(apply(c, cmd, 0).is_ok());
        }
        c.tick(s);
        assert!(apply(c, r#"{"cmd":"record_stop"}"#, s).is_ok());
        s
    }

    /// Goals clicked on the page: an unreachable one says why (and the
    /// state carries it for the map); reachable ones give the way, and
    /// driven, the twin follows it and the drive becomes the rehearsal,
    /// ending at the last waypoint, which the pipeline plans from.
    #[test]
    fn goals_give_a_way_and_a_rehearsal_and_an_unreachable_one_says_why() {
        let mut c = core(true);
        let e = apply(
            &mut c,
            r#"{"cmd":"goals","goals":{"waypoints":[{"x_m":4.5,"y_m":1.5}]}}"#,
            0,
        )
        .err()
        .unwrap();
        assert!(e.contains("waypoint 1 at (4.50, 1.50)"), "{e}");
        let st = state(&mut c, 0);
        assert_eq!(st["route"]["unreachable"]["why"], "too_close", "{st}");
        // A keep-out zone drawn on the page over the goal: refused by it.
        let e = apply(
            &mut c,
            r#"{"cmd":"goals","keep_out":[{"name":"pond","polygon":[[1.2,0.7],[1.8,0.7],[1.8,1.3],[1.2,1.3]]}],
                "goals":{"waypoints":[{"x_m":1.5,"y_m":1.0}]}}"#,
            0,
        )
        .err()
        .unwrap();
        assert!(e.contains("waypoint 1 at (1.50, 1.00)"), "{e}");
        assert!(apply(&mut c, r#"{"cmd":"speed","factor":64}"#, 0).is_ok());
        let goals = r#"{"cmd":"goals","drive":true,"goals":{"speed_m_s":0.25,"waypoints":[{"x_m":1.5,"y_m":1.0},{"x_m":1.1,"y_m":2.2,"heading_rad":1.57}]}}"#;
        let Ok(Applied::Done(Some(line))) = apply(&mut c, goals, 0) else {
            panic!("a way")
        };
        assert!(line.contains("driving it"), "{line}");
        let st = state(&mut c, 0);
        assert_eq!(st["twin"]["drive"], "route");
        assert!(st["route"]["length_m"].as_f64().unwrap() > 2.5, "{st}");
        assert!(st["twin"]["recording_s"].is_number());
        let mut t = 0;
        while c.ws.rehearsal().is_none() {
            t += 100_000_000;
            assert!(t < 10_000_000_000, "the twin did not get there");
            c.tick(t);
        }
        let st = state(&mut c, t);
        assert_eq!(st["twin"]["drive"], "idle");
        assert!(st["twin"]["bumps"].as_array().unwrap().is_empty(), "{st}");
        let end = c.ws.pose();
        assert!((end.x_m - 1.1).hypot(end.y_m - 2.2) < 0.03, "{end:?}");
        let Ok(Applied::Job(job)) = apply(&mut c, r#"{"cmd":"plan"}"#, t) else {
            panic!("a planning job")
        };
        let line = c.finish(job.run()).unwrap();
        assert!(line.contains("verification passed"), "{line}");
    }

    /// An area drawn on the page is swept: the way's stops are its lanes
    /// and touch-ups, and the drive becomes the rehearsal.
    #[test]
    fn an_area_is_swept_into_a_rehearsal() {
        let mut c = core(true);
        assert!(apply(&mut c, r#"{"cmd":"speed","factor":64}"#, 0).is_ok());
        let goals = r#"{"cmd":"goals","drive":true,"goals":{"clearance_m":0.02,"speed_m_s":0.3,"areas":[{"polygon":[[0.3,2.0],[1.3,2.0],[1.3,3.0],[0.3,3.0]]}]}}"#;
        assert!(apply(&mut c, goals, 0).is_ok());
        let st = state(&mut c, 0);
        let area = &st["route"]["areas"][0];
        assert!(area["lanes"].as_u64().unwrap() >= 3, "{area}");
        assert!(area["planned_percent"].as_f64().unwrap() >= 95.0, "{area}");
        let mut t = 0;
        while c.ws.rehearsal().is_none() {
            t += 100_000_000;
            assert!(t < 20_000_000_000, "the twin did not finish the sweep");
            c.tick(t);
        }
        c.tick(t);
        let st = state(&mut c, t);
        assert!(st["twin"]["bumps"].as_array().unwrap().is_empty());
        let swept = st["route"]["areas"][0]["swept_percent"].as_f64().unwrap();
        assert!(swept >= 95.0, "{swept}");
        assert!(
            st["events"].to_string().contains("twin: area 1 swept"),
            "{}",
            st["events"]
        );
    }

    /// A refused goal says why in the operator's words (the waypoint, the
    /// zone by its name), and the state keeps it beside the goals' buttons
    /// until a goals command succeeds; Clear forgets the way and the
    /// refusal, so a page opened later shows neither; the way shown keeps
    /// the goals as given, for a page opened later to take up.
    #[test]
    fn goals_refusals_are_in_words_and_clear_forgets_the_way() {
        let mut c = core(true);
        let e = apply(
            &mut c,
            r#"{"cmd":"goals","goals":{"waypoints":[{"x_m":1.5,"y_m":1.0},{"x_m":1.1,"y_m":2.2,"speed_m_s":-1}]}}"#,
            0,
        )
        .err()
        .unwrap();
        assert!(
            e.contains("the speed of waypoint 2: expected a number > 0"),
            "{e}"
        );
        let st = state(&mut c, 0);
        assert_eq!(st["refusals"]["goals"], e.as_str());
        assert_eq!(st["route"], Value::Null, "no way for refused goals");
        let e = apply(
            &mut c,
            r#"{"cmd":"goals","keep_out":[{"name":"flowers","polygon":[[0,0],[1,1],[1,0],[0,1]]}],
                "goals":{"waypoints":[{"x_m":1.5,"y_m":1.0}]}}"#,
            0,
        )
        .err()
        .unwrap();
        assert!(
            e.contains("the outline of the keep-out zone 'flowers': its sides 1 and 3 cross"),
            "{e}"
        );
        assert!(!e.contains("keep_out["), "{e}");
        // A way: the refusal is gone, the goals are kept with the way.
        let goals =
            r#"{"cmd":"goals","goals":{"return_home":true,"waypoints":[{"x_m":1.5,"y_m":1.0}]}}"#;
        assert!(apply(&mut c, goals, 0).is_ok());
        let st = state(&mut c, 0);
        assert_eq!(st["refusals"]["goals"], Value::Null, "{st}");
        assert!(st["route"]["length_m"].as_f64().unwrap() > 0.0, "{st}");
        assert_eq!(st["route"]["goals"]["return_home"], true);
        assert_eq!(st["route"]["goals"]["waypoints"][0]["x_m"], 1.5);
        // Home is a stop of the way too.
        assert_eq!(st["route"]["waypoints"].as_array().unwrap().len(), 2);
        // Unreachable: the way's refusal (the cell that blocks it) and the
        // refusal beside the buttons, until Clear.
        assert!(
            apply(
                &mut c,
                r#"{"cmd":"goals","goals":{"waypoints":[{"x_m":4.5,"y_m":1.5}]}}"#,
                0
            )
            .is_err()
        );
        let st = state(&mut c, 0);
        assert_eq!(st["route"]["unreachable"]["why"], "too_close", "{st}");
        assert!(st["refusals"]["goals"].is_string(), "{st}");
        assert!(apply(&mut c, r#"{"cmd":"goals_clear"}"#, 0).is_ok());
        let st = state(&mut c, 0);
        assert_eq!(st["route"], Value::Null, "{st}");
        assert_eq!(st["refusals"]["goals"], Value::Null, "{st}");
        // Other parts of the page keep their own.
        let e = apply(
            &mut c,
            r#"{"cmd":"place","x_m":0.05,"y_m":0.05,"heading_rad":0}"#,
            0,
        )
        .err()
        .unwrap();
        assert_eq!(state(&mut c, 0)["refusals"]["twin"], e.as_str());
    }

    #[test]
    fn without_a_robot_model_the_console_refuses_to_plan() {
        let mut c = core_with(true, false);
        let s = rehearse(&mut c, 1);
        let e = apply(&mut c, r#"{"cmd":"plan"}"#, s)
            .err()
            .expect("refused");
        assert!(e.contains("--calibration"), "{e}");
        assert_eq!(state(&mut c, s)["job"], Value::Null);
    }

    #[test]
    fn the_robots_freedom_goes_with_the_plan_and_a_zone_on_its_path_fails_it() {
        let mut c = core(true);
        let s = rehearse(&mut c, 1);
        // A corridor narrower than the robot is refused at once, naming it.
        let e = apply(
            &mut c,
            r#"{"cmd":"plan","freedom":{"corridor":[{"region":[[0,0],[1,0],[1,1]],"half_width_m":0.01}]}}"#,
            s,
        )
        .err()
        .unwrap();
        assert!(e.contains("the half width of corridor region 1"), "{e}");
        let st = state(&mut c, s);
        assert_eq!(st["job"], Value::Null);
        // Beside the freedom panel, not the plan button.
        assert_eq!(st["refusals"]["freedom"], e.as_str(), "{st}");
        assert_eq!(st["refusals"]["plan"], Value::Null, "{st}");
        // A zone over where the robot starts: no plan is made, and the
        // refusal beside the plan button names the zone and where the way
        // enters it.
        let Ok(Applied::Job(job)) = apply(
            &mut c,
            r#"{"cmd":"plan","freedom":{"keep_out":[{"name":"pond","polygon":[[2.5,0.8],[3.5,0.8],[3.5,1.3],[2.5,1.3]]}]}}"#,
            s,
        ) else {
            panic!("a planning job")
        };
        let e = c.finish(job.run()).unwrap_err();
        assert!(
            e.contains("keep-out zone `pond` at 0.00 s (3.00, 1.05)"),
            "{e}"
        );
        let st = state(&mut c, s);
        assert_eq!(st["freedom"]["keep_out"][0]["name"], "pond");
        assert_eq!(st["refusals"]["plan"], e.as_str(), "{st}");
        assert!(c.frame(s).plan.is_none());
        // Away from the way, the zone goes with the plan, signed with it.
        let Ok(Applied::Job(job)) = apply(
            &mut c,
            r#"{"cmd":"plan","freedom":{"keep_out":[{"name":"pond","polygon":[[5.6,4.6],[5.9,4.6],[5.9,4.9],[5.6,4.9]]}]}}"#,
            s,
        ) else {
            panic!("a planning job")
        };
        c.finish(job.run()).unwrap();
        let frame = c.frame(s);
        let plan: Value = serde_json::from_str(&frame.plan.unwrap().1).unwrap();
        assert_eq!(plan["freedom"]["keep_out"][0]["name"], "pond");
    }

    #[test]
    fn a_plan_is_verified_when_made_and_a_failed_one_is_not_uploaded_unless_forced() {
        let mut c = core(true);
        let s = rehearse(&mut c, 1);
        let Ok(Applied::Job(job)) = apply(&mut c, r#"{"cmd":"plan"}"#, s) else {
            panic!("a planning job")
        };
        let line = c.finish(job.run()).unwrap();
        assert!(line.contains("verification passed"), "{line}");
        assert_eq!(state(&mut c, s)["verdict"]["passed"], true);
        // A passed plan gets past the gate (to the missing robot).
        let e = apply(&mut c, r#"{"cmd":"upload","robot":"r1"}"#, s)
            .err()
            .unwrap();
        assert!(e.contains("no robot `r1`"), "{e}");
        // The same plan verified on a twin whose wheels differ by 3 %
        // fails: the upload is refused with the reasons.
        let plan = c.plan.as_ref().unwrap().plan.clone();
        let mut other = c.ws.scenario().clone();
        other.robot.true_params.left_diameter_m *= 1.03;
        c.finish(JobResult::Verify(planning::verify(&plan, &other)))
            .unwrap();
        let st = state(&mut c, s);
        assert_eq!(st["verdict"]["passed"], false);
        assert!(
            !st["verdict"]["reasons"].as_array().unwrap().is_empty(),
            "{st}"
        );
        let e = apply(&mut c, r#"{"cmd":"upload","robot":"r1"}"#, s)
            .err()
            .unwrap();
        assert!(
            e.contains("failed verification") && e.contains("departs"),
            "{e}"
        );
        // Forced: logged as an error event, and on to the (missing) robot.
        let e = apply(&mut c, r#"{"cmd":"upload","robot":"r1","force":true}"#, s)
            .err()
            .unwrap();
        assert!(e.contains("no robot `r1`"), "{e}");
        let st = state(&mut c, s);
        let events = st["events"].as_array().unwrap();
        assert!(
            events
                .iter()
                .any(|e| e["level"] == "error"
                    && e["text"].as_str().unwrap().contains("sent anyway")),
            "{st}"
        );
    }
}
