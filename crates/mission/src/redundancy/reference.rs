//! The paper's method: a full matrix of distances between all samples, and
//! every pair of segments tested for a crossing. `O(n²)` time and memory on
//! purpose: it is what the fast finder is checked and timed against.

use super::geometry::{distance2, segments_meet};
use super::track::{Criteria, Track};
use super::{Pinch, PinchFinder, PinchKind, RedundancyError};

/// The matrix of squared distances, asked one sample at a time.
pub(super) struct ReferenceFinder<'a> {
    track: &'a Track,
    crit: Criteria,
    /// Squared distances: comparing them with the squared pinch distance
    /// is the same test as comparing distances, without n² square roots.
    matrix: Vec<f64>,
}

impl<'a> ReferenceFinder<'a> {
    pub fn new(track: &'a Track, crit: &Criteria) -> Result<Self, RedundancyError> {
        let n = track.len();
        let pts = &track.points;
        let too_large = || RedundancyError::ReferenceTooLarge { samples: n };
        let size = n.checked_mul(n).ok_or_else(too_large)?;
        let mut matrix: Vec<f64> = Vec::new();
        matrix.try_reserve_exact(size).map_err(|_| too_large())?;
        for &p in pts {
            matrix.extend(pts.iter().map(|&q| distance2(p, q)));
        }
        Ok(Self {
            track,
            crit: *crit,
            matrix,
        })
    }
}

impl PinchFinder for ReferenceFinder<'_> {
    fn farthest(&mut self, i: usize, hi: usize) -> Option<Pinch> {
        let (track, crit) = (self.track, &self.crit);
        let n = track.len();
        let pts = &track.points;
        for j in (i + 2..=hi.min(n.saturating_sub(1))).rev() {
            let long = track.cum_length_m[j] - track.cum_length_m[i] >= crit.min_loop_length_m
                && track.t_s[j] - track.t_s[i] >= crit.min_loop_duration_s;
            if !long {
                continue;
            }
            let kind = if self.matrix[i * n + j] < crit.pinch_distance2 {
                PinchKind::Near
            } else if j >= i + 3 && segments_meet(pts[i], pts[i + 1], pts[j - 1], pts[j]) {
                PinchKind::Crossing
            } else {
                continue;
            };
            return Some(Pinch {
                i,
                j,
                distance_m: self.matrix[i * n + j].sqrt(),
                kind,
            });
        }
        None
    }
}

/// For each sample, its farthest partner up to the next protected sample.
pub(super) fn farthest_pinches(
    track: &Track,
    crit: &Criteria,
) -> Result<Vec<Pinch>, RedundancyError> {
    let mut finder = ReferenceFinder::new(track, crit)?;
    let n = track.len();
    Ok((0..n)
        .filter_map(|i| {
            let limit = (i + 1..n).find(|&k| track.protected[k]).unwrap_or(n - 1);
            finder.farthest(i, limit)
        })
        .collect())
}
