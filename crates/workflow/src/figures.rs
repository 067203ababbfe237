//! The figures: those of `simulate` (the world with the driven path and bump
//! points, paper Figs. 4 and 6a; wheel speeds and side-range readings over
//! time, Fig. 5) and of `plan` (Figs. 7, 8a, 8b and 9). A calibration's
//! are `twindrive-calibrate`'s.

use std::path::Path;

use twindrive_log::MissionLog;
use twindrive_mission::redundancy::DeletionReason;
use twindrive_plot::{Markers, Series, TimeFigure, WorldFigure, palette, stride};
use twindrive_sim::World;

pub fn walls(world: &World) -> Vec<[(f64, f64); 2]> {
    world
        .segments()
        .iter()
        .map(|s| [(s.a.x, s.a.y), (s.b.x, s.b.y)])
        .collect()
}

pub fn mission_figures(log: &MissionLog, world: &World, dir: &Path) -> anyhow::Result<()> {
    let steps = &log.steps;
    let path: Vec<(f64, f64)> = steps
        .iter()
        .map(|s| (s.ground_truth.x_m, s.ground_truth.y_m))
        .collect();
    let bump_points: Vec<(f64, f64)> = steps
        .windows(2)
        .filter(|w| w[1].bump && !w[0].bump)
        .map(|w| (w[1].ground_truth.x_m, w[1].ground_truth.y_m))
        .collect();
    let start = [path[0]];
    let title = format!("{}: driven path (ground truth)", log.header.scenario);
    WorldFigure {
        title: &title,
        regions: &[],
        references: &[],
        walls: &walls(world),
        paths: &[Series {
            label: "path",
            points: &path,
            color: palette::TRUTH,
        }],
        markers: &[
            Markers {
                label: "start",
                points: &start,
                color: palette::GOOD,
            },
            Markers {
                label: "bump",
                points: &bump_points,
                color: palette::BAD,
            },
        ],
        outlines: &[],
    }
    .write(&dir.join("path"))?;

    let k = stride(steps.len());
    let left: Vec<(f64, f64)> = steps
        .iter()
        .step_by(k)
        .map(|s| (s.t_s(), s.wheel_rad_s[0]))
        .collect();
    let right: Vec<(f64, f64)> = steps
        .iter()
        .step_by(k)
        .map(|s| (s.t_s(), s.wheel_rad_s[1]))
        .collect();
    let bump_times: Vec<(f64, f64)> = steps
        .windows(2)
        .filter(|w| w[1].bump && !w[0].bump)
        .map(|w| (w[1].t_s(), 0.0))
        .collect();
    TimeFigure {
        title: "Wheel angular speeds",
        strip: None,
        x_label: "t [s]",
        y_label: "wheel speed [rad/s]",
        series: &[
            Series {
                label: "left",
                points: &left,
                color: palette::TRUTH,
            },
            Series {
                label: "right",
                points: &right,
                color: palette::ALT,
            },
        ],
        markers: &[Markers {
            label: "bump",
            points: &bump_times,
            color: palette::BAD,
        }],
        bands: &[],
    }
    .write(&dir.join("wheel_speeds"))?;

    // One figure of every ranger (the side IR of the case study).
    let singles: Vec<(usize, &str)> = log
        .header
        .range_sensors
        .iter()
        .enumerate()
        .filter(|(_, s)| s.kind == twindrive_log::SensorKind::Ranger)
        .map(|(i, s)| (i, s.name.as_str()))
        .collect();
    if !singles.is_empty() {
        let readings: Vec<Vec<(f64, f64)>> = singles
            .iter()
            .map(|&(i, _)| {
                let pts: Vec<(f64, f64)> = (0..steps.len())
                    .filter_map(|k| log.range_reading(k, i).map(|r| (steps[k].t_s(), r[0])))
                    .collect();
                let k = stride(pts.len());
                pts.into_iter().step_by(k).collect()
            })
            .collect();
        let colors = [palette::TRUTH, palette::ALT, palette::GOOD, palette::PURPLE];
        let series: Vec<Series> = singles
            .iter()
            .zip(&readings)
            .enumerate()
            .map(|(j, (&(_, name), pts))| Series {
                label: name,
                points: pts,
                color: colors[j % colors.len()],
            })
            .collect();
        TimeFigure {
            title: "Side range sensor: distance to the wall along the beam",
            strip: None,
            x_label: "t [s]",
            y_label: "range [m]",
            series: &series,
            markers: &[Markers {
                label: "bump",
                points: &bump_times,
                color: palette::BAD,
            }],
            bands: &[],
        }
        .write(&dir.join("side_ir"))?;
    }
    Ok(())
}

