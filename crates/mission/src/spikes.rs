//! Filter control signals (paper section 5): deleting parts of a path leaves
//! jumps that would need impossible wheel speeds or accelerations ("spikes").
//! Around each spike the path is re-interpolated and driven with a longer
//! travel time: positions by a cubic Hermite curve that keeps the path's own
//! velocity at both ends, the heading separately along the shorter arc, then
//! the window's segments are re-timed as fast as the wheel limits allow
//! ([`crate::retime`]) but never faster than before. Repeated until no spike
//! is left.
//!
//! [`time_optimal`] re-times a whole path the same way with no lower bound:
//! the shortest mission the limits allow on that geometry.

use twindrive_kinematics::{DiffDriveParams, Pose, wheel_speeds, wrap_angle};

use crate::control::{WheelCommand, recompute, segment_arc};
use crate::error::PipelineError;
use crate::path::PathSample;
use crate::retime::{WheelLimits, fastest_durations};

/// Which limit a segment breaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SpikeKind {
    Speed,
    Acceleration,
}

/// A wheel speed or acceleration above the robot's limit.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Spike {
    /// Segment index (from sample `segment` to `segment + 1`).
    pub segment: usize,
    pub t_s: f64,
    /// 0 left, 1 right.
    pub wheel: usize,
    pub kind: SpikeKind,
    pub value: f64,
    pub limit: f64,
}

/// Relative tolerance on the limits (round-off of the re-timing).
const TOLERANCE: f64 = 1e-6;

/// Wheel speeds above the limit and speed changes faster than the
/// acceleration limit (spread over the two half segments), from rest at the
/// start to rest at the end.
pub fn find_spikes(
    samples: &[PathSample],
    commands: &[WheelCommand],
    limits: &WheelLimits,
) -> Vec<Spike> {
    let mut out = Vec::new();
    let n = samples.len();
    if n < 2 {
        return out;
    }
    // (wheel speeds, duration) of the previous segment; rest before the start.
    let mut previous: ([f64; 2], f64) = ([0.0; 2], 0.0);
    for k in 0..n {
        // The last "segment" is the stop after the final sample.
        let (wheels, duration) = if k + 1 < n {
            (commands[k].wheels(), samples[k + 1].t_s - samples[k].t_s)
        } else {
            ([0.0; 2], 0.0)
        };
        let span = 0.5 * (previous.1 + duration);
        for (w, (speed, before)) in wheels.iter().zip(previous.0).enumerate() {
            if speed.abs() > limits.max_speed_rad_s * (1.0 + TOLERANCE) {
                out.push(Spike {
                    segment: k,
                    t_s: samples[k].t_s,
                    wheel: w,
                    kind: SpikeKind::Speed,
                    value: speed.abs(),
                    limit: limits.max_speed_rad_s,
                });
            }
            if span > 0.0 {
                let accel = (speed - before).abs() / span;
                if accel > limits.max_accel_rad_s2 * (1.0 + TOLERANCE) {
                    out.push(Spike {
                        segment: k.min(n - 2),
                        t_s: samples[k].t_s,
                        wheel: w,
                        kind: SpikeKind::Acceleration,
                        value: accel,
                        limit: limits.max_accel_rad_s2,
                    });
                }
            }
        }
        previous = (wheels, duration);
    }
    out
}

/// Settings of the spike filter.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FilterSettings {
    /// Samples kept on each side of a spike in the first window.
    pub window_samples: usize,
    /// Largest heading change per re-interpolated segment (rad).
    pub max_turn_per_segment_rad: f64,
    /// Re-interpolated windows get this many times their old sample count.
    pub oversample: usize,
    pub max_iterations: usize,
}

impl Default for FilterSettings {
    fn default() -> Self {
        Self {
            window_samples: 3,
            max_turn_per_segment_rad: 0.05,
            oversample: 8,
            max_iterations: 20,
        }
    }
}

