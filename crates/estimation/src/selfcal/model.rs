//! The measurement model: odometry over a motion's encoder steps and the
//! lidar motion it predicts, `s = ℓ⁻¹ ⊕ o ⊕ ℓ`, with analytic Jacobians.
//! Frames as in the [module](super) (REP-103; the paper's eq. (3) has the
//! opposite heading sign).

use nalgebra::Matrix3;

use crate::ekf::NoiseModel;
use crate::odometry_chain::OdometryChain;

/// The robot's motion over one interval in `base_link` at its start.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Odometry {
    /// `o = [x (m), y (m), θ (rad)]`.
    pub(crate) pose: [f64; 3],
    /// ∂o/∂(dL, dR, b): rows x, y, θ.
    pub(crate) d_params: Matrix3<f64>,
    /// Covariance of `o` from the wheel noise.
    pub(crate) cov: Matrix3<f64>,
}

/// Chains exact arcs over `steps` (`[left, right]` wheel radians) from
/// (0, 0, 0) with `params = [dL, dR, b]`.
pub(crate) fn odometry(steps: &[[f64; 2]], params: [f64; 3], noise: &NoiseModel) -> Odometry {
    let mut chain = OdometryChain::new([0.0; 3], params);
    for s in steps {
        chain.step(s[0], s[1], noise);
    }
    Odometry {
        pose: chain.pose(),
        d_params: Matrix3::from_fn(|i, j| chain.jac.params[i][j]),
        cov: Matrix3::from_fn(|i, j| chain.cov[i][j]),
    }
}

/// The lidar motion predicted from an odometry `o` and a mount `ℓ`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Prediction {
    /// `s = [dx (m), dy (m), dθ (rad)]` in the lidar frame at the start.
    pub(crate) s: [f64; 3],
    /// ∂s/∂o (rows sx, sy, sθ; columns ox, oy, oθ).
    pub(crate) d_odometry: Matrix3<f64>,
    /// ∂s/∂ℓ (columns ℓx, ℓy, ℓθ).
    pub(crate) d_mount: Matrix3<f64>,
}

/// `s = ℓ⁻¹ ⊕ o ⊕ ℓ`: `s_θ = o_θ`,
/// `s_xy = R(−ℓθ)·[R(o_θ)·ℓ_xy + o_xy − ℓ_xy]`.
#[inline]
pub(crate) fn predict(o: [f64; 3], mount: [f64; 3]) -> Prediction {
    let [lx, ly, lt] = mount;
    let (so, co) = o[2].sin_cos();
    let (sl, cl) = lt.sin_cos();
    // v = R(oθ) ℓ + o − ℓ in base_link at the start.
    let vx = co * lx - so * ly + o[0] - lx;
    let vy = so * lx + co * ly + o[1] - ly;
    // R(−ℓθ) = [[cl, sl], [−sl, cl]].
    let sx = cl * vx + sl * vy;
    let sy = -sl * vx + cl * vy;
    // ∂v/∂oθ = R(oθ)·Ω·ℓ = (−so lx − co ly, co lx − so ly).
    let (dvx, dvy) = (-so * lx - co * ly, co * lx - so * ly);
    let d_odometry = Matrix3::new(
        cl,
        sl,
        cl * dvx + sl * dvy,
        -sl,
        cl,
        -sl * dvx + cl * dvy,
        0.0,
        0.0,
        1.0,
    );
    // ∂v/∂ℓ_xy = R(oθ) − I; ∂s_xy/∂ℓθ = −Ω s_xy = (sy, −sx).
    let (a00, a01, a10, a11) = (co - 1.0, -so, so, co - 1.0);
    let d_mount = Matrix3::new(
        cl * a00 + sl * a10,
        cl * a01 + sl * a11,
        sy,
        -sl * a00 + cl * a10,
        -sl * a01 + cl * a11,
        -sx,
        0.0,
        0.0,
        0.0,
    );
    Prediction {
        s: [sx, sy, o[2]],
        d_odometry,
        d_mount,
    }
}

/// The lidar frame's motion `[dx (m), dy (m), dθ (rad)]` (in the lidar
/// frame at the start) that encoder increments `wheel_steps` (`[left,
/// right]` rad, forward positive) produce with `params = [dL, dR, b, ℓx,
/// ℓy, ℓθ]` (m, m, m, m, m, rad): exact arcs, `s = ℓ⁻¹ ⊕ o ⊕ ℓ`. For
/// simulating laser odometry and checking a calibration.
pub fn predict_laser_motion(wheel_steps: &[[f64; 2]], params: [f64; 6]) -> [f64; 3] {
    let noise = NoiseModel {
        wheel_rad2_per_rad: 0.0,
        wheel_floor_rad2: 0.0,
        ..NoiseModel::default()
    };
    let o = odometry(wheel_steps, [params[0], params[1], params[2]], &noise);
    predict(o.pose, [params[3], params[4], params[5]]).s
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn compose(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        let (s, c) = a[2].sin_cos();
        [
            a[0] + c * b[0] - s * b[1],
            a[1] + s * b[0] + c * b[1],
            a[2] + b[2],
        ]
    }

    fn inverse(a: [f64; 3]) -> [f64; 3] {
        let (s, c) = a[2].sin_cos();
        [-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2]]
    }

    #[test]
    fn prediction_is_the_conjugated_motion_and_its_jacobians_match_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for _ in 0..500 {
            let o = [
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
                rng.random_range(-3.0..3.0),
            ];
            let l = [
                rng.random_range(-0.2..0.2),
                rng.random_range(-0.2..0.2),
                rng.random_range(-3.1..3.1),
            ];
            let p = predict(o, l);
            let s = compose(compose(inverse(l), o), l);
            for i in 0..3 {
                assert!((p.s[i] - s[i]).abs() < 1e-12, "{:?} vs {s:?}", p.s);
            }
            let h = 1e-6;
            for j in 0..3 {
                let (mut op, mut om, mut lp, mut lm) = (o, o, l, l);
                op[j] += h;
                om[j] -= h;
                lp[j] += h;
                lm[j] -= h;
                for i in 0..3 {
                    let dn_o = (predict(op, l).s[i] - predict(om, l).s[i]) / (2.0 * h);
                    let dn_l = (predict(o, lp).s[i] - predict(o, lm).s[i]) / (2.0 * h);
                    assert!((p.d_odometry[(i, j)] - dn_o).abs() < 1e-7, "∂s{i}/∂o{j}");
                    assert!((p.d_mount[(i, j)] - dn_l).abs() < 1e-7, "∂s{i}/∂ℓ{j}");
                }
            }
        }
    }

    #[test]
    fn odometry_jacobian_matches_differences_over_many_steps() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let noise = NoiseModel::default();
        for _ in 0..100 {
            let steps: Vec<[f64; 2]> = (0..rng.random_range(1..20))
                .map(|_| [rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)])
                .collect();
            let p = [
                rng.random_range(0.04..0.2),
                rng.random_range(0.04..0.2),
                rng.random_range(0.08..0.6),
            ];
            let o = odometry(&steps, p, &noise);
            let h = 1e-7;
            for j in 0..3 {
                let (mut pp, mut pm) = (p, p);
                pp[j] += h;
                pm[j] -= h;
                let (a, b) = (odometry(&steps, pp, &noise), odometry(&steps, pm, &noise));
                for i in 0..3 {
                    let dn = (a.pose[i] - b.pose[i]) / (2.0 * h);
                    assert!((o.d_params[(i, j)] - dn).abs() < 1e-6 * (1.0 + dn.abs()));
                }
            }
        }
    }
}
