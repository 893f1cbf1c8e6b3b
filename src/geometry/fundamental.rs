//! Fundamental matrices: x₂ᵀ·F·x₁ = 0, rank 2.
//!
//! **Normalised 8-point (HZ §11.2).** Each image is normalised by its own similarity
//! (x̂ = T·x). Each correspondence gives one row `[x̂₂x̂₁, x̂₂ŷ₁, x̂₂, ŷ₂x̂₁, ŷ₂ŷ₁, ŷ₂, x̂₁, ŷ₁, 1]`
//! (× √wᵢ), f̂ is the right singular vector of the smallest singular value ([`null_vector`]),
//! rank 2 is enforced by zeroing the smallest singular value of F̂ (SVD), and F = T₂ᵀ·F̂·T₁,
//! scaled to ‖f‖ = 1 with `f[8]` > 0 ([`unit_norm_sign`]).
//!
//! **Residual.** The Sampson distance, pixels:
//! e = x₂ᵀFx₁ / √((Fx₁)₁² + (Fx₁)₂² + (Fᵀx₂)₁² + (Fᵀx₂)₂²), the first-order distance of the
//! 4-vector (x₁, x₂) to the variety x₂ᵀFx₁ = 0; with noise σ per coordinate its RMS is ≈ σ.
//!
//! **Refinement.** Levenberg–Marquardt on Σ e² with rank 2 kept by the parameterisation
//! F̂ = U·diag(1, s, 0)·Vᵀ (Bartoli & Sturm's orthonormal representation): a step rotates U and V
//! by small rotations (3 + 3 parameters) and moves s (1): 7 parameters for F's 7 degrees of
//! freedom. The Sampson error is computed exactly in pixels from normalised coordinates (the
//! numerator is invariant, the gradient terms scale by k₂ and k₁). A step is kept only if it
//! lowers the cost, so the result is never worse than the 8-point estimate.
//!
//! **Degenerate.** Fewer than 8 correspondences, coincident points, or an 8-point system whose
//! second-smallest singular value is below 10⁻⁶ of the largest: F is then not unique, which is
//! the case of a planar scene, a pure rotation, or a pure image translation x₂ = x₁ + t (all
//! consistent with a homography, which GRIC then prefers).

use super::homography::NULLITY;
use super::linalg::{
    Mat3, mat3_mul, mat3_transpose, mat3_vec, null_vector, rodrigues, svd, unit_norm_sign,
};
use super::lm::{LeastSquares, minimise};
use super::normalise::TwoView;
use super::robust::Estimator;
use super::{GeometryError, Model};

/// Levenberg–Marquardt evaluations of the refinement.
const REFINE_EVALUATIONS: usize = 8;

/// Sampson distance of a correspondence `[x1, y1, x2, y2]` to `f` (row-major, any scale),
/// caller's units; INFINITY where the gradient vanishes (the point at both epipoles).
pub fn sampson_distance(f: &Mat3, p: &[f64; 4]) -> f64 {
    let x1 = [p[0], p[1], 1.0];
    let x2 = [p[2], p[3], 1.0];
    let a = mat3_vec(f, x1);
    let b = mat3_vec(&mat3_transpose(f), x2);
    let num = x2[0] * a[0] + x2[1] * a[1] + x2[2] * a[2];
    let den = (a[0] * a[0] + a[1] * a[1] + b[0] * b[0] + b[1] * b[1]).sqrt();
    if !(den > 0.0) {
        return f64::INFINITY;
    }
    (num / den).abs()
}

