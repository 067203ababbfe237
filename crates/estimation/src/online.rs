//! Online calibration: encoder and pose samples arrive as they come, at
//! different rates and times, and the filter keeps a current estimate.
//!
//! Samples must be pushed in time order across both streams (merge them by
//! timestamp). A pose stamped between two encoder samples waits for the
//! later one; the encoder increment is then split at the pose time (linear
//! interpolation of the cumulative wheel angles), the filter predicts to the
//! pose time, fuses the pose and predicts the rest of the increment.

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};
use twindrive_kinematics::{Mat6, StateVec};

use twindrive_kinematics::Transition;

use crate::covariance::{PackedEstimate, chain};
use crate::ekf::{
    AugmentedEkf, FilterError, FilterStats, GateConfig, NoiseModel, StateAndCovariance,
    UpdateOutcome,
};

/// Cumulative wheel rotation (radians, forward positive) at a time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WheelSample {
    pub t_s: f64,
    pub left_rad: f64,
    pub right_rad: f64,
}

/// An absolute reference pose; `heading_rad: None` for position-only.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseSample {
    pub t_s: f64,
    pub x_m: f64,
    pub y_m: f64,
    pub heading_rad: Option<f64>,
}

/// Filter settings.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FilterConfig {
    pub noise: NoiseModel,
    pub gate: GateConfig,
}

/// The estimate at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    pub t_s: f64,
    pub state: StateVec,
    pub covariance: Mat6,
}

impl Estimate {
    /// Standard deviation of state component `i`.
    pub fn std(&self, i: usize) -> f64 {
        self.covariance[(i, i)].max(0.0).sqrt()
    }
}

/// Calibration input that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibrationError {
    #[error(transparent)]
    Filter(#[from] FilterError),
    #[error(
        "{stream} sample at t = {t_s} s arrived after t = {after_s} s; push samples in time order"
    )]
    OutOfOrder {
        stream: &'static str,
        t_s: f64,
        after_s: f64,
    },
    #[error("{0}")]
    Input(String),
}

/// One fused pose: time, innovation components and NIS, for plots.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InnovationRecord {
    pub t_s: f64,
    pub innovation: [f64; 3],
    pub nis: f64,
    pub accepted: bool,
}

/// Filter nodes kept for the Rauch-Tung-Striebel smoother: one per fused
/// pose, with the prediction that led to it.
#[derive(Debug, Clone, Default)]
pub struct FilterHistory {
    pub t_s: Vec<f64>,
    /// Filtered estimate at each node.
    pub filtered: Vec<PackedEstimate>,
    /// Prediction into each node from the previous one (unused for node 0).
    pub predicted: Vec<PackedEstimate>,
    /// Jacobian of the whole transition from the previous node.
    pub transition: Vec<Transition>,
    pub innovations: Vec<InnovationRecord>,
}

/// The online calibrator.
#[derive(Debug, Clone)]
pub struct OnlineCalibrator {
    ekf: AugmentedEkf,
    t_s: f64,
    last_wheels: Option<WheelSample>,
    /// The latest encoder sample before the start time, to interpolate the
    /// wheel angles at the start.
    before_start: Option<WheelSample>,
    /// Poses waiting for the encoder sample at or after their time, in time order.
    pending: std::collections::VecDeque<PoseSample>,
    last_pose_t_s: f64,
    history: Option<FilterHistory>,
    /// Product of step Jacobians since the last node, for the history.
    transition: Transition,
}

impl OnlineCalibrator {
    /// Starts from `initial` at time `t0_s`. With `keep_history` every fused
    /// pose is kept for smoothing and plotting.
    pub fn new(
        initial: StateAndCovariance,
        t0_s: f64,
        config: FilterConfig,
        keep_history: bool,
    ) -> Self {
        let history = keep_history.then(|| {
            let mut h = FilterHistory::default();
            let packed = PackedEstimate::pack(&initial);
            h.t_s.push(t0_s);
            h.filtered.push(packed);
            h.predicted.push(packed);
            h.transition.push(Transition::IDENTITY);
            h
        });
        Self {
            ekf: AugmentedEkf::new(initial, config.noise, config.gate),
            t_s: t0_s,
            last_wheels: None,
            before_start: None,
            pending: std::collections::VecDeque::new(),
            last_pose_t_s: f64::NEG_INFINITY,
            history,
            transition: Transition::IDENTITY,
        }
    }

