//! Censi's two-step closed form (`solver2 -mode 0`), his outlier trimming
//! and his covariance: see [`closed_form_with`].

use nalgebra::{Matrix2, Matrix3, SMatrix, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::RelativeMotion;
use super::model::{odometry, predict};
use crate::ekf::NoiseModel;

/// Censi's solver options (`solver2`: `-outliers_iterations 4`,
/// `-outliers_percentage 0.01`, `-max_cond_number 75`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClosedFormConfig {
    /// Rounds of outlier removal; the estimate is solved `rounds + 1` times.
    pub outlier_rounds: usize,
    /// In each round, motions whose heading residual or whose position
    /// residual is above this upper fraction of all are dropped (0 to 0.5).
    pub outlier_fraction: f64,
    /// Largest condition number of the first step's 2x2 system: above it
    /// the wheels did not turn in enough different ratios ("not very
    /// exciting data", as Censi's solver says).
    pub max_condition_number: f64,
}

impl Default for ClosedFormConfig {
    fn default() -> Self {
        Self {
            outlier_rounds: 4,
            outlier_fraction: 0.01,
            max_condition_number: 75.0,
        }
    }
}

/// The closed-form estimate of the six parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Estimate6 {
    /// `[dL (m), dR (m), b (m), ℓx (m), ℓy (m), ℓθ (rad)]`: wheel diameters,
    /// wheelbase and the lidar's pose in `base_link`.
    pub params: [f64; 6],
    /// Cramér-Rao covariance over `params` (diameters, not Censi's radii).
    pub covariance: [[f64; 6]; 6],
    /// Square roots of the covariance's diagonal.
    pub std: [f64; 6],
    /// The scan matcher's noise as estimated from the residuals:
    /// `[σx (m), σy (m), σθ (rad)]`.
    pub laser_std: [f64; 3],
    /// Motions the final solve used.
    pub used: usize,
    /// Motions dropped as outliers before the final solve.
    pub trimmed: usize,
}

/// [`closed_form_with`] with Censi's settings.
pub fn closed_form(motions: &[RelativeMotion]) -> Option<Estimate6> {
    closed_form_with(motions, &ClosedFormConfig::default())
}

