//! The robot side, without I/O: the [`backend::RobotBackend`] boundary (a
//! simulator running the robot's site today) and the [`executive`] that
//! drives an accepted plan on its own, with every stop decided locally.

pub mod backend;
pub mod executive;
