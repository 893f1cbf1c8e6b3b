//! multifit-train: data generation, training, evaluation and cross-validation.
#![forbid(unsafe_code)]

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use multifit::data::frames::FrameSampling;
use multifit::data::synthetic::{LceConfig, LceSpec, LceVariant, parse_range};
use multifit::data::{DataSource, Kind, Normalization, Sample, Sequence, Symmetry};
use multifit::loss::Loss;
use multifit::model::ModelConfig;
use multifit::refine::RefineParams;
use multifit::registry::{
    LoadedModel, MetricRecord, ModelCard, TrainingInfo, WEIGHTS_FILE, card_for, write_ensemble,
};
use multifit::train::cv::{self, CvSpec, Protocol, SamplePlan};
use multifit::train::eval::{EvalSettings, evaluate_sample, format_table, totals};
use multifit::train::{EpochLog, Hooks, Schedule, TrainConfig, prepare, train};

static STOP: AtomicBool = AtomicBool::new(false);

/// Train, evaluate and cross-validate multifit models.
#[derive(Parser, Debug)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Write synthetic LCE / LCE-Unmixed samples as dataset JSON files.
    GenLce(GenLceArgs),
    /// Train one model and write its directory (weights + model.json).
    Train(TrainCmd),
    /// Evaluate a model directory on a dataset.
    Eval(EvalCmd),
    /// Leave-one-sequence-out cross-validation.
    Cv(CvCmd),
    /// Combine trained models into one that clusters all their embeddings side by side.
    Ensemble(EnsembleCmd),
    /// The robustness grid: a model evaluated on inputs that drift from its training data
    /// (density, scale, structure mix, arcs, outliers, similarity; subsampling, rescaling;
    /// frame strides), written as a Markdown table and JSON.
    Robustness(RobustnessCmd),
}

