//! Planning from a mission log: a verified-format, hashed mission plan out,
//! with the pipeline's figures and an MCAP of every stage.

use std::io::Write;
use std::path::Path;

use anyhow::{Context, bail};
use twindrive_files::Staging;
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_log::MissionLog;
use twindrive_mission::pipeline::{PipelineSettings, StageSummary, Stages};
use twindrive_mission::plan::{MissionPlan, PlanGeometry, sha256_hex};
use twindrive_mission::{PathSample, pipeline};
use twindrive_sim::Scenario;

use crate::figures;

/// Everything one plan needs, checked.
pub struct Job {
    pub log: MissionLog,
    pub log_sha256: String,
    pub params: DiffDriveParams,
    /// The twin the plan's sensor predictions come from.
    pub scenario: Scenario,
    pub settings: PipelineSettings,
    /// Use the time-optimal re-timing as the plan.
    pub time_optimal: bool,
}

/// SHA-256 of a log directory's two files: each file's name, length and
/// bytes, in order (so no two different pairs hash alike).
pub fn log_dir_sha256(dir: &Path) -> anyhow::Result<String> {
    let mut bytes = Vec::new();
    for name in ["log.meta.json", "log.csv"] {
        let path = dir.join(name);
        let content =
            std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
        bytes.extend_from_slice(name.as_bytes());
        bytes.extend_from_slice(&(content.len() as u64).to_le_bytes());
        bytes.extend(content);
    }
    Ok(sha256_hex(&bytes))
}

/// The scenario named in the log, when it is a built-in one.
pub fn scenario_for(log: &MissionLog, given: Option<&Path>) -> anyhow::Result<Scenario> {
    match given {
        Some(path) => Ok(Scenario::load(path)?),
        None => match twindrive_sim::builtin::load(&log.header.scenario) {
            Some(s) => Ok(s?),
            None => bail!(
                "the log's scenario `{}` is not built in; pass --scenario with its TOML file (the twin predicts the plan's sensor readings)",
                log.header.scenario
            ),
        },
    }
}

/// Runs the pipeline and assembles the plan (with the twin's sensor predictions).
pub fn make_plan(job: &Job) -> anyhow::Result<(MissionPlan, Stages)> {
    pipeline::plan_from_log(
        &job.log,
        &job.log_sha256,
        &job.params,
        &job.scenario,
        &job.settings,
        job.time_optimal,
    )
    .map_err(|e| match (&e, job.time_optimal) {
        (twindrive_mission::PipelineError::Infeasible(m), true)
            if m.starts_with("the time-optimal") =>
        {
            anyhow::anyhow!("--time-optimal: {m}")
        }
        _ => e.into(),
    })
}

fn ns(t_s: f64) -> u64 {
    (t_s * 1e9).round().max(0.0) as u64
}

/// Writes `out` (the plan JSON) and beside it `<stem>.csv`, `<stem>.tum`,
/// `<stem>_stages.mcap` and the figures.
pub fn write_outputs(
    plan: &MissionPlan,
    stages: &Stages,
    scenario: &Scenario,
    out: &Path,
) -> anyhow::Result<()> {
    let (dir, stem, file_name) = twindrive_files::split_out_path(out, "plan")?;
    let staging = Staging::new(&dir, &format!("plan:{stem}"))?;
    staging.write_with(&file_name, |w| {
        serde_json::to_writer_pretty(&mut *w, plan)?;
        writeln!(w)?;
        Ok(())
    })?;
    staging.write_with(&format!("{stem}.csv"), |w| {
        plan.write_csv(w).map_err(Into::into)
    })?;
    staging.write_with(&format!("{stem}.tum"), |w| {
        plan.write_tum(w).map_err(Into::into)
    })?;
    let poses =
        |p: &[PathSample]| -> Vec<(u64, Pose)> { p.iter().map(|s| (ns(s.t_s), s.pose)).collect() };
    let wheels = |p: &[PathSample], c: &[twindrive_mission::control::WheelCommand]| {
        p.iter()
            .zip(c)
            .map(|(s, c)| (ns(s.t_s), c.wheels()))
            .collect::<Vec<_>>()
    };
    let (executed, cleaned, filtered, fastest) = (
        poses(&stages.executed),
        poses(&stages.cleaned),
        poses(&stages.filtered.samples),
        stages
            .fastest
            .as_ref()
            .map_or(Vec::new(), |(p, _)| poses(p)),
    );
    let (cleaned_w, filtered_w, fastest_w) = (
        wheels(&stages.cleaned, &stages.cleaned_commands),
        wheels(&stages.filtered.samples, &stages.filtered.commands),
        stages
            .fastest
            .as_ref()
            .map_or(Vec::new(), |(p, c)| wheels(p, c)),
    );
    staging.write_with(&format!("{stem}_stages.mcap"), |w| {
        twindrive_log::write_tracks_mcap(
            &[
                twindrive_log::Track {
                    topic: "/executed",
                    poses: &executed,
                    wheels: &[],
                },
                twindrive_log::Track {
                    topic: "/cleaned",
                    poses: &cleaned,
                    wheels: &cleaned_w,
                },
                twindrive_log::Track {
                    topic: "/plan",
                    poses: &filtered,
                    wheels: &filtered_w,
                },
                twindrive_log::Track {
                    topic: "/time_optimal",
                    poses: &fastest,
                    wheels: &fastest_w,
                },
            ],
            &[(
                "twindrive.plan_header",
                serde_json::to_string(&plan.header)?,
            )],
            Some(&scenario.world.log_map()),
            w,
        )
        .map_err(Into::into)
    })?;
    figures::plan_figures(
        stages,
        &figures::walls(&scenario.world),
        staging.dir(),
        &stem,
    )?;
    staging.commit()
}

