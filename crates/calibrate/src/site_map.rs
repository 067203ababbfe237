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
    pub wheels: Vec<WheelSample>,
    /// The lidar's scans in its own frame, in time order.
    pub scans: Vec<Scan>,
    /// The lidar, with its calibrated mount.
    pub lidar: RangeSensorInfo,
    /// The calibrated wheels.
    pub params: DiffDriveParams,
    /// The robot's pose at the first wheel sample: it fixes the map's
    /// frame (a log's start pose; the origin for a bag).
    pub start: Pose,
    pub settings: MappingSettings,
    /// A map already drawn of the same site, in the same frame, to extend.
    pub prior: Option<LogOddsGrid>,
}

/// A drive mapped.
#[derive(Debug, Clone)]
pub struct SiteMap {
    pub mapping: Mapping,
    /// The time of each pose in `mapping.poses` (s).
    pub times_s: Vec<f64>,
    /// Scans outside the encoders' time span, left out.
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
    pub scans_outside_encoders: usize,
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
}

/// Maps the drive. `progress(done, total)` as it goes.
pub fn map_site(job: &MapJob, progress: impl FnMut(usize, usize)) -> anyhow::Result<SiteMap> {
    let (Some(first), Some(last)) = (job.wheels.first(), job.wheels.last()) else {
        bail!("no wheel samples: a map needs the encoders to place the scans");
    };
    let track = dead_reckon(&job.wheels, job.start, first.t_s, last.t_s, &job.params);
    let mut scans = Vec::with_capacity(job.scans.len());
    let mut times_s = Vec::with_capacity(job.scans.len());
    let mut outside = 0;
    let min_points = job.settings.matching.min_points;
    for s in &job.scans {
        let Some(p) = pose_at(&track, s.t_s) else {
            outside += 1;
            continue;
        };
        scans.push((s.clone(), [p.x_m, p.y_m, p.heading_rad]));
        times_s.push(s.t_s);
    }
    let with_returns = scans
        .iter()
        .filter(|(s, _)| s.endpoints().flatten().count() >= min_points)
        .count();
    if with_returns < MIN_SCANS {
        bail!(
            "no usable scans: {} of {} scans from {} fall within the encoders' time span and \
             {with_returns} of them have at least {min_points} returns; a map needs {MIN_SCANS} \
             (is the lidar in range of anything, and its topic the right one?)",
            scans.len(),
            job.scans.len(),
            job.lidar.name
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
            scans_outside_encoders: self.scans_outside,
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

/// `site.toml`'s text, and a file it names that must be copied beside it
/// (a manual mission's commands), if any.
pub fn site_toml(
    name: &str,
    map: &SiteMap,
    job: &MapJob,
    scenario: &SiteScenario,
) -> anyhow::Result<(String, Option<std::path::PathBuf>)> {
    let mut world = toml::Table::new();
    world.insert("map".into(), "map.yaml".into());
    let mount = job.lidar.mount;
    let start = map
        .mapping
        .poses
        .first()
        .map_or(job.start, |p| Pose::new(p[0], p[1], p[2]));
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
    let occupancy: Vec<Option<f64>> = (0..grid.height())
        .flat_map(|r| (0..grid.width()).map(move |c| (c, r)))
        .map(|(c, r)| grid.probability(c, r))
        .collect();
    let image = twindrive_sim::map::MapImage {
        width: grid.width(),
        height: grid.height(),
        resolution_m: grid.resolution_m(),
        origin_m: grid.origin_m(),
        occupancy: &occupancy,
    };
    twindrive_sim::map::encode_map(&image, "map.pgm")
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

/// Writes `map.pgm`, `map.yaml`, `site.toml` (and a file it names),
/// `poses.tum` (the drive's poses in the map) and `map_report.json` into
/// `out`, whole or not at all: nothing is written unless `site.toml` loads
/// as a scenario on the map.
pub fn write_site(
    out: &Path,
    map: &SiteMap,
    report: &MapReport,
    site: &(String, Option<std::path::PathBuf>),
) -> anyhow::Result<()> {
    let (pgm, yaml) = map_files(&map.grid());
    let staging = Staging::new(out, "map")?;
    staging.write_with("map.pgm", |w| Ok(w.write_all(&pgm)?))?;
    staging.write_with("map.yaml", |w| Ok(w.write_all(yaml.as_bytes())?))?;
    staging.write_with("site.toml", |w| Ok(w.write_all(site.0.as_bytes())?))?;
    if let Some(from) = &site.1 {
        stage_copy(&staging, from)?;
    }
    staging.write_with("poses.tum", |w| {
        twindrive_log::write_tum(
            map.times_s.iter().zip(&map.mapping.poses).map(|(t, p)| {
                (
                    (t.max(0.0) * 1e9).round() as u64,
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
    twindrive_sim::Scenario::load(&staging.path("site.toml"))
        .context("the site.toml written does not load as a scenario on the map; nothing written")?;
    staging.commit()
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
