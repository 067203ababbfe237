//! A calibration's figures: each parameter over time with its ±3σ band,
//! and the innovations of the fused poses.

use std::path::Path;

use twindrive_plot::{Markers, Series, TimeFigure, palette, stride};

/// The fraction of the time the `trace` spans during which `value` lies
/// within ±3σ of the estimate of parameter `i` (each node holds until the
/// next).
pub fn inside_3_sigma_fraction(trace: &[(f64, [f64; 3], [f64; 3])], i: usize, value: f64) -> f64 {
    let (mut inside_s, mut total_s) = (0.0, 0.0);
    for w in trace.windows(2) {
        let ((t, v, s), (next_t, _, _)) = (&w[0], &w[1]);
        let dt_s = next_t - t;
        total_s += dt_s;
        if (value - v[i]).abs() <= 3.0 * s[i] {
            inside_s += dt_s;
        }
    }
    if total_s > 0.0 {
        inside_s / total_s
    } else {
        0.0
    }
}

/// Each parameter over time with its ±3σ band (drawn around the filter's
/// estimate at each time), the reported value and, for a simulated drive,
/// the truth, each with the fraction of the time it lies inside the band;
/// and the innovations.
pub fn calibration_figures(
    trace: &[(f64, [f64; 3], [f64; 3])],
    reported: [f64; 3],
    truth: Option<[f64; 3]>,
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
        let level = |v: f64| -> Vec<(f64, f64)> { span.iter().map(|t| (*t, v)).collect() };
        let pct = |v: f64| 100.0 * inside_3_sigma_fraction(trace, i, v);
        // The reported value a point at the end: the estimate ends there.
        let fin = [(span[1], reported[i])];
        let fin_label = format!(
            "reported (the final estimate): inside the band {:.0} % of the time",
            pct(reported[i])
        );
        let true_line = truth.map(|t| level(t[i]));
        let true_label = truth.map(|t| {
            format!(
                "truth (simulated): inside the band {:.0} % of the time",
                pct(t[i])
            )
        });
        // The truth first, the estimate above it: after convergence the
        // estimate runs along it.
        let mut series = Vec::new();
        if let (Some(points), Some(label)) = (&true_line, &true_label) {
            series.push(Series {
                label,
                points,
                color: palette::GOOD,
            });
        }
        series.push(Series {
            label: "filter estimate at each time",
            points: &mean,
            color: palette::TRUTH,
        });
        TimeFigure {
            title,
            strip: None,
            x_label: "t [s]",
            y_label: unit,
            series: &series,
            markers: &[Markers {
                label: &fin_label,
                points: &fin,
                color: palette::BAD,
            }],
            bands: &[twindrive_plot::Band {
                label: "±3σ around the filter estimate",
                lower: &lower,
                upper: &upper,
                color: palette::TRUTH,
            }],
        }
        .write(&dir.join(format!("{stem}_{file}")))?;
    }
    innovation_figure(innovations, &dir.join(format!("{stem}_innovations")))
}

/// The innovations of the fused poses, one panel per unit: position (x, y)
/// in metres, heading in radians; rejected poses marked in each.
fn innovation_figure(
    innovations: &[twindrive_estimation::InnovationRecord],
    base: &Path,
) -> anyhow::Result<()> {
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
    let rejected_xy: Vec<(f64, f64)> = comp(0, false).into_iter().chain(comp(1, false)).collect();
    let rejected_th = comp(2, false);
    let panels = [
        TimeFigure {
            title: "Position innovations of the fused poses",
            strip: None,
            x_label: "t [s]",
            y_label: "innovation [m]",
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
            ],
            markers: &[Markers {
                label: "rejected pose (x and y)",
                points: &rejected_xy,
                color: palette::BAD,
            }],
            bands: &[],
        },
        TimeFigure {
            title: "Heading innovations of the fused poses",
            strip: None,
            x_label: "t [s]",
            y_label: "innovation [rad]",
            series: &[Series {
                label: "θ [rad]",
                points: &th,
                color: palette::GOOD,
            }],
            markers: &[Markers {
                label: "rejected pose (θ)",
                points: &rejected_th,
                color: palette::BAD,
            }],
            bands: &[],
        },
    ];
    twindrive_plot::Panels { panels: &panels }.write(base)?;
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
        strip: None,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inside_fraction_weighs_each_node_by_the_time_it_holds() {
        // Estimate 1.0 ± 3 × 0.1 for 3 s, then 2.0 ± 3 × 0.1 for 1 s.
        let trace = [
            (0.0, [1.0; 3], [0.1; 3]),
            (3.0, [2.0; 3], [0.1; 3]),
            (4.0, [2.0; 3], [0.1; 3]),
        ];
        assert_eq!(inside_3_sigma_fraction(&trace, 0, 1.1), 0.75);
        assert_eq!(inside_3_sigma_fraction(&trace, 2, 2.0), 0.25);
        assert_eq!(inside_3_sigma_fraction(&trace, 1, 5.0), 0.0);
        assert_eq!(inside_3_sigma_fraction(&trace[..1], 1, 1.0), 0.0);
    }
}