/// The pipeline's summary as a few lines for a terminal.
pub fn print_summary(
    s: &StageSummary,
    plan: &MissionPlan,
    out: &Path,
    o: &mut impl Write,
) -> std::io::Result<()> {
    writeln!(
        o,
        "executed path {:.2} m in {:.1} s; removed {} loop(s), {} bump-and-back-up kink(s) and {:.2} m of trailing retrace -> {:.2} m",
        s.executed_length_m,
        s.executed_duration_s,
        s.loops_removed,
        s.kinks_removed,
        s.trailing_retrace_m,
        s.cleaned_length_m
    )?;
    for r in &s.refused_cuts {
        writeln!(
            o,
            "kept: a {:?} cut from t = {:.2} s to {:.2} s ({:.2} m) would have dropped {:.2} m of explored ground",
            r.reason, r.t_start_s, r.t_end_s, r.length_m, r.would_drop_m
        )?;
    }
    let fastest = match (&s.time_optimal_duration_s, &s.time_optimal_error) {
        (Some(t), _) => format!("time-optimal re-timing {t:.1} s"),
        (None, Some(e)) => format!("no time-optimal re-timing: {e}"),
        (None, None) => "no time-optimal re-timing".into(),
    };
    writeln!(
        o,
        "{} control spike(s) filtered in {} window(s): plan {:.2} m in {:.1} s ({fastest})",
        s.spikes_found, s.filter_windows, s.filtered_length_m, s.filtered_duration_s
    )?;
    let c = &s.coverage;
    writeln!(
        o,
        "coverage: the plan passes within {} m of {:.2} % of the executed route ({:.2} m uncovered); plan {:.2} m of {:.2} m executed, {:.3} m driven backwards",
        c.radius_m,
        c.covered_percent,
        c.uncovered_m,
        c.plan_length_m,
        c.route_length_m,
        s.reversing_m
    )?;
    for w in &s.goals.waypoints {
        let heading = w.heading_error_rad.map_or(String::new(), |e| {
            format!(", facing its heading within {e:.3} rad")
        });
        let dwell = if w.dwell_s > 0.0 {
            format!(", standing {:.1} s of {:.1} s", w.stood_s, w.dwell_s)
        } else {
            String::new()
        };
        writeln!(
            o,
            "goal kept: {} within {:.3} m at {:.1} s{heading}{dwell}",
            w.name, w.passed_m, w.at_t_s
        )?;
    }
    for a in &s.goals.areas {
        let rehearsed = a
            .rehearsed_percent
            .map_or(String::new(), |r| format!(" (the rehearsal {r:.1} %)"));
        writeln!(
            o,
            "goal kept: {} swept {:.1} % of its free ground{rehearsed}",
            a.name, a.swept_percent
        )?;
    }
    let f = &plan.header.freedom;
    let widths = f
        .corridor
        .iter()
        .map(|c| c.half_width_m)
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), w| {
            (lo.min(w), hi.max(w))
        });
    let corridor = if f.corridor.is_empty() {
        "no corridor (the robot keeps to its path)".to_string()
    } else {
        format!(
            "corridor of {} stretch(es), half width {:.2} to {:.2} m",
            f.corridor.len(),
            widths.0,
            widths.1
        )
    };
    writeln!(
        o,
        "freedom: {corridor}; {} keep-out zone(s){}; detours may add {:.0} s in all and {:.1} m each",
        f.keep_out.len(),
        if f.keep_out.is_empty() {
            String::new()
        } else {
            format!(
                " ({})",
                f.keep_out
                    .iter()
                    .map(|z| z.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        },
        f.max_extra_time_s,
        f.max_extra_distance_m
    )?;
    writeln!(
        o,
        "plan {} ({} samples, sha256 {}) and its figures beside it",
        out.display(),
        plan.samples.len(),
        &plan.sha256[..16]
    )?;
    Ok(())
}
