//! Offline training: the Adam loop over labelled samples, evaluation and cross-validation.
//!
//! One step takes one set when the sets differ in size (the paper), or a batch of sets of equal
//! size (synthetic data). After every epoch the model is scored on the validation samples (error
//! rate with known K) and the best epoch is kept; without validation samples the last epoch is.
//!
//! The commands of `multifit-train` (train, eval, cv, robustness, ...) are library functions in
//! [`cli`]; the binary only parses their flags.

pub mod cli;
pub mod cv;
pub mod eval;
pub mod robustness;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::prelude::*;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::cluster::{ClusterParams, Points, Selection, cluster};
use crate::data::{Normalization, Sample};
use crate::loss::{Loss, one_hot};
use crate::metrics::error_rate;
use crate::model::{EmbeddingNet, ModelConfig, ModelError, cpu_device};
use crate::pipeline::network_input;

/// Learning-rate schedule over the epochs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Schedule {
    Constant,
    /// Cosine decay from the learning rate to 1 % of it at the last epoch.
    Cosine,
}

/// Everything that defines a training run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    pub model: ModelConfig,
    pub loss: Loss,
    pub learning_rate: f64,
    pub schedule: Schedule,
    pub epochs: usize,
    pub seed: u64,
    /// Sets per step when they share a size.
    pub batch_size: usize,
    /// Gaussian jitter (sigma, in normalised units) added to training inputs; 0 = off.
    pub jitter: f64,
}

/// Why training could not run.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("invalid training config: {0}")]
    Config(String),
    #[error("no training samples")]
    NoSamples,
    #[error("sample {name}: {reason}")]
    Sample { name: String, reason: String },
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error("{path}: {reason}")]
    Checkpoint { path: PathBuf, reason: String },
}

impl TrainConfig {
    pub fn validate(&self) -> Result<(), TrainError> {
        let bad = |m: &str| Err(TrainError::Config(m.into()));
        self.model.validate()?;
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return bad("learning rate must be finite and positive");
        }
        if self.epochs == 0 {
            return bad("epochs must be at least 1");
        }
        if self.batch_size == 0 {
            return bad("batch size must be at least 1");
        }
        if !(self.jitter.is_finite() && self.jitter >= 0.0) {
            return bad("jitter must be finite and non-negative");
        }
        if let Loss::Mimi { alpha } = self.loss
            && !(0.0..=1.0).contains(&alpha)
        {
            return bad("MIMI alpha must be in [0, 1]");
        }
        Ok(())
    }

    fn lr_at(&self, epoch: usize) -> f64 {
        match self.schedule {
            Schedule::Constant => self.learning_rate,
            Schedule::Cosine => {
                let t = epoch as f64 / (self.epochs.max(2) - 1) as f64;
                let floor = 0.01;
                self.learning_rate
                    * (floor + (1.0 - floor) * 0.5 * (1.0 + (std::f64::consts::PI * t).cos()))
            }
        }
    }
}

/// A sample normalised for the network.
#[derive(Debug, Clone)]
pub struct Prepared {
    pub name: String,
    /// Row-major `[n, dim]` network input (features).
    pub input: Vec<f32>,
    /// Values per point of `input` (the model's feature dimension).
    pub dim: usize,
    pub labels: Vec<usize>,
    pub k: usize,
}

impl Prepared {
    pub fn n(&self) -> usize {
        self.labels.len()
    }
}

/// Normalises samples (and appends `neighbors` neighbour offsets) as the model will see them at
/// serving time.
pub fn prepare(
    samples: &[Sample],
    normalization: Normalization,
    neighbors: usize,
) -> Vec<Prepared> {
    samples
        .iter()
        .map(|s| Prepared {
            name: s.name.clone(),
            input: network_input(normalization, &s.points, s.image_size, neighbors),
            dim: s.points.dim() * (1 + neighbors),
            labels: s.labels.clone(),
            k: s.k,
        })
        .collect()
}

/// One line of the training log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpochLog {
    pub epoch: usize,
    pub learning_rate: f64,
    pub train_loss: f64,
    /// Mean error rate with known K on the validation samples.
    pub val_error: Option<f64>,
    pub best: bool,
    pub seconds: f64,
    pub steps: usize,
}

