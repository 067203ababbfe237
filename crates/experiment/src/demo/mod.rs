//! The case study end to end: calibration drive -> calibration -> the
//! paper's Table 1 and Section 6 -> wall-following mission on the twin ->
//! plan -> verification, and `report.md` / `report.html` that tell the story.

use std::io::Write;
use std::path::Path;

use anyhow::Context;
use twindrive_sim::Scenario;

use twindrive_calibrate::{Method, calibration_job};
use twindrive_files::Staging;
use twindrive_kinematics::DiffDriveParams;
use twindrive_mission::pipeline::PipelineSettings;
use twindrive_mission::redundancy::RedundancyConfig;
use twindrive_progress::Stages;
use twindrive_workflow::plan;
use twindrive_workflow::simulate::{print_summary, simulate_into};
use twindrive_workflow::verify::{self as verify_plan, PlanFailed};

use crate::latency;
use crate::rehearsal::{Rehearsal, site_like};

mod case_study;
pub mod decoupled;
pub mod evidence;
pub mod mapped_site;
pub mod report;

use case_study::{CaseStudy, case_study_report};

fn builtin(name: &str) -> anyhow::Result<Scenario> {
    twindrive_sim::builtin::load(name)
        .with_context(|| format!("{name} is not built in"))?
        .with_context(|| format!("the built-in {name} scenario"))
}

/// The demo's stages, for the stage lines' `i/N`.
const STAGES: usize = 15;

/// Runs the case study into `out`, saying what it found on `stdout` and,
/// on stderr, what it is doing (each stage as it starts, and at least
/// every second while it runs).
pub fn run(out: &Path, stdout: &mut impl Write) -> anyhow::Result<()> {
    let mut stages = Stages::new("demo", STAGES);
    let result = run_stages(out, stdout, &mut stages);
    let times = stages.times().to_vec();
    drop(stages);
    for t in &times {
        tracing::info!(
            stage = %t.name,
            wall_s = t.wall_s,
            cpu_s = t.cpu_s,
            "demo stage"
        );
    }
    tracing::info!(
        wall_s = times.iter().map(|t| t.wall_s).sum::<f64>(),
        cpu_s = times.iter().map(|t| t.cpu_s).sum::<Option<f64>>(),
        stages = times.len(),
        "demo"
    );
    result
}

