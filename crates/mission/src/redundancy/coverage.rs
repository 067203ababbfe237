//! Coverage: the places a path passed within a radius, and whether a cut
//! keeps them.
//!
//! A sample is **covered** by a set of path pieces when it lies within the
//! coverage radius of one of them (closed distance, `<=`). The pieces are
//! segments `(a, a+1)` and single points; which ones count is up to the
//! caller (the kept path up to the sweep's sample, the path after a cut,
//! a whole plan).
//!
//! [`CoverageIndex`] puts every segment of a polyline in a uniform grid:
//! cells `1.25` radii wide, each segment anchored at both ends and at points
//! at most `0.2` cells apart, so a point within the radius of a segment is
//! within `0.9` cells of one of its anchors: in the 3×3 cells around it.
//! A cell holds **runs**: consecutive segment indices that pass through it,
//! with their bounding box, so one pass through a cell is one entry and a
//! query skips a pass whose box is out of reach.
//!
//! [`FastCoverage`] answers the sweep's question (the first sample after
//! `i` that the kept path up to `i` does not cover) with that index and two
//! facts: the kept path only grows as the sweep goes on (so a sample once
//! covered stays covered), and a sample found uncovered need only be tested
//! again against what was added since. [`BruteCoverage`] answers by
//! testing every piece, for the reference removal and the tests.

use serde::{Deserialize, Serialize};

use super::RedundancyError;
use super::geometry::{Point, box_distance2, distance, segment_distance2};
use super::grid::{CellIds, NO_CELL, by_cell, cell_of};
use super::track::Track;
use crate::path::PathSample;

/// Cell size, in coverage radii.
const CELL_IN_RADII: f64 = 1.25;
/// Largest spacing of a segment's anchors, in cells.
const SPACING_IN_CELLS: f64 = 0.2;
/// Boxes are compared with the squared radius times this, so that a box
/// test never rules out a piece the exact test would accept after rounding.
const BOX_MARGIN: f64 = 1.0 + 1e-9;
/// Beyond this many new pieces, a sample found uncovered is tested again
/// through the grid rather than piece by piece.
const INCREMENTAL_LIMIT: usize = 64;

/// Segment indices `first..=last` that pass through one cell, and the box
/// around those segments.
#[derive(Debug, Clone, Copy)]
struct Run {
    first: u32,
    last: u32,
    lo: Point,
    hi: Point,
}

/// Every segment of a polyline (and its last point) in a grid hash.
pub(super) struct CoverageIndex<'a> {
    pts: &'a [Point],
    radius2: f64,
    cell_m: f64,
    ids: CellIds,
    /// Runs of cell `c` are `runs[starts[c]..starts[c + 1]]`, by first index.
    starts: Vec<u32>,
    runs: Vec<Run>,
    neighbours: Vec<[u32; 9]>,
    /// The cell of each point of the polyline.
    point_cell: Vec<u32>,
}

