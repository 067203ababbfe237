//! The site's walls for scan matching: two-sided segments and a lookup grid
//! that names the nearest two walls of every cell, so a point's distance
//! to the map (and its gradient) costs one cell read and two exact
//! point-to-segment projections, with no interpolation error.

/// One wall: its start, unit direction and length.
#[derive(Debug, Clone, Copy)]
struct Wall {
    a: [f64; 2],
    u: [f64; 2],
    len: f64,
}

impl Wall {
    fn new(w: &[f64; 4]) -> Self {
        let (dx, dy) = (w[2] - w[0], w[3] - w[1]);
        let len = dx.hypot(dy);
        let u = if len > 0.0 {
            [dx / len, dy / len]
        } else {
            [1.0, 0.0]
        };
        Self {
            a: [w[0], w[1]],
            u,
            len,
        }
    }

    /// Residual and its gradient in the point: the signed distance from
    /// the wall's line where the point projects inside the wall (gradient
    /// the normal), the distance from the nearer end otherwise (gradient
    /// away from it).
    #[inline]
    fn residual(&self, x: f64, y: f64) -> (f64, [f64; 2]) {
        let (px, py) = (x - self.a[0], y - self.a[1]);
        let t = px * self.u[0] + py * self.u[1];
        if t >= 0.0 && t <= self.len {
            let n = [-self.u[1], self.u[0]];
            (px * n[0] + py * n[1], n)
        } else {
            let t = t.clamp(0.0, self.len);
            let (ex, ey) = (px - t * self.u[0], py - t * self.u[1]);
            let d = ex.hypot(ey);
            if d > 0.0 {
                (d, [ex / d, ey / d])
            } else {
                (0.0, [0.0, 0.0])
            }
        }
    }
}

/// No wall within reach of a cell.
const NONE: u32 = u32::MAX;

/// Walls and the per-cell lookup of the nearest two.
#[derive(Debug, Clone)]
pub struct SegmentMap {
    walls: Vec<Wall>,
    origin: [f64; 2],
    resolution_m: f64,
    width: usize,
    height: usize,
    cells: Vec<[u32; 2]>,
    reach_m: f64,
}

impl SegmentMap {
    /// The lookup over `walls` (`[x0, y0, x1, y1]`, metres) at
    /// `resolution_m`, naming walls within `reach_m` of each cell's centre
    /// (points farther than that from every wall have no residual: they are
    /// not on the map).
    pub fn new(walls: &[[f64; 4]], resolution_m: f64, reach_m: f64) -> Self {
        assert!(
            resolution_m > 0.0 && reach_m > 0.0,
            "resolution and reach are positive"
        );
        let list: Vec<Wall> = walls.iter().map(Wall::new).collect();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for w in walls {
            lo = [lo[0].min(w[0]).min(w[2]), lo[1].min(w[1]).min(w[3])];
            hi = [hi[0].max(w[0]).max(w[2]), hi[1].max(w[1]).max(w[3])];
        }
        if walls.is_empty() {
            (lo, hi) = ([0.0; 2], [0.0; 2]);
        }
        let pad = reach_m + resolution_m;
        let origin = [lo[0] - pad, lo[1] - pad];
        let width = (((hi[0] - lo[0] + 2.0 * pad) / resolution_m).ceil() as usize).max(1);
        let height = (((hi[1] - lo[1] + 2.0 * pad) / resolution_m).ceil() as usize).max(1);
        let mut cells = vec![[NONE; 2]; width * height];
        let mut dist = vec![[f32::INFINITY; 2]; width * height];
        // A point anywhere in a cell is within half a diagonal of its centre.
        let keep = reach_m + resolution_m * std::f64::consts::FRAC_1_SQRT_2;
        for (i, (w, raw)) in list.iter().zip(walls).enumerate() {
            let c0 = ((raw[0].min(raw[2]) - keep - origin[0]) / resolution_m).floor();
            let c1 = ((raw[0].max(raw[2]) + keep - origin[0]) / resolution_m).ceil();
            let r0 = ((raw[1].min(raw[3]) - keep - origin[1]) / resolution_m).floor();
            let r1 = ((raw[1].max(raw[3]) + keep - origin[1]) / resolution_m).ceil();
            let (c0, c1) = (c0.max(0.0) as usize, (c1.max(0.0) as usize).min(width));
            let (r0, r1) = (r0.max(0.0) as usize, (r1.max(0.0) as usize).min(height));
            for row in r0..r1 {
                let y = origin[1] + (row as f64 + 0.5) * resolution_m;
                for col in c0..c1 {
                    let x = origin[0] + (col as f64 + 0.5) * resolution_m;
                    let d = w.residual(x, y).0.abs();
                    if d > keep {
                        continue;
                    }
                    let k = row * width + col;
                    let d = d as f32;
                    let (ids, ds) = (&mut cells[k], &mut dist[k]);
                    if d < ds[0] {
                        *ids = [i as u32, ids[0]];
                        *ds = [d, ds[0]];
                    } else if d < ds[1] {
                        ids[1] = i as u32;
                        ds[1] = d;
                    }
                }
            }
        }
        Self {
            walls: list,
            origin,
            resolution_m,
            width,
            height,
            cells,
            reach_m,
        }
    }

