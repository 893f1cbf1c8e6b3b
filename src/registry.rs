//! Model directories (`models/<name>/`: `model.json` card + `weights.safetensors`) and the fit
//! pipeline that runs a loaded model: normalise -> embed -> cluster.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::prelude::Device;
use serde::{Deserialize, Serialize};

use crate::cluster::{self, ClusterError, ClusterParams, Clustering, Points, Selection};
use crate::data::features::with_neighbors;
use crate::data::symmetry::{self, closure};
use crate::data::{ImageSize, Kind, Normalization, PointSet, Symmetry};
use crate::loss::Loss;
use crate::model::{EmbeddingNet, FusedNet, ModelConfig, ModelError, cpu_device};
use crate::threads::Threads;

/// File names inside a model directory.
pub const CARD_FILE: &str = "model.json";
pub const WEIGHTS_FILE: &str = "weights.safetensors";

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
    /// Test-time symmetries: the input's images under every combination of these are embedded
    /// too, and each point's embeddings are concatenated (scaled to unit length) before
    /// clustering. Empty: the input alone, as in the paper.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub test_symmetries: Vec<Symmetry>,
    #[serde(default)]
    pub metrics: Vec<MetricRecord>,
    /// multifit version and git commit that trained it.
    pub multifit_version: String,
    #[serde(default)]
    pub git_commit: Option<String>,
}

/// Why a model directory cannot be served.
#[derive(Debug, thiserror::Error)]
pub enum RegistryError {
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: invalid model card: {reason}")]
    Card { path: PathBuf, reason: String },
    #[error(transparent)]
    Weights(#[from] ModelError),
    #[error("{path}: no model directories (each needs {CARD_FILE} and {WEIGHTS_FILE})")]
    Empty { path: PathBuf },
    #[error("two model directories are named {name:?}")]
    Duplicate { name: String },
}

impl ModelCard {
    /// Checks the card is internally consistent.
    pub fn validate(&self) -> Result<(), String> {
        if self.name.is_empty()
            || !self
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            return Err(format!(
                "name {:?} must be non-empty ASCII letters, digits, '-' or '_'",
                self.name
            ));
        }
        if self.input_dim != self.architecture.input_dim {
            return Err(format!(
                "input_dim {} differs from architecture.input_dim {}",
                self.input_dim, self.architecture.input_dim
            ));
        }
        if !self.kind.accepts_dim(self.input_dim) {
            return Err(format!(
                "input_dim {} is not valid for kind {}",
                self.input_dim, self.kind
            ));
        }
        if self.normalization != Normalization::for_kind(self.kind) {
            return Err(format!(
                "normalization {:?} is not the one kind {} uses",
                self.normalization, self.kind
            ));
        }
        if self.k_max == 0 {
            return Err("k_max must be at least 1".into());
        }
        if matches!(self.selection, Selection::Fixed(_)) {
            return Err("the default selection must be sod or silhouette".into());
        }
        symmetry::check(&self.test_symmetries, self.kind)
            .map_err(|e| format!("test_symmetries: {e}"))?;
        self.architecture.validate().map_err(|e| e.to_string())
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
        card.validate()
            .map_err(|reason| RegistryError::Card { path, reason })?;
        Ok(card)
    }

    pub fn write(&self, dir: &Path) -> std::io::Result<()> {
        std::fs::create_dir_all(dir)?;
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        std::fs::write(dir.join(CARD_FILE), text + "\n")
    }
}

/// A model ready to fit point sets. Embeddings come from the fused serving forward
/// ([`FusedNet`]); the burn network is kept for training-side use and for cross-checks.
#[derive(Debug)]
pub struct LoadedModel {
    pub card: ModelCard,
    pub net: EmbeddingNet,
    fused: FusedNet,
    /// Threads one fit may use.
    threads: Threads,
    device: Device,
}

/// Why a fit request cannot be answered by this model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    #[error("model {model} takes {expected} input, got {found}")]
    WrongKind {
        model: String,
        expected: Kind,
        found: Kind,
    },
    #[error("model {model} takes rows of {expected} values, got {found}")]
    WrongDim {
        model: String,
        expected: usize,
        found: usize,
    },
    #[error(transparent)]
    Cluster(#[from] ClusterError),
}

