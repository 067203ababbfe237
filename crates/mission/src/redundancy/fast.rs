//! The fast pinch finder: one grid hash over the samples and over anchors
//! along the segments.
//!
//! For sample `i` the candidates `j` form an index window: `j >= lo(i)`,
//! where the path from `i` is long and slow enough (a two-pointer sweep, as
//! lengths and times only grow), and `j <= hi(i)`, the next protected sample.
//! Each cell holds its entries in index order, so the farthest partner in a
//! cell is the first hit scanning down from `hi(i)`, and the scan stops at
//! `lo(i)`. On a path without loops the cells around `i` hold only `i`'s own
//! neighbours along the path, below `lo(i)`: one look-up of the largest
//! index around settles it.
//!
//! Segment `(b, b+1)` is anchored at sample `b`, and if it is long, also at
//! points along it: two segments that meet then have anchors less than 0.9
//! cells apart, in neighbouring cells.

use super::geometry::{Point, distance, distance2, segments_meet};
use super::grid::{Anchor, Entry, Grid, NO_CELL};
use super::track::{Criteria, Track};
use super::{Pinch, PinchFinder, PinchKind};

/// Largest spacing of segment anchors, in cells.
const ANCHOR_SPACING_IN_CELLS: f64 = 0.45;

/// The farthest partner of one sample at a time, for samples in
/// increasing order (the sweep's and [`farthest_pinches`]'s question).
pub(super) struct FastFinder<'a> {
    track: &'a Track,
    crit: Criteria,
    anchors: Anchors<'a>,
    grid: Grid,
    anchor_cell: Vec<u32>,
    /// The first sample far enough along from the last one asked about.
    lo: usize,
}

impl<'a> FastFinder<'a> {
    pub fn new(track: &'a Track, crit: &Criteria) -> Self {
        let cell_m = cell_size_m(track, crit.pinch_distance_m);
        let anchors = Anchors::new(track, ANCHOR_SPACING_IN_CELLS * cell_m);
        let (grid, anchor_cell) = Grid::build(cell_m, anchors.len(), anchors.iter());
        Self {
            track,
            crit: *crit,
            anchors,
            grid,
            anchor_cell,
            lo: 0,
        }
    }
}

impl PinchFinder for FastFinder<'_> {
    fn farthest(&mut self, i: usize, hi: usize) -> Option<Pinch> {
        let (track, crit) = (self.track, &self.crit);
        let n = track.len();
        if i + 2 >= n {
            return None;
        }
        let pts = &track.points;
        // lo(i) never decreases with i: a two-pointer sweep.
        self.lo = self.lo.max(i + 2);
        while self.lo < n && !long_enough(track, crit, i, self.lo) {
            self.lo += 1;
        }
        let lo = self.lo;
        if lo >= n || lo > hi {
            return None;
        }
        let grid = &self.grid;
        // Segment b ends at j = b + 1, so segments from lo - 1 count.
        let cells = self.anchors.of_segment(i, &self.anchor_cell);
        if cells
            .iter()
            .all(|&c| (grid.latest_around(c) as usize) < lo - 1)
        {
            return None;
        }
        let near = farthest_near(
            grid,
            cells[0],
            pts[i],
            crit.pinch_distance2,
            lo as u32,
            hi as u32,
        );
        // A crossing only matters if it reaches beyond the nearest pinch.
        let b_lo = (lo - 1).max(i + 2).max(near.map_or(0, |j| j as usize));
        let crossing = (b_lo < hi)
            .then(|| farthest_meeting(grid, cells, pts, i, b_lo as u32, (hi - 1) as u32))
            .flatten();
        let (j, kind) = match (near, crossing) {
            (_, Some(b)) => (b as usize + 1, PinchKind::Crossing),
            (Some(j), None) => (j as usize, PinchKind::Near),
            (None, None) => return None,
        };
        Some(Pinch {
            i,
            j,
            distance_m: distance(pts[i], pts[j]),
            kind,
        })
    }
}

/// For each sample, its farthest partner up to the next protected sample.
pub(super) fn farthest_pinches(track: &Track, crit: &Criteria) -> Vec<Pinch> {
    let n = track.len();
    if n < 3 {
        return Vec::new();
    }
    let next_protected = track.next_protected();
    let mut finder = FastFinder::new(track, crit);
    (0..n - 2)
        .filter_map(|i| finder.farthest(i, next_protected[i] as usize))
        .collect()
}

