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

/// A further network in an ensemble: same architecture, input and normalisation as the card's
/// own network, its own weights and training.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Member {
    /// Its weights file, a plain file name inside the model directory.
    pub weights: String,
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
    #[error("cannot make an ensemble: {0}")]
    Ensemble(String),
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
        let files: Vec<&str> = self.weight_files().collect();
        for (i, file) in files.iter().enumerate().skip(1) {
            let plain = Path::new(file).file_name() == Some(file.as_ref());
            if !plain || !file.ends_with(".safetensors") {
                return Err(format!(
                    "members: weights {file:?} must be a plain .safetensors file name"
                ));
            }
            if files[..i].contains(file) {
                return Err(format!("members: weights {file:?} named twice"));
            }
        }
        self.architecture.validate().map_err(|e| e.to_string())
    }

    /// The weight files of the model's networks, relative to its directory: the card's own
    /// network ([`WEIGHTS_FILE`]) first, then each member's.
    pub fn weight_files(&self) -> impl Iterator<Item = &str> {
        std::iter::once(WEIGHTS_FILE).chain(self.members.iter().map(|m| m.weights.as_str()))
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
    /// The fused forwards of the card's further networks, in the card's order.
    members: Vec<FusedNet>,
    /// Threads one fit may use.
    threads: Threads,
    device: Device,
    /// Hex SHA-256 of the weight files, concatenated in [`ModelCard::weight_files`] order;
    /// `None` for a network that was never read from a file ([`LoadedModel::from_parts`]).
    weights_sha256: Option<String>,
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
        let members = card
            .weight_files()
            .skip(1)
            .map(|file| {
                let net = EmbeddingNet::load(&card.architecture, &dir.join(file), &device)?;
                FusedNet::from_net(&net)
            })
            .collect::<Result<Vec<_>, _>>()?;
        let weights_sha256 = weights_sha256(dir, &card)?;
        let mut model = Self::assemble(card, net, device)?;
        model.members = members;
        model.weights_sha256 = Some(weights_sha256);
        Ok(model)
    }

    /// Hex SHA-256 of the weight files the model was loaded from, concatenated in the card's
    /// order (`cat weights.safetensors weights-1.safetensors ... | sha256sum`): the identity of
    /// exactly these weights, which the card's `version` is not. `None` for a network built in
    /// this process ([`LoadedModel::from_parts`]). The files are read again for the digest after
    /// the networks are built: replace a model directory while no server is loading it.
    pub fn weights_sha256(&self) -> Option<&str> {
        self.weights_sha256.as_deref()
    }

    /// Wraps a freshly trained network. Fits run on the calling thread until
    /// [`LoadedModel::with_threads`] says otherwise.
    /// A card with `members` needs their weights: load it with [`LoadedModel::load`].
    pub fn from_parts(
        card: ModelCard,
        net: EmbeddingNet,
        device: Device,
    ) -> Result<Self, ModelError> {
        if !card.members.is_empty() {
            return Err(ModelError::Config(format!(
                "model {} is an ensemble of {} networks: load it from its directory",
                card.name,
                card.members.len() + 1
            )));
        }
        Self::assemble(card, net, device)
    }

    fn assemble(card: ModelCard, net: EmbeddingNet, device: Device) -> Result<Self, ModelError> {
        let fused = FusedNet::from_net(&net)?;
        Ok(Self {
            card,
            net,
            fused,
            members: Vec::new(),
            threads: Threads::default(),
            device,
            weights_sha256: None,
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

    /// Embeddings of prepared input by the fused forward of the card's own network (not its
    /// members'): `[n, feature_dim]` -> `[n, e]`.
    pub fn embed(&self, features: &[f32]) -> Vec<f32> {
        self.fused.forward(features, &self.threads)
    }

    /// The embeddings a fit clusters and their width: `points` `[n, d]` -> `[n, e * m]`, where
    /// m counts the networks (the card's and its members) times the images (the input and its
    /// images under every combination of `symmetries`). Row i holds the embeddings of point i by
    /// each network of each image (networks vary fastest), side by side, divided by the square
    /// root of m so that it keeps unit length. An image that does not exist (a symmetry that
    /// does not apply to the kind, or coordinates pushed past the accepted range) is left out.
    pub fn fit_embeddings(
        &self,
        points: &PointSet,
        image: Option<ImageSize>,
        symmetries: &[Symmetry],
    ) -> Result<(Vec<f32>, usize), FitError> {
        let e = self.card.architecture.embed_dim;
        let images = if symmetries.is_empty() {
            vec![points.clone()]
        } else {
            closure(vec![points.clone()], symmetries, |s, p| {
                s.apply_points(p, image)
            })
        };
        let mut all = Vec::new();
        for p in &images {
            let x = self.prepare(p, image)?;
            all.push(self.embed(&x));
            for member in &self.members {
                all.push(member.forward(&x, &self.threads));
            }
        }
        if all.len() == 1 {
            return Ok((all.remove(0), e));
        }
        let scale = 1.0 / (all.len() as f32).sqrt();
        let rows = (0..points.len())
            .flat_map(|i| all.iter().flat_map(move |z| &z[i * e..(i + 1) * e]))
            .map(|v| v * scale)
            .collect();
        Ok((rows, e * all.len()))
    }

    /// Clusters embeddings from [`LoadedModel::fit_embeddings`] on this model's threads:
    /// `embeddings` `[n, e]` -> n labels.
    pub fn cluster(
        &self,
        embeddings: &[f32],
        e: usize,
        params: &ClusterParams,
    ) -> Result<Clustering, FitError> {
        Ok(cluster::cluster_on(
            Points::new(embeddings, e)?,
            params,
            &self.threads,
        )?)
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
    /// input alone, one forward pass per network).
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
        let clustering = self.cluster(&embeddings, e, params)?;
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

/// Writes to `out` a model named `name` that embeds with every model in `dirs` (an ensemble):
/// the first model's card and weights, and the others as its members (`weights-<i>.safetensors`).
/// The models must be distinct single networks sharing kind, input, normalisation, architecture
/// and test symmetries. The first card's metrics are dropped: they measured that network alone;
/// its K defaults are kept. The model is written beside `out`, loaded to check it, and only then
/// put in `out`'s place (which must be absent, empty or a model directory), so a failure never
/// leaves a half-written model behind.
pub fn write_ensemble(
    dirs: &[PathBuf],
    out: &Path,
    name: &str,
) -> Result<ModelCard, RegistryError> {
    let fail = |reason: String| RegistryError::Ensemble(reason);
    if dirs.len() < 2 {
        return Err(fail(format!(
            "needs at least two models, got {}",
            dirs.len()
        )));
    }
    let cards = dirs
        .iter()
        .map(|d| ModelCard::read(d))
        .collect::<Result<Vec<_>, _>>()?;
    let first = &cards[0];
    let out_path = out.canonicalize().ok();
    let mut seen = Vec::new();
    for (dir, card) in dirs.iter().zip(&cards) {
        if !card.members.is_empty() {
            return Err(fail(format!("{} is itself an ensemble", dir.display())));
        }
        let same = (
            card.kind,
            card.input_dim,
            card.normalization,
            &card.architecture,
            &card.test_symmetries,
        ) == (
            first.kind,
            first.input_dim,
            first.normalization,
            &first.architecture,
            &first.test_symmetries,
        );
        if !same {
            return Err(fail(format!(
                "{} differs from {} in kind, input, normalisation, architecture or test symmetries",
                dir.display(),
                dirs[0].display()
            )));
        }
        let path = dir.canonicalize().ok();
        if path.is_some() && path == out_path {
            return Err(fail(format!(
                "{} is both a member and the output",
                dir.display()
            )));
        }
        if path.is_some() && seen.contains(&path) {
            return Err(fail(format!("{} is named twice", dir.display())));
        }
        seen.push(path);
    }
    let mut card = first.clone();
    card.name = name.to_string();
    card.metrics.clear();
    card.members = cards[1..]
        .iter()
        .enumerate()
        .map(|(i, c)| Member {
            weights: format!("weights-{}.safetensors", i + 1),
            loss: c.loss,
            training: c.training.clone(),
        })
        .collect();
    card.validate().map_err(|reason| RegistryError::Card {
        path: out.join(CARD_FILE),
        reason,
    })?;
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| RegistryError::Io { path, source }
    };
    let replaceable = match std::fs::read_dir(out) {
        Ok(mut entries) => entries.next().is_none() || out.join(CARD_FILE).is_file(),
        Err(e) => e.kind() == std::io::ErrorKind::NotFound,
    };
    if !replaceable {
        return Err(fail(format!(
            "{} exists and is not a model directory",
            out.display()
        )));
    }
    let staging = sibling(out, "partial");
    let _ = std::fs::remove_dir_all(&staging);
    std::fs::create_dir_all(&staging).map_err(io(&staging))?;
    for (dir, file) in dirs.iter().zip(card.weight_files()) {
        // Read and write rather than copy: a copy would keep the source's permissions.
        let from = dir.join(WEIGHTS_FILE);
        let bytes = std::fs::read(&from).map_err(io(&from))?;
        std::fs::write(staging.join(file), bytes).map_err(io(&staging.join(file)))?;
    }
    card.write(&staging).map_err(io(&staging.join(CARD_FILE)))?;
    let installed = LoadedModel::load(&staging).and_then(|_| {
        let old = sibling(out, "old");
        let _ = std::fs::remove_dir_all(&old);
        if out.exists() {
            std::fs::rename(out, &old).map_err(io(out))?;
        }
        std::fs::rename(&staging, out).map_err(io(out))?;
        let _ = std::fs::remove_dir_all(&old);
        Ok(())
    });
    if installed.is_err() {
        let _ = std::fs::remove_dir_all(&staging);
    }
    installed.map(|()| card)
}

/// `dir` with `.<tag>` appended to its last component: a scratch directory beside it.
fn sibling(dir: &Path, tag: &str) -> PathBuf {
    let mut name = dir.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".{tag}"));
    dir.with_file_name(name)
}

/// Hex SHA-256 of `dir`'s weight files, concatenated in [`ModelCard::weight_files`] order.
fn weights_sha256(dir: &Path, card: &ModelCard) -> Result<String, RegistryError> {
    use sha2::{Digest, Sha256};
    let mut hasher = Sha256::new();
    for file in card.weight_files() {
        let path = dir.join(file);
        std::fs::File::open(&path)
            .and_then(|mut f| std::io::copy(&mut f, &mut hasher))
            .map_err(|source| RegistryError::Io { path, source })?;
    }
    Ok(format!("{:x}", hasher.finalize()))
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
pub(crate) mod tests {
    use super::*;
    use crate::train::cv::card_for;
    use crate::train::{Schedule, TrainConfig};
    use tempfile::TempDir;

    fn tiny(symmetries: Vec<Symmetry>) -> LoadedModel {
        tiny_seeded(symmetries, 7)
    }

    /// A one-block network on 2-frame tracks (D = 4), embedding in 3 dimensions.
    pub(crate) fn tiny_seeded(symmetries: Vec<Symmetry>, seed: u64) -> LoadedModel {
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
        let net = model.init_seeded(&device, seed).unwrap();
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
            seed,
            seconds: 0.0,
            machine: String::new(),
        };
        let mut card = card_for("tiny", Kind::Trajectories, &config, 4, info);
        card.test_symmetries = symmetries;
        card.validate().unwrap();
        LoadedModel::from_parts(card, net, device).unwrap()
    }

    /// Ten 2-frame tracks with coordinates `(v * a) % m`, a 20 x 20 image and k-means with K = 2.
    fn ten_tracks(a: usize, m: usize) -> (PointSet, Option<ImageSize>, ClusterParams) {
        let values = (0..40).map(|v| ((v * a) % m) as f64).collect();
        let points = PointSet::from_flat(Kind::Trajectories, 4, values).unwrap();
        let image = Some(ImageSize::new(20.0, 20.0).unwrap());
        let params = ClusterParams::builder()
            .selection(Selection::Fixed(2))
            .seed(1)
            .build()
            .unwrap();
        (points, image, params)
    }

    #[test]
    fn test_symmetries_concatenate_unit_embeddings_of_every_image() {
        let (points, image, params) = ten_tracks(7, 13);
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

    /// A fresh directory (`multifit-<tag>-XXXXXX` in the system temp dir), removed when dropped.
    fn scratch(tag: &str) -> TempDir {
        tempfile::Builder::new()
            .prefix(&format!("multifit-{tag}-"))
            .tempdir()
            .unwrap()
    }

    fn save(model: &LoadedModel, dir: &Path) {
        model.card.write(dir).unwrap();
        model.net.save(&dir.join(WEIGHTS_FILE)).unwrap();
    }

    /// Two tiny single-network models of different seeds (7, 8), saved in `<tmp>/a` and `<tmp>/b`.
    fn two_saved_models(tmp: &TempDir) -> (LoadedModel, LoadedModel, [PathBuf; 2]) {
        let (a, b) = (tiny_seeded(vec![], 7), tiny_seeded(vec![], 8));
        let dirs = [tmp.path().join("a"), tmp.path().join("b")];
        save(&a, &dirs[0]);
        save(&b, &dirs[1]);
        (a, b, dirs)
    }

    #[test]
    fn an_ensemble_sets_every_network_of_every_image_side_by_side() {
        let tmp = scratch("ensemble");
        let (a, b, dirs) = two_saved_models(&tmp);
        let out = tmp.path().join("both");
        let card = write_ensemble(&dirs, &out, "both").unwrap();
        assert_eq!(card.name, "both");
        assert_eq!(card.members.len(), 1);
        assert_eq!(card.members[0].weights, "weights-1.safetensors");
        assert_eq!(card.members[0].training.seed, 8);
        assert_eq!(ModelCard::read(&out).unwrap(), card);
        let mut both = LoadedModel::load(&out).unwrap();

        let (points, image, params) = ten_tracks(5, 11);
        let fit = both.fit(&points, image, &params).unwrap();
        let (za, zb) = (
            a.fit(&points, image, &params).unwrap().embeddings,
            b.fit(&points, image, &params).unwrap().embeddings,
        );
        assert_eq!(fit.embed_dim, 6);
        let s = 1.0 / 2f32.sqrt();
        for i in 0..points.len() {
            for j in 0..3 {
                assert!((fit.embeddings[i * 6 + j] - za[i * 3 + j] * s).abs() < 1e-6);
                assert!((fit.embeddings[i * 6 + 3 + j] - zb[i * 3 + j] * s).abs() < 1e-6);
            }
        }
        // Two different seeds: the member is a real second network.
        assert!((0..3).any(|j| (za[j] - zb[j]).abs() > 1e-4));
        // With a symmetry: 2 networks x 2 images, networks varying fastest.
        both.card.test_symmetries = vec![Symmetry::Mirror];
        let fit = both.fit(&points, image, &params).unwrap();
        assert_eq!(fit.embed_dim, 12);
        let mirrored = Symmetry::Mirror.apply_points(&points, image).unwrap();
        let zbm = b.fit(&mirrored, image, &params).unwrap().embeddings;
        // Point 0's last block: the member's embedding of the mirrored input.
        for (got, want) in fit.embeddings[9..12].iter().zip(&zbm[..3]) {
            assert!((got - want / 2.0).abs() < 1e-6);
        }
        // A freshly trained network cannot claim members it does not have.
        let err = LoadedModel::from_parts(card, a.net.clone(), cpu_device()).unwrap_err();
        assert!(err.to_string().contains("ensemble of 2 networks"), "{err}");
    }

    #[test]
    fn ensembles_refuse_mismatched_or_single_models() {
        let tmp = scratch("ensemble-refusals");
        let a = tiny(vec![]);
        let mut wider = tiny(vec![]);
        wider.card.architecture.width = 16;
        let dirs = [tmp.path().join("a"), tmp.path().join("w")];
        save(&a, &dirs[0]);
        wider.card.write(&dirs[1]).unwrap();
        let out = tmp.path().join("e");
        let err = write_ensemble(&dirs[..1], &out, "e").unwrap_err();
        assert!(err.to_string().contains("at least two"), "{err}");
        let err = write_ensemble(&dirs, &out, "e").unwrap_err();
        assert!(err.to_string().contains("architecture"), "{err}");
        let err = write_ensemble(&[dirs[0].clone(), dirs[0].clone()], &dirs[0], "e").unwrap_err();
        assert!(
            err.to_string().contains("both a member and the output"),
            "{err}"
        );
        assert!(!out.exists());
        // Cards refuse member weights that are not plain, distinct file names.
        let mut card = a.card.clone();
        let member = |w: &str| Member {
            weights: w.into(),
            loss: Loss::L2,
            training: card.training.clone(),
        };
        for bad in [
            "../x.safetensors",
            "weights.safetensors",
            "w.bin",
            "sub/w.safetensors",
        ] {
            card.members = vec![member(bad)];
            assert!(card.validate().is_err(), "{bad}");
        }
        card.members = vec![member("w1.safetensors"), member("w1.safetensors")];
        assert!(card.validate().unwrap_err().contains("named twice"));
        card.members = vec![member("w1.safetensors"), member("w2.safetensors")];
        card.validate().unwrap();
    }

    #[test]
    fn ensembles_replace_a_model_whole_and_refuse_other_outputs() {
        let tmp = scratch("ensemble-out");
        let (_, _, dirs) = two_saved_models(&tmp);
        let out = tmp.path().join("e");
        let refuse = |dirs: &[PathBuf], out: &Path| write_ensemble(dirs, out, "e").unwrap_err();

        // The same model twice, even by another path, is not an ensemble.
        let again = tmp.path().join(".").join("a");
        let err = refuse(&[dirs[0].clone(), again], &out);
        assert!(err.to_string().contains("named twice"), "{err}");
        // Networks that would be served with different test symmetries.
        let mut mirrored = tiny_seeded(vec![], 9);
        mirrored.card.test_symmetries = vec![Symmetry::Mirror];
        save(&mirrored, &tmp.path().join("m"));
        let err = refuse(&[dirs[0].clone(), tmp.path().join("m")], &out);
        assert!(err.to_string().contains("test symmetries"), "{err}");
        // A directory that holds something other than a model is never replaced.
        let other = tmp.path().join("other");
        std::fs::create_dir_all(&other).unwrap();
        std::fs::write(other.join("notes.txt"), b"keep me").unwrap();
        let err = refuse(&dirs, &other);
        assert!(err.to_string().contains("not a model directory"), "{err}");
        assert!(other.join("notes.txt").is_file());
        assert!(!out.exists());

        // A model directory is replaced whole: the old card's stale member file goes with it.
        write_ensemble(&dirs, &out, "e").unwrap();
        std::fs::write(out.join("weights-9.safetensors"), b"stale").unwrap();
        let card = write_ensemble(&[dirs[1].clone(), dirs[0].clone()], &out, "e").unwrap();
        assert_eq!(card.training.seed, 8);
        assert!(!out.join("weights-9.safetensors").exists());
        assert!(!tmp.path().join("e.partial").exists() && !tmp.path().join("e.old").exists());
        LoadedModel::load(&out).unwrap();
        // An ensemble is not a member of another.
        let err = refuse(&[out.clone(), dirs[0].clone()], &tmp.path().join("f"));
        assert!(err.to_string().contains("itself an ensemble"), "{err}");

        // A member whose weights do not load leaves the existing model untouched.
        let before = std::fs::read(out.join(WEIGHTS_FILE)).unwrap();
        std::fs::write(dirs[1].join(WEIGHTS_FILE), b"truncated").unwrap();
        refuse(&dirs, &out);
        assert_eq!(std::fs::read(out.join(WEIGHTS_FILE)).unwrap(), before);
        assert!(!tmp.path().join("e.partial").exists());
    }

    #[cfg(unix)]
    #[test]
    fn ensemble_weights_do_not_keep_private_source_permissions() {
        use std::os::unix::fs::PermissionsExt;
        let tmp = scratch("ensemble-mode");
        let dirs = [tmp.path().join("a"), tmp.path().join("b")];
        save(&tiny_seeded(vec![], 7), &dirs[0]);
        save(&tiny_seeded(vec![], 8), &dirs[1]);
        for d in &dirs {
            let w = d.join(WEIGHTS_FILE);
            std::fs::set_permissions(&w, std::fs::Permissions::from_mode(0o600)).unwrap();
        }
        let out = tmp.path().join("e");
        let card = write_ensemble(&dirs, &out, "e").unwrap();
        // The mode of a new file under this process's umask (0644 under the usual 022).
        let probe = tmp.path().join("probe");
        std::fs::write(&probe, b"").unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode();
        for file in card.weight_files() {
            assert_eq!(
                mode(&out.join(file)),
                mode(&probe),
                "{file}, not the source's 600"
            );
        }
    }

    #[test]
    fn the_weights_digest_is_the_sha256_of_the_weight_files_in_card_order() {
        let tmp = scratch("digest");
        let mut card = tiny_seeded(vec![], 7).card;
        std::fs::create_dir_all(tmp.path()).unwrap();
        std::fs::write(tmp.path().join(WEIGHTS_FILE), b"abc").unwrap();
        // `printf abc | sha256sum`
        assert_eq!(
            weights_sha256(tmp.path(), &card).unwrap(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        std::fs::write(tmp.path().join("weights-1.safetensors"), b"def").unwrap();
        card.members = vec![Member {
            weights: "weights-1.safetensors".into(),
            loss: card.loss,
            training: card.training.clone(),
        }];
        // `printf abcdef | sha256sum`
        assert_eq!(
            weights_sha256(tmp.path(), &card).unwrap(),
            "bef57ec7f53a6d40beb640a780a639c83bc29ac8a9816f1fc6c5c6dcd93c4721"
        );
        std::fs::remove_file(tmp.path().join("weights-1.safetensors")).unwrap();
        assert!(matches!(
            weights_sha256(tmp.path(), &card),
            Err(RegistryError::Io { path, .. }) if path.ends_with("weights-1.safetensors")
        ));
    }

    #[test]
    fn a_loaded_model_reports_its_weights_digest_and_a_model_built_in_process_none() {
        let tmp = scratch("loaded-digest");
        let (a, _, dirs) = two_saved_models(&tmp);
        assert_eq!(a.weights_sha256(), None);
        let loaded = LoadedModel::load(&dirs[0]).unwrap();
        let other = LoadedModel::load(&dirs[1]).unwrap();
        let digest = loaded.weights_sha256().unwrap();
        assert_eq!(digest.len(), 64);
        assert!(
            digest
                .bytes()
                .all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase())
        );
        assert_ne!(Some(digest), other.weights_sha256());
        let both = tmp.path().join("both");
        write_ensemble(&dirs, &both, "both").unwrap();
        let ensemble = LoadedModel::load(&both).unwrap();
        assert_ne!(ensemble.weights_sha256(), Some(digest));
        assert_ne!(ensemble.weights_sha256(), other.weights_sha256());
    }
}
