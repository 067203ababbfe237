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

use nalgebra::{Matrix2, Matrix3, SMatrix, Vector2, Vector3};
use serde::{Deserialize, Serialize};
#[cfg(test)]
use twindrive_kinematics::step_jacobians;
use twindrive_kinematics::{Mat6, Mat6x2, StateVec, step_with_jacobians, wrap_angle};

/// The estimate: mean and covariance (the filter's contract).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateAndCovariance {
    pub state: StateVec,
    pub covariance: Mat6,
}

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
    /// lasting `dt_s`. Returns the state Jacobian `F` of the step.
    #[inline]
    pub fn predict(&mut self, left_rad: f64, right_rad: f64, dt_s: f64) -> Mat6 {
        let (next, f, g) = step_with_jacobians(&self.est.state, left_rad, right_rad);
        self.est.state = next;
        let q_left = self.noise.wheel_rad2_per_rad * left_rad.abs() + self.noise.wheel_floor_rad2;
        let q_right = self.noise.wheel_rad2_per_rad * right_rad.abs() + self.noise.wheel_floor_rad2;
        let p = &mut self.est.covariance;
        *p = propagate(&f, p);
        add_input_noise(p, &g, q_left, q_right);
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
        let nu = Vector3::new(x_m - s[0], y_m - s[1], wrap_angle(heading_rad - s[2]));
        let r = Matrix3::from_diagonal(&Vector3::new(
            self.noise.position_std_m.powi(2),
            self.noise.position_std_m.powi(2),
            self.noise.heading_std_rad.powi(2),
        ));
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
        let nu = Vector2::new(x_m - s[0], y_m - s[1]);
        let r = Matrix2::from_diagonal_element(self.noise.position_std_m.powi(2));
        self.update::<2>(t_s, nu, r)
    }

    fn update<const M: usize>(
        &mut self,
        t_s: f64,
        nu: SMatrix<f64, M, 1>,
        r: SMatrix<f64, M, M>,
    ) -> Result<UpdateOutcome, FilterError> {
        if nu.iter().any(|v| !v.is_finite()) {
            return Err(FilterError::NonFinite {
                t_s,
                what: "measurement",
            });
        }
        let p = &self.est.covariance;
        // H selects the first M state components.
        let s_mat: SMatrix<f64, M, M> = p.fixed_view::<M, M>(0, 0) + r;
        // M is 2 or 3: a closed-form inverse beats a general factorisation.
        let s_inv = match s_mat.try_inverse() {
            Some(inv) if leading_minors_positive(&s_mat) => inv,
            _ => {
                return Err(FilterError::NotPositiveDefinite {
                    t_s,
                    what: "innovation covariance",
                });
            }
        };
        let nis = nu.dot(&(s_inv * nu));
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
        // K = P Hᵀ S⁻¹ = P[:, 0..M] S⁻¹.
        let pht: SMatrix<f64, 6, M> = p.fixed_view::<6, M>(0, 0).into_owned();
        let k: SMatrix<f64, 6, M> = pht * s_inv;
        self.est.state += k * nu;
        self.est.covariance = joseph(p, &k, &r);
        check_covariance(
            &self.est.covariance,
            t_s,
            self.stats.accepted % FULL_CHECK_EVERY == 0,
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

impl AugmentedEkf {
    /// Moves the pose onto the reference (innovation `nu`, noise `r`),
    /// keeps the parameters and forgets the pose-parameter correlation.
    fn reanchor<const M: usize>(&mut self, nu: &SMatrix<f64, M, 1>, r: &SMatrix<f64, M, M>) {
        let p = &mut self.est.covariance;
        for i in 0..M {
            self.est.state[i] += nu[i];
            for j in 0..6 {
                if i != j {
                    p[(i, j)] = 0.0;
                    p[(j, i)] = 0.0;
                }
            }
            p[(i, i)] = r[(i, i)];
        }
        self.consecutive_rejections = 0;
        self.reanchored_since_accept = true;
        self.stats.reanchors += 1;
    }
}

/// `F P Fᵀ` for `F = [[A, B], [0, I]]` (3x3 blocks), evaluated by blocks;
/// only the changed blocks are computed, the pose block as a lower triangle
/// mirrored (the result is exactly symmetric).
#[inline]
pub(crate) fn propagate(f: &Mat6, p: &Mat6) -> Mat6 {
    // Top block row of F P: T = [A Ppp + B Pqp, A Ppq + B Pqq] (3x6).
    let mut t = [[0.0f64; 6]; 3];
    for (i, row) in t.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            let mut acc = 0.0;
            for k in 0..6 {
                acc += f[(i, k)] * p[(k, j)];
            }
            *v = acc;
        }
    }
    let mut out = *p;
    // New pose block: T Fᵀ restricted to the pose rows (lower triangle).
    for i in 0..3 {
        for j in 0..=i {
            let mut acc = 0.0;
            for k in 0..6 {
                acc += t[i][k] * f[(j, k)];
            }
            out[(i, j)] = acc;
            out[(j, i)] = acc;
        }
        // Pose-parameter block: T[:, 3..6] (the parameter block of F is I).
        for j in 3..6 {
            out[(i, j)] = t[i][j];
            out[(j, i)] = t[i][j];
        }
    }
    out
}

