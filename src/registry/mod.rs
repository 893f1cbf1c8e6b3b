//! Model directories: `models/<name>/` holds a card (`model.json`, [`card`]) and the weights of
//! one network or more (`weights.safetensors`, `weights-<i>.safetensors`). [`LoadedModel`] is a
//! directory read, checked and ready to fit; [`write_ensemble`] (trainer only) joins several
//! trained networks into one model directory.

mod card;
mod ensemble;
mod load;

use std::path::PathBuf;

use crate::model::ModelError;

pub use card::{
    CARD_FILE, CardError, Member, MetricRecord, ModelCard, Observed, SparseNetwork, TrainingInfo,
    ValidatedRange, WEIGHTS_FILE, card_for,
};
pub use ensemble::{SPARSE_WEIGHTS_FILE, write_ensemble, write_sparse};
pub use load::{LoadedModel, load_all};

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
    #[error("models {first:?} and {second:?} are both the default for {kind}")]
    TwoDefaults {
        kind: crate::data::Kind,
        first: String,
        second: String,
    },
    #[error("cannot make an ensemble: {0}")]
    Ensemble(String),
}

#[cfg(test)]
pub(crate) mod tests {
    use std::path::{Path, PathBuf};

    use tempfile::TempDir;

    use super::*;
    use crate::data::{Kind, Symmetry};
    use crate::loss::Loss;
    use crate::model::{ModelConfig, cpu_device};

    pub(crate) fn tiny(symmetries: Vec<Symmetry>) -> LoadedModel {
        tiny_seeded(symmetries, 7)
    }

    /// A one-block network on 2-frame tracks (D = 4), embedding in 3 dimensions.
    pub(crate) fn tiny_seeded(symmetries: Vec<Symmetry>, seed: u64) -> LoadedModel {
        let mut model = tiny_model("tiny", Kind::Trajectories, 4, seed);
        model.card.test_symmetries = symmetries;
        model.card.validate().unwrap();
        model
    }

    /// A one-block network named `name` for `kind` on rows of `input_dim` values, embedding in
    /// 3 dimensions, initialised from `seed`.
    pub(crate) fn tiny_model(name: &str, kind: Kind, input_dim: usize, seed: u64) -> LoadedModel {
        tiny_reading(name, kind, input_dim, seed, 0)
    }

    /// [`tiny_model`] reading each point's `neighbors` nearest others too.
    pub(crate) fn tiny_reading(
        name: &str,
        kind: Kind,
        input_dim: usize,
        seed: u64,
        neighbors: usize,
    ) -> LoadedModel {
        let model = ModelConfig {
            input_dim,
            width: 8,
            depth: 1,
            embed_dim: 3,
            batch_norm: false,
            cn_epsilon: 1e-3,
            neighbors,
            graph_neighbors: 0,
        };
        let device = cpu_device();
        let net = model.init_seeded(&device, seed).unwrap();
        let info = TrainingInfo {
            data: String::new(),
            command: String::new(),
            epochs: 1,
            learning_rate: 1e-3,
            seed,
            seconds: 0.0,
            machine: String::new(),
        };
        let card = card_for(name, kind, &model, Loss::L2, 4, info);
        LoadedModel::from_parts(card, net, device).unwrap()
    }

    /// A fresh directory (`multifit-<tag>-XXXXXX` in the system temp dir), removed when dropped.
    pub(crate) fn scratch(tag: &str) -> TempDir {
        tempfile::Builder::new()
            .prefix(&format!("multifit-{tag}-"))
            .tempdir()
            .unwrap()
    }

    pub(crate) fn save(model: &LoadedModel, dir: &Path) {
        model.card.write(dir).unwrap();
        model.net.save(&dir.join(WEIGHTS_FILE)).unwrap();
    }

    /// Two tiny single-network models of different seeds (7, 8), saved in `<tmp>/a` and `<tmp>/b`.
    pub(crate) fn two_saved_models(tmp: &TempDir) -> (LoadedModel, LoadedModel, [PathBuf; 2]) {
        let (a, b) = (tiny_seeded(vec![], 7), tiny_seeded(vec![], 8));
        let dirs = [tmp.path().join("a"), tmp.path().join("b")];
        save(&a, &dirs[0]);
        save(&b, &dirs[1]);
        (a, b, dirs)
    }
}
