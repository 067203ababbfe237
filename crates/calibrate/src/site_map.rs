//! The site's map from a drive's encoders and scans (`twindrive map`): the
//! calibrated odometry at each scan, each scan located against the map
//! drawn so far ([`twindrive_estimation::mapping`]), the log-odds grid
//! written as ROS map_server files, and `site.toml`, a scenario on that
//! map for the twin (`simulate`, `plan`, `verify-plan`, `console`, `robot`).

use std::io::Write;
use std::path::Path;

use anyhow::{Context, bail};
use serde::Serialize;
use twindrive_estimation::WheelSample;
use twindrive_estimation::dead_reckoning::{dead_reckon, pose_at};
use twindrive_estimation::localize::Scan;
use twindrive_estimation::mapping::{LogOddsGrid, Mapping, MappingSettings, map_drive};
use twindrive_files::Staging;
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_log::RangeSensorInfo;

/// Fewest scans with returns a map is drawn from.
pub const MIN_SCANS: usize = 10;

/// One map's checked inputs.
#[derive(Debug, Clone)]
pub struct MapJob {
    /// How the robot moved between scans.
    pub motion: Motion,
    /// The lidar's scans in its own frame, in time order.
    pub scans: Vec<Scan>,
    /// The lidar, with its calibrated mount.
    pub lidar: RangeSensorInfo,
    /// The calibrated wheels (they dead-reckon [`Motion::Wheels`], and are
    /// the site's robot's).
    pub params: DiffDriveParams,
    /// The robot's pose at the first motion sample: it fixes the map's
    /// frame (a log's start pose; the origin for a bag).
    pub start: Pose,
    pub settings: MappingSettings,
    /// A map already drawn of the same site, in the same frame, to extend.
    pub prior: Option<LogOddsGrid>,
    /// Where the times of `motion` and `scans` count from on the
    /// recording's own clock (a bag's: its scans' header stamps; 0 for a
    /// log), in whole seconds: `poses.tum` is stamped on that clock.
    pub time_origin_s: f64,
}

/// How the robot moved between its scans, as the recording tells it.
#[derive(Debug, Clone)]
pub enum Motion {
    /// Wheel angles, dead-reckoned with the job's calibrated wheels.
    Wheels(Vec<WheelSample>),
    /// Poses the robot's own odometry reported (`nav_msgs/msg/Odometry`,
    /// TF `odom -> base`): already in metres, no calibration needed.
    /// `(t_s, pose)` in time order, in the odometry's own frame; the map's
    /// frame puts the first at the job's start.
    Odometry(Vec<(f64, Pose)>),
}

impl Motion {
    /// What the motion is read from, for messages.
    fn what(&self) -> &'static str {
        match self {
            Motion::Wheels(_) => "the encoders",
            Motion::Odometry(_) => "the odometry",
        }
    }

    /// The robot's track in the map's frame: starting at `start`, over
    /// the motion's time span.
    pub fn track(&self, start: Pose, params: &DiffDriveParams) -> Vec<(f64, Pose)> {
        match self {
            Motion::Wheels(wheels) => match (wheels.first(), wheels.last()) {
                (Some(first), Some(last)) => {
                    dead_reckon(wheels, start, first.t_s, last.t_s, params)
                }
                _ => Vec::new(),
            },
            Motion::Odometry(poses) => {
                let Some(&(_, first)) = poses.first() else {
                    return Vec::new();
                };
                // The rigid motion taking the first odometry pose to `start`.
                let dh = start.heading_rad - first.heading_rad;
                let (s, c) = dh.sin_cos();
                poses
                    .iter()
                    .map(|&(t, p)| {
                        let (dx, dy) = (p.x_m - first.x_m, p.y_m - first.y_m);
                        (
                            t,
                            Pose::new(
                                start.x_m + c * dx - s * dy,
                                start.y_m + s * dx + c * dy,
                                twindrive_kinematics::wrap_angle(p.heading_rad + dh),
                            ),
                        )
                    })
                    .collect()
            }
        }
    }
}

/// A drive mapped.
#[derive(Debug, Clone)]
pub struct SiteMap {
    pub mapping: Mapping,
    /// The time of each pose in `mapping.poses` (s, from the job's
    /// `time_origin_s`).
    pub times_s: Vec<f64>,
    /// The job's `time_origin_s`.
    pub time_origin_s: f64,
    /// The index in the job's scans of each pose's scan.
    pub scan_index: Vec<usize>,
    /// Scans outside the motion's time span (encoders or odometry), left out.
    pub scans_outside: usize,
    /// The matches' median RMS residual: the lidar's range noise and the
    /// map's own, as the twin's lidar noise (m).
    pub range_noise_m: Option<f64>,
}

