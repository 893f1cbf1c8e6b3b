//! A model directory read and checked, its networks ready to embed on a pool of threads.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::prelude::Device;

use super::{ModelCard, RegistryError, WEIGHTS_FILE};
use crate::model::{EmbeddingNet, FusedNet, ModelError, cpu_device};
use crate::threads::Threads;

/// A model ready to fit point sets. Embeddings come from the fused serving forward
/// ([`FusedNet`]); the burn network is kept for training-side use and for cross-checks.
#[derive(Debug)]
pub struct LoadedModel {
    pub card: ModelCard,
    pub net: EmbeddingNet,
    fused: FusedNet,
    /// The fused forwards of the card's further networks, in the card's order.
    members: Vec<FusedNet>,
    /// The fused forward of the card's network for sparse sets.
    sparse: Option<FusedNet>,
    /// Threads one fit may use.
    threads: Threads,
    device: Device,
    /// Hex SHA-256 of the weight files, concatenated in [`ModelCard::weight_files`] order;
    /// `None` for a network that was never read from a file ([`LoadedModel::from_parts`]).
    weights_sha256: Option<String>,
}

impl LoadedModel {
    /// Loads and cross-checks `dir/model.json` and `dir/weights.safetensors`.
    pub fn load(dir: &Path) -> Result<Self, RegistryError> {
        let card = ModelCard::read(dir)?;
        let device = cpu_device();
        let net = EmbeddingNet::load(&card.architecture, &dir.join(WEIGHTS_FILE), &device)?;
        let fused = |file: &str| {
            let net = EmbeddingNet::load(&card.architecture, &dir.join(file), &device)?;
            FusedNet::from_net(&net)
        };
        let members = card
            .members
            .iter()
            .map(|m| fused(&m.weights))
            .collect::<Result<Vec<_>, _>>()?;
        let sparse = card
            .sparse
            .as_ref()
            .map(|s| fused(&s.weights))
            .transpose()?;
        let weights_sha256 = weights_sha256(dir, &card)?;
        let mut model = Self::assemble(card, net, device)?;
        model.members = members;
        model.sparse = sparse;
        model.weights_sha256 = Some(weights_sha256);
        Ok(model)
    }

    /// Hex SHA-256 of the weight files the model was loaded from, concatenated in the card's
    /// order (`cat weights.safetensors weights-1.safetensors ... weights-sparse.safetensors |
    /// sha256sum`): the identity of exactly these weights, which the card's `version` is not.
    /// `None` for a network built in this process ([`LoadedModel::from_parts`]). The files are
    /// read again for the digest after the networks are built: replace a model directory while
    /// no server is loading it.
    pub fn weights_sha256(&self) -> Option<&str> {
        self.weights_sha256.as_deref()
    }

    /// Wraps a freshly trained network. Fits run on the calling thread until
    /// [`LoadedModel::with_threads`] says otherwise.
    /// A card with `members` or a `sparse` network needs their weights: load it with
    /// [`LoadedModel::load`].
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
        if card.sparse.is_some() {
            return Err(ModelError::Config(format!(
                "model {} has a network for sparse sets: load it from its directory",
                card.name
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
            sparse: None,
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

    /// Embeddings of network input by the fused forward of every network that reads it: the
    /// card's own first, then its members'; for a `sparse` set the card's sparse network
    /// alone, where it has one: features `[n, feature_dim]` -> one `[n, e]` each.
    pub fn embed_all(&self, features: &[f32], sparse: bool) -> Vec<Vec<f32>> {
        if let (true, Some(net)) = (sparse, &self.sparse) {
            return vec![net.forward(features, &self.threads)];
        }
        std::iter::once(&self.fused)
            .chain(&self.members)
            .map(|net| net.forward(features, &self.threads))
            .collect()
    }

    /// Embeddings of network input by the fused forward of the card's own network (not its
    /// members'): `[n, feature_dim]` -> `[n, e]`.
    pub fn embed(&self, features: &[f32]) -> Vec<f32> {
        self.fused.forward(features, &self.threads)
    }

    /// The pool fits run on.
    pub fn pool(&self) -> &Threads {
        &self.threads
    }
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
    let defaults: Vec<&ModelCard> = models
        .values()
        .map(|m| &m.card)
        .filter(|c| c.default)
        .collect();
    for (i, first) in defaults.iter().enumerate() {
        if let Some(second) = defaults[i + 1..].iter().find(|c| c.kind == first.kind) {
            return Err(RegistryError::TwoDefaults {
                kind: first.kind,
                first: first.name.clone(),
                second: second.name.clone(),
            });
        }
    }
    Ok(models)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::Kind;
    use crate::registry::tests::{save, scratch, tiny_model, tiny_seeded, two_saved_models};
    use crate::registry::{Member, write_ensemble};

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
    fn two_defaults_of_one_kind_are_refused_and_one_per_kind_is_served() {
        let tmp = scratch("defaults");
        let names = ["a", "b", "c"];
        let save_all = |defaults: [bool; 3], kinds: [Kind; 3]| {
            for (i, name) in names.iter().enumerate() {
                let input_dim = if kinds[i] == Kind::Points2d { 2 } else { 4 };
                let mut model = tiny_model(name, kinds[i], input_dim, 7);
                model.card.default = defaults[i];
                save(&model, &tmp.path().join(name));
            }
        };
        let (t, p) = (Kind::Trajectories, Kind::Points2d);
        save_all([true, false, true], [t, t, t]);
        match load_all(tmp.path()) {
            Err(RegistryError::TwoDefaults {
                kind,
                first,
                second,
            }) => assert_eq!((kind, first.as_str(), second.as_str()), (t, "a", "c")),
            other => panic!("expected TwoDefaults, got {:?}", other.map(|m| m.len())),
        }
        save_all([true, false, true], [t, t, p]);
        let models = load_all(tmp.path()).unwrap();
        assert!(models["a"].card.default && models["c"].card.default);
        assert!(!models["b"].card.default);
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
