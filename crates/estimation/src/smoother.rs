//! Rauch-Tung-Striebel smoothing of a filter history (offline use).
//!
//! Each backward step works on matrix columns (see [`crate::covariance`]):
//! the gain `C = P_f Fᵀ P_pred⁻¹` comes from a Cholesky factorisation of the
//! predicted covariance and two triangular solves from the right.

use crate::covariance::{
    Col, Lanes, PackedCovariance, PackedEstimate, load_all, mirror_lower, pose_columns_of_p_ft,
};
use crate::online::FilterHistory;
use twindrive_kinematics::Mat6;

/// Smoothed estimates at every node of `history`, or `None` if a predicted
/// covariance is not positive-definite.
pub fn rts_smooth(history: &FilterHistory) -> Option<Vec<PackedEstimate>> {
    let n = history.filtered.len();
    let Some(last) = history.filtered.last() else {
        return Some(Vec::new());
    };
    // Filled backwards over a copy of the filtered nodes; the last node's
    // smoothed estimate is the filtered one.
    let mut out = history.filtered.clone();
    let mut next_state: Col = last.state.into();
    let mut next_cov = last.covariance.unpack().data.0;
    for k in (0..n - 1).rev() {
        let filt = &history.filtered[k];
        let pred = &history.predicted[k + 1];
        let pf_cols = filt.covariance.unpack().data.0;
        let pf = load_all(&pf_cols);
        let pp = pred.covariance.unpack();
        // W = P_f Fᵀ: its parameter columns are those of P_f.
        let w_pose = pose_columns_of_p_ft(&pf, &history.transition[k + 1]);
        let w = [w_pose[0], w_pose[1], w_pose[2], pf[3], pf[4], pf[5]];
        let c = right_solve_spd(&pp, w)?;
        let c_cols = c.map(Lanes::to_col);

        // x_s = x_f + C (x_s,next − x_pred).
        let mut state = Lanes::load(&filt.state.into());
        for (j, cj) in c.iter().enumerate() {
            state.axpy(next_state[j] - pred.state[j], cj);
        }
        // P_s = P_f + C (P_s,next − P_pred) Cᵀ, via E = C (P_s,next − P_pred).
        let pp = pp.data.0;
        let mut e = [Lanes::ZERO; 6];
        for (j, ej) in e.iter_mut().enumerate() {
            for (kk, ck) in c.iter().enumerate() {
                ej.axpy(next_cov[j][kk] - pp[j][kk], ck);
            }
        }
        let mut cov = pf_cols;
        for (j, covj) in cov.iter_mut().enumerate() {
            let mut col = pf[j];
            for (ek, ck) in e.iter().zip(&c_cols) {
                col.axpy(ck[j], ek);
            }
            col.store(covj);
        }
        mirror_lower(&mut cov);

        next_state = state.to_col();
        next_cov = cov;
        out[k] = PackedEstimate {
            state: next_state.into(),
            covariance: PackedCovariance::pack(&Mat6::from_data(nalgebra::ArrayStorage(cov))),
        };
    }
    Some(out)
}

/// Solves `X A = B` for symmetric positive-definite `A` (`B` and `X` as
/// columns) through `A = L D Lᵀ` with unit lower-triangular `L` (no square
/// roots on the critical path); `None` if `A` is not positive-definite.
fn right_solve_spd(a: &Mat6, b: [Lanes; 6]) -> Option<[Lanes; 6]> {
    let a = &a.data.0;
    let mut l = [[0.0f64; 6]; 6];
    let mut d = [0.0f64; 6];
    let mut inv_d = [0.0f64; 6];
    for j in 0..6 {
        // ld[k] = L[j][k] d_k.
        let mut ld = [0.0f64; 6];
        let mut dj = a[j][j];
        for k in 0..j {
            ld[k] = l[j][k] * d[k];
            dj -= l[j][k] * ld[k];
        }
        if dj.is_nan() || dj <= 0.0 {
            return None;
        }
        d[j] = dj;
        inv_d[j] = 1.0 / dj;
        for i in j + 1..6 {
            let mut v = a[j][i];
            for k in 0..j {
                v -= l[i][k] * ld[k];
            }
            l[i][j] = v * inv_d[j];
        }
    }
    // Z Lᵀ = B: Z[:, j] = B[:, j] − Σ_{k<j} Z[:, k] L[j][k].
    let mut z = b;
    for (j, lj) in l.iter().enumerate().skip(1) {
        let (done, rest) = z.split_at_mut(j);
        for (zk, ljk) in done.iter().zip(lj) {
            rest[0].axpy(-ljk, zk);
        }
    }
    // Y = Z D⁻¹, then X L = Y: X[:, j] = Y[:, j] − Σ_{k>j} X[:, k] L[k][j].
    for j in (0..6).rev() {
        let (head, done) = z.split_at_mut(j + 1);
        let xj = &mut head[j];
        xj.scale(inv_d[j]);
        for (k, xk) in done.iter().enumerate() {
            xj.axpy(-l[j + 1 + k][j], xk);
        }
    }
    Some(z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn right_spd_solve_matches_the_general_one() {
        let m = Mat6::from_fn(|i, j| ((i * 7 + j * 3) % 11) as f64 / 11.0 - 0.4);
        let a = m * m.transpose() + Mat6::identity() * 0.2;
        let a = (a + a.transpose()) * 0.5;
        let b = Mat6::from_fn(|i, j| (i as f64 - j as f64) * 0.3 + 1.0);
        let solved = right_solve_spd(&a, load_all(&b.data.0)).unwrap();
        let x = Mat6::from_data(nalgebra::ArrayStorage(solved.map(Lanes::to_col)));
        assert!((x * a - b).abs().max() < 1e-10);
        let mut not_pd = a;
        not_pd[(2, 2)] = -1.0;
        assert!(right_solve_spd(&not_pd, load_all(&b.data.0)).is_none());
    }
}
