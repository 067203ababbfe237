//! The `twindrive` binary: parse arguments, set up logging, run the command,
//! turn errors into a message and an exit code.

mod cli;
mod commands;
mod flags;
mod usage;

use std::io::{IsTerminal, Write};
use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches};
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;

fn main() -> ExitCode {
    let matches = usage::negative_numbers_as_values(cli::Args::command()).get_matches();
    let args = cli::Args::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    // Colour and the network's Rust source locations only on a terminal: a log
    // file or a journal gets plain lines.
    let terminal = std::io::stderr().is_terminal();
    let subscriber = tracing_subscriber::fmt()
        .with_ansi(terminal)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
                tracing_subscriber::EnvFilter::new(format!(
                    "warn,{}",
                    twindrive_net::QUIET_LOG_DIRECTIVES
                ))
            }),
        );
    // A TLS listener's refused clients said in words and counted, not
    // zenoh's "increase the system open file limit" for each.
    let refusals = twindrive_net::TlsRefusals::new();
    if terminal {
        subscriber
            .with_writer(std::io::stderr)
            .finish()
            .with(refusals)
            .init();
    } else {
        subscriber
            .with_writer(|| PlainStderr)
            .finish()
            .with(refusals)
            .init();
    }
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
            eprintln!("error: {}", twindrive_net::plain_error(&message(&err)));
            if usage::is_usage(&err) {
                eprintln!("\nFor more information, try '--help'.");
                ExitCode::from(2)
            } else if err.is::<twindrive_workflow::verify::PlanFailed>() {
                // A plan that failed verification is an answer, not a fault.
                ExitCode::from(3)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// Standard error for log lines when it is not a terminal: each line
/// without colour codes and without the Rust source locations zenoh's
/// errors carry.
struct PlainStderr;

impl Write for PlainStderr {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let text = String::from_utf8_lossy(buf);
        let mut plain: Vec<String> = text.lines().map(twindrive_net::plain_error).collect();
        if text.ends_with('\n') {
            plain.push(String::new());
        }
        std::io::stderr().write_all(plain.join("\n").as_bytes())?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

/// The error and its causes, outermost first, separated by `: `; a cause
/// whose text the message already holds (an io::Error that its wrapper
/// prints as well) is said once.
fn message(err: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

#[cfg(test)]
mod tests {
    use anyhow::Context;

    #[test]
    fn a_cause_the_message_already_holds_is_said_once() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file (os error 2)");
        #[derive(Debug)]
        struct Wrapper {
            source: std::io::Error,
        }
        impl std::fmt::Display for Wrapper {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "a.toml: {}", self.source)
            }
        }
        impl std::error::Error for Wrapper {
            fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
                Some(&self.source)
            }
        }
        let err = anyhow::Error::new(Wrapper { source: io }).context("--site");
        assert_eq!(
            super::message(&err),
            "--site: a.toml: No such file (os error 2)"
        );
        let plain: anyhow::Result<()> = Err(anyhow::anyhow!("inner"));
        let err = plain.context("outer").unwrap_err();
        assert_eq!(super::message(&err), "outer: inner");
    }
}
