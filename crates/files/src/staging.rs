//! Output directories. Files are written into a hidden staging directory
//! next to the destination and moved in only when every one was written:
//! a failure leaves no partial output and no new directories. Into an
//! existing directory the files move one by one, and a failed move puts back
//! what was there. Files twindrive wrote there last time (listed in
//! `.twindrive-files`) and does not write now are removed; anything else in
//! the directory is left alone.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

/// Lists the files twindrive wrote into a directory.
const MANIFEST: &str = ".twindrive-files";

pub struct Staging {
    dest: PathBuf,
    /// Which command wrote the files; only its own stale files are removed.
    producer: String,
    dir: Option<tempfile::TempDir>,
    /// The outermost directory this staging created, removed again if the
    /// output is never committed.
    created: Option<PathBuf>,
}

impl Staging {
    pub fn new(dest: &Path, producer: &str) -> anyhow::Result<Self> {
        if dest.exists() && !dest.is_dir() {
            bail!("{} exists and is not a directory", dest.display());
        }
        let parent = match dest.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let created = parent
            .ancestors()
            .take_while(|a| !a.as_os_str().is_empty() && !a.exists())
            .last()
            .map(Path::to_path_buf);
        std::fs::create_dir_all(&parent)
            .with_context(|| format!("creating {}", parent.display()))?;
        let dir = tempfile::Builder::new()
            .prefix(".twindrive-staging-")
            .tempdir_in(&parent)
            .with_context(|| format!("creating a staging directory in {}", parent.display()))?;
        Ok(Self {
            dest: dest.to_path_buf(),
            producer: producer.to_string(),
            dir: Some(dir),
            created,
        })
    }

    pub fn dir(&self) -> &Path {
        self.dir.as_ref().expect("present until commit").path()
    }

    pub fn path(&self, name: &str) -> PathBuf {
        self.dir().join(name)
    }

    /// Creates `name` in the staging directory and fills it with `write`.
    pub fn write_with(
        &self,
        name: &str,
        write: impl FnOnce(&mut BufWriter<File>) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        let path = self.path(name);
        let file = File::create(&path).with_context(|| format!("creating {name}"))?;
        let mut w = BufWriter::new(file);
        write(&mut w).with_context(|| format!("writing {name}"))?;
        w.flush().with_context(|| format!("writing {name}"))?;
        Ok(())
    }

    /// Moves everything into the destination.
    pub fn commit(mut self) -> anyhow::Result<()> {
        let staged = self.dir().to_path_buf();
        let mut names: Vec<String> = std::fs::read_dir(&staged)?
            .map(|e| e.map(|e| e.file_name().to_string_lossy().into_owned()))
            .collect::<Result<_, _>>()?;
        names.sort();
        // The list: `producer<TAB>file` lines, ours replacing our old ones.
        let previous: Vec<(String, String)> = std::fs::read_to_string(self.dest.join(MANIFEST))
            .map(|t| {
                t.lines()
                    .filter_map(|l| l.split_once('\t'))
                    .map(|(p, n)| (p.to_owned(), n.to_owned()))
                    .collect()
            })
            .unwrap_or_default();
        let mut manifest: Vec<String> = previous
            .iter()
            .filter(|(p, n)| *p != self.producer && !names.contains(n))
            .map(|(p, n)| format!("{p}\t{n}"))
            .collect();
        manifest.extend(names.iter().map(|n| format!("{}\t{n}", self.producer)));
        std::fs::write(staged.join(MANIFEST), manifest.join("\n") + "\n")
            .context("writing the file list")?;

        if !self.dest.exists() {
            std::fs::rename(&staged, &self.dest)
                .with_context(|| format!("moving results into {}", self.dest.display()))?;
            // Renamed away: nothing left for the TempDir to delete.
            let _ = self.dir.take().map(tempfile::TempDir::keep);
            self.created = None;
            return Ok(());
        }

        // Never overwrite what twindrive did not write.
        for name in &names {
            if self.dest.join(name).exists() && !previous.iter().any(|(_, n)| n == name) {
                bail!(
                    "{} already exists and was not written by twindrive; move it away or choose another output directory",
                    self.dest.join(name).display()
                );
            }
        }
        let names_with_manifest: Vec<&str> =
            names.iter().map(String::as_str).chain([MANIFEST]).collect();
        move_all(&names_with_manifest, &staged, &self.dest, |from, to| {
            std::fs::rename(from, to)
        })?;
        // This command's files from its last run that it did not write now.
        for (_, stale) in previous
            .iter()
            .filter(|(p, n)| *p == self.producer && !names.contains(n))
        {
            if !stale.contains(['/', '\\']) && stale != MANIFEST {
                let _ = std::fs::remove_file(self.dest.join(stale));
            }
        }
        Ok(())
    }
}

/// Moves `names` from `staged` into `dest`, keeping previous versions in
/// `staged/.previous` until all moves succeeded; on a failure every move is
/// undone.
fn move_all(
    names: &[&str],
    staged: &Path,
    dest: &Path,
    mut rename: impl FnMut(&Path, &Path) -> std::io::Result<()>,
) -> anyhow::Result<()> {
    let backup = staged.join(".previous");
    std::fs::create_dir(&backup)?;
    let mut moved: Vec<(&str, bool)> = Vec::new(); // (name, had a previous version)
    for &name in names {
        let target = dest.join(name);
        let had = target.exists();
        if had && let Err(e) = rename(&target, &backup.join(name)) {
            undo(&moved, dest, &backup);
            return Err(anyhow::Error::new(e).context(format!("moving the previous {name} aside")));
        }
        if let Err(e) = rename(&staged.join(name), &target) {
            if had {
                let _ = std::fs::rename(backup.join(name), &target);
            }
            undo(&moved, dest, &backup);
            return Err(
                anyhow::Error::new(e).context(format!("moving {name} into {}", dest.display()))
            );
        }
        moved.push((name, had));
    }
    Ok(())
}