#[derive(Args, Debug)]
struct RobustnessCmd {
    /// Model directory.
    #[arg(long)]
    model: PathBuf,
    /// Output directory (robustness.md, robustness.json).
    #[arg(long)]
    out: PathBuf,
    /// Generated samples per points2d cell (the paper-protocol cell keeps its 200).
    #[arg(long, default_value_t = multifit::train::robustness::GridSettings::DEFAULT_SETS)]
    sets: usize,
    /// Seeded draws per sequence in the random real-data cells (subsampling, added outliers).
    #[arg(long, default_value_t = 3)]
    draws: usize,
    /// Seed of the generated data and of the draws.
    #[arg(long, default_value_t = multifit::train::robustness::GridSettings::DEFAULT_SEED)]
    seed: u64,
    #[arg(long, default_value_t = 4)]
    restarts: usize,
    /// Largest K for automatic selection (default: the card's).
    #[arg(long)]
    k_max: Option<usize>,
    /// Run only these cells (comma-separated names; default: all).
    #[arg(long, value_delimiter = ',')]
    cells: Vec<String>,
    /// Dataset directory for correspondence and trajectory models (default:
    /// ../shared/datasets/adelaidermf or ../shared/datasets/kt3dmoseg).
    #[arg(long)]
    data: Option<PathBuf>,
    /// AdelaideRMF model type (homography or fundamental; default: from the model's name).
    #[arg(long)]
    model_type: Option<String>,
    /// Score each real sequence with its leave-one-out fold model, <FOLDS>/models/<sequence>/
    /// (a `cv --out` directory), instead of the shipped model.
    #[arg(long)]
    folds: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct EnsembleCmd {
    /// Model directory (repeatable, at least two; the first one's card is the ensemble's).
    #[arg(long = "model", required = true)]
    models: Vec<PathBuf>,
    /// Output model directory.
    #[arg(long)]
    out: PathBuf,
    /// The ensemble's name (default: the output directory's name).
    #[arg(long)]
    name: Option<String>,
}

#[derive(Args, Debug)]
struct GenLceArgs {
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// Number of samples.
    #[arg(long, default_value_t = 200)]
    count: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// mixed (line, 2 ellipses, circle), unmixed (2-4 of one type) or random (2-6 of random
    /// types).
    #[arg(long, value_enum, default_value = "mixed")]
    variant: LceVariant,
    /// Points per structure: N, or MIN-MAX to draw each structure's count in that range.
    #[arg(long, default_value = "50")]
    points_per_shape: String,
    /// Gaussian noise sigma on the unit-scale frame.
    #[arg(long, default_value_t = 0.05, allow_negative_numbers = true)]
    noise: f64,
    /// Multiplies every shape length but not the noise (2 = half the relative noise).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    scale: f64,
    /// Circles and ellipses as partial arcs: span in degrees, MIN-MAX (or one value), within
    /// (0, 360] (default: whole shapes).
    #[arg(long)]
    arc: Option<String>,
    /// Gross outliers as a share of the inliers, in [0, 1): uniform over the bounding box,
    /// label 0.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    outliers: f64,
    /// Apply a random similarity (rotation, scale, translation) to every sample.
    #[arg(long)]
    similarity: bool,
}

/// Data selection shared by train, eval and cv.
#[derive(Args, Debug, Clone)]
struct DataArgs {
    /// Dataset directory or file, or LCE samples generated in memory:
    /// lce:<mixed|unmixed|random>[,count=N][,seed=S][,scale=X][,noise=X][,points=N|MIN-MAX]
    /// [,arc=MIN-MAX][,outliers=R][,similarity=true] (what gen-lce would write with the same
    /// settings; defaults 200 samples, seed 0, scale 1, noise 0.05, 50 points per shape, whole
    /// shapes, no outliers, no similarity). Repeatable.
    #[arg(long, required = true)]
    data: Vec<DataSource>,
    /// Keep only AdelaideRMF sequences of this model type (homography or fundamental).
    #[arg(long)]
    model_type: Option<String>,
    /// Frames per trajectory clip.
    #[arg(long, default_value_t = 5)]
    clip_len: usize,
}

/// Model and optimisation settings shared by train and cv.
#[derive(Args, Debug, Clone)]
struct TrainArgs {
    /// l2, ce or mimi.
    #[arg(long, default_value = "mimi")]
    loss: String,
    /// MIMI's weight of the inter-cluster term.
    #[arg(long, default_value_t = 0.6)]
    alpha: f64,
    #[arg(long, default_value_t = 128)]
    width: usize,
    #[arg(long, default_value_t = 12)]
    depth: usize,
    /// Embedding dimension E (the paper: the largest number of structures).
    #[arg(long, default_value_t = 6)]
    embed_dim: usize,
    /// BatchNorm after Context Normalization (CNe).
    #[arg(long)]
    batch_norm: bool,
    /// Append offsets to this many nearest neighbours to every point (0 = the paper's input).
    #[arg(long, default_value_t = 0)]
    neighbors: usize,
    /// Graph aggregation in every block over this many nearest points, itself included
    /// (0 = the paper's network).
    #[arg(long, default_value_t = 0)]
    graph_neighbors: usize,
    #[arg(long, default_value_t = 1e-3)]
    lr: f64,
    #[arg(long, value_enum, default_value = "cosine")]
    schedule: ScheduleArg,
    #[arg(long, default_value_t = 100)]
    epochs: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Sets per step when they have equal size.
    #[arg(long, default_value_t = 1)]
    batch_size: usize,
    /// Gaussian jitter sigma on normalised training inputs (0 = off).
    #[arg(long, default_value_t = 0.0)]
    jitter: f64,
    /// Protocol for trajectory data: vanilla (first clip) or augment (all non-overlapping clips);
    /// augment-leaky (cv only) also trains each fold on its held-out sequence's later clips, as
    /// the authors' code does: a diagnostic, not an honest protocol.
    #[arg(long, value_enum, default_value = "vanilla")]
    protocol: Protocol,
    /// Augment protocol: frames between the starts of two clips (default: the clip length, the
    /// paper's non-overlapping clips; 1 = every clip).
    #[arg(long)]
    clip_stride: Option<usize>,
    /// Add the images of every training sample under these symmetries (comma-separated:
    /// mirror, reverse, rotate); every combination is added (mirror and reverse: four copies;
    /// rotate counts its three quarter turns).
    #[arg(long, value_enum, value_delimiter = ',')]
    symmetry: Vec<Symmetry>,
    /// Test-time symmetries stored in the card: fits embed the input and its images under these
    /// (comma-separated: mirror, reverse, rotate) and cluster the concatenated embeddings.
    #[arg(long, value_enum, value_delimiter = ',')]
    test_symmetry: Vec<Symmetry>,
    /// Largest K for automatic selection (stored in the card).
    #[arg(long, default_value_t = 8)]
    k_max: usize,
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum ScheduleArg {
    Constant,
    Cosine,
}

#[derive(Args, Debug)]
struct TrainCmd {
    #[command(flatten)]
    data: DataArgs,
    #[command(flatten)]
    train: TrainArgs,
    /// Validation dataset (directory, file or lce:... as for --data); the best epoch on it is kept.
    #[arg(long)]
    val: Option<DataSource>,
    /// Model name (the card's name).
    #[arg(long)]
    name: String,
    /// Output model directory (default models/<name>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Directory for checkpoints and the JSONL log (default runs/<name>).
    #[arg(long)]
    run_dir: Option<PathBuf>,
    /// Continue from the checkpoint in the run directory.
    #[arg(long)]
    resume: bool,
    /// Start from the weights of this model directory (same architecture) instead of a seeded
    /// initialisation: a warm restart that continues an earlier training with a new schedule.
    #[arg(long)]
    init: Option<PathBuf>,
    /// What the data is, for the model card.
    #[arg(long, default_value = "")]
    describe: String,
}

#[derive(Args, Debug)]
struct EvalCmd {
    /// Model directory.
    #[arg(long)]
    model: PathBuf,
    #[command(flatten)]
    data: DataArgs,
    #[arg(long, default_value_t = 8)]
    k_max: usize,
    #[arg(long, default_value_t = 4)]
    restarts: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Record the known-K mean error in the model card under this metric name.
    #[arg(long)]
    record: Option<String>,
    /// Evaluate with these test-time symmetries instead of the card's (comma-separated: mirror,
    /// reverse, rotate; the flag alone: none).
    #[arg(long, value_enum, value_delimiter = ',', num_args = 0..)]
    test_symmetry: Option<Vec<Symmetry>>,
    /// Score the geometric refinement (outliers as one group) or the clustering alone; default:
    /// the card's.
    #[arg(long, value_enum)]
    refine: Option<Switch>,
    /// With refinement: whether points may be labelled outliers (−1); default: the card's.
    #[arg(long, value_enum)]
    outliers: Option<Switch>,
    /// Trajectories: frames per test clip (a number >= 2, or `all`: every frame of the sequence,
    /// on the tracks visible throughout); default: the model's.
    #[arg(long)]
    frames: Option<FrameCount>,
    /// Trajectories: take every `stride`-th frame for the test clip (faster apparent motion).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    stride: u64,
    /// Trajectories: which frames of a clip of another length the network reads, instead of the
    /// card's.
    #[arg(long, value_enum)]
    frame_sampling: Option<FrameSampling>,
}

/// On or off.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Switch {
    On,
    Off,
}

/// A number of frames, or every frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FrameCount {
    N(usize),
    All,
}

