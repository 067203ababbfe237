//! The demo's last section: the twin built from the robot's own sensors.
//! A site the twin has never seen (its walls hidden from everything but
//! the simulated robot); the robot drives a calibration drive reporting
//! only encoders, lidar and gyro; self-calibration; the site's map from
//! the same drive; the case-study mission rehearsed, planned and verified
//! on the mapped twin; the plan executed by the robot agent on the true
//! site over the lunar link. Scored against the hidden truth: the
//! parameters, the map against the true walls, the mission's outcome.

use std::path::Path;

use anyhow::Context;
use twindrive_calibrate::scan_inputs::ScanRecording;
use twindrive_calibrate::site_map::{self, MapJob, Motion, SiteScenario};
use twindrive_calibrate::{ScanJob, self_calibrate, write_scan_outputs};
use twindrive_estimation::mapping::{MapScore, MappingSettings, score};
use twindrive_estimation::selfcal::LaserOdometrySettings;
use twindrive_kinematics::{DiffDriveParams, Pose, wrap_angle};
use twindrive_mission::pipeline::PipelineSettings;
use twindrive_mission::redundancy::RedundancyConfig;
use twindrive_plot::{Markers, Series, WorldFigure, palette};
use twindrive_sim::Scenario;
use twindrive_workflow::figures::walls;
use twindrive_workflow::plan;
use twindrive_workflow::simulate::simulate_into;
use twindrive_workflow::verify::{self as verify_plan, PlanFailed};

use super::decoupled::{self, Decoupled};
use super::report::Report;
use twindrive_progress::Stages;

/// The hidden site: a room with clutter along its walls. Only the
/// simulator reads its walls; the twin gets what the robot's lidar drew.
const SITE_WORLD: &str = r#"[world]
polylines = [
  { points = [[0.0, 0.0], [7.0, 0.0], [7.0, 5.5], [0.0, 5.5]], closed = true },
]
rectangles = [
  { min = [1.5, 0.0], max = [2.1, 0.4] },
  { min = [6.5, 2.0], max = [7.0, 2.6] },
  { min = [3.0, 5.1], max = [3.8, 5.5] },
  { min = [0.0, 3.5], max = [0.35, 4.2] },
]
"#;

/// The robot on the site: wheels unlike their nominal values, a lidar off
/// its axle and turned, the paper's side IR, a gyro with a bias and a
/// scale error. `{start}`, `{duration}`, `{seed}` and `{controller}` are
/// filled in per run.
const ROBOT: &str = r#"[robot]
start = {start}
footprint_radius_m = 0.15
max_wheel_speed_rad_s = 12.0
max_wheel_accel_rad_s2 = 30.0
slip_std = 0.001
true_params = { left_diameter_m = 0.0655, right_diameter_m = 0.0668, wheelbase_m = 0.2641 }
nominal_params = { left_diameter_m = 0.066, right_diameter_m = 0.066, wheelbase_m = 0.26 }

[encoders]
ticks_per_rev = 2048
rate_hz = 50.0

[[range_sensors]]
name = "lidar"
kind = "lidar"
mount = { x_m = 0.04, y_m = -0.015, heading_rad = 0.35 }
beams = 360
fov_rad = 6.283185307179586
max_range_m = 12.0
noise_std_m = 0.02
dropout_probability = 0.01
rate_hz = 10.0

[[range_sensors]]
name = "side_ir"
kind = "ranger"
mount = { x_m = 0.05, y_m = -0.12, heading_rad = -1.0471975511965976 }
min_range_m = 0.1
max_range_m = 0.8
noise_std_m = 0.004
rate_hz = 50.0

[bump]
arc_rad = 3.141592653589793
contact_margin_m = 0.002

[gyro]
rate_hz = 100.0
noise_std_rad_s = 0.002
bias_rad_s = -0.006
scale_error = 0.012
"#;

