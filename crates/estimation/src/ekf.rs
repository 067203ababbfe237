//! The augmented extended Kalman filter over [x, y, θ, dL, dR, b] (paper
//! section 4.4), in REP-103 conventions.
//!
//! Prediction runs the arc step on encoder increments with the analytic
//! Jacobians `F` (state) and `G` (wheel rotations); wheel noise grows with
//! the rotation. Updates take an absolute pose or a position with an
//! angle-wrapped innovation, Mahalanobis gating and the Joseph-form
//! covariance update. Both exploit the block structure of the model: `F`
//! is `[[A, B], [0, I]]` and `H` selects the pose, so the products below are
//! the textbook ones evaluated block by block (tests compare them with the
//! dense formulas).

use nalgebra::SMatrix;
use serde::{Deserialize, Serialize};
use twindrive_kinematics::{Mat6, StateVec, Transition, step_with_jacobian, wrap_angle};

pub use crate::covariance::StateAndCovariance;
use crate::covariance::{
    Col, Lanes, add_wheel_noise, gain, joseph_update, propagate, symmetric_inverse,
};

/// Process and measurement noise.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NoiseModel {
    /// Each wheel's rotation error variance grows with its rotation:
    /// `σ² = wheel_rad2_per_rad · |Δφ| + wheel_floor_rad2` (rad²).
    pub wheel_rad2_per_rad: f64,
    pub wheel_floor_rad2: f64,
    /// Random walk of [dL, dR, b] (m²/s each): tyre wear, load. `None` (the
    /// default) keeps the parameters constant.
    pub param_random_walk_m2_per_s: Option<[f64; 3]>,
    /// Standard deviation of the absolute pose reference.
    pub position_std_m: f64,
    pub heading_std_rad: f64,
}

impl Default for NoiseModel {
    fn default() -> Self {
        Self {
            wheel_rad2_per_rad: 1e-4,
            wheel_floor_rad2: 1e-8,
            param_random_walk_m2_per_s: None,
            position_std_m: 0.002,
            heading_std_rad: 0.005,
        }
    }
}

/// Outlier gating.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GateConfig {
    /// Measurements whose squared Mahalanobis distance exceeds the chi-square
    /// quantile at this probability are rejected.
    pub probability: f64,
    /// This many rejections in a row mean the filter has lost track.
    pub max_consecutive_rejections: usize,
    /// When the filter has lost track, re-anchor the pose on the reference
    /// (keeping the parameters) instead of failing: slip, or a robot picked
    /// up and moved. A second loss with no accepted pose in between is
    /// still an error.
    pub reanchor: bool,
}

impl Default for GateConfig {
    fn default() -> Self {
        Self {
            probability: 0.9999,
            max_consecutive_rejections: 240,
            reanchor: true,
        }
    }
}

/// The filter can no longer be trusted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FilterError {
    #[error("at t = {t_s} s the covariance is no longer symmetric positive-definite ({what})")]
    NotPositiveDefinite { t_s: f64, what: &'static str },
    #[error(
        "at t = {t_s} s the filter diverged: {rejections} pose measurements in a row failed the gate (last NIS {nis:.1})"
    )]
    Diverged {
        t_s: f64,
        rejections: usize,
        nis: f64,
    },
    #[error("at t = {t_s} s a non-finite value entered the filter ({what})")]
    NonFinite { t_s: f64, what: &'static str },
}

/// What became of one measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum UpdateOutcome {
    /// Fused; normalised innovation squared and its degrees of freedom.
    Accepted {
        nis: f64,
        dof: usize,
    },
    Rejected {
        nis: f64,
        dof: usize,
    },
    /// Too many rejections in a row: the pose was moved onto this measurement.
    Reanchored {
        nis: f64,
        dof: usize,
    },
}

/// Running innovation statistics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FilterStats {
    pub predictions: u64,
    pub accepted: u64,
    pub rejected: u64,
    pub nis_sum: f64,
    /// Accepted updates whose NIS lies inside the two-sided 95 % chi-square interval.
    pub nis_inside_95: u64,
    /// Times the pose was re-anchored on the reference after losing track.
    pub reanchors: u64,
}