/// The pipeline's figures (paper Figs. 7, 8a, 8b and 9): `<stem>_executed`,
/// `<stem>_cleaned`, `<stem>_filtered` and `<stem>_wheel_speeds`.
pub fn plan_figures(
    stages: &twindrive_mission::pipeline::Stages,
    walls: &[[(f64, f64); 2]],
    dir: &Path,
    stem: &str,
) -> anyhow::Result<()> {
    use twindrive_mission::PathSample;
    let xy = |p: &[PathSample]| -> Vec<(f64, f64)> {
        p.iter().map(|s| (s.pose.x_m, s.pose.y_m)).collect()
    };
    let executed = xy(&stages.executed);
    let deleted: Vec<Vec<(f64, f64)>> = stages
        .pruned
        .deletions
        .iter()
        .map(|d| {
            let from = d.first_removed.saturating_sub(1);
            let to = (d.last_removed + 1).min(executed.len() - 1);
            executed[from..=to].to_vec()
        })
        .collect();
    // Kept runs: between deletions, each joined to the next across its jump.
    let mut kept: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut from = 0;
    for d in &stages.pruned.deletions {
        let last_kept = d.first_removed.saturating_sub(1);
        let mut run = executed[from..=last_kept].to_vec();
        if let Some(&next) = executed.get(d.last_removed + 1) {
            run.push(next);
        }
        kept.push(run);
        from = d.last_removed + 1;
    }
    if from < executed.len() {
        kept.push(executed[from..].to_vec());
    }
    let uncovered: Vec<Vec<(f64, f64)>> = stages
        .coverage
        .uncovered_stretches
        .iter()
        .map(|u| {
            executed[u.first.saturating_sub(1)..=(u.last + 1).min(executed.len() - 1)].to_vec()
        })
        .collect();
    let mut paths = Vec::new();
    for (k, d) in deleted.iter().enumerate() {
        paths.push(Series {
            label: if k == 0 { "redundant (deleted)" } else { "" },
            points: d,
            color: palette::BAD,
        });
    }
    for (k, run) in kept.iter().enumerate() {
        paths.push(Series {
            label: if k == 0 {
                "kept (the plan's route)"
            } else {
                ""
            },
            points: run,
            color: palette::TRUTH,
        });
    }
    for (k, u) in uncovered.iter().enumerate() {
        paths.push(Series {
            label: if k == 0 {
                "explored but not covered by the plan"
            } else {
                ""
            },
            points: u,
            color: palette::ALT,
        });
    }
    // The pinch points each cut joined (the kept samples either side).
    let pinches: Vec<(f64, f64)> = stages
        .pruned
        .deletions
        .iter()
        .filter(|d| d.reason != DeletionReason::TrailingRetrace)
        .flat_map(|d| {
            [
                executed[d.first_removed.saturating_sub(1)],
                executed[(d.last_removed + 1).min(executed.len() - 1)],
            ]
        })
        .collect();
    let start = [executed[0]];
    let plan_end = [stages
        .pruned
        .kept
        .last()
        .map_or(executed[0], |&k| executed[k])];
    let mission_end = [*executed.last().expect("an executed path")];
    let mut markers = vec![
        Markers {
            label: "start",
            points: &start,
            color: palette::GOOD,
        },
        Markers {
            label: "pinch points",
            points: &pinches,
            color: palette::PURPLE,
        },
    ];
    if plan_end != mission_end {
        markers.push(Markers {
            label: "plan ends (the rest retraced covered ground)",
            points: &plan_end,
            color: palette::TRUTH,
        });
        markers.push(Markers {
            label: "mission ended",
            points: &mission_end,
            color: palette::BAD,
        });
    }
    WorldFigure {
        title: "Mission planner: executed path, kept and redundant parts, pinch points (Fig. 7)",
        regions: &[],
        references: &[],
        walls,
        paths: &paths,
        markers: &markers,
        outlines: &[],
    }
    .write(&dir.join(format!("{stem}_executed")))?;

    let cleaned = xy(&stages.cleaned);
    let spikes: Vec<(f64, f64)> = stages
        .filtered
        .spikes
        .iter()
        .map(|s| cleaned[s.segment.min(cleaned.len() - 1)])
        .collect();
    WorldFigure {
        title: "Redundancy removed: control spikes (Fig. 8a)",
        regions: &[],
        references: &[],
        walls,
        paths: &[Series {
            label: "cleaned path",
            points: &cleaned,
            color: palette::TRUTH,
        }],
        markers: &[Markers {
            label: "control spikes",
            points: &spikes,
            color: palette::BAD,
        }],
        outlines: &[],
    }
    .write(&dir.join(format!("{stem}_cleaned")))?;

    let filtered = xy(&stages.filtered.samples);
    WorldFigure {
        title: "Filtered path: the plan (Fig. 8b)",
        regions: &[],
        references: &[],
        walls,
        paths: &[
            Series {
                label: "cleaned path",
                points: &cleaned,
                color: palette::MUTED,
            },
            Series {
                label: "plan (spikes filtered)",
                points: &filtered,
                color: palette::GOOD,
            },
        ],
        markers: &[],
        outlines: &[],
    }
    .write(&dir.join(format!("{stem}_filtered")))?;

    // Every segment: thinning could drop the one-segment spikes this
    // figure exists to show.
    let wheel = |p: &[PathSample], c: &[twindrive_mission::control::WheelCommand], w: usize| {
        p.iter()
            .zip(c)
            .map(|(s, c)| (s.t_s, c.wheels()[w]))
            .collect::<Vec<_>>()
    };
    let (cl, cr) = (
        wheel(&stages.cleaned, &stages.cleaned_commands, 0),
        wheel(&stages.cleaned, &stages.cleaned_commands, 1),
    );
    let f = &stages.filtered;
    let (fl, fr) = (
        wheel(&f.samples, &f.commands, 0),
        wheel(&f.samples, &f.commands, 1),
    );
    TimeFigure {
        title: "Wheel speeds before and after filtering (Fig. 9)",
        strip: None,
        x_label: "t [s]",
        y_label: "wheel speed [rad/s]",
        series: &[
            Series {
                label: "left, before",
                points: &cl,
                color: palette::MUTED,
            },
            Series {
                label: "right, before",
                points: &cr,
                color: palette::ALT,
            },
            Series {
                label: "left, filtered",
                points: &fl,
                color: palette::TRUTH,
            },
            Series {
                label: "right, filtered",
                points: &fr,
                color: palette::GOOD,
            },
        ],
        markers: &[],
        bands: &[],
    }
    .write(&dir.join(format!("{stem}_wheel_speeds")))?;
    Ok(())
}
