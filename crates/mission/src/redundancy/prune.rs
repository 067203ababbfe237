//! Loop and kink removal: cut outermost first, round after round, until
//! the path has nothing left to cut.

use serde::{Deserialize, Serialize};

use super::track::{Criteria, Track};
use super::{Pinch, PinchKind, RedundancyConfig, RedundancyError, fast, reference, reversal};
use crate::path::PathSample;

/// The outcome of [`remove_redundancy`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Pruned {
    /// Indices of the surviving input samples, increasing; always holds the
    /// first and the last sample and every protected one.
    pub kept: Vec<usize>,
    /// What was cut, in input indices: disjoint, sorted, and together
    /// exactly the samples not in `kept`.
    pub deletions: Vec<Deletion>,
    /// The pinch points the loop removal started from (found after the
    /// kinks were cut), in input indices: for figures like the paper's Fig. 7.
    pub pinches: Vec<Pinch>,
}

/// One deleted stretch: samples `first_removed..=last_removed` of the
/// input. The loop runs between the kept samples on either side.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Deletion {
    pub first_removed: usize,
    pub last_removed: usize,
    /// Input time of the kept sample before (`first_removed - 1`).
    pub t_start_s: f64,
    /// Input time of the kept sample after (`last_removed + 1`).
    pub t_end_s: f64,
    /// Input path length between those two samples.
    pub length_m: f64,
    pub reason: DeletionReason,
}

/// Why a stretch was deleted (for a deletion that swallowed earlier ones:
/// why the outermost cut was made).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DeletionReason {
    /// Between two samples closer than the pinch distance.
    Loop,
    /// Between two passes of a self-crossing.
    Crossing,
    /// A "bump and back up" kink.
    Reversal,
}

impl Pruned {
    /// The surviving samples, unchanged.
    pub fn apply(&self, path: &[PathSample]) -> Vec<PathSample> {
        self.kept.iter().map(|&k| path[k]).collect()
    }
}

/// Deletes the loops and kinks of a path (see the module docs). A path
/// without any passes through unchanged; fewer than three samples always do.
pub fn remove_redundancy(
    path: &[PathSample],
    cfg: &RedundancyConfig,
) -> Result<Pruned, RedundancyError> {
    prune(path, cfg, Finder::Fast)
}

