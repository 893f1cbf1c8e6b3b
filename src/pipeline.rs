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

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::ops::RangeInclusive;
use std::time::Instant;

use crate::cluster::{self, ClusterError, ClusterParams, Clustering, Points, Selection};
use crate::data::features::with_neighbors;
use crate::data::screen::{self, Screened, screen};
use crate::data::symmetry::closure;
use crate::data::visibility::MIN_SEEN_FRAMES;
use crate::data::{ImageSize, Kind, Normalization, PointSet, Symmetry, Visibility};
use crate::data::{density, frames};
use crate::geometry::subspace::masked_subspace_distance;
use crate::geometry::{self, Model};
use crate::refine::{self, RefineParams, Refined, Structure};
use crate::registry::{LoadedModel, Observed};

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
    /// The rows set apart as far from the rest ([`screen`]).
    far: Vec<usize>,
}

/// Stage 1: how the model reads the set. No row far from the rest, and, for a network that
/// reads neighbourhoods, each distinct row once ([`screen`]: both give the network a picture it
/// was never trained on); then, for cards that
/// record their training spacing ([`density::reading`]), a set denser than training at a seeded
/// subset, one sparser than the card's sparse network's threshold by that network. Rows not
/// read take their nearest read row's embedding. `whole` is the set as sent (rows compared over
/// every frame), `read` the same rows at the model's frames.
fn read_plan(
    model: &LoadedModel,
    whole: &PointSet,
    read: &PointSet,
    image: Option<ImageSize>,
    seed: u64,
) -> Result<ReadPlan, FitError> {
    let card = &model.card;
    let neighbourhoods = card.architecture.neighbors > 0 || card.architecture.graph_neighbors > 0;
    let Screened { read: kept, far } = screen(whole, neighbourhoods);
    let Some(trained) = card.spacing else {
        return Ok(ReadPlan {
            thinned: kept
                .map(|rows| owned_by_nearest(model, read, image, rows, &far))
                .transpose()?,
            sparse: false,
            far,
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
    /// The input rows not read for lying far from the rest ([`screen`]), ascending.
    pub far: Vec<usize>,
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
    } = read_plan(model, &points, &windows[0], image, seed)?;
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
    // Two images of two sizes: the fit runs with the second view in the first image's frame
    // (where the network reads it, and where refinement weighs both views' pixels alike), and
    // the structures come back in each image's own pixels. Anything else, or a move out of the
    // accepted range (which the API refuses), is fitted as sent.
    let Some(size) = image else {
        return as_sent();
    };
    let (Some((scale, shift)), (Cow::Owned(moved), first)) =
        (size.second_view_move(), size.in_first_frame(points))
    else {
        return as_sent();
    };
    let mut outcome = fit_counting(model, &moved, Some(first), options, "points", None)?;
    for s in &mut outcome.structures {
        s.model = s.model.second_view_unmoved(scale, shift);
    }
    // Each image's span, in its own pixels.
    outcome.warnings.extend(image_warnings(points, image));
    Ok(outcome)
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
    } = *options;
    if let Selection::Fixed(k) = params.selection()
        && k > points.len()
    {
        return Err(ClusterError::KOutOfRange { k, n: points.len() }.into());
    }
    let t0 = Instant::now();
    let embedding = embed(model, points, image, symmetries, params.seed())?;
    let read = embedding.values.len() / embedding.width.max(1);
    if let Selection::Fixed(k) = params.selection()
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
    let t3 = Instant::now();
    // Whether this fit may answer -1: refinement with outliers, or a model whose outlier group
    // is answered apart.
    let flags_outliers = match refine_params {
        Some(r) => r.outliers,
        None => outlier_group && model.card.family() != geometry::Family::Subspace,
    };
    let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
    let mut warnings = model.card.warnings(&Observed {
        rows,
        ..observed(points, image, &labels, k, flags_outliers)
    });
    if let Selection::Fixed(asked) = params.selection() {
        warnings.extend(fewer_than_asked(asked, k, refine_params.is_some()));
    }
    let far: Vec<usize> = match row_of {
        Some(row_of) => embedding.far.iter().map(|&i| row_of[i]).collect(),
        None => embedding.far.clone(),
    };
    warnings.extend(far_apart(&far, rows));
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

/// [`fit`] of tracks that were not all seen in every frame ([`Visibility`]): the stages run on
/// the tracks seen throughout, and each other track seen in at least [`MIN_SEEN_FRAMES`] frames
/// then goes to the motion whose subspace (the refined structure's, or one fitted on the
/// group's tracks over every frame) is nearest over the frames it was seen in
/// ([`nearest_motion`]); with the caller's outlier threshold it is an outlier (−1) beyond it.
/// A track seen in enough consecutive frames for the network may then be placed by it instead,
/// window by window, where the network places the tracks seen throughout better
/// ([`Window::place`]). A track seen in fewer frames, or with no motion to join, is −1, and the
/// warnings count both. Structures then count, and measure their RMS over, every track labelled
/// with them (a partly seen one over its seen frames); the placement's time counts as
/// refinement's. The embeddings are those of the tracks seen throughout.
pub fn fit_seen(
    model: &LoadedModel,
    points: &PointSet,
    visibility: &Visibility,
    image: Option<ImageSize>,
    options: &FitOptions,
) -> Result<FitOutcome, FitError> {
    if visibility.len() != points.len() || visibility.frames() != points.dim() / 2 {
        return Err(FitError::Input(format!(
            "a visibility of {} tracks by {} frames for {} tracks of {} frames",
            visibility.len(),
            visibility.frames(),
            points.len(),
            points.dim() / 2
        )));
    }
    if visibility.is_complete() {
        return fit_sent(model, points, image, options, true);
    }
    let complete = visibility.complete();
    let throughout = points
        .select(&complete)
        .map_err(|e| FitError::Input(e.to_string()))?;
    let mut outcome = fit_counting(
        model,
        &throughout,
        image,
        options,
        "tracks seen in every frame",
        Some(&complete),
    )?;
    outcome.warnings.extend(image_warnings(&throughout, image));
    let t0 = Instant::now();
    let motions = motions(&throughout, &outcome);
    let placing = Placing {
        complete: &complete,
        labels: &outcome.labels,
        motions: &motions,
        threshold: options
            .refine
            .filter(|r| r.outliers)
            .and_then(|r| r.threshold),
    };
    let mut placed = place(points, visibility, &placing);
    let window = Window {
        model,
        image,
        options,
    };
    window.place(points, visibility, &complete, &mut placed)?;
    // Per structure: its tracks seen throughout's RMS, and its partly seen tracks' distances.
    let mut fits: Vec<(f64, Vec<f64>)> = Vec::new();
    for s in &mut outcome.structures {
        // A partly seen track's distance over the frames it was seen in.
        let prepared = s.model.prepared();
        let distance = |i: usize| match &s.model {
            Model::Subspace { mean, basis, .. } if !visibility.throughout(i) => {
                masked_subspace_distance(mean, basis, points.row(i), visibility.seen(i))
            }
            _ => prepared.residual(points.row(i)),
        };
        let mine: Vec<usize> = (0..points.len())
            .filter(|&i| placed.labels[i] == s.label as i64)
            .collect();
        let distances: Vec<f64> = mine.iter().map(|&i| distance(i)).collect();
        let of = |throughout: bool| {
            mine.iter()
                .zip(&distances)
                .filter(move |&(&i, _)| visibility.throughout(i) == throughout)
                .map(|(_, &d)| d)
        };
        fits.push((rms(of(true)), of(false).filter(|d| d.is_finite()).collect()));
        s.inliers = distances.len();
        let ms = distances.iter().map(|d| d * d).sum::<f64>() / distances.len().max(1) as f64;
        if ms.is_finite() {
            s.rms = ms.sqrt();
        }
    }
    outcome.warnings.extend(
        outcome
            .structures
            .iter()
            .zip(drifted(&fits))
            .filter_map(|(s, drift)| drift.map(|(n, ratio)| (s.label, n, ratio)))
            .map(|(label, n, ratio)| {
                format!(
                    "the {n} partly seen tracks placed on structure {label} lie {ratio:.1} times \
                     farther from it (median) than the noise of the tracks seen throughout: they \
                     may follow a motion that no track seen throughout shows"
                )
            }),
    );
    let tracks = |n: usize| {
        if n == 1 {
            ("track", "is")
        } else {
            ("tracks", "are")
        }
    };
    if placed.few > 0 {
        let (noun, verb) = tracks(placed.few);
        outcome.warnings.push(format!(
            "{} {noun} seen in fewer than {MIN_SEEN_FRAMES} frames {verb} labelled -1",
            placed.few
        ));
    }
    if placed.homeless > 0 {
        let (noun, verb) = tracks(placed.homeless);
        outcome.warnings.push(format!(
            "{} partly seen {noun} {verb} labelled -1: no structure has a motion subspace to \
             place {} on",
            placed.homeless,
            if placed.homeless == 1 { "it" } else { "them" },
        ));
    }
    outcome.labels = placed.labels;
    outcome.refine_ms += t0.elapsed().as_secs_f64() * 1e3;
    Ok(outcome)
}

/// Partly seen tracks placed on a structure draw a warning where their median distance to it
/// exceeds this many times its noise. On generated clips (30-60 frames, 30-60 % of the tracks
/// partly seen) the ratio stayed at or below 1.1 for every structure; with one object's tracks
/// all partly seen it reached 2.6 to 25 on the structures they were placed on.
const DRIFT_RATIO: f64 = 2.0;
/// The fewest partly seen tracks on a structure that the warning weighs.
const DRIFT_MIN_TRACKS: usize = 5;

/// The root mean square of `distances` (NaN for none).
fn rms(distances: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = distances.fold((0.0, 0usize), |(s, n), d| (s + d * d, n + 1));
    (sum / n as f64).sqrt()
}

/// For each structure, given (the RMS distance of its tracks seen throughout, the finite
/// distances of the partly seen tracks placed on it): `Some((count, ratio))` where at least
/// [`DRIFT_MIN_TRACKS`] partly seen tracks were placed and their median distance exceeds
/// [`DRIFT_RATIO`] times the structure's noise, the larger of its own RMS and the median RMS of
/// the structures (a motion held by a handful of tracks seen throughout fits them almost
/// exactly). Partly seen tracks of a motion that no track seen throughout shows are placed on
/// the nearest motion that is shown, and lie far from it.
fn drifted(fits: &[(f64, Vec<f64>)]) -> Vec<Option<(usize, f64)>> {
    let mut levels: Vec<f64> = fits.iter().map(|f| f.0).filter(|r| r.is_finite()).collect();
    levels.sort_by(f64::total_cmp);
    let Some(&typical) = levels.get(levels.len().saturating_sub(1) / 2) else {
        return vec![None; fits.len()];
    };
    fits.iter()
        .map(|(own, partial)| {
            if partial.len() < DRIFT_MIN_TRACKS {
                return None;
            }
            let mut sorted = partial.clone();
            sorted.sort_by(f64::total_cmp);
            let noise = if own.is_finite() {
                own.max(typical)
            } else {
                typical
            };
            let ratio = sorted[sorted.len() / 2] / noise;
            (noise > 0.0 && ratio > DRIFT_RATIO).then_some((partial.len(), ratio))
        })
        .collect()
}

/// What partly seen tracks are placed with.
struct Placing<'a> {
    /// The tracks seen throughout, ascending, and their labels in that order.
    complete: &'a [usize],
    labels: &'a [i64],
    motions: &'a [Motion],
    /// The caller's outlier threshold, when outliers may be answered: a track farther than it
    /// from every motion (over its seen frames) is an outlier. The threshold the refinement
    /// estimates is not used: it is set on the tracks seen throughout, and distances to a
    /// subspace over only some of the frames spread wider (on a clean KT3DMoSeg sequence it
    /// labelled 190 of 503 partly seen tracks −1).
    threshold: Option<f64>,
}

/// Where [`place`] put every track.
struct Placed {
    labels: Vec<i64>,
    /// Partly seen tracks seen in fewer than [`MIN_SEEN_FRAMES`] frames.
    few: usize,
    /// Partly seen tracks with no motion to join (no structure has a subspace, or none
    /// determines the track's coefficients).
    homeless: usize,
}

/// The labels of every track: those of the tracks seen throughout, and for each other track
/// seen in at least [`MIN_SEEN_FRAMES`] frames the label of the nearest motion over its seen
/// frames (−1 beyond the threshold); −1 for the rest. Nearest by the residual per degree of
/// freedom, e² / (2f − r) over f seen frames and a motion of rank r: a motion of higher rank
/// fits a few coordinates more closely whatever the track, and this is each motion's unbiased
/// noise estimate.
fn place(points: &PointSet, visibility: &Visibility, placing: &Placing) -> Placed {
    let n = points.len();
    let mut out = Placed {
        labels: vec![-1; n],
        few: 0,
        homeless: 0,
    };
    for (&i, &l) in placing.complete.iter().zip(placing.labels) {
        out.labels[i] = l;
    }
    for i in 0..n {
        let seen = visibility.seen(i);
        if visibility.throughout(i) {
            continue;
        }
        if seen.iter().filter(|&&s| s).count() < MIN_SEEN_FRAMES {
            out.few += 1;
            continue;
        }
        match nearest_motion(placing.motions, points.row(i), seen) {
            Some((_, d)) if placing.threshold.is_some_and(|tau| d > tau) => {}
            Some((l, _)) => out.labels[i] = l as i64,
            None => out.homeless += 1,
        }
    }
    out
}

/// The motion nearest `row` over its `seen` frames, by the residual per degree of freedom
/// e² / (2f − r) (f frames seen, r the motion's rank: a motion of higher rank fits a few
/// coordinates more closely whatever the track), with its per-frame distance
/// ([`masked_subspace_distance`]); `None` when no motion determines the track's coefficients.
fn nearest_motion(motions: &[Motion], row: &[f64], seen: &[bool]) -> Option<(usize, f64)> {
    let frames = seen.iter().filter(|&&s| s).count() as f64;
    motions
        .iter()
        .map(|m| {
            let d = masked_subspace_distance(&m.mean, &m.basis, row, seen);
            let free = 2.0 * frames - m.basis.len() as f64;
            (m.label, d, d * d * frames / free)
        })
        .filter(|(_, d, _)| d.is_finite())
        .min_by(|a, b| a.2.total_cmp(&b.2))
        .map(|(l, d, _)| (l, d))
}

/// Placement of partly seen tracks by the network, window by window.
struct Window<'a> {
    model: &'a LoadedModel,
    image: Option<ImageSize>,
    options: &'a FitOptions<'a>,
}

