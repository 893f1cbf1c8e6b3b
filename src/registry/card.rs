//! The model card, `model.json`: what a model is (kind, input, normalisation, architecture),
//! how it was trained and what it scored, checked on every read.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::RegistryError;
use crate::cluster::Selection;
use crate::data::frames::FrameSampling;
use crate::data::symmetry::{self, SymmetryError};
use crate::data::{Kind, Normalization, PointSet, Symmetry};
use crate::geometry::Family;
use crate::loss::Loss;
use crate::model::{ModelConfig, ModelError};
use crate::refine::RefineParams;

/// File names inside a model directory.
pub const CARD_FILE: &str = "model.json";
pub const WEIGHTS_FILE: &str = "weights.safetensors";

/// Why a model card is not internally consistent ([`ModelCard::validate`]).
#[derive(Debug, thiserror::Error)]
pub enum CardError {
    #[error("name {0:?} must be non-empty ASCII letters, digits, '-' or '_'")]
    Name(String),
    #[error("input_dim {input_dim} differs from architecture.input_dim {architecture}")]
    InputDim {
        input_dim: usize,
        architecture: usize,
    },
    #[error("input_dim {input_dim} is not valid for kind {kind}")]
    InputDimForKind { input_dim: usize, kind: Kind },
    #[error("normalization {normalization:?} is not the one kind {kind} uses")]
    Normalization {
        normalization: Normalization,
        kind: Kind,
    },
    #[error("k_max must be at least 1")]
    KMax,
    #[error("the default selection must be sod or silhouette")]
    FixedSelection,
    #[error("test_symmetries: {0}")]
    TestSymmetries(SymmetryError),
    #[error("weights {0:?} (members, sparse) must be a plain .safetensors file name")]
    WeightsFile(String),
    #[error("weights {0:?} (members, sparse) named twice")]
    WeightsTwice(String),
    #[error(
        "sparse: needs the card's training spacing (positive) and a network that reads neighbours"
    )]
    SparseWithoutSpacing,
    #[error("sparse: above must be a finite ratio of at least 1, got {0}")]
    SparseAbove(f64),
    #[error("refine_stay must be a finite number of noise levels, at least 0, got {0}")]
    RefineStay(f64),
    #[error("refine_margin must be a finite number of noise levels, at least 0, got {0}")]
    RefineMargin(f64),
    #[error(transparent)]
    Architecture(ModelError),
}

/// How a model was trained: enough to reproduce it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingInfo {
    /// What data and protocol it saw.
    pub data: String,
    /// The exact command that trained it.
    pub command: String,
    pub epochs: usize,
    pub learning_rate: f64,
    pub seed: u64,
    /// Wall time of the training run on the machine named in `machine`.
    pub seconds: f64,
    pub machine: String,
}

/// A reported metric with the command that measured it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MetricRecord {
    pub name: String,
    pub value: f64,
    pub protocol: String,
    pub command: String,
}

/// A further network in an ensemble: same architecture, input and normalisation as the card's
/// own network, its own weights and training.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Member {
    /// Its weights file, a plain file name inside the model directory.
    pub weights: String,
    pub loss: Loss,
    pub training: TrainingInfo,
}

/// A network for sets sparser than the card's training sets: a set whose spacing exceeds
/// `above` × the card's `spacing` is embedded by this network instead of the card's own (and its
/// members'). Same architecture, input and normalisation as the card's network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SparseNetwork {
    /// Its weights file, a plain file name inside the model directory.
    pub weights: String,
    /// The spacing ratio (set's over training's) above which it reads the set.
    pub above: f64,
    pub loss: Loss,
    pub training: TrainingInfo,
}

