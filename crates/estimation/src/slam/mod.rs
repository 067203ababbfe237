//! Where a robot was over a long real drive, with loop closure: local
//! scan-to-submap matching, submaps, loop closures found by a
//! branch-and-bound correlative search that tolerates metres of drift,
//! false loops switched off, and a sparse pose graph with robust losses
//! (the design of Hess et al., "Real-time loop closure in 2D LIDAR SLAM",
//! ICRA 2016, with the project's PL-ICP as the local matcher).
//!
//! - [`locate_drive`]: every scan's pose, from the scans and the robot's
//!   odometry at each;
//! - [`PoseGraph`]: the graph and its solver (`faer`'s sparse Cholesky);
//! - [`LikelihoodGrid`]: the multi-resolution grid the loop search runs on.
//!
//! Evaluated against `factrs` and `tiny-solver` (both build SE(2) graphs
//! on `faer` with automatic differentiation): the graph here needs one
//! residual with a closed-form Jacobian, Huber weights and switching
//! edges off between solves, so it keeps its own 200-line Gauss-Newton
//! and uses `faer` only for the sparse factorisation.

mod builder;
mod correlative;
mod global;
mod odometry;
mod pose_graph;
#[cfg(test)]
mod tests;

use super::se2;
use crate::localize::{MatchSettings, Scan};

pub use builder::{ScanOutcome, Slam, SlamStats};
pub use correlative::{Found, LikelihoodGrid, SearchWindow};
pub use odometry::OdometryNoise;
pub use pose_graph::{Edge, PoseGraph, SolveError, Solved};

/// How the SLAM runs. One set of defaults serves every drive: they are
/// set from the sensors' physics (a 5 cm grid for centimetre ranges, a
/// search wide enough for the drift of wheel odometry over a submap's
/// length), not per building.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlamSettings {
    /// Local matching of each scan against its submap.
    pub matching: MatchSettings,
    /// Local matching starts from the best pose of a correlative search
    /// this wide around the odometry's prediction, on a grid of
    /// `local_levels` levels.
    pub local_window: SearchWindow,
    pub local_levels: usize,
    /// The returns within this range (m) are searched for (the farther,
    /// the finer the headings searched must be).
    pub local_search_range_m: f64,
    /// At most this many of them, evenly through the scan.
    pub local_search_points: usize,
    /// A local match that moves the odometry's prediction further than
    /// this (m, rad) is not believed.
    pub max_correction_m: f64,
    pub max_correction_rad: f64,
    /// Returns farther than this are not matched (m).
    pub max_range_m: f64,
    /// A scan's returns are thinned to one per cell of this size (m).
    pub scan_voxel_m: f64,
    /// A submap's points are averaged per voxel of this size (m).
    pub voxel_m: f64,
    /// A scan becomes a node once the robot has moved this far (m), turned
    /// this much (rad), or this long has passed (s) since the last node.
    pub node_m: f64,
    pub node_rad: f64,
    pub node_s: f64,
    /// Nodes inserted into a submap before it is finished.
    pub submap_nodes: usize,
    /// How far the odometry's prediction of one scan from the last may be
    /// off (the best odometry there is; scaled to this drive's): of the
    /// two local matches (from the prediction, from the search), the one
    /// likelier given the scan and this is kept.
    pub odometry_noise: OdometryNoise,
    /// The noise model is scaled to the odometry's errors measured over
    /// the last this-many scans (until a quarter of them are in, the
    /// odometry is not trusted over the scans).
    pub odometry_window: usize,
    /// A local match more than this many of the odometry's (measured)
    /// standard deviations from its prediction conflicts with it: the
    /// prediction itself then competes with the match, and the odometry's
    /// cost grows linearly beyond it (its errors are heavy-tailed).
    pub odometry_conflict_sigmas: f64,
    /// Standard deviation of a local match's relative pose (m, m, rad), and
    /// of the odometry's when a scan did not match.
    pub local_std: [f64; 3],
    pub odometry_std: [f64; 3],
    /// The loop search: every `loop_every`-th node, in finished submaps
    /// anchored at least `loop_min_separation` nodes before it, with some
    /// of their nodes within the window's reach.
    pub loop_every: usize,
    pub loop_min_separation: usize,
    /// At most this many submaps searched for a node, the nearest; a
    /// submap closed to a node is not searched again for this many nodes.
    pub loop_max_submaps: usize,
    pub loop_rest_nodes: usize,
    pub loop_window: SearchWindow,
    /// A node's points for the loop search: at most this many, within this
    /// range (m).
    pub loop_points: usize,
    pub loop_range_m: f64,
    /// PL-ICP's confirmation of a branch-and-bound match (refuses views
    /// that pin the pose in too few directions).
    pub loop_matching: MatchSettings,
    /// A loop closure's standard deviation and Huber threshold (whitened).
    pub loop_std: [f64; 3],
    pub loop_huber: f64,
    /// A closure whose whitened residual is above this after a solve is
    /// switched off.
    pub loop_reject_chi: f64,
    /// The global search (for drives that come back further off than the
    /// loop window): every `global_every`-th node, in at most
    /// `global_max_submaps` finished submaps beyond the loop window, the
    /// window grown by `global_drift_m_per_m` of the path through the graph
    /// between node and submap (`global_blind_drift_m_per_m` where scans
    /// did not match), up to `global_max_m`, and its headings by
    /// `global_drift_rad_per_m` of that path (a kilometre's drive turns
    /// tens of degrees off), up to a half turn; matches score at
    /// least `global_min_score`, and two from different nodes within
    /// `global_pending_nodes` of each other must move the drive alike
    /// (within `global_agree_m`, `global_agree_rad`) to be closures.
    pub global_every: usize,
    pub global_max_submaps: usize,
    pub global_drift_m_per_m: f64,
    pub global_blind_drift_m_per_m: f64,
    pub global_max_m: f64,
    pub global_drift_rad_per_m: f64,
    pub global_min_score: f64,
    pub global_pending_nodes: usize,
    pub global_agree_m: f64,
    pub global_agree_rad: f64,
    /// The grid the loop search runs on; at most `loop_grids_kept` of the
    /// finished submaps' grids are kept (the others are built again when
    /// searched).
    pub grid_resolution_m: f64,
    pub grid_sigma_m: f64,
    pub grid_levels: usize,
    pub loop_grids_kept: usize,
    /// Solve every this many nodes when there are new closures, with at
    /// most `solve_iterations` steps; `final_iterations` at the end.
    pub optimize_every: usize,
    pub solve_iterations: usize,
    pub final_iterations: usize,
}

