//! Files written so that a crash or a power cut leaves them whole or absent.

use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes `data` to a temporary file beside `path`, syncs it and renames it
/// into place: the file is whole or absent, even across a crash.
pub fn write_durably(path: &Path, data: &[u8]) -> std::io::Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let mut f = std::fs::File::create(&tmp)?;
    f.write_all(data)?;
    f.sync_all()?;
    std::fs::rename(&tmp, path)?;
    if let Some(dir) = path.parent()
        && let Ok(d) = std::fs::File::open(dir)
    {
        // The rename itself survives a power cut once the directory is synced.
        let _ = d.sync_all();
    }
    Ok(())
}

/// Appends `bytes` to `path` (created if missing) and syncs the data: once
/// this returns, a restart reads them (a power cut mid-write can leave a
/// torn last line, which readers skip).
pub fn append_synced(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)?;
    f.write_all(bytes)?;
    f.sync_data()
}
