//! Explicit geometric models of a group of points: what a structure is, its parameters in the
//! caller's units, and the distance of a point to it.
//!
//! Every model answers in the caller's units (pixels, not normalised coordinates): estimation
//! normalises internally for the numerics (Hartley's isotropic normalisation, HZ §4.4) and maps
//! the parameters back with the inverse transform.
//!
//! | type | params | residual of a row |
//! |---|---|---|
//! | `line` | a·x + b·y + c = 0, a² + b² = 1 | orthogonal distance |
//! | `circle` | centre (cx, cy), radius r | \|‖p − c‖ − r\| |
//! | `ellipse` | centre, semi-axes a ≥ b, θ = angle of the a-axis from +x (radians) | geometric distance |
//! | `homography` | h, 9 numbers row-major, x₂ ~ H·x₁ | symmetric transfer distance |
//! | `fundamental` | f, 9 numbers row-major, x₂ᵀ·F·x₁ = 0, rank 2 | Sampson distance |
//! | `affine` | a, 2 × 3 row-major, x₂ = A·[x₁; 1] | symmetric transfer distance |
//! | `subspace` | rank, mean (2F), basis (rank rows of 2F) | distance to the affine subspace / √F |
//! | `degenerate` | reason | none (infinite) |
//!
//! Rows: points2d `[x, y]`; correspondences `[x1, y1, x2, y2]`; trajectories
//! `[x_1, y_1, x_2, y_2, …, x_F, y_F]` (2F values, interleaved per frame).
//!
//! **How each type is estimated** (details in each file's docs):
//!
//! | type | least squares | geometric refinement | file |
//! |---|---|---|---|
//! | line | total least squares (principal axis) | — (already geometric) | [`line`](mod@line) |
//! | circle | Kåsa: [2x, 2y, 1]·[cx, cy, r² − ‖c‖²]ᵀ = x² + y² | LM on ‖p − c‖ − r | [`conic`] |
//! | ellipse | Fitzgibbon direct LS, Halíř–Flusser form | LM on the orthogonal distance | [`conic`] |
//! | homography | normalised DLT (HZ §4.1, §4.4), H = T₂⁻¹ĤT₁ | LM on the symmetric transfer error | [`homography`] |
//! | affine | LS on x₂ = A·[x₁; 1] | LM on the symmetric transfer error | [`homography`] |
//! | fundamental | normalised 8-point, rank 2 by SVD, F = T₂ᵀF̂T₁ | LM on the Sampson error, rank 2 kept | [`fundamental`] |
//! | subspace | mean + top eigenvectors of the scatter, rank by a GRIC-like rule | — | [`subspace`] |
//!
//! Homogeneous matrices (h, f) are returned with ‖·‖ = 1 (Frobenius) and entry `[8]` > 0 (the first
//! non-zero entry positive if `[8]` = 0); an affine map is its 2 × 3 matrix.
//!
//! **Robustness** ([`robust`]): IRLS with Cauchy weights around each estimator (two-view models
//! first pick their start among least squares and a few minimal samples by least median of
//! squares), then least squares and geometric refinement on the inliers (residual ≤ 3σ,
//! σ = 1.4826 × the median residual, floored at 10⁻⁶ × the data's spread). Deterministic: the
//! samples come from a fixed-seed generator, so the same rows give the same fit, bit for bit.
//!
//! **Type selection** ([`select`]): GRIC (Torr 1998) over the candidates of a [`Family`], with one
//! noise level per group shared by all candidates; for curves it reduces to a robust BIC.
//!
//! **Degenerate input** — too few rows, rows of the wrong width, non-finite values or values beyond
//! ±[`MAX_COORDINATE`], coincident points, collinear points (conics, homographies), correspondences
//! that do not determine F (planar scene, pure rotation, pure image translation), coincident
//! trajectories — gives [`Model::Degenerate`] with a readable reason; no fit ever holds a NaN or
//! panics.
//!
//! Support files: [`linalg`] (symmetric eigen-decomposition, Jacobi SVD, small solves), [`lm`]
//! (Levenberg–Marquardt), [`normalise`] (Hartley's normalisation), and `testutil` (tests only:
//! a seeded PRNG, synthetic cameras).
// `!(x > 0.0)` is this module's deliberate NaN-safe test ("not a positive number"): it is true for
// NaN, where `x <= 0.0` is false.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use serde::{Deserialize, Serialize};

pub mod conic;
pub mod fundamental;
pub mod homography;
pub mod linalg;
pub mod line;
pub mod lm;
pub mod normalise;
pub mod robust;
pub mod select;
pub mod subspace;
#[cfg(test)]
mod testutil;

/// A fitted structure's model, parameters in the caller's units. Serialised as
/// `{"type": "circle", "params": {"cx": .., "cy": .., "r": ..}}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", content = "params", rename_all = "snake_case")]
pub enum Model {
    Line {
        a: f64,
        b: f64,
        c: f64,
    },
    Circle {
        cx: f64,
        cy: f64,
        r: f64,
    },
    Ellipse {
        cx: f64,
        cy: f64,
        a: f64,
        b: f64,
        theta: f64,
    },
    Homography {
        h: [f64; 9],
    },
    Fundamental {
        f: [f64; 9],
    },
    Affine {
        a: [f64; 6],
    },
    Subspace {
        rank: usize,
        mean: Vec<f64>,
        basis: Vec<Vec<f64>>,
    },
    Degenerate {
        reason: String,
    },
}