/// The calibration drive: spins both ways and arcs of two curvatures
/// each way, in the middle of the room.
const DRIVE: &str = r#"[controller]
kind = "scripted"
segments = [
  { duration_s = 15.0, left_rad_s = -1.5, right_rad_s = 1.5 },
  { duration_s = 25.0, left_rad_s = 8.0, right_rad_s = 5.5 },
  { duration_s = 25.0, left_rad_s = 5.5, right_rad_s = 8.0 },
  { duration_s = 20.0, left_rad_s = 7.0, right_rad_s = 2.0 },
  { duration_s = 20.0, left_rad_s = 2.0, right_rad_s = 7.0 },
  { duration_s = 15.0, left_rad_s = 1.5, right_rad_s = -1.5 },
]
"#;

/// The case study's mission: the paper's wall follower on the right-hand
/// side IR.
const MISSION: &str = r#"[controller]
kind = "wall_follower"
side_sensor = "side_ir"
target_range_m = 0.35
cruise_speed_m_s = 0.2
gain_rad_s_per_m = 3.0
max_turn_rate_rad_s = 1.0
reverse_speed_m_s = 0.1
reverse_duration_s = 1.0
turn_rate_rad_s = 1.2
turn_duration_s = 1.3
"#;

fn scenario_text(
    name: &str,
    start: Pose,
    duration_s: f64,
    dt_s: f64,
    seed: u64,
    controller: &str,
) -> String {
    let robot = ROBOT.replace(
        "{start}",
        &format!(
            "{{ x_m = {}, y_m = {}, heading_rad = {} }}",
            start.x_m, start.y_m, start.heading_rad
        ),
    );
    format!(
        "name = \"{name}\"\ndescription = \"The demo's hidden site\"\n\n[simulation]\nduration_s = {duration_s:.1}\ndt_s = {dt_s}\nseed = {seed}\n\n{SITE_WORLD}\n{robot}\n{controller}"
    )
}

fn parse(text: &str, name: &str) -> anyhow::Result<Scenario> {
    Scenario::from_toml(text, Path::new(name)).with_context(|| format!("the demo's {name}"))
}

/// What the section found.
pub struct MappedSite {
    /// [dL, dR, b, ℓx, ℓy, ℓθ]: nominal (the mount as the operator
    /// guessed it: on the axle, straight), self-calibrated, hidden truth.
    pub nominal: [f64; 6],
    pub calibrated: [f64; 6],
    pub truth: [f64; 6],
    pub drive_s: f64,
    pub intervals: usize,
    pub map: MapScore,
    pub map_cells: [usize; 3],
    pub resolution_m: f64,
    pub scans_matched: usize,
    pub scans: usize,
    pub verified: bool,
    pub decoupled: Decoupled,
}

