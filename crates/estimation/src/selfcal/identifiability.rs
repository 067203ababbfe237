//! Identifiability of the self-calibration's parameters: the information
//! matrix's spectrum in scaled units and a verdict in words.

use nalgebra::{DMatrix, SymmetricEigen};

use crate::batch::{Identifiability, combination};

/// Names of the parameters, in the fit's order (the last two only with a
/// gyro).
pub const PARAMETER_NAMES: [&str; 8] = [
    "dL",
    "dR",
    "b",
    "lx",
    "ly",
    "ltheta",
    "gyro_bias",
    "gyro_scale",
];

/// The scaled units of [`identifiability`], for reports.
pub const SCALE_NOTE: &str = "scaled units: dL, dR, b relative (1 = 100 %); lx, ly per 1 cm; \
     ltheta per 0.5°; gyro bias per 1e-3 rad/s; gyro scale relative";

/// The scale of each parameter: dL, dR, b relative (÷ value); ℓx, ℓy per
/// 1 cm; ℓθ per 0.5°; β per 1e-3 rad/s; κ relative (κ is itself a ratio).
pub(super) fn scales(params: &[f64]) -> Vec<f64> {
    let fixed = [0.01, 0.01, 0.5f64.to_radians(), 1e-3, 1.0];
    params
        .iter()
        .take(3)
        .map(|v| v.abs())
        .chain(fixed.iter().copied())
        .take(params.len())
        .collect()
}

/// The standard deviation each parameter should reach, in the units of
/// [`scales`]: 0.2 % for dL, dR, b (as the wheel-only report asks), 2 mm
/// for ℓx, ℓy, 0.1° for ℓθ, 2e-4 rad/s for β and 0.2 % for κ.
const TOLERANCES: [f64; 8] = [0.002, 0.002, 0.002, 0.2, 0.2, 0.2, 0.2, 0.002];

/// The identifiability report for the information `h` (in the parameters'
/// own units) at `params` (6 or 8 of them, in [`PARAMETER_NAMES`] order):
/// `relative_std` in the units of [`SCALE_NOTE`], per-parameter tolerances
/// of 0.2 % (dL, dR, b, gyro scale), 2 mm (ℓx, ℓy), 0.1° (ℓθ) and 2e-4
/// rad/s (gyro bias), the scale-free coupling condition number (see
/// [`Identifiability::from_information_scaled`]) and a verdict that names
/// the weakest combination in words and the motion that would pin it.
pub fn identifiability(h: &DMatrix<f64>, params: &[f64]) -> Identifiability {
    let names = &PARAMETER_NAMES[..params.len()];
    let tolerances = &TOLERANCES[..params.len()];
    let mut id = Identifiability::from_information_scaled(h, &scales(params), tolerances, names)
        .unwrap_or_else(|| unusable(names, tolerances));
    id.verdict = verdict(&id, names, &unobserved_parameters(h, params));
    id
}

/// The report when the information is not even finite.
fn unusable(names: &[&str], tolerances: &[f64]) -> Identifiability {
    let n = names.len();
    Identifiability {
        parameters: names.iter().map(|s| s.to_string()).collect(),
        eigenvalues: vec![0.0; n],
        condition_number: f64::INFINITY,
        relative_std: vec![f64::INFINITY; n],
        weakest_direction: vec![0.0; n],
        well_determined: false,
        verdict: String::new(),
        tolerance: Some(tolerances.to_vec()),
    }
}

/// A combination known worse than this many tolerances (2 m for the mount,
/// 200 % for the wheels, 100° for the lidar's heading) is not observed at
/// all.
const UNOBSERVED_TOLERANCES: f64 = 1e3;

/// The parameters with a share of more than 5 % in a combination the data
/// do not observe at all: in units of the tolerances, an eigenvalue of the
/// information below `1 / UNOBSERVED_TOLERANCES²` or below round-off.
fn unobserved_parameters(h: &DMatrix<f64>, params: &[f64]) -> Vec<usize> {
    let n = h.nrows();
    if !h.iter().all(|v| v.is_finite()) {
        return (0..n).collect();
    }
    let unit: Vec<f64> = scales(params)
        .iter()
        .zip(&TOLERANCES)
        .map(|(s, t)| s * t)
        .collect();
    let ht = DMatrix::from_fn(n, n, |i, k| unit[i] * h[(i, k)] * unit[k]);
    let eig = SymmetricEigen::new(ht);
    let top = eig.eigenvalues.max();
    let mut weight = vec![0.0; n];
    for (k, &e) in eig.eigenvalues.iter().enumerate() {
        if e * UNOBSERVED_TOLERANCES * UNOBSERVED_TOLERANCES < 1.0 || e <= 1e-13 * top {
            for (i, w) in weight.iter_mut().enumerate() {
                *w += eig.eigenvectors[(i, k)].powi(2);
            }
        }
    }
    (0..n).filter(|&i| weight[i] > 0.05).collect()
}

