//! Figures as SVG and PNG from plain data: a top-down world view with paths
//! and markers, and time-series plots. Text is rendered with an embedded
//! DejaVu Sans, so PNGs need no system fonts.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;

pub use plotters::style::RGBColor;

/// Colours used across the project's figures.
pub mod palette {
    use plotters::style::RGBColor;
    pub const WALL: RGBColor = RGBColor(40, 40, 40);
    pub const TRUTH: RGBColor = RGBColor(31, 119, 180);
    pub const ALT: RGBColor = RGBColor(255, 127, 14);
    pub const GOOD: RGBColor = RGBColor(44, 160, 44);
    pub const BAD: RGBColor = RGBColor(214, 39, 40);
    pub const MUTED: RGBColor = RGBColor(127, 127, 127);
    pub const PURPLE: RGBColor = RGBColor(148, 103, 189);
}

/// A figure could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("{}: {message}", path.display())]
    Draw { path: PathBuf, message: String },
    #[error("{what}: {message}")]
    Data { what: String, message: String },
}

/// A line through points.
#[derive(Debug, Clone, Copy)]
pub struct Series<'a> {
    pub label: &'a str,
    pub points: &'a [(f64, f64)],
    pub color: RGBColor,
}

/// Isolated points drawn as filled circles.
#[derive(Debug, Clone, Copy)]
pub struct Markers<'a> {
    pub label: &'a str,
    pub points: &'a [(f64, f64)],
    pub color: RGBColor,
}

/// A shaded band between two curves sampled at the same x values (for
/// example an estimate ± 3σ).
#[derive(Debug, Clone, Copy)]
pub struct Band<'a> {
    pub label: &'a str,
    pub lower: &'a [(f64, f64)],
    pub upper: &'a [(f64, f64)],
    pub color: RGBColor,
}

/// A top-down view of walls, paths and markers, axes equal.
#[derive(Debug, Clone, Copy)]
pub struct WorldFigure<'a> {
    pub title: &'a str,
    pub walls: &'a [[(f64, f64); 2]],
    pub paths: &'a [Series<'a>],
    pub markers: &'a [Markers<'a>],
}

/// Lines over a shared x axis.
#[derive(Debug, Clone, Copy)]
pub struct TimeFigure<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub series: &'a [Series<'a>],
    pub markers: &'a [Markers<'a>],
    pub bands: &'a [Band<'a>],
}

fn register_fonts() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // The bytes are a valid font shipped by the dejavu crate.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
        let _ = plotters::style::register_font("sans-serif", FontStyle::Bold, dejavu::sans::bold());
    });
}

fn draw_err(path: &Path, e: impl std::fmt::Display) -> PlotError {
    PlotError::Draw {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// Writes `<base>.svg` and `<base>.png`; returns both paths.
fn write_both(
    base: &Path,
    size: (u32, u32),
    draw_svg: impl Fn(DrawingArea<SVGBackend, Shift>) -> Result<(), String>,
    draw_png: impl Fn(DrawingArea<BitMapBackend, Shift>) -> Result<(), String>,
) -> Result<Vec<PathBuf>, PlotError> {
    register_fonts();
    let svg = base.with_extension("svg");
    let png = base.with_extension("png");
    {
        let root = SVGBackend::new(&svg, size).into_drawing_area();
        draw_svg(root).map_err(|e| draw_err(&svg, e))?;
    }
    {
        let root = BitMapBackend::new(&png, size).into_drawing_area();
        draw_png(root).map_err(|e| draw_err(&png, e))?;
    }
    Ok(vec![svg, png])
}

fn bounds<'a>(points: impl Iterator<Item = &'a (f64, f64)>) -> Option<((f64, f64), (f64, f64))> {
    let mut b: Option<((f64, f64), (f64, f64))> = None;
    for &(x, y) in points {
        if !(x.is_finite() && y.is_finite()) {
            continue;
        }
        b = Some(match b {
            None => ((x, x), (y, y)),
            Some(((x0, x1), (y0, y1))) => ((x0.min(x), x1.max(x)), (y0.min(y), y1.max(y))),
        });
    }
    b
}

/// Drops points closer than `min_step` to the last kept one (dense paths
/// render badly); always keeps the last point.
pub fn decimate(points: &[(f64, f64)], min_step: f64) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::new();
    for &p in points {
        if out
            .last()
            .is_none_or(|q| (p.0 - q.0).hypot(p.1 - q.1) >= min_step)
        {
            out.push(p);
        }
    }
    if let Some(&last) = points.last()
        && out.last() != Some(&last)
    {
        out.push(last);
    }
    out
}

