//! An independent batch estimate of (dL, dR, b): Levenberg-Marquardt over the
//! relative motion between pose samples, used as a cross-check of the EKF and
//! for the identifiability analysis.
//!
//! The poses are cut into windows of about `window_s`. Each window starts
//! from the measured pose, dead-reckons through the encoder increments with
//! the candidate parameters and compares the end with the measured pose. The
//! residual covariance accounts for the reference noise at both ends and the
//! odometry noise of the window; a Huber weight tames slip and glitches.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use serde::{Deserialize, Serialize};
use twindrive_kinematics::{StateVec, Transition, step_with_jacobian, wrap_angle};

use crate::covariance::chain;
use crate::dead_reckoning::wheel_angles_at;
use crate::ekf::NoiseModel;
use crate::online::{CalibrationError, PoseSample, WheelSample};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BatchConfig {
    /// Target length of each window in seconds.
    pub window_s: f64,
    pub max_iterations: usize,
    /// Huber threshold on the whitened residual norm.
    pub huber_k: f64,
    pub noise: NoiseModel,
}

impl Default for BatchConfig {
    fn default() -> Self {
        Self {
            window_s: 1.0,
            max_iterations: 50,
            huber_k: 3.0,
            noise: NoiseModel::default(),
        }
    }
}

/// The fit and what it says about the data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BatchResult {
    /// [dL, dR, b] in metres.
    pub params: [f64; 3],
    /// Standard deviations from the inverse information.
    pub std: [f64; 3],
    pub iterations: usize,
    pub windows: usize,
    /// Root mean square of the whitened residuals (≈ 1 when the noise model fits).
    pub whitened_rms: f64,
    /// RMS of the raw end-of-window residuals [x (m), y (m), θ (rad)].
    pub residual_rms: [f64; 3],
    pub identifiability: Identifiability,
}

/// How well the drive excites each parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Identifiability {
    /// Eigenvalues of the information matrix in relative units (parameters
    /// scaled by their values), ascending.
    pub eigenvalues: [f64; 3],
    pub condition_number: f64,
    /// Relative standard deviation of each parameter.
    pub relative_std: [f64; 3],
    /// The least-determined combination of relative changes of (dL, dR, b).
    pub weakest_direction: [f64; 3],
    pub well_determined: bool,
    /// A sentence for people.
    pub verdict: String,
}

/// Relative standard deviation above which a combination counts as not pinned.
const POOR_RELATIVE_STD: f64 = 0.002;
/// Condition numbers above this mean the drive's geometry leaves a
/// direction unobserved, not merely noisy.
const DEGENERATE_CONDITION: f64 = 1e3;

impl Identifiability {
    /// Relative standard deviation of the least-determined combination of
    /// (dL, dR, b).
    pub fn weakest_relative_std(&self) -> f64 {
        if self.eigenvalues[0] > 0.0 {
            1.0 / self.eigenvalues[0].sqrt()
        } else {
            f64::INFINITY
        }
    }

    /// Whether the motion pins every parameter at all: the drive's geometry
    /// separates them (no unobserved direction) and the weakest combination
    /// is known to better than `max_relative_std`. Weaker than
    /// [`well_determined`](Self::well_determined), which asks for precision.
    pub fn pins_every_parameter(&self, max_relative_std: f64) -> bool {
        self.condition_number <= DEGENERATE_CONDITION
            && self.weakest_relative_std() < max_relative_std
    }