impl<'a> CoverageIndex<'a> {
    /// Indexes `pts` (finite) for queries at `radius_m` (> 0).
    pub fn new(pts: &'a [Point], radius_m: f64) -> Self {
        let n = pts.len();
        let max_abs = pts
            .iter()
            .fold(0.0f64, |m, p| m.max(p[0].abs()).max(p[1].abs()));
        let length: f64 = pts.windows(2).map(|w| distance(w[0], w[1])).sum();
        let mean_segment = length / (n.max(2) - 1) as f64;
        // Large enough that cell coordinates stay within ±2^30, and that a
        // segment has a handful of anchors on average.
        let cell_m = (CELL_IN_RADII * radius_m)
            .max(max_abs * (-30f64).exp2())
            .max(mean_segment);
        let spacing_m = SPACING_IN_CELLS * cell_m;

        let mut ids = CellIds::default();
        let mut coords: Vec<(i32, i32)> = Vec::new();
        // Per cell: the index in `raw` of its latest run.
        let mut open: Vec<u32> = Vec::new();
        let mut raw: Vec<(u32, Run)> = Vec::with_capacity(n);
        let mut point_cell = Vec::with_capacity(n);
        let mut last_cell: Option<((i32, i32), u32)> = None;
        for a in 0..n {
            let p = pts[a];
            let q = pts.get(a + 1).copied().unwrap_or(p);
            let lo = [p[0].min(q[0]), p[1].min(q[1])];
            let hi = [p[0].max(q[0]), p[1].max(q[1])];
            let length = distance(p, q);
            let pieces = if length > spacing_m {
                (length / spacing_m).ceil() as usize
            } else {
                1
            };
            let tag = a as u32;
            for m in 0..=pieces {
                let pos = match m {
                    0 => p,
                    m if m == pieces => q,
                    m => {
                        let f = m as f64 / pieces as f64;
                        [p[0] + f * (q[0] - p[0]), p[1] + f * (q[1] - p[1])]
                    }
                };
                let cell = cell_of(pos, cell_m);
                let id = match last_cell {
                    Some((c, id)) if c == cell => id,
                    _ => {
                        let id = ids.id_or_insert(cell, || {
                            coords.push(cell);
                            open.push(u32::MAX);
                            (coords.len() - 1) as u32
                        });
                        last_cell = Some((cell, id));
                        id
                    }
                };
                if m == 0 {
                    point_cell.push(id);
                }
                let o = open[id as usize];
                if o != u32::MAX && raw[o as usize].1.last + 1 >= tag {
                    let run = &mut raw[o as usize].1;
                    if run.last != tag {
                        run.last = tag;
                        run.lo = [run.lo[0].min(lo[0]), run.lo[1].min(lo[1])];
                        run.hi = [run.hi[0].max(hi[0]), run.hi[1].max(hi[1])];
                    }
                } else {
                    open[id as usize] = raw.len() as u32;
                    raw.push((
                        id,
                        Run {
                            first: tag,
                            last: tag,
                            lo,
                            hi,
                        },
                    ));
                }
            }
        }

        // Runs were made in order of their first index.
        let (starts, runs) = by_cell(coords.len(), raw);
        let neighbours = ids.neighbours(&coords);
        Self {
            pts,
            radius2: radius_m * radius_m,
            cell_m,
            ids,
            starts,
            runs,
            neighbours,
            point_cell,
        }
    }

    /// The 3×3 cells around point `k` of the polyline.
    #[inline]
    fn cells_at_point(&self, k: usize) -> [u32; 9] {
        self.neighbours[self.point_cell[k] as usize]
    }

    /// The 3×3 cells around any point.
    fn cells_around(&self, s: Point) -> [u32; 9] {
        let (cx, cy) = cell_of(s, self.cell_m);
        let mut around = [NO_CELL; 9];
        for (k, id) in around.iter_mut().enumerate() {
            let (dx, dy) = (k as i32 % 3 - 1, k as i32 / 3 - 1);
            *id = self.ids.id((cx.saturating_add(dx), cy.saturating_add(dy)));
        }
        around
    }

    /// Whether a piece `piece(a)`, for an index `a` in one of the inclusive
    /// `ranges` (increasing), lies within the radius of `s`.
    fn any_within(
        &self,
        s: Point,
        cells: &[u32; 9],
        ranges: &[(u32, u32)],
        piece: impl Fn(usize) -> Option<(Point, Point)>,
    ) -> bool {
        let Some(&(_, top)) = ranges.last() else {
            return false;
        };
        for &c in cells {
            if c == NO_CELL {
                continue;
            }
            let c = c as usize;
            for run in &self.runs[self.starts[c] as usize..self.starts[c + 1] as usize] {
                if run.first > top {
                    break;
                }
                if box_distance2(s, run.lo, run.hi) > self.radius2 * BOX_MARGIN {
                    continue;
                }
                for &(from, to) in ranges {
                    for a in run.first.max(from)..=run.last.min(to) {
                        if let Some((p, q)) = piece(a as usize)
                            && segment_distance2(s, p, q) <= self.radius2
                        {
                            return true;
                        }
                    }
                }
            }
        }
        false
    }
}

