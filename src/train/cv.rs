//! Leave-one-sequence-out cross-validation (the paper's protocol for KT3DMoSeg and AdelaideRMF).
//!
//! For each sequence: train on the others, test on it. Trajectory sequences are cut into clips
//! of `clip_len` frames: the test clip is frames 1..clip_len of the held-out sequence; 'vanilla'
//! trains on the first clip of every other sequence, 'augment' on every non-overlapping clip of
//! every other sequence (or, with a smaller clip stride, overlapping ones), and training samples may
//! be multiplied by structure-preserving symmetries ([`SamplePlan`]). No clip of the held-out
//! sequence is seen in training, except under the diagnostic 'augment-leaky' protocol.
//! Correspondence sequences are used whole. Each finished fold is written to
//! `<out>/folds/<name>.json`, its model to `<out>/models/<name>/`, and is not retrained when the
//! run is restarted.

use std::path::{Path, PathBuf};
use std::process::{Child, Command};

use rand::RngExt;
use serde::{Deserialize, Serialize};

use super::eval::{EvalRow, EvalSettings, evaluate_sample};
use super::{Hooks, TrainConfig, TrainError, checkpoint_err, prepare, train};
use crate::data::dataset::family_of;
use crate::data::{Kind, Normalization, Sample, Sequence, Symmetry, seeded_rng, with_symmetries};
use crate::registry::{LoadedModel, TrainingInfo, WEIGHTS_FILE, card_for};

/// Which training clips a fold uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Protocol {
    /// The test clip (first `clip_len` frames) of every other sequence.
    Vanilla,
    /// Every non-overlapping clip of every other sequence.
    Augment,
    /// 'augment', plus the clips of the held-out sequence that start after its test clip: what
    /// the authors' public code trains on. The later clips show the test clip's motions, so this
    /// is not an honest protocol; it exists to measure how much that leak is worth.
    AugmentLeaky,
}

/// One finished fold.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FoldResult {
    pub row: EvalRow,
    pub train_samples: usize,
    pub train_seconds: f64,
    pub best_epoch: usize,
}

/// How a sequence becomes a test sample and training samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SamplePlan {
    pub protocol: Protocol,
    /// Frames per trajectory clip (the paper: 5).
    pub clip_len: usize,
    /// Frames between the starts of two 'augment' clips: `clip_len` gives the paper's
    /// non-overlapping clips, less gives overlapping ones.
    pub clip_stride: usize,
    /// Structure-preserving images added to the training samples (none in the paper).
    pub symmetries: Vec<Symmetry>,
    /// Copies of every training sequence at lower densities (none in the paper).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub subsample: Option<Subsample>,
}

/// Copies of a training sequence that keep fewer of its rows: the densities users send (a
/// matcher or tracker keeps fewer correspondences or tracks than a dataset's annotators did).
/// Copy c of a sequence keeps a share of its rows drawn uniformly in `[low, high]`, the rows
/// drawn without replacement ([`Sequence::subsample`]), from a stream fixed by `seed`, the
/// sequence's name and c.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Subsample {
    pub low: f64,
    pub high: f64,
    pub copies: usize,
    pub seed: u64,
}

impl Subsample {
    pub fn validate(&self) -> Result<(), TrainError> {
        if !(self.low > 0.0 && self.low <= self.high && self.high <= 1.0) {
            return Err(TrainError::Config(format!(
                "subsample shares {}-{} are not within (0, 1] and ascending",
                self.low, self.high
            )));
        }
        if self.copies == 0 {
            return Err(TrainError::Config(
                "subsampled copies must be at least 1".into(),
            ));
        }
        Ok(())
    }

    /// The subsampled copies of `seq`.
    pub fn copies(&self, seq: &Sequence) -> Vec<Sequence> {
        (0..self.copies)
            .map(|c| {
                let mut rng = seeded_rng(&format!("{}/subsample/{}/{c}", self.seed, seq.name));
                let share = rng.random_range(self.low..=self.high);
                seq.subsample(share, &mut rng)
            })
            .collect()
    }
}

impl SamplePlan {
    pub fn validate(&self) -> Result<(), TrainError> {
        if self.clip_len < 2 {
            return Err(TrainError::Config("clips need at least 2 frames".into()));
        }
        if self.clip_stride == 0 {
            return Err(TrainError::Config("clip stride must be at least 1".into()));
        }
        self.subsample.as_ref().map_or(Ok(()), Subsample::validate)
    }

    /// The test sample of a sequence: frames 1..clip_len of a trajectory sequence, a
    /// correspondence sequence whole.
    pub fn test_sample(&self, seq: &Sequence) -> Option<Sample> {
        match seq.points.kind() {
            Kind::Trajectories => seq.clip(0, self.clip_len),
            _ => Some(seq.sample()),
        }
    }