#[inline]
fn long_enough(track: &Track, crit: &Criteria, i: usize, j: usize) -> bool {
    track.cum_length_m[j] - track.cum_length_m[i] >= crit.min_loop_length_m
        && track.t_s[j] - track.t_s[i] >= crit.min_loop_duration_s
}

/// At least the pinch distance (plus a relative margin that absorbs the
/// rounding of `x / cell`, so partners are never two cells apart); large
/// enough that cell coordinates stay within ±2^30; and at least the mean
/// segment length / 0.9, which bounds the anchors to 3 per sample.
fn cell_size_m(track: &Track, pinch_distance_m: f64) -> f64 {
    let max_abs = track
        .points
        .iter()
        .fold(0.0f64, |m, p| m.max(p[0].abs()).max(p[1].abs()));
    let length = track.cum_length_m.last().copied().unwrap_or(0.0);
    let mean_segment = length / (track.len().max(2) - 1) as f64;
    (pinch_distance_m * (1.0 + 1e-6))
        .max(max_abs * (-30f64).exp2())
        .max(mean_segment / (2.0 * ANCHOR_SPACING_IN_CELLS))
}

/// The anchors in order: sample `k` itself, then points along segment
/// `(k, k+1)` if it is longer than the spacing.
struct Anchors<'a> {
    pts: &'a [Point],
    cum_length_m: &'a [f64],
    spacing_m: f64,
    /// Index of sample `k`'s anchor among all anchors (`k + 1` entries);
    /// empty when no segment needs extra anchors.
    starts: Vec<u32>,
}

impl<'a> Anchors<'a> {
    fn new(track: &'a Track, spacing_m: f64) -> Self {
        let mut anchors = Self {
            pts: &track.points,
            cum_length_m: &track.cum_length_m,
            spacing_m,
            starts: Vec::new(),
        };
        let n = track.len();
        if (1..n).any(|k| anchors.extra(k - 1) > 0) {
            let mut count = 0u32;
            anchors.starts.reserve(n + 1);
            for k in 0..n {
                anchors.starts.push(count);
                count += 1 + anchors.extra(k) as u32;
            }
            anchors.starts.push(count);
        }
        anchors
    }

    /// Anchors segment `k` needs beyond sample `k` (its length from the
    /// running sum: a rounding error far inside the spacing's margin).
    #[inline]
    fn extra(&self, k: usize) -> usize {
        let length = match self.cum_length_m.get(k + 1) {
            Some(next) => next - self.cum_length_m[k],
            None => return 0,
        };
        if length > self.spacing_m {
            (length / self.spacing_m).ceil() as usize - 1
        } else {
            0
        }
    }

    fn len(&self) -> usize {
        self.starts.last().map_or(self.pts.len(), |&c| c as usize)
    }

    /// Where segment `k` is anchored: sample `k`, then points along it.
    fn positions(&self, k: usize) -> impl Iterator<Item = Point> + '_ {
        let p = self.pts[k];
        let q = self.pts.get(k + 1).copied().unwrap_or(p);
        let pieces = self.extra(k) + 1;
        (0..pieces).map(move |m| {
            let f = m as f64 / pieces as f64;
            if m == 0 {
                p
            } else {
                [p[0] + f * (q[0] - p[0]), p[1] + f * (q[1] - p[1])]
            }
        })
    }

    fn iter(&self) -> impl Iterator<Item = Anchor> + '_ {
        let samples = self.starts.is_empty().then(|| {
            self.pts.iter().enumerate().map(|(k, &pos)| Anchor {
                pos,
                tag: k as u32,
                is_sample: true,
            })
        });
        let with_extra = (!self.starts.is_empty()).then(|| {
            (0..self.pts.len()).flat_map(move |k| {
                self.positions(k).enumerate().map(move |(m, pos)| Anchor {
                    pos,
                    tag: k as u32,
                    is_sample: m == 0,
                })
            })
        });
        samples
            .into_iter()
            .flatten()
            .chain(with_extra.into_iter().flatten())
    }

    /// Cells of segment `a`'s anchors; the first is sample `a`'s cell.
    fn of_segment<'c>(&self, a: usize, anchor_cell: &'c [u32]) -> &'c [u32] {
        if self.starts.is_empty() {
            &anchor_cell[a..a + 1]
        } else {
            &anchor_cell[self.starts[a] as usize..self.starts[a + 1] as usize]
        }
    }
}

