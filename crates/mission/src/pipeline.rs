//! The whole chain on one mission log: planner → redundancy removal →
//! re-compute control → filter control signals (and the time-optimal
//! alternative). Each stage's output is kept for figures and reports.

use serde::{Deserialize, Serialize};
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_log::MissionLog;

use crate::control::{WheelCommand, recompute};
use crate::error::PipelineError;
use crate::freedom::FreedomSettings;
use crate::kept::GoalsKept;
use crate::path::{PathSample, path_length_m};
use crate::plan::{SiteMap, SiteMapGeometry};
use crate::planner::{PlannerSettings, executed_path};
use crate::redundancy::{
    Deletion, DeletionReason, Pruned, RedundancyConfig, RefusedCut, RouteCoverage, TimeWindow,
    remove_redundancy, route_coverage,
};
use crate::retime::WheelLimits;
use crate::spikes::{FilterSettings, Filtered, filter_spikes_keeping, time_optimal_keeping};

/// Every setting of the pipeline (the plan records them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PipelineSettings {
    #[serde(default)]
    pub planner: PlannerSettings,
    pub redundancy: RedundancyConfig,
    #[serde(default)]
    pub filter: FilterSettings,
    /// The robot's corridor, keep-out zones and detour bounds.
    #[serde(default)]
    pub freedom: FreedomSettings,
}

/// Each stage's output.
#[derive(Debug, Clone)]
pub struct Stages {
    /// The executed path from the encoders (mission planner).
    pub executed: Vec<PathSample>,
    pub pruned: Pruned,
    /// The path without its redundant parts; every junction is driven in
    /// one control period, as the deletion leaves it.
    pub cleaned: Vec<PathSample>,
    pub cleaned_commands: Vec<WheelCommand>,
    /// The plan: spikes filtered (Fig. 8b); its `spikes` are those of the
    /// cleaned path (Fig. 8a).
    pub filtered: Filtered,
    /// The same path as fast as the limits allow, or why not.
    pub fastest: Result<(Vec<PathSample>, Vec<WheelCommand>), PipelineError>,
    /// The control period of the source (mean encoder period).
    pub period_s: f64,
    /// How much of the executed route the plan passes within the coverage
    /// radius.
    pub coverage: RouteCoverage,
    /// The operator's goals the rehearsal met (empty for a manual one),
    /// and how the plan keeps them.
    pub goals: twindrive_plan::PlanGoals,
    pub kept: GoalsKept,
}

/// Numbers for people.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageSummary {
    pub executed_length_m: f64,
    pub executed_duration_s: f64,
    pub deletions: usize,
    /// Loops and self-crossings cut.
    pub loops_removed: usize,
    pub kinks_removed: usize,
    /// Length of the trailing retrace cut from the end (0 if none).
    pub trailing_retrace_m: f64,
    /// The path with its redundant parts removed (jumps included).
    pub cleaned_length_m: f64,
    pub spikes_found: usize,
    /// The plan's own path and duration.
    pub filtered_length_m: f64,
    pub filtered_duration_s: f64,
    /// How far the plan drives backwards in all.
    pub reversing_m: f64,
    pub filter_windows: usize,
    /// The longest the plan holds one wheel command (s).
    pub longest_hold_s: f64,
    /// `None` when the time-optimal re-timing failed (`time_optimal_error`).
    pub time_optimal_duration_s: Option<f64>,
    pub time_optimal_error: Option<String>,
    /// The executed route's coverage by the plan: radius, lengths, percent
    /// within the radius, uncovered metres and stretches.
    pub coverage: RouteCoverage,
    /// Every deletion: time span and length on the executed path, why, and
    /// the coverage it lost (zero).
    pub deletion_list: Vec<Deletion>,
    /// Cuts refused because they would have dropped explored ground.
    pub refused_cuts: Vec<RefusedCut>,
    /// How the plan keeps each of the operator's goals (a rehearsal from
    /// goals).
    #[serde(skip_serializing_if = "GoalsKept::is_empty")]
    pub goals: GoalsKept,
}

