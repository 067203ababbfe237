//! Rauch-Tung-Striebel smoothing of a filter history (offline use).

use crate::ekf::StateAndCovariance;
use crate::online::FilterHistory;

/// Smoothed estimates at every node of `history`, or `None` if a predicted
/// covariance cannot be inverted.
pub fn rts_smooth(history: &FilterHistory) -> Option<Vec<StateAndCovariance>> {
    let n = history.filtered.len();
    let mut out = history.filtered.clone();
    for k in (0..n.saturating_sub(1)).rev() {
        let filt = &history.filtered[k];
        let pred = &history.predicted[k + 1];
        let f = &history.transition[k + 1];
        // C = P_f Fᵀ P_pred⁻¹, via Cᵀ = P_pred⁻¹ F P_f (P_f symmetric).
        let chol = pred.covariance.cholesky()?;
        let c = chol.solve(&(f * filt.covariance)).transpose();
        let next = out[k + 1];
        let state = filt.state + c * (next.state - pred.state);
        let mut cov = filt.covariance + c * (next.covariance - pred.covariance) * c.transpose();
        cov = 0.5 * (cov + cov.transpose());
        out[k] = StateAndCovariance {
            state,
            covariance: cov,
        };
    }
    Some(out)
}