/// The filtered path and what was done.
#[derive(Debug, Clone, PartialEq)]
pub struct Filtered {
    pub samples: Vec<PathSample>,
    pub commands: Vec<WheelCommand>,
    /// Spikes of the input.
    pub spikes: Vec<Spike>,
    /// Re-interpolated windows (time spans in the output).
    pub windows: Vec<(f64, f64)>,
    pub iterations: usize,
    /// Per sample: whether it is one the filter was to keep where it was
    /// (an operator's goal; see [`filter_spikes_keeping`]).
    pub fixed: Vec<bool>,
}

/// What the filter knows of a sample: whether it was re-interpolated, and
/// whether it must stay where it is.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Marks {
    touched: bool,
    fixed: bool,
}

/// Wheel rotations [left, right] of the arc from `a` to `b`.
fn increments(a: &PathSample, b: &PathSample, params: &DiffDriveParams) -> [f64; 2] {
    let (ds, dtheta) = segment_arc(a, b);
    let (l, r) = wheel_speeds(params, ds, dtheta);
    [l, r]
}

/// Cubic Hermite basis at `s` in [0, 1]: (h00, h10, h01, h11).
fn hermite(s: f64) -> [f64; 4] {
    let (s2, s3) = (s * s, s * s * s);
    [
        2.0 * s3 - 3.0 * s2 + 1.0,
        s3 - 2.0 * s2 + s,
        -2.0 * s3 + 3.0 * s2,
        s3 - s2,
    ]
}

/// Re-interpolates samples `a..=b` (positions by Hermite with the path's
/// velocities arriving at `a` and leaving `b`, heading along the shorter arc
/// with the turn rates there).
fn reinterpolate(
    samples: &[PathSample],
    a: usize,
    b: usize,
    settings: &FilterSettings,
) -> Vec<PathSample> {
    let (pa, pb) = (&samples[a], &samples[b]);
    let span = pb.t_s - pa.t_s;
    // The path's own motion on either side of the window: arriving at `a`
    // (the segment before it; the window's first segment may be the spike)
    // and leaving `b` (the segment after it).
    let before = &samples[a.saturating_sub(1)];
    let (v_a, w_a) = if a > 0 {
        (before.v_m_s, before.omega_rad_s)
    } else {
        (0.0, 0.0)
    };
    let velocity = |heading: f64, v: f64| {
        let (s, c) = heading.sin_cos();
        [v * c * span, v * s * span]
    };
    let (ma, mb) = (
        velocity(pa.pose.heading_rad, v_a),
        velocity(pb.pose.heading_rad, pb.v_m_s),
    );
    let dtheta = wrap_angle(pb.pose.heading_rad - pa.pose.heading_rad);
    let (wa, wb) = (w_a * span, pb.omega_rad_s * span);
    // Several times the old sample count: the window will be driven more
    // slowly, and its segments should stay short in time.
    let segments = ((b - a) * settings.oversample.max(1))
        .max((dtheta.abs() / settings.max_turn_per_segment_rad).ceil() as usize)
        .max(1);
    (0..=segments)
        .map(|i| {
            let s = i as f64 / segments as f64;
            let h = hermite(s);
            let x = h[0] * pa.pose.x_m + h[1] * ma[0] + h[2] * pb.pose.x_m + h[3] * mb[0];
            let y = h[0] * pa.pose.y_m + h[1] * ma[1] + h[2] * pb.pose.y_m + h[3] * mb[1];
            // Heading relative to a, ending at a + Δθ (the shorter arc).
            let th = h[1] * wa + h[2] * dtheta + h[3] * wb;
            PathSample {
                t_s: pa.t_s + s * span,
                pose: Pose::new(x, y, pa.pose.heading_rad + th),
                v_m_s: 0.0,
                omega_rad_s: 0.0,
            }
        })
        .collect()
}

