//! Synthetic two-view correspondences: planes seen by two cameras (homographies) or
//! independently moving rigid objects seen by two views (fundamental matrices), with pixel noise
//! and gross outliers (the data AdelaideRMF holds).
//!
//! **Cameras.** World coordinates are camera 1's frame (x right, y down, z forward). Both views
//! are pinholes with square pixels, no skew and the principal point at the image centre, on one
//! image size `W x H` px (each uniform in the `--width` / `--height` range, rounded to whole
//! pixels, default 400 to 1280 by 300 to 960, which holds AdelaideRMF's 455x341 to 980x735).
//! View 1 has focal `f1` uniform in the `--focal` range (default 300 to 1500 px), view 2
//! `f2 = f1 * z` with the zoom `z` log-uniform in [`ZOOM`] = `[1/1.2, 1.2]`:
//! `K_i = [[f_i, 0, W/2], [0, f_i, H/2], [0, 0, 1]]`.
//! - Camera 1 is `K1 [I | 0]`.
//! - Camera 2 fixates the point `Q = (0, 0, d)` on camera 1's axis, `d` uniform in [`FIXATION`]
//!   = 6 to 10. Its centre is `C2 = b d e`, `e` uniform on the unit sphere and the baseline ratio
//!   `b` uniform in [`BASELINE`] = 0.05 to 0.3. Its camera-to-world rotation is
//!   `R2 = P * L * Rz(roll)`: `L` looks from `C2` at `Q` (z axis `Q - C2`, x axis
//!   `y_world x z`), `roll` uniform in +-[`ROLL`] = 10 degrees about its axis, and `P` a
//!   perturbation of axis uniform on the sphere and angle uniform in `[0, `[`TILT`]` = 5]` degrees.
//!   A world point X is at `X_2 = R X + t` in camera 2, `R = R2^T`, `t = -R2^T C2`.
//!
//! A point is seen by a view when its depth there is at least [`NEAR`] = 0.5 and its (noisy)
//! pixel lies in `[0, W) x [0, H)`.
//!
//! **Mode `homography`.** `K` planes (uniform in the `--groups` range, default 2 to 6). A plane
//! passes through the back-projection `c` of a pixel uniform in the central 80% of image 1
//! (`[0.1 W, 0.9 W] x [0.1 H, 0.9 H]`) at a depth uniform in [`PLANE_DEPTH`] = 4 to 12; its unit
//! normal `n` makes an angle uniform in `[0, `[`TILT_PLANE`]` = 60]` degrees (azimuth uniform)
//! with the direction from `c` to camera 1, and is drawn again until it also faces camera 2
//! (cosine with `C2 - c` at least [`FACING`] = 0.17, i.e. within 80 degrees). Its points are
//! uniform in the square of half-size `U(0.15, 0.4) * depth * min(W, H) / (2 f1)` around `c` in
//! the plane (15% to 40% of the half-image across). With `n^T X = d_p` the plane, its group's
//! model is `H = K2 (R + t n^T / d_p) K1^-1` (x2 ~ H x1).
//!
//! **Mode `fundamental`.** `K` rigid objects (`--groups`, default 2 to 5), each moving between
//! the views. An object is a cloud uniform in a cube of half-size
//! `r = min(U(0.1, 0.3) * depth * min(W, H) / (2 f1), 0.4 depth)`, turned by a random rotation
//! (axis uniform on the sphere, angle uniform in `[0, pi)`), centred on the back-projection `c`
//! of a pixel uniform in the central 80% of image 1 at a depth uniform in [`OBJ_DEPTH`] = 4 to
//! 12. Between the views it turns about `c` by `R_j` (axis uniform on the sphere, angle uniform
//! in `[0, `[`OBJ_TURN`]` = 15]` degrees) and moves by `t_j` (direction uniform on the sphere,
//! length uniform in [`OBJ_SHIFT`] = 0.02 to 0.15 times its depth): view 2 sees
//! `X' = R_j (X - c) + c + t_j`. So camera 2 sees the object through `R' = R2^T R_j`,
//! `t' = R2^T (c + t_j - R_j c - C2)`, and its group's model is `F = K2^-T [t']_x R' K1^-1`
//! (x2^T F x1 = 0). A motion with `|t'|` below [`MIN_TRANSLATION`] = 0.02 times the depth (nearly
//! a rotation about camera 2's centre, where F is not determined) is drawn again.
//!
//! Each group has `n` correspondences, `n` uniform in the `--points` range (default 30 to 150;
//! at least 4 for homographies and 8 for fundamental matrices, what determines the model).
//!
//! **Noise.** Isotropic Gaussian noise of sigma px on every coordinate of both images, sigma
//! uniform per sample in the `--noise` range (default 0 to 1 px; at most 20 px and at most 1/16
//! of the smallest image side the `--width` / `--height` ranges allow).
//!
//! **Visibility.** A correspondence is drawn (point, both projections, noise) and kept only when
//! it is seen by both views; otherwise it is drawn again. A group that has not found its `n`
//! correspondences after `ATTEMPTS_PER_POINT * n + ATTEMPTS_EXTRA` ([`ATTEMPTS_PER_POINT`] = 50,
//! [`ATTEMPTS_EXTRA`] = 1000) draws is itself drawn again (a new plane or object), up to
//! [`GROUP_TRIES`] = 20 times; then the whole scene (cameras and groups; counts, image, focal and
//! noise kept) is drawn again, until every group is found.
//!
//! **Gross outliers**, as AdelaideRMF's: a fraction `phi` of all rows (uniform per sample in the
//! `--outliers` range, `0 <= phi < 1`, default 0 to 0.5; AdelaideRMF has 6% to 77%) is
//! `round(phi / (1 - phi) * inliers)` pairs of independent points uniform in image 1 and in
//! image 2.
//!
//! **Labels**, as AdelaideRMF's load: in files, raw label 0 is the outliers and the groups are
//! 1..=K, `model_type` is `homography` or `fundamental`. In the [`Sample`]: without outliers the
//! groups are 0..K; with outliers label 0 is the outlier group, the groups 1..=K, and `k` counts
//! the outlier group. Rows `[x1, y1, x2, y2]` px (kind `correspondences`), shuffled, with
//! `image_size` set.
//!
//! **Spec.** `--data twoview:<homography|fundamental>[,count=N][,seed=S][,groups=A-B]
//! [,points=A-B][,noise=A-B][,outliers=A-B][,focal=A-B][,width=A-B][,height=A-B]` generates in
//! memory ([`TwoViewSpec`]; defaults: 200 samples, seed 0, [`TwoViewParams::new`] of the mode);
//! one value `A` is the range `A-A`.

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal, UnitSphere};

