//! Robust fitting inside one group: iteratively reweighted least squares (IRLS) with Cauchy
//! weights around any estimator, then a final least-squares fit and geometric refinement on the
//! inliers alone.
//!
//! For residuals r_i (the model's geometric distance, caller's units):
//!
//! 1. fit by least squares with unit weights; for estimators that ask for it (two-view models),
//!    also on a few minimal samples drawn by a fixed-seed generator, and start from the fit of
//!    least median residual (LMedS);
//! 2. up to [`MAX_IRLS`] times: σ = max(1.4826 · median_i r_i, σ_floor); weights
//!    w_i = 1 / (1 + (r_i / (c·σ))²) with c = [`CAUCHY_C`] (95 % efficiency at Gaussian noise);
//!    weighted least squares again; stop when σ moves by less than 2 % and the inlier set
//!    (below) no longer changes;
//! 3. inliers: r_i ≤ [`INLIER_SIGMAS`] · σ; least squares on the inliers only, then the
//!    estimator's geometric refinement (Gauss–Newton / Levenberg–Marquardt) on them; residuals,
//!    σ and inliers once more, and if the inlier set changed, the refinement once more on the
//!    new inliers.
//!
//! σ_floor = [`SIGMA_FLOOR`] × the data's scale (its RMS spread), so that noise-free data does
//! not make σ = 0 and every point but the exact ones an outlier through round-off. No
//! randomness: the same rows give the same fit, bit for bit.

use super::GeometryError;
use super::linalg::median;

/// Cauchy weight constant, in units of σ.
pub const CAUCHY_C: f64 = 2.385;
/// Most reweighting rounds.
pub const MAX_IRLS: usize = 6;
/// Inlier threshold, in units of σ.
pub const INLIER_SIGMAS: f64 = 3.0;
/// The floor of σ relative to the data's scale (1 ppm).
pub const SIGMA_FLOOR: f64 = 1e-6;
/// 1 / Φ⁻¹(3/4): the median absolute deviation of a unit normal is 0.6745.
pub const MAD_TO_SIGMA: f64 = 1.4826;

/// A model estimator, as the robust loop drives it.
pub trait Estimator {
    /// One data point (a row of the input).
    type Point: Copy;
    /// The estimated parameters, caller's units.
    type Params: Clone;
    /// Points that determine the model.
    fn min_points(&self) -> usize;
    /// How many minimal samples to try as starting points besides the least-squares fit
    /// (0: least squares only). Worth it where one foreign point can drag least squares far
    /// away (two-view models).
    fn samples(&self) -> usize {
        0
    }
    /// Weighted least-squares fit; a zero weight drops the point. `Err` with a readable reason
    /// when the weighted points do not determine a model.
    fn fit(&self, points: &[Self::Point], weights: &[f64]) -> Result<Self::Params, GeometryError>;
    /// Geometric refinement of `params` on the points of positive weight (identity when the
    /// least-squares fit is already geometric).
    fn refine(&self, params: Self::Params, points: &[Self::Point], weights: &[f64])
    -> Self::Params;
    /// [`Estimator::refine`], then the refined model's [`Estimator::residuals`] of every point
    /// (override where the refinement leaves work that makes them cheaper).
    fn refine_residuals(
        &self,
        params: Self::Params,
        points: &[Self::Point],
        weights: &[f64],
    ) -> (Self::Params, Vec<f64>) {
        let refined = self.refine(params, points, weights);
        let res = self.residuals(&refined, points);
        (refined, res)
    }
    /// Geometric distance of one point, caller's units; `f64::INFINITY` where undefined.
    fn residual(&self, params: &Self::Params, point: &Self::Point) -> f64;
    /// A cheaper stand-in for [`Estimator::residual`], good near the model, for the
    /// reweighting rounds (the final inliers and σ always use `residual`).
    fn quick_residual(&self, params: &Self::Params, point: &Self::Point) -> f64 {
        self.residual(params, point)
    }
    /// [`Estimator::residual`] of every point (override to share per-model set-up work).
    fn residuals(&self, params: &Self::Params, points: &[Self::Point]) -> Vec<f64> {
        points.iter().map(|p| self.residual(params, p)).collect()
    }
    /// [`Estimator::quick_residual`] of every point.
    fn quick_residuals(&self, params: &Self::Params, points: &[Self::Point]) -> Vec<f64> {
        points
            .iter()
            .map(|p| self.quick_residual(params, p))
            .collect()
    }
}

/// The outcome of [`fit_robust`].
#[derive(Debug, Clone)]
pub struct Robust<P> {
    pub params: P,
    /// One per point, the final model's residual.
    pub residuals: Vec<f64>,
    /// max(1.4826 · median residual, floor).
    pub sigma: f64,
    pub inliers: Vec<bool>,
    /// RMS residual over the inliers.
    pub rms: f64,
}

