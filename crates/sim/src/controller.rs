//! Controllers that drive the twin: the paper's wall follower, scripted
//! wheel-speed segments and manual (v, ω) commands. Controllers only know the
//! *nominal* parameters, as the operator does.

use std::path::Path;

use twindrive_kinematics::{DiffDriveParams, wheel_speeds};

use crate::SimError;
use crate::config::ControllerConfig;
use crate::scenario::{ScriptedSpec, WallFollowerSpec};

/// One timed command of a manual drive, held until the next one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ManualCommand {
    pub t_ns: u64,
    pub v_m_s: f64,
    pub omega_rad_s: f64,
}

/// What a controller sees at a step: the bump state and the latest reading
/// of each single-beam range sensor (held between samples).
#[derive(Debug, Clone, Copy)]
pub struct Observation<'a> {
    pub t_ns: u64,
    pub bump: bool,
    pub latest_range_m: &'a [f64],
}

/// Wall-follower mode, logged for figures and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WallMode {
    Follow,
    Reverse { until_ns: u64 },
    Turn { until_ns: u64 },
}

#[derive(Debug, Clone)]
pub enum Controller {
    WallFollower {
        spec: WallFollowerSpec,
        sensor: usize,
        mode: WallMode,
    },
    Scripted {
        spec: ScriptedSpec,
        /// Segment end times in ns, cumulative.
        ends_ns: Vec<u64>,
    },
    Manual {
        commands: Vec<ManualCommand>,
        next: usize,
    },
}

impl Controller {
    pub fn new(config: &ControllerConfig) -> Self {
        match config {
            ControllerConfig::WallFollower { spec, sensor } => Self::WallFollower {
                spec: spec.clone(),
                sensor: *sensor,
                mode: WallMode::Follow,
            },
            ControllerConfig::Scripted(spec) => {
                let mut total = 0u64;
                let ends_ns = spec
                    .segments
                    .iter()
                    .map(|s| {
                        total = total.saturating_add((s.duration_s * 1e9).round() as u64);
                        total
                    })
                    .collect();
                Self::Scripted {
                    spec: spec.clone(),
                    ends_ns,
                }
            }
            ControllerConfig::Manual(commands) => Self::Manual {
                commands: commands.clone(),
                next: 0,
            },
        }
    }

    /// Wheel angular speeds [left, right] to command now.
    pub fn command(&mut self, obs: &Observation, nominal: &DiffDriveParams) -> [f64; 2] {
        match self {
            Self::WallFollower { spec, sensor, mode } => {
                let (v, omega) = wall_follow(spec, mode, obs, obs.latest_range_m[*sensor]);
                let (l, r) = wheel_speeds(nominal, v, omega);
                [l, r]
            }
            Self::Scripted { spec, ends_ns } => {
                let total = *ends_ns.last().expect("validated non-empty");
                let t = if spec.repeat {
                    obs.t_ns % total
                } else {
                    obs.t_ns
                };
                match ends_ns.iter().position(|&end| t < end) {
                    Some(i) => [spec.segments[i].left_rad_s, spec.segments[i].right_rad_s],
                    None => [0.0, 0.0],
                }
            }
            Self::Manual { commands, next } => {
                while *next < commands.len() && commands[*next].t_ns <= obs.t_ns {
                    *next += 1;
                }
                match next.checked_sub(1) {
                    None => [0.0, 0.0],
                    Some(i) => {
                        let (l, r) =
                            wheel_speeds(nominal, commands[i].v_m_s, commands[i].omega_rad_s);
                        [l, r]
                    }
                }
            }
        }
    }

    pub fn wall_mode(&self) -> Option<WallMode> {
        match self {
            Self::WallFollower { mode, .. } => Some(*mode),
            _ => None,
        }
    }
}

/// The paper's routine: on a bump, reverse, then turn left, then follow the
/// wall on the right with a proportional law on the side range reading.
fn wall_follow(
    spec: &WallFollowerSpec,
    mode: &mut WallMode,
    obs: &Observation,
    side_range_m: f64,
) -> (f64, f64) {
    let secs = |s: f64| (s * 1e9).round() as u64;
    if *mode == WallMode::Follow && obs.bump {
        *mode = WallMode::Reverse {
            until_ns: obs.t_ns.saturating_add(secs(spec.reverse_duration_s)),
        };
    }
    if let WallMode::Reverse { until_ns } = *mode
        && obs.t_ns >= until_ns
    {
        *mode = WallMode::Turn {
            until_ns: obs.t_ns.saturating_add(secs(spec.turn_duration_s)),
        };
    }
    if let WallMode::Turn { until_ns } = *mode
        && obs.t_ns >= until_ns
    {
        *mode = WallMode::Follow;
    }
    match *mode {
        WallMode::Reverse { .. } => (-spec.reverse_speed_m_s, 0.0),
        WallMode::Turn { .. } => (0.0, spec.turn_rate_rad_s),
        WallMode::Follow => {
            // Too far from the wall (positive error) turns right, towards it.
            let error = side_range_m - spec.target_range_m;
            let omega = (-spec.gain_rad_s_per_m * error)
                .clamp(-spec.max_turn_rate_rad_s, spec.max_turn_rate_rad_s);
            (spec.cruise_speed_m_s, omega)
        }
    }
}

/// Reads a manual command file: CSV with header `t_s,v_m_s,omega_rad_s`,
/// times strictly increasing.
pub fn read_manual_commands(path: &Path) -> Result<Vec<ManualCommand>, SimError> {
    let text = std::fs::read_to_string(path).map_err(|e| SimError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let bad = |line: usize, message: String| SimError::Commands {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim() == "t_s,v_m_s,omega_rad_s" => {}
        _ => return Err(bad(1, "expected the header `t_s,v_m_s,omega_rad_s`".into())),
    }
    let mut out: Vec<ManualCommand> = Vec::new();
    for (i, line) in lines {
        let line_no = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != 3 {
            return Err(bad(
                line_no,
                format!("expected 3 columns, found {}", cells.len()),
            ));
        }
        let mut values = [0.0; 3];
        for (k, (cell, name)) in cells
            .iter()
            .zip(["t_s", "v_m_s", "omega_rad_s"])
            .enumerate()
        {
            values[k] = cell
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    bad(
                        line_no,
                        format!("column `{name}`: expected a finite number, found `{cell}`"),
                    )
                })?;
        }
        let t_ns = twindrive_log::ns_from_seconds(values[0]).ok_or_else(|| {
            bad(
                line_no,
                format!("column `t_s`: must be >= 0, found {}", values[0]),
            )
        })?;
        if out.last().is_some_and(|c| c.t_ns >= t_ns) {
            return Err(bad(line_no, "column `t_s`: times must increase".into()));
        }
        out.push(ManualCommand {
            t_ns,
            v_m_s: values[1],
            omega_rad_s: values[2],
        });
    }
    if out.is_empty() {
        return Err(bad(1, "no commands after the header".into()));
    }
    Ok(out)
}
