//! A link's epochs on disk ([`twindrive_link::secure::EpochStore`]): one
//! small JSON file per peer key, `{"epoch": E, "peer_floor": F}`, written
//! whole (temporary file, synced, renamed) under an exclusive lock held
//! only while it is read and written, so two processes with the same key
//! never take the same epoch.

use std::fs::File;
use std::path::{Path, PathBuf};

use anyhow::Context;
use serde::{Deserialize, Serialize};
use twindrive_link::envelope::{SigningKey, VerifyingKey};
use twindrive_link::secure::{Channel, EpochStore, Peers, Role};

#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct State {
    epoch: u32,
    peer_floor: u32,
}

/// The epochs of one link, kept in `path` (its `.lock` beside it).
#[derive(Debug)]
pub struct EpochFile {
    path: PathBuf,
    lock: PathBuf,
}

impl EpochFile {
    /// The file for the link with `peer` (its name is `prefix` and the
    /// key's fingerprint) in `dir`, created with the directory on first
    /// use. Fails now if the directory cannot be written.
    pub fn for_peer(dir: &Path, prefix: &str, peer: &VerifyingKey) -> std::io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        let name = format!("{prefix}-{}", fingerprint(peer));
        let file = Self {
            path: dir.join(format!("{name}.json")),
            lock: dir.join(format!("{name}.lock")),
        };
        file.locked(|_| Ok(None))?;
        Ok(file)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Runs `change` on the state under the lock; writes what it returns.
    fn locked(
        &self,
        change: impl FnOnce(State) -> std::io::Result<Option<State>>,
    ) -> std::io::Result<State> {
        let lock = File::options()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&self.lock)?;
        lock.lock()?;
        let state = self.read()?;
        let result = match change(state)? {
            Some(next) => {
                let json = serde_json::to_vec(&next).expect("two numbers serialise");
                twindrive_files::write_durably(&self.path, &json).map(|()| next)
            }
            None => Ok(state),
        };
        drop(lock);
        result
    }

    fn read(&self) -> std::io::Result<State> {
        match std::fs::read(&self.path) {
            Ok(bytes) => serde_json::from_slice(&bytes).map_err(|e| {
                std::io::Error::other(format!(
                    "{}: not a link state (epoch, peer_floor): {e}",
                    self.path.display()
                ))
            }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(State::default()),
            Err(e) => Err(e),
        }
    }

    fn context(&self, e: std::io::Error) -> String {
        format!("{}: {e}", self.path.display())
    }
}

impl EpochStore for EpochFile {
    fn next_epoch(&mut self, at_least: u32) -> Result<u32, String> {
        self.locked(|mut s| {
            s.epoch = s
                .epoch
                .checked_add(1)
                .ok_or_else(|| std::io::Error::other("the epoch counter is exhausted"))?
                .max(at_least)
                .max(clock_epoch());
            Ok(Some(s))
        })
        .map(|s| s.epoch)
        .map_err(|e| self.context(e))
    }

    fn peer_floor(&self) -> u32 {
        // Unreadable: as if every epoch had been seen (refuse, never risk
        // a replay); the error shows when the floor is raised.
        self.read().map_or(u32::MAX, |s| s.peer_floor)
    }

    fn raise_peer_floor(&mut self, epoch: u32) -> Result<(), String> {
        self.locked(|mut s| {
            if epoch <= s.peer_floor {
                return Ok(None);
            }
            s.peer_floor = epoch;
            Ok(Some(s))
        })
        .map(|_| ())
        .map_err(|e| self.context(e))
    }
}

