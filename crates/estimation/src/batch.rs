//! An independent batch estimate of (dL, dR, b): Levenberg-Marquardt over the
//! relative motion between pose samples, used as a cross-check of the EKF and
//! for the identifiability analysis.
//!
//! The poses are cut into windows of about `window_s`. Each window starts
//! from the measured pose, dead-reckons through the encoder increments with
//! the candidate parameters and compares the end with the measured pose. The
//! residual covariance accounts for the reference noise at both ends and the
//! odometry noise of the window; a Huber weight tames slip and glitches.

use nalgebra::{DMatrix, DVector, Matrix3, SymmetricEigen, Vector3};
use serde::{Deserialize, Serialize};
use twindrive_kinematics::wrap_angle;

use crate::dead_reckoning::wheel_angles_at;
use crate::ekf::NoiseModel;
use crate::odometry_chain::OdometryChain;
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
///
/// Built for the three wheel parameters (dL, dR, b) by
/// [`from_information`](Self::from_information), and for any set of
/// parameters in scaled units by
/// [`from_information_scaled`](Self::from_information_scaled) (the
/// self-calibration's wheel parameters, lidar mount and gyro). The JSON of
/// the three-parameter report has no `parameters` field; the vectors then
/// hold three numbers in the order (dL, dR, b).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Identifiability {
    /// Names of the parameters, in the order of the vectors below. Left out
    /// of the JSON (and defaulted when reading it) for (dL, dR, b).
    #[serde(
        default = "wheel_parameter_names",
        skip_serializing_if = "is_wheel_parameters"
    )]
    pub parameters: Vec<String>,
    /// Eigenvalues of the information matrix in scaled units (for the wheel
    /// parameters: relative, i.e. scaled by their values), ascending.
    pub eigenvalues: Vec<f64>,
    pub condition_number: f64,
    /// Standard deviation of each parameter in scaled units (for the wheel
    /// parameters: relative).
    pub relative_std: Vec<f64>,
    /// The least-determined combination of scaled changes of the parameters.
    pub weakest_direction: Vec<f64>,
    pub well_determined: bool,
    /// A sentence for people.
    pub verdict: String,
    /// Per parameter, the standard deviation (in the units of
    /// `relative_std`) below which it counts as well determined; absent for
    /// the wheel parameters, where it is 0.002 for every combination. When
    /// present, `eigenvalues` and `weakest_direction` are in units of
    /// `tolerance / 0.002` and `condition_number` is the scale-free coupling
    /// one (see [`from_information_scaled`](Self::from_information_scaled)).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<Vec<f64>>,
}

/// The condition number of `h` normalised to a unit diagonal, `F h F` with
/// `F = diag(h_ii^-1/2)`: 1 for uncoupled parameters, infinite when a
/// combination is unobserved (or a parameter has no information at all).
fn coupling_condition_number(h: &DMatrix<f64>) -> f64 {
    let n = h.nrows();
    if (0..n).any(|i| h[(i, i)].is_nan() || h[(i, i)] <= 0.0) {
        return f64::INFINITY;
    }
    let f = DMatrix::from_fn(
        n,
        n,
        |i, k| if i == k { 1.0 / h[(i, i)].sqrt() } else { 0.0 },
    );
    let eig = SymmetricEigen::new(&f * h * &f).eigenvalues;
    let (lo, hi) = (eig.min(), eig.max());
    if lo > 0.0 { hi / lo } else { f64::INFINITY }
}

/// The names of the three wheel parameters, the default of
/// [`Identifiability::parameters`].
fn wheel_parameter_names() -> Vec<String> {
    WHEEL_PARAMETERS.iter().map(|n| n.to_string()).collect()
}

fn is_wheel_parameters(names: &[String]) -> bool {
    names.iter().map(String::as_str).eq(WHEEL_PARAMETERS)
}

const WHEEL_PARAMETERS: [&str; 3] = ["dL", "dR", "b"];

