//! An occupancy grid in log-odds that grows as the robot sees more: each
//! beam lowers the odds of the cells it crosses and raises those of the
//! cell it ends in (the standard inverse sensor model, Thrun, Burgard and
//! Fox, *Probabilistic Robotics*, ch. 9). A cell no beam reached stays
//! unknown, whatever its neighbours.

/// The inverse sensor model's increments and the clamp that keeps a cell
/// able to change its mind (log-odds, natural logarithm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogOdds {
    /// Added to the cell a beam ends in (0.85: p = 0.7).
    pub hit: f32,
    /// Added to each cell a beam crosses (-0.4: p = 0.4).
    pub miss: f32,
    pub min: f32,
    pub max: f32,
}

impl Default for LogOdds {
    fn default() -> Self {
        Self {
            hit: 0.85,
            miss: -0.4,
            min: -2.0,
            max: 3.5,
        }
    }
}

/// One beam of a scan: where it ended (map frame; not finite for a
/// return not to be drawn), and how far along it the cells it crossed are
/// known to be free.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Beam {
    pub end: [f64; 2],
    pub free_to: [f64; 2],
}

/// What a cell is, by ROS map_server's thresholds on its probability.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellState {
    Free,
    Occupied,
    Unknown,
}

/// map_server's default thresholds (`occupied_thresh`, `free_thresh`).
pub const OCCUPIED_ABOVE: f64 = 0.65;
pub const FREE_BELOW: f64 = 0.196;

/// Cells this many wide are added around what a scan needs when the grid
/// grows, so a drive does not reallocate at every step.
const GROWTH_MARGIN_CELLS: i64 = 64;

/// A log-odds occupancy grid in the map's frame (row 0 at the lowest y).
/// Cell `(i, j)` of the plane covers `[i r, (i + 1) r) x [j r, (j + 1) r)`,
/// so grids of the same resolution line up whatever their extent.
#[derive(Debug, Clone, PartialEq)]
pub struct LogOddsGrid {
    resolution_m: f64,
    model: LogOdds,
    /// The plane's cell index of this grid's column 0 and row 0.
    first: [i64; 2],
    width: usize,
    height: usize,
    /// Log-odds, row-major from the bottom row; NaN where no beam reached.
    cells: Vec<f32>,
    /// The scan that last updated each cell: a cell changes once a scan,
    /// a hit before any miss (so a beam grazing a wall does not clear the
    /// cell another beam of the same scan ended in).
    stamp: Vec<u32>,
    scan: u32,
}

impl LogOddsGrid {
    /// An empty grid (everything unknown).
    pub fn new(resolution_m: f64, model: LogOdds) -> Self {
        Self {
            resolution_m,
            model,
            first: [0, 0],
            width: 0,
            height: 0,
            cells: Vec::new(),
            stamp: Vec::new(),
            scan: 0,
        }
    }

    /// A grid of known cells: `probabilities` row-major from the bottom
    /// row, `None` for unknown; the lower-left corner at `origin_m` (which
    /// is moved to the nearest cell corner of the plane's lattice).
    pub fn from_probabilities(
        resolution_m: f64,
        model: LogOdds,
        origin_m: [f64; 2],
        width: usize,
        height: usize,
        probabilities: impl IntoIterator<Item = Option<f64>>,
    ) -> Self {
        let first = origin_m.map(|v| (v / resolution_m).round() as i64);
        let cells: Vec<f32> = probabilities
            .into_iter()
            .take(width * height)
            .map(|p| match p {
                None => f32::NAN,
                Some(p) => {
                    let p = p.clamp(1e-6, 1.0 - 1e-6);
                    ((p / (1.0 - p)).ln() as f32).clamp(model.min, model.max)
                }
            })
            .collect();
        let stamp = vec![0; cells.len()];
        Self {
            resolution_m,
            model,
            first,
            width,
            height,
            cells,
            stamp,
            scan: 0,
        }
    }

