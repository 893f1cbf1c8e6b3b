//! The commands of `multifit-train` as library functions: the binary parses flags, maps them to
//! the job types here and calls them, so that tests can run a command without a process.
//!
//! | module | holds |
//! |---|---|
//! | [`options`] | the flag groups train, eval and cv share, and their checks |
//! | [`provenance`] | the command line, machine and commit recorded with results |
//! | [`card`] | model cards of trained models: `--init`, descriptions, metrics |
//! | [`gen_lce`] | `gen-lce`: synthetic samples written as dataset files |
//! | [`gen_scene`] | `gen-motion`, `gen-twoview`: synthetic tracks and correspondences, likewise |
//! | [`train`] | `train`: one model directory, with its log and progress bar |
//! | [`eval`] | `eval`: a model scored on a dataset, optionally recorded in its card |
//! | [`pictures`] | `eval --pictures`: every evaluated fit drawn, worst first, with an index |
//! | [`cv`] | `cv`: the folds, in this process or fanned out, and their summary |
//! | [`ensemble`] | `ensemble`: trained models combined into one |
//! | [`robustness`] | `robustness`: the grid run, reported and written |
//!
//! Flags: the groups of [`options`] and the jobs of `train` and `cv` ([`train::TrainJob`],
//! [`cv::CvJob`], made of those groups) are `clap` argument groups that the binary flattens; the
//! other commands' flags are declared by the binary and mapped to the types here.
//!
//! Commands write progress to standard error as they go and return what the binary prints on
//! standard output. Every error is a [`CliError`], whose message (with its sources, as
//! `{:#}` of an `anyhow::Error` joins them) is what the command line shows.

pub mod card;
pub mod cv;
pub mod ensemble;
pub mod eval;
pub mod gen_lce;
pub mod gen_scene;
pub mod options;
pub mod pictures;
pub mod provenance;
pub mod robustness;
pub mod train;

use std::path::PathBuf;

use crate::data::{DataError, Kind};
use crate::model::ModelError;
use crate::pipeline::FitError;
use crate::registry::RegistryError;
use crate::train::TrainError;
use crate::train::robustness::RobustnessError;
use eval::FrameCount;

/// Why a command stopped. Messages name the flag, file or sample at fault.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    #[error(transparent)]
    Data(#[from] DataError),
    #[error(transparent)]
    Train(#[from] TrainError),
    #[error(transparent)]
    Registry(#[from] RegistryError),
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error(transparent)]
    Robustness(#[from] RobustnessError),
    #[error(transparent)]
    Setting(#[from] crate::data::ranges::RangeError),
    #[error(transparent)]
    Io(#[from] std::io::Error),
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// A flag whose setting cannot be used (`--symmetry: ...`).
    #[error("{flag}: {reason}")]
    Flag { flag: &'static str, reason: String },
    /// A flag whose value cannot be used (`--arc 0-400: ...`).
    #[error("{flag} {value}: {reason}")]
    FlagValue {
        flag: &'static str,
        value: String,
        reason: String,
    },
    #[error("unknown loss {0:?} (l2, ce, mimi)")]
    UnknownLoss(String),
    #[error("{name}: kind {kind} differs from {first} of the other sequences")]
    MixedKinds {
        name: String,
        kind: Kind,
        first: Kind,
    },
    #[error(
        "--protocol augment-leaky is a cross-validation diagnostic (cv only); train has no held-out sequence"
    )]
    LeakyTrain,
    #[error("{}: --init needs a single network; this model is an ensemble of {networks}", dir.display())]
    InitEnsemble { dir: PathBuf, networks: usize },
    /// `model` and `flags` are the two architectures, as `{:?}` writes them.
    #[error(
        "{}: --init needs the same architecture as the flags give; the model has {model}, the flags {flags}",
        dir.display()
    )]
    InitArchitecture {
        dir: PathBuf,
        model: String,
        flags: String,
    },
    #[error("{}: cannot write the card", dir.display())]
    WriteCard {
        dir: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "--record stores a metric of the model as served, with its card's test symmetries: drop --test-symmetry"
    )]
    RecordTestSymmetry,
    #[error(
        "--record stores a metric of the model as served: drop --refine, --frames and --stride"
    )]
    RecordOverride,
    #[error("--refine-from-truth scores refinement: add --refine on")]
    TruthWithoutRefine,
    #[error("no sequence has a test clip of {frames:?} frames at stride {stride}")]
    NoTestClip { frames: FrameCount, stride: usize },
    #[error("sample {name}")]
    Sample { name: String, source: FitError },
    #[error("{}: cannot write the report", dir.display())]
    WriteReport {
        dir: PathBuf,
        source: std::io::Error,
    },
    #[error("--out has no directory name to take as the ensemble's: give --name")]
    NoEnsembleName,
    #[error("no sequences")]
    NoSequences,
    #[error("no test sample")]
    NoTestSample,
    #[error("no sequence named {0}")]
    NoSuchFold(String),
    #[error("folds failed: {0:?} (rerun to retry them; finished folds are kept)")]
    FoldsFailed(Vec<String>),
    #[error("interrupted; finished folds are kept in {}", .0.display())]
    Interrupted(PathBuf),
    #[error("{}: cannot create", .path.display())]
    Create {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: cannot write", .path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}