/// Censi's two-step closed form (Censi et al., IEEE T-RO 2013, sec. V; his
/// `solver2` with `-mode 0`), his outlier trimming and his covariance.
///
/// 1. The heading: `s̃_θ = J21·ΔφL + J22·ΔφR` with `J21 = −dL/(2b)` and
///    `J22 = dR/(2b)` (REP-103, counter-clockwise positive; the paper's
///    eq. (3) has the opposite sign) is linear least squares.
/// 2. With `J21`, `J22` known, each motion's odometry is `o = (b·c_x, b·c_y,
///    o_θ)` and `ℓ ⊕ s̃ = o ⊕ ℓ` is linear in `x = (b, ℓx, ℓy, cos ℓθ,
///    sin ℓθ)`: two rows `L_k x = 0` per motion. Minimising `xᵀMx` (`M =
///    Σ L_kᵀL_k`) subject to `x4² + x5² = 1` by a Lagrange multiplier λ
///    leads to `det(M + λW) = 0`, `W = diag(0, 0, 0, 1, 1)`, a quadratic in
///    λ (Censi's `full_calibration_min`). With `M = [[A, B], [Bᵀ, D]]`
///    (`A` 3x3) that determinant is `det(A)·det(S + λI)` with the Schur
///    complement `S = D − BᵀA⁻¹B`, so the two roots are minus the
///    eigenvalues of `S` and the minimum `xᵀMx` (which equals −λ) belongs to
///    the smaller eigenvalue: `(x4, x5)` is its unit eigenvector and
///    `(x1, x2, x3) = −A⁻¹B(x4, x5)`, signed so that `b = x1 > 0`. Then
///    `dL = −2b·J21`, `dR = 2b·J22`, `ℓθ = atan2(x5, x4)`.
///
/// No initial guess is needed, of the mount or anything else. Each motion is
/// taken as one arc at constant wheel speeds (its encoder steps summed).
///
/// `None` for fewer than
/// [`MIN_MOTIONS`](super::MIN_MOTIONS) motions, unusable numbers, an
/// insane configuration or data that do not excite the parameters (the
/// first step's condition number above the limit, a singular second step).
///
/// As Censi's `solver2` does, round `i` solves, computes each motion's
/// residual `ℓ ⊕ s̃ − o ⊕ ℓ`, and drops the motions whose |heading
/// residual| or |position residual| is above the value at index
/// `round((1 − fraction)·n)` of the sorted residuals; the estimate is that
/// of the last solve. The covariance is the inverse Fisher information
/// `(Σ Jᵀ Σ_s⁻¹ J)⁻¹` with `J = ∂s/∂(dL, dR, b, ℓ)` and `Σ_s =
/// diag(σx², σy², σθ²)`, the σ being the sample standard deviations of the
/// residuals `s − s̃` over the motions left after the first round; like
/// Censi's, the sum runs over the motions left after one more round of
/// removal than the final solve saw. With heavy-tailed scan-matching errors
/// those σ are inflated by what one round leaves of the tails (on Censi's
/// l90 drive 10.7 mm, 5.6 mm, 1.1° against the 0.77 mm, 0.56 mm, 0.12° that
/// [`fit`](super::fit) finds), so this covariance is then conservative.
pub fn closed_form_with(motions: &[RelativeMotion], cfg: &ClosedFormConfig) -> Option<Estimate6> {
    super::check_motions(motions).ok()?;
    if !(cfg.outlier_fraction > 0.0 && cfg.outlier_fraction <= 0.5) {
        return None;
    }
    let mut set: Vec<&RelativeMotion> = motions.iter().collect();
    let mut after_first_round: Vec<&RelativeMotion> = Vec::new();
    let mut params = None;
    let mut used = 0;
    for round in 0..=cfg.outlier_rounds {
        if round == 1 {
            after_first_round = set.clone();
        }
        if set.len() < super::MIN_MOTIONS {
            return None;
        }
        let p = solve(&set, cfg.max_condition_number)?;
        used = set.len();
        params = Some(p);
        set = drop_outliers(&set, p, cfg.outlier_fraction);
    }
    let params = params?;
    if after_first_round.is_empty() {
        after_first_round = motions.iter().collect();
    }
    let laser_std = residual_std(&after_first_round, params);
    let covariance = cramer_rao(&set, params, laser_std);
    let std = std::array::from_fn(|i| covariance[i][i].max(0.0).sqrt());
    Some(Estimate6 {
        params,
        covariance,
        std,
        laser_std,
        used,
        trimmed: motions.len() - used,
    })
}