/// The piece of index `a` of the kept path up to sample `i`: the segment
/// `(a, a+1)` when both ends are kept and `a < i`, else the point `a` if kept.
#[inline]
fn kept_piece(pts: &[Point], kept: &[bool], i: usize, a: usize) -> Option<(Point, Point)> {
    if !kept[a] {
        None
    } else if a < i && kept[a + 1] {
        Some((pts[a], pts[a + 1]))
    } else {
        Some((pts[a], pts[a]))
    }
}

/// The piece of index `a` of the whole polyline up to point `upto`.
#[inline]
fn prefix_piece(pts: &[Point], upto: usize, a: usize) -> (Point, Point) {
    if a < upto {
        (pts[a], pts[a + 1])
    } else {
        (pts[a], pts[a])
    }
}

/// What the removal sweep asks about coverage. `kept` marks the samples
/// still in the path; the sweep only ever clears entries after `i`.
pub(super) trait Coverage {
    /// The first sample in `(i, end)` that the kept path up to `i` does not
    /// cover. Calls come with `i` never decreasing.
    fn first_uncovered(&mut self, i: usize, end: usize, kept: &[bool]) -> Option<usize>;

    /// Whether sample `s` is within the radius of the kept path up to `i`
    /// or of the whole path from `j` on.
    fn covered_around_cut(&self, s: usize, i: usize, j: usize, kept: &[bool]) -> bool;

    /// Whether sample `s` is within the radius of the whole path up to
    /// sample `upto`.
    fn covered_by_prefix(&self, s: usize, upto: usize) -> bool;
}

/// The grid-hash answers, with the sweep's state.
pub(super) struct FastCoverage<'a> {
    index: CoverageIndex<'a>,
    /// Samples `(i, verified]` are covered by the kept path up to `i`.
    verified: usize,
    /// When `verified + 1` was found uncovered: the `i` it was tested at.
    pending: Option<usize>,
}

impl<'a> FastCoverage<'a> {
    pub fn new(track: &'a Track, radius_m: f64) -> Self {
        Self {
            index: CoverageIndex::new(&track.points, radius_m),
            verified: 0,
            pending: None,
        }
    }

    /// Sample `s` against the kept path up to `i`.
    fn covered(&self, s: usize, i: usize, kept: &[bool]) -> bool {
        let pts = self.index.pts;
        let p = pts[s];
        let r2 = self.index.radius2;
        // The last piece or two are the usual witnesses of a sample just ahead.
        let near = |a: usize| {
            kept_piece(pts, kept, i, a).is_some_and(|(a, b)| segment_distance2(p, a, b) <= r2)
        };
        if near(i) || (i > 0 && near(i - 1)) {
            return true;
        }
        self.index
            .any_within(p, &self.index.cells_at_point(s), &[(0, i as u32)], |a| {
                kept_piece(pts, kept, i, a)
            })
    }

    /// Sample `s` against the pieces of the kept path up to `i` that start
    /// at `from` or later.
    fn covered_since(&self, s: usize, from: usize, i: usize, kept: &[bool]) -> bool {
        let pts = self.index.pts;
        let p = pts[s];
        if i - from > INCREMENTAL_LIMIT {
            return self.index.any_within(
                p,
                &self.index.cells_at_point(s),
                &[(from as u32, i as u32)],
                |a| kept_piece(pts, kept, i, a),
            );
        }
        (from..=i).any(|a| {
            kept_piece(pts, kept, i, a)
                .is_some_and(|(a, b)| segment_distance2(p, a, b) <= self.index.radius2)
        })
    }
}

