//! The demo's decoupled-operation section: the case-study plan, signed, goes
//! over the `lunar` profile to a robot whose site has a box on the route
//! that the twin lacks. Upload, execution, hand-back, twin update (the box
//! appears in the twin), continuation, completion. It runs in virtual time
//! with the protocol code the two processes run, in one process.

use std::io::Write;
use std::path::Path;

use twindrive_agent::backend::SimBackend;
use twindrive_agent::operator::{Outcome, Report};
use twindrive_files::Staging;
use twindrive_link::emulator::LinkProfile;
use twindrive_link::envelope::SigningKey;
use twindrive_mission::plan::MissionPlan;
use twindrive_plot::{Lane, LaneFigure, Markers, Outline, Region, Series, WorldFigure, palette};
use twindrive_sim::Scenario;
use twindrive_store::MasterArchive;
use twindrive_workflow::figures::walls;

use crate::mission::Mission;
use crate::rehearsal::SITE_BOX;

/// The link.
pub const PROFILE: &str = "lunar";

/// What the section found, for the printed summary and the report.
pub struct Decoupled {
    pub report: Report,
    pub signed_bytes: usize,
    pub plan_duration_s: f64,
    pub virtual_s: f64,
}

/// Runs the section into `out` (the `decoupled/` directory).
pub fn run(
    plan: &MissionPlan,
    plan_json: &[u8],
    twin: &Scenario,
    world_toml: &[u8],
    out: &Path,
) -> anyhow::Result<Decoupled> {
    // The robot's site: the twin's world and the box.
    let mut site = twin.clone();
    site.world = site.world.with_blocks(&[SITE_BOX]);
    let (min, max) = SITE_BOX;
    let site_box = [
        (min[0], min[1]),
        (max[0], min[1]),
        (max[0], max[1]),
        (min[0], max[1]),
    ];
    run_on_site(
        plan,
        plan_json,
        twin,
        world_toml,
        &site,
        &[Outline {
            label: "the site's box (the twin lacked it)",
            corners: &site_box,
            color: palette::BAD,
        }],
        out,
    )
}

