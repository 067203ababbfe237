//! Maximum-likelihood self-calibration: see [`fit`].

use nalgebra::{DMatrix, DVector, Matrix4, SMatrix, SymmetricEigen, Vector4};
use serde::{Deserialize, Serialize};
use twindrive_kinematics::wrap_angle;

use super::RelativeMotion;
use super::identifiability::identifiability;
use super::model::{odometry, predict};
use crate::batch::Identifiability;
use crate::ekf::{NoiseModel, chi2_quantile};
use crate::online::CalibrationError;

/// Settings of [`fit`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SelfCalConfig {
    /// Levenberg-Marquardt iterations per solve.
    pub max_iterations: usize,
    /// Huber threshold on each motion's whitened residual norm;
    /// `f64::INFINITY` for plain least squares.
    pub huber_k: f64,
    /// Wheel noise of the odometry (`wheel_rad2_per_rad`,
    /// `wheel_floor_rad2`); the pose-reference fields are not used.
    pub noise: NoiseModel,
    /// Largest number of rounds of outlier trimming; each round refits.
    pub trim_rounds: usize,
    /// In each round, the motions whose whitened residual (squared
    /// Mahalanobis distance over 3 or, with a gyro, 4 dimensions) lies
    /// beyond the chi-square quantile at this probability are dropped; the
    /// rounds stop when none is. Unlike a fixed share per round (Censi's
    /// rule, which [`closed_form`](super::closed_form) follows), clean data
    /// then keep all but about 1 − probability of their motions, so the
    /// fitted noise levels are not biased low by the trimming.
    pub trim_probability: f64,
    /// Starting gyro bias (rad/s) and scale error (unitless).
    pub gyro_initial: [f64; 2],
    /// Largest number of times the noise levels are re-estimated and the
    /// parameters solved again, per trimming round.
    pub max_noise_iterations: usize,
}

impl Default for SelfCalConfig {
    fn default() -> Self {
        Self {
            max_iterations: 50,
            huber_k: 3.0,
            noise: NoiseModel::default(),
            trim_rounds: 10,
            trim_probability: 0.999,
            gyro_initial: [0.0, 0.0],
            max_noise_iterations: 30,
        }
    }
}

/// The laser noise the fit settled on.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LaserNoise {
    /// `[σx (m), σy (m), σθ (rad)]` of the motions without a matcher
    /// covariance (`None` if every motion has one).
    pub axis_std: Option<[f64; 3]>,
    /// The factor α on the matcher's covariances (`None` if no motion has
    /// one).
    pub covariance_scale: Option<f64>,
}

/// The gyro's calibration.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GyroCalibration {
    /// β: the rate the gyro reads at standstill (rad/s).
    pub bias_rad_s: f64,
    pub bias_std_rad_s: f64,
    /// κ: the gyro reads (1 + κ) times the true rate.
    pub scale_error: f64,
    pub scale_error_std: f64,
    /// The gyro's angle noise density σ_g (rad/√s), fitted.
    pub noise_rad_per_sqrt_s: f64,
    /// RMS of the gyro residuals (rad).
    pub residual_rms_rad: f64,
}

/// The self-calibration and what it says about the drive.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SelfCalResult {
    /// `[dL, dR, b]` (m).
    pub params: [f64; 3],
    /// Their standard deviations (m), from the inverse information.
    pub std: [f64; 3],
    /// The lidar's pose in `base_link`: `[ℓx (m), ℓy (m), ℓθ (rad)]`, ℓθ in
    /// (−π, π].
    pub mount: [f64; 3],
    /// Their standard deviations (m, m, rad); infinite for what the drive
    /// does not observe at all.
    pub mount_std: [f64; 3],
    /// Present when the motions carry gyro angles.
    pub gyro: Option<GyroCalibration>,
    /// Covariance over the estimated parameters in the order of
    /// `identifiability.parameters` (dL, dR, b, lx, ly, ltheta, and with a
    /// gyro bias, scale), in their units.
    pub covariance: Vec<Vec<f64>>,
    pub laser_noise: LaserNoise,
    /// Levenberg-Marquardt iterations over all solves.
    pub iterations: usize,
    /// RMS of the whitened residuals of the used motions (≈ 1).
    pub whitened_rms: f64,
    /// RMS of the laser residuals of the used motions `[x (m), y (m), θ (rad)]`.
    pub residual_rms: [f64; 3],
    /// Motions in the final solve.
    pub used: usize,
    /// Motions trimmed as outliers.
    pub trimmed: usize,
    pub identifiability: Identifiability,
}

