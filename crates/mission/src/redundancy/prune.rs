//! Loop, kink and retrace removal: one sweep along the path that keeps the
//! first visit of every place and cuts only what the kept path covers.

use serde::{Deserialize, Serialize};

use super::coverage::{self, BruteCoverage, Coverage, FastCoverage};
use super::fast::FastFinder;
use super::reference::ReferenceFinder;
use super::track::{Criteria, Track};
use super::{PinchFinder, PinchKind, RedundancyConfig, RedundancyError, reversal};
use crate::path::PathSample;

/// The outcome of [`remove_redundancy`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Pruned {
    /// Indices of the surviving input samples, increasing; always holds the
    /// first sample and every protected one (the last with `keep_end`).
    pub kept: Vec<usize>,
    /// What was cut, in input indices: disjoint, sorted, and together
    /// exactly the samples not in `kept`.
    pub deletions: Vec<Deletion>,
    /// Cuts the coverage rule refused that would have dropped ground (the
    /// first of each overlapping group of refusals is measured), with the
    /// metres they would have dropped.
    pub refused: Vec<RefusedCut>,
    /// The coverage radius the cuts were checked at.
    pub coverage_radius_m: f64,
}

/// One deleted stretch: samples `first_removed..=last_removed` of the
/// input. A loop, crossing or kink runs between the kept samples on either
/// side; a trailing retrace runs from the kept sample before to the end.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Deletion {
    pub first_removed: usize,
    pub last_removed: usize,
    /// Input time of the kept sample before (`first_removed - 1`).
    pub t_start_s: f64,
    /// Input time of the kept sample after (`last_removed + 1`), or of the
    /// last sample for a trailing retrace.
    pub t_end_s: f64,
    /// Input path length between those two samples.
    pub length_m: f64,
    pub reason: DeletionReason,
    /// Coverage the cut lost: metres of the deleted path whose samples lie
    /// farther than the coverage radius from the path that remains. Zero,
    /// since the sweep applies no other cut (the rule is checked at the
    /// samples; see the module docs for paths sparser than the radius).
    pub uncovered_m: f64,
}

/// Why a stretch was deleted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DeletionReason {
    /// Between two samples closer than the pinch distance.
    Loop,
    /// Between two passes of a self-crossing.
    Crossing,
    /// A "bump and back up" kink.
    Reversal,
    /// The end of the mission, over ground already covered.
    TrailingRetrace,
}

/// A cut from `i` to `j` (input indices) that would have dropped ground:
/// the path between them farther than the coverage radius from the kept
/// path before `i` and the path from `j` on.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RefusedCut {
    pub i: usize,
    pub j: usize,
    pub t_start_s: f64,
    pub t_end_s: f64,
    /// Path length between `i` and `j`.
    pub length_m: f64,
    pub reason: DeletionReason,
    /// Metres of path it would have left uncovered.
    pub would_drop_m: f64,
}

impl Pruned {
    /// The surviving samples, unchanged.
    pub fn apply(&self, path: &[PathSample]) -> Vec<PathSample> {
        self.kept.iter().map(|&k| path[k]).collect()
    }
}

/// Deletes the retraced loops, kinks and trailing retrace of a path (see
/// the module docs). A path without any passes through unchanged; fewer
/// than three samples always do.
pub fn remove_redundancy(
    path: &[PathSample],
    cfg: &RedundancyConfig,
) -> Result<Pruned, RedundancyError> {
    let track = Track::new(path, cfg)?;
    let crit = Criteria::new(cfg);
    let radius_m = cfg.effective_coverage_radius_m();
    let mut finder = FastFinder::new(&track, &crit);
    let mut coverage = FastCoverage::new(&track, radius_m);
    Ok(sweep(&track, cfg, &crit, &mut finder, &mut coverage))
}

/// [`remove_redundancy`] with the reference pinch finder and coverage that
/// tests every piece of path: the same result in `O(n²)` memory and up to
/// `O(n³)` time. For tests and benchmarks.
pub fn remove_redundancy_reference(
    path: &[PathSample],
    cfg: &RedundancyConfig,
) -> Result<Pruned, RedundancyError> {
    let track = Track::new(path, cfg)?;
    let crit = Criteria::new(cfg);
    let radius_m = cfg.effective_coverage_radius_m();
    let mut finder = ReferenceFinder::new(&track, &crit)?;
    let mut coverage = BruteCoverage::new(&track, radius_m);
    Ok(sweep(&track, cfg, &crit, &mut finder, &mut coverage))
}

/// A cut `(i, j)`: samples strictly between go (to the end for a trailing
/// retrace, whose `j` is the path's length).
type Cut = (usize, usize, DeletionReason);