use super::dataset::{
    DataError, Sample, Sequence, SequenceFile, Setting, SpecError, check_count, load_files,
};
use super::motion::{V3, add, log_uniform, random_rotation, scale, sub, uniform};
use super::points::{ImageSize, Kind, PointSet};
use super::ranges::{RangeError, check_range, range_text};
use crate::geometry::linalg::{
    Mat3, mat3_inverse, mat3_mul, mat3_transpose, mat3_vec, rodrigues, unit_norm_sign,
};

/// Nearest depth at which a view sees a point.
pub const NEAR: f64 = 0.5;
/// Range of view 2's focal length over view 1's (log-uniform).
pub const ZOOM: [f64; 2] = [1.0 / 1.2, 1.2];
/// Depth range of the point both cameras look at.
pub const FIXATION: [f64; 2] = [6.0, 10.0];
/// Baseline length as a fraction of the fixation depth.
pub const BASELINE: [f64; 2] = [0.05, 0.3];
/// Largest roll of camera 2 about its axis, degrees.
pub const ROLL: f64 = 10.0;
/// Largest deviation of camera 2's axis from the fixation point, degrees.
pub const TILT: f64 = 5.0;
/// Depth range of a plane's centre.
pub const PLANE_DEPTH: [f64; 2] = [4.0, 12.0];
/// Largest angle between a plane's normal and the direction to camera 1, degrees.
pub const TILT_PLANE: f64 = 60.0;
/// Smallest cosine between a plane's normal and the direction to camera 2.
pub const FACING: f64 = 0.17;
/// A plane's half-size as a fraction of the half-image it spans at its depth.
pub const PLANE_SIZE: [f64; 2] = [0.15, 0.4];
/// Depth range of an object's centre.
pub const OBJ_DEPTH: [f64; 2] = [4.0, 12.0];
/// An object's half-size as a fraction of the half-image it spans at its depth.
pub const OBJ_SIZE: [f64; 2] = [0.1, 0.3];
/// Largest turn of an object between the views, degrees.
pub const OBJ_TURN: f64 = 15.0;
/// Range of an object's shift between the views, as a fraction of its depth.
pub const OBJ_SHIFT: [f64; 2] = [0.02, 0.15];
/// Smallest translation of camera 2 relative to an object, as a fraction of its depth.
pub const MIN_TRANSLATION: f64 = 0.02;
/// Draws per wanted correspondence before a group is drawn again (plus [`ATTEMPTS_EXTRA`]).
pub const ATTEMPTS_PER_POINT: usize = 50;
/// Draws a group may spend beyond `ATTEMPTS_PER_POINT` per correspondence.
pub const ATTEMPTS_EXTRA: usize = 1000;
/// Times a group is drawn again before the whole scene is.
pub const GROUP_TRIES: usize = 20;

/// What the groups of a sample are.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum TwoViewMode {
    /// Planes: each group's matches are related by a homography.
    Homography,
    /// Rigid objects moving independently: each group has its fundamental matrix.
    Fundamental,
}

impl TwoViewMode {
    /// Its name in specs, sample names and files' `model_type` (AdelaideRMF's).
    pub fn as_str(self) -> &'static str {
        match self {
            TwoViewMode::Homography => "homography",
            TwoViewMode::Fundamental => "fundamental",
        }
    }

    /// Correspondences that determine a group's model: 4 for H, 8 for F.
    pub fn min_points(self) -> usize {
        match self {
            TwoViewMode::Homography => 4,
            TwoViewMode::Fundamental => 8,
        }
    }
}

/// Generator settings: the mode, then inclusive ranges `[min, max]` a sample draws its values
/// from (see the module docs for the distributions and [`TwoViewParams::validate`] for the
/// limits).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TwoViewParams {
    pub mode: TwoViewMode,
    /// Planes or objects per sample (`--groups`, 1 to [`TwoViewParams::MAX_GROUPS`]).
    pub groups: [usize; 2],
    /// Correspondences per group (`--points`, [`TwoViewMode::min_points`] to
    /// [`TwoViewParams::MAX_POINTS`]).
    pub points: [usize; 2],
    /// Noise sigma, px per coordinate (`--noise`, 0 to [`TwoViewParams::MAX_NOISE`]).
    pub noise: [f64; 2],
    /// Fraction of all rows that are gross outliers (`--outliers`, in `[0, 1)`).
    pub outliers: [f64; 2],
    /// View 1's focal length, px (`--focal`, 50 to 1e5).
    pub focal: [f64; 2],
    /// Image width, px (`--width`, 64 to 1e5).
    pub width: [f64; 2],
    /// Image height, px (`--height`, 64 to 1e5).
    pub height: [f64; 2],
}

impl TwoViewParams {
    /// Most groups a sample may have.
    pub const MAX_GROUPS: usize = 10;
    /// Most correspondences per group.
    pub const MAX_POINTS: usize = 100_000;
    /// Largest noise, px.
    pub const MAX_NOISE: f64 = 20.0;
    /// The smallest image side must be at least this many times the largest noise.
    pub const NOISE_TO_IMAGE: f64 = 16.0;
    /// Most rows (inliers and outliers) one sample may reach.
    pub const MAX_ROWS: usize = 10_000_000;

    /// The defaults of a mode: 2 to 6 planes or 2 to 5 objects, 30 to 150 correspondences each,
    /// noise 0 to 1 px, outlier fraction 0 to 0.5, focal 300 to 1500 px, images 400 to 1280 by
    /// 300 to 960 px.
    pub fn new(mode: TwoViewMode) -> Self {
        Self {
            mode,
            groups: match mode {
                TwoViewMode::Homography => [2, 6],
                TwoViewMode::Fundamental => [2, 5],
            },
            points: [30, 150],
            noise: [0.0, 1.0],
            outliers: [0.0, 0.5],
            focal: [300.0, 1500.0],
            width: [400.0, 1280.0],
            height: [300.0, 960.0],
        }
    }

