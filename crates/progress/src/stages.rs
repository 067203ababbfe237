//! Long work in named stages that is never silent for long: each stage
//! says what it does when it starts and, while it runs, at least every
//! [`Stages::PULSE`] (its progress where the work reports it, otherwise
//! how long it has run); its wall and CPU time are kept for the caller.
//!
//! On a terminal the running stage is a live line below the finished
//! ones; on a pipe every line is a plain line. A stage whose work draws
//! its own bar ([`Stages::run_with_bar`]) keeps quiet on a terminal while
//! it runs, so that the two live lines do not fight.

use std::io::{IsTerminal, Write};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// What one stage took.
#[derive(Clone, Debug, PartialEq)]
pub struct StageTime {
    pub name: String,
    pub wall_s: f64,
    /// The process's CPU time (user and system, every thread) over the
    /// stage, where the system tells.
    pub cpu_s: Option<f64>,
}

/// The running stage, as the work reports it.
#[derive(Clone)]
pub struct StageProgress {
    shared: Arc<Shared>,
}

impl StageProgress {
    /// `done` of `total` `unit` (e.g. "scans").
    pub fn set(&self, done: u64, total: u64, unit: &'static str) {
        if let Some(c) = self.shared.lock().current.as_mut() {
            c.progress = Some((done, total, unit));
        }
    }
}

/// A process's stages, numbered `1/total` on.
pub struct Stages {
    prefix: String,
    total: usize,
    shared: Arc<Shared>,
    pulse: Option<JoinHandle<()>>,
    times: Vec<StageTime>,
}

struct Shared {
    state: Mutex<State>,
    wake: Condvar,
    out: Output,
    every: Duration,
}

enum Output {
    /// A live line on a terminal, finished stages printed above it.
    Live(ProgressBar),
    /// Plain lines (a pipe, a log file; a test's buffer).
    Lines(Mutex<Box<dyn Write + Send>>),
}

struct State {
    current: Option<Current>,
    /// When the last line was written.
    said: Instant,
    stop: bool,
}

struct Current {
    label: String,
    started: Instant,
    progress: Option<(u64, u64, &'static str)>,
    /// The work draws its own bar: no live line meanwhile.
    own_bar: bool,
}

impl Current {
    fn status(&self) -> String {
        let elapsed = self.started.elapsed().as_secs_f64();
        match self.progress {
            Some((done, total, unit)) if total > 0 => format!(
                "{}: {done}/{total} {unit} ({:.0} %), {elapsed:.1} s",
                self.label,
                100.0 * done as f64 / total as f64
            ),
            _ => format!("{}: {elapsed:.1} s", self.label),
        }
    }
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// One finished line (above the live line on a terminal).
    fn say(&self, state: &mut State, line: &str) {
        match &self.out {
            Output::Live(bar) => bar.println(line),
            Output::Lines(w) => {
                let mut w = w.lock().unwrap_or_else(|e| e.into_inner());
                // A closed stderr is no reason to stop the work.
                let _ = writeln!(w, "{line}");
                let _ = w.flush();
            }
        }
        state.said = Instant::now();
    }

    /// What the running stage is doing now, if it has been quiet for a
    /// pulse (on a pipe) or always (the live line on a terminal).
    fn pulse(&self, state: &mut State) {
        let Some(c) = &state.current else {
            return;
        };
        match &self.out {
            Output::Live(bar) => {
                if c.own_bar {
                    bar.set_message(String::new());
                } else {
                    bar.set_message(c.status());
                }
            }
            Output::Lines(_) => {
                if state.said.elapsed() >= self.every {
                    let line = c.status();
                    self.say(state, &line);
                }
            }
        }
    }
}

impl Stages {
    /// At most this long between two lines while a stage runs on a pipe.
    pub const PULSE: Duration = Duration::from_secs(1);

    /// Stages whose lines go to stderr (live on a terminal), each named
    /// `prefix i/total`.
    pub fn new(prefix: &str, total: usize) -> Self {
        let out = if std::io::stderr().is_terminal() {
            let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
            bar.set_style(ProgressStyle::with_template("{msg}").expect("static template"));
            Output::Live(bar)
        } else {
            Output::Lines(Mutex::new(Box::new(std::io::stderr())))
        };
        Self::with_output(prefix, total, out, Self::PULSE)
    }

    /// Stages whose lines go to `w` as plain lines, with at most `every`
    /// between two lines while a stage runs.
    pub fn to_writer(
        prefix: &str,
        total: usize,
        w: impl Write + Send + 'static,
        every: Duration,
    ) -> Self {
        Self::with_output(prefix, total, Output::Lines(Mutex::new(Box::new(w))), every)
    }

