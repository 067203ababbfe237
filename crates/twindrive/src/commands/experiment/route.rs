//! The intended route (the rehearsal's) as a set of points a few
//! millimetres apart in a uniform grid: which of it a robot has passed
//! within a radius of, and how far a robot's pose is from it.

use std::collections::HashMap;

/// Route points at most this far apart (m).
const SPACING_M: f64 = 0.01;

pub struct Route {
    points: Vec<[f64; 2]>,
    cell_m: f64,
    cells: HashMap<(i32, i32), Vec<u32>>,
    covered: Vec<bool>,
    covered_count: usize,
    /// The cells holding points lie within `lo..=hi`.
    lo: (i32, i32),
    hi: (i32, i32),
}

impl Route {
    /// The polyline through `points`, for coverage at `radius_m`.
    pub fn new(polyline: &[[f64; 2]], radius_m: f64) -> Self {
        let mut points: Vec<[f64; 2]> = Vec::with_capacity(polyline.len());
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
        let mut cells: HashMap<(i32, i32), Vec<u32>> = HashMap::new();
        for (k, p) in points.iter().enumerate() {
            cells.entry(cell_of(p, cell_m)).or_default().push(k as u32);
        }
        let (mut lo, mut hi) = ((i32::MAX, i32::MAX), (i32::MIN, i32::MIN));
        for &(x, y) in cells.keys() {
            lo = (lo.0.min(x), lo.1.min(y));
            hi = (hi.0.max(x), hi.1.max(y));
        }
        Self {
            covered: vec![false; points.len()],
            points,
            cell_m,
            cells,
            covered_count: 0,
            lo,
            hi,
        }
    }

    /// Marks the route within the radius of `p` as covered.
    pub fn visit(&mut self, p: [f64; 2]) {
        let (cx, cy) = cell_of(&p, self.cell_m);
        let r2 = self.cell_m * self.cell_m;
        for dx in -1..=1 {
            for dy in -1..=1 {
                let Some(members) = self.cells.get(&(cx + dx, cy + dy)) else {
                    continue;
                };
                for &k in members {
                    let q = self.points[k as usize];
                    let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
                    if d2 <= r2 && !self.covered[k as usize] {
                        self.covered[k as usize] = true;
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
    pub fn distance_m(&self, p: [f64; 2]) -> f64 {
        let (cx, cy) = cell_of(&p, self.cell_m);
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
                    let Some(members) = self.cells.get(&(cx + dx, cy + dy)) else {
                        continue;
                    };
                    for &k in members {
                        let q = self.points[k as usize];
                        best = best.min((q[0] - p[0]).hypot(q[1] - p[1]));
                    }
                }
            }
        }
        best
    }
}

fn cell_of(p: &[f64; 2], cell_m: f64) -> (i32, i32) {
    (
        (p[0] / cell_m).floor() as i32,
        (p[1] / cell_m).floor() as i32,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coverage_and_distance_on_a_straight_route() {
        let mut route = Route::new(&[[0.0, 0.0], [1.0, 0.0]], 0.15);
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
}