/// Splits every segment longer than [`MAX_HOLD_IN_PERIODS`] times
/// `max_duration_s` into equal pieces of at most `max_duration_s` along its
/// arc, so that no wheel command is held much longer than the control period: a robot (and the twin) changes wheel speed at most `α dt` per
/// tick, so a plan's speed changes must come in steps that small. Returns
/// the new samples and, per input sample, whether its pieces inherit a flag.
fn subdivide(
    samples: &[PathSample],
    flags: &[Marks],
    max_duration_s: f64,
) -> (Vec<PathSample>, Vec<Marks>) {
    let mut out = Vec::with_capacity(samples.len());
    let mut out_flags = Vec::with_capacity(samples.len());
    for (k, w) in samples.windows(2).enumerate() {
        let (a, b) = (&w[0], &w[1]);
        let dt = b.t_s - a.t_s;
        let pieces = if dt <= MAX_HOLD_IN_PERIODS * max_duration_s {
            1
        } else {
            (dt / max_duration_s).ceil() as usize
        };
        let (ds, dtheta) = segment_arc(a, b);
        for i in 0..pieces {
            let f = i as f64 / pieces as f64;
            let pose = if i == 0 {
                a.pose
            } else {
                twindrive_kinematics::arc_step(&a.pose, ds * f, dtheta * f)
            };
            out.push(PathSample {
                t_s: a.t_s + f * dt,
                pose,
                ..*a
            });
            // A piece inside a kept stretch is kept too.
            out_flags.push(if i == 0 {
                flags[k]
            } else {
                Marks {
                    fixed: flags[k].fixed && flags[k + 1].fixed,
                    ..flags[k]
                }
            });
        }
    }
    if let Some(last) = samples.last() {
        out.push(*last);
        out_flags.push(flags[samples.len() - 1]);
    }
    (out, out_flags)
}

/// Assigns the segment durations to the samples, from the first sample's time.
fn apply_durations(samples: &mut [PathSample], durations: &[f64]) {
    let mut t = samples.first().map_or(0.0, |p| p.t_s);
    for (k, p) in samples.iter_mut().enumerate() {
        p.t_s = t;
        if let Some(d) = durations.get(k) {
            t += d;
        }
    }
}

/// Re-times `samples` as fast as `limits` allow but never faster than
/// `min_durations`. The re-timing's acceleration model is continuous while
/// the check ([`find_spikes`]) is per segment; where they disagree (jagged
/// geometry) the segments around each remaining spike get a longer minimum
/// duration and the re-timing runs again, so only those places slow down.
/// Returns the commands and the spikes still left after those attempts.
fn retime_checked(
    samples: &mut [PathSample],
    min_durations: &[f64],
    params: &DiffDriveParams,
    limits: &WheelLimits,
) -> Result<(Vec<WheelCommand>, Vec<Spike>), PipelineError> {
    let inc: Vec<[f64; 2]> = samples
        .windows(2)
        .map(|w| increments(&w[0], &w[1], params))
        .collect();
    let mut mins = min_durations.to_vec();
    let planning = limits.scaled(0.95);
    let mut attempt = 0;
    loop {
        let durations = fastest_durations(&inc, &mins, &planning)?;
        apply_durations(samples, &durations);
        let commands = recompute(samples, params);
        let spikes = find_spikes(samples, &commands, limits);
        attempt += 1;
        if spikes.is_empty() || attempt == REPAIR_ATTEMPTS {
            return Ok((commands, spikes));
        }
        for s in &spikes {
            let lo = s.segment.saturating_sub(1);
            let hi = (s.segment + 1).min(durations.len() - 1);
            for k in lo..=hi {
                // A standstill (a dwell) is no faster for being longer.
                if inc[k].iter().any(|v| v.abs() >= 1e-9) {
                    mins[k] = mins[k].max(durations[k] * 1.15);
                }
            }
        }
    }
}

/// Re-timings per call of [`retime_checked`].
const REPAIR_ATTEMPTS: usize = 60;

