//! The twin keeps learning its site: after a mission, the robot's logs
//! (their encoders and lidar scans) extend the twin's map
//! (`twindrive master --site-maps`).
//!
//! The twin's map (the map_server image its world was loaded from) is the
//! prior: its occupied and free cells enter as confident as the grid can
//! be, unknown stays unknown. Each log's drive is located by the SLAM from
//! its calibrated odometry, placed on the map (near the start the log
//! says, else anywhere on it at any heading: a robot moved by hand, a
//! mistyped start), its scans matched against the map
//! ([`twindrive_estimation::mapping::map_drive`]), and drawn into it; the
//! next log extends the result. A log that matches nowhere on the map, or
//! whose located scans contradict it (ending in space the map has seen
//! free, or crossing its walls: another site, a broken lidar), is not
//! drawn, and the update says why: a map is only ever changed by scans
//! that agree with it.

use std::io::Write;
use std::path::Path;

use anyhow::{Context, bail};
use serde::Serialize;
use twindrive_estimation::mapping::{CellState, LogOddsGrid, MappingSettings};
use twindrive_files::Staging;
use twindrive_kinematics::DiffDriveParams;
use twindrive_log::{MissionLog, RangeSensorInfo};
use twindrive_sim::Scenario;
use twindrive_sim::map::{Cell, OccupancyGrid};

use crate::scan_inputs::{ScanRecording, choose_lidar};
use crate::site_map::{MapJob, Motion, commands_beside, map_files, map_site, stage_copy};

/// How robot logs update a map.
#[derive(Debug, Clone, Copy)]
pub struct UpdateSettings {
    /// A log is drawn only when it was placed on the map
    /// ([`MappingSettings::placement`]), at least this fraction of its
    /// scans matched the map,
    pub min_matched_fraction: f64,
    /// as many of its first `start_scans` did (it starts where it was
    /// placed),
    pub start_scans: usize,
    /// and at least this share of the map's walls its beams reached were
    /// confirmed by a return rather than passed through
    /// ([`twindrive_estimation::mapping::drive_agreement`]).
    pub min_agreement: f64,
    /// The mapper's settings; the cell size is the twin's map's.
    pub mapping: MappingSettings,
}

impl Default for UpdateSettings {
    fn default() -> Self {
        Self {
            min_matched_fraction: 0.5,
            start_scans: 10,
            // A site changes between missions (see `drive_agreement`):
            // logs seeing half a room through a partition since taken away
            // agreed 70-74 %, other sites' logs placed where their first
            // metres fit 39-51 % (the tests' sites).
            min_agreement: 0.6,
            mapping: MappingSettings {
                // A log's scans join the matcher's map only where they
                // matched it, never from the odometry alone: a log that
                // does not agree with the map cannot draw a map of its own
                // and then agree with that. (Scans that did not match are
                // still drawn, at the odometry's pose, if the log is.)
                bridge_m: f64::INFINITY,
                ..MappingSettings::default()
            },
        }
    }
}

/// What became of one robot log.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LogUpdate {
    /// The log's name (where the master keeps it).
    pub log: String,
    pub scans: usize,
    pub scans_matched: usize,
    /// Whether its scans were drawn into the map.
    pub drawn: bool,
    /// Why not, when not.
    pub refused: Option<String>,
    /// Where it was placed, when not where the log says it started.
    pub placed: Option<String>,
}

impl LogUpdate {
    fn not_drawn(log: String, scans: usize, scans_matched: usize, why: String) -> Self {
        Self {
            log,
            scans,
            scans_matched,
            drawn: false,
            refused: Some(why),
            placed: None,
        }
    }
}

/// Cells by state: free, occupied, unknown.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct CellCounts {
    pub free: usize,
    pub occupied: usize,
    pub unknown: usize,
}

impl CellCounts {
    fn of(grid: &LogOddsGrid) -> Self {
        let [free, occupied, unknown] = grid.counts();
        Self {
            free,
            occupied,
            unknown,
        }
    }

