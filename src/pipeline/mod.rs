//! The fit pipeline: one place that reads in the order a fit runs.
//!
//! 1. **normalise** ([`check`], [`frames_read`], [`Normalization`], thinning): the input
//!    must be the model's kind; tracks of any length F ≥ 2 are read at the model's frame count
//!    (frames spread over the whole track, or the first ones, as the card says); coordinates are
//!    mapped into the frame the network was trained in; a set denser than the model's training
//!    sets is read at a subset of the training density, and one much sparser by the card's
//!    network for sparse sets where it has one ([`crate::data::density`]).
//! 2. **features** ([`network_input`]): the offsets to each point's nearest neighbours. Training
//!    builds its input with the same function, so training and serving cannot drift apart.
//! 3. **embed** ([`embed`]): every network of the model that reads the set (the card's and its
//!    members', or for a much sparser set its network for sparse sets) on the input and on its
//!    images under the card's test-time symmetries; each point's unit embeddings side by side,
//!    scaled to unit length.
//! 4. **cluster** ([`cluster`]): k-means on the embeddings, K given or chosen from the residual
//!    curve (SOD or silhouette).
//! 5. **refine** ([`crate::refine`]): an explicit model per group (line, circle, ellipse,
//!    homography, fundamental matrix, motion subspace), fitted on the input as sent (every frame,
//!    caller's units); points reassigned to the structure they fit best, outliers labelled −1.
//!    With K chosen, the k + 1 clustering is refined too and answers where it parts structures
//!    that pooled two, and from it the k + 2 one, and so on ([`refine_chosen`]); with a k given, where the outliers take a group of
//!    their own, and the clustering K chosen would give answers where its k structures are far
//!    less noisy ([`crate::refine::replaces_given`]). A small set of curves, or of
//!    correspondences given k (at most [`SEEDED_MAX_ROWS`] rows), is also clustered from more
//!    k-means seeds at the same K, and the answer whose structures explain the rows at the least
//!    truncated cost is kept ([`refine_seeded`]).
//! 6. **answer** ([`FitOutcome`]): labels, K, structures, the residual curve and the stage
//!    timings.
//!
//! Tracks seen in some frames only run these stages on the tracks seen throughout, and the
//! others are placed on the motions found ([`fit_seen`]).

use std::borrow::Cow;
use std::time::Instant;

use crate::cluster::{self, ClusterError, ClusterParams, Clustering, Points, Selection};
use crate::data::features::with_neighbors;
use crate::data::screen::{self, Screened, screen};
use crate::data::symmetry::closure;
use crate::data::{ImageSize, Kind, Normalization, PointSet, Symmetry};
use crate::data::{density, frames};
use crate::geometry::{self, UNMOVED};
use crate::refine::{self, RefineParams, Refined, Structure};
use crate::registry::{LoadedModel, Observed};

mod seen;
mod warnings;
pub use seen::fit_seen;
use warnings::{erratic_apart, far_apart, fewer_than_asked, image_warnings, lost_marks, observed};

/// Why a fit request cannot be answered by this model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    #[error("model {model} takes {expected} input, got {found}")]
    WrongKind {
        model: String,
        expected: Kind,
        found: Kind,
    },
    #[error("model {model} takes rows of {expected} values, got {found}")]
    WrongDim {
        model: String,
        expected: usize,
        found: usize,
    },
    #[error(
        "k = {k} is more than the {read} points model {model} reads from these {n}: it reads \
         each repeated point once, sets apart points far from the rest, and thins a set denser \
         than its training data before reading it"
    )]
    KAboveRead {
        model: String,
        k: usize,
        read: usize,
        n: usize,
    },
    #[error(transparent)]
    Cluster(#[from] ClusterError),
    #[error("input: {0}")]
    Input(String),
}

/// What one fit does beyond the input: K, test-time symmetries, refinement.
#[derive(Debug, Clone, Copy)]
pub struct FitOptions<'a> {
    pub params: &'a ClusterParams,
    /// Test-time symmetries (`&[]`: the input alone, one forward pass per network).
    pub symmetries: &'a [Symmetry],
    /// Geometric refinement, or `None` for the learned clustering alone.
    pub refine: Option<RefineParams>,
    /// Without refinement, whether a fit may answer the network's outlier group −1 (curves and
    /// correspondences; the request's `outliers`, by default the card's): the group of the chosen
    /// K that holds the outliers ([`refine::outlier_group`]), or the one group of the k + 1
    /// clustering for a k given that follows no model.
    pub outlier_group: bool,
    /// Whether tracks set apart as erratic ([`Embedding::erratic`]) are answered −1, refined or
    /// not: they follow no motion (the request's `outliers` unless it is false). Otherwise each
    /// takes the label of the structure, or of the read track, nearest it.
    pub erratic_outliers: bool,
}

/// The answer to one fit.
#[derive(Debug, Clone)]
pub struct FitOutcome {
    /// The learned clustering (stage 4): its labels, K and residual curve. With a K given on a
    /// model whose network learned the outliers as a group, the k + 1 clustering when its answer
    /// was kept; the residual curve then holds both Ks.
    pub clustering: Clustering,
    /// The answer's labels: the refined ones (−1 for outliers) with refinement, else the
    /// clustering's (its outlier group −1 when [`fit`] answered it apart).
    pub labels: Vec<i64>,
    /// The answer's structures: one per label 0..k with refinement, none without.
    pub structures: Vec<Structure>,
    /// The answer's K (structures, not counting outliers).
    pub k: usize,
    /// Quantities of the input outside what the model was validated on.
    pub warnings: Vec<String>,
    /// Row-major `[n, embed_dim]`.
    pub embeddings: Vec<f32>,
    pub embed_dim: usize,
    pub embed_ms: f64,
    pub cluster_ms: f64,
    pub refine_ms: f64,
}

/// Stage 1: the input is of the model's kind and width. Trajectories of any frame count F ≥ 2
/// pass: [`frames_read`] brings them to the model's.
pub fn check(model: &LoadedModel, points: &PointSet) -> Result<(), FitError> {
    let card = &model.card;
    if points.kind() != card.kind {
        return Err(FitError::WrongKind {
            model: card.name.clone(),
            expected: card.kind,
            found: points.kind(),
        });
    }
    let any_length = card.kind == Kind::Trajectories;
    if points.dim() != card.input_dim && !any_length {
        return Err(FitError::WrongDim {
            model: card.name.clone(),
            expected: card.input_dim,
            found: points.dim(),
        });
    }
    Ok(())
}

/// Stage 1: the frames the network reads, `[n, 2F]` -> one `[n, input_dim]` set per window:
/// the input itself when it has the model's width, else its tracks resampled to the model's
/// frame count as the card's `frames` says (one window, or several for
/// [`frames::FrameSampling::Windows`]). Only trajectories have frames; other kinds pass
/// unchanged.
pub fn frames_read(model: &LoadedModel, points: &PointSet) -> Vec<PointSet> {
    if read_as_sent(model, points) {
        return vec![points.clone()];
    }
    frames::resample_windows(points, model.card.input_dim / 2, model.card.frames)
}

/// Whether the network reads `points` as sent: not trajectories, or already the model's frames.
fn read_as_sent(model: &LoadedModel, points: &PointSet) -> bool {
    model.card.kind != Kind::Trajectories || points.dim() == model.card.input_dim
}

/// Stages 1 and 2, the one place the network input is built, for training and serving alike:
/// normalised `points` `[n, d]` followed by the offsets to each point's `neighbors` nearest
/// others -> `[n, d * (1 + neighbors)]` row-major.
pub fn network_input(
    normalization: Normalization,
    points: &PointSet,
    image: Option<ImageSize>,
    neighbors: usize,
) -> Vec<f32> {
    with_neighbors(&normalization.apply(points, image), points.dim(), neighbors)
}

