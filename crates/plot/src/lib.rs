//! Figures as SVG and PNG from plain data: a top-down world view with paths,
//! markers and outlines, time-series plots, and lanes of spans and events
//! over time. Text is rendered with an embedded DejaVu Sans, so PNGs need no
//! system fonts.
//!
//! Time plots look after their reader: the y range ignores a few outliers
//! (see [`robust_range`]) and says so, a series that would hide exactly
//! under another is drawn dashed with marked points and says so, a series
//! of one point is drawn as a point, and x values without a y go in a named
//! strip above the axis. World figures draw reference paths as pale bands
//! under the paths measured against them. For either kind, `misleading`
//! rasterises each layer as the PNG draws it and names every legend entry
//! with nothing drawn or hidden under what is drawn after it.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::coord::ranged1d::{SegmentValue, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, Pos, VPos};

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
    pub const BROWN: RGBColor = RGBColor(140, 86, 75);
    pub const PINK: RGBColor = RGBColor(227, 119, 194);
    pub const OLIVE: RGBColor = RGBColor(188, 189, 34);
    pub const CYAN: RGBColor = RGBColor(23, 190, 207);

    /// Colours for a run of like things (continuations, say) that are
    /// none of TRUTH, ALT and BAD; the `k`-th, cycling.
    pub fn cycle(k: usize) -> RGBColor {
        const CYCLE: [RGBColor; 6] = [PURPLE, BROWN, PINK, OLIVE, CYAN, GOOD];
        CYCLE[k % CYCLE.len()]
    }
}

/// A figure could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("{}: {message}", path.display())]
    Draw { path: PathBuf, message: String },
    #[error("{what}: {message}")]
    Data { what: String, message: String },
    #[error("{what} would mislead: {}", found.iter().map(ToString::to_string).collect::<Vec<_>>().join("; "))]
    Misleading {
        what: String,
        found: Vec<Misleading>,
    },
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

/// A closed outline (a box, say), drawn above everything else as a thick
/// dashed line with its own legend entry, so nothing hides it.
#[derive(Debug, Clone, Copy)]
pub struct Outline<'a> {
    pub label: &'a str,
    /// The corners in order; the last joins the first.
    pub corners: &'a [(f64, f64)],
    pub color: RGBColor,
}

/// A closed area (a block, say) drawn shaded with a solid edge under the
/// paths, with its own legend entry.
#[derive(Debug, Clone, Copy)]
pub struct Region<'a> {
    pub label: &'a str,
    /// The corners in order; the last joins the first.
    pub corners: &'a [(f64, f64)],
    pub color: RGBColor,
}

/// A top-down view of walls, regions, paths, markers and outlines, axes
/// equal. `references` are the paths the others are measured against (a
/// plan, the true path): they are drawn as wide pale bands under the
/// `paths`, so a path that follows one closely runs inside it and cannot
/// hide it.
#[derive(Debug, Clone, Copy)]
pub struct WorldFigure<'a> {
    pub title: &'a str,
    pub walls: &'a [[(f64, f64); 2]],
    pub regions: &'a [Region<'a>],
    pub paths: &'a [Series<'a>],
    pub references: &'a [Series<'a>],
    pub markers: &'a [Markers<'a>],
    pub outlines: &'a [Outline<'a>],
}

/// Lines over a shared x axis. The y range is [`robust_range`] of
/// everything drawn: points beyond it are drawn as triangles at the axis'
/// edge, and the legend says how many and how far they went. A series
/// whose points are another's, or among another's, is drawn dashed with
/// marked points, and the legend says whose. x values that have no y (runs
/// that did not complete, say) go in a [`Strip`] above the axis.
#[derive(Debug, Clone, Copy)]
pub struct TimeFigure<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub series: &'a [Series<'a>],
    pub markers: &'a [Markers<'a>],
    pub bands: &'a [Band<'a>],
    pub strip: Option<Strip<'a>>,
}

/// x values with no y value, one row of marks each, in a shaded strip
/// above the y axis' numbers, named where the numbers would be: outside the
/// axis, so they cannot be read as values.
#[derive(Debug, Clone, Copy)]
pub struct Strip<'a> {
    /// Stands in for the y value ("not completed").
    pub name: &'a str,
    pub rows: &'a [StripRow<'a>],
}

/// One row of a [`Strip`].
#[derive(Debug, Clone, Copy)]
pub struct StripRow<'a> {
    pub label: &'a str,
    pub xs: &'a [f64],
    pub color: RGBColor,
}

/// One named row of a [`LaneFigure`]: spans (from, to) drawn as bars and
/// instants drawn as ticks across the row.
#[derive(Debug, Clone, Copy)]
pub struct Lane<'a> {
    pub name: &'a str,
    pub spans: &'a [(f64, f64)],
    pub events: &'a [f64],
    pub color: RGBColor,
}

/// Named rows over a shared x axis (a timeline): the rows are categories,
/// labelled with their names, top to bottom in order.
#[derive(Debug, Clone, Copy)]
pub struct LaneFigure<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub lanes: &'a [Lane<'a>],
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

/// Time plots keep at most this many points per series.
pub const MAX_POINTS: usize = 4000;

/// The step that thins a series of `len` points to at most [`MAX_POINTS`].
pub fn stride(len: usize) -> usize {
    len.div_ceil(MAX_POINTS).max(1)
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

/// An axis range for values of which a few may be wild (one control spike
/// among thousands of wheel speeds), and what it leaves out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobustRange {
    pub lo: f64,
    pub hi: f64,
    /// How many values lie below `lo` and above `hi`.
    pub below: usize,
    pub above: usize,
    /// The values' own extremes.
    pub min: f64,
    pub max: f64,
}

impl RobustRange {
    /// Whether some values lie outside the range.
    pub fn clips(&self) -> bool {
        self.below + self.above > 0
    }
}

/// The bulk of the values: from this fraction to one minus it.
const BULK_TAIL: f64 = 0.01;
/// The bulk is padded by this fraction of its span each side.
const BULK_PAD: f64 = 0.25;
/// Outliers flatten a plot when they need more than this many times the
/// padded bulk's span; below it the range is the values' own.
const FLATTEN: f64 = 3.0;

/// The range of the finite `values`: their own [min, max], unless a few
/// outliers (beyond the 1st..99th percentile) would squeeze the rest into
/// less than a third of it. Then it is the 1st..99th percentile padded by a
/// quarter of its span each side, and `below`/`above` count what it leaves
/// out. `None` when no value is finite.
pub fn robust_range(values: &[f64]) -> Option<RobustRange> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let (min, max) = (v[0], v[n - 1]);
    let own = RobustRange {
        lo: min,
        hi: max,
        below: 0,
        above: 0,
        min,
        max,
    };
    let k = (n as f64 * BULK_TAIL).floor() as usize;
    let (q0, q1) = (v[k], v[n - 1 - k]);
    let body = q1 - q0;
    // A constant bulk has no scale to judge outliers by.
    if body <= 0.0 || max - min <= FLATTEN * (1.0 + 2.0 * BULK_PAD) * body {
        return Some(own);
    }
    let lo = (q0 - BULK_PAD * body).max(min);
    let hi = (q1 + BULK_PAD * body).min(max);
    Some(RobustRange {
        lo,
        hi,
        below: v.iter().take_while(|&&x| x < lo).count(),
        above: v.iter().rev().take_while(|&&x| x > hi).count(),
        min,
        max,
    })
}