/// Relative standard deviation above which a combination counts as not pinned.
const POOR_RELATIVE_STD: f64 = 0.002;
/// Condition numbers above this mean the drive's geometry leaves a
/// direction unobserved, not merely noisy.
const DEGENERATE_CONDITION: f64 = 1e3;
/// The same for the scale-free coupling condition number of
/// [`Identifiability::from_information_scaled`]. Wheel diameters and
/// wheelbase are strongly coupled by nature (the heading pins only their
/// ratios): Censi's three real Khepera drives reach 160-440, a drive of one
/// curvature or of straight lines is exactly singular.
const DEGENERATE_COUPLING: f64 = 1e5;
/// An eigenvalue this small against the largest is no information at all
/// (round-off of a singular matrix).
const UNOBSERVED_EIGENVALUE: f64 = 1e-13;
/// A parameter with more than this share (squared component) in such a
/// direction has an infinite standard deviation; smaller shares are the
/// round-off of the eigenvectors.
const UNOBSERVED_SHARE: f64 = 1e-3;

impl Identifiability {
    /// Standard deviation of the least-determined combination, in scaled
    /// units (for the wheel parameters: relative).
    pub fn weakest_relative_std(&self) -> f64 {
        match self.eigenvalues.first() {
            Some(&e) if e > 0.0 => 1.0 / e.sqrt(),
            _ => f64::INFINITY,
        }
    }

    /// Whether the motion pins every parameter at all: the drive's geometry
    /// separates them (no unobserved direction) and the weakest combination
    /// is known to better than `max_relative_std`. Weaker than
    /// [`well_determined`](Self::well_determined), which asks for precision.
    ///
    /// For a report with [`tolerance`](Self::tolerance)s (see
    /// [`from_information_scaled`](Self::from_information_scaled)),
    /// `max_relative_std / 0.002` is a multiple of the tolerances and the
    /// condition number is the scale-free coupling one.
    pub fn pins_every_parameter(&self, max_relative_std: f64) -> bool {
        let limit = if self.tolerance.is_some() {
            DEGENERATE_COUPLING
        } else {
            DEGENERATE_CONDITION
        };
        self.condition_number <= limit && self.weakest_relative_std() < max_relative_std
    }

    /// Whether the drive's geometry separates the parameters at all (no
    /// combination unobserved), whatever the noise.
    pub fn separable(&self) -> bool {
        let limit = if self.tolerance.is_some() {
            DEGENERATE_COUPLING
        } else {
            DEGENERATE_CONDITION
        };
        self.condition_number <= limit
    }

