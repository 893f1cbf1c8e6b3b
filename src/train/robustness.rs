//! The robustness grid (`multifit-train robustness`): how a model holds up when its input drifts
//! from what it was trained on. Every cell is built in memory from a seed, evaluated with the
//! evaluation code of `eval` ([`evaluate_sample`]: known K, and K chosen by the card's
//! selection) and reported as one row of a table and of a JSON file.
//!
//! Cells by model kind:
//! - **points2d** (the LCE generator, [`crate::data::synthetic`]): the *paper-protocol* cell,
//!   the LCE mixed test set itself (200 sets, seed 4, 1 line + 2 ellipses + 1 circle, 50 points
//!   per shape, scale 2: the figures `eval --data lce:mixed,count=200,seed=4,scale=2` gives);
//!   a *sweep* of density (20, 50, 150 and 400 points per shape) times scale (1, 2, 4) at the
//!   paper's mix without outliers; and *one factor at a time* from the sweep's 50-per-shape,
//!   scale-2 cell: 2 to 6 structures of random types, partial arcs (90 to 360 degrees), gross
//!   outliers at 0.2 and 0.5 of the inliers (their own group), a random similarity, and unequal
//!   densities (20 to 300 points per shape). `sets` samples per cell from the data seed `seed`
//!   (every cell from the same seed, so that cells differing in one factor share what they can
//!   of the random stream). Each cell is an `lce:...` data source, written in the report, that
//!   `eval --data` reproduces.
//! - **correspondences** (AdelaideRMF pairs of the model's type): every pair as it is; each pair
//!   subsampled to 50 % and 25 % of its points; with 20 % more points as gross outliers
//!   (uniform over each image, in the outlier group); the coordinates and image size rescaled by
//!   0.5 and by 2; the pair without its image size (the bounding box stands in for it); the
//!   second image at another resolution; every coordinate rounded to a whole pixel; and the
//!   rows in a random order (the files list many points of one structure together, an order a
//!   caller's matcher need not keep). Random cells take `draws` seeded draws per pair.
//! - **trajectories** (KT3DMoSeg): the first clip of each sequence with frame strides 1, 2 and 3
//!   (frames 1, 1 + s, ..., 1 + 4s: faster apparent motion), and stride 1 again on only the
//!   sequences long enough for stride 3, so the two compare on the same sequences.
//!
//! Outliers are scored as one group of their own, as AdelaideRMF's are (label 0, one more group
//! in K). Real-data cells are scored with the shipped model by default, which was trained on
//! every sequence, so they measure robustness on seen data, not generalisation; with
//! `folds` (a `multifit-train cv` output directory) each sequence is scored with the fold model
//! that never saw it (`<folds>/models/<sequence>/`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rand::RngExt;
use rand::rngs::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::eval::{EvalRow, EvalSettings, Summary, Totals, evaluate_sample, totals};
use crate::cluster::Selection;
use crate::data::synthetic::{LceConfig, LceSpec, LceVariant};
use crate::data::{ImageSize, Kind, PointSet, Sample, Sequence, load_sequences, seeded_rng};
use crate::registry::LoadedModel;

/// Why the grid could not run.
#[derive(Debug, thiserror::Error)]
pub enum RobustnessError {
    #[error("{path}: cannot load the model: {reason}")]
    Model { path: PathBuf, reason: String },
    #[error("{0}")]
    Data(#[from] crate::data::DataError),
    #[error("{0}")]
    Config(String),
    #[error("sample {sample}: {reason}")]
    Fit { sample: String, reason: String },
}

/// What to run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridSettings {
    /// Generated samples per points2d cell (the paper-protocol cell always has its 200).
    pub sets: usize,
    /// Seeded draws per sequence in the random real-data cells (subsampling, outliers).
    pub draws: usize,
    /// Seed of the generated data and of the draws.
    pub seed: u64,
    /// k-means restarts, as `eval --restarts`.
    pub restarts: usize,
    /// Largest K for automatic selection; `None`: the card's.
    pub k_max: Option<usize>,
    /// Run only the cells of these names; empty: every cell.
    pub cells: Vec<String>,
    /// Dataset directory for correspondences and trajectories (AdelaideRMF or KT3DMoSeg files).
    pub data: Option<PathBuf>,
    /// AdelaideRMF model type (homography, fundamental); `None`: read from the model's name.
    pub model_type: Option<String>,
    /// Whether refinement's hypotheses stage runs ([`crate::refine::RefineParams::hypotheses`]).
    #[serde(default = "hypotheses_on")]
    pub hypotheses: bool,
}

fn hypotheses_on() -> bool {
    true
}

impl GridSettings {
    /// Samples per LCE cell by default: the whole points2d grid of the shipped `lce` takes
    /// about 9 minutes on one thread here.
    pub const DEFAULT_SETS: usize = 100;
    /// A data seed no shipped model was trained on (their LCE data used seeds up to 432).
    pub const DEFAULT_SEED: u64 = 1000;

    fn validate(&self) -> Result<(), RobustnessError> {
        if self.sets == 0 || self.sets > LceSpec::MAX_COUNT {
            return Err(RobustnessError::Config(format!(
                "--sets {}: must be 1 to {}",
                self.sets,
                LceSpec::MAX_COUNT
            )));
        }
        if self.draws == 0 {
            return Err(RobustnessError::Config(
                "--draws 0: must be at least 1".into(),
            ));
        }
        if self.restarts == 0 {
            return Err(RobustnessError::Config(
                "--restarts 0: must be at least 1".into(),
            ));
        }
        if self.k_max == Some(0) {
            return Err(RobustnessError::Config(
                "--k-max 0: must be at least 1".into(),
            ));
        }
        Ok(())
    }
}

impl Default for GridSettings {
    fn default() -> Self {
        Self {
            sets: Self::DEFAULT_SETS,
            draws: 3,
            seed: Self::DEFAULT_SEED,
            restarts: 4,
            k_max: None,
            cells: vec![],
            data: None,
            model_type: None,
            hypotheses: true,
        }
    }
}

/// One evaluated cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellResult {
    pub name: String,
    /// `paper protocol`, `sweep`, `one factor` or `reference`.
    pub group: String,
    /// The cell's settings, by the report's column names.
    pub factors: BTreeMap<String, serde_json::Value>,
    /// Where its samples come from: an `lce:...` source `eval --data` takes, or a description.
    pub data: String,
    pub samples: usize,
    pub mean_points: f64,
    /// Mean true number of groups (outliers included).
    pub mean_k: f64,
    /// With the true K.
    pub known: Summary,
    /// With K chosen by the card's selection (named in the report).
    pub chosen: Summary,
    /// Known K, SOD and silhouette, as `eval` prints them.
    pub totals: Totals,
    /// Sequences without a sample in this cell (too few frames for the stride).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub skipped: Vec<String>,
    /// Each sample's errors, in the cell's order: which draws carry a mean.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub per_sample: Vec<SampleResult>,
    pub seconds: f64,
}