/// The parts of a polyline within `lo <= y <= hi`, cut where it crosses
/// the bounds; non-finite points break it.
fn clip_y(points: &[(f64, f64)], lo: f64, hi: f64) -> Vec<Vec<(f64, f64)>> {
    let inside = |p: (f64, f64)| p.0.is_finite() && p.1 >= lo && p.1 <= hi;
    let mut pieces: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut piece: Vec<(f64, f64)> = Vec::new();
    let push = |piece: &mut Vec<(f64, f64)>, p: (f64, f64)| {
        if piece.last() != Some(&p) {
            piece.push(p);
        }
    };
    for (k, &p) in points.iter().enumerate() {
        let prev = k.checked_sub(1).map(|j| points[j]);
        match prev {
            Some(q) if q.0.is_finite() && q.1.is_finite() && p.0.is_finite() && p.1.is_finite() => {
                // The part of q -> p within the bounds, as t in [0, 1].
                let at = |y: f64| (y - q.1) / (p.1 - q.1);
                let (t0, t1) = if p.1 == q.1 {
                    if inside(p) { (0.0, 1.0) } else { (1.0, 0.0) }
                } else {
                    let (a, b) = (at(lo), at(hi));
                    (a.min(b).max(0.0), a.max(b).min(1.0))
                };
                if t0 > t1 {
                    continue;
                }
                let lerp = |t: f64| (q.0 + t * (p.0 - q.0), q.1 + t * (p.1 - q.1));
                if t0 > 0.0 && !piece.is_empty() {
                    pieces.push(std::mem::take(&mut piece));
                }
                push(&mut piece, lerp(t0));
                push(&mut piece, if t1 >= 1.0 { p } else { lerp(t1) });
                if t1 < 1.0 {
                    pieces.push(std::mem::take(&mut piece));
                }
            }
            _ => {
                if !piece.is_empty() {
                    pieces.push(std::mem::take(&mut piece));
                }
                if inside(p) && p.1.is_finite() {
                    piece.push(p);
                }
            }
        }
    }
    if !piece.is_empty() {
        pieces.push(piece);
    }
    pieces
}

/// How series `b` relates to series `a` drawn before it.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Overlap {
    /// The same points.
    Same,
    /// Every point of one is a point of the other.
    Within,
}

/// Whether two series would hide one another (exactly, not by chance
/// crossings): the same points, or every point of one among the other's.
fn overlap(a: &[(f64, f64)], b: &[(f64, f64)], tol: f64) -> Option<Overlap> {
    let close =
        |p: &(f64, f64), q: &(f64, f64)| (p.0 - q.0).abs() <= tol && (p.1 - q.1).abs() <= tol;
    if a.is_empty() || b.is_empty() {
        return None;
    }
    if a.len() == b.len() && a.iter().zip(b).all(|(p, q)| close(p, q)) {
        return Some(Overlap::Same);
    }
    // Pairwise search only for short series (points of an experiment).
    if a.len().saturating_mul(b.len()) > 1_000_000 {
        return None;
    }
    let among =
        |x: &[(f64, f64)], y: &[(f64, f64)]| x.iter().all(|p| y.iter().any(|q| close(p, q)));
    (among(a, b) || among(b, a)).then_some(Overlap::Within)
}

/// A reference path in a world figure: a band this wide and this opaque
/// under the paths, so a path along it runs visibly inside it.
const REFERENCE_PX: u32 = 7;
/// How much wider each reference is than the one drawn after it.
const REFERENCE_STEP_PX: u32 = 6;
const REFERENCE_ALPHA: f64 = 0.35;

/// Shapes of marked points.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Shape {
    Circle,
    Triangle,
    Square,
    Cross,
}

/// A line as drawn: its pieces within the range and how it looks.
struct Line {
    label: String,
    color: RGBColor,
    pieces: Vec<Vec<(f64, f64)>>,
    dashed: bool,
    /// A pale band this many pixels wide (a reference path, drawn under
    /// the others); 0 for a line.
    band_px: u32,
    vertices: Option<Shape>,
}

/// Points as drawn.
struct Dots {
    label: String,
    color: RGBColor,
    points: Vec<(f64, f64)>,
}

/// A band or a region as drawn.
struct Shade {
    label: String,
    color: RGBColor,
    outline: Vec<(f64, f64)>,
    /// A solid edge (a region) or none (a band).
    edge: bool,
}

/// A strip as drawn: it starts at `from_y` and runs to the top of the axes.
struct StripSpec {
    name: String,
    from_y: f64,
}

/// Points beyond the y range, drawn as triangles at its edge.
struct Beyond {
    label: String,
    up: Vec<((f64, f64), RGBColor)>,
    down: Vec<((f64, f64), RGBColor)>,
}

/// A number with about four significant digits.
fn short(v: f64) -> String {
    let digits = if v == 0.0 {
        0
    } else {
        (3 - v.abs().log10().floor() as i32).clamp(0, 6) as usize
    };
    format!("{v:.digits$}")
}

impl<'a> WorldFigure<'a> {
    /// What is drawn and the figure's size in pixels. Paths are thinned to
    /// about four pixels between points.
    fn spec(&self) -> Result<(ChartSpec<'a>, (u32, u32)), PlotError> {
        let all = self
            .walls
            .iter()
            .flat_map(|w| w.iter())
            .chain(self.regions.iter().flat_map(|r| r.corners.iter()))
            .chain(
                self.paths
                    .iter()
                    .chain(self.references)
                    .flat_map(|s| s.points.iter()),
            )
            .chain(self.markers.iter().flat_map(|m| m.points.iter()))
            .chain(self.outlines.iter().flat_map(|o| o.corners.iter()));
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
        let line = |s: &Series, band_px: u32| Line {
            label: s.label.to_string(),
            color: s.color,
            pieces: vec![decimate(s.points, step)],
            dashed: false,
            band_px,
            vertices: (s.points.len() == 1).then_some(Shape::Circle),
        };
        // Each reference narrower than the one before: one that follows
        // another (a continuation along the plan) runs inside it.
        let n = self.references.len() as u32;
        let lines = (0..n)
            .zip(self.references)
            .map(|(k, s)| line(s, REFERENCE_PX + REFERENCE_STEP_PX * (n - 1 - k)))
            .chain(self.paths.iter().map(|s| line(s, 0)))
            .collect();
        let shades = self
            .regions
            .iter()
            .map(|r| Shade {
                label: r.label.to_string(),
                color: r.color,
                outline: r.corners.to_vec(),
                edge: true,
            })
            .collect();
        let spec = ChartSpec {
            title: self.title,
            x_label: "x [m]",
            y_label: "y [m]",
            range: (x0, x1, y0, y1),
            walls: self.walls,
            lines,
            dots: self.markers.iter().map(Dots::from).collect(),
            shades,
            outlines: self.outlines,
            beyond: None,
            strip: None,
            marker_radius: 5,
        };
        Ok((spec, size))
    }

    /// Writes `<base>.svg` and `<base>.png`.
    pub fn write(&self, base: &Path) -> Result<Vec<PathBuf>, PlotError> {
        let (spec, size) = self.spec()?;
        write_both(
            base,
            size,
            |r| draw_chart(&r, &spec),
            |r| draw_chart(&r, &spec),
        )
    }

