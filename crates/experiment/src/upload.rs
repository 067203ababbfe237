//! `twindrive experiment upload`: the plan upload against the ideal the link
//! allows, over each named profile and a grid of losses, in virtual time.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::bail;
use twindrive_link::efficiency::{self, Trial};
use twindrive_link::emulator::{LinkProfile, Outage};

use twindrive_files::Staging;

/// The signed case-study plan (bytes), as `twindrive demo` makes it.
pub const CASE_STUDY_BYTES: usize = 109_950;
/// The signed office-drive plan (a 181-beam lidar robot, 40.5 s).
pub const OFFICE_LIDAR_BYTES: usize = 52_000;
/// A one-hour plan at the case study's rate (1.62 kB per second of mission).
pub const ONE_HOUR_BYTES: usize = 5_832_000;
const PROFILES: [&str; 5] = ["lan", "wifi", "satellite-lossy", "lunar", "mars-relay"];
const LOSSES: [f64; 4] = [0.0, 0.01, 0.1, 0.3];
/// The target: within this factor of the ideal at loss up to 10 %.
const TARGET: f64 = 1.1;

struct Row {
    profile: String,
    loss: f64,
    size_label: &'static str,
    size: usize,
    trials: Vec<Trial>,
}

impl Row {
    fn mean(&self, f: impl Fn(&Trial) -> f64) -> f64 {
        self.trials.iter().map(f).sum::<f64>() / self.trials.len() as f64
    }
}

/// What to measure.
#[derive(Debug, Clone)]
pub struct Config {
    /// Also write results.csv and results.md here.
    pub out: Option<PathBuf>,
    /// Seeds per row.
    pub seeds: u64,
    /// A quick run (one 20 kB file, loss up to 10 %) that only checks it works.
    pub smoke: bool,
}

/// Runs the measurement; the table and the verdict to `out`.
pub fn run(args: &Config, out: &mut impl Write) -> anyhow::Result<()> {
    let sizes: Vec<(usize, &'static str)> = if args.smoke {
        vec![(20_000, "20 kB")]
    } else {
        vec![
            (OFFICE_LIDAR_BYTES, "office lidar 52 kB"),
            (CASE_STUDY_BYTES, "case study 110 kB"),
            (ONE_HOUR_BYTES, "one hour 5.8 MB"),
        ]
    };
    let profiles: &[&str] = if args.smoke {
        &PROFILES[..4]
    } else {
        &PROFILES
    };
    let mut rows = Vec::new();
    let total = (profiles.len() * LOSSES.len() * sizes.len()) as u64 * args.seeds;
    let bar = twindrive_progress::bar(total, "uploading");
    for name in profiles {
        for loss in LOSSES {
            let mut profile = LinkProfile::named(name).expect("a named profile");
            profile.loss = loss;
            for &(size, label) in &sizes {
                let mut trials = Vec::new();
                for seed in 0..args.seeds {
                    // Far beyond any ideal here: a stuck upload, not a slow one.
                    let give_up_s = 100.0
                        * efficiency::ideal_s(&profile, size, &efficiency::sender_config(&profile))
                        + 600.0;
                    match efficiency::upload(&profile, size, seed, give_up_s) {
                        Some(t) => trials.push(t),
                        None => bail!(
                            "{name} at {} % loss, {label}, seed {seed}: the upload did not complete in {give_up_s:.0} s of link time",
                            loss * 100.0
                        ),
                    }
                    bar.inc(1);
                }
                rows.push(Row {
                    profile: name.to_string(),
                    loss,
                    size_label: label,
                    size,
                    trials,
                });
            }
        }
    }
    bar.finish_and_clear();

    // Through a 60 s outage in the middle of a lunar upload at 10 % loss.
    let mut lunar = LinkProfile::named("lunar").expect("a named profile");
    lunar.loss = 0.1;
    // The case-study plan (the smoke run's only file otherwise).
    let size = sizes
        .iter()
        .find(|(s, _)| *s == CASE_STUDY_BYTES)
        .unwrap_or(&sizes[0])
        .0;
    let ideal = efficiency::ideal_s(&lunar, size, &efficiency::sender_config(&lunar));
    let start_s = 0.5 * ideal;
    lunar.outages.push(Outage {
        start_s,
        end_s: start_s + 60.0,
    });
    let Some(outage) = efficiency::upload(&lunar, size, 0, 100.0 * ideal + 600.0) else {
        bail!("the upload through a 60 s outage did not complete");
    };

    let mut csv = String::from(
        "profile,loss,size_bytes,seeds,mean_time_s,ideal_s,ratio,chunks_resent_mean\n",
    );
    let mut md = String::from(
        "| profile | loss | size | time (s) | ideal (s) | ratio |\n|---|---:|---|---:|---:|---:|\n",
    );
    writeln!(
        out,
        "{:<16} {:>5} {:<18} {:>10} {:>10} {:>7}",
        "profile", "loss", "size", "time (s)", "ideal (s)", "ratio"
    )?;
    let mut missed = Vec::new();
    for r in &rows {
        let (t, ideal) = (r.mean(|t| t.time_s), r.mean(|t| t.ideal_s));
        let ratio = t / ideal;
        if r.loss <= 0.1 && ratio > TARGET {
            missed.push(format!(
                "{} {:.0} % {}: {ratio:.2}x",
                r.profile,
                r.loss * 100.0,
                r.size_label
            ));
        }
        writeln!(
            out,
            "{:<16} {:>4.0}% {:<18} {t:>10.2} {ideal:>10.2} {ratio:>6.2}x",
            r.profile,
            r.loss * 100.0,
            r.size_label
        )?;
        csv.push_str(&format!(
            "{},{},{},{},{t:.4},{ideal:.4},{ratio:.4},{:.2}\n",
            r.profile,
            r.loss,
            r.size,
            r.trials.len(),
            r.mean(|t| t.chunks_resent as f64)
        ));
        md.push_str(&format!(
            "| {} | {:.0} % | {} | {t:.2} | {ideal:.2} | {ratio:.2}x |\n",
            r.profile,
            r.loss * 100.0,
            r.size_label
        ));
    }
    let outage_line = format!(
        "lunar at 10 % loss, {size} bytes, 60 s outage from {start_s:.1} s (mid-upload): {:.2} s (ideal without the outage {:.2} s, with it {:.2} s)",
        outage.time_s,
        outage.ideal_s,
        outage.ideal_s + 60.0
    );
    writeln!(out, "{outage_line}")?;
    let verdict = if missed.is_empty() {
        format!("every upload at loss up to 10 % within {TARGET}x of the ideal")
    } else {
        format!(
            "beyond {TARGET}x of the ideal at loss up to 10 %: {}",
            missed.join("; ")
        )
    };
    writeln!(out, "{verdict}")?;
    md.push_str(&format!("\n{outage_line}\n\n{verdict}\n"));

    if let Some(dir) = &args.out {
        write_results(dir, &csv, &md)?;
        writeln!(out, "-> {}/results.csv, results.md", dir.display())?;
    }
    Ok(())
}

fn write_results(dir: &Path, csv: &str, md: &str) -> anyhow::Result<()> {
    let staging = Staging::new(dir, "experiment-upload")?;
    staging.write_with("results.csv", |w| Ok(w.write_all(csv.as_bytes())?))?;
    staging.write_with("results.md", |w| Ok(w.write_all(md.as_bytes())?))?;
    staging.commit()?;
    Ok(())
}
