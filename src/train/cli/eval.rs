//! `eval`: a model directory scored on the test sample of every `--data` sequence (known K, SOD
//! and silhouette, [`crate::train::eval`]), printed as a table or JSON, and optionally recorded in
//! the model's card. What `--record` stores is a metric of the model as served, so it refuses
//! the flags that evaluate something else.

use std::path::PathBuf;

use super::CliError;
use super::card::record_metrics;
use super::options::{DataArgs, check_symmetries};
use super::provenance::command_line;
use crate::data::frames::FrameSampling;
use crate::data::{Kind, Sample, Sequence, Symmetry};
use crate::refine::RefineParams;
use crate::registry::{LoadedModel, ModelCard};
use crate::train::eval::{EvalRow, EvalSettings, Totals, evaluate_sample, format_table, totals};

/// On or off.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Switch {
    On,
    Off,
}

/// A number of frames, or every frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameCount {
    N(usize),
    All,
}

/// A `--frames` value that is neither `all` nor a number of frames >= 2.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0:?} is not `all` or a number of frames >= 2")]
pub struct FrameCountError(pub String);

impl std::str::FromStr for FrameCount {
    type Err = FrameCountError;
    fn from_str(s: &str) -> Result<Self, FrameCountError> {
        match s {
            "all" => Ok(FrameCount::All),
            _ => match s.parse::<usize>() {
                Ok(n) if n >= 2 => Ok(FrameCount::N(n)),
                _ => Err(FrameCountError(s.to_string())),
            },
        }
    }
}

