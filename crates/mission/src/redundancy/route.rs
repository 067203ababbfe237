//! A route being driven: the intended route (a rehearsal's) as points at
//! most a centimetre apart in the redundancy grid (cells one coverage
//! radius wide), which of it a robot has passed within the radius of, and
//! how far a pose is from it. The experiments score their runs with it.

use super::geometry::Point;
use super::grid::{CellIds, NO_CELL, by_cell, cell_of};

/// Route points at most this far apart (m).
const SPACING_M: f64 = 0.01;

/// The route, and how much of it a robot has passed within a radius of.
pub struct RouteProgress {
    points: Vec<Point>,
    cell_m: f64,
    ids: CellIds,
    /// Points of cell `c` are `members[starts[c]..starts[c + 1]]`.
    starts: Vec<u32>,
    members: Vec<u32>,
    covered: Vec<bool>,
    covered_count: usize,
    /// The cells holding points lie within `lo..=hi`.
    lo: (i32, i32),
    hi: (i32, i32),
}

impl RouteProgress {
    /// The polyline through `polyline`'s points, for coverage at `radius_m`
    /// (> 0).
    pub fn new(polyline: &[Point], radius_m: f64) -> Self {
        let mut points: Vec<Point> = Vec::with_capacity(polyline.len());
        for (k, &p) in polyline.iter().enumerate() {
            if k > 0 {
                let q = polyline[k - 1];
                let length = (p[0] - q[0]).hypot(p[1] - q[1]);
                let pieces = (length / SPACING_M).ceil() as usize;
                for m in 1..pieces {
                    let f = m as f64 / pieces as f64;
                    points.push([q[0] + f * (p[0] - q[0]), q[1] + f * (p[1] - q[1])]);
                }
            }
            points.push(p);
        }
        let cell_m = radius_m;
        let mut ids = CellIds::default();
        let mut cells = 0u32;
        let (mut lo, mut hi) = ((i32::MAX, i32::MAX), (i32::MIN, i32::MIN));
        let tagged: Vec<(u32, u32)> = points
            .iter()
            .enumerate()
            .map(|(k, &p)| {
                let cell = cell_of(p, cell_m);
                lo = (lo.0.min(cell.0), lo.1.min(cell.1));
                hi = (hi.0.max(cell.0), hi.1.max(cell.1));
                let id = ids.id_or_insert(cell, || {
                    cells += 1;
                    cells - 1
                });
                (id, k as u32)
            })
            .collect();
        let (starts, members) = by_cell(cells as usize, tagged);
        Self {
            covered: vec![false; points.len()],
            points,
            cell_m,
            ids,
            starts,
            members,
            covered_count: 0,
            lo,
            hi,
        }
    }

    /// Where the route points of cell `cell` lie in `members`.
    fn cell(&self, cell: (i32, i32)) -> std::ops::Range<usize> {
        match self.ids.id(cell) {
            NO_CELL => 0..0,
            c => self.starts[c as usize] as usize..self.starts[c as usize + 1] as usize,
        }
    }

    /// Marks the route within the radius of `p` as covered.
    pub fn visit(&mut self, p: Point) {
        let (cx, cy) = cell_of(p, self.cell_m);
        let r2 = self.cell_m * self.cell_m;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for i in self.cell((cx + dx, cy + dy)) {
                    let k = self.members[i] as usize;
                    let q = self.points[k];
                    let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
                    if d2 <= r2 && !self.covered[k] {
                        self.covered[k] = true;
                        self.covered_count += 1;
                    }
                }
            }
        }
    }

    /// The share of the route covered so far, 0 to 1.
    pub fn covered_fraction(&self) -> f64 {
        if self.points.is_empty() {
            return 1.0;
        }
        self.covered_count as f64 / self.points.len() as f64
    }

    /// Distance from `p` to the nearest route point (m).
    pub fn distance_m(&self, p: Point) -> f64 {
        let (cx, cy) = cell_of(p, self.cell_m);
        let mut best = f64::INFINITY;
        // Rings of cells outwards: a point in ring k is at least
        // (k - 1) cells away, so stop once that exceeds the best found.
        let far = [
            cx - self.lo.0,
            self.hi.0 - cx,
            cy - self.lo.1,
            self.hi.1 - cy,
        ]
        .into_iter()
        .max()
        .unwrap_or(0)
        .max(0);
        for ring in 0..=far {
            if best.is_finite() && f64::from(ring - 1) * self.cell_m > best {
                break;
            }
            for dx in -ring..=ring {
                for dy in -ring..=ring {
                    if dx.abs() != ring && dy.abs() != ring {
                        continue;
                    }
                    for i in self.cell((cx + dx, cy + dy)) {
                        let q = self.points[self.members[i] as usize];
                        best = best.min((q[0] - p[0]).hypot(q[1] - p[1]));
                    }
                }
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coverage_and_distance_on_a_straight_route() {
        let mut route = RouteProgress::new(&[[0.0, 0.0], [1.0, 0.0]], 0.15);
        assert_eq!(route.covered_fraction(), 0.0);
        route.visit([0.5, 0.1]);
        // Within 0.15 m of (0.5, 0.1): x in 0.5 ± 0.112.
        let f = route.covered_fraction();
        assert!((f - 0.224).abs() < 0.02, "{f}");
        assert!((route.distance_m([0.5, 0.3]) - 0.3).abs() < 1e-9);
        assert!((route.distance_m([3.0, 0.0]) - 2.0).abs() < 1e-9);
        assert!((route.distance_m([-0.3, -0.4]) - 0.5).abs() < 1e-9);
        for k in 0..=20 {
            route.visit([k as f64 * 0.05, -0.05]);
        }
        assert_eq!(route.covered_fraction(), 1.0);
    }

    #[test]
    fn distance_is_the_nearest_point_on_random_routes() {
        // A deterministic scramble: routes that wander, queries far and near.
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..20 {
            let polyline: Vec<Point> = (0..8)
                .map(|_| [4.0 * next() - 2.0, 4.0 * next() - 2.0])
                .collect();
            let radius = 0.05 + 0.3 * next();
            let mut route = RouteProgress::new(&polyline, radius);
            for _ in 0..50 {
                let p = [8.0 * next() - 4.0, 8.0 * next() - 4.0];
                let brute = route
                    .points
                    .iter()
                    .map(|q| (q[0] - p[0]).hypot(q[1] - p[1]))
                    .fold(f64::INFINITY, f64::min);
                assert_eq!(route.distance_m(p), brute);
                let before: Vec<bool> = route.covered.clone();
                route.visit(p);
                for (k, q) in route.points.iter().enumerate() {
                    let within = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) <= radius * radius;
                    assert_eq!(route.covered[k], before[k] || within);
                }
            }
            assert_eq!(
                route.covered_count,
                route.covered.iter().filter(|c| **c).count()
            );
        }
    }
}