    /// Every legend entry that shows nothing or hides under what is drawn
    /// after it (see [`Misleading`]), as the PNG would draw them.
    pub fn misleading(&self) -> Result<Vec<Misleading>, PlotError> {
        let (spec, size) = self.spec()?;
        misleading(&spec, size).map_err(|message| PlotError::Data {
            what: self.title.into(),
            message,
        })
    }

    /// [`WorldFigure::write`], refused with [`PlotError::Misleading`] when
    /// [`WorldFigure::misleading`] finds anything.
    pub fn write_checked(&self, base: &Path) -> Result<Vec<PathBuf>, PlotError> {
        let found = self.misleading()?;
        if !found.is_empty() {
            return Err(PlotError::Misleading {
                what: self.title.into(),
                found,
            });
        }
        self.write(base)
    }
}

impl From<&Markers<'_>> for Dots {
    fn from(m: &Markers) -> Self {
        Dots {
            label: m.label.to_string(),
            color: m.color,
            points: m.points.to_vec(),
        }
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
        let all = || {
            self.series
                .iter()
                .flat_map(|s| s.points.iter())
                .chain(self.markers.iter().flat_map(|m| m.points.iter()))
                .chain(
                    self.bands
                        .iter()
                        .flat_map(|b| b.lower.iter().chain(b.upper.iter())),
                )
        };
        let nothing = || PlotError::Data {
            what: self.title.into(),
            message: "nothing to draw".into(),
        };
        let ((x0, x1), (y0, y1)) = bounds(all()).ok_or_else(nothing)?;
        // The strip's marks widen the x range, never the y range.
        let strip_xs = self
            .strip
            .iter()
            .flat_map(|s| s.rows.iter())
            .flat_map(|r| r.xs.iter().copied())
            .filter(|x| x.is_finite());
        let (x0, x1) = strip_xs.fold((x0, x1), |(a, b), x| (a.min(x), b.max(x)));
        let ys: Vec<f64> = all().filter(|p| p.0.is_finite()).map(|p| p.1).collect();
        let r = robust_range(&ys).ok_or_else(nothing)?;
        let (lo, hi) = (r.lo, r.hi);
        let tol = 1e-9 * ((x1 - x0) + (y1 - y0)).max(1e-12);

        let mut beyond = Beyond {
            label: String::new(),
            up: Vec::new(),
            down: Vec::new(),
        };
        let mut off_axis = |points: &[(f64, f64)], color: RGBColor| {
            for &(x, y) in points.iter().filter(|p| p.0.is_finite()) {
                if y > hi {
                    beyond.up.push(((x, hi), color));
                } else if y < lo {
                    beyond.down.push(((x, lo), color));
                }
            }
        };
        let mut lines: Vec<Line> = Vec::new();
        let mut rank = 0;
        for (j, s) in self.series.iter().enumerate() {
            off_axis(s.points, s.color);
            let hidden = self.series[..j]
                .iter()
                .find_map(|a| overlap(a.points, s.points, tol).map(|o| (a.label, o)));
            let (label, dashed, vertices) = match hidden {
                Some((under, o)) => {
                    let shape = [Shape::Triangle, Shape::Square, Shape::Cross][rank % 3];
                    rank += 1;
                    let how = match o {
                        Overlap::Same => "same points as",
                        Overlap::Within => "shares its points with",
                    };
                    let label = if s.label.is_empty() {
                        String::new()
                    } else {
                        format!("{} (dashed: {how} {under})", s.label)
                    };
                    (label, true, Some(shape))
                }
                None => (
                    s.label.to_string(),
                    false,
                    (s.points.len() == 1).then_some(Shape::Circle),
                ),
            };
            lines.push(Line {
                label,
                color: s.color,
                pieces: clip_y(s.points, lo, hi),
                dashed,
                band_px: 0,
                vertices,
            });
        }
        let mut dots = Vec::new();
        for m in self.markers {
            off_axis(m.points, m.color);
            dots.push(Dots {
                points: m
                    .points
                    .iter()
                    .copied()
                    .filter(|p| p.1 >= lo && p.1 <= hi)
                    .collect(),
                ..Dots::from(m)
            });
        }
        let shades = self
            .bands
            .iter()
            .map(|b| Shade {
                label: b.label.to_string(),
                color: b.color,
                outline: b
                    .upper
                    .iter()
                    .chain(b.lower.iter().rev())
                    .map(|&(x, y)| (x, y.clamp(lo, hi)))
                    .collect(),
                edge: false,
            })
            .collect();
        let beyond = r.clips().then(|| {
            let mut parts = Vec::new();
            if r.above > 0 {
                parts.push(format!("up to {}", short(r.max)));
            }
            if r.below > 0 {
                parts.push(format!("down to {}", short(r.min)));
            }
            beyond.label = format!(
                "{} point(s) off the axis, at its edge ({})",
                r.above + r.below,
                parts.join(", ")
            );
            beyond
        });
        let ypad = 0.05 * (hi - lo).max(1e-6);
        // Markers at the x extremes would be cut in half by the frame.
        let xpad = if self.markers.is_empty() && self.strip.is_none() {
            0.0
        } else {
            0.02 * (x1 - x0)
        };
        // The strip: a row per entry above the axis' top, and a margin.
        let mut top = hi + ypad;
        let mut strip = None;
        if let Some(s) = self
            .strip
            .filter(|s| s.rows.iter().any(|r| !r.xs.is_empty()))
        {
            let row_h = 0.08 * (hi - lo).max(1e-6);
            let from_y = top;
            for (k, r) in s.rows.iter().enumerate() {
                dots.push(Dots {
                    label: r.label.to_string(),
                    color: r.color,
                    points: r
                        .xs
                        .iter()
                        .map(|&x| (x, from_y + row_h * (k as f64 + 0.75)))
                        .collect(),
                });
            }
            top = from_y + row_h * (s.rows.len() as f64 + 0.5);
            strip = Some(StripSpec {
                name: s.name.to_string(),
                from_y,
            });
        }
        Ok(ChartSpec {
            title: self.title,
            x_label: self.x_label,
            y_label: self.y_label,
            range: (x0 - xpad, (x1 + xpad).max(x0 + 1e-9), lo - ypad, top),
            walls: &[],
            lines,
            dots,
            shades,
            outlines: &[],
            beyond,
            strip,
            marker_radius: 3,
        })
    }
}

/// The size of a time figure in pixels.
const TIME_FIGURE_PX: (u32, u32) = (1100, 450);

impl TimeFigure<'_> {
    /// Writes `<base>.svg` and `<base>.png`.
    pub fn write(&self, base: &Path) -> Result<Vec<PathBuf>, PlotError> {
        let spec = self.spec()?;
        write_both(
            base,
            TIME_FIGURE_PX,
            |r| draw_chart(&r, &spec),
            |r| draw_chart(&r, &spec),
        )
    }

    /// Every legend entry that shows nothing or hides under what is drawn
    /// after it (see [`Misleading`]), as [`TimeFigure::write`] draws them.
    pub fn misleading(&self) -> Result<Vec<Misleading>, PlotError> {
        let spec = self.spec()?;
        misleading(&spec, TIME_FIGURE_PX).map_err(|message| PlotError::Data {
            what: self.title.into(),
            message,
        })
    }
}

