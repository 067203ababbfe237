//! "Bump and back up" kinks (paper section 5.1): the robot drives forward,
//! bumps, reverses, then turns away. The reversing run and the forward
//! stretch it retraces are redundant.

use super::geometry::distance2;
use super::track::{Criteria, Track};

/// Cuts `(k, e)` that delete each kink: `e` is the first sample after a
/// maximal run of reversing samples (where forward motion resumes; the last
/// sample if the path ends reversing) and `k` the sample before the run
/// nearest to it, searched back along the path over the reversed length plus
/// one pinch distance (ties: the later sample, the smaller cut). A kink is
/// cut only if `k` is closer to `e` than the pinch distance (the robot came
/// back along its way) and no protected sample lies in between.
///
/// A run that reverses less than a quarter of the pinch distance is no back-up:
/// a turn in place wobbles around zero speed (after smoothing, or with
/// encoder noise) and must keep its heading change.
/// Shortest back-up that makes a kink, in pinch distances.
const MIN_BACKUP_IN_PINCH_DISTANCES: f64 = 0.25;

pub(super) fn kinks(track: &Track, crit: &Criteria) -> Vec<(usize, usize)> {
    let n = track.len();
    let mut out = Vec::new();
    if n < 3 {
        return out;
    }
    let cum = &track.cum_length_m;
    // last_protected[k]: the last protected sample at or before k.
    let mut last_protected = vec![0; n];
    let mut last = 0;
    for (k, slot) in last_protected.iter_mut().enumerate() {
        if track.protected[k] {
            last = k;
        }
        *slot = last;
    }

    let mut r = 0;
    while r < n {
        if !track.reversing[r] {
            r += 1;
            continue;
        }
        let r0 = r;
        while r < n && track.reversing[r] {
            r += 1;
        }
        let e = r.min(n - 1);
        if cum[e] - cum[r0] < MIN_BACKUP_IN_PINCH_DISTANCES * crit.pinch_distance_m {
            continue;
        }
        let first_allowed = last_protected[e - 1];
        if r0 == 0 || first_allowed >= r0 {
            continue;
        }
        let reach_m = cum[e] - cum[r0] + crit.pinch_distance_m;
        let mut best: Option<(f64, usize)> = None;
        for k in (first_allowed..r0).rev() {
            if cum[r0] - cum[k] > reach_m {
                break;
            }
            let d2 = distance2(track.points[k], track.points[e]);
            if best.is_none_or(|(b, _)| d2 < b) {
                best = Some((d2, k));
            }
        }
        if let Some((d2, k)) = best
            && d2 < crit.pinch_distance2
            && e >= k + 2
        {
            out.push((k, e));
        }
    }
    out
}