/// What `map_report.json` says.
#[derive(Debug, Clone, Serialize)]
pub struct MapReport {
    pub scans: usize,
    pub scans_matched: usize,
    pub scans_unmatched: Vec<(String, usize)>,
    /// Scans outside the motion's time span (encoders or odometry).
    pub scans_outside_motion: usize,
    pub resolution_m: f64,
    pub width_cells: usize,
    pub height_cells: usize,
    pub origin_m: [f64; 2],
    pub free_cells: usize,
    pub occupied_cells: usize,
    pub unknown_cells: usize,
    pub path_length_m: f64,
    pub range_noise_m: Option<f64>,
    pub lidar: String,
    pub lidar_mount: [f64; 3],
    pub params: [f64; 3],
    /// What the SLAM did: loop searches and closures (those of the global
    /// search among them), closures switched off as false loops, and the
    /// global search's matches that no second one confirmed (loops seen
    /// but not taken: when one is real, the map is bent there).
    pub slam: twindrive_estimation::slam::SlamStats,
}

impl MapReport {
    /// The SLAM's loop closures in a line, for the terminal.
    pub fn closures_line(&self) -> String {
        let s = &self.slam;
        let mut line = format!(
            "loop closures: {} ({} by the global search), {} switched off as false loops",
            s.loop_closures, s.global_closures, s.loops_rejected
        );
        if s.global_unconfirmed > 0 {
            line.push_str(&format!(
                "; {} match(es) of the global search left unconfirmed (a loop seen but not taken: \
                 if it was real, the map does not close there)",
                s.global_unconfirmed
            ));
        }
        line
    }
}

/// Maps the drive. `progress(done, total)` as it goes.
pub fn map_site(job: &MapJob, progress: impl FnMut(usize, usize)) -> anyhow::Result<SiteMap> {
    let track = job.motion.track(job.start, &job.params);
    if track.is_empty() {
        bail!(
            "no samples from {}: a map needs the robot's motion to place the scans",
            job.motion.what()
        );
    }
    let mut scans = Vec::with_capacity(job.scans.len());
    let mut times_s = Vec::with_capacity(job.scans.len());
    let mut scan_index = Vec::with_capacity(job.scans.len());
    let mut outside = 0;
    let min_points = job.settings.matching.min_points;
    for (k, s) in job.scans.iter().enumerate() {
        let Some(p) = pose_at(&track, s.t_s) else {
            outside += 1;
            continue;
        };
        scans.push((s.clone(), [p.x_m, p.y_m, p.heading_rad]));
        times_s.push(s.t_s);
        scan_index.push(k);
    }
    let with_returns = scans
        .iter()
        .filter(|(s, _)| s.endpoints().flatten().count() >= min_points)
        .count();
    if with_returns < MIN_SCANS {
        bail!(
            "no usable scans: {} of {} scans from {} fall within the time span of {} and \
             {with_returns} of them have at least {min_points} returns; a map needs {MIN_SCANS} \
             (is the lidar in range of anything, and its topic the right one?)",
            scans.len(),
            job.scans.len(),
            job.lidar.name,
            job.motion.what()
        );
    }
    let m = job.lidar.mount;
    let mapping = map_drive(
        &scans,
        [m.x_m, m.y_m, m.heading_rad],
        job.settings,
        job.prior.as_ref(),
        progress,
    );
    let mut rms = mapping.rms_m.clone();
    rms.sort_by(f64::total_cmp);
    let range_noise_m = rms.get(rms.len() / 2).copied();
    Ok(SiteMap {
        mapping,
        times_s,
        time_origin_s: job.time_origin_s,
        scan_index,
        scans_outside: outside,
        range_noise_m,
    })
}

impl SiteMap {
    /// The report's numbers.
    pub fn report(&self, job: &MapJob) -> MapReport {
        let grid = self.grid();
        let [free, occupied, unknown] = grid.counts();
        let m = job.lidar.mount;
        MapReport {
            scans: self.mapping.poses.len(),
            scans_matched: self.mapping.matched,
            scans_unmatched: self.mapping.unmatched.clone(),
            scans_outside_motion: self.scans_outside,
            resolution_m: grid.resolution_m(),
            width_cells: grid.width(),
            height_cells: grid.height(),
            origin_m: grid.origin_m(),
            free_cells: free,
            occupied_cells: occupied,
            unknown_cells: unknown,
            path_length_m: self
                .mapping
                .poses
                .windows(2)
                .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
                .sum(),
            range_noise_m: self.range_noise_m,
            lidar: job.lidar.name.clone(),
            lidar_mount: [m.x_m, m.y_m, m.heading_rad],
            params: [
                job.params.left_diameter_m,
                job.params.right_diameter_m,
                job.params.wheelbase_m,
            ],
            slam: self.mapping.slam,
        }
    }

