//! Labelled sequences on disk (the JSON format of `../shared/datasets/README.md`), the labelled
//! samples training and evaluation use, and KT3DMoSeg clip cutting.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::motion::MotionSpec;
use super::points::{ImageSize, InputError, Kind, PointSet};
use super::ranges::RangeError;
use super::synthetic::{LceConfigError, LceSpec};
use super::twoview::TwoViewSpec;

/// Why a dataset file or directory could not be used. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: not valid dataset JSON: {source}")]
    Json {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error("{path}: {reason}")]
    Invalid { path: PathBuf, reason: String },
    #[error("{path}: no dataset files (*.json) found")]
    NoFiles { path: PathBuf },
}

/// Why the text of a [`DataSource`] (or of a range, [`super::synthetic::parse_range`]) cannot be
/// used. Errors about a generator's settings name the spec key (`frames=1: ...`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpecError {
    #[error("empty dataset path")]
    EmptyPath,
    #[error("unknown LCE variant {0:?} (mixed, unmixed, random)")]
    UnknownLceVariant(String),
    #[error("unknown two-view mode {0:?} (homography, fundamental)")]
    UnknownTwoViewMode(String),
    #[error("{part:?} is not key=value")]
    NotKeyValue { part: String },
    /// A key the generator does not have; `known` lists those it has.
    #[error("unknown {generator} setting {key:?} ({known})")]
    UnknownSetting {
        generator: &'static str,
        key: String,
        known: &'static str,
    },
    /// A value that does not parse as its setting's type.
    #[error("{key}={value:?}: {reason}")]
    Value {
        key: String,
        value: String,
        reason: String,
    },
    /// One end of a range (`N` or `MIN-MAX`) that does not parse.
    #[error("{text:?}: {reason}")]
    Range { text: String, reason: String },
    #[error("count={count}: count must be 1 to {max}")]
    Count { count: usize, max: usize },
    #[error(transparent)]
    Lce(#[from] LceConfigError),
    /// A motion or two-view generator setting out of range.
    #[error("{}", .0.for_spec())]
    Setting(RangeError),
}

/// One sequence file as stored on disk.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SequenceFile {
    pub name: String,
    pub kind: Kind,
    pub points: Vec<Vec<f64>>,
    /// 0 = gross outlier (AdelaideRMF only); structures 1..K.
    pub labels: Vec<i64>,
    #[serde(default)]
    pub num_models: Option<usize>,
    #[serde(default)]
    pub image_size: Option<[f64; 2]>,
    #[serde(default)]
    pub source: Option<String>,
    /// AdelaideRMF: "homography" or "fundamental".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_type: Option<String>,
    /// KT3DMoSeg full files: P x F visibility (0/1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visible: Option<Vec<Vec<u8>>>,
}

/// A validated labelled sequence.
#[derive(Debug, Clone)]
pub struct Sequence {
    pub name: String,
    pub points: PointSet,
    /// Raw labels as in the file (0 = outlier).
    pub labels: Vec<i64>,
    pub image_size: Option<ImageSize>,
    pub model_type: Option<String>,
    /// P x F visibility, for trajectories with missing frames.
    pub visible: Option<Vec<Vec<u8>>>,
}

/// A random stream fixed by `key` alone: FNV-1a of its bytes seeds ChaCha8 (stable across
/// platforms and releases, unlike std's hasher).
pub fn seeded_rng(key: &str) -> rand::rngs::ChaCha8Rng {
    use rand::SeedableRng;
    let hash = key.bytes().fold(0xcbf29ce484222325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x100000001b3)
    });
    rand::rngs::ChaCha8Rng::seed_from_u64(hash)
}

/// The family of models sequences follow, when their files say and all agree: AdelaideRMF's
/// (and the two-view generator's) `model_type` `homography` or `fundamental`; `None` otherwise
/// (the card's kind then decides, [`crate::registry::ModelCard::family`]).
pub fn family_of(seqs: &[Sequence]) -> Option<crate::geometry::Family> {
    use crate::geometry::Family;
    let family = |s: &Sequence| match s.model_type.as_deref() {
        Some("homography") => Some(Family::Homography),
        Some("fundamental") => Some(Family::Fundamental),
        _ => None,
    };
    let first = family(seqs.first()?)?;
    seqs.iter()
        .all(|s| family(s) == Some(first))
        .then_some(first)
}

/// A labelled sample ready for training or evaluation: labels renumbered to `0..k`, outliers
/// (raw label 0) kept as one more group, as the paper does.
#[derive(Debug, Clone)]
pub struct Sample {
    pub name: String,
    pub points: PointSet,
    pub labels: Vec<usize>,
    /// Number of groups in `labels` (structures, plus one when outliers are present).
    pub k: usize,
    pub image_size: Option<ImageSize>,
    /// Whether label 0 is the gross outliers' group (raw label 0 was present).
    pub outliers: bool,
}

