//! Synthetic multi-body motion: 2D feature trajectories of independently moving rigid objects
//! and the static background, seen by a moving perspective camera (the data KT3DMoSeg holds).
//!
//! **Scene.** World coordinates are the camera's frame at the middle of the clip: with F frames
//! `f = 0..F`, the time of frame f is `tau = f - (F - 1) / 2`, and the camera at `tau = 0` sits at
//! the origin looking along +z (x right, y down). Units are metres-like; only ratios matter.
//!
//! **Camera.** A pinhole with focal length `focal` px (one per sample, uniform in the `--focal`
//! range, default 300 to 1500), square pixels, no skew, principal point at the image centre, image
//! `W x H` px (each uniform in the `--width` / `--height` range, rounded to whole pixels, default
//! 640 to 1920 by 360 to 1080). A world point X, camera-to-world pose `(R, c)`, projects to
//! `X_c = R^T (X - c)`, `(u, v) = focal * (X_c.x, X_c.y) / X_c.z + (W / 2, H / 2)`; it is seen
//! when `X_c.z >= NEAR` ([`NEAR`] = 0.5) and `0 <= u < W`, `0 <= v < H`.
//!
//! **Smooth motion.** Every moving thing (the camera, each object) has a pose quadratic in time:
//! position `p(tau) = p0 + v tau + a tau^2 / 2` and rotation `R(tau) = exp([w tau + alpha tau^2
//! / 2]_x) R0` (Rodrigues' formula): constant linear and angular velocity plus a small constant
//! acceleration. With the sample's motion scale `s` (log-uniform in the `--motion-scale` range,
//! default 0.05 to 1) the velocities are, per frame:
//! - camera: `p0 = 0`, `R0 = I`, `v = s * V_CAM * U(0, 1) * d` (d uniform on the unit sphere,
//!   [`V_CAM`] = 1), `w = s * W_CAM * b` (b uniform in the unit ball, [`W_CAM`] = 0.02 rad),
//!   `a = s * A_CAM * N(0, I3)` ([`A_CAM`] = 0.01), `alpha = s * ALPHA_CAM * N(0, I3)`
//!   ([`ALPHA_CAM`] = 0.001 rad);
//! - object: `v = s * V_OBJ * U(0.2, 1) * d` ([`V_OBJ`] = 1), `w = s * W_OBJ * b` ([`W_OBJ`] =
//!   0.05 rad), `a = s * A_OBJ * N(0, I3)` ([`A_OBJ`] = 0.01), `alpha = s * ALPHA_OBJ * N(0, I3)`
//!   ([`ALPHA_OBJ`] = 0.002 rad); its speed is at least a fifth of the largest, so every object
//!   moves in the world, where the background stands still.
//!
//! So `s = 1` is a car-mounted camera at 10 fps (up to 1 unit per frame, some 100 px per frame
//! at depth 10 and focal 1000) and `s = 0.05` a hand-held camera at 30 fps (a few px per frame).
//!
//! **Motions.** `K` motions per sample (uniform in the `--motions` range, default 2 to 5), the
//! static background counting as one (motion 0) and `K - 1` rigid objects:
//! - background: static points (body = world coordinates) back-projected from a pixel uniform in
//!   the image of the `tau = 0` camera at a depth uniform in [`BG_DEPTH`] = 10 to 100;
//! - object: a random 3D point cloud, uniform in a cube of half-size
//!   `r = min(U(0.1, 0.3) * depth * min(W, H) / (2 focal), 0.4 depth)` (in the image, 10% to
//!   30% of half the smaller side), turned by a random rotation `R0` (axis uniform on the sphere, angle
//!   uniform in `[0, pi)`), centred at `tau = 0` on the back-projection of a pixel uniform in the
//!   central 60% of the image (`[0.2 W, 0.8 W] x [0.2 H, 0.8 H]`) at a depth uniform in
//!   [`OBJ_DEPTH`] = 4 to 20. Objects are drawn through each other and the background: no
//!   occlusion is modelled.
//!
//! - a flat object (`--planar`: each object is flat with the sample's probability, uniform in
//!   that range, default 0): its points uniform on the square of the same half-size in its body
//!   frame's x-y plane (z = 0), turned and moved as any object: a planar patch such as a
//!   checkerboard, whose centred tracks under an affine camera span 2 dimensions, not 3.
//!
//! Each motion has `n` tracks, `n` uniform in the `--points` range (default 30 to 200).
//!
//! **Noise.** Every inlier position gets isotropic Gaussian noise of sigma px per coordinate,
//! sigma uniform per sample in the `--noise` range (default 0 to 1 px, at most 20 px, and at most
//! 1/16 of the smallest image side the `--width` / `--height` ranges allow).
//!
//! **Visibility: every track is seen in every frame.** A track is drawn (body point, projections
//! in all F frames, noise) and kept only when every noisy position lies inside `[0, W) x [0, H)`
//! and the point is at least [`NEAR`] in front of the camera in every frame; otherwise it is
//! drawn again. A motion that has not found its `n` tracks after
//! `ATTEMPTS_PER_TRACK * n + ATTEMPTS_EXTRA` ([`ATTEMPTS_PER_TRACK`] = 50,
//! [`ATTEMPTS_EXTRA`] = 1000) draws (it left the image, or the camera turned away) makes the
//! generator draw the whole scene again (camera, objects, points; counts, frames, image and noise
//! kept) at half the motion scale, up to [`MAX_HALVINGS`] = 16 times, and then without a limit
//! (at `s / 2^16` the frames barely differ and nearly every draw is kept). The scale used is
//! [`MotionTruth::motion_scale`] (after [`MotionTruth::halvings`] halvings): long clips at large
//! scales end up slower than drawn (with the defaults about one sample in five is redrawn at
//! least once, long clips most often).
//!
//! **Gross outliers.** A fraction `phi` of all tracks (uniform per sample in the `--outliers`
//! range, `0 <= phi < 1`, default 0: KT3DMoSeg has none) is `round(phi / (1 - phi) * inliers)`
//! random walks: a start uniform in the image and per frame a Gaussian step of
//! `sigma_walk = max(0.5, median inlier step / sqrt(2))` px per coordinate (the median over all
//! inlier tracks and frames of the per-frame displacement, so outliers move as much as real
//! tracks), reflected at the image borders to stay inside.
//!
//! **Dropout.** With `--dropout` (a range in `[0, 1)`, default 0: KT3DMoSeg's clips as
//! evaluated hold the tracks seen throughout), a share φ of the tracks (uniform per sample in
//! the range; every row but the first two after shuffling, outliers included, independently) is
//! seen only in a run of L consecutive frames, L uniform in 2..F and its start uniform; at least
//! two tracks are seen throughout, and clips of 2 frames have no dropout. The positions outside
//! the run stay in the rows; the file's `visible` mask (N x F, 1 seen) says which were seen
//! ([`crate::data::Visibility`]). Without dropout nothing is drawn for it, so every other setting
//! gives the samples it gave before.
//!
//! **Labels**, as the dataset format has them ([`crate::data::dataset`]): in files, raw label 0
//! is the outlier group (AdelaideRMF's convention; KT3DMoSeg itself has no outliers), the
//! background 1 and the objects 2..=K. In the [`Sample`], as loading such a file gives: without
//! outliers the background is 0 and the objects 1..K (KT3DMoSeg's labels 1..K renumbered from 0),
//! with outliers label 0 is the outlier group, the background 1 and the objects 2..=K, and `k`
//! counts the outlier group. Rows are shuffled. Rows are `[x_1, y_1, ..., x_F, y_F]` (2F values,
//! kind `trajectories`), `image_size` is set, every value lies in the image.
//!
//! **Spec.** `--data motion:[count=N][,seed=S][,frames=A-B][,motions=A-B][,points=A-B]
//! [,noise=A-B][,outliers=A-B][,motion-scale=A-B][,focal=A-B][,width=A-B][,height=A-B]
//! [,dropout=A-B]` generates in memory ([`MotionSpec`]; defaults: 200 samples, seed 0,
//! [`MotionParams::default`]); one value `A` is the range `A-A`.

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal, StandardNormal, UnitBall, UnitSphere};