/// The test sample of every sequence: trajectories cut to the first `frames` frames taken every
/// `stride`-th (all of them: as many as the sequence has); other kinds whole. Sequences too short
/// for the clip have none.
pub fn eval_samples(seqs: &[Sequence], frames: FrameCount, stride: usize) -> Vec<Sample> {
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

/// One evaluation, as the `eval` flags give it.
#[derive(Debug, Clone)]
pub struct EvalJob {
    pub model: PathBuf,
    pub data: DataArgs,
    pub k_max: usize,
    pub restarts: usize,
    pub seed: u64,
    /// Record the known-K mean error in the card under this metric name.
    pub record: Option<String>,
    /// Test-time symmetries instead of the card's.
    pub test_symmetry: Option<Vec<Symmetry>>,
    /// Refinement on or off instead of the card's choice.
    pub refine: Option<Switch>,
    /// Outliers on or off instead of the card's choice (with refinement).
    pub outliers: Option<Switch>,
    /// Hypotheses beyond the learned groups on or off (with refinement; default on).
    pub hypotheses: Option<Switch>,
    /// Frames per test clip; default: the model's.
    pub frames: Option<FrameCount>,
    /// Every `stride`-th frame for the test clip (at least 1).
    pub stride: usize,
    /// Which frames of a clip of another length the network reads, instead of the card's.
    pub frame_sampling: Option<FrameSampling>,
    /// Write the picture of every sample's fit here, worst first (see [`super::pictures`]).
    pub pictures: Option<PathBuf>,
    /// Refinement starts from each sample's true groups ([`EvalSettings::from_truth`]); needs
    /// `refine` on.
    pub refine_from_truth: bool,
}

/// What [`run`] measured, not yet recorded.
#[derive(Debug, Clone)]
pub struct Evaluated {
    pub rows: Vec<EvalRow>,
    pub totals: Totals,
    /// The card to record in (the model's as read), its directory and the metric's name.
    record: Option<(ModelCard, PathBuf, String)>,
    /// The metric protocol: `<n> samples from <sources>`.
    protocol: String,
}

impl Evaluated {
    /// What `eval` prints: the table, or with `json` the rows and totals (with a newline).
    pub fn output(&self, json: bool) -> Result<String, serde_json::Error> {
        if json {
            let value = serde_json::json!({ "rows": self.rows, "totals": self.totals });
            Ok(serde_json::to_string_pretty(&value)? + "\n")
        } else {
            Ok(format_table(&self.rows))
        }
    }

    /// Writes the metrics to the card when `--record` asked for it (see [`record_metrics`]).
    pub fn record(&self) -> Result<(), CliError> {
        let Some((card, dir, name)) = &self.record else {
            return Ok(());
        };
        let mut card = card.clone();
        record_metrics(
            &mut card,
            name,
            &self.totals,
            &self.protocol,
            &command_line(),
        );
        card.write(dir)?;
        Ok(())
    }
}

/// Loads the model, checks the flags against it and evaluates every test sample.
pub fn run(job: &EvalJob) -> Result<Evaluated, CliError> {
    let mut model = LoadedModel::load(&job.model)?;
    if let Some(list) = &job.test_symmetry {
        if job.record.is_some() {
            return Err(CliError::RecordTestSymmetry);
        }
        check_symmetries("--test-symmetry", list, model.card.kind)?;
        model.card.test_symmetries = list.clone();
    }
    let seqs = job.data.sequences()?;
    if let Some(sampling) = job.frame_sampling {
        model.card.frames = sampling;
    }
    let frames = job
        .frames
        .unwrap_or(FrameCount::N(model.card.input_dim / 2));
    let samples = eval_samples(&seqs, frames, job.stride);
    if samples.is_empty() {
        return Err(CliError::NoTestClip {
            frames,
            stride: job.stride,
        });
    }
    if job.record.is_some()
        && (job
            .refine
            .is_some_and(|r| (r == Switch::On) != model.card.refine)
            || job.frames.is_some()
            || job.stride != 1
            || job.refine_from_truth)
    {
        return Err(CliError::RecordOverride);
    }
    if job.refine_from_truth && job.refine != Some(Switch::On) {
        return Err(CliError::TruthWithoutRefine);
    }
    let params = RefineParams {
        outliers: job
            .outliers
            .map_or(model.card.outliers, |o| o == Switch::On),
        hypotheses: job.hypotheses != Some(Switch::Off),
        ..model.card.refine_params()
    };
    // Without `--refine`, each sample refines as a fit of it would by default.
    let settings = |s: &Sample| EvalSettings {
        k_max: job.k_max,
        restarts: job.restarts,
        seed: job.seed,
        refine: job
            .refine
            .map_or_else(|| model.card.refines(&s.points), |r| r == Switch::On)
            .then_some(params),
        from_truth: job.refine_from_truth,
    };
    let mut rows = Vec::new();
    for s in &samples {
        let row = evaluate_sample(&model, s, &settings(s)).map_err(|source| CliError::Sample {
            name: s.name.clone(),
            source,
        })?;
        rows.push(row);
    }
    if let Some(dir) = &job.pictures {
        super::pictures::write(&model, &samples, &rows, settings, dir)?;
    }
    let protocol = format!("{} samples from {}", rows.len(), job.data.sources());
    Ok(Evaluated {
        totals: totals(&rows),
        rows,
        // The card as evaluated: `--record` refuses every override but `--frame-sampling`,
        // which is stored with the metrics.
        record: job
            .record
            .clone()
            .map(|name| (model.card.clone(), job.model.clone(), name)),
        protocol,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::SequenceFile;

    fn tracks(name: &str, frames: usize, visible: Option<Vec<Vec<u8>>>) -> Sequence {
        let points = (0..4)
            .map(|i| (0..2 * frames).map(|v| (i * 31 + v * 7) as f64).collect())
            .collect();
        let file = SequenceFile {
            name: name.into(),
            kind: Kind::Trajectories,
            points,
            labels: vec![1, 1, 2, 2],
            num_models: Some(2),
            image_size: Some([100.0, 100.0]),
            source: None,
            model_type: None,
            visible,
        };
        Sequence::from_file(file, std::path::Path::new(name)).unwrap()
    }

    #[test]
    fn frame_counts_parse() {
        assert_eq!("all".parse(), Ok(FrameCount::All));
        assert_eq!("5".parse(), Ok(FrameCount::N(5)));
        let e = "1".parse::<FrameCount>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "\"1\" is not `all` or a number of frames >= 2"
        );
        assert!("x".parse::<FrameCount>().is_err());
    }

    #[test]
    fn eval_samples_cut_trajectories() {
        let seqs = [tracks("a", 7, None), tracks("b", 3, None)];
        // The first 5 frames: only a has them.
        let five = eval_samples(&seqs, FrameCount::N(5), 1);
        assert_eq!(five.len(), 1);
        assert_eq!(
            (five[0].name.as_str(), five[0].points.dim()),
            ("a[1..5]", 10)
        );
        // Stride 2: frames 1, 3, 5 of a, and of b only 1, 3 would exist.
        let strided = eval_samples(&seqs, FrameCount::N(3), 2);
        let names: Vec<_> = strided.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["a[1..5 every 2]"]);
        // Every frame: each sequence whole; at stride 2 as many as fit (4 of a's 7, 2 of b's 3).
        let all = eval_samples(&seqs, FrameCount::All, 1);
        assert_eq!(
            all.iter().map(|s| s.points.dim()).collect::<Vec<_>>(),
            [14, 6]
        );
        assert_eq!(all[0].name, "a");
        let all2 = eval_samples(&seqs, FrameCount::All, 2);
        assert_eq!(
            all2.iter().map(|s| s.points.dim()).collect::<Vec<_>>(),
            [8, 4]
        );
        // A sequence with a track missing a frame is cut to the tracks visible throughout.
        let mut vis = vec![vec![1; 3]; 4];
        vis[2][1] = 0;
        let holes = eval_samples(&[tracks("h", 3, Some(vis))], FrameCount::All, 1);
        assert_eq!((holes[0].points.len(), holes[0].labels.len()), (3, 3));
    }

    #[test]
    fn other_kinds_are_used_whole() {
        let seq = crate::data::synthetic::LceSpec {
            variant: crate::data::synthetic::LceVariant::Mixed,
            count: 1,
            seed: 0,
            config: Default::default(),
        }
        .sequences()
        .unwrap();
        let samples = eval_samples(&seq, FrameCount::N(5), 3);
        assert_eq!(samples.len(), 1);
        assert_eq!(samples[0].points.len(), seq[0].points.len());
    }
}
