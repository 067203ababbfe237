//! Figures as SVG and PNG from plain data: a top-down world view with paths,
//! markers and outlines, time-series plots, and lanes of spans and events
//! over time. Text is rendered with an embedded DejaVu Sans, so PNGs need no
//! system fonts.
//!
//! Time plots look after their reader: the y range ignores a few outliers
//! (see [`robust_range`]) and says so, a series that would hide exactly
//! under another is drawn dashed with marked points over the other drawn
//! wide and says so, a series of one point is drawn as a point, and x
//! values without a y go in a named strip above the axis. World figures
//! draw reference paths as pale bands under the paths measured against
//! them, a path on another's points dashed over it, and
//! [`WaypointFigure`] numbered waypoints with their headings. For either
//! kind the legend goes where it covers no drawn pixel (inside the axes
//! when a spot is free, else under the chart), and `write` first
//! rasterises each layer as the PNG draws it and refuses the figure
//! ([`PlotError::Misleading`]) when the legend lies over anything drawn or
//! a legend entry has nothing drawn or hides under what is drawn after it
//! (`misleading` says what it finds).
//! [`MapPicture`] draws an occupancy map's cells with a drive on it.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::coord::ranged1d::{SegmentValue, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, Pos, VPos};

pub use plotters::style::RGBColor;

pub mod map_picture;
pub use map_picture::MapPicture;

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

/// A line through points; a non-finite point breaks it (the pieces of one
/// thing under one legend entry).
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

/// Goals in order over a world figure: each a disc with its number (from
/// 1) inside and, where it has one, its heading as an arrow from it.
#[derive(Debug, Clone, Copy)]
pub struct Waypoints<'a> {
    pub label: &'a str,
    pub points: &'a [(f64, f64)],
    /// Each point's heading (rad, counter-clockwise from x), where one is
    /// given; missing entries have none.
    pub headings_rad: &'a [Option<f64>],
    pub color: RGBColor,
}

/// A [`WorldFigure`] with [`Waypoints`] drawn over its paths and markers
/// (a route through goals).
#[derive(Debug, Clone, Copy)]
pub struct WaypointFigure<'a> {
    pub world: WorldFigure<'a>,
    pub waypoints: Waypoints<'a>,
}

impl<'a> WaypointFigure<'a> {
    fn spec(&self) -> Result<(ChartSpec<'a>, (u32, u32)), PlotError> {
        let (mut spec, size) = self.world.spec_with(self.waypoints.points)?;
        spec.waypoints = Some(self.waypoints);
        Ok((spec, size))
    }

    /// Writes `<base>.svg` and `<base>.png` as [`WorldFigure::write`] does,
    /// checked the same way.
    pub fn write(&self, base: &Path) -> Result<Vec<PathBuf>, PlotError> {
        let (spec, size) = self.spec()?;
        Checked::new(self.world.title, spec, size)?.write(base)
    }

    /// What would mislead in the figure (see [`Misleading`]).
    pub fn misleading(&self) -> Result<Vec<Misleading>, PlotError> {
        let (spec, size) = self.spec()?;
        Ok(Checked::new(self.world.title, spec, size)?.found)
    }

    /// Where the world point `p` lands in the PNG, in pixels from its top
    /// left corner.
    pub fn pixel_of(&self, p: (f64, f64)) -> Result<(i32, i32), PlotError> {
        let (spec, size) = self.spec()?;
        pixel_of(self.world.title, &spec, size, p)
    }
}

/// Where `p` lands on a chart of `size` drawn from `spec`.
fn pixel_of(
    what: &str,
    spec: &ChartSpec,
    size: (u32, u32),
    p: (f64, f64),
) -> Result<(i32, i32), PlotError> {
    register_fonts();
    let mut buf = vec![255u8; (size.0 * size.1 * 3) as usize];
    let root = BitMapBackend::with_buffer(&mut buf, size).into_drawing_area();
    let chart = frame(&root, spec).map_err(|message| PlotError::Data {
        what: what.into(),
        message,
    })?;
    Ok(chart.backend_coord(&p))
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
/// A time series another runs dashed along is drawn this wide under it;
/// a world path, as wide as the dashes (a path may circle many times: a
/// wide one would blot the circles out), so the two alternate along it.
const UNDER_PX: u32 = 6;
const UNDER_PATH_PX: u32 = 2;

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
    /// A band this many pixels wide (a reference path, drawn under the
    /// others; a line another runs dashed along); 0 for a line.
    band_px: u32,
    /// The band's opacity.
    band_alpha: f64,
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
        self.spec_with(&[])
    }

    /// [`WorldFigure::spec`] with `more` points inside the axes.
    fn spec_with(&self, more: &[(f64, f64)]) -> Result<(ChartSpec<'a>, (u32, u32)), PlotError> {
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
            .chain(self.outlines.iter().flat_map(|o| o.corners.iter()))
            .chain(more);
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
            pieces: s
                .points
                .split(|p| !(p.0.is_finite() && p.1.is_finite()))
                .filter(|piece| !piece.is_empty())
                .map(|piece| decimate(piece, step))
                .collect(),
            dashed: false,
            band_px,
            band_alpha: REFERENCE_ALPHA,
            vertices: (s.points.len() == 1).then_some(Shape::Circle),
        };
        // Each reference narrower than the one before: one that follows
        // another (a continuation along the plan) runs inside it.
        let n = self.references.len() as u32;
        let mut lines: Vec<Line> = (0..n)
            .zip(self.references)
            .map(|(k, s)| line(s, REFERENCE_PX + REFERENCE_STEP_PX * (n - 1 - k)))
            .collect();
        // A path with the points of one drawn before it (two runs that
        // went the same way) is drawn dashed over it, which shows between
        // the dashes, and says so.
        let tol = 1e-9 * ((x1 - x0) + (y1 - y0));
        let first = lines.len();
        for (j, s) in self.paths.iter().enumerate() {
            let mut l = line(s, 0);
            let under = self.paths[..j]
                .iter()
                .enumerate()
                .find(|(_, a)| overlap(a.points, s.points, tol) == Some(Overlap::Same));
            if let Some((i, a)) = under {
                let under = a.label;
                if !lines[first + i].dashed {
                    lines[first + i].band_px = UNDER_PATH_PX;
                    lines[first + i].band_alpha = 1.0;
                }
                l.dashed = true;
                if !s.label.is_empty() {
                    l.label = format!("{} (dashed: same path as {under})", s.label);
                }
            }
            lines.push(l);
        }
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
            waypoints: None,
            marker_radius: 5,
            along_x: false,
        };
        Ok((spec, size))
    }

    /// Writes `<base>.svg` and `<base>.png`, the legend where it covers
    /// nothing drawn; refused with [`PlotError::Misleading`] when
    /// [`WorldFigure::misleading`] finds anything.
    pub fn write(&self, base: &Path) -> Result<Vec<PathBuf>, PlotError> {
        let (spec, size) = self.spec()?;
        Checked::new(self.title, spec, size)?.write(base)
    }

    /// Every legend entry that shows nothing or hides under what is drawn
    /// after it, and a legend over anything drawn (see [`Misleading`]), as
    /// [`WorldFigure::write`] would draw them.
    pub fn misleading(&self) -> Result<Vec<Misleading>, PlotError> {
        let (spec, size) = self.spec()?;
        Ok(Checked::new(self.title, spec, size)?.found)
    }

    /// Where the world point `p` lands in the PNG, in pixels from its top
    /// left corner.
    pub fn pixel_of(&self, p: (f64, f64)) -> Result<(i32, i32), PlotError> {
        let (spec, size) = self.spec()?;
        pixel_of(self.title, &spec, size, p)
    }
}

