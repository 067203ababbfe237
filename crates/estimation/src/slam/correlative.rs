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
    /// The centre of cell (0, 0) (m, submap frame).
    origin: [f64; 2],
    resolution_m: f64,
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
    /// The headings are stepped so the farthest point moves a cell, but
    /// never finer than this (rad; 0 for no bound): a search whose best
    /// pose is refined after needs no finer one.
    pub min_step_rad: f64,
}

/// The best pose found and its score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Found {
    /// The sensor's pose in the submap frame.
    pub pose: [f64; 3],
    /// Mean likelihood of the scan's points (0 to 1).
    pub score: f64,
}

impl LikelihoodGrid {
    /// The field of `points` (the submap's surfaces, submap frame), with
    /// cells of `resolution_m`, a spread `sigma_m` and `levels` levels
    /// (the coarsest spans `2^(levels-1)` cells).
    pub fn new(points: &[[f64; 2]], resolution_m: f64, sigma_m: f64, levels: usize) -> Self {
        let reach = (3.0 * sigma_m / resolution_m).ceil() as i64;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in points {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        if points.is_empty() {
            lo = [0.0; 2];
            hi = [0.0; 2];
        }
        let margin = (reach + 1) as f64 * resolution_m;
        let origin = [lo[0] - margin, lo[1] - margin];
        let width = ((hi[0] - lo[0] + 2.0 * margin) / resolution_m).ceil() as usize + 1;
        let height = ((hi[1] - lo[1] + 2.0 * margin) / resolution_m).ceil() as usize + 1;
        let mut base = vec![0u8; width * height];
        let inv_two_var = 1.0 / (2.0 * sigma_m * sigma_m);
        for p in points {
            let cx = ((p[0] - origin[0]) / resolution_m).round() as i64;
            let cy = ((p[1] - origin[1]) / resolution_m).round() as i64;
            for y in (cy - reach).max(0)..=(cy + reach).min(height as i64 - 1) {
                let dy = origin[1] + y as f64 * resolution_m - p[1];
                for x in (cx - reach).max(0)..=(cx + reach).min(width as i64 - 1) {
                    let dx = origin[0] + x as f64 * resolution_m - p[0];
                    let v = ((-(dx * dx + dy * dy) * inv_two_var).exp() * 255.0).round() as u8;
                    let cell = &mut base[y as usize * width + x as usize];
                    if v > *cell {
                        *cell = v;
                    }
                }
            }
        }
        let mut grids = vec![base];
        for h in 1..levels.max(1) {
            let half = 1usize << (h - 1);
            let prev = &grids[h - 1];
            let at = |x: usize, y: usize| {
                if x < width && y < height {
                    prev[y * width + x]
                } else {
                    0
                }
            };
            let mut next = vec![0u8; width * height];
            for y in 0..height {
                for x in 0..width {
                    next[y * width + x] = at(x, y)
                        .max(at(x + half, y))
                        .max(at(x, y + half))
                        .max(at(x + half, y + half));
                }
            }
            grids.push(next);
        }
        Self {
            origin,
            resolution_m,
            width,
            height,
            levels: grids,
        }
    }

    /// The centres of the grid's first and last cells (m, submap frame).
    pub fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        let far = [
            self.origin[0] + (self.width - 1) as f64 * self.resolution_m,
            self.origin[1] + (self.height - 1) as f64 * self.resolution_m,
        ];
        (self.origin, far)
    }

    /// The field at `p` (submap frame): level 0 at the nearest cell, 0 off
    /// the grid.
    pub fn at(&self, p: [f64; 2]) -> f64 {
        let x = ((p[0] - self.origin[0]) / self.resolution_m).round();
        let y = ((p[1] - self.origin[1]) / self.resolution_m).round();
        if x < 0.0 || y < 0.0 || x >= self.width as f64 || y >= self.height as f64 {
            return 0.0;
        }
        f64::from(self.levels[0][y as usize * self.width + x as usize]) / 255.0
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
        if points.is_empty() {
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
        let rotated: Vec<(f64, Vec<(i64, i64)>)> = (-turns..=turns)
            .map(|k| {
                let heading = guess[2] + k as f64 * step_rad;
                let pose = [guess[0], guess[1], heading];
                let cells = points
                    .iter()
                    .map(|p| {
                        let w = apply(pose, *p);
                        (
                            ((w[0] - self.origin[0]) / res).round() as i64,
                            ((w[1] - self.origin[1]) / res).round() as i64,
                        )
                    })
                    .collect();
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
            for &(x, y) in &rotated[angle].1 {
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
                min_step_rad: 0.0,
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
            min_step_rad: 0.0,
        };
        let found = grid
            .search(&scan, [0.2, -0.3, 0.1], window)
            .expect("a match");
        assert!(found.score > 0.5, "its own scan scores {:.3}", found.score);
        window.min_score = found.score + 1e-6;
        assert_eq!(grid.search(&scan, [0.2, -0.3, 0.1], window), None);
    }

    const LIDAR: Lidar = Lidar {
        beams: 360,
        noise_std_m: 0.01,
        dropout: 0.05,
        max_range_m: 12.0,
    };
}
