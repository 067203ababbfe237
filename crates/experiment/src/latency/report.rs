//! What the grid found: the mean of each cell, `results.md` (completion
//! time and contacts pivoted by latency, then every cell), `results.csv`
//! and the figures.

use std::path::Path;

use twindrive_plot::{Series, Strip, StripRow, TimeFigure, WorldFigure, palette};
use twindrive_workflow::figures::walls;

use super::model::{Method, Settings};
use super::runner::RunRow;
use crate::rehearsal::Rehearsal;

/// The mean of the rows of one method in one cell.
#[derive(Debug, Clone)]
pub struct Cell {
    pub method: Method,
    pub latency_s: f64,
    pub loss: f64,
    pub runs: usize,
    pub completed: usize,
    /// Mean over completed runs.
    pub completion_s: Option<f64>,
    pub collisions: f64,
    /// Mean over completed runs.
    pub collisions_completed: Option<f64>,
    pub bumps: f64,
    pub contact_s: f64,
    pub coverage_percent: f64,
    pub path_error_mean_m: f64,
    pub bytes_up: f64,
    pub bytes_down: f64,
    pub handbacks: f64,
}

pub fn cells(rows: &[RunRow], settings: &Settings) -> Vec<Cell> {
    let mut out = Vec::new();
    for &latency_s in &settings.latencies_s {
        for &loss in &settings.losses {
            for method in settings.methods() {
                let these: Vec<&RunRow> = rows
                    .iter()
                    .filter(|r| {
                        r.method == method.name() && r.latency_s == latency_s && r.loss == loss
                    })
                    .collect();
                let n = these.len().max(1) as f64;
                let mean = |f: &dyn Fn(&RunRow) -> f64| these.iter().map(|r| f(r)).sum::<f64>() / n;
                let done: Vec<f64> = these.iter().filter_map(|r| r.completion_s).collect();
                let done_collisions: Vec<f64> = these
                    .iter()
                    .filter(|r| r.completion_s.is_some())
                    .map(|r| f64::from(r.collisions))
                    .collect();
                out.push(Cell {
                    method,
                    latency_s,
                    loss,
                    runs: these.len(),
                    completed: done.len(),
                    completion_s: (!done.is_empty())
                        .then(|| done.iter().sum::<f64>() / done.len() as f64),
                    collisions: mean(&|r| f64::from(r.collisions)),
                    collisions_completed: (!done_collisions.is_empty()).then(|| {
                        done_collisions.iter().sum::<f64>() / done_collisions.len() as f64
                    }),
                    bumps: mean(&|r| f64::from(r.bumps)),
                    contact_s: mean(&|r| r.contact_s),
                    coverage_percent: mean(&|r| r.coverage_percent),
                    path_error_mean_m: mean(&|r| r.path_error_mean_m),
                    bytes_up: mean(&|r| r.bytes_up as f64),
                    bytes_down: mean(&|r| r.bytes_down as f64),
                    handbacks: mean(&|r| r.handbacks as f64),
                });
            }
        }
    }
    out
}

fn pct(loss: f64) -> String {
    format!(
        "{} %",
        ryu::Buffer::new()
            .format(loss * 100.0)
            .trim_end_matches(".0")
    )
}

fn secs(latency: f64) -> String {
    ryu::Buffer::new()
        .format(latency)
        .trim_end_matches(".0")
        .to_string()
}

/// One table of methods (columns) against latency (rows) at one loss.
fn pivot(
    md: &mut String,
    title: &str,
    cells: &[Cell],
    settings: &Settings,
    loss: f64,
    entry: impl Fn(&Cell) -> String,
) {
    let methods = settings.methods();
    md.push_str(&format!("\n{title}\n\n| one-way latency (s) |"));
    for m in &methods {
        md.push_str(&format!(" {} |", m.name()));
    }
    md.push_str("\n|---:|");
    md.push_str(&"---:|".repeat(methods.len()));
    md.push('\n');
    for &lat in &settings.latencies_s {
        md.push_str(&format!("| {} |", secs(lat)));
        for m in &methods {
            let c = cells
                .iter()
                .find(|c| c.method == *m && c.latency_s == lat && c.loss == loss)
                .expect("every cell");
            md.push_str(&format!(" {} |", entry(c)));
        }
        md.push('\n');
    }
}