    /// From the information matrix `h` (per metre²) at `params`.
    pub fn from_information(h: &Matrix3<f64>, params: [f64; 3]) -> Self {
        let d = Matrix3::from_diagonal(&Vector3::from(params));
        let rel = d * h * d;
        let eig = SymmetricEigen::new(rel);
        let mut order = [0, 1, 2];
        order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        let eigenvalues = order.map(|i| eig.eigenvalues[i]);
        let weakest = eig.eigenvectors.column(order[0]);
        let sign = if weakest.iter().map(|v| v.abs()).fold(0.0, f64::max) == weakest.max() {
            1.0
        } else {
            -1.0
        };
        let weakest_direction = [sign * weakest[0], sign * weakest[1], sign * weakest[2]];
        let condition_number = if eigenvalues[0] > 0.0 {
            eigenvalues[2] / eigenvalues[0]
        } else {
            f64::INFINITY
        };
        let cov = rel.try_inverse();
        let relative_std = match cov {
            Some(c) => [0, 1, 2].map(|i| c[(i, i)].max(0.0).sqrt()),
            None => [f64::INFINITY; 3],
        };
        let weakest_std = if eigenvalues[0] > 0.0 {
            1.0 / eigenvalues[0].sqrt()
        } else {
            f64::INFINITY
        };
        let well_determined = weakest_std < POOR_RELATIVE_STD;
        let names = ["dL", "dR", "b"];
        let combo: Vec<String> = weakest_direction
            .iter()
            .zip(names)
            .filter(|(v, _)| v.abs() > 0.1)
            .map(|(v, n)| format!("{v:+.2}·{n}"))
            .collect();
        let verdict = if well_determined {
            format!(
                "all three parameters are determined (weakest combination {} known to {:.3} %)",
                combo.join(" "),
                100.0 * weakest_std
            )
        } else if condition_number > DEGENERATE_CONDITION {
            format!(
                "WARNING: this drive cannot separate the parameters: the relative change {} is only known to {:.2} % \
                 (condition number {:.1e}). One constant curvature pins only two combinations of (dL, dR, b); \
                 drive at least two different curvatures (circles of different radii, both directions, a spin in place)",
                combo.join(" "),
                100.0 * weakest_std,
                condition_number
            )
        } else {
            format!(
                "WARNING: the parameters are separable (condition number {:.1e}) but the data pin {} only to {:.2} %: \
                 the drive is short or the reference and wheels are noisy (slip); a longer drive would help",
                condition_number,
                combo.join(" "),
                100.0 * weakest_std
            )
        };
        Self {
            eigenvalues,
            condition_number,
            relative_std,
            weakest_direction,
            well_determined,
            verdict,
        }
    }
}

/// One window: start and end pose samples.
struct Window {
    start: PoseSample,
    end: PoseSample,
}

fn windows(poses: &[PoseSample], wheels: &[WheelSample], window_s: f64) -> Vec<Window> {
    let (Some(w0), Some(w1)) = (wheels.first(), wheels.last()) else {
        return Vec::new();
    };
    let usable: Vec<&PoseSample> = poses
        .iter()
        .filter(|p| p.heading_rad.is_some() && p.t_s >= w0.t_s && p.t_s <= w1.t_s)
        .collect();
    let mut out = Vec::new();
    let mut k = 0;
    while k < usable.len() {
        let start = usable[k];
        let Some(end_idx) = (k + 1..usable.len()).find(|&j| usable[j].t_s - start.t_s >= window_s)
        else {
            break;
        };
        out.push(Window {
            start: *start,
            end: *usable[end_idx],
        });
        k = end_idx;
    }
    out
}

