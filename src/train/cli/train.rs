//! `train`: one model trained on the `--data` sequences and written as a model directory
//! (weights and card), with a JSONL line per epoch in the run directory and its curves beside it
//! (`train.svg`: training loss and validation error per epoch, redrawn after every epoch from
//! the whole log, so a resumed run has one picture), checkpoints there for `--resume`, and a
//! progress bar on standard error.

use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use super::CliError;
use super::card::{init_card, trained_card, training_data, validation_metric};
use super::options::{DataArgs, TrainArgs, check_symmetries};
use super::provenance::{command_line, machine};
use crate::data::dataset::family_of;
use crate::data::{DataSource, Normalization, Sample};
use crate::registry::{TrainingInfo, WEIGHTS_FILE};
use crate::train::cv::Protocol;
use crate::train::{EpochLog, Hooks, prepare, train};

/// One training run: the flags of `train` (the binary's `train` command is this group).
#[derive(Args, Debug, Clone)]
pub struct TrainJob {
    #[command(flatten)]
    pub data: DataArgs,
    #[command(flatten)]
    pub train: TrainArgs,
    /// Validation dataset (directory, file or lce:... as for --data); the best epoch on it is kept.
    #[arg(long)]
    pub val: Option<DataSource>,
    /// Model name (the card's name).
    #[arg(long)]
    pub name: String,
    /// Output model directory (default models/<name>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Directory for checkpoints and the JSONL log (default runs/<name>).
    #[arg(long)]
    pub run_dir: Option<PathBuf>,
    /// Continue from the checkpoint in the run directory.
    #[arg(long)]
    pub resume: bool,
    /// Start from the weights of this model directory (same architecture) instead of a seeded
    /// initialisation: a warm restart that continues an earlier training with a new schedule.
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// What the data is, for the model card.
    #[arg(long, default_value = "")]
    pub describe: String,
}

impl TrainJob {
    /// The model directory written: `--out`, else `models/<name>`.
    pub fn out_dir(&self) -> PathBuf {
        self.out
            .clone()
            .unwrap_or_else(|| Path::new("models").join(&self.name))
    }

    /// The directory of checkpoints and `train.jsonl`: `--run-dir`, else `runs/<name>`.
    pub fn run_dir(&self) -> PathBuf {
        self.run_dir
            .clone()
            .unwrap_or_else(|| Path::new("runs").join(&self.name))
    }
}

/// What [`run`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Trained {
    pub out: PathBuf,
    pub best_epoch: usize,
    pub seconds: f64,
    /// Stopped by the stop flag before the last epoch.
    pub interrupted: bool,
}

impl fmt::Display for Trained {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "wrote {} (best epoch {}, {:.0} s{})",
            self.out.display(),
            self.best_epoch,
            self.seconds,
            if self.interrupted {
                ", interrupted"
            } else {
                ""
            }
        )
    }
}

/// The epoch bar: `epoch <i>/<epochs> [====>   ] <step>/<steps> eta ...`.
fn progress(len: u64) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} epoch {prefix} [{bar:30}] {pos}/{len} {msg} eta {eta}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar
}

/// One line of the epoch log as the bar prints it.
fn epoch_line(e: &EpochLog) -> String {
    format!(
        "epoch {:>4} loss {:.5} val_err {} lr {:.2e} {:.1}s{}",
        e.epoch,
        e.train_loss,
        e.val_error
            .map_or("-".into(), |v| format!("{:.2}%", 100.0 * v)),
        e.learning_rate,
        e.seconds,
        if e.best { " *" } else { "" }
    )
}

