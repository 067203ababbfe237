//! A drawn map against the true walls, for tests, the demo and anyone with
//! a surveyed plan of the site: how many occupied cells lie on a wall, and
//! how much of the wall the lidar saw is drawn.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use serde::Serialize;

use super::grid::LogOddsGrid;

/// The map's accuracy and completeness.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MapScore {
    pub tolerance_m: f64,
    pub occupied_cells: usize,
    /// Share of the occupied cells whose centre is within the tolerance
    /// of a true wall.
    pub on_a_wall: f64,
    /// The farthest occupied cell centre from every true wall (m).
    pub worst_m: f64,
    /// Length of true wall the lidar's beams reached (m).
    pub seen_wall_m: f64,
    /// Share of that length with an occupied cell within the tolerance.
    pub seen_drawn: f64,
}

/// Distance from `p` to the segment `w` ([x0, y0, x1, y1]).
pub fn distance_to_segment(p: [f64; 2], w: &[f64; 4]) -> f64 {
    let (ax, ay, bx, by) = (w[0], w[1], w[2], w[3]);
    let (dx, dy) = (bx - ax, by - ay);
    let len_sq = dx * dx + dy * dy;
    let t = if len_sq > 0.0 {
        (((p[0] - ax) * dx + (p[1] - ay) * dy) / len_sq).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - ax - t * dx).hypot(p[1] - ay - t * dy)
}

/// Scores `grid` against `walls`; `seen` are the points where the lidar's
/// beams met the walls (from the true poses), which say which stretches
/// of wall the map could have drawn.
pub fn score(
    grid: &LogOddsGrid,
    walls: &[[f64; 4]],
    seen: &[[f64; 2]],
    tolerance_m: f64,
) -> MapScore {
    let occupied = grid.occupied_centres();
    let nearest_wall = |p: [f64; 2]| {
        walls
            .iter()
            .map(|w| distance_to_segment(p, w))
            .fold(f64::INFINITY, f64::min)
    };
    let mut on = 0usize;
    let mut worst_m = 0.0f64;
    for c in &occupied {
        let d = nearest_wall(*c);
        worst_m = worst_m.max(d);
        if d <= tolerance_m {
            on += 1;
        }
    }
    // Walls sampled every centimetre; a sample is seen when a beam met the
    // wall within two centimetres of it.
    const STEP_M: f64 = 0.01;
    let seen_tree = ImmutableKdTree::<f64, 2>::new_from_slice(seen).ok();
    let occupied_tree = ImmutableKdTree::<f64, 2>::new_from_slice(&occupied).ok();
    let near = |tree: &Option<ImmutableKdTree<f64, 2>>, p: [f64; 2], r: f64| {
        tree.as_ref().is_some_and(|tree| {
            let hit = tree
                .query(&p)
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute();
            hit.distance <= r * r
        })
    };
    let (mut seen_n, mut drawn_n) = (0usize, 0usize);
    for w in walls {
        let len = (w[2] - w[0]).hypot(w[3] - w[1]);
        let n = (len / STEP_M).ceil().max(1.0) as usize;
        for k in 0..n {
            let t = (k as f64 + 0.5) / n as f64;
            let p = [w[0] + t * (w[2] - w[0]), w[1] + t * (w[3] - w[1])];
            if !near(&seen_tree, p, 0.02) {
                continue;
            }
            seen_n += 1;
            if near(&occupied_tree, p, tolerance_m) {
                drawn_n += 1;
            }
        }
    }
    MapScore {
        tolerance_m,
        occupied_cells: occupied.len(),
        on_a_wall: if occupied.is_empty() {
            0.0
        } else {
            on as f64 / occupied.len() as f64
        },
        worst_m,
        seen_wall_m: seen_n as f64 * STEP_M,
        seen_drawn: if seen_n == 0 {
            0.0
        } else {
            drawn_n as f64 / seen_n as f64
        },
    }
}