    /// The training samples a sequence contributes to the folds that do not hold it out: its
    /// clips (or itself), then those of its subsampled copies, each with its symmetric images.
    pub fn train_samples(&self, seq: &Sequence) -> Vec<Sample> {
        let copies = self.subsample.map(|s| s.copies(seq)).unwrap_or_default();
        let cut = std::iter::once(seq)
            .chain(&copies)
            .flat_map(|seq| match (seq.points.kind(), self.protocol) {
                (Kind::Trajectories, Protocol::Vanilla) => {
                    seq.clip(0, self.clip_len).into_iter().collect()
                }
                (Kind::Trajectories, Protocol::Augment | Protocol::AugmentLeaky) => {
                    seq.clips(self.clip_len, self.clip_stride)
                }
                _ => vec![seq.sample()],
            })
            .collect();
        with_symmetries(cut, &self.symmetries)
    }

    /// The training samples the held-out sequence itself adds to its fold: none, except under
    /// [`Protocol::AugmentLeaky`], where its clips starting after the test clip (frames
    /// clip_len + 1 onwards) join, with their symmetric images.
    pub fn held_out_samples(&self, seq: &Sequence) -> Vec<Sample> {
        if self.protocol != Protocol::AugmentLeaky || seq.points.kind() != Kind::Trajectories {
            return vec![];
        }
        let later = seq.clips_from(self.clip_len, self.clip_len, self.clip_stride);
        with_symmetries(later, &self.symmetries)
    }

    /// One line for model cards and logs.
    pub fn describe(&self) -> String {
        let mut text = format!(
            "protocol {:?}, clip {} frames",
            self.protocol, self.clip_len
        );
        if self.protocol != Protocol::Vanilla && self.clip_stride != self.clip_len {
            text.push_str(&format!(", clips every {} frames", self.clip_stride));
        }
        if !self.symmetries.is_empty() {
            text.push_str(&format!(", with symmetries {:?}", self.symmetries));
        }
        if let Some(s) = &self.subsample {
            text.push_str(&format!(
                ", {} subsampled copies keeping {}-{} of the rows",
                s.copies, s.low, s.high
            ));
        }
        text
    }
}

/// A cross-validation run.
#[derive(Debug, Clone)]
pub struct CvSpec {
    pub train: TrainConfig,
    pub samples: SamplePlan,
    /// The test symmetries of every fold's model card (see [`ModelCard::test_symmetries`]).
    pub test_symmetries: Vec<Symmetry>,
    pub eval: EvalSettings,
    pub out: PathBuf,
    /// Weights every fold starts from (a pretrained model of the same architecture), instead of
    /// a fresh initialisation.
    pub init: Option<PathBuf>,
    /// Sequences every fold also trains on, never held out.
    pub extra: Vec<Sequence>,
}

fn fold_path(out: &Path, name: &str) -> PathBuf {
    out.join("folds").join(format!("{name}.json"))
}

/// The saved result of a fold, if it finished before.
pub fn finished_fold(out: &Path, name: &str) -> Option<FoldResult> {
    let text = std::fs::read_to_string(fold_path(out, name)).ok()?;
    serde_json::from_str(&text).ok()
}

/// Trains on every sequence but `held_out` and evaluates on `held_out`'s test sample.
/// Writes the result to `<out>/folds/<name>.json`; returns the saved result when it exists.
pub fn run_fold(
    spec: &CvSpec,
    seqs: &[Sequence],
    held_out: usize,
) -> Result<FoldResult, TrainError> {
    let name = &seqs[held_out].name;
    if let Some(done) = finished_fold(&spec.out, name) {
        return Ok(done);
    }
    let test = spec
        .samples
        .test_sample(&seqs[held_out])
        .ok_or_else(|| TrainError::Sample {
            name: name.clone(),
            reason: "no test clip".into(),
        })?;
    let kind = test.points.kind();
    let train_set: Vec<Sample> = seqs
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != held_out)
        .flat_map(|(_, s)| spec.samples.train_samples(s))
        .chain(spec.samples.held_out_samples(&seqs[held_out]))
        .chain(
            spec.extra
                .iter()
                .flat_map(|s| spec.samples.train_samples(s)),
        )
        .collect();
    let prepared = prepare(
        &train_set,
        Normalization::for_kind(kind),
        spec.train.model.neighbors,
    );
    let hooks = Hooks {
        init: spec.init.as_deref(),
        ..Hooks::default()
    };
    let outcome = train(&spec.train, &prepared, &[], hooks)?;
    let info = TrainingInfo {
        data: match spec.samples.protocol {
            Protocol::AugmentLeaky => format!("fold of {name}, with its clips after the test clip"),
            _ => format!("fold without {name}"),
        } + &match spec.extra.len() {
            0 => String::new(),
            n => format!(", plus {n} more sequences"),
        },
        command: String::new(),
        epochs: spec.train.epochs,
        learning_rate: spec.train.learning_rate,
        seed: spec.train.seed,
        seconds: outcome.seconds,
        machine: String::new(),
    };
    let mut card = card_for(
        &format!("fold-{name}"),
        kind,
        &spec.train.model,
        spec.train.loss,
        spec.eval.k_max,
        info,
    );
    card.test_symmetries = spec.test_symmetries.clone();
    card.geometry = family_of(seqs);
    // The fold's model is kept, so that it can be evaluated again without retraining.
    let model_dir = spec.out.join("models").join(name);
    let keep = || -> Result<(), TrainError> {
        card.write(&model_dir)
            .map_err(|e| checkpoint_err(&model_dir, e))?;
        outcome.net.save(&model_dir.join(WEIGHTS_FILE))?;
        Ok(())
    };
    keep()?;
    let model = LoadedModel::from_parts(card, outcome.net, crate::model::cpu_device())?;
    let row = evaluate_sample(&model, &test, &spec.eval).map_err(|e| TrainError::Sample {
        name: name.clone(),
        reason: e.to_string(),
    })?;
    let result = FoldResult {
        row,
        train_samples: prepared.len(),
        train_seconds: outcome.seconds,
        best_epoch: outcome.best_epoch,
    };
    let path = fold_path(&spec.out, name);
    let write = || -> std::io::Result<()> {
        std::fs::create_dir_all(path.parent().expect("folds dir"))?;
        let tmp = path.with_extension("json.tmp");
        std::fs::write(
            &tmp,
            serde_json::to_string_pretty(&result).map_err(std::io::Error::other)?,
        )?;
        std::fs::rename(&tmp, &path)
    };
    write().map_err(|e| checkpoint_err(&path, e))?;
    Ok(result)
}