/// The rank-2 matrix closest to `m` in Frobenius norm, as (U, s₁, s₂, V) with
/// m ≈ U·diag(s₁, s₂, 0)·Vᵀ.
fn rank2(m: &Mat3) -> (Mat3, f64, f64, Mat3) {
    let d = svd(m, 3, 3);
    let mut u = [0.0; 9];
    let mut v = [0.0; 9];
    u.copy_from_slice(&d.u);
    v.copy_from_slice(&d.v);
    // U may have a zero third column when m is already rank 2: complete it (u₃ = u₁ × u₂).
    let c = |m: &Mat3, j: usize| [m[j], m[3 + j], m[6 + j]];
    let (u1, u2) = (c(&u, 0), c(&u, 1));
    let u3 = [
        u1[1] * u2[2] - u1[2] * u2[1],
        u1[2] * u2[0] - u1[0] * u2[2],
        u1[0] * u2[1] - u1[1] * u2[0],
    ];
    for i in 0..3 {
        u[i * 3 + 2] = u3[i];
    }
    (u, d.s[0], d.s[1], v)
}

/// U·diag(s₁, s₂, 0)·Vᵀ.
fn compose(u: &Mat3, s1: f64, s2: f64, v: &Mat3) -> Mat3 {
    let mut f = [0.0; 9];
    for i in 0..3 {
        for j in 0..3 {
            f[i * 3 + j] = s1 * u[i * 3] * v[j * 3] + s2 * u[i * 3 + 1] * v[j * 3 + 1];
        }
    }
    f
}

/// F = T₂ᵀ·F̂·T₁.
fn denormalise(tv: &TwoView, fhat: &Mat3) -> Mat3 {
    mat3_mul(
        &mat3_mul(&mat3_transpose(&tv.t2.matrix()), fhat),
        &tv.t1.matrix(),
    )
}

/// F̂ = T₂⁻ᵀ·F·T₁⁻¹.
fn normalise_f(tv: &TwoView, f: &Mat3) -> Mat3 {
    mat3_mul(
        &mat3_mul(&mat3_transpose(&tv.t2.inverse_matrix()), f),
        &tv.t1.inverse_matrix(),
    )
}

/// Fundamental matrix: normalised 8-point, rank 2, then Levenberg–Marquardt on the Sampson
/// error. Points `[x1, y1, x2, y2]`, params F (row-major, ‖f‖ = 1, `f[8]` ≥ 0).
pub struct FundamentalEstimator;

impl Estimator for FundamentalEstimator {
    type Point = [f64; 4];
    type Params = Mat3;

    fn min_points(&self) -> usize {
        8
    }

    fn samples(&self) -> usize {
        10
    }

    fn fit(&self, points: &[[f64; 4]], weights: &[f64]) -> Result<Mat3, GeometryError> {
        let tv = TwoView::new(points, weights)?;
        let mut rows: Vec<[f64; 9]> = Vec::with_capacity(points.len());
        for ((a, b), &w) in tv.q1.iter().zip(&tv.q2).zip(weights) {
            if w <= 0.0 {
                continue;
            }
            let s = w.sqrt();
            let (x1, y1, x2, y2) = (a[0], a[1], b[0], b[1]);
            rows.push([x2 * x1, x2 * y1, x2, y2 * x1, y2 * y1, y2, x1, y1, 1.0].map(|v| s * v));
        }
        if rows.len() < 8 {
            return Err(GeometryError::TooFewCorrespondences {
                n: rows.len(),
                min: 8,
            });
        }
        let (f, sv) = null_vector(&rows).ok_or(GeometryError::FewerCorrespondences { min: 8 })?;
        if !(sv[7] > NULLITY * sv[0]) {
            return Err(GeometryError::FundamentalUndetermined);
        }
        let (u, s1, s2, v) = rank2(&f);
        unit_norm_sign(&denormalise(&tv, &compose(&u, s1, s2, &v)))
            .ok_or(GeometryError::NoFundamental)
    }

    fn refine(&self, f: Mat3, points: &[[f64; 4]], weights: &[f64]) -> Mat3 {
        let Ok(tv) = TwoView::new(points, weights) else {
            return f;
        };
        let (u, s1, s2, v) = rank2(&normalise_f(&tv, &f));
        if !(s1 > 0.0) {
            return f;
        }
        let problem = SampsonProblem { tv: &tv, weights };
        let start = FState { u, v, s: s2 / s1 };
        let Some(best) = minimise(&problem, start, REFINE_EVALUATIONS).filter(|m| m.improved)
        else {
            return f;
        };
        let best = best.state;
        unit_norm_sign(&denormalise(&tv, &compose(&best.u, 1.0, best.s, &best.v))).unwrap_or(f)
    }