/// One sample of a cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampleResult {
    pub name: String,
    /// True number of groups (outliers included).
    pub k_true: usize,
    /// Error with the true K.
    pub known_error: f64,
    /// Error and K with K chosen by the card's selection.
    pub chosen_error: f64,
    pub chosen_k: usize,
}

/// A whole grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    pub model: String,
    pub model_dir: PathBuf,
    pub kind: Kind,
    /// Hex SHA-256 of the model's weight files.
    pub weights_sha256: Option<String>,
    /// The cross-validation directory whose fold models scored the real-data cells.
    pub folds: Option<PathBuf>,
    /// The card's K selection, which `chosen` reports.
    pub selection: String,
    pub k_max: usize,
    /// Whether fits were scored after the card's geometric refinement.
    #[serde(default)]
    pub refine: bool,
    /// The card's stay radius in refinement (σ; 0: nearest structure).
    #[serde(default)]
    pub refine_stay: f64,
    /// The card's margin in refinement (σ; 0: any nearer structure).
    #[serde(default)]
    pub refine_margin: f64,
    pub settings: GridSettings,
    /// The factor columns, in table order.
    pub columns: Vec<String>,
    /// The cell the deltas of the table are taken from.
    pub reference: String,
    /// What the numbers mean and do not mean.
    pub notes: Vec<String>,
    /// The command that made the report (filled in by the caller).
    #[serde(default)]
    pub command: String,
    pub cells: Vec<CellResult>,
    pub seconds: f64,
}

/// The models that score the cells: one, or a fold model per real sequence.
struct Models {
    main: LoadedModel,
    folds: Option<(PathBuf, BTreeMap<String, LoadedModel>)>,
}

fn load(dir: &Path) -> Result<LoadedModel, RobustnessError> {
    LoadedModel::load(dir).map_err(|e| RobustnessError::Model {
        path: dir.to_path_buf(),
        reason: e.to_string(),
    })
}

impl Models {
    /// The model that scores samples of sequence `name`. A fold model stands in for the
    /// model's network: it embeds under the model card's test symmetries, as a fit would.
    fn for_sequence(&mut self, name: &str) -> Result<&LoadedModel, RobustnessError> {
        let Some((dir, cache)) = &mut self.folds else {
            return Ok(&self.main);
        };
        if !cache.contains_key(name) {
            let mut model = load(&dir.join("models").join(name))?;
            model.card.test_symmetries = self.main.card.test_symmetries.clone();
            if model.card.kind != self.main.card.kind
                || model.card.input_dim != self.main.card.input_dim
            {
                return Err(RobustnessError::Config(format!(
                    "fold model {name} takes {} rows of {}, the model {} rows of {}",
                    model.card.kind,
                    model.card.input_dim,
                    self.main.card.kind,
                    self.main.card.input_dim
                )));
            }
            cache.insert(name.to_string(), model);
        }
        Ok(&cache[name])
    }
}

/// A cell before evaluation: its samples, each with the sequence whose model scores it.
struct Cell {
    name: String,
    group: &'static str,
    factors: BTreeMap<String, serde_json::Value>,
    data: String,
    samples: Vec<(String, Sample)>,
    skipped: Vec<String>,
}

