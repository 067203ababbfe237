//! Replaying a plan on the twin before the real robot sees it: open loop,
//! closed loop and open loop through the nominal parameters, the verdict,
//! the replayed tracks and the overlay figure.

use std::io::Write;
use std::path::Path;

use serde::Serialize;
use twindrive_files::Staging;
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_link::envelope::Tolerances;
use twindrive_mission::freedom::FreedomMap;
use twindrive_mission::plan::MissionPlan;
use twindrive_mission::verify::{self, Replay, ReplayReport, Verdict};
use twindrive_plot::{Series, WorldFigure, palette};
use twindrive_sim::Scenario;

use crate::figures;

/// `report.json`.
#[derive(Debug, Clone, Serialize)]
pub struct VerifyReport {
    pub plan_sha256: String,
    pub scenario: String,
    /// Over the plan's open- and closed-loop replays: collisions and bumps
    /// added up, the larger maximum deviation, the mean of the mean deviations.
    pub collisions: u64,
    pub bumps: u64,
    pub max_deviation_m: f64,
    pub mean_deviation_m: f64,
    /// The plan's own duration and path length.
    pub duration_s: f64,
    pub path_length_m: f64,
    /// The plan's wheel speeds played blind.
    pub open_loop: ReplayReport,
    /// Trajectory tracking (Kanayama) on odometry with the calibrated parameters.
    pub closed_loop: ReplayReport,
    /// The same path's wheel speeds through the operator's nominal parameters.
    pub open_loop_nominal: ReplayReport,
    pub nominal_params: DiffDriveParams,
    pub calibrated_params: DiffDriveParams,
    /// Passed, or why not: the open- and closed-loop replays touch nothing
    /// and stay within the robot's deviation tolerance of the plan's path.
    pub verdict: Verdict,
}

/// The three replays.
pub struct Verification {
    pub report: VerifyReport,
    pub open_loop: Replay,
    pub closed_loop: Replay,
    pub open_loop_nominal: Replay,
}

/// Verifies `plan` on the twin `scenario` against the robot's deviation
/// tolerance (the default one signed plans carry), and replays the same
/// path through the nominal parameters for comparison.
pub fn verify(plan: &MissionPlan, scenario: &Scenario) -> anyhow::Result<Verification> {
    let samples = &plan.samples;
    let calibrated = plan.header.calibrated;
    let nominal = scenario.robot.nominal_params;
    let criteria = twindrive_agent::executive::criteria(&Tolerances::default());
    let (checked, open_loop_nominal) = std::thread::scope(|s| {
        let nominal_run = s.spawn(|| {
            verify::open_loop(
                samples,
                scenario.clone(),
                Some(&nominal),
                &FreedomMap::of_plan(plan),
            )
        });
        let checked = verify::verify(plan, scenario, &criteria);
        (checked, nominal_run.join())
    });
    let verify::PlanVerification {
        open_loop,
        closed_loop,
        verdict,
    } = checked?;
    let open_loop_nominal =
        open_loop_nominal.map_err(|_| anyhow::anyhow!("a replay panicked"))??;
    let (o, c) = (&open_loop.report, &closed_loop.report);
    let path_length_m = samples
        .windows(2)
        .map(|w| (w[1].x_m - w[0].x_m).hypot(w[1].y_m - w[0].y_m))
        .sum();
    let report = VerifyReport {
        plan_sha256: plan.sha256.clone(),
        scenario: scenario.name.clone(),
        collisions: o.collisions + c.collisions,
        bumps: o.bumps + c.bumps,
        max_deviation_m: o.max_deviation_m.max(c.max_deviation_m),
        mean_deviation_m: 0.5 * (o.mean_deviation_m + c.mean_deviation_m),
        duration_s: plan.duration_s(),
        path_length_m,
        open_loop: open_loop.report.clone(),
        closed_loop: closed_loop.report.clone(),
        open_loop_nominal: open_loop_nominal.report.clone(),
        nominal_params: nominal,
        calibrated_params: calibrated,
        verdict,
    };
    Ok(Verification {
        report,
        open_loop,
        closed_loop,
        open_loop_nominal,
    })
}

/// Writes report.json, the replayed tracks (TUM) and the overlay figure.
pub fn write_outputs(
    plan: &MissionPlan,
    v: &Verification,
    scenario: &Scenario,
    out: &Path,
) -> anyhow::Result<()> {
    let staging = Staging::new(out, "verify-plan")?;
    staging.write_with("report.json", |w| {
        serde_json::to_writer_pretty(&mut *w, &v.report)?;
        writeln!(w)?;
        Ok(())
    })?;
    for (name, replay) in [
        ("open_loop", &v.open_loop),
        ("closed_loop", &v.closed_loop),
        ("open_loop_nominal", &v.open_loop_nominal),
    ] {
        staging.write_with(&format!("{name}.tum"), |w| {
            let ns = |t: f64| (t * 1e9).round().max(0.0) as u64;
            twindrive_log::write_tum(replay.track.iter().map(|(t, p)| (ns(*t), *p)), w)
                .map_err(Into::into)
        })?;
    }
    let xy =
        |t: &[(f64, Pose)]| -> Vec<(f64, f64)> { t.iter().map(|(_, p)| (p.x_m, p.y_m)).collect() };
    let planned: Vec<(f64, f64)> = plan.samples.iter().map(|s| (s.x_m, s.y_m)).collect();
    let (open, closed, nominal) = (
        xy(&v.open_loop.track),
        xy(&v.closed_loop.track),
        xy(&v.open_loop_nominal.track),
    );
    // The plan and the calibrated open loop pale bands, one inside the
    // other: the replays that succeed run within a centimetre of the plan.
    WorldFigure {
        title: "Plan replayed on the twin (true parameters and noise)",
        regions: &[],
        references: &[
            Series {
                label: "plan",
                points: &planned,
                color: palette::WALL,
            },
            Series {
                label: "open loop, calibrated plan",
                points: &open,
                color: palette::TRUTH,
            },
        ],
        walls: &figures::walls(&scenario.world),
        paths: &[
            Series {
                label: "open loop, nominal parameters",
                points: &nominal,
                color: palette::BAD,
            },
            Series {
                label: "closed loop (trajectory tracking)",
                points: &closed,
                color: palette::GOOD,
            },
        ],
        markers: &[],
        outlines: &[],
    }
    .write(&staging.dir().join("replays"))?;
    staging.commit()
}

/// The replays and the verdict as a few lines for a terminal.
pub fn print_report(r: &VerifyReport, out: &Path, o: &mut impl Write) -> std::io::Result<()> {
    for (name, x) in [
        ("open loop (plan)", &r.open_loop),
        ("closed loop", &r.closed_loop),
        ("open loop (nominal)", &r.open_loop_nominal),
    ] {
        writeln!(
            o,
            "{name:20} collisions {}, bumps {}, deviation max {:.3} m mean {:.3} m, end error {:.3} m, {:.1} s, {:.2} m",
            x.collisions,
            x.bumps,
            x.max_deviation_m,
            x.mean_deviation_m,
            x.final_error_m,
            x.duration_s,
            x.path_length_m
        )?;
    }
    writeln!(o, "verification: {}", r.verdict.summary())?;
    writeln!(o, "report in {}/report.json", out.display())?;
    Ok(())
}

/// A plan that failed verification (`verify-plan` exits 3).
#[derive(Debug)]
pub struct PlanFailed(pub Verdict);

impl std::fmt::Display for PlanFailed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the plan failed verification: {}",
            self.0.reasons.join("; ")
        )
    }
}

impl std::error::Error for PlanFailed {}