/// Progress saved after every epoch, for `--resume`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct CheckpointState {
    config: TrainConfig,
    history: Vec<EpochLog>,
    best_epoch: usize,
    best_score: f64,
}

/// What a training run produced.
pub struct TrainOutcome {
    /// The kept network (best validation epoch, else the last), without autodiff.
    pub net: EmbeddingNet,
    pub best_epoch: usize,
    pub best_val_error: Option<f64>,
    pub history: Vec<EpochLog>,
    pub seconds: f64,
    /// True when stopped by the stop flag before the last epoch.
    pub interrupted: bool,
}

/// Side channels of a run: a stop flag (Ctrl-C), a per-epoch callback, a checkpoint directory,
/// starting weights.
#[derive(Default)]
pub struct Hooks<'a> {
    pub stop: Option<&'a AtomicBool>,
    pub on_epoch: Option<&'a mut dyn FnMut(&EpochLog)>,
    pub on_step: Option<&'a mut dyn FnMut(usize, usize)>,
    pub checkpoint: Option<&'a Path>,
    pub resume: bool,
    /// Weights (safetensors of `config.model`) to start from instead of the seeded
    /// initialisation: a warm restart or fine-tuning. A resumed checkpoint takes precedence.
    pub init: Option<&'a Path>,
}

const LAST: &str = "last.safetensors";
const BEST: &str = "best.safetensors";
const STATE: &str = "state.json";

/// Groups sample indices into batches of equal-size sets, in a seeded random order.
fn batches(samples: &[Prepared], batch_size: usize, rng: &mut ChaCha8Rng) -> Vec<Vec<usize>> {
    let mut order: Vec<usize> = (0..samples.len()).collect();
    for i in (1..order.len()).rev() {
        order.swap(i, rng.random_range(0..=i));
    }
    if batch_size == 1 {
        return order.into_iter().map(|i| vec![i]).collect();
    }
    let mut open: Vec<Vec<usize>> = Vec::new();
    let mut out = Vec::new();
    for i in order {
        let key = (samples[i].n(), samples[i].dim);
        match open
            .iter_mut()
            .position(|b| (samples[b[0]].n(), samples[b[0]].dim) == key)
        {
            Some(p) => {
                open[p].push(i);
                if open[p].len() == batch_size {
                    out.push(open.swap_remove(p));
                }
            }
            None => open.push(vec![i]),
        }
    }
    out.extend(open);
    out
}

/// Mean error rate with known K of `net` on `samples` (seeded k-means, 2 restarts).
pub fn known_k_error(
    net: &EmbeddingNet,
    samples: &[Prepared],
    embed_dim: usize,
    device: &Device,
) -> f64 {
    let errors: Vec<f64> = samples
        .iter()
        .map(|s| {
            let z = net.embed(&s.input, s.dim, device);
            let params = ClusterParams::builder()
                .selection(Selection::Fixed(s.k))
                .restarts(2)
                .seed(0)
                .build();
            match params
                .ok()
                .and_then(|p| cluster(Points::new(&z, embed_dim).ok()?, &p).ok())
            {
                Some(c) => error_rate(&s.labels, &c.labels),
                None => 1.0,
            }
        })
        .collect();
    errors.iter().sum::<f64>() / errors.len().max(1) as f64
}

pub(crate) fn checkpoint_err(path: &Path, e: impl std::fmt::Display) -> TrainError {
    TrainError::Checkpoint {
        path: path.to_path_buf(),
        reason: e.to_string(),
    }
}