impl std::str::FromStr for FrameCount {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "all" => Ok(FrameCount::All),
            _ => match s.parse::<usize>() {
                Ok(n) if n >= 2 => Ok(FrameCount::N(n)),
                _ => Err(format!("{s:?} is not `all` or a number of frames >= 2")),
            },
        }
    }
}

#[derive(Args, Debug)]
struct CvCmd {
    #[command(flatten)]
    data: DataArgs,
    #[command(flatten)]
    train: TrainArgs,
    /// Output directory (folds/<name>.json, summary.json).
    #[arg(long)]
    out: PathBuf,
    /// Folds trained at once, each in its own one-thread process.
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// Run only this fold (used by --jobs; also handy by hand).
    #[arg(long)]
    fold: Option<String>,
    #[arg(long, default_value_t = 4)]
    restarts: usize,
    #[arg(long)]
    json: bool,
}

impl TrainArgs {
    /// The validated sample plan for sequences of `kind`.
    fn samples(&self, clip_len: usize, kind: Kind) -> Result<SamplePlan> {
        check_symmetries("--symmetry", &self.symmetry, kind)?;
        let plan = SamplePlan {
            protocol: self.protocol,
            clip_len,
            clip_stride: self.clip_stride.unwrap_or(clip_len),
            symmetries: self.symmetry.clone(),
        };
        plan.validate()?;
        Ok(plan)
    }