/// Stages 1 and 2 for one model: checked, read at the model's frames (the first window when
/// the card reads several), normalised and with neighbour offsets: `points` `[n, d]` ->
/// `[n, feature_dim]`.
pub fn prepare(
    model: &LoadedModel,
    points: &PointSet,
    image: Option<ImageSize>,
) -> Result<Vec<f32>, FitError> {
    check(model, points)?;
    let (points, image) = in_first_frame(points, image);
    let points = points.as_ref();
    let card = &model.card;
    let resampled;
    let read = if read_as_sent(model, points) {
        points
    } else {
        resampled = frames::resample(points, card.input_dim / 2, card.frames);
        &resampled
    };
    Ok(network_input(
        card.normalization,
        read,
        image,
        card.architecture.neighbors,
    ))
}

/// Stage 1 for pairs of images of two sizes: the second view carried into the first image's
/// frame ([`ImageSize::in_first_frame`]), so that the network reads both views in one frame.
fn in_first_frame(
    points: &PointSet,
    image: Option<ImageSize>,
) -> (Cow<'_, PointSet>, Option<ImageSize>) {
    match image {
        Some(size) => {
            let (points, size) = size.in_first_frame(points);
            (points, Some(size))
        }
        None => (Cow::Borrowed(points), None),
    }
}

/// How the network reads a set (stage 1).
struct ReadPlan {
    /// The rows read, and for every input row its read row; `None`: every row.
    thinned: Option<(Vec<usize>, Vec<usize>)>,
    /// Whether the card's network for sparse sets reads it.
    sparse: bool,
    /// The rows set apart as far from the rest ([`screen`]), the erratic tracks among them.
    far: Vec<usize>,
    /// The tracks among `far` set apart for moving erratically.
    erratic: Vec<usize>,
}

/// Stage 1: how the model reads the set. No row far from the rest, and, for a network that
/// reads neighbourhoods, each distinct row once ([`screen`]: both give the network a picture it
/// was never trained on); then, for cards that
/// record their training spacing ([`density::reading`]), a set denser than training at a seeded
/// subset, one sparser than the card's sparse network's threshold by that network. Rows not
/// read take their nearest read row's embedding. `whole` is the set as sent (rows compared over
/// every frame), `windows` the same rows at each window of the model's frames it reads.
fn read_plan(
    model: &LoadedModel,
    whole: &PointSet,
    windows: &[PointSet],
    image: Option<ImageSize>,
    seed: u64,
) -> Result<ReadPlan, FitError> {
    let card = &model.card;
    let neighbourhoods = card.architecture.neighbors > 0 || card.architecture.graph_neighbors > 0;
    let Screened {
        read: kept,
        far,
        erratic,
    } = screen(whole, neighbourhoods, windows);
    let read = &windows[0];
    let Some(trained) = card.spacing else {
        return Ok(ReadPlan {
            thinned: kept
                .map(|rows| owned_by_nearest(model, read, image, rows, &far))
                .transpose()?,
            sparse: false,
            far,
            erratic,
        });
    };
    let subset = match &kept {
        Some(rows) => Cow::Owned(
            read.select(rows)
                .map_err(|e| FitError::Input(e.to_string()))?,
        ),
        None => Cow::Borrowed(read),
    };
    let normalised = card.normalization.apply(&subset, image);
    let k = card.architecture.neighbors;
    let above = card.sparse.as_ref().map(|s| s.above);
    let reading = density::reading(&normalised, read.dim(), k, trained, above, seed);
    let (rows, sparse) = match reading {
        density::Reading::Whole => (kept, false),
        density::Reading::Sparse => (kept, true),
        density::Reading::Thinned(rows) => {
            let rows = match &kept {
                Some(kept) => rows.into_iter().map(|r| kept[r]).collect(),
                None => rows,
            };
            (Some(rows), false)
        }
    };
    // Each row's nearest read row: in the frame the subset was read in where every row is in
    // it, otherwise in the frame of the rows that are not far ([`owned_by_nearest`]).
    let thinned = rows
        .map(|rows| match subset {
            Cow::Borrowed(_) => {
                let owner = density::nearest_read(&normalised, read.dim(), &rows);
                Ok((rows, owner))
            }
            Cow::Owned(_) => owned_by_nearest(model, read, image, rows, &far),
        })
        .transpose()?;
    Ok(ReadPlan {
        thinned,
        sparse,
        far,
        erratic,
    })
}

/// The `rows` of `read` a model reads (ascending, none of them `far`), and for every row of
/// `read` its nearest read row (in the card's normalised frame of the rows that are not far,
/// where a row read is its own: a far row in the frame would squeeze the others together, and
/// in f32 a row left out could no longer tell the read row nearest it from its neighbours; a
/// far row takes the read row nearest it in the caller's units).
fn owned_by_nearest(
    model: &LoadedModel,
    read: &PointSet,
    image: Option<ImageSize>,
    rows: Vec<usize>,
    far: &[usize],
) -> Result<(Vec<usize>, Vec<usize>), FitError> {
    let dim = read.dim();
    if far.is_empty() {
        let normalised = model.card.normalization.apply(read, image);
        let owner = density::nearest_read(&normalised, dim, &rows);
        return Ok((rows, owner));
    }
    let near = screen::not_far(read.len(), far);
    let subset = read
        .select(&near)
        .map_err(|e| FitError::Input(e.to_string()))?;
    let normalised = model.card.normalization.apply(&subset, image);
    // Each read row's place among the rows that are not far (every read row is one of them).
    let places: Vec<usize> = rows
        .iter()
        .filter_map(|r| near.binary_search(r).ok())
        .collect();
    debug_assert_eq!(places.len(), rows.len(), "a read row is far");
    let owner_near = density::nearest_read(&normalised, dim, &places);
    // Far rows: the nearest read row in the caller's units (f32 holds a far row's distance
    // well enough to rank the read rows from it), searched among the read rows alone: in
    // `units` the read rows come first, in order, then the far ones.
    let units: Vec<f32> = rows
        .iter()
        .chain(far)
        .flat_map(|&i| read.row(i).iter().map(|&v| v as f32))
        .collect();
    let first: Vec<usize> = (0..rows.len()).collect();
    let owner_far = density::nearest_read(&units, dim, &first);
    let mut owner = vec![0; read.len()];
    for (&i, &o) in near.iter().zip(&owner_near) {
        owner[i] = o;
    }
    for (&i, &o) in far.iter().zip(&owner_far[rows.len()..]) {
        owner[i] = o;
    }
    Ok((rows, owner))
}

/// The embeddings of a set: one row per point read.
#[derive(Debug, Clone, PartialEq)]
pub struct Embedding {
    /// Row-major `[m, width]`: the points read, in input order.
    pub values: Vec<f32>,
    pub width: usize,
    /// For each input row, its row in `values` (its own, or its nearest read point's); `None`
    /// when every row was read (m = n).
    pub owner: Option<Vec<usize>>,
    /// The input rows not read for lying far from the rest ([`screen`]), ascending; the erratic
    /// tracks among them.
    pub far: Vec<usize>,
    /// The tracks among `far` not read for moving erratically, ascending.
    pub erratic: Vec<usize>,
}

impl Embedding {
    /// One row per input point `[n, width]`: a point that was not read gets its nearest read
    /// point's embedding.
    pub fn per_point(&self) -> Vec<f32> {
        match &self.owner {
            None => self.values.clone(),
            Some(owner) => owner
                .iter()
                .flat_map(|&o| &self.values[o * self.width..(o + 1) * self.width])
                .copied()
                .collect(),
        }
    }
}