/// Residual (world frame), its Jacobian w.r.t. the parameters and its covariance for one window.
fn window_terms(
    w: &Window,
    wheels: &[WheelSample],
    params: [f64; 3],
    noise: &NoiseModel,
) -> Option<(Vector3<f64>, Matrix3<f64>, Matrix3<f64>)> {
    let h0 = w.start.heading_rad?;
    let h1 = w.end.heading_rad?;
    let mut state = StateVec::new(
        w.start.x_m,
        w.start.y_m,
        h0,
        params[0],
        params[1],
        params[2],
    );
    let mut at = wheel_angles_at(wheels, w.start.t_s)?;
    let end = wheel_angles_at(wheels, w.end.t_s)?;
    // Step Jacobians are [[A, B], [0, I]] with A = [[1, 0, a], [0, 1, b],
    // [0, 0, 1]] (see `Transition`): the chain's d pose / d params follows
    // J ← A J + B, d pose_end / d pose_start keeps A's form (the couplings
    // add up), and the odometry covariance follows C ← A C Aᵀ + G q Gᵀ.
    let mut jac = Transition::IDENTITY;
    let mut odo_cov = [[0.0f64; 3]; 3];
    let first = wheels.partition_point(|s| s.t_s <= w.start.t_s);
    let inner = wheels[first..]
        .iter()
        .take_while(|s| s.t_s < w.end.t_s)
        .map(|s| (s.left_rad, s.right_rad));
    for next in inner.chain(std::iter::once(end)) {
        let (l, r) = (next.0 - at.0, next.1 - at.1);
        at = next;
        let (stepped, step) = step_with_jacobian(&state, l, r);
        state = stepped;
        jac = chain(&jac, &step.state);
        let (a, b) = (step.state.heading_to_x, step.state.heading_to_y);
        // A C Aᵀ: rows/columns 0 and 1 pick up a, b times row/column 2.
        let c = odo_cov;
        let c02 = c[0][2] + a * c[2][2];
        let c12 = c[1][2] + b * c[2][2];
        let c00 = c[0][0] + a * (c[0][2] + c02);
        let c11 = c[1][1] + b * (c[1][2] + c12);
        let c01 = c[0][1] + a * c[1][2] + b * c02;
        let q = [
            noise.wheel_rad2_per_rad * l.abs() + noise.wheel_floor_rad2,
            noise.wheel_rad2_per_rad * r.abs() + noise.wheel_floor_rad2,
        ];
        let g = &step.wheels;
        let gqg = |i: usize, j: usize| g[i][0] * q[0] * g[j][0] + g[i][1] * q[1] * g[j][1];
        odo_cov = [
            [c00 + gqg(0, 0), c01 + gqg(0, 1), c02 + gqg(0, 2)],
            [0.0, c11 + gqg(1, 1), c12 + gqg(1, 2)],
            [0.0, 0.0, c[2][2] + gqg(2, 2)],
        ];
        odo_cov[1][0] = odo_cov[0][1];
        odo_cov[2][0] = odo_cov[0][2];
        odo_cov[2][1] = odo_cov[1][2];
    }
    let residual = Vector3::new(
        w.end.x_m - state[0],
        w.end.y_m - state[1],
        wrap_angle(h1 - state[2]),
    );
    let r = Matrix3::from_diagonal(&Vector3::new(
        noise.position_std_m.powi(2),
        noise.position_std_m.powi(2),
        noise.heading_std_rad.powi(2),
    ));
    let mut pose_prop = Matrix3::identity();
    pose_prop[(0, 2)] = jac.heading_to_x;
    pose_prop[(1, 2)] = jac.heading_to_y;
    let cov = pose_prop * r * pose_prop.transpose() + Matrix3::from(odo_cov) + r;
    let jac = Matrix3::from(jac.params).transpose();
    // The residual decreases as the prediction grows: ∂r/∂params = −J.
    Some((residual, -jac, cov))
}

/// The normal equations of the windows at some parameters.
struct NormalEquations {
    /// Information Jᵀ W C⁻¹ J.
    h: Matrix3<f64>,
    /// Gradient Jᵀ W C⁻¹ r.
    g: Vector3<f64>,
    /// Huber cost.
    cost: f64,
    whitened_rms: f64,
    raw_rms: [f64; 3],
    windows: usize,
}

fn normal_equations(
    ws: &[Window],
    wheels: &[WheelSample],
    params: [f64; 3],
    cfg: &BatchConfig,
) -> NormalEquations {
    let mut h = Matrix3::zeros();
    let mut g = Vector3::zeros();
    let (mut cost, mut sq, mut n) = (0.0, 0.0, 0usize);
    let mut raw = [0.0; 3];
    for w in ws {
        let Some((r, j, c)) = window_terms(w, wheels, params, &cfg.noise) else {
            continue;
        };
        // 3x3: closed-form inverse after a positive-definiteness check.
        let Some(c_inv) = c
            .try_inverse()
            .filter(|_| crate::ekf::is_positive_definite(&c))
        else {
            continue;
        };
        let c_inv_r = c_inv * r;
        let m2 = r.dot(&c_inv_r);
        let m = m2.sqrt();
        // Huber IRLS weight.
        let weight = if m <= cfg.huber_k {
            1.0
        } else {
            cfg.huber_k / m
        };
        let c_inv_j = c_inv * j;
        h += weight * j.transpose() * c_inv_j;
        g += weight * j.transpose() * c_inv_r;
        cost += if m <= cfg.huber_k {
            0.5 * m2
        } else {
            cfg.huber_k * (m - 0.5 * cfg.huber_k)
        };
        sq += m2;
        for (acc, v) in raw.iter_mut().zip(r.iter()) {
            *acc += v * v;
        }
        n += 1;
    }
    let nf = n.max(1) as f64;
    NormalEquations {
        h,
        g,
        cost,
        whitened_rms: (sq / (3.0 * nf)).sqrt(),
        raw_rms: raw.map(|v| (v / nf).sqrt()),
        windows: n,
    }
}

