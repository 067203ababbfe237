//! Command-line arguments (clap derive). Checked and resolved into typed
//! configuration by each command before any work starts.

use std::path::PathBuf;

use clap::{Parser, Subcommand};

/// Operate differential-drive robots over slow, lossy links through a digital twin.
#[derive(Debug, Parser)]
#[command(name = "twindrive", version, about, propagate_version = true)]
pub struct Args {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a scenario on the twin and write its mission log and figures.
    ///
    /// Writes log.csv, log.meta.json, log.mcap, ground_truth.tum,
    /// summary.json and figures (path, wheel_speeds, side_ir as SVG and PNG)
    /// into DIR. Files are staged beside DIR and moved in only when all are
    /// written; a failed move puts back the previous files. Files in DIR that
    /// twindrive did not write are never replaced.
    Simulate {
        /// Scenario TOML file.
        scenario: PathBuf,
        /// Output directory (created if missing; files twindrive did not write are kept).
        #[arg(long)]
        out: PathBuf,
        /// Override the scenario's random seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Override the scenario's duration, in seconds.
        #[arg(long, value_name = "SECONDS")]
        duration_s: Option<f64>,
    },
    /// Run the paper's case study end to end into ./twindrive-out/.
    ///
    /// Currently: the built-in wall-following mission on the twin, with its
    /// log, summary and figures in twindrive-out/wall_following/.
    Demo {
        /// Output directory.
        #[arg(long, default_value = "twindrive-out")]
        out: PathBuf,
    },
    /// Write the office occupancy map (ROS map_server PGM + YAML) that the
    /// project draws itself into DIR.
    DrawMap {
        /// Directory for office.pgm and office.yaml.
        dir: PathBuf,
    },
}
