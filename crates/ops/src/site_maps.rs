//! `twindrive master --site-maps DIR`: the twin's map of its site, kept
//! across missions. Before the mission the twin runs on the latest
//! version kept ([`KeptSite::resolve`]); after it, the robot logs that
//! came back extend the map into the next version ([`KeptSite::update`]).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use twindrive_calibrate::site_update::{
    RobotLog, UpdateSettings, check_twin, update_site, write_site_version,
};
use twindrive_kinematics::DiffDriveParams;
use twindrive_sim::Scenario;
use twindrive_store::SiteMaps;

/// The twin's site as kept in `--site-maps`.
#[derive(Debug)]
pub struct KeptSite {
    maps: SiteMaps,
    /// The site's name (its scenario's `name`).
    pub site: String,
    /// The site.toml the twin runs on: the latest version kept, or
    /// `--scenario` when none is yet.
    pub path: PathBuf,
    /// The version `path` is, if one.
    pub version: Option<u32>,
}

/// A robot's logs that came back, and its wheels as the twin knows them.
pub struct ReturnedLogs<'a> {
    pub dirs: &'a [String],
    pub params: DiffDriveParams,
}

impl KeptSite {
    /// The twin's site for a master given `--scenario scenario` and
    /// `--site-maps dir`. Refuses a site the map cannot be kept of (no map,
    /// no lidar) before anything is sent.
    pub fn resolve(dir: &Path, scenario: &Path) -> anyhow::Result<Self> {
        let given = Scenario::load(scenario).map_err(|e| anyhow::anyhow!("--scenario: {e}"))?;
        check_twin(&given).context("--site-maps")?;
        let maps = SiteMaps::new(dir);
        let site = given.name.clone();
        let latest = maps.latest(&site).context("--site-maps")?;
        let kept = match latest {
            Some(v) => {
                let kept = Scenario::load(&v.site_toml())
                    .map_err(|e| anyhow::anyhow!("--site-maps: {e}"))?;
                check_twin(&kept).with_context(|| format!("--site-maps: {}", v.dir.display()))?;
                Self {
                    maps,
                    site,
                    path: v.site_toml(),
                    version: Some(v.number),
                }
            }
            None => Self {
                maps,
                site,
                path: scenario.to_path_buf(),
                version: None,
            },
        };
        Ok(kept)
    }

    /// What the master says of the twin's site before the mission.
    pub fn describe(&self) -> String {
        match self.version {
            Some(v) => format!(
                "the twin runs on site `{}` as kept in {} (version {v})",
                self.site,
                self.path.parent().unwrap_or(Path::new(".")).display()
            ),
            None => format!(
                "no map of site `{}` is kept in {} yet: the twin runs on --scenario, and the robot's logs start the site's versions",
                self.site,
                self.maps.dir().display()
            ),
        }
    }

    /// Extends the map with the robot logs that came back (read from their
    /// directories), into the next version, and says what changed on `out`.
    pub fn update(
        &self,
        returned: &[ReturnedLogs<'_>],
        out: &mut impl Write,
        quiet: bool,
    ) -> anyhow::Result<()> {
        let mut logs = Vec::new();
        for r in returned {
            for dir in r.dirs {
                let path = Path::new(dir).join("log.mcap");
                let log = twindrive_log::read_mcap(&path)
                    .with_context(|| format!("reading the robot log {}", path.display()))?;
                logs.push((dir.clone(), log, r.params));
            }
        }
        if logs.is_empty() {
            writeln!(
                out,
                "site map: no robot log came back; site `{}` stays as it was",
                self.site
            )?;
            return Ok(());
        }
        let twin = Scenario::load(&self.path)
            .map_err(|e| anyhow::anyhow!("the twin's site {}: {e}", self.path.display()))?;
        let inputs: Vec<RobotLog<'_>> = logs
            .iter()
            .map(|(name, log, params)| RobotLog {
                name,
                log,
                params: *params,
            })
            .collect();
        let bar = (!quiet).then(|| twindrive_progress::bar(0, "updating the site's map"));
        let update = update_site(&twin, &inputs, &UpdateSettings::default(), |done, total| {
            if let Some(bar) = &bar {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            }
        })?;
        if let Some(bar) = bar {
            bar.finish_and_clear();
        }
        for l in &update.logs {
            if let Some(placed) = &l.placed {
                writeln!(out, "site map: {} {placed}", l.log)?;
            }
        }
        for l in update.logs.iter().filter(|l| !l.drawn) {
            writeln!(
                out,
                "site map: {} not drawn: {}",
                l.log,
                l.refused.as_deref().unwrap_or("refused")
            )?;
        }
        if !update.drawn() {
            writeln!(
                out,
                "site map: site `{}` stays as it was (no log agreed with its map)",
                self.site
            )?;
            return Ok(());
        }
        let next = self.maps.next(&self.site).context("--site-maps")?;
        let report = update.report(next.number, self.version);
        write_site_version(&next.dir, &self.path, &update, &report)
            .with_context(|| format!("writing {}", next.dir.display()))?;
        let (before, after) = (report.cells_before, report.cells_after);
        let c = report.changes;
        let drawn: Vec<_> = update.logs.iter().filter(|l| l.drawn).collect();
        writeln!(
            out,
            "site map: site `{}` version {} from {} robot log(s), {} of {} scans matched the map: {} cells known (was {}); {} newly free, {} newly occupied, {} free turned occupied, {} occupied turned free -> {}",
            self.site,
            next.number,
            drawn.len(),
            drawn.iter().map(|l| l.scans_matched).sum::<usize>(),
            drawn.iter().map(|l| l.scans).sum::<usize>(),
            after.known(),
            before.known(),
            c.unknown_to_free,
            c.unknown_to_occupied,
            c.free_to_occupied,
            c.occupied_to_free,
            next.site_toml().display()
        )?;
        Ok(())
    }
}
