//! Lines by total least squares.
//!
//! The line a·x + b·y + c = 0 (a² + b² = 1) that minimises Σ w_i (a·x_i + b·y_i + c)², the sum
//! of squared orthogonal distances, passes through the weighted centroid m, and its direction is
//! the principal axis of the weighted covariance of the points: the normal (a, b) is the
//! eigenvector of the smaller eigenvalue. c = −(a·m_x + b·m_y). This is already the geometric
//! optimum, so there is no refinement step.
//!
//! Sign convention: a > 0, or a = 0 and b > 0.

use super::linalg::{norm2, sym2_eigen};
use super::normalise::is_coincident;
use super::robust::Estimator;
use super::{GeometryError, Model};

/// Orthogonal distance of (x, y) to a·x + b·y + c = 0 (any scale of (a, b, c)); INFINITY when
/// a = b = 0.
pub fn distance(a: f64, b: f64, c: f64, x: f64, y: f64) -> f64 {
    let n = norm2(a, b);
    if !(n > 0.0) {
        return f64::INFINITY;
    }
    (a * x + b * y + c).abs() / n
}

/// Total least squares line, points `[x, y]`, params `[a, b, c]`.
pub struct LineEstimator;

impl Estimator for LineEstimator {
    type Point = [f64; 2];
    type Params = [f64; 3];

    fn min_points(&self) -> usize {
        2
    }

    fn fit(&self, points: &[[f64; 2]], weights: &[f64]) -> Result<[f64; 3], GeometryError> {
        let (mut sw, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for (p, &w) in points.iter().zip(weights) {
            sw += w;
            sx += w * p[0];
            sy += w * p[1];
        }
        if !(sw > 0.0) {
            return Err(GeometryError::NoWeightedPoints);
        }
        let (mx, my) = (sx / sw, sy / sw);
        let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
        for (p, &w) in points.iter().zip(weights) {
            let (dx, dy) = (p[0] - mx, p[1] - my);
            sxx += w * dx * dx;
            sxy += w * dx * dy;
            syy += w * dy * dy;
        }
        let (sxx, sxy, syy) = (sxx / sw, sxy / sw, syy / sw);
        if is_coincident((sxx + syy).sqrt(), mx.abs() + my.abs()) {
            return Err(GeometryError::Coincident);
        }
        let (_, _, direction) = sym2_eigen(sxx, sxy, syy);
        let (mut a, mut b) = (-direction.sin(), direction.cos());
        if a < 0.0 || (a == 0.0 && b < 0.0) {
            a = -a;
            b = -b;
        }
        Ok([a, b, -(a * mx + b * my)])
    }

    fn refine(&self, params: [f64; 3], _: &[[f64; 2]], _: &[f64]) -> [f64; 3] {
        params
    }

    fn residual(&self, l: &[f64; 3], p: &[f64; 2]) -> f64 {
        distance(l[0], l[1], l[2], p[0], p[1])
    }
}

/// The wire model of line parameters.
pub fn to_model(l: [f64; 3]) -> Model {
    Model::Line {
        a: l[0],
        b: l[1],
        c: l[2],
    }
}

#[cfg(test)]
mod tests {
    use super::super::testutil::{Rng, assert_sane, is_degenerate, view};
    use super::super::{Fit, Model, fit_type};
    use super::*;

    /// 50 points on a segment of `length` at angle `angle` through (cx, cy), noise σ, and
    /// `outliers` extra points uniform in the segment's bounding square.
    fn line_rows(
        rng: &mut Rng,
        angle: f64,
        length: f64,
        sigma: f64,
        outliers: usize,
    ) -> Vec<Vec<f64>> {
        let (c, s) = (angle.cos(), angle.sin());
        let (cx, cy) = (0.7, -0.4);
        let mut rows: Vec<Vec<f64>> = (0..50)
            .map(|_| {
                let t = rng.range(-0.5, 0.5) * length;
                vec![
                    cx + t * c + sigma * rng.normal(),
                    cy + t * s + sigma * rng.normal(),
                ]
            })
            .collect();
        for _ in 0..outliers {
            rows.push(vec![
                cx + rng.range(-0.5, 0.5) * length,
                cy + rng.range(-0.5, 0.5) * length,
            ]);
        }
        rows
    }