/// Trains a network on `train`, choosing the epoch by `val` (when non-empty).
pub fn train(
    config: &TrainConfig,
    train: &[Prepared],
    val: &[Prepared],
    mut hooks: Hooks,
) -> Result<TrainOutcome, TrainError> {
    config.validate()?;
    if train.is_empty() {
        return Err(TrainError::NoSamples);
    }
    for s in train.iter().chain(val) {
        if s.dim != config.model.feature_dim() {
            return Err(TrainError::Sample {
                name: s.name.clone(),
                reason: format!(
                    "rows of {} values, the model takes {}",
                    s.dim,
                    config.model.feature_dim()
                ),
            });
        }
        if s.labels.iter().any(|&l| l >= s.k) || s.n() < 2 {
            return Err(TrainError::Sample {
                name: s.name.clone(),
                reason: "labels out of range or fewer than 2 points".into(),
            });
        }
    }
    let start = Instant::now();
    let device = cpu_device();
    let ad = device.clone().autodiff();
    let mut model = None;
    let mut history: Vec<EpochLog> = Vec::new();
    let mut best_epoch = 0;
    let mut best_score = f64::INFINITY;
    let mut best: Option<EmbeddingNet> = None;
    let mut first_epoch = 0;

    if let (Some(dir), true) = (hooks.checkpoint, hooks.resume) {
        let state_path = dir.join(STATE);
        if state_path.is_file() {
            let text =
                std::fs::read_to_string(&state_path).map_err(|e| checkpoint_err(&state_path, e))?;
            let state: CheckpointState =
                serde_json::from_str(&text).map_err(|e| checkpoint_err(&state_path, e))?;
            if state.config != *config {
                return Err(checkpoint_err(
                    &state_path,
                    "the checkpoint was made with a different config",
                ));
            }
            model = Some(EmbeddingNet::load(&config.model, &dir.join(LAST), &ad)?);
            best = Some(EmbeddingNet::load(&config.model, &dir.join(BEST), &device)?);
            first_epoch = state.history.len();
            history = state.history;
            best_epoch = state.best_epoch;
            best_score = state.best_score;
        }
    }
    // Without a checkpoint to resume: the given weights, else the seeded initialisation.
    let mut model = match (model, hooks.init) {
        (Some(resumed), _) => resumed,
        (None, Some(path)) => EmbeddingNet::load(&config.model, path, &ad)?,
        (None, None) => config.model.init_seeded(&ad, config.seed)?,
    };

    let mut optim = AdamConfig::new().with_epsilon(1e-8).init();
    let noise = Normal::new(0.0, config.jitter.max(0.0)).expect("finite sigma");
    let e = config.model.embed_dim;
    let mut interrupted = false;
    for epoch in first_epoch..config.epochs {
        let t0 = Instant::now();
        // Each epoch draws from its own stream, so a resumed run sees the same order.
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed.wrapping_add(epoch as u64 * 7919));
        let lr = config.lr_at(epoch);
        let plan = batches(train, config.batch_size, &mut rng);
        let mut loss_sum = 0.0;
        for (step, batch) in plan.iter().enumerate() {
            if hooks.stop.is_some_and(|s| s.load(Ordering::Relaxed)) {
                interrupted = true;
                break;
            }
            let (n, d) = (train[batch[0]].n(), train[batch[0]].dim);
            let mut input: Vec<f32> = Vec::with_capacity(batch.len() * n * d);
            for &i in batch {
                input.extend(train[i].input.iter().map(|&v| {
                    if config.jitter > 0.0 {
                        v + noise.sample(&mut rng) as f32
                    } else {
                        v
                    }
                }));
            }
            let x = Tensor::<3>::from_data(TensorData::new(input, [batch.len(), n, d]), &ad);
            let z = model.forward(x);
            let mut loss: Option<Tensor<1>> = None;
            for (b, &i) in batch.iter().enumerate() {
                let zi = z.clone().narrow(0, b, 1).reshape([n, e]);
                let li = config
                    .loss
                    .compute(zi, one_hot(&train[i].labels, train[i].k, &ad));
                loss = Some(match loss {
                    Some(acc) => acc + li,
                    None => li,
                });
            }
            let loss = loss
                .expect("non-empty batch")
                .div_scalar(batch.len() as f64);
            loss_sum += loss.clone().into_scalar::<f32>() as f64;
            let grads = GradientsParams::from_grads(loss.backward(), &model);
            model = optim.step(lr, model, grads);
            if let Some(f) = hooks.on_step.as_deref_mut() {
                f(step + 1, plan.len());
            }
        }
        if interrupted {
            break;
        }
        let inner = model.valid();
        let val_error = (!val.is_empty()).then(|| known_k_error(&inner, val, e, &device));
        let train_loss = loss_sum / plan.len() as f64;
        // Without validation samples the last epoch is kept.
        let score = val_error.unwrap_or(-(epoch as f64));
        let is_best = score < best_score;
        if is_best {
            best_score = score;
            best_epoch = epoch + 1;
            best = Some(inner.clone());
        }
        let log = EpochLog {
            epoch: epoch + 1,
            learning_rate: lr,
            train_loss,
            val_error,
            best: is_best,
            seconds: t0.elapsed().as_secs_f64(),
            steps: plan.len(),
        };
        if let Some(dir) = hooks.checkpoint {
            std::fs::create_dir_all(dir).map_err(|e| checkpoint_err(dir, e))?;
            inner.save(&dir.join(LAST))?;
            if is_best {
                inner.save(&dir.join(BEST))?;
            }
        }
        history.push(log.clone());
        if let Some(dir) = hooks.checkpoint {
            let state = CheckpointState {
                config: config.clone(),
                history: history.clone(),
                best_epoch,
                best_score,
            };
            let path = dir.join(STATE);
            let text =
                serde_json::to_string_pretty(&state).map_err(|e| checkpoint_err(&path, e))?;
            std::fs::write(&path, text).map_err(|e| checkpoint_err(&path, e))?;
        }
        if let Some(f) = hooks.on_epoch.as_deref_mut() {
            f(&log);
        }
    }
    let net = match best {
        Some(net) => net,
        None => model.valid(),
    };
    let best_val_error = history
        .iter()
        .find(|h| h.epoch == best_epoch)
        .and_then(|h| h.val_error);
    Ok(TrainOutcome {
        net,
        best_epoch,
        best_val_error,
        history,
        seconds: start.elapsed().as_secs_f64(),
        interrupted,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::synthetic::{LceConfig, LceGenerator, Shape};

    fn tiny_config(loss: Loss) -> TrainConfig {
        TrainConfig {
            model: ModelConfig {
                input_dim: 2,
                width: 16,
                depth: 1,
                embed_dim: 3,
                batch_norm: false,
                cn_epsilon: 1e-3,
                neighbors: 0,
                graph_neighbors: 0,
            },
            loss,
            learning_rate: 1e-2,
            schedule: Schedule::Constant,
            epochs: 3,
            seed: 1,
            batch_size: 4,
            jitter: 0.0,
        }
    }

    fn two_lines(count: usize, seed: u64) -> Vec<Prepared> {
        let cfg = LceConfig {
            points_per_shape: 16,
            noise: 0.01,
            scale: 1.0,
            ..LceConfig::default()
        };
        let mut g = LceGenerator::new(seed, cfg);
        let samples: Vec<Sample> = (0..count)
            .map(|i| {
                g.with_shapes(&[Shape::Line, Shape::Circle], &i.to_string())
                    .sample
            })
            .collect();
        prepare(&samples, Normalization::CentroidUnitRms, 0)
    }

    #[test]
    fn batches_group_equal_sizes_and_cover_everything() {
        let mut samples = two_lines(5, 1);
        samples[2].labels.push(0);
        samples[2].input.extend([0.0, 0.0]);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let b = batches(&samples, 2, &mut rng);
        let mut all: Vec<usize> = b.iter().flatten().copied().collect();
        all.sort();
        assert_eq!(all, vec![0, 1, 2, 3, 4]);
        for batch in &b {
            assert!(
                batch
                    .iter()
                    .all(|&i| samples[i].n() == samples[batch[0]].n())
            );
            assert!(batch.len() <= 2);
        }
    }

    #[test]
    fn training_lowers_the_loss_and_is_deterministic() {
        let train_set = two_lines(8, 2);
        let val = two_lines(2, 3);
        for loss in [Loss::L2, Loss::CrossEntropy, Loss::Mimi { alpha: 0.6 }] {
            let cfg = TrainConfig {
                epochs: 6,
                ..tiny_config(loss)
            };
            let a = train(&cfg, &train_set, &val, Hooks::default()).unwrap();
            assert_eq!(a.history.len(), 6);
            assert!(
                a.history.last().unwrap().train_loss < a.history[0].train_loss,
                "{loss:?}: {:?}",
                a.history
            );
            assert!(a.best_val_error.is_some());
            let b = train(&cfg, &train_set, &val, Hooks::default()).unwrap();
            let x = &train_set[0].input;
            let device = cpu_device();
            assert_eq!(
                a.net.embed(x, 2, &device),
                b.net.embed(x, 2, &device),
                "{loss:?} not deterministic"
            );
        }
    }

    #[test]
    fn stop_flag_interrupts_and_resume_continues() {
        let train_set = two_lines(4, 4);
        let tmp = tempfile::Builder::new()
            .prefix("multifit-resume-")
            .tempdir()
            .unwrap();
        // A directory that does not exist yet: the first run creates it.
        let dir = tmp.path().join("checkpoint");
        let cfg = tiny_config(Loss::L2);
        let stop = AtomicBool::new(false);
        let mut seen = 0;
        let mut on_epoch = |_: &EpochLog| {
            seen += 1;
            if seen == 2 {
                stop.store(true, Ordering::Relaxed);
            }
        };
        let hooks = Hooks {
            stop: Some(&stop),
            on_epoch: Some(&mut on_epoch),
            checkpoint: Some(&dir),
            ..Hooks::default()
        };
        let first = train(&cfg, &train_set, &[], hooks).unwrap();
        assert!(first.interrupted);
        assert_eq!(first.history.len(), 2);
        let hooks = Hooks {
            checkpoint: Some(&dir),
            resume: true,
            ..Hooks::default()
        };
        let second = train(&cfg, &train_set, &[], hooks).unwrap();
        assert_eq!(second.history.len(), 3);
        assert_eq!(second.history[..2], first.history[..]);
        // A different config refuses the checkpoint.
        let other = TrainConfig { epochs: 5, ..cfg };
        let hooks = Hooks {
            checkpoint: Some(&dir),
            resume: true,
            ..Hooks::default()
        };
        assert!(matches!(
            train(&other, &train_set, &[], hooks),
            Err(TrainError::Checkpoint { .. })
        ));
    }

    #[test]
    fn init_starts_from_given_weights_and_rejects_other_shapes() {
        let train_set = two_lines(4, 6);
        let dir = tempfile::Builder::new()
            .prefix("multifit-init-")
            .tempdir()
            .unwrap();
        let weights = dir.path().join("w.safetensors");
        let cfg = tiny_config(Loss::L2);
        let first = train(&cfg, &train_set, &[], Hooks::default()).unwrap();
        first.net.save(&weights).unwrap();
        // One epoch at a negligible learning rate from those weights leaves them as they were,
        // unlike the same epoch from the seeded initialisation.
        let still = TrainConfig {
            learning_rate: 1e-12,
            epochs: 1,
            ..cfg.clone()
        };
        let hooks = Hooks {
            init: Some(&weights),
            ..Hooks::default()
        };
        let warm = train(&still, &train_set, &[], hooks).unwrap();
        let cold = train(&still, &train_set, &[], Hooks::default()).unwrap();
        let device = cpu_device();
        let x = &train_set[0].input;
        let (a, w, c) = (
            first.net.embed(x, 2, &device),
            warm.net.embed(x, 2, &device),
            cold.net.embed(x, 2, &device),
        );
        let gap = |p: &[f32], q: &[f32]| {
            p.iter()
                .zip(q)
                .map(|(u, v)| (u - v).abs())
                .fold(0.0f32, f32::max)
        };
        assert!(gap(&a, &w) < 1e-5, "warm start moved by {}", gap(&a, &w));
        assert!(gap(&a, &c) > 1e-2, "cold start equals the trained net");
        // Weights of another width are refused, not silently reshaped.
        let wider = TrainConfig {
            model: ModelConfig {
                width: 8,
                ..cfg.model.clone()
            },
            ..still
        };
        let hooks = Hooks {
            init: Some(&weights),
            ..Hooks::default()
        };
        assert!(matches!(
            train(&wider, &train_set, &[], hooks),
            Err(TrainError::Model(_))
        ));
    }

    #[test]
    fn rejects_mismatched_samples_and_configs() {
        let mut s = two_lines(1, 5);
        s[0].dim = 4;
        assert!(matches!(
            train(&tiny_config(Loss::L2), &s, &[], Hooks::default()),
            Err(TrainError::Sample { .. })
        ));
        let bad = TrainConfig {
            learning_rate: -1.0,
            ..tiny_config(Loss::L2)
        };
        assert!(bad.validate().is_err());
        assert!(matches!(
            train(&tiny_config(Loss::L2), &[], &[], Hooks::default()),
            Err(TrainError::NoSamples)
        ));
    }
}