/// Runs the grid for the model in `model_dir`, scoring real-data cells with the fold models of
/// `folds` when given. `on_cell` sees every cell as it finishes.
pub fn run(
    model_dir: &Path,
    folds: Option<&Path>,
    settings: &GridSettings,
    on_cell: &mut dyn FnMut(&CellResult),
) -> Result<Report, RobustnessError> {
    settings.validate()?;
    let start = Instant::now();
    let main = load(model_dir)?;
    let card = main.card.clone();
    let mut models = Models {
        main,
        folds: folds.map(|d| (d.to_path_buf(), BTreeMap::new())),
    };
    let k_max = settings.k_max.unwrap_or(card.k_max);
    let eval = eval_settings(&card, k_max, settings.restarts, settings.hypotheses);
    let (columns, reference, mut notes, builders) = match card.kind {
        Kind::Points2d => {
            if folds.is_some() {
                return Err(RobustnessError::Config(
                    "--folds: a points2d model is scored on generated data, which no fold holds out".into(),
                ));
            }
            lce_grid(settings)
        }
        Kind::Correspondences => {
            let model_type = model_type(settings, &card.name)?;
            let seqs = real_sequences(settings, "adelaidermf", Some(&model_type))?;
            correspondence_grid(settings, seqs, &model_type)
        }
        Kind::Trajectories => {
            let seqs = real_sequences(settings, "kt3dmoseg", None)?;
            trajectory_grid(seqs, card.input_dim / 2)
        }
    };
    if card.kind != Kind::Points2d {
        notes.push(match folds {
            None => "Scored with the shipped model, which was trained on every sequence here: these cells measure how the model holds up on data it has seen, under the changes named, not how it generalises to new scenes. Leave-one-out fold models (--folds) measure that.".to_string(),
            Some(d) => format!(
                "Each sequence scored with the fold model that never saw it ({}/models/<sequence>/).",
                d.display()
            ),
        });
    }
    let known_names: Vec<&str> = builders.iter().map(|b| b.0.as_str()).collect();
    if let Some(bad) = settings
        .cells
        .iter()
        .find(|c| !known_names.contains(&c.as_str()))
    {
        return Err(RobustnessError::Config(format!(
            "--cells: no cell {bad:?} for a {} model (cells: {})",
            card.kind,
            known_names.join(", ")
        )));
    }
    let mut cells = Vec::new();
    for (name, build) in builders {
        if !settings.cells.is_empty() && !settings.cells.contains(&name) {
            continue;
        }
        let cell_start = Instant::now();
        let cell = build()?;
        let result = evaluate_cell(&mut models, cell, &eval, &card.selection)?;
        let result = CellResult {
            seconds: cell_start.elapsed().as_secs_f64(),
            ..result
        };
        on_cell(&result);
        cells.push(result);
    }
    Ok(Report {
        model: card.name.clone(),
        model_dir: model_dir.to_path_buf(),
        kind: card.kind,
        weights_sha256: models.main.weights_sha256().map(str::to_string),
        folds: folds.map(Path::to_path_buf),
        selection: card.selection.name().to_string(),
        k_max,
        refine: refine_of(&card),
        refine_stay: card.refine_stay,
        refine_margin: card.refine_margin,
        settings: settings.clone(),
        columns,
        reference,
        notes,
        command: String::new(),
        cells,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The evaluation `eval` runs by default for this card; refinement applies to the samples a fit
/// refines by default ([`crate::registry::ModelCard::refines`]).
fn eval_settings(
    card: &crate::registry::ModelCard,
    k_max: usize,
    restarts: usize,
    hypotheses: bool,
) -> EvalSettings {
    EvalSettings {
        k_max,
        restarts,
        seed: 0,
        refine: Some(crate::refine::RefineParams {
            hypotheses,
            ..card.refine_params()
        }),
        from_truth: false,
    }
}

fn refine_of(card: &crate::registry::ModelCard) -> bool {
    card.refine
}

fn evaluate_cell(
    models: &mut Models,
    cell: Cell,
    eval: &EvalSettings,
    selection: &Selection,
) -> Result<CellResult, RobustnessError> {
    let mut rows: Vec<EvalRow> = Vec::with_capacity(cell.samples.len());
    for (sequence, sample) in &cell.samples {
        // The shipped model's card decides what a fit does; a fold model stands in for its
        // network only.
        let refines = models.main.card.refines(&sample.points);
        let model = models.for_sequence(sequence)?;
        let eval = EvalSettings {
            refine: eval.refine.filter(|_| refines),
            ..*eval
        };
        let row = evaluate_sample(model, sample, &eval).map_err(|e| RobustnessError::Fit {
            sample: sample.name.clone(),
            reason: e.to_string(),
        })?;
        rows.push(row);
    }
    let t = totals(&rows);
    let n = rows.len().max(1) as f64;
    let per_sample = rows
        .iter()
        .map(|r| {
            let chosen = by_selection(selection, &r.known, &r.sod, &r.silhouette);
            SampleResult {
                name: r.name.clone(),
                k_true: r.k_true,
                known_error: r.known.error,
                chosen_error: chosen.error,
                chosen_k: chosen.k,
            }
        })
        .collect();
    Ok(CellResult {
        name: cell.name,
        group: cell.group.to_string(),
        factors: cell.factors,
        data: cell.data,
        samples: rows.len(),
        mean_points: rows.iter().map(|r| r.n as f64).sum::<f64>() / n,
        mean_k: rows.iter().map(|r| r.k_true as f64).sum::<f64>() / n,
        known: t.known,
        chosen: by_selection(selection, t.known, t.sod, t.silhouette),
        totals: t,
        skipped: cell.skipped,
        per_sample,
        seconds: 0.0,
    })
}

/// Of the same quantity with the true K, by SOD and by the silhouette, the one `selection`
/// gives (the true K's for a fixed K).
fn by_selection<T>(selection: &Selection, known: T, sod: T, silhouette: T) -> T {
    match selection {
        Selection::Sod => sod,
        Selection::Silhouette => silhouette,
        Selection::Fixed(_) => known,
    }
}

/// Builds a cell's samples (only when it runs).
type BuildFn<'a> = Box<dyn FnOnce() -> Result<Cell, RobustnessError> + 'a>;

/// A cell's name and how to build it.
type Builder<'a> = (String, BuildFn<'a>);

/// Column names, the reference cell, notes, and the cells.
type Grid<'a> = (Vec<String>, String, Vec<String>, Vec<Builder<'a>>);

fn factors(pairs: &[(&str, serde_json::Value)]) -> BTreeMap<String, serde_json::Value> {
    pairs
        .iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect()
}

/// The points2d grid: the paper-protocol test set, the density x scale sweep and the
/// one-factor cells.
fn lce_grid(s: &GridSettings) -> Grid<'static> {
    use serde_json::json;
    let base = LceSpec {
        variant: LceVariant::Mixed,
        count: s.sets,
        seed: s.seed,
        config: LceConfig {
            scale: 2.0,
            ..LceConfig::default()
        },
    };
    let mut cells: Vec<(String, &'static str, LceSpec)> = vec![(
        "paper-protocol".into(),
        "paper protocol",
        LceSpec {
            count: 200,
            seed: 4,
            ..base.clone()
        },
    )];
    for scale in [1.0, 2.0, 4.0] {
        for points in [20, 50, 150, 400] {
            let mut spec = base.clone();
            spec.config.scale = scale;
            spec.config.points_per_shape = points;
            cells.push((format!("sweep-{points}-s{scale}"), "sweep", spec));
        }
    }
    let one = |name: &str, f: &dyn Fn(&mut LceSpec)| {
        let mut spec = base.clone();
        f(&mut spec);
        (name.to_string(), "one factor", spec)
    };
    cells.extend([
        one("random-types", &|s| s.variant = LceVariant::Random),
        one("arcs-90-360", &|s| s.config.arc = Some([90.0, 360.0])),
        one("outliers-0.2", &|s| s.config.outliers = 0.2),
        one("outliers-0.5", &|s| s.config.outliers = 0.5),
        one("similarity", &|s| s.config.similarity = true),
        one("unequal-20-300", &|s| {
            s.config.points_per_shape = 20;
            s.config.points_max = Some(300);
        }),
    ]);
    let columns = [
        "points/shape",
        "scale",
        "structures",
        "arcs (deg)",
        "outliers",
        "similarity",
    ]
    .map(String::from)
    .to_vec();
    let notes = vec![
        "The paper-protocol cell is the LCE mixed test set (200 sets, seed 4) that docs/RESULTS.md reports; the other cells are drawn from the grid's data seed, the sweep-50-s2 cell being the same setting with other samples.".to_string(),
        "Outlier cells: known K counts the outliers as one more group (K = 5), as AdelaideRMF's outliers are scored.".to_string(),
    ];
    let builders = cells
        .into_iter()
        .map(|(name, group, spec)| {
            let c = spec.config;
            let f = factors(&[
                (
                    "points/shape",
                    match c.points_max {
                        Some(max) => json!(format!("{}-{max}", c.points_per_shape)),
                        None => json!(c.points_per_shape),
                    },
                ),
                ("scale", json!(c.scale)),
                (
                    "structures",
                    json!(match spec.variant {
                        LceVariant::Mixed => "1 line + 2 ellipses + 1 circle",
                        LceVariant::Unmixed => "2-4 of one type",
                        LceVariant::Random => "2-6 of random types",
                    }),
                ),
                (
                    "arcs (deg)",
                    match c.arc {
                        Some([a, b]) => json!(format!("{a}-{b}")),
                        None => json!("whole"),
                    },
                ),
                ("outliers", json!(c.outliers)),
                ("similarity", json!(c.similarity)),
            ]);
            let cell_name = name.clone();
            let build = move || {
                let samples = spec
                    .sequences()?
                    .iter()
                    .map(|seq| (seq.name.clone(), seq.sample()))
                    .collect();
                Ok(Cell {
                    name,
                    group,
                    factors: f,
                    data: spec.to_string(),
                    samples,
                    skipped: vec![],
                })
            };
            (cell_name, Box::new(build) as BuildFn<'static>)
        })
        .collect();
    (columns, "sweep-50-s2".into(), notes, builders)
}