/// Runs the section into `out` (the `mapped_site/` directory).
pub fn run(
    out: &Path,
    stdout: &mut impl std::io::Write,
    stages: &mut Stages,
) -> anyhow::Result<MappedSite> {
    // 1. The calibration drive on the hidden site: encoders, lidar, gyro.
    let drive_text = scenario_text(
        "hidden_site_calibration_drive",
        Pose::new(3.5, 2.75, 0.3),
        120.0,
        0.01,
        2024,
        DRIVE,
    );
    let drive = parse(&drive_text, "hidden_site_calibration_drive.toml")?;
    let truth_site = drive.clone();
    let lidar_index = 0;
    let true_mount = truth_site.range_sensors[lidar_index].info.mount;
    let tp = truth_site.robot.true_params;
    let np = truth_site.robot.nominal_params;
    let (summary, log) = stages.run(
        "a calibration drive on a site the twin has never seen",
        |_| simulate_into(drive, &out.join("drive")),
    )?;
    twindrive_workflow::simulate::print_summary(&summary, &out.join("drive"), stdout)?;

    // 2. Self-calibration: no tracker, the mount guessed as on the axle.
    let rec = ScanRecording::from_log(&log, Some("lidar"), [1.0, 1.0])?;
    let job = ScanJob {
        wheels: rec.wheels.clone(),
        scans: rec.scans.clone(),
        gyro: rec.gyro.clone(),
        initial: [np.left_diameter_m, np.right_diameter_m, np.wheelbase_m],
        lidar: rec.lidar.name.clone(),
        mount_guess: Pose::new(0.0, 0.0, 0.0),
        mount_source: "the operator's guess (on the axle, straight ahead)".into(),
        settings: LaserOdometrySettings::default(),
        ticks_per_rev: rec.ticks_per_rev,
        time_origin_s: 0.0,
    };
    let cal = stages.run(
        "self-calibrating the wheels and the lidar's mount from the drive's scans",
        |progress| {
            let (cal, artefacts) = self_calibrate(job, |done, total| {
                progress.set(done as u64, total as u64, "steps")
            })?;
            write_scan_outputs(
                &cal,
                &artefacts,
                &out.join("calibration").join("calib.json"),
            )?;
            anyhow::Ok(cal)
        },
    )?;
    let params = DiffDriveParams::new(cal.left_diameter_m, cal.right_diameter_m, cal.wheelbase_m);
    let mount = Pose::new(
        cal.lidar_mount.x_m,
        cal.lidar_mount.y_m,
        cal.lidar_mount.heading_rad,
    );

    // 3. The site's map from the same drive, and the mission on it.
    let mut lidar = rec.lidar.clone();
    lidar.mount = mount;
    let map_job = MapJob {
        motion: Motion::Wheels(rec.wheels),
        scans: rec.scans,
        lidar,
        params,
        start: log.header.start,
        // Cells of 2.5 cm: the twin's walls are the edges of the free
        // cells, so half a cell of the true wall on average; the lidar's
        // beams that meet a wall at a grazing angle read that many times
        // over.
        settings: MappingSettings {
            resolution_m: 0.025,
            ..MappingSettings::default()
        },
        prior: None,
        time_origin_s: 0.0,
    };
    let mapped = stages.run(
        "mapping the hidden site from the drive (SLAM)",
        |progress| {
            site_map::map_site(&map_job, |done, total| {
                progress.set(done as u64, total as u64, "scans, located then drawn")
            })
        },
    )?;
    let mission_start = Pose::new(3.0, 0.4, 0.0);
    let mission_text = scenario_text(
        "hidden_site_wall_following",
        mission_start,
        90.0,
        0.01,
        2012,
        MISSION,
    );
    let mission_path = out.join("hidden_site_wall_following.toml");
    let scenario = SiteScenario::Mission {
        text: mission_text.clone(),
        path: mission_path,
    };
    let site_dir = out.join("site");
    let report = mapped.report(&map_job);
    let (twin, map_score) = stages.run(
        "the mapped twin, its map scored against the hidden walls",
        |_| {
            site_map::write_site(&site_dir, &mapped, &map_job, &report, |start| {
                site_map::site_toml("mapped_site", &mapped, &map_job, &scenario, start)
            })?;
            let twin = Scenario::load(&site_dir.join("site.toml"))?;
            let map_score = score_map(&mapped, &log, &truth_site, lidar_index, out)?;
            anyhow::Ok((twin, map_score))
        },
    )?;
    // The robot is at the same site the twin mapped: one name.
    let mut true_site = parse(&mission_text, "hidden_site_wall_following.toml")?;
    true_site.name = twin.name.clone();

    // 4. The mission rehearsed on the mapped twin, planned, verified.
    let rehearsal_dir = out.join("rehearsal");
    let plan_path = out.join("plan").join("plan.json");
    let (the_plan, verification) = stages.run(
        "the mission rehearsed, planned and verified on the mapped twin",
        |_| {
            let (_, rehearsal) = simulate_into(twin.clone(), &rehearsal_dir)?;
            let plan_job = plan::Job {
                log_sha256: plan::log_dir_sha256(&rehearsal_dir)?,
                log: rehearsal,
                params,
                scenario: twin.clone(),
                settings: PipelineSettings {
                    planner: Default::default(),
                    redundancy: RedundancyConfig::with_pinch_distance(
                        twin.robot.footprint_radius_m,
                    ),
                    filter: Default::default(),
                    freedom: Default::default(),
                },
                time_optimal: false,
            };
            let (the_plan, plan_stages) = plan::make_plan(&plan_job)?;
            plan::write_outputs(&the_plan, &plan_stages, &twin, &plan_path)?;
            let verification = verify_plan::verify(&the_plan, &twin)?;
            verify_plan::write_outputs(&the_plan, &verification, &twin, &out.join("verification"))?;
            anyhow::Ok((the_plan, verification))
        },
    )?;
    if !verification.report.verdict.passed {
        return Err(PlanFailed(verification.report.verdict.clone()).into());
    }

    // 5. The plan executed by the robot agent on the true site.
    let plan_json = std::fs::read(&plan_path)
        .with_context(|| format!("reading back {}", plan_path.display()))?;
    let world_toml = std::fs::read(site_dir.join("site.toml"))?;
    let decoupled = stages.run(
        "the plan over the lunar link to the robot on the hidden site",
        |_| {
            decoupled::run_on_site(
                &the_plan,
                &plan_json,
                &twin,
                &world_toml,
                &true_site,
                &[],
                &out.join("decoupled"),
            )
        },
    )?;

    let nominal = [
        np.left_diameter_m,
        np.right_diameter_m,
        np.wheelbase_m,
        0.0,
        0.0,
        0.0,
    ];
    let calibrated = [
        cal.left_diameter_m,
        cal.right_diameter_m,
        cal.wheelbase_m,
        mount.x_m,
        mount.y_m,
        mount.heading_rad,
    ];
    let truth = [
        tp.left_diameter_m,
        tp.right_diameter_m,
        tp.wheelbase_m,
        true_mount.x_m,
        true_mount.y_m,
        true_mount.heading_rad,
    ];
    Ok(MappedSite {
        nominal,
        calibrated,
        truth,
        drive_s: summary.duration_s,
        intervals: cal.laser_odometry.intervals,
        map: map_score,
        map_cells: [
            report.free_cells,
            report.occupied_cells,
            report.unknown_cells,
        ],
        resolution_m: report.resolution_m,
        scans_matched: report.scans_matched,
        scans: report.scans,
        verified: verification.report.verdict.passed,
        decoupled,
    })
}

