//! The shortest way for a circular robot over a grid of clearances: A*
//! (8-connected) through cells whose centres keep the robot's footprint
//! clear, at a cost that grows steeply as the clearance falls below the
//! wanted one, then shortened by line of sight (a straight leg replaces a
//! run of cells when every point along it keeps at least the clearance its
//! ends have, or the wanted one).
//!
//! One search serves the twin's continuations ([`crate::detour`]: clearances
//! from the twin's walls, exact) and the robot's own local planner
//! (`twindrive_agent::local_planner`: clearances from its occupancy grid,
//! inside its corridor and out of keep-out zones). Each fills the grid its
//! own way; a cell that may not be entered has a negative clearance.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// What a search keeps of the footprint's clearance (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clearances {
    /// Wanted: passing closer costs more.
    pub want_m: f64,
    /// A floor held everywhere a way keeps it, except within `ends_m` of
    /// either end (a robot against what it touched has to leave it); 0 for
    /// none.
    pub floor_m: f64,
    pub ends_m: f64,
}

/// Footprint clearances at the centres of a rectangular grid of cells.
#[derive(Debug, Clone)]
pub struct ClearanceGrid {
    origin: [f64; 2],
    cell_m: f64,
    size: [usize; 2],
    /// Clearance of the footprint centred on each cell (m; negative where
    /// it would overlap an obstacle or the cell is out of bounds).
    clearance: Vec<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Open {
    f: f64,
    cell: usize,
}

impl Eq for Open {}

impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        // Min-heap on f, ties by cell for determinism.
        other
            .f
            .total_cmp(&self.f)
            .then_with(|| other.cell.cmp(&self.cell))
    }
}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// Neighbours of a cell: four sides, then four diagonals.
pub const NEIGHBOURS: [(isize, isize); 8] = [
    (1, 0),
    (-1, 0),
    (0, 1),
    (0, -1),
    (1, 1),
    (1, -1),
    (-1, 1),
    (-1, -1),
];

impl ClearanceGrid {
    /// A grid of `size` cells of `cell_m` whose cell (i, j) is centred at
    /// `origin + (i, j) * cell_m`, with `clearance[i + j * size[0]]`.
    pub fn new(origin: [f64; 2], cell_m: f64, size: [usize; 2], clearance: Vec<f64>) -> Self {
        assert_eq!(clearance.len(), size[0] * size[1], "one clearance a cell");
        Self {
            origin,
            cell_m,
            size,
            clearance,
        }
    }

    pub fn cell_m(&self) -> f64 {
        self.cell_m
    }

    pub fn size(&self) -> [usize; 2] {
        self.size
    }

    /// The footprint's clearance at cell `cell`.
    pub fn clearance(&self, cell: usize) -> f64 {
        self.clearance[cell]
    }

    /// The clearances, cell `i + j * size[0]` at index.
    /// How many cells the grid has.
    pub fn clearances_len(&self) -> usize {
        self.clearance.len()
    }

    pub fn clearances_mut(&mut self) -> &mut [f64] {
        &mut self.clearance
    }

    pub fn centre(&self, cell: usize) -> [f64; 2] {
        let (i, j) = (cell % self.size[0], cell / self.size[0]);
        [
            self.origin[0] + i as f64 * self.cell_m,
            self.origin[1] + j as f64 * self.cell_m,
        ]
    }

    /// The cell nearest `p`, clamped to the grid.
    pub fn cell_of(&self, p: [f64; 2]) -> usize {
        let index = |v: f64, o: f64, n: usize| {
            let k = ((v - o) / self.cell_m).round();
            if k.is_nan() || k <= 0.0 {
                0
            } else {
                (k as usize).min(n - 1)
            }
        };
        index(p[0], self.origin[0], self.size[0])
            + index(p[1], self.origin[1], self.size[1]) * self.size[0]
    }

    /// Whether `p` lies on the grid (within half a cell of a centre).
    pub fn contains(&self, p: [f64; 2]) -> bool {
        let h = 0.5 * self.cell_m;
        (0..2).all(|a| {
            p[a] >= self.origin[a] - h
                && p[a] <= self.origin[a] + (self.size[a] - 1) as f64 * self.cell_m + h
        })
    }

    /// Cost factor of passing a cell of footprint clearance `clearance_m`:
    /// 1 at the wanted one, growing steeply below it; `None` where the
    /// footprint would touch.
    fn factor(clearance_m: f64, want_m: f64) -> Option<f64> {
        (clearance_m > 0.002).then(|| {
            let deficit = (want_m - clearance_m).max(0.0);
            1.0 + 40.0 * deficit / want_m.max(1e-3)
        })
    }

    /// A* from `from` to `to`: the cells along the way. Keeps the floor
    /// away from the ends when any way does.
    pub fn search(&self, from: [f64; 2], to: [f64; 2], keep: &Clearances) -> Option<Vec<usize>> {
        if keep.floor_m > 0.0
            && let Ok(path) = self.search_above(from, to, keep, keep.floor_m)
        {
            return Some(path);
        }
        self.search_above(from, to, keep, 0.0).ok()
    }

    /// A* from `from` to `to` through cells that keep the floor (away from
    /// the ends): the cells along the way, or, when none exists, the cell
    /// the search reached nearest to `to` (where the way is closed).
    pub fn search_or_nearest(
        &self,
        from: [f64; 2],
        to: [f64; 2],
        keep: &Clearances,
    ) -> Result<Vec<usize>, usize> {
        self.search_above(from, to, keep, keep.floor_m)
    }

