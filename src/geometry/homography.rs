//! Homographies and affine maps between two images.
//!
//! **Homography, normalised DLT (HZ §4.1, §4.4).** Each image is normalised by its own
//! similarity (x̂ = T·x: centroid to the origin, mean distance √2). Each correspondence gives
//! two rows of Â·ĥ = 0 (w₂ = 1):
//! `[0ᵀ, −x̂₁ᵀ, ŷ₂x̂₁ᵀ]` and `[x̂₁ᵀ, 0ᵀ, −x̂₂x̂₁ᵀ]`, scaled by √wᵢ for weighted fits; ĥ is the right
//! singular vector of the smallest singular value, taken as the eigenvector of ÂᵀÂ's smallest
//! eigenvalue ([`null_vector`]). Then H = T₂⁻¹·Ĥ·T₁.
//!
//! **Four correspondences** (the minimal samples of the robust fit) determine H exactly, and it
//! is solved directly (HZ §2.3, the projective basis): A maps e₁, e₂, e₃ and (1, 1, 1) onto the
//! four normalised points of image 1, B onto those of image 2, and Ĥ = B·A⁻¹. The columns of A
//! are λᵢ·(x̂ᵢ, ŷᵢ, 1) with λ solving Σᵢ₌₁³ λᵢ·x̂ᵢ = x̂₄. By Cramer's rule λᵢ = Dᵢ / D, with D
//! twice the area of the triangle of points 1 to 3 and Dᵢ that of the triangle with point 4 in
//! place of point i: where three of the four points lie on a line, one of these areas vanishes
//! and no single H maps them. The sample is refused when any area is below 10⁻⁶ of the largest
//! (some λᵢ below 10⁻⁶ of the largest, or the largest above 10⁶). It is the DLT's answer, without
//! its eigen-decomposition.
//!
//! **Gauge.** H is returned with ‖h‖ = 1 (Frobenius) and `h[8]` > 0 (the first non-zero entry
//! positive if `h[8]` = 0), see [`unit_norm_sign`]. An affine map is returned as its 2 × 3 matrix
//! (`h[8]` = 1).
//!
//! **Residual.** The symmetric transfer distance, pixels:
//! e = √((d(x₂, H·x₁)² + d(x₁, H⁻¹·x₂)²) / 2). With independent noise σ in both images,
//! E(e²) ≈ 4σ² (each transfer sees the noise of both images), so the RMS of e is ≈ 2σ; with
//! noise in one image only it is ≈ √2·σ.
//!
//! **Refinement.** Levenberg–Marquardt on exactly that error (both transfers, in pixels), in
//! normalised coordinates: 8 free entries of Ĥ (the largest one held fixed, which fixes the
//! scale), analytic Jacobian; the inverse transfer uses ∂(H⁻¹)/∂h_jk = −H⁻¹·E_jk·H⁻¹.
//! The affine map refines its 6 entries the same way (last row held at (0, 0, 1)).
//!
//! **Degenerate.** Fewer than 4 correspondences (3 for affine), coincident or collinear points
//! in either image, or a DLT whose second-smallest singular value is below 10⁻⁶ of the largest
//! (the correspondences do not determine H), or a singular H.

use super::linalg::{Mat3, mat3_inverse, mat3_mul, mat3_vec, null_vector, solve, unit_norm_sign};
use super::lm::{LeastSquares, minimise};
use super::normalise::{TwoView, is_collinear};
use super::robust::Estimator;
use super::{GeometryError, Model};

/// Levenberg–Marquardt evaluations of the refinement.
const REFINE_EVALUATIONS: usize = 8;
/// Singular-value ratio below which a homogeneous system has more than one solution.
pub const NULLITY: f64 = 1e-6;

/// A homography (or an affine map, last row (0, 0, 1)) with its inverse, caller's units.
#[derive(Debug, Clone, PartialEq)]
pub struct Homography {
    pub h: Mat3,
    pub inv: Mat3,
}

impl Homography {
    /// `None` when `h` is singular or not finite. The test is the same at any image size: `h`
    /// is inverted as D·h·D⁻¹ with D = diag(1, 1, c), which has h's determinant, its
    /// translation column divided by c and its perspective row multiplied by c, for a power of
    /// two c that brings the translations to the size of the linear part. In pixels those
    /// entries grow with the image side and its perspective ones shrink, so without it a plane
    /// seen in a 4000-pixel image counted as singular where the same plane at 640 pixels did
    /// not. Scaling by powers of two is exact: the inverse is the same to the last bit.
    pub fn new(h: Mat3) -> Option<Self> {
        let translation = h[2].abs().max(h[5].abs());
        let linear = h[0].abs().max(h[1].abs()).max(h[3].abs()).max(h[4].abs());
        let c = if translation > 0.0 && linear > 0.0 && (translation / linear).is_finite() {
            (translation / linear).log2().round().exp2()
        } else {
            1.0
        };
        let b = mat3_inverse(&projective_scaled(&h, c))?;
        let inv = projective_scaled(&b, 1.0 / c);
        Some(Self { h, inv })
    }
}

