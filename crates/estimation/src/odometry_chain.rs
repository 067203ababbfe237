//! Dead reckoning through a run of encoder increments with the Jacobian of
//! the end pose with respect to the parameters and the odometry covariance:
//! the one kinematic chain shared by [`crate::batch`] and [`crate::selfcal`].
//!
//! Exact arcs per encoder step ([`step_with_jacobian`]); REP-103 (x forward,
//! y left, heading counter-clockwise positive). The paper's eq. (3) has the
//! opposite heading sign.

use twindrive_kinematics::{StateVec, Transition, step_with_jacobian};

use crate::covariance::chain;
use crate::ekf::NoiseModel;

/// A pose dead-reckoned from a start pose, with what the fits need to know
/// about it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct OdometryChain {
    /// [x, y, θ, dL, dR, b]; the parameters are carried unchanged.
    pub(crate) state: StateVec,
    /// d end / d start and d end / d (dL, dR, b) of the chain so far.
    pub(crate) jac: Transition,
    /// Covariance of the end pose from the wheel noise of the steps so far
    /// (rows and columns x, y, θ).
    pub(crate) cov: [[f64; 3]; 3],
}

impl OdometryChain {
    /// A chain of no steps at `pose` ([x, y, θ]) with parameters
    /// [dL, dR, b] (m).
    pub(crate) fn new(pose: [f64; 3], params: [f64; 3]) -> Self {
        Self {
            state: StateVec::new(pose[0], pose[1], pose[2], params[0], params[1], params[2]),
            jac: Transition::IDENTITY,
            cov: [[0.0; 3]; 3],
        }
    }

    /// One encoder step of `l`, `r` wheel radians (forward positive).
    #[inline]
    pub(crate) fn step(&mut self, l: f64, r: f64, noise: &NoiseModel) {
        // Step Jacobians are [[A, B], [0, I]] with A = [[1, 0, a], [0, 1, b],
        // [0, 0, 1]] (see `Transition`): the chain's d pose / d params follows
        // J ← A J + B, d pose_end / d pose_start keeps A's form (the couplings
        // add up), and the odometry covariance follows C ← A C Aᵀ + G q Gᵀ.
        let (stepped, step) = step_with_jacobian(&self.state, l, r);
        self.state = stepped;
        self.jac = chain(&self.jac, &step.state);
        let (a, b) = (step.state.heading_to_x, step.state.heading_to_y);
        // A C Aᵀ: rows/columns 0 and 1 pick up a, b times row/column 2.
        let c = self.cov;
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
        let mut cov = [
            [c00 + gqg(0, 0), c01 + gqg(0, 1), c02 + gqg(0, 2)],
            [0.0, c11 + gqg(1, 1), c12 + gqg(1, 2)],
            [0.0, 0.0, c[2][2] + gqg(2, 2)],
        ];
        cov[1][0] = cov[0][1];
        cov[2][0] = cov[0][2];
        cov[2][1] = cov[1][2];
        self.cov = cov;
    }

    /// The end pose [x, y, θ].
    #[inline]
    pub(crate) fn pose(&self) -> [f64; 3] {
        [self.state[0], self.state[1], self.state[2]]
    }
}
