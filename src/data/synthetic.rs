//! Synthetic LCE data (lines, circles, ellipses), following the paper's description.
//!
//! The authors' generator is not public; these are the ranges this project chose. All shapes live
//! in a unit-scale frame (roughly `[-1.6, 1.6]^2`) and every point gets isotropic Gaussian noise of
//! `noise` (0.05 by default, the paper's sigma):
//! - line: centre uniform in `[-0.5, 0.5]^2`, direction uniform in `[0, pi)`, half-length uniform
//!   in `[0.6, 1.0]`, points uniform along the segment;
//! - circle: centre uniform in `[-0.5, 0.5]^2`, radius uniform in `[0.25, 0.6]`, angle uniform;
//! - ellipse: centre uniform in `[-0.5, 0.5]^2`, semi-major axis uniform in `[0.3, 0.7]`, minor /
//!   major ratio uniform in `[0.3, 0.7]` (so it never looks like a circle), rotation uniform in
//!   `[0, pi)`, parameter angle uniform;
//! - `points_per_shape` points per structure (50 by default), rows shuffled;
//! - `scale` (1 by default) multiplies every length above (centre box, half-length, radii, axes)
//!   but not the noise, so `scale = 2` gives the same shapes with half the relative noise.
//!
//! LCE (mixed): one line, two ellipses and one circle. LCE-Unmixed: 2 to 4 instances of one type.

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use super::dataset::{DataError, Sample, Sequence, SequenceFile};
use super::points::{Kind, PointSet};

/// A curve type of the LCE data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Shape {
    Line,
    Circle,
    Ellipse,
}

impl Shape {
    pub const ALL: [Shape; 3] = [Shape::Line, Shape::Circle, Shape::Ellipse];
}

/// Which LCE variant to generate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum LceVariant {
    /// One line, two ellipses and one circle.
    Mixed,
    /// 2 to 4 instances of one shape type (type and count drawn per sample).
    Unmixed,
}

/// Generator settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LceConfig {
    pub points_per_shape: usize,
    pub noise: f64,
    /// Multiplies every shape length (not the noise); 1 is the unit-scale frame.
    pub scale: f64,
}

impl LceConfig {
    /// Checks the settings a generator can draw from.
    pub fn validate(&self) -> Result<(), String> {
        if self.points_per_shape < 2 || !(self.noise.is_finite() && self.noise >= 0.0) {
            return Err(
                "points per shape must be at least 2 and noise finite and non-negative".into(),
            );
        }
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return Err("scale must be finite and positive".into());
        }
        Ok(())
    }
}

impl Default for LceConfig {
    fn default() -> Self {
        Self {
            points_per_shape: 50,
            noise: 0.05,
            scale: 1.0,
        }
    }
}

/// A seeded LCE generator: the same seed gives the same samples.
pub struct LceGenerator {
    rng: ChaCha8Rng,
    config: LceConfig,
    noise: Normal<f64>,
}

/// A generated sample: the shapes used and the points, labels `0..k` in shape order.
#[derive(Debug, Clone)]
pub struct LceSample {
    pub shapes: Vec<Shape>,
    pub sample: Sample,
}