/// What one chart shows; world and time figures draw through [`draw_chart`].
struct ChartSpec<'a> {
    title: &'a str,
    x_label: &'a str,
    y_label: &'a str,
    range: (f64, f64, f64, f64),
    walls: &'a [[(f64, f64); 2]],
    lines: Vec<Line>,
    dots: Vec<Dots>,
    shades: Vec<Shade>,
    outlines: &'a [Outline<'a>],
    beyond: Option<Beyond>,
    strip: Option<StripSpec>,
    marker_radius: i32,
}

type Chart<'c, DB> = ChartContext<'c, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Draws `shape` at each point; returns nothing to label.
fn draw_shapes<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    points: &[(f64, f64)],
    shape: Shape,
    color: RGBColor,
    size: i32,
) -> Result<(), String> {
    let style = color.stroke_width(2);
    let p = points.iter().copied();
    match shape {
        Shape::Circle => chart
            .draw_series(p.map(|c| Circle::new(c, size, color.filled())))
            .map(|_| ()),
        Shape::Triangle => chart
            .draw_series(p.map(|c| TriangleMarker::new(c, size + 2, style)))
            .map(|_| ()),
        Shape::Square => chart
            .draw_series(p.map(|c| {
                EmptyElement::at(c)
                    + Rectangle::new([(-size - 1, -size - 1), (size + 1, size + 1)], style)
            }))
            .map(|_| ()),
        Shape::Cross => chart
            .draw_series(p.map(|c| Cross::new(c, size + 1, style)))
            .map(|_| ()),
    }
    .map_err(|e| e.to_string())
}

/// One thing drawn on a chart, in the order drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Layer {
    Walls,
    Strip,
    Shade(usize),
    Line(usize),
    Dots(usize),
    Beyond,
    Outline(usize),
}

/// Everything a chart draws, bottom to top.
fn layers(spec: &ChartSpec) -> Vec<Layer> {
    let mut all = vec![Layer::Walls];
    all.extend(spec.strip.as_ref().map(|_| Layer::Strip));
    all.extend((0..spec.shades.len()).map(Layer::Shade));
    all.extend((0..spec.lines.len()).map(Layer::Line));
    all.extend((0..spec.dots.len()).map(Layer::Dots));
    all.push(Layer::Beyond);
    all.extend((0..spec.outlines.len()).map(Layer::Outline));
    all
}

/// The legend entry of a layer: `None` when it has none (nothing drawn,
/// or no label).
fn legend_label<'s>(spec: &'s ChartSpec, layer: Layer) -> Option<&'s str> {
    let label = match layer {
        Layer::Walls | Layer::Strip => None,
        Layer::Shade(i) => Some(spec.shades[i].label.as_str()),
        Layer::Line(i) => {
            let s = &spec.lines[i];
            s.pieces
                .iter()
                .any(|p| !p.is_empty())
                .then_some(s.label.as_str())
        }
        Layer::Dots(i) => {
            let m = &spec.dots[i];
            (!m.points.is_empty()).then_some(m.label.as_str())
        }
        Layer::Beyond => spec
            .beyond
            .as_ref()
            .filter(|b| !b.up.is_empty() || !b.down.is_empty())
            .map(|b| b.label.as_str()),
        Layer::Outline(i) => Some(spec.outlines[i].label),
    };
    label.filter(|l| !l.is_empty())
}

/// The frame of a chart: caption, axes and their labels (a strip's rows
/// get no numbers but the strip's name).
fn frame<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    spec: &ChartSpec,
) -> Result<Chart<'a, DB>, String> {
    let (x0, x1, y0, y1) = spec.range;
    let y_area = if spec.strip.is_some() { 90 } else { 60 };
    let mut chart = ChartBuilder::on(root)
        .caption(spec.title, ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(y_area)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| e.to_string())?;
    let data_top = spec.strip.as_ref().map_or(f64::INFINITY, |s| s.from_y);
    let ticks = |v: &f64| {
        if *v > data_top {
            String::new()
        } else {
            RangedCoordf64::format(v)
        }
    };
    chart
        .configure_mesh()
        .x_desc(spec.x_label)
        .y_desc(spec.y_label)
        .y_label_formatter(&ticks)
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(|e| e.to_string())?;
    Ok(chart)
}

