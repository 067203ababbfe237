//! The calibration itself: the clock offset, the window, the augmented EKF
//! (and smoother) beside the independent batch fit, the consistency checks.

use std::time::Instant;

use anyhow::{Context, bail};
use twindrive_estimation::batch::{self, BatchConfig};
use twindrive_estimation::{PackedEstimate, PoseSample, clock, run_filter, smooth};
use twindrive_kinematics::Pose;

use crate::inputs;
use crate::job::{Job, Method, Offset};
use crate::report::{Artefacts, CrossCheck, DataSummary, Report, Residuals, params_of};

/// Fewest reference poses the filter must accept for a calibration to count.
pub const MIN_ACCEPTED_POSES: u64 = 30;
/// Smallest share of the reference poses the filter's gate may accept: below
/// it the poses and the wheels disagree (a sign, a clock, a noise level or a
/// reference that is not what it seems), and a fit to the few that pass is
/// not evidence of anything.
pub const MIN_ACCEPTED_FRACTION: f64 = 0.5;

/// What to check when the reference and the wheels disagree.
const DISAGREE_HINT: &str = "check --left-sign/--right-sign, the clock offset (--time-offset auto), \
     --initial, and that --position-std-m/--heading-std-rad match the reference's noise";

/// Largest relative standard deviation of the weakest combination of
/// (dL, dR, b) a calibration may have; between the batch fit's precision
/// threshold (0.2 %) and this, it is written with a warning.
pub const MAX_WEAKEST_RELATIVE_STD: f64 = 0.05;

/// Refuses a calibration the data does not support: too few reference
/// poses accepted, most of them rejected, or motion that leaves a parameter
/// unpinned. The error says what was accepted and rejected and why.
fn check_support(r: &Report) -> anyhow::Result<()> {
    let (accepted, rejected) = (r.residuals.filter_accepted, r.residuals.filter_rejected);
    let total = accepted + rejected;
    let fraction = accepted as f64 / total.max(1) as f64;
    let mut why = Vec::new();
    if accepted < MIN_ACCEPTED_POSES {
        why.push(format!(
            "only {accepted} reference poses were accepted (at least {MIN_ACCEPTED_POSES} are needed)"
        ));
    }
    if fraction < MIN_ACCEPTED_FRACTION {
        why.push(format!(
            "the filter's gate rejected {rejected} of {total} reference poses ({:.0} %; at most {:.0} % may be): \
             the poses disagree with the wheels: {DISAGREE_HINT}",
            100.0 * (1.0 - fraction),
            100.0 * (1.0 - MIN_ACCEPTED_FRACTION)
        ));
    }
    if !r
        .identifiability
        .pins_every_parameter(MAX_WEAKEST_RELATIVE_STD)
    {
        why.push(format!(
            "the motion does not pin every parameter (the weakest combination must be known to {:.0} %): {}",
            100.0 * MAX_WEAKEST_RELATIVE_STD,
            r.identifiability.verdict
        ));
    }
    if why.is_empty() {
        return Ok(());
    }
    anyhow::bail!(
        "calibration refused, nothing written: {}.\n\
         Data: {accepted} reference poses accepted, {rejected} rejected ({} in the window), {} encoder samples, \
         t = {:.3} .. {:.3} s; relative standard deviations of (left, right, wheelbase): {:.2e}, {:.2e}, {:.2e}",
        why.join("; "),
        r.data.pose_samples,
        r.data.encoder_samples,
        r.data.start_s,
        r.data.end_s,
        r.identifiability.relative_std[0],
        r.identifiability.relative_std[1],
        r.identifiability.relative_std[2],
    )
}

/// Runs a calibration. `progress(done, total)` follows the filter. A
/// calibration the data does not support is an error (see
/// [`MIN_ACCEPTED_POSES`], [`MIN_ACCEPTED_FRACTION`] and
/// [`MAX_WEAKEST_RELATIVE_STD`]), so nothing is written from it.
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
    let run = run.map_err(|e| {
        let text = e.to_string();
        if text.contains("diverged") {
            anyhow::anyhow!(
                "calibration refused, nothing written: {text}. The poses disagree with the wheels: {DISAGREE_HINT}"
            )
        } else {
            anyhow::Error::from(e)
        }
    })?;
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

    check_support(&report)?;

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
        truth: None,
    };
    Ok((report, artefacts))
}