impl Sequence {
    /// Validates a parsed file; `path` only names the file in errors.
    pub fn from_file(file: SequenceFile, path: &Path) -> Result<Self, DataError> {
        let invalid = |reason: String| DataError::Invalid {
            path: path.to_path_buf(),
            reason,
        };
        let points = PointSet::from_rows(file.kind, &file.points)
            .map_err(|e: InputError| invalid(format!("points: {e}")))?;
        if file.labels.len() != points.len() {
            return Err(invalid(format!(
                "{} labels for {} points",
                file.labels.len(),
                points.len()
            )));
        }
        if let Some(l) = file.labels.iter().find(|&&l| l < 0) {
            return Err(invalid(format!("negative label {l}")));
        }
        let image_size = match file.image_size {
            Some([w, h]) => {
                Some(ImageSize::new(w, h).map_err(|e| invalid(format!("image_size: {e}")))?)
            }
            None => None,
        };
        if let Some(vis) = &file.visible {
            let frames = points.dim() / 2;
            if vis.len() != points.len() || vis.iter().any(|r| r.len() != frames) {
                return Err(invalid(format!(
                    "visible must be {} x {frames}",
                    points.len()
                )));
            }
        }
        Ok(Self {
            name: file.name,
            points,
            labels: file.labels,
            image_size,
            model_type: file.model_type,
            visible: file.visible,
        })
    }

