//! The embedding network: a CNe-style stack of per-point layers with Context Normalization.
//!
//! ```text
//! x [b, n, d] -> Linear(d, w)
//!   -> depth x { u = Linear(w, w) x  [+ mean over the point's graph neighbours j of G x_j]
//!                h = ReLU(BN?(CN(u))); h = ReLU(BN?(CN(Linear(w, w) h))); x = x + h }
//!   -> Linear(w, e) -> L2-normalise each point -> z [b, n, e]
//! ```
//! The bracketed term is the optional graph aggregation (beyond the paper, `graph_neighbors > 0`):
//! a linear `G` of every block, averaged over the point's `graph_neighbors` nearest points in the
//! input (itself included), as in GraphSAGE's mean aggregator. Stacked over the blocks it lets a
//! point see along its curve, hop by hop, where context norm alone only gives it the whole set's
//! statistics. It costs one more multiply per block and a gather.
//! Context Normalization (CN) standardises every channel over the points of one set (no learned
//! scale or shift). Linears inside the blocks carry no bias: CN's mean subtraction would cancel it.
//! The optional BatchNorm follows CNe; note that after CN every channel already has zero mean and
//! unit variance over each set, so BatchNorm adds little beyond its learned scale and shift.

pub mod fused;
pub mod gemm;

use std::path::Path;

use burn::module::Module;
use burn::nn::{BatchNorm, BatchNormConfig, Linear, LinearConfig};
use burn::prelude::*;
use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::activation::relu;
use serde::{Deserialize, Serialize};

use crate::data::features::knn_graph;
pub use fused::FusedNet;

/// Architecture of the embedding network; stored in every model card.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelConfig {
    /// Values per input point (2 for points2d, 4 for correspondences, 2F for trajectories).
    pub input_dim: usize,
    /// Channels of every hidden layer.
    pub width: usize,
    /// Number of residual blocks.
    pub depth: usize,
    /// Output embedding dimension E.
    pub embed_dim: usize,
    /// BatchNorm after each Context Normalization (CNe) or not (the authors' later code).
    pub batch_norm: bool,
    /// Epsilon added to the variance in Context Normalization.
    pub cn_epsilon: f64,
    /// Offsets to this many nearest neighbours appended to every point (0 = the paper's input;
    /// see [`crate::data::features`]).
    #[serde(default)]
    pub neighbors: usize,
    /// Graph aggregation over this many nearest points (itself included) in every block; 0 = off
    /// (the paper's network). See the module docs.
    #[serde(default)]
    pub graph_neighbors: usize,
}

/// Why a model could not be built, saved or loaded.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("invalid model config: {0}")]
    Config(String),
    #[error("{path}: cannot write weights: {reason}")]
    Save { path: String, reason: String },
    #[error("{path}: weights do not match the card's architecture: {reason}")]
    Load { path: String, reason: String },
}

/// Why a saved safetensors file's header could not be rewritten in sorted order. Its text is the
/// `reason` of [`ModelError::Save`].
#[derive(Debug, thiserror::Error)]
enum HeaderError {
    #[error("{0}")]
    Io(std::io::Error),
    #[error("not a safetensors file: bad header length")]
    Length,
    #[error("header: {0}")]
    Parse(serde_json::Error),
    #[error("{0}")]
    Write(serde_json::Error),
}

impl ModelConfig {
    pub fn new(input_dim: usize) -> Self {
        Self {
            input_dim,
            width: 128,
            depth: 12,
            embed_dim: 6,
            batch_norm: false,
            cn_epsilon: 1e-3,
            neighbors: 0,
            graph_neighbors: 0,
        }
    }

    /// Values per point the first layer takes: `input_dim * (1 + neighbors)`.
    pub fn feature_dim(&self) -> usize {
        self.input_dim * (1 + self.neighbors)
    }

    pub fn validate(&self) -> Result<(), ModelError> {
        let bad = |m: &str| Err(ModelError::Config(m.to_string()));
        if self.input_dim == 0 || self.input_dim > 4096 {
            return bad("input_dim must be in 1..=4096");
        }
        if self.width == 0 || self.width > 4096 {
            return bad("width must be in 1..=4096");
        }
        if self.neighbors > 64 {
            return bad("neighbors must be at most 64");
        }
        if self.graph_neighbors > 64 {
            return bad("graph_neighbors must be at most 64");
        }
        if self.depth > 256 {
            return bad("depth must be at most 256");
        }
        if self.embed_dim < 2 || self.embed_dim > 256 {
            return bad("embed_dim must be in 2..=256");
        }
        if !(self.cn_epsilon.is_finite() && self.cn_epsilon > 0.0) {
            return bad("cn_epsilon must be finite and positive");
        }
        Ok(())
    }

