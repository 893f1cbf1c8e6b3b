//! Model directories (`models/<name>/`: `model.json` card + `weights.safetensors`) and the fit
//! pipeline that runs a loaded model: normalise -> embed -> cluster.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::prelude::Device;
use serde::{Deserialize, Serialize};

use crate::cluster::{self, ClusterError, ClusterParams, Clustering, Points, Selection};
use crate::data::features::with_neighbors;
use crate::data::{ImageSize, Kind, Normalization, PointSet};
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

    /// Normalise, embed and cluster one point set.
    pub fn fit(
        &self,
        points: &PointSet,
        image: Option<ImageSize>,
        params: &ClusterParams,
    ) -> Result<FitOutcome, FitError> {
        if let Selection::Fixed(k) = params.selection()
            && k > points.len()
        {
            return Err(ClusterError::KOutOfRange { k, n: points.len() }.into());
        }
        let input = self.prepare(points, image)?;
        let t0 = Instant::now();
        let embeddings = self.embed(&input);
        let t1 = Instant::now();
        let e = self.card.architecture.embed_dim;
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