/// Trains the model of `job` and writes its directory; stops cleanly after the current step when
/// `stop` is set, keeping what it has. Everything is checked before training starts.
pub fn run(job: &TrainJob, stop: &AtomicBool) -> Result<Trained, CliError> {
    let seqs = job.data.sequences()?;
    let kind = seqs[0].points.kind();
    let plan = job.train.samples(job.data.clip_len, kind)?;
    if plan.protocol == Protocol::AugmentLeaky {
        return Err(CliError::LeakyTrain);
    }
    let train_samples: Vec<Sample> = seqs.iter().flat_map(|s| plan.train_samples(s)).collect();
    let val_samples = match &job.val {
        Some(p) => {
            let vs = p.sequences(job.data.model_type.as_deref())?;
            vs.iter().filter_map(|s| plan.test_sample(s)).collect()
        }
        None => vec![],
    };
    let input_dim = train_samples
        .first()
        .ok_or(crate::train::TrainError::NoSamples)?
        .points
        .dim();
    let config = job.train.config(input_dim)?;
    check_symmetries("--test-symmetry", &job.train.test_symmetry, kind)?;
    let init = job
        .init
        .as_deref()
        .map(|dir| init_card(dir, &config))
        .transpose()?;
    let (out, run_dir) = (job.out_dir(), job.run_dir());
    let norm = Normalization::for_kind(kind);
    let k = config.model.neighbors;
    let (train_set, val_set) = (
        prepare(&train_samples, norm, k),
        prepare(&val_samples, norm, k),
    );
    std::fs::create_dir_all(&run_dir)?;
    let mut log = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(run_dir.join("train.jsonl"))?;
    eprintln!(
        "training {} on {} samples ({} validation), {} epochs, {:?}",
        job.name,
        train_set.len(),
        val_set.len(),
        config.epochs,
        config.loss
    );
    let bar = progress(train_set.len() as u64);
    let mut on_epoch = |e: &EpochLog| {
        let _ = writeln!(log, "{}", serde_json::to_string(e).unwrap_or_default());
        let _ = log.flush();
        if let Ok(text) = std::fs::read_to_string(run_dir.join("train.jsonl")) {
            let _ = std::fs::write(run_dir.join("train.svg"), curves(&job.name, &text));
        }
        bar.println(epoch_line(e));
        bar.set_prefix(format!("{}/{}", e.epoch + 1, config.epochs));
    };
    let bar2 = bar.clone();
    let mut on_step = |step: usize, total: usize| {
        bar2.set_length(total as u64);
        bar2.set_position(step as u64);
    };
    let hooks = Hooks {
        stop: Some(stop),
        on_epoch: Some(&mut on_epoch),
        on_step: Some(&mut on_step),
        checkpoint: Some(&run_dir),
        resume: job.resume,
        init: init.as_ref().map(|(weights, _)| weights.as_path()),
    };
    let outcome = train(&config, &train_set, &val_set, hooks)?;
    bar.finish_and_clear();
    let data = training_data(
        &job.describe,
        &job.data.sources(),
        seqs.len(),
        train_set.len(),
        &plan,
        init.as_ref().map(|(_, card)| card),
    );
    let info = TrainingInfo {
        data,
        command: command_line(),
        epochs: outcome.history.len(),
        learning_rate: config.learning_rate,
        seed: config.seed,
        seconds: outcome.seconds,
        machine: machine(),
    };
    let mut card = trained_card(
        &job.name,
        kind,
        &config,
        job.train.k_max,
        &job.train.test_symmetry,
        info,
    );
    card.geometry = family_of(&seqs);
    if let Some(v) = outcome.best_val_error {
        let metric =
            validation_metric(v, val_set.len(), outcome.best_epoch, &card.training.command);
        card.metrics.push(metric);
    }
    card.write(&out).map_err(|source| CliError::WriteCard {
        dir: out.clone(),
        source,
    })?;
    outcome.net.save(&out.join(WEIGHTS_FILE))?;
    Ok(Trained {
        out,
        best_epoch: outcome.best_epoch,
        seconds: outcome.seconds,
        interrupted: outcome.interrupted,
    })
}