/// The map against the site's hidden walls, and the figure of it.
fn score_map(
    mapped: &site_map::SiteMap,
    log: &twindrive_log::MissionLog,
    truth_site: &Scenario,
    lidar_index: usize,
    out: &Path,
) -> anyhow::Result<MapScore> {
    let grid = mapped.grid();
    let true_walls = truth_site.world.walls();
    let seen = site_map::seen_wall_points(log, truth_site, lidar_index);
    let map_score = score(&grid, &true_walls, &seen, 0.05);
    let occupied: Vec<(f64, f64)> = grid
        .occupied_centres()
        .into_iter()
        .map(|c| (c[0], c[1]))
        .collect();
    let path: Vec<(f64, f64)> = mapped.mapping.poses.iter().map(|p| (p[0], p[1])).collect();
    WorldFigure {
        title: "the site's map from the robot's scans (occupied cells) over the hidden true walls",
        regions: &[],
        references: &[],
        walls: &walls(&truth_site.world),
        paths: &[Series {
            label: "calibration drive (mapped poses)",
            points: &path,
            color: palette::ALT,
        }],
        markers: &[Markers {
            label: "occupied cell of the map",
            points: &occupied,
            color: palette::BAD,
        }],
        outlines: &[],
    }
    .write(&out.join("map_vs_truth"))?;
    Ok(map_score)
}

/// The printed summary.
pub fn print(m: &MappedSite, out: &Path, w: &mut impl std::io::Write) -> anyhow::Result<()> {
    let pct = |i: usize| 100.0 * (m.calibrated[i] / m.truth[i] - 1.0);
    writeln!(
        w,
        "mapped site: self-calibrated from {} intervals of a {:.0} s drive (no tracker): dL {:+.3} %, dR {:+.3} %, b {:+.3} %, lidar mount {:.1} mm and {:.2} deg off the hidden truth",
        m.intervals,
        m.drive_s,
        pct(0),
        pct(1),
        pct(2),
        1e3 * (m.calibrated[3] - m.truth[3]).hypot(m.calibrated[4] - m.truth[4]),
        wrap_angle(m.calibrated[5] - m.truth[5]).abs().to_degrees()
    )?;
    writeln!(
        w,
        "  map: {} of {} scans matched to the map; {} occupied cells, {:.1} % within {:.0} cm of a true wall, {:.1} % of the {:.1} m of wall the lidar saw drawn",
        m.scans_matched,
        m.scans,
        m.map.occupied_cells,
        100.0 * m.map.on_a_wall,
        100.0 * m.map.tolerance_m,
        100.0 * m.map.seen_drawn,
        m.map.seen_wall_m
    )?;
    decoupled::print(&m.decoupled, &out.join("decoupled"), w)?;
    Ok(())
}

