//! The `twindrive` binary: parse arguments, set up logging, run the command,
//! turn errors into a message and an exit code.

mod cli;
mod commands;
mod evidence;
mod figures;
mod inputs;
mod output;
mod progress;
mod report;
mod verification;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Args::parse();
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .init();
    match commands::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            // A closed pipe (`twindrive ... | head`) is not a failure.
            if err
                .chain()
                .filter_map(|e| e.downcast_ref::<std::io::Error>())
                .any(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
            {
                return ExitCode::SUCCESS;
            }
            eprintln!("error: {err:#}");
            // A plan that failed verification is an answer, not a fault.
            if err.is::<commands::verify_plan::PlanFailed>() {
                return ExitCode::from(3);
            }
            ExitCode::FAILURE
        }
    }
}
