//! A master process's configuration, checked.

use std::path::PathBuf;

use twindrive_agent::narrate::Verbosity;
use twindrive_agent::operator::OnHandback;
use twindrive_link::LinkProfile;
use twindrive_link::envelope::{SigningKey, VerifyingKey};
use twindrive_net::SessionOptions;

/// A master process, checked.
pub struct MasterSettings {
    /// The plan to sign (`--plan`), or a plan signed already (`--signed`).
    pub plan: Option<PathBuf>,
    pub signed: Option<PathBuf>,
    /// The master's key: signs plans and seals every message.
    pub key: SigningKey,
    /// Each robot's public key (every robot of `robots` has one).
    pub robot_keys: std::collections::BTreeMap<String, VerifyingKey>,
    /// Where the master keeps each robot link's epochs.
    pub link_state: PathBuf,
    /// The robots, distinct; more than one is a fleet (each its own folder
    /// under `out`).
    pub robots: Vec<String>,
    pub out: PathBuf,
    pub zenoh: SessionOptions,
    /// Emulate this link at the master on every robot's traffic.
    pub profile: Option<LinkProfile>,
    pub seed: u64,
    pub expires_in: u64,
    pub supervise: Option<f64>,
    pub on_handback: OnHandback,
    /// The twin's scenario (default: the built-in one the plan names).
    pub scenario: Option<PathBuf>,
    /// Where the twin's map of each site is kept across missions.
    pub site_maps: Option<PathBuf>,
    pub timeout: f64,
    pub telemetry_budget: f64,
    pub log_wait: f64,
    /// Ask for the robot's full-rate logs once the digests are in.
    pub full_logs: bool,
    pub allow_failed_verification: bool,
    pub verbosity: Verbosity,
}
