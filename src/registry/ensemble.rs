//! Models of several networks of one architecture, written as one model directory atomically
//! (staged beside the target, loaded to check it, then renamed into place): ensembles, whose
//! networks all embed every set, and a model with a network for sets sparser than training.

use std::path::{Path, PathBuf};

use super::{
    CARD_FILE, LoadedModel, Member, ModelCard, RegistryError, SparseNetwork, WEIGHTS_FILE,
};

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
    not_an_input(out, dirs)?;
    let mut seen = Vec::new();
    for (dir, card) in dirs.iter().zip(&cards) {
        single_like(card, dir, first, &dirs[0])?;
        let path = dir.canonicalize().ok();
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
    let sources: Vec<PathBuf> = dirs.iter().map(|d| d.join(WEIGHTS_FILE)).collect();
    install(card, &sources, out)
}

/// The weights file of a model's network for sparse sets.
pub const SPARSE_WEIGHTS_FILE: &str = "weights-sparse.safetensors";

/// Writes to `out` the model in `base` with the single network of the model in `sparse` as its
/// network for sets whose spacing exceeds `above` × `base`'s training spacing
/// ([`crate::registry::SparseNetwork`]; one it had is replaced). The two must share kind,
/// input, normalisation, architecture and test symmetries, and `base` must record its training
/// spacing. `base`'s name, defaults and metrics are kept (they measure its own network, which
/// still reads every set within the threshold: re-record any measured on sets beyond it).
/// Written as [`write_ensemble`] writes.
pub fn write_sparse(
    base: &Path,
    sparse: &Path,
    above: f64,
    out: &Path,
) -> Result<ModelCard, RegistryError> {
    let (mut card, extra) = (ModelCard::read(base)?, ModelCard::read(sparse)?);
    single_like(&extra, sparse, &card, base)?;
    not_an_input(out, &[base, sparse])?;
    card.sparse = Some(SparseNetwork {
        weights: SPARSE_WEIGHTS_FILE.into(),
        above,
        loss: extra.loss,
        training: extra.training,
    });
    let mut sources: Vec<PathBuf> = card.weight_files().map(|file| base.join(file)).collect();
    *sources.last_mut().expect("the sparse network's file") = sparse.join(WEIGHTS_FILE);
    install(card, &sources, out)
}

/// Refuses an output directory that is one of the `inputs` (by any path).
fn not_an_input(out: &Path, inputs: &[impl AsRef<Path>]) -> Result<(), RegistryError> {
    let Some(out_path) = out.canonicalize().ok() else {
        return Ok(());
    };
    match inputs
        .iter()
        .find(|dir| dir.as_ref().canonicalize().ok().as_ref() == Some(&out_path))
    {
        Some(dir) => Err(RegistryError::Ensemble(format!(
            "{} is both an input and the output",
            dir.as_ref().display()
        ))),
        None => Ok(()),
    }
}

/// Checks that the model in `dir` (`card`) is a single network that `first` (in `first_dir`)
/// could carry beside its own: same kind, input, normalisation, architecture and symmetries.
fn single_like(
    card: &ModelCard,
    dir: &Path,
    first: &ModelCard,
    first_dir: &Path,
) -> Result<(), RegistryError> {
    let fail = |reason: String| Err(RegistryError::Ensemble(reason));
    if !card.members.is_empty() || card.sparse.is_some() {
        return fail(format!(
            "{} is itself several networks (an ensemble or one with a sparse network)",
            dir.display()
        ));
    }
    let key = |c: &ModelCard| {
        (
            c.kind,
            c.input_dim,
            c.normalization,
            c.architecture.clone(),
            c.test_symmetries.clone(),
        )
    };
    if key(card) != key(first) {
        return fail(format!(
            "{} differs from {} in kind, input, normalisation, architecture or test symmetries",
            dir.display(),
            first_dir.display()
        ));
    }
    Ok(())
}