    pub fn estimate(&self) -> Estimate {
        let e = self.ekf.estimate();
        Estimate {
            t_s: self.t_s,
            state: e.state,
            covariance: e.covariance,
        }
    }

    pub fn stats(&self) -> &FilterStats {
        self.ekf.stats()
    }

    /// The kept history (if asked for in [`OnlineCalibrator::new`]).
    /// Reserves room in the history for `nodes` more fused poses.
    pub fn reserve(&mut self, nodes: usize) {
        if let Some(h) = &mut self.history {
            h.t_s.reserve(nodes);
            h.filtered.reserve(nodes);
            h.predicted.reserve(nodes);
            h.transition.reserve(nodes);
            h.innovations.reserve(nodes);
        }
    }

    pub fn into_history(self) -> Option<FilterHistory> {
        self.history
    }

    /// Fuses an encoder sample; any poses stamped up to its time are fused
    /// at their own times first. Samples before the start time only serve
    /// to interpolate the wheel angles at the start.
    pub fn push_wheels(&mut self, w: WheelSample) -> Result<(), CalibrationError> {
        let Some(prev) = self.last_wheels else {
            if w.t_s < self.t_s {
                self.before_start = Some(w);
                return Ok(());
            }
            let anchor = match self.before_start.take() {
                Some(b) if w.t_s > self.t_s => {
                    let f = (self.t_s - b.t_s) / (w.t_s - b.t_s);
                    WheelSample {
                        t_s: self.t_s,
                        left_rad: b.left_rad + f * (w.left_rad - b.left_rad),
                        right_rad: b.right_rad + f * (w.right_rad - b.right_rad),
                    }
                }
                // No sample before the start: the state is taken to hold
                // at this first sample.
                _ => {
                    self.t_s = w.t_s;
                    w
                }
            };
            self.last_wheels = Some(anchor);
            self.pending.retain(|p| p.t_s >= anchor.t_s);
            return if anchor.t_s < w.t_s {
                self.push_wheels(w)
            } else {
                Ok(())
            };
        };
        if w.t_s <= prev.t_s {
            return Err(CalibrationError::OutOfOrder {
                stream: "encoder",
                t_s: w.t_s,
                after_s: prev.t_s,
            });
        }
        let mut at = prev; // wheel angles at the filter's current time
        while let Some(pose) = self.pending.front().copied() {
            if pose.t_s > w.t_s {
                break;
            }
            self.pending.pop_front();
            let frac = (pose.t_s - prev.t_s) / (w.t_s - prev.t_s);
            let mid = WheelSample {
                t_s: pose.t_s,
                left_rad: prev.left_rad + frac * (w.left_rad - prev.left_rad),
                right_rad: prev.right_rad + frac * (w.right_rad - prev.right_rad),
            };
            self.predict_between(&at, &mid);
            at = mid;
            self.fuse(&pose)?;
        }
        self.predict_between(&at, &w);
        self.last_wheels = Some(w);
        Ok(())
    }

    /// Queues a pose; it is fused when the encoder sample at or after its
    /// time arrives (at once if one already has).
    pub fn push_pose(&mut self, pose: PoseSample) -> Result<(), CalibrationError> {
        if pose.t_s < self.last_pose_t_s {
            return Err(CalibrationError::OutOfOrder {
                stream: "pose",
                t_s: pose.t_s,
                after_s: self.last_pose_t_s,
            });
        }
        self.last_pose_t_s = pose.t_s;
        match self.last_wheels {
            Some(w) if pose.t_s < w.t_s => Err(CalibrationError::OutOfOrder {
                stream: "pose",
                t_s: pose.t_s,
                after_s: w.t_s,
            }),
            Some(w) if pose.t_s == w.t_s => self.fuse(&pose),
            _ => {
                self.pending.push_back(pose);
                Ok(())
            }
        }
    }

