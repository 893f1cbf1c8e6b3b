//! Choosing a group's model type by a penalised criterion, and running one type's fit.
//!
//! Every candidate of the family is fitted robustly on its own ([`super::robust`]); two-view
//! candidates are compared before their geometric refinement, which only the winner then gets
//! (the normalised DLT / 8-point estimates are close enough to decide, and the refinement is
//! most of a fit's cost). Each candidate is scored on all the group's rows with Torr's GRIC
//! (1998):
//!
//! GRIC = Σᵢ min(eᵢ²/s², λ₃·(r − d)) + λ₁·d·n + λ₂·k, λ₁ = ln r, λ₂ = ln(r·n), λ₃ = 2,
//!
//! with eᵢ the distance of row i to the model in the data space (dimension r), d the dimension
//! of the model's manifold, k its number of parameters, and s the noise per coordinate,
//! estimated robustly once per group and shared by all candidates. The lowest score wins; a tie
//! goes to the simpler model.
//!
//! | family | candidate | r | d | k | eᵢ |
//! |---|---|---|---|---|---|
//! | curves | line | 2 | 1 | 2 | orthogonal distance |
//! | curves | circle | 2 | 1 | 3 | \|‖p − c‖ − r\| |
//! | curves | ellipse | 2 | 1 | 5 | orthogonal distance |
//! | two-view | affine | 4 | 2 | 6 | Sampson distance of H (HZ §4.2.6) |
//! | two-view | homography | 4 | 2 | 8 | Sampson distance of H (HZ §4.2.6) |
//! | two-view | fundamental | 4 | 3 | 7 | Sampson distance |
//!
//! For curves all candidates have r = 2, d = 1, so GRIC reduces to a robust BIC on the geometric
//! residuals (Σ min(e²/s², 2) + k·ln(2n)). For two-view models eᵢ is each model's first-order
//! distance in ℝ⁴ (Sampson), not the symmetric transfer distance of [`Model::residual`], which
//! over-counts the noise where H magnifies.
//!
//! **Shared noise.** s comes from the inliers of the most general candidate that is not
//! degenerate (ellipse, else circle, else line; F, else H, else affine):
//! s² = Σ_inliers eᵢ² / ((r − d)·n_inliers − k) (Kanatani's estimator; a median would be twice as
//! noisy and flip close calls). Where a simpler candidate's own estimate is within 1.5 × of it,
//! the larger of the two is used: both explain the data, and the general model's spare freedom
//! only deflates s (F fitted to a plane underestimates it by ~15 %, enough to hand the choice
//! to F). Floored at 10⁻⁶ of the data's spread.
//!
//! **Thin conics.** On a noisy line, an ellipse (or circle) can hug the points from both sides
//! and beat the line on residuals: one whose minor radius is within 3σ of its own noise, or a
//! needle (at most 6σ thick, tip radius of curvature b²/a below σ, major semi-axis beyond 3 × the
//! data's spread: the points wrapped around its tip). Such a candidate is dropped from the
//! comparison.

use super::conic::{CircleEstimator, EllipseEstimator, circle_model, ellipse_model};
use super::fundamental::{FundamentalEstimator, fundamental_model};
use super::homography::{
    AffineEstimator, Homography, HomographyEstimator, affine_model, homography_model,
    sampson_distance_h,
};
use super::linalg::Mat3;
use super::line::{self, LineEstimator};
use super::robust::{
    Estimator, INLIER_SIGMAS, Robust, SIGMA_FLOOR, evaluate, fit_robust, fit_unrefined,
    refine_robust, sigma_floor,
};
use super::subspace::{RIGID_RANK, SubspaceEstimator, fit_subspace, subspace_model};
use super::{Family, Fit, GeometryError, Model, validate};

/// A fitted candidate: the answer and the distance of every row to it in the data space
/// (what GRIC scores).
struct Candidate {
    name: &'static str,
    fit: Fit,
    distances: Vec<f64>,
}

/// A candidate whose GRIC distances are its residuals (curves, F, subspace).
fn candidate<P>(name: &'static str, r: Robust<P>, model: impl Fn(&P) -> Model) -> Candidate {
    Candidate {
        name,
        fit: Fit {
            model: model(&r.params),
            rms: r.rms,
            inliers: r.inliers,
            sigma: r.sigma,
        },
        distances: r.residuals,
    }
}

