//! The augmented state [x, y, θ, dL, dR, b] and the analytic Jacobians of the
//! arc step with respect to it and to the wheel rotations.

use nalgebra::{SMatrix, SVector};

use crate::arc::sinc_and_derivative;

pub type StateVec = SVector<f64, 6>;
pub type Mat6 = SMatrix<f64, 6, 6>;
pub type Mat6x2 = SMatrix<f64, 6, 2>;

/// Index names for [`StateVec`]: pose, then the kinematic parameters.
#[derive(Debug, Clone, Copy)]
pub struct AugmentedState;

impl AugmentedState {
    pub const X: usize = 0;
    pub const Y: usize = 1;
    pub const THETA: usize = 2;
    pub const LEFT_DIAMETER: usize = 3;
    pub const RIGHT_DIAMETER: usize = 4;
    pub const WHEELBASE: usize = 5;
}

/// Intermediate quantities of one step, shared by the step and its Jacobians.
struct StepTerms {
    ds: f64,
    half_turn: f64,
    chord: f64,
    sinc_half: f64,
    sinc_half_derivative: f64,
    cos_mid: f64,
    sin_mid: f64,
}

fn terms(state: &StateVec, left_rad: f64, right_rad: f64) -> StepTerms {
    let (theta, dl, dr, b) = (state[2], state[3], state[4], state[5]);
    let left_m = 0.5 * dl * left_rad;
    let right_m = 0.5 * dr * right_rad;
    let ds = 0.5 * (left_m + right_m);
    let half_turn = 0.5 * (right_m - left_m) / b;
    let (sinc_half, sinc_half_derivative) = sinc_and_derivative(half_turn);
    let (sin_mid, cos_mid) = (theta + half_turn).sin_cos();
    StepTerms {
        ds,
        half_turn,
        chord: ds * sinc_half,
        sinc_half,
        sinc_half_derivative,
        cos_mid,
        sin_mid,
    }
}

/// The arc step on the augmented state; wheel rotations in radians. The
/// parameters are carried through unchanged.
pub fn step_augmented(state: &StateVec, left_rad: f64, right_rad: f64) -> StateVec {
    let t = terms(state, left_rad, right_rad);
    let mut next = *state;
    next[0] += t.chord * t.cos_mid;
    next[1] += t.chord * t.sin_mid;
    next[2] += 2.0 * t.half_turn;
    next
}

/// The state Jacobian of one arc step or of a chain of them, by blocks:
/// `[[A, B], [0, I]]` with `A = [[1, 0, heading_to_x], [0, 1,
/// heading_to_y], [0, 0, 1]]` and `B = params` (rows x, y, θ; columns dL,
/// dR, b). Products of such matrices keep the form, so a chain is these 11
/// numbers too.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    /// ∂x'/∂θ.
    pub heading_to_x: f64,
    /// ∂y'/∂θ.
    pub heading_to_y: f64,
    /// ∂(x', y', θ')/∂(dL, dR, b).
    pub params: [[f64; 3]; 3],
}

impl Transition {
    pub const IDENTITY: Transition = Transition {
        heading_to_x: 0.0,
        heading_to_y: 0.0,
        params: [[0.0; 3]; 3],
    };

    /// The dense 6x6 matrix.
    pub fn state_matrix(&self) -> Mat6 {
        let mut f = Mat6::identity();
        f[(0, 2)] = self.heading_to_x;
        f[(1, 2)] = self.heading_to_y;
        for (i, row) in self.params.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                f[(i, 3 + j)] = *v;
            }
        }
        f
    }
}

/// The Jacobians of one arc step, by blocks (rows x, y, θ): with respect to
/// the state, `state`; with respect to the wheel rotations only the pose rows
/// are non-zero, `wheels`. Filters use the blocks directly; the dense
/// matrices are there for reference and tests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepJacobian {
    pub state: Transition,
    /// ∂(x', y', θ')/∂(left_rad, right_rad).
    pub wheels: [[f64; 2]; 3],
}

