//! The twin's map of each site, kept by the master across missions
//! (`twindrive master --site-maps DIR`):
//! - `DIR/<site>/0001/`, `0002/`, ...: each version of the site whole, as
//!   the twin runs on it (`site.toml`, `map.yaml`, `map.pgm`, and what the
//!   update that made it says, `update.json`);
//! - a version is written whole into a staging directory and renamed into
//!   place, and never changed after: the latest is the highest number, and
//!   every earlier one stays, so nothing the robot taught the twin is lost.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

/// The site maps a master keeps, under one directory.
#[derive(Debug, Clone)]
pub struct SiteMaps {
    dir: PathBuf,
}

/// One version of a site.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SiteVersion {
    pub number: u32,
    /// `DIR/<site>/NNNN`.
    pub dir: PathBuf,
}

impl SiteVersion {
    /// The scenario the twin runs on.
    pub fn site_toml(&self) -> PathBuf {
        self.dir.join("site.toml")
    }
}

impl SiteMaps {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// `DIR/<site>`; a site's name must be usable as a directory's.
    pub fn site_dir(&self, site: &str) -> anyhow::Result<PathBuf> {
        let ok = !site.is_empty()
            && site.len() <= 100
            && !site.starts_with('.')
            && site
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'));
        if !ok {
            bail!(
                "the site's name `{site}` cannot name its folder of maps: use up to 100 letters, digits, `_`, `-` and `.` (not first) in the scenario's `name`"
            );
        }
        Ok(self.dir.join(site))
    }

    /// Every version of `site` kept so far, oldest first.
    pub fn versions(&self, site: &str) -> anyhow::Result<Vec<SiteVersion>> {
        let dir = self.site_dir(site)?;
        let entries = match std::fs::read_dir(&dir) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(e) => return Err(e).with_context(|| format!("reading {}", dir.display())),
        };
        let mut versions = Vec::new();
        for entry in entries {
            let entry = entry.with_context(|| format!("reading {}", dir.display()))?;
            let name = entry.file_name();
            let Some(name) = name.to_str() else { continue };
            // Only NNNN directories are versions (staging directories and
            // anything else a person put there are not).
            if name.len() != 4 || !name.bytes().all(|b| b.is_ascii_digit()) {
                continue;
            }
            let number: u32 = name.parse().expect("four digits");
            if number > 0 && entry.path().join("site.toml").is_file() {
                versions.push(SiteVersion {
                    number,
                    dir: entry.path(),
                });
            }
        }
        versions.sort_by_key(|v| v.number);
        Ok(versions)
    }

    /// The latest version of `site`, if one was kept.
    pub fn latest(&self, site: &str) -> anyhow::Result<Option<SiteVersion>> {
        Ok(self.versions(site)?.pop())
    }

    /// Where the next version of `site` goes (not yet there).
    pub fn next(&self, site: &str) -> anyhow::Result<SiteVersion> {
        let number = self.latest(site)?.map_or(1, |v| v.number + 1);
        if number > 9999 {
            bail!(
                "{} holds 9,999 versions of site `{site}`: move the old ones away",
                self.site_dir(site)?.display()
            );
        }
        Ok(SiteVersion {
            number,
            dir: self.site_dir(site)?.join(format!("{number:04}")),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn versions_count_up_and_only_whole_ones_count() {
        let tmp = tempfile::tempdir().unwrap();
        let maps = SiteMaps::new(tmp.path().join("maps"));
        assert_eq!(maps.latest("lab").unwrap(), None);
        let first = maps.next("lab").unwrap();
        assert_eq!(first.number, 1);
        assert!(first.dir.ends_with("maps/lab/0001"));
        std::fs::create_dir_all(&first.dir).unwrap();
        // Not whole yet: no site.toml.
        assert_eq!(maps.latest("lab").unwrap(), None);
        std::fs::write(first.site_toml(), "name = \"lab\"").unwrap();
        assert_eq!(maps.latest("lab").unwrap(), Some(first.clone()));
        let second = maps.next("lab").unwrap();
        assert_eq!(second.number, 2);
        std::fs::create_dir_all(&second.dir).unwrap();
        std::fs::write(second.site_toml(), "").unwrap();
        // Not versions: staging directories, other names, 0000.
        for other in [".twindrive-staging-x", "notes", "0000", "12345"] {
            std::fs::create_dir_all(maps.site_dir("lab").unwrap().join(other)).unwrap();
        }
        let all = maps.versions("lab").unwrap();
        assert_eq!(all.iter().map(|v| v.number).collect::<Vec<_>>(), vec![1, 2]);
        assert_eq!(maps.next("lab").unwrap().number, 3);
        // Sites are apart.
        assert_eq!(maps.latest("mine_level_2").unwrap(), None);
    }

    #[test]
    fn a_name_that_cannot_be_a_folder_is_refused() {
        let maps = SiteMaps::new("maps");
        for bad in ["", "../up", "a/b", ".hidden", "sp ace", &"x".repeat(101)] {
            let e = maps.site_dir(bad).unwrap_err().to_string();
            assert!(e.contains("cannot name its folder"), "{bad}: {e}");
        }
        assert!(maps.site_dir("office-2.level_1").is_ok());
    }
}
