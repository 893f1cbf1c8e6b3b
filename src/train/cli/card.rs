//! Model cards of the models `train` writes, and the metrics `train` and `eval --record` add:
//! the `--init` model checked against the flags, the description of the training data (which
//! nests a warm-started parent's), the card of a trained network and its metric records.

use std::path::{Path, PathBuf};

use super::CliError;
use super::provenance::git_commit;
use crate::data::{Kind, Symmetry};
use crate::registry::{MetricRecord, ModelCard, TrainingInfo, WEIGHTS_FILE, card_for};
use crate::train::TrainConfig;
use crate::train::cv::SamplePlan;
use crate::train::eval::Totals;

/// The weights file and card of the `--init` model, checked against the architecture to train.
pub fn init_card(dir: &Path, config: &TrainConfig) -> Result<(PathBuf, ModelCard), CliError> {
    let card = ModelCard::read(dir)?;
    if !card.members.is_empty() {
        return Err(CliError::InitEnsemble {
            dir: dir.to_path_buf(),
            networks: card.members.len() + 1,
        });
    }
    if card.architecture != config.model {
        return Err(CliError::InitArchitecture {
            dir: dir.to_path_buf(),
            model: format!("{:?}", card.architecture),
            flags: format!("{:?}", config.model),
        });
    }
    Ok((dir.join(WEIGHTS_FILE), card))
}

/// What a trained model saw, for its card: `given` (`--describe`) when not empty, else the
/// sources, the counts and the sample plan; followed by the parent's training when the run was
/// warm-started from `parent`, so that a chain of warm restarts reads whole.
pub fn training_data(
    given: &str,
    sources: &str,
    sequences: usize,
    samples: usize,
    plan: &SamplePlan,
    parent: Option<&ModelCard>,
) -> String {
    let data = if given.is_empty() {
        format!(
            "{sources} ({sequences} sequences, {samples} training samples, {})",
            plan.describe()
        )
    } else {
        given.to_string()
    };
    match parent {
        Some(from) => format!(
            "{data}; warm-started from the model {} ({} epochs, {:.0} s; its data: {})",
            from.name, from.training.epochs, from.training.seconds, from.training.data
        ),
        None => data,
    }
}

/// The card of a network trained with `config` on data of `kind`, with the test symmetries it
/// will be served with and the commit of the source tree.
pub fn trained_card(
    name: &str,
    kind: Kind,
    config: &TrainConfig,
    k_max: usize,
    test_symmetries: &[Symmetry],
    info: TrainingInfo,
) -> ModelCard {
    let mut card = card_for(name, kind, &config.model, config.loss, k_max, info);
    card.test_symmetries = test_symmetries.to_vec();
    card.git_commit = git_commit();
    card
}

/// The metric `train` records for the kept epoch when it had validation samples.
pub fn validation_metric(
    error: f64,
    samples: usize,
    best_epoch: usize,
    command: &str,
) -> MetricRecord {
    MetricRecord {
        name: "validation_error_known_k".into(),
        value: error,
        protocol: format!(
            "mean error rate with known K on {samples} validation samples, best epoch {best_epoch}"
        ),
        command: command.to_string(),
    }
}