impl Default for SlamSettings {
    fn default() -> Self {
        Self {
            matching: MatchSettings {
                min_information_ratio: 0.0,
                ..MatchSettings::scan_to_scan()
            },
            local_window: SearchWindow {
                linear_m: 0.2,
                angular_rad: 0.35,
                min_score: 0.0,
            },
            local_levels: 3,
            local_search_range_m: 30.0,
            local_search_points: 150,
            max_correction_m: 0.3,
            max_correction_rad: 0.4,
            max_range_m: 30.0,
            scan_voxel_m: 0.05,
            voxel_m: 0.05,
            node_m: 0.2,
            node_rad: 0.1,
            node_s: 5.0,
            submap_nodes: 60,
            odometry_noise: OdometryNoise {
                m_per_m: 0.02,
                rad_per_rad: 0.02,
                rad_per_m: 0.01,
                floor_m: 0.002,
                floor_rad: 0.001,
            },
            odometry_window: 100,
            odometry_conflict_sigmas: 3.0,
            local_std: [0.01, 0.01, 0.005],
            odometry_std: [0.1, 0.1, 0.05],
            loop_every: 3,
            loop_min_separation: 90,
            loop_max_submaps: 3,
            loop_rest_nodes: 10,
            loop_window: SearchWindow {
                linear_m: 4.0,
                angular_rad: 0.35,
                min_score: 0.55,
            },
            loop_points: 250,
            loop_range_m: 15.0,
            loop_matching: MatchSettings::scan_to_scan(),
            loop_std: [0.03, 0.03, 0.01],
            loop_huber: 2.0,
            loop_reject_chi: 10.0,
            global_every: 5,
            global_max_submaps: 2,
            global_drift_m_per_m: 0.05,
            global_blind_drift_m_per_m: 0.2,
            global_max_m: 40.0,
            global_drift_rad_per_m: 0.0005,
            global_min_score: 0.6,
            global_pending_nodes: 100,
            global_agree_m: 0.3,
            global_agree_rad: 0.05,
            grid_resolution_m: 0.05,
            grid_sigma_m: 0.05,
            grid_levels: 7,
            loop_grids_kept: 16,
            optimize_every: 30,
            solve_iterations: 10,
            final_iterations: 50,
        }
    }
}

/// A drive located: every scan's robot pose and how the scans matched.
#[derive(Debug, Clone)]
pub struct DriveLocated {
    /// The robot's pose at each scan, in the frame of the first scan's
    /// odometry pose.
    pub poses: Vec<[f64; 3]>,
    /// Whether each scan matched its submap.
    pub matched_each: Vec<bool>,
    /// The RMS residual of each match (m), in scan order.
    pub rms_m: Vec<f64>,
    pub stats: SlamStats,
}

/// Locates a drive: `scans` with the robot's odometry pose at each, in
/// time order, the lidar at `mount` on the robot. Calls
/// `progress(done, total)` as it goes.
pub fn locate_drive(
    scans: &[(Scan, [f64; 3])],
    mount: [f64; 3],
    settings: SlamSettings,
    mut progress: impl FnMut(usize, usize),
) -> DriveLocated {
    // The SLAM runs in the frame of the first odometry pose: its grids are
    // aligned with that frame, so the same drive recorded in another frame
    // (a bag's odometry starting at zero, a log's at the start pose) is
    // located the same way, then moved back.
    let origin = scans.first().map_or([0.0; 3], |(_, o)| *o);
    let mut slam = Slam::new(mount, settings);
    let mut matched_each = Vec::with_capacity(scans.len());
    let mut rms_m = Vec::new();
    for (k, (scan, odometry)) in scans.iter().enumerate() {
        let points = thin(scan, settings.max_range_m, settings.scan_voxel_m);
        let outcome = slam.add(scan.t_s, se2::between(origin, *odometry), &points);
        matched_each.push(outcome.matched);
        rms_m.extend(outcome.rms_m);
        if k % 64 == 0 {
            progress(k, scans.len());
        }
    }
    let (poses, stats) = slam.finish();
    let poses = poses.into_iter().map(|p| se2::compose(origin, p)).collect();
    progress(scans.len(), scans.len());
    DriveLocated {
        poses,
        matched_each,
        rms_m,
        stats,
    }
}

/// A scan's returns within `max_range_m`, one per `voxel_m` cell (the
/// first in beam order), in the sensor's frame.
pub fn thin(scan: &Scan, max_range_m: f64, voxel_m: f64) -> Vec<[f64; 2]> {
    let mut seen = std::collections::HashSet::new();
    let max_sq = max_range_m * max_range_m;
    scan.endpoints()
        .flatten()
        .filter(|p| p[0] * p[0] + p[1] * p[1] <= max_sq)
        .filter(|p| {
            seen.insert((
                (p[0] / voxel_m).floor() as i64,
                (p[1] / voxel_m).floor() as i64,
            ))
        })
        .collect()
}