    fn config(&self, input_dim: usize) -> Result<TrainConfig> {
        let loss = Loss::parse(&self.loss, self.alpha)
            .with_context(|| format!("unknown loss {:?} (l2, ce, mimi)", self.loss))?;
        let config = TrainConfig {
            model: ModelConfig {
                input_dim,
                width: self.width,
                depth: self.depth,
                embed_dim: self.embed_dim,
                batch_norm: self.batch_norm,
                cn_epsilon: 1e-3,
                neighbors: self.neighbors,
                graph_neighbors: self.graph_neighbors,
            },
            loss,
            learning_rate: self.lr,
            schedule: match self.schedule {
                ScheduleArg::Constant => Schedule::Constant,
                ScheduleArg::Cosine => Schedule::Cosine,
            },
            epochs: self.epochs,
            seed: self.seed,
            batch_size: self.batch_size,
            jitter: self.jitter,
        };
        config.validate()?;
        Ok(config)
    }
}

impl DataArgs {
    fn sequences(&self) -> Result<Vec<Sequence>> {
        let mut all = Vec::new();
        for source in &self.data {
            all.extend(source.sequences(self.model_type.as_deref())?);
        }
        let kind = all[0].points.kind();
        if let Some(s) = all.iter().find(|s| s.points.kind() != kind) {
            bail!(
                "{}: kind {} differs from {} of the other sequences",
                s.name,
                s.points.kind(),
                kind
            );
        }
        Ok(all)
    }
}

fn command_line() -> String {
    std::env::args().collect::<Vec<_>>().join(" ")
}

fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    format!("{cores} cores, {cpu}")
}

fn git_commit() -> Option<String> {
    let out = std::process::Command::new("git")
        .args(["rev-parse", "--short", "HEAD"])
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

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

fn gen_lce(a: GenLceArgs) -> Result<()> {
    let (points_per_shape, points_max) = parse_range::<usize>(&a.points_per_shape)
        .map_err(|e| anyhow::anyhow!("--points-per-shape {}: {e}", a.points_per_shape))?;
    let arc = match &a.arc {
        Some(text) => {
            let (lo, hi) =
                parse_range::<f64>(text).map_err(|e| anyhow::anyhow!("--arc {text}: {e}"))?;
            Some([lo, hi.unwrap_or(lo)])
        }
        None => None,
    };
    let spec = LceSpec {
        variant: a.variant,
        count: a.count,
        seed: a.seed,
        config: LceConfig {
            points_per_shape,
            noise: a.noise,
            scale: a.scale,
            points_max,
            arc,
            outliers: a.outliers,
            similarity: a.similarity,
        },
    };
    spec.config
        .validate()
        .map_err(|e| anyhow::anyhow!(e.for_flag()))?;
    if spec.validate().is_err() {
        bail!(
            "--count {}: count must be 1 to {}",
            a.count,
            LceSpec::MAX_COUNT
        );
    }
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("{}: cannot create", a.out.display()))?;
    for file in spec.files() {
        let path = a.out.join(format!("{}.json", file.name));
        let text = serde_json::to_string(&file)?;
        std::fs::write(&path, text).with_context(|| format!("{}: cannot write", path.display()))?;
    }
    println!(
        "wrote {} {} samples to {}",
        a.count,
        spec.variant.tag(),
        a.out.display()
    );
    Ok(())
}

