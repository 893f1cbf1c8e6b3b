//! The fused serving forward against burn's forward (the training code path), on every shipped
//! model and on real inputs of its kind: embeddings within 1e-4, and the fit's labels unchanged.

mod common;

use multifit::cluster::{ClusterParams, Points, Selection, cluster};
use multifit::data::dataset::Sequence;
use multifit::data::synthetic::{LceGenerator, LceVariant};
use multifit::data::{Kind, Sample};
use multifit::registry::LoadedModel;

/// Real samples of a model's input kind.
fn samples(kind: Kind) -> Vec<Sample> {
    let load = |rel: &str| {
        Sequence::load(&common::datasets().join(rel))
            .unwrap_or_else(|e| panic!("{rel}: {e}"))
            .sample()
    };
    match kind {
        Kind::Trajectories => vec![
            load("kt3dmoseg_first5/Seq009_Clip01.json"),
            load("kt3dmoseg_first5/Seq038_Clip01.json"),
        ],
        Kind::Correspondences => vec![
            load("adelaidermf/bonython.json"),
            load("adelaidermf/breadcube.json"),
        ],
        Kind::Points2d => {
            let mut generator = LceGenerator::new(7, Default::default());
            vec![
                generator.sample(LceVariant::Mixed, "mixed").sample,
                generator.sample(LceVariant::Unmixed, "unmixed").sample,
            ]
        }
    }
}

#[test]
fn fused_forward_matches_burn_on_every_shipped_model() {
    let dirs = std::fs::read_dir(common::repo().join("models")).unwrap();
    let mut checked = Vec::new();
    for dir in dirs.map(|d| d.unwrap().path()).filter(|p| p.is_dir()) {
        let model = LoadedModel::load(&dir).unwrap();
        let name = model.card.name.clone();
        for sample in samples(model.card.kind) {
            let input =
                multifit::pipeline::prepare(&model, &sample.points, sample.image_size).unwrap();
            let burn = model.embed_burn(&input);
            for threads in [1, 2] {
                let model = LoadedModel::load(&dir)
                    .unwrap()
                    .with_threads(threads)
                    .unwrap();
                let fused = model.embed(&input);
                assert_eq!(fused.len(), burn.len());
                let diff = fused
                    .iter()
                    .zip(&burn)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0f32, f32::max);
                assert!(
                    diff < 1e-4,
                    "{name} on {} with {threads} threads: max |fused - burn| = {diff}",
                    sample.name
                );
                // The same partition for the known K.
                let e = model.card.architecture.embed_dim;
                let params = ClusterParams::builder()
                    .selection(Selection::Fixed(sample.k))
                    .seed(3)
                    .build()
                    .unwrap();
                let a = cluster(Points::new(&fused, e).unwrap(), &params).unwrap();
                let b = cluster(Points::new(&burn, e).unwrap(), &params).unwrap();
                let agree = a
                    .labels
                    .iter()
                    .zip(&b.labels)
                    .filter(|(x, y)| x == y)
                    .count();
                assert!(
                    agree as f64 >= 0.99 * a.labels.len() as f64,
                    "{name} on {}: labels agree on {agree} of {}",
                    sample.name,
                    a.labels.len()
                );
            }
        }
        checked.push(name);
    }
    checked.sort();
    assert_eq!(
        checked,
        [
            "adelaide-fundamental",
            "adelaide-homography",
            "kt3dmoseg",
            "lce",
            "motion"
        ],
        "every shipped model is checked"
    );
}