use super::dataset::{
    DataError, Sample, Sequence, SequenceFile, Setting, SpecError, check_count, load_files,
};
use super::points::{ImageSize, Kind, PointSet};
use super::ranges::{RangeError, check_range, range_text};
use crate::geometry::linalg::{IDENTITY3, Mat3, mat3_mul, mat3_transpose, mat3_vec, rodrigues};

/// Nearest depth (world units) at which a point is seen.
pub const NEAR: f64 = 0.5;
/// Depth range of the background points (at `tau = 0`).
pub const BG_DEPTH: [f64; 2] = [10.0, 100.0];
/// Depth range of an object's centre (at `tau = 0`).
pub const OBJ_DEPTH: [f64; 2] = [4.0, 20.0];
/// An object's half-size as a fraction of the half-image it spans at its depth.
pub const OBJ_SIZE: [f64; 2] = [0.1, 0.3];
/// Largest camera speed (units per frame) at motion scale 1.
pub const V_CAM: f64 = 1.0;
/// Largest camera angular speed (radians per frame) at motion scale 1.
pub const W_CAM: f64 = 0.02;
/// Standard deviation of the camera's linear acceleration (units per frame^2) at scale 1.
pub const A_CAM: f64 = 0.01;
/// Standard deviation of the camera's angular acceleration (radians per frame^2) at scale 1.
pub const ALPHA_CAM: f64 = 0.001;
/// Largest object speed (units per frame) at motion scale 1; the smallest is a fifth of it.
pub const V_OBJ: f64 = 1.0;
/// Largest object angular speed (radians per frame) at motion scale 1.
pub const W_OBJ: f64 = 0.05;
/// Standard deviation of an object's linear acceleration at scale 1.
pub const A_OBJ: f64 = 0.01;
/// Standard deviation of an object's angular acceleration at scale 1.
pub const ALPHA_OBJ: f64 = 0.002;
/// Draws per wanted track before a motion gives up (plus [`ATTEMPTS_EXTRA`]).
pub const ATTEMPTS_PER_TRACK: usize = 50;
/// Draws a motion may spend beyond `ATTEMPTS_PER_TRACK` per track.
pub const ATTEMPTS_EXTRA: usize = 1000;
/// How many times a scene is redrawn at half the motion scale before draws are unlimited.
pub const MAX_HALVINGS: u32 = 16;

/// Generator settings: every field is an inclusive range `[min, max]` a sample draws its value
/// from (see the module docs for the distributions and [`MotionParams::validate`] for the
/// limits).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MotionParams {
    /// Frames per clip (`--frames`, 2 to [`MotionParams::MAX_FRAMES`]).
    pub frames: [usize; 2],
    /// Motions per sample, the background included (`--motions`, 1 to
    /// [`MotionParams::MAX_MOTIONS`]).
    pub motions: [usize; 2],
    /// Tracks per motion (`--points`, 4 to [`MotionParams::MAX_POINTS`]).
    pub points: [usize; 2],
    /// Track noise sigma, px per coordinate (`--noise`, 0 to [`MotionParams::MAX_NOISE`]).
    pub noise: [f64; 2],
    /// Fraction of all tracks that are gross outliers (`--outliers`, in `[0, 1)`).
    pub outliers: [f64; 2],
    /// Motion scale, drawn log-uniformly (`--motion-scale`, in `(0, 10]`).
    pub motion_scale: [f64; 2],
    /// Focal length, px (`--focal`, 50 to 1e5).
    pub focal: [f64; 2],
    /// Image width, px (`--width`, 64 to 1e5).
    pub width: [f64; 2],
    /// Image height, px (`--height`, 64 to 1e5).
    pub height: [f64; 2],
    /// Fraction of the tracks seen in only part of the clip (`--dropout`, in `[0, 1)`).
    pub dropout: [f64; 2],
    /// Probability that an object is flat (`--planar`, in `[0, 1]`), drawn per sample.
    #[serde(default)]
    pub planar: [f64; 2],
}

impl Default for MotionParams {
    fn default() -> Self {
        Self {
            frames: [2, 30],
            motions: [2, 5],
            points: [30, 200],
            noise: [0.0, 1.0],
            outliers: [0.0, 0.0],
            motion_scale: [0.05, 1.0],
            focal: [300.0, 1500.0],
            width: [640.0, 1920.0],
            height: [360.0, 1080.0],
            dropout: [0.0, 0.0],
            planar: [0.0, 0.0],
        }
    }
}

impl MotionParams {
    /// Most frames a clip may have.
    pub const MAX_FRAMES: usize = 100;
    /// Most motions a sample may have.
    pub const MAX_MOTIONS: usize = 10;
    /// Fewest tracks per motion: an affine motion subspace of rank 3 needs 4.
    pub const MIN_POINTS: usize = 4;
    /// Most tracks per motion.
    pub const MAX_POINTS: usize = 100_000;
    /// Largest track noise, px.
    pub const MAX_NOISE: f64 = 20.0;
    /// The smallest image side must be at least this many times the largest noise.
    pub const NOISE_TO_IMAGE: f64 = 16.0;
    /// Most rows (tracks and outliers) one sample may reach.
    pub const MAX_ROWS: usize = 10_000_000;

    /// Checks the settings a generator can draw from; the error names the flag.
    pub fn validate(&self) -> Result<(), RangeError> {
        check_range(
            "--frames",
            self.frames,
            (2, Self::MAX_FRAMES, false),
            "frames",
        )?;
        check_range(
            "--motions",
            self.motions,
            (1, Self::MAX_MOTIONS, false),
            "motions",
        )?;
        check_range(
            "--points",
            self.points,
            (Self::MIN_POINTS, Self::MAX_POINTS, false),
            "tracks per motion",
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
        check_range(
            "--dropout",
            self.dropout,
            (0.0, 1.0, true),
            "the fraction of partly seen tracks",
        )?;
        check_range(
            "--planar",
            self.planar,
            (0.0, 1.0, false),
            "the probability that an object is flat",
        )?;
        let scale = self.motion_scale;
        if !(scale[0] > 0.0 && scale[1] > 0.0) {
            return Err(RangeError::OutOfRange {
                flag: "--motion-scale",
                value: range_text(scale),
                reason: "the motion scale must lie in (0, 10]".into(),
            });
        }
        check_range("--motion-scale", scale, (0.0, 10.0, false), "motion scale")?;
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
        let inliers = (self.motions[1] * self.points[1]) as f64;
        let rows = inliers + (self.outliers[1] / (1.0 - self.outliers[1]) * inliers).round();
        if rows > Self::MAX_ROWS as f64 {
            return Err(RangeError::OutOfRange {
                flag: "--outliers",
                value: range_text(self.outliers),
                reason: format!(
                    "with up to {inliers} tracks this gives up to {rows} rows, above {}",
                    Self::MAX_ROWS
                ),
            });
        }
        Ok(())
    }
}

pub(super) type V3 = [f64; 3];

pub(super) fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(super) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(super) fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// Uniform in `[lo, hi]` (`lo` when they are equal).
pub(super) fn uniform(rng: &mut ChaCha8Rng, [lo, hi]: [f64; 2]) -> f64 {
    if lo < hi {
        rng.random_range(lo..=hi)
    } else {
        lo
    }
}

/// Log-uniform in `[lo, hi]`, `0 < lo`.
pub(super) fn log_uniform(rng: &mut ChaCha8Rng, [lo, hi]: [f64; 2]) -> f64 {
    if lo < hi {
        uniform(rng, [lo.ln(), hi.ln()]).exp().clamp(lo, hi)
    } else {
        lo
    }
}

fn gauss3(rng: &mut ChaCha8Rng) -> V3 {
    [0; 3].map(|_| StandardNormal.sample(rng))
}

/// A random rotation: axis uniform on the sphere, angle uniform in `[0, pi)`.
pub(super) fn random_rotation(rng: &mut ChaCha8Rng) -> Mat3 {
    let axis: V3 = UnitSphere.sample(rng);
    let angle = rng.random_range(0.0..std::f64::consts::PI);
    rodrigues(scale(axis, angle))
}

/// A rigid pose: `x -> rotation * x + translation`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub rotation: Mat3,
    pub translation: [f64; 3],
}

