//! `twindrive calibrate`: wheel diameters and wheelbase from encoders plus an
//! absolute pose reference.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, bail};
use serde::Serialize;
use twindrive_estimation::batch::{self, BatchConfig, Identifiability};
use twindrive_estimation::dead_reckoning::dead_reckon;
use twindrive_estimation::{
    FilterConfig, FilterHistory, PackedEstimate, PoseSample, StateVec, WheelSample, clock,
    run_filter, smooth,
};
use twindrive_kinematics::{DiffDriveParams, Pose};

use crate::cli::{CalibrateArgs, Method};
use crate::output::Staging;
use crate::usage::{OrUsage, usage};
use crate::{figures, inputs, progress};

/// How the clock offset between the two logs is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Offset {
    Given(f64),
    Auto,
}

/// Everything one calibration needs, checked.
#[derive(Debug, Clone)]
pub struct Job {
    pub wheels: Vec<WheelSample>,
    pub poses: Vec<PoseSample>,
    pub initial: [f64; 3],
    pub offset: Offset,
    /// Only poses in this interval of the pose clock are used.
    pub start_s: Option<f64>,
    pub end_s: Option<f64>,
    pub method: Method,
    pub filter: FilterConfig,
    pub param_rel_std: f64,
    pub batch_window_s: f64,
    pub ticks_per_rev: Option<u32>,
    /// The true pose track, when the log has one (simulations).
    pub truth: Option<Vec<(f64, Pose)>>,
    /// Subtracted from the input's times (bags: Unix seconds).
    pub time_origin_s: f64,
}

/// `calib.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub left_diameter_m: f64,
    pub right_diameter_m: f64,
    pub wheelbase_m: f64,
    pub left_diameter_std_m: f64,
    pub right_diameter_std_m: f64,
    pub wheelbase_std_m: f64,
    pub method: Method,
    pub initial: [f64; 3],
    /// `t_pose = t_encoder + clock_offset_s`.
    pub clock_offset_s: f64,
    pub clock_offset_source: &'static str,
    pub clock_offset_correlation: Option<f64>,
    pub identifiability: Identifiability,
    pub residuals: Residuals,
    pub cross_check: CrossCheck,
    pub data: DataSummary,
}