/// The tables of `results.md`: completion time and contacts pivoted by
/// latency, then every cell.
pub fn markdown(cells: &[Cell], settings: &Settings, intro: &str) -> String {
    let mut md = String::new();
    md.push_str(intro);
    for &loss in &settings.losses {
        pivot(
            &mut md,
            &format!(
                "**Completion time (s), loss {}** (mean over completed runs; `—`: none completed; completed/runs in brackets where not all)",
                pct(loss)
            ),
            cells,
            settings,
            loss,
            |c| {
                let t = c.completion_s.map_or("—".into(), |t| format!("{t:.0}"));
                if c.completed < c.runs {
                    format!("{t} ({}/{})", c.completed, c.runs)
                } else {
                    t
                }
            },
        );
        pivot(
            &mut md,
            &format!("**Collisions / bumps per run, loss {}**", pct(loss)),
            cells,
            settings,
            loss,
            |c| format!("{:.1} / {:.1}", c.collisions, c.bumps),
        );
    }
    md.push_str("\n**Every cell** (means over seeds)\n\n| method | latency (s) | loss | completed | completion (s) | collisions | bumps | in contact (s) | route covered | path error (m) | kB up | kB down | hand-backs |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for c in cells {
        md.push_str(&format!(
            "| {} | {} | {} | {}/{} | {} | {:.1} | {:.1} | {:.1} | {:.1} % | {:.3} | {:.1} | {:.1} | {:.1} |\n",
            c.method.name(),
            secs(c.latency_s),
            pct(c.loss),
            c.completed,
            c.runs,
            c.completion_s.map_or("—".into(), |t| format!("{t:.1}")),
            c.collisions,
            c.bumps,
            c.contact_s,
            c.coverage_percent,
            c.path_error_mean_m,
            c.bytes_up / 1e3,
            c.bytes_down / 1e3,
            c.handbacks,
        ));
    }
    md
}

/// `results.csv`, one row per run.
pub fn csv(rows: &[RunRow]) -> String {
    let mut s = String::from(
        "method,latency_s,loss,seed,completed,completion_s,collisions,bumps,contact_s,coverage_percent,path_error_mean_m,path_error_max_m,bytes_up,bytes_down,handbacks,uploads\n",
    );
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{:.2},{:.2},{:.4},{:.4},{},{},{},{}\n",
            r.method,
            r.latency_s,
            r.loss,
            r.seed,
            r.completed,
            r.completion_s.map_or(String::new(), |t| format!("{t:.3}")),
            r.collisions,
            r.bumps,
            r.contact_s,
            r.coverage_percent,
            r.path_error_mean_m,
            r.path_error_max_m,
            r.bytes_up,
            r.bytes_down,
            r.handbacks,
            r.uploads
        ));
    }
    s
}

