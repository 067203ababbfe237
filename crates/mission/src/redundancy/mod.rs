//! Redundancy removal (paper section 5, Fig. 7): delete what the robot need
//! not drive again, and never the ground it explored.
//!
//! # What is redundant
//!
//! The paper's definition: what can be removed "without causing a change
//! to the robot's exploration route that would result in the oversight of
//! valuable information". Here that is a rule on **coverage**: the places
//! the path passed within the coverage radius `r` (`coverage_radius_m`,
//! default: the pinch distance). A cut is allowed only when every sample it
//! deletes stays within `r` of the path that remains. Where two passes
//! cover the same ground, the **first** is kept and the later retrace cut.
//!
//! The cuts the user's [`RedundancyConfig`] allows:
//! - a **pinch** is a pair of samples `i < j` that the path could join:
//!   either they are closer than `pinch_distance_m` (strictly,
//!   `j >= i + 2`, kind [`PinchKind::Near`]), or the segments `(i, i+1)` and
//!   `(j-1, j)` meet (a true self-crossing of the polyline, `j >= i + 3`,
//!   kind [`PinchKind::Crossing`]; this catches crossings between sparse
//!   samples that are never near one another); and the path from `i` to `j`
//!   is a loop worth the name: at least `min_loop_length_m` long (default:
//!   [`DEFAULT_LOOP_LENGTH_IN_PINCH_DISTANCES`] pinch distances, so a
//!   straight or gently curving stretch never pinches itself) and lasting at
//!   least `min_loop_duration_s` (by the input's time stamps);
//! - with `reversing_is_redundant` (the default), each "bump and back up"
//!   is a **kink**: a maximal run of samples with `v_m_s < 0` together with
//!   the forward stretch it retraces;
//! - the **trailing retrace**: the end of the mission, when it only passes
//!   ground already covered. By default the plan ends where the last new
//!   ground was covered; with `keep_end` it reaches the mission's final pose
//!   along the recorded route;
//! - samples in `keep_regions` or `keep_windows` (places worth looking at
//!   twice), the first sample, the last with `keep_end`, and — when
//!   reversing is *not* redundant — every reversing sample are
//!   **protected**: no cut deletes them.
//!
//! Cutting a pinch or kink `(i, j)` deletes the samples strictly between
//! `i` and `j`; `i` and `j` stay, so the path jumps by less than the pinch
//! distance (for a crossing, across the crossing point).
//!
//! # Algorithm
//!
//! One sweep along the path (`prune.rs`). At each kept sample `i` it takes
//! the kink that starts there, or else the farthest pinch back to `i`, if
//! its deleted samples are all within `r` of the kept path up to `i`, and
//! goes on from the cut's end. A cut that would drop ground gives way to the
//! farthest cut that ends at or before the first sample it would drop. The
//! first refused cut of each overlapping group is measured (one pass over
//! the path in all) and listed with the metres it would have dropped, if
//! any: a refused cut that drops nothing (only a later pass covers what it
//! would delete) is not listed, and the refusals inside its reach are not
//! measured. A pinch that is little more than a kink
//! (the path it cuts around the kink is shorter than a loop) waits for the
//! kink, so the turn after a back-up stays in the plan. Witnesses lie before `i`, where
//! no later cut reaches, so the coverage checked is the coverage the plan
//! has. Once past the last new ground (the last sample farther than `r`
//! from the path that ends `2 r` metres, along the path, before it) and the
//! last protected sample, the first sample whose kept path covers everything
//! after it ends the path.
//!
//! The rule is checked at the samples: on a path sampled more sparsely than
//! `r`, a deleted segment can pass farther than `r` from what remains though
//! its ends do not. [`route_coverage`] measures along the segments, so a plan
//! made from such a path reports what it lost.
//!
//! The pinch finders answer "the farthest partner of `i` up to `hi`":
//! [`find_pinches`] indexes the samples in a uniform grid hash with cells
//! one pinch distance wide (a hand-written table of 8×8-cell tiles; each
//! cell's entries in one flat array, in index order). A sample's partners
//! lie in the 3×3 cells around it, so the farthest one is the first hit
//! scanning each cell down from `hi`, and the scan stops where the path
//! from `i` is too short to be a loop; a sample whose 3×3 cells hold
//! nothing that far along is settled by one look-up. Segments are found
//! through the same grid: segment `(b, b+1)` is anchored at sample `b` and,
//! if longer than 0.45 cells, at points along it, so two segments that meet
//! have anchors in neighbouring cells. Runs of samples at one position
//! (standing still, turning in place) are one grid entry.
//!
//! Coverage (`coverage.rs`) has a grid of its own, cells 1.25 `r` wide,
//! holding each pass of the path through a cell as one run with its box.
//! The kept path only grows as the sweep goes on, so a sample once covered
//! stays covered, and one found uncovered is tested again only against what
//! was added since: each sample is tested through the grid about once.
//!
//! [`find_pinches_reference`] is the paper's method: it materialises the
//! full `n × n` matrix of squared distances and tests every segment pair, in
//! `O(n²)` time and memory; [`remove_redundancy_reference`] sweeps with it
//! and tests coverage against every piece of path. The tests compare the
//! fast and the reference results on random paths; both share the
//! floating-point predicates (`geometry.rs`), so they agree to the bit.
//!
//! The sweep is `O(n)` expected on ordinary paths (grid builds are a hash
//! insert per sample and a counting sort). The worst case is a path that
//! lingers at many *distinct* points near another place where it also
//! lingers: each sample there scans the other place's samples.
//!
//! [`route_coverage`] measures a finished plan: the route's length within
//! `r` of the plan, and the stretches it leaves uncovered.
//! [`RouteProgress`] follows a route being driven on the same grid: which
//! of it a robot has passed within `r` of, and how far a pose is from it.
//!
//! Lengths are along the polyline, durations by the input's time stamps.

mod config;
mod coverage;
mod fast;
mod geometry;
mod grid;
mod prune;
mod reference;
mod reversal;
mod route;
mod track;

pub use config::{
    DEFAULT_LOOP_LENGTH_IN_PINCH_DISTANCES, KeepRegion, RedundancyConfig, TimeWindow,
};
pub use coverage::{RouteCoverage, UncoveredStretch, route_coverage};
pub use prune::{
    Deletion, DeletionReason, Pruned, RefusedCut, remove_redundancy, remove_redundancy_reference,
};
pub use route::RouteProgress;

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

/// The finders' one question.
pub(super) trait PinchFinder {
    /// The farthest `j` in `i + 2..=hi` that pinches `i` (see the module
    /// docs); calls come with `i` never decreasing.
    fn farthest(&mut self, i: usize, hi: usize) -> Option<Pinch>;
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