    fn residual(&self, f: &Mat3, p: &[f64; 4]) -> f64 {
        sampson_distance(f, p)
    }
}

/// F̂ = U·diag(1, s, 0)·Vᵀ.
#[derive(Debug, Clone)]
struct FState {
    u: Mat3,
    v: Mat3,
    s: f64,
}

/// Σ w e², e the Sampson distance in pixels, over normalised coordinates.
struct SampsonProblem<'a> {
    tv: &'a TwoView,
    weights: &'a [f64],
}

impl SampsonProblem<'_> {
    /// The Sampson residual of point i (pixels) and, when asked, its gradient over the 9
    /// entries of F̂.
    fn point(&self, f: &Mat3, i: usize, grad: Option<&mut [f64; 9]>) -> Option<f64> {
        let (q1, q2) = (self.tv.q1[i], self.tv.q2[i]);
        let (k1, k2) = (self.tv.t1.k, self.tv.t2.k);
        let x1 = [q1[0], q1[1], 1.0];
        let x2 = [q2[0], q2[1], 1.0];
        let a = mat3_vec(f, x1);
        let b = mat3_vec(&mat3_transpose(f), x2);
        let num = x2[0] * a[0] + x2[1] * a[1] + x2[2] * a[2];
        let den = k2 * k2 * (a[0] * a[0] + a[1] * a[1]) + k1 * k1 * (b[0] * b[0] + b[1] * b[1]);
        if !(den > 0.0) {
            return None;
        }
        let sd = den.sqrt();
        let e = num / sd;
        if let Some(g) = grad {
            for j in 0..3 {
                for k in 0..3 {
                    let dnum = x2[j] * x1[k];
                    let mut dden = 0.0;
                    if j < 2 {
                        dden += 2.0 * k2 * k2 * a[j] * x1[k];
                    }
                    if k < 2 {
                        dden += 2.0 * k1 * k1 * b[k] * x2[j];
                    }
                    g[j * 3 + k] = (dnum - 0.5 * e / sd * dden) / sd;
                }
            }
        }
        e.is_finite().then_some(e)
    }

    /// ∂F̂/∂p for the 7 parameters: rotations of U (3), of V (3), and s.
    fn tangents(st: &FState) -> [Mat3; 7] {
        let sigma = [1.0, 0.0, 0.0, 0.0, st.s, 0.0, 0.0, 0.0, 0.0];
        let vt = mat3_transpose(&st.v);
        let skew = |i: usize| -> Mat3 {
            match i {
                0 => [0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0],
                1 => [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0],
                _ => [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            }
        };
        let mut out = [[0.0; 9]; 7];
        for i in 0..3 {
            let e = skew(i);
            out[i] = mat3_mul(&mat3_mul(&mat3_mul(&st.u, &e), &sigma), &vt);
            out[3 + i] = mat3_mul(&mat3_mul(&mat3_mul(&st.u, &sigma), &e), &vt).map(|v| -v);
        }
        out[6] = compose(&st.u, 0.0, 1.0, &st.v);
        out
    }
}

impl LeastSquares for SampsonProblem<'_> {
    type State = FState;
    fn n_params(&self) -> usize {
        7
    }
    fn normal_equations(&self, st: &FState) -> Option<(f64, Vec<f64>, Vec<f64>)> {
        let f = compose(&st.u, 1.0, st.s, &st.v);
        let tangents = Self::tangents(st);
        let (mut a, mut g, mut cost) = (vec![0.0; 49], vec![0.0; 7], 0.0);
        let mut grad = [0.0; 9];
        for (i, &w) in self.weights.iter().enumerate() {
            if w <= 0.0 {
                continue;
            }
            let e = self.point(&f, i, Some(&mut grad))?;
            let j: [f64; 7] = tangents.map(|t| t.iter().zip(&grad).map(|(x, y)| x * y).sum());
            cost += w * e * e;
            for p in 0..7 {
                g[p] += w * j[p] * e;
                for q in 0..7 {
                    a[p * 7 + q] += w * j[p] * j[q];
                }
            }
        }
        Some((cost, a, g))
    }
    fn step(&self, st: &FState, d: &[f64]) -> Option<FState> {
        let u = mat3_mul(&st.u, &rodrigues([d[0], d[1], d[2]]));
        let v = mat3_mul(&st.v, &rodrigues([d[3], d[4], d[5]]));
        let s = st.s + d[6];
        s.is_finite().then_some(FState { u, v, s })
    }
}

