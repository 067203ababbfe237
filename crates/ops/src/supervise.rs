//! One robot's operator driven over the master's network until its
//! mission is decided and its logs are in, its plans and logs written as
//! they come, and what happens said as `-q`/`-v` ask.

use std::time::Duration;

use twindrive_agent::narrate::{Narrator, Verbosity};
use twindrive_agent::operator::Operator;
use twindrive_net::Emulation;
use twindrive_store::{DirStore, MasterArchive};

/// One robot the master supervises.
pub struct Supervised {
    pub robot: String,
    /// Its output directory (`--out`, or `--out/<id>` in a fleet).
    pub archive: MasterArchive,
    pub op: Operator<DirStore>,
    pub stats: twindrive_net::DriveStats,
    /// Its link: key expressions and sealing.
    pub link: twindrive_net::LinkEnd,
}

/// A file the master could not write (its mission may have gone well).
#[derive(Debug)]
pub struct WriteError(anyhow::Error);

impl std::fmt::Display for WriteError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:#}", self.0)
    }
}

impl std::error::Error for WriteError {}

/// What the master says about one robot: its events, and what it waits
/// for (a live line on a terminal, a line after a quiet while on a pipe),
/// as `-q`/`-v` ask.
struct Speaker {
    narrator: Narrator,
    /// `None` when quiet.
    voice: Option<twindrive_progress::Voice>,
}

impl Speaker {
    /// `live`: a live line on a terminal (one robot; a fleet's robots say
    /// plain lines).
    fn new(robot: &str, verbosity: Verbosity, live: bool) -> Self {
        let voice = if live {
            twindrive_progress::Voice::new
        } else {
            twindrive_progress::Voice::plain
        };
        Self {
            narrator: Narrator::new(robot, verbosity),
            voice: (verbosity != Verbosity::Quiet).then(voice),
        }
    }

    fn say(&mut self, line: &str) {
        if let Some(voice) = &mut self.voice {
            voice.say(line);
        }
    }

    fn tell(&mut self, op: &Operator<DirStore>, now_ns: u64) {
        let Some(voice) = &mut self.voice else {
            return;
        };
        for line in self.narrator.lines(op, now_ns) {
            voice.say(&line);
        }
        voice.status(|| self.narrator.waiting_line(op, now_ns));
    }
}

/// Drives one robot's operator over the network until its mission is
/// decided and its logs are in; writes its plans and logs as they come.
pub async fn supervise(
    m: &mut Supervised,
    network: &twindrive_net::Network,
    emulation: Option<Emulation>,
    deadline: Duration,
    zero: std::time::Instant,
    show_progress: bool,
    verbosity: Verbosity,
) -> anyhow::Result<()> {
    let robot = m.robot.clone();
    let archive = &mut m.archive;
    let mut speaker = Speaker::new(&robot, verbosity, show_progress);
    let mut write_error: Option<anyhow::Error> = None;
    let r = twindrive_net::drive_counting(
        &mut m.op,
        network,
        &mut m.link,
        emulation,
        deadline,
        zero,
        &mut m.stats,
        |op| {
            let now_ns = zero.elapsed().as_nanos() as u64;
            if op.master.upload_finished() {
                archive.upload_finished();
            }
            while let Some((plan, json, signed)) = op.new_plans.pop_front() {
                if let Err(e) = archive.write_plan(&plan, &json, Some(&signed)) {
                    write_error.get_or_insert(
                        anyhow::Error::new(e)
                            .context(format!("writing a plan into {}", archive.dir().display())),
                    );
                }
            }
            while let Some(log) = op.new_logs.pop_front() {
                match archive.write_robot_log(log.plan.as_deref(), &log.mcap, log.full_rate) {
                    Ok(written) => {
                        let dir = written.dir.display().to_string();
                        speaker.say(&format!("{robot}: robot log written to {dir}"));
                        op.report.robot_logs.push(dir);
                    }
                    Err(e) => {
                        write_error.get_or_insert(e);
                    }
                }
            }
            speaker.tell(op, now_ns);
            op.is_done()
        },
    )
    .await;
    if let Some(e) = write_error {
        return Err(WriteError(e).into());
    }
    r
}