impl FilterStats {
    pub fn mean_nis(&self) -> f64 {
        if self.accepted == 0 {
            0.0
        } else {
            self.nis_sum / self.accepted as f64
        }
    }
}

/// Chi-square quantile.
pub fn chi2_quantile(dof: usize, p: f64) -> f64 {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    ChiSquared::new(dof as f64).expect("dof > 0").inverse_cdf(p)
}

/// The augmented EKF.
#[derive(Debug, Clone)]
pub struct AugmentedEkf {
    est: StateAndCovariance,
    noise: NoiseModel,
    gate: GateConfig,
    /// Gate thresholds and 95 % NIS bounds for 2 and 3 degrees of freedom.
    gate_chi2: [f64; 2],
    nis_95: [(f64, f64); 2],
    stats: FilterStats,
    consecutive_rejections: usize,
    /// True after a re-anchor until the next accepted pose.
    reanchored_since_accept: bool,
}

impl AugmentedEkf {
    pub fn new(initial: StateAndCovariance, noise: NoiseModel, gate: GateConfig) -> Self {
        let dofs = [2, 3];
        Self {
            est: initial,
            noise,
            gate,
            gate_chi2: dofs.map(|d| chi2_quantile(d, gate.probability)),
            nis_95: dofs.map(|d| (chi2_quantile(d, 0.025), chi2_quantile(d, 0.975))),
            stats: FilterStats::default(),
            consecutive_rejections: 0,
            reanchored_since_accept: false,
        }
    }

    pub fn estimate(&self) -> &StateAndCovariance {
        &self.est
    }

    pub fn stats(&self) -> &FilterStats {
        &self.stats
    }

    pub fn noise(&self) -> &NoiseModel {
        &self.noise
    }

    /// Propagates through one encoder increment (wheel rotations in radians)
    /// lasting `dt_s`. Returns the state Jacobian of the step.
    #[inline]
    pub fn predict(&mut self, left_rad: f64, right_rad: f64, dt_s: f64) -> Transition {
        let (next, jac) = step_with_jacobian(&self.est.state, left_rad, right_rad);
        self.est.state = next;
        let q_left = self.noise.wheel_rad2_per_rad * left_rad.abs() + self.noise.wheel_floor_rad2;
        let q_right = self.noise.wheel_rad2_per_rad * right_rad.abs() + self.noise.wheel_floor_rad2;
        let f = jac.state;
        let p = &mut self.est.covariance;
        propagate(p, &f);
        add_wheel_noise(p, &jac.wheels, [q_left, q_right]);
        if let Some(walk) = self.noise.param_random_walk_m2_per_s {
            for (i, w) in walk.iter().enumerate() {
                p[(3 + i, 3 + i)] += w * dt_s;
            }
        }
        self.stats.predictions += 1;
        f
    }

    /// Fuses an absolute pose (x, y, θ).
    pub fn update_pose(
        &mut self,
        t_s: f64,
        x_m: f64,
        y_m: f64,
        heading_rad: f64,
    ) -> Result<UpdateOutcome, FilterError> {
        let s = &self.est.state;
        let nu = [x_m - s[0], y_m - s[1], wrap_angle(heading_rad - s[2])];
        let pos_var = self.noise.position_std_m * self.noise.position_std_m;
        let r = [
            pos_var,
            pos_var,
            self.noise.heading_std_rad * self.noise.heading_std_rad,
        ];
        self.update::<3>(t_s, nu, r)
    }

    /// Fuses a position-only reference (x, y).
    pub fn update_position(
        &mut self,
        t_s: f64,
        x_m: f64,
        y_m: f64,
    ) -> Result<UpdateOutcome, FilterError> {
        let s = &self.est.state;
        let nu = [x_m - s[0], y_m - s[1]];
        let pos_var = self.noise.position_std_m * self.noise.position_std_m;
        self.update::<2>(t_s, nu, [pos_var; 2])
    }

