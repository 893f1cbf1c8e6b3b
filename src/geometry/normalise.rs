//! Hartley's isotropic normalisation (HZ §4.4): the similarity x̂ = k·(x − m) that moves the
//! (weighted) centroid m of a set of image points to the origin and scales their mean distance
//! from it to √2. Estimation runs in normalised coordinates; parameters go back to the caller's
//! units with the inverse transform.

use super::GeometryError;
use super::linalg::{Mat3, norm2, sym2_eigen};

/// x̂ = k·(x − m), one per image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Similarity {
    pub mx: f64,
    pub my: f64,
    /// Scale: √2 / (mean distance to the centroid).
    pub k: f64,
}

/// Whether a spread (a length) is zero to working precision at coordinates of magnitude
/// `magnitude`: all points coincide.
pub fn is_coincident(spread: f64, magnitude: f64) -> bool {
    !(spread > 1e-12 * magnitude) || spread == 0.0
}

impl Similarity {
    /// The normalisation of the points of positive weight (weights scale their say in the
    /// centroid and mean distance). `None` when they have no weight or all coincide.
    pub fn hartley(points: impl Iterator<Item = ([f64; 2], f64)> + Clone) -> Option<Self> {
        let (mut sw, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for (p, w) in points.clone() {
            if w > 0.0 {
                sw += w;
                sx += w * p[0];
                sy += w * p[1];
            }
        }
        if !(sw > 0.0) {
            return None;
        }
        let (mx, my) = (sx / sw, sy / sw);
        let mut sd = 0.0;
        for (p, w) in points {
            if w > 0.0 {
                sd += w * norm2(p[0] - mx, p[1] - my);
            }
        }
        let mean = sd / sw;
        if is_coincident(mean, mx.abs() + my.abs()) || !mean.is_finite() {
            return None;
        }
        Some(Self {
            mx,
            my,
            k: std::f64::consts::SQRT_2 / mean,
        })
    }

    /// x̂ = k·(x − m).
    pub fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        [self.k * (p[0] - self.mx), self.k * (p[1] - self.my)]
    }

    /// T with x̂ = T·x (homogeneous).
    pub fn matrix(&self) -> Mat3 {
        [
            self.k,
            0.0,
            -self.k * self.mx,
            0.0,
            self.k,
            -self.k * self.my,
            0.0,
            0.0,
            1.0,
        ]
    }

    /// T⁻¹ with x = T⁻¹·x̂.
    pub fn inverse_matrix(&self) -> Mat3 {
        [
            1.0 / self.k,
            0.0,
            self.mx,
            0.0,
            1.0 / self.k,
            self.my,
            0.0,
            0.0,
            1.0,
        ]
    }
}

/// Eigenvalue ratio of the points' covariance below which they lie on one line.
pub const COLLINEAR: f64 = 1e-12;

/// Whether the points of positive weight (normalised coordinates) lie on one line: the smaller
/// eigenvalue of their weighted covariance is below [`COLLINEAR`] × the larger.
pub fn is_collinear(points: &[[f64; 2]], weights: &[f64]) -> bool {
    let (mut sw, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for (p, &w) in points.iter().zip(weights) {
        if w > 0.0 {
            sw += w;
            sx += w * p[0];
            sy += w * p[1];
        }
    }
    if !(sw > 0.0) {
        return true;
    }
    let (mx, my) = (sx / sw, sy / sw);
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for (p, &w) in points.iter().zip(weights) {
        if w > 0.0 {
            let (dx, dy) = (p[0] - mx, p[1] - my);
            sxx += w * dx * dx;
            sxy += w * dx * dy;
            syy += w * dy * dy;
        }
    }
    let (l1, l2, _) = sym2_eigen(sxx, sxy, syy);
    !(l2 > COLLINEAR * l1)
}

/// Correspondences `[x1, y1, x2, y2]` in normalised coordinates, one transform per image.
#[derive(Debug, Clone)]
pub struct TwoView {
    pub t1: Similarity,
    pub t2: Similarity,
    /// T₁·x₁ per row.
    pub q1: Vec<[f64; 2]>,
    /// T₂·x₂ per row.
    pub q2: Vec<[f64; 2]>,
}

impl TwoView {
    /// Normalises each image by its points of positive weight. `Err` when the points of one
    /// image coincide.
    pub fn new(points: &[[f64; 4]], weights: &[f64]) -> Result<Self, GeometryError> {
        let w = weights.iter().copied();
        let t1 = Similarity::hartley(points.iter().map(|p| [p[0], p[1]]).zip(w.clone()))
            .ok_or(GeometryError::CoincidentImage { image: 1 })?;
        let t2 = Similarity::hartley(points.iter().map(|p| [p[2], p[3]]).zip(w))
            .ok_or(GeometryError::CoincidentImage { image: 2 })?;
        let q1 = points.iter().map(|p| t1.apply([p[0], p[1]])).collect();
        let q2 = points.iter().map(|p| t2.apply([p[2], p[3]])).collect();
        Ok(Self { t1, t2, q1, q2 })
    }
}

#[cfg(test)]
mod tests {
    use super::super::linalg::{IDENTITY3, mat3_mul};
    use super::*;

    #[test]
    fn centroid_to_origin_mean_distance_root_two() {
        let pts = [[100.0, 200.0], [300.0, 200.0], [200.0, 400.0], [200.0, 0.0]];
        let t = Similarity::hartley(pts.iter().map(|p| (*p, 1.0))).unwrap();
        let q: Vec<[f64; 2]> = pts.iter().map(|p| t.apply(*p)).collect();
        let (cx, cy) = q.iter().fold((0.0, 0.0), |(a, b), p| (a + p[0], b + p[1]));
        assert!(cx.abs() < 1e-12 && cy.abs() < 1e-12);
        let mean: f64 = q.iter().map(|p| p[0].hypot(p[1])).sum::<f64>() / 4.0;
        assert!((mean - 2f64.sqrt()).abs() < 1e-12);
        let id = mat3_mul(&t.matrix(), &t.inverse_matrix());
        assert!(
            id.iter()
                .zip(&IDENTITY3)
                .all(|(a, b)| (a - b).abs() < 1e-12)
        );
    }

    #[test]
    fn coincident_or_weightless_points_have_no_normalisation() {
        assert!(Similarity::hartley([[3.0, 4.0]; 5].iter().map(|p| (*p, 1.0))).is_none());
        assert!(Similarity::hartley([[3.0, 4.0], [5.0, 1.0]].iter().map(|p| (*p, 0.0))).is_none());
    }
}