impl Coverage for FastCoverage<'_> {
    fn first_uncovered(&mut self, i: usize, end: usize, kept: &[bool]) -> Option<usize> {
        if self.verified < i {
            self.verified = i;
            self.pending = None;
        }
        if let Some(tested_at) = self.pending {
            // Covered now only by a piece added since: the segment from
            // `tested_at` (a point then) and everything after.
            let s = self.verified + 1;
            if self.covered_since(s, tested_at, i, kept) {
                self.verified = s;
                self.pending = None;
            } else {
                self.pending = Some(i);
            }
        }
        loop {
            let s = self.verified + 1;
            if s >= end {
                return None;
            }
            if self.pending.is_some() {
                return Some(s);
            }
            if self.covered(s, i, kept) {
                self.verified = s;
            } else {
                self.pending = Some(i);
                return Some(s);
            }
        }
    }

    fn covered_around_cut(&self, s: usize, i: usize, j: usize, kept: &[bool]) -> bool {
        let pts = self.index.pts;
        let n = pts.len();
        let ranges = [(0, i as u32), (j as u32, (n - 1) as u32)];
        self.index
            .any_within(pts[s], &self.index.cells_at_point(s), &ranges, |a| {
                if a <= i {
                    kept_piece(pts, kept, i, a)
                } else {
                    Some(prefix_piece(pts, n - 1, a))
                }
            })
    }

    fn covered_by_prefix(&self, s: usize, upto: usize) -> bool {
        let pts = self.index.pts;
        self.index.any_within(
            pts[s],
            &self.index.cells_at_point(s),
            &[(0, upto as u32)],
            |a| Some(prefix_piece(pts, upto, a)),
        )
    }
}

/// Every piece tested, every time: the reference.
pub(super) struct BruteCoverage<'a> {
    pts: &'a [Point],
    radius2: f64,
}

impl<'a> BruteCoverage<'a> {
    pub fn new(track: &'a Track, radius_m: f64) -> Self {
        Self {
            pts: &track.points,
            radius2: radius_m * radius_m,
        }
    }

    fn within(&self, s: usize, piece: Option<(Point, Point)>) -> bool {
        piece.is_some_and(|(a, b)| segment_distance2(self.pts[s], a, b) <= self.radius2)
    }
}

impl Coverage for BruteCoverage<'_> {
    fn first_uncovered(&mut self, i: usize, end: usize, kept: &[bool]) -> Option<usize> {
        (i + 1..end).find(|&s| !(0..=i).any(|a| self.within(s, kept_piece(self.pts, kept, i, a))))
    }

    fn covered_around_cut(&self, s: usize, i: usize, j: usize, kept: &[bool]) -> bool {
        let n = self.pts.len();
        (0..=i).any(|a| self.within(s, kept_piece(self.pts, kept, i, a)))
            || (j..n).any(|a| self.within(s, Some(prefix_piece(self.pts, n - 1, a))))
    }

    fn covered_by_prefix(&self, s: usize, upto: usize) -> bool {
        (0..=upto).any(|a| self.within(s, Some(prefix_piece(self.pts, upto, a))))
    }
}

/// Metres of path between samples `i` and `j` whose samples are flagged
/// by `uncovered` (`i` and `j` themselves never are; each segment counts
/// half for each flagged end).
pub(super) fn half_weighted_between(
    track: &Track,
    i: usize,
    j: usize,
    uncovered: impl Fn(usize) -> bool,
) -> f64 {
    let flags: Vec<bool> = (i..=j).map(|s| s != i && s != j && uncovered(s)).collect();
    half_weighted_m(&track.cum_length_m[i..=j], &flags)
}

/// Path length, in coverage radii, that a sample's own approach may take
/// before the path behind it counts as another visit.
const APPROACH_IN_RADII: f64 = 2.0;