/// Completion time and collisions against latency, one line per method,
/// one panel per loss, both over the runs that completed. A method's cells
/// where no run completed are marked in a row of their own in a strip above
/// the axis, named "not completed" and without numbers (never drawn as if
/// they completed: the contacts of a run cut short are not comparable, they
/// are in `results.md`); lines that coincide are told apart by the plot.
pub fn figures(cells: &[Cell], settings: &Settings, dir: &Path) -> anyhow::Result<()> {
    let methods = settings.methods();
    for (base, title, y_label, value) in [
        (
            "completion_time",
            "mission completion time",
            "completion time (s)",
            (&|c: &Cell| c.completion_s) as &dyn Fn(&Cell) -> Option<f64>,
        ),
        (
            "collisions",
            "contacts per completed run",
            "collisions per completed run",
            &|c: &Cell| c.collisions_completed,
        ),
    ] {
        let titles: Vec<String> = settings
            .losses
            .iter()
            .map(|l| format!("{title}, loss {}", pct(*l)))
            .collect();
        let of = |m: Method, loss: f64| {
            cells
                .iter()
                .filter(move |c| c.method == m && c.loss == loss)
        };
        let lines: Vec<Vec<Vec<(f64, f64)>>> = settings
            .losses
            .iter()
            .map(|&loss| {
                methods
                    .iter()
                    .map(|m| {
                        of(*m, loss)
                            .filter_map(|c| value(c).map(|v| (c.latency_s, v)))
                            .collect()
                    })
                    .collect()
            })
            .collect();
        // Not completed: method k's row in a strip above the axis, which
        // has no numbers, so the marks cannot be read as values.
        let missing: Vec<Vec<Vec<f64>>> = settings
            .losses
            .iter()
            .map(|&loss| {
                methods
                    .iter()
                    .map(|m| {
                        of(*m, loss)
                            .filter(|c| value(c).is_none())
                            .map(|c| c.latency_s)
                            .collect()
                    })
                    .collect()
            })
            .collect();
        let missing_labels: Vec<String> = methods
            .iter()
            .map(|m| format!("{}: not completed (strip above the axis)", m.name()))
            .collect();
        let series: Vec<Vec<Series>> = lines
            .iter()
            .map(|per_method| {
                per_method
                    .iter()
                    .zip(&methods)
                    .map(|(points, m)| Series {
                        label: m.name(),
                        points,
                        color: m.color(),
                    })
                    .collect()
            })
            .collect();
        let rows: Vec<Vec<StripRow>> = missing
            .iter()
            .map(|per_method| {
                per_method
                    .iter()
                    .zip(&methods)
                    .zip(&missing_labels)
                    .map(|((xs, m), label)| StripRow {
                        label,
                        xs,
                        color: m.color(),
                    })
                    .collect()
            })
            .collect();
        let panels: Vec<TimeFigure> = series
            .iter()
            .zip(&rows)
            .zip(&titles)
            .map(|((s, rows), t)| TimeFigure {
                title: t,
                x_label: "one-way latency (s)",
                y_label,
                series: s,
                markers: &[],
                bands: &[],
                strip: Some(Strip {
                    name: "not completed",
                    rows,
                }),
            })
            .collect();
        twindrive_plot::Panels { panels: &panels }.write(&dir.join(base))?;
    }
    Ok(())
}

/// The true paths of every method in one cell (seed 0), over the route.
pub fn paths_figure(
    rows: &[RunRow],
    m: &Rehearsal,
    settings: &Settings,
    latency_s: f64,
    loss: f64,
    base: &Path,
) -> anyhow::Result<()> {
    let route: Vec<(f64, f64)> = m.plan.samples.iter().map(|s| (s.x_m, s.y_m)).collect();
    let mut series = Vec::new();
    for method in settings.methods() {
        if let Some(r) = rows.iter().find(|r| {
            r.method == method.name() && r.latency_s == latency_s && r.loss == loss && r.seed == 0
        }) {
            series.push(Series {
                label: method.name(),
                points: &r.path,
                color: method.color(),
            });
        }
    }
    let title = format!(
        "true paths at {} s one way, loss {} (seed 0)",
        secs(latency_s),
        pct(loss)
    );
    // The route a pale band under the paths: the decoupled run follows it
    // closely and would hide a line.
    WorldFigure {
        title: &title,
        regions: &[],
        references: &[Series {
            label: "intended route (the rehearsal's plan)",
            points: &route,
            color: palette::TRUTH,
        }],
        walls: &walls(&m.site.world),
        paths: &series,
        markers: &[],
        outlines: &[],
    }
    .write(base)?;
    Ok(())
}

