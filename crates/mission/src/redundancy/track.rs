//! The path as the finders see it: flat arrays of the samples still in
//! play, with their cumulative length and protection.

use super::geometry::distance;
use super::{RedundancyConfig, RedundancyError};
use crate::path::PathSample;

/// The largest path the finders index (entries are `u32`).
pub(super) const MAX_SAMPLES: usize = u32::MAX as usize - 1;

/// The thresholds every finder applies, from a validated config.
#[derive(Debug, Clone, Copy)]
pub(super) struct Criteria {
    pub pinch_distance_m: f64,
    pub pinch_distance2: f64,
    pub min_loop_length_m: f64,
    pub min_loop_duration_s: f64,
}

impl Criteria {
    pub fn new(cfg: &RedundancyConfig) -> Self {
        Self {
            pinch_distance_m: cfg.pinch_distance_m,
            pinch_distance2: cfg.pinch_distance_m * cfg.pinch_distance_m,
            min_loop_length_m: cfg.effective_min_loop_length_m(),
            min_loop_duration_s: cfg.min_loop_duration_s,
        }
    }
}

/// The input path as the finders see it: positions, lengths, times and
/// which samples no cut may delete.
#[derive(Debug, Clone)]
pub(super) struct Track {
    pub points: Vec<[f64; 2]>,
    /// Path length from the first sample, along the polyline.
    pub cum_length_m: Vec<f64>,
    pub t_s: Vec<f64>,
    pub reversing: Vec<bool>,
    /// Never deleted: the first sample, the last with `keep_end`, kept
    /// regions and windows, and reversing samples when reversing is not
    /// redundant.
    pub protected: Vec<bool>,
}

impl Track {
    /// Validates the config and the path, and sets up the full path.
    pub fn new(path: &[PathSample], cfg: &RedundancyConfig) -> Result<Self, RedundancyError> {
        cfg.validate()?;
        check_samples(path)?;
        let n = path.len();
        let mut track = Self {
            points: Vec::with_capacity(n),
            cum_length_m: Vec::new(),
            t_s: Vec::with_capacity(n),
            reversing: Vec::with_capacity(n),
            protected: Vec::with_capacity(n),
        };
        let keeps_any = !cfg.keep_regions.is_empty() || !cfg.keep_windows.is_empty();
        for (k, s) in path.iter().enumerate() {
            let reversing = s.v_m_s < 0.0;
            track.points.push(s.position());
            track.t_s.push(s.t_s);
            track.reversing.push(reversing);
            track.protected.push(
                k == 0
                    || (cfg.keep_end && k + 1 == n)
                    || (!cfg.reversing_is_redundant && reversing)
                    || (keeps_any && cfg.keeps(s.position(), s.t_s)),
            );
        }
        track.cum_length_m = cumulative_length_m(&track.points);
        Ok(track)
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// For each sample, the first protected sample after it (`len - 1`
    /// for the last): a cut starting at `i` may end at most there.
    pub fn next_protected(&self) -> Vec<u32> {
        let n = self.len();
        let mut next = vec![0u32; n];
        let mut after = (n.max(1) - 1) as u32;
        for k in (0..n).rev() {
            next[k] = after;
            if self.protected[k] {
                after = k as u32;
            }
        }
        next
    }
}

/// Running sum of segment lengths, in order (every finder and the Python
/// peer sum the same way, so thresholds agree to the bit).
pub(super) fn cumulative_length_m(points: &[[f64; 2]]) -> Vec<f64> {
    let mut cum = Vec::with_capacity(points.len());
    let mut total = 0.0;
    let mut previous = points.first().copied();
    for &p in points {
        if let Some(q) = previous {
            total += distance(q, p);
        }
        cum.push(total);
        previous = Some(p);
    }
    cum
}

fn check_samples(path: &[PathSample]) -> Result<(), RedundancyError> {
    if path.len() > MAX_SAMPLES {
        return Err(RedundancyError::TooManySamples {
            samples: path.len(),
            max: MAX_SAMPLES,
        });
    }
    for (index, s) in path.iter().enumerate() {
        for (field, value) in [
            ("t_s", s.t_s),
            ("pose.x_m", s.pose.x_m),
            ("pose.y_m", s.pose.y_m),
            ("v_m_s", s.v_m_s),
        ] {
            if !value.is_finite() {
                return Err(RedundancyError::NotFinite {
                    index,
                    field,
                    value,
                });
            }
        }
        if index > 0 && s.t_s <= path[index - 1].t_s {
            return Err(RedundancyError::TimeNotIncreasing {
                index,
                t_s: s.t_s,
                previous_t_s: path[index - 1].t_s,
            });
        }
    }
    Ok(())
}