/// The model card, `model.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelCard {
    pub name: String,
    pub version: String,
    pub kind: Kind,
    pub input_dim: usize,
    pub normalization: Normalization,
    pub architecture: ModelConfig,
    pub loss: Loss,
    /// Default largest K tried by automatic selection.
    pub k_max: usize,
    /// Default K selection (`sod` or `silhouette`).
    pub selection: Selection,
    pub training: TrainingInfo,
    /// Served to requests of this kind that name no model. At most one card of a kind says
    /// so; without one, the first of the kind by name is served.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub default: bool,
    /// Test-time symmetries: the input's images under every combination of these are embedded
    /// too, and each point's embeddings are concatenated (scaled to unit length) before
    /// clustering. Empty: the input alone, as in the paper.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub test_symmetries: Vec<Symmetry>,
    /// Further networks (an ensemble): a fit embeds every test image with the card's network
    /// (`weights.safetensors`, `loss`, `training`) and with each of these, and sets all the
    /// embeddings of a point side by side. Empty: one network, as in the paper.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub members: Vec<Member>,
    /// Trajectory models: which frames of a track of another length the network reads.
    #[serde(default)]
    pub frames: FrameSampling,
    /// Whether fits refine the learned groups into geometric structures by default.
    #[serde(default)]
    pub refine: bool,
    /// Trajectory models: fits of tracks of at least this many frames refine by default even
    /// when `refine` is off (a motion subspace separates motions only on long enough tracks).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refine_from_frames: Option<usize>,
    /// Whether refinement labels points that fit no structure −1 by default (data without gross
    /// outliers, such as tracks, is better served without).
    #[serde(default = "yes")]
    pub outliers: bool,
    /// Refinement keeps a point with its structure while it fits it within this many σ, even
    /// where another structure is nearer ([`RefineParams::stay`]); 0: always the nearest.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub refine_stay: f64,
    /// Refinement moves a point to another structure only where that one fits it better by
    /// more than this many σ ([`RefineParams::margin`]; a point past the outlier threshold is
    /// not kept); 0: wherever another is nearer.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub refine_margin: f64,
    /// The models a structure may follow; default by kind: curves for points2d, fundamental
    /// (or homography where GRIC prefers it) for correspondences, subspaces for trajectories.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub geometry: Option<Family>,
    /// The spacing of the training sets (median distance from a point to its k-th nearest other
    /// point, k = `architecture.neighbors`, normalised coordinates): a denser set is read at a
    /// subset of this density ([`crate::data::density`]). `None`: every set is read whole.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spacing: Option<f64>,
    /// The network that reads sets sparser than training ([`SparseNetwork`]); `None`: the
    /// card's networks read every set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sparse: Option<SparseNetwork>,
    /// The range of inputs the model was validated on; a fit outside it answers with warnings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub validated: Option<ValidatedRange>,
    #[serde(default)]
    pub metrics: Vec<MetricRecord>,
    /// multifit version and git commit that trained it.
    pub multifit_version: String,
    #[serde(default)]
    pub git_commit: Option<String>,
}

fn yes() -> bool {
    true
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// The inputs a model was validated on: every bound inclusive, every field optional.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ValidatedRange {
    /// Points in a set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points: Option<[usize; 2]>,
    /// Points per structure (the answer's smallest and largest group).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points_per_structure: Option<[usize; 2]>,
    /// Frames per track.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<[usize; 2]>,
    /// The longer image side, pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image_side: Option<[f64; 2]>,
    /// Share of points that are outliers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outlier_ratio: Option<[f64; 2]>,
    /// Where these bounds come from (the data the model was trained and validated on).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub source: String,
}

/// What a fit saw, measured against a [`ValidatedRange`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Observed {
    /// What the rows counted in `points` are, for the warning ("points" when empty).
    pub rows: &'static str,
    pub points: usize,
    /// The smallest and largest structure of the answer.
    pub points_per_structure: Option<[usize; 2]>,
    pub frames: Option<usize>,
    pub image_side: Option<f64>,
    pub outlier_ratio: Option<f64>,
}

/// Which side of a validated range a quantity is checked on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Side {
    Both,
    /// Only below the range: above it is no harder (a larger image whose coordinates scale
    /// with it is the same input, normalised, with less relative noise).
    Below,
    /// Only above the range: below it is no harder (an outlier share smaller than validated).
    Above,
}

