//! Where a drive lies in a map drawn before (`master --site-maps`: a later
//! mission's log placed in the kept map): its first metres, located by the
//! SLAM, as one composite scan, searched for by the loop closure's
//! branch-and-bound matcher ([`crate::slam::LikelihoodGrid`]) on the map's
//! occupied cells. First near where the log says it started; when it does
//! not match there, anywhere on the map at any heading, so a log whose
//! start is wrong (a robot moved by hand, a start pose mistyped) is still
//! placed, and one from another site matches nowhere.

use std::collections::HashSet;

use super::LogOddsGrid;
use crate::localize::Scan;
use crate::se2::{apply, between, compose, inverse};
use crate::slam::{LikelihoodGrid, SearchWindow, thin};

/// How a drive is placed on a prior map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacementSettings {
    /// The composite scan: the drive's scans over its first `span_m` of
    /// travel (at most `max_scans` of them),
    pub span_m: f64,
    pub max_scans: usize,
    /// one point per `voxel_m` cell, at most `max_points` of them.
    pub voxel_m: f64,
    pub max_points: usize,
    /// The search's likelihood field: cell, spread and levels.
    pub resolution_m: f64,
    pub sigma_m: f64,
    pub levels: usize,
    /// The window around the start the log claims, searched first.
    pub claim_m: f64,
    pub claim_rad: f64,
    /// A placement scores at least this (mean likelihood of the composite's
    /// points, 0 to 1). A drive's first metres can fit a map by chance (a
    /// corner like the map's corner): whether the whole drive agrees with
    /// the map is [`drive_agreement`]'s to say.
    pub min_score: f64,
}

impl Default for PlacementSettings {
    fn default() -> Self {
        Self {
            span_m: 5.0,
            max_scans: 200,
            voxel_m: 0.1,
            max_points: 2_000,
            resolution_m: 0.1,
            sigma_m: 0.1,
            levels: 8,
            claim_m: 0.5,
            claim_rad: 0.35,
            min_score: 0.5,
        }
    }
}

/// Where a drive was placed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// The rigid motion that carries the drive's own poses onto the map.
    pub onto: [f64; 3],
    /// The robot's first pose on the map.
    pub start: [f64; 3],
    /// The composite scan's score there.
    pub score: f64,
    /// Whether the log's claimed start was wrong: found by the search over
    /// the whole map, not near the claim.
    pub moved: bool,
}

/// Places a drive on a prior map, given by its occupied cells' centres
/// (`occupied`, [`LogOddsGrid::occupied_centres`]): `scans` with the
/// odometry pose each claims (the first is where the log says it started,
/// in the prior's frame), `own` the drive's poses as the SLAM located them
/// (same frame, drift and all), the lidar at `mount`. `None` when nothing
/// on the map scores `min_score`.
pub fn place(
    occupied: &[[f64; 2]],
    scans: &[(Scan, [f64; 3])],
    own: &[[f64; 3]],
    mount: [f64; 3],
    max_range_m: f64,
    settings: &PlacementSettings,
) -> Option<Placement> {
    let (first_claim, first_own) = (scans.first()?.1, *own.first()?);
    let points = composite(scans, own, mount, max_range_m, settings);
    if points.is_empty() || occupied.is_empty() {
        return None;
    }
    let grid = LikelihoodGrid::new(
        occupied,
        settings.resolution_m,
        settings.sigma_m,
        settings.levels,
    );
    let window = |linear_m, angular_rad| SearchWindow {
        linear_m,
        angular_rad,
        min_score: settings.min_score,
    };
    let near = grid.search(
        &points,
        first_claim,
        window(settings.claim_m, settings.claim_rad),
    );
    let (found, moved) = match near {
        Some(f) => (f, false),
        None => {
            // Anywhere: the window reaches every corner of the map.
            let (lo, hi) = grid.bounds();
            let reach = [lo[0] - first_claim[0], hi[0] - first_claim[0]]
                .into_iter()
                .chain([lo[1] - first_claim[1], hi[1] - first_claim[1]])
                .map(f64::abs)
                .fold(0.0, f64::max);
            let everywhere = window(reach, std::f64::consts::PI);
            (grid.search(&points, first_claim, everywhere)?, true)
        }
    };
    Some(Placement {
        onto: compose(found.pose, inverse(first_own)),
        start: found.pose,
        score: found.score,
        moved,
    })
}