impl Pose {
    pub const IDENTITY: Pose = Pose {
        rotation: IDENTITY3,
        translation: [0.0; 3],
    };

    pub fn apply(&self, x: [f64; 3]) -> [f64; 3] {
        add(mat3_vec(&self.rotation, x), self.translation)
    }
}

/// A pose quadratic in time (see the module docs).
#[derive(Debug, Clone, Copy)]
struct Smooth {
    p0: V3,
    v: V3,
    a: V3,
    r0: Mat3,
    w: V3,
    alpha: V3,
}

impl Smooth {
    fn at(&self, tau: f64) -> Pose {
        let t2 = 0.5 * tau * tau;
        Pose {
            rotation: mat3_mul(
                &rodrigues(add(scale(self.w, tau), scale(self.alpha, t2))),
                &self.r0,
            ),
            translation: add(self.p0, add(scale(self.v, tau), scale(self.a, t2))),
        }
    }
}

/// What a sample was drawn from: the camera, the motions and each row's 3D point.
#[derive(Debug, Clone)]
pub struct MotionTruth {
    /// Focal length, px.
    pub focal: f64,
    pub image: ImageSize,
    /// The motion scale used: the drawn one halved `halvings` times.
    pub motion_scale: f64,
    /// How often the scene was redrawn at half the motion scale (see the module docs).
    pub halvings: u32,
    /// Track noise sigma, px.
    pub noise: f64,
    /// Per frame, the camera-to-world pose (rotation, camera centre).
    pub cameras: Vec<Pose>,
    /// Per motion, per frame, the body-to-world pose (the background's is the identity).
    pub motions: Vec<Vec<Pose>>,
    /// Per motion, whether it is a flat object (`--planar`; the background never is).
    pub flat: Vec<bool>,
    /// Per row of the sample, its motion index (0 = background) and body-frame point; `None`
    /// for an outlier.
    pub body: Vec<Option<(usize, [f64; 3])>>,
}

impl MotionTruth {
    /// The pixel at which body point `x` of motion `motion` is seen in frame `frame`, or `None`
    /// when it is nearer than [`NEAR`] (the image bounds are not checked).
    pub fn project(&self, motion: usize, frame: usize, x: [f64; 3]) -> Option<[f64; 2]> {
        let world = self.motions[motion][frame].apply(x);
        project(
            &self.cameras[frame],
            self.focal,
            self.image.width,
            self.image.height,
            world,
        )
    }
}

fn project(camera: &Pose, focal: f64, w: f64, h: f64, x: V3) -> Option<[f64; 2]> {
    let c = mat3_vec(
        &mat3_transpose(&camera.rotation),
        sub(x, camera.translation),
    );
    (c[2] >= NEAR).then(|| [focal * c[0] / c[2] + 0.5 * w, focal * c[1] / c[2] + 0.5 * h])
}

/// A generated sample and the truth it was drawn from.
#[derive(Debug, Clone)]
pub struct MotionSample {
    pub sample: Sample,
    /// Motions, the background included.
    pub motions: usize,
    pub frames: usize,
    /// Gross outlier tracks (0 without them).
    pub outliers: usize,
    /// With dropout, per track the frames it was seen in (1) or not (0); `None`: every track
    /// in every frame.
    pub visible: Option<Vec<Vec<u8>>>,
    pub truth: MotionTruth,
}

/// What one sample draws before its scene: counts, camera and noise.
struct Setup {
    frames: usize,
    counts: Vec<usize>,
    focal: f64,
    width: f64,
    height: f64,
    noise: f64,
    outlier_fraction: f64,
    motion_scale: f64,
    /// Probability that an object is flat.
    planar: f64,
}

/// A seeded motion generator: the same seed and params give the same samples.
pub struct MotionGenerator {
    rng: ChaCha8Rng,
    params: MotionParams,
}

/// One emitted row while a sample is assembled: the track, its raw label, and for inliers the
/// motion and body point it follows.
type TrackRow = (Vec<f64>, usize, Option<(usize, V3)>);