impl ValidatedRange {
    /// One warning per observed quantity outside its bounds, naming it, its value and the range.
    /// Points, structure sizes and frames are checked on both sides; the image side only below
    /// the range (inputs are normalised by the image, so a rescaled image answers the same), the
    /// outlier share only above it.
    pub fn warnings(&self, seen: &Observed) -> Vec<String> {
        fn out<T: PartialOrd + std::fmt::Display + Copy>(
            name: &str,
            value: Option<T>,
            range: Option<[T; 2]>,
            side: Side,
            warnings: &mut Vec<String>,
        ) {
            if let (Some(v), Some([lo, hi])) = (value, range)
                && ((v < lo && side != Side::Above) || (v > hi && side != Side::Below))
            {
                warnings.push(format!(
                    "{name} {v} is outside the range the model was validated on ({lo} to {hi})"
                ));
            }
        }
        let mut w = Vec::new();
        let rows = if seen.rows.is_empty() {
            "points"
        } else {
            seen.rows
        };
        out(rows, Some(seen.points), self.points, Side::Both, &mut w);
        if let Some([small, large]) = seen.points_per_structure {
            let range = self.points_per_structure;
            out(
                "smallest structure's points",
                Some(small),
                range,
                Side::Both,
                &mut w,
            );
            out(
                "largest structure's points",
                Some(large),
                range,
                Side::Both,
                &mut w,
            );
        }
        out("frames", seen.frames, self.frames, Side::Both, &mut w);
        out(
            "image side",
            seen.image_side,
            self.image_side,
            Side::Below,
            &mut w,
        );
        let ratio = seen.outlier_ratio.map(|v| (v * 1e3).round() / 1e3);
        out(
            "outlier ratio",
            ratio,
            self.outlier_ratio,
            Side::Above,
            &mut w,
        );
        w
    }
}

impl ModelCard {
    /// Whether a fit of `points` refines when its request does not say.
    pub fn refines(&self, points: &PointSet) -> bool {
        let long = |from: usize| points.kind() == Kind::Trajectories && points.dim() / 2 >= from;
        self.refine || self.refine_from_frames.is_some_and(long)
    }

    /// How fits of this model refine by default: its outliers, stay and margin settings, the
    /// outlier threshold from the data, hypotheses on.
    pub fn refine_params(&self) -> RefineParams {
        RefineParams {
            outliers: self.outliers,
            threshold: None,
            hypotheses: true,
            stay: self.refine_stay,
            margin: self.refine_margin,
        }
    }

    /// The models a structure of this model may follow.
    pub fn family(&self) -> Family {
        self.geometry.unwrap_or(match self.kind {
            Kind::Points2d => Family::Curves,
            Kind::Correspondences => Family::Fundamental,
            Kind::Trajectories => Family::Subspace,
        })
    }

    /// Warnings for a fit outside the card's validated range (none without a range).
    pub fn warnings(&self, seen: &Observed) -> Vec<String> {
        self.validated
            .as_ref()
            .map_or_else(Vec::new, |v| v.warnings(seen))
    }

