//! The case-study plan and site scenarios the agent tests share.
#![allow(dead_code)]

use std::sync::OnceLock;

use twindrive_kinematics::DiffDriveParams;
use twindrive_mission::pipeline::{self, PipelineSettings};
use twindrive_mission::plan::{MissionPlan, PlanHeader, PlanSample, RobotInfo};
use twindrive_mission::redundancy::RedundancyConfig;
use twindrive_mission::retime::WheelLimits;
use twindrive_sim::{Scenario, SensorModel, Simulator};

const CALIBRATED: DiffDriveParams = DiffDriveParams {
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
pub fn plan() -> &'static MissionPlan {
    static PLAN: OnceLock<MissionPlan> = OnceLock::new();
    PLAN.get_or_init(|| {
        let scenario = twin();
        let log = Simulator::new(scenario.clone()).run(|_, _| {});
        let limits = WheelLimits {
            max_speed_rad_s: log.header.max_wheel_speed_rad_s,
            max_accel_rad_s2: log.header.max_wheel_accel_rad_s2,
        };
        let settings = PipelineSettings {
            planner: Default::default(),
            redundancy: RedundancyConfig::with_pinch_distance(0.15),
            filter: Default::default(),
        };
        let stages = pipeline::run(&log, &CALIBRATED, &limits, &settings).unwrap();
        let mut model = SensorModel::new(&scenario);
        let mut ranges = vec![0.0; model.beams()];
        let samples = stages
            .filtered
            .samples
            .iter()
            .zip(&stages.filtered.commands)
            .map(|(p, c)| {
                let bump = model.read(&p.pose, &mut ranges);
                PlanSample::new(p, c, ranges.clone(), bump)
            })
            .collect();
        MissionPlan::new(
            PlanHeader {
                robot: RobotInfo {
                    scenario: "wall_following".into(),
                    footprint_radius_m: 0.15,
                    ticks_per_rev: log.header.ticks_per_rev,
                    range_sensors: scenario
                        .range_sensors
                        .iter()
                        .map(|s| s.info.clone())
                        .collect(),
                },
                calibrated: CALIBRATED,
                limits,
                time_step_s: stages.period_s,
                start: log.header.start,
                source_log_sha256: "0".repeat(64),
                settings: serde_json::json!({}),
                summary: serde_json::json!({}),
            },
            samples,
        )
    })
}

/// The site: the twin's world, plus what the twin does not know.
pub fn site(extra_world: &str) -> Scenario {
    let text = twindrive_sim::builtin::WALL_FOLLOWING
        .replace("[world]\n", &format!("[world]\n{extra_world}\n"));
    Scenario::from_toml(&text, std::path::Path::new("<site>.toml")).unwrap()
}
