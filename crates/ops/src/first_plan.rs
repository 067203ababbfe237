//! The signed plan a master starts with: `--signed` as given, or `--plan`
//! signed now; either resumes an upload an earlier run of this master
//! began and did not finish, when it carries the same plan.

use std::sync::Arc;

use anyhow::{Context, bail};
use twindrive_link::envelope::{
    Envelope, Supervision, Tolerances, peek_envelope, sha256_hex, sign_plan,
};
use twindrive_mission::plan::MissionPlan;
use twindrive_store::MasterArchive;
use twindrive_workflow::inputs::{parse_plan, since_epoch, world_bytes};

use crate::settings::MasterSettings;

/// The signed plan the master starts with, the plan inside it, and whether
/// it resumes an upload an earlier run of this master began.
pub struct FirstPlan {
    pub plan: Arc<MissionPlan>,
    pub plan_json: Vec<u8>,
    pub signed: Vec<u8>,
    pub counter: u64,
    /// The hash of the twin's world in its envelope.
    pub world_sha256: String,
    pub resume: bool,
}

/// `scenario` is the twin's site (`--scenario`, or the version of it kept
/// in `--site-maps`), whose hash the envelope carries.
pub fn first_plan(
    args: &MasterSettings,
    robot: &str,
    archive: &MasterArchive,
    scenario: Option<&std::path::Path>,
) -> anyhow::Result<FirstPlan> {
    // An upload this master began and did not finish is resumed when it
    // carries the same plan (a self-signed plan signs to new bytes each run).
    let pending = archive.upload_path();
    let unfinished = archive.unfinished_upload();
    let (signed, resume) = if let Some(path) = &args.signed {
        let bytes =
            std::fs::read(path).with_context(|| format!("--signed: reading {}", path.display()))?;
        let resume = unfinished.as_deref() == Some(&bytes[..]);
        (bytes, resume)
    } else {
        let path = args.plan.as_ref().context("--plan or --signed is needed")?;
        let plan_json =
            std::fs::read(path).with_context(|| format!("--plan: reading {}", path.display()))?;
        let same = unfinished.as_deref().is_some_and(|u| {
            twindrive_link::envelope::open_unchecked(u).is_ok_and(|j| j == plan_json)
                && peek_envelope(u).is_ok_and(|e| e.robot_id == robot)
        });
        if same {
            (unfinished.clone().expect("checked"), true)
        } else {
            let plan = parse_plan(&plan_json, path)?;
            let world = world_bytes(&plan.header.robot.scenario, scenario)?;
            let key = &args.key;
            let now = since_epoch()?;
            let envelope = Envelope::new(
                robot,
                now.as_millis() as u64,
                now.as_secs(),
                args.expires_in,
                sha256_hex(&world),
                Supervision {
                    dead_man_timeout_s: args.supervise,
                },
                Tolerances::default(),
            );
            let signed = sign_plan(key, &plan_json, envelope)
                .map_err(|e| anyhow::anyhow!("--plan {}: {e}", path.display()))?;
            (signed, false)
        }
    };
    if resume {
        eprintln!("master: resuming the upload in {}", pending.display());
    } else if unfinished.is_some() {
        eprintln!(
            "master: {} held an unfinished upload of another plan; starting this one",
            pending.display()
        );
    }
    // Errors name the file the signed plan came from.
    let source = match &args.signed {
        Some(path) => format!("--signed {}", path.display()),
        None => "the signed plan".to_string(),
    };
    let damaged = |e: &dyn std::fmt::Display| {
        anyhow::anyhow!("{source}: not a whole signed plan (damaged or cut short?): {e}")
    };
    let envelope = peek_envelope(&signed).map_err(|e| damaged(&e))?;
    if envelope.robot_id != robot {
        bail!(
            "{source} is for robot `{}`, not --robot {robot}",
            envelope.robot_id,
        );
    }
    // The plan inside, for the report and for continuations.
    let plan_json = twindrive_link::envelope::open_unchecked(&signed).map_err(|e| damaged(&e))?;
    let plan: MissionPlan = serde_json::from_slice(&plan_json)
        .with_context(|| format!("{source}: the plan document inside"))?;
    Ok(FirstPlan {
        plan: Arc::new(plan),
        plan_json,
        signed,
        counter: envelope.counter,
        world_sha256: envelope.world_sha256,
        resume,
    })
}
