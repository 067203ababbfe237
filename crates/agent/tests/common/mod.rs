//! The case-study plan and site scenarios the agent tests share.
#![allow(dead_code)]

use std::sync::{Arc, OnceLock};

use twindrive_kinematics::DiffDriveParams;
use twindrive_mission::pipeline::{self, PipelineSettings};
use twindrive_mission::plan::MissionPlan;
use twindrive_mission::redundancy::RedundancyConfig;
use twindrive_sim::{Scenario, Simulator};

pub const CALIBRATED: DiffDriveParams = DiffDriveParams {
    left_diameter_m: 0.0652,
    right_diameter_m: 0.0665,
    wheelbase_m: 0.2678,
};

pub fn twin() -> Scenario {
    twindrive_sim::builtin::load("wall_following")
        .unwrap()
        .unwrap()
}

/// The case-study plan, made on the twin (as `twindrive plan` makes it).
pub fn plan() -> &'static Arc<MissionPlan> {
    static PLAN: OnceLock<Arc<MissionPlan>> = OnceLock::new();
    PLAN.get_or_init(|| Arc::new(plan_of(&twin(), &CALIBRATED)))
}

/// The plan `twindrive plan` makes from a run of `scenario` on its twin,
/// for a robot calibrated to `calibrated`.
pub fn plan_of(scenario: &Scenario, calibrated: &DiffDriveParams) -> MissionPlan {
    let log = Simulator::new(scenario.clone()).run(|_, _| {});
    let settings = PipelineSettings {
        planner: Default::default(),
        redundancy: RedundancyConfig::with_pinch_distance(0.15),
        filter: Default::default(),
        freedom: Default::default(),
    };
    pipeline::plan_from_log(
        &log,
        &"0".repeat(64),
        calibrated,
        scenario,
        &settings,
        false,
    )
    .unwrap()
    .0
}

/// The site: the twin's world, plus what the twin does not know.
pub fn site(extra_world: &str) -> Scenario {
    let text = twindrive_sim::builtin::WALL_FOLLOWING
        .replace("[world]\n", &format!("[world]\n{extra_world}\n"));
    Scenario::from_toml(&text, std::path::Path::new("<site>.toml")).unwrap()
}
