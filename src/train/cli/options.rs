//! The flag groups `train`, `eval` and `cv` share, as `clap` argument groups the binary
//! flattens into its commands, and their mapping to validated configs: which data
//! ([`DataArgs`]: the sequences, of one kind) and how to train on it ([`TrainArgs`]: the
//! [`TrainConfig`] and the [`SamplePlan`]).

use clap::Args;

use super::CliError;
use crate::data::{DataSource, Kind, Sequence, Symmetry};
use crate::loss::Loss;
use crate::model::ModelConfig;
use crate::train::cv::{Protocol, SamplePlan, Subsample};
use crate::train::{Schedule, TrainConfig};

/// Data selection shared by train, eval and cv.
#[derive(Args, Debug, Clone)]
pub struct DataArgs {
    /// Dataset directory or file, or LCE samples generated in memory:
    /// lce:<mixed|unmixed|random>[,count=N][,seed=S][,scale=X][,noise=X][,points=N|MIN-MAX]
    /// [,arc=MIN-MAX][,outliers=R][,similarity=true] (what gen-lce would write with the same
    /// settings; defaults 200 samples, seed 0, scale 1, noise 0.05, 50 points per shape, whole
    /// shapes, no outliers, no similarity). Repeatable.
    #[arg(long, required = true)]
    pub data: Vec<DataSource>,
    /// Keep only AdelaideRMF sequences of this model type (homography or fundamental).
    #[arg(long)]
    pub model_type: Option<String>,
    /// Frames per trajectory clip.
    #[arg(long, default_value_t = 5)]
    pub clip_len: usize,
}

/// Model and optimisation settings shared by train and cv.
#[derive(Args, Debug, Clone)]
pub struct TrainArgs {
    /// l2, ce or mimi.
    #[arg(long, default_value = "mimi")]
    pub loss: String,
    /// MIMI's weight of the inter-cluster term.
    #[arg(long, default_value_t = 0.6)]
    pub alpha: f64,
    #[arg(long, default_value_t = 128)]
    pub width: usize,
    #[arg(long, default_value_t = 12)]
    pub depth: usize,
    /// Embedding dimension E (the paper: the largest number of structures).
    #[arg(long, default_value_t = 6)]
    pub embed_dim: usize,
    /// BatchNorm after Context Normalization (CNe).
    #[arg(long)]
    pub batch_norm: bool,
    /// Append offsets to this many nearest neighbours to every point (0 = the paper's input).
    #[arg(long, default_value_t = 0)]
    pub neighbors: usize,
    /// Graph aggregation in every block over this many nearest points, itself included
    /// (0 = the paper's network).
    #[arg(long, default_value_t = 0)]
    pub graph_neighbors: usize,
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    #[arg(long, value_enum, default_value = "cosine")]
    pub schedule: ScheduleArg,
    #[arg(long, default_value_t = 100)]
    pub epochs: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Sets per step when they have equal size.
    #[arg(long, default_value_t = 1)]
    pub batch_size: usize,
    /// Gaussian jitter sigma on normalised training inputs (0 = off).
    #[arg(long, default_value_t = 0.0)]
    pub jitter: f64,
    /// Protocol for trajectory data: vanilla (first clip) or augment (all non-overlapping clips);
    /// augment-leaky (cv only) also trains each fold on its held-out sequence's later clips, as
    /// the authors' code does: a diagnostic, not an honest protocol.
    #[arg(long, value_enum, default_value = "vanilla")]
    pub protocol: Protocol,
    /// Augment protocol: frames between the starts of two clips (default: the clip length, the
    /// paper's non-overlapping clips; 1 = every clip).
    #[arg(long)]
    pub clip_stride: Option<usize>,
    /// Add the images of every training sample under these symmetries (comma-separated:
    /// mirror, reverse, rotate); every combination is added (mirror and reverse: four copies;
    /// rotate counts its three quarter turns).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub symmetry: Vec<Symmetry>,
    /// Add copies of every training sequence that keep a share of its rows drawn uniformly in
    /// this range (`A-B`, or one share `A`; 0 < A <= B <= 1): training at the lower densities
    /// users send. Seeded by --seed.
    #[arg(long)]
    pub subsample: Option<String>,
    /// Subsampled copies per training sequence (with --subsample).
    #[arg(long, default_value_t = 2, requires = "subsample")]
    pub subsample_copies: usize,
    /// Test-time symmetries stored in the card: fits embed the input and its images under these
    /// (comma-separated: mirror, reverse, rotate) and cluster the concatenated embeddings.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub test_symmetry: Vec<Symmetry>,
    /// Largest K for automatic selection (stored in the card).
    #[arg(long, default_value_t = 8)]
    pub k_max: usize,
}