/// Stage 3: the embeddings a fit clusters: `points` `[n, d]` -> `[m, e * c]` over the m rows
/// read (a set denser than the model's training sets is thinned, with `seed`), where c counts
/// the frame windows read ([`frames_read`]) times the networks (the card's and its members, or
/// for a set sparser than training its network for sparse sets alone) times the images (the
/// input and its images under every combination of `symmetries`). Row i holds the embeddings
/// of point i by each network of each image of each window (networks vary fastest, windows
/// slowest), side by side, divided by the square root of c so that it keeps unit length. An
/// image that does not exist (a symmetry that does not apply to the kind, or coordinates pushed
/// past the accepted range) is left out.
pub fn embed(
    model: &LoadedModel,
    points: &PointSet,
    image: Option<ImageSize>,
    symmetries: &[Symmetry],
    seed: u64,
) -> Result<Embedding, FitError> {
    check(model, points)?;
    let (points, image) = in_first_frame(points, image);
    let mut windows = frames_read(model, &points);
    let ReadPlan {
        thinned,
        sparse,
        far,
        erratic,
    } = read_plan(model, &points, &windows, image, seed)?;
    let (rows, owner) = thinned.unzip();
    // The windows side by side on the model's threads (each one's neighbour searches run on
    // one thread; its forward pass spreads over all of them).
    let pool = model.pool();
    let blocks = pool
        .install(|| {
            pool.map(&mut windows, |read| {
                embed_rows(model, read, rows.as_deref(), sparse, image, symmetries)
            })
        })
        .into_iter()
        .collect::<Result<Vec<_>, _>>()?;
    let (block_width, width) = (blocks[0].1, blocks[0].1 * blocks.len());
    let values = side_by_side(blocks.into_iter().map(|(v, _)| v).collect(), block_width);
    Ok(Embedding {
        values,
        width,
        owner,
        far,
        erratic,
    })
}

/// [`embed`] of the given rows (`None`: all) of `read`, one window at the model's frames, by
/// the card's networks or (`sparse`) its network for sparse sets:
/// -> (`[m, width]`, width), rows of unit length.
fn embed_rows(
    model: &LoadedModel,
    read: &PointSet,
    rows: Option<&[usize]>,
    sparse: bool,
    image: Option<ImageSize>,
    symmetries: &[Symmetry],
) -> Result<(Vec<f32>, usize), FitError> {
    let e = model.card.architecture.embed_dim;
    let read = match rows {
        Some(rows) => read
            .select(rows)
            .map_err(|e| FitError::Input(e.to_string()))?,
        None => read.clone(),
    };
    let m = read.len();
    let mut images = if symmetries.is_empty() {
        vec![read]
    } else {
        closure(vec![read], symmetries, |s, p| s.apply_points(p, image))
    };
    // The images side by side on the model's threads, as the windows are.
    let pool = model.pool();
    let mut all = Vec::new();
    for per_image in pool.install(|| {
        pool.map(&mut images, |p| {
            prepare(model, p, image).map(|input| model.embed_all(&input, sparse))
        })
    }) {
        all.extend(per_image?);
    }
    let width = e * all.len();
    debug_assert!(all.iter().all(|z| z.len() == m * e));
    Ok((side_by_side(all, e), width))
}

/// c blocks of unit rows, each `[m, width]` -> `[m, c * width]`: row i holds row i of every
/// block in order, divided by the square root of c so that it keeps unit length.
fn side_by_side(mut blocks: Vec<Vec<f32>>, width: usize) -> Vec<f32> {
    if blocks.len() == 1 {
        return blocks.remove(0);
    }
    let m = blocks[0].len() / width;
    let scale = 1.0 / (blocks.len() as f32).sqrt();
    (0..m)
        .flat_map(|i| {
            blocks
                .iter()
                .flat_map(move |z| &z[i * width..(i + 1) * width])
        })
        .map(|v| v * scale)
        .collect()
}

/// Stage 4: clusters embeddings from [`embed`] on the model's threads: `[m, width]` -> K, the
/// residual curve and one label per input point (a point that was not read takes its nearest
/// read point's).
pub fn cluster(
    model: &LoadedModel,
    embedding: &Embedding,
    params: &ClusterParams,
) -> Result<Clustering, FitError> {
    let points = Points::new(&embedding.values, embedding.width)?;
    let mut clustering = cluster::cluster_on(points, params, model.pool())?;
    if let Some(owner) = &embedding.owner {
        clustering.labels = owner.iter().map(|&o| clustering.labels[o]).collect();
        clustering.cluster_sizes = vec![0; clustering.k];
        for &l in &clustering.labels {
            clustering.cluster_sizes[l] += 1;
        }
    }
    Ok(clustering)
}

/// The rows refinement fits: every row of `points`, or, where some lie far from the rest
/// ([`Embedding::far`]), the others, selected once per fit for all its refinements.
pub struct RefineRows<'a> {
    points: &'a PointSet,
    far: &'a [usize],
    /// The rows that are not far, and the set of them; `None` when no row is far.
    near: Option<(Vec<usize>, PointSet)>,
}

impl<'a> RefineRows<'a> {
    /// How many rows refinement fits.
    pub fn count(&self) -> usize {
        self.near
            .as_ref()
            .map_or(self.points.len(), |(near, _)| near.len())
    }

    pub fn new(points: &'a PointSet, far: &'a [usize]) -> Self {
        let near = (!far.is_empty())
            .then(|| {
                let near = screen::not_far(points.len(), far);
                points.select(&near).ok().map(|kept| (near, kept))
            })
            .flatten();
        Self { points, far, near }
    }
}

/// Stage 5: the learned clustering refined into explicit structures of the model's family,
/// on the points as the caller sent them. Rows far from the rest ([`Embedding::far`]) take no
/// part: they would sway the fits of the groups they were clustered with (a normalisation that
/// centres and scales a group's rows moves with them). They are answered −1 where outliers may
/// be, else joined to the structure they are nearest.
pub fn refine(
    model: &LoadedModel,
    rows: &RefineRows,
    clustering: &Clustering,
    params: &RefineParams,
) -> Refined {
    // A K the caller gave is kept; a chosen one may change within the K the choice considered.
    let k_chosen = (!matches!(clustering.selection, Selection::Fixed(_))).then(|| {
        let considered = clustering.scores.iter().map(|s| s.0).max();
        considered.unwrap_or(clustering.k).max(clustering.k)
    });
    let on = |points: &PointSet, labels: &[usize]| {
        refine::refine_on(
            points,
            labels,
            clustering.k,
            model.card.family(),
            params,
            k_chosen,
            model.pool(),
        )
    };
    let Some((near, kept)) = &rows.near else {
        return on(rows.points, &clustering.labels);
    };
    // Every group keeps rows: a far row takes the label of its nearest read row.
    let labels: Vec<usize> = near.iter().map(|&i| clustering.labels[i]).collect();
    let mut refined = on(kept, &labels);
    let mut all = vec![-1; rows.points.len()];
    for (&i, &l) in near.iter().zip(&refined.labels) {
        all[i] = l;
    }
    if !params.outliers {
        for &i in rows.far {
            let nearest = refined
                .structures
                .iter()
                .map(|s| (s.model.residual(rows.points.row(i)), s.label as i64))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            all[i] = nearest.map_or(-1, |(_, l)| l);
        }
    }
    refined.labels = all;
    refined
}

/// Sets whose refinement fits at most this many rows are refined from more k-means seeds
/// ([`refine_seeded`]).
pub const SEEDED_MAX_ROWS: usize = 500;
/// The k-means seeds [`refine_seeded`] tries beyond the request's.
pub const EXTRA_SEEDS: u64 = 3;

