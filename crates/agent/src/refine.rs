//! Where a robot that handed back stands, as the master's twin sees it.
//!
//! The hand-back carries the robot's own estimate (odometry fused with what
//! its localizer matched) and its covariance, and the sensor window: the
//! last couple of seconds of range readings, each with the pose the robot
//! believed then. Over a window that short odometry is good, so the
//! readings are put into the frame of the final pose as one rigid scan and
//! matched against the twin's map (a grid search within three standard
//! deviations of the robot's estimate, then Gauss-Newton, as the robot's own
//! localizer does: [`twindrive_estimation::localize`]). The match is fused
//! with the robot's estimate in the augmented filter (one gated scalar
//! update per direction the readings constrain), so directions the
//! readings say nothing about keep the robot's uncertainty, and a match the
//! robot's estimate rules out is not taken.
//!
//! The twin then plans from the refined pose, places what it learns from
//! the window with it, and keeps the continuation three of its standard
//! deviations clear of everything it knows ([`crate::twin`]).

use serde::Serialize;
use twindrive_estimation::localize::{MatchSettings, SegmentMap, search};
use twindrive_estimation::{AugmentedEkf, GateConfig, NoiseModel};
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_link::wire::Handback;
use twindrive_log::RangeSensorInfo;
use twindrive_sim::World;

use crate::localize::beams;
use crate::navigator::{covariance_block, initial_estimate};

/// How a hand-back pose is refined.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineSettings {
    pub matching: MatchSettings,
    /// The map's lookup resolution (m).
    pub resolution_m: f64,
    /// Poses a side of the search grid.
    pub search_steps: usize,
    /// The search reaches three standard deviations of the robot's estimate
    /// each way, and at least and at most these (x, y in m, heading in rad).
    pub min_half_width: [f64; 3],
    pub max_half_width: [f64; 3],
}

impl Default for RefineSettings {
    fn default() -> Self {
        Self {
            matching: MatchSettings::default(),
            resolution_m: 0.05,
            search_steps: 7,
            min_half_width: [0.03, 0.03, 0.03],
            max_half_width: [0.3, 0.3, 0.2],
        }
    }
}

/// A hand-back pose as the twin takes it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RefinedPose {
    /// x, y (m), heading (rad).
    pub pose: [f64; 3],
    /// Its 3 x 3 covariance (row major).
    pub covariance: [f64; 9],
    /// The robot's own estimate.
    pub reported: [f64; 3],
    /// Readings in the window that were matched against the map, and how
    /// many of them fit it.
    pub points: usize,
    pub inliers: usize,
    /// Directions the readings constrained and the filter took (0 to 3).
    pub directions: usize,
}

impl RefinedPose {
    /// The largest standard deviation of the position (m): the square root
    /// of the larger eigenvalue of its 2 x 2 covariance.
    pub fn position_std_m(&self) -> f64 {
        let (a, b, d) = (self.covariance[0], self.covariance[1], self.covariance[4]);
        let mid = 0.5 * (a + d);
        let spread = (0.25 * (a - d) * (a - d) + b * b).sqrt();
        (mid + spread).max(0.0).sqrt()
    }

    /// How far the refinement moved the robot's estimate (m).
    pub fn moved_m(&self) -> f64 {
        (self.pose[0] - self.reported[0]).hypot(self.pose[1] - self.reported[1])
    }

    /// The rigid correction from the robot's frame to the twin's: where a
    /// pose the robot believed in the window really was.
    pub fn correct(&self, believed: [f64; 3]) -> [f64; 3] {
        let dh = self.pose[2] - self.reported[2];
        let (s, c) = dh.sin_cos();
        let (dx, dy) = (
            believed[0] - self.reported[0],
            believed[1] - self.reported[1],
        );
        [
            self.pose[0] + c * dx - s * dy,
            self.pose[1] + s * dx + c * dy,
            believed[2] + dh,
        ]
    }
}

/// The robot's estimate in `h` refined against `world` with the window's
/// readings of `sensors` (the robot's range sensors, in reading order).
/// Without readings, or without a match, it is the robot's estimate.
pub fn refine(
    world: &World,
    sensors: &[RangeSensorInfo],
    params: &DiffDriveParams,
    h: &Handback,
    settings: &RefineSettings,
) -> RefinedPose {
    let prior = initial_estimate(h.pose, Some(&h.pose_covariance), params);
    let mut refined = RefinedPose {
        pose: h.pose,
        covariance: covariance_block(&prior, 0),
        reported: h.pose,
        points: 0,
        inliers: 0,
        directions: 0,
    };
    let points = window_points(sensors, h);
    refined.points = points.len();
    if points.is_empty() {
        return refined;
    }
    let reach = settings.matching.outlier_m + settings.resolution_m;
    let map = SegmentMap::new(&world.walls(), settings.resolution_m, reach);
    let half = [0, 1, 2].map(|i| {
        (3.0 * prior.covariance[(i, i)].max(0.0).sqrt())
            .clamp(settings.min_half_width[i], settings.max_half_width[i])
    });
    let Some(matched) = search(
        &map,
        &points,
        h.pose,
        half,
        settings.search_steps,
        &settings.matching,
    ) else {
        return refined;
    };
    refined.inliers = matched.inliers;
    let mut filter = AugmentedEkf::new(prior, NoiseModel::default(), GateConfig::default());
    let Ok(outcome) = filter.update_pose_information(0.0, matched.pose, &matched.information)
    else {
        return refined;
    };
    let e = filter.estimate();
    refined.pose = [e.state[0], e.state[1], e.state[2]];
    refined.covariance = covariance_block(e, 0);
    refined.directions = outcome.accepted;
    refined
}

/// The window's range endpoints in the frame of the hand-back pose.
fn window_points(sensors: &[RangeSensorInfo], h: &Handback) -> Vec<[f64; 2]> {
    let beams = beams(sensors);
    let last = Pose::new(h.pose[0], h.pose[1], h.pose[2]);
    let (s, c) = last.heading_rad.sin_cos();
    let mut points = Vec::new();
    for w in &h.window {
        let at = Pose::new(w.pose[0], w.pose[1], w.pose[2]);
        for (beam, &r) in beams.iter().zip(&w.ranges_m) {
            let r = f64::from(r);
            // Readings at the sensor's limit say only that nothing is nearer.
            if !(r.is_finite() && r > beam.min_m && r < beam.max_m - 0.02) {
                continue;
            }
            let (bx, by) = beam.endpoint(r);
            let (x, y) = at.transform_point(bx, by);
            let (dx, dy) = (x - last.x_m, y - last.y_m);
            points.push([c * dx + s * dy, -s * dx + c * dy]);
        }
    }
    points
}
