//! Where a scan lies in a submap when the guess is metres and tens of
//! degrees off: a branch-and-bound correlative scan matcher on a
//! multi-resolution grid (Olson, "Real-time correlative scan matching",
//! ICRA 2009; Hess et al., "Real-time loop closure in 2D LIDAR SLAM",
//! ICRA 2016, section V).
//!
//! The submap is a likelihood field: each cell holds how likely a return
//! is there, `exp(-d² / 2σ²)` of its distance `d` to the nearest surface
//! point. A candidate pose scores the mean of the field at its scan's
//! points. Level `h` of the grid holds, per cell, the most of level 0
//! over the `2^h × 2^h` cells from it, so a candidate at level `h`
//! bounds from above every finer translation it covers: whole branches
//! are left unscored when their bound is below the best found.

use super::se2::apply;

/// A likelihood field over a submap and its coarser max-levels.
#[derive(Debug, Clone)]
pub struct LikelihoodGrid {
    /// The grid's cells are those of a lattice centred at `phase + i ×
    /// resolution_m` (set by the first points: a grid grows without
    /// moving its cells); cell (0, 0) is lattice cell `origin_cells`.
    phase: [f64; 2],
    origin_cells: [i64; 2],
    resolution_m: f64,
    sigma_m: f64,
    width: usize,
    height: usize,
    /// `levels[h][y * width + x]`: the most of level 0 over
    /// `[x, x + 2^h) × [y, y + 2^h)`, in 255ths (a byte a cell: a
    /// building's submaps hold tens of millions of cells).
    levels: Vec<Vec<u8>>,
}

/// How a scan is searched for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchWindow {
    /// Half-width of the translation searched, along x and y (m).
    pub linear_m: f64,
    /// Half-width of the headings searched (rad).
    pub angular_rad: f64,
    /// Candidates scoring below this (mean likelihood, 0 to 1) are not
    /// matches.
    pub min_score: f64,
}

/// The best pose found and its score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Found {
    /// The sensor's pose in the submap frame.
    pub pose: [f64; 3],
    /// Mean likelihood of the scan's points (0 to 1).
    pub score: f64,
}

/// Cells added on each side a grid grows to (a submap grows a few metres
/// at a time).
const GROWTH_CELLS: i64 = 128;

impl LikelihoodGrid {
    /// The field of `points` (the submap's surfaces, submap frame), with
    /// cells of `resolution_m`, a spread `sigma_m` and `levels` levels
    /// (the coarsest spans `2^(levels-1)` cells).
    pub fn new(points: &[[f64; 2]], resolution_m: f64, sigma_m: f64, levels: usize) -> Self {
        let mut grid = Self {
            phase: [0.0; 2],
            origin_cells: [0; 2],
            resolution_m,
            sigma_m,
            width: 0,
            height: 0,
            levels: vec![Vec::new(); levels.max(1)],
        };
        grid.insert(points);
        grid
    }

    /// Cells a point's field reaches on each side.
    fn reach_cells(&self) -> i64 {
        (3.0 * self.sigma_m / self.resolution_m).ceil() as i64
    }

    /// The lattice cell of `p` (m, submap frame).
    fn lattice(&self, p: [f64; 2]) -> [i64; 2] {
        [
            ((p[0] - self.phase[0]) / self.resolution_m).round() as i64,
            ((p[1] - self.phase[1]) / self.resolution_m).round() as i64,
        ]
    }