    /// Checks the settings a generator can draw from; the error names the flag.
    pub fn validate(&self) -> Result<(), RangeError> {
        check_range(
            "--groups",
            self.groups,
            (1, Self::MAX_GROUPS, false),
            "groups",
        )?;
        check_range(
            "--points",
            self.points,
            (self.mode.min_points(), Self::MAX_POINTS, false),
            &format!("{} correspondences per group", self.mode.as_str()),
        )?;
        check_range(
            "--noise",
            self.noise,
            (0.0, Self::MAX_NOISE, false),
            "noise (px)",
        )?;
        check_range(
            "--outliers",
            self.outliers,
            (0.0, 1.0, true),
            "the outlier fraction",
        )?;
        check_range("--focal", self.focal, (50.0, 1e5, false), "focal (px)")?;
        check_range("--width", self.width, (64.0, 1e5, false), "width (px)")?;
        check_range("--height", self.height, (64.0, 1e5, false), "height (px)")?;
        let side = self.width[0].min(self.height[0]).round();
        if self.noise[1] * Self::NOISE_TO_IMAGE > side {
            return Err(RangeError::OutOfRange {
                flag: "--noise",
                value: range_text(self.noise),
                reason: format!(
                    "noise up to {} px needs images of at least {} px a side, and the smallest may be {side}",
                    self.noise[1],
                    self.noise[1] * Self::NOISE_TO_IMAGE
                ),
            });
        }
        let inliers = (self.groups[1] * self.points[1]) as f64;
        let rows = inliers + (self.outliers[1] / (1.0 - self.outliers[1]) * inliers).round();
        if rows > Self::MAX_ROWS as f64 {
            return Err(RangeError::OutOfRange {
                flag: "--outliers",
                value: range_text(self.outliers),
                reason: format!(
                    "with up to {inliers} correspondences this gives up to {rows} rows, above {}",
                    Self::MAX_ROWS
                ),
            });
        }
        Ok(())
    }
}

impl Default for TwoViewParams {
    /// [`TwoViewParams::new`] of homographies.
    fn default() -> Self {
        Self::new(TwoViewMode::Homography)
    }
}

/// What a sample was drawn from.
#[derive(Debug, Clone)]
pub struct TwoViewTruth {
    /// Focal lengths of views 1 and 2, px.
    pub focal: [f64; 2],
    pub image: ImageSize,
    /// Camera 2's camera-to-world rotation (world = camera 1's frame).
    pub rotation: Mat3,
    /// Camera 2's centre.
    pub centre: [f64; 3],
    /// Noise sigma, px.
    pub noise: f64,
    /// Per group (label order, outliers excluded), its homography or fundamental matrix in
    /// pixels, unit Frobenius norm, entry `[8]` positive.
    pub models: Vec<Mat3>,
}

/// A generated sample and the truth it was drawn from.
#[derive(Debug, Clone)]
pub struct TwoViewSample {
    pub sample: Sample,
    pub mode: TwoViewMode,
    /// Planes or objects.
    pub groups: usize,
    /// Gross outliers (0 without them).
    pub outliers: usize,
    pub truth: TwoViewTruth,
}

/// What one sample draws before its scene.
struct Setup {
    counts: Vec<usize>,
    focal: [f64; 2],
    width: f64,
    height: f64,
    noise: f64,
    outlier_fraction: f64,
}

/// The two cameras of a scene.
struct Cameras {
    k: [Mat3; 2],
    /// Camera 2's camera-to-world rotation and centre.
    r2: Mat3,
    c2: V3,
    w: f64,
    h: f64,
}

impl Cameras {
    fn pixel(k: &Mat3, x: V3) -> Option<[f64; 2]> {
        (x[2] >= NEAR).then(|| {
            let p = mat3_vec(k, x);
            [p[0] / p[2], p[1] / p[2]]
        })
    }

    /// World point (camera 1's frame) to pixels in views 1 and 2, when in front of both.
    fn project(&self, x1: V3, x2: V3) -> Option<[f64; 4]> {
        let a = Self::pixel(&self.k[0], x1)?;
        let b = Self::pixel(
            &self.k[1],
            mat3_vec(&mat3_transpose(&self.r2), sub(x2, self.c2)),
        )?;
        Some([a[0], a[1], b[0], b[1]])
    }

    /// The back-projection of pixel (u, v) of view 1 at depth z.
    fn back(&self, u: f64, v: f64, z: f64) -> V3 {
        let k = &self.k[0];
        [(u - k[2]) / k[0] * z, (v - k[5]) / k[4] * z, z]
    }
}

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(a: V3) -> V3 {
    scale(a, 1.0 / dot(a, a).sqrt())
}

/// A unit vector orthogonal to `n`.
fn orthogonal(n: V3) -> V3 {
    let other = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    normalize(cross(n, other))
}

/// The matrix whose columns are `a`, `b`, `c`.
fn columns(a: V3, b: V3, c: V3) -> Mat3 {
    [a[0], b[0], c[0], a[1], b[1], c[1], a[2], b[2], c[2]]
}

/// A group's geometry: how to draw a point (in both views' world positions) and its model.
enum Group {
    Plane {
        centre: V3,
        e1: V3,
        e2: V3,
        half: f64,
    },
    Object {
        centre: V3,
        orientation: Mat3,
        half: f64,
        turn: Mat3,
        shift: V3,
    },
}

/// A seeded two-view generator: the same seed and params give the same samples.
pub struct TwoViewGenerator {
    rng: ChaCha8Rng,
    params: TwoViewParams,
}