fn undo(moved: &[(&str, bool)], dest: &Path, backup: &Path) {
    for (name, had) in moved.iter().rev() {
        let target = dest.join(name);
        let _ = std::fs::remove_file(&target);
        if *had {
            let _ = std::fs::rename(backup.join(name), &target);
        }
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        // Delete the staging directory first, then any directories we created.
        drop(self.dir.take());
        if let Some(created) = self.created.take() {
            let parent = match self.dest.parent() {
                Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
                _ => return,
            };
            for dir in parent.ancestors() {
                if std::fs::remove_dir(dir).is_err() || dir == created {
                    break;
                }
            }
        }
    }
}

/// Splits an `--out` file path into (directory, stem, file name); the stem
/// names the files written beside it. `default_stem` when the name has none.
pub fn split_out_path(
    out: &Path,
    default_stem: &str,
) -> anyhow::Result<(std::path::PathBuf, String, String)> {
    let file_name = out
        .file_name()
        .context("--out needs a file name")?
        .to_string_lossy()
        .into_owned();
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| default_stem.into());
    let dir = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    Ok((dir, stem, file_name))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn uncommitted_output_leaves_nothing() {
        let tmp = tempfile::tempdir().unwrap();
        let dest = tmp.path().join("a/b/out");
        let s = Staging::new(&dest, "test").unwrap();
        s.write_with("x.txt", |w| Ok(w.write_all(b"x")?)).unwrap();
        drop(s);
        assert!(names(tmp.path()).is_empty(), "{:?}", names(tmp.path()));
    }

    #[test]
    fn replaces_own_files_keeps_others_removes_stale() {
        let tmp = tempfile::tempdir().unwrap();
        let dest = tmp.path().join("out");
        let s = Staging::new(&dest, "test").unwrap();
        s.write_with("a.txt", |w| Ok(w.write_all(b"1")?)).unwrap();
        s.write_with("old.txt", |w| Ok(w.write_all(b"1")?)).unwrap();
        s.commit().unwrap();
        std::fs::write(dest.join("mine.txt"), "user").unwrap();

        let s = Staging::new(&dest, "test").unwrap();
        s.write_with("a.txt", |w| Ok(w.write_all(b"2")?)).unwrap();
        s.commit().unwrap();
        assert_eq!(names(&dest), vec![".twindrive-files", "a.txt", "mine.txt"]);
        // Another command's files in the same directory are left alone.
        let s = Staging::new(&dest, "other").unwrap();
        s.write_with("b.txt", |w| Ok(w.write_all(b"b")?)).unwrap();
        s.commit().unwrap();
        let s = Staging::new(&dest, "test").unwrap();
        s.write_with("a.txt", |w| Ok(w.write_all(b"3")?)).unwrap();
        s.commit().unwrap();
        assert_eq!(
            names(&dest),
            vec![".twindrive-files", "a.txt", "b.txt", "mine.txt"]
        );
        assert_eq!(std::fs::read_to_string(dest.join("a.txt")).unwrap(), "3");
        assert_eq!(names(tmp.path()), vec!["out"]);
    }

    #[test]
    fn a_failed_move_restores_the_previous_files() {
        let tmp = tempfile::tempdir().unwrap();
        let (staged, dest) = (tmp.path().join("staged"), tmp.path().join("dest"));
        std::fs::create_dir_all(&staged).unwrap();
        std::fs::create_dir_all(&dest).unwrap();
        for n in ["a", "b", "c"] {
            std::fs::write(staged.join(n), "new").unwrap();
        }
        std::fs::write(dest.join("a"), "old").unwrap();
        std::fs::write(dest.join("b"), "old").unwrap();
        let err = move_all(&["a", "b", "c"], &staged, &dest, |from, to| {
            if to.ends_with("c") {
                Err(std::io::Error::other("disk full"))
            } else {
                std::fs::rename(from, to)
            }
        })
        .unwrap_err();
        assert!(format!("{err:#}").contains("moving c into"), "{err:#}");
        assert_eq!(names(&dest), vec!["a", "b"]);
        assert_eq!(std::fs::read_to_string(dest.join("a")).unwrap(), "old");
        assert_eq!(std::fs::read_to_string(dest.join("b")).unwrap(), "old");
    }

    #[test]
    fn files_not_written_by_twindrive_are_never_replaced() {
        let tmp = tempfile::tempdir().unwrap();
        let dest = tmp.path().join("out");
        std::fs::create_dir(&dest).unwrap();
        std::fs::write(dest.join("a.txt"), "user").unwrap();
        let s = Staging::new(&dest, "test").unwrap();
        s.write_with("a.txt", |w| Ok(w.write_all(b"new")?)).unwrap();
        let err = s.commit().unwrap_err().to_string();
        assert!(
            err.contains("a.txt already exists and was not written by twindrive"),
            "{err}"
        );
        assert_eq!(std::fs::read_to_string(dest.join("a.txt")).unwrap(), "user");
        assert_eq!(names(tmp.path()), vec!["out"]);
    }
}