/// The two steps on one set of motions.
fn solve(set: &[&RelativeMotion], max_condition_number: f64) -> Option<[f64; 6]> {
    // Step 1: s̃_θ = J21 ΔφL + J22 ΔφR.
    let mut a = Matrix2::zeros();
    let mut g = Vector2::zeros();
    for m in set {
        let phi = Vector2::from(m.total_wheel_rad());
        a += phi * phi.transpose();
        g += phi * m.laser[2];
    }
    // Finite inputs can still overflow; the eigen-solver wants finite numbers.
    if !a.iter().chain(g.iter()).all(|v| v.is_finite()) {
        return None;
    }
    let eig = a.symmetric_eigenvalues();
    let (lo, hi) = (
        eig[0].abs().min(eig[1].abs()),
        eig[0].abs().max(eig[1].abs()),
    );
    if !(lo > 0.0 && hi / lo <= max_condition_number) {
        return None;
    }
    let j = a.try_inverse()? * g;
    let (j21, j22) = (j[0], j[1]);

    // Step 2: M = Σ L_kᵀ L_k over x = (b, ℓx, ℓy, cos ℓθ, sin ℓθ).
    let mut m5 = SMatrix::<f64, 5, 5>::zeros();
    for m in set {
        let [pl, pr] = m.total_wheel_rad();
        let o_theta = j21 * pl + j22 * pr;
        let (t1, t2) = if o_theta.abs() > 1e-12 {
            (o_theta.sin() / o_theta, (1.0 - o_theta.cos()) / o_theta)
        } else {
            (1.0, 0.0)
        };
        // Travel per metre of wheelbase: ds = b·(−J21 ΔφL + J22 ΔφR)/2.
        let travel = 0.5 * (-j21 * pl + j22 * pr);
        let (cx, cy) = (travel * t1, travel * t2);
        let (so, co) = o_theta.sin_cos();
        let s = m.laser;
        let l = SMatrix::<f64, 2, 5>::new(
            -cx,
            1.0 - co,
            so,
            s[0],
            -s[1],
            -cy,
            -so,
            1.0 - co,
            s[1],
            s[0],
        );
        m5 += l.transpose() * l;
    }
    if !m5.iter().all(|v| v.is_finite()) {
        return None;
    }
    let a3: Matrix3<f64> = m5.fixed_view::<3, 3>(0, 0).into();
    let b32: SMatrix<f64, 3, 2> = m5.fixed_view::<3, 2>(0, 3).into();
    let d2: Matrix2<f64> = m5.fixed_view::<2, 2>(3, 3).into();
    let a3_inv_b = a3.try_inverse()? * b32;
    let schur = d2 - b32.transpose() * a3_inv_b;
    // The smaller eigenvalue of the symmetric 2x2 S and its unit eigenvector.
    let (p, q, r) = (
        schur[(0, 0)],
        0.5 * (schur[(0, 1)] + schur[(1, 0)]),
        schur[(1, 1)],
    );
    let mu = 0.5 * (p + r) - (0.25 * (p - r) * (p - r) + q * q).sqrt();
    let (u, v) = (Vector2::new(q, mu - p), Vector2::new(mu - r, q));
    let e = if u.norm_squared() >= v.norm_squared() {
        u
    } else {
        v
    };
    let norm = e.norm();
    let e = if norm > 0.0 {
        e / norm
    } else {
        // S is a multiple of the identity: every ℓθ fits alike.
        Vector2::new(1.0, 0.0)
    };
    let head = -(a3_inv_b * e);
    let sign = if head[0] < 0.0 { -1.0 } else { 1.0 };
    let (b, lx, ly) = (sign * head[0], sign * head[1], sign * head[2]);
    let (c, s) = (sign * e[0], sign * e[1]);
    let out = [-2.0 * b * j21, 2.0 * b * j22, b, lx, ly, s.atan2(c)];
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// Censi's disagreement `ℓ ⊕ s̃ − o ⊕ ℓ` (component-wise) of one motion,
/// with the motion as one arc.
fn disagreement(m: &RelativeMotion, p: [f64; 6]) -> [f64; 3] {
    let [dl, dr, b, lx, ly, lt] = p;
    let [pl, pr] = m.total_wheel_rad();
    let speed = 0.25 * (dl * pl + dr * pr);
    let o_theta = 0.5 * (dr * pr - dl * pl) / b;
    let (t1, t2) = if o_theta.abs() > 1e-12 {
        (o_theta.sin() / o_theta, (1.0 - o_theta.cos()) / o_theta)
    } else {
        (1.0, 0.0)
    };
    let o = [t1 * speed, t2 * speed, o_theta];
    let (sl, cl) = lt.sin_cos();
    let s = m.laser;
    let l_plus_s = [
        lx + cl * s[0] - sl * s[1],
        ly + sl * s[0] + cl * s[1],
        lt + s[2],
    ];
    let (so, co) = o[2].sin_cos();
    let o_plus_l = [
        o[0] + co * lx - so * ly,
        o[1] + so * lx + co * ly,
        o[2] + lt,
    ];
    std::array::from_fn(|i| l_plus_s[i] - o_plus_l[i])
}

/// The set without the motions above the `1 − fraction` quantile of
/// |heading residual| or of |position residual|.
fn drop_outliers<'a>(
    set: &[&'a RelativeMotion],
    p: [f64; 6],
    fraction: f64,
) -> Vec<&'a RelativeMotion> {
    let err: Vec<(f64, f64)> = set
        .iter()
        .map(|m| {
            let e = disagreement(m, p);
            (e[2].abs(), e[0].hypot(e[1]))
        })
        .collect();
    let n = err.len();
    let index = ((1.0 - fraction) * n as f64)
        .round()
        .clamp(0.0, (n - 1) as f64) as usize;
    let threshold = |pick: fn(&(f64, f64)) -> f64| {
        let mut v: Vec<f64> = err.iter().map(pick).collect();
        v.sort_by(f64::total_cmp);
        v[index]
    };
    let (theta_max, xy_max) = (threshold(|e| e.0), threshold(|e| e.1));
    set.iter()
        .zip(&err)
        .filter(|(_, e)| !(e.0 > theta_max || e.1 > xy_max))
        .map(|(m, _)| *m)
        .collect()
}