    /// The report for an information matrix `h` over any parameters (in
    /// their own units), such as the self-calibration's wheel parameters,
    /// lidar mount and gyro, whose units differ and whose precisions differ
    /// by orders of magnitude. `None` when the sizes disagree or `h` is not
    /// finite.
    ///
    /// - `scales`: scaled parameter = parameter / scale; `relative_std` is
    ///   in these units.
    /// - `tolerances`: in scaled units, the standard deviation each
    ///   parameter should reach to count as well determined (for dL, dR, b
    ///   relative that is 0.002 as in
    ///   [`from_information`](Self::from_information)). `eigenvalues` and
    ///   `weakest_direction` are those of the information in units of
    ///   `tolerance / 0.002`, so that, as for the wheel parameters, a
    ///   combination is well determined below 0.002 and
    ///   [`pins_every_parameter`](Self::pins_every_parameter)`(max)` means
    ///   every combination within `max / 0.002` tolerances.
    /// - `condition_number` is that of `h` normalised to a unit diagonal
    ///   (scale-free): how much the parameters' coupling costs, not how
    ///   their precisions compare. It is infinite when a combination is not
    ///   observed at all.
    ///
    /// The verdict names the weakest combination generically; callers that
    /// know what the parameters mean replace it with a sentence of their own.
    pub fn from_information_scaled(
        h: &DMatrix<f64>,
        scales: &[f64],
        tolerances: &[f64],
        names: &[&str],
    ) -> Option<Self> {
        let n = scales.len();
        if h.nrows() != n
            || h.ncols() != n
            || names.len() != n
            || tolerances.len() != n
            || n == 0
            || !h
                .iter()
                .chain(scales)
                .chain(tolerances)
                .all(|v| v.is_finite())
        {
            return None;
        }
        let diag = |v: Vec<f64>| DMatrix::from_diagonal(&DVector::from_vec(v));
        let d = diag(scales.to_vec());
        let scaled = &d * h * &d;
        // Through the eigen-decomposition, so that only the parameters with
        // a share in an unobserved direction come out infinite.
        let spectrum = SymmetricEigen::new(scaled.clone());
        let top = spectrum.eigenvalues.max();
        let relative_std: Vec<f64> = (0..n)
            .map(|i| {
                let mut var = 0.0;
                for (k, &e) in spectrum.eigenvalues.iter().enumerate() {
                    let share = spectrum.eigenvectors[(i, k)].powi(2);
                    if e > UNOBSERVED_EIGENVALUE * top {
                        var += share / e;
                    } else if share > UNOBSERVED_SHARE {
                        return f64::INFINITY;
                    }
                }
                var.sqrt()
            })
            .collect();
        let e = diag(tolerances.iter().map(|t| t / POOR_RELATIVE_STD).collect());
        let eig = SymmetricEigen::new(&e * &scaled * &e);
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        let eigenvalues: Vec<f64> = order.iter().map(|&i| eig.eigenvalues[i]).collect();
        let weakest = eig.eigenvectors.column(order[0]);
        let sign = if weakest.iter().map(|v| v.abs()).fold(0.0, f64::max) == weakest.max() {
            1.0
        } else {
            -1.0
        };
        let weakest_direction: Vec<f64> = weakest.iter().map(|v| sign * v).collect();
        let condition_number = coupling_condition_number(h);
        let weakest_std = match eigenvalues[0] {
            e if e > 0.0 => 1.0 / e.sqrt(),
            _ => f64::INFINITY,
        };
        let well_determined =
            weakest_std < POOR_RELATIVE_STD && condition_number <= DEGENERATE_COUPLING;
        let verdict = format!(
            "the weakest combination {} is known to {:.2} of its tolerance (coupling condition number {:.1e})",
            combination(&weakest_direction, names),
            weakest_std / POOR_RELATIVE_STD,
            condition_number
        );
        Some(Self {
            parameters: names.iter().map(|n| n.to_string()).collect(),
            eigenvalues,
            condition_number,
            relative_std,
            weakest_direction,
            well_determined,
            verdict,
            tolerance: Some(tolerances.to_vec()),
        })
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
        let weakest_direction = vec![sign * weakest[0], sign * weakest[1], sign * weakest[2]];
        let condition_number = if eigenvalues[0] > 0.0 {
            eigenvalues[2] / eigenvalues[0]
        } else {
            f64::INFINITY
        };
        let cov = rel.try_inverse();
        let relative_std = match cov {
            Some(c) => vec![
                c[(0, 0)].max(0.0).sqrt(),
                c[(1, 1)].max(0.0).sqrt(),
                c[(2, 2)].max(0.0).sqrt(),
            ],
            None => vec![f64::INFINITY; 3],
        };
        let weakest_std = if eigenvalues[0] > 0.0 {
            1.0 / eigenvalues[0].sqrt()
        } else {
            f64::INFINITY
        };
        let well_determined = weakest_std < POOR_RELATIVE_STD;
        let combo = combination(&weakest_direction, &WHEEL_PARAMETERS);
        let verdict = if well_determined {
            format!(
                "all three parameters are determined (weakest combination {} known to {:.3} %)",
                combo,
                100.0 * weakest_std
            )
        } else if condition_number > DEGENERATE_CONDITION {
            format!(
                "WARNING: this drive cannot separate the parameters: the relative change {} is only known to {:.2} % \
                 (condition number {:.1e}). One constant curvature pins only two combinations of (dL, dR, b); \
                 drive at least two different curvatures (circles of different radii, both directions, a spin in place)",
                combo,
                100.0 * weakest_std,
                condition_number
            )
        } else {
            format!(
                "WARNING: the parameters are separable (condition number {:.1e}) but the data pin {} only to {:.2} %: \
                 the drive is short or the reference and wheels are noisy (slip); a longer drive would help",
                condition_number,
                combo,
                100.0 * weakest_std
            )
        };
        Self {
            parameters: wheel_parameter_names(),
            eigenvalues: eigenvalues.to_vec(),
            condition_number,
            relative_std,
            weakest_direction,
            well_determined,
            verdict,
            tolerance: None,
        }
    }
}