    /// Reads and validates one sequence file.
    pub fn load(path: &Path) -> Result<Self, DataError> {
        let text = std::fs::read_to_string(path).map_err(|source| DataError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let file: SequenceFile = serde_json::from_str(&text).map_err(|source| DataError::Json {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_file(file, path)
    }

    /// Number of frames (trajectories) or views (correspondences: 2, points2d: 1).
    pub fn frames(&self) -> usize {
        self.points.dim() / 2
    }

    /// The labelled sample, labels renumbered to `0..k` in the order of the raw labels.
    pub fn sample(&self) -> Sample {
        let (labels, k) = renumber(&self.labels);
        Sample {
            name: self.name.clone(),
            points: self.points.clone(),
            labels,
            k,
            image_size: self.image_size,
            outliers: self.labels.contains(&0),
        }
    }

    /// The rows `rows` of the sequence (labels, visibility and all), in the order given.
    pub fn rows(&self, rows: &[usize]) -> Sequence {
        Sequence {
            name: self.name.clone(),
            points: self.points.select(rows).expect("rows of a valid set"),
            labels: rows.iter().map(|&i| self.labels[i]).collect(),
            image_size: self.image_size,
            model_type: self.model_type.clone(),
            visible: self
                .visible
                .as_ref()
                .map(|v| rows.iter().map(|&i| v[i].clone()).collect()),
        }
    }

    /// `round(share * n)` of the rows (at least 2), drawn without replacement, in their order.
    pub fn subsample(&self, share: f64, rng: &mut impl rand::RngExt) -> Sequence {
        let n = self.points.len();
        let keep = ((share * n as f64).round() as usize).clamp(2.min(n), n);
        let mut order: Vec<usize> = (0..n).collect();
        for i in 0..keep {
            let j = rng.random_range(i..n);
            order.swap(i, j);
        }
        order.truncate(keep);
        order.sort_unstable();
        self.rows(&order)
    }

    /// Every row, in an order drawn uniformly at random (Fisher–Yates): the same set as a
    /// caller whose tool lists its points in another order sends it.
    pub fn shuffled(&self, rng: &mut impl rand::RngExt) -> Sequence {
        let n = self.points.len();
        let mut order: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            let j = rng.random_range(0..=i);
            order.swap(i, j);
        }
        self.rows(&order)
    }

    /// Frames `[start, start + len)` of a trajectory sequence: the rows visible in all of those
    /// frames, their `2 * len` values, labels renumbered. `None` when the frames do not exist or
    /// fewer than two points are visible throughout.
    pub fn clip(&self, start: usize, len: usize) -> Option<Sample> {
        self.clip_every(start, len, 1)
    }

    /// Frames `start, start + step, ..., start + (len - 1) step` of a trajectory sequence (a
    /// clip at a frame stride: faster apparent motion), as [`Sequence::clip`] takes them.
    pub fn clip_every(&self, start: usize, len: usize, step: usize) -> Option<Sample> {
        let step = step.max(1);
        let end = start + (len.max(1) - 1) * step;
        if self.points.kind() != Kind::Trajectories || len < 2 || end >= self.frames() {
            return None;
        }
        let frames: Vec<usize> = (0..len).map(|f| start + f * step).collect();
        let rows: Vec<usize> = (0..self.points.len())
            .filter(|&i| match &self.visible {
                Some(vis) => frames.iter().all(|&f| vis[i][f] == 1),
                None => true,
            })
            .collect();
        let values: Vec<f64> = rows
            .iter()
            .flat_map(|&i| {
                let row = self.points.row(i);
                frames
                    .iter()
                    .flat_map(move |&f| [row[2 * f], row[2 * f + 1]])
            })
            .collect();
        let points = PointSet::from_flat(Kind::Trajectories, 2 * len, values).ok()?;
        let raw: Vec<i64> = rows.iter().map(|&i| self.labels[i]).collect();
        let (labels, k) = renumber(&raw);
        let name = if step == 1 {
            format!("{}[{}..{}]", self.name, start + 1, end + 1)
        } else {
            format!("{}[{}..{} every {step}]", self.name, start + 1, end + 1)
        };
        Some(Sample {
            name,
            points,
            labels,
            k,
            image_size: self.image_size,
            outliers: raw.contains(&0),
        })
    }

    /// Clips of `len` frames starting at frame 0, then `stride`, `2 stride`, ... while they fit.
    /// `stride = len` gives the non-overlapping clips of the paper's 'Augment' setting; the first
    /// clip is always the test clip.
    pub fn clips(&self, len: usize, stride: usize) -> Vec<Sample> {
        self.clips_from(0, len, stride)
    }

    /// [`Sequence::clips`] whose first clip starts at frame `first` (0-based) instead of 0.
    pub fn clips_from(&self, first: usize, len: usize, stride: usize) -> Vec<Sample> {
        let (len, stride) = (len.max(1), stride.max(1));
        let Some(last) = self.frames().checked_sub(len) else {
            return vec![];
        };
        (first..=last)
            .step_by(stride)
            .filter_map(|start| self.clip(start, len))
            .collect()
    }
}

/// Renumbers arbitrary labels to `0..k` preserving their order; returns the labels and `k`.
pub fn renumber(raw: &[i64]) -> (Vec<usize>, usize) {
    let mut distinct: Vec<i64> = raw.to_vec();
    distinct.sort_unstable();
    distinct.dedup();
    let labels = raw
        .iter()
        .map(|l| distinct.binary_search(l).unwrap_or(0))
        .collect();
    (labels, distinct.len())
}

/// One `key=value` setting of a generator spec (`lce:`, `motion:`, `twoview:`); a value that
/// does not parse is an error naming the key.
pub(crate) struct Setting<'a> {
    pub key: &'a str,
    value: &'a str,
}

impl<'a> Setting<'a> {
    pub fn parse(part: &'a str) -> Result<Self, SpecError> {
        let (key, value) = part.split_once('=').ok_or_else(|| SpecError::NotKeyValue {
            part: part.to_string(),
        })?;
        Ok(Self { key, value })
    }

    fn bad(&self, e: &dyn std::fmt::Display) -> SpecError {
        SpecError::Value {
            key: self.key.to_string(),
            value: self.value.to_string(),
            reason: e.to_string(),
        }
    }

    /// The value as one `T`.
    pub fn value<T: std::str::FromStr>(&self) -> Result<T, SpecError>
    where
        T::Err: std::fmt::Display,
    {
        self.value.parse().map_err(|e| self.bad(&e))
    }

    /// The value as `N` or `MIN-MAX`: `(N, None)` or `(MIN, Some(MAX))`.
    pub fn range<T: std::str::FromStr>(&self) -> Result<(T, Option<T>), SpecError>
    where
        T::Err: std::fmt::Display,
    {
        super::synthetic::parse_range(self.value).map_err(|e| self.bad(&e))
    }