/// Entries of a cell with `first <= hi`.
#[inline]
fn up_to(entries: &[Entry], hi: u32) -> &[Entry] {
    match entries.last() {
        Some(e) if e.first > hi => &entries[..entries.partition_point(|e| e.first <= hi)],
        _ => entries,
    }
}

/// The largest sample index in `lo..=hi` closer than the pinch distance.
fn farthest_near(
    grid: &Grid,
    cell: u32,
    p: Point,
    pinch_distance2: f64,
    lo: u32,
    hi: u32,
) -> Option<u32> {
    // Fails for anchors along segments (NaN position).
    farthest_in(grid, [cell], lo, hi, |e, _| {
        distance2(e.pos, p) < pinch_distance2
    })
}

/// The largest segment index `b` in `lo..=hi` whose segment `(b, b+1)`
/// meets segment `(a, a+1)`, whose anchors lie in `cells`.
fn farthest_meeting(
    grid: &Grid,
    cells: &[u32],
    pts: &[Point],
    a: usize,
    lo: u32,
    hi: u32,
) -> Option<u32> {
    let (p1, p2) = (pts[a], pts[a + 1]);
    // Segments first..last-1 of a sample entry have zero length at e.pos,
    // and one test covers the entry: such a segment meets (p1, p2) only if
    // e.pos lies on it, and then so does (to the bit) segment `last`, which
    // leaves e.pos.
    farthest_in(grid, cells.iter().copied(), lo, hi, |_, top| {
        segments_meet(p1, p2, pts[top as usize], pts[top as usize + 1])
    })
}

/// The largest `top = min(e.last, hi)` in `lo..=hi`, over the entries in
/// the neighbourhoods of `cells`, for which `hit(e, top)` holds. Each
/// cell's entries are scanned from the latest down, and a hit raises the
/// bound for the cells after it.
#[inline]
fn farthest_in(
    grid: &Grid,
    cells: impl IntoIterator<Item = u32>,
    mut lo: u32,
    hi: u32,
    mut hit: impl FnMut(&Entry, u32) -> bool,
) -> Option<u32> {
    let mut best = None;
    for anchor_cell in cells {
        for &c in grid.neighbours(anchor_cell) {
            if c == NO_CELL {
                continue;
            }
            for e in up_to(grid.entries(c), hi).iter().rev() {
                let top = e.last.min(hi);
                if top < lo {
                    break;
                }
                if hit(e, top) {
                    best = Some(top);
                    lo = top + 1;
                    break;
                }
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::path::PathSample;
    use crate::redundancy::RedundancyConfig;
    use twindrive_kinematics::Pose;

    fn path(points: &[[f64; 2]]) -> Vec<PathSample> {
        points
            .iter()
            .enumerate()
            .map(|(k, p)| PathSample {
                t_s: k as f64,
                pose: Pose::new(p[0], p[1], 0.0),
                v_m_s: 1.0,
                omega_rad_s: 0.0,
            })
            .collect()
    }

    #[test]
    fn partners_just_under_the_pinch_distance_are_one_cell_apart() {
        // 1 - 4e-10 apart, just either side of where cells of 1 - 1e-9
        // (a cell a hair smaller than the pinch distance) would put them
        // two cells apart.
        let (a, b) = (1.0 - 1.5e-9, 2.0 - 1.9e-9);
        let mut cfg = RedundancyConfig::with_pinch_distance(1.0);
        cfg.min_loop_length_m = Some(0.0);
        // Up from A, across, down to B in short steps (so cells stay one
        // pinch distance wide); only A and B are that close.
        let mut points: Vec<[f64; 2]> = (0..=10).map(|k| [a, 0.5 * k as f64]).collect();
        points.extend((0..10).map(|k| [b, 5.0 - 0.5 * k as f64]));
        points.push([b, 0.0]);
        let track = Track::new(&path(&points), &cfg).unwrap();
        let pinches = farthest_pinches(&track, &Criteria::new(&cfg));
        assert_eq!((pinches[0].i, pinches[0].j), (0, points.len() - 1));
    }
}