/// Cost changes below this (whitened χ² units) are round-off and the
/// reweighting's wobble: a step that changes the cost less has converged.
/// Half a quadratic form of 1e-4 is a parameter change of about 1 % of a
/// standard deviation.
const COST_TOLERANCE: f64 = 1e-4;

/// Fits (dL, dR, b) by Levenberg-Marquardt from `initial`.
pub fn fit(
    wheels: &[WheelSample],
    poses: &[PoseSample],
    initial: [f64; 3],
    cfg: &BatchConfig,
) -> Result<BatchResult, CalibrationError> {
    let ws = windows(poses, wheels, cfg.window_s);
    if ws.len() < 3 {
        return Err(CalibrationError::Input(format!(
            "only {} windows of {} s with heading references overlap the encoder data; the batch fit needs at least 3",
            ws.len(),
            cfg.window_s
        )));
    }
    let mut params = initial;
    let mut lambda = 1e-3;
    let mut at = normal_equations(&ws, wheels, params, cfg);
    let mut iterations = 0;
    while iterations < cfg.max_iterations {
        iterations += 1;
        let mut damped = at.h;
        for i in 0..3 {
            damped[(i, i)] *= 1.0 + lambda;
        }
        // Gauss-Newton on r(p) with ∂r/∂p = J: step = −(JᵀJ)⁻¹ Jᵀ r.
        let Some(step) = damped.cholesky().map(|c| -c.solve(&at.g)) else {
            lambda *= 10.0;
            continue;
        };
        let candidate = [
            params[0] + step[0],
            params[1] + step[1],
            params[2] + step[2],
        ];
        if candidate.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            lambda *= 10.0;
            continue;
        }
        let next = normal_equations(&ws, wheels, candidate, cfg);
        let flat = (at.cost - next.cost).abs() <= COST_TOLERANCE;
        if next.cost <= at.cost {
            // Converged once the step is tiny against the parameters'
            // own uncertainty, or the cost stops moving.
            let tiny = next
                .h
                .try_inverse()
                .is_some_and(|c| (0..3).all(|i| step[i].abs() < 1e-2 * c[(i, i)].max(0.0).sqrt()));
            params = candidate;
            at = next;
            lambda = (lambda * 0.3).max(1e-9);
            if tiny || flat {
                break;
            }
        } else if flat {
            // Uphill only by round-off: already at the minimum.
            break;
        } else {
            lambda *= 10.0;
            if lambda > 1e12 {
                break;
            }
        }
    }
    let std = match at.h.try_inverse() {
        Some(c) => [0, 1, 2].map(|i| c[(i, i)].max(0.0).sqrt()),
        None => [f64::INFINITY; 3],
    };
    Ok(BatchResult {
        params,
        std,
        iterations,
        windows: at.windows,
        whitened_rms: at.whitened_rms,
        residual_rms: at.raw_rms,
        identifiability: Identifiability::from_information(&at.h, params),
    })
}

/// The information the data carries about the parameters at `params`
/// (no fitting): for judging a drive whatever method estimated it.
pub fn identifiability(
    wheels: &[WheelSample],
    poses: &[PoseSample],
    params: [f64; 3],
    cfg: &BatchConfig,
) -> Option<Identifiability> {
    let ws = windows(poses, wheels, cfg.window_s);
    let at = normal_equations(&ws, wheels, params, cfg);
    (at.windows >= 3).then(|| Identifiability::from_information(&at.h, params))
}