    pub fn known(&self) -> usize {
        self.free + self.occupied
    }
}

/// Cells whose state the update changed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct CellChanges {
    pub unknown_to_free: usize,
    pub unknown_to_occupied: usize,
    pub free_to_occupied: usize,
    pub occupied_to_free: usize,
}

/// A site's map after a mission's logs.
#[derive(Debug, Clone)]
pub struct SiteUpdate {
    pub site: String,
    /// The map before (the twin's) and after.
    pub before: LogOddsGrid,
    pub after: LogOddsGrid,
    pub logs: Vec<LogUpdate>,
    pub changes: CellChanges,
}

/// What `update.json` says.
#[derive(Debug, Clone, Serialize)]
pub struct UpdateReport<'a> {
    pub site: &'a str,
    pub version: u32,
    /// The version the update started from (none: the site as given).
    pub previous: Option<u32>,
    pub resolution_m: f64,
    pub logs: &'a [LogUpdate],
    pub cells_before: CellCounts,
    pub cells_after: CellCounts,
    pub changes: CellChanges,
}

impl SiteUpdate {
    /// Whether any log was drawn.
    pub fn drawn(&self) -> bool {
        self.logs.iter().any(|l| l.drawn)
    }

    pub fn cells_before(&self) -> CellCounts {
        CellCounts::of(&self.before)
    }

    pub fn cells_after(&self) -> CellCounts {
        CellCounts::of(&self.after)
    }

    /// `update.json`'s content.
    pub fn report(&self, version: u32, previous: Option<u32>) -> UpdateReport<'_> {
        UpdateReport {
            site: &self.site,
            version,
            previous,
            resolution_m: self.after.resolution_m(),
            logs: &self.logs,
            cells_before: self.cells_before(),
            cells_after: self.cells_after(),
            changes: self.changes,
        }
    }
}

/// A map_server map as a log-odds grid: occupied and free cells at the
/// bounds of `settings.log_odds`, unknown cells unknown.
pub fn prior_grid(map: &OccupancyGrid, settings: &MappingSettings) -> anyhow::Result<LogOddsGrid> {
    if map.origin_yaw_rad.abs() > 1e-9 {
        bail!(
            "the map's origin is turned by {} rad: only maps aligned with the site's frame (yaw 0, as `twindrive map` writes them) can be extended",
            map.origin_yaw_rad
        );
    }
    let model = settings.log_odds;
    let p = |l: f32| 1.0 / (1.0 + (-f64::from(l)).exp());
    let (occupied, free) = (p(model.max), p(model.min));
    Ok(LogOddsGrid::from_probabilities(
        map.resolution_m,
        model,
        [map.origin_x_m, map.origin_y_m],
        map.width,
        map.height,
        map.cells.iter().map(|c| match c {
            Cell::Occupied => Some(occupied),
            Cell::Free => Some(free),
            Cell::Unknown => None,
        }),
    ))
}

/// A robot's log of a mission, to draw into the map.
#[derive(Debug, Clone, Copy)]
pub struct RobotLog<'a> {
    /// Its name (where the master keeps it).
    pub name: &'a str,
    pub log: &'a MissionLog,
    /// The robot's calibrated wheels.
    pub params: DiffDriveParams,
}

/// The twin's map and lidar, or why its site cannot be kept and extended.
pub fn check_twin(twin: &Scenario) -> anyhow::Result<(&OccupancyGrid, &RangeSensorInfo)> {
    let Some(map) = twin.world.grid() else {
        bail!(
            "the twin's site `{}` has no map (its world is drawn by hand): only a site with a map_server map (`[world] map`, as `twindrive map` writes) is kept and extended",
            twin.name
        );
    };
    let sensors: Vec<&RangeSensorInfo> = twin.range_sensors.iter().map(|s| &s.info).collect();
    let owner = format!("the twin's robot in `{}`", twin.name);
    let (_, lidar) = choose_lidar(&sensors, None, &owner)?;
    Ok((map, lidar))
}

