//! What a calibration reports (`calib.json`) and what its figures and
//! trajectories are drawn from.

use std::io::Write;
use std::path::Path;

use serde::Serialize;
use twindrive_estimation::batch::Identifiability;
use twindrive_estimation::dead_reckoning::dead_reckon;
use twindrive_estimation::{FilterHistory, PoseSample, StateVec, WheelSample};
use twindrive_kinematics::{DiffDriveParams, Pose};

use crate::job::Method;

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
    /// The true [dL, dR, b] when the drive was simulated (the log does not
    /// carry them; the caller that simulated it does), for the figures.
    pub truth: Option<[f64; 3]>,
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
pub(crate) fn params_of(state: &StateVec, std: impl Fn(usize) -> f64) -> ([f64; 3], [f64; 3]) {
    ([state[3], state[4], state[5]], [3, 4, 5].map(std))
}

/// The report as a few lines for a terminal; `out` is where it was written.
pub fn print_report(r: &Report, out: &Path, o: &mut impl Write) -> std::io::Result<()> {
    writeln!(
        o,
        "method {:?}, clock offset {:.3} s ({})",
        r.method, r.clock_offset_s, r.clock_offset_source
    )?;
    write_parameters(
        o,
        [r.left_diameter_m, r.right_diameter_m, r.wheelbase_m],
        [
            r.left_diameter_std_m,
            r.right_diameter_std_m,
            r.wheelbase_std_m,
        ],
        r.initial,
    )?;
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

/// The three parameters with their deviations and their change from the
/// initial values, one line each.
pub(crate) fn write_parameters(
    o: &mut impl Write,
    values: [f64; 3],
    stds: [f64; 3],
    initial: [f64; 3],
) -> std::io::Result<()> {
    for (i, name) in ["left diameter ", "right diameter", "wheelbase     "]
        .iter()
        .enumerate()
    {
        writeln!(
            o,
            "  {name} {:.6} m ± {:.6} (initial {:.6}, {:+.3} %)",
            values[i],
            stds[i],
            initial[i],
            100.0 * (values[i] / initial[i] - 1.0)
        )?;
    }
    Ok(())
}
