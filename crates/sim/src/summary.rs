//! Headline numbers of a simulated mission.

use serde::{Deserialize, Serialize};
use twindrive_log::MissionLog;

use crate::{Vector, World};

/// What `summary.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MissionSummary {
    pub scenario: String,
    pub seed: u64,
    pub steps: usize,
    pub dt_s: f64,
    pub duration_s: f64,
    /// Ground-truth path length.
    pub distance_m: f64,
    /// Bump episodes (rising edges of the bump sensor).
    pub bumps: usize,
    pub bump_time_s: f64,
    /// Smallest distance from the robot's centre to a wall, minus the
    /// footprint radius; never negative, as the footprint never penetrates.
    pub min_clearance_m: f64,
    pub encoder_samples: usize,
    pub tracker_samples: usize,
}

impl MissionSummary {
    pub fn new(log: &MissionLog, world: &World) -> Self {
        let dt_s = log.header.dt_s;
        let radius = log.header.footprint_radius_m;
        let bumps = log
            .steps
            .iter()
            .scan(false, |prev, s| {
                let rising = s.bump && !*prev;
                *prev = s.bump;
                Some(rising)
            })
            .filter(|&r| r)
            .count();
        // Any wall lies within the world's diagonal of any point inside it.
        let reach = world.bounds().map_or(1.0, |b| (b.maxs - b.mins).length());
        let min_clearance_m = log
            .steps
            .iter()
            .map(|s| {
                let p = Vector::new(s.ground_truth.x_m, s.ground_truth.y_m);
                world
                    .nearest_within(p, reach)
                    .map_or(reach, |n| n.distance_m - radius)
            })
            .fold(f64::INFINITY, f64::min);
        Self {
            scenario: log.header.scenario.clone(),
            seed: log.header.seed,
            steps: log.steps.len(),
            dt_s,
            duration_s: log.steps.len() as f64 * dt_s,
            distance_m: log.ground_truth_distance_m(),
            bumps,
            bump_time_s: log.steps.iter().filter(|s| s.bump).count() as f64 * dt_s,
            min_clearance_m,
            encoder_samples: log
                .steps
                .iter()
                .filter(|s| s.encoder_ticks.is_some())
                .count(),
            tracker_samples: log.steps.iter().filter(|s| s.tracker.is_some()).count(),
        }
    }
}
