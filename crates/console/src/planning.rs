//! The pipeline on a rehearsal, and verification on the twin, with what
//! the page draws of each stage. No I/O.

use std::sync::Arc;

use serde::Serialize;
use serde_json::{Value, json};
use twindrive_link::envelope::Tolerances;
use twindrive_log::MissionLog;
use twindrive_mission::freedom::{FreedomSettings, sample_arc_lengths};
use twindrive_mission::path::PathSample;
use twindrive_mission::pipeline::{PipelineSettings, plan_from_log};
use twindrive_mission::plan::{MissionPlan, SiteMapGeometry, sha256_hex};
use twindrive_mission::redundancy::RedundancyConfig;
use twindrive_mission::verify::{Replay, Verdict};
use twindrive_sim::Scenario;

/// A plan made on the console.
pub struct PlanResult {
    pub plan: Arc<MissionPlan>,
    /// The plan document as uploaded (its bytes are what gets signed).
    pub plan_json: Vec<u8>,
    /// The rehearsal as MCAP (the plan names its SHA-256).
    pub rehearsal_mcap: Vec<u8>,
    /// What the page draws: every stage (JSON).
    pub view: Value,
}

/// Rounds to 0.1 mm (or 0.1 ms): the page draws, it does not compute.
fn r4(v: f64) -> f64 {
    (v * 1e4).round() * 1e-4
}

/// A path as three columns (`t`, `x`, `y`), compact in JSON.
pub fn columns(points: impl Iterator<Item = (f64, f64, f64)>) -> Value {
    let (mut t, mut x, mut y) = (Vec::new(), Vec::new(), Vec::new());
    for (a, b, c) in points {
        t.push(r4(a));
        x.push(r4(b));
        y.push(r4(c));
    }
    json!({ "t": t, "x": x, "y": y })
}

fn path_columns(path: &[PathSample]) -> Value {
    columns(path.iter().map(|p| (p.t_s, p.pose.x_m, p.pose.y_m)))
}

/// The rehearsal as MCAP bytes with the twin's world on `/map` (the same
/// log gives the same bytes).
pub fn mcap_bytes(log: &MissionLog, scenario: &Scenario) -> Result<Vec<u8>, String> {
    let mut cursor = std::io::Cursor::new(Vec::new());
    let map = scenario.world.log_map();
    twindrive_log::write_mcap_with_map(log, Some(&map), &mut cursor)
        .map_err(|e| format!("writing the MCAP: {e}"))?;
    Ok(cursor.into_inner())
}

/// What the page draws of a plan's freedom: the corridor's half width at
/// each sample (m; `null` without a corridor), the band the page fills
/// (its spokes in order round it, `[from_x, from_y, to_x, to_y, …]`: the
/// corridor clipped to what the path sees on the plan's own map, see
/// [`crate::corridor`]), the keep-out zones and the detour bounds, as
/// signed in the plan.
pub fn freedom_view(plan: &MissionPlan) -> Value {
    let f = &plan.header.freedom;
    let corridor = (!f.corridor.is_empty()).then(|| {
        sample_arc_lengths(&plan.samples)
            .iter()
            .map(|&s| f.half_width_at(s).unwrap_or(0.0))
            .collect::<Vec<_>>()
    });
    let band = corridor.as_ref().map(|widths| {
        let path: Vec<[f64; 2]> = plan.samples.iter().map(|s| [s.x_m, s.y_m]).collect();
        crate::corridor::band(&path, widths, &plan.header.site_map.world())
            .into_iter()
            .flat_map(|(a, b)| [r4(a[0]), r4(a[1]), r4(b[0]), r4(b[1])])
            .collect::<Vec<_>>()
    });
    let corridor = corridor.map(|w| w.into_iter().map(r4).collect::<Vec<_>>());
    json!({
        "corridor_half_width_m": corridor,
        "corridor_band": band,
        "stretches": f.corridor.len(),
        "keep_out": f.keep_out,
        "max_extra_time_s": f.max_extra_time_s,
        "max_extra_distance_m": f.max_extra_distance_m,
    })
}

/// The redundancy settings the console starts with: pinch at the robot's
/// footprint, as `twindrive plan` does.
pub fn default_redundancy(scenario: &Scenario) -> RedundancyConfig {
    RedundancyConfig::with_pinch_distance(scenario.robot.footprint_radius_m)
}