    /// A freshly initialised network drawn from `seed`. burn's random state is global to the
    /// backend, so seeding and drawing hold one process-wide lock: two inits at once (tests, or
    /// trainings in one process) cannot interleave their draws, and a seed always gives the
    /// same weights.
    pub fn init_seeded(&self, device: &Device, seed: u64) -> Result<EmbeddingNet, ModelError> {
        static RNG: std::sync::Mutex<()> = std::sync::Mutex::new(());
        let _guard = RNG.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        device.seed(seed);
        let net = self.init(device)?;
        // burn draws a parameter's values on its first access: draw them all now, in field
        // order, while the lock is held.
        net.visit(&mut Materialize);
        Ok(net)
    }

    /// A freshly initialised network on `device`, drawn from burn's current random state (see
    /// [`ModelConfig::init_seeded`] for reproducible weights).
    pub fn init(&self, device: &Device) -> Result<EmbeddingNet, ModelError> {
        self.validate()?;
        let w = self.width;
        let bn = |on: bool| on.then(|| BatchNormConfig::new(w).init(device));
        let blocks = (0..self.depth)
            .map(|_| Block {
                l1: LinearConfig::new(w, w).with_bias(false).init(device),
                agg: (self.graph_neighbors > 0)
                    .then(|| LinearConfig::new(w, w).with_bias(false).init(device)),
                bn1: bn(self.batch_norm),
                l2: LinearConfig::new(w, w).with_bias(false).init(device),
                bn2: bn(self.batch_norm),
            })
            .collect();
        Ok(EmbeddingNet {
            input: LinearConfig::new(self.feature_dim(), w).init(device),
            blocks,
            output: LinearConfig::new(w, self.embed_dim).init(device),
            cn_epsilon: self.cn_epsilon,
            coord_dim: self.input_dim,
            graph_neighbors: self.graph_neighbors,
        })
    }

    /// Multiply-adds per point of one forward pass (for FLOP accounting in benchmarks).
    pub fn macs_per_point(&self) -> usize {
        self.feature_dim() * self.width
            + (2 + usize::from(self.graph_neighbors > 0)) * self.depth * self.width * self.width
            + self.width * self.embed_dim
    }
}

/// Forces burn's lazy parameter initialisation (the random draws happen on first access).
struct Materialize;

impl burn::module::ModuleVisitor for Materialize {
    fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
        let _ = param.val();
    }
}

/// One residual block: `[Linear (+ graph mean), CN, BN?, ReLU] x 2 + skip`.
#[derive(Module, Debug)]
pub struct Block {
    pub l1: Linear,
    /// The graph aggregation's linear map `G` (graph models only).
    pub agg: Option<Linear>,
    pub bn1: Option<BatchNorm>,
    pub l2: Linear,
    pub bn2: Option<BatchNorm>,
}

/// The embedding network.
#[derive(Module, Debug)]
pub struct EmbeddingNet {
    pub input: Linear,
    pub blocks: Vec<Block>,
    pub output: Linear,
    pub cn_epsilon: f64,
    /// Leading values of each input row that are the point's coordinates (the graph is built on
    /// them).
    pub coord_dim: usize,
    /// Points per neighbourhood of the graph aggregation; 0 = none.
    pub graph_neighbors: usize,
}

/// Context Normalization: zero mean, unit variance per channel over the points of each set.
/// x: [b, n, c] -> [b, n, c]
pub fn context_norm(x: Tensor<3>, epsilon: f64) -> Tensor<3> {
    let (var, mean) = x.clone().var_mean_bias(1);
    (x - mean) / (var + epsilon).sqrt()
}

/// BatchNorm over every point of every set: x: [b, n, c] -> [b, n, c]
fn batch_norm(bn: &BatchNorm, x: Tensor<3>) -> Tensor<3> {
    let [b, n, c] = x.dims();
    bn.forward(x.reshape([b * n, c])).reshape([b, n, c])
}

/// L2-normalises every point: z: [b, n, e] -> [b, n, e]
pub fn l2_normalize(z: Tensor<3>) -> Tensor<3> {
    let norm = z.clone().square().sum_dim(2).sqrt().clamp_min(1e-12);
    z / norm
}

/// The neighbourhoods of a batch of sets: `others[t]` holds, for each of the b * n rows, the row
/// of its (t + 1)-th nearest point (the point itself is the 0-th and is implied).
#[derive(Debug, Clone)]
pub struct Graph {
    pub others: Vec<Tensor<1, Int>>,
}

