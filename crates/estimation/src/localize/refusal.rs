//! Why the matcher gives no pose: said in words, and counted by kind.

use std::fmt;

/// A match refused, with the numbers that decided it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Refusal {
    /// Too few valid readings to match at all (dropouts, max-range returns,
    /// an open space).
    TooFewPoints { points: usize, needed: usize },
    /// Too few readings fall on the reference: the views do not overlap, or
    /// the prior is far off.
    TooFewInliers { inliers: usize, needed: usize },
    /// The readings sit too far from the reference on average: a wrong
    /// alignment, or a scene that changed.
    RmsTooLarge { rms_m: f64, max_m: f64 },
    /// The readings do not pin the pose along `direction` (x, y in m,
    /// heading in rad; unit length with the heading in metres at the
    /// readings' range): a corridor, a single wall.
    Degenerate {
        direction: [f64; 3],
        ratio: f64,
        min_ratio: f64,
    },
}

impl Refusal {
    /// Every kind, in the order reports list them.
    pub const KINDS: [&'static str; 4] = [
        "too few points",
        "too few inliers",
        "residuals too large",
        "degenerate",
    ];

    /// A short name for counting refusals by reason (one of [`Self::KINDS`]).
    pub fn kind(&self) -> &'static str {
        match self {
            Self::TooFewPoints { .. } => Self::KINDS[0],
            Self::TooFewInliers { .. } => Self::KINDS[1],
            Self::RmsTooLarge { .. } => Self::KINDS[2],
            Self::Degenerate { .. } => Self::KINDS[3],
        }
    }
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::TooFewPoints { points, needed } => write!(
                f,
                "too few points: {points} valid readings, {needed} needed"
            ),
            Self::TooFewInliers { inliers, needed } => write!(
                f,
                "too few inliers: {inliers} readings fall on the reference, {needed} needed \
                 (the views do not overlap, or the prior is far off)"
            ),
            Self::RmsTooLarge { rms_m, max_m } => write!(
                f,
                "residuals too large: the readings sit {:.1} cm from the reference (RMS), \
                 more than {:.1} cm",
                rms_m * 100.0,
                max_m * 100.0
            ),
            Self::Degenerate {
                direction,
                ratio,
                min_ratio,
            } => {
                let along = if direction[2].abs() > direction[0].hypot(direction[1]) {
                    "the heading".to_string()
                } else {
                    format!(
                        "the direction ({:+.2}, {:+.2}) of the sensor's frame",
                        direction[0], direction[1]
                    )
                };
                write!(
                    f,
                    "degenerate: the readings do not pin {along} (a corridor or a single \
                     wall; weakest information {ratio:.1e} of the strongest, {min_ratio:.0e} needed)"
                )
            }
        }
    }
}

impl std::error::Error for Refusal {}