/// Segments held longer than this many control periods are split.
pub const MAX_HOLD_IN_PERIODS: f64 = 1.5;

/// Splits segments held longer than [`MAX_HOLD_IN_PERIODS`] and re-times
/// them (never faster), a few passes at most: re-timing stretches some
/// pieces again where it has to slow down, so holds end up near, not
/// strictly under, that bound (the case study's longest is 2.5 periods).
/// Returns the commands and the spikes left.
fn make_executable(
    samples: &mut Vec<PathSample>,
    flags: &mut Vec<Marks>,
    period_s: f64,
    mut commands: Vec<WheelCommand>,
    params: &DiffDriveParams,
    limits: &WheelLimits,
) -> Result<(Vec<WheelCommand>, Vec<Spike>), PipelineError> {
    let mut spikes = Vec::new();
    for _ in 0..PASSES {
        if samples
            .windows(2)
            .all(|w| w[1].t_s - w[0].t_s <= MAX_HOLD_IN_PERIODS * period_s)
        {
            break;
        }
        let (finer, finer_flags) = subdivide(samples, flags, period_s);
        let mins: Vec<f64> = finer.windows(2).map(|w| w[1].t_s - w[0].t_s).collect();
        *samples = finer;
        *flags = finer_flags;
        (commands, spikes) = retime_checked(samples, &mins, params, limits)?;
    }
    Ok((commands, spikes))
}

/// Split-and-re-time passes of [`make_executable`].
const PASSES: usize = 4;

/// Removes every spike; see the module docs. `period_s` is the control
/// period of the robot: segments held much longer are split (see
/// [`make_executable`]).
pub fn filter_spikes(
    input: &[PathSample],
    params: &DiffDriveParams,
    limits: &WheelLimits,
    period_s: f64,
    settings: &FilterSettings,
) -> Result<Filtered, PipelineError> {
    let fixed = vec![false; input.len()];
    filter_spikes_keeping(input, &fixed, params, limits, period_s, settings)
}