/// The last sample that is new ground: farther than the radius from the
/// path that ends two radii (along the path) before it, so that its own
/// approach does not count. 0 for an empty path. One grid query per sample
/// from the end back to it.
///
/// This only bounds where a trailing retrace may start: a sample taken for
/// old ground here is still cut only where the kept path covers it.
pub(super) fn last_new_sample(coverage: &impl Coverage, track: &Track, radius_m: f64) -> usize {
    let cum = &track.cum_length_m;
    let n = track.len();
    let mut upto = n;
    for s in (0..n).rev() {
        let reach = cum[s] - APPROACH_IN_RADII * radius_m;
        if reach < 0.0 {
            return s;
        }
        upto = upto.min(s);
        while upto > 0 && cum[upto] > reach {
            upto -= 1;
        }
        if !coverage.covered_by_prefix(s, upto) {
            return s;
        }
    }
    0
}

/// Length of the segments along `cum` (cumulative lengths), each counted
/// half for each end flagged.
fn half_weighted_m(cum: &[f64], flagged: &[bool]) -> f64 {
    let mut total = 0.0;
    for a in 1..cum.len() {
        let ends = u8::from(flagged[a - 1]) + u8::from(flagged[a]);
        if ends > 0 {
            total += 0.5 * f64::from(ends) * (cum[a] - cum[a - 1]);
        }
    }
    total
}

/// How much of a route a plan passes within a radius of.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RouteCoverage {
    pub radius_m: f64,
    /// Length of the route (the executed path).
    pub route_length_m: f64,
    /// Length of the plan's own path.
    pub plan_length_m: f64,
    /// Route length within the radius of the plan (each segment counts half
    /// for each end within).
    pub covered_length_m: f64,
    /// `covered_length_m` as a percentage of the route (100 for an empty route).
    pub covered_percent: f64,
    /// Route length farther than the radius from the plan.
    pub uncovered_m: f64,
    /// Maximal stretches of the route farther than the radius from the plan.
    pub uncovered_stretches: Vec<UncoveredStretch>,
}

/// A stretch of the route farther than the radius from the plan, between
/// route samples `first` and `last` (it may start or end between samples,
/// on a segment longer than half the radius).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct UncoveredStretch {
    pub first: usize,
    pub last: usize,
    pub t_start_s: f64,
    pub t_end_s: f64,
    /// Route length this stretch leaves uncovered.
    pub length_m: f64,
}

