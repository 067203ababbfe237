//! The two ends of decoupled operation as processes over zenoh, and a
//! router for a fleet: `twindrive robot`, `twindrive master` and
//! `twindrive router` read their flags into these configurations and call
//! these. The protocol is twindrive-agent's state machines; this crate
//! opens the network, drives them on the clock and writes what they
//! produce (through `twindrive-store`).
//!
//! - [`robot`]: the robot agent on a simulated site or a ROS 2 robot;
//! - [`master`]: one robot or a fleet, each with its operator, twin and
//!   output folder;
//! - [`first_plan`]: the signed plan a master starts with (or resumes);
//! - [`supervise`]: one robot's operator driven over the network;
//! - [`settings`]: a master's checked configuration ([`MasterSettings`]);
//! - [`site_maps`]: the twin's map of its site kept across missions
//!   (`--site-maps`);
//! - [`router`]: a zenoh router;
//! - [`certs`]: a fleet's CA, certificates and TLS configurations with the
//!   router's access control.

pub mod certs;
pub mod first_plan;
pub mod master;
pub mod robot;
pub mod router;
pub mod settings;
pub mod site_maps;
pub mod supervise;

use anyhow::Context;

pub use settings::MasterSettings;

/// The processes' async runtime: two worker threads.
pub(crate) fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")
}

/// Now, in Unix seconds.
pub(crate) fn unix_now_s() -> anyhow::Result<f64> {
    Ok(twindrive_workflow::inputs::since_epoch()?.as_secs_f64())
}