/// Records an evaluation in `card` under `name` (the known-K mean error), `<name>_nmi` (its mean
/// NMI) and `<name>_sod` (the mean error with K chosen by SOD), replacing earlier records of
/// those names.
pub fn record_metrics(
    card: &mut ModelCard,
    name: &str,
    totals: &Totals,
    protocol: &str,
    command: &str,
) {
    card.metrics.retain(|m| {
        m.name != name && m.name != format!("{name}_nmi") && m.name != format!("{name}_sod")
    });
    for (suffix, value) in [
        ("", totals.known.mean_error),
        ("_nmi", totals.known.mean_nmi),
        ("_sod", totals.sod.mean_error),
    ] {
        card.metrics.push(MetricRecord {
            name: format!("{name}{suffix}"),
            value,
            protocol: protocol.to_string(),
            command: command.to_string(),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registry::tests::{save, scratch, tiny, two_saved_models};
    use crate::train::Schedule;
    use crate::train::cv::Protocol;
    use crate::train::eval::Summary;

    fn config_of(card: &ModelCard) -> TrainConfig {
        TrainConfig {
            model: card.architecture.clone(),
            loss: card.loss,
            learning_rate: 1e-3,
            schedule: Schedule::Cosine,
            epochs: 2,
            seed: 0,
            batch_size: 1,
            jitter: 0.0,
        }
    }

    #[test]
    fn init_card_checks_the_architecture() {
        let tmp = scratch("init-card");
        let model = tiny(vec![]);
        save(&model, tmp.path());
        let mut config = config_of(&model.card);
        let (weights, card) = init_card(tmp.path(), &config).unwrap();
        assert_eq!(weights, tmp.path().join(WEIGHTS_FILE));
        assert_eq!(card, model.card);
        config.model.width += 1;
        let e = init_card(tmp.path(), &config).unwrap_err().to_string();
        assert!(
            e.contains("--init needs the same architecture") && e.contains("width: 9"),
            "{e}"
        );
        let (_, _, dirs) = two_saved_models(&tmp);
        let both = tmp.path().join("both");
        crate::registry::write_ensemble(&dirs, &both, "both").unwrap();
        let e = init_card(&both, &config_of(&model.card))
            .unwrap_err()
            .to_string();
        assert!(
            e.ends_with("--init needs a single network; this model is an ensemble of 2"),
            "{e}"
        );
    }

    #[test]
    fn training_data_nests_the_parent() {
        let plan = SamplePlan {
            protocol: Protocol::Augment,
            clip_len: 5,
            clip_stride: 2,
            symmetries: vec![],
            subsample: None,
        };
        let own = training_data("", "a, b", 3, 40, &plan, None);
        assert_eq!(
            own,
            "a, b (3 sequences, 40 training samples, protocol Augment, clip 5 frames, clips every 2 frames)"
        );
        assert_eq!(training_data("mine", "a", 1, 1, &plan, None), "mine");
        let mut parent = tiny(vec![]).card;
        parent.name = "p".into();
        parent.training.data = "its own".into();
        parent.training.seconds = 12.4;
        let nested = training_data("mine", "a", 1, 1, &plan, Some(&parent));
        assert_eq!(
            nested,
            "mine; warm-started from the model p (1 epochs, 12 s; its data: its own)"
        );
    }

    #[test]
    fn record_metrics_replaces_the_three_records() {
        let mut card = tiny(vec![]).card;
        let s = |e: f64| Summary {
            mean_error: e,
            median_error: e,
            mean_nmi: 1.0 - e,
            k_correct: 1.0,
            outliers: None,
        };
        let totals = |e: f64| Totals {
            samples: 2,
            known: s(e),
            sod: s(2.0 * e),
            silhouette: s(3.0 * e),
        };
        card.metrics.push(validation_metric(0.5, 4, 7, "cmd"));
        record_metrics(&mut card, "lce", &totals(0.1), "p1", "c1");
        record_metrics(&mut card, "lce", &totals(0.2), "p2", "c2");
        let names: Vec<_> = card.metrics.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(
            names,
            ["validation_error_known_k", "lce", "lce_nmi", "lce_sod"]
        );
        assert_eq!(
            card.metrics[0].protocol,
            "mean error rate with known K on 4 validation samples, best epoch 7"
        );
        let values: Vec<_> = card.metrics[1..].iter().map(|m| m.value).collect();
        assert_eq!(values, [0.2, 0.8, 0.4]);
        assert!(
            card.metrics[1..]
                .iter()
                .all(|m| m.protocol == "p2" && m.command == "c2")
        );
    }
}