/// D·h·D⁻¹ with D = diag(1, 1, c): the translation column divided by c, the perspective row
/// multiplied by c, the rest as it is (the map in units c times larger, up to scale).
fn projective_scaled(h: &Mat3, c: f64) -> Mat3 {
    [
        h[0],
        h[1],
        h[2] / c,
        h[3],
        h[4],
        h[5] / c,
        h[6] * c,
        h[7] * c,
        h[8],
    ]
}

/// The image of (x, y) under H, or `None` at infinity.
fn map(h: &Mat3, x: f64, y: f64) -> Option<[f64; 2]> {
    let u = mat3_vec(h, [x, y, 1.0]);
    let p = [u[0] / u[2], u[1] / u[2]];
    (p[0].is_finite() && p[1].is_finite()).then_some(p)
}

/// Symmetric transfer distance of a correspondence `[x1, y1, x2, y2]`, caller's units:
/// √((d(x₂, H·x₁)² + d(x₁, H⁻¹·x₂)²) / 2); INFINITY where a point maps to infinity.
pub fn transfer_distance(h: &Homography, p: &[f64; 4]) -> f64 {
    let (Some(f), Some(b)) = (map(&h.h, p[0], p[1]), map(&h.inv, p[2], p[3])) else {
        return f64::INFINITY;
    };
    let (fx, fy) = (f[0] - p[2], f[1] - p[3]);
    let (bx, by) = (b[0] - p[0], b[1] - p[1]);
    (0.5 * (fx * fx + fy * fy + bx * bx + by * by)).sqrt()
}

/// The Sampson distance of a correspondence to H (HZ §4.2.6): the first-order distance in ℝ⁴
/// of (x₁, x₂) to the graph of H, √(εᵀ(JJᵀ)⁻¹ε) with ε the two DLT residuals
/// (u₀ − x₂u₂, y₂u₂ − u₁), u = H·x₁, and J their Jacobian over (x₁, y₁, x₂, y₂). With noise σ per
/// coordinate its square is ≈ σ²·χ²(2). Used by model selection; INFINITY where undefined.
pub fn sampson_distance_h(h: &Mat3, p: &[f64; 4]) -> f64 {
    let (x2, y2) = (p[2], p[3]);
    let u = mat3_vec(h, [p[0], p[1], 1.0]);
    let e = [u[0] - x2 * u[2], y2 * u[2] - u[1]];
    let j = [
        [h[0] - x2 * h[6], h[1] - x2 * h[7], -u[2], 0.0],
        [y2 * h[6] - h[3], y2 * h[7] - h[4], 0.0, u[2]],
    ];
    let dot = |a: &[f64; 4], b: &[f64; 4]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let (a, b, c) = (dot(&j[0], &j[0]), dot(&j[0], &j[1]), dot(&j[1], &j[1]));
    let det = a * c - b * b;
    if !(det > 0.0) {
        return f64::INFINITY;
    }
    // εᵀ·[[a, b], [b, c]]⁻¹·ε
    let q = (c * e[0] * e[0] - 2.0 * b * e[0] * e[1] + a * e[1] * e[1]) / det;
    if q >= 0.0 { q.sqrt() } else { f64::INFINITY }
}

/// The homography of the wire model `h` (row-major, any scale).
pub fn from_wire(h: &[f64; 9]) -> Option<Homography> {
    Homography::new(*h)
}

/// The affine map of the wire model `a` (2 × 3, row-major).
pub fn affine_from_wire(a: &[f64; 6]) -> Option<Homography> {
    Homography::new([a[0], a[1], a[2], a[3], a[4], a[5], 0.0, 0.0, 1.0])
}

/// Normalised two-view data with the collinearity checks of both images.
fn normalised(points: &[[f64; 4]], weights: &[f64]) -> Result<TwoView, GeometryError> {
    let tv = TwoView::new(points, weights)?;
    if is_collinear(&tv.q1, weights) {
        return Err(GeometryError::CollinearImage { image: 1 });
    }
    if is_collinear(&tv.q2, weights) {
        return Err(GeometryError::CollinearImage { image: 2 });
    }
    Ok(tv)
}

/// The homography that maps the four points `from` onto `to` exactly: B·A⁻¹ (module docs).
/// `None` where three of either four lie on a line.
fn four_point(from: &[[f64; 2]], to: &[[f64; 2]]) -> Option<Mat3> {
    let a = basis_map(from)?;
    let b = basis_map(to)?;
    Some(mat3_mul(&b, &mat3_inverse(&a)?))
}