impl LceGenerator {
    pub fn new(seed: u64, config: LceConfig) -> Self {
        let noise = Normal::new(0.0, config.noise.max(0.0)).expect("finite sigma");
        Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
            config,
            noise,
        }
    }

    /// One sample of the given variant; `name` is stored with it.
    pub fn sample(&mut self, variant: LceVariant, name: &str) -> LceSample {
        let shapes = match variant {
            LceVariant::Mixed => vec![Shape::Line, Shape::Ellipse, Shape::Ellipse, Shape::Circle],
            LceVariant::Unmixed => {
                let shape = Shape::ALL[self.rng.random_range(0..3)];
                let k = self.rng.random_range(2..=4);
                vec![shape; k]
            }
        };
        self.with_shapes(&shapes, name)
    }

    /// One sample with exactly these shapes (labels follow their order).
    pub fn with_shapes(&mut self, shapes: &[Shape], name: &str) -> LceSample {
        let m = self.config.points_per_shape;
        let mut rows: Vec<([f64; 2], usize)> = Vec::with_capacity(shapes.len() * m);
        for (label, &shape) in shapes.iter().enumerate() {
            for p in self.shape_points(shape, m) {
                rows.push((p, label));
            }
        }
        // Fisher-Yates with our own rng, so the order is part of the seed.
        for i in (1..rows.len()).rev() {
            let j = self.rng.random_range(0..=i);
            rows.swap(i, j);
        }
        let values: Vec<f64> = rows.iter().flat_map(|(p, _)| *p).collect();
        let points = PointSet::from_flat(Kind::Points2d, 2, values).expect("finite, non-empty");
        LceSample {
            shapes: shapes.to_vec(),
            sample: Sample {
                name: name.to_string(),
                points,
                labels: rows.iter().map(|r| r.1).collect(),
                k: shapes.len(),
                image_size: None,
            },
        }
    }

    fn centre(&mut self) -> (f64, f64) {
        let h = 0.5 * self.config.scale;
        (self.rng.random_range(-h..=h), self.rng.random_range(-h..=h))
    }

    fn shape_points(&mut self, shape: Shape, m: usize) -> Vec<[f64; 2]> {
        use std::f64::consts::PI;
        let (cx, cy) = self.centre();
        let scale = self.config.scale;
        let clean: Vec<[f64; 2]> = match shape {
            Shape::Line => {
                let theta = self.rng.random_range(0.0..PI);
                let half = scale * self.rng.random_range(0.6..=1.0);
                (0..m)
                    .map(|_| {
                        let t = self.rng.random_range(-half..=half);
                        [cx + t * theta.cos(), cy + t * theta.sin()]
                    })
                    .collect()
            }
            Shape::Circle => {
                let r = scale * self.rng.random_range(0.25..=0.6);
                (0..m)
                    .map(|_| {
                        let a = self.rng.random_range(0.0..2.0 * PI);
                        [cx + r * a.cos(), cy + r * a.sin()]
                    })
                    .collect()
            }
            Shape::Ellipse => {
                let a = scale * self.rng.random_range(0.3..=0.7);
                let b = a * self.rng.random_range(0.3..=0.7);
                let rot = self.rng.random_range(0.0..PI);
                let (s, c) = rot.sin_cos();
                (0..m)
                    .map(|_| {
                        let t = self.rng.random_range(0.0..2.0 * PI);
                        let (u, v) = (a * t.cos(), b * t.sin());
                        [cx + c * u - s * v, cy + s * u + c * v]
                    })
                    .collect()
            }
        };
        clean
            .into_iter()
            .map(|[x, y]| {
                [
                    x + self.noise.sample(&mut self.rng),
                    y + self.noise.sample(&mut self.rng),
                ]
            })
            .collect()
    }
}

impl LceSample {
    /// The sample in the on-disk dataset format (labels 1..K, kind `points2d`).
    pub fn to_file(&self, variant: LceVariant, seed: u64, config: &LceConfig) -> SequenceFile {
        let s = &self.sample;
        SequenceFile {
            name: s.name.clone(),
            kind: Kind::Points2d,
            points: (0..s.points.len())
                .map(|i| s.points.row(i).to_vec())
                .collect(),
            labels: s.labels.iter().map(|&l| l as i64 + 1).collect(),
            num_models: Some(s.k),
            image_size: None,
            source: Some(format!(
                "multifit synthetic LCE ({variant:?}, seed {seed}, {} points per shape, noise {}, scale {}); shapes {:?}",
                config.points_per_shape, config.noise, config.scale, self.shapes
            )),
            model_type: None,
            visible: None,
        }
    }
}

/// A generated LCE dataset, the in-memory twin of a `gen-lce` directory: `count` samples of
/// `variant` from `seed` with `config`. Written `lce:<variant>[,count=N][,seed=S][,scale=X]
/// [,noise=X][,points=N]` wherever a dataset path is accepted (defaults: 200 samples, seed 0, and
/// [`LceConfig::default`]), so training reads the samples without writing them to disk.
#[derive(Debug, Clone, PartialEq)]
pub struct LceSpec {
    pub variant: LceVariant,
    pub count: usize,
    pub seed: u64,
    pub config: LceConfig,
}

impl LceSpec {
    /// Most samples one spec may ask for: a million samples of 200 points take about 4 GB once
    /// loaded, past what a training here can use (the shipped chain's largest stage had 48000).
    pub const MAX_COUNT: usize = 1_000_000;

    /// Checks what a generator needs: a valid config and 1 to [`Self::MAX_COUNT`] samples.
    pub fn validate(&self) -> Result<(), String> {
        if self.count == 0 || self.count > Self::MAX_COUNT {
            return Err(format!("count must be 1 to {}", Self::MAX_COUNT));
        }
        self.config.validate()
    }

    /// The samples in the on-disk format, in generation order, each with its file name: what
    /// `gen-lce` writes (names `lce-<variant>-s<seed>-<i:05>`, so a directory listing sorts
    /// them back into this order for fewer than 100000 samples).
    pub fn files(&self) -> impl Iterator<Item = SequenceFile> + '_ {
        let mut generator = LceGenerator::new(self.seed, self.config);
        let tag = self.variant.tag();
        (0..self.count).map(move |i| {
            let name = format!("lce-{tag}-s{}-{i:05}", self.seed);
            generator
                .sample(self.variant, &name)
                .to_file(self.variant, self.seed, &self.config)
        })
    }

    /// The samples as validated sequences: exactly what loading the `gen-lce` directory of the
    /// same settings gives (checked by a test), without the disk. Fails only where a file would
    /// not load either (a scale so large that points overflow).
    pub fn sequences(&self) -> Result<Vec<Sequence>, DataError> {
        self.files()
            .map(|file| {
                let name = std::path::PathBuf::from(&file.name);
                Sequence::from_file(file, &name)
            })
            .collect()
    }
}

