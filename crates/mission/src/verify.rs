//! Verification: replay a plan on the twin's robot, with its hidden *true*
//! parameters and noise, before it goes anywhere near the real one.
//!
//! - Open loop: the plan's wheel speeds, held sample by sample, as the real
//!   robot would play them blind.
//! - Closed loop: a regulated pure pursuit tracker (Macenski et al., 2023)
//!   follows the plan's path with the robot's own odometry (its encoders and
//!   the plan's calibrated parameters): lookahead on the path, curvature
//!   `κ = 2 y / (x² + y²)` to the lookahead point in the body frame, the
//!   plan's speed at the robot's progress, slowed on tight curves and near
//!   the end; turns in place follow the plan's turn rate with a heading
//!   correction.
//!
//! Deviation is the distance from the true position to the plan's path,
//! searched near the robot's progress along it (so a path that passes a
//! place twice is not matched to the wrong pass).

use serde::Serialize;
use twindrive_kinematics::{DiffDriveParams, Pose, arc_step_wheels, wheel_speeds, wrap_angle};
use twindrive_sim::{Scenario, Sensed, Simulator, StepOutput};

use crate::error::PipelineError;
use crate::plan::PlanSample;

/// What a replay found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReplayReport {
    /// Times a wall stopped the robot.
    pub collisions: u64,
    /// Times the bumper closed.
    pub bumps: u64,
    pub max_deviation_m: f64,
    pub mean_deviation_m: f64,
    /// Distance from the plan's last position when the replay ended.
    pub final_error_m: f64,
    pub duration_s: f64,
    pub path_length_m: f64,
}

/// A replay: the report and the true track.
#[derive(Debug, Clone)]
pub struct Replay {
    pub report: ReplayReport,
    pub track: Vec<(f64, Pose)>,
}

/// Closed-loop tracker settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct TrackerSettings {
    /// Lookahead distance (m).
    pub lookahead_m: f64,
    /// Below this radius of curvature the speed is scaled down (m).
    pub regulate_radius_m: f64,
    /// Heading gain for turns in place (1/s).
    pub heading_gain: f64,
    /// The replay ends this long after the plan's duration (s) at the latest.
    pub timeout_extra_s: f64,
    /// Within this distance of the last position the mission is complete (m).
    pub goal_tolerance_m: f64,
}

impl Default for TrackerSettings {
    fn default() -> Self {
        Self {
            lookahead_m: 0.2,
            regulate_radius_m: 0.3,
            heading_gain: 3.0,
            timeout_extra_s: 10.0,
            goal_tolerance_m: 0.02,
        }
    }
}

/// Progress along the plan's path and the distance to it.
struct PathCursor<'a> {
    samples: &'a [PlanSample],
    index: usize,
}

impl<'a> PathCursor<'a> {
    fn new(samples: &'a [PlanSample]) -> Self {
        Self { samples, index: 0 }
    }