/// Runs `exe <args> --fold <name>` for every unfinished fold, at most `jobs` at a time, each child
/// limited to one compute thread (on two cores, two one-thread processes train faster than one
/// two-thread process). Returns the names of folds whose process failed.
pub fn run_in_processes(
    exe: &Path,
    args: &[String],
    out: &Path,
    names: &[String],
    jobs: usize,
) -> std::io::Result<Vec<String>> {
    let mut pending: Vec<&String> = names
        .iter()
        .filter(|n| finished_fold(out, n).is_none())
        .rev()
        .collect();
    let mut running: Vec<(String, Child)> = Vec::new();
    let mut failed = Vec::new();
    while !pending.is_empty() || !running.is_empty() {
        while running.len() < jobs.max(1) {
            let Some(name) = pending.pop() else { break };
            let child = Command::new(exe)
                .args(args)
                .arg("--fold")
                .arg(name)
                .env("RAYON_NUM_THREADS", "1")
                .spawn()?;
            running.push((name.clone(), child));
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
        let mut i = 0;
        while i < running.len() {
            if let Some(status) = running[i].1.try_wait()? {
                let (name, _) = running.swap_remove(i);
                if !status.success() {
                    failed.push(name);
                }
            } else {
                i += 1;
            }
        }
    }
    Ok(failed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::dataset::tests::pair;

    fn plan(subsample: Option<Subsample>) -> SamplePlan {
        SamplePlan {
            protocol: Protocol::Vanilla,
            clip_len: 5,
            clip_stride: 5,
            symmetries: vec![],
            subsample,
        }
    }

    /// Each sequence trains as itself plus its copies, each keeping a seeded share of the rows
    /// within the range (labels following their rows); the same seed draws the same copies.
    #[test]
    fn subsampled_copies_keep_a_seeded_share_within_the_range() {
        let seq = pair();
        let sub = Subsample {
            low: 0.25,
            high: 0.5,
            copies: 3,
            seed: 7,
        };
        let samples = plan(Some(sub)).train_samples(&seq);
        assert_eq!(samples.len(), 4);
        assert_eq!(samples[0].points, seq.points);
        for s in &samples[1..] {
            assert!((10..=20).contains(&s.points.len()), "{}", s.points.len());
            for i in 0..s.points.len() {
                let row = s.points.row(i);
                let at = (0..seq.points.len())
                    .find(|&j| seq.points.row(j) == row)
                    .expect("a row of the sequence");
                assert_eq!(s.labels[i], samples[0].labels[at]);
            }
        }
        assert_ne!(samples[1].points, samples[2].points);
        let again = plan(Some(sub)).train_samples(&seq);
        assert!(
            again
                .iter()
                .zip(&samples)
                .all(|(a, b)| a.points == b.points)
        );
        let other = Subsample { seed: 8, ..sub };
        assert_ne!(
            plan(Some(other)).train_samples(&seq)[1].points,
            samples[1].points
        );
        assert_eq!(plan(None).train_samples(&seq).len(), 1);
    }

    #[test]
    fn bad_subsampling_is_refused() {
        let ok = Subsample {
            low: 0.2,
            high: 1.0,
            copies: 1,
            seed: 0,
        };
        assert!(plan(Some(ok)).validate().is_ok());
        for bad in [
            Subsample { low: 0.0, ..ok },
            Subsample { high: 1.5, ..ok },
            Subsample {
                low: 0.6,
                high: 0.5,
                ..ok
            },
            Subsample {
                low: f64::NAN,
                ..ok
            },
            Subsample { copies: 0, ..ok },
        ] {
            assert!(plan(Some(bad)).validate().is_err(), "{bad:?}");
        }
    }
}