/// σ of residuals: 1.4826 × their median, floored at `floor`; never NaN (NaN residuals count as
/// infinitely large).
pub fn robust_sigma(residuals: &[f64], floor: f64) -> f64 {
    let mut r: Vec<f64> = residuals
        .iter()
        .map(|v| if v.is_nan() { f64::INFINITY } else { v.abs() })
        .collect();
    let s = MAD_TO_SIGMA * median(&mut r);
    if s.is_nan() { floor } else { s.max(floor) }
}

/// `count` samples of `size` distinct indices in 0..n, from a fixed-seed generator (SplitMix64):
/// the same for every call with the same (n, size, count), so fits are reproducible. None
/// when n < 2·size (too few points for sampling to say anything least squares does not).
fn minimal_samples(n: usize, size: usize, count: usize) -> Vec<Vec<usize>> {
    if size == 0 || n < 2 * size {
        return Vec::new();
    }
    let mut state: u64 = 0x5EED_0F6E_03E7;
    let mut next = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    (0..count)
        .map(|_| {
            let mut sample: Vec<usize> = Vec::with_capacity(size);
            while sample.len() < size {
                let i = (next() % n as u64) as usize;
                if !sample.contains(&i) {
                    sample.push(i);
                }
            }
            sample
        })
        .collect()
}

/// The Cauchy weight of a residual at scale `s`.
fn cauchy_weight(r: f64, s: f64) -> f64 {
    let u = r / s;
    if u.is_finite() {
        1.0 / (1.0 + u * u)
    } else {
        0.0
    }
}

/// NaN (an undefined distance) counts as infinitely far.
fn no_nan(mut r: Vec<f64>) -> Vec<f64> {
    r.iter_mut()
        .filter(|v| v.is_nan())
        .for_each(|v| *v = f64::INFINITY);
    r
}

fn residuals<E: Estimator>(est: &E, params: &E::Params, points: &[E::Point]) -> Vec<f64> {
    no_nan(est.residuals(params, points))
}

fn quick_residuals<E: Estimator>(est: &E, params: &E::Params, points: &[E::Point]) -> Vec<f64> {
    no_nan(est.quick_residuals(params, points))
}

fn inlier_mask(residuals: &[f64], sigma: f64) -> Vec<bool> {
    residuals
        .iter()
        .map(|&r| r <= INLIER_SIGMAS * sigma)
        .collect()
}

/// Fits `est` to `points` robustly (see the module docs): [`fit_unrefined`], then
/// [`refine_robust`]. `scale` is the data's RMS spread in the residual's units (sets σ's floor).
/// `Err` when the points do not determine a model even with unit weights.
pub fn fit_robust<E: Estimator>(
    est: &E,
    points: &[E::Point],
    scale: f64,
) -> Result<Robust<E::Params>, GeometryError> {
    let unrefined = fit_unrefined(est, points, scale)?;
    Ok(refine_robust(est, points, unrefined, scale))
}

/// Steps 1–2 of the module docs and the least-squares fit on the inliers, without the geometric
/// refinement (model selection refines only the winner). Residuals, σ and inliers are those of
/// the returned parameters.
pub fn fit_unrefined<E: Estimator>(
    est: &E,
    points: &[E::Point],
    scale: f64,
) -> Result<Robust<E::Params>, GeometryError> {
    let n = points.len();
    if n < est.min_points() {
        return Err(GeometryError::TooFewPoints {
            n,
            min: est.min_points(),
        });
    }
    let floor = sigma_floor(scale);
    let mut weights = vec![1.0; n];
    let mut params = est.fit(points, &weights)?;
    let mut res = quick_residuals(est, &params, points);
    let mut sigma = robust_sigma(&res, floor);
    // Least median of squares over a few deterministic minimal samples: the start with the
    // smallest median residual wins.
    let ones = vec![1.0; est.min_points()];
    for sample in minimal_samples(n, est.min_points(), est.samples()) {
        let subset: Vec<E::Point> = sample.iter().map(|&i| points[i]).collect();
        let Ok(candidate) = est.fit(&subset, &ones) else {
            continue;
        };
        let candidate_res = quick_residuals(est, &candidate, points);
        let candidate_sigma = robust_sigma(&candidate_res, floor);
        if candidate_sigma < sigma {
            params = candidate;
            res = candidate_res;
            sigma = candidate_sigma;
        }
    }

    for _ in 0..MAX_IRLS {
        for (w, r) in weights.iter_mut().zip(&res) {
            *w = cauchy_weight(*r, CAUCHY_C * sigma);
        }
        let Ok(next) = est.fit(points, &weights) else {
            break;
        };
        let next_res = quick_residuals(est, &next, points);
        let next_sigma = robust_sigma(&next_res, floor);
        // Only the inlier set matters from here on (least squares on it follows): stop once it
        // and σ have settled.
        let settled = (next_sigma - sigma).abs() <= 0.02 * sigma
            && inlier_mask(&next_res, next_sigma) == inlier_mask(&res, sigma);
        params = next;
        res = next_res;
        sigma = next_sigma;
        if settled {
            break;
        }
    }

    // Least squares on the inliers alone.
    let inliers = inlier_mask(&res, sigma);
    if inliers.iter().filter(|&&v| v).count() >= est.min_points() {
        let w01: Vec<f64> = inliers.iter().map(|&v| if v { 1.0 } else { 0.0 }).collect();
        if let Ok(ls) = est.fit(points, &w01) {
            params = ls;
        }
    }
    Ok(evaluate(est, params, points, scale))
}