/// [`remove_redundancy`] with the reference pinch finder in every round:
/// the same result in `O(n²)` time and memory. For tests and benchmarks.
pub fn remove_redundancy_reference(
    path: &[PathSample],
    cfg: &RedundancyConfig,
) -> Result<Pruned, RedundancyError> {
    prune(path, cfg, Finder::Reference)
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Finder {
    /// The grid hash; after the first round, only the new jumps are searched.
    Fast,
    /// The full distance matrix in every round.
    Reference,
}

/// A cut `(i, j)` in current indices: samples strictly between go.
type Cut = (usize, usize, DeletionReason);

/// Rounds of kink cuts and pinch cuts until neither finds anything.
///
/// After the first pinch search, a pair of samples can pinch only through a
/// segment that a cut has made since the last search (a "junction"): two
/// samples that pinch now pinched then too, with no less path between them
/// (cuts only shorten it); the search found the farthest partner of each,
/// and the cut from the earlier sample went there, leaving them adjacent.
/// So the fast finder searches only around the junctions after that; the
/// reference searches everything every round, and the tests compare them.
fn prune(
    path: &[PathSample],
    cfg: &RedundancyConfig,
    finder: Finder,
) -> Result<Pruned, RedundancyError> {
    let mut track = Track::new(path, cfg)?;
    let crit = Criteria::new(cfg);
    let input_length_m = track.cum_length_m.clone();
    let input_t_s = track.t_s.clone();
    // Records the cuts, remembers their junctions and takes them out of the track.
    let apply = |deletions: &mut Vec<Deletion>,
                 junctions: &mut Vec<usize>,
                 track: &mut Track,
                 cuts: &[Cut]| {
        for &(i, j, reason) in cuts {
            let (a, b) = (track.input_index[i], track.input_index[j]);
            deletions.push(Deletion {
                first_removed: a + 1,
                last_removed: b - 1,
                t_start_s: input_t_s[a],
                t_end_s: input_t_s[b],
                length_m: input_length_m[b] - input_length_m[a],
                reason,
            });
        }
        merge_nested(deletions);
        junctions.extend(cuts.iter().map(|c| track.input_index[c.0]));
        *track = track.without(&spans(cuts));
    };

    // Input indices of the samples whose outgoing segment is a junction.
    let mut junctions: Vec<usize> = Vec::new();
    let mut deletions = Vec::new();
    let mut first_pinches: Option<Vec<Pinch>> = None;
    let mut kinks_stale = cfg.reversing_is_redundant;
    let mut pinches_stale = true;
    while kinks_stale || pinches_stale {
        if kinks_stale {
            kinks_stale = false;
            let kinks = reversal::kinks(&track, &crit);
            let cuts = outermost(
                kinks
                    .into_iter()
                    .map(|(k, e)| (k, e, DeletionReason::Reversal))
                    .collect(),
            );
            if !cuts.is_empty() {
                apply(&mut deletions, &mut junctions, &mut track, &cuts);
                pinches_stale = true;
            }
        }
        if pinches_stale {
            pinches_stale = false;
            let pinches = match (finder, &first_pinches) {
                (Finder::Reference, _) => reference::farthest_pinches(&track, &crit)?,
                (Finder::Fast, None) => fast::farthest_pinches(&track, &crit),
                (Finder::Fast, Some(_)) => {
                    let at = current_indices(&track, &junctions);
                    fast::farthest_pinches_at_junctions(&track, &crit, &at)
                }
            };
            junctions.clear();
            let cuts = outermost(
                pinches
                    .iter()
                    .map(|p| {
                        let reason = match p.kind {
                            PinchKind::Near => DeletionReason::Loop,
                            PinchKind::Crossing => DeletionReason::Crossing,
                        };
                        (p.i, p.j, reason)
                    })
                    .collect(),
            );
            if first_pinches.is_none() {
                first_pinches = Some(
                    pinches
                        .into_iter()
                        .map(|p| Pinch {
                            i: track.input_index[p.i],
                            j: track.input_index[p.j],
                            ..p
                        })
                        .collect(),
                );
            }
            if !cuts.is_empty() {
                apply(&mut deletions, &mut junctions, &mut track, &cuts);
                pinches_stale = true;
                kinks_stale = cfg.reversing_is_redundant;
            }
        }
    }
    Ok(Pruned {
        kept: track.input_index,
        deletions,
        pinches: first_pinches.unwrap_or_default(),
    })
}

/// Where the given input samples are in the track, skipping those gone and
/// the last sample (which starts no segment).
fn current_indices(track: &Track, input: &[usize]) -> Vec<usize> {
    let mut at: Vec<usize> = input
        .iter()
        .filter_map(|k| track.input_index.binary_search(k).ok())
        .filter(|&i| i + 1 < track.len())
        .collect();
    at.sort_unstable();
    at.dedup();
    at
}

/// Outermost first: the earliest start, cut to its farthest end, go on
/// from there. The cuts returned are sorted and share at most end samples.
fn outermost(mut candidates: Vec<Cut>) -> Vec<Cut> {
    candidates.sort_by(|a, b| a.0.cmp(&b.0).then(b.1.cmp(&a.1)));
    let mut cuts = Vec::new();
    let mut from = 0;
    for c in candidates {
        if c.0 >= from {
            from = c.1;
            cuts.push(c);
        }
    }
    cuts
}

fn spans(cuts: &[Cut]) -> Vec<(usize, usize)> {
    cuts.iter().map(|&(i, j, _)| (i, j)).collect()
}

/// Sorts deletions and drops those inside a later round's larger one (a
/// later cut's ends are kept samples, so spans nest or are apart).
fn merge_nested(deletions: &mut Vec<Deletion>) {
    deletions.sort_by(|a, b| {
        a.first_removed
            .cmp(&b.first_removed)
            .then(b.last_removed.cmp(&a.last_removed))
    });
    let mut reach = None;
    deletions.retain(|d| {
        if reach.is_some_and(|r| d.last_removed <= r) {
            false
        } else {
            reach = Some(d.last_removed);
            true
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outermost_takes_the_earliest_then_the_farthest() {
        let l = DeletionReason::Loop;
        let cuts = outermost(vec![
            (5, 9, l),
            (2, 8, l),
            (3, 20, l),
            (8, 12, l),
            (20, 25, l),
        ]);
        assert_eq!(cuts, vec![(2, 8, l), (8, 12, l), (20, 25, l)]);
    }
}