impl MotionGenerator {
    /// A generator of valid `params`.
    pub fn new(seed: u64, params: MotionParams) -> Result<Self, RangeError> {
        params.validate()?;
        Ok(Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
            params,
        })
    }

    /// One sample; `name` is stored with it.
    pub fn sample(&mut self, name: &str) -> MotionSample {
        let p = self.params;
        let rng = &mut self.rng;
        let frames = rng.random_range(p.frames[0]..=p.frames[1]);
        let motions = rng.random_range(p.motions[0]..=p.motions[1]);
        let counts = (0..motions)
            .map(|_| rng.random_range(p.points[0]..=p.points[1]))
            .collect();
        let setup = Setup {
            frames,
            counts,
            focal: uniform(rng, p.focal),
            width: uniform(rng, p.width).round(),
            height: uniform(rng, p.height).round(),
            noise: uniform(rng, p.noise),
            outlier_fraction: uniform(rng, p.outliers),
            motion_scale: log_uniform(rng, p.motion_scale),
            // Drawn only when asked, so that every other setting gives the samples it gave.
            planar: if p.planar[1] > 0.0 {
                uniform(rng, p.planar)
            } else {
                0.0
            },
        };
        let mut halvings = 0;
        let (tracks, mut truth) = loop {
            let s = setup.motion_scale * 0.5f64.powi(halvings as i32);
            if let Some(scene) = self.scene(&setup, s, halvings < MAX_HALVINGS) {
                break scene;
            }
            halvings += 1;
        };
        truth.halvings = halvings;
        self.finish(&setup, tracks, truth, name)
    }

    /// Draws the camera, the motions and every inlier track at motion scale `s`; `None` when a
    /// motion ran out of draws (only when `limited`).
    #[allow(clippy::type_complexity)]
    fn scene(
        &mut self,
        setup: &Setup,
        s: f64,
        limited: bool,
    ) -> Option<(Vec<(Vec<f64>, usize, V3)>, MotionTruth)> {
        let rng = &mut self.rng;
        let (w, h, focal) = (setup.width, setup.height, setup.focal);
        let mid = (setup.frames - 1) as f64 / 2.0;
        let taus: Vec<f64> = (0..setup.frames).map(|f| f as f64 - mid).collect();
        let unit = |rng: &mut ChaCha8Rng| -> V3 { UnitSphere.sample(rng) };
        let ball = |rng: &mut ChaCha8Rng| -> V3 { UnitBall.sample(rng) };
        let camera = Smooth {
            p0: [0.0; 3],
            v: scale(unit(rng), s * V_CAM * rng.random_range(0.0..=1.0)),
            a: scale(gauss3(rng), s * A_CAM),
            r0: IDENTITY3,
            w: scale(ball(rng), s * W_CAM),
            alpha: scale(gauss3(rng), s * ALPHA_CAM),
        };
        let cameras: Vec<Pose> = taus.iter().map(|&t| camera.at(t)).collect();
        // The camera at tau = 0 is the identity: a pixel at depth z back-projects to this.
        let back = |u: f64, v: f64, z: f64| -> V3 {
            [(u - 0.5 * w) / focal * z, (v - 0.5 * h) / focal * z, z]
        };
        let mut motions = vec![vec![Pose::IDENTITY; setup.frames]];
        let mut half_sizes = vec![0.0];
        let mut flat = vec![false];
        for _ in 1..setup.counts.len() {
            let depth = uniform(rng, OBJ_DEPTH);
            let (u, v) = (
                uniform(rng, [0.2 * w, 0.8 * w]),
                uniform(rng, [0.2 * h, 0.8 * h]),
            );
            let centre = back(u, v, depth);
            let r = (uniform(rng, OBJ_SIZE) * depth * w.min(h) / (2.0 * focal)).min(0.4 * depth);
            let r0 = random_rotation(rng);
            let speed = s * V_OBJ * rng.random_range(0.2..=1.0);
            let object = Smooth {
                p0: centre,
                v: scale(unit(rng), speed),
                a: scale(gauss3(rng), s * A_OBJ),
                r0,
                w: scale(ball(rng), s * W_OBJ),
                alpha: scale(gauss3(rng), s * ALPHA_OBJ),
            };
            motions.push(taus.iter().map(|&t| object.at(t)).collect());
            half_sizes.push(r);
            flat.push(setup.planar > 0.0 && rng.random_bool(setup.planar));
        }
        let noise = Normal::new(0.0, setup.noise).expect("validated sigma");
        let mut tracks = Vec::new();
        for (m, &n) in setup.counts.iter().enumerate() {
            let budget = ATTEMPTS_PER_TRACK * n + ATTEMPTS_EXTRA;
            let (mut found, mut tries) = (0, 0);
            while found < n {
                if limited && tries >= budget {
                    return None;
                }
                tries += 1;
                let body = if m == 0 {
                    let (u, v) = (rng.random_range(0.0..w), rng.random_range(0.0..h));
                    back(u, v, uniform(rng, BG_DEPTH))
                } else {
                    let r = half_sizes[m];
                    let mut x: V3 = [0; 3].map(|_| rng.random_range(-r..=r));
                    if flat[m] {
                        x[2] = 0.0;
                    }
                    x
                };
                let mut row = Vec::with_capacity(2 * setup.frames);
                for (camera, pose) in cameras.iter().zip(&motions[m]) {
                    let Some([x, y]) = project(camera, focal, w, h, pose.apply(body)) else {
                        break;
                    };
                    let (x, y) = (x + noise.sample(rng), y + noise.sample(rng));
                    if !((0.0..w).contains(&x) && (0.0..h).contains(&y)) {
                        break;
                    }
                    row.extend([x, y]);
                }
                if row.len() == 2 * setup.frames {
                    tracks.push((row, m, body));
                    found += 1;
                }
            }
        }
        let truth = MotionTruth {
            focal,
            image: ImageSize::new(w, h).expect("validated image size"),
            motion_scale: s,
            halvings: 0,
            noise: setup.noise,
            cameras,
            motions,
            flat,
            body: vec![],
        };
        Some((tracks, truth))
    }

    /// Adds the outlier walks, shuffles and labels.
    fn finish(
        &mut self,
        setup: &Setup,
        tracks: Vec<(Vec<f64>, usize, V3)>,
        mut truth: MotionTruth,
        name: &str,
    ) -> MotionSample {
        let rng = &mut self.rng;
        let (w, h, frames) = (setup.width, setup.height, setup.frames);
        let inliers = tracks.len();
        let phi = setup.outlier_fraction;
        let outliers = (phi / (1.0 - phi) * inliers as f64).round() as usize;
        // Raw labels as in a file: outliers 0, motions 1..=K.
        let mut rows: Vec<TrackRow> = tracks
            .into_iter()
            .map(|(row, m, body)| (row, m + 1, Some((m, body))))
            .collect();
        if outliers > 0 {
            let mut steps: Vec<f64> = rows
                .iter()
                .flat_map(|(row, ..)| {
                    (1..frames).map(move |f| {
                        (row[2 * f] - row[2 * f - 2]).hypot(row[2 * f + 1] - row[2 * f - 1])
                    })
                })
                .collect();
            steps.sort_by(f64::total_cmp);
            let median = steps[steps.len() / 2];
            let walk = Normal::new(0.0, (median / 2f64.sqrt()).max(0.5)).expect("finite sigma");
            for _ in 0..outliers {
                let mut p = [rng.random_range(0.0..w), rng.random_range(0.0..h)];
                let mut row = vec![p[0], p[1]];
                for _ in 1..frames {
                    p = [
                        reflect(p[0] + walk.sample(rng), w),
                        reflect(p[1] + walk.sample(rng), h),
                    ];
                    row.extend(p);
                }
                rows.push((row, 0, None));
            }
        }
        // Fisher-Yates with our own rng, so the order is part of the seed.
        for i in (1..rows.len()).rev() {
            let j = rng.random_range(0..=i);
            rows.swap(i, j);
        }
        let shift = usize::from(outliers == 0);
        let labels = rows.iter().map(|r| r.1 - shift).collect();
        truth.body = rows.iter().map(|r| r.2).collect();
        let values: Vec<f64> = rows.into_iter().flat_map(|r| r.0).collect();
        let points =
            PointSet::from_flat(Kind::Trajectories, 2 * frames, values).expect("finite, in image");
        let motions = setup.counts.len();
        let range = self.params.dropout;
        let visible = (range[1] > 0.0).then(|| dropout(rng, range, points.len(), frames));
        MotionSample {
            visible,
            sample: Sample {
                name: name.to_string(),
                points,
                labels,
                k: motions + usize::from(outliers > 0),
                image_size: Some(truth.image),
                outliers: outliers > 0,
            },
            motions,
            frames,
            outliers,
            truth,
        }
    }
}

/// Which frames each of `tracks` tracks is seen in: a share φ (uniform in `range`) of them, in
/// input order, is seen only in a run of L consecutive frames (L uniform in 2..frames, its start
/// uniform), the others in every frame; at least 2 tracks are seen throughout, and with 2
/// frames every track is.
fn dropout(rng: &mut ChaCha8Rng, range: [f64; 2], tracks: usize, frames: usize) -> Vec<Vec<u8>> {
    let phi = uniform(rng, range);
    let mut seen = vec![vec![1u8; frames]; tracks];
    for row in seen.iter_mut().skip(2) {
        if frames < 3 || rng.random::<f64>() >= phi {
            continue;
        }
        let len = rng.random_range(2..frames);
        let start = rng.random_range(0..=frames - len);
        for (f, v) in row.iter_mut().enumerate() {
            *v = u8::from((start..start + len).contains(&f));
        }
    }
    seen
}

/// `x` reflected at 0 and `len` into `[0, len)`.
fn reflect(x: f64, len: f64) -> f64 {
    let y = x.rem_euclid(2.0 * len);
    let y = if y >= len { 2.0 * len - y } else { y };
    y.min(len.next_down()).max(0.0)
}