/// The robot's end of its link: a channel per trusted master key, each
/// with its epochs in `state_dir/link/master-<fingerprint>.json`.
pub fn robot_end(
    state_dir: &Path,
    robot_id: &str,
    key: &SigningKey,
    masters: &[VerifyingKey],
) -> anyhow::Result<Peers> {
    let dir = state_dir.join("link");
    let mut channels = Vec::new();
    for master in masters {
        let file = EpochFile::for_peer(&dir, "master", master)
            .with_context(|| format!("the link's state in {}", dir.display()))?;
        channels.push(
            Channel::new(Role::Robot, key, master, robot_id, Box::new(file))
                .with_context(|| format!("the link with master key {}", fingerprint(master)))?,
        );
    }
    anyhow::ensure!(!channels.is_empty(), "a robot needs a trusted master key");
    Ok(Peers::new(channels))
}

/// The master's end of robot `robot_id`'s link, its epochs in
/// `dir/<robot_id>-<fingerprint>.json`.
pub fn master_end(
    dir: &Path,
    robot_id: &str,
    key: &SigningKey,
    robot: &VerifyingKey,
) -> anyhow::Result<Peers> {
    let file = EpochFile::for_peer(dir, robot_id, robot)
        .with_context(|| format!("the link's state in {}", dir.display()))?;
    let channel = Channel::new(Role::Master, key, robot, robot_id, Box::new(file))
        .with_context(|| format!("the link with robot {robot_id}"))?;
    Ok(Peers::one(channel))
}

/// Seconds since 2024-01-01 (until 2160 in a u32): no epoch starts below
/// it, so a link state lost with its directory (a robot's state wiped, its
/// key kept) starts above every epoch used before, as long as epochs were
/// taken less than once a second on average.
fn clock_epoch() -> u32 {
    const Y2024_UNIX_S: u64 = 1_704_067_200;
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs().saturating_sub(Y2024_UNIX_S))
        .min(u64::from(u32::MAX)) as u32
}

/// The first 8 bytes of a public key's SHA-256, in hex: names its files.
pub fn fingerprint(key: &VerifyingKey) -> String {
    twindrive_link::envelope::sha256_hex(key.as_bytes())[..16].to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epochs_grow_across_reopenings_and_two_holders_never_share_one() {
        let dir = tempfile::tempdir().unwrap();
        let peer = twindrive_link::secure::key_from_seed(1, 0).verifying_key();
        let mut a = EpochFile::for_peer(dir.path(), "r1", &peer).unwrap();
        let mut b = EpochFile::for_peer(dir.path(), "r1", &peer).unwrap();
        let mut seen = std::collections::HashSet::new();
        for _ in 0..5 {
            assert!(seen.insert(a.next_epoch(1).unwrap()));
            assert!(seen.insert(b.next_epoch(1).unwrap()));
        }
        // Epochs start at the clock (seconds since 2024), never below.
        let now = clock_epoch();
        assert!(seen.iter().all(|&e| e >= now - 5));
        let top = *seen.iter().max().unwrap();
        assert_eq!(a.next_epoch(top + 100).unwrap(), top + 100);
        assert_eq!(b.next_epoch(1).unwrap(), top + 101);
        assert_eq!(a.peer_floor(), 0);
        a.raise_peer_floor(7).unwrap();
        a.raise_peer_floor(3).unwrap();
        let c = EpochFile::for_peer(dir.path(), "r1", &peer).unwrap();
        assert_eq!(c.peer_floor(), 7);
        // Another peer's key: its own file.
        let other = twindrive_link::secure::key_from_seed(2, 0).verifying_key();
        assert_eq!(
            EpochFile::for_peer(dir.path(), "r1", &other)
                .unwrap()
                .peer_floor(),
            0
        );
        // A damaged file refuses rather than starts over: at once when
        // opened, and if it is damaged while in use.
        std::fs::write(c.path(), b"{").unwrap();
        let e = EpochFile::for_peer(dir.path(), "r1", &peer).unwrap_err();
        assert!(e.to_string().contains("not a link state"), "{e}");
        assert_eq!(c.peer_floor(), u32::MAX);
        let e = a.next_epoch(1).unwrap_err();
        assert!(e.contains("not a link state"), "{e}");
    }
}