impl WorldFigure<'_> {
    /// Writes `<base>.svg` and `<base>.png`. Paths are thinned to about four
    /// pixels between points.
    pub fn write(&self, base: &Path) -> Result<Vec<PathBuf>, PlotError> {
        let all = self
            .walls
            .iter()
            .flat_map(|w| w.iter())
            .chain(self.paths.iter().flat_map(|s| s.points.iter()))
            .chain(self.markers.iter().flat_map(|m| m.points.iter()));
        let ((x0, x1), (y0, y1)) = bounds(all).ok_or_else(|| PlotError::Data {
            what: self.title.into(),
            message: "nothing to draw".into(),
        })?;
        let pad = 0.04 * (x1 - x0).max(y1 - y0).max(1e-3);
        let (x0, x1, y0, y1) = (x0 - pad, x1 + pad, y0 - pad, y1 + pad);
        // Equal axes: size the plot area in proportion to the world.
        let width = 1000u32;
        let plot_w = 900.0;
        let plot_h = (plot_w * (y1 - y0) / (x1 - x0)).clamp(200.0, 1400.0);
        let size = (width, plot_h as u32 + 130);
        let step = (x1 - x0).max(y1 - y0) / 250.0;
        let thinned: Vec<Vec<(f64, f64)>> = self
            .paths
            .iter()
            .map(|s| decimate(s.points, step))
            .collect();
        let paths: Vec<Series> = self
            .paths
            .iter()
            .zip(&thinned)
            .map(|(s, pts)| Series { points: pts, ..*s })
            .collect();
        let spec = ChartSpec {
            title: self.title,
            x_label: "x [m]",
            y_label: "y [m]",
            range: (x0, x1, y0, y1),
            walls: self.walls,
            series: &paths,
            markers: self.markers,
            bands: &[],
            marker_radius: 5,
        };
        write_both(
            base,
            size,
            |r| draw_chart(&r, &spec),
            |r| draw_chart(&r, &spec),
        )
    }
}

/// Time figures side by side in one file, each with its own axes (the
/// same quantity under two conditions, say).
#[derive(Debug, Clone, Copy)]
pub struct Panels<'a> {
    pub panels: &'a [TimeFigure<'a>],
}

impl Panels<'_> {
    /// Writes `<base>.svg` and `<base>.png`.
    pub fn write(&self, base: &Path) -> Result<Vec<PathBuf>, PlotError> {
        let specs = self
            .panels
            .iter()
            .map(TimeFigure::spec)
            .collect::<Result<Vec<_>, _>>()?;
        let n = specs.len().max(1) as u32;
        write_both(
            base,
            (700 * n, 450),
            |r| draw_panels(r, &specs),
            |r| draw_panels(r, &specs),
        )
    }
}

fn draw_panels<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    specs: &[ChartSpec],
) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    for (area, spec) in root.split_evenly((1, specs.len().max(1))).iter().zip(specs) {
        draw_chart(area, spec)?;
    }
    Ok(())
}

impl<'a> TimeFigure<'a> {
    fn spec(&self) -> Result<ChartSpec<'a>, PlotError> {
        let all = self
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .chain(self.markers.iter().flat_map(|m| m.points.iter()))
            .chain(
                self.bands
                    .iter()
                    .flat_map(|b| b.lower.iter().chain(b.upper.iter())),
            );
        let ((x0, x1), (y0, y1)) = bounds(all).ok_or_else(|| PlotError::Data {
            what: self.title.into(),
            message: "nothing to draw".into(),
        })?;
        let ypad = 0.05 * (y1 - y0).max(1e-6);
        Ok(ChartSpec {
            title: self.title,
            x_label: self.x_label,
            y_label: self.y_label,
            range: (x0, x1.max(x0 + 1e-9), y0 - ypad, y1 + ypad),
            walls: &[],
            series: self.series,
            markers: self.markers,
            bands: self.bands,
            marker_radius: 3,
        })
    }
}

impl TimeFigure<'_> {
    /// Writes `<base>.svg` and `<base>.png`.
    pub fn write(&self, base: &Path) -> Result<Vec<PathBuf>, PlotError> {
        let spec = self.spec()?;
        write_both(
            base,
            (1100, 450),
            |r| draw_chart(&r, &spec),
            |r| draw_chart(&r, &spec),
        )
    }
}