/// The mean over each point's neighbourhood (itself and `graph.others`) of `g`'s rows.
/// g: [b, n, w] -> [b, n, w]
pub fn neighbourhood_mean(g: Tensor<3>, graph: &Graph) -> Tensor<3> {
    let [b, n, w] = g.dims();
    let rows = g.reshape([b * n, w]);
    let k = graph.others.len() + 1;
    graph
        .others
        .iter()
        .fold(rows.clone(), |m, idx| {
            m + rows.clone().select(0, idx.clone())
        })
        .div_scalar(k as f64)
        .reshape([b, n, w])
}

impl Block {
    /// x: [b, n, w] -> [b, n, w]; `graph` (see [`Graph`]) is required when the block aggregates.
    fn forward(&self, x: Tensor<3>, eps: f64, graph: Option<&Graph>) -> Tensor<3> {
        let norm_relu = |u: Tensor<3>, bn: &Option<BatchNorm>| {
            let mut h = context_norm(u, eps);
            if let Some(bn) = bn {
                h = batch_norm(bn, h);
            }
            relu(h)
        };
        let mut u = self.l1.forward(x.clone());
        if let Some(agg) = &self.agg {
            let graph = graph.expect("EmbeddingNet::forward passes the graph to graph blocks");
            u = u + neighbourhood_mean(agg.forward(x.clone()), graph);
        }
        let h = norm_relu(u, &self.bn1);
        let h = norm_relu(self.l2.forward(h), &self.bn2);
        x + h
    }
}

impl EmbeddingNet {
    /// points: [b, n, d] -> embeddings [b, n, e], each row of unit length. The graph of graph
    /// models is built here from each set's coordinates (the first `coord_dim` values per row).
    pub fn forward(&self, points: Tensor<3>) -> Tensor<3> {
        let graph = (self.graph_neighbors > 0).then(|| self.graph_of(&points));
        let mut x = self.input.forward(points);
        for block in &self.blocks {
            x = block.forward(x, self.cn_epsilon, graph.as_ref());
        }
        l2_normalize(self.output.forward(x))
    }

    /// The neighbourhood graph of every set of a batch (see [`knn_graph`]), as indices into
    /// its b * n rows. points: [b, n, d] -> graph_neighbors - 1 index tensors of [b * n]
    fn graph_of(&self, points: &Tensor<3>) -> Graph {
        let [b, n, d] = points.dims();
        let k = self.graph_neighbors;
        let values: Vec<f32> = points
            .clone()
            .into_data()
            .convert::<f32>()
            .try_to_vec::<f32>()
            .expect("f32 points");
        let mut ranks: Vec<Vec<i64>> = vec![Vec::with_capacity(b * n); k.saturating_sub(1)];
        for (s, set) in values.chunks_exact((n * d).max(1)).enumerate() {
            let g = knn_graph(set, d, self.coord_dim.min(d), k);
            for row in g.chunks_exact(k) {
                for (rank, &j) in ranks.iter_mut().zip(&row[1..]) {
                    rank.push((s * n + j) as i64);
                }
            }
        }
        let device = points.device();
        let others = ranks
            .into_iter()
            .map(|r| {
                let len = r.len();
                Tensor::<1, Int>::from_data(TensorData::new(r, [len]), &device)
            })
            .collect();
        Graph { others }
    }

    /// Embeds one normalised point set given row-major `[n, d]`; returns row-major `[n, e]`.
    pub fn embed(&self, points: &[f32], dim: usize, device: &Device) -> Vec<f32> {
        let n = points.len() / dim;
        let x = Tensor::<3>::from_data(TensorData::new(points.to_vec(), [1, n, dim]), device);
        self.forward(x)
            .into_data()
            .try_to_vec::<f32>()
            .expect("f32 embeddings")
    }

    /// Writes the weights as safetensors.
    pub fn save(&self, path: &Path) -> Result<(), ModelError> {
        let err = |reason: String| ModelError::Save {
            path: path.display().to_string(),
            reason,
        };
        let mut store = SafetensorsStore::from_file(path).overwrite(true);
        self.save_into(&mut store).map_err(|e| err(e.to_string()))?;
        sort_safetensors_header(path).map_err(|e| err(e.to_string()))
    }

