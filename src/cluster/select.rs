//! The second-order difference (SOD) of the log residual curve, and the K it picks.

/// SOD scores `(K, sod(K))` for the inner points of the curve.
pub fn sod_scores(residuals: &[(usize, f64)]) -> Vec<(usize, f64)> {
    let floor = residuals.first().map_or(0.0, |r| r.1) * 1e-9 + 1e-12;
    let l: Vec<f64> = residuals.iter().map(|&(_, r)| (r + floor).ln()).collect();
    (1..residuals.len().saturating_sub(1))
        .map(|i| (residuals[i].0, l[i - 1] + l[i + 1] - 2.0 * l[i]))
        .collect()
}

pub(super) fn argmax(scores: &[(usize, f64)]) -> Option<usize> {
    scores
        .iter()
        .fold(None, |best: Option<(usize, f64)>, &(k, s)| match best {
            Some((_, b)) if b >= s => best,
            _ => Some((k, s)),
        })
        .map(|b| b.0)
}
