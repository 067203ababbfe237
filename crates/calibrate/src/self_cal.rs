//! Self-calibration: the wheel diameters, the wheelbase and the lidar's
//! mount on the robot (and a gyro's bias and scale) from the robot's own
//! encoders, scans and gyro, with no pose reference (Censi, Franchi,
//! Marchionni, Oriolo, IEEE T-RO 2013): laser odometry, Censi's closed form
//! (which needs no guess of the mount), then the maximum-likelihood fit
//! from it, checked against each other; a drive that does not pin every
//! parameter is refused with the reason.

use std::collections::BTreeMap;

use anyhow::bail;
use serde::Serialize;
use twindrive_estimation::WheelSample;
use twindrive_estimation::batch::Identifiability;
use twindrive_estimation::localize::Scan;
use twindrive_estimation::selfcal::{
    LaserOdometrySettings, SelfCalConfig, closed_form, fit, laser_odometry, predict_laser_motion,
};
use twindrive_kinematics::{Pose, wrap_angle};

/// Fewest intervals the matcher must give for a self-calibration to count.
pub const MIN_INTERVALS: usize = 30;
/// A parameter known to worse than this many times its tolerance (0.2 %
/// on the wheels, 2 mm and 0.1° on the mount) is not pinned: refused.
/// Between its tolerance and this the report warns.
pub const MAX_TOLERANCE_MULTIPLE: f64 = 25.0;

/// One self-calibration's inputs, checked.
#[derive(Debug, Clone)]
pub struct ScanJob {
    pub wheels: Vec<WheelSample>,
    /// The lidar's scans in its own frame, in time order.
    pub scans: Vec<Scan>,
    /// The gyro's yaw rate `(t_s, rad_s)`; empty without a gyro.
    pub gyro: Vec<(f64, f64)>,
    /// Starting [dL, dR, b] (m).
    pub initial: [f64; 3],
    /// The lidar: its name and where it is believed to sit, the priors'
    /// guess (the estimate does not start from it).
    pub lidar: String,
    pub mount_guess: Pose,
    /// Where the guess came from ("log header", "/tf_static", "--mount").
    pub mount_source: String,
    pub settings: LaserOdometrySettings,
    pub ticks_per_rev: Option<u32>,
    /// Subtracted from the input's times (bags: Unix seconds).
    pub time_origin_s: f64,
}

/// A planar pose in a report.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Mount {
    pub x_m: f64,
    pub y_m: f64,
    pub heading_rad: f64,
}

/// `calib.json` of a self-calibration. Its first six fields are those of a
/// calibration against a pose reference, so everything that reads a
/// calibration's parameters reads this one too.
#[derive(Debug, Clone, Serialize)]
pub struct ScanReport {
    pub left_diameter_m: f64,
    pub right_diameter_m: f64,
    pub wheelbase_m: f64,
    pub left_diameter_std_m: f64,
    pub right_diameter_std_m: f64,
    pub wheelbase_std_m: f64,
    /// Always "scans": no pose reference.
    pub reference: &'static str,
    pub method: &'static str,
    pub initial: [f64; 3],
    pub lidar: String,
    /// The lidar's pose in `base_link`.
    pub lidar_mount: Mount,
    pub lidar_mount_std: Mount,
    pub lidar_mount_guess: Mount,
    pub lidar_mount_guess_source: String,
    pub gyro: Option<GyroReport>,
    pub identifiability: Identifiability,
    pub laser_odometry: OdometrySummary,
    pub cross_check: ScanCrossCheck,
    pub data: ScanData,
}