    /// A* through cells that keep `floor_m`, or are within `ends_m` of
    /// either end; without a way, the reached cell nearest to `to`.
    fn search_above(
        &self,
        from: [f64; 2],
        to: [f64; 2],
        keep: &Clearances,
        floor_m: f64,
    ) -> Result<Vec<usize>, usize> {
        let near = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]) <= keep.ends_m;
        let (start, goal) = (self.cell_of(from), self.cell_of(to));
        let n = self.clearance.len();
        let mut cost = vec![f64::INFINITY; n];
        let mut parent = vec![usize::MAX; n];
        let mut open = BinaryHeap::new();
        let goal_p = self.centre(goal);
        // Octile distance: the shortest 8-connected way on an empty grid,
        // as tight as an admissible estimate gets here.
        let h = |c: usize| {
            let p = self.centre(c);
            let (dx, dy) = ((p[0] - goal_p[0]).abs(), (p[1] - goal_p[1]).abs());
            dx.max(dy) + (std::f64::consts::SQRT_2 - 1.0) * dx.min(dy)
        };
        cost[start] = 0.0;
        open.push(Open {
            f: h(start),
            cell: start,
        });
        let (w, hgt) = (self.size[0] as isize, self.size[1] as isize);
        let mut nearest = (h(start), start);
        while let Some(Open { f, cell }) = open.pop() {
            if cell == goal {
                let mut path = vec![goal];
                let mut c = goal;
                while c != start {
                    c = parent[c];
                    path.push(c);
                }
                path.reverse();
                return Ok(path);
            }
            if f > cost[cell] + h(cell) + 1e-12 {
                continue; // A stale entry.
            }
            let here = h(cell);
            if here < nearest.0 {
                nearest = (here, cell);
            }
            let (i, j) = (
                (cell % self.size[0]) as isize,
                (cell / self.size[0]) as isize,
            );
            for (di, dj) in NEIGHBOURS {
                let (ni, nj) = (i + di, j + dj);
                if ni < 0 || nj < 0 || ni >= w || nj >= hgt {
                    continue;
                }
                let next = (ni + nj * w) as usize;
                let c_next = self.clearance[next];
                // The goal and the start are where the robot must be; every
                // other cell must keep the footprint clear.
                let factor = match Self::factor(c_next, keep.want_m) {
                    Some(_)
                        if c_next < floor_m
                            && !near(self.centre(next), from)
                            && !near(self.centre(next), to) =>
                    {
                        continue;
                    }
                    Some(f) => f,
                    None if next == goal => 1.0,
                    None => continue,
                };
                let step = self.cell_m * if di != 0 && dj != 0 { 2f64.sqrt() } else { 1.0 };
                let c = cost[cell] + step * factor;
                if c < cost[next] {
                    cost[next] = c;
                    parent[next] = cell;
                    open.push(Open {
                        f: c + h(next),
                        cell: next,
                    });
                }
            }
        }
        Err(nearest.1)
    }

    /// Waypoints from `from` to `to`: the searched cells shortened by line
    /// of sight, judged by `clearance_at` (the footprint's clearance at any
    /// point, as exact as the caller has it). Where the robot starts or ends
    /// closer than the wanted clearance (it stopped against what it
    /// touched), the cells are kept until the clearance is reached: the
    /// search leaves contact the cheapest way, and a leg straight from there
    /// could slide along the face. Between, a leg replaces a run of cells
    /// when it keeps the wanted clearance, or at least the lowest clearance
    /// of the cells it replaces (a narrow passage stays as narrow, never
    /// narrower).
    pub fn waypoints(
        &self,
        from: [f64; 2],
        to: [f64; 2],
        keep: &Clearances,
        clearance_at: &dyn Fn([f64; 2]) -> f64,
    ) -> Option<Vec<[f64; 2]>> {
        let cells = self.search(from, to, keep)?;
        let mut points: Vec<[f64; 2]> = Vec::with_capacity(cells.len() + 2);
        points.push(from);
        points.extend(cells.iter().skip(1).map(|&c| self.centre(c)));
        if cells.len() > 1 {
            points.pop(); // The goal cell's centre: `to` itself follows.
        }
        points.push(to);
        let wanted = keep.want_m;
        let clearance: Vec<f64> = points.iter().map(|&p| clearance_at(p)).collect();
        let clear = |k: usize| clearance[k] >= wanted - 1e-9;
        let last = points.len() - 1;
        let head = (0..=last).find(|&k| clear(k)).unwrap_or(last);
        let tail = (head..=last).rev().find(|&k| clear(k)).unwrap_or(head);
        let mut out = points[..=head].to_vec();
        let mut at = head;
        while at < tail {
            let mut next = at + 1;
            for j in (at + 2..=tail).rev() {
                let need = clearance[at..=j].iter().fold(wanted, |a, &c| a.min(c));
                if self.leg_clearance(points[at], points[j], clearance_at) >= need - 1e-9 {
                    next = j;
                    break;
                }
            }
            out.push(points[next]);
            at = next;
        }
        out.extend_from_slice(&points[tail + 1..]);
        Some(out)
    }

    /// The lowest clearance along the straight leg from `a` to `b`, sampled
    /// every quarter cell.
    pub fn leg_clearance(
        &self,
        a: [f64; 2],
        b: [f64; 2],
        clearance_at: &dyn Fn([f64; 2]) -> f64,
    ) -> f64 {
        let length = (b[0] - a[0]).hypot(b[1] - a[1]);
        let steps = (length / (0.25 * self.cell_m)).ceil().max(1.0) as usize;
        (0..=steps)
            .map(|k| {
                let s = k as f64 / steps as f64;
                clearance_at([a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])])
            })
            .fold(f64::INFINITY, f64::min)
    }
}
