//! The mission pipeline (paper section 5): turn a mission run on the twin
//! into a clean plan for the real robot.
//!
//! One algorithm per module, each usable alone:
//! - [`path`]: the path type shared by every stage;
//! - [`planner`]: the executed path from encoder counts and calibrated parameters;
//! - [`redundancy`]: pinch points, self-crossings and reversals; loop removal;
//! - [`control`]: body and wheel speeds along a path (inverse kinematics);
//! - [`spikes`]: control spikes, their removal by re-interpolation, and
//!   time-optimal re-timing;
//! - [`plan`]: the mission plan (`twindrive-plan`, data only) with what needs
//!   the simulator: its range model, its map as a world, the TUM export;
//! - [`retime`]: the fastest timing of a path under wheel speed and acceleration limits;
//! - [`freedom`]: the robot's corridor and keep-out zones along a plan;
//! - [`grid_search`]: the shortest way for a circular robot over a grid of
//!   clearances (the twin's continuations and the robot's local planner);
//! - [`distance_transform`]: the exact Euclidean distance transform of a grid;
//! - [`site_grid`]: the twin's site as a grid of footprint clearances;
//! - [`goals`]: the operator's waypoints for a rehearsal (`mission.toml`);
//! - [`itinerary`]: the goals as the stops of one way (waypoints, sweeps,
//!   home), and the record of what a drive met and when;
//! - [`kept`]: whether a path keeps the operator's goals;
//! - [`route`]: goal-level planning, the way through the operator's waypoints;
//! - [`follower`]: driving that way on the twin;
//! - [`coverage`]: sweeping an area the operator drew;
//! - [`verify`]: replaying a plan on the twin, open and closed loop;
//! - [`pipeline`]: the whole chain on one mission log.
//!
//! REP-103 frames, SI units, radians throughout.

pub mod control;
pub mod coverage;
pub mod detour;
pub mod distance_transform;
mod error;
pub mod follower;
pub mod freedom;
pub mod goals;
pub mod grid_search;
pub mod itinerary;
pub mod kept;
pub mod path;
pub mod pipeline;
pub mod plan;
pub mod planner;
pub mod redundancy;
pub mod retime;
pub mod route;
pub mod site_grid;
pub mod spikes;
pub mod verify;

pub use error::PipelineError;
pub use path::{PathSample, path_length_m};