/// The map of the projective basis e₁, e₂, e₃, (1, 1, 1) onto four points: columns
/// λᵢ·(xᵢ, yᵢ, 1), with λ solving Σᵢ₌₁³ λᵢ·(xᵢ, yᵢ, 1) = (x₄, y₄, 1).
fn basis_map(q: &[[f64; 2]]) -> Option<Mat3> {
    let m = [
        q[0][0], q[1][0], q[2][0], q[0][1], q[1][1], q[2][1], 1.0, 1.0, 1.0,
    ];
    let lambda = mat3_vec(&mat3_inverse(&m)?, [q[3][0], q[3][1], 1.0]);
    let largest = lambda.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    // λᵢ = Dᵢ / D: a vanishing Dᵢ, or a vanishing D (points 1 to 3 on a line).
    if lambda.iter().any(|v| !(v.abs() > NULLITY * largest)) || !(largest < 1.0 / NULLITY) {
        return None;
    }
    Some(std::array::from_fn(|i| m[i] * lambda[i % 3]))
}

/// H = T₂⁻¹·Ĥ·T₁.
fn denormalise(tv: &TwoView, hn: &Mat3) -> Mat3 {
    mat3_mul(&mat3_mul(&tv.t2.inverse_matrix(), hn), &tv.t1.matrix())
}

/// Ĥ = T₂·H·T₁⁻¹.
fn normalise_h(tv: &TwoView, h: &Mat3) -> Mat3 {
    mat3_mul(&mat3_mul(&tv.t2.matrix(), h), &tv.t1.inverse_matrix())
}

/// Homography: normalised DLT, then Levenberg–Marquardt on the symmetric transfer error.
/// Points `[x1, y1, x2, y2]`.
pub struct HomographyEstimator;

impl Estimator for HomographyEstimator {
    type Point = [f64; 4];
    type Params = Homography;

    fn min_points(&self) -> usize {
        4
    }

    fn samples(&self) -> usize {
        6
    }

    fn fit(&self, points: &[[f64; 4]], weights: &[f64]) -> Result<Homography, GeometryError> {
        let tv = normalised(points, weights)?;
        if points.len() == 4 && weights.iter().all(|&w| w > 0.0) {
            let hn = four_point(&tv.q1, &tv.q2).ok_or(GeometryError::HomographyUndetermined)?;
            let h = unit_norm_sign(&denormalise(&tv, &hn)).ok_or(GeometryError::NoHomography)?;
            return Homography::new(h).ok_or(GeometryError::SingularHomography);
        }
        let mut rows: Vec<[f64; 9]> = Vec::with_capacity(2 * points.len());
        for ((a, b), &w) in tv.q1.iter().zip(&tv.q2).zip(weights) {
            if w <= 0.0 {
                continue;
            }
            let s = w.sqrt();
            let (x, y, u, v) = (s * a[0], s * a[1], b[0], b[1]);
            rows.push([0.0, 0.0, 0.0, -x, -y, -s, v * x, v * y, v * s]);
            rows.push([x, y, s, 0.0, 0.0, 0.0, -u * x, -u * y, -u * s]);
        }
        let (hn, sv) = null_vector(&rows).ok_or(GeometryError::FewerCorrespondences { min: 4 })?;
        if !(sv[7] > NULLITY * sv[0]) {
            return Err(GeometryError::HomographyUndetermined);
        }
        let h = unit_norm_sign(&denormalise(&tv, &hn)).ok_or(GeometryError::NoHomography)?;
        Homography::new(h).ok_or(GeometryError::SingularHomography)
    }

    fn refine(&self, h: Homography, points: &[[f64; 4]], weights: &[f64]) -> Homography {
        refine_transfer(h, points, weights, false)
    }

    fn residual(&self, h: &Homography, p: &[f64; 4]) -> f64 {
        transfer_distance(h, p)
    }
}

/// Affine map x₂ = A·[x₁; 1]: least squares on the forward error, then Levenberg–Marquardt on
/// the symmetric transfer error. Points `[x1, y1, x2, y2]`.
pub struct AffineEstimator;

impl Estimator for AffineEstimator {
    type Point = [f64; 4];
    type Params = Homography;

    fn min_points(&self) -> usize {
        3
    }

    fn samples(&self) -> usize {
        6
    }

    fn fit(&self, points: &[[f64; 4]], weights: &[f64]) -> Result<Homography, GeometryError> {
        let tv = TwoView::new(points, weights)?;
        if is_collinear(&tv.q1, weights) {
            return Err(GeometryError::CollinearImage { image: 1 });
        }
        let (mut n, mut rx, mut ry) = ([0.0; 9], [0.0; 3], [0.0; 3]);
        for ((a, b), &w) in tv.q1.iter().zip(&tv.q2).zip(weights) {
            if w <= 0.0 {
                continue;
            }
            let d = [a[0], a[1], 1.0];
            for i in 0..3 {
                rx[i] += w * d[i] * b[0];
                ry[i] += w * d[i] * b[1];
                for j in 0..3 {
                    n[i * 3 + j] += w * d[i] * d[j];
                }
            }
        }
        let ax = solve(&n, &rx, 3).ok_or(GeometryError::CollinearImage { image: 1 })?;
        let ay = solve(&n, &ry, 3).ok_or(GeometryError::CollinearImage { image: 1 })?;
        let hn = [ax[0], ax[1], ax[2], ay[0], ay[1], ay[2], 0.0, 0.0, 1.0];
        Homography::new(denormalise(&tv, &hn)).ok_or(GeometryError::SingularAffine)
    }