    /// Loads weights written by [`EmbeddingNet::save`] into a network built from `config`.
    /// Every tensor must be present, of the right shape, and none may be left over.
    pub fn load(config: &ModelConfig, path: &Path, device: &Device) -> Result<Self, ModelError> {
        let err = |reason: String| ModelError::Load {
            path: path.display().to_string(),
            reason,
        };
        if !path.is_file() {
            return Err(err("file not found".into()));
        }
        let mut net = config.init(device)?;
        let mut store = SafetensorsStore::from_file(path);
        let result = net.load_from(&mut store).map_err(|e| err(e.to_string()))?;
        if !result.errors.is_empty() || !result.missing.is_empty() || !result.unused.is_empty() {
            let missing: Vec<&str> = result.missing.iter().map(|m| m.0.as_str()).collect();
            return Err(err(format!(
                "missing tensors {missing:?}, unexpected tensors {:?}, errors {:?}",
                result.unused, result.errors
            )));
        }
        Ok(net)
    }
}

/// The CPU device of the backend selected by Cargo features (`flex` unless only `ndarray` is on).
pub fn cpu_device() -> Device {
    #[cfg(feature = "flex")]
    {
        Device::flex()
    }
    #[cfg(all(feature = "ndarray", not(feature = "flex")))]
    #[allow(deprecated)]
    {
        Device::ndarray()
    }
}