/// Draws one layer, with its legend entry when `legend`.
fn draw_layer<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    spec: &ChartSpec,
    layer: Layer,
    legend: bool,
) -> Result<(), String> {
    let label = legend_label(spec, layer).filter(|_| legend);
    let radius = spec.marker_radius;
    match layer {
        Layer::Walls => {
            chart
                .draw_series(
                    spec.walls
                        .iter()
                        .map(|w| PathElement::new(vec![w[0], w[1]], palette::WALL.stroke_width(3))),
                )
                .map_err(|e| e.to_string())?;
        }
        Layer::Strip => {
            let Some(strip) = &spec.strip else {
                return Ok(());
            };
            let (x0, x1, _, y1) = spec.range;
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(x0, strip.from_y), (x1, y1)],
                    RGBColor(225, 225, 225).mix(0.6).filled(),
                )))
                .map_err(|e| e.to_string())?;
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(x0, strip.from_y), (x1, strip.from_y)],
                    BLACK.stroke_width(1),
                )))
                .map_err(|e| e.to_string())?;
            // The strip's name where its numbers would be (in pixels from
            // the plotting area's corner).
            let (left, mid) = chart.backend_coord(&(x0, 0.5 * (strip.from_y + y1)));
            let (xs, ys) = chart.plotting_area().get_pixel_range();
            let (left, mid) = (left - xs.start, mid - ys.start);
            let font = ("sans-serif", 13)
                .into_font()
                .color(&BLACK)
                .pos(Pos::new(HPos::Right, VPos::Center));
            chart
                .plotting_area()
                .strip_coord_spec()
                .draw(&Text::new(strip.name.clone(), (left - 6, mid), font))
                .map_err(|e| e.to_string())?;
        }
        Layer::Shade(i) => {
            let b = &spec.shades[i];
            let color = b.color;
            let fill = Polygon::new(b.outline.clone(), color.mix(0.25).filled());
            let drawn = if b.edge {
                chart
                    .draw_series(std::iter::once(fill))
                    .map_err(|e| e.to_string())?;
                let mut ring = b.outline.clone();
                ring.extend(b.outline.first().copied());
                chart.draw_series(std::iter::once(PathElement::new(
                    ring,
                    color.stroke_width(2),
                )))
            } else {
                chart.draw_series(std::iter::once(fill))
            }
            .map_err(|e| e.to_string())?;
            if let Some(label) = label {
                let edge: ShapeStyle = if b.edge {
                    color.stroke_width(2)
                } else {
                    color.mix(0.25).stroke_width(2)
                };
                drawn.label(label).legend(move |(x, y)| {
                    EmptyElement::at((x, y))
                        + Rectangle::new([(0, -5), (20, 5)], color.mix(0.25).filled())
                        + Rectangle::new([(0, -5), (20, 5)], edge)
                });
            }
        }
        Layer::Line(i) => {
            // Width 1: plotters' bitmap backend leaves gaps in thicker
            // polylines. A series with an empty label draws without a
            // legend entry (several pieces of one thing).
            let s = &spec.lines[i];
            let color = s.color;
            let band_px = s.band_px;
            let drawn = if band_px > 0 {
                let style = color.mix(REFERENCE_ALPHA).stroke_width(band_px);
                chart.draw_series(
                    s.pieces
                        .iter()
                        .map(move |piece| PathElement::new(piece.clone(), style)),
                )
            } else if s.dashed {
                chart.draw_series(s.pieces.iter().map(|piece| {
                    DashedPathElement::new(piece.iter().copied(), 8, 5, color.stroke_width(2))
                }))
            } else {
                chart.draw_series(
                    s.pieces
                        .iter()
                        .map(|piece| PathElement::new(piece.clone(), color.stroke_width(1))),
                )
            }
            .map_err(|e| e.to_string())?;
            if let (Some(label), true) = (label, band_px > 0) {
                drawn.label(label).legend(move |(x, y)| {
                    PathElement::new(
                        vec![(x, y), (x + 20, y)],
                        color.mix(REFERENCE_ALPHA).stroke_width(band_px.min(10)),
                    )
                });
            } else if let Some(label) = label {
                let dash = if s.dashed { 5 } else { 100 };
                let mark: Vec<(i32, i32)> = match s.vertices {
                    None => vec![],
                    Some(Shape::Circle) => vec![(8, -2), (12, -2), (12, 2), (8, 2), (8, -2)],
                    Some(Shape::Triangle) => vec![(10, -5), (14, 3), (6, 3), (10, -5)],
                    Some(Shape::Square) => vec![(6, -4), (14, -4), (14, 4), (6, 4), (6, -4)],
                    Some(Shape::Cross) => vec![(6, -4), (14, 4), (10, 0), (14, -4), (6, 4)],
                };
                drawn.label(label).legend(move |(x, y)| {
                    EmptyElement::at((x, y))
                        + DashedPathElement::new(
                            vec![(0, 0), (20, 0)],
                            dash,
                            3,
                            color.stroke_width(2),
                        )
                        + PathElement::new(mark.clone(), color.stroke_width(2))
                });
            }
            if let Some(shape) = s.vertices {
                let points: Vec<(f64, f64)> = s.pieces.concat();
                draw_shapes(chart, &points, shape, color, radius)?;
            }
        }
        Layer::Dots(i) => {
            let m = &spec.dots[i];
            let color = m.color;
            let drawn = chart
                .draw_series(
                    m.points
                        .iter()
                        .map(|&p| Circle::new(p, radius, color.filled())),
                )
                .map_err(|e| e.to_string())?;
            if let Some(label) = label {
                drawn
                    .label(label)
                    .legend(move |(x, y)| Circle::new((x + 10, y), radius, color.filled()));
            }
        }
        Layer::Beyond => {
            let Some(b) = &spec.beyond else {
                return Ok(());
            };
            let size = radius + 3;
            let up = move |c: (f64, f64), color: RGBColor| {
                EmptyElement::at(c)
                    + Polygon::new(vec![(-size, 0), (size, 0), (0, -2 * size)], color.filled())
            };
            let down = move |c: (f64, f64), color: RGBColor| {
                EmptyElement::at(c)
                    + Polygon::new(vec![(-size, 0), (size, 0), (0, 2 * size)], color.filled())
            };
            chart
                .draw_series(b.down.iter().map(|&(c, color)| down(c, color)))
                .map_err(|e| e.to_string())?;
            let drawn = chart
                .draw_series(b.up.iter().map(|&(c, color)| up(c, color)))
                .map_err(|e| e.to_string())?;
            if let Some(label) = label {
                drawn.label(label).legend(move |(x, y)| {
                    EmptyElement::at((x + 10, y))
                        + Polygon::new(vec![(-5, 4), (5, 4), (0, -6)], BLACK.filled())
                });
            }
        }
        Layer::Outline(i) => {
            let o = &spec.outlines[i];
            let color = o.color;
            let mut ring = o.corners.to_vec();
            ring.extend(o.corners.first().copied());
            let drawn = chart
                .draw_series(
                    ring.windows(2)
                        .map(|w| DashedPathElement::new(w.to_vec(), 6, 4, color.stroke_width(3))),
                )
                .map_err(|e| e.to_string())?;
            if let Some(label) = label {
                drawn.label(label).legend(move |(x, y)| {
                    Rectangle::new([(x + 2, y - 5), (x + 18, y + 5)], color.stroke_width(2))
                });
            }
        }
    }
    Ok(())
}

fn draw_chart<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    spec: &ChartSpec,
) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let mut chart = frame(root, spec)?;
    // Outlines last: nothing may hide them.
    for layer in layers(spec) {
        draw_layer(&mut chart, spec, layer, true)?;
    }
    let position = legend_position(&chart, spec)?;
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(position)
        .draw()
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())
}

/// What makes a figure mislead its reader.
#[derive(Debug, Clone, PartialEq)]
pub enum Misleading {
    /// The legend names it, but nothing of it (fewer than [`MIN_PIXELS`])
    /// shows inside the axes.
    NothingDrawn { label: String },
    /// Almost all of it lies under what is drawn after it.
    Hidden {
        label: String,
        /// The fraction of its pixels still seen.
        visible_fraction: f64,
    },
}

impl std::fmt::Display for Misleading {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Misleading::NothingDrawn { label } => {
                write!(f, "\"{label}\" is in the legend but nothing of it is drawn")
            }
            Misleading::Hidden {
                label,
                visible_fraction,
            } => write!(
                f,
                "\"{label}\" is hidden under what is drawn after it ({:.0} % of it shows)",
                100.0 * visible_fraction
            ),
        }
    }
}

/// A legend entry is hidden when less than this fraction of its pixels
/// shows; a pixel next to one drawn later counts as covered (a line a pixel
/// beside another merges with it).
pub const MIN_VISIBLE_FRACTION: f64 = 0.15;

/// A legend entry with fewer pixels than this inside the axes shows
/// nothing a reader can find.
pub const MIN_PIXELS: usize = 9;

/// The pixels of the plot area that `layer` covers, drawn alone at `size`.
fn layer_mask(spec: &ChartSpec, size: (u32, u32), layer: Layer) -> Result<Vec<bool>, String> {
    let (w, h) = size;
    let mut buf = vec![255u8; (w * h * 3) as usize];
    let (xs, ys) = {
        let root = BitMapBackend::with_buffer(&mut buf, size).into_drawing_area();
        let mut chart = frame(&root, spec)?;
        // The frame drawn, then wiped: only the layer's own pixels count.
        let range = chart.plotting_area().get_pixel_range();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        draw_layer(&mut chart, spec, layer, false)?;
        root.present().map_err(|e| e.to_string())?;
        range
    };
    let mut mask = vec![false; (w * h) as usize];
    for y in ys.start.max(0)..ys.end.min(h as i32) {
        for x in xs.start.max(0)..xs.end.min(w as i32) {
            let i = (y as u32 * w + x as u32) as usize;
            mask[i] = buf[3 * i..3 * i + 3] != [255, 255, 255];
        }
    }
    Ok(mask)
}