/// The label of the nearest centroid (`sums` of embeddings and counts by label) to `v`.
fn nearest_centroid(sums: &BTreeMap<i64, (Vec<f64>, usize)>, v: &[f32]) -> Option<i64> {
    sums.iter()
        .filter(|(_, (_, n))| *n > 0)
        .map(|(&l, (sum, n))| {
            let d: f64 = sum
                .iter()
                .zip(v)
                .map(|(s, &x)| (s / *n as f64 - f64::from(x)).powi(2))
                .sum();
            (l, d)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(l, _)| l)
}

/// The fewest points that stab every one of `ranges` (a point in each), ascending: the greedy
/// by right end (each range not yet stabbed gives its right end), which is optimal.
/// ranges `[m]` -> points `[p]`, p ≤ m.
fn fewest_stabbing(mut ranges: Vec<RangeInclusive<usize>>) -> Vec<usize> {
    ranges.sort_by_key(|r| (*r.end(), *r.start()));
    let mut points: Vec<usize> = Vec::new();
    for r in ranges {
        if points.last().is_none_or(|p| p < r.start()) {
            points.push(*r.end());
        }
    }
    points
}

/// The frame windows of `width` frames that place `tracks` (index, seen flags per frame): each
/// track seen in a run of at least `width` consecutive frames gets a window inside its longest
/// run (the first, among equally long runs). The starts are the fewest that give every such
/// track one ([`fewest_stabbing`]), and a track takes the one nearest the centre of its run
/// (the earlier of two as near). -> window start -> the tracks it places, ascending.
fn window_starts<'a>(
    tracks: impl Iterator<Item = (usize, &'a [bool])>,
    width: usize,
) -> BTreeMap<usize, Vec<usize>> {
    let width = width.max(1);
    // Each track's valid starts: a run [a, a + L) holds the windows starting at a..=a + L - width.
    let mut valid: Vec<(usize, RangeInclusive<usize>)> = Vec::new();
    for (i, seen) in tracks {
        let (mut best, mut run) = ((0, 0), 0);
        for (f, &s) in seen.iter().enumerate() {
            run = if s { run + 1 } else { 0 };
            if run > best.1 {
                best = (f + 1 - run, run);
            }
        }
        if best.1 >= width {
            valid.push((i, best.0..=best.0 + best.1 - width));
        }
    }
    let starts = fewest_stabbing(valid.iter().map(|(_, r)| r.clone()).collect());
    let mut windows: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (i, range) in valid {
        let centre = (range.start() + range.end()) / 2;
        let inside = starts.iter().copied().filter(|s| range.contains(s));
        if let Some(start) = inside.min_by_key(|&s| (s.abs_diff(centre), s)) {
            windows.entry(start).or_default().push(i);
        }
    }
    windows
}

impl Window<'_> {
    /// Partly seen tracks with a run of at least the network's frame count of consecutive seen
    /// frames: a window of that many frames inside the longest run is embedded with every track
    /// seen in all of it ([`window_starts`]: the fewest windows that give every such track
    /// one). Where the network's label centroids place the tracks seen throughout better than
    /// the motion subspaces do over the window's frames (each half of them judged by both
    /// fitted on the other half), the window's partly seen tracks take the label of the
    /// nearest centroid.
    fn place(
        &self,
        points: &PointSet,
        visibility: &Visibility,
        complete: &[usize],
        placed: &mut Placed,
    ) -> Result<(), FitError> {
        let width = self.model.card.input_dim / 2;
        let frames = visibility.frames();
        if width < 2 || width > frames {
            return Ok(());
        }
        let placeable = (0..points.len())
            .filter(|&i| !visibility.throughout(i) && placed.labels[i] >= 0)
            .map(|i| (i, visibility.seen(i)));
        let windows = window_starts(placeable, width);
        if windows.is_empty() {
            return Ok(());
        }
        let labelled: Vec<usize> = complete
            .iter()
            .copied()
            .filter(|&i| placed.labels[i] >= 0)
            .collect();
        // The judge: each half of the tracks seen throughout placed by both methods fitted on
        // the other half. The halves' motions (fitted over every frame) serve every window.
        let halves: [Vec<usize>; 2] = [
            labelled.iter().copied().step_by(2).collect(),
            labelled.iter().copied().skip(1).step_by(2).collect(),
        ];
        let half_motions = |half: &[usize]| -> Vec<Motion> {
            let mut labels: Vec<i64> = half.iter().map(|&i| placed.labels[i]).collect();
            labels.sort_unstable();
            labels.dedup();
            labels
                .into_iter()
                .filter_map(|l| {
                    let rows: Vec<&[f64]> = half
                        .iter()
                        .filter(|&&i| placed.labels[i] == l)
                        .map(|&i| points.row(i))
                        .collect();
                    Motion::fitted(l as usize, &rows)
                })
                .collect()
        };
        let judges = [
            (&halves[0], &halves[1], half_motions(&halves[0])),
            (&halves[1], &halves[0], half_motions(&halves[1])),
        ];
        for (start, tracks) in windows {
            let rows: Vec<usize> = (0..points.len())
                .filter(|&i| visibility.seen(i)[start..start + width].iter().all(|&s| s))
                .collect();
            let values: Vec<f64> = rows
                .iter()
                .flat_map(|&i| {
                    points.row(i)[2 * start..2 * (start + width)]
                        .iter()
                        .copied()
                })
                .collect();
            let cut = PointSet::from_flat(Kind::Trajectories, 2 * width, values)
                .map_err(|e| FitError::Input(e.to_string()))?;
            let options = self.options;
            let z = embed(
                self.model,
                &cut,
                self.image,
                options.symmetries,
                options.params.seed(),
            )?;
            let e = z.width;
            let z = z.per_point();
            let at = |i: usize| rows.binary_search(&i).ok().map(|r| &z[r * e..(r + 1) * e]);
            let centroids = |tracks: &[usize]| {
                let mut sums: BTreeMap<i64, (Vec<f64>, usize)> = BTreeMap::new();
                for &i in tracks {
                    let Some(v) = at(i) else { continue };
                    let entry = sums
                        .entry(placed.labels[i])
                        .or_insert_with(|| (vec![0.0; e], 0));
                    for (a, &b) in entry.0.iter_mut().zip(v) {
                        *a += f64::from(b);
                    }
                    entry.1 += 1;
                }
                sums
            };
            let seen_in_window: Vec<bool> = (0..frames)
                .map(|f| (start..start + width).contains(&f))
                .collect();
            let (mut network, mut subspaces) = (0, 0);
            for (fitted, judged, motions) in &judges {
                let sums = centroids(fitted);
                for &i in judged.iter() {
                    let l = placed.labels[i];
                    let by_network = at(i).and_then(|v| nearest_centroid(&sums, v));
                    network += usize::from(by_network == Some(l));
                    let by_subspace = nearest_motion(motions, points.row(i), &seen_in_window);
                    subspaces += usize::from(by_subspace.is_some_and(|(m, _)| m as i64 == l));
                }
            }
            if network <= subspaces {
                continue;
            }
            let sums = centroids(&labelled);
            for i in tracks {
                if let Some(l) = at(i).and_then(|v| nearest_centroid(&sums, v)) {
                    placed.labels[i] = l;
                }
            }
        }
        Ok(())
    }
}