/// A chart laid out (its legend placed) and checked, ready to draw.
struct Checked<'a> {
    what: String,
    spec: ChartSpec<'a>,
    /// The chart's size without a legend under it.
    size: (u32, u32),
    layout: Layout,
    found: Vec<Misleading>,
}

impl<'a> Checked<'a> {
    fn new(what: &str, mut spec: ChartSpec<'a>, size: (u32, u32)) -> Result<Self, PlotError> {
        let (layout, found) = lay_out(&mut spec, size).map_err(|message| PlotError::Data {
            what: what.into(),
            message,
        })?;
        Ok(Checked {
            what: what.into(),
            spec,
            size,
            layout,
            found,
        })
    }

    /// The error that refuses the chart, if anything in it would mislead.
    fn refusal(&self) -> Result<(), PlotError> {
        if self.found.is_empty() {
            Ok(())
        } else {
            Err(PlotError::Misleading {
                what: self.what.clone(),
                found: self.found.clone(),
            })
        }
    }

    /// Writes `<base>.svg` and `<base>.png` when nothing misleads.
    fn write(&self, base: &Path) -> Result<Vec<PathBuf>, PlotError> {
        self.refusal()?;
        let size = (self.size.0, self.size.1 + self.layout.below_px);
        write_both(
            base,
            size,
            |r| draw_chart(&r, &self.spec, &self.layout, self.size.1),
            |r| draw_chart(&r, &self.spec, &self.layout, self.size.1),
        )
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

/// The size of one of [`Panels`] in pixels (without a legend under it).
const PANEL_PX: (u32, u32) = (700, 450);

impl Panels<'_> {
    /// Writes `<base>.svg` and `<base>.png`, each panel checked as
    /// [`TimeFigure::write`] checks a figure; refused with
    /// [`PlotError::Misleading`] (naming the panel) when one would mislead.
    pub fn write(&self, base: &Path) -> Result<Vec<PathBuf>, PlotError> {
        let charts = self
            .panels
            .iter()
            .map(|p| Checked::new(p.title, p.spec()?, PANEL_PX))
            .collect::<Result<Vec<_>, _>>()?;
        for c in &charts {
            c.refusal()?;
        }
        let n = charts.len().max(1) as u32;
        let below = charts.iter().map(|c| c.layout.below_px).max().unwrap_or(0);
        write_both(
            base,
            (PANEL_PX.0 * n, PANEL_PX.1 + below),
            |r| draw_panels(r, &charts),
            |r| draw_panels(r, &charts),
        )
    }

    /// What would mislead in each panel (see [`Misleading`]), as
    /// [`Panels::write`] would draw them, with the panel's title.
    pub fn misleading(&self) -> Result<Vec<(String, Vec<Misleading>)>, PlotError> {
        self.panels
            .iter()
            .map(|p| Ok((p.title.to_string(), p.misleading()?)))
            .collect()
    }
}

fn draw_panels<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    charts: &[Checked],
) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    for (area, c) in root
        .split_evenly((1, charts.len().max(1)))
        .iter()
        .zip(charts)
    {
        draw_chart(area, &c.spec, &c.layout, c.size.1)?;
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
                .enumerate()
                .find_map(|(i, a)| overlap(a.points, s.points, tol).map(|o| (i, a.label, o)));
            let (label, dashed, vertices) = match hidden {
                Some((i, under, o)) => {
                    // The line under it drawn wide, so it shows either
                    // side of the dashes (unless dashed itself, over
                    // another).
                    if !lines[i].dashed {
                        lines[i].band_px = UNDER_PX;
                        lines[i].band_alpha = 1.0;
                    }
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
                band_alpha: 1.0,
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
            waypoints: None,
            marker_radius: 3,
            along_x: true,
        })
    }
}

/// The size of a time figure in pixels.
const TIME_FIGURE_PX: (u32, u32) = (1100, 450);

impl TimeFigure<'_> {
    /// Writes `<base>.svg` and `<base>.png`, the legend where it covers
    /// nothing drawn; refused with [`PlotError::Misleading`] when
    /// [`TimeFigure::misleading`] finds anything.
    pub fn write(&self, base: &Path) -> Result<Vec<PathBuf>, PlotError> {
        Checked::new(self.title, self.spec()?, TIME_FIGURE_PX)?.write(base)
    }

    /// Every legend entry that shows nothing or hides under what is drawn
    /// after it, and a legend over anything drawn (see [`Misleading`]), as
    /// [`TimeFigure::write`] draws them.
    pub fn misleading(&self) -> Result<Vec<Misleading>, PlotError> {
        Ok(Checked::new(self.title, self.spec()?, TIME_FIGURE_PX)?.found)
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
    waypoints: Option<Waypoints<'a>>,
    marker_radius: i32,
    /// Read along the x axis (a time figure), not along paths.
    along_x: bool,
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
    Waypoints,
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
    all.extend(spec.waypoints.as_ref().map(|_| Layer::Waypoints));
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
        Layer::Waypoints => spec
            .waypoints
            .as_ref()
            .filter(|w| !w.points.is_empty())
            .map(|w| w.label),
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

/// Draws one layer (its legend entry is [`draw_symbol`]'s).
fn draw_layer<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    spec: &ChartSpec,
    layer: Layer,
) -> Result<(), String> {
    let radius = spec.marker_radius;
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    match layer {
        Layer::Walls => {
            chart
                .draw_series(
                    spec.walls
                        .iter()
                        .map(|w| PathElement::new(vec![w[0], w[1]], palette::WALL.stroke_width(3))),
                )
                .map_err(err)?;
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
                .map_err(err)?;
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(x0, strip.from_y), (x1, strip.from_y)],
                    BLACK.stroke_width(1),
                )))
                .map_err(err)?;
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
                .map_err(err)?;
        }
        Layer::Shade(i) => {
            let b = &spec.shades[i];
            let color = b.color;
            let fill = Polygon::new(b.outline.clone(), color.mix(0.25).filled());
            chart.draw_series(std::iter::once(fill)).map_err(err)?;
            if b.edge {
                let mut ring = b.outline.clone();
                ring.extend(b.outline.first().copied());
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        ring,
                        color.stroke_width(2),
                    )))
                    .map_err(err)?;
            }
        }
        Layer::Line(i) => {
            // Width 1: plotters' bitmap backend leaves gaps in thicker
            // polylines. A series with an empty label draws without a
            // legend entry (several pieces of one thing).
            let s = &spec.lines[i];
            let color = s.color;
            if s.band_px > 0 && s.band_alpha >= 1.0 {
                // Opaque: segment by segment with round joins (a wide
                // polyline's sharp turns draw as spikes).
                let style = color.filled().stroke_width(s.band_px);
                let r = (s.band_px / 2) as i32;
                chart
                    .draw_series(s.pieces.iter().flat_map(|piece| {
                        piece
                            .windows(2)
                            .map(move |w| PathElement::new(w.to_vec(), style))
                    }))
                    .map_err(err)?;
                chart.draw_series(
                    s.pieces
                        .iter()
                        .flatten()
                        .map(|&p| Circle::new(p, r, color.filled())),
                )
            } else if s.band_px > 0 {
                let style = color.mix(s.band_alpha).stroke_width(s.band_px);
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
            .map_err(err)?;
            if let Some(shape) = s.vertices {
                let points: Vec<(f64, f64)> = s.pieces.concat();
                // Under another's marked points: larger, to show round
                // them; the marks of lines on the same points nest (a
                // triangle in a square in a cross), so none hides another.
                let size = if s.band_px > 0 {
                    radius + 5
                } else {
                    match shape {
                        Shape::Circle | Shape::Triangle => radius,
                        Shape::Square => radius + 4,
                        Shape::Cross => radius + 7,
                    }
                };
                draw_shapes(chart, &points, shape, color, size)?;
            }
        }
        Layer::Dots(i) => {
            let m = &spec.dots[i];
            let color = m.color;
            chart
                .draw_series(
                    m.points
                        .iter()
                        .map(|&p| Circle::new(p, radius, color.filled())),
                )
                .map_err(err)?;
        }
        Layer::Waypoints => {
            let Some(w) = &spec.waypoints else {
                return Ok(());
            };
            let color = w.color;
            let number = ("sans-serif", 12)
                .into_font()
                .style(FontStyle::Bold)
                .color(&WHITE)
                .pos(Pos::new(HPos::Center, VPos::Center));
            let heading = |k: usize| w.headings_rad.get(k).copied().flatten();
            // The arrows first: each starts under its disc.
            chart
                .draw_series(w.points.iter().enumerate().filter_map(|(k, &p)| {
                    heading(k).map(|h| {
                        let (shaft, head) = arrow(h, HEADING_ARROW_PX, color);
                        EmptyElement::at(p) + shaft + head
                    })
                }))
                .map_err(err)?;
            chart
                .draw_series(w.points.iter().enumerate().map(|(k, &p)| {
                    EmptyElement::at(p)
                        + Circle::new((0, 0), WAYPOINT_RADIUS_PX, color.filled())
                        + Text::new((k + 1).to_string(), (0, 1), number.clone())
                }))
                .map_err(err)?;
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
                .map_err(err)?;
            chart
                .draw_series(b.up.iter().map(|&(c, color)| up(c, color)))
                .map_err(err)?;
        }
        Layer::Outline(i) => {
            let o = &spec.outlines[i];
            let color = o.color;
            let mut ring = o.corners.to_vec();
            ring.extend(o.corners.first().copied());
            chart
                .draw_series(
                    ring.windows(2)
                        .map(|w| DashedPathElement::new(w.to_vec(), 6, 4, color.stroke_width(3))),
                )
                .map_err(err)?;
        }
    }
    Ok(())
}

