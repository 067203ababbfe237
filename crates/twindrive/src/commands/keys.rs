//! `twindrive keygen` and `twindrive sign`: the master's key pair and signed
//! plans.

use std::io::Write;
use std::path::Path;

use anyhow::{Context, bail};
use twindrive_link::envelope::{
    Envelope, Supervision, private_key_pem, public_key_pem, read_private_key_pem, sha256_hex,
    sign_plan,
};

use crate::cli::SignArgs;

/// Writes `DIR/master.key` (0600) and `DIR/master.pub`; never replaces a key.
pub fn keygen(dir: &Path) -> anyhow::Result<()> {
    let (private, public) = (dir.join("master.key"), dir.join("master.pub"));
    for p in [&private, &public] {
        if p.exists() {
            bail!(
                "{} exists: twindrive never replaces a key (move it away first)",
                p.display()
            );
        }
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let key = twindrive_store::generate_key()
        .map_err(|e| anyhow::anyhow!("no randomness for a key: {e}"))?;
    write_new(&private, private_key_pem(&key).as_bytes(), 0o600)?;
    if let Err(e) = write_new(
        &public,
        public_key_pem(&key.verifying_key()).as_bytes(),
        0o644,
    ) {
        // No half pair.
        let _ = std::fs::remove_file(&private);
        return Err(e);
    }
    writeln!(
        std::io::stdout().lock(),
        "wrote {} (keep it secret) and {} (give it to robots: --trust)",
        private.display(),
        public.display()
    )?;
    Ok(())
}

/// Writes a file that must not exist yet, synced, with the given mode.
fn write_new(path: &Path, bytes: &[u8], mode: u32) -> anyhow::Result<()> {
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(mode);
    }
    #[cfg(not(unix))]
    let _ = mode;
    let mut f = options
        .open(path)
        .with_context(|| format!("creating {}", path.display()))?;
    f.write_all(bytes)
        .and_then(|_| f.sync_all())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

pub fn sign(args: &SignArgs) -> anyhow::Result<()> {
    let plan_json =
        std::fs::read(&args.plan).with_context(|| format!("reading {}", args.plan.display()))?;
    let key_text = std::fs::read_to_string(&args.key)
        .with_context(|| format!("--key: reading {}", args.key.display()))?;
    let key = read_private_key_pem(&key_text)
        .map_err(|e| anyhow::anyhow!("{}: {e}", args.key.display()))?;
    let plan = crate::flags::parse_plan(&plan_json, &args.plan)?;
    let world = crate::flags::world_bytes(&plan.header.robot.scenario, args.scenario.as_deref())?;
    let twin = crate::verification::twin_of(&plan, args.scenario.as_deref())?;
    crate::verification::check_before_sending(&plan, &twin, args.allow_failed_verification)?;
    let now = crate::flags::since_epoch()?;
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
    let (dir, _, _) = crate::output::split_out_path(&args.out, "plan")?;
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    twindrive_store::write_durably(&args.out, &signed)
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