/// The report's section.
pub fn add_to(r: &mut Report, m: &MappedSite) {
    let f = |v: f64, d: usize| format!("{v:.d$}");
    r.heading(2, "The twin from the robot's own sensors");
    r.paragraph(format!(
        "A site the twin has never seen: its walls are known only to the simulator. The robot drives          a {:.0} s calibration drive (spins and arcs) reporting only its encoders, its lidar and its          gyro. Self-calibration (Censi et al., T-RO 2013: laser odometry, closed form, maximum          likelihood) estimates the wheels and where the lidar sits on the robot, starting from the          operator's hand-measured wheels and a lidar guessed to be on the axle, looking ahead. The same          drive, placed by the calibrated odometry and matched scan by scan against the map drawn so          far, draws the site: a ROS map_server map and a scenario on it (`mapped_site/site/`).",
        m.drive_s
    ));
    let names = [
        "left wheel diameter (m)",
        "right wheel diameter (m)",
        "wheelbase (m)",
        "lidar x on the robot (m)",
        "lidar y on the robot (m)",
        "lidar heading on the robot (rad)",
    ];
    r.table(
        &[
            "parameter",
            "hand-measured / guessed",
            "self-calibrated",
            "hidden truth",
            "error",
        ],
        (0..6)
            .map(|i| {
                let err = if i < 3 {
                    format!("{:+.3} %", 100.0 * (m.calibrated[i] / m.truth[i] - 1.0))
                } else if i < 5 {
                    format!("{:+.1} mm", 1e3 * (m.calibrated[i] - m.truth[i]))
                } else {
                    format!(
                        "{:+.3} deg",
                        wrap_angle(m.calibrated[i] - m.truth[i]).to_degrees()
                    )
                };
                vec![
                    names[i].to_string(),
                    f(m.nominal[i], 4),
                    f(m.calibrated[i], 5),
                    f(m.truth[i], 5),
                    err,
                ]
            })
            .collect(),
    );
    r.paragraph(format!(
        "The map: {} of {} scans matched to the map drawn before them; {} free, {} occupied and {}          unknown cells of {:.1} cm. {:.1} % of the occupied cells lie within {:.0} cm of a true wall (the          farthest {:.1} cm), and {:.1} % of the {:.1} m of wall the lidar's beams reached is drawn.",
        m.scans_matched,
        m.scans,
        m.map_cells[0],
        m.map_cells[1],
        m.map_cells[2],
        100.0 * m.resolution_m,
        100.0 * m.map.on_a_wall,
        100.0 * m.map.tolerance_m,
        100.0 * m.map.worst_m,
        100.0 * m.map.seen_drawn,
        m.map.seen_wall_m
    ));
    r.figure(
        "mapped_site/map_vs_truth",
        "The map drawn from the robot's scans (its occupied cells) over the site's hidden true walls.",
    );
    let d = &m.decoupled.report;
    r.paragraph(format!(
        "The case-study mission (the wall follower on its side IR) is rehearsed on the mapped twin,          planned, and verified there ({}). The plan goes over the lunar link to the robot agent on the          true site: outcome {}, {} hand-back(s), {} contact(s) that held the robot, {} bump(s).",
        if m.verified { "passed" } else { "failed" },
        d.outcome.map_or("none".to_string(), |o| format!("{o:?}")),
        d.handbacks.len(),
        d.collisions,
        d.bumps
    ));
    r.figure(
        "mapped_site/decoupled/twin",
        "The plan made on the mapped twin and the robot's true path on the hidden site.",
    );
}