    /// Innovation `nu` of the first `M` state components, measurement noise
    /// `diag(r)`.
    #[inline]
    fn update<const M: usize>(
        &mut self,
        t_s: f64,
        nu: [f64; M],
        r: [f64; M],
    ) -> Result<UpdateOutcome, FilterError> {
        if nu.iter().any(|v| !v.is_finite()) {
            return Err(FilterError::NonFinite {
                t_s,
                what: "measurement",
            });
        }
        let p = &self.est.covariance;
        // S = H P Hᵀ + R with H = [I_M 0].
        let mut s_mat = [[0.0f64; 3]; 3];
        for (i, row) in s_mat.iter_mut().enumerate().take(M) {
            for (j, v) in row.iter_mut().enumerate().take(M) {
                *v = p[(i, j)];
            }
            row[i] += r[i];
        }
        let Some(s_inv) = symmetric_inverse(&s_mat, M) else {
            return Err(FilterError::NotPositiveDefinite {
                t_s,
                what: "innovation covariance",
            });
        };
        let mut nis = 0.0;
        for i in 0..M {
            for j in 0..M {
                nis += nu[i] * s_inv[i][j] * nu[j];
            }
        }
        let k_dof = M - 2;
        if nis > self.gate_chi2[k_dof] {
            self.stats.rejected += 1;
            self.consecutive_rejections += 1;
            if self.consecutive_rejections > self.gate.max_consecutive_rejections {
                if !self.gate.reanchor || self.reanchored_since_accept {
                    return Err(FilterError::Diverged {
                        t_s,
                        rejections: self.consecutive_rejections,
                        nis,
                    });
                }
                self.reanchor(&nu, &r);
                return Ok(UpdateOutcome::Reanchored { nis, dof: M });
            }
            return Ok(UpdateOutcome::Rejected { nis, dof: M });
        }
        self.consecutive_rejections = 0;
        self.reanchored_since_accept = false;
        let k: [Col; M] = gain::<M>(p, &s_inv);
        let mut state = Lanes::load(&self.est.state.into());
        for (km, v) in k.iter().zip(&nu) {
            state.axpy(*v, &Lanes::load(km));
        }
        self.est.state = state.to_col().into();
        joseph_update(&mut self.est.covariance, &k, &r);
        check_covariance(
            &self.est.covariance,
            t_s,
            self.stats.accepted.is_multiple_of(FULL_CHECK_EVERY),
        )?;

        self.stats.accepted += 1;
        self.stats.nis_sum += nis;
        let (lo, hi) = self.nis_95[k_dof];
        if (lo..=hi).contains(&nis) {
            self.stats.nis_inside_95 += 1;
        }
        Ok(UpdateOutcome::Accepted { nis, dof: M })
    }
}

/// What became of a pose measurement with an information matrix: the
/// directions fused and those the gate refused.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct InformationOutcome {
    pub accepted: usize,
    pub rejected: usize,
    /// The largest normalised innovation squared (one degree of freedom each).
    pub max_nis: f64,
}

