//! The paper's method: a full matrix of distances between all samples, and
//! every pair of segments tested for a crossing. `O(n²)` time and memory on
//! purpose: it is what the fast finder is checked and timed against.

use super::geometry::{distance2, segments_meet};
use super::track::{Criteria, Track};
use super::{Pinch, PinchKind, RedundancyError};

pub(super) fn farthest_pinches(
    track: &Track,
    crit: &Criteria,
) -> Result<Vec<Pinch>, RedundancyError> {
    let n = track.len();
    let pts = &track.points;
    let too_large = || RedundancyError::ReferenceTooLarge { samples: n };
    let size = n.checked_mul(n).ok_or_else(too_large)?;
    // Squared distances: comparing them with the squared pinch distance is
    // the same test as comparing distances, without n² square roots.
    let mut matrix: Vec<f64> = Vec::new();
    matrix.try_reserve_exact(size).map_err(|_| too_large())?;
    for &p in pts {
        matrix.extend(pts.iter().map(|&q| distance2(p, q)));
    }

    let mut out = Vec::new();
    for i in 0..n {
        let limit = (i + 1..n).find(|&k| track.protected[k]).unwrap_or(n - 1);
        for j in (i + 2..=limit).rev() {
            let long = track.cum_length_m[j] - track.cum_length_m[i] >= crit.min_loop_length_m
                && track.t_s[j] - track.t_s[i] >= crit.min_loop_duration_s;
            if !long {
                continue;
            }
            let kind = if matrix[i * n + j] < crit.pinch_distance2 {
                PinchKind::Near
            } else if j >= i + 3 && segments_meet(pts[i], pts[i + 1], pts[j - 1], pts[j]) {
                PinchKind::Crossing
            } else {
                continue;
            };
            out.push(Pinch {
                i,
                j,
                distance_m: matrix[i * n + j].sqrt(),
                kind,
            });
            break;
        }
    }
    Ok(out)
}
