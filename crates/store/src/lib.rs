//! Durable files at the edge of the processes. The protocol (`twindrive-link`)
//! and the agents (`twindrive-agent`) touch no file system: what they must
//! keep goes through their store traits, and this crate keeps it on disk.
//!
//! - [`chunks`]: upload chunks on disk ([`DirStore`], a
//!   `twindrive_link::upload::ChunkStore`);
//! - [`counter`]: the last plan counter a robot accepted ([`CounterFile`]);
//! - [`robot_dir`]: the robot's state directory ([`RobotDir`], a
//!   `twindrive_agent::store::RobotStore`);
//! - [`keys`]: fresh ed25519 keys from the operating system's randomness,
//!   key pairs on disk, the robot keys a master trusts;
//! - [`link_state`]: a link's epochs ([`EpochFile`], a
//!   `twindrive_link::secure::EpochStore`);
//! - [`archive`]: the master's output folder ([`MasterArchive`]), one
//!   layout for the master process, the console and in-process missions;
//! - [`robot_log`]: what the master makes of a robot log it received;
//! - [`site_maps`]: the twin's map of each site, kept across missions
//!   ([`SiteMaps`]).

pub mod archive;
pub mod chunks;
pub mod counter;
pub mod keys;
pub mod link_state;
pub mod robot_dir;
pub mod robot_log;
pub mod site_maps;

pub use archive::{ArchivedLog, MasterArchive};
pub use chunks::DirStore;
pub use counter::CounterFile;
pub use keys::generate_key;
pub use link_state::EpochFile;
pub use robot_dir::RobotDir;
pub use site_maps::{SiteMaps, SiteVersion};