fn run_stages(out: &Path, stdout: &mut impl Write, stages: &mut Stages) -> anyhow::Result<()> {
    // 1. The calibration drive on the twin, and its calibration.
    let cal_scenario = builtin("calibration_drive")?;
    let tracker = cal_scenario
        .tracker
        .clone()
        .context("the calibration drive has a tracker")?;
    let nominal = cal_scenario.robot.nominal_params;
    let true_params = cal_scenario.robot.true_params;
    let nominal = [
        nominal.left_diameter_m,
        nominal.right_diameter_m,
        nominal.wheelbase_m,
    ];
    let cal_dir = out.join("calibration_drive");
    let (cal_summary, cal_log) = stages.run("the calibration drive on the twin", |_| {
        simulate_into(cal_scenario, &cal_dir)
    })?;
    print_summary(&cal_summary, &cal_dir, stdout)?;

    let calib_path = out.join("calibration").join("calib.json");
    let report = stages.run("calibrating the wheels from the drive", |progress| {
        let job = calibration_job(&cal_log, &tracker, nominal, Method::Smoother);
        let total = (job.wheels.len() + job.poses.len()) as u64;
        let (report, mut artefacts) =
            twindrive_calibrate::calibrate(job, |d, _| progress.set(d as u64, total, "samples"))?;
        // The drive was simulated: the figures show the truth against the band.
        artefacts.truth = Some([
            true_params.left_diameter_m,
            true_params.right_diameter_m,
            true_params.wheelbase_m,
        ]);
        twindrive_calibrate::write_outputs(&report, &artefacts, &calib_path)?;
        anyhow::Ok(report)
    })?;
    let calibrated = [
        report.left_diameter_m,
        report.right_diameter_m,
        report.wheelbase_m,
    ];
    writeln!(
        stdout,
        "calibration: dL {:.5} m, dR {:.5} m, b {:.5} m (nominal {:.3}, {:.3}, {:.3}) -> {}",
        calibrated[0],
        calibrated[1],
        calibrated[2],
        nominal[0],
        nominal[1],
        nominal[2],
        calib_path.display()
    )?;

    // 2. The wall-following mission (paper section 5.1).
    let wf_dir = out.join("wall_following");
    let (wf_summary, wf_log) = stages.run("the wall-following mission on the twin", |_| {
        simulate_into(builtin("wall_following")?, &wf_dir)
    })?;
    print_summary(&wf_summary, &wf_dir, stdout)?;

    // 3. The paper's evidence.
    let ev_dir = out.join("evidence");
    let (t1, s6) = stages.run("the paper's evidence (Table 1, Section 6)", |_| {
        let staging = Staging::new(&ev_dir, "demo")?;
        let t1 = evidence::table1(&cal_log, nominal, calibrated, staging.dir())?;
        let s6 = evidence::section6(&wf_log, calibrated, staging.dir())?;
        let md = evidence::markdown(&t1, &s6, staging.dir())?;
        staging.write_with("evidence.md", |w| Ok(w.write_all(md.as_bytes())?))?;
        staging.write_with("evidence.json", |w| {
            serde_json::to_writer_pretty(w, &serde_json::json!({ "table1": t1, "section6": s6 }))
                .map_err(Into::into)
        })?;
        staging.commit()?;
        anyhow::Ok((t1, s6))
    })?;

    for r in &t1.rows {
        writeln!(
            stdout,
            "Table 1  {:<28} major {:.4} m ({:+.3} %), minor {:.4} m ({:+.3} %), area {:.4} m² ({:+.3} %)",
            r.source,
            r.major_axis_m,
            r.major_error_pct,
            r.minor_axis_m,
            r.minor_error_pct,
            r.area_m2,
            r.area_error_pct
        )?;
    }
    for e in &s6.wheelbase_perturbation {
        writeln!(
            stdout,
            "Section 6  {:<16} MSE {:.4} m², sum of absolute differences {:.1} m",
            e.label, e.mean_squared_error_m2, e.sum_abs_difference_m
        )?;
    }
    writeln!(
        stdout,
        "evidence in {}/ (evidence.md, figures)",
        ev_dir.display()
    )?;

    // 4. The plan from the wall-following mission, with calibrated parameters.
    let wf_scenario = builtin("wall_following")?;
    let truth = wf_scenario.robot.true_params;
    // Redundancy at the robot's own size: loops that come back within a
    // footprint radius, and ground within a footprint radius of the plan
    // counts as covered.
    let pinch_distance_m = wf_scenario.robot.footprint_radius_m;
    let plan_job = plan::Job {
        log_sha256: plan::log_dir_sha256(&wf_dir)?,
        log: wf_log,
        params: DiffDriveParams::new(calibrated[0], calibrated[1], calibrated[2]),
        scenario: wf_scenario,
        settings: PipelineSettings {
            planner: Default::default(),
            redundancy: RedundancyConfig::with_pinch_distance(pinch_distance_m),
            filter: Default::default(),
            freedom: Default::default(),
        },
        time_optimal: false,
    };
    let plan_path = out.join("plan").join("plan.json");
    let (the_plan, summary) = stages.run("planning from the mission's log", |_| {
        let (the_plan, plan_stages) = plan::make_plan(&plan_job)?;
        plan::write_outputs(&the_plan, &plan_stages, &plan_job.scenario, &plan_path)?;
        anyhow::Ok((the_plan, plan_stages.summary()))
    })?;
    plan::print_summary(&summary, &the_plan, &plan_path, stdout)?;

    // 5. Verification on the twin's true robot.
    let verify_dir = out.join("verification");
    let verification = stages.run("verifying the plan on the twin", |_| {
        let verification = verify_plan::verify(&the_plan, &plan_job.scenario)?;
        verify_plan::write_outputs(&the_plan, &verification, &plan_job.scenario, &verify_dir)?;
        anyhow::Ok(verification)
    })?;
    verify_plan::print_report(&verification.report, &verify_dir, stdout)?;
    if !verification.report.verdict.passed {
        // Nothing that fails verification goes to the robot.
        return Err(PlanFailed(verification.report.verdict.clone()).into());
    }

    // 6. The report.
    // Decoupled operation: the plan over the lunar link to a robot whose
    // site has a box the twin lacks.
    let plan_json = std::fs::read(&plan_path)
        .with_context(|| format!("reading back {}", plan_path.display()))?;
    let world_toml = twindrive_sim::builtin::WALL_FOLLOWING.as_bytes();
    let decoupled_dir = out.join("decoupled");
    let decoupled = stages.run(
        "decoupled operation: the plan over the lunar link to a site with a box",
        |_| {
            decoupled::run(
                &the_plan,
                &plan_json,
                &plan_job.scenario,
                world_toml,
                &decoupled_dir,
            )
        },
    )?;
    decoupled::print(&decoupled, &decoupled_dir, stdout)?;

    // Why decouple: direct tele-operation against decoupled operation on
    // a site with other true kinematics, a short version of `twindrive
    // experiment latency`.
    let mission = Rehearsal {
        twin: plan_job.scenario.clone(),
        world_toml: world_toml.to_vec(),
        site: site_like(&plan_job.scenario),
        plan: the_plan.clone(),
        plan_json: plan_json.clone(),
    };
    let experiment_dir = out.join("experiment");
    let (exp_settings, exp_cells) = stages.run_with_bar(
        "the latency experiment, short: direct against decoupled operation",
        |_| latency::demo_section(&mission, &experiment_dir),
    )?;
    for c in &exp_cells {
        writeln!(
            stdout,
            "experiment: {:<26} at {:.1} s one way, 10 % loss: {}, {:.0} collision(s), route covered {:.0} %",
            c.method.name(),
            c.latency_s,
            c.completion_s
                .map_or("not completed".into(), |t| format!("completed in {t:.0} s")),
            c.collisions,
            c.coverage_percent
        )?;
    }

    // The twin from the robot's own sensors: a site the twin has never
    // seen, self-calibration and its map from one drive, the mission
    // planned on the mapped twin and executed on the true site.
    let mapped_dir = out.join("mapped_site");
    let mapped = mapped_site::run(&mapped_dir, stdout, stages)?;
    mapped_site::print(&mapped, &mapped_dir, stdout)?;

    let mut report = case_study_report(&CaseStudy {
        nominal,
        calibrated,
        truth: [
            truth.left_diameter_m,
            truth.right_diameter_m,
            truth.wheelbase_m,
        ],
        cal_summary: &cal_summary,
        t1: &t1,
        s6: &s6,
        wf_summary: &wf_summary,
        plan: &the_plan,
        summary: &summary,
        verification: &verification.report,
        pinch_distance_m,
        decoupled: &decoupled,
        experiment: (&exp_settings, &exp_cells),
    });
    mapped_site::add_to(&mut report, &mapped);
    stages.run("the report", |_| {
        let md = report.markdown(out)?;
        let staging = Staging::new(out, "demo-report")?;
        staging.write_with("report.md", |w| Ok(w.write_all(md.as_bytes())?))?;
        let html = report.html("twindrive: the case study", out)?;
        staging.write_with("report.html", |w| Ok(w.write_all(html.as_bytes())?))?;
        staging.commit()
    })?;
    writeln!(
        stdout,
        "the whole story: {}/report.md (and report.html)",
        out.display()
    )?;
    Ok(())
}