/// The fixed layout of the parameter vector: six, then β and κ.
const NP: usize = 8;
type Params = [f64; NP];
type Jac = SMatrix<f64, 4, NP>;

/// The noise levels being fitted.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Noise {
    /// σx², σy², σθ² for motions without a matcher covariance.
    axis_var: [f64; 3],
    /// α for motions with one.
    alpha: f64,
    /// σ_g² (rad²/s).
    gyro_var_per_s: f64,
}

/// One motion's residual (4th entry the gyro's, zero without one), its
/// Jacobian with respect to the parameters, and its covariance split into
/// the laser/gyro part and the odometry part.
struct Term {
    r: Vector4<f64>,
    j: Jac,
    /// Odometry noise carried into the residual.
    odo: Matrix4<f64>,
}

fn term(m: &RelativeMotion, p: &Params, noise: &NoiseModel) -> Term {
    let o = odometry(&m.wheel_steps, [p[0], p[1], p[2]], noise);
    let pr = predict(o.pose, [p[3], p[4], p[5]]);
    let mut r = Vector4::new(
        m.laser[0] - pr.s[0],
        m.laser[1] - pr.s[1],
        wrap_angle(m.laser[2] - pr.s[2]),
        0.0,
    );
    // K = ∂(s, g)/∂o (4x3).
    let mut k = SMatrix::<f64, 4, 3>::zeros();
    k.fixed_view_mut::<3, 3>(0, 0).copy_from(&pr.d_odometry);
    let mut j = Jac::zeros();
    let ds_dp = pr.d_odometry * o.d_params;
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-ds_dp));
    j.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-pr.d_mount));
    if let Some(g) = m.gyro_rad {
        let t = m.duration_s();
        let scale = 1.0 + p[7];
        r[3] = g - scale * o.pose[2] - p[6] * t;
        k[(3, 2)] = scale;
        for c in 0..3 {
            j[(3, c)] = -scale * o.d_params[(2, c)];
        }
        j[(3, 6)] = -t;
        j[(3, 7)] = -o.pose[2];
    }
    Term {
        r,
        j,
        odo: k * o.cov * k.transpose(),
    }
}

/// The laser/gyro part of a motion's covariance at the current noise levels.
fn sensor_cov(m: &RelativeMotion, noise: &Noise) -> Matrix4<f64> {
    let mut c = Matrix4::zeros();
    match &m.laser_cov {
        Some(l) => {
            for i in 0..3 {
                for k in 0..3 {
                    c[(i, k)] = noise.alpha * l[i][k];
                }
            }
        }
        None => {
            for i in 0..3 {
                c[(i, i)] = noise.axis_var[i];
            }
        }
    }
    c[(3, 3)] = match m.gyro_rad {
        Some(_) => noise.gyro_var_per_s * m.duration_s(),
        // No gyro residual: a unit variance on a zero residual adds nothing.
        None => 1.0,
    };
    c
}

/// The inverse of a residual covariance. The odometry part has rank two
/// (two wheels) and the laser's heading and the gyro see the same odometry
/// heading, so with very small laser and gyro noise the matrix is close to
/// singular; a relative jitter of 1e-12 on the diagonal then keeps the
/// factorisation alive without changing any weight that matters.
fn inverse_cov(c: &Matrix4<f64>) -> Option<Matrix4<f64>> {
    if let Some(ch) = c.cholesky() {
        return Some(ch.inverse());
    }
    let mut jittered = *c;
    for i in 0..4 {
        jittered[(i, i)] += 1e-12 * c[(i, i)].abs() + 1e-300;
    }
    jittered.cholesky().map(|ch| ch.inverse())
}