impl StepJacobian {
    /// The dense 6x6 state Jacobian.
    pub fn state_matrix(&self) -> Mat6 {
        self.state.state_matrix()
    }

    /// The dense 6x2 wheel-rotation Jacobian.
    pub fn wheel_matrix(&self) -> Mat6x2 {
        let mut g = Mat6x2::zeros();
        for (i, row) in self.wheels.iter().enumerate() {
            g[(i, 0)] = row[0];
            g[(i, 1)] = row[1];
        }
        g
    }
}

/// [`step_augmented`] and its Jacobians by blocks in one go (the
/// trigonometry once).
#[inline]
pub fn step_with_jacobian(
    state: &StateVec,
    left_rad: f64,
    right_rad: f64,
) -> (StateVec, StepJacobian) {
    let t = terms(state, left_rad, right_rad);
    let mut next = *state;
    next[0] += t.chord * t.cos_mid;
    next[1] += t.chord * t.sin_mid;
    next[2] += 2.0 * t.half_turn;
    (next, jacobian_from_terms(state, left_rad, right_rad, &t))
}

/// [`step_augmented`] and [`step_jacobians`] in one go.
pub fn step_with_jacobians(
    state: &StateVec,
    left_rad: f64,
    right_rad: f64,
) -> (StateVec, Mat6, Mat6x2) {
    let (next, j) = step_with_jacobian(state, left_rad, right_rad);
    (next, j.state_matrix(), j.wheel_matrix())
}

/// Jacobians of [`step_augmented`]: `F = ∂f/∂state` (6x6) and
/// `G = ∂f/∂[left_rad, right_rad]` (6x2), the latter for mapping wheel-travel
/// noise into the state.
pub fn step_jacobians(state: &StateVec, left_rad: f64, right_rad: f64) -> (Mat6, Mat6x2) {
    let t = terms(state, left_rad, right_rad);
    let j = jacobian_from_terms(state, left_rad, right_rad, &t);
    (j.state_matrix(), j.wheel_matrix())
}