    pub fn reach_m(&self) -> f64 {
        self.reach_m
    }

    /// The residual of a point against the nearest wall (signed distance
    /// from its line, or distance from its end) and the residual's gradient
    /// in the point; `None` where no wall is within reach.
    #[inline]
    pub fn residual(&self, x: f64, y: f64) -> Option<(f64, [f64; 2])> {
        let col = (x - self.origin[0]) / self.resolution_m;
        let row = (y - self.origin[1]) / self.resolution_m;
        if !(col >= 0.0 && row >= 0.0) {
            return None;
        }
        let (col, row) = (col as usize, row as usize);
        if col >= self.width || row >= self.height {
            return None;
        }
        let [first, second] = self.cells[row * self.width + col];
        if first == NONE {
            return None;
        }
        let best = self.walls[first as usize].residual(x, y);
        if second == NONE {
            return Some(best);
        }
        let other = self.walls[second as usize].residual(x, y);
        Some(if other.0.abs() < best.0.abs() {
            other
        } else {
            best
        })
    }

    /// Distance from a point to the nearest wall, where one is within reach.
    pub fn distance_m(&self, x: f64, y: f64) -> Option<f64> {
        self.residual(x, y).map(|(r, _)| r.abs())
    }
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    fn exact(walls: &[[f64; 4]], x: f64, y: f64) -> f64 {
        walls
            .iter()
            .map(|w| Wall::new(w).residual(x, y).0.abs())
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn distances_are_exact_within_reach_on_random_walls() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..20 {
            let walls: Vec<[f64; 4]> = (0..rng.random_range(1..12))
                .map(|_| {
                    let (x, y) = (rng.random_range(0.0..8.0), rng.random_range(0.0..8.0));
                    let a = rng.random_range(0.0..std::f64::consts::TAU);
                    let l = rng.random_range(0.2..4.0);
                    [x, y, x + l * a.cos(), y + l * a.sin()]
                })
                .collect();
            let map = SegmentMap::new(&walls, 0.05, 0.4);
            let mut checked = 0;
            for _ in 0..2_000 {
                let (x, y) = (rng.random_range(-1.0..10.0), rng.random_range(-1.0..10.0));
                let truth = exact(&walls, x, y);
                match map.distance_m(x, y) {
                    // The nearest two walls of the cell hold the nearest
                    // wall of the point, except within a cell of a third.
                    Some(d) => {
                        assert!(d >= truth - 1e-12, "never closer than the truth");
                        assert!(d - truth < 0.08, "{d} against {truth}");
                        if d == truth {
                            checked += 1;
                        }
                    }
                    None => assert!(truth > 0.4 - 0.04, "{truth} is within reach"),
                }
            }
            assert!(checked > 0);
        }
    }

    #[test]
    fn the_gradient_is_the_residual_s() {
        let map = SegmentMap::new(&[[0.0, 0.0, 2.0, 0.0], [2.0, 0.0, 2.0, 2.0]], 0.05, 0.5);
        for (x, y) in [
            (1.0, 0.2),
            (1.0, -0.13),
            (2.3, 1.0),
            (2.2, -0.2),
            (1.7, 0.1),
        ] {
            let (r, g) = map.residual(x, y).unwrap();
            let h = 1e-6;
            let rx = map.residual(x + h, y).unwrap().0;
            let ry = map.residual(x, y + h).unwrap().0;
            assert!(((rx - r) / h - g[0]).abs() < 1e-5, "d/dx at ({x}, {y})");
            assert!(((ry - r) / h - g[1]).abs() < 1e-5, "d/dy at ({x}, {y})");
        }
        assert_eq!(map.residual(1.0, 0.7), None, "out of reach");
        assert_eq!(map.residual(-5.0, 0.0), None, "off the grid");
    }
}