/// The answer to one fit.
#[derive(Debug, Clone)]
pub struct FitOutcome {
    pub clustering: Clustering,
    /// Row-major `[n, embed_dim]`.
    pub embeddings: Vec<f32>,
    pub embed_dim: usize,
    pub embed_ms: f64,
    pub cluster_ms: f64,
}

impl LoadedModel {
    /// Loads and cross-checks `dir/model.json` and `dir/weights.safetensors`.
    pub fn load(dir: &Path) -> Result<Self, RegistryError> {
        let card = ModelCard::read(dir)?;
        let device = cpu_device();
        let net = EmbeddingNet::load(&card.architecture, &dir.join(WEIGHTS_FILE), &device)?;
        Ok(Self::from_parts(card, net, device)?)
    }

    /// Wraps a freshly trained network. Fits run on the calling thread until
    /// [`LoadedModel::with_threads`] says otherwise.
    pub fn from_parts(
        card: ModelCard,
        net: EmbeddingNet,
        device: Device,
    ) -> Result<Self, ModelError> {
        let fused = FusedNet::from_net(&net)?;
        Ok(Self {
            card,
            net,
            fused,
            threads: Threads::default(),
            device,
        })
    }

    /// Runs fits (forward pass and k-means) on a pool of `threads` threads of this model's own.
    pub fn with_threads(self, threads: usize) -> Result<Self, ModelError> {
        let pool = Threads::new(threads)
            .map_err(|e| ModelError::Config(format!("cannot start {threads} threads: {e}")))?;
        Ok(self.with_pool(pool))
    }

    /// Runs fits on `pool`, which other models and fits may share: the server gives every model
    /// one pool of as many threads as cores, so a fit alone uses every core and fits at once
    /// split them, never oversubscribing.
    pub fn with_pool(mut self, pool: Threads) -> Self {
        self.threads = pool;
        self
    }

    /// Threads of the pool fits run on.
    pub fn threads(&self) -> usize {
        self.threads.count()
    }

    /// Embeddings by the burn forward (training's code path), for cross-checks:
    /// features `[n, feature_dim]` -> `[n, e]`.
    pub fn embed_burn(&self, features: &[f32]) -> Vec<f32> {
        self.net
            .embed(features, self.card.architecture.feature_dim(), &self.device)
    }

    /// Network input for `points` (normalised, neighbour offsets appended), checking kind and
    /// width: row-major `[n, feature_dim]`.
    pub fn prepare(
        &self,
        points: &PointSet,
        image: Option<ImageSize>,
    ) -> Result<Vec<f32>, FitError> {
        if points.kind() != self.card.kind {
            return Err(FitError::WrongKind {
                model: self.card.name.clone(),
                expected: self.card.kind,
                found: points.kind(),
            });
        }
        if points.dim() != self.card.input_dim {
            return Err(FitError::WrongDim {
                model: self.card.name.clone(),
                expected: self.card.input_dim,
                found: points.dim(),
            });
        }
        let normalised = self.card.normalization.apply(points, image);
        Ok(with_neighbors(
            &normalised,
            self.card.input_dim,
            self.card.architecture.neighbors,
        ))
    }

    /// Embeddings of prepared input by the fused forward: `[n, feature_dim]` -> `[n, e]`.
    pub fn embed(&self, features: &[f32]) -> Vec<f32> {
        self.fused.forward(features, &self.threads)
    }