/// The wire model.
pub fn fundamental_model(f: &Mat3) -> Model {
    Model::Fundamental { f: *f }
}

#[cfg(test)]
pub(super) mod tests {
    use super::super::homography::tests::planar_scene;
    use super::super::linalg::{IDENTITY3, mat3_inverse};
    use super::super::testutil::{
        Camera, Rng, assert_sane, corr_row, intrinsics, is_degenerate, mul, rms_on, rotation, view,
    };
    use super::super::{Model, fit_type};
    use super::*;

    /// F = K⁻ᵀ·[t]×·R·K⁻¹ for P₁ = K[I|0], P₂ = K[R|t].
    pub fn true_f(k: &Mat3, r: &Mat3, t: [f64; 3]) -> Mat3 {
        let tx = [0.0, -t[2], t[1], t[2], 0.0, -t[0], -t[1], t[0], 0.0];
        let kinv = mat3_inverse(k).unwrap();
        mul(&mul(&mat3_transpose(&kinv), &mul(&tx, r)), &kinv)
    }

    /// A rigid 3-D scene (points at depth 4–10 in front of camera 1) seen by P₁ = K[I|0] and
    /// P₂ = K[R|t]; `n` visible correspondences, noise σ per coordinate in each image, then
    /// `outliers` random correspondences. Returns (rows, true F).
    pub fn rigid_scene(
        rng: &mut Rng,
        n: usize,
        sigma: f64,
        outliers: usize,
        r: [f64; 3],
        t: [f64; 3],
    ) -> (Vec<Vec<f64>>, Mat3) {
        let k = intrinsics(600.0);
        let cam1 = Camera {
            k,
            r: IDENTITY3,
            t: [0.0; 3],
        };
        let cam2 = Camera {
            k,
            r: rotation(r),
            t,
        };
        let mut rows = Vec::new();
        while rows.len() < n {
            let z = rng.range(4.0, 10.0);
            let x = [rng.range(-0.55, 0.55) * z, rng.range(-0.4, 0.4) * z, z];
            let (Some(p1), Some(p2)) = (cam1.project(x), cam2.project(x)) else {
                continue;
            };
            if (0.0..640.0).contains(&p2[0]) && (0.0..480.0).contains(&p2[1]) {
                rows.push(corr_row(rng, p1, p2, sigma, sigma));
            }
        }
        for _ in 0..outliers {
            let p1 = [rng.range(0.0, 640.0), rng.range(0.0, 480.0)];
            let p2 = [rng.range(0.0, 640.0), rng.range(0.0, 480.0)];
            rows.push(corr_row(rng, p1, p2, 0.0, 0.0));
        }
        (rows, true_f(&k, &rotation(r), t))
    }

    pub const MOTION_R: [f64; 3] = [0.05, -0.12, 0.04];
    pub const MOTION_T: [f64; 3] = [-1.0, 0.15, 0.3];

    fn f_of(m: &Model) -> Mat3 {
        match m {
            Model::Fundamental { f } => *f,
            m => panic!("{m:?}"),
        }
    }

    /// |cos| of the angle between two matrices as 9-vectors.
    fn alignment(a: &Mat3, b: &Mat3) -> f64 {
        let dot: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
        let na: f64 = a.iter().map(|x| x * x).sum::<f64>().sqrt();
        let nb: f64 = b.iter().map(|x| x * x).sum::<f64>().sqrt();
        (dot / (na * nb)).abs()
    }

