//! Where the robot agent keeps what it must not forget across restarts,
//! as a trait: the agent itself touches no file system. A process keeps it
//! in a state directory (`twindrive-store`'s `RobotDir`); in-process
//! missions and tests keep it in memory ([`MemoryRobotStore`]).

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard};

use twindrive_link::upload::{ChunkStore, MemoryStore};

/// The files of one robot log: what the robot recorded while it drove a
/// plan, as the master receives it (`log.mcap`) and for people and
/// spreadsheets (`log.csv`, `log.meta.json`).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct LogFiles {
    /// What comes home: `twindrive_log::digest`.
    pub digest: Vec<u8>,
    pub mcap: Vec<u8>,
    pub csv: Vec<u8>,
    pub meta_json: Vec<u8>,
}

/// The robot's durable state. Every write returns once a restart would
/// still see it; a failed write is reported and the robot carries on (its
/// safety never depends on its storage).
pub trait RobotStore {
    /// Where uploads in progress are kept.
    type Chunks: ChunkStore;
    /// The chunk store for uploads (taken once, when the agent starts).
    fn chunks(&mut self) -> std::io::Result<Self::Chunks>;
    /// The journal as written so far: JSON lines (empty before the first).
    fn read_journal(&mut self) -> std::io::Result<Vec<u8>>;
    /// Appends one journal line (its bytes end with a newline).
    fn append_journal(&mut self, line: &[u8]) -> std::io::Result<()>;
    /// The last plan counter accepted (0 before any).
    fn load_counter(&mut self) -> std::io::Result<u64>;
    fn store_counter(&mut self, counter: u64) -> std::io::Result<()>;
    /// Keeps an accepted plan document (byte for byte the master's
    /// `plan.json`), named by its content hash.
    fn store_plan(&mut self, plan_sha256: &str, plan_json: &[u8]) -> std::io::Result<()>;
    /// Keeps the robot's log of a plan it drove, until the master has it.
    fn store_log(&mut self, plan_sha256: &str, log: &LogFiles) -> std::io::Result<()>;
    /// The MCAP of a kept log (the full log).
    fn log_mcap(&mut self, plan_sha256: &str) -> std::io::Result<Vec<u8>>;
    /// The digest of a kept log (what back-fills to the master).
    fn log_digest(&mut self, plan_sha256: &str) -> std::io::Result<Vec<u8>>;
}

/// The journal's lines: every line that parses (a torn last line from a power cut is skipped).
pub fn parse_journal(journal: &[u8]) -> Vec<serde_json::Value> {
    journal
        .split(|&b| b == b'\n')
        .filter_map(|l| serde_json::from_slice(l).ok())
        .collect()
}

/// A robot's state in memory. Clones share one store, so a test (or an
/// in-process mission) can restart an agent on what it had, and read what
/// it wrote.
#[derive(Debug, Clone, Default)]
pub struct MemoryRobotStore {
    inner: Arc<Mutex<MemoryInner>>,
    chunks: MemoryStore,
}

#[derive(Debug, Default)]
struct MemoryInner {
    journal: Vec<u8>,
    counter: u64,
    plans: BTreeMap<String, Vec<u8>>,
    logs: BTreeMap<String, LogFiles>,
}

impl MemoryRobotStore {
    fn kept_log(&self, plan_sha256: &str) -> std::io::Result<LogFiles> {
        self.inner().logs.get(plan_sha256).cloned().ok_or_else(|| {
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("no log of plan {plan_sha256}"),
            )
        })
    }

    fn inner(&self) -> MutexGuard<'_, MemoryInner> {
        // A test that panicked while holding the lock leaves whole values.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The journal's bytes.
    pub fn journal(&self) -> Vec<u8> {
        self.inner().journal.clone()
    }

    /// The journal's lines, parsed.
    pub fn journal_lines(&self) -> Vec<serde_json::Value> {
        parse_journal(&self.inner().journal)
    }

    /// The last plan counter accepted.
    pub fn counter(&self) -> u64 {
        self.inner().counter
    }

    /// Sets the counter, as a robot that accepted plans before would have.
    pub fn set_counter(&self, counter: u64) {
        self.inner().counter = counter;
    }

    /// An accepted plan document, by its content hash.
    pub fn plan(&self, plan_sha256: &str) -> Option<Vec<u8>> {
        self.inner().plans.get(plan_sha256).cloned()
    }

    /// A kept robot log, by its plan's content hash.
    pub fn log(&self, plan_sha256: &str) -> Option<LogFiles> {
        self.inner().logs.get(plan_sha256).cloned()
    }
}

impl RobotStore for MemoryRobotStore {
    type Chunks = MemoryStore;

    fn chunks(&mut self) -> std::io::Result<MemoryStore> {
        Ok(self.chunks.clone())
    }

    fn read_journal(&mut self) -> std::io::Result<Vec<u8>> {
        Ok(self.journal())
    }

    fn append_journal(&mut self, line: &[u8]) -> std::io::Result<()> {
        self.inner().journal.extend_from_slice(line);
        Ok(())
    }

    fn load_counter(&mut self) -> std::io::Result<u64> {
        Ok(self.counter())
    }

    fn store_counter(&mut self, counter: u64) -> std::io::Result<()> {
        self.set_counter(counter);
        Ok(())
    }

    fn store_plan(&mut self, plan_sha256: &str, plan_json: &[u8]) -> std::io::Result<()> {
        self.inner()
            .plans
            .insert(plan_sha256.into(), plan_json.to_vec());
        Ok(())
    }

    fn store_log(&mut self, plan_sha256: &str, log: &LogFiles) -> std::io::Result<()> {
        self.inner().logs.insert(plan_sha256.into(), log.clone());
        Ok(())
    }

    fn log_mcap(&mut self, plan_sha256: &str) -> std::io::Result<Vec<u8>> {
        self.kept_log(plan_sha256).map(|l| l.mcap)
    }

    fn log_digest(&mut self, plan_sha256: &str) -> std::io::Result<Vec<u8>> {
        self.kept_log(plan_sha256).map(|l| l.digest)
    }
}