/// The coverage of `route` by the polyline through `plan`'s samples, at
/// `radius_m`: which parts of the route lie within the radius of the plan
/// (tested at the route's samples and at most half a radius apart along
/// its segments), and how many metres of route that leaves uncovered.
pub fn route_coverage(
    route: &[PathSample],
    plan: &[PathSample],
    radius_m: f64,
) -> Result<RouteCoverage, RedundancyError> {
    if !(radius_m > 0.0 && radius_m.is_finite()) {
        return Err(RedundancyError::Config {
            field: "coverage_radius_m".into(),
            requirement: "must be > 0 and finite",
            got: radius_m.to_string(),
        });
    }
    let points = |samples: &[PathSample]| -> Result<Vec<Point>, RedundancyError> {
        samples
            .iter()
            .enumerate()
            .map(|(index, s)| {
                for (field, value) in [("pose.x_m", s.pose.x_m), ("pose.y_m", s.pose.y_m)] {
                    if !value.is_finite() {
                        return Err(RedundancyError::NotFinite {
                            index,
                            field,
                            value,
                        });
                    }
                }
                Ok(s.position())
            })
            .collect()
    };
    let route_pts = points(route)?;
    let plan_pts = points(plan)?;
    let plan_length_m = super::track::cumulative_length_m(&plan_pts)
        .last()
        .copied()
        .unwrap_or(0.0);
    // Check points: the route's samples, and points along any segment
    // longer than half the radius, so that coverage is measured along the
    // route and not only where it was sampled.
    let spacing_m = 0.5 * radius_m;
    let mut checks: Vec<(Point, usize, f64)> = Vec::with_capacity(route_pts.len());
    let mut along = 0.0;
    for (k, &p) in route_pts.iter().enumerate() {
        if k > 0 {
            let q = route_pts[k - 1];
            let length = distance(q, p);
            let pieces = (length / spacing_m).ceil();
            if pieces > 1.0 && pieces.is_finite() {
                let pieces = pieces as usize;
                for m in 1..pieces {
                    let f = m as f64 / pieces as f64;
                    checks.push((
                        [q[0] + f * (p[0] - q[0]), q[1] + f * (p[1] - q[1])],
                        k - 1,
                        along + f * length,
                    ));
                }
            }
            along += length;
        }
        checks.push((p, k, along));
    }
    let uncovered: Vec<bool> = if plan_pts.is_empty() {
        vec![true; checks.len()]
    } else {
        let index = CoverageIndex::new(&plan_pts, radius_m);
        let last = plan_pts.len() - 1;
        checks
            .iter()
            .map(|&(p, _, _)| {
                !index.any_within(p, &index.cells_around(p), &[(0, last as u32)], |a| {
                    Some(prefix_piece(&plan_pts, last, a))
                })
            })
            .collect()
    };
    let cum: Vec<f64> = checks.iter().map(|c| c.2).collect();
    let route_length_m = along;
    let uncovered_m = half_weighted_m(&cum, &uncovered);
    let mut stretches = Vec::new();
    let mut k = 0;
    while k < uncovered.len() {
        if !uncovered[k] {
            k += 1;
            continue;
        }
        let first = k;
        while k + 1 < uncovered.len() && uncovered[k + 1] {
            k += 1;
        }
        // The half segments on either side count too.
        let from = first.saturating_sub(1);
        let to = (k + 1).min(uncovered.len() - 1);
        // In route samples: from the one at or before the first point to the
        // one at or after the last.
        let (a, b) = (checks[first].1, checks[k].1);
        let b = if checks[k].0 == route_pts[b] {
            b
        } else {
            b + 1
        };
        stretches.push(UncoveredStretch {
            first: a,
            last: b,
            t_start_s: route[a].t_s,
            t_end_s: route[b].t_s,
            length_m: half_weighted_m(&cum[from..=to], &uncovered[from..=to]),
        });
        k += 1;
    }
    let covered_length_m = (route_length_m - uncovered_m).max(0.0);
    // From the uncovered share, so that full coverage is exactly 100.
    let covered_percent = if route_length_m > 0.0 {
        (100.0 - 100.0 * uncovered_m / route_length_m).clamp(0.0, 100.0)
    } else {
        100.0
    };
    Ok(RouteCoverage {
        radius_m,
        route_length_m,
        plan_length_m,
        covered_length_m,
        covered_percent,
        uncovered_m,
        uncovered_stretches: stretches,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(from: Point, to: Point, n: usize) -> Vec<Point> {
        (0..n)
            .map(|k| {
                let f = k as f64 / (n - 1) as f64;
                [
                    from[0] + f * (to[0] - from[0]),
                    from[1] + f * (to[1] - from[1]),
                ]
            })
            .collect()
    }

    #[test]
    fn the_index_finds_every_segment_within_the_radius() {
        // Long sparse segments and dense ones; queries on a lattice, each
        // checked against every piece.
        let mut pts = line([0.0, 0.0], [3.0, 0.0], 4);
        pts.extend(line([3.0, 0.1], [0.2, 2.9], 300));
        pts.push([-1.0, 1.0]);
        for radius in [0.05, 0.3, 1.0] {
            let index = CoverageIndex::new(&pts, radius);
            let last = pts.len() - 1;
            for gx in -20..=70 {
                for gy in -20..=70 {
                    let s = [gx as f64 * 0.0513, gy as f64 * 0.0497];
                    let fast =
                        index.any_within(s, &index.cells_around(s), &[(0, last as u32)], |a| {
                            Some(prefix_piece(&pts, last, a))
                        });
                    let brute = (0..=last).any(|a| {
                        let (p, q) = prefix_piece(&pts, last, a);
                        segment_distance2(s, p, q) <= radius * radius
                    });
                    assert_eq!(fast, brute, "radius {radius}, point {s:?}");
                }
            }
        }
    }
}
