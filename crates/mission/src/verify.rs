//! Verification: replay a plan on the twin's robot, with its hidden *true*
//! parameters and noise, before it goes anywhere near the real one.
//!
//! - Open loop: the plan's wheel speeds, held sample by sample, as the real
//!   robot would play them blind.
//! - Closed loop: the plan's trajectory tracked with the robot's own
//!   odometry (its encoders and the plan's calibrated parameters) by
//!   Kanayama's tracking law (Kanayama et al., 1990): with the reference pose
//!   and velocities `(v_r, ω_r)` of the plan at the current time and the
//!   error `(e_x, e_y, e_θ)` in the body frame,
//!   `v = v_r cos e_θ + k_x e_x`, `ω = ω_r + v_r (k_y e_y + k_θ sin e_θ)`.
//!   plus a small heading correction that does not vanish with `v_r` (turns
//!   in place, stops). Following the plan's timing (not only its geometry)
//!   keeps reversals, turns in place and stops, which a pure path follower
//!   cannot resolve where the path doubles back on itself. The replay ends
//!   when the plan has ended and the robot is level with its goal (along-track
//!   error within the goal tolerance), or at the timeout.
//!
//! Deviation is the distance from the true position to the plan's path,
//! searched near the robot's progress along it (so a path that passes a
//! place twice is not matched to the wrong pass).

use serde::Serialize;
use twindrive_kinematics::{DiffDriveParams, Pose, arc_step_wheels, wheel_speeds, wrap_angle};
use twindrive_sim::{Scenario, Sensed, Simulator, StepOutput};

use crate::error::PipelineError;
use crate::freedom::FreedomMap;
use crate::plan::{MissionPlan, PlanSample};

/// What a replay found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReplayReport {
    /// Times a wall stopped the robot.
    pub collisions: u64,
    /// Times the bumper closed.
    pub bumps: u64,
    /// How long the robot was in contact at the plan's start before it
    /// first came clear (s): a plan that starts where its robot touches
    /// something (a continuation after a bump) is judged on the contacts
    /// that follow, not on the one it leaves.
    pub start_contact_s: f64,
    pub max_deviation_m: f64,
    pub mean_deviation_m: f64,
    /// The plan's keep-out zones the robot's footprint entered (each
    /// named once, in the order entered).
    pub keep_out_entered: Vec<String>,
    /// The furthest the footprint reached beyond the plan's corridor (m;
    /// 0 when it stayed inside, or the plan has none); a verdict allows
    /// the deviation tolerance.
    pub corridor_excess_m: f64,
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
    /// Along-track gain `k_x` (1/s).
    pub gain_along_per_s: f64,
    /// Cross-track gain `k_y` (1/m²).
    pub gain_cross_per_m2: f64,
    /// Heading gain `k_θ` (1/m).
    pub gain_heading_per_m: f64,
    /// Heading gain that does not scale with the plan's speed (1/s), for
    /// turns in place and stops.
    pub gain_heading_still_per_s: f64,
    /// The replay ends this long after the plan's duration (s) at the latest.
    pub timeout_extra_s: f64,
    /// Within this distance of the last position the mission is complete (m).
    pub goal_tolerance_m: f64,
}