    /// The value as `[MIN, MAX]` (one value `N`: `[N, N]`).
    pub fn pair<T: std::str::FromStr + Copy>(&self) -> Result<[T; 2], SpecError>
    where
        T::Err: std::fmt::Display,
    {
        let (a, b) = self.range::<T>()?;
        Ok([a, b.unwrap_or(a)])
    }
}

/// The spec count check every generator shares: 1 to `max` samples.
pub(crate) fn check_count(count: usize, max: usize) -> Result<(), SpecError> {
    if count == 0 || count > max {
        return Err(SpecError::Count { count, max });
    }
    Ok(())
}

/// Generated files as validated sequences: exactly what loading them from disk gives.
pub(crate) fn load_files(
    files: impl Iterator<Item = SequenceFile>,
) -> Result<Vec<Sequence>, DataError> {
    files
        .map(|file| {
            let name = PathBuf::from(&file.name);
            Sequence::from_file(file, &name)
        })
        .collect()
}

/// Where labelled sequences come from: a dataset file or directory, or samples generated in
/// memory: LCE (`lce:...`, see [`LceSpec`]), multi-body motion trajectories (`motion:...`, see
/// [`MotionSpec`]) or two-view correspondences (`twoview:...`, see [`TwoViewSpec`]). Parsed from
/// a command-line value: anything that does not start with one of those prefixes is a path.
#[derive(Debug, Clone, PartialEq)]
pub enum DataSource {
    Path(PathBuf),
    Lce(LceSpec),
    Motion(MotionSpec),
    TwoView(TwoViewSpec),
}

impl std::str::FromStr for DataSource {
    type Err = SpecError;

    fn from_str(text: &str) -> Result<Self, SpecError> {
        if let Some(spec) = text.strip_prefix("motion:") {
            return spec.parse().map(DataSource::Motion);
        }
        if let Some(spec) = text.strip_prefix("twoview:") {
            return spec.parse().map(DataSource::TwoView);
        }
        match text.strip_prefix("lce:") {
            Some(spec) => spec.parse().map(DataSource::Lce),
            None if text.is_empty() => Err(SpecError::EmptyPath),
            None => Ok(DataSource::Path(PathBuf::from(text))),
        }
    }
}

impl std::fmt::Display for DataSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DataSource::Path(p) => write!(f, "{}", p.display()),
            DataSource::Lce(spec) => write!(f, "{spec}"),
            DataSource::Motion(spec) => write!(f, "{spec}"),
            DataSource::TwoView(spec) => write!(f, "{spec}"),
        }
    }
}

impl DataSource {
    /// Its sequences, keeping only AdelaideRMF pairs of `model_type` when given; as
    /// [`load_sequences`] for a path.
    pub fn sequences(&self, model_type: Option<&str>) -> Result<Vec<Sequence>, DataError> {
        match self {
            DataSource::Path(path) => load_sequences(path, model_type),
            DataSource::Lce(spec) => {
                let all = spec.sequences()?;
                match model_type {
                    None => Ok(all),
                    Some(t) => Err(DataError::Invalid {
                        path: PathBuf::from(self.to_string()),
                        reason: format!("generated LCE samples have no model type {t:?}"),
                    }),
                }
            }
            DataSource::Motion(spec) => match model_type {
                None => spec.sequences(),
                Some(t) => Err(DataError::Invalid {
                    path: PathBuf::from(self.to_string()),
                    reason: format!("generated motion samples have no model type {t:?}"),
                }),
            },
            DataSource::TwoView(spec) => {
                let mode = spec.params.mode.as_str();
                match model_type {
                    Some(t) if t != mode => Err(DataError::Invalid {
                        path: PathBuf::from(self.to_string()),
                        reason: format!(
                            "generated two-view samples are of model type {mode:?}, not {t:?}"
                        ),
                    }),
                    _ => spec.sequences(),
                }
            }
        }
    }
}