/// `--schedule`: the [`Schedule`] of the flags (its own type, so that `--help` lists the values
/// without the schedule's documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ScheduleArg {
    Constant,
    Cosine,
}

impl From<ScheduleArg> for Schedule {
    fn from(s: ScheduleArg) -> Self {
        match s {
            ScheduleArg::Constant => Schedule::Constant,
            ScheduleArg::Cosine => Schedule::Cosine,
        }
    }
}

impl DataArgs {
    /// Every sequence of every `--data` source, in order; they must all be of one kind.
    pub fn sequences(&self) -> Result<Vec<Sequence>, CliError> {
        let mut all = Vec::new();
        for source in &self.data {
            all.extend(source.sequences(self.model_type.as_deref())?);
        }
        let Some(first) = all.first().map(|s| s.points.kind()) else {
            // A source yields at least one sequence or an error, and clap requires a source.
            return Err(CliError::NoSequences);
        };
        if let Some(s) = all.iter().find(|s| s.points.kind() != first) {
            return Err(CliError::MixedKinds {
                name: s.name.clone(),
                kind: s.points.kind(),
                first,
            });
        }
        Ok(all)
    }

    /// The sources as given, comma-separated (for cards and metric protocols).
    pub fn sources(&self) -> String {
        self.data
            .iter()
            .map(|p| p.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    }
}

impl TrainArgs {
    /// The validated sample plan for sequences of `kind`.
    pub fn samples(&self, clip_len: usize, kind: Kind) -> Result<SamplePlan, CliError> {
        check_symmetries("--symmetry", &self.symmetry, kind)?;
        let subsample = self.subsample()?;
        let plan = SamplePlan {
            protocol: self.protocol,
            clip_len,
            clip_stride: self.clip_stride.unwrap_or(clip_len),
            symmetries: self.symmetry.clone(),
            subsample,
        };
        plan.validate()?;
        Ok(plan)
    }

    /// `--subsample` and `--subsample-copies`, checked; errors name the flag.
    fn subsample(&self) -> Result<Option<Subsample>, CliError> {
        let Some(text) = &self.subsample else {
            return Ok(None);
        };
        let flag = |reason: String| CliError::Flag {
            flag: "--subsample",
            reason,
        };
        let share = |v: &str| {
            v.trim()
                .parse::<f64>()
                .map_err(|_| flag(format!("{v:?} is not a number")))
        };
        let (low, high) = match text.split_once('-') {
            Some((a, b)) => (share(a)?, share(b)?),
            None => (share(text)?, share(text)?),
        };
        let plan = Subsample {
            low,
            high,
            copies: self.subsample_copies,
            seed: self.seed,
        };
        // The shares first, then the count, each error under its own flag.
        Subsample { copies: 1, ..plan }
            .validate()
            .map_err(|e| flag(e.to_string()))?;
        plan.validate().map_err(|e| CliError::Flag {
            flag: "--subsample-copies",
            reason: e.to_string(),
        })?;
        Ok(Some(plan))
    }

    /// The validated training config for rows of `input_dim` values.
    pub fn config(&self, input_dim: usize) -> Result<TrainConfig, CliError> {
        let loss = Loss::parse(&self.loss, self.alpha)
            .ok_or_else(|| CliError::UnknownLoss(self.loss.clone()))?;
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
            schedule: self.schedule.into(),
            epochs: self.epochs,
            seed: self.seed,
            batch_size: self.batch_size,
            jitter: self.jitter,
        };
        config.validate()?;
        Ok(config)
    }
}

