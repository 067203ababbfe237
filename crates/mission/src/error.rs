//! What can go wrong in the pipeline.

/// A pipeline input or setting that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PipelineError {
    #[error("the mission log has no steps")]
    EmptyLog,
    #[error("the mission log has {0} encoder sample(s); the planner needs at least 2")]
    NoEncoderData(usize),
    #[error("{what} at sample {index} is not a finite number")]
    NonFinite { what: &'static str, index: usize },
    #[error("sample {index}: time {t_s} s does not increase (previous {previous_s} s)")]
    TimeNotIncreasing {
        index: usize,
        t_s: f64,
        previous_s: f64,
    },
    #[error("{field} must be a finite number > 0, got {value}")]
    BadSetting { field: &'static str, value: f64 },
    #[error("{0}")]
    Infeasible(String),
    #[error(transparent)]
    Redundancy(#[from] crate::redundancy::RedundancyError),
}