impl LceVariant {
    /// Its name on the command line and in sample names.
    pub fn tag(self) -> &'static str {
        match self {
            LceVariant::Mixed => "mixed",
            LceVariant::Unmixed => "unmixed",
        }
    }
}

impl std::fmt::Display for LceSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let c = &self.config;
        write!(
            f,
            "lce:{},count={},seed={},scale={},noise={},points={}",
            self.variant.tag(),
            self.count,
            self.seed,
            c.scale,
            c.noise,
            c.points_per_shape
        )
    }
}

impl std::str::FromStr for LceSpec {
    type Err = String;

    /// Parses the part after `lce:`, e.g. `mixed,count=12000,seed=301,scale=2`.
    fn from_str(text: &str) -> Result<Self, String> {
        let mut parts = text.split(',');
        let variant = match parts.next().unwrap_or_default() {
            "mixed" => LceVariant::Mixed,
            "unmixed" => LceVariant::Unmixed,
            other => return Err(format!("unknown LCE variant {other:?} (mixed, unmixed)")),
        };
        let mut spec = LceSpec {
            variant,
            count: 200,
            seed: 0,
            config: LceConfig::default(),
        };
        for part in parts {
            let (key, value) = part
                .split_once('=')
                .ok_or_else(|| format!("{part:?} is not key=value"))?;
            let bad = |e: &dyn std::fmt::Display| format!("{key}={value:?}: {e}");
            match key {
                "count" => spec.count = value.parse().map_err(|e| bad(&e))?,
                "seed" => spec.seed = value.parse().map_err(|e| bad(&e))?,
                "scale" => spec.config.scale = value.parse().map_err(|e| bad(&e))?,
                "noise" => spec.config.noise = value.parse().map_err(|e| bad(&e))?,
                "points" => spec.config.points_per_shape = value.parse().map_err(|e| bad(&e))?,
                _ => {
                    return Err(format!(
                        "unknown LCE setting {key:?} (count, seed, scale, noise, points)"
                    ));
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

    #[test]
    fn mixed_has_four_structures_of_equal_size() {
        let mut g = LceGenerator::new(1, LceConfig::default());
        let s = g.sample(LceVariant::Mixed, "a");
        assert_eq!(s.sample.k, 4);
        assert_eq!(s.sample.points.len(), 200);
        for l in 0..4 {
            assert_eq!(s.sample.labels.iter().filter(|&&x| x == l).count(), 50);
        }
    }

    #[test]
    fn unmixed_has_two_to_four_of_one_type() {
        let mut g = LceGenerator::new(2, LceConfig::default());
        for i in 0..30 {
            let s = g.sample(LceVariant::Unmixed, &i.to_string());
            assert!((2..=4).contains(&s.shapes.len()));
            assert!(s.shapes.iter().all(|&t| t == s.shapes[0]));
        }
    }

    #[test]
    fn spec_parses_prints_and_rejects_what_it_cannot_generate() {
        let spec: LceSpec = "unmixed,count=12000,seed=302,scale=2".parse().unwrap();
        assert_eq!(spec.variant, LceVariant::Unmixed);
        assert_eq!(
            (spec.count, spec.seed, spec.config.scale),
            (12000, 302, 2.0)
        );
        assert_eq!(spec.config.points_per_shape, 50);
        let text = spec.to_string();
        assert_eq!(
            text,
            "lce:unmixed,count=12000,seed=302,scale=2,noise=0.05,points=50"
        );
        assert_eq!(text["lce:".len()..].parse::<LceSpec>().unwrap(), spec);
        let defaults: LceSpec = "mixed".parse().unwrap();
        assert_eq!((defaults.count, defaults.seed), (200, 0));
        for (bad, says) in [
            ("triangles", "unknown LCE variant"),
            ("mixed,count=0", "count must be 1 to 1000000"),
            ("mixed,count=1000001", "count must be 1 to 1000000"),
            ("mixed,count=-3", "count=\"-3\""),
            ("mixed,scale=0", "scale must be finite and positive"),
            ("mixed,noise=nan", "noise finite"),
            ("mixed,points=1", "points per shape"),
            ("mixed,colour=red", "unknown LCE setting"),
            ("mixed,seed", "not key=value"),
        ] {
            let err = bad.parse::<LceSpec>().unwrap_err();
            assert!(err.contains(says), "{bad}: {err}");
        }
    }

    #[test]
    fn spec_gives_what_its_files_give_after_a_trip_through_disk() {
        let spec: LceSpec = "mixed,count=12,seed=9,scale=2".parse().unwrap();
        let dir = tempfile::tempdir().unwrap();
        // Written as gen-lce writes them, in reverse so the listing, not the writing, orders them.
        let files: Vec<SequenceFile> = spec.files().collect();
        for file in files.iter().rev() {
            let text = serde_json::to_string(file).unwrap();
            std::fs::write(dir.path().join(format!("{}.json", file.name)), text).unwrap();
        }
        let loaded = crate::data::load_sequences(dir.path(), None).unwrap();
        let generated = spec.sequences().unwrap();
        assert_eq!(loaded.len(), 12);
        for (a, b) in loaded.iter().zip(&generated) {
            assert_eq!(a.name, b.name);
            assert_eq!(a.labels, b.labels);
            let bits = |s: &Sequence| {
                s.points
                    .values()
                    .iter()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            };
            assert_eq!(bits(a), bits(b), "{}", a.name);
        }
        assert_eq!(generated[3].name, "lce-mixed-s9-00003");
        // A different seed is different data.
        let other: LceSpec = "mixed,count=12,seed=10,scale=2".parse().unwrap();
        assert_ne!(other.sequences().unwrap()[0].points, generated[0].points);
    }

    #[test]
    fn seeded_and_reproducible() {
        let a = LceGenerator::new(7, LceConfig::default()).sample(LceVariant::Mixed, "x");
        let b = LceGenerator::new(7, LceConfig::default()).sample(LceVariant::Mixed, "x");
        let c = LceGenerator::new(8, LceConfig::default()).sample(LceVariant::Mixed, "x");
        assert_eq!(a.sample.points, b.sample.points);
        assert_eq!(a.sample.labels, b.sample.labels);
        assert_ne!(a.sample.points, c.sample.points);
    }

    #[test]
    fn noiseless_circle_points_lie_on_a_circle() {
        let cfg = LceConfig {
            points_per_shape: 40,
            noise: 0.0,
            scale: 1.0,
        };
        let s = LceGenerator::new(3, cfg)
            .with_shapes(&[Shape::Circle], "c")
            .sample;
        let n = s.points.len() as f64;
        let (cx, cy) = (0..s.points.len()).fold((0.0, 0.0), |(a, b), i| {
            (a + s.points.row(i)[0] / n, b + s.points.row(i)[1] / n)
        });
        let radii: Vec<f64> = (0..s.points.len())
            .map(|i| ((s.points.row(i)[0] - cx).powi(2) + (s.points.row(i)[1] - cy).powi(2)).sqrt())
            .collect();
        // The centroid of uniform angles is near the centre; radii agree within a few percent.
        let mean = radii.iter().sum::<f64>() / n;
        assert!((0.2..=0.65).contains(&mean));
        assert!(
            radii.iter().all(|r| (r - mean).abs() < 0.25 * mean),
            "{radii:?}"
        );
    }

    #[test]
    fn validate_rejects_settings_it_cannot_draw_from() {
        assert!(LceConfig::default().validate().is_ok());
        for bad in [
            LceConfig {
                points_per_shape: 1,
                ..LceConfig::default()
            },
            LceConfig {
                noise: f64::NAN,
                ..LceConfig::default()
            },
            LceConfig {
                noise: -0.1,
                ..LceConfig::default()
            },
            LceConfig {
                scale: 0.0,
                ..LceConfig::default()
            },
            LceConfig {
                scale: f64::INFINITY,
                ..LceConfig::default()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn scale_stretches_the_shapes_and_not_the_noise() {
        let at = |scale: f64, noise: f64| {
            let cfg = LceConfig {
                points_per_shape: 30,
                noise,
                scale,
            };
            LceGenerator::new(5, cfg)
                .sample(LceVariant::Mixed, "s")
                .sample
        };
        // Without noise the same draws give exactly twice the coordinates.
        let (one, two) = (at(1.0, 0.0), at(2.0, 0.0));
        assert_eq!(one.labels, two.labels);
        for i in 0..one.points.len() {
            for d in 0..2 {
                let (a, b) = (one.points.row(i)[d], two.points.row(i)[d]);
                assert!((2.0 * a - b).abs() < 1e-12, "{a} {b}");
            }
        }
        // With noise, the offset from the noiseless point has the same size at both scales.
        let (noisy1, noisy2) = (at(1.0, 0.05), at(2.0, 0.05));
        for i in 0..one.points.len() {
            for d in 0..2 {
                let e1 = noisy1.points.row(i)[d] - one.points.row(i)[d];
                let e2 = noisy2.points.row(i)[d] - two.points.row(i)[d];
                assert!((e1 - e2).abs() < 1e-12, "{e1} {e2}");
            }
        }
    }
}
