//! How far a drive's odometry can be trusted between two scans: a noise
//! model (a share of the step, a floor) scaled by the errors the scans
//! measure on this drive. Real odometry differs by orders of magnitude
//! from robot to robot (on the SLAM benchmark's relations the Freiburg
//! hospital's is off by 0.08 m over seconds, MIT CSAIL's by 1.7 m and 5°),
//! so no one constant serves: the model is the best odometry there is, and
//! the drive's own innovations say how many times worse this one is.

use std::collections::VecDeque;

/// The standard deviation of wheel odometry's step between two scans:
/// a share of the distance driven and of the turn, a heading error per
/// metre (one wheel slipping), and a floor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryNoise {
    pub m_per_m: f64,
    pub rad_per_rad: f64,
    pub rad_per_m: f64,
    pub floor_m: f64,
    pub floor_rad: f64,
}

impl OdometryNoise {
    /// The standard deviation (m, rad) of a step of `step_m` and
    /// `step_rad`.
    pub fn std(&self, step_m: f64, step_rad: f64) -> [f64; 2] {
        [
            self.floor_m + self.m_per_m * step_m,
            self.floor_rad + self.rad_per_rad * step_rad + self.rad_per_m * step_m,
        ]
    }
}

/// The odometry's recent errors as the scans measured them, in units of
/// the noise model's standard deviation (translation, heading).
#[derive(Debug, Clone)]
pub(super) struct MeasuredNoise {
    window: usize,
    innovations: VecDeque<[f64; 2]>,
}

impl MeasuredNoise {
    /// Keeps the latest `window` innovations.
    pub(super) fn new(window: usize) -> Self {
        Self {
            window: window.max(1),
            innovations: VecDeque::with_capacity(window.max(1)),
        }
    }

    /// One scan's match less the odometry's prediction: its length (m) and
    /// its heading (rad, absolute), with the model's standard deviations
    /// for the step.
    pub(super) fn record(&mut self, moved_m: f64, turned_rad: f64, std: [f64; 2]) {
        if self.innovations.len() == self.window {
            self.innovations.pop_front();
        }
        self.innovations
            .push_back([moved_m / std[0], turned_rad.abs() / std[1]]);
    }

    /// How many times the model's standard deviations the odometry's
    /// errors are on this drive (translation, heading): from the median of
    /// the recent innovations (a robust scale: a person walking ahead, a
    /// false match do not move it), never below 1. Until a quarter of the
    /// window is in, the odometry is not trusted over the scans (infinite).
    pub(super) fn scale(&self) -> [f64; 2] {
        if self.innovations.len() < self.window.div_ceil(4) {
            return [f64::INFINITY; 2];
        }
        [0, 1].map(|i| {
            let mut v: Vec<f64> = self.innovations.iter().map(|u| u[i]).collect();
            let mid = v.len() / 2;
            let (_, median, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
            // The median of a 2D normal's length is 1.1774 σ; of a 1D
            // normal's magnitude, 0.6745 σ.
            let per_sigma = if i == 0 { 1.1774 } else { 0.6745 };
            (*median / per_sigma).max(1.0)
        })
    }
}

#[cfg(test)]
mod tests {
    use rand_distr::{Distribution, StandardNormal};

    use super::*;
    use crate::localize::testkit::rng;

    fn noise() -> OdometryNoise {
        OdometryNoise {
            m_per_m: 0.02,
            rad_per_rad: 0.02,
            rad_per_m: 0.01,
            floor_m: 0.002,
            floor_rad: 0.001,
        }
    }

    /// Standard normal deviates from the seed.
    fn normals(seed: u64, n: usize) -> Vec<f64> {
        let mut r = rng(seed);
        (0..n).map(|_| StandardNormal.sample(&mut r)).collect()
    }

    #[test]
    fn the_scale_is_the_odometrys_measured_error_over_the_model() {
        for (seed, times) in [(1, 3.0), (2, 12.0), (3, 40.0)] {
            let mut measured = MeasuredNoise::new(400);
            let e = normals(seed, 1200);
            for k in 0..400 {
                let step_m = 0.1 + 0.2 * (k % 3) as f64;
                let std = noise().std(step_m, 0.05);
                let (x, y, h) = (e[3 * k], e[3 * k + 1], e[3 * k + 2]);
                measured.record(times * std[0] * x.hypot(y), times * std[1] * h, std);
            }
            let [t, r] = measured.scale();
            assert!((t / times - 1.0).abs() < 0.15, "{seed}: {t} for {times}");
            assert!((r / times - 1.0).abs() < 0.15, "{seed}: {r} for {times}");
        }
    }

    #[test]
    fn a_few_wild_matches_do_not_move_the_scale_and_better_odometry_than_the_model_is_not_believed()
    {
        let mut measured = MeasuredNoise::new(100);
        assert_eq!(measured.scale(), [f64::INFINITY; 2]);
        let std = noise().std(0.2, 0.0);
        let e = normals(7, 300);
        for k in 0..100 {
            // A fifth of the matches jump half a metre (a person ahead).
            let wild = k % 5 == 0;
            let moved = if wild {
                0.5
            } else {
                0.5 * std[0] * e[2 * k].hypot(e[2 * k + 1])
            };
            measured.record(moved, 0.2 * std[1] * e[200 + k], std);
        }
        let [t, r] = measured.scale();
        assert!(t < 1.5, "{t}");
        assert_eq!(r, 1.0);
    }
}