fn train_cmd(a: TrainCmd) -> Result<()> {
    let seqs = a.data.sequences()?;
    let kind = seqs[0].points.kind();
    let plan = a.train.samples(a.data.clip_len, kind)?;
    if plan.protocol == Protocol::AugmentLeaky {
        bail!(
            "--protocol augment-leaky is a cross-validation diagnostic (cv only); train has no held-out sequence"
        );
    }
    let train_samples: Vec<Sample> = seqs.iter().flat_map(|s| plan.train_samples(s)).collect();
    let val_samples = match &a.val {
        Some(p) => {
            let vs = p.sequences(a.data.model_type.as_deref())?;
            vs.iter().filter_map(|s| plan.test_sample(s)).collect()
        }
        None => vec![],
    };
    let input_dim = train_samples
        .first()
        .context("no training samples")?
        .points
        .dim();
    let config = a.train.config(input_dim)?;
    check_symmetries("--test-symmetry", &a.train.test_symmetry, kind)?;
    let init = a
        .init
        .as_deref()
        .map(|dir| init_card(dir, &config))
        .transpose()?;
    let norm = Normalization::for_kind(kind);
    let k = config.model.neighbors;
    let (train_set, val_set) = (
        prepare(&train_samples, norm, k),
        prepare(&val_samples, norm, k),
    );
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| Path::new("models").join(&a.name));
    let run_dir = a
        .run_dir
        .clone()
        .unwrap_or_else(|| Path::new("runs").join(&a.name));
    std::fs::create_dir_all(&run_dir)?;
    let log_path = run_dir.join("train.jsonl");
    let mut log = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&log_path)?;
    eprintln!(
        "training {} on {} samples ({} validation), {} epochs, {:?}",
        a.name,
        train_set.len(),
        val_set.len(),
        config.epochs,
        config.loss
    );
    let bar = progress(train_set.len() as u64);
    let mut on_epoch = |e: &EpochLog| {
        use std::io::Write;
        let _ = writeln!(log, "{}", serde_json::to_string(e).unwrap_or_default());
        bar.println(format!(
            "epoch {:>4} loss {:.5} val_err {} lr {:.2e} {:.1}s{}",
            e.epoch,
            e.train_loss,
            e.val_error
                .map_or("-".into(), |v| format!("{:.2}%", 100.0 * v)),
            e.learning_rate,
            e.seconds,
            if e.best { " *" } else { "" }
        ));
        bar.set_prefix(format!("{}/{}", e.epoch + 1, config.epochs));
    };
    let bar2 = bar.clone();
    let mut on_step = |step: usize, total: usize| {
        bar2.set_length(total as u64);
        bar2.set_position(step as u64);
    };
    let hooks = Hooks {
        stop: Some(&STOP),
        on_epoch: Some(&mut on_epoch),
        on_step: Some(&mut on_step),
        checkpoint: Some(&run_dir),
        resume: a.resume,
        init: init.as_ref().map(|(weights, _)| weights.as_path()),
    };
    let outcome = train(&config, &train_set, &val_set, hooks)?;
    bar.finish_and_clear();
    let data = if a.describe.is_empty() {
        format!(
            "{} ({} sequences, {} training samples, {})",
            a.data
                .data
                .iter()
                .map(|p| p.to_string())
                .collect::<Vec<_>>()
                .join(", "),
            seqs.len(),
            train_set.len(),
            plan.describe()
        )
    } else {
        a.describe.clone()
    };
    let data = match &init {
        // The parent's own description nests, so a chain of warm restarts reads whole.
        Some((_, from)) => format!(
            "{data}; warm-started from the model {} ({} epochs, {:.0} s; its data: {})",
            from.name, from.training.epochs, from.training.seconds, from.training.data
        ),
        None => data,
    };
    let info = TrainingInfo {
        data,
        command: command_line(),
        epochs: outcome.history.len(),
        learning_rate: config.learning_rate,
        seed: config.seed,
        seconds: outcome.seconds,
        machine: machine(),
    };
    let mut card = card_for(
        &a.name,
        kind,
        &config.model,
        config.loss,
        a.train.k_max,
        info,
    );
    card.test_symmetries = a.train.test_symmetry.clone();
    card.git_commit = git_commit();
    if let Some(v) = outcome.best_val_error {
        card.metrics.push(MetricRecord {
            name: "validation_error_known_k".into(),
            value: v,
            protocol: format!(
                "mean error rate with known K on {} validation samples, best epoch {}",
                val_set.len(),
                outcome.best_epoch
            ),
            command: card.training.command.clone(),
        });
    }
    card.write(&out)
        .with_context(|| format!("{}: cannot write the card", out.display()))?;
    outcome.net.save(&out.join(WEIGHTS_FILE))?;
    println!(
        "wrote {} (best epoch {}, {:.0} s{})",
        out.display(),
        outcome.best_epoch,
        outcome.seconds,
        if outcome.interrupted {
            ", interrupted"
        } else {
            ""
        }
    );
    Ok(())
}