impl AugmentedEkf {
    /// Fuses a pose measurement known only along some directions (a scan
    /// match: a corridor says nothing of where along it the robot is):
    /// `information` is its inverse covariance, singular where it says
    /// nothing. Each eigen-direction of the information is fused as one
    /// scalar measurement (Joseph form), gated on its own at the filter's
    /// gate probability with one degree of freedom; directions with no
    /// information are skipped. The gate's rejections here do not count
    /// towards the absolute-pose divergence test.
    pub fn update_pose_information(
        &mut self,
        t_s: f64,
        pose: [f64; 3],
        information: &[[f64; 3]; 3],
    ) -> Result<InformationOutcome, FilterError> {
        use nalgebra::{Matrix3, SVector, SymmetricEigen};
        if pose
            .iter()
            .chain(information.iter().flatten())
            .any(|v| !v.is_finite())
        {
            return Err(FilterError::NonFinite {
                t_s,
                what: "pose measurement",
            });
        }
        let info = Matrix3::from_fn(|r, c| 0.5 * (information[r][c] + information[c][r]));
        let eig = SymmetricEigen::new(info);
        let gate = chi2_quantile(1, self.gate.probability);
        let mut outcome = InformationOutcome::default();
        for i in 0..3 {
            let lambda = eig.eigenvalues[i];
            if lambda.is_nan() || lambda <= 0.0 {
                continue;
            }
            let u = eig.eigenvectors.column(i);
            let variance = 1.0 / lambda;
            let s = &self.est.state;
            let nu = u[0] * (pose[0] - s[0])
                + u[1] * (pose[1] - s[1])
                + u[2] * wrap_angle(pose[2] - s[2]);
            let p = &self.est.covariance;
            // P Hᵀ for H = [uᵀ 0].
            let pht: SVector<f64, 6> =
                SVector::from_fn(|r, _| p[(r, 0)] * u[0] + p[(r, 1)] * u[1] + p[(r, 2)] * u[2]);
            let innovation_var = u[0] * pht[0] + u[1] * pht[1] + u[2] * pht[2] + variance;
            if innovation_var.is_nan() || innovation_var <= 0.0 {
                return Err(FilterError::NotPositiveDefinite {
                    t_s,
                    what: "innovation covariance",
                });
            }
            let nis = nu * nu / innovation_var;
            outcome.max_nis = outcome.max_nis.max(nis);
            if nis > gate {
                outcome.rejected += 1;
                self.stats.rejected += 1;
                continue;
            }
            let k = pht / innovation_var;
            for r in 0..6 {
                self.est.state[r] += k[r] * nu;
            }
            // Joseph form: (I - K H) P (I - K H)ᵀ + K R Kᵀ.
            let mut h = SVector::<f64, 6>::zeros();
            h[0] = u[0];
            h[1] = u[1];
            h[2] = u[2];
            let a = Mat6::identity() - k * h.transpose();
            let updated = a * p * a.transpose() + k * k.transpose() * variance;
            self.est.covariance = 0.5 * (updated + updated.transpose());
            outcome.accepted += 1;
            self.stats.accepted += 1;
        }
        check_covariance(&self.est.covariance, t_s, true)?;
        Ok(outcome)
    }

    /// Moves the pose onto the reference (innovation `nu`, noise `r`),
    /// keeps the parameters and forgets the pose-parameter correlation.
    fn reanchor<const M: usize>(&mut self, nu: &[f64; M], r: &[f64; M]) {
        let p = &mut self.est.covariance;
        for i in 0..M {
            self.est.state[i] += nu[i];
            for j in 0..6 {
                if i != j {
                    p[(i, j)] = 0.0;
                    p[(j, i)] = 0.0;
                }
            }
            p[(i, i)] = r[i];
        }
        self.consecutive_rejections = 0;
        self.reanchored_since_accept = true;
        self.stats.reanchors += 1;
    }
}

/// The full positive-definiteness test runs on every this many accepted
/// updates (and the first); the cheap diagonal test runs on all of them.
const FULL_CHECK_EVERY: u64 = 16;

fn check_covariance(p: &Mat6, t_s: f64, full: bool) -> Result<(), FilterError> {
    // NaN and infinities spread into the diagonal within a step.
    if !(0..6).all(|i| p[(i, i)] > 0.0 && p[(i, i)].is_finite()) {
        if p.iter().any(|v| !v.is_finite()) {
            return Err(FilterError::NonFinite {
                t_s,
                what: "covariance",
            });
        }
        return Err(FilterError::NotPositiveDefinite {
            t_s,
            what: "state covariance",
        });
    }
    if !full {
        return Ok(());
    }
    if p.iter().any(|v| !v.is_finite()) {
        return Err(FilterError::NonFinite {
            t_s,
            what: "covariance",
        });
    }
    if !is_positive_definite(p) {
        return Err(FilterError::NotPositiveDefinite {
            t_s,
            what: "state covariance",
        });
    }
    Ok(())
}

/// Symmetric positive-definiteness by an in-place LDLᵀ factorisation that
/// stops at the first non-positive pivot (the matrix is assumed symmetric;
/// only its lower triangle is read).
#[inline]
pub(crate) fn is_positive_definite<const N: usize>(a: &SMatrix<f64, N, N>) -> bool {
    let mut l = [[0.0f64; N]; N];
    let mut d = [0.0f64; N];
    for j in 0..N {
        let mut dj = a[(j, j)];
        for k in 0..j {
            dj -= l[j][k] * l[j][k] * d[k];
        }
        // Also rejects NaN.
        if dj.is_nan() || dj <= 0.0 {
            return false;
        }
        d[j] = dj;
        for i in j + 1..N {
            let mut v = a[(i, j)];
            for k in 0..j {
                v -= l[i][k] * l[j][k] * d[k];
            }
            l[i][j] = v / dj;
        }
    }
    true
}