/// Runs the pipeline on the rehearsal `log` made in `scenario`, with the
/// robot's calibrated `params` (the operator's knowledge of the real robot;
/// `twindrive calibrate` gives them).
pub fn make_plan(
    log: &MissionLog,
    scenario: &Scenario,
    params: &twindrive_kinematics::DiffDriveParams,
    redundancy: RedundancyConfig,
    freedom: FreedomSettings,
) -> Result<PlanResult, String> {
    let rehearsal_mcap = mcap_bytes(log, scenario)?;
    let settings = PipelineSettings {
        planner: Default::default(),
        redundancy,
        filter: Default::default(),
        freedom,
    };
    let (plan, stages) = plan_from_log(
        log,
        &sha256_hex(&rehearsal_mcap),
        params,
        scenario,
        &settings,
        false,
    )
    .map_err(|e| format!("the pipeline: {e}"))?;
    let plan_json =
        serde_json::to_vec_pretty(&plan).map_err(|e| format!("the plan document: {e}"))?;
    let summary = stages.summary();
    let pinches: Vec<[f64; 4]> = stages
        .pruned
        .deletions
        .iter()
        .filter_map(|d| {
            let a = stages.executed.get(d.first_removed.checked_sub(1)?)?;
            let b = stages.executed.get(d.last_removed + 1)?;
            Some([
                r4(a.pose.x_m),
                r4(a.pose.y_m),
                r4(b.pose.x_m),
                r4(b.pose.y_m),
            ])
        })
        .collect();
    let spikes: Vec<[f64; 3]> = stages
        .filtered
        .spikes
        .iter()
        .filter_map(|s| {
            let p = stages.cleaned.get(s.segment)?;
            Some([r4(p.pose.x_m), r4(p.pose.y_m), r4(s.t_s)])
        })
        .collect();
    let view = json!({
        "executed": path_columns(&stages.executed),
        "deletions": stages.pruned.deletions.iter().map(|d| json!({
            "first": d.first_removed, "last": d.last_removed,
            "reason": d.reason, "length_m": r4(d.length_m),
        })).collect::<Vec<_>>(),
        "refused": stages.pruned.refused.iter().map(|c| json!({
            "first": c.i, "last": c.j, "would_drop_m": r4(c.would_drop_m),
        })).collect::<Vec<_>>(),
        "uncovered": summary.coverage.uncovered_stretches.iter().map(|u| json!({
            "first": u.first, "last": u.last, "length_m": r4(u.length_m),
        })).collect::<Vec<_>>(),
        "pinches": pinches,
        "spikes": spikes,
        "plan": columns(plan.samples.iter().map(|s| (s.t_s, s.x_m, s.y_m))),
        "summary": {
            "executed_length_m": r4(summary.executed_length_m),
            "executed_duration_s": r4(summary.executed_duration_s),
            "plan_length_m": r4(summary.filtered_length_m),
            "plan_duration_s": r4(summary.filtered_duration_s),
            "deletions": summary.deletions,
            "loops_removed": summary.loops_removed,
            "kinks_removed": summary.kinks_removed,
            "trailing_retrace_m": r4(summary.trailing_retrace_m),
            "spikes_found": summary.spikes_found,
            "filter_windows": summary.filter_windows,
            "coverage_percent": r4(summary.coverage.covered_percent),
            "coverage_radius_m": r4(summary.coverage.radius_m),
            "uncovered_m": r4(summary.coverage.uncovered_m),
            "refused_cuts": summary.refused_cuts.len(),
            "reversing_m": r4(summary.reversing_m),
        },
        "goals": summary.goals,
        "settings": settings.redundancy,
        "freedom_settings": settings.freedom,
        "freedom": freedom_view(&plan),
        "sha256": plan.sha256,
        "samples": plan.samples.len(),
    });
    Ok(PlanResult {
        plan: Arc::new(plan),
        plan_json,
        rehearsal_mcap,
        view,
    })
}

/// Both replays of a plan on the twin, and the verdict.
#[derive(Debug, Clone, Serialize)]
pub struct Verification {
    pub plan_sha256: String,
    pub open_loop: twindrive_mission::verify::ReplayReport,
    pub closed_loop: twindrive_mission::verify::ReplayReport,
    /// Passed: neither replay touches anything or departs from the plan's
    /// path by more than the robot's deviation tolerance.
    pub passed: bool,
    pub verdict: Verdict,
}

fn track(replay: &Replay) -> Value {
    // A point every 0.1 s at most is plenty to draw.
    let every = (replay.track.len() / 20_000).max(1);
    columns(
        replay
            .track
            .iter()
            .step_by(every)
            .map(|(t, p)| (*t, p.x_m, p.y_m)),
    )
}

