//! A calibration's files: the report, the reference and dead-reckoned
//! trajectories (TUM) and the figures, written whole or not at all.

use std::path::Path;

use twindrive_files::Staging;
use twindrive_kinematics::Pose;

use crate::figures;
use crate::report::{Artefacts, Report};
use crate::self_cal::{ScanArtefacts, ScanReport};

/// Writes `out` (calib.json) and, beside it, `<stem>_*.svg/png` figures and
/// `<stem>_*.tum` trajectories.
pub fn write_outputs(report: &Report, art: &Artefacts, out: &Path) -> anyhow::Result<()> {
    let (dir, stem, file_name) = twindrive_files::split_out_path(out, "calib")?;
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
            art.truth,
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

/// Writes a self-calibration's `out` (calib.json) and, beside it, the
/// laser residual figure and the dead-reckoned tracks with the initial and
/// the calibrated parameters (`<stem>_dead_reckoning_*.tum`, in the frame
/// of the drive's start).
pub fn write_scan_outputs(
    report: &ScanReport,
    art: &ScanArtefacts,
    out: &Path,
) -> anyhow::Result<()> {
    let (dir, stem, file_name) = twindrive_files::split_out_path(out, "calib")?;
    let staging = Staging::new(&dir, &format!("calibrate:{stem}"))?;
    staging.write_with(&file_name, |w| {
        serde_json::to_writer_pretty(w, report).map_err(Into::into)
    })?;
    for (suffix, p) in [
        ("dead_reckoning_initial", art.initial),
        ("dead_reckoning_calibrated", art.reported),
    ] {
        let track = twindrive_estimation::dead_reckoning::dead_reckon(
            &art.wheels,
            Pose::new(0.0, 0.0, 0.0),
            art.span_s.0,
            art.span_s.1,
            &twindrive_kinematics::DiffDriveParams::new(p[0], p[1], p[2]),
        );
        staging.write_with(&format!("{stem}_{suffix}.tum"), |w| {
            let ns = |t: f64| (t * 1e9).round().max(0.0) as u64;
            twindrive_log::write_tum(track.into_iter().map(|(t, p)| (ns(t), p)), w)
                .map_err(Into::into)
        })?;
    }
    figures::laser_residual_figure(&art.residuals, staging.dir(), &stem)?;
    staging.commit()
}