/// Loads every `*.json` file of a directory (sorted by file name), or a single file.
/// `model_type`, when given, keeps only sequences of that AdelaideRMF model type.
pub fn load_sequences(path: &Path, model_type: Option<&str>) -> Result<Vec<Sequence>, DataError> {
    let files = if path.is_dir() {
        let mut files: Vec<PathBuf> = std::fs::read_dir(path)
            .map_err(|source| DataError::Io {
                path: path.to_path_buf(),
                source,
            })?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "json") && p.is_file())
            .filter(|p| p.file_name().is_some_and(|n| n != "INDEX.json"))
            .collect();
        files.sort();
        files
    } else {
        vec![path.to_path_buf()]
    };
    let mut out = Vec::new();
    for f in &files {
        let seq = Sequence::load(f)?;
        if model_type.is_none_or(|t| seq.model_type.as_deref() == Some(t)) {
            out.push(seq);
        }
    }
    if out.is_empty() {
        return Err(DataError::NoFiles {
            path: path.to_path_buf(),
        });
    }
    Ok(out)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// 40 correspondences of a 640 x 480 pair: 10 outliers (label 0), 30 in two structures.
    pub(crate) fn pair() -> Sequence {
        let rows: Vec<Vec<f64>> = (0..40)
            .map(|i| {
                let x = (i * 13 % 97) as f64 * 6.0;
                let y = (i * 7 % 53) as f64 * 8.0;
                vec![x, y, x + 3.0, y - 2.0]
            })
            .collect();
        let labels: Vec<i64> = (0..40).map(|i| [0, 1, 2, 2][i % 4]).collect();
        Sequence::from_file(
            crate::data::SequenceFile {
                name: "pair".into(),
                kind: Kind::Correspondences,
                points: rows,
                labels,
                num_models: Some(2),
                image_size: Some([640.0, 480.0]),
                source: None,
                model_type: Some("homography".into()),
                visible: None,
            },
            std::path::Path::new("pair"),
        )
        .unwrap()
    }

    fn traj_file() -> SequenceFile {
        // 3 points, 4 frames; point 2 invisible in frame 3.
        SequenceFile {
            name: "t".into(),
            kind: Kind::Trajectories,
            points: vec![
                (0..8).map(|v| v as f64).collect(),
                (0..8).map(|v| 10.0 + v as f64).collect(),
                vec![1.0, 1.0, 2.0, 2.0, 0.0, 0.0, 3.0, 3.0],
            ],
            labels: vec![2, 5, 5],
            num_models: Some(2),
            image_size: Some([100.0, 50.0]),
            source: None,
            model_type: None,
            visible: Some(vec![vec![1, 1, 1, 1], vec![1, 1, 1, 1], vec![1, 1, 0, 1]]),
        }
    }

    #[test]
    fn the_family_comes_from_the_files_model_type_when_all_agree() {
        use crate::geometry::Family;
        let pair = |t: Option<&str>| Sequence {
            name: "p".into(),
            points: PointSet::from_flat(
                Kind::Correspondences,
                4,
                vec![0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 3.0, 3.0],
            )
            .unwrap(),
            labels: vec![1, 1],
            image_size: None,
            model_type: t.map(String::from),
            visible: None,
        };
        let h = || pair(Some("homography"));
        assert_eq!(family_of(&[h(), h()]), Some(Family::Homography));
        assert_eq!(
            family_of(&[pair(Some("fundamental"))]),
            Some(Family::Fundamental)
        );
        assert_eq!(family_of(&[h(), pair(Some("fundamental"))]), None);
        assert_eq!(family_of(&[h(), pair(None)]), None);
        assert_eq!(family_of(&[]), None);
    }

    #[test]
    fn renumber_keeps_order_and_counts() {
        assert_eq!(renumber(&[7, 0, 7, 3]), (vec![2, 0, 2, 1], 3));
    }

    #[test]
    fn clips_keep_only_fully_visible_rows() {
        let seq = Sequence::from_file(traj_file(), Path::new("t.json")).unwrap();
        let first = seq.clip(0, 2).unwrap();
        assert_eq!(first.points.len(), 3);
        assert_eq!(first.points.row(1), &[10.0, 11.0, 12.0, 13.0]);
        assert_eq!(first.labels, vec![0, 1, 1]);
        let second = seq.clip(2, 2).unwrap();
        assert_eq!(second.points.len(), 2);
        assert_eq!(second.points.row(0), &[4.0, 5.0, 6.0, 7.0]);
        assert_eq!(second.k, 2);
        assert!(seq.clip(3, 2).is_none());
        assert_eq!(seq.clips(2, 2).len(), 2);
        // Overlapping clips: starts 0, 1, 2 of 4 frames.
        let sliding = seq.clips(2, 1);
        assert_eq!(sliding.len(), 3);
        assert_eq!(sliding[1].points.row(0), &[2.0, 3.0, 4.0, 5.0]);
        assert_eq!(
            sliding[1].points.len(),
            2,
            "point 2 is invisible in frame 3"
        );
        assert_eq!(seq.clips(3, 3).len(), 1);
        // From frame 2 (0-based) on: the one clip of frames 3..4.
        let later = seq.clips_from(2, 2, 1);
        assert_eq!(later.len(), 1);
        assert_eq!(later[0].name, second.name);
        assert!(seq.clips_from(3, 2, 1).is_empty());
        // Strides and starts past the end give what fits, never an overflow.
        assert_eq!(seq.clips(2, usize::MAX).len(), 1);
        assert!(seq.clips_from(usize::MAX, 2, 1).is_empty());
        assert!(seq.clips(5, 1).is_empty());
    }

    #[test]
    fn bad_files_name_the_reason() {
        let mut f = traj_file();
        f.labels.pop();
        let err = Sequence::from_file(f, Path::new("x.json"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("x.json") && err.contains("2 labels for 3 points"),
            "{err}"
        );
        let mut f = traj_file();
        f.points[1].pop();
        let err = Sequence::from_file(f, Path::new("x.json"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("row 1"), "{err}");
    }
}