/// The AdelaideRMF model type a correspondence model is scored on.
fn model_type(s: &GridSettings, name: &str) -> Result<String, RobustnessError> {
    if let Some(t) = &s.model_type {
        return Ok(t.clone());
    }
    ["homography", "fundamental"]
        .into_iter()
        .find(|t| name.contains(t))
        .map(str::to_string)
        .ok_or_else(|| {
            RobustnessError::Config(format!(
                "--model-type: the model's name {name:?} does not say homography or fundamental; give --model-type"
            ))
        })
}

/// The sequences of `settings.data`, or of `../shared/datasets/<default>`.
fn real_sequences(
    s: &GridSettings,
    default: &str,
    model_type: Option<&str>,
) -> Result<Vec<Sequence>, RobustnessError> {
    let dir = s
        .data
        .clone()
        .unwrap_or_else(|| Path::new("../shared/datasets").join(default));
    Ok(load_sequences(&dir, model_type)?)
}

/// A seeded generator for one draw of one sequence in one cell.
fn rng_for(seed: u64, cell: &str, sequence: &str, draw: usize) -> ChaCha8Rng {
    seeded_rng(&format!("{seed}/{cell}/{sequence}/{draw}"))
}

/// `round(ratio * n)` more rows, every (x, y) pair uniform over the image (or, without an image
/// size, over the bounding box of that pair's column), labelled 0, the outlier group; visible in
/// every frame.
pub fn add_outliers(seq: &Sequence, ratio: f64, rng: &mut ChaCha8Rng) -> Sequence {
    let n = seq.points.len();
    let dim = seq.points.dim();
    let extra = (ratio * n as f64).round() as usize;
    let boxes: Vec<[f64; 2]> = (0..dim)
        .map(|d| match seq.image_size {
            Some(s) => [0.0, if d % 2 == 0 { s.width } else { s.height }],
            None => (0..n).fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], i| {
                let v = seq.points.row(i)[d];
                [lo.min(v), hi.max(v)]
            }),
        })
        .collect();
    let mut values = seq.points.values().to_vec();
    for _ in 0..extra {
        values.extend(boxes.iter().map(|&[lo, hi]| rng.random_range(lo..=hi)));
    }
    let mut labels = seq.labels.clone();
    labels.extend(std::iter::repeat_n(0, extra));
    Sequence {
        name: seq.name.clone(),
        points: PointSet::from_flat(seq.points.kind(), dim, values).expect("finite values"),
        labels,
        image_size: seq.image_size,
        model_type: seq.model_type.clone(),
        visible: seq.visible.as_ref().map(|v| {
            let frames = dim / 2;
            let mut v = v.clone();
            v.extend(std::iter::repeat_n(vec![1; frames], extra));
            v
        }),
    }
}

/// Every coordinate and the image size multiplied by `factor`.
pub fn rescale(seq: &Sequence, factor: f64) -> Sequence {
    Sequence {
        points: each_value(seq, |v| v * factor),
        image_size: seq
            .image_size
            .map(|s| ImageSize::new(s.width * factor, s.height * factor).expect("positive")),
        ..seq.clone()
    }
}

/// Every coordinate rounded to the nearest whole pixel (a tracker that reports integer
/// positions).
pub fn whole_pixels(seq: &Sequence) -> Sequence {
    Sequence {
        points: each_value(seq, f64::round),
        ..seq.clone()
    }
}

/// `seq`'s points with `map` applied to every coordinate (finite to finite).
fn each_value(seq: &Sequence, map: impl Fn(f64) -> f64) -> PointSet {
    let values: Vec<f64> = seq.points.values().iter().map(|&v| map(v)).collect();
    PointSet::from_flat(seq.points.kind(), seq.points.dim(), values).expect("finite values")
}

/// The second image taken at `factor` times the first's resolution: its coordinates and its
/// size (sent per image) multiplied by `factor`, the first view's unchanged.
pub fn rescale_second_view(seq: &Sequence, factor: f64) -> Sequence {
    Sequence {
        points: (seq.points)
            .second_view_mapped(|_, v| v * factor)
            .expect("finite values"),
        image_size: seq.image_size.map(|s| {
            ImageSize::per_view([s.width, s.height], [s.width * factor, s.height * factor])
                .expect("positive")
        }),
        ..seq.clone()
    }
}

/// How a pair's two images are presented to the fit, beside how the files give them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ViewChange {
    /// As the files give them.
    AsSent,
    /// The second image first: rows `[x2, y2, x1, y1]`.
    Swapped,
    /// `y` measured upwards from the bottom edge of each image: `y -> h - y`.
    YFlipped,
    /// Both images turned a quarter turn clockwise: `(x, y) -> (h - y, x)`, size `w x h -> h x w`.
    QuarterTurn,
}

impl ViewChange {
    fn describe(self) -> &'static str {
        match self {
            ViewChange::AsSent => "as sent",
            ViewChange::Swapped => "swapped",
            ViewChange::YFlipped => "y flipped",
            ViewChange::QuarterTurn => "quarter turn",
        }
    }

    /// `seq` as presented; labels and row order unchanged. Without an image size the bounding
    /// box of each view's points stands for its image.
    fn apply(self, seq: &Sequence) -> Sequence {
        let (points, image_size) = match self {
            ViewChange::AsSent => return seq.clone(),
            ViewChange::Swapped => (
                (crate::data::Symmetry::Reverse.apply_points(&seq.points, None))
                    .expect("correspondences have two views"),
                (seq.image_size)
                    .map(|s| ImageSize::per_view(s.view(1), s.view(0)).expect("valid sizes")),
            ),
            ViewChange::YFlipped | ViewChange::QuarterTurn => {
                let turn = self == ViewChange::QuarterTurn;
                let (dim, rows) = (seq.points.dim(), seq.points.len());
                let views = dim / 2;
                let heights: Vec<f64> = (0..views)
                    .map(|v| match seq.image_size {
                        Some(size) => size.view(v)[1],
                        None => (0..rows)
                            .map(|i| seq.points.row(i)[2 * v + 1])
                            .fold(0.0, f64::max),
                    })
                    .collect();
                let values: Vec<f64> = (seq.points.values().chunks_exact(2).enumerate())
                    .flat_map(|(j, p)| {
                        let up = heights[j % views] - p[1];
                        if turn { [up, p[0]] } else { [p[0], up] }
                    })
                    .collect();
                let size = seq.image_size.map(|s| match turn {
                    true => {
                        let ([w1, h1], [w2, h2]) = (s.view(0), s.view(1));
                        ImageSize::per_view([h1, w1], [h2, w2]).expect("valid sizes")
                    }
                    false => s,
                });
                let kind = seq.points.kind();
                let points = PointSet::from_flat(kind, dim, values).expect("finite values");
                (points, size)
            }
        };
        Sequence {
            points,
            image_size,
            ..seq.clone()
        }
    }
}