#[derive(Debug, Clone, Serialize)]
pub struct Residuals {
    /// Mean normalised innovation squared of the filter's accepted poses
    /// (≈ the measurement dimension when the noise model fits).
    pub filter_mean_nis: f64,
    pub filter_nis_inside_95_fraction: f64,
    pub filter_accepted: u64,
    pub filter_rejected: u64,
    /// Times the filter lost track (slip, a moved robot) and re-anchored its
    /// pose on the reference.
    pub filter_reanchors: u64,
    pub batch_whitened_rms: f64,
    /// RMS of the batch end-of-window residuals [x (m), y (m), θ (rad)].
    pub batch_residual_rms: [f64; 3],
    pub batch_windows: usize,
    /// Simulated logs only (they carry the true pose): mean normalised
    /// estimation error squared of the pose at the filter's nodes (3 for a
    /// consistent filter) and the fraction inside the 95 % chi-square interval.
    pub pose_nees_mean: Option<f64>,
    pub pose_nees_inside_95_fraction: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct CrossCheck {
    pub ekf: [f64; 3],
    pub ekf_std: [f64; 3],
    pub batch: [f64; 3],
    pub batch_std: [f64; 3],
    pub batch_iterations: usize,
    /// Largest |ekf / batch − 1| over the three parameters.
    pub max_relative_difference: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct DataSummary {
    pub encoder_samples: usize,
    pub pose_samples: usize,
    pub start_s: f64,
    pub end_s: f64,
    pub ticks_per_rev: Option<u32>,
    /// Added to every time in this report to get the input's own times.
    pub time_origin_s: f64,
}

/// What the figures and trajectories are drawn from.
pub struct Artefacts {
    /// The reported parameters.
    pub reported: [f64; 3],
    pub initial: [f64; 3],
    /// The filter's nodes (how it converged) and innovations.
    pub history: FilterHistory,
    /// The reference poses used.
    pub poses: Vec<PoseSample>,
    /// The encoder samples on the pose clock.
    pub wheels: Vec<WheelSample>,
    /// Where dead reckoning starts, and the time span it covers.
    pub start_pose: Pose,
    pub span_s: (f64, f64),
}

impl Artefacts {
    /// (t, [dL, dR, b], [σ]) of the filter at its nodes.
    pub fn trace(&self) -> Vec<(f64, [f64; 3], [f64; 3])> {
        let h = &self.history;
        h.t_s
            .iter()
            .zip(&h.filtered)
            .map(|(t, s)| {
                let (v, sd) = params_of(&s.state, |i| s.std(i));
                (*t, v, sd)
            })
            .collect()
    }

    /// The reference poses that carry a heading, as a track.
    pub fn reference(&self) -> impl Iterator<Item = (f64, Pose)> + '_ {
        self.poses
            .iter()
            .filter_map(|p| p.heading_rad.map(|h| (p.t_s, Pose::new(p.x_m, p.y_m, h))))
    }

    /// Dead reckoning over the span with parameters [dL, dR, b].
    pub fn dead_reckoning(&self, p: [f64; 3]) -> Vec<(f64, Pose)> {
        dead_reckon(
            &self.wheels,
            self.start_pose,
            self.span_s.0,
            self.span_s.1,
            &DiffDriveParams::new(p[0], p[1], p[2]),
        )
    }
}

/// [dL, dR, b] and their standard deviations from a state and the
/// standard deviation of each of its components.
fn params_of(state: &StateVec, std: impl Fn(usize) -> f64) -> ([f64; 3], [f64; 3]) {
    ([state[3], state[4], state[5]], [3, 4, 5].map(std))
}

/// Runs a calibration. `progress(done, total)` follows the filter.
pub fn calibrate(
    mut job: Job,
    progress: impl FnMut(usize, usize),
) -> anyhow::Result<(Report, Artefacts)> {
    if let Some(i) = job
        .initial
        .iter()
        .position(|v| !(v.is_finite() && *v > 0.0))
    {
        bail!(
            "--initial: {} must be a finite number > 0 (metres), got {}",
            ["the left diameter", "the right diameter", "the wheelbase"][i],
            job.initial[i]
        );
    }
    let (offset_s, source, correlation) = match job.offset {
        Offset::Given(s) => (s, "given", None),
        Offset::Auto => {
            let span = |a: f64, b: f64| b - a;
            let shorter = span(job.wheels[0].t_s, job.wheels.last().expect("non-empty").t_s).min(
                span(job.poses[0].t_s, job.poses.last().expect("non-empty").t_s),
            );
            let found = clock::estimate_offset(
                &job.wheels,
                &job.poses,
                job.initial,
                (0.5 * shorter).min(30.0),
            )
            .context(
                "--time-offset auto: the encoder and pose logs show no common motion to align",
            )?;
            tracing::info!(
                offset_s = found.offset_s,
                correlation = found.correlation,
                "clock offset"
            );
            (found.offset_s, "auto", Some(found.correlation))
        }
    };
    inputs::shift(&mut job.wheels, offset_s);

    let (w0, w1) = (job.wheels[0].t_s, job.wheels.last().expect("non-empty").t_s);
    let (p0, p1) = (job.poses[0].t_s, job.poses.last().expect("non-empty").t_s);
    if w1.min(p1) - w0.max(p0) <= 1.0 {
        bail!(
            "the encoder log (t = {w0:.3} .. {w1:.3} s on the pose clock, offset {offset_s} s) and the pose log \
             (t = {p0:.3} .. {p1:.3} s) do not overlap in time; pass --time-offset auto or the offset in seconds"
        );
    }
    let start = job.start_s.unwrap_or(f64::NEG_INFINITY).max(w0);
    let end = job.end_s.unwrap_or(f64::INFINITY).min(w1);
    let poses: Vec<PoseSample> = job
        .poses
        .iter()
        .copied()
        .filter(|p| p.t_s >= start && p.t_s <= end)
        .collect();
    if poses.len() < 10 {
        bail!(
            "only {} pose samples fall in the encoder data between t = {start} and {end} s; need at least 10",
            poses.len()
        );
    }

    // The filter and the independent batch fit run side by side (two cores),
    // both from the initial guess.
    let stage = Instant::now();
    let batch_cfg = BatchConfig {
        window_s: job.batch_window_s,
        noise: job.filter.noise,
        ..BatchConfig::default()
    };
    let (run, b) = std::thread::scope(|scope| {
        let batch = scope.spawn(|| {
            let fit = batch::fit(&job.wheels, &poses, job.initial, &batch_cfg);
            tracing::info!(elapsed_s = stage.elapsed().as_secs_f64(), "batch fit");
            fit
        });
        let run = run_filter(
            &job.wheels,
            &poses,
            job.initial,
            job.param_rel_std,
            job.filter,
            true,
            progress,
        );
        tracing::info!(elapsed_s = stage.elapsed().as_secs_f64(), "filter");
        (run, batch.join())
    });
    let run = run?;
    let b = b.map_err(|_| anyhow::anyhow!("the batch fit panicked"))??;
    let history = run.history.as_ref().expect("kept");
    let smoothed;
    let nodes: &[PackedEstimate] = match job.method {
        Method::Smoother => {
            smoothed = smooth(&run)?;
            &smoothed
        }
        _ => &history.filtered,
    };
    tracing::info!(
        elapsed_s = stage.elapsed().as_secs_f64(),
        batch_iterations = b.iterations,
        "filter, smoother and batch"
    );
    let (ekf, ekf_std) = params_of(&run.estimate.state, |i| run.estimate.std(i));

    let (params, std) = match job.method {
        Method::Batch => (b.params, b.std),
        _ => {
            let last = nodes.last().expect("one node at least");
            params_of(&last.state, |i| last.std(i))
        }
    };
    let max_relative_difference = (0..3)
        .map(|i| (ekf[i] / b.params[i] - 1.0).abs())
        .fold(0.0, f64::max);
    let nees: Option<(f64, f64)> = job.truth.as_ref().map(|truth| {
        let (lo, hi) = (
            twindrive_estimation::chi2_quantile(3, 0.025),
            twindrive_estimation::chi2_quantile(3, 0.975),
        );
        let values: Vec<f64> = history
            .t_s
            .iter()
            .zip(nodes)
            .skip(1)
            .filter_map(|(t, s)| {
                let g = twindrive_estimation::dead_reckoning::pose_at(truth, *t)?;
                let truth_state = twindrive_estimation::StateVec::new(
                    g.x_m,
                    g.y_m,
                    g.heading_rad,
                    s.state[3],
                    s.state[4],
                    s.state[5],
                );
                Some(twindrive_estimation::nees(
                    &s.unpack(),
                    &truth_state,
                    &[0, 1, 2],
                ))
            })
            .collect();
        let n = values.len().max(1) as f64;
        (
            values.iter().sum::<f64>() / n,
            values.iter().filter(|v| (lo..=hi).contains(*v)).count() as f64 / n,
        )
    });
    let stats = run.stats;
    let report = Report {
        left_diameter_m: params[0],
        right_diameter_m: params[1],
        wheelbase_m: params[2],
        left_diameter_std_m: std[0],
        right_diameter_std_m: std[1],
        wheelbase_std_m: std[2],
        method: job.method,
        initial: job.initial,
        clock_offset_s: offset_s,
        clock_offset_source: source,
        clock_offset_correlation: correlation,
        identifiability: b.identifiability.clone(),
        residuals: Residuals {
            filter_mean_nis: stats.mean_nis(),
            filter_nis_inside_95_fraction: stats.nis_inside_95 as f64
                / stats.accepted.max(1) as f64,
            filter_accepted: stats.accepted,
            filter_rejected: stats.rejected,
            filter_reanchors: stats.reanchors,
            batch_whitened_rms: b.whitened_rms,
            batch_residual_rms: b.residual_rms,
            batch_windows: b.windows,
            pose_nees_mean: nees.map(|n| n.0),
            pose_nees_inside_95_fraction: nees.map(|n| n.1),
        },
        cross_check: CrossCheck {
            ekf,
            ekf_std,
            batch: b.params,
            batch_std: b.std,
            batch_iterations: b.iterations,
            max_relative_difference,
        },
        data: DataSummary {
            encoder_samples: job
                .wheels
                .iter()
                .filter(|w| w.t_s >= start && w.t_s <= end)
                .count(),
            pose_samples: poses.len(),
            start_s: poses[0].t_s,
            end_s: poses.last().expect("non-empty").t_s,
            ticks_per_rev: job.ticks_per_rev,
            time_origin_s: job.time_origin_s,
        },
    };

    let start_pose = match poses.iter().find_map(|p| p.heading_rad.map(|h| (p, h))) {
        Some((p, h)) => Pose::new(p.x_m, p.y_m, h),
        None => {
            let s = &history.filtered[0].state;
            Pose::new(s[0], s[1], s[2])
        }
    };
    let artefacts = Artefacts {
        reported: params,
        initial: job.initial,
        history: run.history.expect("kept"),
        poses,
        wheels: job.wheels,
        start_pose,
        span_s: (report.data.start_s, report.data.end_s),
    };
    Ok((report, artefacts))
}

/// Reads the inputs named on the command line into a [`Job`].
fn resolve(args: &CalibrateArgs) -> anyhow::Result<Job> {
    let signs = [f64::from(args.left_sign), f64::from(args.right_sign)];
    let mut time_origin_s = 0.0;
    let (wheels, poses, default_initial, ticks_per_rev, truth) =
        match (&args.log_dir, &args.encoders, &args.poses) {
            (None, None, None) if args.bag.is_some() => {
                let (wheels, poses, origin) = inputs::from_bag(args, signs)?;
                time_origin_s = origin;
                (wheels, poses, None, args.ticks_per_rev, None)
            }
            (Some(dir), None, None) => {
                let log = read_log_dir(dir)?;
                let mut wheels = inputs::wheels_from_log(&log);
                for w in &mut wheels {
                    w.left_rad *= signs[0];
                    w.right_rad *= signs[1];
                }
                let n = log.header.nominal;
                let tpr = log.header.ticks_per_rev;
                if let Some(t) = args.ticks_per_rev
                    && t != tpr
                {
                    return Err(usage(format!(
                        "--ticks-per-rev {t} contradicts the log header's ticks_per_rev {tpr}"
                    )));
                }
                let truth: Vec<(f64, Pose)> = log
                    .steps
                    .iter()
                    .map(|s| (s.t_s(), s.ground_truth))
                    .collect();
                (
                    wheels,
                    inputs::poses_from_log(&log),
                    Some([n.left_diameter_m, n.right_diameter_m, n.wheelbase_m]),
                    Some(tpr),
                    Some(truth),
                )
            }
            (None, Some(enc), Some(pose)) => {
                // The two files are read side by side.
                let (e, p) = std::thread::scope(|scope| {
                    let e = scope.spawn(|| twindrive_log::calib_csv::read_encoder_csv(enc));
                    let p = twindrive_log::calib_csv::read_pose_csv(pose);
                    (e.join(), p)
                });
                let e = e
                    .map_err(|_| anyhow::anyhow!("reading the encoder log panicked"))?
                    .context("--encoders")?;
                let p = p.context("--poses")?;
                (
                    inputs::wheels_from_csv(&e, enc, args.ticks_per_rev, signs)?,
                    inputs::poses_from_csv(&p),
                    None,
                    args.ticks_per_rev,
                    None,
                )
            }
            _ => return Err(usage(INPUTS)),
        };
    if wheels.len() < 2 {
        bail!(
            "the encoder log has {} samples; need at least 2",
            wheels.len()
        );
    }
    if poses.is_empty() {
        bail!("the pose log has no samples");
    }
    let initial = match (&args.initial, default_initial) {
        (Some(text), _) => parse_initial(text).or_usage()?,
        (None, Some(i)) => i,
        (None, None) => {
            return Err(usage(
                "--initial DL,DR,B (metres) is needed for CSV and bag inputs",
            ));
        }
    };
    let offset = match args.time_offset.trim() {
        "auto" => Offset::Auto,
        text => Offset::Given(
            text.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    usage(format!(
                        "--time-offset: expected `auto` or seconds, got `{text}`"
                    ))
                })?,
        ),
    };
    let mut filter = FilterConfig::default();
    filter.noise.position_std_m = args.position_std_m;
    filter.noise.heading_std_rad = args.heading_std_rad;
    filter.noise.wheel_rad2_per_rad = args.wheel_noise;
    if let Some(rw) = args.param_random_walk {
        filter.noise.param_random_walk_m2_per_s = Some([rw; 3]);
    }
    Ok(Job {
        wheels,
        poses,
        initial,
        offset,
        start_s: args.start_s,
        end_s: args.end_s,
        method: args.method,
        filter,
        param_rel_std: 0.1,
        batch_window_s: args.batch_window_s,
        ticks_per_rev,
        truth,
        time_origin_s,
    })
}

