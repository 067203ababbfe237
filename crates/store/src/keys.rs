//! Fresh ed25519 keys, and the master's key pair on disk. Their PEM forms
//! are `twindrive_link::envelope`'s.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use ed25519_dalek::SigningKey;
use twindrive_link::envelope::{private_key_pem, public_key_pem};

/// A fresh key pair from the operating system's randomness.
pub fn generate_key() -> Result<SigningKey, getrandom::Error> {
    let mut secret = [0u8; 32];
    getrandom::fill(&mut secret)?;
    Ok(SigningKey::from_bytes(&secret))
}

/// Writes a new key pair, `dir/master.key` (0600) and `dir/master.pub`,
/// and returns their paths; never replaces a key, never leaves half a pair.
pub fn write_key_pair(dir: &Path) -> anyhow::Result<(PathBuf, PathBuf)> {
    write_named_key_pair(dir, "master")
}

/// [`write_key_pair`] as `dir/NAME.key` and `dir/NAME.pub` (a robot's:
/// its id).
pub fn write_named_key_pair(dir: &Path, name: &str) -> anyhow::Result<(PathBuf, PathBuf)> {
    let (private, public) = (
        dir.join(format!("{name}.key")),
        dir.join(format!("{name}.pub")),
    );
    for p in [&private, &public] {
        if p.exists() {
            bail!(
                "{} exists: twindrive never replaces a key (move it away first)",
                p.display()
            );
        }
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let key = generate_key().map_err(|e| anyhow::anyhow!("no randomness for a key: {e}"))?;
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
    Ok((private, public))
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