    /// The grid cropped to what was seen, with a margin of unknown.
    pub fn grid(&self) -> LogOddsGrid {
        self.mapping.grid.cropped(4)
    }
}

/// The robot as `site.toml` describes it when no mission scenario is given.
#[derive(Debug, Clone)]
pub struct SiteRobot {
    pub footprint_radius_m: f64,
    pub max_wheel_speed_rad_s: f64,
    pub max_wheel_accel_rad_s2: f64,
    pub ticks_per_rev: u32,
    /// The lidar's scan rate (Hz).
    pub scan_rate_hz: f64,
    /// The gyro's name and rate, if the robot has one.
    pub gyro: Option<(String, f64)>,
}

/// The scenario the twin runs on the mapped site.
#[derive(Debug, Clone)]
pub enum SiteScenario {
    /// The robot as recorded, standing where the drive started, holding
    /// still: the operator gives the mission.
    Hold(SiteRobot),
    /// A mission scenario's robot, sensors and controller moved onto the
    /// map (its TOML text and path), with the calibrated wheels and mount.
    Mission {
        text: String,
        path: std::path::PathBuf,
    },
}

fn params_table(p: &DiffDriveParams) -> toml::Table {
    let mut t = toml::Table::new();
    t.insert("left_diameter_m".into(), p.left_diameter_m.into());
    t.insert("right_diameter_m".into(), p.right_diameter_m.into());
    t.insert("wheelbase_m".into(), p.wheelbase_m.into());
    t
}

fn pose_table(p: Pose) -> toml::Table {
    let mut t = toml::Table::new();
    t.insert("x_m".into(), p.x_m.into());
    t.insert("y_m".into(), p.y_m.into());
    t.insert("heading_rad".into(), p.heading_rad.into());
    t
}