/// A sample named after its sequence and what was done to it.
fn named(seq: &Sequence, what: &str) -> (String, Sample) {
    let mut sample = seq.sample();
    if !what.is_empty() {
        sample.name = format!("{} ({what})", seq.name);
    }
    (seq.name.clone(), sample)
}

/// The correspondence grid.
fn correspondence_grid(s: &GridSettings, seqs: Vec<Sequence>, model_type: &str) -> Grid<'static> {
    use serde_json::json;
    let seqs = std::rc::Rc::new(seqs);
    let (seed, draws) = (s.seed, s.draws);
    let columns = [
        "points kept",
        "added outliers",
        "image scale",
        "image size sent",
        "second image scale",
        "whole pixels",
        "rows shuffled",
        "views",
    ]
    .map(String::from)
    .to_vec();
    let source = format!("AdelaideRMF {model_type} pairs ({})", seqs.len());
    // What each cell changes, from the pairs as they are.
    #[derive(Clone, Copy)]
    struct Spec {
        name: &'static str,
        /// Share of the points kept.
        keep: f64,
        /// Gross outliers added, as a share of the points.
        outliers: f64,
        /// Coordinates and image size multiplied by this.
        factor: f64,
        /// Whether the image size is sent.
        image: bool,
        /// The second image's resolution relative to the first's.
        second: f64,
        /// Coordinates rounded to whole pixels.
        whole: bool,
        /// Rows in a random order.
        shuffled: bool,
        /// How the two images are presented.
        view: ViewChange,
    }
    const AS_IS: Spec = Spec {
        name: "as-is",
        keep: 1.0,
        outliers: 0.0,
        factor: 1.0,
        image: true,
        second: 1.0,
        whole: false,
        shuffled: false,
        view: ViewChange::AsSent,
    };
    let specs = [
        AS_IS,
        Spec {
            name: "subsample-50",
            keep: 0.5,
            ..AS_IS
        },
        Spec {
            name: "subsample-25",
            keep: 0.25,
            ..AS_IS
        },
        Spec {
            name: "outliers+20",
            outliers: 0.2,
            ..AS_IS
        },
        Spec {
            name: "rescale-0.5",
            factor: 0.5,
            ..AS_IS
        },
        Spec {
            name: "rescale-2",
            factor: 2.0,
            ..AS_IS
        },
        Spec {
            name: "no-image-size",
            image: false,
            ..AS_IS
        },
        Spec {
            name: "second-image-1.5",
            second: 1.5,
            ..AS_IS
        },
        Spec {
            name: "second-image-0.75",
            second: 0.75,
            ..AS_IS
        },
        Spec {
            name: "whole-pixels",
            whole: true,
            ..AS_IS
        },
        Spec {
            name: "rows-shuffled",
            shuffled: true,
            ..AS_IS
        },
        Spec {
            name: "views-swapped",
            view: ViewChange::Swapped,
            ..AS_IS
        },
        Spec {
            name: "y-flipped",
            view: ViewChange::YFlipped,
            ..AS_IS
        },
        Spec {
            name: "quarter-turn",
            view: ViewChange::QuarterTurn,
            ..AS_IS
        },
    ];
    let builders = specs
        .into_iter()
        .map(|spec| {
            let Spec {
                name,
                keep,
                outliers,
                factor,
                image,
                second,
                whole,
                shuffled,
                view,
            } = spec;
            let seqs = seqs.clone();
            let source = source.clone();
            let random = keep < 1.0 || outliers > 0.0 || shuffled;
            let build = move || {
                let mut samples = Vec::new();
                for seq in seqs.iter() {
                    if !random {
                        let mut changed = rescale(seq, factor);
                        if second != 1.0 {
                            changed = rescale_second_view(&changed, second);
                        }
                        if !image {
                            changed.image_size = None;
                        }
                        if whole {
                            changed = whole_pixels(&changed);
                        }
                        changed = view.apply(&changed);
                        let what = if view != ViewChange::AsSent {
                            view.describe().to_string()
                        } else if whole {
                            "whole pixels".to_string()
                        } else if second != 1.0 {
                            format!("second image x{second}")
                        } else if factor != 1.0 {
                            format!("x{factor}")
                        } else if !image {
                            "no image size".to_string()
                        } else {
                            String::new()
                        };
                        samples.push(named(&changed, &what));
                        continue;
                    }
                    for draw in 0..draws {
                        let mut rng = rng_for(seed, name, &seq.name, draw);
                        let (changed, what) = if shuffled {
                            (
                                seq.shuffled(&mut rng),
                                format!("rows shuffled, draw {draw}"),
                            )
                        } else if keep < 1.0 {
                            let kept = seq.subsample(keep, &mut rng);
                            (kept, format!("{} %, draw {draw}", 100.0 * keep))
                        } else {
                            let more = add_outliers(seq, outliers, &mut rng);
                            (
                                more,
                                format!("+{} % outliers, draw {draw}", 100.0 * outliers),
                            )
                        };
                        samples.push(named(&changed, &what));
                    }
                }
                let data = if random {
                    format!("{source}, {draws} seeded draws each (seed {seed})")
                } else {
                    source
                };
                Ok(Cell {
                    name: name.to_string(),
                    group: if name == "as-is" {
                        "reference"
                    } else {
                        "one factor"
                    },
                    factors: factors(&[
                        ("points kept", json!(format!("{} %", 100.0 * keep))),
                        ("added outliers", json!(format!("{} %", 100.0 * outliers))),
                        ("image scale", json!(factor)),
                        ("image size sent", json!(image)),
                        ("second image scale", json!(second)),
                        ("whole pixels", json!(whole)),
                        ("rows shuffled", json!(shuffled)),
                        ("views", json!(view.describe())),
                    ]),
                    data,
                    samples,
                    skipped: vec![],
                })
            };
            (name.to_string(), Box::new(build) as BuildFn<'static>)
        })
        .collect();
    let notes = vec![
        "Known K counts the gross outliers as one group (AdelaideRMF's label 0), so K is the number of structures plus one wherever a pair has outliers.".to_string(),
        "Rescaling multiplies the coordinates and the image size together; the image-frame normalisation divides one by the other, so those cells test that invariance (by a power of two it is exact in floating point).".to_string(),
        "The rows-shuffled cell sends each pair's rows in a random order (the order the pairs' files list them in groups many points of one structure together): the same sets, which a fit should answer alike in any order.".to_string(),
        "The views-swapped cell sends each pair with its two images in the other order, the y-flipped cell with y measured upwards from the bottom of each image, the quarter-turn cell with both images turned a quarter turn clockwise (a photo whose orientation tag was not applied; the image size sent turns too): the same scenes, as other tools and cameras report them.".to_string(),
        "The whole-pixels cell rounds every coordinate to the nearest whole pixel, as trackers and annotation tools that report integer pixels do: about 0.29 px of uniform noise more per coordinate.".to_string(),
        "The second-image cells give the second view another resolution (a second camera) and send each image's size, [[w, h], [w2, h2]]: the fit reads and refines the second view in the first image's frame, and answers its structures in each image's own pixels. Scored by labels, these cells check that a second camera answers as one camera would, up to rounding.".to_string(),
    ];
    (columns, "as-is".into(), notes, builders)
}