/// Draws the legend's symbol of `layer` on `area`, its left end at `(x, y)`
/// (pixels in `area`), in a [`LEGEND_SYMBOL_PX`] wide column.
fn draw_symbol<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    spec: &ChartSpec,
    layer: Layer,
    (x, y): (i32, i32),
) -> Result<(), String> {
    let radius = spec.marker_radius;
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    match layer {
        Layer::Walls | Layer::Strip => {}
        Layer::Shade(i) => {
            let b = &spec.shades[i];
            let color = b.color;
            let edge: ShapeStyle = if b.edge {
                color.stroke_width(2)
            } else {
                color.mix(0.25).stroke_width(2)
            };
            area.draw(
                &(EmptyElement::at((x, y))
                    + Rectangle::new([(0, -5), (20, 5)], color.mix(0.25).filled())
                    + Rectangle::new([(0, -5), (20, 5)], edge)),
            )
            .map_err(err)?;
        }
        Layer::Line(i) => {
            let s = &spec.lines[i];
            let color = s.color;
            if s.band_px > 0 {
                area.draw(&PathElement::new(
                    vec![(x, y), (x + 20, y)],
                    color.mix(s.band_alpha).stroke_width(s.band_px.min(10)),
                ))
                .map_err(err)?;
            } else {
                let dash = if s.dashed { 5 } else { 100 };
                let mark: Vec<(i32, i32)> = match s.vertices {
                    None => vec![],
                    Some(Shape::Circle) => vec![(8, -2), (12, -2), (12, 2), (8, 2), (8, -2)],
                    Some(Shape::Triangle) => vec![(10, -5), (14, 3), (6, 3), (10, -5)],
                    Some(Shape::Square) => vec![(6, -4), (14, -4), (14, 4), (6, 4), (6, -4)],
                    Some(Shape::Cross) => vec![(6, -4), (14, 4), (10, 0), (14, -4), (6, 4)],
                };
                area.draw(
                    &(EmptyElement::at((x, y))
                        + DashedPathElement::new(
                            vec![(0, 0), (20, 0)],
                            dash,
                            3,
                            color.stroke_width(2),
                        )
                        + PathElement::new(mark, color.stroke_width(2))),
                )
                .map_err(err)?;
            }
        }
        Layer::Dots(i) => {
            area.draw(&Circle::new(
                (x + 10, y),
                radius,
                spec.dots[i].color.filled(),
            ))
            .map_err(err)?;
        }
        Layer::Waypoints => {
            if let Some(w) = &spec.waypoints {
                let (shaft, head) = arrow(0.0, 22, w.color);
                area.draw(
                    &(EmptyElement::at((x + 6, y))
                        + shaft
                        + head
                        + Circle::new((0, 0), 6, w.color.filled())),
                )
                .map_err(err)?;
            }
        }
        Layer::Beyond => {
            area.draw(
                &(EmptyElement::at((x + 10, y))
                    + Polygon::new(vec![(-5, 4), (5, 4), (0, -6)], BLACK.filled())),
            )
            .map_err(err)?;
        }
        Layer::Outline(i) => {
            area.draw(&Rectangle::new(
                [(x + 2, y - 5), (x + 18, y + 5)],
                spec.outlines[i].color.stroke_width(2),
            ))
            .map_err(err)?;
        }
    }
    Ok(())
}

/// Draws the legend as plotters lays one out (a box, a column of symbols,
/// a line of text each) at `b`, the axes' top left corner at `origin`
/// (pixels in `area`).
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    spec: &ChartSpec,
    b: LegendBox,
    origin: (i32, i32),
) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let (x, y) = (origin.0 + b.x, origin.1 + b.y);
    let corners = [(x, y), (x + b.w, y + b.h)];
    area.draw(&Rectangle::new(corners, WHITE.mix(0.85).filled()))
        .map_err(err)?;
    area.draw(&Rectangle::new(corners, BLACK)).map_err(err)?;
    let m = LEGEND_MARGIN_PX as i32;
    let font = legend_font();
    let entries: Vec<(Layer, &str)> = layers(spec)
        .into_iter()
        .filter_map(|l| legend_label(spec, l).map(|label| (l, label)))
        .collect();
    let mut text = plotters::element::MultiLineText::<_, &str>::new(
        (x + m + LEGEND_SYMBOL_PX as i32, y + m),
        &font,
    );
    for (_, label) in &entries {
        text.push_line(*label);
    }
    area.draw(&text).map_err(err)?;
    let lines = text.compute_line_layout().map_err(|e| e.to_string())?;
    for (((_, y0), (_, y1)), (layer, _)) in lines.into_iter().zip(entries) {
        draw_symbol(area, spec, layer, (x + m, (y0 + y1) / 2))?;
    }
    Ok(())
}