impl Stages {
    pub fn summary(&self) -> StageSummary {
        let duration = |p: &[PathSample]| match (p.first(), p.last()) {
            (Some(a), Some(b)) => b.t_s - a.t_s,
            _ => 0.0,
        };
        let deletions = &self.pruned.deletions;
        let count =
            |r: &[DeletionReason]| deletions.iter().filter(|d| r.contains(&d.reason)).count();
        StageSummary {
            executed_length_m: path_length_m(&self.executed),
            executed_duration_s: duration(&self.executed),
            deletions: deletions.len(),
            loops_removed: count(&[DeletionReason::Loop, DeletionReason::Crossing]),
            kinks_removed: count(&[DeletionReason::Reversal]),
            trailing_retrace_m: deletions
                .iter()
                .filter(|d| d.reason == DeletionReason::TrailingRetrace)
                .fold(0.0, |a, d| a + d.length_m),
            cleaned_length_m: path_length_m(&self.cleaned),
            spikes_found: self.filtered.spikes.len(),
            filtered_length_m: path_length_m(&self.filtered.samples),
            filtered_duration_s: duration(&self.filtered.samples),
            reversing_m: reversing_m(&self.filtered.samples),
            filter_windows: self.filtered.windows.len(),
            longest_hold_s: crate::spikes::longest_hold_s(&self.filtered.samples),
            time_optimal_duration_s: self.fastest.as_ref().ok().map(|(p, _)| duration(p)),
            time_optimal_error: self.fastest.as_ref().err().map(|e| e.to_string()),
            coverage: self.coverage.clone(),
            deletion_list: deletions.clone(),
            refused_cuts: self.pruned.refused.clone(),
            goals: self.kept.clone(),
        }
    }
}

/// Length of the path driven backwards: segments whose displacement points
/// against the heading at their start.
pub fn reversing_m(path: &[PathSample]) -> f64 {
    path.windows(2)
        .map(|w| {
            let (dx, dy) = (w[1].pose.x_m - w[0].pose.x_m, w[1].pose.y_m - w[0].pose.y_m);
            let (s, c) = w[0].pose.heading_rad.sin_cos();
            if dx * c + dy * s < 0.0 {
                dx.hypot(dy)
            } else {
                0.0
            }
        })
        .fold(0.0, |a, d| a + d)
}

/// Re-times kept samples: each kept stretch keeps its durations, and each
/// junction a deletion left is given one control period.
fn close_gaps(path: &[PathSample], kept: &[usize], period_s: f64) -> Vec<PathSample> {
    let mut out: Vec<PathSample> = Vec::with_capacity(kept.len());
    for (n, &k) in kept.iter().enumerate() {
        let t = match n.checked_sub(1) {
            None => path[k].t_s,
            Some(m) => {
                let previous = kept[m];
                let step = if k == previous + 1 {
                    path[k].t_s - path[previous].t_s
                } else {
                    period_s
                };
                out[m].t_s + step
            }
        };
        out.push(PathSample { t_s: t, ..path[k] });
    }
    out
}

/// Runs the pipeline on `log` with the calibrated `params`.
pub fn run(
    log: &MissionLog,
    params: &DiffDriveParams,
    limits: &WheelLimits,
    settings: &PipelineSettings,
) -> Result<Stages, PipelineError> {
    limits.validate()?;
    let executed = executed_path(log, params, &settings.planner)?;
    let period_s = (executed.last().expect("two samples at least").t_s - executed[0].t_s)
        / (executed.len() - 1) as f64;
    // The operator's goals are intent: no cut deletes, and no smoothing or
    // re-timing moves, what the rehearsal drove while meeting one, so every
    // cut lies between goals.
    // (Half a period either side: the log's times and the follower's are
    // the same steps, summed differently.)
    let windows: Vec<(f64, f64)> = log
        .header
        .goals
        .windows_s()
        .into_iter()
        .map(|(a, b)| (a - 0.5 * period_s, b + 0.5 * period_s))
        .collect();
    let mut redundancy = settings.redundancy.clone();
    redundancy.keep_windows.extend(
        windows
            .iter()
            .map(|&(start_s, end_s)| TimeWindow { start_s, end_s }),
    );
    let pruned = remove_redundancy(&executed, &redundancy)?;
    let mut cleaned = close_gaps(&executed, &pruned.kept, period_s);
    let fixed: Vec<bool> = pruned
        .kept
        .iter()
        .map(|&k| {
            let t = executed[k].t_s;
            windows.iter().any(|&(a, b)| (a..=b).contains(&t))
        })
        .collect();
    let cleaned_commands = recompute(&mut cleaned, params);
    let filtered =
        filter_spikes_keeping(&cleaned, &fixed, params, limits, period_s, &settings.filter)?;
    // The alternative must not cost the plan: its failure is reported.
    let fastest =
        time_optimal_keeping(&filtered.samples, &filtered.fixed, params, limits, period_s);
    let coverage = route_coverage(
        &executed,
        &filtered.samples,
        settings.redundancy.effective_coverage_radius_m(),
    )?;
    let goals = plan_goals(
        &log.header.goals,
        executed.last().map_or(0.0, |p| p.t_s),
        period_s,
    );
    let kept = GoalsKept {
        waypoints: goals.check_waypoints(&timed_poses(&filtered.samples)),
        areas: Vec::new(),
    };
    Ok(Stages {
        executed,
        pruned,
        cleaned,
        cleaned_commands,
        filtered,
        fastest,
        period_s,
        coverage,
        goals,
        kept,
    })
}

