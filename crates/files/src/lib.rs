//! Files at the edge of the commands and processes, written so that a
//! failure or a power cut never leaves a partial result:
//!
//! - [`durable`]: one file written whole or not at all (temporary file,
//!   sync, rename, directory sync), and a line appended and synced;
//! - [`staging`]: an output directory whose files move in only once every
//!   one was written ([`Staging`]);
//! - [`json`]: JSON inputs read with errors that name the file and say
//!   what it should have been.

pub mod durable;
pub mod json;
pub mod staging;

pub use durable::{append_synced, write_durably};
pub use staging::{Staging, split_out_path};