/// What the experiment did, for the top of `results.md`.
pub fn intro(m: &Rehearsal, s: &Settings) -> String {
    let t = &m.twin.robot.true_params;
    let r = &m.site.robot.true_params;
    format!(
        "Mission: `{}` rehearsed on the twin, plan of {:.1} s. Site: true wheel diameters {:.4} / {:.4} m and \
         wheelbase {:.4} m (the twin's: {:.4} / {:.4} / {:.4}). Link both ways: the one-way latency, 2 % of it \
         as jitter, the loss, {:.0} kbit/s. Direct operation runs the twin's controller at the master at 50 Hz \
         ((b): wheels zeroed after {} s without a command; (c): moves of {} s); a run is complete when the \
         robot has passed within {} m of {:.0} % of the route, plus one latency for the operator to see it. \
         Decoupled: signed upload, autonomous execution, hand-back and continuation; complete when the master \
         learns the last plan finished. {} seed(s) per cell; runs cut at {:.0} s.\n",
        m.twin.name,
        m.plan.duration_s(),
        r.left_diameter_m,
        r.right_diameter_m,
        r.wheelbase_m,
        t.left_diameter_m,
        t.right_diameter_m,
        t.wheelbase_m,
        s.bandwidth_bit_s / 1e3,
        s.watchdog_timeout_s,
        s.move_s,
        s.coverage_radius_m,
        s.complete_at * 100.0,
        s.seeds,
        s.max_duration_s,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cell(method: Method, latency_s: f64, completion_s: Option<f64>) -> Cell {
        Cell {
            method,
            latency_s,
            loss: 0.1,
            runs: 1,
            completed: usize::from(completion_s.is_some()),
            completion_s,
            // Slower runs bump more: the lines differ where the times do.
            collisions: completion_s.map_or(3.0, |t| (t / 20.0).round()),
            collisions_completed: completion_s.map(|t| (t / 20.0).round()),
            bumps: 0.0,
            contact_s: 0.0,
            coverage_percent: 90.0,
            path_error_mean_m: 0.0,
            bytes_up: 0.0,
            bytes_down: 0.0,
            handbacks: 0.0,
        }
    }

    #[test]
    fn figures_mark_runs_that_did_not_complete_and_coinciding_lines() {
        let settings = Settings::demo();
        let [hold, watchdog, move_wait, decoupled] = settings.methods();
        let mut cells = Vec::new();
        for (lat, direct, mw, dec) in [
            (0.0, Some(57.0), 77.0, 79.0),
            (0.5, None, 170.0, 80.0),
            (2.0, None, 504.0, 84.0),
        ] {
            cells.push(cell(hold, lat, direct));
            cells.push(cell(watchdog, lat, direct));
            cells.push(cell(move_wait, lat, Some(mw)));
            cells.push(cell(decoupled, lat, Some(dec)));
        }
        let dir = tempfile::tempdir().unwrap();
        figures(&cells, &settings, dir.path()).unwrap();
        let svg = std::fs::read_to_string(dir.path().join("completion_time.svg")).unwrap();
        for text in [
            "direct (a) hold-last: not completed (strip above the axis)",
            "direct (b) watchdog: not completed (strip above the axis)",
            "direct (b) watchdog (dashed: same points as direct (a) hold-last)",
        ] {
            assert!(svg.contains(text), "no `{text}` in the figure");
        }
        assert!(!svg.contains("move-and-wait: not completed"));
        // The strip is named, and no number on the time axis reaches above
        // the slowest completion (the marks are not times).
        let texts: Vec<&str> = svg.lines().map(str::trim).collect();
        assert!(texts.contains(&"not completed"), "{svg}");
        let ticks: Vec<f64> = texts.iter().filter_map(|t| t.parse().ok()).collect();
        assert!(ticks.iter().any(|&v| v >= 400.0), "{ticks:?}");
        assert!(ticks.iter().all(|&v| v <= 504.0 * 1.05), "{ticks:?}");
        assert!(dir.path().join("completion_time.png").is_file());
        assert!(dir.path().join("collisions.png").is_file());
        // Contacts are drawn for the runs that completed; the others are in
        // the strip, not on the lines.
        let svg = std::fs::read_to_string(dir.path().join("collisions.svg")).unwrap();
        for text in [
            "contacts per completed run",
            "direct (a) hold-last: not completed (strip above the axis)",
            "direct (b) watchdog: not completed (strip above the axis)",
        ] {
            assert!(svg.contains(text), "no `{text}` in the figure");
        }
    }
}