    fn refine(&self, h: Homography, points: &[[f64; 4]], weights: &[f64]) -> Homography {
        refine_transfer(h, points, weights, true)
    }

    fn residual(&self, h: &Homography, p: &[f64; 4]) -> f64 {
        transfer_distance(h, p)
    }
}

/// Levenberg–Marquardt on the symmetric transfer error of the points of positive weight.
/// Keeps `h` when the refinement cannot start (e.g. too few points).
fn refine_transfer(
    h: Homography,
    points: &[[f64; 4]],
    weights: &[f64],
    affine: bool,
) -> Homography {
    let Ok(tv) = TwoView::new(points, weights) else {
        return h;
    };
    let mut hn = normalise_h(&tv, &h.h);
    let free: Vec<usize> = if affine {
        // Exactly affine: last row (0, 0, 1).
        let s = hn[8];
        if s == 0.0 {
            return h;
        }
        hn = hn.map(|v| v / s);
        hn[6] = 0.0;
        hn[7] = 0.0;
        hn[8] = 1.0;
        (0..6).collect()
    } else {
        let fixed = (0..9)
            .max_by(|&i, &j| hn[i].abs().total_cmp(&hn[j].abs()))
            .unwrap_or(8);
        (0..9).filter(|&i| i != fixed).collect()
    };
    let problem = TransferProblem {
        tv: &tv,
        weights,
        free,
    };
    let Some(best) = minimise(&problem, hn, REFINE_EVALUATIONS).filter(|m| m.improved) else {
        return h;
    };
    let out = denormalise(&tv, &best.state);
    let out = if affine {
        let s = out[8];
        Some(out.map(|v| v / s))
    } else {
        unit_norm_sign(&out)
    };
    out.and_then(Homography::new).unwrap_or(h)
}

/// Σ w (d(x₂, H·x₁)² + d(x₁, H⁻¹·x₂)²) / 2 in pixels, over normalised coordinates.
struct TransferProblem<'a> {
    tv: &'a TwoView,
    weights: &'a [f64],
    /// Entries of Ĥ that move.
    free: Vec<usize>,
}

impl TransferProblem<'_> {
    /// Residuals (4, pixels, already ÷ √2) and, when asked, their gradients over the 9 entries.
    fn point(
        &self,
        hn: &Mat3,
        g: &Mat3,
        i: usize,
        jac: Option<&mut [[f64; 9]; 4]>,
    ) -> Option<[f64; 4]> {
        let (q1, q2) = (self.tv.q1[i], self.tv.q2[i]);
        let (k1, k2) = (self.tv.t1.k, self.tv.t2.k);
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let x1 = [q1[0], q1[1], 1.0];
        let x2 = [q2[0], q2[1], 1.0];
        let u = mat3_vec(hn, x1);
        let y = mat3_vec(g, x2);
        if u[2] == 0.0 || y[2] == 0.0 {
            return None;
        }
        let (f2, b2) = (s / k2, s / k1);
        let r = [
            f2 * (u[0] / u[2] - q2[0]),
            f2 * (u[1] / u[2] - q2[1]),
            b2 * (y[0] / y[2] - q1[0]),
            b2 * (y[1] / y[2] - q1[1]),
        ];
        if let Some(j) = jac {
            *j = [[0.0; 9]; 4];
            let iu = 1.0 / u[2];
            for k in 0..3 {
                j[0][k] = f2 * x1[k] * iu;
                j[0][6 + k] = -f2 * u[0] * iu * iu * x1[k];
                j[1][3 + k] = f2 * x1[k] * iu;
                j[1][6 + k] = -f2 * u[1] * iu * iu * x1[k];
            }
            // ∂y/∂h_jk = −G[:, j]·y_k.
            let iy = 1.0 / y[2];
            for jj in 0..3 {
                let c0 = g[jj] * iy - y[0] * g[6 + jj] * iy * iy;
                let c1 = g[3 + jj] * iy - y[1] * g[6 + jj] * iy * iy;
                for k in 0..3 {
                    j[2][jj * 3 + k] = -b2 * c0 * y[k];
                    j[3][jj * 3 + k] = -b2 * c1 * y[k];
                }
            }
        }
        r.iter().all(|v| v.is_finite()).then_some(r)
    }
}