/// `site.toml`'s text with the robot at `start`, and a file it names that
/// must be copied beside it (a manual mission's commands), if any.
pub fn site_toml(
    name: &str,
    map: &SiteMap,
    job: &MapJob,
    scenario: &SiteScenario,
    start: Pose,
) -> anyhow::Result<(String, Option<std::path::PathBuf>)> {
    let mut world = toml::Table::new();
    world.insert("map".into(), "map.yaml".into());
    let mount = job.lidar.mount;
    match scenario {
        SiteScenario::Hold(robot) => {
            let mut doc = toml::Table::new();
            doc.insert("name".into(), name.into());
            doc.insert(
                "description".into(),
                format!(
                    "The site as the robot's lidar ({}) mapped it; the robot with its calibrated wheels and mount, holding still",
                    job.lidar.name
                )
                .into(),
            );
            let mut sim = toml::Table::new();
            sim.insert("duration_s".into(), 1.0.into());
            sim.insert("dt_s".into(), 0.01.into());
            sim.insert("seed".into(), 1.into());
            doc.insert("simulation".into(), sim.into());
            doc.insert("world".into(), world.into());
            let mut r = toml::Table::new();
            r.insert("start".into(), pose_table(start).into());
            r.insert("footprint_radius_m".into(), robot.footprint_radius_m.into());
            r.insert(
                "max_wheel_speed_rad_s".into(),
                robot.max_wheel_speed_rad_s.into(),
            );
            r.insert(
                "max_wheel_accel_rad_s2".into(),
                robot.max_wheel_accel_rad_s2.into(),
            );
            r.insert("true_params".into(), params_table(&job.params).into());
            r.insert("nominal_params".into(), params_table(&job.params).into());
            doc.insert("robot".into(), r.into());
            let mut enc = toml::Table::new();
            enc.insert(
                "ticks_per_rev".into(),
                i64::from(robot.ticks_per_rev).into(),
            );
            doc.insert("encoders".into(), enc.into());
            let mut lidar = toml::Table::new();
            lidar.insert("name".into(), job.lidar.name.clone().into());
            lidar.insert("kind".into(), job.lidar.kind.as_str().into());
            lidar.insert("mount".into(), pose_table(mount).into());
            lidar.insert("beams".into(), i64::from(job.lidar.beams).into());
            lidar.insert("fov_rad".into(), job.lidar.fov_rad.into());
            lidar.insert("min_range_m".into(), job.lidar.min_range_m.into());
            lidar.insert("max_range_m".into(), job.lidar.max_range_m.into());
            lidar.insert(
                "noise_std_m".into(),
                map.range_noise_m.unwrap_or(0.02).into(),
            );
            lidar.insert("rate_hz".into(), robot.scan_rate_hz.into());
            doc.insert(
                "range_sensors".into(),
                toml::Value::Array(vec![lidar.into()]),
            );
            if let Some((gyro_name, rate)) = &robot.gyro {
                let mut g = toml::Table::new();
                g.insert("name".into(), gyro_name.clone().into());
                g.insert("rate_hz".into(), (*rate).into());
                doc.insert("gyro".into(), g.into());
            }
            let mut c = toml::Table::new();
            c.insert("kind".into(), "scripted".into());
            let mut hold = toml::Table::new();
            hold.insert("duration_s".into(), 1.0.into());
            hold.insert("left_rad_s".into(), 0.0.into());
            hold.insert("right_rad_s".into(), 0.0.into());
            c.insert("segments".into(), toml::Value::Array(vec![hold.into()]));
            doc.insert("controller".into(), c.into());
            let head = String::from(
                "# The twin's site, drawn by `twindrive map` from the robot's own scans\n\
                 # (map.yaml, map.pgm); the robot with its calibrated wheels and lidar\n\
                 # mount, where the mapping drive started, holding still. Give the\n\
                 # mission's controller here, or map again with --mission SCENARIO.\n",
            );
            Ok((head + &toml::to_string(&doc)?, None))
        }
        SiteScenario::Mission { text, path } => {
            let mut doc: toml::Table = toml::from_str(text)
                .with_context(|| format!("--mission {}: not a TOML scenario", path.display()))?;
            let what = |field: &str| format!("--mission {}: field `{field}`", path.display());
            let old_name = doc
                .get("name")
                .and_then(|v| v.as_str())
                .unwrap_or("mission")
                .to_string();
            doc.insert("name".into(), format!("{old_name}_on_{name}").into());
            doc.insert("world".into(), world.into());
            let robot = doc
                .get_mut("robot")
                .and_then(|v| v.as_table_mut())
                .with_context(|| what("robot"))?;
            robot.insert("true_params".into(), params_table(&job.params).into());
            robot.insert("nominal_params".into(), params_table(&job.params).into());
            if let Some(sensors) = doc.get_mut("range_sensors").and_then(|v| v.as_array_mut()) {
                for s in sensors.iter_mut().filter_map(|s| s.as_table_mut()) {
                    if s.get("name").and_then(|n| n.as_str()) == Some(job.lidar.name.as_str()) {
                        s.insert("mount".into(), pose_table(mount).into());
                    }
                }
            }
            let copy = commands_beside(&mut doc, path, "--mission")?;
            let head = format!(
                "# The mission of {} on the site drawn by `twindrive map` from the robot's\n\
                 # own scans (map.yaml, map.pgm), with the calibrated wheels and lidar mount.\n",
                path.display()
            );
            Ok((head + &toml::to_string(&doc)?, copy))
        }
    }
}

/// A manual mission's commands file goes beside the site.toml made from
/// the scenario at `path`: its `controller.commands` is renamed to the
/// file's name, and the file to copy is returned. `flag` names the
/// scenario in errors.
pub(crate) fn commands_beside(
    doc: &mut toml::Table,
    path: &Path,
    flag: &str,
) -> anyhow::Result<Option<std::path::PathBuf>> {
    let Some(c) = doc.get_mut("controller").and_then(|v| v.as_table_mut()) else {
        return Ok(None);
    };
    let Some(rel) = c.get("commands").and_then(|v| v.as_str()).map(String::from) else {
        return Ok(None);
    };
    let from = path.parent().unwrap_or(Path::new(".")).join(&rel);
    let file = from
        .file_name()
        .with_context(|| format!("{flag} {}: field `controller.commands`", path.display()))?
        .to_string_lossy()
        .into_owned();
    c.insert("commands".into(), file.into());
    Ok(Some(from))
}

/// `grid` as map_server files: `map.pgm`'s bytes and `map.yaml`'s text.
pub(crate) fn map_files(grid: &LogOddsGrid) -> (Vec<u8>, String) {
    let image = twindrive_sim::map::MapImage {
        width: grid.width(),
        height: grid.height(),
        resolution_m: grid.resolution_m(),
        origin_m: grid.origin_m(),
        occupancy: &|col, row| grid.probability(col, row),
    };
    twindrive_sim::map::encode_map(&image, "map.pgm")
}

