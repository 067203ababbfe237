//! A decoupled mission in one process, in virtual time: the operator
//! (master and twin) and the robot agent, both keeping their state in
//! memory, joined by an emulated link. The demo and the experiments run
//! the code the `twindrive master` and `twindrive robot` processes run.

use std::sync::Arc;

use anyhow::Context;
use twindrive_agent::backend::RobotBackend;
use twindrive_agent::master::{Master, MasterConfig};
use twindrive_agent::operator::{Operator, OperatorConfig};
use twindrive_agent::robot::{AgentConfig, RobotAgent};
use twindrive_agent::store::MemoryRobotStore;
use twindrive_agent::twin::Twin;
use twindrive_link::emulator::LinkProfile;
use twindrive_link::envelope::{Envelope, SigningKey, Supervision, Tolerances, sign_plan};
use twindrive_link::upload::MemoryStore;
use twindrive_link::vtime::VirtualLink;
use twindrive_mission::plan::{MissionPlan, sha256_hex};
use twindrive_sim::Scenario;

/// Unix time at the start of the virtual run (the plan's validity window
/// is checked against it).
pub const UNIX_AT_ZERO_S: f64 = 1.8e9;

/// A decoupled mission in one process: the operator (master and twin) and
/// the robot agent joined by an emulated link in virtual time, the plan
/// signed and its upload started.
pub struct Mission<B: RobotBackend> {
    pub op: Operator<MemoryStore>,
    pub robot: RobotAgent<B, MemoryRobotStore>,
    pub link: VirtualLink,
    pub signed_bytes: usize,
}

impl<B: RobotBackend> Mission<B> {
    /// `plan` (its JSON `plan_json`), rehearsed on `twin` whose world file
    /// is `world_toml`, signed with `key` for robot `rover` and on its way
    /// over `profile` (seeded with `seed`) to a robot driving `backend`,
    /// which keeps its state in memory. The operator replans on a
    /// hand-back.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        plan: &MissionPlan,
        plan_json: &[u8],
        twin: &Scenario,
        world_toml: &[u8],
        key: &SigningKey,
        profile: &LinkProfile,
        seed: u64,
        backend: B,
    ) -> anyhow::Result<Self> {
        let robot_id = "rover";
        let world_sha256 = sha256_hex(world_toml);
        let envelope = Envelope::new(
            robot_id,
            1,
            UNIX_AT_ZERO_S as u64,
            86_400,
            world_sha256.clone(),
            Supervision {
                dead_man_timeout_s: None,
            },
            Tolerances::default(),
        );
        let signed = sign_plan(key, plan_json, envelope).context("signing the plan")?;
        let signed_bytes = signed.len();
        // Every message sealed, as over zenoh: the robot's key from the seed.
        let (master_end, robot_end) = twindrive_link::secure::memory_pair(
            key,
            &twindrive_link::secure::key_from_seed(seed, 1),
            robot_id,
        );
        let link = VirtualLink::symmetric(profile, seed).sealed(master_end, robot_end);
        let master = Master::new(
            robot_id,
            MasterConfig::for_link(Some(profile), 8_000.0),
            MemoryStore::default(),
        );
        let mut op = Operator::new(
            master,
            Some(Twin::new(twin.clone(), plan.header.calibrated)),
            Some(key.clone()),
            OperatorConfig::replanning(robot_id, 1, world_sha256, UNIX_AT_ZERO_S),
        );
        let mut config = AgentConfig::new(robot_id, vec![key.verifying_key()]);
        config.unix_time_at_zero_s = UNIX_AT_ZERO_S;
        let robot = RobotAgent::new(config, backend, MemoryRobotStore::default())
            .context("the robot agent")?;
        op.start(Arc::new(plan.clone()), signed, 1, false, 0);
        Ok(Self {
            op,
            robot,
            link,
            signed_bytes,
        })
    }
}