/// The trajectory grid: first clips at frame strides 1, 2 and 3, and stride 1 on the
/// sequences stride 3 covers.
fn trajectory_grid(seqs: Vec<Sequence>, frames: usize) -> Grid<'static> {
    use serde_json::json;
    let seqs = std::rc::Rc::new(seqs);
    let columns = ["frame stride", "frames read", "sequences"]
        .map(String::from)
        .to_vec();
    let specs: [(&str, usize, bool); 4] = [
        ("stride-1", 1, false),
        ("stride-2", 2, false),
        ("stride-3", 3, false),
        ("stride-1-long", 1, true),
    ];
    let builders = specs
        .into_iter()
        .map(|(name, stride, long)| {
            let seqs = seqs.clone();
            let build = move || {
                let (mut samples, mut skipped) = (Vec::new(), Vec::new());
                for seq in seqs.iter() {
                    let covered = !long || seq.clip_every(0, frames, 3).is_some();
                    match seq.clip_every(0, frames, stride) {
                        Some(sample) if covered => samples.push((seq.name.clone(), sample)),
                        _ => skipped.push(seq.name.clone()),
                    }
                }
                let read: Vec<String> = (0..frames)
                    .map(|f| (1 + f * stride).to_string())
                    .collect();
                let which = if long {
                    "those with a stride-3 clip"
                } else {
                    "all with the frames"
                };
                Ok(Cell {
                    name: name.to_string(),
                    group: if name == "stride-1" {
                        "reference"
                    } else {
                        "one factor"
                    },
                    factors: factors(&[
                        ("frame stride", json!(stride)),
                        ("frames read", json!(read.join(", "))),
                        ("sequences", json!(which)),
                    ]),
                    data: format!(
                        "KT3DMoSeg, first clip of {} sequences (tracks visible in every frame read)",
                        samples.len()
                    ),
                    samples,
                    skipped,
                })
            };
            (name.to_string(), Box::new(build) as BuildFn<'static>)
        })
        .collect();
    let notes = vec![
        "Stride s reads frames 1, 1 + s, ..., 1 + 4s of each sequence (faster apparent motion); sequences too short for it are skipped, so stride-1-long repeats stride 1 on exactly the sequences stride 3 covers.".to_string(),
    ];
    (columns, "stride-1".into(), notes, builders)
}

fn value_text(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::String(s) => s.clone(),
        serde_json::Value::Bool(true) => "yes".into(),
        serde_json::Value::Bool(false) => "no".into(),
        serde_json::Value::Number(n) => match n.as_f64() {
            Some(x) if x.fract() == 0.0 && x.abs() < 1e15 => format!("{}", x as i64),
            _ => n.to_string(),
        },
        other => other.to_string(),
    }
}

/// The report as a Markdown table, with what it measured above it.
pub fn markdown(r: &Report) -> String {
    let pct = |v: f64| format!("{:.2}", 100.0 * v);
    let sel = r
        .selection
        .to_uppercase()
        .replace("SILHOUETTE", "silhouette");
    let mut out = format!("# Robustness grid: `{}`\n\n", r.model);
    out += &format!(
        "Model `{}` ({}{}), known K and K chosen by the card's selection ({sel}, K = 1..{}){}. \
         Errors in % under the best matching of groups: mean / median over the cell's samples; \
         \"K right\" is the share of samples whose K {sel} chose right; Δ is the known-K mean \
         minus that of `{}`, in points; \"outliers P / R\" (cells with gross outliers, after \
         refinement, known K): the share of points answered −1 that are outliers, and of \
         outliers answered −1. {} samples per generated cell, {} draws per sequence in \
         random real-data cells, data seed {}, {} k-means restarts. {:.0} s in all.\n\n",
        r.model_dir.display(),
        r.kind,
        r.weights_sha256
            .as_deref()
            .map_or(String::new(), |h| format!(
                ", weights sha256 {}",
                &h[..h.len().min(12)]
            )),
        r.k_max,
        if r.refine {
            ", scored after geometric refinement"
        } else {
            ""
        },
        r.reference,
        r.settings.sets,
        r.settings.draws,
        r.settings.seed,
        r.settings.restarts,
        r.seconds
    );
    if !r.command.is_empty() {
        out += &format!("Command: `{}`\n\n", r.command);
    }
    for note in &r.notes {
        out += &format!("- {note}\n");
    }
    if !r.notes.is_empty() {
        out += "\n";
    }
    let reference = r
        .cells
        .iter()
        .find(|c| c.name == r.reference)
        .map(|c| c.known.mean_error);
    out += "| cell | ";
    for c in &r.columns {
        out += &format!("{c} | ");
    }
    let outlier_column = r.cells.iter().any(|c| c.known.outliers.is_some());
    out += &format!("samples | points | K | known K | Δ | {sel} | K right | ");
    if outlier_column {
        out += "outliers P / R | ";
    }
    out += "s |\n|---|";
    out += &"---|".repeat(r.columns.len() + 8 + usize::from(outlier_column));
    out += "\n";
    for c in &r.cells {
        out += &format!("| {} | ", c.name);
        for col in &r.columns {
            out += &format!(
                "{} | ",
                c.factors.get(col).map_or(String::new(), value_text)
            );
        }
        let delta = reference.map_or("".into(), |base| {
            format!("{:+.2}", 100.0 * (c.known.mean_error - base))
        });
        out += &format!(
            "{} | {:.0} | {:.2} | {} / {} | {} | {} / {} | {:.1} % | ",
            c.samples,
            c.mean_points,
            c.mean_k,
            pct(c.known.mean_error),
            pct(c.known.median_error),
            delta,
            pct(c.chosen.mean_error),
            pct(c.chosen.median_error),
            100.0 * c.chosen.k_correct,
        );
        if outlier_column {
            out += &c.known.outliers.map_or(String::new(), |o| {
                format!("{:.2} / {:.2} | ", o.precision, o.recall)
            });
            if c.known.outliers.is_none() {
                out += " | ";
            }
        }
        out += &format!("{:.0} |\n", c.seconds);
    }
    let skipped: Vec<String> = r
        .cells
        .iter()
        .filter(|c| !c.skipped.is_empty())
        .map(|c| format!("{}: {}", c.name, c.skipped.join(", ")))
        .collect();
    if !skipped.is_empty() {
        out += &format!(
            "\nSkipped (no sample in the cell): {}.\n",
            skipped.join("; ")
        );
    }
    out += "\nData of each cell:\n\n";
    for c in &r.cells {
        out += &format!("- {}: `{}`\n", c.name, c.data);
    }
    out
}

