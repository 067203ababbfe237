//! The mission as rehearsed on the twin (the plan the robot will run, and
//! the route it is scored against), the site it runs on, and the score of
//! a true path against that route.

use anyhow::Context;
use twindrive_kinematics::{DiffDriveParams, Pose};
use twindrive_mission::pipeline::PipelineSettings;
use twindrive_mission::plan::{MissionPlan, sha256_hex};
use twindrive_mission::redundancy::{RedundancyConfig, RouteProgress};
use twindrive_sim::{Scenario, Simulator};

/// The box on the site's route that the twin does not have.
pub const SITE_BOX: ([f64; 2], [f64; 2]) = ([1.9, 0.9], [2.1, 1.2]);

/// The default site: the twin's true wheel diameters and wheelbase scaled
/// by these (tyres worn unevenly, a heavier payload).
pub const SITE_SCALE: [f64; 3] = [1.004, 0.996, 1.01];

/// The mission as rehearsed on the twin, and the site it runs on.
pub struct Rehearsal {
    pub twin: Scenario,
    pub world_toml: Vec<u8>,
    pub site: Scenario,
    pub plan: MissionPlan,
    pub plan_json: Vec<u8>,
}

impl Rehearsal {
    /// Rehearses `twin`'s mission (its own controller, its full duration)
    /// and makes the plan with `calibrated` parameters.
    pub fn rehearse(
        twin: Scenario,
        world_toml: Vec<u8>,
        site: Scenario,
        calibrated: DiffDriveParams,
    ) -> anyhow::Result<Self> {
        let log = Simulator::new(twin.clone()).run(|_, _| {});
        let mut csv = Vec::new();
        twindrive_log::write_csv(&log, &mut csv)?;
        let settings = PipelineSettings {
            planner: Default::default(),
            redundancy: RedundancyConfig::with_pinch_distance(twin.robot.footprint_radius_m),
            filter: Default::default(),
            freedom: Default::default(),
        };
        let (plan, _) = twindrive_mission::pipeline::plan_from_log(
            &log,
            &sha256_hex(&csv),
            &calibrated,
            &twin,
            &settings,
            false,
        )
        .context("planning the rehearsal")?;
        let mut plan_json = serde_json::to_vec_pretty(&plan)?;
        plan_json.push(b'\n');
        Ok(Self {
            twin,
            world_toml,
            site,
            plan,
            plan_json,
        })
    }

    /// This rehearsal's plan with its freedom changed by `change` (its
    /// hash and its JSON renewed).
    pub fn with_freedom(
        &self,
        change: impl FnOnce(&mut twindrive_mission::plan::Freedom),
    ) -> anyhow::Result<Self> {
        let mut header = self.plan.header.clone();
        change(&mut header.freedom);
        let plan = MissionPlan::new(header, self.plan.samples.clone());
        plan.validate()?;
        let mut plan_json = serde_json::to_vec_pretty(&plan)?;
        plan_json.push(b'\n');
        Ok(Self {
            twin: self.twin.clone(),
            world_toml: self.world_toml.clone(),
            site: self.site.clone(),
            plan,
            plan_json,
        })
    }

    pub fn route(&self) -> Vec<[f64; 2]> {
        self.plan.samples.iter().map(|s| [s.x_m, s.y_m]).collect()
    }
}

/// The default site: `twin` with its true kinematics scaled by
/// [`SITE_SCALE`] and its own seed.
pub fn site_like(twin: &Scenario) -> Scenario {
    let mut site = twin.clone();
    let t = &mut site.robot.true_params;
    t.left_diameter_m *= SITE_SCALE[0];
    t.right_diameter_m *= SITE_SCALE[1];
    t.wheelbase_m *= SITE_SCALE[2];
    site.seed = twin.seed.wrapping_add(1_000);
    site
}

/// Coverage (percent of the route's points within the radius of the path)
/// and path error (mean and largest distance from the path to the route, m)
/// of a true path.
pub fn score(route: &mut RouteProgress, path: &[(f64, Pose)]) -> (f64, f64, f64) {
    let (mut sum, mut max, mut n) = (0.0, 0.0f64, 0usize);
    for (k, (_, p)) in path.iter().enumerate() {
        route.visit([p.x_m, p.y_m]);
        // The error changes little within ten steps.
        if k % 10 == 0 {
            let d = route.distance_m([p.x_m, p.y_m]);
            sum += d;
            max = max.max(d);
            n += 1;
        }
    }
    (100.0 * route.covered_fraction(), sum / n.max(1) as f64, max)
}