/// What a pass over the used motions gives.
struct Pass {
    h: DMatrix<f64>,
    g: DVector<f64>,
    cost: f64,
    whitened_sq: f64,
    dims: usize,
    raw_sq: [f64; 4],
    count: usize,
    gyro_count: usize,
}

fn pass(
    motions: &[RelativeMotion],
    used: &[usize],
    p: &Params,
    noise: &Noise,
    cfg: &SelfCalConfig,
    n: usize,
) -> Option<Pass> {
    let mut h = SMatrix::<f64, NP, NP>::zeros();
    let mut g = SMatrix::<f64, NP, 1>::zeros();
    let (mut cost, mut whitened_sq, mut dims) = (0.0, 0.0, 0usize);
    let mut raw_sq = [0.0; 4];
    let mut gyro_count = 0;
    for &i in used {
        let m = &motions[i];
        let t = term(m, p, &cfg.noise);
        let c_inv = inverse_cov(&(sensor_cov(m, noise) + t.odo))?;
        let c_inv_r = c_inv * t.r;
        let m2 = t.r.dot(&c_inv_r);
        let dist = m2.sqrt();
        let weight = if dist <= cfg.huber_k {
            1.0
        } else {
            cfg.huber_k / dist
        };
        let jt_w = t.j.transpose() * (c_inv * weight);
        h += jt_w * t.j;
        g += jt_w * t.r;
        cost += if dist <= cfg.huber_k {
            0.5 * m2
        } else {
            cfg.huber_k * (dist - 0.5 * cfg.huber_k)
        };
        whitened_sq += m2;
        dims += 3;
        if m.gyro_rad.is_some() {
            dims += 1;
            gyro_count += 1;
        }
        for (acc, v) in raw_sq.iter_mut().zip(t.r.iter()) {
            *acc += v * v;
        }
    }
    Some(Pass {
        h: DMatrix::from_fn(n, n, |i, k| h[(i, k)]),
        g: DVector::from_fn(n, |i, _| g[i]),
        cost,
        whitened_sq,
        dims,
        raw_sq,
        count: used.len(),
        gyro_count,
    })
}

/// A ridge on the diagonal of the Levenberg-Marquardt system: `1/w²` per
/// parameter with widths `w` far beyond anything a drive leaves uncertain
/// (100 % of dL, dR, b; 1 m for ℓx, ℓy; 1 rad for ℓθ; 0.1 rad/s for the
/// gyro bias; 1 for its scale error). Where a drive observes a combination
/// not at all (straight lines leave b, ℓx, ℓy free) both the information
/// and the gradient vanish and a Gauss-Newton step would be round-off
/// divided by round-off, walking those parameters off to metres; the ridge
/// keeps them where they are. It damps steps only (no pull towards the
/// start), so the point the iteration converges to is the maximum of the
/// likelihood, and it is left out of the reported information.
fn step_ridge(p: &Params, n: usize) -> Vec<f64> {
    let widths = [p[0], p[1], p[2], 1.0, 1.0, 1.0, 0.1, 1.0];
    widths[..n].iter().map(|w| 1.0 / (w * w)).collect()
}

/// Relative cost changes below this are round-off: converged.
const RELATIVE_COST_TOLERANCE: f64 = 1e-9;