#[inline]
fn jacobian_from_terms(
    state: &StateVec,
    left_rad: f64,
    right_rad: f64,
    t: &StepTerms,
) -> StepJacobian {
    let (dl, dr) = (state[3], state[4]);
    let inv_b = 1.0 / state[5];

    // Partials of (x', y', θ') for a variable with the given partials of ds
    // and of the half turn α.
    let column = |dds: f64, dalpha: f64| -> [f64; 3] {
        let dchord = dds * t.sinc_half + t.ds * t.sinc_half_derivative * dalpha;
        [
            dchord * t.cos_mid - t.chord * t.sin_mid * dalpha,
            dchord * t.sin_mid + t.chord * t.cos_mid * dalpha,
            2.0 * dalpha,
        ]
    };
    let p = [
        column(0.25 * left_rad, -0.25 * left_rad * inv_b),
        column(0.25 * right_rad, 0.25 * right_rad * inv_b),
        column(0.0, -t.half_turn * inv_b),
    ];
    let w = [
        column(0.25 * dl, -0.25 * dl * inv_b),
        column(0.25 * dr, 0.25 * dr * inv_b),
    ];
    StepJacobian {
        state: Transition {
            heading_to_x: -t.chord * t.sin_mid,
            heading_to_y: t.chord * t.cos_mid,
            params: std::array::from_fn(|i| [p[0][i], p[1][i], p[2][i]]),
        },
        wheels: std::array::from_fn(|i| [w[0][i], w[1][i]]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{DiffDriveParams, Pose, arc_step_wheels};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_state(rng: &mut ChaCha8Rng) -> StateVec {
        StateVec::new(
            rng.random_range(-5.0..5.0),
            rng.random_range(-5.0..5.0),
            rng.random_range(-4.0..4.0),
            rng.random_range(0.03..0.3),
            rng.random_range(0.03..0.3),
            rng.random_range(0.1..0.6),
        )
    }

    /// Central differences; returns (F, G) numerically.
    fn numeric(state: &StateVec, l: f64, r: f64) -> (Mat6, Mat6x2) {
        let h = 1e-6;
        let mut f = Mat6::zeros();
        for j in 0..6 {
            let mut plus = *state;
            let mut minus = *state;
            plus[j] += h;
            minus[j] -= h;
            let col = (step_augmented(&plus, l, r) - step_augmented(&minus, l, r)) / (2.0 * h);
            f.set_column(j, &col);
        }
        let mut g = Mat6x2::zeros();
        let cl = (step_augmented(state, l + h, r) - step_augmented(state, l - h, r)) / (2.0 * h);
        let cr = (step_augmented(state, l, r + h) - step_augmented(state, l, r - h)) / (2.0 * h);
        g.set_column(0, &cl);
        g.set_column(1, &cr);
        (f, g)
    }

    fn assert_close(label: &str, analytic: &[f64], numeric: &[f64], seed_info: &str) {
        for (k, (a, n)) in analytic.iter().zip(numeric).enumerate() {
            // Central differences with h = 1e-6 are good to ~1e-8 relative.
            let tol = 1e-6 * n.abs() + 1e-9;
            assert!(
                (a - n).abs() < tol,
                "{label}[{k}] analytic {a} vs numeric {n} ({seed_info})"
            );
        }
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let seed = 7;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        for case in 0..5000 {
            let state = random_state(&mut rng);
            // Mix general steps with the singular-looking special cases.
            let (l, r) = match case % 5 {
                0 => {
                    let w = rng.random_range(-8.0..8.0);
                    (w, w * state[3] / state[4]) // straight line: equal travel
                }
                1 => {
                    let w = rng.random_range(-8.0..8.0);
                    (w, -w * state[3] / state[4]) // pure rotation: opposite travel
                }
                2 => (rng.random_range(-1e-4..1e-4), rng.random_range(-1e-4..1e-4)),
                3 => {
                    // Half turn α right at the series switch (1e-3 ± ε), long travel.
                    let alpha = [1e-3 - 1e-9, 1e-3 + 1e-9, -1e-3 + 1e-9][case % 3];
                    let travel = rng.random_range(0.2..0.6);
                    let (dl, dr, b) = (state[3], state[4], state[5]);
                    // sR − sL = 2 α b, sR + sL = 2 travel.
                    let (sl, sr) = (travel - alpha * b, travel + alpha * b);
                    (2.0 * sl / dl, 2.0 * sr / dr)
                }
                _ => (rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0)),
            };
            let (fa, ga) = step_jacobians(&state, l, r);
            let (fn_, gn) = numeric(&state, l, r);
            let info = format!("seed {seed}, case {case}, state {state:?}, l {l}, r {r}");
            assert_close("F", fa.as_slice(), fn_.as_slice(), &info);
            assert_close("G", ga.as_slice(), gn.as_slice(), &info);
        }
    }

    #[test]
    fn combined_step_equals_the_separate_ones() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for _ in 0..100 {
            let s = random_state(&mut rng);
            let (l, r) = (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let (next, f, g) = step_with_jacobians(&s, l, r);
            assert_eq!(next, step_augmented(&s, l, r));
            assert_eq!((f, g), step_jacobians(&s, l, r));
            let (next_blocks, j) = step_with_jacobian(&s, l, r);
            assert_eq!(next_blocks, next);
            assert_eq!((j.state_matrix(), j.wheel_matrix()), (f, g));
        }
    }

    #[test]
    fn augmented_step_matches_pose_step() {
        let p = DiffDriveParams::new(0.07, 0.071, 0.29);
        let pose = Pose::new(0.5, 1.5, -2.0);
        let s = StateVec::new(0.5, 1.5, -2.0, 0.07, 0.071, 0.29);
        let a = step_augmented(&s, 0.3, 0.5);
        let b = arc_step_wheels(&pose, &p, 0.3, 0.5);
        assert_eq!((a[0], a[1], a[2]), (b.x_m, b.y_m, b.heading_rad));
        assert_eq!((a[3], a[4], a[5]), (0.07, 0.071, 0.29));
    }
}