impl MotionSample {
    /// The sample in the on-disk dataset format (kind `trajectories`; outliers raw label 0, the
    /// background 1, objects 2..=K; with dropout, the `visible` mask).
    pub fn to_file(&self, seed: u64) -> SequenceFile {
        let s = &self.sample;
        let t = &self.truth;
        let shift = usize::from(self.outliers == 0);
        let mut source = format!(
            "multifit synthetic motion (seed {seed}): {} motions (label 1 the static background, 2..={} rigid objects), {} frames, focal {} px, image {}x{}, motion scale {}, noise {} px",
            self.motions,
            self.motions,
            self.frames,
            t.focal,
            t.image.width,
            t.image.height,
            t.motion_scale,
            t.noise
        );
        if self.outliers > 0 {
            source += &format!(
                "; {} gross outlier tracks (label 0, random walks)",
                self.outliers
            );
        }
        let flat: Vec<String> = t
            .flat
            .iter()
            .enumerate()
            .filter(|&(_, &f)| f)
            .map(|(m, _)| (m + 1).to_string())
            .collect();
        if !flat.is_empty() {
            source += &format!(
                "; flat objects (planar patches): labels {}",
                flat.join(", ")
            );
        }
        if let Some(v) = &self.visible {
            let partly = v.iter().filter(|row| row.contains(&0)).count();
            source += &format!("; {partly} tracks seen in only part of the clip (visible)");
        }
        SequenceFile {
            name: s.name.clone(),
            kind: Kind::Trajectories,
            points: (0..s.points.len())
                .map(|i| s.points.row(i).to_vec())
                .collect(),
            labels: s.labels.iter().map(|&l| (l + shift) as i64).collect(),
            num_models: Some(self.motions),
            image_size: Some([t.image.width, t.image.height]),
            source: Some(source),
            model_type: None,
            visible: self.visible.clone(),
        }
    }
}

/// `count` samples of `params` from `seed`, named `motion-s<seed>-<i:05>`.
pub fn generate(params: &MotionParams, count: usize, seed: u64) -> Result<Vec<Sample>, RangeError> {
    let mut generator = MotionGenerator::new(seed, *params)?;
    Ok((0..count)
        .map(|i| generator.sample(&format!("motion-s{seed}-{i:05}")).sample)
        .collect())
}

/// A generated motion dataset, written `motion:[count=N][,seed=S][,frames=A-B][,motions=A-B]
/// [,points=A-B][,noise=A-B][,outliers=A-B][,motion-scale=A-B][,focal=A-B][,width=A-B]
/// [,height=A-B]` wherever a dataset path is accepted (defaults: 200 samples, seed 0,
/// [`MotionParams::default`]).
#[derive(Debug, Clone, PartialEq)]
pub struct MotionSpec {
    pub count: usize,
    pub seed: u64,
    pub params: MotionParams,
}

impl MotionSpec {
    /// Most samples one spec may ask for.
    pub const MAX_COUNT: usize = 1_000_000;

    /// Checks the count and the params; errors name the spec key (`frames=1: ...`).
    pub fn validate(&self) -> Result<(), SpecError> {
        check_count(self.count, Self::MAX_COUNT)?;
        self.params.validate().map_err(SpecError::Setting)
    }