/// Levenberg-Marquardt at fixed noise levels from `p`.
fn solve(
    motions: &[RelativeMotion],
    used: &[usize],
    p: &mut Params,
    noise: &Noise,
    cfg: &SelfCalConfig,
    n: usize,
    iterations: &mut usize,
) -> Result<Pass, CalibrationError> {
    let singular = || {
        CalibrationError::Input(
            "a motion's residual covariance is not positive-definite; \
             the noise levels or the parameters are not sane"
                .to_string(),
        )
    };
    let mut at = pass(motions, used, p, noise, cfg, n).ok_or_else(singular)?;
    let mut lambda = 1e-3;
    for _ in 0..cfg.max_iterations {
        *iterations += 1;
        let mut damped = at.h.clone();
        let ridge = step_ridge(p, n);
        for i in 0..n {
            damped[(i, i)] = damped[(i, i)] * (1.0 + lambda) + ridge[i];
        }
        let Some(step) = damped.cholesky().map(|c| c.solve(&at.g)) else {
            lambda *= 10.0;
            if lambda > 1e12 {
                break;
            }
            continue;
        };
        // r(p) with ∂r/∂p = J: the Gauss-Newton step is −(JᵀWJ)⁻¹JᵀWr.
        let mut candidate = *p;
        for i in 0..n {
            candidate[i] -= step[i];
        }
        let sane =
            candidate.iter().all(|v| v.is_finite()) && candidate[..3].iter().all(|v| *v > 0.0);
        let next = if sane {
            pass(motions, used, &candidate, noise, cfg, n)
        } else {
            None
        };
        let Some(next) = next else {
            lambda *= 10.0;
            if lambda > 1e12 {
                break;
            }
            continue;
        };
        let flat = (at.cost - next.cost).abs() <= RELATIVE_COST_TOLERANCE * (1.0 + at.cost.abs());
        if next.cost <= at.cost {
            let tiny =
                next.h.clone().try_inverse().is_some_and(|c| {
                    (0..n).all(|i| step[i].abs() < 1e-3 * c[(i, i)].max(0.0).sqrt())
                });
            *p = candidate;
            at = next;
            lambda = (lambda * 0.3).max(1e-12);
            if tiny || flat {
                break;
            }
        } else if flat {
            break;
        } else {
            lambda *= 10.0;
            if lambda > 1e12 {
                break;
            }
        }
    }
    Ok(at)
}

/// Noise levels below these are taken as these (noise-free data): a laser
/// or gyro standard deviation of 1e-9 m or rad (per √s for the gyro).
const MIN_VAR_M2: f64 = 1e-18;
const MIN_ALPHA: f64 = 1e-12;

/// One step of the maximum-likelihood fixed point for the noise levels at
/// `p`. The residual covariance of a motion is `Σ = Σ_c θ_c V_c + B`, the
/// θ_c being σx², σy², σθ² (motions without a matcher covariance: `V_c =
/// e_c e_cᵀ`), α (with one: `V = Σ_matcher`) and σ_g² (`V = T e_g e_gᵀ`),
/// and `B` the odometry part. The likelihood is stationary where
/// `Σ_k uᵀ V_c u = Σ_k tr(Σ⁻¹ V_c)` with `u = Σ⁻¹ r`; the update `θ_c ←
/// θ_c · Σ uᵀ V_c u / Σ tr(Σ⁻¹ V_c)` has that fixed point and keeps every
/// θ_c positive. Without odometry noise it is the mean square residual in
/// one step (Censi's per-axis standard deviation, without his mean); with
/// it, it never attributes more than the data show to the sensors, even
/// where the configured wheel noise is too large (its rank is two, so a
/// subtraction per axis would go negative).
fn update_noise(motions: &[RelativeMotion], used: &[usize], terms: &[Term], old: &Noise) -> Noise {
    let (mut axis_num, mut axis_den) = ([0.0; 3], [0.0; 3]);
    let (mut alpha_num, mut alpha_den) = (0.0, 0.0);
    let (mut gyro_num, mut gyro_den) = (0.0, 0.0);
    for (&i, t) in used.iter().zip(terms) {
        let m = &motions[i];
        let Some(c_inv) = inverse_cov(&(sensor_cov(m, old) + t.odo)) else {
            continue;
        };
        let u = c_inv * t.r;
        match &m.laser_cov {
            None => {
                for a in 0..3 {
                    axis_num[a] += u[a] * u[a];
                    axis_den[a] += c_inv[(a, a)];
                }
            }
            Some(l) => {
                for a in 0..3 {
                    for b in 0..3 {
                        alpha_num += u[a] * l[a][b] * u[b];
                        alpha_den += c_inv[(a, b)] * l[b][a];
                    }
                }
            }
        }
        if m.gyro_rad.is_some() {
            let dt = m.duration_s();
            gyro_num += dt * u[3] * u[3];
            gyro_den += dt * c_inv[(3, 3)];
        }
    }
    let step = |theta: f64, num: f64, den: f64, floor: f64| {
        if den > 0.0 && num.is_finite() {
            (theta * num / den).max(floor)
        } else {
            theta
        }
    };
    Noise {
        axis_var: std::array::from_fn(|a| {
            step(old.axis_var[a], axis_num[a], axis_den[a], MIN_VAR_M2)
        }),
        alpha: step(old.alpha, alpha_num, alpha_den, MIN_ALPHA),
        gyro_var_per_s: step(old.gyro_var_per_s, gyro_num, gyro_den, MIN_VAR_M2),
    }
}

