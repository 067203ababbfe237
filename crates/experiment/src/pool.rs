//! The experiments' runs on every core: each job once, results in the
//! jobs' order, progress as they finish.

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

/// `run` on every job, on every core; the first error in the jobs' order,
/// or every result in it.
pub fn run_all<J: Sync, R: Send>(
    jobs: &[J],
    run: impl Fn(&J) -> anyhow::Result<R> + Sync,
) -> anyhow::Result<Vec<R>> {
    let bar = twindrive_progress::bar(jobs.len() as u64, "runs");
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<anyhow::Result<R>>>> =
        Mutex::new((0..jobs.len()).map(|_| None).collect());
    let workers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(jobs.len().max(1));
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(job) = jobs.get(k) else {
                        break;
                    };
                    let r = run(job);
                    results.lock().expect("no worker panicked")[k] = Some(r);
                    bar.inc(1);
                }
            });
        }
    });
    bar.finish_and_clear();
    results
        .into_inner()
        .expect("no worker panicked")
        .into_iter()
        .map(|r| r.expect("every job ran"))
        .collect()
}