impl TwoViewGenerator {
    /// A generator of valid `params`.
    pub fn new(seed: u64, params: TwoViewParams) -> Result<Self, RangeError> {
        params.validate()?;
        Ok(Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
            params,
        })
    }

    /// One sample; `name` is stored with it.
    pub fn sample(&mut self, name: &str) -> TwoViewSample {
        let p = self.params;
        let rng = &mut self.rng;
        let groups = rng.random_range(p.groups[0]..=p.groups[1]);
        let counts = (0..groups)
            .map(|_| rng.random_range(p.points[0]..=p.points[1]))
            .collect();
        let f1 = uniform(rng, p.focal);
        let setup = Setup {
            counts,
            focal: [f1, f1 * log_uniform(rng, ZOOM)],
            width: uniform(rng, p.width).round(),
            height: uniform(rng, p.height).round(),
            noise: uniform(rng, p.noise),
            outlier_fraction: uniform(rng, p.outliers),
        };
        let (rows, truth) = loop {
            if let Some(scene) = self.scene(&setup) {
                break scene;
            }
        };
        self.finish(&setup, rows, truth, name)
    }

    fn cameras(&mut self, setup: &Setup) -> Cameras {
        let rng = &mut self.rng;
        let (w, h) = (setup.width, setup.height);
        let k = setup
            .focal
            .map(|f| [f, 0.0, 0.5 * w, 0.0, f, 0.5 * h, 0.0, 0.0, 1.0]);
        let d = uniform(rng, FIXATION);
        let dir: V3 = UnitSphere.sample(rng);
        let c2 = scale(dir, uniform(rng, BASELINE) * d);
        let z = normalize(sub([0.0, 0.0, d], c2));
        let x = normalize(cross([0.0, 1.0, 0.0], z));
        let y = cross(z, x);
        let look = columns(x, y, z);
        let roll = rodrigues([0.0, 0.0, uniform(rng, [-ROLL, ROLL]).to_radians()]);
        let axis: V3 = UnitSphere.sample(rng);
        let tilt = rodrigues(scale(axis, uniform(rng, [0.0, TILT]).to_radians()));
        Cameras {
            k,
            r2: mat3_mul(&tilt, &mat3_mul(&look, &roll)),
            c2,
            w,
            h,
        }
    }

    /// A new plane or object, and its model.
    fn group(&mut self, cams: &Cameras) -> (Group, Mat3) {
        let rng = &mut self.rng;
        let (w, h) = (cams.w, cams.h);
        let (u, v) = (
            uniform(rng, [0.1 * w, 0.9 * w]),
            uniform(rng, [0.1 * h, 0.9 * h]),
        );
        let across = w.min(h) / (2.0 * cams.k[0][0]);
        // Camera 2 as world-to-camera: X_2 = r X + t.
        let r = mat3_transpose(&cams.r2);
        let t = scale(mat3_vec(&r, cams.c2), -1.0);
        let kinv = [
            mat3_inverse(&cams.k[0]).expect("focal > 0"),
            mat3_inverse(&cams.k[1]).expect("focal > 0"),
        ];
        match self.params.mode {
            TwoViewMode::Homography => {
                let depth = uniform(rng, PLANE_DEPTH);
                let centre = cams.back(u, v, depth);
                let to1 = normalize(scale(centre, -1.0));
                let (a, b) = (orthogonal(to1), cross(to1, orthogonal(to1)));
                let n = loop {
                    let tilt = uniform(rng, [0.0, TILT_PLANE]).to_radians();
                    let azimuth = rng.random_range(0.0..std::f64::consts::TAU);
                    let side = add(scale(a, azimuth.cos()), scale(b, azimuth.sin()));
                    let n = add(scale(to1, tilt.cos()), scale(side, tilt.sin()));
                    if dot(n, normalize(sub(cams.c2, centre))) >= FACING {
                        break n;
                    }
                };
                let e1 = orthogonal(n);
                let e2 = cross(n, e1);
                let half = uniform(rng, PLANE_SIZE) * depth * across;
                // n^T X = dp on the plane: H = K2 (r + t n^T / dp) K1^-1.
                let dp = dot(n, centre);
                let mut m = r;
                for i in 0..3 {
                    for j in 0..3 {
                        m[i * 3 + j] += t[i] * n[j] / dp;
                    }
                }
                let model = mat3_mul(&mat3_mul(&cams.k[1], &m), &kinv[0]);
                let group = Group::Plane {
                    centre,
                    e1,
                    e2,
                    half,
                };
                (group, model)
            }
            TwoViewMode::Fundamental => {
                let depth = uniform(rng, OBJ_DEPTH);
                let centre = cams.back(u, v, depth);
                let half = (uniform(rng, OBJ_SIZE) * depth * across).min(0.4 * depth);
                let orientation = random_rotation(rng);
                loop {
                    let axis: V3 = UnitSphere.sample(rng);
                    let turn = rodrigues(scale(axis, uniform(rng, [0.0, OBJ_TURN]).to_radians()));
                    let dir: V3 = UnitSphere.sample(rng);
                    let shift = scale(dir, uniform(rng, OBJ_SHIFT) * depth);
                    // X_2 = r (turn X + moved - C2): r' = r turn, t' = r (moved - C2).
                    let moved = sub(add(centre, shift), mat3_vec(&turn, centre));
                    let rp = mat3_mul(&r, &turn);
                    let tp = mat3_vec(&r, sub(moved, cams.c2));
                    if dot(tp, tp).sqrt() < MIN_TRANSLATION * depth {
                        continue;
                    }
                    let tx = [0.0, -tp[2], tp[1], tp[2], 0.0, -tp[0], -tp[1], tp[0], 0.0];
                    let model = mat3_mul(
                        &mat3_mul(&mat3_transpose(&kinv[1]), &mat3_mul(&tx, &rp)),
                        &kinv[0],
                    );
                    let group = Group::Object {
                        centre,
                        orientation,
                        half,
                        turn,
                        shift,
                    };
                    break (group, model);
                }
            }
        }
    }

    /// A point of the group: its world positions at views 1 and 2.
    fn point(&mut self, group: &Group) -> (V3, V3) {
        let rng = &mut self.rng;
        match group {
            Group::Plane {
                centre,
                e1,
                e2,
                half,
            } => {
                let (a, b) = (
                    rng.random_range(-half..=*half),
                    rng.random_range(-half..=*half),
                );
                let x = add(*centre, add(scale(*e1, a), scale(*e2, b)));
                (x, x)
            }
            Group::Object {
                centre,
                orientation,
                half,
                turn,
                shift,
            } => {
                let body = [0; 3].map(|_| rng.random_range(-half..=*half));
                let offset = mat3_vec(orientation, body);
                let x1 = add(*centre, offset);
                let x2 = add(add(*centre, *shift), mat3_vec(turn, offset));
                (x1, x2)
            }
        }
    }

    /// Draws the cameras and every group; `None` when a group could not be found.
    #[allow(clippy::type_complexity)]
    fn scene(&mut self, setup: &Setup) -> Option<(Vec<([f64; 4], usize)>, TwoViewTruth)> {
        let cams = self.cameras(setup);
        let noise = Normal::new(0.0, setup.noise).expect("validated sigma");
        let (w, h) = (cams.w, cams.h);
        let mut rows = Vec::new();
        let mut models = Vec::new();
        for (label, &n) in setup.counts.iter().enumerate() {
            let budget = ATTEMPTS_PER_POINT * n + ATTEMPTS_EXTRA;
            let found = (0..GROUP_TRIES).find_map(|_| {
                let (group, model) = self.group(&cams);
                let mut got = Vec::with_capacity(n);
                for _ in 0..budget {
                    let (x1, x2) = self.point(&group);
                    let Some(p) = cams.project(x1, x2) else {
                        continue;
                    };
                    let q = p.map(|v| v + noise.sample(&mut self.rng));
                    let inside = |x: f64, y: f64| (0.0..w).contains(&x) && (0.0..h).contains(&y);
                    if inside(q[0], q[1]) && inside(q[2], q[3]) {
                        got.push((q, label + 1));
                        if got.len() == n {
                            return Some((got, model));
                        }
                    }
                }
                None
            });
            let (got, model) = found?;
            rows.extend(got);
            models.push(unit_norm_sign(&model).expect("finite, non-zero model"));
        }
        let truth = TwoViewTruth {
            focal: setup.focal,
            image: ImageSize::new(w, h).expect("validated image size"),
            rotation: cams.r2,
            centre: cams.c2,
            noise: setup.noise,
            models,
        };
        Some((rows, truth))
    }

    /// Adds the outliers, shuffles and labels.
    fn finish(
        &mut self,
        setup: &Setup,
        mut rows: Vec<([f64; 4], usize)>,
        truth: TwoViewTruth,
        name: &str,
    ) -> TwoViewSample {
        let rng = &mut self.rng;
        let (w, h) = (setup.width, setup.height);
        let phi = setup.outlier_fraction;
        let outliers = (phi / (1.0 - phi) * rows.len() as f64).round() as usize;
        for _ in 0..outliers {
            let p = [
                rng.random_range(0.0..w),
                rng.random_range(0.0..h),
                rng.random_range(0.0..w),
                rng.random_range(0.0..h),
            ];
            rows.push((p, 0));
        }
        // Fisher-Yates with our own rng, so the order is part of the seed.
        for i in (1..rows.len()).rev() {
            let j = rng.random_range(0..=i);
            rows.swap(i, j);
        }
        let shift = usize::from(outliers == 0);
        let labels = rows.iter().map(|r| r.1 - shift).collect();
        let values: Vec<f64> = rows.iter().flat_map(|r| r.0).collect();
        let points =
            PointSet::from_flat(Kind::Correspondences, 4, values).expect("finite, in image");
        let groups = setup.counts.len();
        TwoViewSample {
            sample: Sample {
                name: name.to_string(),
                points,
                labels,
                k: groups + usize::from(outliers > 0),
                image_size: Some(truth.image),
                outliers: outliers > 0,
            },
            mode: self.params.mode,
            groups,
            outliers,
            truth,
        }
    }
}