/// A waypoint's disc: this radius in pixels, its number inside.
pub const WAYPOINT_RADIUS_PX: i32 = 9;
/// A waypoint's heading: an arrow this long from the disc's centre.
pub const HEADING_ARROW_PX: i32 = 36;

/// An arrow's shaft and head, in pixels from its tail.
type Arrow = (PathElement<(i32, i32)>, Polygon<(i32, i32)>);

/// An arrow from (0, 0) along `heading_rad` (counter-clockwise from the
/// x axis; pixels' y runs down), `length_px` long.
fn arrow(heading_rad: f64, length_px: i32, color: RGBColor) -> Arrow {
    let (c, s) = (heading_rad.cos(), -heading_rad.sin());
    let at = |along: f64, across: f64| {
        (
            (along * c - across * s).round() as i32,
            (along * s + across * c).round() as i32,
        )
    };
    let len = f64::from(length_px);
    (
        PathElement::new(vec![(0, 0), at(len - 8.0, 0.0)], color.stroke_width(3)),
        Polygon::new(
            vec![at(len, 0.0), at(len - 11.0, 6.0), at(len - 11.0, -6.0)],
            color.filled(),
        ),
    )
}

/// Draws a chart on `root`: the chart itself on its top `chart_h` pixels,
/// its legend where `layout` puts it (under the chart: in the rest).
fn draw_chart<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    spec: &ChartSpec,
    layout: &Layout,
    chart_h: u32,
) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let area = if root.dim_in_pixel().1 > chart_h {
        root.split_vertically(chart_h).0
    } else {
        root.clone()
    };
    let mut chart = frame(&area, spec)?;
    // Outlines last: nothing may hide them.
    for layer in layers(spec) {
        draw_layer(&mut chart, spec, layer)?;
    }
    if let Some(b) = layout.legend {
        let (xs, ys) = chart.plotting_area().get_pixel_range();
        let base = root.get_base_pixel();
        draw_legend(root, spec, b, (xs.start - base.0, ys.start - base.1))?;
    }
    root.present().map_err(|e| e.to_string())
}

/// What makes a figure mislead its reader.
#[derive(Debug, Clone, PartialEq)]
pub enum Misleading {
    /// The legend names it, but nothing of it (fewer than [`MIN_PIXELS`])
    /// shows inside the axes.
    NothingDrawn { label: String },
    /// Almost all of it lies under what is drawn after it (the legend
    /// included).
    Hidden {
        label: String,
        /// The fraction of its pixels still seen.
        visible_fraction: f64,
    },
    /// The legend's box lies over this many pixels of what is drawn.
    LegendOverData { pixels: usize },
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
            Misleading::LegendOverData { pixels } => {
                write!(f, "the legend covers {pixels} drawn pixel(s)")
            }
        }
    }
}

/// A legend entry is hidden when less than this fraction of its pixels
/// shows (a pixel next to one drawn later counts as covered: a line a pixel
/// beside another merges with it) and it shows in less than
/// [`MIN_VISIBLE_SPREAD`] of the places it is drawn in.
pub const MIN_VISIBLE_FRACTION: f64 = 0.15;

/// A legend entry that shows in at least this share of the places it is
/// drawn in is seen, however little of each place shows (a noisy series
/// whose peaks stand out of another's all along the time axis). Places are
/// [`SPREAD_PX`] wide columns of a time figure (read along its time axis)
/// and squares of that side in a world figure (read along a path).
pub const MIN_VISIBLE_SPREAD: f64 = 0.5;
pub const SPREAD_PX: usize = 16;

/// The share of the places `mask` is drawn in (see [`MIN_VISIBLE_SPREAD`])
/// where some of it is not under `above`.
fn spread(mask: &[bool], above: &[bool], w: usize, along_x: bool) -> f64 {
    let h = mask.len() / w.max(1);
    let (cw, ch) = (SPREAD_PX, if along_x { h.max(1) } else { SPREAD_PX });
    let nx = w.div_ceil(cw);
    let mut drawn = vec![false; nx * h.div_ceil(ch)];
    let mut seen = drawn.clone();
    for (i, (&m, &a)) in mask.iter().zip(above).enumerate() {
        if m {
            let place = (i / w / ch) * nx + (i % w) / cw;
            drawn[place] = true;
            seen[place] |= !a;
        }
    }
    let count = |v: &[bool]| v.iter().filter(|&&x| x).count();
    count(&seen) as f64 / count(&drawn).max(1) as f64
}

/// A legend entry with fewer pixels than this inside the axes shows
/// nothing a reader can find.
pub const MIN_PIXELS: usize = 9;

/// The legend as plotters draws it: a symbol column this wide, a margin
/// this wide all round, text in this font.
const LEGEND_SYMBOL_PX: u32 = 30;
const LEGEND_MARGIN_PX: u32 = 10;
fn legend_font() -> TextStyle<'static> {
    ("sans-serif", 12).into_font().into()
}

/// The legend keeps this far from anything drawn and from the axes' edges.
const LEGEND_CLEAR_PX: i32 = 4;

/// A chart's layers rasterised one by one as the PNG draws them, each
/// alone: the pixels of the plot area each one covers.
struct Raster {
    /// The chart's size and its plot area's pixels within it.
    size: (u32, u32),
    xs: std::ops::Range<i32>,
    ys: std::ops::Range<i32>,
    /// Per layer of [`layers`], row by row over the plot area.
    masks: Vec<Vec<bool>>,
}

impl Raster {
    fn plot_size(&self) -> (usize, usize) {
        (
            (self.xs.end - self.xs.start).max(0) as usize,
            (self.ys.end - self.ys.start).max(0) as usize,
        )
    }

    /// Everything drawn.
    fn union(&self) -> Vec<bool> {
        let (w, h) = self.plot_size();
        let mut all = vec![false; w * h];
        for mask in &self.masks {
            for (a, &m) in all.iter_mut().zip(mask) {
                *a |= m;
            }
        }
        all
    }
}

/// The plot area's pixels across and down.
type PixelRanges = (std::ops::Range<i32>, std::ops::Range<i32>);

/// The pixels of the plot area that `layer` covers, drawn alone at `size`,
/// and the plot area's pixel ranges.
fn layer_mask(
    spec: &ChartSpec,
    size: (u32, u32),
    layer: Layer,
) -> Result<(Vec<bool>, PixelRanges), String> {
    let (w, h) = size;
    let mut buf = vec![255u8; (w * h * 3) as usize];
    let (xs, ys) = {
        let root = BitMapBackend::with_buffer(&mut buf, size).into_drawing_area();
        let mut chart = frame(&root, spec)?;
        // The frame drawn, then wiped: only the layer's own pixels count.
        let range = chart.plotting_area().get_pixel_range();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        draw_layer(&mut chart, spec, layer)?;
        root.present().map_err(|e| e.to_string())?;
        range
    };
    let (x0, x1) = (xs.start.max(0), xs.end.min(w as i32));
    let (y0, y1) = (ys.start.max(0), ys.end.min(h as i32));
    let mut mask = Vec::with_capacity(((x1 - x0).max(0) * (y1 - y0).max(0)) as usize);
    for y in y0..y1 {
        for x in x0..x1 {
            let i = (y as u32 * w + x as u32) as usize;
            mask.push(buf[3 * i..3 * i + 3] != [255, 255, 255]);
        }
    }
    Ok((mask, (x0..x1, y0..y1)))
}

