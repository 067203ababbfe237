//! Progress of long work: a bar on a terminal; on a pipe (a log, CI), one
//! plain line at most every [`PIPED_EVERY`], so that no long run is silent
//! for more than a few seconds and a log is not flooded.

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle, TermLike};

pub mod stages;
pub use stages::{StageProgress, StageTime, Stages, process_cpu_s};

/// A progress line on a pipe at most this often.
pub const PIPED_EVERY: Duration = Duration::from_secs(3);

pub fn bar(total: u64, message: &str) -> ProgressBar {
    let bar = ProgressBar::new(total);
    if std::io::stderr().is_terminal() {
        bar.set_style(
            ProgressStyle::with_template(
                "{msg} [{bar:40}] {percent:>3}% {elapsed_precise} ETA {eta}",
            )
            .expect("static template")
            .progress_chars("=> "),
        );
    } else {
        bar.set_draw_target(ProgressDrawTarget::term_like(Box::new(Lines::default())));
        bar.set_style(
            ProgressStyle::with_template("{msg}: {pos}/{len} ({percent} %), {elapsed} so far")
                .expect("static template"),
        );
        // Redrawn every second even when no work completes; `Lines` keeps
        // one line in three.
        bar.enable_steady_tick(Duration::from_secs(1));
    }
    bar.set_message(message.to_string());
    bar
}

/// A stand-in terminal that writes each drawn line to stderr as a plain
/// line, at most one per [`PIPED_EVERY`] (the first one after that long:
/// work that ends sooner prints nothing), and the line of finished work
/// (100 %, drawn by `ProgressBar::finish`) always.
#[derive(Debug)]
pub struct Lines {
    /// When a line was last written, and whether the finished line was.
    last: Mutex<(Option<Instant>, bool)>,
}

impl Default for Lines {
    fn default() -> Self {
        Self {
            last: Mutex::new((Some(Instant::now()), false)),
        }
    }
}

impl Lines {
    fn line(&self, s: &str) -> std::io::Result<()> {
        let s = s.trim();
        if s.is_empty() {
            return Ok(());
        }
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        let now = Instant::now();
        // The line of finished work is said once, however soon: a log that
        // ends at "50 %" would say the work stopped halfway.
        let finished = s.contains("(100 %)");
        let say = if finished {
            !last.1
        } else {
            last.0.is_none_or(|t| now.duration_since(t) >= PIPED_EVERY)
        };
        if !say {
            return Ok(());
        }
        *last = (Some(now), last.1 || finished);
        writeln!(std::io::stderr().lock(), "{s}")
    }
}

impl TermLike for Lines {
    fn width(&self) -> u16 {
        200
    }
    fn move_cursor_up(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_down(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_right(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_left(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn write_line(&self, s: &str) -> std::io::Result<()> {
        self.line(s)
    }
    fn write_str(&self, s: &str) -> std::io::Result<()> {
        self.line(s)
    }
    fn clear_line(&self) -> std::io::Result<()> {
        Ok(())
    }
    fn flush(&self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

/// A long-running process's voice: event lines as they happen and, when
/// nothing was said for [`Voice::QUIET_AFTER`], what it is doing now. On a
/// terminal the latter is a live status line below the events; on a pipe
/// it is a plain line, so the process is never silent for long.
pub struct Voice {
    live: Option<ProgressBar>,
    last: Instant,
}

impl Voice {
    pub const QUIET_AFTER: Duration = Duration::from_secs(4);

    pub fn new() -> Self {
        let live = std::io::stderr().is_terminal().then(|| {
            let bar = ProgressBar::new_spinner();
            bar.enable_steady_tick(Duration::from_millis(250));
            bar
        });
        Self {
            live,
            last: Instant::now(),
        }
    }

    /// Plain lines even on a terminal (one of several voices in a process,
    /// which would fight over one live line).
    pub fn plain() -> Self {
        Self {
            live: None,
            last: Instant::now(),
        }
    }

    /// One event, now.
    pub fn say(&mut self, line: &str) {
        match &self.live {
            Some(bar) => bar.println(line),
            None => eprintln!("{line}"),
        }
        self.last = Instant::now();
    }

    /// What the process is doing now: the live line on a terminal; on a
    /// pipe, a line when nothing was said for a while. `status` is only
    /// called when it may be shown.
    pub fn status(&mut self, status: impl FnOnce() -> String) {
        match &self.live {
            Some(bar) => bar.set_message(status()),
            None => {
                if self.last.elapsed() >= Self::QUIET_AFTER {
                    eprintln!("{}", status());
                    self.last = Instant::now();
                }
            }
        }
    }
}

impl Default for Voice {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for Voice {
    fn drop(&mut self) {
        if let Some(bar) = &self.live {
            bar.finish_and_clear();
        }
    }
}