/// The goals a rehearsal met, as a plan keeps them; the plan ends at the
/// last waypoint when the rehearsal did (its last goal is a waypoint, met
/// at the log's end, `end_t_s`, within two control periods).
pub fn plan_goals(
    met: &twindrive_log::RehearsedGoals,
    end_t_s: f64,
    period_s: f64,
) -> twindrive_plan::PlanGoals {
    use twindrive_plan::{GoalArea, GoalWaypoint, PlanGoals};
    let last_area_s = met
        .areas
        .iter()
        .map(|a| a.end_t_s)
        .fold(f64::NEG_INFINITY, f64::max);
    let ends_at_last_waypoint = met
        .waypoints
        .last()
        .is_some_and(|w| w.left_t_s > last_area_s && w.left_t_s >= end_t_s - 2.0 * period_s);
    PlanGoals {
        waypoints: met
            .waypoints
            .iter()
            .map(|w| GoalWaypoint {
                name: w.name.clone(),
                x_m: w.x_m,
                y_m: w.y_m,
                heading_rad: w.heading_rad,
                dwell_s: w.dwell_s,
            })
            .collect(),
        areas: met
            .areas
            .iter()
            .map(|a| GoalArea {
                name: a.name.clone(),
                polygon: a.polygon.clone(),
                sweep_radius_m: a.sweep_radius_m,
                swept_percent: a.swept_percent,
            })
            .collect(),
        ends_at_last_waypoint,
    }
}

/// Each sample's time and pose.
pub fn timed_poses(path: &[PathSample]) -> Vec<(f64, twindrive_kinematics::Pose)> {
    path.iter().map(|p| (p.t_s, p.pose)).collect()
}