impl TwoViewSample {
    /// The sample in the on-disk dataset format, as AdelaideRMF's files: kind
    /// `correspondences`, outliers raw label 0, groups 1..=K, `model_type` the mode.
    pub fn to_file(&self, seed: u64) -> SequenceFile {
        let s = &self.sample;
        let t = &self.truth;
        let shift = usize::from(self.outliers == 0);
        let what = match self.mode {
            TwoViewMode::Homography => "planes",
            TwoViewMode::Fundamental => "rigid objects",
        };
        let mut source = format!(
            "multifit synthetic two-view {} (seed {seed}): {} {what}, focal {} and {} px, image {}x{}, noise {} px",
            self.mode.as_str(),
            self.groups,
            t.focal[0],
            t.focal[1],
            t.image.width,
            t.image.height,
            t.noise
        );
        if self.outliers > 0 {
            source += &format!("; {} gross outliers (label 0)", self.outliers);
        }
        SequenceFile {
            name: s.name.clone(),
            kind: Kind::Correspondences,
            points: (0..s.points.len())
                .map(|i| s.points.row(i).to_vec())
                .collect(),
            labels: s.labels.iter().map(|&l| (l + shift) as i64).collect(),
            num_models: Some(self.groups),
            image_size: Some([t.image.width, t.image.height]),
            source: Some(source),
            model_type: Some(self.mode.as_str().to_string()),
            visible: None,
        }
    }
}

/// `count` samples of `params` from `seed`, named `twoview-<mode>-s<seed>-<i:05>`.
pub fn generate(
    params: &TwoViewParams,
    count: usize,
    seed: u64,
) -> Result<Vec<Sample>, RangeError> {
    let mut generator = TwoViewGenerator::new(seed, *params)?;
    let mode = params.mode.as_str();
    Ok((0..count)
        .map(|i| {
            generator
                .sample(&format!("twoview-{mode}-s{seed}-{i:05}"))
                .sample
        })
        .collect())
}

/// A generated two-view dataset, written `twoview:<homography|fundamental>[,count=N][,seed=S]
/// [,groups=A-B][,points=A-B][,noise=A-B][,outliers=A-B][,focal=A-B][,width=A-B][,height=A-B]`
/// wherever a dataset path is accepted (defaults: 200 samples, seed 0, [`TwoViewParams::new`]).
#[derive(Debug, Clone, PartialEq)]
pub struct TwoViewSpec {
    pub count: usize,
    pub seed: u64,
    pub params: TwoViewParams,
}

impl TwoViewSpec {
    /// Most samples one spec may ask for.
    pub const MAX_COUNT: usize = 1_000_000;

    /// Checks the count and the params; errors name the spec key (`groups=0: ...`).
    pub fn validate(&self) -> Result<(), SpecError> {
        check_count(self.count, Self::MAX_COUNT)?;
        self.params.validate().map_err(SpecError::Setting)
    }

