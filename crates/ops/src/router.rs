//! `twindrive router`: a zenoh router for a fleet.

use std::path::PathBuf;

use twindrive_net::{Network, SessionOptions};

use crate::runtime;

/// Where a router listens with neither `--listen` nor a configuration file.
pub const DEFAULT_LISTEN: &str = "tcp/127.0.0.1:7447";

/// Runs a zenoh router until Ctrl-C: on `listen` when given, else where
/// the configuration file says (`twindrive certs`' `router.json5`: TLS),
/// else on [`DEFAULT_LISTEN`].
pub fn run(listen: Vec<String>, zenoh_config: Option<PathBuf>) -> anyhow::Result<()> {
    let listen = if listen.is_empty() && zenoh_config.is_none() {
        vec![DEFAULT_LISTEN.to_string()]
    } else {
        listen
    };
    let options = SessionOptions {
        listen,
        config_file: zenoh_config,
        mode: Some("router".into()),
        ..SessionOptions::default()
    };
    let listening = options.endpoints("listen")?;
    if listening.is_empty() {
        anyhow::bail!(
            "the router has no endpoint to listen on: give --listen, or a configuration with listen.endpoints"
        );
    }
    runtime()?.block_on(async {
        let network = Network::open(&options).await?;
        eprintln!("router: listening on {}", listening.join(", "));
        tokio::signal::ctrl_c().await.ok();
        network.close().await;
        anyhow::Ok(())
    })
}