/// Every legend entry of `spec`, drawn at `size`, that shows nothing in the
/// axes or lies almost wholly under what is drawn after it; found on the
/// rasterised layers, so widths, dashes and markers count as drawn.
fn misleading(spec: &ChartSpec, size: (u32, u32)) -> Result<Vec<Misleading>, String> {
    register_fonts();
    let all = layers(spec);
    let masks = all
        .iter()
        .map(|&l| layer_mask(spec, size, l))
        .collect::<Result<Vec<_>, _>>()?;
    let (w, h) = (size.0 as usize, size.1 as usize);
    // What is drawn above the current layer, grown by a pixel each way.
    let mut above = vec![false; w * h];
    let mut found = Vec::new();
    for (layer, mask) in all.iter().zip(&masks).rev() {
        if let Some(label) = legend_label(spec, *layer) {
            let drawn = mask.iter().filter(|&&m| m).count();
            let seen = mask.iter().zip(&above).filter(|&(&m, &a)| m && !a).count();
            if drawn < MIN_PIXELS {
                found.push(Misleading::NothingDrawn {
                    label: label.to_string(),
                });
            } else if (seen as f64) < MIN_VISIBLE_FRACTION * drawn as f64 {
                found.push(Misleading::Hidden {
                    label: label.to_string(),
                    visible_fraction: seen as f64 / drawn as f64,
                });
            }
        }
        for (i, _) in mask.iter().enumerate().filter(|&(_, &m)| m) {
            let (x, y) = (i % w, i / w);
            for yy in y.saturating_sub(1)..(y + 2).min(h) {
                for xx in x.saturating_sub(1)..(x + 2).min(w) {
                    above[yy * w + xx] = true;
                }
            }
        }
    }
    found.reverse();
    Ok(found)
}

/// Where the legend goes: the emptiest corner of the values' area, which
/// ends below a strip (a legend at the top would cover the strip's marks).
fn legend_position<DB: DrawingBackend>(
    chart: &Chart<'_, DB>,
    spec: &ChartSpec,
) -> Result<SeriesLabelPosition, String> {
    let corner = emptiest_corner(spec);
    let Some(strip) = &spec.strip else {
        return Ok(corner);
    };
    let area = chart.plotting_area();
    let (xs, ys) = area.get_pixel_range();
    let top = chart.backend_coord(&(spec.range.0, strip.from_y)).1 - ys.start + 8;
    // plotters' legend: a 30 pixel symbol, 10 pixel margins, 12 pixel text.
    let font: TextStyle = ("sans-serif", 12).into_font().into();
    let mut text_w = 0;
    for layer in layers(spec) {
        if let Some(label) = legend_label(spec, layer) {
            let (w, _) = area
                .estimate_text_size(label, &font)
                .map_err(|e| e.to_string())?;
            text_w = text_w.max(w as i32);
        }
    }
    let legend_w = text_w + 30 + 2 * 10;
    Ok(match corner {
        SeriesLabelPosition::UpperLeft => SeriesLabelPosition::Coordinate(8, top),
        SeriesLabelPosition::UpperRight => {
            SeriesLabelPosition::Coordinate(xs.end - xs.start - legend_w - 8, top)
        }
        lower => lower,
    })
}

/// The corner of the chart with the least drawn in it, for the legend
/// (segments sampled along their length); with a strip, of the values'
/// area below it.
fn emptiest_corner(spec: &ChartSpec) -> SeriesLabelPosition {
    let (x0, x1, y0, y1) = spec.range;
    let y1 = spec.strip.as_ref().map_or(y1, |s| s.from_y);
    let mut drawn: Vec<(f64, f64)> = Vec::new();
    let mut path = |points: &[(f64, f64)]| {
        for w in points.windows(2) {
            drawn.extend((0..8).map(|i| {
                let t = i as f64 / 8.0;
                (
                    w[0].0 + t * (w[1].0 - w[0].0),
                    w[0].1 + t * (w[1].1 - w[0].1),
                )
            }));
        }
        drawn.extend(points.last().copied());
    };
    for w in spec.walls {
        path(w);
    }
    for l in &spec.lines {
        l.pieces.iter().for_each(|p| path(p));
    }
    for b in &spec.shades {
        path(&b.outline);
    }
    for m in &spec.dots {
        m.points.iter().for_each(|&p| path(&[p]));
    }
    if let Some(b) = &spec.beyond {
        b.up.iter().chain(&b.down).for_each(|(c, _)| path(&[*c]));
    }
    let (wx, wy) = (0.45 * (x1 - x0), 0.4 * (y1 - y0));
    // Upper right, upper left, lower right, lower left.
    let mut count = [0usize; 4];
    for (x, y) in drawn {
        let (right, left) = (x >= x1 - wx, x <= x0 + wx);
        let (up, low) = (y >= y1 - wy && y <= y1, y <= y0 + wy);
        for (k, inside) in [up && right, up && left, low && right, low && left]
            .into_iter()
            .enumerate()
        {
            count[k] += usize::from(inside);
        }
    }
    match (0..4).min_by_key(|&k| count[k]) {
        Some(1) => SeriesLabelPosition::UpperLeft,
        Some(2) => SeriesLabelPosition::LowerRight,
        Some(3) => SeriesLabelPosition::LowerLeft,
        _ => SeriesLabelPosition::UpperRight,
    }
}

/// Height of one lane in pixels.
const LANE_PX: u32 = 60;

impl LaneFigure<'_> {
    /// Writes `<base>.svg` and `<base>.png`.
    pub fn write(&self, base: &Path) -> Result<Vec<PathBuf>, PlotError> {
        let xs = self.lanes.iter().flat_map(|l| {
            l.spans
                .iter()
                .flat_map(|&(a, b)| [a, b])
                .chain(l.events.iter().copied())
        });
        let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
        for x in xs.filter(|x| x.is_finite()) {
            x0 = x0.min(x);
            x1 = x1.max(x);
        }
        if x0 > x1 {
            return Err(PlotError::Data {
                what: self.title.into(),
                message: "nothing to draw".into(),
            });
        }
        let pad = 0.02 * (x1 - x0).max(1e-6);
        let range = (x0 - pad, x1 + pad);
        let height = LANE_PX * self.lanes.len() as u32 + 140;
        write_both(
            base,
            (1100, height),
            |r| draw_lanes(&r, self, range),
            |r| draw_lanes(&r, self, range),
        )
    }
}