/// A [`Model`] prepared for the residuals of many rows ([`Model::prepared`]).
pub struct Prepared<'a> {
    model: &'a Model,
    how: Prepare,
}

/// What a model's residuals share: the ellipse's frame, the map with its inverse (`None` where
/// the parameters give none: every residual is then infinite).
enum Prepare {
    Ellipse(Option<conic::EllipseFrame>),
    Map(Option<homography::Homography>),
    AsIs,
}

impl Prepared<'_> {
    /// [`Model::residual`].
    pub fn residual(&self, row: &[f64]) -> f64 {
        if row.iter().any(|v| !v.is_finite()) {
            return f64::INFINITY;
        }
        let pair =
            || -> Option<[f64; 4]> { (row.len() == 4).then(|| [row[0], row[1], row[2], row[3]]) };
        let r = match (&self.how, self.model) {
            (Prepare::Ellipse(frame), _) if row.len() == 2 => frame
                .as_ref()
                .map_or(f64::INFINITY, |f| f.distance(row[0], row[1])),
            (Prepare::Map(map), _) => match (map, pair()) {
                (Some(h), Some(p)) => homography::transfer_distance(h, &p),
                _ => f64::INFINITY,
            },
            (_, Model::Line { a, b, c }) if row.len() == 2 => {
                line::distance(*a, *b, *c, row[0], row[1])
            }
            (_, Model::Circle { cx, cy, r }) if row.len() == 2 => {
                conic::circle_distance(*cx, *cy, *r, row[0], row[1])
            }
            (_, Model::Fundamental { f }) => {
                pair().map_or(f64::INFINITY, |p| fundamental::sampson_distance(f, &p))
            }
            (_, Model::Subspace { mean, basis, .. }) => {
                subspace::subspace_distance(mean, basis, row)
            }
            _ => f64::INFINITY,
        };
        if r.is_nan() { f64::INFINITY } else { r }
    }

    /// min([`Model::residual`], `cap`), cheaper for an ellipse: a row whose first-order
    /// (Sampson) distance exceeds 2 × `cap` is far from the curve and gets `cap` without its
    /// orthogonal distance (which an iterative foot-point search gives).
    pub fn residual_capped(&self, row: &[f64], cap: f64) -> f64 {
        let r = match &self.how {
            Prepare::Ellipse(frame) if row.len() == 2 && row.iter().all(|v| v.is_finite()) => frame
                .as_ref()
                .map_or(f64::INFINITY, |f| f.distance_capped(row[0], row[1], cap)),
            _ => self.residual(row),
        };
        if r.is_nan() { cap } else { r.min(cap) }
    }
}

/// How one view of a correspondence was moved before a fit: x' = scale·x + shift.
pub type ViewMove = (f64, [f64; 2]);
/// A view left as sent.
pub const UNMOVED: ViewMove = (1.0, [0.0, 0.0]);

impl Model {
    /// The model of correspondences in the caller's coordinates, for this model fitted with
    /// each view v moved by x' = s_v·x + t_v (`moves`, [`UNMOVED`] for a view left as sent):
    /// with A_v = [[s_v, 0, t_vx], [0, s_v, t_vy], [0, 0, 1]], H = A₂⁻¹·H'·A₁ and
    /// F = A₂ᵀ·F'·A₁ (each in its gauge: ‖·‖ = 1, last entry positive); an affine map's linear
    /// part L' times s₁ / s₂ and its translation (c' − t₂ + L'·t₁) / s₂. Models of one view:
    /// unchanged.
    pub fn views_unmoved(&self, [(s1, t1), (s2, t2)]: [ViewMove; 2]) -> Model {
        let a1: linalg::Mat3 = [s1, 0.0, t1[0], 0.0, s1, t1[1], 0.0, 0.0, 1.0];
        let unmoved = |m: &linalg::Mat3, second: &linalg::Mat3| {
            linalg::unit_norm_sign(&linalg::mat3_mul(&linalg::mat3_mul(second, m), &a1))
        };
        match self {
            Model::Homography { h } => {
                let a2_inv = [
                    1.0 / s2,
                    0.0,
                    -t2[0] / s2,
                    0.0,
                    1.0 / s2,
                    -t2[1] / s2,
                    0.0,
                    0.0,
                    1.0,
                ];
                unmoved(h, &a2_inv).map_or_else(|| self.clone(), |h| Model::Homography { h })
            }
            Model::Fundamental { f } => {
                let a2_t = [s2, 0.0, 0.0, 0.0, s2, 0.0, t2[0], t2[1], 1.0];
                unmoved(f, &a2_t).map_or_else(|| self.clone(), |f| Model::Fundamental { f })
            }
            Model::Affine { a } => Model::Affine {
                a: [
                    a[0] * s1 / s2,
                    a[1] * s1 / s2,
                    (a[2] - t2[0] + a[0] * t1[0] + a[1] * t1[1]) / s2,
                    a[3] * s1 / s2,
                    a[4] * s1 / s2,
                    (a[5] - t2[1] + a[3] * t1[0] + a[4] * t1[1]) / s2,
                ],
            },
            other => other.clone(),
        }
    }

