//! multifit-train: data generation, training, evaluation and cross-validation.
//!
//! The flags only: they are mapped to the job types of [`multifit::train::cli`], whose functions
//! do the work and return what is printed. `train` and `cv` take their flags from those job types
//! (argument groups of the shared `--data` and training flags); the others are declared here.
#![forbid(unsafe_code)]

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Result;
use clap::{Args, Parser, Subcommand};
use multifit::data::Symmetry;
use multifit::data::frames::FrameSampling;
use multifit::data::synthetic::{LceConfig, LceSpec, LceVariant};
use multifit::train::cli::eval::{FrameCount, Switch};
use multifit::train::cli::options::DataArgs;
use multifit::train::cli::{cv, ensemble, eval, gen_lce, gen_scene, robustness, train};
use multifit::train::robustness::GridSettings;

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
    /// Write synthetic multi-body feature tracks (a moving camera, rigid objects) as dataset JSON files.
    GenMotion(gen_scene::GenMotionJob),
    /// Write synthetic two-view correspondences (planes or rigid motions) as dataset JSON files.
    GenTwoview(gen_scene::GenTwoViewJob),
    /// Train one model and write its directory (weights + model.json).
    Train(Box<train::TrainJob>),
    /// Evaluate a model directory on a dataset.
    Eval(EvalCmd),
    /// Leave-one-sequence-out cross-validation.
    Cv(CvCmd),
    /// Combine trained models into one that clusters all their embeddings side by side.
    Ensemble(EnsembleCmd),
    /// Give a model a second network that reads the sets sparser than its training sets.
    Sparse(SparseCmd),
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
    /// Whether refinement's hypotheses stage runs (models proposed from neighbourhoods of the
    /// input may replace learned structures; default on).
    #[arg(long, value_enum)]
    hypotheses: Option<Switch>,
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
struct SparseCmd {
    /// The model directory (it must record its training spacing).
    #[arg(long)]
    model: PathBuf,
    /// The model directory of the network for sparse sets (a single network of the same
    /// architecture).
    #[arg(long)]
    network: PathBuf,
    /// Sets whose spacing exceeds this multiple of the training spacing are read by it (>= 1).
    #[arg(long)]
    above: f64,
    /// Output model directory.
    #[arg(long)]
    out: PathBuf,
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
    /// With refinement: whether models proposed from neighbourhoods of the input may replace
    /// learned structures (default on; never for motion subspaces).
    #[arg(long, value_enum)]
    hypotheses: Option<Switch>,
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
    /// Write the picture of every sample's fit (SVG) to this directory, worst first, with an
    /// index.html.
    #[arg(long)]
    pictures: Option<PathBuf>,
    /// Refine from each sample's true groups instead of the network's clustering (with
    /// --refine on): what the geometric stage gives a perfect network.
    #[arg(long)]
    refine_from_truth: bool,
}

/// `cv`: the job's flags, and how to print the summary.
#[derive(Args, Debug)]
struct CvCmd {
    #[command(flatten)]
    job: cv::CvJob,
    #[arg(long)]
    json: bool,
}

/// Runs one command -> what it prints on standard output.
fn run(command: Command) -> Result<String> {
    fn line(text: impl std::fmt::Display) -> String {
        format!("{text}\n")
    }
    Ok(match command {
        Command::GenLce(a) => {
            let (points_per_shape, points_max) = gen_lce::points_per_shape(&a.points_per_shape)?;
            let config = LceConfig {
                points_per_shape,
                points_max,
                arc: gen_lce::arc(a.arc.as_deref())?,
                noise: a.noise,
                scale: a.scale,
                outliers: a.outliers,
                similarity: a.similarity,
            };
            let spec = LceSpec {
                variant: a.variant,
                count: a.count,
                seed: a.seed,
                config,
            };
            line(gen_lce::write(&spec, &a.out)?)
        }
        Command::GenMotion(job) => line(job.run()?),
        Command::GenTwoview(job) => line(job.run()?),
        Command::Train(job) => line(train::run(&job, &STOP)?),
        Command::Eval(a) => {
            let job = eval::EvalJob {
                model: a.model,
                data: a.data,
                k_max: a.k_max,
                restarts: a.restarts,
                seed: a.seed,
                record: a.record,
                test_symmetry: a.test_symmetry,
                refine: a.refine,
                outliers: a.outliers,
                hypotheses: a.hypotheses,
                frames: a.frames,
                stride: a.stride as usize,
                frame_sampling: a.frame_sampling,
                pictures: a.pictures,
                refine_from_truth: a.refine_from_truth,
            };
            let evaluated = eval::run(&job)?;
            let output = evaluated.output(a.json)?;
            evaluated.record()?;
            output
        }
        Command::Cv(a) => match cv::run(&a.job, &STOP)? {
            Some(summary) => summary.output(a.json)?,
            None => String::new(),
        },
        Command::Ensemble(a) => line(ensemble::run(&a.models, &a.out, a.name.as_deref())?),
        Command::Sparse(a) => line(ensemble::run_sparse(&a.model, &a.network, a.above, &a.out)?),
        Command::Robustness(a) => {
            let settings = GridSettings {
                sets: a.sets,
                draws: a.draws,
                seed: a.seed,
                restarts: a.restarts,
                k_max: a.k_max,
                cells: a.cells,
                data: a.data,
                model_type: a.model_type,
                hypotheses: a.hypotheses != Some(Switch::Off),
            };
            line(robustness::run(
                &a.model,
                a.folds.as_deref(),
                &settings,
                &a.out,
            )?)
        }
    })
}

/// Writes a command's output; a reader that went away (`| head`) ends the output quietly, as
/// it does for other command-line tools, instead of a panic. -> whether every byte was written
/// or the reader left.
fn emit(text: &str) -> bool {
    use std::io::{ErrorKind, Write};
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => true,
        Err(e) if e.kind() == ErrorKind::BrokenPipe => true,
        Err(e) => {
            eprintln!("error: writing the output: {e}");
            false
        }
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let _ = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!("stopping after the current step (Ctrl-C again to quit at once)");
    });
    match run(cli.command) {
        Ok(text) if emit(&text) => ExitCode::SUCCESS,
        Ok(_) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