    fn angle_error_deg(fit: &Fit, angle: f64) -> f64 {
        let Model::Line { a, b, .. } = fit.model else {
            panic!("{:?}", fit.model)
        };
        // Direction (b, −a) vs (cos, sin), modulo π.
        let d = (-a).atan2(b) - angle;
        let d = (d + std::f64::consts::FRAC_PI_2).rem_euclid(std::f64::consts::PI)
            - std::f64::consts::FRAC_PI_2;
        d.abs().to_degrees()
    }

    #[test]
    fn noise_free_line_is_exact() {
        let mut rng = Rng::new(10);
        let rows = line_rows(&mut rng, 0.3, 3.0, 0.0, 0);
        let fit = fit_type("line", &view(&rows)).unwrap();
        assert_sane(&fit, rows.len());
        assert!(angle_error_deg(&fit, 0.3) < 1e-10);
        assert!(fit.rms < 1e-12 && fit.inliers.iter().all(|&v| v));
        let Model::Line { a, b, c } = fit.model else {
            unreachable!()
        };
        assert!((a * a + b * b - 1.0).abs() < 1e-15 && a >= 0.0);
        assert!(
            (a * 0.7 - b * 0.4 + c).abs() < 1e-12,
            "passes through the centre"
        );
    }

    #[test]
    fn line_angle_within_half_a_degree_at_paper_noise() {
        // 50 points on a segment of length 4, σ = 0.05: the Cramér–Rao bound of the angle is
        // σ / (L·√(n/12)) ≈ 0.35°, so we check the RMS over 20 seeds, and each seed loosely.
        let mut sq = 0.0;
        for seed in 0..20 {
            let mut rng = Rng::new(100 + seed);
            let angle = rng.range(-3.0, 3.0);
            let rows = line_rows(&mut rng, angle, 4.0, 0.05, 0);
            let fit = fit_type("line", &view(&rows)).unwrap();
            assert_sane(&fit, rows.len());
            let e = angle_error_deg(&fit, angle);
            assert!(e < 1.5, "seed {seed}: {e}°");
            sq += e * e;
            // σ recovered within 50 % (1.4826 × the median of 50 residuals scatters by ~16 %).
            assert!((fit.sigma / 0.05 - 1.0).abs() < 0.5, "σ {}", fit.sigma);
        }
        let rms = (sq / 20.0).sqrt();
        assert!(rms < 0.5, "RMS angle error {rms}°");
    }

    #[test]
    fn ten_percent_foreign_points_do_not_move_the_line() {
        let mut sq = 0.0;
        for seed in 0..20 {
            let mut rng = Rng::new(200 + seed);
            let angle = rng.range(-3.0, 3.0);
            let rows = line_rows(&mut rng, angle, 4.0, 0.05, 5);
            let fit = fit_type("line", &view(&rows)).unwrap();
            let e = angle_error_deg(&fit, angle);
            sq += e * e;
            // Foreign points far from the true line are not inliers.
            let (c, s) = (angle.cos(), angle.sin());
            for (i, row) in rows.iter().enumerate().skip(50) {
                let d = ((row[0] - 0.7) * -s + (row[1] + 0.4) * c).abs();
                if d > 8.0 * 0.05 {
                    assert!(
                        !fit.inliers[i],
                        "seed {seed}: foreign point {i} at {d} is an inlier"
                    );
                }
            }
            let kept = fit.inliers[..50].iter().filter(|&&v| v).count();
            assert!(kept >= 47, "seed {seed}: {kept} of 50 true points kept");
        }
        assert!((sq / 20.0).sqrt() < 0.5);
    }

    #[test]
    fn degenerate_lines() {
        let one = [vec![1.0, 2.0]];
        let fit = fit_type("line", &view(&one)).unwrap();
        assert!(is_degenerate(&fit));
        assert_sane(&fit, 1);
        let same = vec![vec![1.0, 2.0]; 10];
        let fit = fit_type("line", &view(&same)).unwrap();
        assert!(is_degenerate(&fit), "{fit:?}");
        assert_sane(&fit, 10);
        let two = [vec![0.0, 0.0], vec![1.0, 1.0]];
        let fit = fit_type("line", &view(&two)).unwrap();
        assert!(!is_degenerate(&fit));
        assert!(fit.rms < 1e-15);
    }

    #[test]
    fn distance_is_orthogonal() {
        assert_eq!(distance(3.0, 4.0, 0.0, 3.0, 4.0), 5.0);
        assert_eq!(distance(0.0, 0.0, 1.0, 3.0, 4.0), f64::INFINITY);
    }
}