/// `map.png`: the map's cells in the PGM's greys (`pgm`, as
/// [`map_files`] encodes `grid`), the drive's path on it, its start
/// marked ([`twindrive_plot::MapPicture`]).
fn map_picture(grid: &LogOddsGrid, pgm: &[u8], map: &SiteMap) -> anyhow::Result<Vec<u8>> {
    let cells = grid.width() * grid.height();
    let path: Vec<(f64, f64)> = map.mapping.poses.iter().map(|p| (p[0], p[1])).collect();
    let picture = twindrive_plot::MapPicture {
        width: grid.width(),
        height: grid.height(),
        resolution_m: grid.resolution_m(),
        origin_m: grid.origin_m(),
        grey: &pgm[pgm.len().saturating_sub(cells)..],
        path_m: &path,
        start: map.mapping.poses.first().map(|p| (p[0], p[1], p[2])),
    };
    Ok(picture.png()?)
}

/// Copies `from` into `staging` under its own file name.
pub(crate) fn stage_copy(staging: &Staging, from: &Path) -> anyhow::Result<()> {
    let name = from
        .file_name()
        .context("the mission's commands file")?
        .to_string_lossy()
        .into_owned();
    let bytes = std::fs::read(from).with_context(|| format!("reading {}", from.display()))?;
    staging.write_with(&name, |w| Ok(w.write_all(&bytes)?))
}

/// Where the site's robot may start: the drive's poses (the first, then
/// one every quarter metre of it), at most 64.
fn start_candidates(map: &SiteMap) -> Vec<Pose> {
    let mut out: Vec<Pose> = Vec::new();
    for p in &map.mapping.poses {
        let p = Pose::new(p[0], p[1], p[2]);
        let far = out
            .last()
            .is_none_or(|q| (p.x_m - q.x_m).hypot(p.y_m - q.y_m) >= 0.25);
        if far {
            out.push(p);
        }
        if out.len() == 64 {
            break;
        }
    }
    out
}

/// Writes `map.pgm`, `map.yaml`, `map.png` (a picture of the map with the
/// drive on it), `site.toml` (and a file it names),
/// `poses.tum` (the drive's poses in the map, each stamped with its scan's
/// time on the recording's clock) and `map_report.json` into `out`, as one
/// directory. `site` makes `site.toml` with the robot at a start: the
/// drive's first pose, else the first of the drive's later poses where the
/// site loads (the robot's footprint clear of the map's walls). The map is
/// never thrown away: when no start serves, everything but `site.toml` is
/// written and the error says what to change.
pub fn write_site(
    out: &Path,
    map: &SiteMap,
    job: &MapJob,
    report: &MapReport,
    site: impl Fn(Pose) -> anyhow::Result<(String, Option<std::path::PathBuf>)>,
) -> anyhow::Result<()> {
    let grid = map.grid();
    let (pgm, yaml) = map_files(&grid);
    let png = map_picture(&grid, &pgm, map)?;
    let staging = Staging::new(out, "map")?;
    staging.write_with("map.pgm", |w| Ok(w.write_all(&pgm)?))?;
    staging.write_with("map.png", |w| Ok(w.write_all(&png)?))?;
    staging.write_with("map.yaml", |w| Ok(w.write_all(yaml.as_bytes())?))?;
    staging.write_with("poses.tum", |w| {
        twindrive_log::write_tum(
            map.times_s.iter().zip(&map.mapping.poses).map(|(t, p)| {
                // Whole seconds of origin, then the scan's offset: no
                // rounding of a Unix time's nanoseconds through an f64.
                let origin_ns = (map.time_origin_s.max(0.0).round() as u64) * 1_000_000_000;
                (
                    origin_ns + (t.max(0.0) * 1e9).round() as u64,
                    Pose::new(p[0], p[1], p[2]),
                )
            }),
            w,
        )
        .map_err(Into::into)
    })?;
    staging.write_with("map_report.json", |w| {
        serde_json::to_writer_pretty(w, report).map_err(Into::into)
    })?;
    let candidates = start_candidates(map);
    let mut first_error: Option<anyhow::Error> = None;
    for (k, start) in candidates.iter().enumerate() {
        let (text, beside) = site(*start)?;
        staging.write_with("site.toml", |w| Ok(w.write_all(text.as_bytes())?))?;
        if let Some(from) = &beside {
            stage_copy(&staging, from)?;
        }
        match twindrive_sim::Scenario::load(&staging.path("site.toml")) {
            Ok(_) => {
                if k > 0 {
                    tracing::warn!(
                        "the drive's first pose leaves no room for the site's robot there ({:#}); \
                         site.toml starts it at ({:.2}, {:.2}, {:.2}), the drive's pose {k} quarter-metre(s) on",
                        first_error.as_ref().expect("set on the first pose"),
                        start.x_m,
                        start.y_m,
                        start.heading_rad
                    );
                }
                return staging.commit();
            }
            Err(e) => {
                // Named as the file will be, not by the staging place.
                let staged = staging.path("site.toml").display().to_string();
                first_error.get_or_insert(anyhow::anyhow!(
                    "{}",
                    format!("{e:#}").replace(&staged, "site.toml")
                ));
            }
        }
    }
    // The map stays; the site cannot be made from it as asked.
    let _ = std::fs::remove_file(staging.path("site.toml"));
    staging.commit()?;
    let why = first_error.map_or_else(|| "the drive has no pose".to_string(), |e| format!("{e:#}"));
    let tried: Vec<[f64; 2]> = candidates.iter().map(|p| [p.x_m, p.y_m]).collect();
    let advice = unplaced_advice(map, job, &tried);
    bail!(
        "the map is written to {} (map.pgm, map.yaml, map.png, poses.tum, map_report.json), but no site.toml: \
         at none of the drive's {} poses tried does the site load as a scenario on it (first: {why}); {advice}",
        out.display(),
        candidates.len()
    )
}

