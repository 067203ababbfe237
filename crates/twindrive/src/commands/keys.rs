//! `twindrive keygen`, `twindrive certs` and `twindrive sign`: key pairs,
//! a fleet's TLS certificates, and signed plans.

use std::io::Write;
use std::path::Path;

use anyhow::Context;
use twindrive_link::envelope::{Envelope, Supervision, sha256_hex, sign_plan};

use crate::cli::SignArgs;

/// `twindrive keygen`: a new key pair in `dir`, the master's or robot
/// `robot`'s.
pub fn keygen(dir: &Path, robot: Option<&str>) -> anyhow::Result<()> {
    let (private, public, whom) = match robot {
        None => {
            let (private, public) = twindrive_store::keys::write_key_pair(dir)?;
            (private, public, "robots: --trust")
        }
        Some(id) => {
            let (private, public) = twindrive_store::keys::write_named_key_pair(dir, id)?;
            (private, public, "the master: --trust-robot")
        }
    };
    writeln!(
        std::io::stdout().lock(),
        "wrote {} (keep it secret) and {} (give it to {whom})",
        private.display(),
        public.display()
    )?;
    Ok(())
}

/// `twindrive certs`: a fleet's CA, certificates and TLS configurations.
pub fn certs(request: twindrive_ops::certs::CertsRequest) -> anyhow::Result<()> {
    crate::flags::check_distinct_robots(&request.robots)?;
    let written = twindrive_ops::certs::write(&request)?;
    writeln!(
        std::io::stdout().lock(),
        "wrote {} files into {}: {} (keep ca.key and every .key secret; give each process its .json5 with --zenoh-config)",
        written.len(),
        request.out.display(),
        written.join(", ")
    )?;
    Ok(())
}

pub fn sign(args: &SignArgs) -> anyhow::Result<()> {
    let plan_json =
        std::fs::read(&args.plan).with_context(|| format!("reading {}", args.plan.display()))?;
    let key = crate::flags::master_key(&args.key, std::slice::from_ref(&args.robot), None)?;
    let plan = twindrive_workflow::inputs::parse_plan(&plan_json, &args.plan)?;
    let world = twindrive_workflow::inputs::world_bytes(
        &plan.header.robot.scenario,
        args.scenario.as_deref(),
    )?;
    let twin = twindrive_workflow::verification::twin_of(&plan, args.scenario.as_deref())?;
    twindrive_workflow::verification::check_before_sending(
        &plan,
        &twin,
        args.allow_failed_verification,
    )?;
    let now = twindrive_workflow::inputs::since_epoch()?;
    let envelope = Envelope::new(
        &args.robot,
        args.counter.unwrap_or(now.as_millis() as u64),
        now.as_secs(),
        args.expires_in,
        sha256_hex(&world),
        Supervision {
            dead_man_timeout_s: args.supervise,
        },
        Default::default(),
    );
    let signed = sign_plan(&key, &plan_json, envelope)
        .map_err(|e| anyhow::anyhow!("{}: {e}", args.plan.display()))?;
    // One file: written beside its place, synced, renamed (other signed
    // plans in the directory are left alone).
    let (dir, _, _) = twindrive_files::split_out_path(&args.out, "plan")?;
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    twindrive_files::write_durably(&args.out, &signed)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let env = twindrive_link::envelope::peek_envelope(&signed).expect("just signed");
    writeln!(
        std::io::stdout().lock(),
        "signed plan {} for robot {} (counter {}, valid until Unix {}), {} bytes ({} of plan JSON) -> {}",
        &env.plan_sha256[..16],
        env.robot_id,
        env.counter,
        env.expires_unix_s,
        signed.len(),
        plan_json.len(),
        args.out.display()
    )?;
    Ok(())
}