/// No wheel noise: Censi's model puts all the noise in the scan matcher.
const NOISELESS_WHEELS: NoiseModel = NoiseModel {
    wheel_rad2_per_rad: 0.0,
    wheel_floor_rad2: 0.0,
    param_random_walk_m2_per_s: None,
    position_std_m: 0.0,
    heading_std_rad: 0.0,
};

/// Predicted lidar motion and its Jacobian over the six parameters.
fn prediction_and_jacobian(m: &RelativeMotion, p: [f64; 6]) -> ([f64; 3], SMatrix<f64, 3, 6>) {
    let o = odometry(&m.wheel_steps, [p[0], p[1], p[2]], &NOISELESS_WHEELS);
    let pr = predict(o.pose, [p[3], p[4], p[5]]);
    let mut j = SMatrix::<f64, 3, 6>::zeros();
    j.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(pr.d_odometry * o.d_params));
    j.fixed_view_mut::<3, 3>(0, 3).copy_from(&pr.d_mount);
    (pr.s, j)
}

/// Sample standard deviations (n − 1) of the residuals `s − s̃` per axis.
fn residual_std(set: &[&RelativeMotion], p: [f64; 6]) -> [f64; 3] {
    let errors: Vec<[f64; 3]> = set
        .iter()
        .map(|m| {
            let (s, _) = prediction_and_jacobian(m, p);
            let heading = twindrive_kinematics::wrap_angle(s[2]) - m.laser[2];
            [s[0] - m.laser[0], s[1] - m.laser[1], heading]
        })
        .collect();
    let n = errors.len() as f64;
    std::array::from_fn(|i| {
        let mean = errors.iter().map(|e| e[i]).sum::<f64>() / n;
        let ss: f64 = errors.iter().map(|e| (e[i] - mean).powi(2)).sum();
        (ss / (n - 1.0).max(1.0)).sqrt()
    })
}

/// The smallest noise level used for the information (noise-free data).
const MIN_STD: f64 = 1e-15;