/// The normalised estimation error squared of `est` against the truth, over
/// the state components `indices`.
pub fn nees(est: &StateAndCovariance, truth: &StateVec, indices: &[usize]) -> f64 {
    let n = indices.len();
    let mut e = nalgebra::DVector::zeros(n);
    let mut p = nalgebra::DMatrix::zeros(n, n);
    for (a, &i) in indices.iter().enumerate() {
        e[a] = if i == 2 {
            wrap_angle(est.state[i] - truth[i])
        } else {
            est.state[i] - truth[i]
        };
        for (b, &j) in indices.iter().enumerate() {
            p[(a, b)] = est.covariance[(i, j)];
        }
    }
    match p.cholesky() {
        Some(c) => e.dot(&c.solve(&e)),
        None => f64::INFINITY,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_spd(rng: &mut ChaCha8Rng) -> Mat6 {
        let m = Mat6::from_fn(|_, _| rng.random_range(-1.0..1.0));
        m * m.transpose() + Mat6::identity() * 0.1
    }

    #[test]
    fn positive_definiteness_test_agrees_with_cholesky() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for k in 0..500 {
            let mut m = random_spd(&mut rng);
            if k % 2 == 0 {
                // Push one eigenvalue below zero.
                let v = nalgebra::SVector::<f64, 6>::from_fn(|_, _| rng.random_range(-1.0..1.0));
                m -= v * v.transpose() * rng.random_range(0.0..50.0);
            }
            assert_eq!(is_positive_definite(&m), m.cholesky().is_some(), "case {k}");
        }
    }

    #[test]
    fn heading_innovation_is_wrapped() {
        let mut p = Mat6::identity() * 1e-6;
        p[(2, 2)] = 0.01;
        let init = StateAndCovariance {
            state: StateVec::new(0.0, 0.0, 3.1, 0.1, 0.1, 0.3),
            covariance: p,
        };
        let mut ekf = AugmentedEkf::new(init, NoiseModel::default(), GateConfig::default());
        // -3.1 is 0.083 rad away across the ±π cut, not 6.2 rad.
        let out = ekf.update_pose(0.0, 0.0, 0.0, -3.1).unwrap();
        assert!(matches!(out, UpdateOutcome::Accepted { .. }), "{out:?}");
        let th = ekf.estimate().state[2];
        assert!(th > 3.1 && th < 3.1 + 0.0832, "{th}");
    }

    /// A filter sure it is at the origin (gate: 5 rejections in a row),
    /// after five poses 3 m away were rejected.
    fn certain_filter_after_five_rejections(reanchor: bool) -> AugmentedEkf {
        let init = StateAndCovariance {
            state: StateVec::new(0.0, 0.0, 0.0, 0.1, 0.1, 0.3),
            covariance: Mat6::identity() * 1e-6,
        };
        let gate = GateConfig {
            probability: 0.9999,
            max_consecutive_rejections: 5,
            reanchor,
        };
        let mut ekf = AugmentedEkf::new(init, NoiseModel::default(), gate);
        for _ in 0..5 {
            assert!(matches!(
                ekf.update_pose(0.0, 3.0, 0.0, 0.0).unwrap(),
                UpdateOutcome::Rejected { .. }
            ));
        }
        ekf
    }

    #[test]
    fn outliers_are_gated_and_divergence_is_an_error() {
        let mut ekf = certain_filter_after_five_rejections(false);
        assert_eq!(
            ekf.estimate().state[0],
            0.0,
            "a rejected pose must not move the estimate"
        );
        assert!(matches!(
            ekf.update_pose(0.0, 3.0, 0.0, 0.0),
            Err(FilterError::Diverged { rejections: 6, .. })
        ));
        assert_eq!(ekf.stats().rejected, 6);
    }

    #[test]
    fn a_moved_robot_is_reanchored_once_and_a_second_loss_is_an_error() {
        let mut ekf = certain_filter_after_five_rejections(true);
        assert!(matches!(
            ekf.update_pose(0.0, 3.0, 0.0, 0.0).unwrap(),
            UpdateOutcome::Reanchored { .. }
        ));
        let s = ekf.estimate().state;
        assert_eq!((s[0], s[1], s[2]), (3.0, 0.0, 0.0));
        assert_eq!((s[3], s[4], s[5]), (0.1, 0.1, 0.3), "parameters kept");
        assert_eq!(ekf.stats().reanchors, 1);
        // Lost again before any pose was accepted: now it is an error.
        for _ in 0..5 {
            assert!(matches!(
                ekf.update_pose(0.0, -3.0, 0.0, 0.0).unwrap(),
                UpdateOutcome::Rejected { .. }
            ));
        }
        assert!(matches!(
            ekf.update_pose(0.0, -3.0, 0.0, 0.0),
            Err(FilterError::Diverged { .. })
        ));
    }

    #[test]
    fn loss_of_positive_definiteness_is_an_error() {
        let mut p = Mat6::identity();
        p[(4, 4)] = -1.0;
        let init = StateAndCovariance {
            state: StateVec::new(0.0, 0.0, 0.0, 0.1, 0.1, 0.3),
            covariance: p,
        };
        let mut ekf = AugmentedEkf::new(init, NoiseModel::default(), GateConfig::default());
        let err = ekf.update_pose(1.5, 0.0, 0.0, 0.0).unwrap_err();
        assert!(
            matches!(
                err,
                FilterError::NotPositiveDefinite {
                    what: "state covariance",
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("t = 1.5 s"));
    }

    #[test]
    fn information_updates_match_the_pose_update_and_skip_what_is_unknown() {
        let mut initial = StateAndCovariance {
            state: StateVec::from([1.0, 2.0, 0.3, 0.066, 0.066, 0.26]),
            covariance: Mat6::from_diagonal(&nalgebra::Vector6::new(
                0.01, 0.02, 0.005, 1e-6, 1e-6, 1e-5,
            )),
        };
        initial.covariance[(0, 3)] = 2e-5;
        initial.covariance[(3, 0)] = 2e-5;
        let noise = NoiseModel {
            position_std_m: 0.03,
            heading_std_rad: 0.02,
            ..NoiseModel::default()
        };
        let mut a = AugmentedEkf::new(initial, noise, GateConfig::default());
        let mut b = a.clone();
        let z = [1.05, 1.93, 0.33];
        a.update_pose(0.0, z[0], z[1], z[2]).unwrap();
        let info = [
            [1.0 / 0.03f64.powi(2), 0.0, 0.0],
            [0.0, 1.0 / 0.03f64.powi(2), 0.0],
            [0.0, 0.0, 1.0 / 0.02f64.powi(2)],
        ];
        let out = b.update_pose_information(0.0, z, &info).unwrap();
        assert_eq!((out.accepted, out.rejected), (3, 0));
        let (ea, eb) = (a.estimate(), b.estimate());
        for i in 0..6 {
            assert!((ea.state[i] - eb.state[i]).abs() < 1e-12, "state {i}");
            for j in 0..6 {
                assert!(
                    (ea.covariance[(i, j)] - eb.covariance[(i, j)]).abs() < 1e-12,
                    "covariance ({i}, {j})"
                );
            }
        }
        // Information along y only: x and the heading keep their prior.
        let mut c = AugmentedEkf::new(initial, noise, GateConfig::default());
        let only_y = [[0.0; 3], [0.0, 1e4, 0.0], [0.0; 3]];
        let out = c.update_pose_information(0.0, z, &only_y).unwrap();
        assert_eq!(out.accepted, 1);
        let e = c.estimate();
        assert!(
            (e.state[1] - 1.93).abs() < 0.001,
            "y moves to the measurement"
        );
        assert_eq!(e.state[2], 0.3, "uncorrelated heading stays");
        assert!(e.covariance[(1, 1)] < 1.1e-4 && e.covariance[(0, 0)] == 0.01);
        // A measurement far outside the gate is refused.
        let far = [[1e6, 0.0, 0.0], [0.0; 3], [0.0; 3]];
        let out = c
            .update_pose_information(0.0, [9.0, 1.93, 0.3], &far)
            .unwrap();
        assert_eq!((out.accepted, out.rejected), (0, 1));
        assert_eq!(c.estimate().state[0], 1.0);
    }
}
