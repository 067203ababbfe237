//! `twindrive router`: a zenoh router for a fleet.

use std::path::PathBuf;

use twindrive_net::{SessionOptions, open_session};

use crate::runtime;

/// Runs a zenoh router listening on `listen` until Ctrl-C.
pub fn run(listen: Vec<String>, zenoh_config: Option<PathBuf>) -> anyhow::Result<()> {
    let options = SessionOptions {
        listen: listen.clone(),
        connect: Vec::new(),
        config_file: zenoh_config,
        mode: Some("router".into()),
    };
    runtime()?.block_on(async {
        let session = open_session(&options).await?;
        eprintln!("router: listening on {}", listen.join(", "));
        tokio::signal::ctrl_c().await.ok();
        let _ = session.close().await;
        anyhow::Ok(())
    })
}