/// `P += G diag(q) Gᵀ`; only the pose rows of `G` are non-zero.
#[inline]
fn add_input_noise(p: &mut Mat6, g: &Mat6x2, q_left: f64, q_right: f64) {
    for i in 0..3 {
        for j in 0..=i {
            let v = g[(i, 0)] * q_left * g[(j, 0)] + g[(i, 1)] * q_right * g[(j, 1)];
            p[(i, j)] += v;
            if i != j {
                p[(j, i)] += v;
            }
        }
    }
}

/// Joseph form `(I − K H) P (I − K H)ᵀ + K R Kᵀ` with `H = [I_M 0]`,
/// evaluated as that product with the structure of `A = I − K H` (it differs
/// from I only in its first M columns), lower triangle mirrored.
#[inline]
fn joseph<const M: usize>(p: &Mat6, k: &SMatrix<f64, 6, M>, r: &SMatrix<f64, M, M>) -> Mat6 {
    // A P = P − K P[0..M, :].
    let mut ap = [[0.0f64; 6]; 6];
    for (i, row) in ap.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            let mut acc = p[(i, j)];
            for m in 0..M {
                acc -= k[(i, m)] * p[(m, j)];
            }
            *v = acc;
        }
    }
    // K R (R is diagonal for our measurements, but take it whole).
    let kr = k * r;
    let mut out = Mat6::zeros();
    for i in 0..6 {
        for j in 0..=i {
            // (A P Aᵀ)_ij = (AP)_ij − Σ_m (AP)_im K_jm;  + (K R Kᵀ)_ij.
            let mut acc = ap[i][j];
            for m in 0..M {
                acc += kr[(i, m)] * k[(j, m)] - ap[i][m] * k[(j, m)];
            }
            out[(i, j)] = acc;
            out[(j, i)] = acc;
        }
    }
    out
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

/// Sylvester's criterion for the 2x2 and 3x3 innovation covariances (no
/// divisions; larger sizes fall back to [`is_positive_definite`]).
#[inline]
fn leading_minors_positive<const N: usize>(s: &SMatrix<f64, N, N>) -> bool {
    let minor2 = || s[(0, 0)] * s[(1, 1)] - s[(0, 1)] * s[(1, 0)];
    match N {
        2 => s[(0, 0)] > 0.0 && minor2() > 0.0,
        3 => {
            let det = s[(0, 0)] * (s[(1, 1)] * s[(2, 2)] - s[(1, 2)] * s[(2, 1)])
                - s[(0, 1)] * (s[(1, 0)] * s[(2, 2)] - s[(1, 2)] * s[(2, 0)])
                + s[(0, 2)] * (s[(1, 0)] * s[(2, 1)] - s[(1, 1)] * s[(2, 0)]);
            s[(0, 0)] > 0.0 && minor2() > 0.0 && det > 0.0
        }
        _ => is_positive_definite(s),
    }
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

/// The dense measurement matrix `[I_M 0]`, for reference formulas in tests.
#[cfg(test)]
fn dense_h<const M: usize>() -> SMatrix<f64, M, 6> {
    let mut h = SMatrix::<f64, M, 6>::zeros();
    for i in 0..M {
        h[(i, i)] = 1.0;
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    type Mat6x3 = SMatrix<f64, 6, 3>;

    fn random_spd(rng: &mut ChaCha8Rng) -> Mat6 {
        let m = Mat6::from_fn(|_, _| rng.random_range(-1.0..1.0));
        m * m.transpose() + Mat6::identity() * 0.1
    }

    #[test]
    fn block_products_match_dense_formulas() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..200 {
            let p = random_spd(&mut rng);
            let state = StateVec::new(0.3, -1.0, 2.0, 0.065, 0.066, 0.27);
            let (f, g) = step_jacobians(
                &state,
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            let dense = f * p * f.transpose();
            assert!((propagate(&f, &p) - dense).abs().max() < 1e-12);

            let mut with_noise = p;
            add_input_noise(&mut with_noise, &g, 0.3, 0.7);
            let q = nalgebra::Matrix2::new(0.3, 0.0, 0.0, 0.7);
            assert!((with_noise - (p + g * q * g.transpose())).abs().max() < 1e-12);

            let k = Mat6x3::from_fn(|_, _| rng.random_range(-1.0..1.0));
            let r = Matrix3::from_diagonal(&Vector3::new(0.1, 0.2, 0.3));
            let a = Mat6::identity() - k * dense_h::<3>();
            let dense_joseph = a * p * a.transpose() + k * r * k.transpose();
            assert!((joseph(&p, &k, &r) - dense_joseph).abs().max() < 1e-12);
        }
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
}
