//! Redundancy removal (paper section 5, Fig. 7): find the pinch points of a
//! path and delete the loops and kinks between them.
//!
//! # What is redundant
//!
//! The user says so in a [`RedundancyConfig`]:
//! - a **pinch** is a pair of samples `i < j` that the path could join
//!   without losing anything: either they are closer than
//!   `pinch_distance_m` (strictly, `j >= i + 2`, kind [`PinchKind::Near`]),
//!   or the segments `(i, i+1)` and `(j-1, j)` meet (a true self-crossing of
//!   the polyline, `j >= i + 3`, kind [`PinchKind::Crossing`]; this catches
//!   crossings between sparse samples that are never near one another);
//! - and the path from `i` to `j` is a loop worth the name: at least
//!   `min_loop_length_m` long (default: [`DEFAULT_LOOP_LENGTH_IN_PINCH_DISTANCES`]
//!   pinch distances, so a straight or gently curving stretch never pinches
//!   itself: an arc of constant curvature pinches only once it has turned
//!   through more than about 260°, a corner only if sharper than about 39°)
//!   and lasting at least `min_loop_duration_s` (by the input's time stamps);
//! - with `reversing_is_redundant` (the default), each "bump and back up"
//!   is a **kink**: a maximal run of samples with `v_m_s < 0` together with
//!   the forward stretch it retraces. Kinks are cut whatever their length;
//! - samples in `keep_regions` or `keep_windows` (places worth looking at
//!   twice), the first and the last sample, and — when reversing is *not*
//!   redundant — every reversing sample are **protected**: no cut deletes
//!   them, so a loop through them stays.
//!
//! Cutting a pinch `(i, j)` deletes the samples strictly between `i` and
//! `j`; `i` and `j` stay, so the path jumps by less than the pinch distance
//! (for a crossing, across the crossing point).
//!
//! # Algorithm
//!
//! The pinch finders report, for each sample `i`, only the **farthest** `j`
//! that pinches it and whose cut deletes no protected sample: that is all
//! the removal needs, and it keeps the output linear in the path length (a
//! lap driven twice has a pinch for every sample pair along it).
//!
//! [`find_pinches`] indexes the samples in a uniform grid hash with cells
//! one pinch distance wide (a hand-written table of 8×8-cell tiles; each
//! cell's entries in one flat array, in index order). A sample's partners
//! lie in the 3×3 cells around it, so the farthest one is the first hit
//! scanning each cell down from the protection limit, and the scan stops
//! where the path from `i` is too short to be a loop; a sample whose 3×3
//! cells hold nothing that far along is settled by one look-up. Segments are
//! found through the same grid: segment `(b, b+1)` is anchored at sample `b`
//! and, if longer than 0.45 cells, at points along it, so two segments that
//! meet have anchors in neighbouring cells. Runs of samples at one position
//! (standing still, turning in place) are one grid entry, so a long stop
//! costs no more than one sample.
//!
//! [`find_pinches_reference`] is the paper's method: it materialises the
//! full `n × n` matrix of squared distances and tests every segment pair, in
//! `O(n²)` time and memory. The tests compare the two on random paths, and
//! both share the two floating-point predicates (`geometry.rs`), so they
//! agree to the bit.
//!
//! [`remove_redundancy`] then repeats, until nothing changes:
//! 1. cut the kinks (when reversing is redundant);
//! 2. find the pinches of the current path and cut outermost first: take
//!    the earliest pinch start, cut to its farthest end (so nested loops go
//!    in one cut), go on from that end.
//!
//! A later round can only find crossings through the jumps that earlier
//! cuts left (a pair of samples that pinches after a cut pinched before it,
//! with more path in between, and the cut from the earlier one went to its
//! farthest partner), so the fast removal searches only around those jumps
//! after the first round, while the reference searches everything every
//! round; the tests check that both cut the same. Paths settle in two
//! rounds in practice, the second finding nothing.
//!
//! Each round is `O(n)` expected: building the grid is a hash insert per
//! sample plus a counting sort, a query scans only entries between its
//! window's ends, and a later round is one pass over the samples. The whole
//! is within the `O(n log n)` asked for on ordinary paths. The worst case
//! is a path that lingers at many *distinct* points between one and three
//! pinch distances from another place where it also lingers, with a short
//! `min_loop_length_m`: each sample there scans the other place's samples.
//!
//! Deletions are reported in input indices, disjoint and sorted; a later
//! round's cut that swallows an earlier deletion replaces it.
//!
//! Lengths are along the polyline, durations by the input's time stamps.

mod config;
mod fast;
mod geometry;
mod grid;
mod prune;
mod reference;
mod reversal;
mod track;

pub use config::{
    DEFAULT_LOOP_LENGTH_IN_PINCH_DISTANCES, KeepRegion, RedundancyConfig, TimeWindow,
};
pub use prune::{Deletion, DeletionReason, Pruned, remove_redundancy, remove_redundancy_reference};

use serde::{Deserialize, Serialize};

use crate::path::PathSample;
use track::{Criteria, Track};

/// Why a path or a configuration cannot be processed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RedundancyError {
    /// A configuration value out of range, e.g. `pinch_distance_m must be > 0, got -1`.
    #[error("{field} {requirement}, got {got}")]
    Config {
        field: String,
        requirement: &'static str,
        got: String,
    },
    #[error("path sample {index}: {field} is {value}, not a finite number")]
    NotFinite {
        index: usize,
        field: &'static str,
        value: f64,
    },
    #[error(
        "path sample {index}: time {t_s} s is not after the previous sample's {previous_t_s} s"
    )]
    TimeNotIncreasing {
        index: usize,
        t_s: f64,
        previous_t_s: f64,
    },
    #[error("the path has {samples} samples; at most {max} can be indexed")]
    TooManySamples { samples: usize, max: usize },
    #[error("the reference finder cannot allocate the {samples} x {samples} distance matrix")]
    ReferenceTooLarge { samples: usize },
}

/// Two samples the path could be joined at: cutting deletes the samples
/// strictly between `i` and `j`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pinch {
    pub i: usize,
    pub j: usize,
    /// Distance between samples `i` and `j`: the jump the cut leaves.
    pub distance_m: f64,
    pub kind: PinchKind,
}

/// How the two samples of a [`Pinch`] meet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PinchKind {
    /// Closer than the pinch distance.
    Near,
    /// Segments `(i, i+1)` and `(j-1, j)` meet, and the samples are not near.
    Crossing,
}

/// For each sample `i` of the path, the farthest sample `j` it pinches with
/// whose cut deletes no protected sample; sorted by `i`. Grid hash, `O(n)`
/// expected. See the module docs for what counts.
pub fn find_pinches(
    path: &[PathSample],
    cfg: &RedundancyConfig,
) -> Result<Vec<Pinch>, RedundancyError> {
    let track = Track::new(path, cfg)?;
    Ok(fast::farthest_pinches(&track, &Criteria::new(cfg)))
}

/// The same as [`find_pinches`] by the paper's method: the full `n × n`
/// matrix of (squared) distances and an `O(n²)` crossing test. For tests and
/// benchmarks: 20 000 samples take 3.2 GB.
pub fn find_pinches_reference(
    path: &[PathSample],
    cfg: &RedundancyConfig,
) -> Result<Vec<Pinch>, RedundancyError> {
    let track = Track::new(path, cfg)?;
    reference::farthest_pinches(&track, &Criteria::new(cfg))
}