    /// The embeddings a fit clusters and their width: `points` `[n, d]` -> `[n, e * m]`, where
    /// m counts the input and its images under every combination of `symmetries`. Row i holds
    /// the embeddings of point i in each, side by side, divided by the square root of m so that
    /// it keeps unit length. An image that does not exist (a symmetry that does not apply to the
    /// kind, or coordinates pushed past the accepted range) is left out.
    fn fit_embeddings(
        &self,
        points: &PointSet,
        image: Option<ImageSize>,
        symmetries: &[Symmetry],
    ) -> Result<(Vec<f32>, usize), FitError> {
        let first = self.embed(&self.prepare(points, image)?);
        let e = self.card.architecture.embed_dim;
        if symmetries.is_empty() {
            return Ok((first, e));
        }
        let images = closure(vec![points.clone()], symmetries, |s, p| {
            s.apply_points(p, image)
        });
        let mut all = vec![first];
        for p in &images[1..] {
            all.push(self.embed(&self.prepare(p, image)?));
        }
        let scale = 1.0 / (all.len() as f32).sqrt();
        let rows = (0..points.len())
            .flat_map(|i| all.iter().flat_map(move |z| &z[i * e..(i + 1) * e]))
            .map(|v| v * scale)
            .collect();
        Ok((rows, e * all.len()))
    }

    /// Normalise, embed (with the card's test symmetries) and cluster one point set.
    pub fn fit(
        &self,
        points: &PointSet,
        image: Option<ImageSize>,
        params: &ClusterParams,
    ) -> Result<FitOutcome, FitError> {
        self.fit_with(points, image, params, &self.card.test_symmetries)
    }

    /// [`LoadedModel::fit`] with the given test symmetries instead of the card's (`&[]`: the
    /// input alone, one forward pass).
    pub fn fit_with(
        &self,
        points: &PointSet,
        image: Option<ImageSize>,
        params: &ClusterParams,
        symmetries: &[Symmetry],
    ) -> Result<FitOutcome, FitError> {
        if let Selection::Fixed(k) = params.selection()
            && k > points.len()
        {
            return Err(ClusterError::KOutOfRange { k, n: points.len() }.into());
        }
        let t0 = Instant::now();
        let (embeddings, e) = self.fit_embeddings(points, image, symmetries)?;
        let t1 = Instant::now();
        let clustering = cluster::cluster_on(Points::new(&embeddings, e)?, params, &self.threads)?;
        let t2 = Instant::now();
        Ok(FitOutcome {
            clustering,
            embeddings,
            embed_dim: e,
            embed_ms: (t1 - t0).as_secs_f64() * 1e3,
            cluster_ms: (t2 - t1).as_secs_f64() * 1e3,
        })
    }
}