/// Noise updates at fixed parameters between two solves.
const NOISE_STEPS_PER_SOLVE: usize = 5;

/// Noise levels from the mean square residuals at `p` (all of them
/// ascribed to the sensors: a start from above).
fn initial_noise(motions: &[RelativeMotion], p: &Params, cfg: &SelfCalConfig) -> Noise {
    let (mut axis, mut axis_n) = ([0.0; 3], 0usize);
    let (mut alpha, mut alpha_n) = (0.0, 0usize);
    let (mut gyro, mut gyro_t) = (0.0, 0.0);
    for m in motions {
        let t = term(m, p, &cfg.noise);
        match &m.laser_cov {
            None => {
                for (acc, r) in axis.iter_mut().zip(t.r.iter()) {
                    *acc += r * r;
                }
                axis_n += 1;
            }
            Some(l) => {
                for (a, row) in l.iter().enumerate() {
                    alpha += t.r[a] * t.r[a] / row[a];
                }
                alpha_n += 3;
            }
        }
        if m.gyro_rad.is_some() {
            gyro += t.r[3] * t.r[3];
            gyro_t += m.duration_s();
        }
    }
    let mean = |sum: f64, count: f64, floor: f64| {
        if count > 0.0 && sum.is_finite() {
            (sum / count).max(floor)
        } else {
            1.0
        }
    };
    Noise {
        axis_var: axis.map(|v| mean(v, axis_n as f64, MIN_VAR_M2)),
        alpha: mean(alpha, alpha_n as f64, MIN_ALPHA),
        gyro_var_per_s: mean(gyro, gyro_t, MIN_VAR_M2),
    }
}

fn noise_settled(a: &Noise, b: &Noise) -> bool {
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-3 * x.abs().max(y.abs());
    (0..3).all(|i| close(a.axis_var[i], b.axis_var[i]))
        && close(a.alpha, b.alpha)
        && close(a.gyro_var_per_s, b.gyro_var_per_s)
}

/// Solves with the noise re-estimated until it settles.
#[allow(clippy::too_many_arguments)]
fn solve_with_noise(
    motions: &[RelativeMotion],
    used: &[usize],
    p: &mut Params,
    noise: &mut Noise,
    cfg: &SelfCalConfig,
    n: usize,
    iterations: &mut usize,
) -> Result<Pass, CalibrationError> {
    let mut at = solve(motions, used, p, noise, cfg, n, iterations)?;
    for _ in 0..cfg.max_noise_iterations {
        let start = *noise;
        // The residuals do not change while only the noise levels do.
        let terms: Vec<Term> = used
            .iter()
            .map(|&i| term(&motions[i], p, &cfg.noise))
            .collect();
        for _ in 0..NOISE_STEPS_PER_SOLVE {
            let next = update_noise(motions, used, &terms, noise);
            let settled = noise_settled(&next, noise);
            *noise = next;
            if settled {
                break;
            }
        }
        if noise_settled(&start, noise) {
            break;
        }
        at = solve(motions, used, p, noise, cfg, n, iterations)?;
    }
    Ok(at)
}