/// [`filter_spikes`], keeping every sample marked in `fixed` (one flag per
/// input sample) where it is: no window re-interpolates across one (a
/// window may end on it), so an operator's goal keeps its place, heading
/// and dwell; re-timing only ever slows it.
pub fn filter_spikes_keeping(
    input: &[PathSample],
    fixed: &[bool],
    params: &DiffDriveParams,
    limits: &WheelLimits,
    period_s: f64,
    settings: &FilterSettings,
) -> Result<Filtered, PipelineError> {
    if fixed.len() != input.len() {
        return Err(PipelineError::Infeasible(format!(
            "{} flags for {} samples",
            fixed.len(),
            input.len()
        )));
    }
    limits.validate()?;
    if !(period_s.is_finite() && period_s > 0.0) {
        return Err(PipelineError::Value(
            twindrive_plan::PlanError::BadSetting {
                field: "period_s",
                value: period_s,
            },
        ));
    }
    let mut samples = input.to_vec();
    let mut commands = recompute(&mut samples, params);
    let first_spikes = find_spikes(&samples, &commands, limits);
    // Which samples were re-interpolated (for the windows reported), and
    // which stay where they are.
    let mut touched: Vec<Marks> = fixed
        .iter()
        .map(|&fixed| Marks {
            touched: false,
            fixed,
        })
        .collect();
    let mut width = settings.window_samples.max(1);
    let mut iterations = 0;
    let mut spikes = first_spikes.clone();
    loop {
        if spikes.is_empty() {
            if holds_at_most(&samples, period_s) {
                break;
            }
            (commands, spikes) = make_executable(
                &mut samples,
                &mut touched,
                period_s,
                commands,
                params,
                limits,
            )?;
            if spikes.is_empty() {
                break;
            }
        }
        if iterations == settings.max_iterations {
            return Err(PipelineError::Infeasible(format!(
                "{} control spike(s) remain after {iterations} re-interpolations; the limits cannot be met on this path",
                spikes.len()
            )));
        }
        iterations += 1;
        // Windows around clusters of spikes, merged when they overlap;
        // wider on every round.
        let last = samples.len() - 1;
        let mut spans: Vec<(usize, usize)> = Vec::new();
        for s in &spikes {
            // No kept sample inside a window: it ends on the nearest.
            let lo = (s.segment.saturating_sub(width)..=s.segment)
                .rev()
                .find(|&k| touched[k].fixed)
                .unwrap_or(s.segment.saturating_sub(width));
            let hi = (s.segment + 1..=(s.segment + 1 + width).min(last))
                .find(|&k| touched[k].fixed)
                .unwrap_or((s.segment + 1 + width).min(last));
            // Windows that only touch stay apart (the sample between them
            // may be kept).
            match spans.last_mut() {
                Some(prev) if lo < prev.1 => prev.1 = prev.1.max(hi),
                _ => spans.push((lo, hi)),
            }
        }
        // New geometry in each window, spread evenly over its old time span.
        let mut out: Vec<PathSample> = Vec::with_capacity(samples.len() + 64);
        let mut out_touched: Vec<Marks> = Vec::with_capacity(samples.len() + 64);
        let mut next = 0;
        for &(a, b) in &spans {
            out.extend_from_slice(&samples[next..a]);
            out_touched.extend_from_slice(&touched[next..a]);
            let geometry = reinterpolate(&samples, a, b, settings);
            out.extend_from_slice(&geometry[..geometry.len() - 1]);
            // The window's first sample is `a` as it was; what lies between
            // is kept only inside a kept stretch.
            let inside = touched[a].fixed && touched[b].fixed;
            out_touched.push(Marks {
                touched: true,
                fixed: touched[a].fixed,
            });
            out_touched.extend(std::iter::repeat_n(
                Marks {
                    touched: true,
                    fixed: inside,
                },
                geometry.len() - 2,
            ));
            next = b;
        }
        out.extend_from_slice(&samples[next..]);
        out_touched.extend_from_slice(&touched[next..]);
        // Longer travel times where needed, never shorter than before.
        let min_durations: Vec<f64> = out.windows(2).map(|w| w[1].t_s - w[0].t_s).collect();
        (commands, spikes) = retime_checked(&mut out, &min_durations, params, limits)?;
        samples = out;
        touched = out_touched;
        width *= 2;
    }
    let mut windows: Vec<(f64, f64)> = Vec::new();
    for (k, p) in samples.iter().enumerate() {
        if !touched[k].touched {
            continue;
        }
        let end = samples.get(k + 1).map_or(p.t_s, |q| q.t_s);
        match windows.last_mut() {
            Some(w) if k > 0 && touched[k - 1].touched => w.1 = end,
            _ => windows.push((p.t_s, end)),
        }
    }
    Ok(Filtered {
        samples,
        commands,
        spikes: first_spikes,
        windows,
        iterations,
        fixed: touched.iter().map(|m| m.fixed).collect(),
    })
}

/// Whether no segment is held longer than [`MAX_HOLD_IN_PERIODS`] periods.
fn holds_at_most(samples: &[PathSample], period_s: f64) -> bool {
    longest_hold_s(samples) <= MAX_HOLD_IN_PERIODS * period_s * (1.0 + 1e-9)
}

/// The longest time a plan holds one wheel command.
pub fn longest_hold_s(samples: &[PathSample]) -> f64 {
    samples
        .windows(2)
        .map(|w| w[1].t_s - w[0].t_s)
        .fold(0.0, f64::max)
}

/// Re-times the whole path as fast as the limits allow, from rest to rest
/// (samples where neither wheel moves are merged away), with long holds
/// split as in [`filter_spikes`].
pub fn time_optimal(
    input: &[PathSample],
    params: &DiffDriveParams,
    limits: &WheelLimits,
    period_s: f64,
) -> Result<(Vec<PathSample>, Vec<WheelCommand>), PipelineError> {
    time_optimal_keeping(input, &vec![false; input.len()], params, limits, period_s)
}