/// What to do when the site's robot fits at none of the drive's poses
/// `tried` (where the drive started and the first poses after, in the
/// map's frame): when scans long after the start drew walls there, the map
/// does not close its loop at the start, and the drive up to them maps on
/// its own; otherwise the robot is too big for the map.
fn unplaced_advice(map: &SiteMap, job: &MapJob, tried: &[[f64; 2]]) -> String {
    let drawn = drawn_over(map, job, tried, DRAWN_OVER_RADIUS_M);
    match drawn
        .iter()
        .find(|d| d.from_s - map.times_s[0] > RETURN_AFTER_S)
    {
        Some(d) => {
            let t0 = map.times_s[0];
            format!(
                "the drive's own scans disagree there: the scans of {:.1} to {:.1} s after the first \
                 ({} scans, the drive come back) draw walls on its first metres, where the site's \
                 robot would stand, so the map does not close its loop there and is bent where the \
                 drive comes back (map.png shows the path beside itself; map_report.json's `slam` \
                 counts the loop closures); the drive up to then maps on its own: `--until-s {:.0}`",
                d.from_s - t0,
                d.to_s - t0,
                d.scans,
                (d.from_s - t0 - SPAN_GAP_S).floor()
            )
        }
        None => "give the site's robot a smaller footprint (--footprint-radius-m) or a --mission \
                 whose robot fits"
            .to_string(),
    }
}

/// Returns drawn within this of where the drive started conflict with the
/// robot standing there (m): a robot's half-width.
const DRAWN_OVER_RADIUS_M: f64 = 0.25;
/// A span of scans this long after the start (s) is the drive come back.
const RETURN_AFTER_S: f64 = 60.0;
/// Scans closer in time than this (s) are one span.
const SPAN_GAP_S: f64 = 5.0;

/// A span of scans that drew returns at one place.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrawnSpan {
    /// The first and last scan's times (s, the job's clock).
    pub from_s: f64,
    pub to_s: f64,
    pub scans: usize,
}

/// The spans of scans that put at least three returns within `radius_m`
/// of one of the points `at` (the map's frame), by their located poses.
pub fn drawn_over(map: &SiteMap, job: &MapJob, at: &[[f64; 2]], radius_m: f64) -> Vec<DrawnSpan> {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in at {
        for c in 0..2 {
            lo[c] = lo[c].min(p[c] - radius_m);
            hi[c] = hi[c].max(p[c] + radius_m);
        }
    }
    let m = job.lidar.mount;
    let mount = [m.x_m, m.y_m, m.heading_rad];
    let mut spans: Vec<DrawnSpan> = Vec::new();
    for ((&k, pose), &t) in map
        .scan_index
        .iter()
        .zip(&map.mapping.poses)
        .zip(&map.times_s)
    {
        let Some(scan) = job.scans.get(k) else {
            continue;
        };
        let sensor = twindrive_estimation::se2::compose(*pose, mount);
        let (s, c) = sensor[2].sin_cos();
        let near = scan
            .endpoints()
            .flatten()
            .filter(|p| {
                let (x, y) = (
                    sensor[0] + c * p[0] - s * p[1],
                    sensor[1] + s * p[0] + c * p[1],
                );
                (lo[0]..=hi[0]).contains(&x)
                    && (lo[1]..=hi[1]).contains(&y)
                    && at.iter().any(|a| (x - a[0]).hypot(y - a[1]) <= radius_m)
            })
            .count();
        if near < 3 {
            continue;
        }
        match spans.last_mut() {
            Some(last) if t - last.to_s <= SPAN_GAP_S => {
                last.to_s = t;
                last.scans += 1;
            }
            _ => spans.push(DrawnSpan {
                from_s: t,
                to_s: t,
                scans: 1,
            }),
        }
    }
    spans
}