/// Every model under a directory, by name. Fails on the first directory that cannot be loaded,
/// naming it: a server must not start with half its models.
pub fn load_all(root: &Path) -> Result<BTreeMap<String, LoadedModel>, RegistryError> {
    let entries = std::fs::read_dir(root).map_err(|source| RegistryError::Io {
        path: root.to_path_buf(),
        source,
    })?;
    let mut dirs: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    dirs.sort();
    let mut models = BTreeMap::new();
    for dir in dirs {
        let model = LoadedModel::load(&dir)?;
        let name = model.card.name.clone();
        if models.insert(name.clone(), model).is_some() {
            return Err(RegistryError::Duplicate { name });
        }
    }
    if models.is_empty() {
        return Err(RegistryError::Empty {
            path: root.to_path_buf(),
        });
    }
    Ok(models)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::cv::card_for;
    use crate::train::{Schedule, TrainConfig};

    fn tiny(symmetries: Vec<Symmetry>) -> LoadedModel {
        let model = ModelConfig {
            input_dim: 4,
            width: 8,
            depth: 1,
            embed_dim: 3,
            batch_norm: false,
            cn_epsilon: 1e-3,
            neighbors: 0,
            graph_neighbors: 0,
        };
        let device = cpu_device();
        let net = model.init_seeded(&device, 7).unwrap();
        let config = TrainConfig {
            model,
            loss: Loss::L2,
            learning_rate: 1e-3,
            schedule: Schedule::Constant,
            epochs: 1,
            seed: 0,
            batch_size: 1,
            jitter: 0.0,
        };
        let info = TrainingInfo {
            data: String::new(),
            command: String::new(),
            epochs: 1,
            learning_rate: 1e-3,
            seed: 0,
            seconds: 0.0,
            machine: String::new(),
        };
        let mut card = card_for("tiny", Kind::Trajectories, &config, 4, info);
        card.test_symmetries = symmetries;
        card.validate().unwrap();
        LoadedModel::from_parts(card, net, device).unwrap()
    }

    #[test]
    fn test_symmetries_concatenate_unit_embeddings_of_every_image() {
        let values = (0..40).map(|v| ((v * 7) % 13) as f64).collect();
        let points = PointSet::from_flat(Kind::Trajectories, 4, values).unwrap();
        let image = Some(ImageSize::new(20.0, 20.0).unwrap());
        let params = ClusterParams::builder()
            .selection(Selection::Fixed(2))
            .seed(1)
            .build()
            .unwrap();
        let plain = tiny(vec![]);
        let both = tiny(vec![Symmetry::Mirror, Symmetry::Reverse]);
        let a = plain.fit(&points, image, &params).unwrap();
        let b = both.fit(&points, image, &params).unwrap();
        assert_eq!((a.embed_dim, b.embed_dim), (3, 12));
        assert_eq!(b.embeddings.len(), 12 * points.len());
        assert_eq!(b.clustering.labels.len(), points.len());
        // Row i: [input, mirrored, reversed, mirrored and reversed] embeddings of point i, / 2.
        let image_of = |ss: &[Symmetry]| {
            let p = ss
                .iter()
                .fold(points.clone(), |p, s| s.apply_points(&p, image).unwrap());
            plain.fit(&p, image, &params).unwrap().embeddings
        };
        let blocks = [
            a.embeddings.clone(),
            image_of(&[Symmetry::Mirror]),
            image_of(&[Symmetry::Reverse]),
            image_of(&[Symmetry::Mirror, Symmetry::Reverse]),
        ];
        for i in 0..points.len() {
            let row = &b.embeddings[i * 12..(i + 1) * 12];
            let norm = row.iter().map(|v| v * v).sum::<f32>().sqrt();
            assert!((norm - 1.0).abs() < 1e-4, "row {i} has norm {norm}");
            for (c, block) in blocks.iter().enumerate() {
                for j in 0..3 {
                    let want = block[i * 3 + j] / 2.0;
                    assert!((row[c * 3 + j] - want).abs() < 1e-6, "row {i} block {c}");
                }
            }
        }
        // The mirrored input's own block differs from the input's: the images are real inputs.
        assert!((0..3).any(|j| (blocks[0][j] - blocks[1][j]).abs() > 1e-4));
        // Without symmetries the same model embeds the input alone; quarter turns give 4 images.
        let alone = both.fit_with(&points, image, &params, &[]).unwrap();
        assert_eq!(alone.embeddings, a.embeddings);
        let turns = both
            .fit_with(&points, image, &params, &[Symmetry::Rotate])
            .unwrap();
        assert_eq!(turns.embed_dim, 12);
        // An image whose coordinates would leave the accepted range is left out, not an error:
        // mirrored about x = 5e8, x = -1e9 would become 2e9.
        let far = PointSet::from_flat(
            Kind::Trajectories,
            4,
            vec![-1e9, 0.0, -1e9, 1.0, 1e9, 0.0, 1e9, 1.0, 0.0, 5.0, 1.0, 6.0],
        )
        .unwrap();
        let wide = Some(ImageSize::new(1e9, 10.0).unwrap());
        let fit = both
            .fit_with(&far, wide, &params, &[Symmetry::Mirror])
            .unwrap();
        assert_eq!(fit.embed_dim, 3);
        assert_eq!(fit.embeddings.len(), 3 * 3);
    }

    #[test]
    fn cards_refuse_symmetries_that_do_not_apply() {
        let mut card = tiny(vec![]).card;
        card.test_symmetries = vec![Symmetry::Mirror, Symmetry::Mirror];
        assert!(card.validate().unwrap_err().contains("repeated"));
        card.kind = Kind::Points2d;
        card.input_dim = 2;
        card.architecture.input_dim = 2;
        card.normalization = Normalization::for_kind(Kind::Points2d);
        card.test_symmetries = vec![Symmetry::Reverse];
        assert!(
            card.validate()
                .unwrap_err()
                .contains("does not apply to points2d")
        );
        card.test_symmetries = vec![Symmetry::Mirror];
        card.validate().unwrap();
    }
}