/// The used motions without those whose squared whitened residual is
/// beyond the chi-square gate.
fn trim(
    motions: &[RelativeMotion],
    used: &[usize],
    p: &Params,
    noise: &Noise,
    cfg: &SelfCalConfig,
) -> Vec<usize> {
    let gate = [
        chi2_quantile(3, cfg.trim_probability),
        chi2_quantile(4, cfg.trim_probability),
    ];
    used.iter()
        .copied()
        .filter(|&i| {
            let m = &motions[i];
            let t = term(m, p, &cfg.noise);
            let Some(c_inv) = inverse_cov(&(sensor_cov(m, noise) + t.odo)) else {
                return false;
            };
            let d2 = t.r.dot(&(c_inv * t.r));
            d2 <= gate[usize::from(m.gyro_rad.is_some())]
        })
        .collect()
}

/// The inverse of the information `h` at `p`, through its eigen-decomposition
/// in the identifiability report's scaled units: parameters with a share of
/// more than 0.1 % in a direction with no information (an eigenvalue below
/// 1e-13 of the largest) get an infinite variance, the rest the
/// pseudo-inverse's. Returns the covariance and the standard deviations.
fn covariance(h: &DMatrix<f64>, p: &[f64]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let n = p.len();
    if !h.iter().all(|v| v.is_finite()) {
        return (vec![vec![f64::NAN; n]; n], vec![f64::INFINITY; n]);
    }
    let s = super::identifiability::scales(p);
    let eig = SymmetricEigen::new(DMatrix::from_fn(n, n, |i, k| s[i] * h[(i, k)] * s[k]));
    let top = eig.eigenvalues.max();
    let mut cov = DMatrix::<f64>::zeros(n, n);
    let mut free = vec![false; n];
    for (k, &e) in eig.eigenvalues.iter().enumerate() {
        let v = eig.eigenvectors.column(k);
        if e > 1e-13 * top && top > 0.0 {
            cov += v * v.transpose() / e;
        } else {
            for (i, f) in free.iter_mut().enumerate() {
                *f |= v[i] * v[i] > 1e-3;
            }
        }
    }
    let covariance: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            (0..n)
                .map(|k| {
                    if i == k && free[i] {
                        f64::INFINITY
                    } else {
                        s[i] * cov[(i, k)] * s[k]
                    }
                })
                .collect()
        })
        .collect();
    let std = (0..n).map(|i| covariance[i][i].max(0.0).sqrt()).collect();
    (covariance, std)
}

