//! Scenarios compiled into the binary, so `twindrive demo` runs from any
//! directory. The files themselves live in the repository's `scenarios/`.

use std::path::Path;

use crate::{Scenario, SimError};

/// `scenarios/wall_following.toml`: the paper's case study.
pub const WALL_FOLLOWING: &str = include_str!("../../../scenarios/wall_following.toml");
/// `scenarios/calibration_drive.toml`: circles at several wheel-speed ratios.
pub const CALIBRATION_DRIVE: &str = include_str!("../../../scenarios/calibration_drive.toml");

/// Names and texts of the built-in scenarios that need no other files.
pub const ALL: [(&str, &str); 2] = [
    ("wall_following", WALL_FOLLOWING),
    ("calibration_drive", CALIBRATION_DRIVE),
];

/// Resolves a built-in scenario by name.
pub fn load(name: &str) -> Option<Result<Scenario, SimError>> {
    ALL.iter()
        .find(|(n, _)| *n == name)
        .map(|(n, text)| Scenario::from_toml(text, Path::new(&format!("<built-in>/{n}.toml"))))
}
