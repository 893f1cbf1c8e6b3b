//! Test helpers: a tiny deterministic PRNG with Box–Muller normals, synthetic cameras, and
//! checks shared by the tests of every file. Test-only (`#[cfg(test)]`).

use super::linalg::{Mat3, mat3_mul, mat3_vec};
use super::{Fit, Model};

/// SplitMix64: 64-bit state, passes BigCrush, and is the same on every platform.
pub struct Rng {
    state: u64,
    spare: Option<f64>,
}

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self {
            state: seed ^ 0x9E37_79B9_7F4A_7C15,
            spare: None,
        }
    }

    fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal (Box–Muller, the second value kept for the next call).
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let t = std::f64::consts::TAU * u2;
        self.spare = Some(r * t.sin());
        r * t.cos()
    }
}

/// A pinhole camera P = K [R | t].
pub struct Camera {
    pub k: Mat3,
    pub r: Mat3,
    pub t: [f64; 3],
}

impl Camera {
    /// Image of a 3-D point, pixels (None behind the camera).
    pub fn project(&self, x: [f64; 3]) -> Option<[f64; 2]> {
        let mut c = mat3_vec(&self.r, x);
        for (ci, ti) in c.iter_mut().zip(self.t) {
            *ci += ti;
        }
        if c[2] <= 1e-6 {
            return None;
        }
        let p = mat3_vec(&self.k, c);
        Some([p[0] / p[2], p[1] / p[2]])
    }
}

/// Intrinsics of a 640 × 480 camera with focal length `f` px.
pub fn intrinsics(f: f64) -> Mat3 {
    [f, 0.0, 320.0, 0.0, f, 240.0, 0.0, 0.0, 1.0]
}

/// Rotation by the axis-angle vector `w` (radians).
pub fn rotation(w: [f64; 3]) -> Mat3 {
    super::linalg::rodrigues(w)
}

/// `a · b`, re-exported for the camera set-ups of the tests.
pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    mat3_mul(a, b)
}

/// Noisy row `[x1, y1, x2, y2]` from two image points, N(0, σ²) per coordinate of each
/// image (σ1 for the first image, σ2 for the second).
pub fn corr_row(rng: &mut Rng, p1: [f64; 2], p2: [f64; 2], s1: f64, s2: f64) -> Vec<f64> {
    vec![
        p1[0] + s1 * rng.normal(),
        p1[1] + s1 * rng.normal(),
        p2[0] + s2 * rng.normal(),
        p2[1] + s2 * rng.normal(),
    ]
}

/// Borrowed view of owned rows, as `fit` takes them.
pub fn view(rows: &[Vec<f64>]) -> Vec<&[f64]> {
    rows.iter().map(Vec::as_slice).collect()
}

/// Every number of a model (or nothing for `Degenerate`).
pub fn model_numbers(m: &Model) -> Vec<f64> {
    match m {
        Model::Line { a, b, c } => vec![*a, *b, *c],
        Model::Circle { cx, cy, r } => vec![*cx, *cy, *r],
        Model::Ellipse {
            cx,
            cy,
            a,
            b,
            theta,
        } => vec![*cx, *cy, *a, *b, *theta],
        Model::Homography { h } => h.to_vec(),
        Model::Fundamental { f } => f.to_vec(),
        Model::Affine { a } => a.to_vec(),
        Model::Subspace { mean, basis, .. } => {
            mean.iter().chain(basis.iter().flatten()).copied().collect()
        }
        Model::Degenerate { .. } => Vec::new(),
    }
}

/// The contract on every returned fit: no NaN anywhere; a non-degenerate model has finite
/// parameters, rms and sigma, and one inlier flag per row.
pub fn assert_sane(fit: &Fit, n_rows: usize) {
    assert_eq!(fit.inliers.len(), n_rows, "one inlier flag per row");
    assert!(!fit.rms.is_nan() && !fit.sigma.is_nan(), "{fit:?}");
    match &fit.model {
        Model::Degenerate { reason } => {
            assert!(!reason.is_empty());
            assert!(
                fit.inliers.iter().all(|v| !v),
                "a degenerate fit has no inliers"
            );
        }
        m => {
            assert!(model_numbers(m).iter().all(|v| v.is_finite()), "{m:?}");
            assert!(fit.rms.is_finite() && fit.sigma.is_finite(), "{fit:?}");
        }
    }
}

/// Whether the fit is degenerate.
pub fn is_degenerate(fit: &Fit) -> bool {
    matches!(fit.model, Model::Degenerate { .. })
}

/// RMS of the model's residuals over the rows with `mask[i]`.
pub fn rms_on(model: &Model, rows: &[Vec<f64>], mask: &[bool]) -> f64 {
    let (mut ss, mut n) = (0.0, 0usize);
    for (row, &m) in rows.iter().zip(mask) {
        if m {
            ss += model.residual(row).powi(2);
            n += 1;
        }
    }
    (ss / n.max(1) as f64).sqrt()
}
