//! Usage errors: the checked flag values every command shares (clap value
//! parsers, so a bad value is refused before any work starts, naming the
//! flag and what was expected) and the error type for the checks clap
//! cannot make. `main` exits with status 2 on either.

use std::fmt;

/// A command line that cannot be run as given (exit status 2).
#[derive(Debug)]
pub struct UsageError(pub String);

impl fmt::Display for UsageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

/// A usage error with this message.
pub fn usage(message: impl fmt::Display) -> anyhow::Error {
    anyhow::Error::new(UsageError(message.to_string()))
}

/// Turns any error of a check on the command line into a usage error.
pub trait OrUsage<T> {
    fn or_usage(self) -> anyhow::Result<T>;
}

impl<T, E: Into<anyhow::Error>> OrUsage<T> for Result<T, E> {
    fn or_usage(self) -> anyhow::Result<T> {
        self.map_err(|e| usage(format!("{:#}", e.into())))
    }
}

/// Whether `err` (or any error it wraps) is a usage error.
pub fn is_usage(err: &anyhow::Error) -> bool {
    err.chain().any(|e| e.is::<UsageError>())
}

/// Every flag and argument that takes a value also takes a negative number
/// (`--duration-s -5` is a value, refused by the flag's own check, not an
/// unknown argument).
pub fn negative_numbers_as_values(cmd: clap::Command) -> clap::Command {
    cmd.mut_args(|a| {
        if a.get_action().takes_values() {
            a.allow_negative_numbers(true)
        } else {
            a
        }
    })
    .mut_subcommands(negative_numbers_as_values)
}

/// A finite number for which `ok` holds, else "`what`, got `text`".
fn number(text: &str, what: &str, ok: impl Fn(f64) -> bool) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && ok(v) => Ok(v),
        _ => Err(format!("{what}, got {text}")),
    }
}

/// A duration > 0 seconds.
pub fn seconds(text: &str) -> Result<f64, String> {
    number(text, "a duration > 0 s", |v| v > 0.0)
}

/// A duration ≥ 0 seconds.
pub fn seconds_or_zero(text: &str) -> Result<f64, String> {
    number(text, "a duration ≥ 0 s", |v| v >= 0.0)
}

/// A time on some clock, seconds (any finite number).
pub fn time(text: &str) -> Result<f64, String> {
    number(text, "a time in seconds", |_| true)
}

/// A number > 0.
pub fn positive(text: &str) -> Result<f64, String> {
    number(text, "a number > 0", |v| v > 0.0)
}

/// A distance > 0 metres.
pub fn metres(text: &str) -> Result<f64, String> {
    number(text, "a distance > 0 m", |v| v > 0.0)
}

/// A distance ≥ 0 metres.
pub fn metres_or_zero(text: &str) -> Result<f64, String> {
    number(text, "a distance ≥ 0 m", |v| v >= 0.0)
}

/// How many times faster than real time a simulation runs.
pub fn time_scale(text: &str) -> Result<f64, String> {
    number(text, "a time scale > 0", |v| v > 0.0)
}

/// A telemetry budget.
pub fn telemetry_budget(text: &str) -> Result<f64, String> {
    number(text, "at least 100 bytes per second", |v| v >= 100.0)
}

/// A fraction in (0, 1].
pub fn fraction(text: &str) -> Result<f64, String> {
    number(text, "a fraction in (0, 1]", |v| v > 0.0 && v <= 1.0)
}

/// A kinematic error: a fraction in [0, 0.5).
pub fn kinematic_error(text: &str) -> Result<f64, String> {
    number(text, "a fraction in [0, 0.5) (0.01 is 1 %)", |v| {
        (0.0..0.5).contains(&v)
    })
}

/// Unix seconds that a ROS time holds.
pub fn unix_time(text: &str) -> Result<f64, String> {
    number(text, "Unix seconds between 0 and 4e9", |v| {
        (0.0..4.0e9).contains(&v)
    })
}

/// A count ≥ 1.
pub fn count(text: &str) -> Result<u64, String> {
    match text.trim().parse::<u64>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!("a whole number ≥ 1, got {text}")),
    }
}

/// Encoder ticks per wheel revolution.
pub fn ticks_per_rev(text: &str) -> Result<u32, String> {
    match text.trim().parse::<u32>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!(
            "a whole number of ticks per revolution from 1 to {}, got {text}",
            u32::MAX
        )),
    }
}

/// The number of robots in a fleet run.
pub fn fleet_size(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(n) if (1..=200).contains(&n) => Ok(n),
        _ => Err(format!("a fleet size from 1 to 200, got {text}")),
    }
}

/// The direction of an encoder counter: 1 or -1.
pub fn wheel_sign(text: &str) -> Result<i8, String> {
    match text.trim() {
        "1" | "+1" => Ok(1),
        "-1" => Ok(-1),
        _ => Err(format!("1 or -1, got {text}")),
    }
}

/// A robot id: 1 to MAX_ROBOT_ID_BYTES letters, digits, `-` or `_` (it is
/// part of zenoh key expressions and file names).
pub fn robot_id(text: &str) -> Result<String, String> {
    let max = twindrive_link::wire::MAX_ROBOT_ID_BYTES;
    if text.is_empty()
        || text.len() > max
        || !text
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        return Err(format!(
            "a robot id of 1 to {max} letters, digits, `-` or `_`, got `{text}`"
        ));
    }
    Ok(text.to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_are_checked_and_say_what_was_expected() {
        assert_eq!(seconds("2.5"), Ok(2.5));
        assert_eq!(seconds("-5").unwrap_err(), "a duration > 0 s, got -5");
        assert!(seconds("0").is_err() && seconds("inf").is_err() && seconds("x").is_err());
        assert_eq!(seconds_or_zero("0"), Ok(0.0));
        assert_eq!(time("-3"), Ok(-3.0));
        assert!(time("NaN").is_err());
        assert!(telemetry_budget("99").is_err() && telemetry_budget("100").is_ok());
        assert!(fraction("1").is_ok() && fraction("0").is_err() && fraction("1.1").is_err());
        assert_eq!(count("0").unwrap_err(), "a whole number ≥ 1, got 0");
        assert!(fleet_size("201").is_err() && fleet_size("200").is_ok());
        assert_eq!(wheel_sign("-1"), Ok(-1));
        assert!(wheel_sign("2").is_err());
        assert!(robot_id("r-1_a").is_ok());
        assert!(robot_id("a/b").is_err() && robot_id("").is_err());
    }

    #[test]
    fn every_flag_that_takes_a_value_takes_a_negative_number() {
        use clap::CommandFactory;
        let cmd = negative_numbers_as_values(crate::cli::Args::command());
        cmd.clone().debug_assert();
        let m = cmd
            .try_get_matches_from([
                "twindrive",
                "simulate",
                "s.toml",
                "--out",
                "o",
                "--duration-s",
                "-5",
            ])
            .unwrap_err();
        assert_eq!(m.kind(), clap::error::ErrorKind::ValueValidation);
    }

    #[test]
    fn usage_errors_are_found_through_contexts() {
        use anyhow::Context;
        let e: anyhow::Result<()> = Err(usage("--x: bad"));
        assert!(is_usage(&e.context("while running").unwrap_err()));
        assert!(!is_usage(&anyhow::anyhow!("a file error")));
        let e: Result<(), String> = Err("--y: worse".into());
        assert!(is_usage(
            &e.map_err(anyhow::Error::msg).or_usage().unwrap_err()
        ));
    }
}