    /// The samples in the on-disk format, in generation order, named `motion-s<seed>-<i:05>`.
    pub fn files(&self) -> Result<impl Iterator<Item = SequenceFile> + '_, RangeError> {
        let mut generator = MotionGenerator::new(self.seed, self.params)?;
        Ok((0..self.count).map(move |i| {
            generator
                .sample(&format!("motion-s{}-{i:05}", self.seed))
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

impl std::fmt::Display for MotionSpec {
    /// Every setting, so that the text parses back to the same spec.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let p = &self.params;
        write!(
            f,
            "motion:count={},seed={},frames={},motions={},points={},noise={},outliers={},motion-scale={},focal={},width={},height={}",
            self.count,
            self.seed,
            range_text(p.frames),
            range_text(p.motions),
            range_text(p.points),
            range_text(p.noise),
            range_text(p.outliers),
            range_text(p.motion_scale),
            range_text(p.focal),
            range_text(p.width),
            range_text(p.height)
        )?;
        if p.dropout != [0.0, 0.0] {
            write!(f, ",dropout={}", range_text(p.dropout))?;
        }
        if p.planar != [0.0, 0.0] {
            write!(f, ",planar={}", range_text(p.planar))?;
        }
        Ok(())
    }
}

impl std::str::FromStr for MotionSpec {
    type Err = SpecError;

    /// Parses the part after `motion:`, e.g. `count=500,seed=3,frames=5,motions=2-4` (empty:
    /// every default).
    fn from_str(text: &str) -> Result<Self, SpecError> {
        let mut spec = MotionSpec {
            count: 200,
            seed: 0,
            params: MotionParams::default(),
        };
        for part in text.split(',').filter(|p| !p.is_empty()) {
            let setting = Setting::parse(part)?;
            let p = &mut spec.params;
            match setting.key {
                "count" => spec.count = setting.value()?,
                "seed" => spec.seed = setting.value()?,
                "frames" => p.frames = setting.pair()?,
                "motions" => p.motions = setting.pair()?,
                "points" => p.points = setting.pair()?,
                "noise" => p.noise = setting.pair()?,
                "outliers" => p.outliers = setting.pair()?,
                "motion-scale" => p.motion_scale = setting.pair()?,
                "focal" => p.focal = setting.pair()?,
                "width" => p.width = setting.pair()?,
                "height" => p.height = setting.pair()?,
                "dropout" => p.dropout = setting.pair()?,
                "planar" => p.planar = setting.pair()?,
                _ => {
                    return Err(SpecError::UnknownSetting {
                        generator: "motion",
                        key: setting.key.to_string(),
                        known: "count, seed, frames, motions, points, noise, outliers, motion-scale, focal, width, height, dropout, planar",
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
    use crate::geometry::{Model, fit_type, linalg::svd};

    fn params(f: impl FnOnce(&mut MotionParams)) -> MotionParams {
        let mut p = MotionParams::default();
        f(&mut p);
        p
    }

    /// The rows of `s` whose label is `label`.
    fn group(s: &Sample, label: usize) -> Vec<&[f64]> {
        (0..s.points.len())
            .filter(|&i| s.labels[i] == label)
            .map(|i| s.points.row(i))
            .collect()
    }

    #[test]
    fn seeded_and_reproducible() {
        let p = params(|p| p.outliers = [0.0, 0.3]);
        let a = generate(&p, 3, 7).unwrap();
        let b = generate(&p, 3, 7).unwrap();
        let c = generate(&p, 3, 8).unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.points, y.points);
            assert_eq!(x.labels, y.labels);
            assert_eq!((x.k, &x.name, x.image_size), (y.k, &y.name, y.image_size));
        }
        assert_ne!(a[0].points, c[0].points);
        assert_eq!(a[2].name, "motion-s7-00002");
    }

    #[test]
    fn shapes_counts_and_labels_follow_the_ranges() {
        let p = MotionParams::default();
        let mut g = MotionGenerator::new(3, p).unwrap();
        let (mut frames, mut motions) = (
            std::collections::BTreeSet::new(),
            std::collections::BTreeSet::new(),
        );
        for i in 0..40 {
            let m = g.sample(&i.to_string());
            let s = &m.sample;
            assert_eq!(s.points.kind(), Kind::Trajectories);
            assert_eq!(s.points.dim(), 2 * m.frames, "rows are 2F wide");
            assert!((2..=30).contains(&m.frames));
            assert!((2..=5).contains(&m.motions));
            assert_eq!((m.outliers, s.k), (0, m.motions), "no outliers by default");
            for l in 0..m.motions {
                assert!((30..=200).contains(&group(s, l).len()), "motion {l}");
            }
            assert!(s.labels.iter().all(|&l| l < s.k));
            // Label 0 is the background: its body points are world points, the identity pose.
            for (row, &label) in s.labels.iter().enumerate() {
                let (motion, _) = m.truth.body[row].unwrap();
                assert_eq!(motion, label);
            }
            let size = s.image_size.unwrap();
            assert!((640.0..=1920.0).contains(&size.width) && size.width.fract() == 0.0);
            assert!((360.0..=1080.0).contains(&size.height));
            assert!((300.0..=1500.0).contains(&m.truth.focal));
            assert!((0.0..=1.0).contains(&m.truth.noise));
            assert!(m.truth.motion_scale <= 1.0);
            for i in 0..s.points.len() {
                for (d, v) in s.points.row(i).iter().enumerate() {
                    let side = if d % 2 == 0 { size.width } else { size.height };
                    assert!((0.0..side).contains(v), "row {i} value {d}: {v}");
                }
            }
            frames.insert(m.frames);
            motions.insert(m.motions);
        }
        assert_eq!(motions.len(), 4, "{motions:?}");
        assert!(frames.len() > 15, "{frames:?}");
    }

    #[test]
    fn noise_free_tracks_are_the_projections_of_their_points() {
        let p = params(|p| p.noise = [0.0, 0.0]);
        let mut g = MotionGenerator::new(11, p).unwrap();
        for _ in 0..5 {
            let m = g.sample("n");
            let s = &m.sample;
            for i in 0..s.points.len() {
                let (motion, body) = m.truth.body[i].unwrap();
                for f in 0..m.frames {
                    let [x, y] = m.truth.project(motion, f, body).unwrap();
                    let row = s.points.row(i);
                    assert!((row[2 * f] - x).abs() < 1e-9 && (row[2 * f + 1] - y).abs() < 1e-9);
                }
            }
        }
        // With noise, the offsets from the projections have the drawn sigma.
        let p = params(|p| p.noise = [1.5, 1.5]);
        let m = MotionGenerator::new(12, p).unwrap().sample("n");
        let (mut ss, mut n) = (0.0, 0);
        for i in 0..m.sample.points.len() {
            let (motion, body) = m.truth.body[i].unwrap();
            let row = m.sample.points.row(i);
            for f in 0..m.frames {
                let [x, y] = m.truth.project(motion, f, body).unwrap();
                ss += (row[2 * f] - x).powi(2) + (row[2 * f + 1] - y).powi(2);
                n += 2;
            }
        }
        let sigma = (ss / n as f64).sqrt();
        assert!((1.3..1.7).contains(&sigma), "{sigma}");
    }

    /// The frame-`a` and frame-`b` positions of tracks, as correspondence rows.
    fn pairs(rows: &[&[f64]], a: usize, b: usize) -> Vec<Vec<f64>> {
        rows.iter()
            .map(|r| vec![r[2 * a], r[2 * a + 1], r[2 * b], r[2 * b + 1]])
            .collect()
    }

    /// Each rigid group is seen through one perspective camera pair: its first and last frames
    /// satisfy one fundamental matrix exactly (fitted by `crate::geometry`), and two groups
    /// together do not.
    #[test]
    fn noise_free_rigid_groups_obey_epipolar_geometry() {
        let p = params(|p| {
            p.noise = [0.0, 0.0];
            p.frames = [6, 6];
            p.motions = [3, 3];
            p.points = [40, 60];
            p.motion_scale = [0.3, 0.3];
        });
        let mut g = MotionGenerator::new(21, p).unwrap();
        for _ in 0..4 {
            let m = g.sample("e");
            let s = &m.sample;
            let rms = |rows: &[Vec<f64>]| {
                let view: Vec<&[f64]> = rows.iter().map(|r| r.as_slice()).collect();
                let fit = fit_type("fundamental", &view).unwrap();
                assert!(matches!(fit.model, Model::Fundamental { .. }), "{fit:?}");
                let sq: f64 = view.iter().map(|r| fit.model.residual(r).powi(2)).sum();
                (sq / view.len() as f64).sqrt()
            };
            for l in 0..m.motions {
                let rows = pairs(&group(s, l), 0, m.frames - 1);
                let e = rms(&rows);
                assert!(e < 1e-6, "motion {l}: Sampson rms {e}");
            }
            let mut both = pairs(&group(s, 0), 0, m.frames - 1);
            both.extend(pairs(&group(s, 1), 0, m.frames - 1));
            let e = rms(&both);
            assert!(e > 0.1, "background and object share one F: {e}");
        }
    }

    /// The share of the centred block's energy beyond its top `rank` singular values.
    fn beyond_rank(rows: &[&[f64]], rank: usize) -> f64 {
        let (n, d) = (rows.len(), rows[0].len());
        let mean: Vec<f64> = (0..d)
            .map(|j| rows.iter().map(|r| r[j]).sum::<f64>() / n as f64)
            .collect();
        // n x 2F (n >= 2F here), the transpose of the 2F x n block: same singular values.
        let a: Vec<f64> = rows
            .iter()
            .flat_map(|r| r.iter().zip(&mean).map(|(v, m)| v - m))
            .collect();
        let s = svd(&a, n, d).s;
        let all: f64 = s.iter().map(|v| v * v).sum();
        (s[rank..].iter().map(|v| v * v).sum::<f64>() / all).sqrt()
    }

    /// Under small motion the perspective camera is nearly affine: each rigid group's centred
    /// 2F x n block is nearly of rank 4 (an affine camera gives 3). Its energy beyond a static
    /// image (rank 2) is real motion, and rank 4 holds at least 95% of that too. (Two groups
    /// together are no test here: under small, nearly constant velocity every track is close to
    /// `x0 + tau u`, rank 4 whatever its group; `noise_free_rigid_groups_obey_epipolar_geometry`
    /// tells groups apart.)
    #[test]
    fn small_motion_groups_are_nearly_low_rank() {
        let p = params(|p| {
            p.noise = [0.0, 0.0];
            p.frames = [5, 5];
            p.motions = [3, 3];
            p.points = [60, 60];
            p.motion_scale = [0.05, 0.05];
        });
        let mut g = MotionGenerator::new(5, p).unwrap();
        for _ in 0..5 {
            let m = g.sample("r");
            for l in 0..3 {
                let rows = group(&m.sample, l);
                let (r2, r4) = (beyond_rank(&rows, 2), beyond_rank(&rows, 4));
                assert!(r4 < 1e-4, "motion {l}: rank-4 residual {r4}");
                assert!(r2 > 1e-4 && r4 < 0.05 * r2, "motion {l}: {r2} {r4}");
            }
        }
    }

    #[test]
    fn motion_scale_sets_the_pixel_speed() {
        let speed = |scale: f64| {
            let p = params(|p| {
                p.noise = [0.0, 0.0];
                p.frames = [5, 5];
                p.motion_scale = [scale, scale];
            });
            let mut steps = Vec::new();
            for s in generate(&p, 10, 4).unwrap() {
                for i in 0..s.points.len() {
                    let r = s.points.row(i);
                    for f in 1..5 {
                        steps.push((r[2 * f] - r[2 * f - 2]).hypot(r[2 * f + 1] - r[2 * f - 1]));
                    }
                }
            }
            steps.sort_by(f64::total_cmp);
            steps[steps.len() / 2]
        };
        let (slow, fast) = (speed(0.05), speed(1.0));
        assert!(slow < 5.0, "hand-held median step {slow} px");
        assert!(
            fast > 8.0 * slow,
            "driving {fast} px vs hand-held {slow} px"
        );
    }

    /// Motion too large to keep anything in view for 30 frames: the scene is redrawn slower
    /// until every track is visible in every frame.
    #[test]
    fn tracks_that_would_leave_the_image_are_redrawn_slower() {
        let p = params(|p| {
            p.frames = [30, 30];
            p.motion_scale = [10.0, 10.0];
            p.noise = [0.0, 0.0];
        });
        let m = MotionGenerator::new(2, p).unwrap().sample("fast");
        assert!(m.truth.motion_scale < 10.0, "{}", m.truth.motion_scale);
        let size = m.sample.image_size.unwrap();
        for i in 0..m.sample.points.len() {
            let (motion, body) = m.truth.body[i].unwrap();
            for f in 0..30 {
                let [x, y] = m.truth.project(motion, f, body).expect("in front");
                assert!((0.0..size.width).contains(&x) && (0.0..size.height).contains(&y));
            }
        }
    }

    #[test]
    fn outliers_are_random_walks_labelled_0_inside_the_image() {
        let p = params(|p| {
            p.outliers = [0.3, 0.3];
            p.frames = [8, 8];
        });
        let m = MotionGenerator::new(9, p).unwrap().sample("o");
        let s = &m.sample;
        let inliers = s.labels.iter().filter(|&&l| l != 0).count();
        assert_eq!(m.outliers, (0.3 / 0.7 * inliers as f64).round() as usize);
        assert_eq!(group(s, 0).len(), m.outliers);
        assert_eq!(s.k, m.motions + 1);
        for (row, &label) in s.labels.iter().enumerate() {
            match m.truth.body[row] {
                None => assert_eq!(label, 0),
                Some((motion, _)) => assert_eq!(label, motion + 1),
            }
        }
        let size = s.image_size.unwrap();
        let mut moved = 0.0;
        for r in group(s, 0) {
            for f in 0..8 {
                assert!((0.0..size.width).contains(&r[2 * f]));
                assert!((0.0..size.height).contains(&r[2 * f + 1]));
            }
            moved += (r[14] - r[0]).hypot(r[15] - r[1]);
        }
        assert!(moved > 0.0, "outlier tracks move");
        // In a file: raw label 0 for outliers, background 1, objects 2..=K; loading it gives the
        // sample back.
        let file = m.to_file(9);
        assert_eq!(file.num_models, Some(m.motions));
        assert_eq!(file.image_size, Some([size.width, size.height]));
        assert!(
            file.labels
                .iter()
                .all(|&l| (0..=m.motions as i64).contains(&l))
        );
        let back = Sequence::from_file(file, std::path::Path::new("o"))
            .unwrap()
            .sample();
        assert_eq!((back.labels, back.k), (s.labels.clone(), s.k));
        assert_eq!(back.points, s.points);
        // Without outliers a file holds 1..=K, as KT3DMoSeg's, and loads to 0..K.
        let m = MotionGenerator::new(9, MotionParams::default())
            .unwrap()
            .sample("c");
        let file = m.to_file(9);
        assert!(
            file.labels
                .iter()
                .all(|&l| (1..=m.motions as i64).contains(&l))
        );
        let back = Sequence::from_file(file, std::path::Path::new("c"))
            .unwrap()
            .sample();
        assert_eq!(back.labels, m.sample.labels);
    }

    #[test]
    fn validate_names_the_flag_of_each_bad_setting() {
        assert!(MotionParams::default().validate().is_ok());
        for (bad, says) in [
            (
                params(|p| p.frames = [1, 30]),
                "--frames 1-30: frames must lie in [2, 100]",
            ),
            (params(|p| p.frames = [2, 101]), "--frames 2-101: "),
            (
                params(|p| p.frames = [9, 3]),
                "--frames 9-3: the smallest value (9) exceeds the largest (3)",
            ),
            (
                params(|p| p.motions = [0, 3]),
                "--motions 0-3: motions must lie in [1, 10]",
            ),
            (params(|p| p.motions = [2, 11]), "--motions 2-11: "),
            (
                params(|p| p.points = [0, 0]),
                "--points 0: tracks per motion must lie in [4, 100000]",
            ),
            (params(|p| p.points = [3, 10]), "--points 3-10: "),
            (
                params(|p| p.points = [50, 20]),
                "--points 50-20: the smallest value (50)",
            ),
            (
                params(|p| p.noise = [-0.1, 1.0]),
                "--noise -0.1-1: noise (px) must lie in [0, 20]",
            ),
            (params(|p| p.noise = [0.0, f64::NAN]), "--noise 0-NaN: "),
            (
                params(|p| p.noise = [2.0, 1.0]),
                "--noise 2-1: the smallest value (2)",
            ),
            (
                params(|p| {
                    p.noise = [10.0, 10.0];
                    p.height = [100.0, 200.0];
                }),
                "--noise 10: noise up to 10 px needs images of at least 160 px a side",
            ),
            (
                params(|p| p.outliers = [0.0, 1.0]),
                "--outliers 0-1: the outlier fraction must lie in [0, 1)",
            ),
            (params(|p| p.outliers = [-0.5, 0.0]), "--outliers -0.5-0: "),
            (
                params(|p| p.outliers = [0.5, 0.2]),
                "--outliers 0.5-0.2: the smallest",
            ),
            (
                params(|p| p.outliers = [0.9999999, 0.9999999]),
                "--outliers 0.9999999: with up to 1000 tracks",
            ),
            (
                params(|p| p.motion_scale = [0.0, 1.0]),
                "--motion-scale 0-1: the motion scale must lie in (0, 10]",
            ),
            (
                params(|p| p.motion_scale = [0.1, 11.0]),
                "--motion-scale 0.1-11: ",
            ),
            (
                params(|p| p.motion_scale = [1.0, 0.5]),
                "--motion-scale 1-0.5: the smallest",
            ),
            (
                params(|p| p.focal = [10.0, 100.0]),
                "--focal 10-100: focal (px) must lie in [50, 100000]",
            ),
            (
                params(|p| p.focal = [f64::INFINITY, f64::INFINITY]),
                "--focal inf: ",
            ),
            (
                params(|p| p.width = [32.0, 640.0]),
                "--width 32-640: width (px) must lie in [64, 100000]",
            ),
            (
                params(|p| p.height = [480.0, 240.0]),
                "--height 480-240: the smallest",
            ),
        ] {
            let err = bad.validate().unwrap_err();
            assert!(err.to_string().starts_with(says), "{err} (wanted {says})");
            assert!(says.starts_with(err.flag()));
            assert!(MotionGenerator::new(0, bad).is_err());
            assert!(generate(&bad, 1, 0).is_err());
        }
        let err = params(|p| p.frames = [1, 1]).validate().unwrap_err();
        assert_eq!(err.key(), "frames");
        assert_eq!(err.for_spec(), "frames=1: frames must lie in [2, 100]");
        assert!(matches!(
            params(|p| p.frames = [5, 2]).validate(),
            Err(RangeError::Inverted {
                flag: "--frames",
                ..
            })
        ));
    }

    /// An optional setting is printed only when set: absent from `plain`'s text, last in
    /// `with`'s, which parses back to `with`.
    fn printed_only_when_set(plain: &MotionSpec, with: &MotionSpec, setting: &str) {
        let key = setting.split('=').next().unwrap_or(setting);
        assert!(!plain.to_string().contains(key));
        let text = with.to_string();
        assert!(text.ends_with(&format!(",{setting}")), "{text}");
        assert_eq!(
            text["motion:".len()..].parse::<MotionSpec>().unwrap(),
            *with
        );
    }

    /// Dropout: a share of the tracks seen in one run of 2 or more consecutive frames, at least
    /// two seen throughout, the rows as without it; no dropout draws nothing (the same samples
    /// as before it existed), and the spec prints it only when set.
    #[test]
    fn dropout_hides_runs_of_frames_and_leaves_the_rest_as_it_was() {
        let plain: MotionSpec = "count=4,seed=9,frames=12,motions=2-3,points=20-30"
            .parse()
            .unwrap();
        let spec: MotionSpec = "count=4,seed=9,frames=12,motions=2-3,points=20-30,dropout=0.5"
            .parse()
            .unwrap();
        printed_only_when_set(&plain, &spec, "dropout=0.5");
        let a: Vec<SequenceFile> = plain.files().unwrap().collect();
        let b: Vec<SequenceFile> = spec.files().unwrap().collect();
        // The first sample is drawn before any dropout: its rows are the same.
        assert_eq!(a[0].points, b[0].points);
        assert!(a.iter().all(|f| f.visible.is_none()));
        for f in &b {
            let v = f.visible.as_ref().unwrap();
            assert_eq!(v.len(), f.points.len());
            assert!(v.iter().filter(|r| r.iter().all(|&x| x == 1)).count() >= 2);
            let partly: Vec<&Vec<u8>> = v.iter().filter(|r| r.contains(&0)).collect();
            let share = partly.len() as f64 / v.len() as f64;
            assert!((0.3..0.7).contains(&share), "{share}");
            for r in partly {
                let on: Vec<usize> = (0..12).filter(|&t| r[t] == 1).collect();
                assert!(on.len() >= 2 && on.len() < 12);
                assert_eq!(on.last().unwrap() - on[0] + 1, on.len(), "one run: {r:?}");
            }
        }
        let bad = "dropout=1".parse::<MotionSpec>().unwrap_err().to_string();
        assert!(bad.starts_with("dropout=1"), "{bad}");
    }

    #[test]
    fn flat_objects_lie_on_a_plane_and_leave_other_settings_as_they_were() {
        let base = "count=6,seed=21,frames=8,motions=3-4,points=20-30,noise=0";
        let plain: MotionSpec = base.parse().unwrap();
        let none: MotionSpec = format!("{base},planar=0").parse().unwrap();
        let all: MotionSpec = format!("{base},planar=1").parse().unwrap();
        printed_only_when_set(&plain, &all, "planar=1");
        // Asking for none draws nothing more: the same samples.
        let a: Vec<SequenceFile> = plain.files().unwrap().collect();
        let b: Vec<SequenceFile> = none.files().unwrap().collect();
        assert_eq!(
            a.iter().map(|f| &f.points).collect::<Vec<_>>(),
            b.iter().map(|f| &f.points).collect::<Vec<_>>()
        );
        let mut flat_rows = 0;
        let mut generator = MotionGenerator::new(21, all.params).unwrap();
        for i in 0..6 {
            let m = generator.sample(&format!("s{i}"));
            assert!(!m.truth.flat[0] && m.truth.flat[1..].iter().all(|&f| f));
            for (motion, body) in m.truth.body.iter().flatten() {
                if *motion > 0 {
                    assert_eq!(body[2], 0.0);
                    flat_rows += 1;
                }
            }
            assert!(m.to_file(21).source.unwrap().contains("flat objects"));
        }
        assert!(flat_rows > 100);
        // Cube objects (the default) are not flat. Under an affine camera a flat object's
        // centred tracks span 2 dimensions and a solid one's 3; under small perspective motion,
        // nearly: the flat objects' energy beyond rank 2 is a fraction of the cubes'.
        let small = |spec: &MotionSpec| MotionParams {
            motion_scale: [0.05, 0.05],
            ..spec.params
        };
        let beyond = |params: MotionParams| -> f64 {
            let mut generator = MotionGenerator::new(5, params).unwrap();
            let shares: Vec<f64> = (0..6)
                .map(|i| {
                    let m = generator.sample(&format!("s{i}"));
                    beyond_rank(&group(&m.sample, 1), 2)
                })
                .collect();
            shares.iter().sum::<f64>() / shares.len() as f64
        };
        let (flat, solid) = (beyond(small(&all)), beyond(small(&plain)));
        assert!(flat < 0.2 * solid, "flat {flat}, solid {solid}");
        let m = MotionGenerator::new(21, plain.params)
            .unwrap()
            .sample("cube");
        assert!(m.truth.flat.iter().all(|&f| !f));
        assert!(
            m.truth
                .body
                .iter()
                .flatten()
                .any(|(motion, body)| *motion > 0 && body[2] != 0.0)
        );
        let bad = "planar=1.5".parse::<MotionSpec>().unwrap_err().to_string();
        assert!(bad.starts_with("planar=1.5"), "{bad}");
    }

    #[test]
    fn spec_parses_prints_and_generates_what_its_files_hold() {
        let text = "count=3,seed=4,frames=5,motions=2-3,points=20-40,noise=0.5,outliers=0-0.2,motion-scale=0.1-0.5,focal=700,width=1242,height=375";
        let spec: MotionSpec = text.parse().unwrap();
        assert_eq!(spec.params.frames, [5, 5]);
        assert_eq!(spec.params.outliers, [0.0, 0.2]);
        assert_eq!(
            (spec.params.width, spec.params.height),
            ([1242.0; 2], [375.0; 2])
        );
        assert_eq!(spec.to_string(), format!("motion:{text}"));
        assert_eq!(
            spec.to_string()["motion:".len()..]
                .parse::<MotionSpec>()
                .unwrap(),
            spec
        );
        let defaults: MotionSpec = "".parse().unwrap();
        assert_eq!((defaults.count, defaults.seed), (200, 0));
        assert_eq!(defaults.params, MotionParams::default());
        // Through the data source, as `--data motion:...`.
        let source: crate::data::DataSource = format!("motion:{text}").parse().unwrap();
        assert_eq!(source, crate::data::DataSource::Motion(spec.clone()));
        assert_eq!(source.to_string(), spec.to_string());
        let seqs = source.sequences(None).unwrap();
        assert!(source.sequences(Some("homography")).is_err());
        let samples = generate(&spec.params, 3, 4).unwrap();
        assert_eq!(seqs.len(), 3);
        for (seq, s) in seqs.iter().zip(&samples) {
            let back = seq.sample();
            assert_eq!(back.name, s.name);
            assert_eq!(back.points, s.points);
            assert_eq!((back.labels, back.k), (s.labels.clone(), s.k));
            assert_eq!(back.image_size, s.image_size);
            assert_eq!(seq.frames(), 5);
        }
        for (bad, says) in [
            ("count=0", "count=0: count must be 1 to 1000000"),
            ("frames=1", "frames=1: frames must lie in [2, 100]"),
            ("points=0", "points=0: tracks per motion"),
            (
                "outliers=1",
                "outliers=1: the outlier fraction must lie in [0, 1)",
            ),
            ("noise=3-1", "noise=3-1: the smallest value (3)"),
            ("frames=x", "frames=\"x\""),
            ("colour=red", "unknown motion setting"),
            ("seed", "not key=value"),
        ] {
            let err = bad.parse::<MotionSpec>().unwrap_err().to_string();
            assert!(err.contains(says), "{bad}: {err}");
        }
    }
}
