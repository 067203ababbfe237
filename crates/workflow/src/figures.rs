//! The figures: those of `simulate` (the world with the driven path and bump
//! points, paper Figs. 4 and 6a; wheel speeds and side-range readings over
//! time, Fig. 5), of `rehearse` (the path with the goals and the planned
//! way) and of `plan` (Figs. 7, 8a, 8b and 9). A calibration's are
//! `twindrive-calibrate`'s.

use std::path::Path;

use twindrive_log::MissionLog;
use twindrive_mission::goals::Goals;
use twindrive_mission::redundancy::DeletionReason;
use twindrive_mission::route::Route;
use twindrive_plot::{
    Markers, Outline, Series, TimeFigure, WaypointFigure, Waypoints, WorldFigure, palette, stride,
};
use twindrive_sim::World;

pub fn walls(world: &World) -> Vec<[(f64, f64); 2]> {
    world
        .segments()
        .iter()
        .map(|s| [(s.a.x, s.a.y), (s.b.x, s.b.y)])
        .collect()
}

/// Points in the site's frame (m).
type Points = Vec<(f64, f64)>;

/// A log's true path and where each bump began.
fn track_and_bumps(log: &MissionLog) -> (Points, Points) {
    let steps = &log.steps;
    let path = steps
        .iter()
        .map(|s| (s.ground_truth.x_m, s.ground_truth.y_m))
        .collect();
    let bumps = steps
        .windows(2)
        .filter(|w| w[1].bump && !w[0].bump)
        .map(|w| (w[1].ground_truth.x_m, w[1].ground_truth.y_m))
        .collect();
    (path, bumps)
}

