//! Rauch-Tung-Striebel smoothing of a filter history (offline use).

use crate::ekf::StateAndCovariance;
use crate::online::FilterHistory;
use twindrive_kinematics::Mat6;

/// Smoothed estimates at every node of `history`, or `None` if a predicted
/// covariance cannot be inverted.
pub fn rts_smooth(history: &FilterHistory) -> Option<Vec<StateAndCovariance>> {
    let n = history.filtered.len();
    // Built backwards from the last node (whose smoothed estimate is the
    // filtered one), then reversed: no copy of the whole filtered history.
    let mut rev: Vec<StateAndCovariance> = Vec::with_capacity(n);
    rev.extend(history.filtered.last().copied());
    for k in (0..n.saturating_sub(1)).rev() {
        let filt = &history.filtered[k];
        let pred = &history.predicted[k + 1];
        let f_top = &history.transition[k + 1];
        // C = P_f Fᵀ P_pred⁻¹, via Cᵀ = P_pred⁻¹ F P_f (P_f symmetric).
        // F = [[A, B], [0, I]]: only the pose rows of F P_f differ from P_f.
        let mut fp = filt.covariance;
        let top = f_top * filt.covariance;
        fp.fixed_view_mut::<3, 6>(0, 0).copy_from(&top);
        let c = solve_spd6(&pred.covariance, &fp)?.transpose();
        let next = *rev.last().expect("the last node is pushed first");
        let state = filt.state + c * (next.state - pred.state);
        let mut cov = filt.covariance + c * (next.covariance - pred.covariance) * c.transpose();
        cov = 0.5 * (cov + cov.transpose());
        rev.push(StateAndCovariance {
            state,
            covariance: cov,
        });
    }
    rev.reverse();
    Some(rev)
}

/// Solves `A X = B` for symmetric positive-definite 6x6 `A` by a Cholesky
/// factorisation on plain arrays (much faster than the general routine at
/// this size); `None` if `A` is not positive-definite.
fn solve_spd6(a: &Mat6, b: &Mat6) -> Option<Mat6> {
    let mut l = [[0.0f64; 6]; 6];
    for j in 0..6 {
        let d = a[(j, j)] - l[j][..j].iter().map(|v| v * v).sum::<f64>();
        if d.is_nan() || d <= 0.0 {
            return None;
        }
        let d = d.sqrt();
        l[j][j] = d;
        for i in j + 1..6 {
            let v = a[(i, j)]
                - l[i][..j]
                    .iter()
                    .zip(&l[j][..j])
                    .map(|(p, q)| p * q)
                    .sum::<f64>();
            l[i][j] = v / d;
        }
    }
    let mut x = Mat6::zeros();
    for c in 0..6 {
        // L y = b, then Lᵀ x = y.
        let mut y = [0.0f64; 6];
        for i in 0..6 {
            let mut v = b[(i, c)];
            for k in 0..i {
                v -= l[i][k] * y[k];
            }
            y[i] = v / l[i][i];
        }
        for i in (0..6).rev() {
            let mut v = y[i];
            for k in i + 1..6 {
                v -= l[k][i] * x[(k, c)];
            }
            x[(i, c)] = v / l[i][i];
        }
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spd_solve_matches_the_general_one() {
        let m = Mat6::from_fn(|i, j| ((i * 7 + j * 3) % 11) as f64 / 11.0 - 0.4);
        let a = m * m.transpose() + Mat6::identity() * 0.2;
        let b = Mat6::from_fn(|i, j| (i as f64 - j as f64) * 0.3 + 1.0);
        let x = solve_spd6(&a, &b).unwrap();
        assert!((a * x - b).abs().max() < 1e-10);
        let mut not_pd = a;
        not_pd[(2, 2)] = -1.0;
        assert!(solve_spd6(&not_pd, &b).is_none());
    }
}