    fn rank_ratio(f: &Mat3) -> f64 {
        let d = svd(f, 3, 3);
        d.s[2] / d.s[0]
    }

    #[test]
    fn noise_free_two_views_give_the_true_f() {
        let mut rng = Rng::new(1);
        let (rows, truth) = rigid_scene(&mut rng, 100, 0.0, 0, MOTION_R, MOTION_T);
        let fit = fit_type("fundamental", &view(&rows)).unwrap();
        assert_sane(&fit, rows.len());
        let f = f_of(&fit.model);
        assert!(fit.rms < 1e-6, "Sampson RMS {}", fit.rms);
        assert!(fit.inliers.iter().all(|&v| v));
        assert!(rank_ratio(&f) < 1e-9, "rank ratio {}", rank_ratio(&f));
        assert!((1.0 - alignment(&f, &truth)) < 1e-9);
        let norm: f64 = f.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!((norm - 1.0).abs() < 1e-12 && f[8] >= 0.0);
    }

    #[test]
    fn one_pixel_noise() {
        for seed in 0..5 {
            let mut rng = Rng::new(10 + seed);
            let (rows, truth) = rigid_scene(&mut rng, 200, 1.0, 0, MOTION_R, MOTION_T);
            let fit = fit_type("fundamental", &view(&rows)).unwrap();
            assert_sane(&fit, rows.len());
            let f = f_of(&fit.model);
            let rms = rms_on(&fit.model, &rows, &vec![true; rows.len()]);
            assert!(rms <= 1.5, "seed {seed}: Sampson RMS {rms}");
            assert!(rank_ratio(&f) < 1e-9);
            // The true F explains the data about as well.
            let truth_rms = rms_on(
                &Model::Fundamental { f: truth },
                &rows,
                &vec![true; rows.len()],
            );
            assert!(
                rms <= truth_rms * 1.01,
                "seed {seed}: {rms} vs truth {truth_rms}"
            );
            assert!((fit.sigma - 1.0).abs() < 0.25, "σ {}", fit.sigma);
        }
    }

    #[test]
    fn refinement_lowers_the_sampson_error() {
        let mut rng = Rng::new(20);
        let (rows, _) = rigid_scene(&mut rng, 60, 1.0, 0, MOTION_R, MOTION_T);
        let pts: Vec<[f64; 4]> = rows.iter().map(|r| [r[0], r[1], r[2], r[3]]).collect();
        let w = vec![1.0; pts.len()];
        let est = FundamentalEstimator;
        let f0 = est.fit(&pts, &w).unwrap();
        let f1 = est.refine(f0, &pts, &w);
        let cost = |f: &Mat3| {
            pts.iter()
                .map(|p| sampson_distance(f, p).powi(2))
                .sum::<f64>()
        };
        assert!(cost(&f1) < cost(&f0), "{} vs {}", cost(&f1), cost(&f0));
        assert!(rank_ratio(&f1) < 1e-9);
    }

    #[test]
    fn sampson_gradient_matches_finite_differences() {
        let mut rng = Rng::new(21);
        let (rows, _) = rigid_scene(&mut rng, 8, 1.0, 0, MOTION_R, MOTION_T);
        let pts: Vec<[f64; 4]> = rows.iter().map(|r| [r[0], r[1], r[2], r[3]]).collect();
        let w = vec![1.0; pts.len()];
        let tv = TwoView::new(&pts, &w).unwrap();
        let problem = SampsonProblem {
            tv: &tv,
            weights: &w,
        };
        let f = [0.1, -0.3, 0.2, 0.4, 0.05, -0.6, -0.2, 0.5, 0.1];
        let mut g = [0.0; 9];
        for i in 0..pts.len() {
            problem.point(&f, i, Some(&mut g)).unwrap();
            for k in 0..9 {
                let h = 1e-7;
                let (mut fp, mut fm) = (f, f);
                fp[k] += h;
                fm[k] -= h;
                let fd = (problem.point(&fp, i, None).unwrap()
                    - problem.point(&fm, i, None).unwrap())
                    / (2.0 * h);
                assert!(
                    (fd - g[k]).abs() < 1e-5 * (1.0 + fd.abs()),
                    "f{k}: {fd} vs {}",
                    g[k]
                );
            }
        }
        // And the Sampson distance in normalised coordinates is the pixel one.
        let fpx = denormalise(&tv, &f);
        for (i, p) in pts.iter().enumerate() {
            let a = problem.point(&f, i, None).unwrap().abs();
            let b = sampson_distance(&fpx, p);
            assert!((a - b).abs() < 1e-9 * (1.0 + b), "{a} vs {b}");
        }
    }

