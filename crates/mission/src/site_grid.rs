//! The twin's site as a grid of footprint clearances: every wall, block and
//! occupied or unknown map cell, and every keep-out zone (the footprint
//! never enters one), rasterized at `cell_m` and turned into distances by
//! the exact distance transform. What the goal planner ([`crate::route`])
//! searches and checks its legs on.
//!
//! The clearance of a cell is the distance from its centre to the nearest
//! obstacle cell's centre, less half a cell's diagonal (the obstacle may
//! lie anywhere in its cell), less the footprint radius: never more than
//! the true clearance of a footprint centred there.

use twindrive_sim::{Vector, World};

use crate::distance_transform::{Scratch, edt};
use crate::freedom::inside;
use crate::grid_search::ClearanceGrid;
use crate::plan::KeepOutZone;

/// The grid of footprint clearances over `world` (its bounds and a margin
/// around them) for a robot of `footprint_m`, with `zones` as obstacles.
/// `None` for a world with nothing in it (no bounds to plan within).
pub fn site_clearances(
    world: &World,
    zones: &[KeepOutZone],
    footprint_m: f64,
    cell_m: f64,
) -> Option<ClearanceGrid> {
    let bounds = world.bounds()?;
    let margin = footprint_m + 2.0 * cell_m;
    let lo = [bounds.mins.x - margin, bounds.mins.y - margin];
    let size = [
        ((bounds.maxs.x + margin - lo[0]) / cell_m).ceil() as usize + 1,
        ((bounds.maxs.y + margin - lo[1]) / cell_m).ceil() as usize + 1,
    ];
    let n = size[0] * size[1];
    let centre = |c: usize| {
        [
            lo[0] + (c % size[0]) as f64 * cell_m,
            lo[1] + (c / size[0]) as f64 * cell_m,
        ]
    };
    let cell_of = |p: [f64; 2]| -> Option<usize> {
        let i = ((p[0] - lo[0]) / cell_m).round();
        let j = ((p[1] - lo[1]) / cell_m).round();
        (i >= 0.0 && j >= 0.0 && (i as usize) < size[0] && (j as usize) < size[1])
            .then(|| i as usize + j as usize * size[0])
    };
    let mut occupied = vec![false; n];
    let mark_line = |a: [f64; 2], b: [f64; 2], occupied: &mut [bool]| {
        let length = (b[0] - a[0]).hypot(b[1] - a[1]);
        let steps = (length / (0.5 * cell_m)).ceil().max(1.0) as usize;
        for k in 0..=steps {
            let f = k as f64 / steps as f64;
            if let Some(c) = cell_of([a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])]) {
                occupied[c] = true;
            }
        }
    };
    for s in world.segments() {
        mark_line([s.a.x, s.a.y], [s.b.x, s.b.y], &mut occupied);
    }
    for z in zones {
        let k = z.polygon.len();
        for i in 0..k {
            mark_line(z.polygon[i], z.polygon[(i + 1) % k], &mut occupied);
        }
    }
    for (c, o) in occupied.iter_mut().enumerate() {
        if *o {
            continue;
        }
        let p = centre(c);
        // Blocks, and occupied or unknown map cells (outside a map too).
        *o = world.inside_obstacle(Vector::new(p[0], p[1]))
            || zones.iter().any(|z| inside(&z.polygon, p));
    }
    let mut d: Vec<f64> = occupied
        .iter()
        .map(|&o| if o { 0.0 } else { 1e12 })
        .collect();
    edt(&mut d, size, &mut Scratch::default());
    let slack = cell_m * std::f64::consts::FRAC_1_SQRT_2 + footprint_m;
    let clearance = d.iter().map(|d2| d2.sqrt() * cell_m - slack).collect();
    Some(ClearanceGrid::new(lo, cell_m, size, clearance))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// On random rooms with random blocks and a zone, no cell claims more
    /// clearance than the footprint has there, and open cells are within
    /// a cell's diagonal of it.
    #[test]
    fn clearances_never_exceed_the_true_ones() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(41);
        for _ in 0..5 {
            let (w, h) = (rng.random_range(3.0..8.0), rng.random_range(3.0..8.0));
            let blocks: Vec<([f64; 2], [f64; 2])> = (0..4)
                .map(|_| {
                    let (x, y) = (
                        rng.random_range(0.5..w - 0.5),
                        rng.random_range(0.5..h - 0.5),
                    );
                    (
                        [x, y],
                        [
                            x + rng.random_range(0.1..0.6),
                            y + rng.random_range(0.1..0.6),
                        ],
                    )
                })
                .collect();
            let walls = [
                [0.0, 0.0, w, 0.0],
                [w, 0.0, w, h],
                [w, h, 0.0, h],
                [0.0, h, 0.0, 0.0],
            ];
            let world = World::from_walls(&walls, &[]).with_blocks(&blocks);
            let (zx, zy) = (
                rng.random_range(0.5..w - 1.0),
                rng.random_range(0.5..h - 1.0),
            );
            let zone = KeepOutZone {
                name: "z".into(),
                polygon: vec![[zx, zy], [zx + 0.5, zy], [zx + 0.5, zy + 0.4]],
            };
            let footprint = 0.15;
            let cell = 0.05;
            let grid =
                site_clearances(&world, std::slice::from_ref(&zone), footprint, cell).unwrap();
            let [nx, ny] = grid.size();
            for c in (0..nx * ny).step_by(7) {
                let p = grid.centre(c);
                let mut truth = world.clearance_m(p[0], p[1], 10.0);
                if inside(&zone.polygon, p) {
                    truth = 0.0;
                } else {
                    truth = truth.min(crate::freedom::distance_to_boundary(&zone.polygon, p));
                }
                let got = grid.clearance(c);
                assert!(
                    got <= truth - footprint + 1e-9,
                    "{p:?}: {got} claimed, {} true",
                    truth - footprint
                );
                let inside_room = p[0] > 0.0 && p[0] < w && p[1] > 0.0 && p[1] < h;
                if inside_room && got > 0.0 {
                    assert!(
                        got >= truth - footprint - 2.0 * cell,
                        "{p:?}: {got} vs {truth}"
                    );
                }
            }
        }
    }
}