/// Refuses symmetries that are repeated or have no image for `kind` (reverse for points2d),
/// rather than skipping them silently; the error names `flag`.
pub fn check_symmetries(flag: &'static str, list: &[Symmetry], kind: Kind) -> Result<(), CliError> {
    crate::data::symmetry::check(list, kind).map_err(|e| CliError::Flag {
        flag,
        reason: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Flags {
        #[command(flatten)]
        data: DataArgs,
        #[command(flatten)]
        train: TrainArgs,
    }

    fn parse(args: &[&str]) -> Flags {
        Flags::try_parse_from(["t", "--data", "lce:mixed,count=2"].iter().chain(args)).unwrap()
    }

    #[test]
    fn defaults_give_the_documented_config() {
        let f = parse(&[]);
        let c = f.train.config(4).unwrap();
        assert_eq!(c.loss, Loss::Mimi { alpha: 0.6 });
        assert_eq!(c.schedule, Schedule::Cosine);
        assert_eq!(
            (c.model.input_dim, c.model.width, c.model.depth),
            (4, 128, 12)
        );
        assert_eq!((c.model.embed_dim, c.epochs, c.batch_size), (6, 100, 1));
        assert_eq!(c.learning_rate, 1e-3);
        let plan = f
            .train
            .samples(f.data.clip_len, Kind::Trajectories)
            .unwrap();
        assert_eq!(
            (plan.protocol, plan.clip_len, plan.clip_stride),
            (Protocol::Vanilla, 5, 5)
        );
        assert_eq!(f.data.sequences().unwrap().len(), 2);
        let two = parse(&["--data", "lce:unmixed,count=1,seed=3"]);
        assert_eq!(two.data.sequences().unwrap().len(), 3);
        assert_eq!(
            two.data.sources(),
            "lce:mixed,count=2,seed=0,scale=1,noise=0.05,points=50, \
             lce:unmixed,count=1,seed=3,scale=1,noise=0.05,points=50"
        );
    }

    #[test]
    fn subsampling_flags_become_the_plan_or_name_the_flag() {
        let f = parse(&[
            "--subsample",
            "0.2-0.8",
            "--subsample-copies",
            "3",
            "--seed",
            "4",
        ]);
        let plan = f.train.samples(5, Kind::Correspondences).unwrap();
        let s = plan.subsample.unwrap();
        assert_eq!((s.low, s.high, s.copies, s.seed), (0.2, 0.8, 3, 4));
        let one = parse(&["--subsample", "0.5"]);
        let s = one.train.samples(5, Kind::Correspondences).unwrap();
        assert_eq!(
            s.subsample.map(|s| (s.low, s.high, s.copies)),
            Some((0.5, 0.5, 2))
        );
        for (args, flag) in [
            (&["--subsample", "0-0.5"][..], "--subsample: "),
            (&["--subsample", "0.5-0.2"][..], "--subsample: "),
            (&["--subsample", "half"][..], "--subsample: "),
            (
                &["--subsample", "0.5", "--subsample-copies", "0"][..],
                "--subsample-copies: ",
            ),
        ] {
            let e = parse(args)
                .train
                .samples(5, Kind::Correspondences)
                .unwrap_err()
                .to_string();
            assert!(e.starts_with(flag), "{args:?}: {e}");
        }
    }

    #[test]
    fn bad_settings_name_their_flag() {
        let f = parse(&["--loss", "hinge"]);
        assert_eq!(
            f.train.config(2).unwrap_err().to_string(),
            "unknown loss \"hinge\" (l2, ce, mimi)"
        );
        let f = parse(&["--symmetry", "mirror,mirror"]);
        let e = f.train.samples(5, Kind::Points2d).unwrap_err().to_string();
        assert!(
            e.starts_with("--symmetry: ") && e.contains("repeated"),
            "{e}"
        );
        let f = parse(&["--symmetry", "reverse"]);
        assert!(f.train.samples(5, Kind::Points2d).is_err());
        assert!(f.train.samples(5, Kind::Trajectories).is_ok());
        let f = parse(&["--clip-stride", "0"]);
        let e = f.train.samples(5, Kind::Trajectories).unwrap_err();
        assert!(
            e.to_string().contains("clip stride must be at least 1"),
            "{e}"
        );
    }
}