/// The weights file and card of the `--init` model, checked against the architecture to train.
fn init_card(dir: &Path, config: &TrainConfig) -> Result<(PathBuf, ModelCard)> {
    let card = ModelCard::read(dir)?;
    if !card.members.is_empty() {
        bail!(
            "{}: --init needs a single network; this model is an ensemble of {}",
            dir.display(),
            card.members.len() + 1
        );
    }
    if card.architecture != config.model {
        bail!(
            "{}: --init needs the same architecture as the flags give; the model has {:?}, the flags {:?}",
            dir.display(),
            card.architecture,
            config.model
        );
    }
    Ok((dir.join(WEIGHTS_FILE), card))
}

/// The test sample of every sequence: trajectories cut to the first `frames` frames taken every
/// `stride`-th (all of them: as many as the sequence has).
fn eval_samples(seqs: &[Sequence], frames: FrameCount, stride: usize) -> Vec<Sample> {
    seqs.iter()
        .filter_map(|s| match s.points.kind() {
            Kind::Trajectories => {
                let len = match frames {
                    FrameCount::N(n) => n,
                    FrameCount::All => (s.frames() - 1) / stride + 1,
                };
                if len == s.frames() && stride == 1 && s.visible.is_none() {
                    Some(s.sample())
                } else {
                    s.clip_every(0, len, stride)
                }
            }
            _ => Some(s.sample()),
        })
        .collect()
}