/// Where the beams of range sensor `sensor` truly met the walls over a
/// simulated drive: from the log's true poses and the site's true mount
/// and walls, without noise; what a map of the drive could have drawn
/// (for [`twindrive_estimation::mapping::score`]).
pub fn seen_wall_points(
    log: &twindrive_log::MissionLog,
    site: &twindrive_sim::Scenario,
    sensor: usize,
) -> Vec<[f64; 2]> {
    let info = &site.range_sensors[sensor].info;
    let (a0, da) = info.angle_min_and_increment();
    let mut seen = Vec::new();
    for (i, step) in log.steps.iter().enumerate() {
        let Some(ranges) = log.range_reading(i, sensor) else {
            continue;
        };
        let t = step.ground_truth;
        let m = info.mount;
        let (s, c) = t.heading_rad.sin_cos();
        let o = [t.x_m + c * m.x_m - s * m.y_m, t.y_m + s * m.x_m + c * m.y_m];
        for (k, r) in ranges.iter().enumerate() {
            if !(r.is_finite() && *r < info.max_range_m && *r > info.min_range_m) {
                continue;
            }
            let a = t.heading_rad + m.heading_rad + a0 + k as f64 * da;
            let dir = twindrive_sim::Vector::new(a.cos(), a.sin());
            let d = site.world.cast_ray(
                twindrive_sim::Vector::new(o[0], o[1]),
                dir,
                info.max_range_m,
            );
            if d < info.max_range_m {
                seen.push([o[0] + d * dir.x, o[1] + d * dir.y]);
            }
        }
    }
    seen
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An odometry track in its own frame, moved to a start: the first
    /// pose lands on the start, and every step keeps its length and turn.
    #[test]
    fn odometry_is_placed_at_the_start_with_its_shape_kept() {
        let mut poses = Vec::new();
        let mut p = Pose::new(3.0, -2.0, 2.5);
        for k in 0..200 {
            let t = 0.05 * f64::from(k);
            poses.push((t, p));
            let (v, w) = (0.3 + 0.1 * (t * 0.7).sin(), 0.4 * (t * 0.3).cos());
            p = Pose::new(
                p.x_m + 0.05 * v * p.heading_rad.cos(),
                p.y_m + 0.05 * v * p.heading_rad.sin(),
                twindrive_kinematics::wrap_angle(p.heading_rad + 0.05 * w),
            );
        }
        let start = Pose::new(-1.0, 4.0, -0.7);
        let params = DiffDriveParams {
            left_diameter_m: 0.07,
            right_diameter_m: 0.07,
            wheelbase_m: 0.2,
        };
        let track = Motion::Odometry(poses.clone()).track(start, &params);
        assert_eq!(track.len(), poses.len());
        assert!((track[0].1.x_m - start.x_m).abs() < 1e-12);
        assert!((track[0].1.y_m - start.y_m).abs() < 1e-12);
        assert!((track[0].1.heading_rad - start.heading_rad).abs() < 1e-12);
        for (a, b) in track.windows(2).zip(poses.windows(2)) {
            let step = |w: &[(f64, Pose)]| {
                (
                    (w[1].1.x_m - w[0].1.x_m).hypot(w[1].1.y_m - w[0].1.y_m),
                    twindrive_kinematics::wrap_angle(w[1].1.heading_rad - w[0].1.heading_rad),
                )
            };
            let ((la, ta), (lb, tb)) = (step(a), step(b));
            assert!((la - lb).abs() < 1e-9 && (ta - tb).abs() < 1e-9);
            assert_eq!(a[1].0, b[1].0, "times kept");
        }
        // The end, seen from the start, is where the odometry's end is seen
        // from its first pose.
        let rel = |from: Pose, to: Pose| {
            let (dx, dy) = (to.x_m - from.x_m, to.y_m - from.y_m);
            let (s, c) = from.heading_rad.sin_cos();
            (c * dx + s * dy, -s * dx + c * dy)
        };
        let (e, o) = (
            rel(track[0].1, track.last().unwrap().1),
            rel(poses[0].1, poses.last().unwrap().1),
        );
        assert!((e.0 - o.0).abs() < 1e-9 && (e.1 - o.1).abs() < 1e-9);
        assert!(
            Motion::Odometry(Vec::new())
                .track(start, &params)
                .is_empty()
        );
    }

    /// A drive that comes back to its start drawn off (its loop not
    /// closed): the scans of its return put walls where it started, and
    /// the advice names them by their time since the first scan and says
    /// how much of the drive maps on its own; early scans near the start
    /// (the robot turning by a wall) are not a return; a drive whose scans
    /// never drew over its start is a robot too big for the map.
    #[test]
    fn a_start_drawn_over_by_the_drives_return_is_named_with_what_maps_alone() {
        use twindrive_estimation::localize::Scan;
        // A scan whose beams fan ±0.1 rad around straight ahead, all at
        // `range_m`.
        let scan = |t_s: f64, range_m: f32| Scan {
            t_s,
            angle_min_rad: -0.1,
            increment_rad: 0.02,
            range_min_m: 0.05,
            range_max_m: 30.0,
            ranges_m: vec![range_m; 11],
        };
        // (time, pose, range): standing at the origin seeing 3 m ahead; at
        // 2 s a metre on, facing back at 0.9 m (near the start, early);
        // then from 100 to 104 s, 1.5 m on facing back at 1.5 m (the
        // return, drawn over the start); then away again.
        let mut drive: Vec<(f64, [f64; 3], f32)> = vec![(0.0, [0.0, 0.0, 0.0], 3.0)];
        drive.push((2.0, [1.0, 0.0, std::f64::consts::PI], 0.9));
        for k in 0..5 {
            drive.push((100.0 + f64::from(k), [1.5, 0.0, std::f64::consts::PI], 1.5));
        }
        drive.push((120.0, [4.0, 0.0, 0.0], 3.0));
        let settings = MappingSettings::default();
        let job = MapJob {
            motion: Motion::Odometry(Vec::new()),
            scans: drive.iter().map(|(t, _, r)| scan(*t, *r)).collect(),
            lidar: RangeSensorInfo {
                kind: twindrive_log::SensorKind::Lidar,
                name: "lidar".into(),
                mount: Pose::new(0.0, 0.0, 0.0),
                beams: 11,
                fov_rad: 0.22,
                min_range_m: 0.05,
                max_range_m: 30.0,
            },
            params: DiffDriveParams {
                left_diameter_m: 0.07,
                right_diameter_m: 0.07,
                wheelbase_m: 0.2,
            },
            start: Pose::new(0.0, 0.0, 0.0),
            settings,
            prior: None,
            time_origin_s: 0.0,
        };
        let map = SiteMap {
            mapping: twindrive_estimation::mapping::Mapping {
                poses: drive.iter().map(|d| d.1).collect(),
                grid: LogOddsGrid::new(settings.resolution_m, settings.log_odds),
                matched: drive.len(),
                matched_each: vec![true; drive.len()],
                unmatched: Vec::new(),
                rms_m: Vec::new(),
                placement: None,
                prior_agreement: None,
                slam: Default::default(),
            },
            times_s: drive.iter().map(|d| d.0).collect(),
            time_origin_s: 0.0,
            scan_index: (0..drive.len()).collect(),
            scans_outside: 0,
            range_noise_m: None,
        };
        let spans = drawn_over(&map, &job, &[[0.0, 0.0]], DRAWN_OVER_RADIUS_M);
        assert_eq!(
            spans,
            [
                DrawnSpan {
                    from_s: 2.0,
                    to_s: 2.0,
                    scans: 1
                },
                DrawnSpan {
                    from_s: 100.0,
                    to_s: 104.0,
                    scans: 5
                }
            ]
        );
        let advice = unplaced_advice(&map, &job, &[[0.0, 0.0]]);
        assert!(
            advice.contains("the scans of 100.0 to 104.0 s after the first (5 scans")
                && advice.contains("`--until-s 95`"),
            "{advice}"
        );
        // Nothing drawn over the start but the early scan: the robot is
        // too big.
        let elsewhere = unplaced_advice(&map, &job, &[[3.0, 2.0]]);
        assert!(elsewhere.contains("smaller footprint"), "{elsewhere}");
        let early_only = SiteMap {
            times_s: vec![0.0, 2.0, 10.0, 11.0, 12.0, 13.0, 14.0, 30.0],
            ..map
        };
        let advice = unplaced_advice(&early_only, &job, &[[0.0, 0.0]]);
        assert!(advice.contains("smaller footprint"), "{advice}");
    }
}