/// The components of a direction above 0.1 with their names, e.g.
/// "+0.71·b -0.70·lx".
pub(crate) fn combination(direction: &[f64], names: &[&str]) -> String {
    let combo: Vec<String> = direction
        .iter()
        .zip(names)
        .filter(|(v, _)| v.abs() > 0.1)
        .map(|(v, n)| format!("{v:+.2}·{n}"))
        .collect();
    combo.join(" ")
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
    let mut odo = OdometryChain::new([w.start.x_m, w.start.y_m, h0], params);
    let mut at = wheel_angles_at(wheels, w.start.t_s)?;
    let end = wheel_angles_at(wheels, w.end.t_s)?;
    let first = wheels.partition_point(|s| s.t_s <= w.start.t_s);
    let inner = wheels[first..]
        .iter()
        .take_while(|s| s.t_s < w.end.t_s)
        .map(|s| (s.left_rad, s.right_rad));
    for next in inner.chain(std::iter::once(end)) {
        let (l, r) = (next.0 - at.0, next.1 - at.1);
        at = next;
        odo.step(l, r, noise);
    }
    let (state, jac, odo_cov) = (odo.state, odo.jac, odo.cov);
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

#[cfg(test)]
mod tests {
    use super::*;

    fn wheel_report() -> Identifiability {
        let h = Matrix3::new(4e7, 1e7, -2e6, 1e7, 5e7, 3e6, -2e6, 3e6, 9e6);
        Identifiability::from_information(&h, [0.066, 0.067, 0.27])
    }

    #[test]
    fn the_wheel_report_keeps_its_json() {
        let id = wheel_report();
        let json = serde_json::to_value(&id).unwrap();
        let mut keys: Vec<&str> = json
            .as_object()
            .unwrap()
            .keys()
            .map(String::as_str)
            .collect();
        keys.sort_unstable();
        assert_eq!(
            keys,
            [
                "condition_number",
                "eigenvalues",
                "relative_std",
                "verdict",
                "weakest_direction",
                "well_determined",
            ]
        );
        for key in ["eigenvalues", "relative_std", "weakest_direction"] {
            assert_eq!(json[key].as_array().unwrap().len(), 3, "{key}");
        }
        // Reports written before the generalisation still read.
        let back: Identifiability = serde_json::from_value(json).unwrap();
        assert_eq!(back, id);
        assert_eq!(back.parameters, ["dL", "dR", "b"]);
    }

    #[test]
    fn scaled_reports_name_their_parameters_and_round_trip() {
        let h = DMatrix::from_fn(4, 4, |i, k| if i == k { 1e6 * (i + 1) as f64 } else { 1e3 });
        let id = Identifiability::from_information_scaled(
            &h,
            &[0.1, 0.1, 0.01, 1.0],
            &[0.002, 0.002, 0.2, 0.2],
            &["a", "b", "c", "d"],
        )
        .unwrap();
        assert!(id.separable());
        let json = serde_json::to_value(&id).unwrap();
        assert_eq!(json["parameters"][3], "d");
        assert_eq!(json["tolerance"].as_array().unwrap().len(), 4);
        let back: Identifiability = serde_json::from_value(json).unwrap();
        assert_eq!(back, id);
        // Sizes that disagree, or information that is not finite: no report.
        assert!(
            Identifiability::from_information_scaled(&h, &[1.0; 3], &[1.0; 3], &["a"; 3]).is_none()
        );
        let mut bad = h.clone();
        bad[(1, 1)] = f64::NAN;
        assert!(
            Identifiability::from_information_scaled(&bad, &[1.0; 4], &[1.0; 4], &["a"; 4])
                .is_none()
        );
    }
}