    /// Adds `points` (submap frame) to the field, growing the grid to
    /// hold them: the same field as a grid made of all the points at
    /// once.
    pub fn insert(&mut self, points: &[[f64; 2]]) {
        let points: Vec<[f64; 2]> = points
            .iter()
            .filter(|p| p[0].is_finite() && p[1].is_finite())
            .copied()
            .collect();
        if points.is_empty() {
            return;
        }
        let margin = self.reach_cells() + 1;
        if self.width == 0 || self.height == 0 {
            // The first points: the lattice starts `margin` cells below
            // and left of the lowest.
            let mut low = [f64::INFINITY; 2];
            for p in &points {
                low = [low[0].min(p[0]), low[1].min(p[1])];
            }
            self.phase = low.map(|v| v - margin as f64 * self.resolution_m);
        }
        let (mut lo, mut hi) = ([i64::MAX; 2], [i64::MIN; 2]);
        for p in &points {
            let c = self.lattice(*p);
            for k in 0..2 {
                lo[k] = lo[k].min(c[k] - margin);
                hi[k] = hi[k].max(c[k] + margin);
            }
        }
        self.grow(lo, hi);
        // Level 0: each point's field, separable (exp(-(dx² + dy²)/2σ²)
        // is the product of its x and y parts).
        let reach = self.reach_cells();
        let inv_two_var = 1.0 / (2.0 * self.sigma_m * self.sigma_m);
        let res = self.resolution_m;
        let side = (2 * reach + 1) as usize;
        let (mut wx, mut wy) = (vec![0.0; side], vec![0.0; side]);
        let mut boxes = Vec::with_capacity(points.len());
        for p in &points {
            let c = self.lattice(*p);
            let (cx, cy) = (c[0] - self.origin_cells[0], c[1] - self.origin_cells[1]);
            for i in 0..side {
                let off = i as i64 - reach;
                let dx = self.phase[0] + (c[0] + off) as f64 * res - p[0];
                let dy = self.phase[1] + (c[1] + off) as f64 * res - p[1];
                wx[i] = (-dx * dx * inv_two_var).exp();
                wy[i] = (-dy * dy * inv_two_var).exp();
            }
            let base = &mut self.levels[0];
            for (j, wy) in wy.iter().enumerate() {
                let row = (cy - reach + j as i64) as usize * self.width;
                for (i, wx) in wx.iter().enumerate() {
                    let v = (wx * wy * 255.0).round() as u8;
                    let cell = &mut base[row + (cx - reach + i as i64) as usize];
                    if v > *cell {
                        *cell = v;
                    }
                }
            }
            boxes.push(([cx - reach, cy - reach], [cx + reach, cy + reach]));
        }
        // The coarser levels over what changed: point by point when the
        // points' boxes are small beside the grid, else all of it.
        let levels = self.levels.len();
        let per_point: i64 = (1..levels)
            .map(|h| (side as i64 + (1i64 << h)).pow(2))
            .sum::<i64>()
            * points.len() as i64;
        if per_point < (self.width * self.height * (levels - 1)) as i64 {
            for (lo, hi) in boxes {
                self.update_levels(lo, hi);
            }
        } else {
            self.update_levels([0, 0], [self.width as i64 - 1, self.height as i64 - 1]);
        }
    }

    /// Makes the grid cover lattice cells `lo..=hi` (grown with room to
    /// spare unless it was empty), moving what it holds.
    fn grow(&mut self, lo: [i64; 2], hi: [i64; 2]) {
        let old_lo = self.origin_cells;
        let old_hi = [
            old_lo[0] + self.width as i64 - 1,
            old_lo[1] + self.height as i64 - 1,
        ];
        let empty = self.width == 0 || self.height == 0;
        if !empty && (0..2).all(|k| lo[k] >= old_lo[k] && hi[k] <= old_hi[k]) {
            return;
        }
        let (new_lo, new_hi) = if empty {
            (lo, hi)
        } else {
            let mut new_lo = old_lo;
            let mut new_hi = old_hi;
            for k in 0..2 {
                if lo[k] < old_lo[k] {
                    new_lo[k] = lo[k] - GROWTH_CELLS;
                }
                if hi[k] > old_hi[k] {
                    new_hi[k] = hi[k] + GROWTH_CELLS;
                }
            }
            (new_lo, new_hi)
        };
        let width = (new_hi[0] - new_lo[0] + 1) as usize;
        let height = (new_hi[1] - new_lo[1] + 1) as usize;
        let (dx, dy) = (
            (old_lo[0] - new_lo[0]) as usize,
            (old_lo[1] - new_lo[1]) as usize,
        );
        for level in &mut self.levels {
            let mut grown = vec![0u8; width * height];
            for y in 0..self.height {
                let from = &level[y * self.width..(y + 1) * self.width];
                let at = (y + dy) * width + dx;
                grown[at..at + self.width].copy_from_slice(from);
            }
            *level = grown;
        }
        self.origin_cells = new_lo;
        self.width = width;
        self.height = height;
    }