/// Maximum-likelihood self-calibration: Levenberg-Marquardt over
/// `[dL, dR, b, ℓx, ℓy, ℓθ]` (m, m, m, m, m, rad), and the gyro's bias β
/// (rad/s) and scale error κ when the motions carry gyro angles, from
/// `initial` (e.g. [`closed_form`](super::closed_form)'s estimate) and
/// `cfg.gyro_initial`. Frames as in the [module](super) (REP-103; the
/// paper's eq. (3) has the opposite heading sign).
///
/// Each motion contributes the laser residual `r = s̃ − s(θ)` (heading
/// wrapped) in the lidar frame at the motion's start and, with a gyro, the
/// residual `g̃ − (1 + κ)·o_θ − β·T`. Their covariance is the laser noise
/// (`α·Σ_matcher`, or `diag(σx², σy², σθ²)` when the matcher gives no
/// covariance), the gyro noise `σ_g²·T`, and the odometry noise carried
/// through the model, `K C_o Kᵀ` with `K = ∂(s, g)/∂o` and `C_o` from the
/// same [`NoiseModel`] as [`crate::batch`]. The noise levels α, σ and σ_g
/// are re-estimated from the residuals until they settle (a concentrated
/// likelihood), outliers beyond a chi-square gate are trimmed in rounds
/// and a Huber weight tames what is left.
///
/// Errors for fewer than
/// [`MIN_MOTIONS`](super::MIN_MOTIONS) motions, a motion with unusable
/// numbers, a non-positive or non-finite initial wheel parameter or an
/// insane configuration.
pub fn fit(
    motions: &[RelativeMotion],
    initial: [f64; 6],
    cfg: &SelfCalConfig,
) -> Result<SelfCalResult, CalibrationError> {
    super::check_motions(motions).map_err(CalibrationError::Input)?;
    if !initial.iter().all(|v| v.is_finite()) || initial[..3].iter().any(|v| *v <= 0.0) {
        return Err(CalibrationError::Input(format!(
            "the initial parameters {initial:?} are not finite, or a wheel diameter or the wheelbase is not positive"
        )));
    }
    if !(cfg.trim_probability > 0.5 && cfg.trim_probability < 1.0)
        || cfg.huber_k.is_nan()
        || cfg.huber_k <= 0.0
        || !cfg.gyro_initial.iter().all(|v| v.is_finite())
        || !(cfg.noise.wheel_rad2_per_rad >= 0.0 && cfg.noise.wheel_floor_rad2 >= 0.0)
    {
        return Err(CalibrationError::Input(format!(
            "the self-calibration settings are not sane: {cfg:?}"
        )));
    }
    let with_gyro = motions.iter().any(|m| m.gyro_rad.is_some());
    if with_gyro
        && motions
            .iter()
            .any(|m| m.gyro_rad.is_some() && m.duration_s() <= 0.0)
    {
        return Err(CalibrationError::Input(
            "a motion with a gyro angle has an interval of zero length".to_string(),
        ));
    }
    let n = if with_gyro { NP } else { 6 };
    let mut p: Params = [
        initial[0],
        initial[1],
        initial[2],
        initial[3],
        initial[4],
        initial[5],
        cfg.gyro_initial[0],
        cfg.gyro_initial[1],
    ];
    // Start from the mean square residuals at the initial parameters.
    let all: Vec<usize> = (0..motions.len()).collect();
    let mut noise = initial_noise(motions, &p, cfg);
    let mut used = all;
    let mut iterations = 0;
    let mut at = solve_with_noise(motions, &used, &mut p, &mut noise, cfg, n, &mut iterations)?;
    for _ in 0..cfg.trim_rounds {
        let kept = trim(motions, &used, &p, &noise, cfg);
        if kept.len() == used.len() {
            break;
        }
        if kept.len() < super::MIN_MOTIONS {
            return Err(CalibrationError::Input(format!(
                "trimming outliers left {} motions; the self-calibration needs at least {}",
                kept.len(),
                super::MIN_MOTIONS
            )));
        }
        used = kept;
        at = solve_with_noise(motions, &used, &mut p, &mut noise, cfg, n, &mut iterations)?;
    }
    p[5] = wrap_angle(p[5]);
    let (covariance, std) = covariance(&at.h, &p[..n]);
    let count = at.count.max(1) as f64;
    let gyro = with_gyro.then(|| GyroCalibration {
        bias_rad_s: p[6],
        bias_std_rad_s: std[6],
        scale_error: p[7],
        scale_error_std: std[7],
        noise_rad_per_sqrt_s: noise.gyro_var_per_s.sqrt(),
        residual_rms_rad: (at.raw_sq[3] / at.gyro_count.max(1) as f64).sqrt(),
    });
    let axis = motions.iter().any(|m| m.laser_cov.is_none());
    let scaled = motions.iter().any(|m| m.laser_cov.is_some());
    Ok(SelfCalResult {
        params: [p[0], p[1], p[2]],
        std: [std[0], std[1], std[2]],
        mount: [p[3], p[4], p[5]],
        mount_std: [std[3], std[4], std[5]],
        gyro,
        covariance,
        laser_noise: LaserNoise {
            axis_std: axis.then(|| noise.axis_var.map(f64::sqrt)),
            covariance_scale: scaled.then_some(noise.alpha),
        },
        iterations,
        whitened_rms: (at.whitened_sq / at.dims.max(1) as f64).sqrt(),
        residual_rms: [
            (at.raw_sq[0] / count).sqrt(),
            (at.raw_sq[1] / count).sqrt(),
            (at.raw_sq[2] / count).sqrt(),
        ],
        used: at.count,
        trimmed: motions.len() - at.count,
        identifiability: identifiability(&at.h, &p[..n]),
    })
}