/// The three ways to give `calibrate` its data.
const INPUTS: &str = "give a simulator output directory (log.csv + log.meta.json from `twindrive simulate`), \
     both --encoders E.csv and --poses P.csv, or --bag REC.mcap|BAG_DIR";

/// A simulator output directory; any other directory is refused with what
/// `calibrate` expects.
fn read_log_dir(dir: &Path) -> anyhow::Result<twindrive_log::MissionLog> {
    if !dir.join("log.meta.json").is_file() {
        let what = if !dir.exists() {
            "does not exist"
        } else if !dir.is_dir() {
            "is a file, not a simulator output directory"
        } else {
            "is not a simulator log (no log.meta.json in it)"
        };
        bail!("{}: {what}; {INPUTS}", dir.display());
    }
    Ok(twindrive_log::read_log_dir(dir)?)
}

fn parse_initial(text: &str) -> anyhow::Result<[f64; 3]> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [l, r, b] = parts[..] else {
        bail!("--initial: expected three numbers DL,DR,B in metres, got `{text}`");
    };
    let mut out = [0.0; 3];
    for (i, (p, name)) in [l, r, b]
        .iter()
        .zip(["left diameter", "right diameter", "wheelbase"])
        .enumerate()
    {
        out[i] = p
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v > 0.0)
            .with_context(|| {
                format!("--initial: the {name} must be a finite number > 0 (metres), got `{p}`")
            })?;
    }
    Ok(out)
}

pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let job = resolve(args)?;
    tracing::info!(elapsed_s = started.elapsed().as_secs_f64(), "read inputs");
    let total = job.wheels.len() + job.poses.len();
    let bar = progress::bar(total as u64, "calibrating");
    let (report, artefacts) = calibrate(job, |done, _| bar.set_position(done as u64))?;
    bar.finish_and_clear();
    let stage = Instant::now();
    write_outputs(&report, &artefacts, &args.out)?;
    tracing::info!(elapsed_s = stage.elapsed().as_secs_f64(), "wrote outputs");
    tracing::info!(elapsed_s = started.elapsed().as_secs_f64(), "calibrated");
    print_report(&report, &args.out)
}

/// Writes `out` (calib.json) and, beside it, `<stem>_*.svg/png` figures and
/// `<stem>_*.tum` trajectories.
pub fn write_outputs(report: &Report, art: &Artefacts, out: &Path) -> anyhow::Result<()> {
    let (dir, stem, file_name) = crate::output::split_out_path(out, "calib")?;
    let staging = Staging::new(&dir, &format!("calibrate:{stem}"))?;
    staging.write_with(&file_name, |w| {
        serde_json::to_writer_pretty(w, report).map_err(Into::into)
    })?;
    // The reference track, the dead-reckoned tracks and the figures side by side.
    let write_tum = |suffix: &str, track: &mut dyn Iterator<Item = (f64, Pose)>| {
        staging.write_with(&format!("{stem}_{suffix}.tum"), |w| {
            let ns = |t: f64| (t * 1e9).round().max(0.0) as u64;
            twindrive_log::write_tum(track.map(|(t, p)| (ns(t), p)), w).map_err(Into::into)
        })
    };
    let (reference, dead_reckoning, figures) = std::thread::scope(|scope| {
        let reference = scope.spawn(|| write_tum("reference", &mut art.reference()));
        let dead_reckoning = scope.spawn(|| -> anyhow::Result<()> {
            for (suffix, params) in [
                ("dead_reckoning_initial", art.initial),
                ("dead_reckoning_calibrated", art.reported),
            ] {
                write_tum(suffix, &mut art.dead_reckoning(params).into_iter())?;
            }
            Ok(())
        });
        let figures = figures::calibration_figures(
            &art.trace(),
            art.reported,
            &art.history.innovations,
            staging.dir(),
            &stem,
        );
        (reference.join(), dead_reckoning.join(), figures)
    });
    let panicked = |_| anyhow::anyhow!("writing the trajectories panicked");
    reference.map_err(panicked)??;
    dead_reckoning.map_err(panicked)??;
    figures?;
    staging.commit()
}

