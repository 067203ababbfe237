//! The last plan counter a robot accepted, in one file.

use std::path::PathBuf;

/// The last plan counter a robot accepted, kept in one file (written to a
/// temporary file, synced, renamed): a restart does not reopen replays.
#[derive(Debug, Clone)]
pub struct CounterFile {
    path: PathBuf,
}

impl CounterFile {
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self { path: path.into() }
    }

    /// 0 when the file does not exist yet.
    pub fn load(&self) -> std::io::Result<u64> {
        match std::fs::read_to_string(&self.path) {
            Ok(text) => text.trim().parse().map_err(|e| {
                std::io::Error::other(format!("{}: not a counter: {e}", self.path.display()))
            }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(0),
            Err(e) => Err(e),
        }
    }

    pub fn store(&self, counter: u64) -> std::io::Result<()> {
        twindrive_files::write_durably(&self.path, format!("{counter}\n").as_bytes())
    }
}