/// The sweep: at each kept sample `i`, from the first on, a cut that starts
/// there whose deleted samples the kept path up to `i` covers: the kink
/// back to `i` (so the turn after a back-up stays), or else the farthest
/// pinch (a loop or crossing back to `i`); then on from the cut's end. A
/// cut that would drop ground gives way to the farthest one that ends at or
/// before the first sample it would drop. Once past the last
/// new ground (and the last protected sample), the first sample whose kept
/// path covers everything after it ends the plan, unless `keep_end`.
///
/// Every sample is deleted by at most one cut and witnessed by kept path
/// before it, which no later cut touches: the coverage the cuts were
/// checked against is the coverage the result has.
fn sweep(
    track: &Track,
    cfg: &RedundancyConfig,
    crit: &Criteria,
    finder: &mut impl PinchFinder,
    coverage: &mut impl Coverage,
) -> Pruned {
    let n = track.len();
    let radius_m = cfg.effective_coverage_radius_m();
    let mut kept = vec![true; n];
    let mut cuts: Vec<Cut> = Vec::new();
    let mut refused: Vec<RefusedCut> = Vec::new();
    if n < 3 {
        return finish(track, kept, cuts, refused, radius_m);
    }
    let next_protected = track.next_protected();
    // The end of the kink that starts at each sample (0: none).
    let mut kink_end = vec![0usize; n];
    if cfg.reversing_is_redundant {
        for (k, e) in reversal::kinks(track, crit) {
            kink_end[k] = kink_end[k].max(e);
        }
    }
    // Where a trailing retrace may start: after the last new ground and the
    // last protected sample.
    let truncate_from = (!cfg.keep_end).then(|| {
        let last_protected = (0..n).rev().find(|&k| track.protected[k]).unwrap_or(0);
        coverage::last_new_sample(coverage, track, radius_m).max(last_protected)
    });
    // The kink from `i`, or else the farthest pinch, ending at most at `hi`.
    let candidate = |finder: &mut dyn PinchFinder, i: usize, hi: usize| {
        let kink = (kink_end[i] != 0 && kink_end[i] <= hi)
            .then_some((kink_end[i], DeletionReason::Reversal));
        if kink.is_some() {
            return kink;
        }
        finder.farthest(i, hi).map(|p| {
            let reason = match p.kind {
                PinchKind::Near => DeletionReason::Loop,
                PinchKind::Crossing => DeletionReason::Crossing,
            };
            (p.j, reason)
        })
    };
    // The first kink that starts after each sample (n: none).
    let mut next_kink = vec![n; n];
    for k in (0..n.saturating_sub(1)).rev() {
        next_kink[k] = if kink_end[k + 1] != 0 {
            k + 1
        } else {
            next_kink[k + 1]
        };
    }
    // A pinch that is little more than a kink (a back-up and the turn after
    // it): the path it cuts around the kink is no loop of its own.
    let swallows_a_kink = |i: usize, j: usize| {
        let k = next_kink[i];
        k < j && kink_end[k] <= j && {
            let cum = &track.cum_length_m;
            (cum[k] - cum[i]) + (cum[j] - cum[kink_end[k]]) < crit.min_loop_length_m
        }
    };
    let mut refused_reach = 0;
    let mut i = 0;
    while i + 1 < n {
        if truncate_from.is_some_and(|t| i >= t) && coverage.first_uncovered(i, n, &kept).is_none()
        {
            kept[i + 1..].fill(false);
            cuts.push((i, n, DeletionReason::TrailingRetrace));
            break;
        }
        let hi = next_protected[i] as usize;
        let mut chosen = None;
        if let Some((j, reason)) = candidate(finder, i, hi) {
            match coverage.first_uncovered(i, j, &kept) {
                None => chosen = Some((j, reason)),
                Some(u) => {
                    // The first refusal of each overlapping group is
                    // measured (so the measuring costs one pass), and listed
                    // only if it would drop ground: a cut whose samples only
                    // the path after it covers is refused to keep the first
                    // visit, and drops nothing.
                    if i >= refused_reach {
                        refused_reach = j;
                        let uncovered = |s: usize| !coverage.covered_around_cut(s, i, j, &kept);
                        let would_drop_m = coverage::half_weighted_between(track, i, j, uncovered);
                        if would_drop_m > 0.0 {
                            refused.push(RefusedCut {
                                i,
                                j,
                                t_start_s: track.t_s[i],
                                t_end_s: track.t_s[j],
                                length_m: track.cum_length_m[j] - track.cum_length_m[i],
                                reason,
                                would_drop_m,
                            });
                        }
                    }
                    // Everything before `u` is covered: the farthest cut to
                    // `u` at most is safe.
                    chosen = candidate(finder, i, hi.min(u));
                }
            }
        }
        match chosen {
            // Left for the kink, which keeps the turn after the back-up.
            Some((j, reason)) if reason != DeletionReason::Reversal && swallows_a_kink(i, j) => {
                i += 1
            }
            Some((j, reason)) => {
                kept[i + 1..j].fill(false);
                cuts.push((i, j, reason));
                i = j;
            }
            None => i += 1,
        }
    }
    finish(track, kept, cuts, refused, radius_m)
}

fn finish(
    track: &Track,
    kept: Vec<bool>,
    cuts: Vec<Cut>,
    refused: Vec<RefusedCut>,
    coverage_radius_m: f64,
) -> Pruned {
    let n = track.len();
    let deletions = cuts
        .into_iter()
        .map(|(i, j, reason)| {
            let end = j.min(n - 1);
            Deletion {
                first_removed: i + 1,
                last_removed: j - 1,
                t_start_s: track.t_s[i],
                t_end_s: track.t_s[end],
                length_m: track.cum_length_m[end] - track.cum_length_m[i],
                reason,
                uncovered_m: 0.0,
            }
        })
        .collect();
    Pruned {
        kept: (0..n).filter(|&k| kept[k]).collect(),
        deletions,
        refused,
        coverage_radius_m,
    }
}