/// Inverse of `Σ Jᵀ diag(σ)⁻² J`; infinite variances when it is singular.
fn cramer_rao(set: &[&RelativeMotion], p: [f64; 6], sigma: [f64; 3]) -> [[f64; 6]; 6] {
    let w = Vector3::from(sigma.map(|s| 1.0 / s.max(MIN_STD).powi(2)));
    let mut fim = SMatrix::<f64, 6, 6>::zeros();
    for m in set {
        let (_, j) = prediction_and_jacobian(m, p);
        fim += j.transpose() * Matrix3::from_diagonal(&w) * j;
    }
    match fim.try_inverse() {
        Some(c) => std::array::from_fn(|i| std::array::from_fn(|k| c[(i, k)])),
        None => std::array::from_fn(|i| {
            std::array::from_fn(|k| if i == k { f64::INFINITY } else { 0.0 })
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `M` built from random motions: the constrained minimum found through
    /// the Schur complement equals a brute-force search over ℓθ.
    #[test]
    fn schur_solution_is_the_constrained_minimum() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for _ in 0..20 {
            let motions: Vec<RelativeMotion> = (0..40)
                .map(|k| {
                    let w = [rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)];
                    let s = [
                        rng.random_range(-0.05..0.05),
                        rng.random_range(-0.05..0.05),
                        rng.random_range(-0.5..0.5),
                    ];
                    RelativeMotion::constant_speed(k as f64, k as f64 + 1.0, w, s)
                })
                .collect();
            let set: Vec<&RelativeMotion> = motions.iter().collect();
            let Some(p) = solve(&set, 1e9) else { continue };
            // Cost of x = (b, ℓx, ℓy, cos, sin) for the J21, J22 of p.
            let cost = |x: [f64; 5]| -> f64 {
                let (j21, j22) = (-p[0] / (2.0 * p[2]), p[1] / (2.0 * p[2]));
                set.iter()
                    .map(|m| {
                        let [pl, pr] = m.total_wheel_rad();
                        let o = j21 * pl + j22 * pr;
                        let (t1, t2) = if o.abs() > 1e-12 {
                            (o.sin() / o, (1.0 - o.cos()) / o)
                        } else {
                            (1.0, 0.0)
                        };
                        let tr = 0.5 * (-j21 * pl + j22 * pr);
                        let (so, co) = o.sin_cos();
                        let s = m.laser;
                        let r0 = -tr * t1 * x[0] + (1.0 - co) * x[1] + so * x[2] + s[0] * x[3]
                            - s[1] * x[4];
                        let r1 = -tr * t2 * x[0] - so * x[1]
                            + (1.0 - co) * x[2]
                            + s[1] * x[3]
                            + s[0] * x[4];
                        r0 * r0 + r1 * r1
                    })
                    .sum()
            };
            let best = cost([p[2], p[3], p[4], p[5].cos(), p[5].sin()]);
            // For each angle the best (b, ℓx, ℓy) is a 3x3 least squares; a
            // coarse scan of the angle with a local linear solve.
            for k in 0..720 {
                let a = -std::f64::consts::PI + k as f64 * std::f64::consts::PI / 360.0;
                let (c, s) = (a.cos(), a.sin());
                // Minimise over the first three by normal equations (numerically).
                let f = |h: [f64; 3]| cost([h[0], h[1], h[2], c, s]);
                let mut h = Matrix3::zeros();
                let mut g = Vector3::zeros();
                let f0 = f([0.0; 3]);
                for i in 0..3 {
                    let mut e = [0.0; 3];
                    e[i] = 1.0;
                    let fi = f(e);
                    let mut em = [0.0; 3];
                    em[i] = -1.0;
                    let fm = f(em);
                    g[i] = 0.5 * (fi - fm);
                    h[(i, i)] = fi + fm - 2.0 * f0;
                    for k2 in 0..i {
                        let mut e2 = [0.0; 3];
                        e2[i] = 1.0;
                        e2[k2] = 1.0;
                        let mut e2k = [0.0; 3];
                        e2k[k2] = 1.0;
                        h[(i, k2)] = f(e2) - f(e) - f(e2k) + f0;
                        h[(k2, i)] = h[(i, k2)];
                    }
                }
                let xh = -(h.try_inverse().unwrap() * g);
                let c_min = f([xh[0], xh[1], xh[2]]);
                assert!(
                    c_min >= best - 1e-9 * (1.0 + best.abs()),
                    "{c_min} < {best}"
                );
            }
        }
    }
}