    pub fn resolution_m(&self) -> f64 {
        self.resolution_m
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// The map-frame position of the lower-left corner of column 0, row 0.
    pub fn origin_m(&self) -> [f64; 2] {
        self.first.map(|i| i as f64 * self.resolution_m)
    }

    /// The plane's cell index of a point.
    #[inline]
    fn index_of(&self, p: [f64; 2]) -> [i64; 2] {
        p.map(|v| (v / self.resolution_m).floor() as i64)
    }

    /// The cell's log-odds; `None` where no beam reached or off the grid.
    pub fn log_odds(&self, col: usize, row: usize) -> Option<f32> {
        let l = *self.cells.get(row * self.width + col)?;
        (!l.is_nan()).then_some(l)
    }

    /// The cell's probability of being occupied; `None` for unknown.
    pub fn probability(&self, col: usize, row: usize) -> Option<f64> {
        self.log_odds(col, row)
            .map(|l| 1.0 - 1.0 / (1.0 + f64::from(l).exp()))
    }

    /// The cell's state by map_server's thresholds.
    pub fn state(&self, col: usize, row: usize) -> CellState {
        match self.probability(col, row) {
            None => CellState::Unknown,
            Some(p) if p > OCCUPIED_ABOVE => CellState::Occupied,
            Some(p) if p < FREE_BELOW => CellState::Free,
            Some(_) => CellState::Unknown,
        }
    }

    /// The state of the cell holding the map-frame point `p`.
    pub fn state_at(&self, p: [f64; 2]) -> CellState {
        let [i, j] = self.index_of(p);
        let (c, r) = (i - self.first[0], j - self.first[1]);
        if c < 0 || r < 0 || c >= self.width as i64 || r >= self.height as i64 {
            return CellState::Unknown;
        }
        self.state(c as usize, r as usize)
    }

    /// The centre of a cell in the map's frame.
    pub fn centre(&self, col: usize, row: usize) -> [f64; 2] {
        [
            (self.first[0] + col as i64) as f64 * self.resolution_m + 0.5 * self.resolution_m,
            (self.first[1] + row as i64) as f64 * self.resolution_m + 0.5 * self.resolution_m,
        ]
    }

    /// Centres of the occupied cells, row by row from the bottom.
    pub fn occupied_centres(&self) -> Vec<[f64; 2]> {
        let mut out = Vec::new();
        for row in 0..self.height {
            for col in 0..self.width {
                if self.state(col, row) == CellState::Occupied {
                    out.push(self.centre(col, row));
                }
            }
        }
        out
    }

    /// Counts of (free, occupied, unknown) cells.
    pub fn counts(&self) -> [usize; 3] {
        let mut n = [0; 3];
        for row in 0..self.height {
            for col in 0..self.width {
                n[match self.state(col, row) {
                    CellState::Free => 0,
                    CellState::Occupied => 1,
                    CellState::Unknown => 2,
                }] += 1;
            }
        }
        n
    }

    /// The smallest grid holding every known cell: a map of a site is
    /// written without the growth margin around it.
    pub fn cropped(&self, margin_cells: usize) -> Self {
        let (mut lo, mut hi) = ([usize::MAX; 2], [0usize; 2]);
        for row in 0..self.height {
            for col in 0..self.width {
                if !self.cells[row * self.width + col].is_nan() {
                    lo = [lo[0].min(col), lo[1].min(row)];
                    hi = [hi[0].max(col), hi[1].max(row)];
                }
            }
        }
        if lo[0] == usize::MAX {
            return Self::new(self.resolution_m, self.model);
        }
        let lo = [0, 1].map(|k| lo[k].saturating_sub(margin_cells));
        let hi = [
            (hi[0] + margin_cells).min(self.width - 1),
            (hi[1] + margin_cells).min(self.height - 1),
        ];
        let (width, height) = (hi[0] - lo[0] + 1, hi[1] - lo[1] + 1);
        let mut cells = Vec::with_capacity(width * height);
        for row in lo[1]..=hi[1] {
            cells.extend_from_slice(
                &self.cells[row * self.width + lo[0]..row * self.width + hi[0] + 1],
            );
        }
        Self {
            resolution_m: self.resolution_m,
            model: self.model,
            first: [self.first[0] + lo[0] as i64, self.first[1] + lo[1] as i64],
            width,
            height,
            stamp: vec![0; cells.len()],
            cells,
            scan: 0,
        }
    }

    /// Grows the grid (unknown cells) to hold the rectangle `lo_m..=hi_m`
    /// (m) at once: a drive whose extent is known before it is drawn
    /// (every pose located, a known range) spares the grid growing a few
    /// metres at a time, each growth a copy of every cell.
    pub fn reserve_m(&mut self, lo_m: [f64; 2], hi_m: [f64; 2]) {
        if lo_m.iter().chain(&hi_m).all(|v| v.is_finite()) {
            let (lo, hi) = (self.index_of(lo_m), self.index_of(hi_m));
            self.reserve(lo, hi);
        }
    }

    /// Grows the grid (unknown cells) to hold the plane's cells `lo..=hi`.
    fn reserve(&mut self, lo: [i64; 2], hi: [i64; 2]) {
        let last = [
            self.first[0] + self.width as i64 - 1,
            self.first[1] + self.height as i64 - 1,
        ];
        let empty = self.cells.is_empty();
        if !empty
            && lo[0] >= self.first[0]
            && lo[1] >= self.first[1]
            && hi[0] <= last[0]
            && hi[1] <= last[1]
        {
            return;
        }
        let (new_lo, new_hi) = if empty {
            (
                lo.map(|v| v - GROWTH_MARGIN_CELLS),
                hi.map(|v| v + GROWTH_MARGIN_CELLS),
            )
        } else {
            (
                [0, 1].map(|k| {
                    if lo[k] < self.first[k] {
                        lo[k] - GROWTH_MARGIN_CELLS
                    } else {
                        self.first[k]
                    }
                }),
                [0, 1].map(|k| {
                    if hi[k] > last[k] {
                        hi[k] + GROWTH_MARGIN_CELLS
                    } else {
                        last[k]
                    }
                }),
            )
        };
        let width = (new_hi[0] - new_lo[0] + 1) as usize;
        let height = (new_hi[1] - new_lo[1] + 1) as usize;
        let mut cells = vec![f32::NAN; width * height];
        let (dc, dr) = (
            (self.first[0] - new_lo[0]) as usize,
            (self.first[1] - new_lo[1]) as usize,
        );
        for row in 0..self.height {
            let to = (row + dr) * width + dc;
            cells[to..to + self.width]
                .copy_from_slice(&self.cells[row * self.width..(row + 1) * self.width]);
        }
        let mut stamp = vec![0; width * height];
        for row in 0..self.height {
            let to = (row + dr) * width + dc;
            stamp[to..to + self.width]
                .copy_from_slice(&self.stamp[row * self.width..(row + 1) * self.width]);
        }
        self.first = new_lo;
        self.width = width;
        self.height = height;
        self.cells = cells;
        self.stamp = stamp;
    }

    /// Adds `delta` to the cell unless this scan already changed it.
    #[inline]
    fn add(&mut self, col: i64, row: i64, delta: f32) {
        let k = row as usize * self.width + col as usize;
        if self.stamp[k] == self.scan {
            return;
        }
        self.stamp[k] = self.scan;
        let l = self.cells[k];
        let l = if l.is_nan() { 0.0 } else { l };
        self.cells[k] = (l + delta).clamp(self.model.min, self.model.max);
    }

    /// One scan from the sensor at `from` (map frame): every beam in
    /// `endpoints` (map frame) clears the cells it crosses and marks the
    /// cell it ends in. Beams with no return are not passed in: what they
    /// crossed is not known to be free.
    pub fn integrate(&mut self, from: [f64; 2], endpoints: &[[f64; 2]]) {
        let beams: Vec<Beam> = endpoints
            .iter()
            .map(|e| Beam {
                end: *e,
                free_to: *e,
            })
            .collect();
        self.integrate_beams(from, &beams);
    }

    /// As [`integrate`](Self::integrate), each beam clearing the cells only
    /// up to its `free_to` point (on the way to its end): a beam that meets
    /// a wall at a grazing angle runs within a cell of it for a long way,
    /// and must not clear the cells the wall lies in.
    pub fn integrate_beams(&mut self, from: [f64; 2], beams: &[Beam]) {
        if beams.is_empty() || !(from[0].is_finite() && from[1].is_finite()) {
            return;
        }
        let finite = |p: &[f64; 2]| p[0].is_finite() && p[1].is_finite();
        let start = self.index_of(from);
        let (mut lo, mut hi) = (start, start);
        for p in beams.iter().flat_map(|b| [b.end, b.free_to]).filter(finite) {
            let c = self.index_of(p);
            lo = [lo[0].min(c[0]), lo[1].min(c[1])];
            hi = [hi[0].max(c[0]), hi[1].max(c[1])];
        }
        self.reserve(lo, hi);
        self.scan = self.scan.wrapping_add(1).max(1);
        let (miss, hit) = (self.model.miss, self.model.hit);
        for b in beams.iter().filter(|b| finite(&b.end)) {
            let end = self.index_of(b.end);
            self.add(end[0] - self.first[0], end[1] - self.first[1], hit);
        }
        for b in beams.iter().filter(|b| finite(&b.free_to)) {
            let to = self.index_of(b.free_to);
            self.trace(from, b.free_to, start, to, |grid, i, j| {
                grid.add(i - grid.first[0], j - grid.first[1], miss)
            });
        }
    }

    /// Visits the plane's cells a segment crosses from `a` (in cell
    /// `start`) up to, not including, the cell `end` it ends in
    /// (Amanatides and Woo's traversal).
    fn trace(
        &mut self,
        a: [f64; 2],
        b: [f64; 2],
        start: [i64; 2],
        end: [i64; 2],
        mut visit: impl FnMut(&mut Self, i64, i64),
    ) {
        let r = self.resolution_m;
        let d = [b[0] - a[0], b[1] - a[1]];
        let step = d.map(|v| if v > 0.0 { 1i64 } else { -1 });
        // Parameter t in [0, 1] along the segment at the next cell border
        // in each axis, and its increment per cell.
        let mut t_max = [0f64; 2];
        let mut t_delta = [0f64; 2];
        for k in 0..2 {
            if d[k] == 0.0 {
                t_max[k] = f64::INFINITY;
                t_delta[k] = f64::INFINITY;
            } else {
                let border = if step[k] > 0 {
                    (start[k] + 1) as f64 * r
                } else {
                    start[k] as f64 * r
                };
                t_max[k] = (border - a[k]) / d[k];
                t_delta[k] = r / d[k].abs();
            }
        }
        let mut cell = start;
        // A beam crosses at most |di| + |dj| borders.
        let mut left = (end[0] - start[0]).abs() + (end[1] - start[1]).abs();
        while cell != end && left > 0 {
            visit(self, cell[0], cell[1]);
            if t_max[0] < t_max[1] {
                cell[0] += step[0];
                t_max[0] += t_delta[0];
            } else {
                cell[1] += step[1];
                t_max[1] += t_delta[1];
            }
            left -= 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_beam_clears_what_it_crosses_and_marks_where_it_ends() {
        let mut g = LogOddsGrid::new(0.1, LogOdds::default());
        for _ in 0..5 {
            g.integrate([0.05, 0.05], &[[1.05, 0.05], [0.05, -0.75]]);
        }
        assert_eq!(g.state_at([1.05, 0.05]), CellState::Occupied);
        assert_eq!(g.state_at([0.05, -0.75]), CellState::Occupied);
        for k in 0..10 {
            assert_eq!(
                g.state_at([0.05 + 0.1 * k as f64, 0.05]),
                CellState::Free,
                "cell {k}"
            );
        }
        assert_eq!(
            g.state_at([1.15, 0.05]),
            CellState::Unknown,
            "behind the wall"
        );
        assert_eq!(g.state_at([0.55, 0.55]), CellState::Unknown, "no beam");
        assert_eq!(g.counts()[1], 2);
    }

    #[test]
    fn a_diagonal_beam_crosses_the_cells_a_brute_force_walk_finds() {
        // Sample the segment densely: every cell it passes through (but the
        // last) must be cleared, and no cell off it.
        let mut g = LogOddsGrid::new(0.05, LogOdds::default());
        let (a, b) = ([0.013, 0.021], [2.377, 1.111]);
        g.integrate(a, &[b]);
        let mut on = std::collections::BTreeSet::new();
        for k in 0..=100_000 {
            let t = k as f64 / 100_000.0;
            let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
            on.insert(g.index_of(p));
        }
        let end = g.index_of(b);
        for row in 0..g.height() {
            for col in 0..g.width() {
                let idx = [g.first[0] + col as i64, g.first[1] + row as i64];
                let l = g.log_odds(col, row);
                if idx == end {
                    assert_eq!(l, Some(0.85));
                } else if on.contains(&idx) {
                    assert_eq!(l, Some(-0.4), "{idx:?}");
                } else {
                    assert_eq!(l, None, "{idx:?} is off the beam");
                }
            }
        }
    }

    #[test]
    fn growing_keeps_what_was_known_and_cropping_drops_only_unknown() {
        let mut g = LogOddsGrid::new(0.05, LogOdds::default());
        g.integrate([0.0, 0.0], &[[1.0, 0.0]]);
        let before = g.state_at([1.0, 0.0]);
        g.integrate([0.0, 0.0], &[[-9.0, 7.0]]);
        assert_eq!(g.state_at([1.0, 0.0]), before);
        let c = g.cropped(2);
        assert!(c.width() < g.width() && c.height() < g.height());
        for p in [[1.0, 0.0], [-9.0, 7.0], [0.5, 0.0], [-4.5, 3.5]] {
            assert_eq!(c.state_at(p), g.state_at(p), "{p:?}");
        }
        assert_eq!(c.counts()[..2], g.counts()[..2]);
    }

    #[test]
    fn probabilities_round_trip_through_from_probabilities() {
        let mut g = LogOddsGrid::new(0.05, LogOdds::default());
        for _ in 0..3 {
            g.integrate([0.0, 0.0], &[[1.0, 0.3], [0.2, -0.9]]);
        }
        let probs: Vec<Option<f64>> = (0..g.height())
            .flat_map(|r| (0..g.width()).map(move |c| (c, r)))
            .map(|(c, r)| g.probability(c, r))
            .collect();
        let back = LogOddsGrid::from_probabilities(
            0.05,
            LogOdds::default(),
            g.origin_m(),
            g.width(),
            g.height(),
            probs,
        );
        assert_eq!(back.origin_m(), g.origin_m());
        for r in 0..g.height() {
            for c in 0..g.width() {
                assert_eq!(back.state(c, r), g.state(c, r));
                if let (Some(a), Some(b)) = (back.log_odds(c, r), g.log_odds(c, r)) {
                    assert!((a - b).abs() < 1e-4);
                }
            }
        }
    }
}