    /// The wire name of the model's type (`"line"`, `"circle"`, ...).
    pub fn type_name(&self) -> &'static str {
        match self {
            Model::Line { .. } => "line",
            Model::Circle { .. } => "circle",
            Model::Ellipse { .. } => "ellipse",
            Model::Homography { .. } => "homography",
            Model::Fundamental { .. } => "fundamental",
            Model::Affine { .. } => "affine",
            Model::Subspace { .. } => "subspace",
            Model::Degenerate { .. } => "degenerate",
        }
    }
}

/// What a group may be: the candidates tried, by the kind of input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Family {
    /// points2d: line, circle or ellipse.
    Curves,
    /// correspondences from planes: homography or affine.
    Homography,
    /// correspondences from rigid motions: fundamental, or homography/affine where GRIC prefers it.
    Fundamental,
    /// trajectories: an affine motion subspace.
    Subspace,
}

impl Model {
    /// Geometric distance of one input row to the model, caller's units (see the table in the
    /// module docs): points2d rows `[x, y]`, correspondence rows `[x1, y1, x2, y2]`, trajectory
    /// rows of 2F values. `f64::INFINITY` for `Degenerate`, for a row of the wrong width or with a
    /// non-finite value, and wherever the distance is undefined (a point mapped to infinity, a
    /// singular H); never NaN. For many rows, [`Model::prepared`] does the per-model work once.
    pub fn residual(&self, row: &[f64]) -> f64 {
        self.prepared().residual(row)
    }

    /// min([`Model::residual`], `cap`), cheaper for an ellipse: see [`Prepared::residual_capped`].
    pub fn residual_capped(&self, row: &[f64], cap: f64) -> f64 {
        self.prepared().residual_capped(row, cap)
    }

    /// The model prepared for the residuals of many rows: an ellipse's frame and a map's
    /// inverse computed once, not per row.
    pub fn prepared(&self) -> Prepared<'_> {
        let how = match self {
            Model::Ellipse {
                cx,
                cy,
                a,
                b,
                theta,
            } => Prepare::Ellipse(conic::EllipseFrame::new(&[*cx, *cy, *a, *b, *theta])),
            Model::Homography { h } => Prepare::Map(homography::from_wire(h)),
            Model::Affine { a } => Prepare::Map(homography::affine_from_wire(a)),
            _ => Prepare::AsIs,
        };
        Prepared { model: self, how }
    }
    /// The number of rows that determine a model of this type: line 2, circle 3, ellipse 5,
    /// homography 4, affine 3, fundamental 8, subspace rank + 1; 0 for `Degenerate`.
    pub fn min_points(&self) -> usize {
        match self {
            Model::Line { .. } => 2,
            Model::Circle { .. } => 3,
            Model::Ellipse { .. } => 5,
            Model::Homography { .. } => 4,
            Model::Fundamental { .. } => 8,
            Model::Affine { .. } => 3,
            Model::Subspace { rank, .. } => rank + 1,
            Model::Degenerate { .. } => 0,
        }
    }

    /// Whether this is `Degenerate` (no model).
    pub fn is_degenerate(&self) -> bool {
        matches!(self, Model::Degenerate { .. })
    }
}

/// The largest |coordinate| a fit accepts: beyond it, squares and products of coordinates could
/// overflow, and a row holding one makes the group degenerate.
pub const MAX_COORDINATE: f64 = 1e150;

impl Family {
    /// The model types [`fit`] tries for this family, simplest first.
    pub fn candidates(self) -> &'static [&'static str] {
        match self {
            Family::Curves => &["line", "circle", "ellipse"],
            Family::Homography => &["affine", "homography"],
            Family::Fundamental => &["affine", "homography", "fundamental"],
            Family::Subspace => &["subspace"],
        }
    }

    /// The most rows a model of this family needs ([`Model::min_points`] of its most demanding
    /// candidate): ellipse 5, homography 4, fundamental 8, a subspace of the highest rank 5.
    pub fn largest_sample(self) -> usize {
        match self {
            Family::Curves => 5,
            Family::Homography => 4,
            Family::Fundamental => 8,
            Family::Subspace => subspace::MAX_RANK + 1,
        }
    }
}

/// A fitted group: its model, the RMS residual over the inliers, which of the given rows are
/// inliers (same order as given).
///
/// `sigma` is the group's robust noise level in the units of [`Model::residual`]:
/// 1.4826 × the median residual over all its rows, floored at 10⁻⁶ of the data's spread. For a
/// 1-D residual (line, circle, ellipse, Sampson) it estimates the noise σ per coordinate; the
/// symmetric transfer distance (H, affine) is ≈ 2σ at noise σ in both images, and the subspace
/// distance / √F ≈ √2·σ. Inliers are the rows with residual ≤ 3 × `sigma`.
///
/// A `Degenerate` fit has `rms` = `sigma` = `f64::INFINITY` and no inliers.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    pub model: Model,
    pub rms: f64,
    pub inliers: Vec<bool>,
    pub sigma: f64,
}