#[derive(Debug, Clone, Copy, Serialize)]
pub struct GyroReport {
    pub bias_rad_s: f64,
    pub bias_std_rad_s: f64,
    pub scale_error: f64,
    pub scale_error_std: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct OdometrySummary {
    pub scans: usize,
    pub interval_s: f64,
    pub consecutive_matched: usize,
    pub consecutive_refused: BTreeMap<&'static str, usize>,
    /// Intervals matched, left out as standstills, refused by reason.
    pub intervals: usize,
    pub standstills: usize,
    pub refused: BTreeMap<&'static str, usize>,
    /// Intervals in the final fit, and trimmed as outliers.
    pub used: usize,
    pub trimmed: usize,
    pub whitened_rms: f64,
    /// RMS of the laser residuals [x (m), y (m), θ (rad)].
    pub residual_rms: [f64; 3],
}

#[derive(Debug, Clone, Serialize)]
pub struct ScanCrossCheck {
    /// [dL, dR, b, ℓx, ℓy, ℓθ] of the maximum-likelihood fit (reported).
    pub ml: [f64; 6],
    /// Censi's closed form, where the drive lets it solve.
    pub closed_form: Option<[f64; 6]>,
    pub closed_form_std: Option<[f64; 6]>,
    /// Largest |ml / closed form − 1| over dL, dR, b.
    pub max_relative_difference: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct ScanData {
    pub encoder_samples: usize,
    pub scans: usize,
    pub gyro_samples: usize,
    pub start_s: f64,
    pub end_s: f64,
    pub ticks_per_rev: Option<u32>,
    pub time_origin_s: f64,
}

/// What the figures and trajectories of a self-calibration are drawn from.
#[derive(Debug, Clone)]
pub struct ScanArtefacts {
    pub reported: [f64; 3],
    pub initial: [f64; 3],
    pub wheels: Vec<WheelSample>,
    /// (t1 of the interval, laser residual [x, y, θ]) of every interval.
    pub residuals: Vec<(f64, [f64; 3])>,
    pub span_s: (f64, f64),
}

/// Runs a self-calibration; `progress(done, total)` follows the scans. A
/// drive the data do not support (too few matched intervals, a parameter
/// not pinned) is an error that says why, and nothing is written.
pub fn self_calibrate(
    job: ScanJob,
    progress: impl FnMut(usize, usize),
) -> anyhow::Result<(ScanReport, ScanArtefacts)> {
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
    let usable = job
        .scans
        .iter()
        .filter(|s| s.points().len() >= job.settings.matcher.min_points)
        .count();
    if usable < 2 {
        bail!(
            "no usable scans: {} scans from {}, {usable} with at least {} returns (all max-range, dropouts or \
             an open space); a self-calibration needs the lidar to see walls",
            job.scans.len(),
            job.lidar,
            job.settings.matcher.min_points
        );
    }
    let g = job.mount_guess;
    let guess = [
        job.initial[0],
        job.initial[1],
        job.initial[2],
        g.x_m,
        g.y_m,
        g.heading_rad,
    ];
    let odo = laser_odometry(
        &job.scans,
        &job.wheels,
        &job.gyro,
        guess,
        &job.settings,
        progress,
    );
    if odo.motions.len() < MIN_INTERVALS {
        bail!(
            "calibration refused, nothing written: only {} intervals of {:.1} s were matched (at least {MIN_INTERVALS} \
             are needed). {} scans; consecutive scans matched {}, refused: {}; intervals refused: {}; standstills {}{}",
            odo.motions.len(),
            job.settings.interval_s,
            odo.scans,
            odo.consecutive_matched,
            counts(&odo.consecutive_refused),
            odo.refusals(),
            odo.standstills,
            if odo.motions.len() * 2 >= MIN_INTERVALS && job.settings.interval_s > 0.2 {
                format!(
                    ". A short drive gives more intervals with a shorter --interval-s (e.g. {:.1})",
                    job.settings.interval_s / 2.0
                )
            } else {
                String::new()
            }
        );
    }
    let cf = closed_form(&odo.motions);
    let start = cf.as_ref().map_or(guess, |c| c.params);
    let config = SelfCalConfig::default();
    let r = fit(&odo.motions, start, &config)
        .map_err(|e| anyhow::anyhow!("calibration refused, nothing written: {e}"))?;
    let ml = [
        r.params[0],
        r.params[1],
        r.params[2],
        r.mount[0],
        r.mount[1],
        r.mount[2],
    ];
    let residuals = odo
        .motions
        .iter()
        .map(|m| {
            let p = predict_laser_motion(&m.wheel_steps, ml);
            (
                m.t1_s,
                [
                    m.laser[0] - p[0],
                    m.laser[1] - p[1],
                    wrap_angle(m.laser[2] - p[2]),
                ],
            )
        })
        .collect();
    let (start_s, end_s) = (
        job.scans.first().map_or(0.0, |s| s.t_s),
        job.scans.last().map_or(0.0, |s| s.t_s),
    );
    let report = ScanReport {
        left_diameter_m: r.params[0],
        right_diameter_m: r.params[1],
        wheelbase_m: r.params[2],
        left_diameter_std_m: r.std[0],
        right_diameter_std_m: r.std[1],
        wheelbase_std_m: r.std[2],
        reference: "scans",
        method: "maximum likelihood over laser odometry (Censi's closed form as the start)",
        initial: job.initial,
        lidar: job.lidar.clone(),
        lidar_mount: Mount {
            x_m: r.mount[0],
            y_m: r.mount[1],
            heading_rad: r.mount[2],
        },
        lidar_mount_std: Mount {
            x_m: r.mount_std[0],
            y_m: r.mount_std[1],
            heading_rad: r.mount_std[2],
        },
        lidar_mount_guess: Mount {
            x_m: g.x_m,
            y_m: g.y_m,
            heading_rad: g.heading_rad,
        },
        lidar_mount_guess_source: job.mount_source.clone(),
        gyro: r.gyro.map(|gc| GyroReport {
            bias_rad_s: gc.bias_rad_s,
            bias_std_rad_s: gc.bias_std_rad_s,
            scale_error: gc.scale_error,
            scale_error_std: gc.scale_error_std,
        }),
        identifiability: r.identifiability.clone(),
        laser_odometry: OdometrySummary {
            scans: odo.scans,
            interval_s: job.settings.interval_s,
            consecutive_matched: odo.consecutive_matched,
            consecutive_refused: odo.consecutive_refused.clone(),
            intervals: odo.intervals,
            standstills: odo.standstills,
            refused: odo.refused.clone(),
            used: r.used,
            trimmed: r.trimmed,
            whitened_rms: r.whitened_rms,
            residual_rms: r.residual_rms,
        },
        cross_check: ScanCrossCheck {
            ml,
            closed_form: cf.as_ref().map(|c| c.params),
            closed_form_std: cf.as_ref().map(|c| c.std),
            max_relative_difference: cf.as_ref().map(|c| {
                (0..3)
                    .map(|i| (ml[i] / c.params[i] - 1.0).abs())
                    .fold(0.0, f64::max)
            }),
        },
        data: ScanData {
            encoder_samples: job.wheels.len(),
            scans: job.scans.len(),
            gyro_samples: job.gyro.len(),
            start_s,
            end_s,
            ticks_per_rev: job.ticks_per_rev,
            time_origin_s: job.time_origin_s,
        },
    };
    check_support(&report)?;
    Ok((
        report,
        ScanArtefacts {
            reported: [r.params[0], r.params[1], r.params[2]],
            initial: job.initial,
            wheels: job.wheels,
            residuals,
            span_s: (start_s, end_s),
        },
    ))
}

fn counts(map: &BTreeMap<&'static str, usize>) -> String {
    if map.is_empty() {
        return "none".into();
    }
    map.iter()
        .map(|(k, n)| format!("{n} {k}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Whether every parameter is pinned: the drive separates them and each is
/// known to within [`MAX_TOLERANCE_MULTIPLE`] times its tolerance.
pub fn pins_every_parameter(id: &Identifiability) -> bool {
    let tolerances = id.tolerance.as_deref().unwrap_or(&[]);
    id.separable()
        && id
            .relative_std
            .iter()
            .zip(tolerances)
            .all(|(s, t)| s.is_finite() && *s <= MAX_TOLERANCE_MULTIPLE * t)
}

fn check_support(r: &ScanReport) -> anyhow::Result<()> {
    if pins_every_parameter(&r.identifiability) {
        return Ok(());
    }
    bail!(
        "calibration refused, nothing written: the drive does not pin every parameter (each must be known to \
         {MAX_TOLERANCE_MULTIPLE} times its tolerance): {}\nData: {} intervals of {:.1} s matched from {} scans, \
         {} trimmed; t = {:.3} .. {:.3} s",
        r.identifiability.verdict,
        r.laser_odometry.intervals,
        r.laser_odometry.interval_s,
        r.laser_odometry.scans,
        r.laser_odometry.trimmed,
        r.data.start_s,
        r.data.end_s
    )
}

/// The report as a few lines for a terminal; `out` is where it was written.
pub fn print_scan_report(
    r: &ScanReport,
    out: &std::path::Path,
    o: &mut impl std::io::Write,
) -> std::io::Result<()> {
    writeln!(
        o,
        "self-calibration from {} ({} intervals matched of {:.1} s, {} trimmed; no pose reference)",
        r.lidar, r.laser_odometry.intervals, r.laser_odometry.interval_s, r.laser_odometry.trimmed
    )?;
    crate::report::write_parameters(
        o,
        [r.left_diameter_m, r.right_diameter_m, r.wheelbase_m],
        [
            r.left_diameter_std_m,
            r.right_diameter_std_m,
            r.wheelbase_std_m,
        ],
        r.initial,
    )?;
    let (m, s) = (&r.lidar_mount, &r.lidar_mount_std);
    writeln!(
        o,
        "  lidar mount    x {:.4} ± {:.4} m, y {:.4} ± {:.4} m, heading {:.3} ± {:.3} deg (guess from {}: {:.3}, {:.3}, {:.1} deg)",
        m.x_m,
        s.x_m,
        m.y_m,
        s.y_m,
        m.heading_rad.to_degrees(),
        s.heading_rad.to_degrees(),
        r.lidar_mount_guess_source,
        r.lidar_mount_guess.x_m,
        r.lidar_mount_guess.y_m,
        r.lidar_mount_guess.heading_rad.to_degrees()
    )?;
    if let Some(g) = &r.gyro {
        writeln!(
            o,
            "  gyro           bias {:.5} ± {:.5} rad/s, scale error {:+.4} ± {:.4}",
            g.bias_rad_s, g.bias_std_rad_s, g.scale_error, g.scale_error_std
        )?;
    }
    if let Some(d) = r.cross_check.max_relative_difference {
        writeln!(
            o,
            "  maximum likelihood vs Censi's closed form: largest difference {:.3} %",
            100.0 * d
        )?;
    }
    writeln!(o, "  {}", r.identifiability.verdict)?;
    writeln!(
        o,
        "wrote {} and its figures and trajectories beside it",
        out.display()
    )
}
