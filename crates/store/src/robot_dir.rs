//! The robot's state directory.

use std::path::{Path, PathBuf};

use twindrive_agent::store::{LogFiles, RobotStore};

use twindrive_files::{append_synced, write_durably};

use crate::{CounterFile, DirStore};

/// A robot's durable state in one directory:
/// - `journal.jsonl`: one JSON object per line, synced on every line;
/// - `counter`: the last plan counter accepted (replays stay closed);
/// - `chunks/`: uploads in progress;
/// - `plans/<sha256>.json`: every accepted plan document, byte for byte the
///   master's `plan.json` (named by its content hash);
/// - `logs/<sha256>/`: the robot's own log of each plan it drove
///   (`log.mcap`, `log.csv`, `log.meta.json`, and `log.digest`, what comes
///   home), kept until the master acknowledges it.
#[derive(Debug, Clone)]
pub struct RobotDir {
    dir: PathBuf,
    counter: CounterFile,
}

impl RobotDir {
    /// Opens (creating what is missing) the state directory `dir`.
    pub fn open(dir: impl Into<PathBuf>) -> std::io::Result<Self> {
        let dir = dir.into();
        for sub in ["chunks", "plans", "logs"] {
            std::fs::create_dir_all(dir.join(sub))?;
        }
        Ok(Self {
            counter: CounterFile::new(dir.join("counter")),
            dir,
        })
    }

    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// The journal's lines in the state directory `dir` (none when it has
    /// no journal yet; a torn last line is skipped).
    pub fn journal(dir: &Path) -> std::io::Result<Vec<serde_json::Value>> {
        Ok(twindrive_agent::store::parse_journal(&journal_bytes(dir)?))
    }

    fn log_dir(&self, plan_sha256: &str) -> PathBuf {
        self.dir.join("logs").join(plan_sha256)
    }

    fn read_log_file(&self, plan_sha256: &str, name: &str) -> std::io::Result<Vec<u8>> {
        let path = self.log_dir(plan_sha256).join(name);
        std::fs::read(&path)
            .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", path.display())))
    }
}

/// The journal's bytes in the state directory `dir` (none before its first line).
fn journal_bytes(dir: &Path) -> std::io::Result<Vec<u8>> {
    match std::fs::read(dir.join("journal.jsonl")) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Vec::new()),
        read => read,
    }
}

impl RobotStore for RobotDir {
    type Chunks = DirStore;

    fn chunks(&mut self) -> std::io::Result<DirStore> {
        Ok(DirStore::new(self.dir.join("chunks")))
    }

    fn read_journal(&mut self) -> std::io::Result<Vec<u8>> {
        journal_bytes(&self.dir)
    }

    fn append_journal(&mut self, line: &[u8]) -> std::io::Result<()> {
        append_synced(&self.dir.join("journal.jsonl"), line)
    }

    fn load_counter(&mut self) -> std::io::Result<u64> {
        self.counter.load()
    }

    fn store_counter(&mut self, counter: u64) -> std::io::Result<()> {
        self.counter.store(counter)
    }

    fn store_plan(&mut self, plan_sha256: &str, plan_json: &[u8]) -> std::io::Result<()> {
        let path = self.dir.join("plans").join(format!("{plan_sha256}.json"));
        write_durably(&path, plan_json)
    }

    fn store_log(&mut self, plan_sha256: &str, log: &LogFiles) -> std::io::Result<()> {
        let dir = self.log_dir(plan_sha256);
        std::fs::create_dir_all(&dir)?;
        write_durably(&dir.join("log.csv"), &log.csv)?;
        write_durably(&dir.join("log.meta.json"), &log.meta_json)?;
        write_durably(&dir.join("log.digest"), &log.digest)?;
        // The MCAP last: the one a restart looks for.
        write_durably(&dir.join("log.mcap"), &log.mcap)
    }

    fn log_mcap(&mut self, plan_sha256: &str) -> std::io::Result<Vec<u8>> {
        self.read_log_file(plan_sha256, "log.mcap")
    }

    fn log_digest(&mut self, plan_sha256: &str) -> std::io::Result<Vec<u8>> {
        self.read_log_file(plan_sha256, "log.digest")
    }
}
