//! Random rooms and scans of them, cast by the simulator's world, for the
//! matcher's tests: held-out-style inputs (sizes, clutter, poses, noise,
//! dropouts drawn from the seed).

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal as Gauss};
use twindrive_sim::{Vector, World};

use super::Scan;

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// A rectangular room of 4-9 m a side with three boxes in it.
pub fn room(rng: &mut ChaCha8Rng) -> Vec<[f64; 4]> {
    let (w, h) = (rng.random_range(4.0..9.0), rng.random_range(4.0..9.0));
    let mut walls = vec![
        [0.0, 0.0, w, 0.0],
        [w, 0.0, w, h],
        [w, h, 0.0, h],
        [0.0, h, 0.0, 0.0],
    ];
    for _ in 0..3 {
        let (x, y) = (
            rng.random_range(0.5..w - 1.0),
            rng.random_range(0.5..h - 1.0),
        );
        let s = rng.random_range(0.2..0.5);
        walls.extend(square(x, y, s));
    }
    walls
}

/// The four walls of a `side_m` square box with its lower-left corner at
/// (x, y).
pub fn square(x: f64, y: f64, side_m: f64) -> [[f64; 4]; 4] {
    let s = side_m;
    [
        [x, y, x + s, y],
        [x + s, y, x + s, y + s],
        [x + s, y + s, x, y + s],
        [x, y + s, x, y],
    ]
}

/// How a simulated scanner reads.
#[derive(Debug, Clone, Copy)]
pub struct Lidar {
    pub beams: usize,
    pub noise_std_m: f64,
    pub dropout: f64,
    pub max_range_m: f64,
}

/// A full-circle scan from `pose` (x, y, heading of the sensor) among the
/// walls: Gaussian range noise, dropouts and max-range readings reported
/// as `max_range_m` (no return).
pub fn scan(walls: &[[f64; 4]], pose: [f64; 3], lidar: Lidar, rng: &mut ChaCha8Rng) -> Scan {
    let world = World::from_walls(walls, &[]);
    let noise = Gauss::new(0.0, lidar.noise_std_m).unwrap();
    let increment_rad = std::f64::consts::TAU / lidar.beams as f64;
    let angle_min_rad = -std::f64::consts::PI;
    let ranges_m = (0..lidar.beams)
        .map(|i| {
            let a = angle_min_rad + i as f64 * increment_rad;
            let dir = Vector::new((pose[2] + a).cos(), (pose[2] + a).sin());
            let r = world.cast_ray(Vector::new(pose[0], pose[1]), dir, lidar.max_range_m);
            let hit = r < lidar.max_range_m;
            let r = r + noise.sample(rng);
            if !hit || rng.random::<f64>() < lidar.dropout || r >= lidar.max_range_m {
                lidar.max_range_m as f32
            } else {
                r as f32
            }
        })
        .collect();
    Scan {
        t_s: 0.0,
        angle_min_rad,
        increment_rad,
        range_min_m: 0.05,
        range_max_m: lidar.max_range_m,
        ranges_m,
    }
}

pub use crate::se2::compose;

/// A pose in the room at least `clearance_m` from every wall.
pub fn free_pose(walls: &[[f64; 4]], clearance_m: f64, rng: &mut ChaCha8Rng) -> [f64; 3] {
    let map = super::SegmentMap::new(walls, 0.05, clearance_m);
    let (w, h) = (walls[0][2], walls[1][3]);
    loop {
        let p = [
            rng.random_range(0.3..w - 0.3),
            rng.random_range(0.3..h - 0.3),
            rng.random_range(-3.1..3.1),
        ];
        if map.distance_m(p[0], p[1]).is_none() {
            return p;
        }
    }
}