/// What one chart shows; both figure kinds draw through [`draw_chart`].
struct ChartSpec<'a> {
    title: &'a str,
    x_label: &'a str,
    y_label: &'a str,
    range: (f64, f64, f64, f64),
    walls: &'a [[(f64, f64); 2]],
    series: &'a [Series<'a>],
    markers: &'a [Markers<'a>],
    bands: &'a [Band<'a>],
    marker_radius: i32,
}

fn draw_chart<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    spec: &ChartSpec,
) -> Result<(), String> {
    let (x0, x1, y0, y1) = spec.range;
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let mut chart = ChartBuilder::on(root)
        .caption(spec.title, ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc(spec.x_label)
        .y_desc(spec.y_label)
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(|e| e.to_string())?;
    chart
        .draw_series(
            spec.walls
                .iter()
                .map(|w| PathElement::new(vec![w[0], w[1]], palette::WALL.stroke_width(3))),
        )
        .map_err(|e| e.to_string())?;
    for b in spec.bands {
        let color = b.color;
        let outline: Vec<(f64, f64)> = b
            .upper
            .iter()
            .chain(b.lower.iter().rev())
            .copied()
            .collect();
        chart
            .draw_series(std::iter::once(Polygon::new(
                outline,
                color.mix(0.25).filled(),
            )))
            .map_err(|e| e.to_string())?
            .label(b.label)
            .legend(move |(x, y)| {
                Rectangle::new([(x, y - 5), (x + 20, y + 5)], color.mix(0.25).filled())
            });
    }
    // Width 1: plotters' bitmap backend leaves gaps in thicker polylines.
    // A series with an empty label draws without a legend entry (several
    // pieces of one thing).
    for s in spec.series {
        let color = s.color;
        let drawn = chart
            .draw_series(LineSeries::new(
                s.points.iter().copied(),
                color.stroke_width(1),
            ))
            .map_err(|e| e.to_string())?;
        if !s.label.is_empty() {
            drawn.label(s.label).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        }
    }
    let radius = spec.marker_radius;
    for m in spec.markers {
        let color = m.color;
        chart
            .draw_series(
                m.points
                    .iter()
                    .map(|&p| Circle::new(p, radius, color.filled())),
            )
            .map_err(|e| e.to_string())?
            .label(m.label)
            .legend(move |(x, y)| Circle::new((x + 10, y), radius, color.filled()));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_real_svg_and_png() {
        let dir = tempfile::tempdir().unwrap();
        let path: Vec<(f64, f64)> = (0..100)
            .map(|i| (i as f64 * 0.05, (i as f64 * 0.1).sin()))
            .collect();
        let walls = [[(0.0, -1.5), (5.0, -1.5)], [(0.0, 1.5), (5.0, 1.5)]];
        let files = WorldFigure {
            title: "test world",
            walls: &walls,
            paths: &[Series {
                label: "path",
                points: &path,
                color: palette::TRUTH,
            }],
            markers: &[Markers {
                label: "bump",
                points: &[(2.0, 0.5)],
                color: palette::BAD,
            }],
        }
        .write(&dir.path().join("world"))
        .unwrap();
        let svg = std::fs::read_to_string(&files[0]).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("test world") && svg.contains("<polyline"));
        let png = image::open(&files[1]).unwrap();
        assert!(png.width() == 1000 && png.height() > 200);
        // Something other than white was drawn.
        assert!(png.to_rgb8().pixels().any(|p| p.0 != [255, 255, 255]));

        let files = TimeFigure {
            title: "series",
            x_label: "t [s]",
            y_label: "v",
            series: &[Series {
                label: "sin",
                points: &path,
                color: palette::ALT,
            }],
            markers: &[],
            bands: &[Band {
                label: "band",
                lower: &path,
                upper: &path,
                color: palette::TRUTH,
            }],
        }
        .write(&dir.path().join("series"))
        .unwrap();
        assert!(files.iter().all(|f| f.metadata().unwrap().len() > 1000));
    }

    #[test]
    fn empty_data_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let err = TimeFigure {
            title: "empty",
            x_label: "",
            y_label: "",
            series: &[],
            markers: &[],
            bands: &[],
        }
        .write(&dir.path().join("e"))
        .unwrap_err();
        assert!(err.to_string().contains("nothing to draw"));
    }
}