    /// Fuses a pose measurement with an information matrix (a scan match,
    /// [`AugmentedEkf::update_pose_information`]) at the filter's current
    /// time: the time of the latest encoder sample.
    ///
    /// [`AugmentedEkf::update_pose_information`]: crate::AugmentedEkf::update_pose_information
    pub fn update_pose_information(
        &mut self,
        pose: [f64; 3],
        information: &[[f64; 3]; 3],
    ) -> Result<crate::ekf::InformationOutcome, CalibrationError> {
        Ok(self
            .ekf
            .update_pose_information(self.t_s, pose, information)?)
    }

    fn predict_between(&mut self, from: &WheelSample, to: &WheelSample) {
        let dt = to.t_s - from.t_s;
        if dt <= 0.0 {
            return;
        }
        let f = self.ekf.predict(
            to.left_rad - from.left_rad,
            to.right_rad - from.right_rad,
            dt,
        );
        if self.history.is_some() {
            self.transition = chain(&self.transition, &f);
        }
        self.t_s = to.t_s;
    }

    fn fuse(&mut self, pose: &PoseSample) -> Result<(), CalibrationError> {
        // The prediction into this node, for the history.
        let before = self.history.as_ref().map(|_| *self.ekf.estimate());
        let outcome = match pose.heading_rad {
            Some(h) => self.ekf.update_pose(pose.t_s, pose.x_m, pose.y_m, h)?,
            None => self.ekf.update_position(pose.t_s, pose.x_m, pose.y_m)?,
        };
        self.t_s = pose.t_s;
        if let (Some(h), Some(before)) = (&mut self.history, before) {
            let s = &before.state;
            let innovation = [
                pose.x_m - s[0],
                pose.y_m - s[1],
                pose.heading_rad
                    .map_or(0.0, |th| twindrive_kinematics::wrap_angle(th - s[2])),
            ];
            let (nis, accepted) = match outcome {
                UpdateOutcome::Accepted { nis, .. } => (nis, true),
                UpdateOutcome::Rejected { nis, .. } | UpdateOutcome::Reanchored { nis, .. } => {
                    (nis, false)
                }
            };
            h.innovations.push(InnovationRecord {
                t_s: pose.t_s,
                innovation,
                nis,
                accepted,
            });
            if accepted {
                h.t_s.push(pose.t_s);
                h.predicted.push(PackedEstimate::pack(&before));
                h.filtered.push(PackedEstimate::pack(self.ekf.estimate()));
                h.transition.push(self.transition);
                self.transition = Transition::IDENTITY;
            }
        }
        Ok(())
    }
}

/// Sensible initial covariance: the first pose's noise for the pose, and a
/// relative standard deviation for the parameters.
pub fn initial_estimate(
    pose: &PoseSample,
    params: [f64; 3],
    noise: &NoiseModel,
    param_rel_std: f64,
) -> StateAndCovariance {
    let mut cov = Mat6::zeros();
    let pos_var = noise.position_std_m.powi(2);
    cov.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::from_diagonal(&nalgebra::Vector3::new(
            pos_var,
            pos_var,
            if pose.heading_rad.is_some() {
                noise.heading_std_rad.powi(2)
            } else {
                0.5f64.powi(2)
            },
        )));
    for (i, p) in params.iter().enumerate() {
        cov[(3 + i, 3 + i)] = (param_rel_std * p).powi(2);
    }
    StateAndCovariance {
        state: StateVec::new(
            pose.x_m,
            pose.y_m,
            pose.heading_rad.unwrap_or(0.0),
            params[0],
            params[1],
            params[2],
        ),
        covariance: cov,
    }
}