    #[test]
    fn ten_percent_outliers() {
        for seed in 0..10 {
            let mut rng = Rng::new(30 + seed);
            let (rows, truth) = rigid_scene(&mut rng, 180, 1.0, 20, MOTION_R, MOTION_T);
            let fit = fit_type("fundamental", &view(&rows)).unwrap();
            assert_sane(&fit, rows.len());
            let mask: Vec<bool> = (0..rows.len()).map(|i| i < 180).collect();
            let rms = rms_on(&fit.model, &rows, &mask);
            let clean = fit_type("fundamental", &view(&rows[..180])).unwrap();
            let clean_rms = rms_on(&clean.model, &rows, &mask);
            assert!(
                rms <= 1.5 && rms <= 1.05 * clean_rms,
                "seed {seed}: RMS on the true inliers {rms} (clean {clean_rms})"
            );
            // An epipolar constraint is 1-D: a random correspondence lies within 3σ of its
            // epipolar line with probability ~1.5 %, and then no F can reject it. So: at most
            // one far outlier (> 10 px from the true F) accepted per group of 20.
            let accepted = rows
                .iter()
                .enumerate()
                .skip(180)
                .filter(|(i, row)| {
                    fit.inliers[*i]
                        && sampson_distance(&truth, &[row[0], row[1], row[2], row[3]]) > 10.0
                })
                .count();
            assert!(
                accepted <= 1,
                "seed {seed}: {accepted} far outliers accepted"
            );
            let kept = fit.inliers[..180].iter().filter(|&&v| v).count();
            assert!(kept >= 174, "seed {seed}: {kept}");
        }
    }

    #[test]
    fn pure_camera_translation_gives_a_skew_symmetric_f() {
        // The camera translates (no rotation): F = K⁻ᵀ[t]×K⁻¹ is still unique.
        let mut rng = Rng::new(40);
        let (rows, truth) = rigid_scene(&mut rng, 100, 0.0, 0, [0.0; 3], [-0.8, 0.2, 0.3]);
        let fit = fit_type("fundamental", &view(&rows)).unwrap();
        assert_sane(&fit, rows.len());
        let f = f_of(&fit.model);
        assert!((1.0 - alignment(&f, &truth)) < 1e-9);
        assert!(fit.rms < 1e-6);
    }

    #[test]
    fn degenerate_fundamentals() {
        let mut rng = Rng::new(50);
        // Fewer than 8.
        let (seven, _) = rigid_scene(&mut rng, 7, 0.0, 0, MOTION_R, MOTION_T);
        // Pure image translation x₂ = x₁ + t.
        let shift: Vec<Vec<f64>> = (0..50)
            .map(|_| {
                let p = [rng.range(0.0, 640.0), rng.range(0.0, 480.0)];
                vec![p[0], p[1], p[0] + 15.0, p[1] - 7.0]
            })
            .collect();
        // A plane.
        let (plane, _) = planar_scene(&mut rng, 50, 0.0, 0.0, 0);
        let same = vec![vec![1.0, 2.0, 3.0, 4.0]; 20];
        for (name, rows) in [
            ("seven", &seven),
            ("translation", &shift),
            ("plane", &plane),
            ("same", &same),
        ] {
            let fit = fit_type("fundamental", &view(rows)).unwrap();
            assert!(is_degenerate(&fit), "{name}: {fit:?}");
            assert_sane(&fit, rows.len());
        }
    }
}