/// The training curves of a `train.jsonl` log (lines that do not parse are skipped): training
/// loss and validation error (a share, 0..1) against the epoch, counted over the whole log.
pub fn curves(name: &str, log: &str) -> String {
    let epochs: Vec<EpochLog> = log
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect();
    let x = |i: usize| (i + 1) as f64;
    let loss: Vec<(f64, f64)> = epochs
        .iter()
        .enumerate()
        .map(|(i, e)| (x(i), e.train_loss))
        .collect();
    let val: Vec<(f64, f64)> = epochs
        .iter()
        .enumerate()
        .map(|(i, e)| (x(i), e.val_error.unwrap_or(f64::NAN)))
        .collect();
    let mut series: Vec<(&str, &[(f64, f64)])> = vec![("training loss", &loss)];
    if epochs.iter().any(|e| e.val_error.is_some()) {
        series.push(("validation error (known K)", &val));
    }
    crate::render::curves_svg(&format!("{name}: training"), &series)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epoch_lines_and_summary_read_as_before() {
        let mut e = EpochLog {
            epoch: 3,
            learning_rate: 1e-3,
            train_loss: 0.123456,
            val_error: Some(0.0525),
            best: true,
            seconds: 1.26,
            steps: 10,
        };
        assert_eq!(
            epoch_line(&e),
            "epoch    3 loss 0.12346 val_err 5.25% lr 1.00e-3 1.3s *"
        );
        (e.val_error, e.best) = (None, false);
        assert_eq!(
            epoch_line(&e),
            "epoch    3 loss 0.12346 val_err - lr 1.00e-3 1.3s"
        );
        let mut t = Trained {
            out: "models/x".into(),
            best_epoch: 4,
            seconds: 12.6,
            interrupted: false,
        };
        assert_eq!(t.to_string(), "wrote models/x (best epoch 4, 13 s)");
        t.interrupted = true;
        assert_eq!(
            t.to_string(),
            "wrote models/x (best epoch 4, 13 s, interrupted)"
        );
    }

    fn job(dir: &Path, args: &[&str]) -> TrainJob {
        #[derive(clap::Parser)]
        struct Flags {
            #[command(flatten)]
            job: TrainJob,
        }
        let base = [
            "t",
            "--name",
            "tiny",
            "--val",
            "lce:mixed,count=2,seed=9,points=12",
        ];
        let flags: Flags = clap::Parser::try_parse_from(base.iter().chain(args)).unwrap();
        TrainJob {
            out: Some(dir.join("model")),
            run_dir: Some(dir.join("run")),
            ..flags.job
        }
    }

    /// A tiny run writes the card, the weights and a log line per epoch, and refuses what it
    /// cannot train before training.
    #[test]
    fn run_writes_a_model_directory() {
        let tmp = crate::registry::tests::scratch("train-run");
        let data = ["--data", "lce:mixed,count=4,points=12"];
        let tiny = "--width 8 --depth 1 --embed-dim 3 --epochs 2 --test-symmetry mirror";
        let args: Vec<&str> = data.into_iter().chain(tiny.split(' ')).collect();
        let j = job(tmp.path(), &args);
        let trained = run(&j, &AtomicBool::new(false)).unwrap();
        assert_eq!(trained.out, tmp.path().join("model"));
        assert!(!trained.interrupted);
        let card = crate::registry::ModelCard::read(&trained.out).unwrap();
        assert_eq!(card.name, "tiny");
        assert_eq!(card.test_symmetries, [crate::data::Symmetry::Mirror]);
        assert_eq!(card.training.epochs, 2);
        assert!(
            card.training.data.starts_with(
                "lce:mixed,count=4,seed=0,scale=1,noise=0.05,points=12 (4 sequences, 4 training samples,"
            ),
            "{}",
            card.training.data
        );
        assert_eq!(card.metrics.len(), 1);
        assert!(card.metrics[0].protocol.contains("on 2 validation samples"));
        assert!(trained.out.join(WEIGHTS_FILE).is_file());
        let log = std::fs::read_to_string(j.run_dir().join("train.jsonl")).unwrap();
        assert_eq!(log.lines().count(), 2);
        let svg = std::fs::read_to_string(j.run_dir().join("train.svg")).unwrap();
        assert_eq!(svg, curves("tiny", &log));
        assert!(svg.contains("tiny: training") && svg.contains("validation error (known K)"));
        let named = TrainJob {
            out: None,
            run_dir: None,
            ..j.clone()
        };
        assert_eq!(
            (named.out_dir(), named.run_dir()),
            ("models/tiny".into(), "runs/tiny".into())
        );

        let leaky = [data[0], data[1], "--protocol", "augment-leaky"];
        let e = run(&job(tmp.path(), &leaky), &AtomicBool::new(false));
        assert!(matches!(e, Err(CliError::LeakyTrain)));
        let reverse = [data[0], data[1], "--test-symmetry", "reverse"];
        let e = run(&job(tmp.path(), &reverse), &AtomicBool::new(false));
        assert!(e.unwrap_err().to_string().starts_with("--test-symmetry: "));
    }
}