fn print_report(r: &Report, out: &Path) -> anyhow::Result<()> {
    let mut o = std::io::stdout().lock();
    writeln!(
        o,
        "method {:?}, clock offset {:.3} s ({})",
        r.method, r.clock_offset_s, r.clock_offset_source
    )?;
    for (name, v, s, init) in [
        (
            "left diameter ",
            r.left_diameter_m,
            r.left_diameter_std_m,
            r.initial[0],
        ),
        (
            "right diameter",
            r.right_diameter_m,
            r.right_diameter_std_m,
            r.initial[1],
        ),
        (
            "wheelbase     ",
            r.wheelbase_m,
            r.wheelbase_std_m,
            r.initial[2],
        ),
    ] {
        writeln!(
            o,
            "  {name} {v:.6} m ± {s:.6} (initial {init:.6}, {:+.3} %)",
            100.0 * (v / init - 1.0)
        )?;
    }
    writeln!(
        o,
        "  EKF vs batch: largest difference {:.3} %; mean NIS {:.2}; {} poses rejected",
        100.0 * r.cross_check.max_relative_difference,
        r.residuals.filter_mean_nis,
        r.residuals.filter_rejected
    )?;
    if r.residuals.filter_reanchors > 0 {
        writeln!(
            o,
            "  WARNING: the filter lost track {} time(s) and re-anchored its pose on the reference (slip, or the robot was moved)",
            r.residuals.filter_reanchors
        )?;
    }
    writeln!(o, "  {}", r.identifiability.verdict)?;
    writeln!(
        o,
        "wrote {} and its figures and trajectories beside it",
        out.display()
    )?;
    Ok(())
}