/// Rewrites a safetensors file's JSON header with its keys sorted. burn fills the header's
/// `__metadata__` from a hash map, so its key order, and with it the file's bytes and
/// `weights_sha256`, changed from save to save of the same weights; sorted, the same weights always
/// give the same file. The tensor data and their offsets (relative to the data) are unchanged.
fn sort_safetensors_header(path: &Path) -> Result<(), HeaderError> {
    let bytes = std::fs::read(path).map_err(HeaderError::Io)?;
    let len = bytes
        .get(..8)
        .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")) as usize)
        .filter(|&n| 8 + n <= bytes.len())
        .ok_or(HeaderError::Length)?;
    let header: std::collections::BTreeMap<String, serde_json::Value> =
        serde_json::from_slice(&bytes[8..8 + len]).map_err(HeaderError::Parse)?;
    let sorted: std::collections::BTreeMap<&String, serde_json::Value> = header
        .iter()
        .map(|(k, v)| match v.as_object() {
            // Nested objects (the metadata, each tensor's entry) sorted too.
            Some(o) => {
                let inner: std::collections::BTreeMap<_, _> = o.iter().collect();
                (k, serde_json::json!(inner))
            }
            None => (k, v.clone()),
        })
        .collect();
    let mut text = serde_json::to_string(&sorted).map_err(HeaderError::Write)?;
    // The data starts 8-aligned, as the format asks: pad the header with spaces.
    while text.len() % 8 != 0 {
        text.push(' ');
    }
    let mut out = Vec::with_capacity(8 + text.len() + bytes.len() - 8 - len);
    out.extend_from_slice(&(text.len() as u64).to_le_bytes());
    out.extend_from_slice(text.as_bytes());
    out.extend_from_slice(&bytes[8 + len..]);
    std::fs::write(path, out).map_err(HeaderError::Io)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny() -> ModelConfig {
        ModelConfig {
            input_dim: 4,
            width: 16,
            depth: 2,
            embed_dim: 3,
            batch_norm: false,
            cn_epsilon: 1e-3,
            neighbors: 0,
            graph_neighbors: 0,
        }
    }

    fn points(n: usize, d: usize) -> Vec<f32> {
        (0..n * d)
            .map(|i| ((i * 7919 % 101) as f32 / 50.0) - 1.0)
            .collect()
    }

    #[test]
    fn context_norm_standardises_each_set_and_channel() {
        let device = cpu_device();
        let x = Tensor::<3>::from_data(
            TensorData::new(
                vec![
                    1.0f32, 10.0, 3.0, 20.0, 5.0, 60.0, 2.0, 2.0, 2.0, 4.0, 2.0, 6.0,
                ],
                [2, 3, 2],
            ),
            &device,
        );
        let y: Vec<f32> = context_norm(x, 1e-9).into_data().try_to_vec().unwrap();
        // Set 0, channel 0: 1, 3, 5 -> mean 3, var 8/3.
        let s = (8.0f32 / 3.0).sqrt();
        assert!(
            (y[0] + 2.0 / s).abs() < 1e-4 && y[2].abs() < 1e-4 && (y[4] - 2.0 / s).abs() < 1e-4
        );
        // Set 1, channel 0 is constant: normalised to 0 (epsilon keeps it finite).
        assert!(y[6].abs() < 1e-3 && y[8].abs() < 1e-3 && y[10].abs() < 1e-3);
        for set in 0..2 {
            for c in 0..2 {
                let mean: f32 = (0..3).map(|i| y[set * 6 + i * 2 + c]).sum::<f32>() / 3.0;
                assert!(mean.abs() < 1e-4);
            }
        }
    }

    #[test]
    fn embeddings_are_unit_length_and_permutation_equivariant() {
        let device = cpu_device();
        for graph_neighbors in [0, 4] {
            let net = ModelConfig {
                graph_neighbors,
                ..tiny()
            }
            .init_seeded(&device, 3)
            .unwrap();
            let n = 9;
            let p = points(n, 4);
            let z = net.embed(&p, 4, &device);
            assert_eq!(z.len(), n * 3);
            for row in z.chunks(3) {
                let len: f32 = row.iter().map(|v| v * v).sum::<f32>().sqrt();
                assert!((len - 1.0).abs() < 1e-5);
            }
            // Reverse the points: the embeddings reverse with them.
            let rev: Vec<f32> = p.chunks(4).rev().flatten().copied().collect();
            let zr = net.embed(&rev, 4, &device);
            for (i, row) in zr.chunks(3).enumerate() {
                let orig = &z[(n - 1 - i) * 3..(n - i) * 3];
                for (a, b) in row.iter().zip(orig) {
                    assert!((a - b).abs() < 1e-5, "graph {graph_neighbors}");
                }
            }
        }
    }

    #[test]
    fn graph_aggregation_by_hand() {
        // Two sets of 3 rows, 2 channels; neighbourhoods of 2 given as indices into the 6 rows.
        let device = cpu_device();
        let g = Tensor::<3>::from_data(
            TensorData::new(
                vec![
                    1.0f32, -1.0, 5.0, 0.0, 2.0, 9.0, 0.0, 0.0, -3.0, 4.0, 1.0, 1.0,
                ],
                [2, 3, 2],
            ),
            &device,
        );
        let graph = Graph {
            others: vec![Tensor::<1, Int>::from_data(
                TensorData::new(vec![1i64, 2, 0, 4, 5, 3], [6]),
                &device,
            )],
        };
        let y: Vec<f32> = neighbourhood_mean(g, &graph)
            .into_data()
            .try_to_vec()
            .unwrap();
        assert_eq!(
            y,
            vec![
                3.0, -0.5, 3.5, 4.5, 1.5, 4.0, -1.5, 2.0, -1.0, 2.5, 0.5, 0.5
            ]
        );
    }

    #[test]
    fn safetensors_round_trip_is_bit_identical() {
        let device = cpu_device();
        for bn in [false, true] {
            let cfg = ModelConfig {
                batch_norm: bn,
                ..tiny()
            };
            let net = cfg.init_seeded(&device, 5).unwrap();
            let dir = tempfile::Builder::new()
                .prefix("multifit-model-test-")
                .tempdir()
                .unwrap();
            let path = dir.path().join("weights.safetensors");
            net.save(&path).unwrap();
            let back = EmbeddingNet::load(&cfg, &path, &device).unwrap();
            let p = points(11, 4);
            assert_eq!(net.embed(&p, 4, &device), back.embed(&p, 4, &device));
            // The same weights give the same file, save after save (burn's header metadata comes
            // from a hash map; 8 saves would all agree by chance with probability 6^-7).
            let first = std::fs::read(&path).unwrap();
            for _ in 0..7 {
                back.save(&path).unwrap();
                assert!(
                    std::fs::read(&path).unwrap() == first,
                    "a save changed the file"
                );
            }
            let n = u64::from_le_bytes(first[..8].try_into().unwrap()) as usize;
            let header = std::str::from_utf8(&first[8..8 + n]).unwrap();
            assert!(
                header.starts_with(r#"{"__metadata__":{"format":"safetensors","producer":"burn""#),
                "{header}"
            );
            assert_eq!((8 + n) % 8, 0, "data 8-aligned");
            // A card that disagrees with the weights is refused.
            let wrong = ModelConfig {
                width: 8,
                ..cfg.clone()
            };
            assert!(matches!(
                EmbeddingNet::load(&wrong, &path, &device),
                Err(ModelError::Load { .. })
            ));
            let deeper = ModelConfig {
                depth: 3,
                ..cfg.clone()
            };
            assert!(matches!(
                EmbeddingNet::load(&deeper, &path, &device),
                Err(ModelError::Load { .. })
            ));
        }
    }

    #[test]
    fn rejects_bad_configs() {
        assert!(
            ModelConfig {
                embed_dim: 1,
                ..tiny()
            }
            .validate()
            .is_err()
        );
        assert!(ModelConfig { width: 0, ..tiny() }.validate().is_err());
        assert!(
            ModelConfig {
                cn_epsilon: 0.0,
                ..tiny()
            }
            .validate()
            .is_err()
        );
    }
}