/// A label's motion: the affine subspace its tracks lie in.
struct Motion {
    label: usize,
    mean: Vec<f64>,
    basis: Vec<Vec<f64>>,
}

impl Motion {
    /// The motion of a subspace model; `None` for any other model.
    fn of(label: usize, model: &Model) -> Option<Self> {
        match model {
            Model::Subspace { mean, basis, .. } => Some(Self {
                label,
                mean: mean.clone(),
                basis: basis.clone(),
            }),
            _ => None,
        }
    }

    /// The subspace fitted on `rows` (tracks over every frame); `None` where they determine
    /// none.
    fn fitted(label: usize, rows: &[&[f64]]) -> Option<Self> {
        Self::of(label, &geometry::fit_type("subspace", rows)?.model)
    }
}

/// Each label's motion: the refined structure's subspace, or, without refinement, one fitted on
/// the label's tracks over every frame.
fn motions(points: &PointSet, outcome: &FitOutcome) -> Vec<Motion> {
    if !outcome.structures.is_empty() {
        return outcome
            .structures
            .iter()
            .filter_map(|s| Motion::of(s.label, &s.model))
            .collect();
    }
    (0..outcome.k)
        .filter_map(|l| {
            let rows: Vec<&[f64]> = (0..points.len())
                .filter(|&i| outcome.labels[i] == l as i64)
                .map(|i| points.row(i))
                .collect();
            Motion::fitted(l, &rows)
        })
        .collect()
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

/// The warning of an answer with fewer structures than the k the caller gave (`refined`:
/// refinement dropped the difference; else one learned group was the outliers'); `None` when
/// it has k.
fn fewer_than_asked(asked: usize, answered: usize, refined: bool) -> Option<String> {
    let dropped = asked.checked_sub(answered).filter(|&d| d > 0)?;
    if !refined {
        return Some(format!(
            "k = {asked} was given and the answer has {answered} structure{}: one of the \
             {asked} learned groups is the outliers', answered -1 (\"outliers\": false answers \
             the {asked} learned groups)",
            if answered == 1 { "" } else { "s" }
        ));
    }
    let (noun, their) = if dropped == 1 {
        ("group", "its")
    } else {
        ("groups", "their")
    };
    let structures = if answered == 1 {
        "structure"
    } else {
        "structures"
    };
    Some(format!(
        "k = {asked} was given and refinement answers {answered} {structures}: {dropped} learned \
         {noun} followed no model or lost most of {their} points to the others (\"refine\": \
         false answers the {asked} learned groups)"
    ))
}

/// Points that span under this share of the image's longer side sit in a corner of what the
/// network reads (inputs are normalised by the image): [`image_barely_used`].
const MIN_IMAGE_SPAN: f64 = 0.1;

/// The warning of pixel coordinates that span under [`MIN_IMAGE_SPAN`] of the `image` given
/// (along x and along y, over every view or frame; for two images of two sizes, each view in
/// its own image): most often an image size that is not the one the coordinates were measured
/// in. `None` for points2d, without an image, or when the points use the image.
fn image_barely_used(points: &PointSet, image: Option<ImageSize>) -> Option<String> {
    let image = image.filter(|_| points.kind() != Kind::Points2d)?;
    let check = "check that image_size is the size of the image the coordinates were measured in";
    if image.second.is_some() && points.kind() == Kind::Correspondences {
        let words: Vec<String> = (0..2)
            .filter_map(|v| {
                let span = points.view_extent(v);
                let [w, h] = image.view(v);
                let side = w.max(h);
                (span < MIN_IMAGE_SPAN * side).then(|| {
                    format!(
                        "the points of image {} span {} px of its {side} px",
                        v + 1,
                        span.round()
                    )
                })
            })
            .collect();
        return (!words.is_empty()).then(|| format!("{}: {check}", words.join("; ")));
    }
    let span = points.extent();
    let side = image.width.max(image.height);
    (span < MIN_IMAGE_SPAN * side).then(|| {
        format!(
            "the points span {} px of the {side} px image: {check}",
            span.round()
        )
    })
}

/// The warnings of pixel coordinates that do not fit the `image` given: spanning a corner of it
/// ([`image_barely_used`]), or lying outside it ([`outside_image`]).
fn image_warnings(points: &PointSet, image: Option<ImageSize>) -> impl Iterator<Item = String> {
    image_barely_used(points, image)
        .into_iter()
        .chain(outside_image(points, image))
}

/// A position outside the image by more than this share of its width or height counts as
/// outside it (tracks and matches may run a little past the border).
const OUTSIDE_MARGIN: f64 = 0.1;
/// The share of positions outside the image past which a fit says so.
const OUTSIDE_SHARE: f64 = 0.05;

/// The warning of pixel coordinates outside the `image` given ([`OUTSIDE_MARGIN`]), for more
/// than [`OUTSIDE_SHARE`] of the positions (each view of a correspondence against its own
/// image): an image_size in other units than the points, or swapped. `None` for points2d, no
/// image, or a few such positions.
fn outside_image(points: &PointSet, image: Option<ImageSize>) -> Option<String> {
    let image = image.filter(|_| points.kind() != Kind::Points2d)?;
    let two_views = points.kind() == Kind::Correspondences;
    let (mut outside, mut total) = (0usize, 0usize);
    let off = |x: f64, side: f64| x < -OUTSIDE_MARGIN * side || x > (1.0 + OUTSIDE_MARGIN) * side;
    for i in 0..points.len() {
        for (j, p) in points.row(i).chunks_exact(2).enumerate() {
            let [w, h] = image.view(if two_views { j } else { 0 });
            total += 1;
            outside += usize::from(off(p[0], w) || off(p[1], h));
        }
    }
    (outside as f64 > OUTSIDE_SHARE * total as f64).then(|| {
        format!(
            "{outside} of the {total} positions lie outside the image_size given: check that it \
             is the size of the image the coordinates were measured in, in the same units, width \
             first"
        )
    })
}

/// The warning of track positions at exactly (0, 0), what many trackers write for a point
/// they lost: read as positions, they pull their tracks to the image corner. `None` for other
/// kinds, or when there are none.
fn lost_marks(points: &PointSet) -> Option<String> {
    if points.kind() != Kind::Trajectories {
        return None;
    }
    let zeros = points
        .values()
        .chunks_exact(2)
        .filter(|p| p[0] == 0.0 && p[1] == 0.0)
        .count();
    (zeros > 0).then(|| {
        format!(
            "{zeros} track position{} exactly (0, 0): if they mark points the tracker lost, send \
             visible (one row of 0/1 flags per track, 0 where it was not seen) so that they are \
             not read as positions",
            if zeros == 1 { " is" } else { "s are" }
        )
    })
}

/// The warning for rows the network did not read for lying far from the rest
/// ([`crate::data::screen`]), naming the first few by the caller's 0-based row numbers.
fn far_apart(far: &[usize], rows: &str) -> Option<String> {
    const NAMED: usize = 10;
    let (count, named) = (far.len(), far.iter().take(NAMED));
    (count > 0).then(|| {
        let list = named.map(|i| i.to_string()).collect::<Vec<_>>().join(", ");
        format!(
            "{count} of the {rows} lie{} far from the rest (more than {} times the spread of \
             the {rows} nearer the centre), so the network did not read {}: {}{list}{}",
            if count == 1 { "s" } else { "" },
            screen::FAR_SPREADS,
            if count == 1 { "it" } else { "them" },
            if count == 1 { "row " } else { "rows " },
            if count > NAMED { ", ..." } else { "" },
        )
    })
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

/// What a fit saw, for the card's validated range: the input's size, frames and image, and the
/// answer's structure sizes and outlier share (only when the fit may answer outliers: a fit
/// that cannot flag them says nothing of their share).
fn observed(
    points: &PointSet,
    image: Option<ImageSize>,
    labels: &[i64],
    k: usize,
    flags_outliers: bool,
) -> Observed {
    let mut sizes = vec![0usize; k];
    for &l in labels {
        if let Some(s) = usize::try_from(l).ok().and_then(|l| sizes.get_mut(l)) {
            *s += 1;
        }
    }
    let outliers = labels.iter().filter(|&&l| l < 0).count();
    Observed {
        rows: "points",
        points: points.len(),
        points_per_structure: sizes
            .iter()
            .min()
            .zip(sizes.iter().max())
            .map(|(&a, &b)| [a, b]),
        frames: (points.kind() == Kind::Trajectories).then(|| points.dim() / 2),
        image_side: image.map(|s| s.width.max(s.height)),
        outlier_ratio: flags_outliers.then(|| outliers as f64 / points.len().max(1) as f64),
    }
}

impl LoadedModel {
    /// [`fit`] with the card's test-time symmetries, without refinement: the learned clustering
    /// (a K given is the number of groups, no outlier group set apart).
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

    #[test]
    fn tracks_at_the_origin_are_named_as_a_trackers_lost_points() {
        let tracks = |lost: &[usize]| {
            let mut values: Vec<f64> = (0..24).map(|v| f64::from(v) + 1.0).collect();
            for &p in lost {
                values[2 * p] = 0.0;
                values[2 * p + 1] = 0.0;
            }
            PointSet::from_flat(Kind::Trajectories, 6, values).unwrap()
        };
        assert_eq!(lost_marks(&tracks(&[])), None);
        let one = lost_marks(&tracks(&[4])).unwrap();
        assert!(
            one.starts_with("1 track position is exactly (0, 0)"),
            "{one}"
        );
        let two = lost_marks(&tracks(&[4, 11])).unwrap();
        assert!(
            two.starts_with("2 track positions are exactly (0, 0)"),
            "{two}"
        );
        // A pair at the origin is a point like any other.
        let pairs = PointSet::from_flat(Kind::Correspondences, 4, vec![0.0; 8]).unwrap();
        assert_eq!(lost_marks(&pairs), None);
    }

    /// Clustering parameters with K given.
    fn fixed(k: usize) -> ClusterParams {
        ClusterParams::builder()
            .selection(Selection::Fixed(k))
            .build()
            .unwrap()
    }

    /// A fit's options with `params`, no symmetries, no refinement.
    fn unrefined(params: &ClusterParams) -> FitOptions<'_> {
        FitOptions {
            params,
            symmetries: &[],
            refine: None,
            outlier_group: false,
        }
    }

    /// The values 0 to 39, and ten correspondences of them: x from 0 to 38, y from 1 to 39.
    fn forty_values() -> (Vec<f64>, PointSet) {
        let values: Vec<f64> = (0..40).map(f64::from).collect();
        let pairs = PointSet::from_flat(Kind::Correspondences, 4, values.clone()).unwrap();
        (values, pairs)
    }

    fn image(w: f64, h: f64) -> Option<ImageSize> {
        Some(ImageSize::new(w, h).unwrap())
    }

    #[test]
    fn points_outside_the_image_say_so() {
        // Inside a 40 x 40 image, outside a 20 x 20 one by far.
        let (values, pairs) = forty_values();
        assert_eq!(outside_image(&pairs, None), None);
        assert_eq!(outside_image(&pairs, image(40.0, 40.0)), None);
        // Within a tenth of the size past the border is inside: 36 x 36 holds up to 39.6.
        assert_eq!(outside_image(&pairs, image(36.0, 36.0)), None);
        let w = outside_image(&pairs, image(20.0, 20.0)).unwrap();
        assert!(w.starts_with("9 of the 20 positions lie outside"), "{w}");
        // Each view against its own image: the second view (x 2..38) fits 40 x 40.
        let two = Some(ImageSize::per_view([20.0, 20.0], [40.0, 40.0]).unwrap());
        let w = outside_image(&pairs, two).unwrap();
        assert!(w.starts_with("4 of the 20 positions lie outside"), "{w}");
        // Tracks: every frame in the one image; curves have no image.
        let tracks = PointSet::from_flat(Kind::Trajectories, 4, values.clone()).unwrap();
        assert!(outside_image(&tracks, image(20.0, 20.0)).is_some());
        let curve = PointSet::from_flat(Kind::Points2d, 2, values).unwrap();
        assert_eq!(outside_image(&curve, image(20.0, 20.0)), None);
    }

    #[test]
    fn points_in_a_corner_of_the_image_say_so() {
        let (values, pairs) = forty_values();
        assert_eq!(image_barely_used(&pairs, None), None);
        assert_eq!(image_barely_used(&pairs, image(380.0, 200.0)), None);
        let w = image_barely_used(&pairs, image(4000.0, 3000.0)).unwrap();
        assert!(
            w.starts_with("the points span 38 px of the 4000 px image"),
            "{w}"
        );
        // Two images of two sizes: each view against its own image.
        let two = |second| Some(ImageSize::per_view([300.0, 200.0], second).unwrap());
        assert_eq!(image_barely_used(&pairs, two([320.0, 240.0])), None);
        let w = image_barely_used(&pairs, two([4000.0, 3000.0])).unwrap();
        assert!(
            w.starts_with("the points of image 2 span 36 px of its 4000 px: check"),
            "{w}"
        );
        let big = Some(ImageSize::per_view([4000.0, 3000.0], [5000.0, 3000.0]).unwrap());
        let w = image_barely_used(&pairs, big).unwrap();
        assert!(
            w.starts_with("the points of image 1 span 36 px of its 4000 px; the points of image 2"),
            "{w}"
        );
        // Curves have no image.
        let curve = PointSet::from_flat(Kind::Points2d, 2, values.clone()).unwrap();
        assert_eq!(lost_marks(&curve), None);
        assert_eq!(image_barely_used(&curve, image(4000.0, 3000.0)), None);
    }

    #[test]
    fn an_answer_with_fewer_structures_than_the_k_given_says_so() {
        assert_eq!(fewer_than_asked(3, 3, true), None);
        assert_eq!(fewer_than_asked(3, 4, true), None);
        assert_eq!(fewer_than_asked(3, 3, false), None);
        let unrefined = fewer_than_asked(3, 2, false).unwrap();
        assert!(
            unrefined.starts_with(
                "k = 3 was given and the answer has 2 structures: one of the 3 learned groups is \
                 the outliers'"
            ),
            "{unrefined}"
        );
        let one = fewer_than_asked(3, 2, true).unwrap();
        assert!(
            one.starts_with(
                "k = 3 was given and refinement answers 2 structures: 1 learned group followed"
            ),
            "{one}"
        );
        let two = fewer_than_asked(4, 2, true).unwrap();
        assert!(two.contains("2 learned groups followed no model or lost most of their points"));
        assert!(
            two.ends_with("(\"refine\": false answers the 4 learned groups)"),
            "{two}"
        );
    }

    #[test]
    fn the_outlier_share_is_observed_only_when_the_fit_may_flag_outliers() {
        let values: Vec<f64> = (0..40).map(f64::from).collect();
        let points = PointSet::from_flat(Kind::Correspondences, 4, values).unwrap();
        let labels = [0, 0, 1, 1, 0, 1, 0, 1, 0, 1];
        let range = crate::registry::ValidatedRange {
            outlier_ratio: Some([0.0, 0.25]),
            ..Default::default()
        };
        // A fit that cannot answer -1 (no refinement, or outliers off) says nothing of the share.
        let half = [0, -1, 1, -1, 0, -1, 0, -1, 1, -1];
        let quiet = observed(&points, None, &half, 2, false);
        assert_eq!(quiet.outlier_ratio, None);
        assert!(range.warnings(&quiet).is_empty());
        // One that may is measured: none flagged is within the range, half is above it.
        let clean = observed(&points, None, &labels, 2, true);
        assert_eq!(clean.outlier_ratio, Some(0.0));
        assert!(range.warnings(&clean).is_empty());
        let flagged = observed(&points, None, &half, 2, true);
        assert_eq!(flagged.outlier_ratio, Some(0.5));
        assert_eq!(range.warnings(&flagged).len(), 1);
    }

    #[test]
    fn each_track_gets_a_window_inside_its_longest_run() {
        let flags = |s: &str| -> Vec<bool> { s.chars().map(|c| c == '1').collect() };
        let tracks = [
            flags("0001111111"), // a run ending at the last frame: starts 3..=5
            flags("1111100000"), // a run exactly the width long: start 0 only
            flags("1111011110"), // two runs of 4: too short for a window of 5
            flags("1111101111"), // runs of 5 and 4: the first, start 0
            flags("0111111000"), // starts 1..=2, centre 1
        ];
        let windows = window_starts(tracks.iter().enumerate().map(|(i, t)| (i, &t[..])), 5);
        let mut got: Vec<(usize, usize)> = windows
            .iter()
            .flat_map(|(&s, ts)| ts.iter().map(move |&t| (t, s)))
            .collect();
        got.sort_unstable();
        // Valid starts by right end: 0..=0 (tracks 1, 3), 1..=2 (track 4), 3..=5 (track 0):
        // the greedy's starts are 0, 2 and 5.
        assert_eq!(got, vec![(0, 5), (1, 0), (3, 0), (4, 2)]);
        for (t, s) in got {
            assert!(tracks[t][s..s + 5].iter().all(|&v| v), "track {t} at {s}");
        }
        // Starts 1 and 3 (tracks 0 and 1 have no other); track 2 (starts 0..=4, centre 2) is
        // as near both and takes the earlier.
        let tie = [flags("011111000"), flags("000111110"), flags("111111111")];
        let windows = window_starts(tie.iter().enumerate().map(|(i, t)| (i, &t[..])), 5);
        assert_eq!(windows.get(&1), Some(&vec![0, 2]));
        assert_eq!(windows.get(&3), Some(&vec![1]));
        let none: [Vec<bool>; 0] = [];
        assert!(window_starts(none.iter().enumerate().map(|(i, t)| (i, &t[..])), 5).is_empty());
    }

    #[test]
    fn the_fewest_window_starts_give_every_track_one() {
        // Brute force over every set of starts in 0..12 for random ranges: the greedy's count is
        // the least that stabs them all, and it stabs them all.
        let mut state = 7u64;
        let mut next = |m: u64| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            ((state >> 33) % m) as usize
        };
        for _ in 0..200 {
            let ranges: Vec<RangeInclusive<usize>> = (0..1 + next(6))
                .map(|_| {
                    let a = next(10);
                    a..=a + next(3)
                })
                .collect();
            let points = fewest_stabbing(ranges.clone());
            assert!(points.windows(2).all(|w| w[0] < w[1]), "{points:?}");
            let stabs = |set: &[usize]| ranges.iter().all(|r| set.iter().any(|p| r.contains(p)));
            assert!(stabs(&points), "{ranges:?} {points:?}");
            let least = (0u32..1 << 12)
                .filter(|mask| {
                    let set: Vec<usize> = (0..12).filter(|b| mask >> b & 1 == 1).collect();
                    stabs(&set)
                })
                .map(u32::count_ones)
                .min()
                .unwrap();
            assert_eq!(points.len(), least as usize, "{ranges:?}");
        }
        assert!(fewest_stabbing(Vec::new()).is_empty());
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

    /// 12 tracks over 4 frames, 6 of each of two motions (turning at different rates and
    /// drifting apart), then a track of each seen in frames 0, 1 and 3 only (garbage in frame
    /// 2) and one seen in frames 0 and 3: rows and visibility.
    fn partly_seen_tracks() -> (PointSet, Visibility) {
        let track = |x: f64, y: f64, m: usize| -> Vec<f64> {
            (0..4)
                .flat_map(|f| {
                    let a = f as f64 * [0.05, -0.2][m];
                    let (s, c) = a.sin_cos();
                    let t = f as f64 * [3.0, -2.0][m];
                    [c * x - s * y + t + 32.0, s * x + c * y - t + 32.0]
                })
                .collect()
        };
        let mut rows: Vec<Vec<f64>> = (0..12)
            .map(|i| track((i * 7 % 11) as f64 - 5.0, (i * 5 % 13) as f64 - 6.0, i / 6))
            .collect();
        for (m, x) in [(0, 4.5), (1, -2.5)] {
            let mut t = track(x, 3.0, m);
            t[4] = 900.0;
            t[5] = -900.0;
            rows.push(t);
        }
        // The first is half a pixel off its motion in frame 0.
        rows[12][0] += 0.5;
        rows.push(track(1.0, 1.0, 0));
        let mut seen = vec![vec![true; 4]; 12];
        seen.extend([
            vec![true, true, false, true],
            vec![true, true, false, true],
            vec![true, false, false, true],
        ]);
        let points = PointSet::from_rows(Kind::Trajectories, &rows).unwrap();
        (points, Visibility::new(&seen, 15, 4).unwrap())
    }

    /// A partly seen track goes to the motion nearest over its seen frames, or is an outlier
    /// beyond the threshold; one seen in too few frames stays −1.
    #[test]
    fn partly_seen_tracks_go_to_the_motion_of_their_seen_frames() {
        let (points, visibility) = partly_seen_tracks();
        let complete = visibility.complete();
        let truth: Vec<i64> = (0..12).map(|i| (i / 6) as i64).collect();
        let motions: Vec<Motion> = (0..2)
            .map(|m| {
                let rows: Vec<&[f64]> = (6 * m..6 * m + 6).map(|i| points.row(i)).collect();
                Motion::fitted(m, &rows).expect("a subspace")
            })
            .collect();
        let mut placing = Placing {
            complete: &complete,
            labels: &truth,
            motions: &motions,
            threshold: None,
        };
        let placed = place(&points, &visibility, &placing);
        let labels = placed.labels.clone();
        assert_eq!(&labels[..12], &truth[..]);
        assert_eq!(&labels[12..], &[0, 1, -1]);
        assert_eq!((placed.few, placed.homeless), (1, 0));
        // No motion to join: every partly seen track is homeless.
        let none = Placing {
            motions: &[],
            ..placing
        };
        let homeless = place(&points, &visibility, &none);
        assert_eq!((homeless.few, homeless.homeless), (1, 2));
        // With an outlier threshold, a partly seen track beyond it from every motion is an
        // outlier (not counted as unplaced); within it, placed as before.
        placing.threshold = Some(0.01);
        let far = place(&points, &visibility, &placing);
        assert_eq!((&far.labels[12..], far.few), (&[-1, 1, -1][..], 1));
        placing.threshold = Some(10.0);
        assert_eq!(place(&points, &visibility, &placing).labels, labels);
    }

    #[test]
    fn the_nearest_centroid_is_that_of_the_nearest_mean() {
        let mut sums = BTreeMap::new();
        // Label 0: mean (1, 0); label 1: mean (0, 2); label 2: no tracks.
        sums.insert(0, (vec![3.0, 0.0], 3));
        sums.insert(1, (vec![0.0, 4.0], 2));
        sums.insert(2, (vec![0.0, 0.0], 0));
        assert_eq!(nearest_centroid(&sums, &[0.9, 0.2]), Some(0));
        assert_eq!(nearest_centroid(&sums, &[0.1, 1.5]), Some(1));
        assert_eq!(nearest_centroid(&BTreeMap::new(), &[0.0, 0.0]), None);
    }

    /// Through the pipeline: the tracks seen throughout are fitted alone (the same labels as
    /// fitting them by themselves), the others take a structure's label or −1 with a warning,
    /// and the structures count every track labelled with them.
    #[test]
    fn a_far_track_is_named_by_the_callers_row_among_partly_seen_tracks() {
        // 24 tracks of two motions seen throughout, one seen in 3 of 4 frames (row 1), and a
        // track far from all of them (row 26), seen throughout: the subset read is rows 0 and
        // 2..=26, where the far track is row 25; the warning names the caller's row.
        let track = |i: usize| -> Vec<f64> {
            let (x, y, m) = ((i * 7 % 11) as f64 - 5.0, (i * 5 % 13) as f64 - 6.0, i % 2);
            (0..4)
                .flat_map(|f| {
                    let t = f as f64 * [3.0, -2.0][m];
                    [x + t + 32.0, y - t + 32.0]
                })
                .collect()
        };
        let mut rows: Vec<Vec<f64>> = (0..26).map(track).collect();
        rows.push(vec![9e4; 8]);
        let mut seen = vec![vec![true; 4]; 27];
        seen[1][2] = false;
        let points = PointSet::from_rows(Kind::Trajectories, &rows).unwrap();
        let visibility = Visibility::new(&seen, 27, 4).unwrap();
        let model = tiny(vec![]);
        let params = fixed(2);
        let options = unrefined(&params);
        let out = fit_seen(&model, &points, &visibility, image(64.0, 64.0), &options).unwrap();
        let far: Vec<&String> = out.warnings.iter().filter(|w| w.contains("far")).collect();
        assert_eq!(far.len(), 1, "{:?}", out.warnings);
        assert!(
            far[0].ends_with("so the network did not read it: row 26"),
            "{}",
            far[0]
        );
    }

    #[test]
    fn fits_of_partly_seen_tracks_fit_the_tracks_seen_throughout() {
        let model = tiny(vec![]);
        let (points, visibility) = partly_seen_tracks();
        let params = ClusterParams::builder()
            .selection(Selection::Fixed(2))
            .seed(1)
            .build()
            .unwrap();
        let options = FitOptions {
            params: &params,
            symmetries: &[],
            refine: Some(RefineParams {
                outliers: false,
                ..RefineParams::default()
            }),
            outlier_group: false,
        };
        let image = Some(ImageSize::new(64.0, 64.0).unwrap());
        let out = fit_seen(&model, &points, &visibility, image, &options).unwrap();
        let throughout = points.select(&visibility.complete()).unwrap();
        let alone = fit(&model, &throughout, image, &options).unwrap();
        assert_eq!(out.labels.len(), 15);
        assert_eq!(&out.labels[..12], &alone.labels[..]);
        assert!(
            out.labels[12..14]
                .iter()
                .all(|&l| (0..out.k as i64).contains(&l))
        );
        assert_eq!(out.labels[14], -1);
        assert!(
            out.warnings
                .iter()
                .any(|w| w == "1 track seen in fewer than 3 frames is labelled -1"),
            "{:?}",
            out.warnings
        );
        for s in &out.structures {
            let n = out.labels.iter().filter(|&&l| l == s.label as i64).count();
            assert_eq!(s.inliers, n);
            assert!(s.rms.is_finite());
        }
        // A mask of other tracks is refused, not a panic.
        let other = Visibility::new(&vec![vec![true; 4]; 3], 3, 4).unwrap();
        assert!(matches!(
            fit_seen(&model, &points, &other, image, &options),
            Err(FitError::Input(_))
        ));
        // Every track seen throughout: the plain fit.
        let all = Visibility::new(&vec![vec![true; 4]; 12], 12, 4).unwrap();
        let plain = fit_seen(&model, &throughout, &all, image, &options).unwrap();
        assert_eq!(plain.labels, alone.labels);
    }

    #[test]
    fn partly_seen_tracks_far_from_their_structure_are_flagged_against_its_noise() {
        let ten = |d: f64| vec![d; 10];
        let fits = [
            // As near as the tracks seen throughout: no warning.
            (1.0, ten(1.0)),
            // Three times farther: flagged, with the count and the ratio.
            (1.0, ten(3.0)),
            // A structure whose few tracks seen throughout fit it exactly: the noise is the
            // median structure's (1.0), and 0.5 is within it.
            (0.001, ten(0.5)),
            // Far, but too few tracks to weigh.
            (1.0, vec![9.0; DRIFT_MIN_TRACKS - 1]),
            // No track seen throughout (RMS NaN): the median structure's noise.
            (f64::NAN, ten(2.5)),
        ];
        let got = drifted(&fits);
        assert_eq!(got, [None, Some((10, 3.0)), None, None, Some((10, 2.5))]);
        // No structure with a finite noise: nothing to weigh against.
        assert_eq!(drifted(&[(f64::NAN, ten(5.0))]), [None]);
        assert!(drifted(&[]).is_empty());
        assert!((rms([3.0, 4.0].into_iter()) - 12.5_f64.sqrt()).abs() < 1e-12);
        assert!(rms(std::iter::empty()).is_nan());
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
    fn refinement_answers_structures_and_counts_them_as_k() {
        let model = tiny(vec![]);
        let (points, image, params) = ten_tracks(7, 13);
        let options = FitOptions {
            params: &params,
            symmetries: &[],
            refine: Some(RefineParams::default()),
            outlier_group: false,
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