/// Fits the best model of `family` to `rows` (each row one point, all the same width),
/// robustly; the type is chosen by GRIC among [`Family::candidates`].
/// Too few points, collinear points (for conics/homographies), coincident points, pure
/// translation for F, non-finite data etc. give `Model::Degenerate { reason }` with a readable
/// reason — never NaN, never a panic.
pub fn fit(family: Family, rows: &[&[f64]]) -> Fit {
    select::fit_family(family, rows)
}

/// [`fit`], where `known` is a fit of one of the family's curve types on exactly `rows`
/// (refinement's last round): that candidate is not fitted again.
pub fn fit_knowing(family: Family, rows: &[&[f64]], known: &Fit) -> Fit {
    select::fit_family_knowing(family, rows, Some(known))
}

/// Fits exactly one model type by name (`"line"`, `"circle"`, `"ellipse"`, `"homography"`,
/// `"affine"`, `"fundamental"`, `"subspace"`), robustly; `None` for any other name. Degenerate
/// input gives `Some` fit with `Model::Degenerate`.
pub fn fit_type(type_name: &str, rows: &[&[f64]]) -> Option<Fit> {
    select::fit_one(type_name, rows)
}

/// A circle or an ellipse fitted again on `rows`, started from `model`: for rows that moved a
/// little since `model` was fitted (refinement's rounds). `None` for other models, or where the
/// start cannot be evaluated: fit from scratch then ([`fit_type`]).
pub fn refit_curve(model: &Model, rows: &[&[f64]]) -> Option<Fit> {
    select::refit_curve(model, rows)
}

/// The plain least-squares fit of one type by name (no robust loop, no geometric refinement):
/// a cheap proposal for refinement's hypotheses, not an answer. `None` for an unknown name or
/// rows that do not determine the model; never a degenerate model.
pub fn fit_plain(type_name: &str, rows: &[&[f64]]) -> Option<Model> {
    select::fit_plain(type_name, rows)
}

/// Why a group's rows do not determine a model of a type. Its text is the `reason` of
/// [`Model::Degenerate`] (part of the JSON API: keep the messages as they are).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryError {
    // The rows themselves ([`validate`]).
    #[error("no points")]
    NoPoints,
    #[error("rows have {width} values, expected {expected}")]
    WrongWidth { width: usize, expected: usize },
    #[error("rows have {width} values: a trajectory holds 2F ≥ 4 (F frames)")]
    TrajectoryWidth { width: usize },
    #[error("row {row} has {found} values, row 0 has {expected}")]
    Ragged {
        row: usize,
        found: usize,
        expected: usize,
    },
    #[error("row {row} holds a non-finite value")]
    NonFinite { row: usize },
    #[error("row {row} holds a value beyond ±{max:e}", max = MAX_COORDINATE)]
    TooLarge { row: usize },
    /// A name [`fit_type`] does not know (never reaches an answer: unknown names give `None`).
    #[error("unknown model type {0:?}")]
    UnknownType(String),

    // Too few points, or no weight on them.
    #[error("{n} points, at least {min} needed")]
    TooFewPoints { n: usize, min: usize },
    #[error("{n} correspondences, at least {min} needed")]
    TooFewCorrespondences { n: usize, min: usize },
    #[error("fewer than {min} correspondences")]
    FewerCorrespondences { min: usize },
    #[error("{n} trajectories, at least {min} needed")]
    TooFewTrajectories { n: usize, min: usize },
    #[error("no points with weight")]
    NoWeightedPoints,
    #[error("no trajectories with weight")]
    NoWeightedTrajectories,

    // Points in special position.
    #[error("all points coincide")]
    Coincident,
    #[error("all points of image {image} coincide")]
    CoincidentImage { image: u8 },
    #[error("all trajectories coincide")]
    CoincidentTrajectories,
    #[error("points are collinear")]
    Collinear,
    #[error("points of image {image} are collinear")]
    CollinearImage { image: u8 },

    // Conics.
    #[error("no circle fits the points")]
    NoCircle,
    #[error("points are nearly collinear (circle radius {radius:.3e} × their spread)")]
    FlatCircle { radius: f64 },
    #[error("points do not determine a conic")]
    NoConic,
    #[error("fewer than 5 points in general position: the conic is not determined")]
    ConicUndetermined,
    #[error("no ellipse fits the points")]
    NoEllipse,
    #[error("no ellipse fits the points (the best conic is not a real ellipse)")]
    NotRealEllipse,
    #[error("points are nearly collinear (ellipse axis {axis:.3e} × their spread)")]
    FlatEllipse { axis: f64 },

    // Two-view models.
    #[error("correspondences do not determine a homography (fewer than 4 in general position)")]
    HomographyUndetermined,
    #[error("no homography fits")]
    NoHomography,
    #[error("the homography is singular")]
    SingularHomography,
    #[error("the affine map is singular")]
    SingularAffine,
    #[error(
        "correspondences do not determine a fundamental matrix (planar scene, pure rotation or pure image translation: a homography explains them)"
    )]
    FundamentalUndetermined,
    #[error("no fundamental matrix fits")]
    NoFundamental,
}