impl LeastSquares for TransferProblem<'_> {
    type State = Mat3;
    fn n_params(&self) -> usize {
        self.free.len()
    }
    fn normal_equations(&self, hn: &Mat3) -> Option<(f64, Vec<f64>, Vec<f64>)> {
        let g = mat3_inverse(hn)?;
        // Accumulate over all 9 entries (upper triangle), then keep the free ones.
        let (mut a9, mut g9, mut cost) = ([[0.0; 9]; 9], [0.0; 9], 0.0);
        let mut jac = [[0.0; 9]; 4];
        for (i, &w) in self.weights.iter().enumerate() {
            if w <= 0.0 {
                continue;
            }
            let r = self.point(hn, &g, i, Some(&mut jac))?;
            cost += w * (r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3]);
            let [j0, j1, j2, j3] = &jac;
            for a in 0..9 {
                g9[a] += w * (j0[a] * r[0] + j1[a] * r[1] + j2[a] * r[2] + j3[a] * r[3]);
                let (w0, w1, w2, w3) = (w * j0[a], w * j1[a], w * j2[a], w * j3[a]);
                for b in a..9 {
                    a9[a][b] += w0 * j0[b] + w1 * j1[b] + w2 * j2[b] + w3 * j3[b];
                }
            }
        }
        let p = self.free.len();
        let mut a = vec![0.0; p * p];
        for (r, &fi) in self.free.iter().enumerate() {
            for (c, &fj) in self.free.iter().enumerate() {
                let (lo, hi) = if fi <= fj { (fi, fj) } else { (fj, fi) };
                a[r * p + c] = a9[lo][hi];
            }
        }
        let grad = self.free.iter().map(|&f| g9[f]).collect();
        cost.is_finite().then_some((cost, a, grad))
    }
    fn step(&self, hn: &Mat3, d: &[f64]) -> Option<Mat3> {
        let mut n = *hn;
        for (&i, v) in self.free.iter().zip(d) {
            n[i] += v;
        }
        n.iter().all(|v| v.is_finite()).then_some(n)
    }
}

/// The homography's wire model.
pub fn homography_model(h: &Homography) -> Model {
    Model::Homography { h: h.h }
}