/// A mission log made on the twin, turned into a plan: the pipeline's
/// stages, then the plan's samples with the twin's predicted range readings
/// and bumps along the path (`scenario` is the twin the log was made in).
/// `time_optimal` takes the time-optimal re-timing instead of the mission's
/// pace. The plan is validated before it is returned.
pub fn plan_from_log(
    log: &MissionLog,
    log_sha256: &str,
    params: &DiffDriveParams,
    scenario: &twindrive_sim::Scenario,
    settings: &PipelineSettings,
    time_optimal: bool,
) -> Result<(crate::plan::MissionPlan, Stages), PipelineError> {
    use crate::plan::{PlanHeader, RobotInfo};
    let header = &log.header;
    let limits = WheelLimits {
        max_speed_rad_s: header.max_wheel_speed_rad_s,
        max_accel_rad_s2: header.max_wheel_accel_rad_s2,
    };
    settings
        .freedom
        .validate(header.footprint_radius_m)
        .map_err(|e| PipelineError::Infeasible(format!("the freedom settings: {e}")))?;
    let mut stages = run(log, params, &limits, settings)?;
    let (path, commands) = if time_optimal {
        let (p, c) = stages.fastest.as_ref().map_err(|e| {
            PipelineError::Infeasible(format!("the time-optimal re-timing failed: {e}"))
        })?;
        (p.clone(), c.clone())
    } else {
        (
            stages.filtered.samples.clone(),
            stages.filtered.commands.clone(),
        )
    };
    // The plan keeps the operator's goals, or it is not made.
    stages.kept = crate::kept::goals_kept(
        &stages.goals,
        &timed_poses(&path),
        &scenario.world,
        header.footprint_radius_m,
        &settings.freedom.keep_out,
    );
    let missed = stages.kept.missed();
    if !missed.is_empty() {
        return Err(PipelineError::Infeasible(format!(
            "the plan would not keep the operator's goals: {}",
            missed.join("; ")
        )));
    }
    let summary = serde_json::to_value(stages.summary())
        .map_err(|e| PipelineError::Infeasible(format!("the stage summary: {e}")))?;
    let plan = plan_document(
        &path,
        &commands,
        PlanHeader {
            robot: RobotInfo {
                scenario: header.scenario.clone(),
                footprint_radius_m: header.footprint_radius_m,
                ticks_per_rev: header.ticks_per_rev,
                range_sensors: Vec::new(),
            },
            calibrated: *params,
            limits,
            time_step_s: stages.period_s,
            start: header.start,
            start_covariance: None,
            site_map: SiteMap::default(),
            freedom: settings.freedom.freedom_along(
                &positions(&path),
                &scenario.world,
                header.footprint_radius_m,
            ),
            goals: stages.goals.clone(),
            source_log_sha256: log_sha256.to_owned(),
            settings: serde_json::json!({
                "pipeline": settings,
                "timing": if time_optimal { "time_optimal" } else { "mission_pace" },
            }),
            summary,
        },
        scenario,
    );
    plan.validate()?;
    // The operator's zones are never crossed on purpose: a rehearsal that
    // drove through one cannot become a plan.
    if let Some(entry) = crate::verify::zone_entry(&plan) {
        return Err(PipelineError::Infeasible(format!(
            "{entry}: the rehearsal drove through it; rehearse a way around it (`rehearse --goals ... --freedom` keeps out of the zones) or draw the zone where the rehearsal did not go"
        )));
    }
    Ok((plan, stages))
}

fn positions(path: &[PathSample]) -> Vec<[f64; 2]> {
    path.iter().map(PathSample::position).collect()
}

/// The plan document for a timed path and its commands: the site's map
/// and the robot's range sensors (`scenario`'s) in the header, and whether
/// the twin's bumper touches at each sample.
fn plan_document(
    path: &[PathSample],
    commands: &[WheelCommand],
    mut header: crate::plan::PlanHeader,
    scenario: &twindrive_sim::Scenario,
) -> crate::plan::MissionPlan {
    use crate::plan::{MissionPlan, PlanSample, plan_sample};
    let model = twindrive_sim::SensorModel::new(scenario);
    let samples: Vec<PlanSample> = path
        .iter()
        .zip(commands)
        .map(|(p, c)| plan_sample(p, c, model.bump(&p.pose)))
        .collect();
    header.robot.range_sensors = scenario
        .range_sensors
        .iter()
        .map(|s| s.info.clone())
        .collect();
    header.site_map = SiteMap::of(&scenario.world);
    MissionPlan::new(header, samples)
}

