//! Shared helpers for the simulator's integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use twindrive_sim::{Scenario, SimError};

pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

pub fn scenario_path(name: &str) -> PathBuf {
    repo_root().join("scenarios").join(name)
}

pub fn load(name: &str) -> Scenario {
    Scenario::load(&scenario_path(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// A 10 m room with an ordinary robot, plus `world` and `controller` TOML.
pub fn scenario_toml(
    extra_world: &str,
    controller: &str,
    duration_s: f64,
    slip_std: f64,
) -> String {
    format!(
        r#"
name = "test"
[simulation]
duration_s = {duration_s}
dt_s = 0.01
seed = 11
[world]
polylines = [{{ points = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]], closed = true }}]
{extra_world}
[robot]
start = {{ x_m = 5.0, y_m = 5.0, heading_rad = 0.3 }}
footprint_radius_m = 0.15
max_wheel_speed_rad_s = 12.0
max_wheel_accel_rad_s2 = 30.0
slip_std = {slip_std}
true_params = {{ left_diameter_m = 0.0652, right_diameter_m = 0.0665, wheelbase_m = 0.2678 }}
nominal_params = {{ left_diameter_m = 0.066, right_diameter_m = 0.066, wheelbase_m = 0.26 }}
[encoders]
ticks_per_rev = 512
[controller]
{controller}
"#
    )
}

pub fn parse(text: &str) -> Result<Scenario, SimError> {
    Scenario::from_toml(text, Path::new("test.toml"))
}