/// The affine map's wire model (2 × 3; H's last row is (0, 0, 1)).
pub fn affine_model(h: &Homography) -> Model {
    let s = h.h[8];
    Model::Affine {
        a: [
            h.h[0] / s,
            h.h[1] / s,
            h.h[2] / s,
            h.h[3] / s,
            h.h[4] / s,
            h.h[5] / s,
        ],
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::super::testutil::{
        Rng, assert_sane, corr_row, intrinsics, is_degenerate, mul, rms_on, rotation, view,
    };
    use super::super::{Model, fit_type};
    use super::*;

    /// The homography induced by the plane nᵀX = d (camera-1 frame) between P₁ = K[I|0] and
    /// P₂ = K[R|t]: H = K (R − t nᵀ/d) K⁻¹.
    fn plane_homography(k: &Mat3, r: &Mat3, t: [f64; 3], n: [f64; 3], d: f64) -> Mat3 {
        let mut m = *r;
        for i in 0..3 {
            for j in 0..3 {
                m[i * 3 + j] -= t[i] * n[j] / d;
            }
        }
        let kinv = mat3_inverse(k).unwrap();
        mul(&mul(k, &m), &kinv)
    }

    #[test]
    fn a_homography_is_invertible_at_any_image_size() {
        // A strongly foreshortening but invertible map in normalised units (it squashes y by
        // 1e-6; det ≈ 1e-6), carried into pixels of images 1 to 4096 units wide:
        // H_s = S·H·S⁻¹ with S = diag(s, s, 1).
        let h: Mat3 = [1.0, 0.0, 0.3, 0.0, 1e-6, 0.2, 0.05, 0.0, 1.0];
        let at = |s: f64| projective_scaled(&h, 1.0 / s);
        let inv1 = Homography::new(h).expect("invertible").inv;
        for s in [1.0, 640.0, 4000.0, 4096.0] {
            let hs = at(s);
            let g = Homography::new(hs)
                .unwrap_or_else(|| panic!("singular at {s}"))
                .inv;
            // The inverse carried back: S⁻¹·H_s⁻¹·S = H⁻¹.
            let back = projective_scaled(&g, s);
            for (a, b) in back.iter().zip(&inv1) {
                assert!(
                    (a - b).abs() <= 1e-9 * b.abs().max(1.0),
                    "{s}: {back:?} against {inv1:?}"
                );
            }
            // Where the plain test passes too, the inverse is the same to the last bit.
            if let Some(plain) = mat3_inverse(&hs) {
                assert_eq!(plain, g, "{s}");
            }
        }
        // Singular stays singular: a rank-2 map at any size.
        let rank2: Mat3 = [1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.1, 0.0, 1.0];
        for s in [1.0, 4096.0] {
            assert!(
                Homography::new(projective_scaled(&rank2, 1.0 / s)).is_none(),
                "{s}"
            );
        }
        // Before, the plain test failed it in pixels of a 4096-unit image.
        assert!(mat3_inverse(&at(4096.0)).is_none());
    }

    /// A plane seen by two cameras: `n` correspondences spread over the 640 × 480 image 1,
    /// noise σ1 / σ2 per coordinate, then `outliers` uniform random correspondences.
    /// Returns (rows, true H).
    pub fn planar_scene(
        rng: &mut Rng,
        n: usize,
        s1: f64,
        s2: f64,
        outliers: usize,
    ) -> (Vec<Vec<f64>>, Mat3) {
        let k = intrinsics(600.0);
        let r = rotation([0.05, -0.2, 0.03]);
        let t = [0.4, -0.05, 0.1];
        let (nrm, d) = ([0.1, -0.2, 0.97], 5.0);
        let h = plane_homography(&k, &r, t, nrm, d);
        let mut rows = Vec::new();
        while rows.len() < n {
            let p1 = [rng.range(0.0, 640.0), rng.range(0.0, 480.0)];
            let p2 = map(&h, p1[0], p1[1]).unwrap();
            if (0.0..640.0).contains(&p2[0]) && (0.0..480.0).contains(&p2[1]) {
                rows.push(corr_row(rng, p1, p2, s1, s2));
            }
        }
        for _ in 0..outliers {
            let p1 = [rng.range(0.0, 640.0), rng.range(0.0, 480.0)];
            let p2 = [rng.range(0.0, 640.0), rng.range(0.0, 480.0)];
            rows.push(corr_row(rng, p1, p2, 0.0, 0.0));
        }
        (rows, h)
    }

    fn h_of(m: &Model) -> Homography {
        match m {
            Model::Homography { h } => Homography::new(*h).unwrap(),
            Model::Affine { a } => affine_from_wire(a).unwrap(),
            m => panic!("{m:?}"),
        }
    }

    /// RMS transfer error of `h` against the noise-free truth `truth` over the image.
    fn error_against_truth(h: &Homography, truth: &Mat3) -> f64 {
        let mut ss = 0.0;
        let mut n = 0;
        for i in 0..16 {
            for j in 0..12 {
                let (x, y) = (20.0 + 40.0 * i as f64, 20.0 + 40.0 * j as f64);
                let want = map(truth, x, y).unwrap();
                let got = map(&h.h, x, y).unwrap();
                ss += (want[0] - got[0]).powi(2) + (want[1] - got[1]).powi(2);
                n += 1;
            }
        }
        (ss / n as f64).sqrt()
    }

    #[test]
    fn noise_free_plane_gives_exact_homography() {
        let mut rng = Rng::new(1);
        let (rows, truth) = planar_scene(&mut rng, 100, 0.0, 0.0, 0);
        let fit = fit_type("homography", &view(&rows)).unwrap();
        assert_sane(&fit, rows.len());
        assert!(fit.rms < 1e-6, "rms {}", fit.rms);
        assert!(fit.inliers.iter().all(|&v| v));
        let h = h_of(&fit.model);
        assert!(error_against_truth(&h, &truth) < 1e-6);
        let norm: f64 = h.h.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!((norm - 1.0).abs() < 1e-12 && h.h[8] > 0.0);
    }

    #[test]
    fn one_pixel_noise_in_image_two() {
        // σ = 1 px per coordinate in image 2: the symmetric transfer residual is ≈ √2 px RMS.
        let mut rng = Rng::new(2);
        let (rows, truth) = planar_scene(&mut rng, 200, 0.0, 1.0, 0);
        let fit = fit_type("homography", &view(&rows)).unwrap();
        assert_sane(&fit, rows.len());
        let all = vec![true; rows.len()];
        let rms = rms_on(&fit.model, &rows, &all);
        assert!(rms <= 1.5, "rms on the true inliers {rms}");
        assert!(error_against_truth(&h_of(&fit.model), &truth) < 0.5);
    }

    #[test]
    fn one_pixel_noise_in_both_images() {
        // σ = 1 px per coordinate in each image: the residual is ≈ 2 px RMS (see the module
        // docs), the estimate itself is within a fraction of a pixel of the truth.
        let mut rng = Rng::new(3);
        let (rows, truth) = planar_scene(&mut rng, 200, 1.0, 1.0, 0);
        let fit = fit_type("homography", &view(&rows)).unwrap();
        let rms = rms_on(&fit.model, &rows, &vec![true; rows.len()]);
        assert!(rms <= 2.0 * 1.1, "rms {rms}");
        assert!(error_against_truth(&h_of(&fit.model), &truth) < 0.5);
        assert!(fit.inliers.iter().filter(|&&v| v).count() >= 195);
    }

    #[test]
    fn ten_percent_outliers_in_a_plane() {
        for seed in 0..10 {
            let mut rng = Rng::new(40 + seed);
            let (rows, truth) = planar_scene(&mut rng, 180, 0.0, 1.0, 20);
            let fit = fit_type("homography", &view(&rows)).unwrap();
            assert_sane(&fit, rows.len());
            // As good as the fit without the outliers (the noisy-data tolerance), and within a
            // pixel of the truth over the whole image (extrapolated corners included).
            let h = h_of(&fit.model);
            let clean = fit_type("homography", &view(&rows[..180])).unwrap();
            let (err, clean_err) = (
                error_against_truth(&h, &truth),
                error_against_truth(&h_of(&clean.model), &truth),
            );
            assert!(
                err <= 1.05 * clean_err + 0.05 && err < 1.0,
                "seed {seed}: {err} vs clean {clean_err}"
            );
            let truth_h = Homography::new(truth).unwrap();
            for (i, row) in rows.iter().enumerate().skip(180) {
                let p = [row[0], row[1], row[2], row[3]];
                if transfer_distance(&truth_h, &p) > 10.0 {
                    assert!(!fit.inliers[i], "seed {seed}: outlier {i} is an inlier");
                }
            }
            let kept = fit.inliers[..180].iter().filter(|&&v| v).count();
            assert!(kept >= 175, "seed {seed}: {kept}");
            let mask: Vec<bool> = (0..rows.len()).map(|i| i < 180).collect();
            assert!(rms_on(&fit.model, &rows, &mask) <= 1.5);
        }
    }

    #[test]
    fn affine_map_recovered() {
        let mut rng = Rng::new(5);
        let a = [1.1, 0.2, 15.0, -0.1, 0.9, -7.0];
        let ha = affine_from_wire(&a).unwrap();
        let rows: Vec<Vec<f64>> = (0..100)
            .map(|_| {
                let p1 = [rng.range(0.0, 640.0), rng.range(0.0, 480.0)];
                let p2 = map(&ha.h, p1[0], p1[1]).unwrap();
                corr_row(&mut rng, p1, p2, 0.0, 0.0)
            })
            .collect();
        let fit = fit_type("affine", &view(&rows)).unwrap();
        assert_sane(&fit, rows.len());
        let Model::Affine { a: got } = fit.model else {
            panic!()
        };
        for (g, w) in got.iter().zip(&a) {
            assert!((g - w).abs() < 1e-9 * w.abs().max(1.0), "{got:?}");
        }
        assert!(fit.rms < 1e-9);
        // Noisy: RMS residual ≈ 2σ at σ = 0.5 px in both images.
        let noisy: Vec<Vec<f64>> = rows
            .iter()
            .map(|r| corr_row(&mut rng, [r[0], r[1]], [r[2], r[3]], 0.5, 0.5))
            .collect();
        let fit = fit_type("affine", &view(&noisy)).unwrap();
        assert!(fit.rms < 1.2, "{}", fit.rms);
    }

    #[test]
    fn sampson_distance_is_the_first_order_distance_in_r4() {
        // H = I: the distance of (x₁, x₂) to {x₂ = x₁} is ‖x₂ − x₁‖ / √2.
        let d = sampson_distance_h(&super::super::linalg::IDENTITY3, &[10.0, 20.0, 13.0, 24.0]);
        assert!((d - 5.0 / 2f64.sqrt()).abs() < 1e-12);
        // Scale invariant, and ≈ the transfer distance / √2 near the identity.
        let h = [1.01, 0.02, 3.0, -0.01, 0.99, -2.0, 1e-5, 2e-5, 1.0];
        let p = [100.0, 200.0, 108.0, 197.0];
        let a = sampson_distance_h(&h, &p);
        let b = sampson_distance_h(&h.map(|v| -3.0 * v), &p);
        assert!((a - b).abs() < 1e-12);
        let t = transfer_distance(&Homography::new(h).unwrap(), &p) / 2f64.sqrt();
        assert!((a - t).abs() < 0.05 * t, "{a} vs {t}");
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let mut rng = Rng::new(6);
        let (rows, _) = planar_scene(&mut rng, 10, 0.5, 0.5, 0);
        let pts: Vec<[f64; 4]> = rows.iter().map(|r| [r[0], r[1], r[2], r[3]]).collect();
        let w = vec![1.0; pts.len()];
        let tv = TwoView::new(&pts, &w).unwrap();
        let problem = TransferProblem {
            tv: &tv,
            weights: &w,
            free: (0..9).collect(),
        };
        let hn = [1.0, 0.1, 0.05, -0.08, 0.95, 0.02, 0.01, -0.02, 1.0];
        let g = mat3_inverse(&hn).unwrap();
        for i in 0..pts.len() {
            let mut jac = [[0.0; 9]; 4];
            problem.point(&hn, &g, i, Some(&mut jac)).unwrap();
            for k in 0..9 {
                let eps = 1e-7;
                let (mut hp, mut hm) = (hn, hn);
                hp[k] += eps;
                hm[k] -= eps;
                let rp = problem
                    .point(&hp, &mat3_inverse(&hp).unwrap(), i, None)
                    .unwrap();
                let rm = problem
                    .point(&hm, &mat3_inverse(&hm).unwrap(), i, None)
                    .unwrap();
                for c in 0..4 {
                    let fd = (rp[c] - rm[c]) / (2.0 * eps);
                    assert!(
                        (fd - jac[c][k]).abs() < 1e-5 * (1.0 + fd.abs()),
                        "r{c} h{k}: {fd} vs {}",
                        jac[c][k]
                    );
                }
            }
        }
    }

    #[test]
    fn four_correspondences_are_solved_as_the_dlt_solves_them() {
        let mut rng = Rng::new(3);
        for _ in 0..20 {
            let (rows, truth) = planar_scene(&mut rng, 4, 0.0, 0.0, 0);
            let pts: Vec<[f64; 4]> = rows.iter().map(|r| [r[0], r[1], r[2], r[3]]).collect();
            let direct = HomographyEstimator.fit(&pts, &[1.0; 4]).unwrap();
            // The DLT of the same four rows: a fifth row of zero weight keeps the direct path out.
            let mut five = pts.clone();
            five.push(pts[0]);
            let dlt = HomographyEstimator
                .fit(&five, &[1.0, 1.0, 1.0, 1.0, 0.0])
                .unwrap();
            // The same H (the DLT's eigen-decomposition of ÂᵀÂ resolves it to ~1e-8), and the
            // direct solve is at least as exact on the four points.
            let gap = direct.h.iter().zip(&dlt.h).map(|(a, b)| (a - b).abs());
            assert!(gap.fold(0.0, f64::max) < 1e-6, "{:?} {:?}", direct.h, dlt.h);
            assert!(error_against_truth(&direct, &truth) < 1e-6);
            let worst = |h: &Homography| {
                pts.iter()
                    .map(|p| transfer_distance(h, p))
                    .fold(0.0, f64::max)
            };
            assert!(
                worst(&direct) <= worst(&dlt).max(1e-9),
                "{} {}",
                worst(&direct),
                worst(&dlt)
            );
        }
        // Three of the four on a line, in either image, whichever three (the first three, or
        // two of them with the fourth; also nearly on a line): no single H maps them.
        let spread = [[10.0, 5.0], [120.0, 0.0], [190.0, 90.0], [40.0, 100.0]];
        let first_three = [[0.0, 0.0], [100.0, 0.0], [200.0, 0.0], [50.0, 80.0]];
        let with_fourth = [[0.0, 0.0], [50.0, 80.0], [100.0, 0.0], [200.0, 0.0]];
        let nearly = [[0.0, 0.0], [100.0, 1e-5], [200.0, 0.0], [50.0, 80.0]];
        let lines = [first_three, with_fourth, nearly];
        for (a, b) in lines.iter().flat_map(|&l| [(l, spread), (spread, l)]) {
            let pts: Vec<[f64; 4]> = (0..4)
                .map(|i| [a[i][0], a[i][1], b[i][0], b[i][1]])
                .collect();
            assert_eq!(
                HomographyEstimator.fit(&pts, &[1.0; 4]).err(),
                Some(GeometryError::HomographyUndetermined)
            );
        }
    }

    #[test]
    fn degenerate_homographies() {
        let mut rng = Rng::new(7);
        // Collinear points in image 1 (and 2).
        let collinear: Vec<Vec<f64>> = (0..20)
            .map(|i| {
                let x = 10.0 + 20.0 * i as f64;
                vec![x, 2.0 * x + 5.0, x + 3.0, 2.0 * x + 1.0]
            })
            .collect();
        let same = vec![vec![5.0, 5.0, 6.0, 7.0]; 10];
        let (plane, _) = planar_scene(&mut rng, 3, 0.0, 0.0, 0);
        // Four distinct points, three of them collinear, repeated.
        let three_collinear: Vec<Vec<f64>> = (0..12)
            .map(|i| {
                let p = [[0.0, 0.0], [100.0, 0.0], [200.0, 0.0], [50.0, 80.0]][i % 4];
                vec![p[0], p[1], p[0] + 10.0, p[1] + 5.0]
            })
            .collect();
        for name in ["homography", "affine"] {
            for rows in [&collinear, &same] {
                let fit = fit_type(name, &view(rows)).unwrap();
                assert!(is_degenerate(&fit), "{name}: {fit:?}");
                assert_sane(&fit, rows.len());
            }
        }
        let fit = fit_type("homography", &view(&plane)).unwrap();
        assert!(is_degenerate(&fit), "3 points: {fit:?}");
        let fit = fit_type("homography", &view(&three_collinear)).unwrap();
        assert!(is_degenerate(&fit), "3 of 4 collinear: {fit:?}");
        assert_sane(&fit, three_collinear.len());
    }
}