/// Step 3's geometric refinement on the inliers of `fit`; if that changes the inliers, once more
/// on the new ones (from where it stopped).
pub fn refine_robust<E: Estimator>(
    est: &E,
    points: &[E::Point],
    fit: Robust<E::Params>,
    scale: f64,
) -> Robust<E::Params> {
    let mut current = fit;
    for _round in 0..2 {
        if current.inliers.iter().filter(|&&v| v).count() < est.min_points() {
            break;
        }
        let w01: Vec<f64> = current
            .inliers
            .iter()
            .map(|&v| if v { 1.0 } else { 0.0 })
            .collect();
        let (refined, res) = est.refine_residuals(current.params.clone(), points, &w01);
        let next = evaluated(refined, no_nan(res), scale);
        let same = next.inliers == current.inliers;
        current = next;
        if same {
            break;
        }
    }
    current
}

/// The floor of σ for data of RMS spread `scale`.
pub(crate) fn sigma_floor(scale: f64) -> f64 {
    if scale.is_finite() && scale > 0.0 {
        SIGMA_FLOOR * scale
    } else {
        f64::MIN_POSITIVE
    }
}

/// Assembles the outcome, with the RMS over the inliers.
fn finish<P>(params: P, residuals: Vec<f64>, sigma: f64, inliers: Vec<bool>) -> Robust<P> {
    let (ss, count) = residuals
        .iter()
        .zip(&inliers)
        .filter(|(_, inlier)| **inlier)
        .fold((0.0, 0usize), |(s, c), (r, _)| (s + r * r, c + 1));
    let rms = if count > 0 {
        (ss / count as f64).sqrt()
    } else {
        f64::INFINITY
    };
    Robust {
        params,
        residuals,
        sigma,
        inliers,
        rms,
    }
}

/// Residuals, σ, inliers and RMS of given parameters, without fitting (`scale` as in
/// [`fit_robust`]).
pub fn evaluate<E: Estimator>(
    est: &E,
    params: E::Params,
    points: &[E::Point],
    scale: f64,
) -> Robust<E::Params> {
    let res = residuals(est, &params, points);
    evaluated(params, res, scale)
}

/// [`evaluate`] with the residuals given.
fn evaluated<P>(params: P, res: Vec<f64>, scale: f64) -> Robust<P> {
    let sigma = robust_sigma(&res, sigma_floor(scale));
    let inliers = inlier_mask(&res, sigma);
    finish(params, res, sigma, inliers)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The mean of scalars: the simplest estimator, to test the loop itself.
    struct Mean;
    impl Estimator for Mean {
        type Point = f64;
        type Params = f64;
        fn min_points(&self) -> usize {
            1
        }
        fn fit(&self, points: &[f64], weights: &[f64]) -> Result<f64, GeometryError> {
            let sw: f64 = weights.iter().sum();
            if sw <= 0.0 {
                return Err(GeometryError::NoWeightedPoints);
            }
            Ok(points.iter().zip(weights).map(|(p, w)| p * w).sum::<f64>() / sw)
        }
        fn refine(&self, params: f64, _: &[f64], _: &[f64]) -> f64 {
            params
        }
        fn residual(&self, params: &f64, point: &f64) -> f64 {
            (point - params).abs()
        }
    }

    #[test]
    fn irls_ignores_gross_outliers_and_flags_them() {
        let mut pts: Vec<f64> = (0..90)
            .map(|i| 10.0 + 0.01 * ((i * 37 % 19) as f64 - 9.0))
            .collect();
        pts.extend((0..10).map(|i| 1000.0 + i as f64));
        let fit = fit_robust(&Mean, &pts, 1.0).unwrap();
        assert!((fit.params - 10.0).abs() < 0.01, "{}", fit.params);
        assert!(fit.inliers[..90].iter().all(|&v| v));
        assert!(fit.inliers[90..].iter().all(|&v| !v));
        assert!(fit.sigma > 0.0 && fit.sigma < 0.1);
    }

    #[test]
    fn sigma_has_a_floor_and_is_deterministic() {
        let pts = vec![5.0; 20];
        let a = fit_robust(&Mean, &pts, 2.0).unwrap();
        let b = fit_robust(&Mean, &pts, 2.0).unwrap();
        assert_eq!(a.sigma, SIGMA_FLOOR * 2.0);
        assert_eq!(a.params.to_bits(), b.params.to_bits());
        assert!(a.inliers.iter().all(|&v| v));
        assert_eq!(robust_sigma(&[f64::NAN, 1.0, 1.0], 0.0), MAD_TO_SIGMA);
        assert!(fit_robust(&Mean, &[], 1.0).is_err());
    }
}