/// [`time_optimal`], where the robot stands still between two samples
/// marked in `fixed` (an operator's dwell at a goal) it stands as long as
/// before.
pub fn time_optimal_keeping(
    input: &[PathSample],
    fixed: &[bool],
    params: &DiffDriveParams,
    limits: &WheelLimits,
    period_s: f64,
) -> Result<(Vec<PathSample>, Vec<WheelCommand>), PipelineError> {
    limits.validate()?;
    // Kept samples: every sample that moves a wheel, and a dwell's samples
    // all (a long standstill as one segment would let the re-timing
    // stretch it; as the control periods it was, it keeps its time).
    let mut kept: Vec<PathSample> = Vec::with_capacity(input.len());
    let mut kept_fixed: Vec<bool> = Vec::with_capacity(input.len());
    for (p, &f) in input.iter().zip(fixed) {
        match kept.last() {
            Some(q)
                if !(f && kept_fixed.last() == Some(&true))
                    && increments(q, p, params).iter().all(|v| v.abs() < 1e-9) => {}
            _ => {
                kept.push(*p);
                kept_fixed.push(f);
            }
        }
    }
    if kept.len() < 2 {
        let commands = recompute(&mut kept, params);
        return Ok((kept, commands));
    }
    let mins: Vec<f64> = kept
        .windows(2)
        .zip(kept_fixed.windows(2))
        .map(|(w, f)| {
            let standing = increments(&w[0], &w[1], params)
                .iter()
                .all(|v| v.abs() < 1e-9);
            if f[0] && f[1] && standing {
                w[1].t_s - w[0].t_s
            } else {
                0.0
            }
        })
        .collect();
    let (commands, spikes) = retime_checked(&mut kept, &mins, params, limits)?;
    let mut flags = vec![Marks::default(); kept.len()];
    let (commands, spikes) = if spikes.is_empty() {
        make_executable(&mut kept, &mut flags, period_s, commands, params, limits)?
    } else {
        (commands, spikes)
    };
    if !spikes.is_empty() {
        return Err(PipelineError::Infeasible(format!(
            "the time-optimal re-timing left {} spike(s)",
            spikes.len()
        )));
    }
    Ok((kept, commands))
}

#[cfg(test)]
mod dwell_tests {
    use super::*;

    /// A straight drive that stops for 3 s (the stop marked as kept): the
    /// time-optimal re-timing stands there 3 s (a few control periods more
    /// at most, where it eases in and out).
    #[test]
    fn the_time_optimal_re_timing_keeps_a_dwell_as_long_as_it_was() {
        let params = DiffDriveParams::new(0.066, 0.066, 0.26);
        let limits = WheelLimits {
            max_speed_rad_s: 10.0,
            max_accel_rad_s2: 20.0,
        };
        let mut path = Vec::new();
        let mut fixed = Vec::new();
        let mut t = 0.0;
        let mut x = 0.0;
        for k in 0..700 {
            let standing = (200..500).contains(&k);
            path.push(PathSample {
                t_s: t,
                pose: Pose::new(x, 0.0, 0.0),
                v_m_s: 0.0,
                omega_rad_s: 0.0,
            });
            fixed.push((195..505).contains(&k));
            t += 0.01;
            if !standing {
                x += 0.002;
            }
        }
        let (out, _) = time_optimal_keeping(&path, &fixed, &params, &limits, 0.01).unwrap();
        let standing: f64 = out
            .windows(2)
            .filter(|w| {
                (w[1].pose.x_m - w[0].pose.x_m).abs() < 1e-12 && (w[1].pose.x_m - 0.4).abs() < 1e-9
            })
            .map(|w| w[1].t_s - w[0].t_s)
            .sum();
        assert!((2.99..3.2).contains(&standing), "stood {standing} s");
    }
}