    /// Distance from `p` to segment `k` and the parameter along it.
    fn segment_distance(&self, k: usize, p: (f64, f64)) -> (f64, f64) {
        let a = &self.samples[k];
        let b = &self.samples[(k + 1).min(self.samples.len() - 1)];
        let (dx, dy) = (b.x_m - a.x_m, b.y_m - a.y_m);
        let len2 = dx * dx + dy * dy;
        let u = if len2 > 0.0 {
            (((p.0 - a.x_m) * dx + (p.1 - a.y_m) * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (cx, cy) = (a.x_m + u * dx, a.y_m + u * dy);
        ((p.0 - cx).hypot(p.1 - cy), u)
    }

    /// Moves the cursor to the nearest segment within `window_m` of path
    /// ahead (never backwards) and returns the distance to the path.
    fn advance(&mut self, p: (f64, f64), window_m: f64) -> f64 {
        let mut best = (self.segment_distance(self.index, p).0, self.index);
        let mut travelled = 0.0;
        let mut k = self.index;
        while k + 1 < self.samples.len() && travelled < window_m {
            k += 1;
            let d = self.segment_distance(k, p).0;
            if d < best.0 {
                best = (d, k);
            }
            let (a, b) = (&self.samples[k - 1], &self.samples[k]);
            travelled += (b.x_m - a.x_m).hypot(b.y_m - a.y_m);
        }
        self.index = best.1;
        best.0
    }

    /// The point `distance_m` further along the path from the cursor.
    fn lookahead(&self, distance_m: f64) -> (f64, f64, usize) {
        let mut left = distance_m;
        let mut k = self.index;
        while k + 1 < self.samples.len() {
            let (a, b) = (&self.samples[k], &self.samples[k + 1]);
            let len = (b.x_m - a.x_m).hypot(b.y_m - a.y_m);
            if len >= left && len > 0.0 {
                let u = left / len;
                return (a.x_m + u * (b.x_m - a.x_m), a.y_m + u * (b.y_m - a.y_m), k);
            }
            left -= len;
            k += 1;
        }
        let last = self.samples.last().expect("non-empty plan");
        (last.x_m, last.y_m, self.samples.len() - 1)
    }
}

/// Runs `control` on the twin from the plan's start until it says stop or
/// the time runs out, measuring deviation from the plan's path.
fn replay(
    samples: &[PlanSample],
    mut scenario: Scenario,
    max_duration_s: f64,
    mut control: impl FnMut(&Sensed, &mut PathCursor) -> Option<[f64; 2]>,
) -> Result<Replay, PipelineError> {
    let first = samples
        .first()
        .ok_or_else(|| PipelineError::Infeasible("the plan has no samples".into()))?;
    scenario.robot.start = first.pose();
    scenario
        .set_duration_s(max_duration_s)
        .map_err(|e| PipelineError::Infeasible(format!("replay duration: {e}")))?;
    let dt_s = scenario.dt_s();
    let mut sim = Simulator::new(scenario);
    let mut out = StepOutput::new(sim.beams());
    let mut cursor = PathCursor::new(samples);
    let mut deviation = PathCursor::new(samples);
    let (mut collisions, mut bumps, mut was_blocked, mut was_bumped) = (0, 0, false, false);
    let (mut max_dev, mut sum_dev, mut n) = (0.0f64, 0.0, 0usize);
    let mut track = vec![(0.0, sim.pose())];
    let mut length = 0.0;
    let mut done_at = None;
    while done_at.is_none() {
        let mut finished = false;
        let stepped = sim.step_with(&mut out, &mut |s: &Sensed| {
            control(s, &mut cursor).unwrap_or_else(|| {
                finished = true;
                [0.0, 0.0]
            })
        });
        if !stepped {
            break;
        }
        let pose = sim.pose();
        let t = out.record.t_s() + dt_s;
        length += pose.distance_to(&track.last().expect("non-empty").1);
        track.push((t, pose));
        if out.blocked && !was_blocked {
            collisions += 1;
        }
        if out.record.bump && !was_bumped {
            bumps += 1;
        }
        (was_blocked, was_bumped) = (out.blocked, out.record.bump);
        let d = deviation.advance((pose.x_m, pose.y_m), 0.5);
        max_dev = max_dev.max(d);
        sum_dev += d;
        n += 1;
        if finished {
            done_at = Some(t);
        }
    }
    let end = track.last().expect("non-empty").1;
    let last = samples.last().expect("non-empty");
    Ok(Replay {
        report: ReplayReport {
            collisions,
            bumps,
            max_deviation_m: max_dev,
            mean_deviation_m: sum_dev / n.max(1) as f64,
            final_error_m: (end.x_m - last.x_m).hypot(end.y_m - last.y_m),
            duration_s: done_at.unwrap_or(track.last().expect("non-empty").0),
            path_length_m: length,
        },
        track,
    })
}

/// Plays the plan's wheel speeds (or, with `params`, the plan's body
/// velocities through those parameters' inverse kinematics) open loop. The
/// plan holds wheel speeds between its samples, which need not fall on the
/// robot's control ticks: each tick commands the mean speed of the plan over
/// that tick, so the wheel angles follow the plan's exactly.
pub fn open_loop(
    samples: &[PlanSample],
    scenario: Scenario,
    params: Option<&DiffDriveParams>,
) -> Result<Replay, PipelineError> {
    let t0 = samples.first().map_or(0.0, |s| s.t_s);
    let end = samples.last().map_or(0.0, |s| s.t_s) - t0;
    let speeds: Vec<[f64; 2]> = samples
        .iter()
        .map(|p| match params {
            None => [p.left_rad_s, p.right_rad_s],
            Some(params) => {
                let (l, r) = wheel_speeds(params, p.v_m_s, p.omega_rad_s);
                [l, r]
            }
        })
        .collect();
    // Planned cumulative wheel angles at the sample times.
    let mut angles = vec![[0.0f64; 2]; samples.len()];
    for k in 1..samples.len() {
        let dt = samples[k].t_s - samples[k - 1].t_s;
        angles[k] = [
            angles[k - 1][0] + speeds[k - 1][0] * dt,
            angles[k - 1][1] + speeds[k - 1][1] * dt,
        ];
    }
    let last = samples.len().saturating_sub(1);
    let angle_at = |t: f64, k: &mut usize| -> [f64; 2] {
        while *k < last && samples[*k + 1].t_s <= t {
            *k += 1;
        }
        if *k >= last {
            return angles[last];
        }
        let dt = (t - samples[*k].t_s).max(0.0);
        [
            angles[*k][0] + speeds[*k][0] * dt,
            angles[*k][1] + speeds[*k][1] * dt,
        ]
    };
    let dt_s = scenario.dt_s();
    let (mut k0, mut k1) = (0, 0);
    replay(samples, scenario, end + 1.0, |s, _| {
        let t = s.t_ns as f64 * 1e-9 + t0;
        if t >= t0 + end {
            return None;
        }
        let (a, b) = (angle_at(t, &mut k0), angle_at(t + dt_s, &mut k1));
        Some([(b[0] - a[0]) / dt_s, (b[1] - a[1]) / dt_s])
    })
}

/// Tracks the plan's path closed loop with odometry from the encoders and
/// `params` (the plan's calibrated parameters).
pub fn closed_loop(
    samples: &[PlanSample],
    scenario: Scenario,
    params: &DiffDriveParams,
    settings: &TrackerSettings,
) -> Result<Replay, PipelineError> {
    let rad_per_tick = std::f64::consts::TAU / f64::from(scenario.robot.encoder.ticks_per_rev);
    let max_wheel = scenario.robot.max_wheel_speed_rad_s;
    let duration = samples.last().map_or(0.0, |s| s.t_s) - samples.first().map_or(0.0, |s| s.t_s);
    let mut estimate = samples.first().map_or(Pose::default(), |s| s.pose());
    let mut last_ticks: Option<[i64; 2]> = None;
    let Some(last) = samples.last().cloned() else {
        return Err(PipelineError::Infeasible("the plan has no samples".into()));
    };
    replay(
        samples,
        scenario,
        duration + settings.timeout_extra_s,
        move |s, cursor| {
            if let Some(ticks) = s.encoder_ticks {
                if let Some(prev) = last_ticks {
                    let dl = (ticks[0] - prev[0]) as f64 * rad_per_tick;
                    let dr = (ticks[1] - prev[1]) as f64 * rad_per_tick;
                    estimate = arc_step_wheels(&estimate, params, dl, dr);
                }
                last_ticks = Some(ticks);
            }
            cursor.advance((estimate.x_m, estimate.y_m), 0.5);
            let to_goal = (last.x_m - estimate.x_m).hypot(last.y_m - estimate.y_m);
            if cursor.index + 2 >= cursor.samples.len() && to_goal < settings.goal_tolerance_m {
                return None;
            }
            let here = &cursor.samples[cursor.index];
            let (v_plan, omega_plan) = (here.v_m_s, here.omega_rad_s);
            let (v, omega) = if v_plan.abs() < 0.02 && omega_plan.abs() > 0.05 {
                // A turn in place: the plan's rate plus a heading correction.
                let next = &cursor.samples[(cursor.index + 1).min(cursor.samples.len() - 1)];
                let err = wrap_angle(next.heading_rad - estimate.heading_rad);
                (0.0, omega_plan + settings.heading_gain * err)
            } else {
                let (lx, ly, _) = cursor.lookahead(settings.lookahead_m);
                let (sn, cs) = estimate.heading_rad.sin_cos();
                let (dx, dy) = (lx - estimate.x_m, ly - estimate.y_m);
                let (bx, by) = (cs * dx + sn * dy, -sn * dx + cs * dy);
                let d2 = bx * bx + by * by;
                let curvature = if d2 > 1e-12 { 2.0 * by / d2 } else { 0.0 };
                // Regulation: slow down on tight curves and for the final approach.
                let mut speed = v_plan.abs().max(0.03);
                let radius = 1.0 / curvature.abs().max(1e-9);
                if radius < settings.regulate_radius_m {
                    speed *= radius / settings.regulate_radius_m;
                }
                speed = speed.min(to_goal.max(0.02) * 2.0);
                let direction = if bx < 0.0 && v_plan < 0.0 { -1.0 } else { 1.0 };
                let v = direction * speed;
                (v, v * curvature)
            };
            let (mut l, mut r) = wheel_speeds(params, v, omega);
            let peak = l.abs().max(r.abs());
            if peak > max_wheel {
                (l, r) = (l * max_wheel / peak, r * max_wheel / peak);
            }
            Some([l, r])
        },
    )
}