/// Writes `robustness.json` and `robustness.md` to `dir` (created if missing).
pub fn write(report: &Report, dir: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let json = serde_json::to_string_pretty(report).map_err(std::io::Error::other)?;
    std::fs::write(dir.join("robustness.json"), json + "\n")?;
    std::fs::write(dir.join("robustness.md"), markdown(report))
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::data::dataset::tests::pair;

    #[test]
    fn views_are_presented_swapped_flipped_and_turned_as_documented() {
        let seq = pair();
        let [w, h] = seq.image_size.unwrap().view(0);
        let swapped = ViewChange::Swapped.apply(&seq);
        let flipped = ViewChange::YFlipped.apply(&seq);
        let turned = ViewChange::QuarterTurn.apply(&seq);
        for i in 0..seq.points.len() {
            let r = seq.points.row(i);
            assert_eq!(swapped.points.row(i), &[r[2], r[3], r[0], r[1]]);
            assert_eq!(flipped.points.row(i), &[r[0], h - r[1], r[2], h - r[3]]);
            assert_eq!(turned.points.row(i), &[h - r[1], r[0], h - r[3], r[2]]);
        }
        assert_eq!(turned.image_size.unwrap().view(1), [h, w]);
        assert_eq!(flipped.image_size, seq.image_size);
        // Flipping twice and turning four times give the pair back; labels never move.
        let back = ViewChange::YFlipped.apply(&flipped);
        assert_eq!(back.points.values(), seq.points.values());
        let mut round = seq.clone();
        for _ in 0..4 {
            round = ViewChange::QuarterTurn.apply(&round);
        }
        assert_eq!(round.points.values(), seq.points.values());
        assert_eq!(round.image_size, seq.image_size);
        for changed in [&swapped, &flipped, &turned] {
            assert_eq!(changed.labels, seq.labels);
        }
        assert_eq!(
            ViewChange::AsSent.apply(&seq).points.values(),
            seq.points.values()
        );
    }

    #[test]
    fn shuffling_keeps_every_row_with_its_label_in_a_seeded_order() {
        let seq = pair();
        let a = seq.shuffled(&mut rng_for(1, "c", "pair", 0));
        let b = seq.shuffled(&mut rng_for(1, "c", "pair", 0));
        let c = seq.shuffled(&mut rng_for(1, "c", "pair", 1));
        assert_eq!(a.points, b.points);
        assert_ne!(a.points, c.points);
        assert_ne!(a.points, seq.points);
        // Each original row appears once, with its label (the pair's rows are distinct).
        let mut seen = vec![false; seq.points.len()];
        for i in 0..a.points.len() {
            let j = (0..seq.points.len())
                .find(|&j| seq.points.row(j) == a.points.row(i))
                .unwrap();
            assert!(!seen[j], "row {j} twice");
            seen[j] = true;
            assert_eq!(seq.labels[j], a.labels[i]);
        }
        assert!(seen.iter().all(|&s| s));
        assert_eq!(a.image_size, seq.image_size);
    }

    #[test]
    fn subsampling_keeps_a_seeded_share_in_order() {
        let seq = pair();
        let a = seq.subsample(0.25, &mut rng_for(1, "c", "pair", 0));
        let b = seq.subsample(0.25, &mut rng_for(1, "c", "pair", 0));
        let c = seq.subsample(0.25, &mut rng_for(1, "c", "pair", 1));
        assert_eq!(a.points.len(), 10);
        assert_eq!(a.points, b.points);
        assert_ne!(a.points, c.points);
        // Every kept row is an original row with its label, in the original order.
        let mut last = None;
        for i in 0..a.points.len() {
            let j = (0..seq.points.len())
                .find(|&j| seq.points.row(j) == a.points.row(i))
                .unwrap();
            assert_eq!(seq.labels[j], a.labels[i]);
            assert!(last < Some(j));
            last = Some(j);
        }
        assert_eq!(
            seq.subsample(0.5, &mut rng_for(1, "c", "pair", 0))
                .points
                .len(),
            20
        );
        assert_eq!(
            seq.subsample(0.0, &mut rng_for(1, "c", "pair", 0))
                .points
                .len(),
            2
        );
    }

    #[test]
    fn added_outliers_are_uniform_over_the_image_and_in_the_outlier_group() {
        let seq = pair();
        let more = add_outliers(&seq, 0.2, &mut rng_for(2, "o", "pair", 0));
        assert_eq!(more.points.len(), 48);
        assert_eq!(&more.labels[..40], &seq.labels[..]);
        assert!(more.labels[40..].iter().all(|&l| l == 0));
        for i in 40..48 {
            let r = more.points.row(i);
            assert!((0.0..=640.0).contains(&r[0]) && (0.0..=640.0).contains(&r[2]));
            assert!((0.0..=480.0).contains(&r[1]) && (0.0..=480.0).contains(&r[3]));
        }
        // They join the existing outlier group: still three groups.
        let (sample, before) = (more.sample(), seq.sample());
        assert_eq!((sample.k, before.k), (3, 3));
        assert_eq!(
            sample.labels.iter().filter(|&&l| l == 0).count(),
            before.labels.iter().filter(|&&l| l == 0).count() + 8
        );
        // Without outliers before, they make a group of their own.
        let clean = seq.rows(&(0..40).filter(|i| i % 4 != 0).collect::<Vec<_>>());
        assert_eq!(clean.sample().k, 2);
        assert_eq!(
            add_outliers(&clean, 0.2, &mut rng_for(2, "o", "p", 0))
                .sample()
                .k,
            3
        );
        // Without an image size, the bounding box of each column bounds them.
        let mut bare = seq.clone();
        bare.image_size = None;
        let more = add_outliers(&bare, 0.5, &mut rng_for(2, "o", "pair", 0));
        for d in 0..4 {
            let col = |s: &Sequence, i: usize| s.points.row(i)[d];
            let lo = (0..40).map(|i| col(&seq, i)).fold(f64::INFINITY, f64::min);
            let hi = (0..40)
                .map(|i| col(&seq, i))
                .fold(f64::NEG_INFINITY, f64::max);
            assert!((40..60).all(|i| (lo..=hi).contains(&col(&more, i))));
        }
    }

    #[test]
    fn rescaling_moves_points_and_image_together() {
        let seq = pair();
        let big = rescale(&seq, 2.0);
        assert_eq!(big.points.row(3)[0], 2.0 * seq.points.row(3)[0]);
        assert_eq!(big.image_size.unwrap().width, 1280.0);
        assert_eq!(big.labels, seq.labels);
        // By a power of two the normalised input is the same, bit for bit.
        let norm = crate::data::Normalization::ImageFrame;
        assert_eq!(
            norm.apply(&big.points, big.image_size),
            norm.apply(&seq.points, seq.image_size)
        );
    }

    #[test]
    fn whole_pixels_rounds_every_coordinate_and_keeps_the_rest() {
        let seq = pair();
        let whole = whole_pixels(&seq);
        for i in 0..seq.points.len() {
            for (w, v) in whole.points.row(i).iter().zip(seq.points.row(i)) {
                assert_eq!(*w, v.round());
                assert!((w - v).abs() <= 0.5);
            }
        }
        assert_eq!(whole.labels, seq.labels);
        assert_eq!(whole.image_size, seq.image_size);
    }

    #[test]
    fn a_second_image_rescaled_keeps_the_first_view_and_sends_both_sizes() {
        let seq = pair();
        let second = rescale_second_view(&seq, 2.0);
        let (a, b) = (seq.points.row(3), second.points.row(3));
        assert_eq!(&b[..2], &a[..2]);
        assert_eq!(&b[2..], &[2.0 * a[2], 2.0 * a[3]]);
        let size = second.image_size.unwrap();
        assert_eq!(
            (size.view(0), size.view(1)),
            ([640.0, 480.0], [1280.0, 960.0])
        );
        // Read in the first image's frame, the network sees the pair as sent in one camera.
        let (moved, first) = size.in_first_frame(&second.points);
        let norm = crate::data::Normalization::ImageFrame;
        assert_eq!(
            norm.apply(&moved, Some(first)),
            norm.apply(&seq.points, seq.image_size)
        );
    }

    #[test]
    fn the_lce_grid_has_its_cells_and_the_paper_test_set() {
        let s = GridSettings {
            sets: 3,
            ..GridSettings::default()
        };
        let (columns, reference, _, builders) = lce_grid(&s);
        let names: Vec<&str> = builders.iter().map(|b| b.0.as_str()).collect();
        assert_eq!(names.len(), 19, "{names:?}");
        assert_eq!(names[0], "paper-protocol");
        assert!(names.contains(&reference.as_str()));
        for want in [
            "sweep-20-s1",
            "sweep-400-s4",
            "random-types",
            "arcs-90-360",
            "outliers-0.2",
            "outliers-0.5",
            "similarity",
            "unequal-20-300",
        ] {
            assert!(names.contains(&want), "{want}");
        }
        assert_eq!(columns.len(), 6);
        let mut cells: BTreeMap<String, Cell> = builders
            .into_iter()
            .map(|(name, build)| (name, build().unwrap()))
            .collect();
        let paper = &cells["paper-protocol"];
        assert_eq!(
            paper.data,
            "lce:mixed,count=200,seed=4,scale=2,noise=0.05,points=50"
        );
        assert_eq!(paper.samples.len(), 200);
        let outliers = cells.remove("outliers-0.5").unwrap();
        assert_eq!(outliers.samples.len(), 3);
        assert!(
            outliers
                .samples
                .iter()
                .all(|(_, s)| s.k == 5 && s.points.len() == 300)
        );
        assert_eq!(
            cells["unequal-20-300"].data,
            "lce:mixed,count=3,seed=1000,scale=2,noise=0.05,points=20-300"
        );
        assert_eq!(
            cells["sweep-150-s4"].factors["scale"],
            serde_json::json!(4.0)
        );
        assert_eq!(
            cells["sweep-150-s4"].factors["points/shape"],
            serde_json::json!(150)
        );
    }

    #[test]
    fn settings_that_cannot_run_are_refused_by_flag() {
        for (bad, says) in [
            (
                GridSettings {
                    sets: 0,
                    ..GridSettings::default()
                },
                "--sets 0",
            ),
            (
                GridSettings {
                    draws: 0,
                    ..GridSettings::default()
                },
                "--draws 0",
            ),
            (
                GridSettings {
                    restarts: 0,
                    ..GridSettings::default()
                },
                "--restarts 0",
            ),
            (
                GridSettings {
                    k_max: Some(0),
                    ..GridSettings::default()
                },
                "--k-max 0",
            ),
        ] {
            let err = bad.validate().unwrap_err().to_string();
            assert!(err.contains(says), "{err}");
        }
        assert!(
            model_type(&GridSettings::default(), "adelaide-fundamental").unwrap() == "fundamental"
        );
        let err = model_type(&GridSettings::default(), "mine")
            .unwrap_err()
            .to_string();
        assert!(err.contains("--model-type"), "{err}");
    }

    #[test]
    fn markdown_has_a_row_per_cell_and_deltas_from_the_reference() {
        let summary = |e: f64| Summary {
            mean_error: e,
            median_error: e / 2.0,
            mean_nmi: 0.5,
            k_correct: 0.75,
            outliers: None,
        };
        let cell = |name: &str, e: f64| CellResult {
            name: name.into(),
            group: "sweep".into(),
            factors: factors(&[
                ("scale", serde_json::json!(2.0)),
                ("similarity", serde_json::json!(true)),
            ]),
            data: format!("lce:{name}"),
            samples: 4,
            mean_points: 200.0,
            mean_k: 4.0,
            known: summary(e),
            chosen: summary(e + 0.01),
            totals: Totals {
                samples: 4,
                known: summary(e),
                sod: summary(e + 0.01),
                silhouette: summary(e + 0.02),
            },
            skipped: if name == "b" {
                vec!["short".into()]
            } else {
                vec![]
            },
            per_sample: vec![],
            seconds: 1.0,
        };
        let report = Report {
            model: "m".into(),
            model_dir: "models/m".into(),
            kind: Kind::Points2d,
            weights_sha256: Some("abcdef0123456789".into()),
            folds: None,
            selection: "sod".into(),
            k_max: 6,
            refine: false,
            refine_stay: 0.0,
            refine_margin: 0.0,
            settings: GridSettings::default(),
            columns: vec!["scale".into(), "similarity".into()],
            reference: "a".into(),
            notes: vec!["a note".into()],
            command: "multifit-train robustness --model models/m".into(),
            cells: vec![cell("a", 0.1), cell("b", 0.125)],
            seconds: 2.0,
        };
        let md = markdown(&report);
        assert!(md.contains("| a | 2 | yes | 4 | 200 | 4.00 | 10.00 / 5.00 | +0.00 | 11.00 / 5.50 | 75.0 % | 1 |"), "{md}");
        assert!(
            md.contains("| b | 2 | yes | 4 | 200 | 4.00 | 12.50 / 6.25 | +2.50 |"),
            "{md}"
        );
        assert!(
            md.contains("Skipped (no sample in the cell): b: short."),
            "{md}"
        );
        assert!(
            md.contains("- a note") && md.contains("abcdef012345"),
            "{md}"
        );
        let back: Report = serde_json::from_str(&serde_json::to_string(&report).unwrap()).unwrap();
        assert_eq!(back, report);
    }
}