    /// Recomputes the coarser levels where level 0 changed in cells
    /// `lo..=hi` (grid indices).
    fn update_levels(&mut self, lo: [i64; 2], hi: [i64; 2]) {
        let (width, height) = (self.width, self.height);
        let (mut lo, hi) = (lo, hi);
        for h in 1..self.levels.len() {
            let half = 1usize << (h - 1);
            // Level h at x reads level h-1 at x and x + half.
            lo = [lo[0] - half as i64, lo[1] - half as i64];
            let (x0, y0) = (lo[0].max(0) as usize, lo[1].max(0) as usize);
            let (x1, y1) = (
                (hi[0].min(width as i64 - 1)) as usize,
                (hi[1].min(height as i64 - 1)) as usize,
            );
            let (below, above) = self.levels.split_at_mut(h);
            let prev = &below[h - 1];
            let next = &mut above[0];
            let at = |x: usize, y: usize| {
                if x < width && y < height {
                    prev[y * width + x]
                } else {
                    0
                }
            };
            for y in y0..=y1 {
                for x in x0..=x1 {
                    next[y * width + x] = at(x, y)
                        .max(at(x + half, y))
                        .max(at(x, y + half))
                        .max(at(x + half, y + half));
                }
            }
        }
    }

    /// The centres of the grid's first and last cells (m, submap frame).
    pub fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        let res = self.resolution_m;
        let o = self.origin_cells;
        let near = [
            self.phase[0] + o[0] as f64 * res,
            self.phase[1] + o[1] as f64 * res,
        ];
        let far = [
            self.phase[0] + (o[0] + self.width as i64 - 1) as f64 * res,
            self.phase[1] + (o[1] + self.height as i64 - 1) as f64 * res,
        ];
        (near, far)
    }

    /// The field at `p` (submap frame): level 0 at the nearest cell, 0 off
    /// the grid.
    pub fn at(&self, p: [f64; 2]) -> f64 {
        f64::from(self.level_at(0, p)) / 255.0
    }

    /// The grid cell (x, y) holding `p` (submap frame), which may lie off
    /// the grid.
    fn cell(&self, p: [f64; 2]) -> [i64; 2] {
        let c = self.lattice(p);
        [c[0] - self.origin_cells[0], c[1] - self.origin_cells[1]]
    }

    /// Level `h` at `p` (submap frame), 0 off the grid.
    fn level_at(&self, h: usize, p: [f64; 2]) -> u8 {
        let [x, y] = self.cell(p);
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return 0;
        }
        self.levels[h][y as usize * self.width + x as usize]
    }

    /// Mean of the field at `points` (sensor frame) seen from `pose`.
    pub fn score(&self, pose: [f64; 3], points: &[[f64; 2]]) -> f64 {
        if points.is_empty() {
            return 0.0;
        }
        points.iter().map(|p| self.at(apply(pose, *p))).sum::<f64>() / points.len() as f64
    }

    /// The best pose of the sensor within `window` of `guess` (submap
    /// frame) for `points` (sensor frame), when one scores at least the
    /// window's `min_score`.
    pub fn search(
        &self,
        points: &[[f64; 2]],
        guess: [f64; 3],
        window: SearchWindow,
    ) -> Option<Found> {
        if points.is_empty() || self.width == 0 {
            return None;
        }
        let res = self.resolution_m;
        let reach = points
            .iter()
            .map(|p| p[0].hypot(p[1]))
            .fold(0.0, f64::max)
            .max(res);
        // The turn that moves the farthest point by one cell.
        let step_rad = (1.0 - res * res / (2.0 * reach * reach))
            .clamp(-1.0, 1.0)
            .acos();
        let turns = (window.angular_rad / step_rad).ceil() as i64;
        let cells = (window.linear_m / res).ceil() as i64;
        let top = self.levels.len() - 1;
        let span = 1i64 << top;
        // Each heading's points as cell indices at zero offset.
        let rotated: Vec<(f64, Vec<[i64; 2]>)> = (-turns..=turns)
            .map(|k| {
                let heading = guess[2] + k as f64 * step_rad;
                let pose = [guess[0], guess[1], heading];
                let cells = points.iter().map(|p| self.cell(apply(pose, *p))).collect();
                (heading, cells)
            })
            .collect();
        let n = points.len() as f64;
        let score = |level: usize, angle: usize, dx: i64, dy: i64| -> f64 {
            let grid = &self.levels[level];
            // A cell of level h bounds the 2^h cells from it: one left of
            // (below) the grid by less than that bounds the grid's first.
            let span = 1i64 << level;
            let mut sum = 0u32;
            for &[x, y] in &rotated[angle].1 {
                let (x, y) = (x + dx, y + dy);
                if x + span <= 0 || y + span <= 0 {
                    continue;
                }
                let (x, y) = (x.max(0) as usize, y.max(0) as usize);
                if x < self.width && y < self.height {
                    sum += u32::from(grid[y * self.width + x]);
                }
            }
            f64::from(sum) / (255.0 * n)
        };
        // The top level's candidates, best first.
        let mut candidates: Vec<Candidate> = Vec::new();
        for angle in 0..rotated.len() {
            let mut dx = -cells;
            while dx <= cells {
                let mut dy = -cells;
                while dy <= cells {
                    candidates.push(Candidate {
                        angle,
                        dx,
                        dy,
                        score: score(top, angle, dx, dy),
                    });
                    dy += span;
                }
                dx += span;
            }
        }
        candidates.sort_by(|a, b| b.score.total_cmp(&a.score));
        let mut best: Option<Candidate> = None;
        let mut floor = window.min_score;
        self.branch(&candidates, top, cells, &score, &mut best, &mut floor);
        best.map(|c| Found {
            pose: [
                guess[0] + c.dx as f64 * res,
                guess[1] + c.dy as f64 * res,
                rotated[c.angle].0,
            ],
            score: c.score,
        })
    }

    /// Depth-first over `candidates` (at `level`, best first), pruning any
    /// whose bound is at most the best leaf's score so far.
    fn branch(
        &self,
        candidates: &[Candidate],
        level: usize,
        cells: i64,
        score: &impl Fn(usize, usize, i64, i64) -> f64,
        best: &mut Option<Candidate>,
        floor: &mut f64,
    ) {
        for c in candidates {
            if c.score <= *floor {
                // Sorted: the rest are no better.
                return;
            }
            if level == 0 {
                *floor = c.score;
                *best = Some(*c);
                continue;
            }
            let half = 1i64 << (level - 1);
            let mut children = Vec::with_capacity(4);
            for (ox, oy) in [(0, 0), (half, 0), (0, half), (half, half)] {
                let (dx, dy) = (c.dx + ox, c.dy + oy);
                if dx > cells || dy > cells {
                    continue;
                }
                children.push(Candidate {
                    angle: c.angle,
                    dx,
                    dy,
                    score: score(level - 1, c.angle, dx, dy),
                });
            }
            children.sort_by(|a, b| b.score.total_cmp(&a.score));
            self.branch(&children, level - 1, cells, score, best, floor);
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Candidate {
    angle: usize,
    dx: i64,
    dy: i64,
    score: f64,
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::super::se2::{between, compose};
    use super::*;
    use crate::localize::testkit::{self, Lidar};

    /// Random rooms, a scan from a random free pose, a guess metres and
    /// degrees off: the search finds the true pose to within a cell and a
    /// step, and an exhaustive search over the same window finds no
    /// better score.
    #[test]
    fn branch_and_bound_finds_what_an_exhaustive_search_finds() {
        for seed in 0..6u64 {
            let mut rng = testkit::rng(seed);
            let walls = testkit::room(&mut rng);
            let lidar = LIDAR;
            let here = testkit::free_pose(&walls, 0.5, &mut rng);
            // The submap: scans from three other free poses, in a frame at
            // the first of them.
            let frame = testkit::free_pose(&walls, 0.5, &mut rng);
            let mut points = Vec::new();
            for _ in 0..3 {
                let at = testkit::free_pose(&walls, 0.5, &mut rng);
                let scan = testkit::scan(&walls, at, lidar, &mut rng);
                let local = between(frame, at);
                points.extend(scan.points().into_iter().map(|p| apply(local, p)));
            }
            let grid = LikelihoodGrid::new(&points, 0.05, 0.05, 6);
            let scan = testkit::scan(&walls, here, lidar, &mut rng).points();
            let truth = between(frame, here);
            let mut r = ChaCha8Rng::seed_from_u64(seed + 100);
            let guess = compose(
                truth,
                [
                    r.random_range(-1.2..1.2),
                    r.random_range(-1.2..1.2),
                    r.random_range(-0.3..0.3),
                ],
            );
            let window = SearchWindow {
                linear_m: 2.0,
                angular_rad: 0.4,
                min_score: 0.1,
            };
            let found = grid.search(&scan, guess, window).expect("a match");
            let off = between(truth, found.pose);
            assert!(
                off[0].hypot(off[1]) < 0.1 && off[2].abs() < 0.035,
                "seed {seed}: found {:?}, truth {:?} (off {:?}), score {:.3}",
                found.pose,
                truth,
                off,
                found.score
            );
            // The search's lattice point nearest the truth scores no better.
            let reach = scan.iter().map(|p| p[0].hypot(p[1])).fold(0.0, f64::max);
            let step = (1.0 - 0.05f64.powi(2) / (2.0 * reach * reach)).acos();
            let on_lattice = [
                guess[0] + ((truth[0] - guess[0]) / 0.05).round() * 0.05,
                guess[1] + ((truth[1] - guess[1]) / 0.05).round() * 0.05,
                guess[2] + ((truth[2] - guess[2]) / step).round() * step,
            ];
            assert!(
                found.score + 1e-6 >= grid.score(on_lattice, &scan),
                "seed {seed}: found {:.3} < the truth's lattice point's {:.3}",
                found.score,
                grid.score(on_lattice, &scan)
            );
            // Nothing in the window scores better on a coarse exhaustive scan.
            let mut best = 0.0f64;
            for k in -8..=8 {
                for i in -20..=20 {
                    for j in -20..=20 {
                        let pose = [
                            guess[0] + i as f64 * 0.1,
                            guess[1] + j as f64 * 0.1,
                            guess[2] + k as f64 * 0.05,
                        ];
                        best = best.max(grid.score(pose, &scan));
                    }
                }
            }
            assert!(
                found.score + 1e-9 >= best,
                "seed {seed}: the search's {:.3} is beaten by {:.3}",
                found.score,
                best
            );
        }
    }

    /// A floor above the best score finds nothing; at the best, finds it.
    #[test]
    fn nothing_below_the_floor_is_a_match() {
        let mut rng = testkit::rng(11);
        let walls = testkit::room(&mut rng);
        let at = testkit::free_pose(&walls, 0.5, &mut rng);
        let points = testkit::scan(&walls, at, LIDAR, &mut rng).points();
        let grid = LikelihoodGrid::new(&points, 0.05, 0.05, 6);
        let scan = testkit::scan(&walls, at, LIDAR, &mut rng).points();
        let mut window = SearchWindow {
            linear_m: 1.0,
            angular_rad: 0.3,
            min_score: 0.3,
        };
        let found = grid
            .search(&scan, [0.2, -0.3, 0.1], window)
            .expect("a match");
        assert!(found.score > 0.5, "its own scan scores {:.3}", found.score);
        window.min_score = found.score + 1e-6;
        assert_eq!(grid.search(&scan, [0.2, -0.3, 0.1], window), None);
    }

    /// A grid grown scan by scan (the points of each inserted as they
    /// come, the grid growing where they fall outside it) is the grid of
    /// all the points at once (on the same lattice): the same field, and the same bounds on it
    /// wherever the grid made at once reaches (a bigger grid bounds the
    /// cells beyond the other's edge more tightly), so the same best
    /// score. Random rooms, scans from random poses, batches of random
    /// sizes.
    #[test]
    fn a_grid_grown_scan_by_scan_is_the_grid_made_at_once() {
        for seed in 0..4u64 {
            let mut rng = testkit::rng(seed + 40);
            let walls = testkit::room(&mut rng);
            let mut batches = Vec::new();
            for _ in 0..5 {
                let at = testkit::free_pose(&walls, 0.5, &mut rng);
                let scan = testkit::scan(&walls, at, LIDAR, &mut rng).points();
                let seen: Vec<[f64; 2]> = scan.iter().map(|p| apply(at, *p)).collect();
                // Split at random: a few points, then the rest.
                let cut = rng.random_range(1..seen.len());
                batches.push(seen[..cut].to_vec());
                batches.push(seen[cut..].to_vec());
            }
            let all: Vec<[f64; 2]> = batches.concat();
            // The first points set the lattice: the lowest in x and in y
            // first, as the grid made at once has it.
            let lowest = |k: usize| {
                *all.iter()
                    .min_by(|a, b| a[k].total_cmp(&b[k]))
                    .expect("points")
            };
            batches.insert(0, vec![lowest(0), lowest(1)]);
            let at_once = LikelihoodGrid::new(&all, 0.05, 0.05, 4);
            let mut grown = LikelihoodGrid::new(&[], 0.05, 0.05, 4);
            for batch in &batches {
                grown.insert(batch);
            }
            let (lo, hi) = at_once.bounds();
            let mut r = ChaCha8Rng::seed_from_u64(seed);
            for _ in 0..2_000 {
                let p = [
                    r.random_range(lo[0] - 1.0..hi[0] + 1.0),
                    r.random_range(lo[1] - 1.0..hi[1] + 1.0),
                ];
                assert_eq!(at_once.level_at(0, p), grown.level_at(0, p), "{p:?}");
                let inside = (0..2).all(|k| p[k] >= lo[k] && p[k] <= hi[k]);
                for h in (1..4).filter(|_| inside) {
                    assert_eq!(
                        at_once.level_at(h, p),
                        grown.level_at(h, p),
                        "{p:?} level {h}"
                    );
                }
            }
            let here = testkit::free_pose(&walls, 0.5, &mut rng);
            let scan = testkit::scan(&walls, here, LIDAR, &mut rng).points();
            let window = SearchWindow {
                linear_m: 0.5,
                angular_rad: 0.2,
                min_score: 0.0,
            };
            let guess = compose(here, [0.2, -0.1, 0.05]);
            let score = |g: &LikelihoodGrid| g.search(&scan, guess, window).map(|f| f.score);
            assert_eq!(score(&at_once), score(&grown));
            assert!(score(&grown).is_some_and(|s| s > 0.5));
        }
    }

    const LIDAR: Lidar = Lidar {
        beams: 360,
        noise_std_m: 0.01,
        dropout: 0.05,
        max_range_m: 12.0,
    };
}