    /// Checks the card is internally consistent.
    pub fn validate(&self) -> Result<(), CardError> {
        if self.name.is_empty()
            || !self
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            return Err(CardError::Name(self.name.clone()));
        }
        if self.input_dim != self.architecture.input_dim {
            return Err(CardError::InputDim {
                input_dim: self.input_dim,
                architecture: self.architecture.input_dim,
            });
        }
        if !self.kind.accepts_dim(self.input_dim) {
            return Err(CardError::InputDimForKind {
                input_dim: self.input_dim,
                kind: self.kind,
            });
        }
        if self.normalization != Normalization::for_kind(self.kind) {
            return Err(CardError::Normalization {
                normalization: self.normalization,
                kind: self.kind,
            });
        }
        if self.k_max == 0 {
            return Err(CardError::KMax);
        }
        if matches!(self.selection, Selection::Fixed(_)) {
            return Err(CardError::FixedSelection);
        }
        symmetry::check(&self.test_symmetries, self.kind).map_err(CardError::TestSymmetries)?;
        let files: Vec<&str> = self.weight_files().collect();
        for (i, file) in files.iter().enumerate().skip(1) {
            let plain = Path::new(file).file_name() == Some(file.as_ref());
            if !plain || !file.ends_with(".safetensors") {
                return Err(CardError::WeightsFile(file.to_string()));
            }
            if files[..i].contains(file) {
                return Err(CardError::WeightsTwice(file.to_string()));
            }
        }
        if !(self.refine_stay.is_finite() && self.refine_stay >= 0.0) {
            return Err(CardError::RefineStay(self.refine_stay));
        }
        if !(self.refine_margin.is_finite() && self.refine_margin >= 0.0) {
            return Err(CardError::RefineMargin(self.refine_margin));
        }
        if let Some(sparse) = &self.sparse {
            let spacing = self.spacing.unwrap_or(f64::NAN);
            if !(spacing.is_finite() && spacing > 0.0 && self.architecture.neighbors > 0) {
                return Err(CardError::SparseWithoutSpacing);
            }
            if !(sparse.above.is_finite() && sparse.above >= 1.0) {
                return Err(CardError::SparseAbove(sparse.above));
            }
        }
        self.architecture
            .validate()
            .map_err(CardError::Architecture)
    }

    /// The weight files of the model's networks, relative to its directory: the card's own
    /// network ([`WEIGHTS_FILE`]) first, then each member's, then the sparse network's.
    pub fn weight_files(&self) -> impl Iterator<Item = &str> {
        std::iter::once(WEIGHTS_FILE)
            .chain(self.members.iter().map(|m| m.weights.as_str()))
            .chain(self.sparse.iter().map(|s| s.weights.as_str()))
    }

    pub fn read(dir: &Path) -> Result<Self, RegistryError> {
        let path = dir.join(CARD_FILE);
        let text = std::fs::read_to_string(&path).map_err(|source| RegistryError::Io {
            path: path.clone(),
            source,
        })?;
        let card: ModelCard = serde_json::from_str(&text).map_err(|e| RegistryError::Card {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        card.validate().map_err(|e| RegistryError::Card {
            path,
            reason: e.to_string(),
        })?;
        Ok(card)
    }

    pub fn write(&self, dir: &Path) -> std::io::Result<()> {
        std::fs::create_dir_all(dir)?;
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        std::fs::write(dir.join(CARD_FILE), text + "\n")
    }
}

/// A model card for a network trained in this process (used for folds and `train`).
pub fn card_for(
    name: &str,
    kind: Kind,
    architecture: &ModelConfig,
    loss: Loss,
    k_max: usize,
    training: TrainingInfo,
) -> ModelCard {
    ModelCard {
        name: name.to_string(),
        version: "1".into(),
        kind,
        input_dim: architecture.input_dim,
        normalization: Normalization::for_kind(kind),
        architecture: architecture.clone(),
        loss,
        k_max,
        selection: crate::cluster::Selection::Sod,
        training,
        default: false,
        test_symmetries: vec![],
        members: vec![],
        frames: FrameSampling::default(),
        refine: false,
        refine_from_frames: None,
        outliers: true,
        refine_stay: 0.0,
        refine_margin: 0.0,
        geometry: None,
        spacing: None,
        sparse: None,
        validated: None,
        metrics: vec![],
        multifit_version: env!("CARGO_PKG_VERSION").into(),
        git_commit: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registry::tests::tiny;

    #[test]
    fn cards_refuse_symmetries_that_do_not_apply() {
        let mut card = tiny(vec![]).card;
        card.test_symmetries = vec![Symmetry::Mirror, Symmetry::Mirror];
        assert!(
            card.validate()
                .unwrap_err()
                .to_string()
                .contains("repeated")
        );
        card.kind = Kind::Points2d;
        card.input_dim = 2;
        card.architecture.input_dim = 2;
        card.normalization = Normalization::for_kind(Kind::Points2d);
        card.test_symmetries = vec![Symmetry::Reverse];
        assert!(
            card.validate()
                .unwrap_err()
                .to_string()
                .contains("does not apply to points2d")
        );
        card.test_symmetries = vec![Symmetry::Mirror];
        card.validate().unwrap();
    }

    #[test]
    fn the_stay_and_margin_settings_reach_refinement_and_bad_values_are_refused() {
        let mut card = tiny(vec![]).card;
        assert_eq!(card.refine_params().stay, 0.0);
        assert_eq!(card.refine_params().margin, 0.0);
        card.refine_stay = 1.0;
        card.refine_margin = 0.1;
        card.validate().unwrap();
        assert_eq!(card.refine_params().stay, 1.0);
        assert_eq!(card.refine_params().margin, 0.1);
        assert_eq!(card.refine_params().outliers, card.outliers);
        for bad in [-0.5, f64::NAN, f64::INFINITY] {
            let mut stay = card.clone();
            stay.refine_stay = bad;
            let mut margin = card.clone();
            margin.refine_margin = bad;
            for (card, name) in [(stay, "refine_stay"), (margin, "refine_margin")] {
                let message = card.validate().unwrap_err().to_string();
                assert!(message.contains(name), "{bad}: {message}");
            }
        }
    }

    #[test]
    fn long_tracks_refine_by_default_from_the_cards_frame_count() {
        let mut card = tiny(vec![]).card;
        let tracks = |frames: usize| {
            let rows: Vec<Vec<f64>> = (0..6)
                .map(|i| (0..2 * frames).map(|j| (i * j) as f64).collect())
                .collect();
            PointSet::from_rows(Kind::Trajectories, &rows).unwrap()
        };
        assert!(!card.refines(&tracks(20)));
        card.refine_from_frames = Some(15);
        assert!(!card.refines(&tracks(14)));
        assert!(card.refines(&tracks(15)) && card.refines(&tracks(40)));
        // Correspondences are 4 wide: never "2 frames" of a trajectory model.
        let pairs = PointSet::from_rows(Kind::Correspondences, &vec![vec![0.0; 4]; 8]).unwrap();
        card.refine_from_frames = Some(2);
        assert!(!card.refines(&pairs));
        card.refine = true;
        assert!(card.refines(&tracks(5)) && card.refines(&pairs));
    }

    #[test]
    fn a_fit_outside_the_validated_range_names_each_quantity() {
        let range = ValidatedRange {
            points: Some([100, 2000]),
            points_per_structure: Some([20, 500]),
            frames: Some([5, 20]),
            image_side: Some([400.0, 1000.0]),
            outlier_ratio: Some([0.0, 0.5]),
            source: String::new(),
        };
        let inside = Observed {
            rows: "",
            points: 300,
            points_per_structure: Some([40, 200]),
            frames: Some(5),
            image_side: Some(640.0),
            outlier_ratio: Some(0.1),
        };
        assert!(range.warnings(&inside).is_empty());
        let outside = Observed {
            rows: "",
            points: 50,
            points_per_structure: Some([3, 900]),
            frames: Some(29),
            image_side: Some(300.0),
            outlier_ratio: Some(0.75),
        };
        let w = range.warnings(&outside);
        assert_eq!(w.len(), 6, "{w:?}");
        for name in [
            "points 50",
            "smallest structure's points 3",
            "largest structure's points 900",
            "frames 29",
            "image side 300",
            "outlier ratio 0.75",
        ] {
            assert!(w.iter().any(|m| m.starts_with(name)), "{name}: {w:?}");
        }
        // An image larger than validated, or fewer outliers, is not harder: no warning.
        let easier = Observed {
            image_side: Some(4000.0),
            outlier_ratio: Some(0.0),
            ..inside
        };
        let narrow = ValidatedRange {
            outlier_ratio: Some([0.05, 0.5]),
            ..range.clone()
        };
        assert!(
            narrow.warnings(&easier).is_empty(),
            "{:?}",
            narrow.warnings(&easier)
        );
        // The rows counted are named as the fit says.
        let seen = Observed {
            rows: "tracks seen in every frame",
            ..outside
        };
        assert!(range.warnings(&seen)[0].starts_with("tracks seen in every frame 50 is outside"));
        // A card without a range never warns.
        let card = tiny(vec![]).card;
        assert!(card.warnings(&outside).is_empty());
    }
}