/// [`refine`] of `clustering` (k-means of `embedding` with `params`' seed). On sets of curves,
/// and of correspondences where the caller gave k (`k_given`: the number of structures is
/// fixed, so the seeds' answers differ only in which structures; with K chosen the split test
/// compares answers' noise, and a search there moved K on sparse pairs), whose refinement fits
/// at most [`SEEDED_MAX_ROWS`] rows (rows set apart as far not counted),
/// k-means also clusters `embedding` at the same K from [`EXTRA_SEEDS`] more seeds derived from
/// `params`' (a seed whose clustering fails is skipped), each partition not seen yet is refined
/// as `clustering` is (its selection and scores, so a chosen K may still merge or grow), and the
/// answer is the first of least truncated cost among those with as many structures as the first
/// ([`refine::cheapest`]). A few sets hold partitions of near-equal k-means residual that
/// refinement takes to different answers, and the seed alone picks one; the cost of the
/// structures on every row tells them apart. The answer stays a function of the input and the
/// seed. The clustering's K, residual curve and scores are those of `clustering` whichever
/// partition the answer came from. -> labels `[n]` (−1 for outliers) and the structures.
pub fn refine_seeded(
    model: &LoadedModel,
    rows: &RefineRows,
    embedding: &Embedding,
    params: &ClusterParams,
    clustering: &Clustering,
    r: &RefineParams,
    k_given: bool,
) -> Refined {
    let first = refine(model, rows, clustering, r);
    let searched = match model.card.family() {
        geometry::Family::Curves => true,
        geometry::Family::Subspace => false,
        _ => k_given,
    };
    if !searched || rows.count() > SEEDED_MAX_ROWS {
        return first;
    }
    let Ok(fixed) = params.with_fixed_k(clustering.k) else {
        return first;
    };
    // Clusterings number their groups by first appearance, so one partition has one labelling.
    let mut seen = vec![clustering.labels.clone()];
    let mut answers = vec![first];
    for i in 1..=EXTRA_SEEDS {
        let seed = params
            .seed()
            .wrapping_add(i.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        // The search is optional: a seed whose clustering fails is skipped, not the fit.
        let Ok(mut other) = cluster(model, embedding, &fixed.with_seed(seed)) else {
            continue;
        };
        if seen.contains(&other.labels) {
            continue;
        }
        seen.push(other.labels.clone());
        // Refined as `clustering` is: a chosen K may still merge or grow.
        other.selection = clustering.selection;
        other.scores = clustering.scores.clone();
        answers.push(refine(model, rows, &other, r));
    }
    let best = refine::cheapest(rows.points, &answers, r.threshold);
    answers.swap_remove(best)
}

/// Stage 5 with K chosen automatically: the clustering refined, and the k + 1 clustering
/// refined too where the choice considered k + 1 (the two side by side on the model's threads);
/// the wider answer is kept where it splits a structure that pooled two
/// ([`refine::splits_pooled`]), and then the k + 2 clustering is tried against it in the same
/// way, and so on ([`refine::split_while_pooled`]). SOD stops at k when splitting a group lowers the embeddings'
/// residual little, and refinement cannot split a structure that holds two planes or curves:
/// their pooled fit sets a noise level under which both fit. A K the caller gave, and motion
/// subspaces, are refined as they are. -> the clustering the answer came from (with both
/// residual curves when it is the wider one), and the answer.
pub fn refine_chosen(
    model: &LoadedModel,
    points: &PointSet,
    embedding: &Embedding,
    params: &ClusterParams,
    clustering: &Clustering,
    r: &RefineParams,
) -> Result<(Clustering, Refined), FitError> {
    let k = clustering.k;
    let considered = clustering.scores.iter().map(|s| s.0).max().unwrap_or(k);
    let read = embedding.values.len() / embedding.width.max(1);
    let rows = RefineRows::new(points, &embedding.far);
    if matches!(clustering.selection, Selection::Fixed(_))
        || model.card.family() == geometry::Family::Subspace
        || k + 1 > considered.min(read)
    {
        let refined = refine_seeded(model, &rows, embedding, params, clustering, r, false);
        return Ok((clustering.clone(), refined));
    }
    let wider = one_more_group(model, embedding, params, clustering)?;
    let (refined, again) = model.pool().join(
        || refine_seeded(model, &rows, embedding, params, clustering, r, false),
        || refine_seeded(model, &rows, embedding, params, &wider, r, false),
    );
    if !refine::splits_pooled(&refined, &again, points.len()) {
        return Ok((clustering.clone(), refined));
    }
    // Each further split is tried only once the one before it was taken, one at a time.
    refine::split_while_pooled((both_ks(clustering, wider), again), points.len(), |from| {
        if from.k + 1 > considered.min(read) {
            return Ok(None);
        }
        let next = one_more_group(model, embedding, params, from)?;
        let answer = refine_seeded(model, &rows, embedding, params, &next, r, false);
        Ok(Some((both_ks(from, next), answer)))
    })
}

/// The clustering of `embedding` into one group more than `clustering`: where the k answer
/// pooled two structures (a chosen K, [`refine_chosen`]) or gave the outliers no group of their
/// own (a k given). A chosen K's selection and scores are kept, so that the wider clustering is
/// refined as a chosen K too (structures may merge, or be added).
fn one_more_group(
    model: &LoadedModel,
    embedding: &Embedding,
    params: &ClusterParams,
    clustering: &Clustering,
) -> Result<Clustering, FitError> {
    let mut wider = cluster(model, embedding, &params.with_fixed_k(clustering.k + 1)?)?;
    if !matches!(clustering.selection, Selection::Fixed(_)) {
        wider.selection = clustering.selection;
        wider.scores = clustering.scores.clone();
    }
    Ok(wider)
}

/// The whole fit of one point set, stage by stage.
pub fn fit(
    model: &LoadedModel,
    points: &PointSet,
    image: Option<ImageSize>,
    options: &FitOptions,
) -> Result<FitOutcome, FitError> {
    fit_sent(model, points, image, options, false)
}

/// [`fit`] of a set sent with (`masked`) or without a visibility mask: tracks at (0, 0) draw
/// the lost-point warning ([`lost_marks`]) only without one.
fn fit_sent(
    model: &LoadedModel,
    points: &PointSet,
    image: Option<ImageSize>,
    options: &FitOptions,
    masked: bool,
) -> Result<FitOutcome, FitError> {
    let as_sent = || {
        let mut outcome = fit_counting(model, points, image, options, "points", None)?;
        outcome.warnings.extend(image_warnings(points, image));
        outcome
            .warnings
            .extend(lost_marks(points).filter(|_| !masked));
        Ok(outcome)
    };
    // Correspondences may be fitted with their views moved, and the structures come back in
    // the caller's pixels:
    // - two images of two sizes: the second view in the first image's frame (where the network
    //   reads it, and where refinement weighs both views' pixels alike); a move out of the
    //   accepted range (which the API refuses) is fitted as sent;
    // - no image, far from the origin: each view at its centroid (a homography in the caller's
    //   pixels that far out is too ill-conditioned to invert).
    let moved = match image {
        Some(size) => match (size.second_view_move(), size.in_first_frame(points)) {
            (Some(second), (Cow::Owned(moved), first)) => {
                Some(([UNMOVED, second], moved, Some(first)))
            }
            _ => None,
        },
        None => views_centred(points).map(|(o1, o2, moved)| {
            let back = |o: [f64; 2]| (1.0, [-o[0], -o[1]]);
            ([back(o1), back(o2)], moved, None)
        }),
    };
    let Some((moves, moved, fitted_in)) = moved else {
        return as_sent();
    };
    let mut outcome = fit_counting(model, &moved, fitted_in, options, "points", None)?;
    for s in &mut outcome.structures {
        s.model = s.model.views_unmoved(moves);
    }
    // Each image's span, in its own pixels.
    outcome.warnings.extend(image_warnings(points, image));
    Ok(outcome)
}

/// A view whose centroid lies farther from the origin than this many times its RMS spread is
/// fitted moved to its centroid ([`views_centred`]).
pub const FAR_FROM_ORIGIN: f64 = 10.0;

/// Correspondences whose centroid in either view lies more than [`FAR_FROM_ORIGIN`] times that
/// view's RMS spread from the origin, moved by each view's centroid rounded to whole units (an
/// exact shift of every coordinate): (shift of view 1, of view 2, the moved rows). `None` for
/// other kinds, or where both views are near the origin (the set is fitted as sent).
fn views_centred(points: &PointSet) -> Option<([f64; 2], [f64; 2], PointSet)> {
    if points.kind() != Kind::Correspondences || points.is_empty() {
        return None;
    }
    let n = points.len() as f64;
    let view = |v: usize| -> ([f64; 2], f64) {
        let mean = [0, 1].map(|c| {
            (0..points.len())
                .map(|i| points.row(i)[2 * v + c])
                .sum::<f64>()
                / n
        });
        let spread = ((0..points.len())
            .map(|i| {
                let r = points.row(i);
                (r[2 * v] - mean[0]).powi(2) + (r[2 * v + 1] - mean[1]).powi(2)
            })
            .sum::<f64>()
            / n)
            .sqrt();
        (mean, spread)
    };
    let ((m1, s1), (m2, s2)) = (view(0), view(1));
    let far = |m: [f64; 2], s: f64| m[0].hypot(m[1]) > FAR_FROM_ORIGIN * s;
    if !far(m1, s1) && !far(m2, s2) {
        return None;
    }
    let (o1, o2) = (m1.map(f64::round), m2.map(f64::round));
    let values = (0..points.len())
        .flat_map(|i| {
            let r = points.row(i);
            [r[0] - o1[0], r[1] - o1[1], r[2] - o2[0], r[3] - o2[1]]
        })
        .collect();
    let moved = PointSet::from_flat(Kind::Correspondences, 4, values).ok()?;
    Some((o1, o2, moved))
}

/// [`fit`], its warnings naming the rows of `points` as `rows` ("points", or the tracks seen
/// in every frame of a partly seen set), row i being the caller's row `row_of[i]` (else i).
fn fit_counting(
    model: &LoadedModel,
    points: &PointSet,
    image: Option<ImageSize>,
    options: &FitOptions,
    rows: &'static str,
    row_of: Option<&[usize]>,
) -> Result<FitOutcome, FitError> {
    let FitOptions {
        params,
        symmetries,
        refine: refine_params,
        outlier_group,
        erratic_outliers,
    } = *options;
    if let Selection::Fixed(k) = params.selection()
        && k > points.len()
    {
        return Err(ClusterError::KOutOfRange { k, n: points.len() }.into());
    }
    let t0 = Instant::now();
    let embedding = embed(model, points, image, symmetries, params.seed())?;
    let read = embedding.values.len() / embedding.width.max(1);
    // Copies of a point are one point: a set of fewer distinct rows than a set needs is read
    // as sent, so `read` alone would not show them.
    if let Selection::Fixed(k) = params.selection()
        && let read = read.min(screen::distinct_up_to(points, k))
        && k > read
    {
        return Err(FitError::KAboveRead {
            model: model.card.name.clone(),
            k,
            read,
            n: points.len(),
        });
    }
    // A K the caller gave counts structures, not the outliers. The curve and correspondence
    // networks learned the outliers as one more group (AdelaideRMF's convention, and LCE's with
    // outliers): clustered into k groups, they take one and two structures share another. Such
    // a fit also reads the k + 1 clustering, below, where there is a point to spare for it.
    let given = match params.selection() {
        Selection::Fixed(k) if model.card.family() != geometry::Family::Subspace => Some(k),
        _ => None,
    };
    let t1 = Instant::now();
    let mut clustering = cluster(model, &embedding, params)?;
    let t2 = Instant::now();
    // With k given: the K chosen clustering's answer, when it replaced the k clustering's
    // (its K, its noise, the k answer's noise).
    let mut replaced = None;
    let (labels, structures, k) = match &refine_params {
        Some(r) => {
            let refined = match given {
                Some(k) => {
                    // The k clustering, the k + 1 one and the one K chosen would give, refined
                    // side by side; the decisions below take them in that order.
                    let wider = (r.outliers && k < read)
                        .then(|| one_more_group(model, &embedding, params, &clustering))
                        .transpose()?;
                    let auto = params.with_chosen_k(model.card.selection, params.k_max().max(k));
                    let chosen = cluster(model, &embedding, &auto)?;
                    let pool = model.pool();
                    let rows = RefineRows::new(points, &embedding.far);
                    let seeded = |c: &Clustering| {
                        refine_seeded(model, &rows, &embedding, params, c, r, true)
                    };
                    let ((mut refined, again), other) = pool.join(
                        || pool.join(|| seeded(&clustering), || wider.as_ref().map(seeded)),
                        || seeded(&chosen),
                    );
                    // Refinement dissolves the outlier group into -1 labels, so the k + 1
                    // clustering is refined too, and its answer is kept when it has no more
                    // than k structures and no fewer than the k clustering's. (Refining it only
                    // where the k answer shows outliers saves the time on clean sets but misses
                    // pairs whose outliers the k answer absorbed: 6.99 against 4.20 % on the
                    // AdelaideRMF homography pairs.) Motion subspaces are not trained with
                    // outliers and drop a structure that shrinks.
                    if let (Some(wider), Some(again)) = (wider, again) {
                        let found = again.structures.len();
                        if found <= k && found >= refined.structures.len() {
                            clustering = both_ks(&clustering, wider);
                            refined = again;
                        }
                    }
                    // Where the k clustering mixed structures, its groups set a noise level
                    // under which refinement cannot part them: the clustering K chosen would
                    // give, refined as a chosen K (structures may be added, up to k_max, or
                    // merge), may reach the k structures at a far lower noise
                    // ([`refine::replaces_given`]).
                    if refine::replaces_given(&refined, &other, k, points.len()) {
                        replaced = Some((chosen.k, other.noise(), refined.noise()));
                        clustering = chosen;
                        other
                    } else {
                        refined
                    }
                }
                None => {
                    let (from, refined) =
                        refine_chosen(model, points, &embedding, params, &clustering, r)?;
                    clustering = from;
                    refined
                }
            };
            let k = refined.structures.len();
            (refined.labels, refined.structures, k)
        }
        None if outlier_group => {
            // Given k: the k + 1 clustering, where the outliers have a group of their own.
            let apart = match given.filter(|&k| k < read) {
                Some(k) => outlier_group_apart(model, points, &embedding, params, k)?,
                None => None,
            };
            match apart {
                Some((wider, labels)) => {
                    let k = wider.k - 1;
                    clustering = both_ks(&clustering, wider);
                    (labels, Vec::new(), k)
                }
                // Else (and with K chosen, where the outliers' group is among the chosen K) the
                // clustering, its own outlier group (if any) answered -1.
                None => outliers_named(model, points, &clustering),
            }
        }
        None => unchanged(&clustering),
    };
    let (mut labels, mut structures) = (labels, structures);
    if erratic_outliers {
        erratic_as_outliers(&mut labels, &embedding.erratic);
    }
    count_joined(points, &embedding.far, &labels, &mut structures);
    let t3 = Instant::now();
    // Whether this fit may answer -1: refinement with outliers, a model whose outlier group is
    // answered apart, or erratic tracks answered -1.
    let flags_outliers = match refine_params {
        Some(r) => r.outliers,
        None => outlier_group && model.card.family() != geometry::Family::Subspace,
    } || (erratic_outliers && !embedding.erratic.is_empty());
    let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
    let mut warnings = model.card.warnings(&Observed {
        rows,
        ..observed(points, image, &labels, k, flags_outliers)
    });
    if let Selection::Fixed(asked) = params.selection() {
        warnings.extend(fewer_than_asked(asked, k, refine_params.is_some()));
    }
    let callers = |among: &[usize]| -> Vec<usize> {
        match row_of {
            Some(row_of) => among.iter().map(|&i| row_of[i]).collect(),
            None => among.to_vec(),
        }
    };
    let only_far: Vec<usize> = (embedding.far.iter())
        .filter(|i| embedding.erratic.binary_search(i).is_err())
        .copied()
        .collect();
    warnings.extend(far_apart(&callers(&only_far), rows));
    warnings.extend(erratic_apart(
        &callers(&embedding.erratic),
        erratic_outliers,
    ));
    if let Some((from, noise, given_noise)) = replaced {
        warnings.push(format!(
            "the {k} structures answered were refined from the clustering into {from} groups \
             that K chosen would give: their noise level is {noise:.3}, against {given_noise:.3} \
             for those refined from the {k} groups asked (which mix structures)"
        ));
    }
    Ok(FitOutcome {
        warnings,
        clustering,
        labels,
        structures,
        k,
        embeddings: embedding.per_point(),
        embed_dim: embedding.width,
        embed_ms: ms(t0, t1),
        cluster_ms: ms(t1, t2),
        refine_ms: ms(t2, t3),
    })
}

/// A fit given `k` without refinement, on a model whose network learned the outliers as a group
/// of their own (curves and correspondences, as [`fit`] checks): the k + 1 clustering, when
/// exactly one of its groups follows no model ([`refine::OutlierGroup::sole`]), with that
/// group's points labelled -1 and the others numbered 0..k. `None` otherwise, and the k
/// clustering stands. Clustered into k groups, the outliers would take one and two structures
/// share another; but the k + 1 clustering is another clustering, and the switch asks for the
/// surer sign.
fn outlier_group_apart(
    model: &LoadedModel,
    points: &PointSet,
    embedding: &Embedding,
    params: &ClusterParams,
    k: usize,
) -> Result<Option<(Clustering, Vec<i64>)>, FitError> {
    let wider = cluster(model, embedding, &params.with_fixed_k(k + 1)?)?;
    let sole = the_outlier_group(model, points, &wider).filter(|out| out.sole);
    Ok(sole.map(|out| {
        let labels = without_group(&wider.labels, out.group);
        (wider, labels)
    }))
}

/// The group of `clustering` that holds the outliers, where the network learned them as a group
/// of their own ([`refine::outlier_group`]); never for motion subspaces, whose networks learned no
/// outlier group.
fn the_outlier_group(
    model: &LoadedModel,
    points: &PointSet,
    clustering: &Clustering,
) -> Option<refine::OutlierGroup> {
    let family = model.card.family();
    if family == geometry::Family::Subspace {
        return None;
    }
    refine::outlier_group(
        points,
        &clustering.labels,
        clustering.k,
        family,
        model.pool(),
    )
}

/// The tracks set apart as erratic (`erratic`, rows) answered −1. A far row takes a read row's
/// label, or joins a structure, only after the groups are made and the structures fitted, so no
/// group loses a point it was made of.
pub fn erratic_as_outliers(labels: &mut [i64], erratic: &[usize]) {
    for &i in erratic {
        labels[i] = -1;
    }
}

/// The far rows (`far`) that refinement joined to a structure (outliers off, [`refine`]) counted
/// in that structure's `inliers` and `rms`, as every point labelled with it is: the structures
/// were fitted, and their noise judged, without them.
fn count_joined(points: &PointSet, far: &[usize], labels: &[i64], structures: &mut [Structure]) {
    for &i in far {
        let Some(s) = usize::try_from(labels[i])
            .ok()
            .and_then(|l| structures.get_mut(l))
        else {
            continue;
        };
        let r = s.model.residual(points.row(i));
        let n = s.inliers as f64;
        s.rms = ((s.rms * s.rms * n + r * r) / (n + 1.0)).sqrt();
        s.inliers += 1;
    }
}

/// The clustering's labels and K as the answer, with no structures (an unrefined fit), its group
/// that holds the outliers ([`the_outlier_group`]) answered -1 and not counted in K. Naming it
/// moves no point to another group, so the widest of several groups that follow no model is
/// named too.
fn outliers_named(
    model: &LoadedModel,
    points: &PointSet,
    clustering: &Clustering,
) -> (Vec<i64>, Vec<Structure>, usize) {
    match the_outlier_group(model, points, clustering) {
        Some(out) => (
            without_group(&clustering.labels, out.group),
            Vec::new(),
            clustering.k - 1,
        ),
        None => unchanged(clustering),
    }
}

/// The clustering's labels and K as the answer, with no structures (an unrefined fit).
fn unchanged(clustering: &Clustering) -> (Vec<i64>, Vec<Structure>, usize) {
    (
        clustering.labels.iter().map(|&l| l as i64).collect(),
        Vec::new(),
        clustering.k,
    )
}

/// `labels` with group `out` answered -1 and the groups after it numbered one lower.
fn without_group(labels: &[usize], out: usize) -> Vec<i64> {
    labels
        .iter()
        .map(|&l| match l.cmp(&out) {
            std::cmp::Ordering::Less => l as i64,
            std::cmp::Ordering::Equal => -1,
            std::cmp::Ordering::Greater => l as i64 - 1,
        })
        .collect()
}

/// `wider` (the k + 1 clustering) with the residual curve of both clusterings, so the answer
/// shows every K clustered.
fn both_ks(first: &Clustering, mut wider: Clustering) -> Clustering {
    let mut residuals = first.residuals.clone();
    residuals.extend(wider.residuals.iter().copied());
    residuals.sort_by_key(|r| r.0);
    residuals.dedup_by_key(|r| r.0);
    wider.residuals = residuals;
    wider
}

impl LoadedModel {
    /// [`fit`] with the card's test-time symmetries, without refinement: the learned clustering
    /// (a K given is the number of groups, no outlier group set apart, erratic tracks labelled).
    pub fn fit(
        &self,
        points: &PointSet,
        image: Option<ImageSize>,
        params: &ClusterParams,
    ) -> Result<FitOutcome, FitError> {
        self.fit_with(points, image, params, &self.card.test_symmetries)
    }

    /// [`fit`] with the given test-time symmetries instead of the card's, as [`LoadedModel::fit`].
    pub fn fit_with(
        &self,
        points: &PointSet,
        image: Option<ImageSize>,
        params: &ClusterParams,
        symmetries: &[Symmetry],
    ) -> Result<FitOutcome, FitError> {
        let options = FitOptions {
            params,
            symmetries,
            refine: None,
            outlier_group: false,
            erratic_outliers: false,
        };
        fit(self, points, image, &options)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::registry::tests::tiny;

    /// `per` points on each of a unit circle at the origin, a circle of radius 2 at (6, 0) and
    /// the line y = -4, noise about 0.02.
    fn two_circles_and_a_line(per: usize) -> PointSet {
        let values = (0..3 * per)
            .flat_map(|i| {
                let t = (i / 3) as f64 * std::f64::consts::TAU / per as f64;
                let e = 0.02 * (((i * 7919) % 101) as f64 / 50.0 - 1.0);
                match i % 3 {
                    0 => [(1.0 + e) * t.cos(), (1.0 + e) * t.sin()],
                    1 => [6.0 + (2.0 + e) * t.cos(), (2.0 + e) * t.sin()],
                    _ => [-3.0 + 12.0 * (i / 3) as f64 / per as f64, -4.0 + e],
                }
            })
            .collect();
        PointSet::from_flat(Kind::Points2d, 2, values).unwrap()
    }

    #[test]
    fn small_sets_of_curves_answer_from_the_cheapest_of_several_seeds() {
        use crate::registry::tests::tiny_model;
        // An untrained network: its embeddings part the curves poorly. Whichever seed's answer
        // is kept, it explains the rows at no higher cost than the request's seed's.
        let model = tiny_model("curves", Kind::Points2d, 2, 3);
        let r = RefineParams {
            threshold: Some(0.1),
            ..RefineParams::default()
        };
        let cost = |points: &PointSet, answer: &Refined| {
            crate::refine::truncated_cost(points, &answer.structures, 0.1)
        };
        let chosen = ClusterParams::builder().k_max(6).build().unwrap();
        for (per, seeded_search, params) in [
            (40, true, fixed(3)),
            (40, true, chosen.clone()),
            (200, false, fixed(3)),
        ] {
            let points = two_circles_and_a_line(per);
            let embedding = embed(&model, &points, None, &[], 0).unwrap();
            let clustering = cluster(&model, &embedding, &params).unwrap();
            let rows = RefineRows::new(&points, &embedding.far);
            let first = refine(&model, &rows, &clustering, &r);
            let answer = refine_seeded(&model, &rows, &embedding, &params, &clustering, &r, false);
            assert_eq!(answer.labels.len(), points.len());
            if seeded_search {
                assert!(cost(&points, &answer) <= cost(&points, &first));
                if answer != first {
                    assert_eq!(answer.structures.len(), first.structures.len());
                    assert!(cost(&points, &answer) < cost(&points, &first));
                }
            } else {
                // 600 rows: past SEEDED_MAX_ROWS, one seed.
                assert!(points.len() > SEEDED_MAX_ROWS);
                assert_eq!(answer, first);
            }
        }
    }

    #[test]
    fn correspondences_search_seeds_only_where_the_caller_gave_k() {
        use crate::registry::tests::tiny_model;
        let model = tiny_model("pairs", Kind::Correspondences, 4, 3);
        // Two motions of 30 pairs each over a 100 x 100 image: a shift and a zoom.
        let values: Vec<f64> = (0..60)
            .flat_map(|i| {
                let (x, y) = ((i * 37 % 97) as f64, (i * 53 % 89) as f64);
                if i % 2 == 0 {
                    [x, y, x + 3.0, y - 2.0]
                } else {
                    [x, y, 1.5 * x - 10.0, 1.5 * y - 5.0]
                }
            })
            .collect();
        let points = PointSet::from_flat(Kind::Correspondences, 4, values).unwrap();
        let embedding = embed(&model, &points, None, &[], 0).unwrap();
        let params = fixed(2);
        let clustering = cluster(&model, &embedding, &params).unwrap();
        let rows = RefineRows::new(&points, &embedding.far);
        // A threshold of the caller's: the cost below is then the one the search compares.
        let r = RefineParams {
            threshold: Some(1.0),
            ..RefineParams::default()
        };
        let first = refine(&model, &rows, &clustering, &r);
        let unsearched = refine_seeded(&model, &rows, &embedding, &params, &clustering, &r, false);
        assert_eq!(unsearched, first);
        let searched = refine_seeded(&model, &rows, &embedding, &params, &clustering, &r, true);
        assert_eq!(searched.labels.len(), points.len());
        let cost = |a: &Refined| crate::refine::truncated_cost(&points, &a.structures, 1.0);
        assert!(cost(&searched) <= cost(&first));
    }

    #[test]
    fn the_outlier_group_is_answered_minus_one_and_the_later_groups_move_down() {
        assert_eq!(
            without_group(&[0, 1, 2, 3, 1, 0], 1),
            vec![0, -1, 1, 2, -1, 0]
        );
        assert_eq!(without_group(&[2, 0, 1], 2), vec![-1, 0, 1]);
        assert_eq!(without_group(&[0, 1], 0), vec![-1, 0]);
    }

    /// Clustering parameters with K given.
    pub(crate) fn fixed(k: usize) -> ClusterParams {
        ClusterParams::builder()
            .selection(Selection::Fixed(k))
            .build()
            .unwrap()
    }

    /// A fit's options with `params`, no symmetries, no refinement.
    pub(crate) fn unrefined(params: &ClusterParams) -> FitOptions<'_> {
        FitOptions {
            params,
            symmetries: &[],
            refine: None,
            outlier_group: false,
            erratic_outliers: false,
        }
    }

    pub(crate) fn image(w: f64, h: f64) -> Option<ImageSize> {
        Some(ImageSize::new(w, h).unwrap())
    }

    /// Ten 2-frame tracks with coordinates `(v * a) % m`, a 20 x 20 image and k-means with K = 2.
    pub(crate) fn ten_tracks(a: usize, m: usize) -> (PointSet, Option<ImageSize>, ClusterParams) {
        let values = (0..40).map(|v| ((v * a) % m) as f64).collect();
        let points = PointSet::from_flat(Kind::Trajectories, 4, values).unwrap();
        let image = Some(ImageSize::new(20.0, 20.0).unwrap());
        let params = ClusterParams::builder()
            .selection(Selection::Fixed(2))
            .seed(1)
            .build()
            .unwrap();
        (points, image, params)
    }

    #[test]
    fn test_symmetries_concatenate_unit_embeddings_of_every_image() {
        let (points, image, params) = ten_tracks(7, 13);
        let plain = tiny(vec![]);
        let both = tiny(vec![Symmetry::Mirror, Symmetry::Reverse]);
        let a = plain.fit(&points, image, &params).unwrap();
        let b = both.fit(&points, image, &params).unwrap();
        assert_eq!((a.embed_dim, b.embed_dim), (3, 12));
        assert_eq!(b.embeddings.len(), 12 * points.len());
        assert_eq!(b.clustering.labels.len(), points.len());
        // Row i: [input, mirrored, reversed, mirrored and reversed] embeddings of point i, / 2.
        let image_of = |ss: &[Symmetry]| {
            let p = ss
                .iter()
                .fold(points.clone(), |p, s| s.apply_points(&p, image).unwrap());
            plain.fit(&p, image, &params).unwrap().embeddings
        };
        let blocks = [
            a.embeddings.clone(),
            image_of(&[Symmetry::Mirror]),
            image_of(&[Symmetry::Reverse]),
            image_of(&[Symmetry::Mirror, Symmetry::Reverse]),
        ];
        for i in 0..points.len() {
            let row = &b.embeddings[i * 12..(i + 1) * 12];
            let norm = row.iter().map(|v| v * v).sum::<f32>().sqrt();
            assert!((norm - 1.0).abs() < 1e-4, "row {i} has norm {norm}");
            for (c, block) in blocks.iter().enumerate() {
                for j in 0..3 {
                    let want = block[i * 3 + j] / 2.0;
                    assert!((row[c * 3 + j] - want).abs() < 1e-6, "row {i} block {c}");
                }
            }
        }
        // The mirrored input's own block differs from the input's: the images are real inputs.
        assert!((0..3).any(|j| (blocks[0][j] - blocks[1][j]).abs() > 1e-4));
        // Without symmetries the same model embeds the input alone; quarter turns give 4 images.
        let alone = both.fit_with(&points, image, &params, &[]).unwrap();
        assert_eq!(alone.embeddings, a.embeddings);
        let turns = both
            .fit_with(&points, image, &params, &[Symmetry::Rotate])
            .unwrap();
        assert_eq!(turns.embed_dim, 12);
        // An image whose coordinates would leave the accepted range is left out, not an error:
        // mirrored about x = 5e8, x = -1e9 would become 2e9.
        let far = PointSet::from_flat(
            Kind::Trajectories,
            4,
            vec![-1e9, 0.0, -1e9, 1.0, 1e9, 0.0, 1e9, 1.0, 0.0, 5.0, 1.0, 6.0],
        )
        .unwrap();
        let wide = Some(ImageSize::new(1e9, 10.0).unwrap());
        let fit = both
            .fit_with(&far, wide, &params, &[Symmetry::Mirror])
            .unwrap();
        assert_eq!(fit.embed_dim, 3);
        assert_eq!(fit.embeddings.len(), 3 * 3);
    }

    #[test]
    fn trajectory_models_read_tracks_of_any_length() {
        let model = tiny(vec![]);
        let (points, image, params) = ten_tracks(7, 13);
        // The same tracks with a middle frame between their two: spread over three frames,
        // the model's two frames are the first and the last, the tracks it was given.
        let values = (0..points.len())
            .flat_map(|i| {
                let r = points.row(i);
                [
                    r[0],
                    r[1],
                    (r[0] + r[2]) / 2.0,
                    (r[1] + r[3]) / 2.0,
                    r[2],
                    r[3],
                ]
            })
            .collect();
        let longer = PointSet::from_flat(Kind::Trajectories, 6, values).unwrap();
        let a = model.fit(&points, image, &params).unwrap();
        let b = model.fit(&longer, image, &params).unwrap();
        assert_eq!(a.embeddings, b.embeddings);
        assert_eq!(a.labels, b.labels);
        // Other kinds still need the model's width.
        let flat = PointSet::from_flat(Kind::Points2d, 2, vec![0.0; 20]).unwrap();
        assert!(matches!(
            model.fit(&flat, None, &params),
            Err(FitError::WrongKind { .. })
        ));
    }

    #[test]
    fn windows_set_the_embeddings_of_every_frame_window_side_by_side() {
        let mut model = tiny(vec![]);
        model.card.frames = frames::FrameSampling::Windows;
        let (points, image, params) = ten_tracks(7, 13);
        // Three frames read by a 2-frame model: windows over frames 0-1 and 1-2.
        let values = (0..points.len())
            .flat_map(|i| {
                let r = points.row(i);
                [r[0], r[1], r[2], r[3], r[2] + 1.0, r[3] - 2.0]
            })
            .collect();
        let longer = PointSet::from_flat(Kind::Trajectories, 6, values).unwrap();
        let fit = model.fit(&longer, image, &params).unwrap();
        assert_eq!(fit.embed_dim, 6);
        let window = |cols: [usize; 4]| {
            let values = (0..longer.len())
                .flat_map(|i| cols.map(|c| longer.row(i)[c]))
                .collect();
            let p = PointSet::from_flat(Kind::Trajectories, 4, values).unwrap();
            model.fit(&p, image, &params).unwrap().embeddings
        };
        let (a, b) = (window([0, 1, 2, 3]), window([2, 3, 4, 5]));
        let scale = 1.0 / 2f32.sqrt();
        for i in 0..longer.len() {
            let row = &fit.embeddings[i * 6..(i + 1) * 6];
            for j in 0..3 {
                assert!((row[j] - a[i * 3 + j] * scale).abs() < 1e-6, "row {i}");
                assert!((row[3 + j] - b[i * 3 + j] * scale).abs() < 1e-6, "row {i}");
            }
        }
        // The model's own frame count is one window, the input itself.
        let own = model.fit(&points, image, &params).unwrap();
        assert_eq!(own.embed_dim, 3);
    }

    #[test]
    fn a_k_above_the_points_read_after_thinning_is_refused_naming_both_counts() {
        // A card trained far sparser than this set: the set is thinned before it is read.
        let mut model = crate::registry::tests::tiny_reading("dense", Kind::Trajectories, 4, 7, 2);
        model.card.spacing = Some(1e3);
        // 300 distinct tracks scattered over the image.
        let values = (0..4 * 300u64)
            .map(|v| (v.wrapping_mul(2_654_435_761) % 10_007) as f64 / 100.07)
            .collect();
        let points = PointSet::from_flat(Kind::Trajectories, 4, values).unwrap();
        let image = Some(ImageSize::new(100.0, 100.0).unwrap());
        let at = |k: usize| {
            let params = fixed(k);
            fit(&model, &points, image, &unrefined(&params))
        };
        let read = at(2).unwrap().clustering.labels.len();
        assert_eq!(read, points.len(), "every point is answered");
        match at(250) {
            Err(FitError::KAboveRead {
                k: 250,
                read,
                n: 300,
                ..
            }) => assert!((density::MIN_READ..250).contains(&read), "{read}"),
            other => panic!("{other:?}"),
        }
        let message = at(250).unwrap_err().to_string();
        assert!(
            message.contains("thins") && message.contains("300"),
            "{message}"
        );
    }

    #[test]
    fn correspondences_far_from_the_origin_are_fitted_centred_on_each_view() {
        let pairs = |o: f64| {
            let values = (0..20)
                .flat_map(|i| {
                    let (x, y) = ((i % 5) as f64 * 30.0, (i / 5) as f64 * 40.0);
                    [x + o, y + o, x + 0.5 * y + 2.0 * o, y + 7.0 + o]
                })
                .collect();
            PointSet::from_flat(Kind::Correspondences, 4, values).unwrap()
        };
        // Near the origin (within 10 spreads): fitted as sent.
        assert!(views_centred(&pairs(100.0)).is_none());
        assert!(
            views_centred(&PointSet::from_flat(Kind::Points2d, 2, vec![1e9; 20]).unwrap())
                .is_none()
        );
        // Far: each view moved by its centroid rounded to whole pixels, exactly.
        let (o1, o2, moved) = views_centred(&pairs(1e7)).unwrap();
        assert_eq!(o1, [1e7 + 60.0, 1e7 + 60.0]);
        assert_eq!(o2, [2e7 + 90.0, 1e7 + 67.0]);
        assert_eq!(moved.row(0), &[-60.0, -60.0, -90.0, -60.0]);
        // The far set is answered as its centred rows are, its structures moved back.
        let model = crate::registry::tests::tiny_model("pairs", Kind::Correspondences, 4, 3);
        let params = fixed(2);
        let options = FitOptions {
            refine: Some(RefineParams::default()),
            ..unrefined(&params)
        };
        let far = fit(&model, &pairs(1e7), None, &options).unwrap();
        let centred = fit(&model, &moved, None, &options).unwrap();
        assert_eq!(far.labels, centred.labels);
        assert!(!far.structures.is_empty());
        for (f, c) in far.structures.iter().zip(&centred.structures) {
            assert_eq!(
                f.model,
                c.model
                    .views_unmoved([o1, o2].map(|o| (1.0, [-o[0], -o[1]])))
            );
            assert_eq!((f.inliers, f.rms), (c.inliers, c.rms));
        }
    }

    #[test]
    fn k_above_the_distinct_rows_is_refused_even_where_every_row_is_read() {
        use crate::registry::tests::tiny_model;
        let model = tiny_model("tracks", Kind::Trajectories, 4, 3);
        // Ten copies of one track, then two copies of a second one.
        let rows = |copies: &[(usize, f64)]| {
            let values = copies
                .iter()
                .flat_map(|&(n, x)| std::iter::repeat_n([x, 0.0, x + 1.0, 0.5], n).flatten())
                .collect();
            PointSet::from_flat(Kind::Trajectories, 4, values).unwrap()
        };
        let one = rows(&[(10, 1.0)]);
        match fit(&model, &one, None, &unrefined(&fixed(2))) {
            Err(FitError::KAboveRead {
                k: 2,
                read: 1,
                n: 10,
                ..
            }) => {}
            other => panic!("{other:?}"),
        }
        let two = rows(&[(10, 1.0), (2, 5.0)]);
        assert!(fit(&model, &two, None, &unrefined(&fixed(2))).is_ok());
        assert!(matches!(
            fit(&model, &two, None, &unrefined(&fixed(3))),
            Err(FitError::KAboveRead { read: 2, .. })
        ));
        // K chosen: the copies are answered alike.
        let chosen = ClusterParams::builder().k_max(3).build().unwrap();
        let fit = fit(&model, &one, None, &unrefined(&chosen)).unwrap();
        assert!(
            fit.labels.iter().all(|&l| l == fit.labels[0]),
            "{:?}",
            fit.labels
        );
    }

    #[test]
    fn erratic_tracks_are_answered_minus_one_unless_outliers_are_off() {
        use crate::registry::tests::tiny_model;
        let model = tiny_model("tracks", Kind::Trajectories, 10, 3);
        // 60 tracks of three motions, then two wanderers (rows 60 and 61).
        let points = crate::data::screen::tests::tracks(2);
        let params = fixed(3);
        let kept = RefineParams {
            outliers: false,
            ..RefineParams::default()
        };
        for refine in [None, Some(kept)] {
            for erratic_outliers in [true, false] {
                let options = FitOptions {
                    params: &params,
                    symmetries: &[],
                    refine,
                    outlier_group: false,
                    erratic_outliers,
                };
                let fit = fit(&model, &points, None, &options).unwrap();
                let case = format!("refine {}, apart {erratic_outliers}", refine.is_some());
                assert!(fit.labels[..60].iter().all(|&l| l >= 0), "{case}");
                let wanderers = &fit.labels[60..];
                match erratic_outliers {
                    true => assert_eq!(wanderers, &[-1, -1], "{case}"),
                    false => assert!(wanderers.iter().all(|&l| l >= 0), "{case}"),
                }
                assert!(
                    fit.warnings
                        .iter()
                        .any(|w| w.contains("a tracker that lost its feature")),
                    "{case}"
                );
                // A structure's inliers are the points it labels, the far rows it took too.
                for s in &fit.structures {
                    let carried = fit.labels.iter().filter(|&&l| l == s.label as i64);
                    assert_eq!(s.inliers, carried.count(), "{case}");
                }
                assert_eq!(fit.structures.is_empty(), refine.is_none(), "{case}");
            }
        }
    }

    #[test]
    fn refinement_answers_structures_and_counts_them_as_k() {
        let model = tiny(vec![]);
        let (points, image, params) = ten_tracks(7, 13);
        let options = FitOptions {
            params: &params,
            symmetries: &[],
            refine: Some(RefineParams::default()),
            outlier_group: false,
            erratic_outliers: false,
        };
        let fit = fit(&model, &points, image, &options).unwrap();
        assert_eq!(fit.labels.len(), points.len());
        assert_eq!(fit.k, fit.structures.len());
        for (label, s) in fit.structures.iter().enumerate() {
            assert_eq!(s.label, label);
            let carried = fit.labels.iter().filter(|&&l| l == label as i64).count();
            assert_eq!(s.inliers, carried);
            assert!(s.rms.is_finite());
        }
        assert!(fit.refine_ms >= 0.0);
    }
}