/// How well a located drive agrees with `prior`, wall by wall: of the
/// map's occupied cells the drive's beams (one per `voxel_m` cell of each
/// scan, scans 0.2 m or 0.2 rad apart) reached, the share some return
/// ended on (within `sigma_m` of it) rather than only passed through. 0
/// when its beams reached none.
///
/// A site changes between missions: a partition taken away is a few cells
/// that beams pass through, among the many walls a drive of the site
/// confirms. A drive from another site, placed where its first metres
/// happened to fit, passes through the map's walls everywhere.
pub fn drive_agreement(
    prior: &LogOddsGrid,
    scans: &[(Scan, [f64; 3])],
    poses: &[[f64; 3]],
    mount: [f64; 3],
    max_range_m: f64,
    settings: &PlacementSettings,
) -> f64 {
    use std::collections::HashMap;

    use super::CellState;
    let res = prior.resolution_m();
    let cell = |p: [f64; 2]| ((p[0] / res).floor() as i64, (p[1] / res).floor() as i64);
    // Each occupied cell reached: whether a return confirmed it.
    let mut reached: HashMap<(i64, i64), bool> = HashMap::new();
    let mut last: Option<[f64; 3]> = None;
    // Along a beam, the last this much before its end is its own surface.
    let clear_m = 2.0 * settings.resolution_m;
    let step_m = 0.5 * res;
    let near = (settings.sigma_m / res).ceil() as i64;
    for ((scan, _), pose) in scans.iter().zip(poses) {
        if let Some(l) = last
            && (pose[0] - l[0]).hypot(pose[1] - l[1]) < 0.2
            && crate::se2::wrap(pose[2] - l[2]).abs() < 0.2
        {
            continue;
        }
        last = Some(*pose);
        let sensor = compose(*pose, mount);
        for p in thin(scan, max_range_m, settings.voxel_m) {
            let q = apply(sensor, p);
            let length = p[0].hypot(p[1]);
            let steps = ((length - clear_m) / step_m).floor().max(0.0) as usize;
            for k in 1..=steps {
                let f = k as f64 * step_m / length;
                let at = [
                    sensor[0] + f * (q[0] - sensor[0]),
                    sensor[1] + f * (q[1] - sensor[1]),
                ];
                if prior.state_at(at) == CellState::Occupied {
                    reached.entry(cell(at)).or_insert(false);
                }
            }
            let (cx, cy) = cell(q);
            for dy in -near..=near {
                for dx in -near..=near {
                    let c = [
                        (cx + dx) as f64 * res + 0.5 * res,
                        (cy + dy) as f64 * res + 0.5 * res,
                    ];
                    if prior.state_at(c) == CellState::Occupied {
                        reached.insert((cx + dx, cy + dy), true);
                    }
                }
            }
        }
    }
    if reached.is_empty() {
        return 0.0;
    }
    reached.values().filter(|c| **c).count() as f64 / reached.len() as f64
}

/// The drive's first metres as one scan, in the robot's frame at its first
/// pose.
fn composite(
    scans: &[(Scan, [f64; 3])],
    own: &[[f64; 3]],
    mount: [f64; 3],
    max_range_m: f64,
    settings: &PlacementSettings,
) -> Vec<[f64; 2]> {
    let mut seen = HashSet::new();
    let mut points = Vec::new();
    let mut travelled_m = 0.0;
    for (k, ((scan, _), pose)) in scans.iter().zip(own).enumerate().take(settings.max_scans) {
        if k > 0 {
            travelled_m += (pose[0] - own[k - 1][0]).hypot(pose[1] - own[k - 1][1]);
            if travelled_m > settings.span_m {
                break;
            }
        }
        let sensor = compose(between(own[0], *pose), mount);
        for p in thin(scan, max_range_m, settings.voxel_m) {
            let q = apply(sensor, p);
            let cell = (
                (q[0] / settings.voxel_m).floor() as i64,
                (q[1] / settings.voxel_m).floor() as i64,
            );
            if seen.insert(cell) {
                points.push(q);
            }
        }
    }
    if points.len() > settings.max_points {
        let stride = points.len().div_ceil(settings.max_points);
        points = points.into_iter().step_by(stride).collect();
    }
    points
}