fn eval_cmd(a: EvalCmd) -> Result<()> {
    let mut model = LoadedModel::load(&a.model)?;
    if let Some(list) = a.test_symmetry {
        if a.record.is_some() {
            bail!(
                "--record stores a metric of the model as served, with its card's test symmetries: drop --test-symmetry"
            );
        }
        check_symmetries("--test-symmetry", &list, model.card.kind)?;
        model.card.test_symmetries = list;
    }
    let seqs = a.data.sequences()?;
    if let Some(sampling) = a.frame_sampling {
        model.card.frames = sampling;
    }
    let frames = a.frames.unwrap_or(FrameCount::N(model.card.input_dim / 2));
    let samples = eval_samples(&seqs, frames, a.stride as usize);
    if samples.is_empty() {
        bail!(
            "no sequence has a test clip of {frames:?} frames at stride {}",
            a.stride
        );
    }
    let refine = a.refine.map_or(model.card.refine, |r| r == Switch::On);
    if a.record.is_some() && (refine != model.card.refine || a.frames.is_some() || a.stride != 1) {
        bail!(
            "--record stores a metric of the model as served: drop --refine, --frames and --stride"
        );
    }
    let settings = EvalSettings {
        k_max: a.k_max,
        restarts: a.restarts,
        seed: a.seed,
        refine: refine.then(|| RefineParams {
            outliers: a.outliers.map_or(model.card.outliers, |o| o == Switch::On),
            threshold: None,
        }),
    };
    let mut rows = Vec::new();
    for s in &samples {
        rows.push(
            evaluate_sample(&model, s, &settings).with_context(|| format!("sample {}", s.name))?,
        );
    }
    let t = totals(&rows);
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({ "rows": rows, "totals": t }))?
        );
    } else {
        print!("{}", format_table(&rows));
    }
    if let Some(name) = a.record {
        let mut card = model.card.clone();
        card.metrics.retain(|m| {
            m.name != name && m.name != format!("{name}_nmi") && m.name != format!("{name}_sod")
        });
        let protocol = format!(
            "{} samples from {}",
            rows.len(),
            a.data
                .data
                .iter()
                .map(|p| p.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
        for (suffix, value) in [
            ("", t.known.mean_error),
            ("_nmi", t.known.mean_nmi),
            ("_sod", t.sod.mean_error),
        ] {
            card.metrics.push(MetricRecord {
                name: format!("{name}{suffix}"),
                value,
                protocol: protocol.clone(),
                command: command_line(),
            });
        }
        card.write(&a.model)?;
    }
    Ok(())
}

fn robustness_cmd(a: RobustnessCmd) -> Result<()> {
    use multifit::train::robustness::{self, GridSettings};
    let settings = GridSettings {
        sets: a.sets,
        draws: a.draws,
        seed: a.seed,
        restarts: a.restarts,
        k_max: a.k_max,
        cells: a.cells,
        data: a.data,
        model_type: a.model_type,
    };
    let mut on_cell = |c: &robustness::CellResult| {
        eprintln!(
            "{:<16} {:>4} samples  known K {:>6.2} / {:>6.2} %  chosen K {:>6.2} % ({:>5.1} % K right)  {:>5.0} s",
            c.name,
            c.samples,
            100.0 * c.known.mean_error,
            100.0 * c.known.median_error,
            100.0 * c.chosen.mean_error,
            100.0 * c.chosen.k_correct,
            c.seconds
        );
    };
    let mut report = robustness::run(&a.model, a.folds.as_deref(), &settings, &mut on_cell)?;
    report.command = command_line();
    robustness::write(&report, &a.out)
        .with_context(|| format!("{}: cannot write the report", a.out.display()))?;
    println!(
        "wrote {} and robustness.json ({} cells, {:.0} s)",
        a.out.join("robustness.md").display(),
        report.cells.len(),
        report.seconds
    );
    Ok(())
}

fn ensemble_cmd(a: EnsembleCmd) -> Result<()> {
    let name = match a.name {
        Some(n) => n,
        None => a
            .out
            .file_name()
            .and_then(|n| n.to_str())
            .context("--out has no directory name to take as the ensemble's: give --name")?
            .to_string(),
    };
    let card = write_ensemble(&a.models, &a.out, &name)?;
    println!(
        "wrote {} ({} networks)",
        a.out.display(),
        card.members.len() + 1
    );
    Ok(())
}

fn cv_cmd(a: CvCmd) -> Result<()> {
    let seqs = a.data.sequences()?;
    let kind = seqs[0].points.kind();
    let samples = a.train.samples(a.data.clip_len, kind)?;
    let input_dim = samples
        .test_sample(&seqs[0])
        .context("no test sample")?
        .points
        .dim();
    check_symmetries("--test-symmetry", &a.train.test_symmetry, kind)?;
    let spec = CvSpec {
        train: a.train.config(input_dim)?,
        samples,
        test_symmetries: a.train.test_symmetry.clone(),
        eval: EvalSettings {
            k_max: a.train.k_max,
            restarts: a.restarts,
            seed: 0,
            refine: None,
        },
        out: a.out.clone(),
    };
    std::fs::create_dir_all(&a.out)?;
    std::fs::write(
        a.out.join("spec.json"),
        serde_json::to_string_pretty(&serde_json::json!({
            "command": command_line(), "train": spec.train, "samples": spec.samples,
        }))?,
    )?;
    let names: Vec<String> = seqs.iter().map(|s| s.name.clone()).collect();
    if let Some(fold) = &a.fold {
        let i = names
            .iter()
            .position(|n| n == fold)
            .with_context(|| format!("no sequence named {fold}"))?;
        let r = cv::run_fold(&spec, &seqs, i)?;
        eprintln!(
            "fold {fold}: error {:.2}% (known K), {:.0} s",
            100.0 * r.row.known.error,
            r.train_seconds
        );
        return Ok(());
    }
    if a.jobs > 1 {
        let exe = std::env::current_exe()?;
        let args: Vec<String> = std::env::args()
            .skip(1)
            .filter(|x| !x.starts_with("--jobs="))
            .collect();
        let args = strip_flag_value(args, "--jobs");
        let failed = cv::run_in_processes(&exe, &args, &a.out, &names, a.jobs)?;
        if !failed.is_empty() {
            bail!("folds failed: {failed:?} (rerun to retry them; finished folds are kept)");
        }
    } else {
        for (i, name) in names.iter().enumerate() {
            if STOP.load(Ordering::Relaxed) {
                bail!(
                    "interrupted; finished folds are kept in {}",
                    a.out.display()
                );
            }
            let r = cv::run_fold(&spec, &seqs, i)?;
            eprintln!(
                "fold {name}: error {:.2}% (known K), {:.0} s",
                100.0 * r.row.known.error,
                r.train_seconds
            );
        }
    }
    let folds: Vec<cv::FoldResult> = names
        .iter()
        .filter_map(|n| cv::finished_fold(&a.out, n))
        .collect();
    let rows: Vec<_> = folds.iter().map(|f| f.row.clone()).collect();
    let t = totals(&rows);
    let train_seconds: f64 = folds.iter().map(|f| f.train_seconds).sum();
    std::fs::write(
        a.out.join("summary.json"),
        serde_json::to_string_pretty(&serde_json::json!({
            "totals": t, "rows": rows, "train_seconds_total": train_seconds,
        }))?,
    )?;
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({ "totals": t, "rows": rows }))?
        );
    } else {
        print!("{}", format_table(&rows));
        println!("training time, all folds: {train_seconds:.0} s");
    }
    Ok(())
}

/// Refuses symmetries that are repeated or have no image for `kind` (reverse for points2d),
/// rather than skipping them silently.
fn check_symmetries(flag: &str, list: &[Symmetry], kind: Kind) -> Result<()> {
    multifit::data::symmetry::check(list, kind).map_err(|e| anyhow::anyhow!("{flag}: {e}"))
}

/// Removes `flag VALUE` pairs (the `--flag=VALUE` form is removed by the caller's filter).
fn strip_flag_value(args: Vec<String>, flag: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut skip = false;
    for a in args {
        if skip {
            skip = false;
            continue;
        }
        if a == flag {
            skip = true;
            continue;
        }
        out.push(a);
    }
    out
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let _ = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!("stopping after the current step (Ctrl-C again to quit at once)");
    });
    let result = match cli.command {
        Command::GenLce(a) => gen_lce(a),
        Command::Train(a) => train_cmd(a),
        Command::Eval(a) => eval_cmd(a),
        Command::Cv(a) => cv_cmd(a),
        Command::Ensemble(a) => ensemble_cmd(a),
        Command::Robustness(a) => robustness_cmd(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