pub fn mission_figures(log: &MissionLog, world: &World, dir: &Path) -> anyhow::Result<()> {
    let steps = &log.steps;
    let (path, bump_points) = track_and_bumps(log);
    let start = [path[0]];
    // A robot that held still, or moved less than the start marker
    // covers (a few pixels: 2 % of the figure's span), drew no path: the
    // start alone says so.
    let wall_points = walls(world);
    let span_m = wall_points
        .iter()
        .flat_map(|w| *w)
        .chain(path.iter().copied())
        .fold(None, |b: Option<[f64; 4]>, (x, y)| {
            Some(b.map_or([x, y, x, y], |b| {
                [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)]
            }))
        })
        .map_or(0.0, |b| (b[2] - b[0]).max(b[3] - b[1]));
    let moved = path
        .iter()
        .any(|p| (p.0 - path[0].0).hypot(p.1 - path[0].1) > 0.02 * span_m);
    let title = format!("{}: driven path (ground truth)", log.header.scenario);
    WorldFigure {
        title: &title,
        regions: &[],
        references: &[],
        walls: &wall_points,
        paths: &[Series {
            label: if moved { "path" } else { "" },
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

/// Where a rehearsal's way and goals are drawn: the goals' waypoints, the
/// areas to sweep, the way planned through them.
pub const WAYPOINT_COLOR: twindrive_plot::RGBColor = palette::PURPLE;
pub const AREA_COLOR: twindrive_plot::RGBColor = palette::CYAN;
pub const WAY_COLOR: twindrive_plot::RGBColor = palette::ALT;

/// A rehearsal from goals' path figure, `path.svg` and `path.png` in `dir`:
/// the track the twin drove (ground truth) over the way planned for it
/// (`route`, a pale band), the goals' waypoints as discs numbered in order
/// with an arrow for each heading given, the areas to sweep shaded with
/// their edges, the start and any bump.
pub fn rehearsal_path_figure(
    log: &MissionLog,
    world: &World,
    route: &Route,
    goals: &Goals,
    dir: &Path,
) -> anyhow::Result<()> {
    with_rehearsal_path_figure(log, world, route, goals, |figure| {
        figure.write(&dir.join("path"))?;
        Ok(())
    })
}

/// The figure of [`rehearsal_path_figure`], handed to `draw`.
fn with_rehearsal_path_figure<T>(
    log: &MissionLog,
    world: &World,
    route: &Route,
    goals: &Goals,
    draw: impl FnOnce(&WaypointFigure) -> anyhow::Result<T>,
) -> anyhow::Result<T> {
    let (track, bumps) = track_and_bumps(log);
    let Some(&first) = track.first() else {
        anyhow::bail!("{}: the rehearsal's log has no steps", log.header.scenario);
    };
    let way: Vec<(f64, f64)> = route.points.iter().map(|p| (p[0], p[1])).collect();
    let polygons: Vec<Vec<(f64, f64)>> = goals
        .areas
        .iter()
        .map(|a| a.polygon.iter().map(|p| (p[0], p[1])).collect())
        .collect();
    // An area is an outline over the track: a sweep fills it, and a
    // shaded area under the track would be hidden by the very sweep it
    // asks for.
    let areas: Vec<Outline> = polygons
        .iter()
        .enumerate()
        .map(|(k, corners)| Outline {
            label: if k == 0 { "area to sweep" } else { "" },
            corners,
            color: AREA_COLOR,
        })
        .collect();
    let points: Vec<(f64, f64)> = goals.waypoints.iter().map(|w| (w.x_m, w.y_m)).collect();
    let headings: Vec<Option<f64>> = goals.waypoints.iter().map(|w| w.heading_rad).collect();
    let title = format!(
        "{}: rehearsal from goals, the twin's track over the planned way",
        log.header.scenario
    );
    draw(&WaypointFigure {
        world: WorldFigure {
            title: &title,
            walls: &walls(world),
            regions: &[],
            paths: &[Series {
                label: "driven (ground truth)",
                points: &track,
                color: palette::TRUTH,
            }],
            references: &[Series {
                label: "planned way (route.json)",
                points: &way,
                color: WAY_COLOR,
            }],
            markers: &[
                Markers {
                    label: "start",
                    points: &[first],
                    color: palette::GOOD,
                },
                Markers {
                    label: "bump",
                    points: &bumps,
                    color: palette::BAD,
                },
            ],
            outlines: &areas,
        },
        waypoints: Waypoints {
            label: "waypoint, numbered in order (arrow: its heading)",
            points: &points,
            headings_rad: &headings,
            color: WAYPOINT_COLOR,
        },
    })
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
    // The redundant parts one pale band under the rest (pieces broken by a
    // NaN): a part that retraces covered ground lies on a kept run, which
    // runs inside it.
    let redundant: Vec<(f64, f64)> = deleted
        .iter()
        .flat_map(|d| d.iter().copied().chain([(f64::NAN, f64::NAN)]))
        .collect();
    let mut paths = Vec::new();
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
        references: &[Series {
            label: if redundant.is_empty() {
                ""
            } else {
                "redundant (deleted)"
            },
            points: &redundant,
            color: palette::BAD,
        }],
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
    // The cleaned path a pale band: the plan runs along it.
    WorldFigure {
        title: "Filtered path: the plan (Fig. 8b)",
        regions: &[],
        references: &[Series {
            label: "cleaned path",
            points: &cleaned,
            color: palette::MUTED,
        }],
        walls,
        paths: &[Series {
            label: "plan (spikes filtered)",
            points: &filtered,
            color: palette::GOOD,
        }],
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use twindrive_mission::goals::Waypoint;

    /// The paper's robot in random rooms, three to five waypoints at
    /// random at least 0.8 m apart (some with a heading) and a random area
    /// to sweep, planned and driven on the twin: the path figure passes the
    /// plot's check (its legend over nothing, every entry seen), and in its
    /// PNG each waypoint is a disc of the waypoints' colour where the
    /// figure puts the waypoint, each heading an arrow of that colour along
    /// it, and the area's edge is drawn.
    #[test]
    fn the_rehearsal_figure_draws_each_waypoint_at_its_place_with_its_heading() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5403);
        let base = twindrive_sim::builtin::load("wall_following")
            .unwrap()
            .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let mut drawn = 0;
        while drawn < 2 {
            let (w, h) = (rng.random_range(5.0..8.0), rng.random_range(5.0..8.0));
            let walls = [
                [0.0, 0.0, w, 0.0],
                [w, 0.0, w, h],
                [w, h, 0.0, h],
                [0.0, h, 0.0, 0.0],
            ];
            let mut scenario = base.clone();
            scenario.world = World::from_walls(&walls, &[]);
            scenario.robot.start.x_m = 0.5;
            scenario.robot.start.y_m = 0.5;
            let mut waypoints: Vec<Waypoint> = Vec::new();
            let n = rng.random_range(3..=5);
            while waypoints.len() < n {
                let (x, y) = (
                    rng.random_range(0.5..w - 0.5),
                    rng.random_range(0.5..h - 0.5),
                );
                if waypoints
                    .iter()
                    .chain([&Waypoint {
                        x_m: 0.5,
                        y_m: 0.5,
                        heading_rad: None,
                        dwell_s: 0.0,
                        speed_m_s: None,
                    }])
                    .all(|q| (x - q.x_m).hypot(y - q.y_m) > 0.8)
                {
                    waypoints.push(Waypoint {
                        x_m: x,
                        y_m: y,
                        heading_rad: rng.random_bool(0.6).then(|| rng.random_range(-3.1..3.1)),
                        dwell_s: 0.0,
                        speed_m_s: None,
                    });
                }
            }
            let (ax, ay) = (
                rng.random_range(0.5..w - 1.5),
                rng.random_range(0.5..h - 1.5),
            );
            let goals = Goals::parse(&format!(
                "speed_m_s = 0.3\n[[areas]]\npolygon = {:?}\n",
                [
                    [ax, ay],
                    [ax + 1.0, ay],
                    [ax + 1.0, ay + 0.8],
                    [ax, ay + 0.8]
                ]
            ))
            .unwrap();
            let goals = Goals { waypoints, ..goals };
            let Ok(planned) = crate::rehearse::plan_route(&scenario, &goals, &[]) else {
                continue; // Refusals are the route's tests.
            };
            let log = crate::rehearse::drive_route(scenario.clone(), &planned).unwrap();
            let out = dir.path().join(format!("case{drawn}"));
            std::fs::create_dir_all(&out).unwrap();
            let places = with_rehearsal_path_figure(
                &log,
                &scenario.world,
                &planned.route,
                &goals,
                |figure| {
                    assert_eq!(figure.misleading().unwrap(), vec![]);
                    figure.write(&out.join("path"))?;
                    goals
                        .waypoints
                        .iter()
                        .map(|w| Ok(figure.pixel_of((w.x_m, w.y_m))?))
                        .collect::<anyhow::Result<Vec<_>>>()
                },
            )
            .unwrap();
            let png = image::open(out.join("path.png")).unwrap().to_rgb8();
            let is = |c: twindrive_plot::RGBColor, x: f64, y: f64| {
                png.get_pixel(x.round() as u32, y.round() as u32).0 == [c.0, c.1, c.2]
            };
            for (k, (wp, &(cx, cy))) in goals.waypoints.iter().zip(&places).enumerate() {
                let (cx, cy) = (f64::from(cx), f64::from(cy));
                let rim = (0..16)
                    .filter(|&i| {
                        let a = f64::from(i) * std::f64::consts::TAU / 16.0;
                        is(WAYPOINT_COLOR, cx + 7.0 * a.cos(), cy - 7.0 * a.sin())
                    })
                    .count();
                assert!(
                    rim >= 15,
                    "waypoint {}: rim {rim}/16 at ({cx}, {cy})",
                    k + 1
                );
                if let Some(h) = wp.heading_rad {
                    assert!(
                        (13..=30).all(|d| {
                            let d = f64::from(d);
                            is(WAYPOINT_COLOR, cx + d * h.cos(), cy - d * h.sin())
                        }),
                        "waypoint {}: no arrow along {h}",
                        k + 1
                    );
                }
            }
            let edge = png
                .pixels()
                .filter(|p| p.0 == [AREA_COLOR.0, AREA_COLOR.1, AREA_COLOR.2])
                .count();
            assert!(edge > 200, "the area's edge: {edge} pixel(s)");
            drawn += 1;
        }
    }
}