fn robust<E: Estimator>(
    est: &E,
    points: &[E::Point],
    scale: f64,
) -> Result<Robust<E::Params>, GeometryError> {
    fit_robust(est, points, scale)
}

/// RMS distance of the points to their centroid.
fn spread(points: impl Iterator<Item = [f64; 2]> + Clone) -> f64 {
    let (mut n, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for p in points.clone() {
        n += 1.0;
        sx += p[0];
        sy += p[1];
    }
    if n == 0.0 {
        return 0.0;
    }
    let (mx, my) = (sx / n, sy / n);
    (points
        .map(|p| (p[0] - mx).powi(2) + (p[1] - my).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

fn curve(name: &str, pts: &[[f64; 2]]) -> Option<Result<Candidate, GeometryError>> {
    let scale = spread(pts.iter().copied());
    Some(match name {
        "line" => {
            robust(&LineEstimator, pts, scale).map(|r| candidate("line", r, |p| line::to_model(*p)))
        }
        "circle" => robust(&CircleEstimator, pts, scale)
            .map(|r| candidate("circle", r, |p| circle_model(*p))),
        "ellipse" => robust(&EllipseEstimator, pts, scale)
            .map(|r| candidate("ellipse", r, |p| ellipse_model(*p))),
        _ => return None,
    })
}

/// The floor under a robust fit's noise level on `rows` of `family` ([`sigma_floor`] of the
/// rows' scale: RMS spread, for correspondences the mean of the two images'), as the fit
/// applies it; the smallest positive number for motion subspaces and rows that are not of the
/// family's width.
pub fn noise_floor(family: Family, rows: &[&[f64]]) -> f64 {
    let scale = match family {
        Family::Curves => points2(rows).map_or(0.0, |p| spread(p.iter().copied())),
        Family::Homography | Family::Fundamental => {
            points4(rows).map_or(0.0, |p| two_view_scale(&p))
        }
        Family::Subspace => 0.0,
    };
    sigma_floor(scale)
}

/// The data's scale for two-view rows: the mean of the two images' RMS spreads.
fn two_view_scale(pts: &[[f64; 4]]) -> f64 {
    0.5 * (spread(pts.iter().map(|p| [p[0], p[1]])) + spread(pts.iter().map(|p| [p[2], p[3]])))
}

/// A two-view fit before its geometric refinement: model selection compares these and refines
/// only the winner (the Levenberg–Marquardt of the losers would be wasted).
enum TwoViewFit {
    Affine(Robust<Homography>),
    Homography(Robust<Homography>),
    Fundamental(Robust<Mat3>),
}

impl TwoViewFit {
    /// The unrefined robust fit of one named type; `None` for an unknown name.
    fn new(name: &str, pts: &[[f64; 4]], scale: f64) -> Option<Result<Self, GeometryError>> {
        Some(match name {
            "affine" => fit_unrefined(&AffineEstimator, pts, scale).map(Self::Affine),
            "homography" => fit_unrefined(&HomographyEstimator, pts, scale).map(Self::Homography),
            "fundamental" => {
                fit_unrefined(&FundamentalEstimator, pts, scale).map(Self::Fundamental)
            }
            _ => return None,
        })
    }

    /// The candidate GRIC scores: Sampson distances in ℝ⁴ for H and affine (their residual, the
    /// symmetric transfer distance, over-counts the noise where H magnifies), the residual
    /// (Sampson) for F.
    fn candidate(&self, pts: &[[f64; 4]]) -> Candidate {
        let mapping = |name, r: &Robust<Homography>, model: fn(&Homography) -> Model| Candidate {
            distances: pts
                .iter()
                .map(|p| sampson_distance_h(&r.params.h, p))
                .collect(),
            ..candidate(name, r.clone(), model)
        };
        match self {
            Self::Affine(r) => mapping("affine", r, affine_model),
            Self::Homography(r) => mapping("homography", r, homography_model),
            Self::Fundamental(r) => candidate("fundamental", r.clone(), fundamental_model),
        }
    }

    /// The geometric refinement, as the answer.
    fn refined(self, pts: &[[f64; 4]], scale: f64) -> Fit {
        match self {
            Self::Affine(r) => {
                candidate(
                    "affine",
                    refine_robust(&AffineEstimator, pts, r, scale),
                    affine_model,
                )
                .fit
            }
            Self::Homography(r) => {
                let r = refine_robust(&HomographyEstimator, pts, r, scale);
                candidate("homography", r, homography_model).fit
            }
            Self::Fundamental(r) => {
                let r = refine_robust(&FundamentalEstimator, pts, r, scale);
                candidate("fundamental", r, fundamental_model).fit
            }
        }
    }
}

/// The rows as 2-D points (validated width 2).
fn points2(rows: &[&[f64]]) -> Result<Vec<[f64; 2]>, GeometryError> {
    validate(rows, Some(2))?;
    Ok(rows.iter().map(|r| [r[0], r[1]]).collect())
}

/// The rows as correspondences (validated width 4).
fn points4(rows: &[&[f64]]) -> Result<Vec<[f64; 4]>, GeometryError> {
    validate(rows, Some(4))?;
    Ok(rows.iter().map(|r| [r[0], r[1], r[2], r[3]]).collect())
}

/// The degenerate answer for `n` rows.
pub fn degenerate(reason: impl Into<String>, n: usize) -> Fit {
    Fit {
        model: Model::Degenerate {
            reason: reason.into(),
        },
        rms: f64::INFINITY,
        inliers: vec![false; n],
        sigma: f64::INFINITY,
    }
}

/// The plain least-squares fit of one named type on `rows` (unit weights: no robust loop and no
/// geometric refinement; a subspace of the rigid-motion rank 3): a cheap proposal, not an
/// answer. `None` for an unknown name or rows that do not determine the model.
pub fn fit_plain(type_name: &str, rows: &[&[f64]]) -> Option<Model> {
    fn least_squares<E: Estimator>(est: &E, points: &[E::Point]) -> Option<E::Params> {
        est.fit(points, &vec![1.0; points.len()]).ok()
    }
    let model = match type_name {
        "line" => line::to_model(least_squares(&LineEstimator, &points2(rows).ok()?)?),
        "circle" => circle_model(least_squares(&CircleEstimator, &points2(rows).ok()?)?),
        "ellipse" => ellipse_model(least_squares(&EllipseEstimator, &points2(rows).ok()?)?),
        "homography" => {
            homography_model(&least_squares(&HomographyEstimator, &points4(rows).ok()?)?)
        }
        "affine" => affine_model(&least_squares(&AffineEstimator, &points4(rows).ok()?)?),
        "fundamental" => {
            fundamental_model(&least_squares(&FundamentalEstimator, &points4(rows).ok()?)?)
        }
        "subspace" => {
            validate(rows, None).ok()?;
            let rank = RIGID_RANK.min(rows.len().saturating_sub(1));
            subspace_model(&least_squares(&SubspaceEstimator::new(rank), rows)?)
        }
        _ => return None,
    };
    (!model.is_degenerate()).then_some(model)
}

/// Fits one named type; `None` for an unknown name.
pub fn fit_one(type_name: &str, rows: &[&[f64]]) -> Option<Fit> {
    let n = rows.len();
    let outcome = match type_name {
        "line" | "circle" | "ellipse" => points2(rows).and_then(|p| {
            curve(type_name, &p)
                .unwrap_or_else(|| Err(GeometryError::UnknownType(type_name.into())))
        }),
        "homography" | "affine" | "fundamental" => points4(rows).and_then(|p| {
            let scale = two_view_scale(&p);
            let fit = TwoViewFit::new(type_name, &p, scale)
                .unwrap_or_else(|| Err(GeometryError::UnknownType(type_name.into())))?;
            Ok(Candidate {
                name: "",
                fit: fit.refined(&p, scale),
                distances: Vec::new(),
            })
        }),
        "subspace" => validate(rows, None)
            .and_then(|()| fit_subspace(rows))
            .map(|r| candidate("subspace", r, subspace_model)),
        _ => return None,
    };
    Some(match outcome {
        Ok(c) => c.fit,
        Err(reason) => degenerate(reason.to_string(), n),
    })
}

/// A curve fitted again from `model` on `rows` that moved a little: the geometric refinement
/// ([`refine_robust`]) started from the model's own parameters, on the rows it explains,
/// instead of a fit from scratch. `None` for a model that is not a circle or an ellipse, or rows
/// it cannot be evaluated on (the caller fits from scratch).
pub fn refit_curve(model: &Model, rows: &[&[f64]]) -> Option<Fit> {
    let pts = points2(rows).ok()?;
    let scale = spread(pts.iter().copied());
    let r = match *model {
        Model::Circle { cx, cy, r } => {
            let est = CircleEstimator;
            if pts.len() < est.min_points() {
                return None;
            }
            let start = evaluate(&est, [cx, cy, r], &pts, scale);
            candidate("circle", refine_robust(&est, &pts, start, scale), |p| {
                circle_model(*p)
            })
        }
        Model::Ellipse {
            cx,
            cy,
            a,
            b,
            theta,
        } => {
            let est = EllipseEstimator;
            if pts.len() < est.min_points() {
                return None;
            }
            let start = evaluate(&est, [cx, cy, a, b, theta], &pts, scale);
            candidate("ellipse", refine_robust(&est, &pts, start, scale), |p| {
                ellipse_model(*p)
            })
        }
        _ => return None,
    };
    let kept = r.fit.inliers.iter().filter(|&&v| v).count();
    (r.fit.rms.is_finite() && kept >= model.min_points()).then_some(r.fit)
}

/// (r, d, k) of a candidate.
fn dimensions(name: &str) -> (f64, f64, f64) {
    match name {
        "line" => (2.0, 1.0, 2.0),
        "circle" => (2.0, 1.0, 3.0),
        "ellipse" => (2.0, 1.0, 5.0),
        "affine" => (4.0, 2.0, 6.0),
        "homography" => (4.0, 2.0, 8.0),
        "fundamental" => (4.0, 3.0, 7.0),
        _ => (1.0, 0.0, 0.0),
    }
}

/// Torr's GRIC of a candidate at noise `s` (see the module docs).
fn gric(c: &Candidate, s: f64) -> f64 {
    let (r, d, k) = dimensions(c.name);
    let n = c.distances.len() as f64;
    let cap = 2.0 * (r - d);
    let fit: f64 = c
        .distances
        .iter()
        .map(|&e| {
            let x = (e / s).powi(2);
            if x.is_nan() { cap } else { x.min(cap) }
        })
        .sum();
    fit + r.ln() * d * n + (r * n).ln() * k
}

/// A candidate's own noise per coordinate from its inliers: s² = Σ e² / ((r − d)·n − k).
fn candidate_noise(c: &Candidate) -> f64 {
    let (r, d, k) = dimensions(c.name);
    let (ss, count) = c
        .distances
        .iter()
        .zip(&c.fit.inliers)
        .filter(|(e, inlier)| **inlier && e.is_finite())
        .fold((0.0, 0.0), |(s, n), (e, _)| (s + e * e, n + 1.0));
    let dof = ((r - d) * count - k).max(1.0);
    (ss / dof).sqrt()
}

/// The shared noise per coordinate: the most general candidate's (the last of `fitted`), raised
/// to a simpler candidate's where that one is within 1.5 × of it — the two then explain the data
/// alike, and the general model's extra freedom would only deflate s (F on a plane underestimates
/// it by ~15 %, which hands the choice to F). Floored at `floor`.
fn shared_noise(fitted: &[Candidate], floor: f64) -> f64 {
    let Some(general) = fitted.last() else {
        return floor;
    };
    let base = candidate_noise(general);
    let mut s = base;
    for c in &fitted[..fitted.len() - 1] {
        let sc = candidate_noise(c);
        if sc <= 1.5 * base {
            s = s.max(sc);
        }
    }
    if s.is_finite() { s.max(floor) } else { floor }
}

/// Whether a circle or ellipse candidate only hugs a noisy line from both sides: GRIC would
/// reward its overfit. Two signatures: a (minor) radius within 3σ of its own noise, or a needle:
/// an ellipse at most 6σ thick (a hugging fit halves its own σ), whose tip radius of curvature
/// b²/a is below σ and whose major semi-axis reaches beyond 3 × the data's spread `scale` (the
/// points wrapped around its tip).
fn is_thin_conic(c: &Candidate, scale: f64) -> bool {
    let sigma = c.fit.sigma;
    match c.fit.model {
        Model::Circle { r, .. } => r <= INLIER_SIGMAS * sigma,
        Model::Ellipse { a, b, .. } => {
            b <= INLIER_SIGMAS * sigma || (b <= 6.0 * sigma && b * b / a < sigma && a > 3.0 * scale)
        }
        _ => false,
    }
}

/// Fits every candidate of `family` and keeps the one GRIC prefers.
pub fn fit_family(family: Family, rows: &[&[f64]]) -> Fit {
    fit_family_knowing(family, rows, None)
}

/// [`fit_family`], where `known` is already a fit of one curve type on exactly `rows`: that
/// candidate is taken as it is instead of being fitted again.
pub fn fit_family_knowing(family: Family, rows: &[&[f64]], known: Option<&Fit>) -> Fit {
    let n = rows.len();
    // Candidates from the simplest to the most general.
    let (fitted, errors, scale): (Vec<Candidate>, Vec<String>, f64) = match family {
        Family::Subspace => {
            return fit_one("subspace", rows).unwrap_or_else(|| degenerate("subspace", n));
        }
        Family::Curves => {
            let pts = match points2(rows) {
                Ok(p) => p,
                Err(reason) => return degenerate(reason.to_string(), n),
            };
            let scale = spread(pts.iter().copied());
            let (mut ok, mut err) = run_all(&["line", "circle", "ellipse"], |name| {
                match known.filter(|f| f.model.type_name() == name) {
                    Some(f) => Some(Ok(Candidate {
                        name: f.model.type_name(),
                        fit: f.clone(),
                        distances: {
                            let model = f.model.prepared();
                            rows.iter().map(|r| model.residual(r)).collect()
                        },
                    })),
                    None => curve(name, &pts),
                }
            });
            ok.retain(|c| {
                let thin = is_thin_conic(c, scale);
                if thin {
                    err.push(format!("{}: thinner than its noise", c.name));
                }
                !thin
            });
            (ok, err, scale)
        }
        Family::Homography | Family::Fundamental => return fit_two_view(family, rows),
    };
    if fitted.is_empty() {
        return degenerate(format!("no model fits: {}", errors.join("; ")), n);
    }
    let s = shared_noise(&fitted, SIGMA_FLOOR * scale);
    let mut best: Option<(f64, Candidate)> = None;
    for c in fitted {
        let score = gric(&c, s);
        if best.as_ref().is_none_or(|(b, _)| score < *b) {
            best = Some((score, c));
        }
    }
    best.map_or_else(|| degenerate("no model fits", n), |(_, c)| c.fit)
}

/// GRIC among the two-view candidates of `family`, fitted without refinement; the winner is
/// then refined.
fn fit_two_view(family: Family, rows: &[&[f64]]) -> Fit {
    let n = rows.len();
    let pts = match points4(rows) {
        Ok(p) => p,
        Err(reason) => return degenerate(reason.to_string(), n),
    };
    let scale = two_view_scale(&pts);
    let (mut fitted, mut errors) = (Vec::new(), Vec::new());
    for name in family.candidates() {
        match TwoViewFit::new(name, &pts, scale) {
            Some(Ok(f)) => fitted.push(f),
            Some(Err(reason)) => errors.push(format!("{name}: {reason}")),
            None => {}
        }
    }
    if fitted.is_empty() {
        return degenerate(format!("no model fits: {}", errors.join("; ")), n);
    }
    let candidates: Vec<Candidate> = fitted.iter().map(|f| f.candidate(&pts)).collect();
    let s = shared_noise(&candidates, SIGMA_FLOOR * scale);
    let scores: Vec<f64> = candidates.iter().map(|c| gric(c, s)).collect();
    // The lowest score; a tie goes to the simpler (earlier) candidate.
    let best = (0..scores.len()).fold(0, |b, i| if scores[i] < scores[b] { i } else { b });
    fitted.swap_remove(best).refined(&pts, scale)
}

/// Runs each named candidate; the fitted ones in order, and the reasons of the others.
fn run_all(
    names: &[&str],
    run: impl Fn(&str) -> Option<Result<Candidate, GeometryError>>,
) -> (Vec<Candidate>, Vec<String>) {
    let (mut ok, mut err) = (Vec::new(), Vec::new());
    for name in names {
        match run(name) {
            Some(Ok(c)) => ok.push(c),
            Some(Err(reason)) => err.push(format!("{name}: {reason}")),
            None => {}
        }
    }
    (ok, err)
}

#[cfg(test)]
mod tests {
    use super::super::fundamental::tests::{MOTION_R, MOTION_T, rigid_scene};
    use super::super::homography::tests::planar_scene;
    use super::super::testutil::{Rng, assert_sane, is_degenerate, view};
    use super::super::{Family, Fit, Model, fit};

    fn curve_rows(rng: &mut Rng, shape: &str, n: usize, sigma: f64) -> Vec<Vec<f64>> {
        (0..n)
            .map(|i| {
                let t = i as f64 / n as f64;
                let (x, y) = match shape {
                    "line" => (4.0 * t - 2.0, 0.5 * (4.0 * t - 2.0) + 1.0),
                    "circle" => {
                        let p = std::f64::consts::TAU * t;
                        (1.5 * p.cos() + 0.3, 1.5 * p.sin() - 0.2)
                    }
                    _ => {
                        // a = 2, b = 1 (a/b = 2), θ = 0.5.
                        let p = std::f64::consts::TAU * t;
                        let (u, v) = (2.0 * p.cos(), 1.0 * p.sin());
                        let (s, c) = 0.5f64.sin_cos();
                        (c * u - s * v, s * u + c * v)
                    }
                };
                vec![x + sigma * rng.normal(), y + sigma * rng.normal()]
            })
            .collect()
    }

    #[test]
    fn curves_pick_the_right_type() {
        for sigma in [0.0, 0.05] {
            for seed in 0..5 {
                for shape in ["line", "circle", "ellipse"] {
                    let mut rng = Rng::new(seed);
                    let rows = curve_rows(&mut rng, shape, 50, sigma);
                    let f = fit(Family::Curves, &view(&rows));
                    assert_sane(&f, rows.len());
                    assert_eq!(
                        f.model.type_name(),
                        shape,
                        "σ = {sigma}, seed {seed}: {:?}",
                        f.model
                    );
                }
            }
        }
    }

    /// A circle or an ellipse moved by (dx, dy), its (major) radius times `grow`, turned by `turn`.
    fn nudged(
        m: &super::super::Model,
        dx: f64,
        dy: f64,
        grow: f64,
        turn: f64,
    ) -> super::super::Model {
        use super::super::Model;
        match *m {
            Model::Circle { cx, cy, r } => Model::Circle {
                cx: cx + dx,
                cy: cy + dy,
                r: r * grow,
            },
            Model::Ellipse {
                cx,
                cy,
                a,
                b,
                theta,
            } => Model::Ellipse {
                cx: cx + dx,
                cy: cy + dy,
                a: a * grow,
                b,
                theta: theta + turn,
            },
            ref m => panic!("not a conic: {m:?}"),
        }
    }

    #[test]
    fn a_curve_refitted_from_its_model_matches_one_fitted_from_scratch() {
        use super::super::{fit_type, refit_curve};
        for shape in ["circle", "ellipse"] {
            let mut rng = Rng::new(3);
            let rows = curve_rows(&mut rng, shape, 80, 0.02);
            let scratch = fit_type(shape, &view(&rows)).unwrap();
            // Started from a model a little off, on the same rows.
            let start = nudged(&scratch.model, 0.05, -0.03, 1.03, 0.02);
            let warm = refit_curve(&start, &view(&rows)).unwrap();
            assert_sane(&warm, rows.len());
            assert_eq!(warm.model.type_name(), shape);
            assert!(
                (warm.rms - scratch.rms).abs() <= 1e-3 * scratch.rms,
                "{warm:?} / {scratch:?}"
            );
            let r = |f: &Fit| rows.iter().map(|p| f.model.residual(p)).fold(0.0, f64::max);
            assert!((r(&warm) - r(&scratch)).abs() < 1e-3, "{shape}");
        }
        // A line (a closed-form fit) and a circle on fewer points than determine it: fitted
        // from scratch by the caller.
        let mut rng = Rng::new(4);
        let line = curve_rows(&mut rng, "line", 20, 0.01);
        let l = fit_type("line", &view(&line)).unwrap();
        assert!(refit_curve(&l.model, &view(&line)).is_none());
        let circle = Model::Circle {
            cx: 0.0,
            cy: 0.0,
            r: 1.0,
        };
        assert!(refit_curve(&circle, &view(&line[..2])).is_none());
    }

    #[test]
    fn a_known_candidate_is_taken_as_it_is() {
        use super::super::{fit_knowing, fit_type};
        for shape in ["circle", "ellipse"] {
            let mut rng = Rng::new(5);
            let rows = curve_rows(&mut rng, shape, 60, 0.03);
            // A fit of the right type that is not the one fitting from scratch gives (its
            // centre moved, its inliers and RMS as they were): it is the answer, as it is.
            let scratch = fit_type(shape, &view(&rows)).unwrap();
            let known = Fit {
                model: nudged(&scratch.model, 1e-3, 0.0, 1.0, 0.0),
                ..scratch.clone()
            };
            assert_ne!(known, scratch);
            assert_eq!(fit_knowing(Family::Curves, &view(&rows), &known), known);
            // A worse fit of another type, brought in, does not win the choice.
            let worse = fit_type("line", &view(&rows)).unwrap();
            let again = fit_knowing(Family::Curves, &view(&rows), &worse);
            assert_eq!(again, fit(Family::Curves, &view(&rows)));
            assert_eq!(again.model.type_name(), shape);
        }
    }

    #[test]
    fn planar_correspondences_pick_h_and_rigid_motion_picks_f() {
        for seed in 0..5 {
            let mut rng = Rng::new(seed);
            let (plane, _) = planar_scene(&mut rng, 150, 1.0, 1.0, 15);
            let f = fit(Family::Fundamental, &view(&plane));
            assert_sane(&f, plane.len());
            assert_eq!(f.model.type_name(), "homography", "seed {seed}");
            let f = fit(Family::Homography, &view(&plane));
            assert_eq!(f.model.type_name(), "homography", "seed {seed}");

            let (rigid, _) = rigid_scene(&mut rng, 150, 1.0, 15, MOTION_R, MOTION_T);
            let f = fit(Family::Fundamental, &view(&rigid));
            assert_sane(&f, rigid.len());
            assert_eq!(f.model.type_name(), "fundamental", "seed {seed}");
            // Noise-free too.
            let (rigid, _) = rigid_scene(&mut rng, 100, 0.0, 0, MOTION_R, MOTION_T);
            assert_eq!(
                fit(Family::Fundamental, &view(&rigid)).model.type_name(),
                "fundamental"
            );
            let (plane, _) = planar_scene(&mut rng, 100, 0.0, 0.0, 0);
            assert_eq!(
                fit(Family::Fundamental, &view(&plane)).model.type_name(),
                "homography"
            );
        }
    }

    #[test]
    fn affine_data_picks_affine() {
        let mut rng = Rng::new(3);
        let rows: Vec<Vec<f64>> = (0..150)
            .map(|_| {
                let (x, y) = (rng.range(0.0, 640.0), rng.range(0.0, 480.0));
                vec![
                    x + rng.normal(),
                    y + rng.normal(),
                    1.05 * x + 0.1 * y + 12.0 + rng.normal(),
                    -0.05 * x + 0.98 * y - 4.0 + rng.normal(),
                ]
            })
            .collect();
        let f = fit(Family::Homography, &view(&rows));
        assert_eq!(f.model.type_name(), "affine", "{:?}", f.model);
    }

    #[test]
    fn family_degenerate_inputs() {
        let cases: Vec<(Family, Vec<Vec<f64>>)> = vec![
            (Family::Curves, vec![]),
            (Family::Curves, vec![vec![1.0, 2.0]]),
            (Family::Curves, vec![vec![1.0, 2.0]; 7]),
            (
                Family::Curves,
                vec![vec![1.0, f64::NAN], vec![2.0, 3.0], vec![4.0, 1.0]],
            ),
            (Family::Curves, vec![vec![1.0, 2.0, 3.0]; 5]),
            (Family::Homography, vec![vec![1.0, 2.0, 3.0, 4.0]; 3]),
            (Family::Fundamental, vec![vec![1.0, 2.0, 3.0, 4.0]; 30]),
            (Family::Fundamental, vec![vec![1.0, 2.0]; 30]),
            (Family::Subspace, vec![vec![1.0, 2.0, 3.0, 4.0]]),
        ];
        for (family, rows) in &cases {
            let f = fit(*family, &view(rows));
            assert!(is_degenerate(&f), "{family:?} {rows:?}: {f:?}");
            assert_sane(&f, rows.len());
        }
        // Two distinct points: a line is still fine.
        let f = fit(Family::Curves, &view(&[vec![0.0, 0.0], vec![1.0, 2.0]]));
        assert_eq!(f.model.type_name(), "line");
    }
}