    fn with_output(prefix: &str, total: usize, out: Output, every: Duration) -> Self {
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                current: None,
                said: Instant::now(),
                stop: false,
            }),
            wake: Condvar::new(),
            out,
            every,
        });
        let pulse = {
            let shared = shared.clone();
            // Checked four times a pulse: a line at most a quarter pulse
            // late.
            let tick = (every / 4).max(Duration::from_millis(1));
            std::thread::Builder::new()
                .name("stages".into())
                .spawn(move || {
                    let mut state = shared.lock();
                    while !state.stop {
                        shared.pulse(&mut state);
                        state = shared
                            .wake
                            .wait_timeout(state, tick)
                            .unwrap_or_else(|e| e.into_inner())
                            .0;
                    }
                })
                .ok()
        };
        Self {
            prefix: prefix.to_string(),
            total,
            shared,
            pulse,
            times: Vec::new(),
        }
    }

    /// Runs `work` as the next stage, `name` saying what it does.
    pub fn run<T>(&mut self, name: &str, work: impl FnOnce(&StageProgress) -> T) -> T {
        self.stage(name, false, work)
    }

    /// As [`Stages::run`], for work that draws its own progress bar.
    pub fn run_with_bar<T>(&mut self, name: &str, work: impl FnOnce(&StageProgress) -> T) -> T {
        self.stage(name, true, work)
    }

    fn stage<T>(&mut self, name: &str, own_bar: bool, work: impl FnOnce(&StageProgress) -> T) -> T {
        let label = format!(
            "{} {}/{}: {name}",
            self.prefix,
            self.times.len() + 1,
            self.total.max(self.times.len() + 1)
        );
        let cpu = process_cpu_s();
        let started = Instant::now();
        {
            let mut state = self.shared.lock();
            self.shared.say(&mut state, &label);
            state.current = Some(Current {
                label: label.clone(),
                started,
                progress: None,
                own_bar,
            });
            self.shared.pulse(&mut state);
        }
        let out = work(&StageProgress {
            shared: self.shared.clone(),
        });
        let time = StageTime {
            name: name.to_string(),
            wall_s: started.elapsed().as_secs_f64(),
            cpu_s: cpu.zip(process_cpu_s()).map(|(a, b)| b - a),
        };
        {
            let mut state = self.shared.lock();
            state.current = None;
            if let Output::Live(bar) = &self.shared.out {
                bar.set_message(String::new());
            }
            // A stage that was heard from while it ran says when it ended.
            if state.said > started + self.shared.every / 2 {
                let line = format!("{label}: done in {:.1} s", time.wall_s);
                self.shared.say(&mut state, &line);
            }
        }
        self.times.push(time);
        out
    }

    /// Every stage run so far, in order.
    pub fn times(&self) -> &[StageTime] {
        &self.times
    }
}

impl Drop for Stages {
    fn drop(&mut self) {
        self.shared.lock().stop = true;
        self.shared.wake.notify_all();
        if let Some(t) = self.pulse.take() {
            let _ = t.join();
        }
        if let Output::Live(bar) = &self.shared.out {
            bar.finish_and_clear();
        }
    }
}

/// This process's CPU time so far (s, user and system, every thread),
/// where the system tells (Linux's /proc; its clock ticks are USER_HZ,
/// 100 a second).
pub fn process_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The fields after the command name, which may hold spaces, in
    // parentheses; utime and stime are the line's 14th and 15th.
    let rest = stat.get(stat.rfind(')')? + 2..)?;
    let mut fields = rest.split_whitespace().skip(11);
    let utime: f64 = fields.next()?.parse().ok()?;
    let stime: f64 = fields.next()?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A writer tests can read while the stages still write to it.
    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Shared {
        fn lines(&self) -> Vec<String> {
            String::from_utf8(self.0.lock().unwrap().clone())
                .unwrap()
                .lines()
                .map(str::to_string)
                .collect()
        }
    }

    /// Waits (at most a minute) until `lines` holds a line `ok` accepts.
    fn wait_for(out: &Shared, ok: impl Fn(&str) -> bool) -> bool {
        let until = Instant::now() + Duration::from_secs(60);
        while Instant::now() < until {
            if out.lines().iter().any(|l| ok(l)) {
                return true;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        false
    }

    #[test]
    fn a_stage_says_what_it_does_and_how_far_it_is_while_it_runs() {
        let out = Shared::default();
        let mut stages = Stages::to_writer("job", 3, out.clone(), Duration::from_millis(10));
        let quick = stages.run("quick", |_| 7);
        assert_eq!(quick, 7);
        let heard = stages.run("slow", |p| {
            p.set(3, 12, "scans");
            // The work waits until the stage has said how far it is.
            wait_for(&out, |l| l.starts_with("job 2/3: slow: 3/12 scans (25 %)"))
        });
        assert!(heard, "{:?}", out.lines());
        let lines = out.lines();
        assert_eq!(lines[0], "job 1/3: quick");
        assert!(lines.contains(&"job 2/3: slow".to_string()), "{lines:?}");
        // Heard from while it ran, the slow stage says when it ended.
        assert!(
            lines.last().unwrap().starts_with("job 2/3: slow: done in "),
            "{lines:?}"
        );
        let times = stages.times();
        assert_eq!(
            times.iter().map(|t| t.name.as_str()).collect::<Vec<_>>(),
            ["quick", "slow"]
        );
        assert!(times.iter().all(|t| t.wall_s >= 0.0));
    }

    #[test]
    fn a_stage_without_progress_says_how_long_it_has_run() {
        let out = Shared::default();
        let mut stages = Stages::to_writer("job", 1, out.clone(), Duration::from_millis(10));
        let heard = stages.run("waiting", |_| {
            wait_for(&out, |l| {
                l.starts_with("job 1/1: waiting: ") && l.ends_with(" s")
            })
        });
        assert!(heard, "{:?}", out.lines());
    }

    #[test]
    fn more_stages_than_announced_count_on() {
        let out = Shared::default();
        let mut stages = Stages::to_writer("job", 1, out.clone(), Duration::from_secs(60));
        stages.run("a", |_| ());
        stages.run("b", |_| ());
        drop(stages);
        assert_eq!(out.lines(), ["job 1/1: a", "job 2/2: b"]);
    }

    #[test]
    fn the_process_cpu_time_grows_with_work() {
        let Some(before) = process_cpu_s() else {
            return; // not Linux: nothing to read
        };
        // Spin until the clock ticks past (at most a minute of CPU).
        let until = Instant::now() + Duration::from_secs(60);
        let mut x = 0u64;
        while process_cpu_s().unwrap() <= before && Instant::now() < until {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
        }
        std::hint::black_box(x);
        assert!(process_cpu_s().unwrap() > before);
    }
}
