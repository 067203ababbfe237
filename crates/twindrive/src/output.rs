//! Output directories: files are written into a hidden staging directory
//! next to the destination and moved in only when everything succeeded, so
//! a failure leaves no partial output, and files already in the destination
//! that we do not produce are kept.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::Context;

pub struct Staging {
    dest: PathBuf,
    dir: tempfile::TempDir,
}

impl Staging {
    pub fn new(dest: &Path) -> anyhow::Result<Self> {
        let parent = match dest.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        if dest.exists() && !dest.is_dir() {
            anyhow::bail!("{} exists and is not a directory", dest.display());
        }
        std::fs::create_dir_all(&parent)
            .with_context(|| format!("creating {}", parent.display()))?;
        let dir = tempfile::Builder::new()
            .prefix(".twindrive-staging-")
            .tempdir_in(&parent)
            .with_context(|| format!("creating a staging directory in {}", parent.display()))?;
        Ok(Self {
            dest: dest.to_path_buf(),
            dir,
        })
    }

    pub fn dir(&self) -> &Path {
        self.dir.path()
    }

    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
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

    /// Moves everything into the destination. A missing destination is
    /// created by renaming the whole staging directory.
    pub fn commit(self) -> anyhow::Result<()> {
        if !self.dest.exists() {
            let staged = self.dir.keep();
            std::fs::rename(&staged, &self.dest)
                .with_context(|| format!("moving results into {}", self.dest.display()))?;
            return Ok(());
        }
        for entry in std::fs::read_dir(self.dir.path())? {
            let entry = entry?;
            let target = self.dest.join(entry.file_name());
            std::fs::rename(entry.path(), &target).with_context(|| {
                format!(
                    "moving {} into {}",
                    entry.file_name().to_string_lossy(),
                    self.dest.display()
                )
            })?;
        }
        Ok(())
    }
}