    /// The samples in the on-disk format, in generation order, named
    /// `twoview-<mode>-s<seed>-<i:05>`.
    pub fn files(&self) -> Result<impl Iterator<Item = SequenceFile> + '_, RangeError> {
        let mut generator = TwoViewGenerator::new(self.seed, self.params)?;
        let mode = self.params.mode.as_str();
        Ok((0..self.count).map(move |i| {
            generator
                .sample(&format!("twoview-{mode}-s{}-{i:05}", self.seed))
                .to_file(self.seed)
        }))
    }

    /// The samples as validated sequences: what loading the files of [`Self::files`] gives.
    pub fn sequences(&self) -> Result<Vec<Sequence>, DataError> {
        let invalid = |e: RangeError| DataError::Invalid {
            path: self.to_string().into(),
            reason: e.for_spec(),
        };
        load_files(self.files().map_err(invalid)?)
    }
}

impl std::fmt::Display for TwoViewSpec {
    /// Every setting, so that the text parses back to the same spec.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let p = &self.params;
        write!(
            f,
            "twoview:{},count={},seed={},groups={},points={},noise={},outliers={},focal={},width={},height={}",
            p.mode.as_str(),
            self.count,
            self.seed,
            range_text(p.groups),
            range_text(p.points),
            range_text(p.noise),
            range_text(p.outliers),
            range_text(p.focal),
            range_text(p.width),
            range_text(p.height)
        )
    }
}

impl std::str::FromStr for TwoViewSpec {
    type Err = SpecError;