/// Which group of parameters `set` (indices) concerns, in words: what
/// cannot be told apart, the same as a subject, and the motion that pins it.
fn in_words(set: &[usize]) -> (&'static str, &'static str, &'static str) {
    let has = |r: std::ops::Range<usize>| set.iter().any(|i| r.contains(i));
    let (wheels, mount_xy, mount_theta, gyro) = (has(0..3), has(3..5), has(5..6), has(6..8));
    if (mount_xy || mount_theta) && wheels {
        (
            "the lidar's mount from the wheelbase",
            "the lidar's mount and the wheelbase",
            "turn in place (both ways) and drive arcs of two different curvatures",
        )
    } else if mount_xy {
        (
            "the lidar's position on the robot from its motion",
            "the lidar's position on the robot",
            "turn in place (both ways) and drive arcs",
        )
    } else if mount_theta {
        (
            "the lidar's heading on the robot from its motion",
            "the lidar's heading on the robot",
            "drive straight stretches and arcs, forwards and backwards",
        )
    } else if wheels {
        (
            "the wheel diameters from the wheelbase (one constant curvature pins only two combinations of dL, dR, b)",
            "the wheel diameters and the wheelbase",
            "drive arcs of two different curvatures and turn in place",
        )
    } else if gyro {
        (
            "the gyro's bias from its scale error",
            "the gyro's bias and scale",
            "turn both ways, and stand still for a while",
        )
    } else {
        ("the parameters", "the parameters", "drive a richer path")
    }
}

fn verdict(id: &Identifiability, names: &[&str], unobserved: &[usize]) -> String {
    // In multiples of the tolerances (see `Identifiability::tolerance`).
    let weakest = id.weakest_relative_std() / 0.002;
    let combo = combination(&id.weakest_direction, names);
    let stds = names
        .iter()
        .zip(&id.relative_std)
        .map(|(n, s)| format!("{n} {s:.2e}"))
        .collect::<Vec<_>>()
        .join(", ");
    if !id.separable() || !weakest.is_finite() || !unobserved.is_empty() {
        let set: Vec<usize> = if unobserved.is_empty() {
            (0..names.len()).collect()
        } else {
            unobserved.to_vec()
        };
        let (separate, _, advice) = in_words(&set);
        let listed: Vec<&str> = set.iter().map(|&i| names[i]).collect();
        format!(
            "WARNING: this drive cannot separate {separate}: combinations of {} are not observed \
             (coupling condition number {:.1e}). To pin them, {advice}",
            listed.join(", "),
            id.condition_number
        )
    } else if id.well_determined {
        format!(
            "all {} parameters are determined to within their tolerances (0.2 %, 2 mm, 0.1°, 2e-4 rad/s; \
             weakest combination {combo} at {weakest:.2} of them); standard deviations {stds} ({SCALE_NOTE})",
            names.len()
        )
    } else {
        let w = &id.weakest_direction;
        let set: Vec<usize> = w
            .iter()
            .enumerate()
            .filter(|(_, v)| v.abs() > 0.3)
            .map(|(i, _)| i)
            .collect();
        let (_, subject, advice) = if set.iter().all(|&i| i < 3)
            && set.len() == 3
            && w[..3].iter().all(|v| v.signum() == w[0].signum())
        {
            // dL, dR and b together: the robot's scale, which only the
            // distance the lidar sees travelled pins.
            (
                "",
                "the overall scale of the wheels and the wheelbase (dL, dR, b together)",
                "drive longer distances",
            )
        } else {
            in_words(&set)
        };
        format!(
            "WARNING: the parameters are separable (coupling condition number {:.1e}) but the combination {combo} \
             is only known to {weakest:.1} times its tolerance (0.2 %, 2 mm, 0.1°, 2e-4 rad/s). It concerns \
             {subject}; to pin it, {advice}. Standard deviations {stds} ({SCALE_NOTE})",
            id.condition_number
        )
    }
}