/// Checks the rows of one group: at least one; all of width `width` (or, for `None`,
/// trajectories: one even width ≥ 4); every value finite and within ±[`MAX_COORDINATE`].
fn validate(rows: &[&[f64]], width: Option<usize>) -> Result<(), GeometryError> {
    let Some(first) = rows.first() else {
        return Err(GeometryError::NoPoints);
    };
    let w = first.len();
    match width {
        Some(want) if w != want => {
            return Err(GeometryError::WrongWidth {
                width: w,
                expected: want,
            });
        }
        None if w < 4 || w % 2 == 1 => {
            return Err(GeometryError::TrajectoryWidth { width: w });
        }
        _ => {}
    }
    for (i, row) in rows.iter().enumerate() {
        if row.len() != w {
            return Err(GeometryError::Ragged {
                row: i,
                found: row.len(),
                expected: w,
            });
        }
        if row.iter().any(|v| !v.is_finite()) {
            return Err(GeometryError::NonFinite { row: i });
        }
        if row.iter().any(|v| v.abs() > MAX_COORDINATE) {
            return Err(GeometryError::TooLarge { row: i });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::testutil::{Rng, assert_sane, view};
    use super::*;

    /// One model of every variant, with realistic numbers.
    fn every_variant() -> Vec<Model> {
        vec![
            Model::Line {
                a: 0.6,
                b: 0.8,
                c: -1.5,
            },
            Model::Circle {
                cx: 1.0,
                cy: -2.0,
                r: 3.5,
            },
            Model::Ellipse {
                cx: 0.5,
                cy: 0.25,
                a: 2.0,
                b: 1.25,
                theta: -0.3,
            },
            Model::Homography {
                h: [0.9, 0.1, 3.0, -0.05, 1.1, -2.0, 1e-4, -2e-4, 1.0],
            },
            Model::Fundamental {
                f: [0.0, -1e-3, 0.2, 1e-3, 0.0, -0.3, -0.2, 0.3, 0.0],
            },
            Model::Affine {
                a: [1.1, 0.2, 15.0, -0.1, 0.9, -7.0],
            },
            Model::Subspace {
                rank: 1,
                mean: vec![1.0, 2.0, 3.0, 4.0],
                basis: vec![vec![0.5, 0.5, 0.5, 0.5]],
            },
            Model::Degenerate {
                reason: "all points coincide".into(),
            },
        ]
    }

    /// The moves of views shifted by −o1 and −o2.
    fn shifted_back(o1: [f64; 2], o2: [f64; 2]) -> [ViewMove; 2] {
        [(1.0, [-o1[0], -o1[1]]), (1.0, [-o2[0], -o2[1]])]
    }

    #[test]
    fn models_fitted_on_shifted_views_fit_the_views_as_sent() {
        // Correspondences 3e7 px from the origin in both views: fitted as sent, a homography
        // is too ill-conditioned to invert; fitted with each view shifted back, and brought
        // back, it maps the pairs as sent.
        let (o1, o2) = ([3e7, -3e7], [3e7 + 512.0, 2e7]);
        let h = [1.1, 0.05, 12.0, -0.03, 0.95, -7.0, 2e-4, -1e-4, 1.0];
        let a = [0.9, 0.1, 15.0, -0.2, 1.05, 4.0];
        let affine_h = [a[0], a[1], a[2], a[3], a[4], a[5], 0.0, 0.0, 1.0];
        let pairs_of = |m: &[f64; 9]| -> Vec<[f64; 4]> {
            (0..12)
                .map(|i| {
                    let (x, y) = (40.0 * (i % 4) as f64 + 50.0, 60.0 * (i / 4) as f64 + 30.0);
                    let w = m[6] * x + m[7] * y + m[8];
                    [
                        x,
                        y,
                        (m[0] * x + m[1] * y + m[2]) / w,
                        (m[3] * x + m[4] * y + m[5]) / w,
                    ]
                })
                .collect()
        };
        for (truth, pairs) in [
            (Model::Homography { h }, pairs_of(&h)),
            (Model::Affine { a }, pairs_of(&affine_h)),
        ] {
            let rows: Vec<Vec<f64>> = pairs.iter().map(|p| p.to_vec()).collect();
            let refs: Vec<&[f64]> = rows.iter().map(Vec::as_slice).collect();
            let fitted = fit_type(truth.type_name(), &refs).unwrap().model;
            let back = fitted.views_unmoved(shifted_back(o1, o2));
            for p in &pairs {
                let sent = [p[0] + o1[0], p[1] + o1[1], p[2] + o2[0], p[3] + o2[1]];
                // Measured at 3e7 px, the residual carries the rounding of a map that far out
                // (a wrong shift would miss by thousands of pixels).
                let r = back.residual(&sent);
                assert!(r < 0.1, "{}: {r}", truth.type_name());
            }
        }
        // x₂ᵀ·F·x₁ = (x₂ − o₂)ᵀ·F'·(x₁ − o₁): one ratio for every pair (F's gauge).
        let f_shifted = [0.0, -1e-3, 0.2, 1e-3, 0.0, -0.3, -0.2, 0.3, 0.0];
        let (o1, o2) = ([1000.0, -2000.0], [300.0, 700.0]);
        let Model::Fundamental { f } =
            (Model::Fundamental { f: f_shifted }).views_unmoved(shifted_back(o1, o2))
        else {
            panic!("not a fundamental matrix");
        };
        let epi = |f: &[f64; 9], [x, y, u, v]: [f64; 4]| {
            u * (f[0] * x + f[1] * y + f[2])
                + v * (f[3] * x + f[4] * y + f[5])
                + (f[6] * x + f[7] * y + f[8])
        };
        let ratios: Vec<f64> = [[10.0, 20.0, 300.0, 40.0], [-5.0, 7.0, 12.0, 640.0]]
            .into_iter()
            .map(|p| {
                let sent = [p[0] + o1[0], p[1] + o1[1], p[2] + o2[0], p[3] + o2[1]];
                epi(&f, sent) / epi(&f_shifted, p)
            })
            .collect();
        assert!(ratios[0].is_finite() && ratios[0] != 0.0);
        assert!(
            (ratios[0] - ratios[1]).abs() < 1e-9 * ratios[0].abs(),
            "{ratios:?}"
        );
    }

    #[test]
    fn a_model_fitted_on_a_moved_second_view_fits_the_view_as_sent() {
        // Correspondences of a known homography, affine map and epipolar geometry, their second
        // view moved by x' = s·x + t before the fit: each model of the moved pairs, brought
        // back, fits the pairs as sent.
        let (s, t) = (0.5, [160.0, 120.0]);
        let moved = |p: [f64; 4]| [p[0], p[1], s * p[2] + t[0], s * p[3] + t[1]];
        let h = [1.1, 0.05, 12.0, -0.03, 0.95, -7.0, 2e-4, -1e-4, 1.0];
        let a = [0.9, 0.1, 15.0, -0.2, 1.05, 4.0];
        let pairs_of = |m: &[f64; 9]| -> Vec<[f64; 4]> {
            (0..12)
                .map(|i| {
                    let (x, y) = (40.0 * (i % 4) as f64 + 50.0, 60.0 * (i / 4) as f64 + 30.0);
                    let w = m[6] * x + m[7] * y + m[8];
                    let u = (m[0] * x + m[1] * y + m[2]) / w;
                    let v = (m[3] * x + m[4] * y + m[5]) / w;
                    [x, y, u, v]
                })
                .collect()
        };
        let affine_h = [a[0], a[1], a[2], a[3], a[4], a[5], 0.0, 0.0, 1.0];
        for (truth, pairs) in [
            (Model::Homography { h }, pairs_of(&h)),
            (Model::Affine { a }, pairs_of(&affine_h)),
        ] {
            let rows: Vec<Vec<f64>> = pairs.iter().map(|&p| moved(p).to_vec()).collect();
            let refs: Vec<&[f64]> = rows.iter().map(Vec::as_slice).collect();
            let fitted = fit_type(truth.type_name(), &refs).unwrap().model;
            let back = fitted.views_unmoved([UNMOVED, (s, t)]);
            for p in &pairs {
                let r = back.residual(p);
                assert!(r < 1e-6, "{}: {r}", truth.type_name());
            }
        }
        // F' of the moved view, F = Aᵀ·F' of the view as sent: x₂ᵀ·F·x₁ = x₂'ᵀ·F'·x₁ = 0.
        let f_moved = [0.0, -1e-3, 0.2, 1e-3, 0.0, -0.3, -0.2, 0.3, 0.0];
        let back = Model::Fundamental { f: f_moved }.views_unmoved([UNMOVED, (s, t)]);
        let Model::Fundamental { f } = back else {
            panic!("not a fundamental matrix");
        };
        let norm = f.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!((norm - 1.0).abs() < 1e-12);
        // x₂ᵀ·F·x₁ is x₂'ᵀ·F'·x₁ up to F's gauge: one ratio for every pair.
        let ratios: Vec<f64> = [(10.0, 20.0, 300.0, 40.0), (-5.0, 7.0, 12.0, 640.0)]
            .into_iter()
            .map(|(x, y, u, v)| {
                let epi = |f: &[f64; 9], u: f64, v: f64| {
                    u * (f[0] * x + f[1] * y + f[2])
                        + v * (f[3] * x + f[4] * y + f[5])
                        + (f[6] * x + f[7] * y + f[8])
                };
                epi(&f, u, v) / epi(&f_moved, s * u + t[0], s * v + t[1])
            })
            .collect();
        assert!(ratios[0].is_finite() && ratios[0] != 0.0);
        assert!(
            (ratios[0] - ratios[1]).abs() < 1e-9 * ratios[0].abs(),
            "{ratios:?}"
        );
        // Models of one view do not move.
        let line = Model::Line {
            a: 0.6,
            b: 0.8,
            c: -3.0,
        };
        assert_eq!(line.views_unmoved([UNMOVED, (s, t)]), line);
    }

    #[test]
    fn every_variant_round_trips_through_json() {
        for m in every_variant() {
            let json = serde_json::to_string(&m).unwrap();
            let back: Model = serde_json::from_str(&json).unwrap();
            assert_eq!(back, m, "{json}");
            let v: serde_json::Value = serde_json::from_str(&json).unwrap();
            assert_eq!(v["type"], m.type_name(), "{json}");
        }
        // The documented shape.
        let json = serde_json::to_string(&Model::Circle {
            cx: 1.0,
            cy: 2.0,
            r: 3.0,
        })
        .unwrap();
        assert_eq!(
            json,
            r#"{"type":"circle","params":{"cx":1.0,"cy":2.0,"r":3.0}}"#
        );
        // Fitted models too (long decimals survive).
        let mut rng = Rng::new(1);
        let rows: Vec<Vec<f64>> = (0..30)
            .map(|i| {
                let t = i as f64 * 0.2;
                vec![
                    1.5 * t.cos() + 0.01 * rng.normal(),
                    1.5 * t.sin() + 0.01 * rng.normal(),
                ]
            })
            .collect();
        for name in ["line", "circle", "ellipse"] {
            let m = fit_type(name, &view(&rows)).unwrap().model;
            let back: Model = serde_json::from_str(&serde_json::to_string(&m).unwrap()).unwrap();
            assert_eq!(back, m);
        }
    }

    #[test]
    fn family_wire_names() {
        for (f, name) in [
            (Family::Curves, "\"curves\""),
            (Family::Homography, "\"homography\""),
            (Family::Fundamental, "\"fundamental\""),
            (Family::Subspace, "\"subspace\""),
        ] {
            assert_eq!(serde_json::to_string(&f).unwrap(), name);
            assert_eq!(serde_json::from_str::<Family>(name).unwrap(), f);
            assert!(!f.candidates().is_empty());
        }
    }

    #[test]
    fn residual_is_never_nan() {
        let extremes = [
            0.0,
            1.0,
            -1.0,
            1e-300,
            1e300,
            -1e300,
            f64::MAX,
            f64::MIN_POSITIVE,
        ];
        let mut rng = Rng::new(2);
        for m in every_variant() {
            for width in [1, 2, 3, 4, 6] {
                for _ in 0..200 {
                    let row: Vec<f64> = (0..width)
                        .map(|_| {
                            if rng.uniform() < 0.3 {
                                extremes[(rng.uniform() * extremes.len() as f64) as usize
                                    % extremes.len()]
                            } else {
                                100.0 * rng.normal()
                            }
                        })
                        .collect();
                    let r = m.residual(&row);
                    assert!(!r.is_nan() && r >= 0.0, "{m:?} {row:?}: {r}");
                }
            }
            // Non-finite input, and the points at the epipoles / centres.
            assert_eq!(m.residual(&[f64::NAN, 0.0]), f64::INFINITY);
            assert_eq!(m.residual(&[f64::INFINITY, 0.0, 1.0, 2.0]), f64::INFINITY);
        }
        // Wrong widths answer INFINITY.
        assert_eq!(
            Model::Line {
                a: 1.0,
                b: 0.0,
                c: 0.0
            }
            .residual(&[1.0, 2.0, 3.0]),
            f64::INFINITY
        );
        assert_eq!(
            Model::Fundamental { f: [0.0; 9] }.residual(&[1.0, 2.0]),
            f64::INFINITY
        );
        assert_eq!(
            Model::Degenerate { reason: "x".into() }.residual(&[1.0, 2.0]),
            f64::INFINITY
        );
        // Degenerate parameters never NaN either.
        for m in [
            Model::Circle {
                cx: 0.0,
                cy: 0.0,
                r: f64::NAN,
            },
            Model::Ellipse {
                cx: 0.0,
                cy: 0.0,
                a: 0.0,
                b: 1.0,
                theta: 0.0,
            },
            Model::Homography { h: [0.0; 9] },
            Model::Fundamental { f: [0.0; 9] },
            Model::Line {
                a: 0.0,
                b: 0.0,
                c: 1.0,
            },
        ] {
            let r = m.residual(
                &[1.0, 2.0, 3.0, 4.0][..if m.type_name() == "homography"
                    || m.type_name() == "fundamental"
                {
                    4
                } else {
                    2
                }],
            );
            assert!(!r.is_nan(), "{m:?}");
        }
    }

    #[test]
    fn degenerate_inputs_never_give_nan_or_panic() {
        let huge = [1e300, -1e300];
        let cases: Vec<(&str, Vec<Vec<f64>>)> = vec![
            ("line", vec![]),
            ("line", vec![vec![1.0, 2.0]]),
            ("circle", vec![vec![1.0, 2.0], vec![3.0, 4.0]]),
            ("ellipse", vec![vec![1.0, 2.0]; 12]),
            (
                "circle",
                (0..10).map(|i| vec![i as f64, 2.0 * i as f64]).collect(),
            ),
            (
                "ellipse",
                (0..10).map(|i| vec![i as f64, -(i as f64)]).collect(),
            ),
            (
                "homography",
                (0..10)
                    .map(|i| vec![i as f64, 0.5 * i as f64, 2.0 * i as f64, 1.0])
                    .collect(),
            ),
            ("affine", vec![vec![1.0, 2.0, 3.0, 4.0]; 2]),
            (
                "fundamental",
                (0..7)
                    .map(|i| vec![i as f64, (i * i) as f64, 1.0 + i as f64, 3.0])
                    .collect(),
            ),
            ("subspace", vec![vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]; 2]),
            (
                "line",
                vec![vec![1.0, 2.0], vec![huge[0], huge[1]], vec![3.0, 1.0]],
            ),
            (
                "circle",
                vec![
                    vec![0.0, 1.0],
                    vec![1.0, 0.0],
                    vec![huge[0], huge[0]],
                    vec![-1.0, 0.0],
                ],
            ),
            (
                "homography",
                vec![
                    vec![1.0, 2.0, 3.0, 4.0],
                    vec![huge[0]; 4],
                    vec![5.0, 1.0, 2.0, 2.0],
                    vec![7.0, 3.0, 1.0, 1.0],
                ],
            ),
            (
                "fundamental",
                (0..12)
                    .map(|i| {
                        if i == 5 {
                            vec![huge[1]; 4]
                        } else {
                            vec![i as f64, (i * i) as f64, 1.0, i as f64]
                        }
                    })
                    .collect(),
            ),
            (
                "subspace",
                vec![
                    vec![1.0, 2.0, 3.0, 4.0],
                    vec![huge[0]; 4],
                    vec![0.0, 1.0, 2.0, 5.0],
                ],
            ),
            (
                "line",
                vec![vec![1.0, f64::NAN], vec![2.0, 3.0], vec![4.0, 1.0]],
            ),
            ("homography", vec![vec![1.0, 2.0, f64::INFINITY, 4.0]; 5]),
            ("circle", vec![vec![1.0, 2.0, 3.0]; 5]),
            ("subspace", vec![vec![1.0, 2.0, 3.0]; 5]),
            ("line", vec![vec![1.0, 2.0], vec![1.0, 2.0, 3.0]]),
        ];
        for (name, rows) in &cases {
            let fit = fit_type(name, &view(rows)).unwrap();
            assert!(fit.model.is_degenerate(), "{name} {rows:?}: {fit:?}");
            assert_sane(&fit, rows.len());
            if let Model::Degenerate { reason } = &fit.model {
                assert!(reason.len() > 5, "readable reason: {reason}");
            }
        }
        for family in [
            Family::Curves,
            Family::Homography,
            Family::Fundamental,
            Family::Subspace,
        ] {
            for (_, rows) in &cases {
                let fit = fit(family, &view(rows));
                assert_sane(&fit, rows.len());
            }
        }
    }

    #[test]
    fn fits_are_deterministic() {
        let mut rng = Rng::new(3);
        let curve: Vec<Vec<f64>> = (0..80)
            .map(|_| {
                let t = rng.range(0.0, 6.0);
                vec![
                    2.0 * t.cos() + 0.05 * rng.normal(),
                    t.sin() + 0.05 * rng.normal(),
                ]
            })
            .collect();
        let pairs: Vec<Vec<f64>> = (0..80)
            .map(|_| {
                let (x, y) = (rng.range(0.0, 640.0), rng.range(0.0, 480.0));
                vec![
                    x,
                    y,
                    x + 0.01 * y + 3.0 + rng.normal(),
                    y - 0.02 * x + rng.normal(),
                ]
            })
            .collect();
        for (family, rows) in [
            (Family::Curves, &curve),
            (Family::Fundamental, &pairs),
            (Family::Homography, &pairs),
        ] {
            let a = fit(family, &view(rows));
            let b = fit(family, &view(rows));
            assert_eq!(a, b);
            let bits = |f: &Fit| -> Vec<u64> {
                super::testutil::model_numbers(&f.model)
                    .iter()
                    .chain([f.rms, f.sigma].iter())
                    .map(|v| v.to_bits())
                    .collect()
            };
            assert_eq!(bits(&a), bits(&b), "bit for bit");
        }
    }

    #[test]
    fn error_texts_are_the_degenerate_reasons() {
        // The text is the wire's `reason`: these are the messages as they were written.
        for (e, text) in [
            (
                GeometryError::TooLarge { row: 2 },
                "row 2 holds a value beyond ±1e150",
            ),
            (
                GeometryError::FlatCircle { radius: 12345.678 },
                "points are nearly collinear (circle radius 1.235e4 × their spread)",
            ),
            (
                GeometryError::FundamentalUndetermined,
                "correspondences do not determine a fundamental matrix (planar scene, pure \
                 rotation or pure image translation: a homography explains them)",
            ),
            (
                GeometryError::CollinearImage { image: 2 },
                "points of image 2 are collinear",
            ),
        ] {
            assert_eq!(e.to_string(), text);
        }
        let f = fit_type("homography", &[&[1.0, 2.0][..]]).unwrap();
        assert_eq!(
            f.model,
            Model::Degenerate {
                reason: "rows have 2 values, expected 4".into()
            }
        );
    }

    #[test]
    fn names_and_counts() {
        assert!(fit_type("parabola", &[&[1.0, 2.0][..]]).is_none());
        assert!(fit_type("degenerate", &[&[1.0, 2.0][..]]).is_none());
        let counts: Vec<usize> = every_variant().iter().map(Model::min_points).collect();
        assert_eq!(counts, vec![2, 3, 5, 4, 8, 3, 2, 0]);
        assert!(
            Model::Degenerate {
                reason: String::new()
            }
            .is_degenerate()
        );
        assert!(
            !Model::Line {
                a: 1.0,
                b: 0.0,
                c: 0.0
            }
            .is_degenerate()
        );
    }
}