fn rasterise(spec: &ChartSpec, size: (u32, u32)) -> Result<Raster, String> {
    register_fonts();
    let mut raster = Raster {
        size,
        xs: 0..0,
        ys: 0..0,
        masks: Vec::new(),
    };
    for layer in layers(spec) {
        let (mask, (xs, ys)) = layer_mask(spec, size, layer)?;
        raster.masks.push(mask);
        (raster.xs, raster.ys) = (xs, ys);
    }
    Ok(raster)
}

/// Where a chart's legend goes, in pixels from its plot area's top left
/// corner (plotters' `SeriesLabelPosition::Coordinate`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct LegendBox {
    x: i32,
    y: i32,
    w: i32,
    h: i32,
    /// Under the chart, in pixels added to the figure's height.
    below: bool,
}

/// A chart's legend: inside the axes where it covers nothing drawn, else
/// under the chart; `below_px` is what the figure grows by for it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Layout {
    legend: Option<LegendBox>,
    below_px: u32,
}

/// The legend's size in pixels, as plotters lays it out; `None` when it
/// has no entries.
fn legend_size(spec: &ChartSpec) -> Result<Option<(i32, i32)>, String> {
    register_fonts();
    let font = legend_font();
    let mut text = plotters::element::MultiLineText::<_, &str>::new((0, 0), &font);
    let mut any = false;
    for layer in layers(spec) {
        if let Some(label) = legend_label(spec, layer) {
            text.push_line(label);
            any = true;
        }
    }
    if !any {
        return Ok(None);
    }
    let (w, h) = text.estimate_dimension().map_err(|e| e.to_string())?;
    let m = LEGEND_MARGIN_PX as i32;
    Ok(Some((w + LEGEND_SYMBOL_PX as i32 + 2 * m, h + 2 * m)))
}

/// The legend's place: the spot inside the axes nearest one of their
/// corners (upper right, upper left, lower right, lower left first) where
/// its box keeps [`LEGEND_CLEAR_PX`] from every pixel drawn; under the
/// chart, left-aligned with the axes, when there is none.
fn place_legend(spec: &ChartSpec, raster: &Raster) -> Result<Layout, String> {
    let Some((w, h)) = legend_size(spec)? else {
        return Ok(Layout {
            legend: None,
            below_px: 0,
        });
    };
    let (pw, ph) = raster.plot_size();
    let (pw, ph) = (pw as i32, ph as i32);
    let c = LEGEND_CLEAR_PX;
    let (x_max, y_max) = (pw - w - c - 1, ph - h - c - 1);
    if x_max > c && y_max > c {
        let drawn = Summed::new(&raster.union(), pw as usize, ph as usize);
        let corners = [
            (x_max, c + 1),
            (c + 1, c + 1),
            (x_max, y_max),
            (c + 1, y_max),
        ];
        let mut best: Option<(i32, (i32, i32))> = None;
        let xs = (c + 1..=x_max).step_by(4).chain(std::iter::once(x_max));
        for x in xs {
            let ys = (c + 1..=y_max).step_by(4).chain(std::iter::once(y_max));
            for y in ys {
                // Nearest corner first; among equals, the corners' order.
                let d = corners
                    .iter()
                    .enumerate()
                    .map(|(k, &(cx, cy))| 4 * ((x - cx).abs() + (y - cy).abs()) + k as i32)
                    .min()
                    .unwrap_or(0);
                if best.is_some_and(|(b, _)| b <= d) {
                    continue;
                }
                if drawn.count(x - c, y - c, x + w + c, y + h + c) == 0 {
                    best = Some((d, (x, y)));
                }
            }
        }
        if let Some((_, (x, y))) = best {
            return Ok(Layout {
                legend: Some(LegendBox {
                    x,
                    y,
                    w,
                    h,
                    below: false,
                }),
                below_px: 0,
            });
        }
    }
    // Under the x axis' label, from the axes' left edge.
    let y = raster.size.1 as i32 - raster.ys.start + 2;
    Ok(Layout {
        legend: Some(LegendBox {
            x: 0,
            y,
            w,
            h,
            below: true,
        }),
        below_px: (h + 8) as u32,
    })
}

/// A summed-area table of a mask: how many pixels of a rectangle are set.
struct Summed {
    w: usize,
    h: usize,
    sums: Vec<u32>,
}

impl Summed {
    fn new(mask: &[bool], w: usize, h: usize) -> Self {
        let mut sums = vec![0u32; (w + 1) * (h + 1)];
        for y in 0..h {
            let mut row = 0u32;
            for x in 0..w {
                row += u32::from(mask[y * w + x]);
                sums[(y + 1) * (w + 1) + x + 1] = sums[y * (w + 1) + x + 1] + row;
            }
        }
        Summed { w, h, sums }
    }

    /// Set pixels with x0 <= x < x1 and y0 <= y < y1 (clipped to the mask).
    fn count(&self, x0: i32, y0: i32, x1: i32, y1: i32) -> u32 {
        let cx = |x: i32| x.clamp(0, self.w as i32) as usize;
        let cy = |y: i32| y.clamp(0, self.h as i32) as usize;
        let (x0, x1, y0, y1) = (cx(x0), cx(x1), cy(y0), cy(y1));
        if x0 >= x1 || y0 >= y1 {
            return 0;
        }
        let at = |x: usize, y: usize| self.sums[y * (self.w + 1) + x];
        at(x1, y1) + at(x0, y0) - at(x0, y1) - at(x1, y0)
    }
}

