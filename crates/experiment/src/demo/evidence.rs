//! The paper's evidence: Table 1 (ellipses fitted to one circle of the
//! tracker path and of dead reckoning with nominal and calibrated parameters)
//! and Section 6 (how parameter errors make dead reckoning drift).

use std::path::Path;

use anyhow::Context;
use serde::Serialize;
use twindrive_estimation::WheelSample;
use twindrive_estimation::dead_reckoning::{dead_reckon, pose_at};
use twindrive_estimation::ellipse_fit::{Ellipse, fit_ellipse};
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_log::MissionLog;
use twindrive_plot::{Series, TimeFigure, WorldFigure, palette};

use twindrive_calibrate::inputs;

use super::report::Report;

#[derive(Debug, Clone, Serialize)]
pub struct EllipseRow {
    pub source: String,
    pub major_axis_m: f64,
    pub minor_axis_m: f64,
    pub area_m2: f64,
    /// Percent errors against the tracker's ellipse.
    pub major_error_pct: f64,
    pub minor_error_pct: f64,
    pub area_error_pct: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Table1 {
    pub t0_s: f64,
    pub t1_s: f64,
    pub rows: Vec<EllipseRow>,
}

fn params(p: [f64; 3]) -> DiffDriveParams {
    DiffDriveParams::new(p[0], p[1], p[2])
}

/// The first full turn of the robot after `after_s`, as (t0, t1).
fn first_lap(track: &[(f64, Pose)], after_s: f64) -> Option<(f64, f64)> {
    let start = track.iter().position(|(t, _)| *t >= after_s)?;
    let h0 = track[start].1.heading_rad;
    let mut acc = 0.0;
    let mut prev = h0;
    for (t, p) in &track[start + 1..] {
        acc += twindrive_kinematics::wrap_angle(p.heading_rad - prev);
        prev = p.heading_rad;
        if acc.abs() >= std::f64::consts::TAU {
            return Some((track[start].0, *t));
        }
    }
    None
}

fn row(source: &str, e: &Ellipse, truth: &Ellipse) -> EllipseRow {
    let pct = |a: f64, b: f64| 100.0 * (a / b - 1.0);
    EllipseRow {
        source: source.into(),
        major_axis_m: e.major_axis_m,
        minor_axis_m: e.minor_axis_m,
        area_m2: e.area_m2(),
        major_error_pct: pct(e.major_axis_m, truth.major_axis_m),
        minor_error_pct: pct(e.minor_axis_m, truth.minor_axis_m),
        area_error_pct: pct(e.area_m2(), truth.area_m2()),
    }
}

/// Table 1 on one circle of a calibration drive, with its figure.
pub fn table1(
    log: &MissionLog,
    nominal: [f64; 3],
    calibrated: [f64; 3],
    dir: &Path,
) -> anyhow::Result<Table1> {
    let wheels = inputs::wheels_from_log(log);
    let tracker: Vec<(f64, Pose)> = log
        .steps
        .iter()
        .filter_map(|s| s.tracker.map(|p| (s.t_s(), p)))
        .collect();
    // Skip the first two seconds: the wheels are still speeding up.
    let (t0, t1) = first_lap(&tracker, 2.0).context("the calibration drive has no full circle")?;
    let lap: Vec<(f64, f64)> = tracker
        .iter()
        .filter(|(t, _)| *t >= t0 && *t <= t1)
        .map(|(_, p)| (p.x_m, p.y_m))
        .collect();
    let start = pose_at(&tracker, t0).context("tracker pose at the lap start")?;
    let dr = |p: [f64; 3]| -> Vec<(f64, f64)> {
        dead_reckon(&wheels, start, t0, t1, &params(p))
            .iter()
            .map(|(_, q)| (q.x_m, q.y_m))
            .collect()
    };
    let (nom, cal) = (dr(nominal), dr(calibrated));
    let fit = |pts: &[(f64, f64)], what: &str| {
        fit_ellipse(pts).with_context(|| format!("fitting an ellipse to {what}"))
    };
    let truth = fit(&lap, "the tracker path")?;
    let rows = vec![
        row("tracker (ground truth)", &truth, &truth),
        row(
            "dead reckoning, nominal",
            &fit(&nom, "nominal dead reckoning")?,
            &truth,
        ),
        row(
            "dead reckoning, calibrated",
            &fit(&cal, "calibrated dead reckoning")?,
            &truth,
        ),
    ];
    WorldFigure {
        title: "Table 1: one circle, tracker vs dead reckoning",
        regions: &[],
        // The tracker is what the others are measured against: a band
        // under them, so the calibrated path cannot hide it.
        references: &[Series {
            label: "tracker",
            points: &lap,
            color: palette::TRUTH,
        }],
        walls: &[],
        paths: &[
            Series {
                label: "dead reckoning, nominal",
                points: &nom,
                color: palette::BAD,
            },
            Series {
                label: "dead reckoning, calibrated",
                points: &cal,
                color: palette::GOOD,
            },
        ],
        markers: &[],
        outlines: &[],
    }
    .write(&dir.join("table1_circle"))?;
    Ok(Table1 {
        t0_s: t0,
        t1_s: t1,
        rows,
    })
}

#[derive(Debug, Clone, Serialize)]
pub struct PathError {
    pub label: String,
    /// Mean squared distance between the true and the dead-reckoned path (m²).
    pub mean_squared_error_m2: f64,
    pub rms_error_m: f64,
    /// Sum over samples of the distance between the paths (m).
    pub sum_abs_difference_m: f64,
    pub final_error_m: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Section6 {
    pub wheelbase_perturbation: Vec<PathError>,
    /// (parameter, relative error %, RMS drift m).
    pub sweep: Vec<(String, f64, f64)>,
}

fn path_error(
    label: &str,
    truth: &[(f64, Pose)],
    wheels: &[WheelSample],
    p: [f64; 3],
) -> PathError {
    let (t0, t1) = (truth[0].0, truth[truth.len() - 1].0);
    let dr = dead_reckon(wheels, truth[0].1, t0, t1, &params(p));
    let d: Vec<f64> = truth
        .iter()
        .filter_map(|(t, g)| pose_at(&dr, *t).map(|q| q.distance_to(g)))
        .collect();
    let n = d.len().max(1) as f64;
    let mse = d.iter().map(|x| x * x).sum::<f64>() / n;
    PathError {
        label: label.into(),
        mean_squared_error_m2: mse,
        rms_error_m: mse.sqrt(),
        sum_abs_difference_m: d.iter().sum(),
        final_error_m: d.last().copied().unwrap_or(0.0),
    }
}

/// Section 6 on a mission log: the wheelbase ±4 % (paper Fig. 10) and a
/// -5 %..+5 % sweep of each parameter, with figures.
pub fn section6(log: &MissionLog, calibrated: [f64; 3], dir: &Path) -> anyhow::Result<Section6> {
    let wheels = inputs::wheels_from_log(log);
    let truth: Vec<(f64, Pose)> = log
        .steps
        .iter()
        .filter(|s| s.encoder_ticks.is_some())
        .map(|s| (s.t_s(), s.ground_truth))
        .collect();
    let scaled = |i: usize, f: f64| {
        let mut p = calibrated;
        p[i] *= f;
        p
    };
    let perturbations = [
        ("calibrated", calibrated),
        ("wheelbase +4 %", scaled(2, 1.04)),
        ("wheelbase -4 %", scaled(2, 0.96)),
    ];
    let wheelbase_perturbation: Vec<PathError> = perturbations
        .iter()
        .map(|(l, p)| path_error(l, &truth, &wheels, *p))
        .collect();

    let xy = |p: [f64; 3]| -> Vec<(f64, f64)> {
        dead_reckon(
            &wheels,
            truth[0].1,
            truth[0].0,
            truth[truth.len() - 1].0,
            &params(p),
        )
        .iter()
        .map(|(_, q)| (q.x_m, q.y_m))
        .collect()
    };
    let true_xy: Vec<(f64, f64)> = truth.iter().map(|(_, p)| (p.x_m, p.y_m)).collect();
    let (plus, minus, cal) = (
        xy(perturbations[1].1),
        xy(perturbations[2].1),
        xy(calibrated),
    );
    WorldFigure {
        title: "Section 6: dead reckoning with the wheelbase off by ±4 % (paper Fig. 10)",
        regions: &[],
        // The true path a band under the dead-reckoned ones: the
        // calibrated one runs along it.
        references: &[Series {
            label: "true path",
            points: &true_xy,
            color: palette::TRUTH,
        }],
        walls: &[],
        paths: &[
            Series {
                label: "calibrated",
                points: &cal,
                color: palette::GOOD,
            },
            Series {
                label: "wheelbase +4 %",
                points: &plus,
                color: palette::BAD,
            },
            Series {
                label: "wheelbase -4 %",
                points: &minus,
                color: palette::ALT,
            },
        ],
        markers: &[],
        outlines: &[],
    }
    .write(&dir.join("section6_wheelbase"))?;

    let names = ["left diameter", "right diameter", "wheelbase"];
    let mut sweep = Vec::new();
    let mut curves: Vec<Vec<(f64, f64)>> = vec![Vec::new(); 3];
    for (i, name) in names.iter().enumerate() {
        for k in -10..=10 {
            let pct = 0.5 * k as f64;
            let e = path_error(name, &truth, &wheels, scaled(i, 1.0 + pct / 100.0));
            curves[i].push((pct, e.rms_error_m));
            sweep.push((name.to_string(), pct, e.rms_error_m));
        }
    }
    TimeFigure {
        title: "Section 6: dead-reckoning drift against parameter error",
        strip: None,
        x_label: "parameter error [%]",
        y_label: "RMS distance to the true path [m]",
        series: &[
            Series {
                label: names[0],
                points: &curves[0],
                color: palette::TRUTH,
            },
            Series {
                label: names[1],
                points: &curves[1],
                color: palette::ALT,
            },
            Series {
                label: names[2],
                points: &curves[2],
                color: palette::GOOD,
            },
        ],
        markers: &[],
        bands: &[],
    }
    .write(&dir.join("section6_sweep"))?;
    Ok(Section6 {
        wheelbase_perturbation,
        sweep,
    })
}

/// Table 1 and Section 6 as sections of `r` at heading `level`, their
/// figures under `figures` (a path prefix relative to the report). The
/// case study's report and `evidence.md` both render them from here.
pub fn add_to(r: &mut Report, t1: &Table1, s6: &Section6, level: u8, figures: &str) {
    let f = |v: f64, d: usize| format!("{v:.d$}");
    r.heading(level, "Table 1: an ellipse fitted to one circle");
    r.paragraph(format!(
        "One circle of the drive (t = {:.2} .. {:.2} s) as the tracker saw it, and as dead reckoning          with the hand-measured and with the calibrated parameters reconstructs it.",
        t1.t0_s, t1.t1_s
    ));
    r.table(
        &[
            "path",
            "major axis (m)",
            "minor axis (m)",
            "area (m²)",
            "major err",
            "minor err",
            "area err",
        ],
        t1.rows
            .iter()
            .map(|row| {
                vec![
                    row.source.clone(),
                    f(row.major_axis_m, 4),
                    f(row.minor_axis_m, 4),
                    f(row.area_m2, 4),
                    format!("{:+.3} %", row.major_error_pct),
                    format!("{:+.3} %", row.minor_error_pct),
                    format!("{:+.3} %", row.area_error_pct),
                ]
            })
            .collect(),
    );
    r.figure(
        format!("{figures}table1_circle"),
        "One circle: tracker, nominal and calibrated dead reckoning",
    );
    r.heading(level, "Section 6: what a wrong wheelbase costs");
    r.table(
        &[
            "dead reckoning",
            "mean squared error (m²)",
            "RMS (m)",
            "sum of abs. differences (m)",
            "final error (m)",
        ],
        s6.wheelbase_perturbation
            .iter()
            .map(|e| {
                vec![
                    e.label.clone(),
                    f(e.mean_squared_error_m2, 4),
                    f(e.rms_error_m, 3),
                    f(e.sum_abs_difference_m, 1),
                    f(e.final_error_m, 3),
                ]
            })
            .collect(),
    );
    r.figure(
        format!("{figures}section6_wheelbase"),
        "Wheelbase ±4 %: dead-reckoned paths against the true one (Fig. 10)",
    );
    r.figure(
        format!("{figures}section6_sweep"),
        "Drift against the error of each parameter",
    );
}

/// `evidence.md`, for the directory `dir` its figures are in.
pub fn markdown(t1: &Table1, s6: &Section6, dir: &Path) -> anyhow::Result<String> {
    let mut r = Report::default();
    add_to(&mut r, t1, s6, 2, "");
    r.markdown(dir)
}