/// Replays `plan` open and closed loop on the twin from the plan's start
/// and judges it against the deviation tolerance robots hand back on;
/// returns the verdict and what the page draws.
pub fn verify(plan: &MissionPlan, scenario: &Scenario) -> Result<(Verification, Value), String> {
    let checked = twindrive_mission::verify::verify(
        plan,
        scenario,
        &twindrive_agent::executive::criteria(&Tolerances::default()),
    )
    .map_err(|e| format!("the replays: {e}"))?;
    let verdict = Verification {
        plan_sha256: plan.sha256.clone(),
        open_loop: checked.open_loop.report.clone(),
        closed_loop: checked.closed_loop.report.clone(),
        passed: checked.verdict.passed,
        verdict: checked.verdict,
    };
    let view = json!({
        "verdict": verdict,
        "open_loop": track(&checked.open_loop),
        "closed_loop": track(&checked.closed_loop),
    });
    Ok((verdict, view))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workspace::Workspace;

    #[test]
    fn a_wall_following_rehearsal_becomes_a_verified_plan() {
        let mut scenario = twindrive_sim::builtin::load("wall_following")
            .unwrap()
            .unwrap();
        // One robot model: the twin moves as the plan's parameters say.
        scenario.robot.true_params = scenario.robot.nominal_params;
        let mut w = Workspace::new(scenario.clone());
        w.wall_follow(0);
        w.set_speed(32.0, 0).unwrap();
        w.record_start(0);
        w.advance(1_000_000_000);
        let log = w.record_stop(1_000_000_000).unwrap().clone();
        let result = make_plan(
            &log,
            w.scenario(),
            &scenario.robot.nominal_params,
            default_redundancy(&scenario),
            FreedomSettings::default(),
        )
        .unwrap();
        let plan = &result.plan;
        assert!(plan.samples.len() > 100);
        assert_eq!(plan.header.start, log.header.start);
        let s = &result.view["summary"];
        assert!(s["coverage_percent"].as_f64().unwrap() > 99.0, "{s}");
        assert_eq!(
            result.view["plan"]["x"].as_array().unwrap().len(),
            plan.samples.len()
        );
        // The document hashes to the plan's hash.
        let back: MissionPlan = serde_json::from_slice(&result.plan_json).unwrap();
        assert_eq!(back.sha256, plan.sha256);
        let (verdict, view) = verify(plan, w.scenario()).unwrap();
        assert!(verdict.passed, "{verdict:?}");
        assert!(verdict.verdict.reasons.is_empty());
        // The same plan on a robot whose wheels differ by 3 % departs from
        // its path: it fails, with the numbers.
        let mut other = w.scenario().clone();
        other.robot.true_params.left_diameter_m *= 1.03;
        let (failed, _) = verify(plan, &other).unwrap();
        assert!(!failed.passed, "{failed:?}");
        assert!(
            failed.verdict.reasons.iter().any(|r| r.contains("departs")),
            "{failed:?}"
        );
        assert!(view["closed_loop"]["x"].as_array().unwrap().len() > 10);
        // The corridor is drawn at every sample, no narrower than the
        // robot's body.
        let corridor = result.view["freedom"]["corridor_half_width_m"]
            .as_array()
            .unwrap();
        assert_eq!(corridor.len(), plan.samples.len());
        let footprint = scenario.robot.footprint_radius_m;
        assert!(
            corridor
                .iter()
                .all(|w| w.as_f64().unwrap() >= footprint - 1e-4),
            "{corridor:?}"
        );
        // The operator's zones and corridor regions are the plan's: a
        // region over the whole site sets the corridor everywhere, a zone
        // away from the route is signed with the plan.
        let freedom: FreedomSettings = serde_json::from_value(json!({
            "corridor": [{"region": [[-100, -100], [100, -100], [100, 100], [-100, 100]], "half_width_m": 0.45}],
            "keep_out": [{"name": "far", "polygon": [[500, 500], [501, 500], [501, 501]]}],
            "max_extra_time_s": 12.5,
        }))
        .unwrap();
        let zoned = make_plan(
            &log,
            w.scenario(),
            &scenario.robot.nominal_params,
            default_redundancy(&scenario),
            freedom,
        )
        .unwrap();
        let f = &zoned.view["freedom"];
        assert!(
            f["corridor_half_width_m"]
                .as_array()
                .unwrap()
                .iter()
                .all(|w| w == 0.45),
            "{f}"
        );
        assert_eq!(f["keep_out"][0]["name"], "far");
        assert_eq!(f["max_extra_time_s"], 12.5);
        assert_eq!(zoned.plan.header.freedom.keep_out.len(), 1);
    }
}
