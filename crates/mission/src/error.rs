//! What can go wrong in the pipeline.

/// A pipeline input or setting that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PipelineError {
    #[error("the mission log has no steps")]
    EmptyLog,
    #[error("the mission log has {0} encoder sample(s); the planner needs at least 2")]
    NoEncoderData(usize),
    /// A number or setting out of range (the plan's own check, shared).
    #[error(transparent)]
    Value(#[from] twindrive_plan::PlanError),
    #[error("{0}")]
    Infeasible(String),
    #[error(transparent)]
    Redundancy(#[from] crate::redundancy::RedundancyError),
}