impl Default for TrackerSettings {
    fn default() -> Self {
        Self {
            gain_along_per_s: 2.0,
            gain_cross_per_m2: 40.0,
            gain_heading_per_m: 8.0,
            gain_heading_still_per_s: 2.0,
            timeout_extra_s: 10.0,
            goal_tolerance_m: 0.01,
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
    /// ahead (never backwards; the later one on ties, so standing-still
    /// stretches of the plan are passed over) and returns the distance to
    /// the path.
    fn advance(&mut self, p: (f64, f64), window_m: f64) -> f64 {
        let mut best = (self.segment_distance(self.index, p).0, self.index);
        let mut travelled = 0.0;
        let mut k = self.index;
        while k + 1 < self.samples.len() && travelled < window_m {
            k += 1;
            let d = self.segment_distance(k, p).0;
            if d <= best.0 {
                best = (d, k);
            }
            let (a, b) = (&self.samples[k - 1], &self.samples[k]);
            travelled += (b.x_m - a.x_m).hypot(b.y_m - a.y_m);
        }
        self.index = best.1;
        best.0
    }
}

/// Runs `control` on the twin from the plan's start until it says stop or
/// the time runs out, measuring deviation from the plan's path and where
/// the footprint went against `freedom`.
fn replay(
    samples: &[PlanSample],
    mut scenario: Scenario,
    max_duration_s: f64,
    freedom: &FreedomMap<'_>,
    mut control: impl FnMut(&Sensed) -> Option<[f64; 2]>,
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
    let mut deviation = PathCursor::new(samples);
    let mut contacts = twindrive_sim::Contacts::default();
    let mut leaving_start_contact = true;
    let mut start_contact_s = 0.0;
    let (mut max_dev, mut sum_dev, mut n) = (0.0f64, 0.0, 0usize);
    let mut track = vec![(0.0, sim.pose())];
    let mut keep_out_entered: Vec<String> = Vec::new();
    let mut corridor_excess_m = 0.0f64;
    let mut length = 0.0;
    let mut done_at = None;
    while done_at.is_none() {
        let mut finished = false;
        let stepped = sim.step_with(&mut out, &mut |s: &Sensed| {
            control(s).unwrap_or_else(|| {
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
        let touching = out.record.bump || out.blocked;
        if leaving_start_contact && touching {
            start_contact_s += dt_s;
        } else {
            leaving_start_contact = false;
            contacts.record(out.record.bump, out.blocked, dt_s);
        }
        let d = deviation.advance((pose.x_m, pose.y_m), 0.5);
        if let Some(zone) = freedom.zone_hit([pose.x_m, pose.y_m])
            && !keep_out_entered.contains(&zone.name)
        {
            keep_out_entered.push(zone.name.clone());
        }
        if let Some(excess) = freedom.corridor_excess_m(deviation.index, d) {
            // A NaN distance is beyond any corridor, and stays so.
            corridor_excess_m = if excess.is_nan() || corridor_excess_m.is_nan() {
                f64::NAN
            } else {
                corridor_excess_m.max(excess)
            };
        }
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
            collisions: u64::from(contacts.collisions),
            bumps: u64::from(contacts.bumps),
            start_contact_s,
            max_deviation_m: max_dev,
            mean_deviation_m: sum_dev / n.max(1) as f64,
            keep_out_entered,
            corridor_excess_m,
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
    freedom: &FreedomMap<'_>,
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
    replay(samples, scenario, end + 1.0, freedom, |s| {
        let t = s.t_ns as f64 * 1e-9 + t0;
        if t >= t0 + end {
            return None;
        }
        let (a, b) = (angle_at(t, &mut k0), angle_at(t + dt_s, &mut k1));
        Some([(b[0] - a[0]) / dt_s, (b[1] - a[1]) / dt_s])
    })
}

/// The plan's reference at time `t` (pose interpolated, heading along the
/// shorter arc; velocities of the segment in progress), and whether the plan
/// has ended.
fn reference_at(samples: &[PlanSample], t: f64, k: &mut usize) -> (Pose, f64, f64, bool) {
    let last = samples.len() - 1;
    while *k < last && samples[*k + 1].t_s <= t {
        *k += 1;
    }
    if *k >= last {
        let s = &samples[last];
        return (s.pose(), 0.0, 0.0, true);
    }
    let (a, b) = (&samples[*k], &samples[*k + 1]);
    let f = ((t - a.t_s) / (b.t_s - a.t_s)).clamp(0.0, 1.0);
    let pose = Pose::new(
        a.x_m + f * (b.x_m - a.x_m),
        a.y_m + f * (b.y_m - a.y_m),
        a.heading_rad + f * wrap_angle(b.heading_rad - a.heading_rad),
    );
    (pose, a.v_m_s, a.omega_rad_s, false)
}

/// The closed-loop trajectory tracker as a state machine: encoder counts
/// and the time since the plan started in, wheel commands out. The robot
/// agent runs the same tracker as [`closed_loop`] does on the twin.
#[derive(Debug, Clone)]
pub struct Tracker {
    params: DiffDriveParams,
    settings: TrackerSettings,
    rad_per_tick: f64,
    max_wheel_rad_s: f64,
    estimate: Pose,
    /// Where the plan was at the last command's time.
    reference: Pose,
    last_ticks: Option<[i64; 2]>,
    cursor: usize,
}

impl Tracker {
    /// From the plan's first pose, with odometry through `params` and wheel
    /// commands capped at `max_wheel_rad_s` (speeds scaled together). Every
    /// [`Tracker::command`] takes the same `samples`.
    pub fn new(
        samples: &[PlanSample],
        params: &DiffDriveParams,
        settings: &TrackerSettings,
        ticks_per_rev: u32,
        max_wheel_rad_s: f64,
    ) -> Result<Self, PipelineError> {
        let first = samples
            .first()
            .ok_or_else(|| PipelineError::Infeasible("the plan has no samples".into()))?;
        Ok(Self {
            params: *params,
            settings: *settings,
            rad_per_tick: std::f64::consts::TAU / f64::from(ticks_per_rev.max(1)),
            max_wheel_rad_s,
            estimate: first.pose(),
            reference: first.pose(),
            last_ticks: None,
            cursor: 0,
        })
    }

    /// Odometry's pose estimate.
    pub fn estimate(&self) -> Pose {
        self.estimate
    }

    /// The plan's pose at the last command's time (interpolated; the last
    /// pose once the plan has ended).
    pub fn reference(&self) -> Pose {
        self.reference
    }

    /// Index of the plan segment in progress.
    pub fn progress(&self) -> usize {
        self.cursor
    }

    /// The wheel commands at `t_s` since the plan started (with the encoder
    /// counts, when they sampled), or `None` once the plan has ended and the
    /// robot is level with its goal.
    pub fn command(
        &mut self,
        samples: &[PlanSample],
        t_s: f64,
        encoder_ticks: Option<[i64; 2]>,
    ) -> Option<[f64; 2]> {
        if let Some(ticks) = encoder_ticks {
            if let Some(prev) = self.last_ticks {
                let dl = (ticks[0] - prev[0]) as f64 * self.rad_per_tick;
                let dr = (ticks[1] - prev[1]) as f64 * self.rad_per_tick;
                self.estimate = arc_step_wheels(&self.estimate, &self.params, dl, dr);
            }
            self.last_ticks = Some(ticks);
        }
        self.steer(samples, t_s)
    }

    /// The wheel commands at `t_s` steering from `estimate` (a robot's own
    /// estimate in the site's frame: odometry fused with localization)
    /// instead of this tracker's odometry; `None` once the plan has ended
    /// and the robot is level with its goal.
    pub fn command_from(
        &mut self,
        samples: &[PlanSample],
        t_s: f64,
        estimate: Pose,
    ) -> Option<[f64; 2]> {
        self.estimate = estimate;
        self.steer(samples, t_s)
    }

    fn steer(&mut self, samples: &[PlanSample], t_s: f64) -> Option<[f64; 2]> {
        let g = &self.settings;
        let t0 = samples[0].t_s;
        let (r, v_r, omega_r, ended) = reference_at(samples, t_s + t0, &mut self.cursor);
        self.reference = r;
        let estimate = self.estimate;
        let (sn, cs) = estimate.heading_rad.sin_cos();
        let (dx, dy) = (r.x_m - estimate.x_m, r.y_m - estimate.y_m);
        let (e_x, e_y) = (cs * dx + sn * dy, -sn * dx + cs * dy);
        let e_theta = wrap_angle(r.heading_rad - estimate.heading_rad);
        // Arrived once the plan has ended and the robot is level with
        // its goal (a differential drive cannot step sideways).
        if ended && e_x.abs() < g.goal_tolerance_m {
            return None;
        }
        let v = v_r * e_theta.cos() + g.gain_along_per_s * e_x;
        // Kanayama's heading and cross-track terms scale with v_r; turns
        // in place and stops (v_r = 0) keep a plain heading correction.
        let omega = omega_r
            + v_r * (g.gain_cross_per_m2 * e_y + g.gain_heading_per_m * e_theta.sin())
            + g.gain_heading_still_per_s * e_theta.sin();
        Some(capped_wheel_speeds(
            &self.params,
            v,
            omega,
            self.max_wheel_rad_s,
        ))
    }
}

/// The wheel speeds (left, right; rad/s) for body velocities `v_m_s` and
/// `omega_rad_s` through `params`, both scaled together so neither wheel
/// exceeds `max_wheel_rad_s` (the path's curvature kept).
pub fn capped_wheel_speeds(
    params: &DiffDriveParams,
    v_m_s: f64,
    omega_rad_s: f64,
    max_wheel_rad_s: f64,
) -> [f64; 2] {
    let (l, r) = wheel_speeds(params, v_m_s, omega_rad_s);
    let peak = l.abs().max(r.abs());
    if peak > max_wheel_rad_s {
        [l * max_wheel_rad_s / peak, r * max_wheel_rad_s / peak]
    } else {
        [l, r]
    }
}

/// Tracks the plan's trajectory closed loop with odometry from the encoders
/// and `params` (the plan's calibrated parameters); see the module docs.
pub fn closed_loop(
    samples: &[PlanSample],
    scenario: Scenario,
    params: &DiffDriveParams,
    settings: &TrackerSettings,
    freedom: &FreedomMap<'_>,
) -> Result<Replay, PipelineError> {
    let mut tracker = Tracker::new(
        samples,
        params,
        settings,
        scenario.robot.encoder.ticks_per_rev,
        scenario.robot.max_wheel_speed_rad_s,
    )?;
    let duration = samples.last().map_or(0.0, |s| s.t_s) - samples[0].t_s;
    replay(
        samples,
        scenario,
        duration + settings.timeout_extra_s,
        freedom,
        move |s| tracker.command(samples, s.t_ns as f64 * 1e-9, s.encoder_ticks),
    )
}

/// A plan that starts in contact must come clear within this (s).
pub const MAX_START_CONTACT_S: f64 = 1.0;

/// What a plan must meet, replayed on the twin, before it may be sent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct Criteria {
    /// The robot's own deviation tolerance, the one it hands back on (m):
    /// a replay further than this from the plan's path would be a hand-back
    /// on the real robot.
    pub max_deviation_m: f64,
}

/// The verdict on a plan: passed, or the reasons it failed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Verdict {
    pub passed: bool,
    /// The tolerance the replays were held to (m).
    pub max_deviation_m: f64,
    /// Why the plan failed, one sentence each (empty when it passed).
    pub reasons: Vec<String>,
    /// What each reason is, for the advice on mending it.
    #[serde(skip)]
    pub causes: Vec<Cause>,
}

/// What kind of failure a reason is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cause {
    /// A replay touched the twin's walls or closed the bumper.
    Contact,
    /// The plan starts in contact and does not come clear.
    StartsInContact,
    /// The plan's path or a replay enters a keep-out zone.
    KeepOut,
    /// A replay leaves the plan's corridor.
    Corridor,
    /// A replay departs from the plan's path or ends off its end.
    Departs,
    /// The plan misses one of the operator's goals.
    Goal,
}

impl Cause {
    /// What the operator can do about it.
    pub fn advice(self) -> &'static str {
        match self {
            Cause::Contact => {
                "the robot would touch the site: rehearse again keeping clear of walls and obstacles"
            }
            Cause::StartsInContact => {
                "the robot starts touching something: place it clear of the walls before the plan starts"
            }
            Cause::KeepOut => {
                "the way enters a keep-out zone: rehearse a way around it (`rehearse --goals ... --freedom FREEDOM.toml` keeps out of the zones) or draw the zone where the robot does not go, then plan again"
            }
            Cause::Corridor => {
                "the robot would leave its corridor: widen the corridor (`plan --freedom` with a [[corridor]] region) or calibrate the robot and plan with its calibration"
            }
            Cause::Departs => {
                "the robot would depart from the plan's path on its own odometry: calibrate the robot and plan with --calibration, and rehearse without contacts"
            }
            Cause::Goal => {
                "the plan misses one of the operator's goals: plan again from the rehearsal from goals (`rehearse --goals`), or rehearse again"
            }
        }
    }
}

impl Verdict {
    /// Judges the open- and closed-loop replays of one plan: each must
    /// touch nothing (no collision, no bump) and stay within the
    /// deviation tolerance of the plan's path, and the closed loop must
    /// end within it of the plan's end.
    pub fn judge(open: &ReplayReport, closed: &ReplayReport, criteria: &Criteria) -> Self {
        Self::of(
            criteria,
            &[("open loop", open), ("closed loop", closed)],
            closed,
        )
    }

    /// Judges the closed-loop replay alone (the way the robot drives a
    /// plan): no contact, within the tolerance of the plan's path, ending
    /// within it of the plan's end.
    pub fn judge_closed_loop(closed: &ReplayReport, criteria: &Criteria) -> Self {
        Self::of(criteria, &[("closed loop", closed)], closed)
    }

    /// The verdict on `replays` (each with its name), and on where
    /// `closed` ended.
    fn of(criteria: &Criteria, replays: &[(&str, &ReplayReport)], closed: &ReplayReport) -> Self {
        let tol = criteria.max_deviation_m;
        // A NaN distance is beyond any tolerance.
        let beyond = |d: f64| d.is_nan() || d > tol;
        let mut reasons = Vec::new();
        let mut causes = Vec::new();
        for &(name, r) in replays {
            if r.collisions > 0 {
                causes.push(Cause::Contact);
                reasons.push(format!(
                    "{name}: {} collision(s) with the twin's walls",
                    r.collisions
                ));
            }
            if r.bumps > 0 {
                causes.push(Cause::Contact);
                reasons.push(format!("{name}: the bumper closed {} time(s)", r.bumps));
            }
            if r.start_contact_s > MAX_START_CONTACT_S {
                causes.push(Cause::StartsInContact);
                reasons.push(format!(
                    "{name}: stays in contact at its start for {:.1} s (at most {MAX_START_CONTACT_S:.1} s to come clear)",
                    r.start_contact_s
                ));
            }
            if !r.keep_out_entered.is_empty() {
                causes.push(Cause::KeepOut);
                reasons.push(format!(
                    "{name}: enters keep-out zone(s) {}",
                    r.keep_out_entered
                        .iter()
                        .map(|z| format!("`{z}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
            }
            // Tracking the plan is held to the deviation tolerance; the
            // corridor bounds what the robot does on its own, and a replay
            // may reach past it (a corridor as narrow as the footprint:
            // directed driving) by no more than that tolerance. A NaN
            // excess is outside any corridor.
            if beyond(r.corridor_excess_m) {
                causes.push(Cause::Corridor);
                reasons.push(format!(
                    "{name}: leaves the plan's corridor by {:.3} m (tolerance {tol:.3} m)",
                    r.corridor_excess_m
                ));
            }
            if beyond(r.max_deviation_m) {
                causes.push(Cause::Departs);
                reasons.push(format!(
                    "{name}: departs {:.3} m from the plan's path (tolerance {tol:.3} m)",
                    r.max_deviation_m
                ));
            }
        }
        if beyond(closed.final_error_m) {
            causes.push(Cause::Departs);
            reasons.push(format!(
                "closed loop: ends {:.3} m from the plan's end (tolerance {tol:.3} m)",
                closed.final_error_m
            ));
        }
        Self {
            passed: reasons.is_empty(),
            max_deviation_m: tol,
            reasons,
            causes,
        }
    }

    /// What to do about each kind of failure, one sentence each, in the
    /// order the reasons come.
    pub fn advice(&self) -> Vec<&'static str> {
        let mut out = Vec::new();
        for c in &self.causes {
            if !out.contains(&c.advice()) {
                out.push(c.advice());
            }
        }
        out
    }

    /// One line for people: `passed (...)` or `FAILED: reason; reason`.
    pub fn summary(&self) -> String {
        if self.passed {
            format!(
                "passed: no contact, within {:.3} m of the plan's path open and closed loop",
                self.max_deviation_m
            )
        } else {
            format!("FAILED: {}", self.reasons.join("; "))
        }
    }
}

/// A plan's verification: both replays on the twin and the verdict.
#[derive(Debug, Clone)]
pub struct PlanVerification {
    pub open_loop: Replay,
    pub closed_loop: Replay,
    pub verdict: Verdict,
}

/// Replays `plan` on the twin `scenario` open loop (the plan's wheel
/// speeds) and closed loop (tracked on odometry through the plan's
/// calibrated parameters), side by side, and judges both by `criteria` and
/// by the plan's freedom (its keep-out zones and corridor, the plan's own
/// path included).
pub fn verify(
    plan: &MissionPlan,
    scenario: &Scenario,
    criteria: &Criteria,
) -> Result<PlanVerification, PipelineError> {
    let samples = &plan.samples;
    let freedom = FreedomMap::of_plan(plan);
    let (open, closed) = std::thread::scope(|s| {
        let closed = s.spawn(|| {
            closed_loop(
                samples,
                scenario.clone(),
                &plan.header.calibrated,
                &TrackerSettings::default(),
                &freedom,
            )
        });
        let open = open_loop(samples, scenario.clone(), None, &freedom);
        (open, closed.join())
    });
    let closed = closed
        .map_err(|_| PipelineError::Infeasible("the closed-loop replay panicked".into()))??;
    let open = open?;
    let mut verdict = Verdict::judge(&open.report, &closed.report, criteria);
    // The plan's own path, beside its replays: the operator's zones are
    // never crossed on purpose, and the operator's goals are kept.
    let mut own = Vec::new();
    if let Some(entry) = zone_entry(plan) {
        own.push((Cause::KeepOut, entry.to_string()));
    }
    own.extend(
        goals_missed(plan, scenario)
            .into_iter()
            .map(|m| (Cause::Goal, m)),
    );
    if !own.is_empty() {
        verdict.passed = false;
        verdict.causes.splice(0..0, own.iter().map(|(c, _)| *c));
        verdict
            .reasons
            .splice(0..0, own.into_iter().map(|(_, r)| r));
    }
    Ok(PlanVerification {
        open_loop: open,
        closed_loop: closed,
        verdict,
    })
}

/// Where a plan's own path first enters one of its keep-out zones.
#[derive(Debug, Clone, PartialEq)]
pub struct ZoneEntry {
    pub zone: String,
    /// Plan time (s from its start) and place.
    pub t_s: f64,
    pub at: [f64; 2],
}

impl std::fmt::Display for ZoneEntry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the plan's own path enters keep-out zone `{}` at {:.2} s ({:.2}, {:.2})",
            self.zone, self.t_s, self.at[0], self.at[1]
        )
    }
}

/// Where `plan`'s own path (the robot's footprint along it) first enters
/// one of its keep-out zones, if it does.
pub fn zone_entry(plan: &MissionPlan) -> Option<ZoneEntry> {
    let freedom = FreedomMap::of_plan(plan);
    let t0 = plan.samples.first().map_or(0.0, |s| s.t_s);
    plan.samples.iter().find_map(|s| {
        freedom.zone_hit([s.x_m, s.y_m]).map(|z| ZoneEntry {
            zone: z.name.clone(),
            t_s: s.t_s - t0,
            at: [s.x_m, s.y_m],
        })
    })
}

/// The operator's goals `plan`'s own path misses on the twin's site, in
/// their words.
pub fn goals_missed(plan: &MissionPlan, scenario: &Scenario) -> Vec<String> {
    if plan.header.goals.is_empty() {
        return Vec::new();
    }
    let path: Vec<(f64, Pose)> = plan.samples.iter().map(|s| (s.t_s, s.pose())).collect();
    crate::kept::goals_kept(
        &plan.header.goals,
        &path,
        &scenario.world,
        plan.header.robot.footprint_radius_m,
        &plan.header.freedom.keep_out,
    )
    .missed()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clean() -> ReplayReport {
        ReplayReport {
            collisions: 0,
            bumps: 0,
            start_contact_s: 0.0,
            max_deviation_m: 0.02,
            mean_deviation_m: 0.01,
            keep_out_entered: Vec::new(),
            corridor_excess_m: 0.0,
            final_error_m: 0.01,
            duration_s: 10.0,
            path_length_m: 3.0,
        }
    }

    #[test]
    fn a_verdict_fails_on_every_departure_and_contact_and_says_which() {
        let c = Criteria {
            max_deviation_m: 0.15,
        };
        assert!(Verdict::judge(&clean(), &clean(), &c).passed);
        // At the tolerance passes; beyond it, or not a number, fails.
        let at = ReplayReport {
            max_deviation_m: 0.15,
            ..clean()
        };
        assert!(Verdict::judge(&at, &at, &c).passed);
        let cases: Vec<(ReplayReport, ReplayReport, &str)> = vec![
            (
                ReplayReport {
                    max_deviation_m: 3.17,
                    ..clean()
                },
                clean(),
                "open loop: departs 3.170 m",
            ),
            (
                clean(),
                ReplayReport {
                    max_deviation_m: f64::NAN,
                    ..clean()
                },
                "closed loop: departs NaN m",
            ),
            (
                clean(),
                ReplayReport {
                    final_error_m: 0.4,
                    ..clean()
                },
                "ends 0.400 m from the plan's end",
            ),
            (
                ReplayReport {
                    collisions: 2,
                    ..clean()
                },
                clean(),
                "2 collision(s)",
            ),
            (
                clean(),
                ReplayReport {
                    bumps: 1,
                    ..clean()
                },
                "bumper closed 1 time(s)",
            ),
            (
                ReplayReport {
                    start_contact_s: 2.5,
                    ..clean()
                },
                clean(),
                "stays in contact at its start for 2.5 s",
            ),
            (
                clean(),
                ReplayReport {
                    keep_out_entered: vec!["crater".into()],
                    ..clean()
                },
                "closed loop: enters keep-out zone(s) `crater`",
            ),
            (
                ReplayReport {
                    corridor_excess_m: 0.16,
                    ..clean()
                },
                clean(),
                "open loop: leaves the plan's corridor by 0.160 m (tolerance 0.150 m)",
            ),
            (
                ReplayReport {
                    corridor_excess_m: f64::NAN,
                    ..clean()
                },
                clean(),
                "leaves the plan's corridor by NaN m",
            ),
        ];
        for (open, closed, reason) in cases {
            let v = Verdict::judge(&open, &closed, &c);
            assert!(!v.passed, "{v:?}");
            assert_eq!(v.reasons.len(), 1, "{v:?}");
            assert!(v.reasons[0].contains(reason), "{v:?}");
            assert!(v.summary().starts_with("FAILED: "), "{}", v.summary());
            // The advice is the cause's own.
            assert_eq!(v.causes.len(), 1, "{v:?}");
            let advice = v.advice().join(" ");
            let says = if reason.contains("keep-out") {
                "keep-out zone"
            } else if reason.contains("corridor") {
                "widen the corridor"
            } else if reason.contains("in contact at its start") {
                "place it clear"
            } else if reason.contains("collision") || reason.contains("bumper") {
                "keeping clear"
            } else {
                "calibrate the robot"
            };
            assert!(advice.contains(says), "{reason}: {advice}");
        }
    }
}