/// A continuation of `interrupted` for a robot that handed back at
/// `plan_t_s`, standing at `scenario`'s start pose in the twin's updated
/// world (`learnt`: the blocks learnt so far): back onto the rest of the
/// plan and around every stretch of it that passes a learnt block
/// ([`crate::detour`]), re-timed as fast as `pace` times the robot's wheel
/// limits allow, for a robot with the parameters `params`. The plan is validated before it is returned; verifying it
/// on the twin is the caller's.
pub fn continuation_plan(
    interrupted: &crate::plan::MissionPlan,
    plan_t_s: f64,
    params: &DiffDriveParams,
    scenario: &twindrive_sim::Scenario,
    learnt: &[crate::detour::Block],
    detour: &crate::detour::DetourSettings,
    pace: f64,
) -> Result<crate::plan::MissionPlan, PipelineError> {
    use crate::plan::PlanHeader;
    let h = &interrupted.header;
    let t0 = interrupted.samples.first().map_or(0.0, |s| s.t_s);
    let remaining: Vec<PathSample> = interrupted
        .samples
        .iter()
        .filter(|s| s.t_s - t0 >= plan_t_s)
        .map(|s| PathSample {
            t_s: s.t_s,
            pose: s.pose(),
            v_m_s: s.v_m_s,
            omega_rad_s: s.omega_rad_s,
        })
        .collect();
    if remaining.is_empty() {
        return Err(PipelineError::Infeasible(format!(
            "the plan ends before {plan_t_s:.2} s: nothing is left to continue"
        )));
    }
    let start = scenario.robot.start;
    // The detours keep out of the operator's zones as out of walls.
    let world = crate::freedom::with_zones_as_walls(&scenario.world, &h.freedom.keep_out);
    let path = crate::detour::continuation_path(
        &world,
        h.robot.footprint_radius_m,
        start,
        &remaining,
        learnt,
        detour,
    )?;
    // The operator's waypoints still ahead stay goals of the continuation
    // (their dwells kept); those met before the hand-back, and the areas,
    // were the interrupted plan's.
    let before: Vec<(f64, Pose)> = interrupted
        .samples
        .iter()
        .map(|s| (s.t_s, s.pose()))
        .collect();
    let met = h.goals.check_waypoints(&before);
    let goals = twindrive_plan::PlanGoals {
        waypoints: h
            .goals
            .waypoints
            .iter()
            .zip(&met)
            .filter(|(_, m)| m.at_t_s >= plan_t_s)
            .map(|(w, _)| w.clone())
            .collect(),
        areas: Vec::new(),
        ends_at_last_waypoint: h.goals.ends_at_last_waypoint,
    };
    let dwell_at = |p: &PathSample| {
        goals.waypoints.iter().any(|w| {
            w.dwell_s > 0.0
                && (p.pose.x_m - w.x_m).hypot(p.pose.y_m - w.y_m) <= crate::kept::GOAL_REACH_M
        })
    };
    let fixed: Vec<bool> = path.iter().map(dwell_at).collect();
    let limits = h.limits.scaled(pace);
    let (path, commands) =
        crate::spikes::time_optimal_keeping(&path, &fixed, params, &limits, h.time_step_s)?;
    // The operator's freedom goes on: their corridor settings (recorded
    // with the interrupted plan, or the defaults) on the new path, their
    // zones and bounds as they were.
    let freedom_settings = FreedomSettings {
        keep_out: h.freedom.keep_out.clone(),
        max_extra_time_s: h.freedom.max_extra_time_s,
        max_extra_distance_m: h.freedom.max_extra_distance_m,
        ..["/pipeline/freedom", "/freedom"]
            .iter()
            .find_map(|at| h.settings.pointer(at))
            .and_then(|v| serde_json::from_value::<FreedomSettings>(v.clone()).ok())
            .unwrap_or_default()
    };
    let length_m = path_length_m(&path);
    let duration_s = path.last().map_or(0.0, |s| s.t_s) - path[0].t_s;
    let plan = plan_document(
        &path,
        &commands,
        PlanHeader {
            robot: h.robot.clone(),
            calibrated: *params,
            limits: h.limits,
            time_step_s: h.time_step_s,
            start,
            start_covariance: None,
            site_map: SiteMap::default(),
            freedom: if h.freedom.corridor.is_empty() {
                // No corridor before, none now: only the zones and bounds.
                twindrive_plan::Freedom {
                    corridor: Vec::new(),
                    ..h.freedom.clone()
                }
            } else {
                freedom_settings.freedom_along(
                    &positions(&path),
                    &scenario.world,
                    h.robot.footprint_radius_m,
                )
            },
            goals,
            source_log_sha256: h.source_log_sha256.clone(),
            settings: serde_json::json!({
                "continuation_of": interrupted.sha256,
                "from_plan_t_s": plan_t_s,
                "clearance_m": detour.clearance_m,
                "pace": pace,
                "timing": "time_optimal",
                "freedom": freedom_settings,
            }),
            summary: serde_json::json!({
                "continuation_of": interrupted.sha256,
                "length_m": length_m,
                "duration_s": duration_s,
                "learnt_blocks": learnt.len(),
            }),
        },
        scenario,
    );
    plan.validate()?;
    Ok(plan)
}
