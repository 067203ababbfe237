//! The master's output folder: one layout for `twindrive master`, the
//! console and the in-process missions.

use std::path::{Path, PathBuf};

use twindrive_log::MissionLog;
use twindrive_mission::plan::MissionPlan;

use twindrive_files::write_durably;

use crate::DirStore;

/// What a master keeps of a mission, in one directory:
/// - `plans/<sha256>.json`: every plan document, byte for byte what was
///   signed (the robot keeps the same file under the same name);
/// - `plans/<sha256>.signed`: the signed file that was uploaded;
/// - `plans/<sha256>.rehearsal.mcap`: the twin's run a plan was made from
///   (plans made in the console);
/// - `robot_logs/NN_<sha12>/`: each robot log as it came back, numbered in
///   order of arrival and named by its plan (see [`crate::robot_log`]);
/// - `report.json`: the mission's report;
/// - `state/`: what a restarted master resumes from (`uploading.signed`,
///   the upload in progress; `log_chunks/`, robot logs in progress).
#[derive(Debug, Clone)]
pub struct MasterArchive {
    dir: PathBuf,
    logs_written: usize,
}

/// A robot log written into the archive.
#[derive(Debug)]
pub struct ArchivedLog {
    /// `robot_logs/NN_<sha12>`, under the archive's directory.
    pub dir: PathBuf,
    /// `robot_logs/NN_<sha12>`, relative to the archive.
    pub name: String,
    pub log: MissionLog,
}

impl MasterArchive {
    /// The archive in `dir` (made as things are written into it).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            logs_written: 0,
        }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn report_path(&self) -> PathBuf {
        self.dir.join("report.json")
    }

    /// Where robot logs wait while they arrive.
    pub fn log_chunks(&self) -> DirStore {
        DirStore::new(self.dir.join("state").join("log_chunks"))
    }

    /// Where the upload in progress is kept.
    pub fn upload_path(&self) -> PathBuf {
        self.dir.join("state").join("uploading.signed")
    }

    /// The signed plan an earlier run of the master was uploading, if any.
    pub fn unfinished_upload(&self) -> Option<Vec<u8>> {
        std::fs::read(self.upload_path()).ok()
    }

    /// Keeps the signed plan being uploaded, so a restarted master resumes it.
    pub fn keep_upload(&self, signed: &[u8]) -> std::io::Result<()> {
        std::fs::create_dir_all(self.dir.join("state"))?;
        write_durably(&self.upload_path(), signed)
    }

    /// The upload is done: nothing to resume.
    pub fn upload_finished(&self) {
        let _ = std::fs::remove_file(self.upload_path());
    }

    fn plan_path(&self, plan_sha256: &str, extension: &str) -> PathBuf {
        self.dir
            .join("plans")
            .join(format!("{plan_sha256}.{extension}"))
    }

    /// `plans/<sha256>.json` and, when signed, `plans/<sha256>.signed`;
    /// returns the document's path.
    pub fn write_plan(
        &self,
        plan: &MissionPlan,
        json: &[u8],
        signed: Option<&[u8]>,
    ) -> std::io::Result<PathBuf> {
        std::fs::create_dir_all(self.dir.join("plans"))?;
        let path = self.plan_path(&plan.sha256, "json");
        write_durably(&path, json)?;
        if let Some(signed) = signed {
            write_durably(&self.plan_path(&plan.sha256, "signed"), signed)?;
        }
        Ok(path)
    }

    /// `plans/<sha256>.rehearsal.mcap`: the twin's run a plan was made from.
    pub fn write_rehearsal(&self, plan_sha256: &str, mcap: &[u8]) -> std::io::Result<PathBuf> {
        std::fs::create_dir_all(self.dir.join("plans"))?;
        let path = self.plan_path(plan_sha256, "rehearsal.mcap");
        write_durably(&path, mcap)?;
        Ok(path)
    }

    /// The next robot log, `robot_logs/NN_<sha12>/` (`NN` without a plan;
    /// `_full` after it for a full-rate log, else it is made from the
    /// digest that came over the link).
    pub fn write_robot_log(
        &mut self,
        plan: Option<&MissionPlan>,
        mcap: &[u8],
        full_rate: bool,
    ) -> anyhow::Result<ArchivedLog> {
        let n = self.logs_written + 1;
        let full = if full_rate { "_full" } else { "" };
        let name = match plan {
            Some(p) => format!("robot_logs/{n:02}_{}{full}", &p.sha256[..12]),
            None => format!("robot_logs/{n:02}{full}"),
        };
        let dir = self.dir.join(&name);
        let log = crate::robot_log::write_robot_log(&dir, plan, mcap)?;
        self.logs_written = n;
        Ok(ArchivedLog { dir, name, log })
    }

    /// Robot logs written so far.
    pub fn logs_written(&self) -> usize {
        self.logs_written
    }

    /// `report.json`.
    pub fn write_report(&self, json: &[u8]) -> std::io::Result<PathBuf> {
        std::fs::create_dir_all(&self.dir)?;
        let path = self.report_path();
        write_durably(&path, json)?;
        Ok(path)
    }
}