/// Extends the map of `twin`'s site with the scans of `logs`, in the
/// order they were driven. The twin's lidar (the one
/// [`choose_lidar`] picks) gives the mount. `progress(done, total)` over all
/// logs' scans.
pub fn update_site(
    twin: &Scenario,
    logs: &[RobotLog<'_>],
    settings: &UpdateSettings,
    mut progress: impl FnMut(usize, usize),
) -> anyhow::Result<SiteUpdate> {
    let (map, lidar) = check_twin(twin)?;
    let mapping = MappingSettings {
        resolution_m: map.resolution_m,
        ..settings.mapping
    };
    let before = prior_grid(map, &mapping)?;
    let mut grid = before.clone();
    let recordings: Vec<anyhow::Result<ScanRecording>> = logs
        .iter()
        .map(|l| ScanRecording::from_log(l.log, Some(&lidar.name), [1.0, 1.0]))
        .collect();
    let total: usize = recordings
        .iter()
        .map(|r| r.as_ref().map_or(0, |r| r.scans.len()))
        .sum();
    let mut done = 0;
    let mut outcomes = Vec::with_capacity(logs.len());
    for (l, rec) in logs.iter().zip(recordings) {
        let name = l.name.to_string();
        let rec = match rec {
            Ok(r) => r,
            Err(e) => {
                outcomes.push(LogUpdate::not_drawn(name, 0, 0, format!("{e:#}")));
                continue;
            }
        };
        let scans = rec.scans.len();
        let mut job_lidar = rec.lidar;
        job_lidar.mount = lidar.mount;
        let job = MapJob {
            motion: Motion::Wheels(rec.wheels),
            scans: rec.scans,
            lidar: job_lidar,
            params: l.params,
            start: l.log.header.start,
            settings: mapping,
            prior: Some(grid.clone()),
            time_origin_s: 0.0,
        };
        let mapped = map_site(&job, |k, n| {
            progress(done + k * scans / n.max(1), total);
        });
        done += scans;
        let mapped = match mapped {
            Ok(m) => m,
            Err(e) => {
                outcomes.push(LogUpdate::not_drawn(name, scans, 0, format!("{e:#}")));
                continue;
            }
        };
        let each = &mapped.mapping.matched_each;
        let matched = mapped.mapping.matched;
        let fraction = matched as f64 / each.len().max(1) as f64;
        let first = &each[..each.len().min(settings.start_scans)];
        let first_matched = first.iter().filter(|m| **m).count();
        let min = settings.min_matched_fraction;
        let agreement = mapped.mapping.prior_agreement.unwrap_or(0.0);
        let refused = if mapped.mapping.placement.is_none() {
            Some(format!(
                "its first {:.0} m of scans match nowhere on the map (near where the log says it started, or anywhere else at any heading)",
                mapping.placement.span_m
            ))
        } else if fraction < min {
            Some(format!(
                "{matched} of {} scans matched the map ({:.0} %, {:.0} % needed)",
                each.len(),
                100.0 * fraction,
                100.0 * min
            ))
        } else if (first_matched as f64) < min * first.len() as f64 {
            Some(format!(
                "{first_matched} of its first {} scans matched the map ({:.0} % needed) where it was placed",
                first.len(),
                100.0 * min
            ))
        } else if agreement < settings.min_agreement {
            Some(format!(
                "its returns confirm {:.0} % of the map's wall cells its beams reached ({:.0} % needed): its beams pass through the rest",
                100.0 * agreement,
                100.0 * settings.min_agreement
            ))
        } else {
            None
        }
        .map(|why| {
            format!(
                "{why}; the log does not agree with this site's map (another site, a broken lidar), so it is not drawn"
            )
        });
        let placed = mapped.mapping.placement.filter(|p| p.moved).map(|p| {
            let s = l.log.header.start;
            format!(
                "placed on the map at ({:.2}, {:.2}, {:.0}°), {:.2} m and {:.0}° from where the log says it started",
                p.start[0],
                p.start[1],
                p.start[2].to_degrees(),
                (p.start[0] - s.x_m).hypot(p.start[1] - s.y_m),
                twindrive_kinematics::wrap_angle(p.start[2] - s.heading_rad)
                    .to_degrees()
                    .abs()
            )
        });
        let scans = mapped.mapping.poses.len();
        outcomes.push(match refused {
            Some(why) => LogUpdate::not_drawn(name, scans, matched, why),
            None => {
                grid = mapped.mapping.grid;
                LogUpdate {
                    log: name,
                    scans,
                    scans_matched: matched,
                    drawn: true,
                    refused: None,
                    placed,
                }
            }
        });
    }
    progress(total, total);
    let after = grid.cropped(4);
    let changes = changes(&before, &after);
    Ok(SiteUpdate {
        site: twin.name.clone(),
        before,
        after,
        logs: outcomes,
        changes,
    })
}

/// How the cells of `after` differ from the same places in `before`.
fn changes(before: &LogOddsGrid, after: &LogOddsGrid) -> CellChanges {
    let mut c = CellChanges::default();
    for row in 0..after.height() {
        for col in 0..after.width() {
            let now = after.state(col, row);
            let was = before.state_at(after.centre(col, row));
            match (was, now) {
                (CellState::Unknown, CellState::Free) => c.unknown_to_free += 1,
                (CellState::Unknown, CellState::Occupied) => c.unknown_to_occupied += 1,
                (CellState::Free, CellState::Occupied) => c.free_to_occupied += 1,
                (CellState::Occupied, CellState::Free) => c.occupied_to_free += 1,
                _ => {}
            }
        }
    }
    c
}

/// Writes the updated site into `dest` (a new version's directory),
/// whole or not at all: `map.pgm`, `map.yaml`, `site.toml` (the twin's
/// scenario at `twin_path` on the new map, and the commands file it names,
/// if any) and `update.json`. Nothing is written unless `site.toml` loads.
pub fn write_site_version(
    dest: &Path,
    twin_path: &Path,
    update: &SiteUpdate,
    report: &UpdateReport<'_>,
) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(twin_path)
        .with_context(|| format!("reading the twin's site {}", twin_path.display()))?;
    let mut doc: toml::Table = toml::from_str(&text)
        .with_context(|| format!("{}: not a TOML scenario", twin_path.display()))?;
    let world = doc
        .entry("world")
        .or_insert_with(|| toml::Table::new().into())
        .as_table_mut()
        .with_context(|| format!("{}: `world` is not a table", twin_path.display()))?;
    world.insert("map".into(), "map.yaml".into());
    let copy = commands_beside(&mut doc, twin_path, "the twin's site")?;
    let head = format!(
        "# Version {} of site `{}`, kept by `twindrive master --site-maps`: the twin's\n\
         # site with its map extended by the robot's logs (update.json says which).\n",
        report.version, update.site
    );
    let site = head + &toml::to_string(&doc)?;
    let (pgm, yaml) = map_files(&update.after);
    let staging = Staging::new(dest, "site-maps")?;
    staging.write_with("map.pgm", |w| Ok(w.write_all(&pgm)?))?;
    staging.write_with("map.yaml", |w| Ok(w.write_all(yaml.as_bytes())?))?;
    staging.write_with("site.toml", |w| Ok(w.write_all(site.as_bytes())?))?;
    if let Some(from) = &copy {
        stage_copy(&staging, from)?;
    }
    staging.write_with("update.json", |w| {
        serde_json::to_writer_pretty(w, report).map_err(Into::into)
    })?;
    Scenario::load(&staging.path("site.toml"))
        .context("the updated site.toml does not load as a scenario on its map; nothing written")?;
    staging.commit()
}