fn draw_lanes<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    fig: &LaneFigure,
    (x0, x1): (f64, f64),
) -> Result<(), String> {
    let n = fig.lanes.len();
    // Lane k (from the top) is centred on y = n - 1 - k.
    let lane_y = |k: usize| (n - 1 - k) as f64;
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let names: Vec<&str> = fig.lanes.iter().map(|l| l.name).collect();
    let label_px = names.iter().map(|s| s.chars().count()).max().unwrap_or(1) as u32 * 8 + 20;
    let mut chart = ChartBuilder::on(root)
        .caption(fig.title, ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(label_px)
        .build_cartesian_2d(x0..x1, (0..n as i32 - 1).into_segmented())
        .map_err(|e| e.to_string())?;
    let label = |v: &SegmentValue<i32>| match v {
        SegmentValue::CenterOf(i) if (*i as usize) < n => names[n - 1 - *i as usize].to_string(),
        _ => String::new(),
    };
    chart
        .configure_mesh()
        .x_desc(fig.x_label)
        .y_labels(n)
        .y_label_formatter(&label)
        .disable_y_mesh()
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(|e| e.to_string())?;
    // Pixels: a bar over the middle 60 % of its row, an instant a tick
    // across the whole row; both at least three pixels wide, so short
    // spans and instants show.
    let px = |x: f64, row: i32| chart.backend_coord(&(x, SegmentValue::Exact(row)));
    for (k, lane) in fig.lanes.iter().enumerate() {
        let row = lane_y(k) as i32;
        // Row k spans Exact(k)..Exact(k + 1); the top row ends at Last.
        let top = if row + 1 == n as i32 {
            chart.backend_coord(&(x0, SegmentValue::Last)).1
        } else {
            px(x0, row + 1).1
        };
        let bottom = px(x0, row).1;
        let inset = (bottom - top) / 5;
        let color = lane.color;
        let bar = |a: f64, b: f64, y0: i32, y1: i32, style: ShapeStyle| {
            let (a, b) = (px(a.min(b), row).0, px(a.max(b), row).0);
            let b = b.max(a + 3);
            Rectangle::new([(a, y0), (b, y1)], style)
        };
        for &(a, b) in lane.spans {
            root.draw(&bar(
                a,
                b,
                top + inset,
                bottom - inset,
                color.mix(0.85).filled(),
            ))
            .map_err(|e| e.to_string())?;
        }
        for &t in lane.events {
            let c = px(t, row).0;
            root.draw(&Rectangle::new(
                [(c - 1, top + 2), (c + 2, bottom - 2)],
                color.filled(),
            ))
            .map_err(|e| e.to_string())?;
            root.draw(&Circle::new((c, (top + bottom) / 2), 6, color.filled()))
                .map_err(|e| e.to_string())?;
        }
    }
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
            regions: &[],
            paths: &[Series {
                label: "path",
                points: &path,
                color: palette::TRUTH,
            }],
            references: &[],
            markers: &[Markers {
                label: "bump",
                points: &[(2.0, 0.5)],
                color: palette::BAD,
            }],
            outlines: &[],
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
            strip: None,
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
            strip: None,
        }
        .write(&dir.path().join("e"))
        .unwrap_err();
        assert!(err.to_string().contains("nothing to draw"));
    }

    /// Wheel speeds of about ±10 rad/s, irregular, with one +140 and one
    /// -139.5 rad/s spike.
    fn speeds_with_spikes() -> Vec<(f64, f64)> {
        let mut v: Vec<(f64, f64)> = (0..3000)
            .map(|i| {
                let t = i as f64 * 0.01;
                (t, 9.0 * (0.7 * t).sin() + 1.5 * (3.1 * t).cos())
            })
            .collect();
        v[1234].1 = 140.0;
        v[2001].1 = -139.5;
        v
    }

    #[test]
    fn robust_range_ignores_a_spike_but_reports_it() {
        let ys: Vec<f64> = speeds_with_spikes().iter().map(|p| p.1).collect();
        let r = robust_range(&ys).unwrap();
        assert!(r.clips());
        assert_eq!((r.above, r.below), (1, 1));
        assert_eq!((r.min, r.max), (-139.5, 140.0));
        // The bulk (±10.5) fills the range, with a margin.
        assert!(r.hi > 10.0 && r.hi < 20.0, "{r:?}");
        assert!(r.lo < -10.0 && r.lo > -20.0, "{r:?}");
        // Every value left out is counted.
        let out = ys.iter().filter(|&&y| y < r.lo || y > r.hi).count();
        assert_eq!(out, r.above + r.below);
    }

    #[test]
    fn robust_range_keeps_data_without_outliers() {
        // A steep but regular series (move-and-wait's completion times).
        let ys: Vec<f64> = (0..12).map(|i| 60.0 + 230.0 * i as f64).collect();
        let r = robust_range(&ys).unwrap();
        assert!(!r.clips());
        assert_eq!((r.lo, r.hi), (60.0, 60.0 + 230.0 * 11.0));
        // Outliers that are 5 % of the data are data.
        let ys: Vec<f64> = (0..1000)
            .map(|i| if i % 20 == 0 { 500.0 } else { (i % 7) as f64 })
            .collect();
        assert!(!robust_range(&ys).unwrap().clips());
        // A constant bulk has no scale: keep everything.
        let mut ys = vec![2.0; 500];
        ys[3] = 1e6;
        assert!(!robust_range(&ys).unwrap().clips());
        assert!(robust_range(&[f64::NAN]).is_none());
    }

    #[test]
    fn clipping_cuts_lines_where_they_leave_the_range() {
        let pieces = clip_y(
            &[(0.0, 0.0), (1.0, 10.0), (2.0, 0.0), (3.0, 1.0)],
            -1.0,
            5.0,
        );
        assert_eq!(
            pieces,
            vec![
                vec![(0.0, 0.0), (0.5, 5.0)],
                vec![(1.5, 5.0), (2.0, 0.0), (3.0, 1.0)]
            ]
        );
        // A line passing through the range from below to above.
        let pieces = clip_y(&[(0.0, -10.0), (2.0, 10.0)], -5.0, 5.0);
        assert_eq!(pieces, vec![vec![(0.5, -5.0), (1.5, 5.0)]]);
        assert_eq!(clip_y(&[(0.0, 3.0)], 0.0, 5.0), vec![vec![(0.0, 3.0)]]);
        assert!(clip_y(&[(0.0, 30.0), (1.0, 40.0)], 0.0, 5.0).is_empty());
    }

    #[test]
    fn overlap_finds_series_that_hide_one_another() {
        let a = [(0.0, 57.0), (0.25, 55.0)];
        let b = [(0.0, 57.0), (0.25, 55.0), (0.5, 126.0)];
        assert_eq!(overlap(&a, &a, 1e-9), Some(Overlap::Same));
        assert_eq!(overlap(&a, &b, 1e-9), Some(Overlap::Within));
        assert_eq!(overlap(&b, &a, 1e-9), Some(Overlap::Within));
        assert_eq!(overlap(&a, &[(0.0, 57.0), (0.25, 56.0)], 1e-9), None);
        assert_eq!(overlap(&a, &[], 1e-9), None);
    }

    #[test]
    fn time_figures_say_what_they_clip_and_what_coincides() {
        let dir = tempfile::tempdir().unwrap();
        let speeds = speeds_with_spikes();
        let same = [(0.0, 57.0), (0.5, 126.0)];
        let one = [(2.0, 90.0)];
        TimeFigure {
            title: "spikes",
            x_label: "t",
            y_label: "v",
            series: &[Series {
                label: "left",
                points: &speeds,
                color: palette::TRUTH,
            }],
            markers: &[],
            bands: &[],
            strip: None,
        }
        .write(&dir.path().join("spikes"))
        .unwrap();
        let svg = std::fs::read_to_string(dir.path().join("spikes.svg")).unwrap();
        assert!(
            svg.contains("2 point(s) off the axis, at its edge (up to 140.0, down to -139.5)"),
            "{svg}"
        );
        // The axis is the bulk's: no tick label near the spike (the x axis
        // runs to 30).
        let ticks: Vec<f64> = svg.lines().filter_map(|l| l.trim().parse().ok()).collect();
        assert!(
            ticks.len() > 5 && ticks.iter().all(|v: &f64| v.abs() <= 30.0),
            "{ticks:?}"
        );

        TimeFigure {
            title: "methods",
            x_label: "latency",
            y_label: "s",
            series: &[
                Series {
                    label: "hold-last",
                    points: &same,
                    color: palette::BAD,
                },
                Series {
                    label: "watchdog",
                    points: &same,
                    color: palette::ALT,
                },
                Series {
                    label: "decoupled",
                    points: &one,
                    color: palette::GOOD,
                },
            ],
            markers: &[],
            bands: &[],
            strip: None,
        }
        .write(&dir.path().join("methods"))
        .unwrap();
        let svg = std::fs::read_to_string(dir.path().join("methods.svg")).unwrap();
        assert!(
            svg.contains("watchdog (dashed: same points as hold-last)"),
            "{svg}"
        );
        assert!(!svg.contains("off the axis"));
        // The single point is drawn (a circle in its colour).
        assert!(svg.contains("<circle") && svg.contains("#2CA02C"), "{svg}");

        // A series or a set of markers with nothing in it has no legend
        // entry: a legend names only what is drawn.
        TimeFigure {
            title: "innovations",
            x_label: "t",
            y_label: "m",
            series: &[
                Series {
                    label: "accepted",
                    points: &same,
                    color: palette::GOOD,
                },
                Series {
                    label: "nothing here",
                    points: &[],
                    color: palette::BAD,
                },
            ],
            markers: &[Markers {
                label: "rejected",
                points: &[],
                color: palette::BAD,
            }],
            bands: &[],
            strip: None,
        }
        .write(&dir.path().join("innovations"))
        .unwrap();
        let svg = std::fs::read_to_string(dir.path().join("innovations.svg")).unwrap();
        assert!(svg.contains("accepted"), "{svg}");
        assert!(
            !svg.contains("nothing here") && !svg.contains("rejected"),
            "{svg}"
        );
    }

    type Points = Vec<(f64, f64)>;

    /// An oval loop, and the same loop two millimetres off.
    fn loop_and_follower() -> (Points, Points) {
        let lap: Vec<(f64, f64)> = (0..400)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / 400.0;
                (2.0 + a.cos(), 2.0 + 0.8 * a.sin())
            })
            .collect();
        let follower = lap.iter().map(|&(x, y)| (x + 0.002, y)).collect();
        (lap, follower)
    }

    #[test]
    fn a_world_path_under_another_is_found_and_a_reference_stays_visible() {
        let (lap, follower) = loop_and_follower();
        let plan = Series {
            label: "plan",
            points: &lap,
            color: palette::ALT,
        };
        let robot = Series {
            label: "robot",
            points: &follower,
            color: palette::TRUTH,
        };
        let figure = |paths: &[Series], references: &[Series]| {
            WorldFigure {
                title: "hidden",
                walls: &[],
                regions: &[],
                paths,
                references,
                markers: &[],
                outlines: &[],
            }
            .misleading()
            .unwrap()
        };
        // The plan drawn first, the robot over it: the plan is lost.
        let found = figure(&[plan, robot], &[]);
        assert!(
            matches!(&found[..], [Misleading::Hidden { label, visible_fraction }]
                if label == "plan" && *visible_fraction < 0.1),
            "{found:?}"
        );
        // The plan as a reference, a band under the robot: both show.
        assert_eq!(figure(&[robot], &[plan]), vec![]);
        // Apart, nothing hides.
        let far: Vec<(f64, f64)> = lap.iter().map(|&(x, y)| (x + 3.0, y)).collect();
        let apart = Series {
            points: &far,
            ..robot
        };
        assert_eq!(figure(&[plan, apart], &[]), vec![]);
        // The check refuses to write a figure that hides its plan.
        let dir = tempfile::tempdir().unwrap();
        let err = WorldFigure {
            title: "hidden",
            walls: &[],
            regions: &[],
            paths: &[plan, robot],
            references: &[],
            markers: &[],
            outlines: &[],
        }
        .write_checked(&dir.path().join("hidden"))
        .unwrap_err();
        assert!(err.to_string().contains("\"plan\" is hidden"), "{err}");
        assert!(!dir.path().join("hidden.png").exists());
    }

    #[test]
    fn a_legend_entry_with_nothing_in_the_axes_is_found() {
        let (lap, _) = loop_and_follower();
        // A block of zero size: a speck, not a block.
        let corners = [(2.0, 2.0); 4];
        let found = WorldFigure {
            title: "empty region",
            walls: &[],
            regions: &[Region {
                label: "learnt block",
                corners: &corners,
                color: palette::PURPLE,
            }],
            paths: &[Series {
                label: "robot",
                points: &lap,
                color: palette::TRUTH,
            }],
            references: &[],
            markers: &[],
            outlines: &[],
        }
        .misleading()
        .unwrap();
        assert_eq!(
            found,
            vec![Misleading::NothingDrawn {
                label: "learnt block".into()
            }]
        );
    }

    #[test]
    fn a_strip_holds_what_has_no_value_outside_the_axis_numbers() {
        let dir = tempfile::tempdir().unwrap();
        let times = [(0.0, 57.0), (0.5, 126.0)];
        let figure = TimeFigure {
            title: "completion",
            x_label: "latency",
            y_label: "s",
            series: &[Series {
                label: "hold-last",
                points: &times,
                color: palette::BAD,
            }],
            markers: &[],
            bands: &[],
            strip: Some(Strip {
                name: "not completed",
                rows: &[StripRow {
                    label: "hold-last: not completed",
                    xs: &[2.0],
                    color: palette::BAD,
                }],
            }),
        };
        let spec = figure.spec().unwrap();
        let strip = spec.strip.as_ref().unwrap();
        let (_, x1, _, top) = spec.range;
        // The mark sits above every value, in the strip, inside the frame.
        let mark = spec.dots[0].points[0];
        assert_eq!(mark.0, 2.0);
        assert!(strip.from_y > 126.0 && mark.1 > strip.from_y && mark.1 < top);
        assert!(x1 > 2.0);
        figure.write(&dir.path().join("completion")).unwrap();
        let svg = std::fs::read_to_string(dir.path().join("completion.svg")).unwrap();
        assert!(
            svg.contains("not completed") && svg.contains("hold-last: not completed"),
            "{svg}"
        );
        // No number labels the strip: every tick label is within the data.
        let ticks: Vec<f64> = svg.lines().filter_map(|l| l.trim().parse().ok()).collect();
        assert!(
            ticks.iter().all(|&v| v <= strip.from_y && v >= -1.0),
            "{ticks:?}"
        );
        assert!(ticks.iter().any(|&v| v >= 100.0), "{ticks:?}");
        assert_eq!(figure.misleading().unwrap(), vec![]);
    }

    #[test]
    fn lanes_are_named_rows_with_visible_instants() {
        let dir = tempfile::tempdir().unwrap();
        let files = LaneFigure {
            title: "timeline",
            x_label: "t [s]",
            lanes: &[
                Lane {
                    name: "upload",
                    spans: &[(0.0, 5.0), (60.0, 60.1)],
                    events: &[],
                    color: palette::ALT,
                },
                Lane {
                    name: "hand-back",
                    spans: &[],
                    events: &[40.0],
                    color: palette::BAD,
                },
            ],
        }
        .write(&dir.path().join("lanes"))
        .unwrap();
        let svg = std::fs::read_to_string(&files[0]).unwrap();
        let texts: Vec<&str> = svg.lines().map(str::trim).collect();
        assert!(
            texts.contains(&"upload") && texts.contains(&"hand-back"),
            "{svg}"
        );
        // Rows, not numbers: no fractional tick labels on the lane axis.
        assert!(!texts.contains(&"0.5") && !texts.contains(&"1.5"), "{svg}");
        let png = image::open(&files[1]).unwrap().to_rgb8();
        let count = |c: RGBColor| png.pixels().filter(|p| p.0 == [c.0, c.1, c.2]).count();
        // The instant is a tick across its row and a dot, not a speck.
        assert!(count(palette::BAD) > 150, "{}", count(palette::BAD));
    }
}