/// The calibration of a calibration drive's log: the tracker's noise, the
/// operator's `nominal` [dL, dR, b] as the start, 10 % standard deviation.
pub fn calibration_job(
    log: &twindrive_log::MissionLog,
    tracker: &twindrive_sim::TrackerConfig,
    nominal: [f64; 3],
    method: Method,
) -> Job {
    let mut filter = FilterConfig::default();
    filter.noise.position_std_m = tracker.position_noise_std_m;
    filter.noise.heading_std_rad = tracker.heading_noise_std_rad;
    filter.noise.wheel_rad2_per_rad = 1e-6;
    Job {
        wheels: inputs::wheels_from_log(log),
        poses: inputs::poses_from_log(log),
        initial: nominal,
        offset: Offset::Given(0.0),
        start_s: None,
        end_s: None,
        method,
        filter,
        param_rel_std: 0.1,
        batch_window_s: 1.0,
        ticks_per_rev: Some(log.header.ticks_per_rev),
        truth: Some(
            log.steps
                .iter()
                .map(|s| (s.t_s(), s.ground_truth))
                .collect(),
        ),
        time_origin_s: 0.0,
    }
}

/// `twin`'s parameters as calibration finds them: the built-in calibration
/// drive run with `twin`'s robot (its hidden truth, the operator's nominal
/// values, its encoders), calibrated by the augmented EKF.
pub fn calibrate_like(twin: &twindrive_sim::Scenario) -> anyhow::Result<DiffDriveParams> {
    let mut drive = twindrive_sim::builtin::load("calibration_drive")
        .context("calibration_drive is not built in")?
        .context("the built-in calibration_drive scenario")?;
    drive.robot.true_params = twin.robot.true_params;
    drive.robot.nominal_params = twin.robot.nominal_params;
    drive.robot.encoder = twin.robot.encoder;
    let tracker = drive
        .tracker
        .clone()
        .context("the calibration drive has a tracker")?;
    let n = drive.robot.nominal_params;
    let nominal = [n.left_diameter_m, n.right_diameter_m, n.wheelbase_m];
    let log = twindrive_sim::Simulator::new(drive).run(|_, _| {});
    let job = calibration_job(&log, &tracker, nominal, Method::Ekf);
    let (report, _) = calibrate(job, |_, _| {})?;
    Ok(DiffDriveParams::new(
        report.left_diameter_m,
        report.right_diameter_m,
        report.wheelbase_m,
    ))
}
