//! A calibration's figures: each parameter over time with its ±3σ band,
//! and the innovations of the fused poses.

use std::path::Path;

use twindrive_plot::{Markers, Series, TimeFigure, palette, stride};

/// Each parameter over time with its ±3σ band, and the innovations.
pub fn calibration_figures(
    trace: &[(f64, [f64; 3], [f64; 3])],
    reported: [f64; 3],
    innovations: &[twindrive_estimation::InnovationRecord],
    dir: &Path,
    stem: &str,
) -> anyhow::Result<()> {
    let k = stride(trace.len());
    let names = [
        ("left_diameter", "Left wheel diameter", "d_L [m]"),
        ("right_diameter", "Right wheel diameter", "d_R [m]"),
        ("wheelbase", "Wheelbase", "b [m]"),
    ];
    for (i, (file, title, unit)) in names.iter().enumerate() {
        // Skip the first nodes, whose prior band would dwarf the rest.
        let pts: Vec<&(f64, [f64; 3], [f64; 3])> = trace.iter().step_by(k).collect();
        let skip = pts.len() / 50;
        let pts = &pts[skip.min(pts.len().saturating_sub(1))..];
        let mean: Vec<(f64, f64)> = pts.iter().map(|(t, v, _)| (*t, v[i])).collect();
        let upper: Vec<(f64, f64)> = pts
            .iter()
            .map(|(t, v, s)| (*t, v[i] + 3.0 * s[i]))
            .collect();
        let lower: Vec<(f64, f64)> = pts
            .iter()
            .map(|(t, v, s)| (*t, v[i] - 3.0 * s[i]))
            .collect();
        let span = [mean[0].0, mean[mean.len() - 1].0];
        let fin: Vec<(f64, f64)> = span.iter().map(|t| (*t, reported[i])).collect();
        TimeFigure {
            title,
            x_label: "t [s]",
            y_label: unit,
            series: &[
                Series {
                    label: "filter estimate",
                    points: &mean,
                    color: palette::TRUTH,
                },
                Series {
                    label: "reported",
                    points: &fin,
                    color: palette::BAD,
                },
            ],
            markers: &[],
            bands: &[twindrive_plot::Band {
                label: "±3σ",
                lower: &lower,
                upper: &upper,
                color: palette::TRUTH,
            }],
        }
        .write(&dir.join(format!("{stem}_{file}")))?;
    }
    let k = stride(innovations.len());
    let comp = |c: usize, accepted: bool| -> Vec<(f64, f64)> {
        innovations
            .iter()
            .step_by(k)
            .filter(|r| r.accepted == accepted)
            .map(|r| (r.t_s, r.innovation[c]))
            .collect()
    };
    let (x, y, th) = (comp(0, true), comp(1, true), comp(2, true));
    let rejected = comp(0, false);
    TimeFigure {
        title: "Innovations of the fused poses",
        x_label: "t [s]",
        y_label: "innovation [m, rad]",
        series: &[
            Series {
                label: "x [m]",
                points: &x,
                color: palette::TRUTH,
            },
            Series {
                label: "y [m]",
                points: &y,
                color: palette::ALT,
            },
            Series {
                label: "θ [rad]",
                points: &th,
                color: palette::GOOD,
            },
        ],
        markers: &[Markers {
            label: "rejected (x)",
            points: &rejected,
            color: palette::BAD,
        }],
        bands: &[],
    }
    .write(&dir.join(format!("{stem}_innovations")))?;
    Ok(())
}

/// A self-calibration's laser residuals (measured minus predicted motion of
/// the lidar over each interval, with the calibrated parameters) over time.
pub fn laser_residual_figure(
    residuals: &[(f64, [f64; 3])],
    dir: &Path,
    stem: &str,
) -> anyhow::Result<()> {
    let k = stride(residuals.len());
    let comp = |c: usize| -> Vec<(f64, f64)> {
        residuals
            .iter()
            .step_by(k)
            .map(|(t, r)| (*t, r[c]))
            .collect()
    };
    let (x, y, th) = (comp(0), comp(1), comp(2));
    TimeFigure {
        title: "Laser odometry against the calibrated model",
        x_label: "t [s]",
        y_label: "residual [m, rad]",
        series: &[
            Series {
                label: "x [m]",
                points: &x,
                color: palette::TRUTH,
            },
            Series {
                label: "y [m]",
                points: &y,
                color: palette::ALT,
            },
            Series {
                label: "θ [rad]",
                points: &th,
                color: palette::GOOD,
            },
        ],
        markers: &[],
        bands: &[],
    }
    .write(&dir.join(format!("{stem}_laser_residuals")))?;
    Ok(())
}