/// Every legend entry of `spec` that shows nothing in the axes or lies
/// almost wholly under what is drawn after it or under the legend, and the
/// legend itself when it lies over anything drawn; found on the rasterised
/// layers, so widths, dashes and markers count as drawn.
fn findings(spec: &ChartSpec, raster: &Raster, layout: &Layout) -> Vec<Misleading> {
    let (w, h) = raster.plot_size();
    // What is drawn above the current layer, grown by a pixel each way;
    // the legend is drawn above everything.
    let mut above = vec![false; w * h];
    let mut found = Vec::new();
    if let Some(b) = layout.legend.filter(|b| !b.below) {
        let mut covered = 0;
        for y in b.y.max(0)..(b.y + b.h + 1).min(h as i32) {
            for x in b.x.max(0)..(b.x + b.w + 1).min(w as i32) {
                let i = y as usize * w + x as usize;
                above[i] = true;
                covered += usize::from(raster.masks.iter().any(|m| m[i]));
            }
        }
        if covered > 0 {
            found.push(Misleading::LegendOverData { pixels: covered });
        }
    }
    let mut per_layer = Vec::new();
    for (layer, mask) in layers(spec).iter().zip(&raster.masks).rev() {
        if let Some(label) = legend_label(spec, *layer) {
            let drawn = mask.iter().filter(|&&m| m).count();
            let seen = mask.iter().zip(&above).filter(|&(&m, &a)| m && !a).count();
            if drawn < MIN_PIXELS {
                per_layer.push(Misleading::NothingDrawn {
                    label: label.to_string(),
                });
            } else if (seen as f64) < MIN_VISIBLE_FRACTION * drawn as f64
                && spread(mask, &above, w, spec.along_x) < MIN_VISIBLE_SPREAD
            {
                per_layer.push(Misleading::Hidden {
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
    per_layer.reverse();
    found.extend(per_layer);
    found
}

/// A chart laid out and checked: a line hidden under one drawn after it
/// restyled (see [`dash_lines_along_others`]), its legend's place, and
/// what would mislead in it.
fn lay_out(spec: &mut ChartSpec, size: (u32, u32)) -> Result<(Layout, Vec<Misleading>), String> {
    let mut raster = rasterise(spec, size)?;
    if dash_lines_along_others(spec, &raster) {
        raster = rasterise(spec, size)?;
    }
    let layout = place_legend(spec, &raster)?;
    let found = findings(spec, &raster, &layout);
    Ok((layout, found))
}

/// A line with a legend entry that lies almost wholly under one line drawn
/// after it (two runs a pixel apart, as drawn: not the same points, which
/// the figures find beforehand) is drawn wide under it, and that one
/// dashed, its legend entry saying along which: as for lines on the same
/// points. Whether any line was restyled.
fn dash_lines_along_others(spec: &mut ChartSpec, raster: &Raster) -> bool {
    let hidden: Vec<String> = findings(
        spec,
        raster,
        &Layout {
            legend: None,
            below_px: 0,
        },
    )
    .into_iter()
    .filter_map(|m| match m {
        Misleading::Hidden { label, .. } => Some(label),
        _ => None,
    })
    .collect();
    if hidden.is_empty() {
        return false;
    }
    let (w, h) = raster.plot_size();
    let all = layers(spec);
    let plain = |spec: &ChartSpec, layer: Layer| match layer {
        Layer::Line(i) if spec.lines[i].band_px == 0 && !spec.lines[i].dashed => Some(i),
        _ => None,
    };
    // How many of `mask`'s pixels lie within a pixel of `over`'s.
    let covered = |mask: &[bool], over: &[bool]| {
        (0..w * h)
            .filter(|&i| {
                let (x, y) = (i % w, i / w);
                mask[i]
                    && (y.saturating_sub(1)..(y + 2).min(h))
                        .any(|yy| (x.saturating_sub(1)..(x + 2).min(w)).any(|xx| over[yy * w + xx]))
            })
            .count()
    };
    let mut changed = false;
    for (a, &layer) in all.iter().enumerate() {
        let Some(i) = plain(spec, layer) else {
            continue;
        };
        if !hidden.contains(&spec.lines[i].label) {
            continue;
        }
        let drawn = raster.masks[a].iter().filter(|&&m| m).count();
        let over = all
            .iter()
            .enumerate()
            .skip(a + 1)
            .filter_map(|(b, &l)| {
                plain(spec, l).map(|k| (covered(&raster.masks[a], &raster.masks[b]), k))
            })
            .max_by_key(|&(c, _)| c);
        if let Some((c, k)) = over
            && 10 * c >= 8 * drawn
        {
            let under = spec.lines[i].label.clone();
            spec.lines[i].band_px = if spec.along_x {
                UNDER_PX
            } else {
                UNDER_PATH_PX
            };
            spec.lines[i].band_alpha = 1.0;
            let l = &mut spec.lines[k];
            l.dashed = true;
            if !l.label.is_empty() {
                l.label = format!("{} (dashed: within a pixel of {under})", l.label);
            }
            changed = true;
        }
    }
    changed
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

        let shifted =
            |dy: f64| -> Vec<(f64, f64)> { path.iter().map(|&(x, y)| (x, y + dy)).collect() };
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
                lower: &shifted(-0.3),
                upper: &shifted(0.3),
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
        // The robot's lap in two halves, two paths.
        let (first, second) = follower.split_at(follower.len() / 2);
        let halves = [
            Series {
                label: "robot, first half",
                points: first,
                color: palette::TRUTH,
            },
            Series {
                label: "robot, second half",
                points: second,
                color: palette::GOOD,
            },
        ];
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
        // The plan drawn first, the halves over it: the plan is lost.
        let both = [plan, halves[0], halves[1]];
        let found = figure(&both, &[]);
        assert!(
            matches!(&found[..], [Misleading::Hidden { label, visible_fraction }]
                if label == "plan" && *visible_fraction < 0.1),
            "{found:?}"
        );
        // Under one path a pixel off, it is drawn wide under it, the robot
        // dashed, and both show.
        assert_eq!(figure(&[plan, robot], &[]), vec![]);
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
        let written = |paths: &[Series], name: &str| {
            WorldFigure {
                title: "hidden",
                walls: &[],
                regions: &[],
                paths,
                references: &[],
                markers: &[],
                outlines: &[],
            }
            .write(&dir.path().join(name))
        };
        let err = written(&both, "hidden").unwrap_err();
        assert!(err.to_string().contains("\"plan\" is hidden"), "{err}");
        assert!(!dir.path().join("hidden.png").exists());
        let files = written(&[plan, robot], "along").unwrap();
        let svg = std::fs::read_to_string(&files[0]).unwrap();
        assert!(svg.contains("robot (dashed: within a pixel of plan)"));
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

    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Pixels of exactly `c` in the PNG at `path` within x0..x1, y0..y1
    /// and outside `skip` (x0, y0, x1, y1).
    fn pixels_of(
        png: &image::RgbImage,
        c: RGBColor,
        area: (i32, i32, i32, i32),
        skip: Option<(i32, i32, i32, i32)>,
    ) -> usize {
        let (x0, y0, x1, y1) = area;
        let mut n = 0;
        for y in y0.max(0)..y1.min(png.height() as i32) {
            for x in x0.max(0)..x1.min(png.width() as i32) {
                let in_skip = skip.is_some_and(|(a, b, c, d)| x >= a && x <= c && y >= b && y <= d);
                if !in_skip && png.get_pixel(x as u32, y as u32).0 == [c.0, c.1, c.2] {
                    n += 1;
                }
            }
        }
        n
    }

    /// Random time figures, one to four random walks each over a random
    /// part of the x range, some dense enough to fill the axes: the legend
    /// lies where nothing is drawn (inside the axes when a spot is free,
    /// else under the chart, which grows for it), the check finds nothing,
    /// and in the PNG every series shows pixels of its own colour in the
    /// axes outside the legend's box.
    #[test]
    fn the_legend_never_covers_what_is_drawn() {
        let mut rng = ChaCha8Rng::seed_from_u64(5401);
        let dir = tempfile::tempdir().unwrap();
        let colors = [palette::TRUTH, palette::ALT, palette::GOOD, palette::PURPLE];
        let labels = ["first", "second series", "a third, longer name", "4th"];
        let (mut inside, mut below) = (0, 0);
        for case in 0..16 {
            let dense = rng.random_bool(0.3);
            let n = rng.random_range(1..=4);
            let walks: Vec<Vec<(f64, f64)>> = (0..n)
                .map(|k| {
                    let (a, b) = if dense {
                        (0.0, 100.0)
                    } else {
                        let a = rng.random_range(0.0..70.0);
                        (a, a + rng.random_range(10.0..30.0))
                    };
                    let count = if dense {
                        2000
                    } else {
                        rng.random_range(3..200)
                    };
                    let mut y = 10.0 * k as f64;
                    (0..count)
                        .map(|i| {
                            // Dense: noise in bands that together fill the
                            // axes.
                            if dense {
                                y = 2.0 * k as f64 + rng.random_range(-1.0..1.0);
                            } else {
                                y += rng.random_range(-1.0..1.0);
                            }
                            (a + (b - a) * i as f64 / (count - 1) as f64, y)
                        })
                        .collect()
                })
                .collect();
            let series: Vec<Series> = walks
                .iter()
                .enumerate()
                .map(|(k, w)| Series {
                    label: labels[k],
                    points: w,
                    color: colors[k],
                })
                .collect();
            let figure = TimeFigure {
                title: "random walks",
                x_label: "t",
                y_label: "y",
                series: &series,
                markers: &[],
                bands: &[],
                strip: None,
            };
            let spec = figure.spec().unwrap();
            let raster = rasterise(&spec, TIME_FIGURE_PX).unwrap();
            let layout = place_legend(&spec, &raster).unwrap();
            let b = layout.legend.unwrap();
            let drawn = raster.union();
            let (w, h) = raster.plot_size();
            let under: usize = (b.y.max(0)..(b.y + b.h + 1).min(h as i32))
                .flat_map(|y| (b.x.max(0)..(b.x + b.w + 1).min(w as i32)).map(move |x| (x, y)))
                .filter(|&(x, y)| drawn[y as usize * w + x as usize])
                .count();
            if b.below {
                below += 1;
                assert!(layout.below_px >= b.h as u32, "{layout:?}");
                assert!(b.y > h as i32, "{layout:?}");
            } else {
                inside += 1;
                assert_eq!(layout.below_px, 0);
                assert_eq!(under, 0, "case {case}: {layout:?}");
            }
            assert_eq!(figure.misleading().unwrap(), vec![], "case {case}");
            let files = figure
                .write(&dir.path().join(format!("walk{case}")))
                .unwrap();
            let png = image::open(&files[1]).unwrap().to_rgb8();
            assert_eq!(
                (png.width(), png.height()),
                (TIME_FIGURE_PX.0, TIME_FIGURE_PX.1 + layout.below_px)
            );
            let area = (
                raster.xs.start,
                raster.ys.start,
                raster.xs.end,
                raster.ys.end,
            );
            let (lx, ly) = (raster.xs.start + b.x, raster.ys.start + b.y);
            for s in &series {
                let seen = pixels_of(&png, s.color, area, Some((lx, ly, lx + b.w, ly + b.h)));
                assert!(
                    seen >= MIN_PIXELS,
                    "case {case}: {} shows {seen} pixel(s)",
                    s.label
                );
            }
        }
        assert!(inside > 0 && below > 0, "{inside} inside, {below} below");
    }

    /// The check itself: a legend put over a line is found, with how much
    /// it covers, and an entry drawn only where the legend lies is hidden.
    #[test]
    fn a_legend_over_data_and_an_entry_under_the_legend_are_found() {
        let across: Vec<(f64, f64)> = (0..=100).map(|i| (i as f64, 10.0)).collect();
        let low: Vec<(f64, f64)> = (0..=100).map(|i| (i as f64, 0.0)).collect();
        // A short line in the upper left corner of the axes.
        let corner = [(0.0, 9.6), (3.0, 9.6)];
        let series = [
            Series {
                label: "across the top",
                points: &across,
                color: palette::TRUTH,
            },
            Series {
                label: "along the bottom",
                points: &low,
                color: palette::ALT,
            },
            Series {
                label: "in the corner",
                points: &corner,
                color: palette::BAD,
            },
        ];
        let figure = TimeFigure {
            title: "forced legend",
            x_label: "t",
            y_label: "y",
            series: &series,
            markers: &[],
            bands: &[],
            strip: None,
        };
        let spec = figure.spec().unwrap();
        let raster = rasterise(&spec, TIME_FIGURE_PX).unwrap();
        // Where `write` puts it: over nothing, every entry seen.
        let placed = place_legend(&spec, &raster).unwrap();
        assert!(!placed.legend.unwrap().below, "{placed:?}");
        assert_eq!(findings(&spec, &raster, &placed), vec![]);
        // The same legend in the upper left corner, over the top line and
        // the corner's line.
        let (w, h) = legend_size(&spec).unwrap().unwrap();
        let forced = Layout {
            legend: Some(LegendBox {
                x: 0,
                y: 0,
                w,
                h,
                below: false,
            }),
            below_px: 0,
        };
        let found = findings(&spec, &raster, &forced);
        assert!(
            matches!(&found[..], [Misleading::LegendOverData { pixels }, Misleading::Hidden { label, visible_fraction }]
                if *pixels > 10 && label == "in the corner" && *visible_fraction == 0.0),
            "{found:?}"
        );
        assert!(found[0].to_string().contains("the legend covers"));
    }

    /// Random rooms with waypoints at least 0.8 m apart, some with a
    /// heading: in the PNG each waypoint is a disc of its colour where
    /// `pixel_of` puts it, and each heading an arrow of its colour along
    /// the heading (none the other way); nothing misleads.
    #[test]
    fn waypoints_are_numbered_discs_at_their_places_with_their_headings() {
        let mut rng = ChaCha8Rng::seed_from_u64(5402);
        let dir = tempfile::tempdir().unwrap();
        for case in 0..6 {
            let (w, h) = (rng.random_range(4.0..9.0), rng.random_range(4.0..9.0));
            let walls = [
                [(0.0, 0.0), (w, 0.0)],
                [(w, 0.0), (w, h)],
                [(w, h), (0.0, h)],
                [(0.0, h), (0.0, 0.0)],
            ];
            let mut points: Vec<(f64, f64)> = Vec::new();
            while points.len() < rng.random_range(2..6) {
                let p = (
                    rng.random_range(0.5..w - 0.5),
                    rng.random_range(0.5..h - 0.5),
                );
                if points.iter().all(|q| (p.0 - q.0).hypot(p.1 - q.1) > 0.8) {
                    points.push(p);
                }
            }
            let headings: Vec<Option<f64>> = points
                .iter()
                .map(|_| rng.random_bool(0.6).then(|| rng.random_range(-3.1..3.1)))
                .collect();
            // The way through them, from a start in a corner.
            let mut way = vec![(0.3, 0.3)];
            way.extend(&points);
            let figure = WaypointFigure {
                world: WorldFigure {
                    title: "goals",
                    walls: &walls,
                    regions: &[],
                    paths: &[],
                    references: &[Series {
                        label: "the way",
                        points: &way,
                        color: palette::TRUTH,
                    }],
                    markers: &[],
                    outlines: &[],
                },
                waypoints: Waypoints {
                    label: "waypoint (in order; arrow: heading)",
                    points: &points,
                    headings_rad: &headings,
                    color: palette::BAD,
                },
            };
            assert_eq!(figure.misleading().unwrap(), vec![], "case {case}");
            let files = figure
                .write(&dir.path().join(format!("goals{case}")))
                .unwrap();
            let png = image::open(&files[1]).unwrap().to_rgb8();
            let is_color = |x: f64, y: f64| {
                png.get_pixel(x.round() as u32, y.round() as u32).0
                    == [palette::BAD.0, palette::BAD.1, palette::BAD.2]
            };
            for (k, (&p, heading)) in points.iter().zip(&headings).enumerate() {
                let (cx, cy) = figure.pixel_of(p).unwrap();
                let (cx, cy) = (f64::from(cx), f64::from(cy));
                // The disc: its rim 7 pixels out, all round but where its
                // arrow leaves it.
                let rim = (0..16)
                    .filter(|&i| {
                        let a = i as f64 * std::f64::consts::TAU / 16.0;
                        is_color(cx + 7.0 * a.cos(), cy - 7.0 * a.sin())
                    })
                    .count();
                assert!(rim >= 15, "case {case}, waypoint {}: rim {rim}/16", k + 1);
                if let Some(h) = heading {
                    let along = |d: f64| is_color(cx + d * h.cos(), cy - d * h.sin());
                    assert!(
                        (13..=26).all(|d| along(f64::from(d))),
                        "case {case}, waypoint {}: no arrow along {h}",
                        k + 1
                    );
                    assert!(
                        !(13..=26).all(|d| along(-f64::from(d))),
                        "case {case}, waypoint {}: an arrow backwards",
                        k + 1
                    );
                }
            }
        }
    }

    /// Two runs that went the same way (the same points, a random wiggly
    /// path): the later is drawn dashed over the earlier drawn wide, both
    /// show and the legend names whose path the dashed one shares; a path
    /// a hair off the first (not the same points, the same pixels) is
    /// found by its pixels, drawn so and said so.
    #[test]
    fn a_world_path_on_the_points_of_another_is_dashed_over_it() {
        let mut rng = ChaCha8Rng::seed_from_u64(5404);
        let dir = tempfile::tempdir().unwrap();
        let (mut x, mut y, mut heading) = (0.0f64, 0.0f64, 0.0f64);
        let path: Vec<(f64, f64)> = (0..3000)
            .map(|_| {
                heading += rng.random_range(-0.2..0.2);
                (x, y) = (x + 0.005 * heading.cos(), y + 0.005 * heading.sin());
                (x, y)
            })
            .collect();
        let hair: Vec<(f64, f64)> = path.iter().map(|&(x, y)| (x + 1e-6, y)).collect();
        // What the check finds, and what writing it gives.
        let figure = |second: &[(f64, f64)], name: &str| {
            let paths = [
                Series {
                    label: "hold-last",
                    points: &path,
                    color: palette::BAD,
                },
                Series {
                    label: "watchdog",
                    points: second,
                    color: palette::ALT,
                },
            ];
            let figure = WorldFigure {
                title: "two runs",
                walls: &[],
                regions: &[],
                paths: &paths,
                references: &[],
                markers: &[],
                outlines: &[],
            };
            (
                figure.misleading().unwrap(),
                figure.write(&dir.path().join(name)),
            )
        };
        let (found, written) = figure(&path, "same");
        assert_eq!(found, vec![]);
        let svg = std::fs::read_to_string(&written.unwrap()[0]).unwrap();
        assert!(svg.contains("watchdog (dashed: same path as hold-last)"));
        let (found, written) = figure(&hair, "hair");
        assert_eq!(found, vec![]);
        let svg = std::fs::read_to_string(&written.unwrap()[0]).unwrap();
        assert!(svg.contains("watchdog (dashed: within a pixel of hold-last)"));
    }

    /// Random noise over a time span, and slightly smaller noise over it
    /// drawn after it: the first's peaks stand out of the second all along
    /// the time axis, so it is seen though most of its pixels lie under the
    /// second; under two series a hair off it, each along half of it, it
    /// is hidden.
    #[test]
    fn a_noisy_series_whose_peaks_show_all_along_is_seen() {
        let mut rng = ChaCha8Rng::seed_from_u64(5405);
        let noise = |rng: &mut ChaCha8Rng, a: f64| -> Vec<(f64, f64)> {
            (0..4000)
                .map(|i| (i as f64 * 0.03, rng.random_range(-a..a)))
                .collect()
        };
        let big = noise(&mut rng, 1.0);
        let small = noise(&mut rng, 0.95);
        // A hair off x, in two halves: neither lies along most of x.
        let hair: Vec<(f64, f64)> = big.iter().map(|&(t, v)| (t, v + 1e-4)).collect();
        let (first, second) = hair.split_at(hair.len() / 2);
        let figure = |over: &[&[(f64, f64)]]| -> Vec<Misleading> {
            let mut series = vec![Series {
                label: "x",
                points: &big,
                color: palette::TRUTH,
            }];
            let labels = ["y", "y, later"];
            for (k, points) in over.iter().enumerate() {
                series.push(Series {
                    label: labels[k],
                    points,
                    color: [palette::ALT, palette::GOOD][k],
                });
            }
            let figure = TimeFigure {
                title: "innovations",
                x_label: "t",
                y_label: "m",
                series: &series,
                markers: &[],
                bands: &[],
                strip: None,
            };
            let spec = figure.spec().unwrap();
            let raster = rasterise(&spec, TIME_FIGURE_PX).unwrap();
            // Most of x lies under what follows: the share alone would call
            // it hidden.
            let x_layer = layers(&spec)
                .iter()
                .position(|l| *l == Layer::Line(0))
                .unwrap();
            let (w, h) = raster.plot_size();
            let x_mask = &raster.masks[x_layer];
            let after = &raster.masks[x_layer + 1..x_layer + 1 + over.len()];
            let drawn = x_mask.iter().filter(|&&m| m).count();
            // Not next to a pixel drawn after it, as the check counts it.
            let free = (0..w * h)
                .filter(|&i| {
                    let (px, py) = (i % w, i / w);
                    x_mask[i]
                        && !(py.saturating_sub(1)..(py + 2).min(h)).any(|yy| {
                            (px.saturating_sub(1)..(px + 2).min(w))
                                .any(|xx| after.iter().any(|m| m[yy * w + xx]))
                        })
                })
                .count();
            assert!(
                drawn > 10_000 && (free as f64) < MIN_VISIBLE_FRACTION * drawn as f64,
                "{free} of {drawn}"
            );
            figure.misleading().unwrap()
        };
        assert_eq!(figure(&[&small]), vec![]);
        let found = figure(&[first, second]);
        assert!(
            matches!(&found[..], [Misleading::Hidden { label, .. }] if label == "x"),
            "{found:?}"
        );
    }

    #[test]
    fn lines_through_one_point_all_show() {
        let one = [(0.0, 1.0)];
        let two = [(0.0, 1.0), (2.0, 1.0)];
        let zero = [(0.0, 0.0), (2.0, 0.0)];
        let series = [
            Series {
                label: "hold-last",
                points: &one,
                color: palette::BAD,
            },
            Series {
                label: "watchdog",
                points: &one,
                color: palette::ALT,
            },
            Series {
                label: "move-and-wait",
                points: &two,
                color: palette::PURPLE,
            },
            Series {
                label: "decoupled",
                points: &zero,
                color: palette::GOOD,
            },
        ];
        let figure = TimeFigure {
            title: "contacts",
            x_label: "latency",
            y_label: "contacts",
            series: &series,
            markers: &[],
            bands: &[],
            strip: None,
        };
        assert_eq!(figure.misleading().unwrap(), vec![]);
    }
}
