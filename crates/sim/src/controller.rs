//! Controllers that drive the twin: the paper's wall follower, scripted
//! wheel-speed segments and manual (v, ω) commands. Controllers only know the
//! *nominal* parameters, as the operator does.

use twindrive_kinematics::{DiffDriveParams, wheel_speeds};

use crate::config::ControllerConfig;
use crate::manual::ManualCommand;
use crate::scenario::{ScriptedSpec, WallFollowerSpec};

/// What a controller sees at a step: the bump state and the latest reading
/// of each ranger (held between samples).
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
