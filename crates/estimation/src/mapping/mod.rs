//! The site's map from the robot's own scans: each scan located against
//! the map drawn so far by the project's one scan matcher, from the pose
//! the calibrated odometry predicts ([`Mapper`]), then drawn into a
//! log-odds occupancy grid ([`LogOddsGrid`]) that keeps unknown what no
//! beam reached. [`score`] measures a map against true walls.

mod grid;
mod mapper;
mod placement;
mod score;
#[cfg(test)]
mod tests;

pub use grid::{Beam, CellState, FREE_BELOW, LogOdds, LogOddsGrid, OCCUPIED_ABOVE};
pub use mapper::{Located, Mapper, Mapping, MappingSettings, MatchFailure, Surfaces, map_drive};
pub use placement::{Placement, PlacementSettings, drive_agreement, place};
pub use score::{MapScore, distance_to_segment, score};