    /// Parses the part after `twoview:`, e.g. `homography,count=500,groups=2-4,outliers=0.3`.
    fn from_str(text: &str) -> Result<Self, SpecError> {
        let mut parts = text.split(',');
        let mode = match parts.next().unwrap_or_default() {
            "homography" => TwoViewMode::Homography,
            "fundamental" => TwoViewMode::Fundamental,
            other => return Err(SpecError::UnknownTwoViewMode(other.to_string())),
        };
        let mut spec = TwoViewSpec {
            count: 200,
            seed: 0,
            params: TwoViewParams::new(mode),
        };
        for part in parts {
            let setting = Setting::parse(part)?;
            let p = &mut spec.params;
            match setting.key {
                "count" => spec.count = setting.value()?,
                "seed" => spec.seed = setting.value()?,
                "groups" => p.groups = setting.pair()?,
                "points" => p.points = setting.pair()?,
                "noise" => p.noise = setting.pair()?,
                "outliers" => p.outliers = setting.pair()?,
                "focal" => p.focal = setting.pair()?,
                "width" => p.width = setting.pair()?,
                "height" => p.height = setting.pair()?,
                _ => {
                    return Err(SpecError::UnknownSetting {
                        generator: "two-view",
                        key: setting.key.to_string(),
                        known: "count, seed, groups, points, noise, outliers, focal, width, height",
                    });
                }
            }
        }
        spec.validate()?;
        Ok(spec)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::fundamental::sampson_distance;
    use crate::geometry::homography::{Homography, transfer_distance};
    use crate::geometry::{Model, fit_type};

    fn params(mode: TwoViewMode, f: impl FnOnce(&mut TwoViewParams)) -> TwoViewParams {
        let mut p = TwoViewParams::new(mode);
        f(&mut p);
        p
    }

    fn group(s: &Sample, label: usize) -> Vec<[f64; 4]> {
        (0..s.points.len())
            .filter(|&i| s.labels[i] == label)
            .map(|i| {
                let r = s.points.row(i);
                [r[0], r[1], r[2], r[3]]
            })
            .collect()
    }

    /// The fit of one model type to a group, and the RMS of its residuals over all the rows.
    fn fit_rms(type_name: &str, rows: &[[f64; 4]]) -> (Model, f64) {
        let view: Vec<&[f64]> = rows.iter().map(|r| r.as_slice()).collect();
        let fit = fit_type(type_name, &view).unwrap();
        let sq: f64 = view.iter().map(|r| fit.model.residual(r).powi(2)).sum();
        (fit.model, (sq / rows.len() as f64).sqrt())
    }

    #[test]
    fn seeded_and_reproducible() {
        for mode in [TwoViewMode::Homography, TwoViewMode::Fundamental] {
            let p = TwoViewParams::new(mode);
            let a = generate(&p, 3, 7).unwrap();
            let b = generate(&p, 3, 7).unwrap();
            let c = generate(&p, 3, 8).unwrap();
            for (x, y) in a.iter().zip(&b) {
                assert_eq!(x.points, y.points);
                assert_eq!(
                    (&x.labels, x.k, x.image_size),
                    (&y.labels, y.k, y.image_size)
                );
            }
            assert_ne!(a[0].points, c[0].points);
            assert_eq!(a[1].name, format!("twoview-{}-s7-00001", mode.as_str()));
        }
    }

    #[test]
    fn shapes_counts_and_labels_follow_the_ranges() {
        for (mode, groups) in [
            (TwoViewMode::Homography, 2..=6),
            (TwoViewMode::Fundamental, 2..=5),
        ] {
            let mut g = TwoViewGenerator::new(3, TwoViewParams::new(mode)).unwrap();
            let mut seen = std::collections::BTreeSet::new();
            let mut with_outliers = 0;
            for i in 0..40 {
                let t = g.sample(&i.to_string());
                let s = &t.sample;
                assert_eq!(s.points.kind(), Kind::Correspondences);
                assert_eq!(s.points.dim(), 4, "rows are [x1, y1, x2, y2]");
                assert!(groups.contains(&t.groups));
                assert_eq!(t.truth.models.len(), t.groups);
                let first = usize::from(t.outliers > 0);
                assert_eq!(s.k, t.groups + first);
                if t.outliers > 0 {
                    assert_eq!(group(s, 0).len(), t.outliers);
                    with_outliers += 1;
                }
                let inliers = s.points.len() - t.outliers;
                for l in first..s.k {
                    assert!((30..=150).contains(&group(s, l).len()), "group {l}");
                }
                // At most half the rows are outliers (default fraction up to 0.5).
                assert!(t.outliers as f64 <= inliers as f64 + 0.5);
                let size = s.image_size.unwrap();
                assert!((400.0..=1280.0).contains(&size.width));
                assert!((300.0..=960.0).contains(&size.height));
                assert!((300.0..=1500.0).contains(&t.truth.focal[0]));
                let zoom = t.truth.focal[1] / t.truth.focal[0];
                assert!((1.0 / 1.2 - 1e-12..=1.2 + 1e-12).contains(&zoom));
                for i in 0..s.points.len() {
                    let r = s.points.row(i);
                    assert!((0.0..size.width).contains(&r[0]) && (0.0..size.width).contains(&r[2]));
                    assert!(
                        (0.0..size.height).contains(&r[1]) && (0.0..size.height).contains(&r[3])
                    );
                }
                seen.insert(t.groups);
            }
            assert_eq!(seen.len(), groups.count(), "{seen:?}");
            assert!(with_outliers > 30);
        }
    }

    /// Noise-free planes: every group is exactly one homography, as `crate::geometry` fits it
    /// (transfer rms below 1e-6 px) and as the generator's truth has it; another plane's H does
    /// not fit the group.
    #[test]
    fn noise_free_planes_are_exact_homographies() {
        let p = params(TwoViewMode::Homography, |p| {
            p.noise = [0.0, 0.0];
            p.outliers = [0.0, 0.0];
        });
        let mut g = TwoViewGenerator::new(5, p).unwrap();
        for _ in 0..8 {
            let t = g.sample("h");
            for l in 0..t.groups {
                let rows = group(&t.sample, l);
                let (model, rms) = fit_rms("homography", &rows);
                assert!(matches!(model, Model::Homography { .. }));
                assert!(rms < 1e-6, "group {l}: fitted transfer rms {rms} px");
                let truth = Homography::new(t.truth.models[l]).unwrap();
                let worst = rows
                    .iter()
                    .map(|r| transfer_distance(&truth, r))
                    .fold(0.0, f64::max);
                assert!(worst < 1e-6, "group {l}: true H off by {worst} px");
                let other = Homography::new(t.truth.models[(l + 1) % t.groups]).unwrap();
                let off = rows
                    .iter()
                    .map(|r| transfer_distance(&other, r))
                    .sum::<f64>()
                    / rows.len() as f64;
                assert!(off > 1.0, "another plane's H fits group {l}: {off} px");
            }
        }
    }

    /// Noise-free objects: every group has Sampson error ~0 under the F `crate::geometry` fits
    /// and under the generator's true F, and is not explained by one homography (a 3D cloud).
    #[test]
    fn noise_free_objects_are_exact_fundamental_matrices() {
        let p = params(TwoViewMode::Fundamental, |p| {
            p.noise = [0.0, 0.0];
            p.outliers = [0.0, 0.0];
        });
        let mut g = TwoViewGenerator::new(6, p).unwrap();
        for _ in 0..8 {
            let t = g.sample("f");
            for l in 0..t.groups {
                let rows = group(&t.sample, l);
                let (model, rms) = fit_rms("fundamental", &rows);
                assert!(matches!(model, Model::Fundamental { .. }), "{model:?}");
                assert!(rms < 1e-6, "group {l}: fitted Sampson rms {rms} px");
                let f = t.truth.models[l];
                let worst = rows
                    .iter()
                    .map(|r| sampson_distance(&f, r))
                    .fold(0.0, f64::max);
                assert!(worst < 1e-6, "group {l}: true F off by {worst} px");
                let (_, planar) = fit_rms("homography", &rows);
                assert!(planar > 0.05, "group {l} is planar: {planar} px");
                let other = t.truth.models[(l + 1) % t.groups];
                let off = rows
                    .iter()
                    .map(|r| sampson_distance(&other, r))
                    .sum::<f64>()
                    / rows.len() as f64;
                assert!(off > 0.5, "another object's F fits group {l}: {off} px");
            }
        }
    }

    #[test]
    fn noise_has_the_drawn_sigma() {
        for mode in [TwoViewMode::Homography, TwoViewMode::Fundamental] {
            let p = params(mode, |p| {
                p.noise = [1.0, 1.0];
                p.outliers = [0.0, 0.0];
                p.points = [150, 150];
            });
            let t = TwoViewGenerator::new(8, p).unwrap().sample("n");
            let (mut ss, mut n) = (0.0, 0);
            for l in 0..t.groups {
                for r in group(&t.sample, l) {
                    let m = t.truth.models[l];
                    let e = match mode {
                        // Symmetric transfer: ~2 sigma with noise in both images.
                        TwoViewMode::Homography => {
                            0.5 * transfer_distance(&Homography::new(m).unwrap(), &r)
                        }
                        // Sampson: ~sigma.
                        TwoViewMode::Fundamental => sampson_distance(&m, &r),
                    };
                    ss += e * e;
                    n += 1;
                }
            }
            let sigma = (ss / n as f64).sqrt();
            assert!((0.8..1.25).contains(&sigma), "{mode:?}: {sigma}");
        }
    }

    #[test]
    fn outliers_are_uniform_pairs_labelled_0() {
        let p = params(TwoViewMode::Fundamental, |p| p.outliers = [0.6, 0.6]);
        let t = TwoViewGenerator::new(9, p).unwrap().sample("o");
        let s = &t.sample;
        let inliers = s.points.len() - t.outliers;
        assert_eq!(t.outliers, (0.6 / 0.4 * inliers as f64).round() as usize);
        assert_eq!(group(s, 0).len(), t.outliers);
        // Outliers fit none of the groups' models.
        let outl = group(s, 0);
        let fitting = outl
            .iter()
            .filter(|r| t.truth.models.iter().any(|f| sampson_distance(f, r) < 0.5))
            .count();
        assert!(fitting < outl.len() / 5, "{fitting} of {}", outl.len());
        // Spread over the whole image in both views.
        let size = s.image_size.unwrap();
        for c in 0..4 {
            let side = if c % 2 == 0 { size.width } else { size.height };
            let mean = outl.iter().map(|r| r[c]).sum::<f64>() / outl.len() as f64;
            assert!((mean / side - 0.5).abs() < 0.1, "column {c}: {mean}");
        }
        // In a file, as AdelaideRMF's: raw label 0, groups 1..=K, the model type; loading it gives
        // the sample back.
        let file = t.to_file(9);
        assert_eq!(file.model_type.as_deref(), Some("fundamental"));
        assert_eq!(file.num_models, Some(t.groups));
        assert_eq!(file.labels.iter().filter(|&&l| l == 0).count(), t.outliers);
        let back = Sequence::from_file(file, std::path::Path::new("o")).unwrap();
        assert_eq!(back.model_type.as_deref(), Some("fundamental"));
        let back = back.sample();
        assert_eq!((back.labels, back.k), (s.labels.clone(), s.k));
        assert_eq!(back.points, s.points);
    }

    #[test]
    fn validate_names_the_flag_of_each_bad_setting() {
        use TwoViewMode::{Fundamental, Homography};
        assert!(TwoViewParams::default().validate().is_ok());
        assert!(TwoViewParams::new(Fundamental).validate().is_ok());
        for (bad, says) in [
            (
                params(Homography, |p| p.groups = [0, 3]),
                "--groups 0-3: groups must lie in [1, 10]",
            ),
            (
                params(Homography, |p| p.groups = [2, 11]),
                "--groups 2-11: ",
            ),
            (
                params(Homography, |p| p.groups = [4, 2]),
                "--groups 4-2: the smallest value (4)",
            ),
            (
                params(Homography, |p| p.points = [0, 0]),
                "--points 0: homography correspondences per group must lie in [4, 100000]",
            ),
            (
                params(Fundamental, |p| p.points = [7, 50]),
                "--points 7-50: fundamental correspondences per group must lie in [8, 100000]",
            ),
            (
                params(Homography, |p| p.points = [60, 30]),
                "--points 60-30: the smallest",
            ),
            (
                params(Homography, |p| p.noise = [-1.0, 0.0]),
                "--noise -1-0: noise (px) must lie in [0, 20]",
            ),
            (
                params(Homography, |p| p.noise = [f64::NAN, 1.0]),
                "--noise NaN-1: ",
            ),
            (
                params(Homography, |p| {
                    p.noise = [8.0, 8.0];
                    p.width = [100.0, 200.0];
                }),
                "--noise 8: noise up to 8 px needs images of at least 128 px a side",
            ),
            (
                params(Homography, |p| p.outliers = [0.2, 1.0]),
                "--outliers 0.2-1: the outlier fraction must lie in [0, 1)",
            ),
            (
                params(Homography, |p| p.outliers = [-0.1, 0.5]),
                "--outliers -0.1-0.5: ",
            ),
            (
                params(Homography, |p| p.outliers = [0.5, 0.1]),
                "--outliers 0.5-0.1: the smallest",
            ),
            (
                params(Homography, |p| p.outliers = [0.99999, 0.99999]),
                "--outliers 0.99999: with up to 900 correspondences",
            ),
            (
                params(Homography, |p| p.focal = [0.0, 500.0]),
                "--focal 0-500: focal (px) must lie in [50, 100000]",
            ),
            (
                params(Homography, |p| p.width = [640.0, 1e6]),
                "--width 640-1000000: ",
            ),
            (
                params(Homography, |p| p.height = [480.0, 300.0]),
                "--height 480-300: the smallest",
            ),
        ] {
            let err = bad.validate().unwrap_err();
            assert!(err.to_string().starts_with(says), "{err} (wanted {says})");
            assert!(says.starts_with(err.flag()));
            assert!(TwoViewGenerator::new(0, bad).is_err());
            assert!(generate(&bad, 1, 0).is_err());
        }
        let err = params(Homography, |p| p.groups = [0, 0])
            .validate()
            .unwrap_err();
        assert_eq!(err.for_spec(), "groups=0: groups must lie in [1, 10]");
    }

    #[test]
    fn spec_parses_prints_and_generates_what_its_files_hold() {
        let text = "fundamental,count=3,seed=2,groups=2-3,points=20-40,noise=0.5,outliers=0.1-0.4,focal=800,width=640,height=480";
        let spec: TwoViewSpec = text.parse().unwrap();
        assert_eq!(spec.params.mode, TwoViewMode::Fundamental);
        assert_eq!(spec.params.groups, [2, 3]);
        assert_eq!(spec.to_string(), format!("twoview:{text}"));
        assert_eq!(
            spec.to_string()["twoview:".len()..]
                .parse::<TwoViewSpec>()
                .unwrap(),
            spec
        );
        let h: TwoViewSpec = "homography".parse().unwrap();
        assert_eq!(
            (h.count, h.seed, h.params),
            (200, 0, TwoViewParams::new(TwoViewMode::Homography))
        );
        let f: TwoViewSpec = "fundamental".parse().unwrap();
        assert_eq!(f.params.groups, [2, 5]);
        // Through the data source, as `--data twoview:...`, with AdelaideRMF's model-type filter.
        let source: crate::data::DataSource = format!("twoview:{text}").parse().unwrap();
        assert_eq!(source, crate::data::DataSource::TwoView(spec.clone()));
        assert_eq!(source.to_string(), spec.to_string());
        let seqs = source.sequences(Some("fundamental")).unwrap();
        assert_eq!(source.sequences(None).unwrap().len(), 3);
        let err = source
            .sequences(Some("homography"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("not \"homography\""), "{err}");
        let samples = generate(&spec.params, 3, 2).unwrap();
        for (seq, s) in seqs.iter().zip(&samples) {
            assert_eq!(seq.model_type.as_deref(), Some("fundamental"));
            let back = seq.sample();
            assert_eq!(back.name, s.name);
            assert_eq!(back.points, s.points);
            assert_eq!((back.labels, back.k), (s.labels.clone(), s.k));
            assert_eq!(back.image_size, s.image_size);
        }
        for (bad, says) in [
            ("affine", "unknown two-view mode"),
            ("", "unknown two-view mode"),
            ("homography,count=0", "count=0: count must be 1"),
            (
                "homography,groups=0",
                "groups=0: groups must lie in [1, 10]",
            ),
            (
                "fundamental,points=5",
                "points=5: fundamental correspondences per group",
            ),
            ("homography,outliers=1", "outliers=1: the outlier fraction"),
            ("homography,noise=-1", "noise=-1: noise (px)"),
            ("homography,groups=x", "groups=\"x\""),
            ("homography,colour=red", "unknown two-view setting"),
            ("homography,seed", "not key=value"),
        ] {
            let err = bad.parse::<TwoViewSpec>().unwrap_err().to_string();
            assert!(err.contains(says), "{bad:?}: {err}");
        }
    }
}
