//! The operator's offline steps on the twin, each into an output directory
//! written whole or not at all, as the commands and the demo run them:
//!
//! - [`simulate`]: a scenario's run (log, ground truth, summary, figures);
//! - [`rehearse`]: a rehearsal from goals (the way planned and driven on
//!   the twin), written as a run is;
//! - [`plan`]: the mission pipeline from a log to a hashed plan, with an
//!   MCAP of every stage and the paper's pipeline figures;
//! - [`verify`]: the plan replayed on the twin, the verdict and the overlay;
//! - [`verification`]: the check every plan passes before it is sent;
//! - [`figures`]: the figures of a run and of the pipeline;
//! - [`inputs`]: plan files and the twin's world, read and checked.

pub mod figures;
pub mod inputs;
pub mod plan;
pub mod rehearse;
pub mod simulate;
pub mod verification;
pub mod verify;