/// Writes `card` and its weight files, copied from `sources` (one per
/// [`ModelCard::weight_files`], in order), as the model directory `out`: staged beside it,
/// loaded to check it, then renamed into place (`out` must be absent, empty or a model
/// directory).
fn install(card: ModelCard, sources: &[PathBuf], out: &Path) -> Result<ModelCard, RegistryError> {
    let fail = |reason: String| RegistryError::Ensemble(reason);
    assert_eq!(
        sources.len(),
        card.weight_files().count(),
        "install: one source per weight file"
    );
    card.validate().map_err(|e| RegistryError::Card {
        path: out.join(CARD_FILE),
        reason: e.to_string(),
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
    for (from, file) in sources.iter().zip(card.weight_files()) {
        // Read and write rather than copy: a copy would keep the source's permissions.
        let bytes = std::fs::read(from).map_err(io(from))?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::Kind;
    use crate::data::Symmetry;
    use crate::data::density::spacing;
    use crate::loss::Loss;
    use crate::model::cpu_device;
    use crate::pipeline::tests::ten_tracks;
    use crate::registry::tests::{
        save, scratch, tiny, tiny_reading, tiny_seeded, two_saved_models,
    };

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
            err.to_string().contains("both an input and the output"),
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
        assert!(
            card.validate()
                .unwrap_err()
                .to_string()
                .contains("named twice")
        );
        card.members = vec![member("w1.safetensors"), member("w2.safetensors")];
        card.validate().unwrap();
        // The sparse network's file too.
        card.spacing = Some(0.3);
        for (bad, why) in [
            ("w2.safetensors", "named twice"),
            ("../s.safetensors", "plain"),
        ] {
            card.sparse = Some(SparseNetwork {
                weights: bad.into(),
                above: 1.5,
                loss: Loss::L2,
                training: card.training.clone(),
            });
            let err = card.validate().unwrap_err().to_string();
            assert!(err.contains(why), "{bad}: {err}");
        }
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
        assert!(err.to_string().contains("itself several networks"), "{err}");

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

    /// The card in `dir` with `spacing` as its training spacing, written back.
    fn record_spacing(dir: &Path, spacing: Option<f64>) {
        let mut card = ModelCard::read(dir).unwrap();
        card.spacing = spacing;
        card.write(dir).unwrap();
    }

    #[test]
    fn a_set_sparser_than_training_is_read_by_the_sparse_network_alone() {
        let tmp = scratch("sparse");
        // Two networks that read each track's 2 nearest others, as spacing needs.
        let (a, b) = (
            tiny_reading("a", Kind::Trajectories, 4, 7, 2),
            tiny_reading("b", Kind::Trajectories, 4, 8, 2),
        );
        let dirs = [tmp.path().join("a"), tmp.path().join("b")];
        save(&a, &dirs[0]);
        save(&b, &dirs[1]);
        let (points, image, params) = ten_tracks(5, 11);
        let normalised = a.card.normalization.apply(&points, image);
        let s = spacing(&normalised, points.dim(), a.card.architecture.neighbors);
        assert!(s > 0.0);
        record_spacing(&dirs[0], Some(s));
        let out = tmp.path().join("sparse");
        let card = write_sparse(&dirs[0], &dirs[1], 1.5, &out).unwrap();
        let sparse = card.sparse.as_ref().unwrap();
        assert_eq!(
            (sparse.weights.as_str(), sparse.above),
            (SPARSE_WEIGHTS_FILE, 1.5)
        );
        assert_eq!(sparse.training.seed, 8);
        assert_eq!(card.weight_files().last(), Some(SPARSE_WEIGHTS_FILE));
        let mut model = LoadedModel::load(&out).unwrap();
        assert_eq!(model.card, card);

        // At the training spacing: the card's own network.
        let (za, zb) = (
            a.fit(&points, image, &params).unwrap().embeddings,
            b.fit(&points, image, &params).unwrap().embeddings,
        );
        assert_ne!(za, zb);
        let fit = model.fit(&points, image, &params).unwrap();
        assert_eq!((fit.embed_dim, &fit.embeddings), (3, &za));
        // Twice as sparse as training (beyond 1.5 x): the sparse network alone.
        model.card.spacing = Some(s / 2.0);
        let fit = model.fit(&points, image, &params).unwrap();
        assert_eq!((fit.embed_dim, &fit.embeddings), (3, &zb));
        // Only from its directory.
        let err = LoadedModel::from_parts(card, a.net.clone(), cpu_device()).unwrap_err();
        assert!(err.to_string().contains("network for sparse sets"), "{err}");
    }

    #[test]
    fn a_sparse_network_needs_a_spacing_a_single_like_network_and_another_output() {
        let tmp = scratch("sparse-refusals");
        let dirs = [tmp.path().join("a"), tmp.path().join("b")];
        for (dir, seed) in dirs.iter().zip([7, 8]) {
            save(&tiny_reading("n", Kind::Trajectories, 4, seed, 2), dir);
        }
        let out = tmp.path().join("s");
        let refuse = |base: &Path, net: &Path, above: f64, out: &Path| {
            write_sparse(base, net, above, out).unwrap_err().to_string()
        };
        let err = refuse(&dirs[0], &dirs[1], 1.5, &out);
        assert!(err.contains("needs the card's training spacing"), "{err}");
        record_spacing(&dirs[0], Some(0.3));
        for above in [0.5, f64::NAN, f64::INFINITY] {
            let err = refuse(&dirs[0], &dirs[1], above, &out);
            assert!(err.contains("finite ratio of at least 1"), "{above}: {err}");
        }
        let err = refuse(&dirs[0], &dirs[1], 1.5, &dirs[0]);
        assert!(err.contains("both an input and the output"), "{err}");
        let mut wider = tiny(vec![]);
        wider.card.architecture.width = 16;
        let w = tmp.path().join("w");
        save(&wider, &w);
        let err = refuse(&dirs[0], &w, 1.5, &out);
        assert!(err.contains("architecture"), "{err}");
        // A model that already has a sparse network is not one; nothing is written.
        write_sparse(&dirs[0], &dirs[1], 1.5, &out).unwrap();
        let err = refuse(&dirs[0], &out, 1.5, &tmp.path().join("t"));
        assert!(err.contains("itself several networks"), "{err}");
        assert!(!tmp.path().join("t").exists() && !tmp.path().join("t.partial").exists());
        // A card that reads no neighbours has no spacing to route by.
        let mut card = ModelCard::read(&dirs[0]).unwrap();
        card.architecture.neighbors = 0;
        card.sparse = ModelCard::read(&out).unwrap().sparse;
        let err = card.validate().unwrap_err().to_string();
        assert!(err.contains("reads neighbours"), "{err}");
    }
}