/// `plan`, rehearsed and verified on `twin` (whose world file is
/// `world_toml`), signed and sent over the lunar link to a robot on
/// `site`; the figure outlines `differences` (what the site has that the
/// twin lacks).
pub fn run_on_site(
    plan: &MissionPlan,
    plan_json: &[u8],
    twin: &Scenario,
    world_toml: &[u8],
    site: &Scenario,
    differences: &[Outline<'_>],
    out: &Path,
) -> anyhow::Result<Decoupled> {
    // A fixed key: the demo is deterministic (same seed, same bytes); a
    // real master's key comes from `twindrive keygen`.
    let key = SigningKey::from_bytes(&[7; 32]);
    let profile: LinkProfile = PROFILE.parse().expect("a named profile");
    let backend = SimBackend::new(site.clone(), plan.samples[0].pose(), 3_600.0)
        .map_err(|e| anyhow::anyhow!("the demo site: {e}"))?;
    std::fs::create_dir_all(out.parent().unwrap_or(Path::new(".")))?;
    let mut mission = Mission::new(
        plan, plan_json, twin, world_toml, &key, &profile, 1, backend,
    )?;
    mission.op.config_mut().max_continuations = 8;
    mission.op.config_mut().log_wait_s = 1_200.0;
    let signed_bytes = mission.signed_bytes;
    let Mission {
        mut op,
        mut robot,
        mut link,
        ..
    } = mission;
    let done = link.run(&mut op, &mut robot, 3_600 * 1_000_000_000, |op, _| {
        op.is_done()
    });
    if !done {
        op.fail(
            "the virtual mission did not end within an hour".into(),
            link.now_ns,
        );
    }
    let virtual_s = link.now_ns as f64 * 1e-9;

    let staging = Staging::new(out, "demo-decoupled")?;
    let dir = staging.dir();
    let mut real_paths: Vec<Vec<(f64, f64)>> = Vec::new();
    // The master's output folder, as `twindrive master` lays it out.
    let mut archive = MasterArchive::new(dir);
    while let Some(log) = op.new_logs.pop_front() {
        let written = archive.write_robot_log(log.plan.as_deref(), &log.mcap, log.full_rate)?;
        op.report.robot_logs.push(written.name);
        real_paths.push(
            written
                .log
                .steps
                .iter()
                .map(|s| (s.ground_truth.x_m, s.ground_truth.y_m))
                .collect(),
        );
    }
    let mut plans: Vec<Vec<(f64, f64)>> =
        vec![plan.samples.iter().map(|s| (s.x_m, s.y_m)).collect()];
    std::fs::create_dir_all(dir.join("plans"))?;
    while let Some((p, json, signed)) = op.new_plans.pop_front() {
        plans.push(p.samples.iter().map(|s| (s.x_m, s.y_m)).collect());
        archive.write_plan(&p, &json, Some(&signed))?;
    }
    op.finish_report();
    staging.write_with("report.json", |w| {
        serde_json::to_writer_pretty(w, &op.report).map_err(Into::into)
    })?;
    let journal = robot.store().journal();
    staging.write_with("robot_journal.jsonl", |w| Ok(w.write_all(&journal)?))?;

    // The twin after the mission: the walls it knew, the blocks it learnt,
    // and against them the site's differences.
    let learnt: Vec<[(f64, f64); 4]> = op
        .twin()
        .map(|t| t.learnt.clone())
        .unwrap_or_default()
        .iter()
        .map(|&(min, max)| {
            [
                (min[0], min[1]),
                (max[0], min[1]),
                (max[0], max[1]),
                (min[0], max[1]),
            ]
        })
        .collect();
    let learnt_label = "block the twin learnt";
    let regions: Vec<Region> = learnt
        .iter()
        .map(|corners| Region {
            label: learnt_label,
            corners,
            color: palette::PURPLE,
        })
        .collect();
    let labels: Vec<String> = (0..plans.len())
        .map(|k| {
            if k == 0 {
                "plan".into()
            } else {
                format!("continuation {k}")
            }
        })
        .collect();
    // The plan orange, each continuation its own colour; bands under the
    // robot's path, which follows them closely.
    let references: Vec<Series> = plans
        .iter()
        .zip(&labels)
        .enumerate()
        .map(|(k, (p, label))| Series {
            label,
            points: p,
            color: if k == 0 {
                palette::ALT
            } else {
                palette::cycle(k)
            },
        })
        .collect();
    let real: Vec<(f64, f64)> = real_paths.concat();
    let handbacks: Vec<(f64, f64)> = op
        .report
        .handbacks
        .iter()
        .map(|h| (h.pose[0], h.pose[1]))
        .collect();
    WorldFigure {
        title: "decoupled operation: the twin's world after the mission (walls and learnt blocks)",
        walls: &walls(&twin.world),
        regions: &regions,
        paths: &[Series {
            label: "robot (true path)",
            points: &real,
            color: palette::TRUTH,
        }],
        references: &references,
        markers: &[Markers {
            label: "hand-back",
            points: &handbacks,
            color: palette::BAD,
        }],
        outlines: differences,
    }
    .write(&dir.join("twin"))?;
    timeline_figure(&op.report, &dir.join("timeline"))?;
    staging.commit()?;
    Ok(Decoupled {
        report: op.report,
        signed_bytes,
        plan_duration_s: plan.duration_s(),
        virtual_s,
    })
}

/// Lanes over mission time: the link up, each upload, each execution, each
/// hand-back and each robot log received.
fn timeline_figure(report: &Report, base: &Path) -> anyhow::Result<()> {
    let at = |event: &str| -> Vec<f64> {
        report
            .timeline
            .iter()
            .filter(|e| e.event == event)
            .map(|e| e.t_s)
            .collect()
    };
    let end = report.timeline.last().map_or(1.0, |e| e.t_s);
    // Each start to the first end at or after it (or the end of the mission).
    let spans = |starts: &[f64], ends: &[f64]| -> Vec<(f64, f64)> {
        starts
            .iter()
            .map(|&a| (a, ends.iter().copied().find(|&b| b >= a).unwrap_or(end)))
            .collect()
    };
    let uploads = spans(&at("upload_started"), &at("upload_finished"));
    let mut stops = at("stopped");
    stops.extend(at("execution_finished"));
    stops.sort_by(f64::total_cmp);
    let executions = spans(&at("execution_started"), &stops);
    let (handbacks, logs) = (at("handback"), at("robot_log"));
    LaneFigure {
        title: "decoupled operation over the lunar link: timeline",
        x_label: "mission time (s)",
        lanes: &[
            Lane {
                name: "link up",
                spans: &[(0.0, end)],
                events: &[],
                color: palette::TRUTH,
            },
            Lane {
                name: "upload",
                spans: &uploads,
                events: &[],
                color: palette::ALT,
            },
            Lane {
                name: "execution",
                spans: &executions,
                events: &[],
                color: palette::GOOD,
            },
            Lane {
                name: "hand-back",
                spans: &[],
                events: &handbacks,
                color: palette::BAD,
            },
            Lane {
                name: "robot log received",
                spans: &[],
                events: &logs,
                color: palette::PURPLE,
            },
        ],
    }
    .write(base)?;
    Ok(())
}

/// The printed summary.
pub fn print(d: &Decoupled, out: &Path, w: &mut impl Write) -> anyhow::Result<()> {
    let r = &d.report;
    writeln!(
        w,
        "decoupled: plan signed {} bytes ({:.2} kB per second of mission), over {PROFILE}",
        d.signed_bytes,
        d.signed_bytes as f64 / 1e3 / d.plan_duration_s
    )?;
    for (k, u) in r.uploads.iter().enumerate() {
        writeln!(
            w,
            "  upload {}: {} bytes in {:.1} s ({} chunks resent)",
            k + 1,
            u.bytes,
            u.duration_s,
            u.chunks_resent
        )?;
    }
    for h in &r.handbacks {
        writeln!(
            w,
            "  hand-back at {:.1} s: {} {:.1} s into its plan at ({:.2}, {:.2})",
            h.t_s, h.reason, h.plan_t_s, h.pose[0], h.pose[1]
        )?;
    }
    let learnt: usize = r.twin_updates.iter().map(|u| u.obstacles_added.len()).sum();
    writeln!(
        w,
        "  outcome {:?} after {:.0} s of link time; the twin learnt {learnt} block(s); {} contact(s) that held the robot, {} bump(s) -> {}/",
        r.outcome.unwrap_or(Outcome::Failed),
        d.virtual_s,
        r.collisions,
        r.bumps,
        out.display()
    )?;
    Ok(())
}
