//! Stage 5 of a fit: geometric refinement of the learned clustering, and outliers.
//!
//! The learned groups are the start. Each group gets an explicit model of its family
//! ([`geometry::fit`]: robust inside the group, its type chosen by GRIC or BIC), fitted on the
//! input as the caller sent it (every frame of a track, pixel units). Then, to a fixed point or
//! [`MAX_ITERATIONS`] rounds:
//!
//! 1. every point goes to the structure with the smallest residual r_j(x) (a geometric distance
//!    in the caller's units: all structures of a fit measure in the same units), except that a
//!    point keeps its current structure while its residual there is within `stay` × σ
//!    ([`RefineParams::stay`], the model card's `refine_stay`, capped at τ), or exceeds the
//!    smallest by at most `margin` × σ ([`RefineParams::margin`], the card's `refine_margin`):
//!    within the noise the geometry cannot tell the structures apart, and the learned label
//!    carries what it saw (a structure the hypotheses stage swapped in keeps, in the first
//!    round, the learned points that fit it so closely). The track models' cards set a margin
//!    of 0.1 σ: on short clips nearest-subspace reassignment moves tracks on differences far
//!    inside the noise, and they drift to the wrong motion. Neither radius keeps a point past
//!    the outlier threshold;
//! 2. a point whose smallest residual exceeds the outlier threshold τ is labelled −1 (when
//!    outliers are allowed); while the rounds run a curve takes the points within
//!    [`GROW_TAUS`] × τ, so that an arc fitted on part of its curve, whose extrapolation
//!    leaves τ at its ends, grows along the curve. Once the rounds settle, every point is
//!    assigned at τ before the types are chosen again and pairs merge, so that the answer's
//!    models are fitted on the points within τ (fitted on the 2 τ sets, they took in more
//!    outliers: `lce` grid at 50 % outliers, known K 35.23 -> 35.12 %);
//! 3. every structure is fitted again on its points, keeping its model type (a line stays a
//!    line while points move; a circle or an ellipse is refined from its current parameters,
//!    its points having moved a little); a structure left with fewer than half the points it started
//!    with, or fewer than its model needs, is dropped and its points go to the others in the
//!    next round. A round that moves no point ends the rounds. With a K the caller gave,
//!    correspondences and curves keep a structure that shrank (only one left too few points
//!    for its model is dropped), as the caller counted it: on the AdelaideRMF homography folds
//!    that lowered the error in every cell of the grid (as-is 5.13 -> 4.65 %), and it leaves the
//!    LCE grid level (21.85 -> 21.88 % over the cells with at most 20 % outliers). Motion subspaces
//!    still drop it, and may answer fewer than K structures: keeping it raised the error on
//!    KT3DMoSeg (3.90 -> 4.17 %) and on long generated clips (4.46 -> 4.70 %), and so did
//!    re-seeding it from the tracks the others explain worst (4.59 and 4.25 %).
//!
//! Before the rounds, models proposed from small neighbourhoods of the input may replace learned
//! structures where they explain the whole set better ([`hypotheses`]): a learned group that
//! mixes two structures, or a structure the network spread over several groups, gives a model
//! that reassignment alone cannot repair. A K the caller gave stays; a K chosen automatically may
//! grow by structures that explain points no structure does. Motion subspaces take no
//! hypotheses: a rank-3 affine subspace fitted to a handful of nearby tracks also holds tracks of
//! other motions that move alike, and swapping such subspaces in raised the error on KT3DMoSeg.
//!
//! Once the rounds settle, each structure's type is chosen again on its final points (the
//! learned group it started from may have held foreign points that swayed the first choice;
//! the fit of its own type on those points is the last round's), and every point is assigned
//! once more.
//!
//! **More structures than the chosen K** ([`splits_pooled`]). When two structures share one
//! learned group, their pooled fit sets a noise level under which both fit, so neither the
//! rounds nor the hypotheses part them. With K chosen the fit also refines the k + 1
//! clustering ([`crate::pipeline::refine_chosen`]) and keeps that answer when it has at least as
//! many structures, a noise level ([`Refined::noise`]) at most 1 / 1.7 of the k answer's
//! ([`SPLIT_NOISE_FACTOR`]), and at most 5 % of the points more as outliers; from an answer so
//! kept it goes on to the k + 2 clustering under the same test, and so on
//! ([`split_while_pooled`]). On the AdelaideRMF
//! homography folds SOD's K was right on 52.9 % of the pairs without it, 82.4 % with it, and
//! 88.2 % once merging asked one of the two structures' models instead of both.
//!
//! **Noise and threshold.** The noise level σ is the median of the groups' robust noise levels
//! (each 1.4826 × the median residual inside its group, [`geometry::Fit::sigma`]): the sensor's
//! noise, shared by every structure, and not moved by one group of outliers. Groups fitted on
//! fewer than [`NOISE_VOTE_POINTS`] times the points that determine their model do not vote:
//! their fit absorbs the noise, and in a sparse set (an AdelaideRMF pair subsampled to 25 %)
//! several such groups pulled σ, and τ with it, below the sensor's. τ = [`OUTLIER_SIGMAS`]
//! × σ, or the caller's `outlier_threshold`. A learned group whose robust fit explains less than
//! [`OUTLIER_GROUP_INLIERS`] of its points, or whose own noise level exceeds
//! [`OUTLIER_GROUP_SIGMAS`] × σ, follows no model: it is the outlier group that models trained
//! with outliers as one more group learn (AdelaideRMF), and it is dissolved: its points go to a
//! structure they fit, or become outliers.
//!
//! **Merging.** When K was chosen automatically, two structures whose union one model of the
//! same family fits with a noise level within [`MERGE_SIGMAS`] × σ are one structure seen twice
//! (K chosen too high), and merge (σ at least the joint fit's floor, [`geometry::robust`]'s
//! σ_floor of the pair's points: on noise-free data every noise level is a floor, and a pair's
//! floor exceeds each structure's). Only pairs where one of the two structures' models already
//! explains at least half of the other's points within τ are fitted jointly: a structure seen
//! twice passes (a curve seen as a long and a short arc passes by the long arc's model, where
//! the short arc's, fitted on a short arc, extrapolates far off), while two nearby planes or
//! curves that one loose joint fit would hold within 1.5 σ fail both ways. Asking both models
//! leaves such arcs apart (SOD, mean over the `lce` grid's cells 23.76 against 23.74 %, the
//! `adelaide-homography` fold grid as-is 5.15 against 4.85 %). A
//! K the caller gave is kept. Motion subspaces never merge: an affine subspace of rank up to 4
//! holds two rigid motions whose frame-to-frame motion is small (a hand-held camera at 30 fps)
//! within the noise, though each motion's own subspace still tells its tracks apart.
//!
//! Groups whose model is degenerate (too few or collinear points) keep their learned points and
//! never take others'.

mod hypotheses;

use crate::data::{Kind, PointSet};
use crate::geometry::{self, Family, Model};
use crate::threads::Threads;

/// Most reassignment rounds.
pub const MAX_ITERATIONS: usize = 10;
/// In the rounds a curve takes the points within this many outlier thresholds τ of it; the
/// final assignment keeps τ.
pub const GROW_TAUS: f64 = 2.0;
/// Outlier threshold in units of the fit's noise level σ.
pub const OUTLIER_SIGMAS: f64 = 3.0;
/// A learned group whose own model explains less than this share of its points follows no
/// model: an outlier group.
pub const OUTLIER_GROUP_INLIERS: f64 = 0.5;
/// A learned group whose own noise level exceeds this many times the fit's σ is spread over the
/// plane (or the images), not along a model: an outlier group too.
pub const OUTLIER_GROUP_SIGMAS: f64 = 3.0;
/// Two structures whose joint fit is within this many σ merge.
pub const MERGE_SIGMAS: f64 = 1.5;
/// A learned group votes for the fit's noise level σ when it was fitted on at least this many
/// times the points that determine its model: on fewer, the fit takes up most of the residual
/// (a homography through 5 correspondences leaves a median residual near 0).
pub const NOISE_VOTE_POINTS: usize = 2;

/// What refinement may do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineParams {
    /// Whether points that fit no structure are labelled −1.
    pub outliers: bool,
    /// A fixed outlier threshold in the caller's units, instead of [`OUTLIER_SIGMAS`] × σ.
    pub threshold: Option<f64>,
    /// Whether models proposed beyond the learned groups may replace them
    /// ([`hypotheses`]; never for motion subspaces).
    pub hypotheses: bool,
    /// A point stays with its structure while its residual there is within this many σ, even
    /// where another structure is nearer; 0: every point goes to the nearest.
    pub stay: f64,
    /// A point leaves its structure only for one whose residual is smaller by more than this
    /// many σ (and within the outlier threshold there); 0: for any nearer one.
    pub margin: f64,
}

impl Default for RefineParams {
    fn default() -> Self {
        Self {
            outliers: true,
            threshold: None,
            hypotheses: true,
            stay: 0.0,
            margin: 0.0,
        }
    }
}

/// One structure of the answer.
#[derive(Debug, Clone, PartialEq)]
pub struct Structure {
    /// Its label in [`Refined::labels`].
    pub label: usize,
    pub model: Model,
    /// Points labelled with it.
    pub inliers: usize,
    /// RMS residual of those points, caller's units.
    pub rms: f64,
}

/// The refined answer.
#[derive(Debug, Clone, PartialEq)]
pub struct Refined {
    /// One per point: a structure's label, or −1 for an outlier.
    pub labels: Vec<i64>,
    /// One per label 0..k, in label order.
    pub structures: Vec<Structure>,
    /// The noise level σ the threshold was set from (caller's units).
    pub sigma: f64,
}

impl Refined {
    /// The structures that measure a noise: a model (not degenerate) on more points than
    /// determine it, with a finite RMS.
    fn measured(&self) -> impl Iterator<Item = &Structure> {
        self.structures.iter().filter(|s| {
            !s.model.is_degenerate() && s.inliers > s.model.min_points() && s.rms.is_finite()
        })
    }

    /// The answer's noise: the geometric mean of its measured structures' RMS, each corrected
    /// for the points its model spends (rms · √(n / (n − m)), m the points that determine it) and
    /// weighted by its points (the per-point log-likelihood scale of a Gaussian fit); INFINITY
    /// with no measured structure.
    pub fn noise(&self) -> f64 {
        let (mut log_sum, mut n) = (0.0, 0.0);
        for s in self.measured() {
            let (count, spent) = (s.inliers as f64, s.model.min_points() as f64);
            let rms = s.rms * (count / (count - spent)).sqrt();
            log_sum += count * rms.max(f64::MIN_POSITIVE).ln();
            n += count;
        }
        if n > 0.0 {
            (log_sum / n).exp()
        } else {
            f64::INFINITY
        }
    }

    fn outliers(&self) -> usize {
        self.labels.iter().filter(|&&l| l < 0).count()
    }
}

/// How much lower the k + 1 answer's noise must be for it to be kept over the k answer. A noise
/// floor shared by every structure (pixels rounded to whole values, a sparse set's fits)
/// pulls the ratio of two answers' noise towards 1: at 2 such sets kept K too low.
pub const SPLIT_NOISE_FACTOR: f64 = 1.7;
/// How much lower the noise of the answer K chosen would give must be for it to replace the
/// answer refined from the caller's k clusters ([`replaces_given`]).
pub const GIVEN_NOISE_FACTOR: f64 = 2.0;
/// The most outliers, as a share of the points, that the k + 1 answer may flag beyond the k
/// answer's.
pub const SPLIT_MORE_OUTLIERS: f64 = 0.05;

/// The most outliers, as a share of the points, that the answer K chosen would give may flag
/// beyond a given k's answer for [`replaces_given`].
pub const GIVEN_MORE_OUTLIERS: f64 = 0.2;

/// Whether `chosen` (refined from the clustering K chosen would give) replaces `given` (refined
/// from the caller's k clusters): exactly `k` structures, each measuring a noise, and
/// [`far_quieter`] by [`GIVEN_NOISE_FACTOR`] with at most [`GIVEN_MORE_OUTLIERS`] of the `n`
/// points more as outliers. Where the k clustering mixed the structures, its groups set a wide
/// noise level under which refinement cannot part them.
pub fn replaces_given(given: &Refined, chosen: &Refined, k: usize, n: usize) -> bool {
    chosen.structures.len() == k
        && chosen.measured().count() == k
        && far_quieter(
            given,
            chosen,
            GIVEN_NOISE_FACTOR,
            GIVEN_MORE_OUTLIERS * n as f64,
        )
}

/// Whether `wider` (refined from one more cluster) splits a structure that `answer` pooled: it
/// has at least as many structures that measure a noise, and is [`far_quieter`] by
/// [`SPLIT_NOISE_FACTOR`] with at most [`SPLIT_MORE_OUTLIERS`] of the `n` points more as
/// outliers. Two planes (or curves) held by one structure give it a noise level near their
/// separation; apart, each has the sensor's. As many structures count too: two structures that
/// each held parts of two crossing curves, against the two curves apart (the extra group taken
/// by a third structure the rounds then dropped or merged). A structure split in two halves keeps its noise, and an outlier group
/// split in two is dissolved again, so neither passes.
pub fn splits_pooled(answer: &Refined, wider: &Refined, n: usize) -> bool {
    wider.measured().count() >= answer.measured().count()
        && far_quieter(
            answer,
            wider,
            SPLIT_NOISE_FACTOR,
            SPLIT_MORE_OUTLIERS * n as f64,
        )
}

/// From `start` (a clustering's answer that split one with a group fewer), one group more at a
/// time while each answer [`splits_pooled`] the one before: a set of several pooled pairs (or
/// a structure that pooled three) is parted one split per step. `wider(&c)` clusters and
/// refines one group more than `c`, or gives `None` where the choice of K considered no more.
/// -> the last clustering that split, and its answer.
pub fn split_while_pooled<C, E>(
    start: (C, Refined),
    n: usize,
    mut wider: impl FnMut(&C) -> Result<Option<(C, Refined)>, E>,
) -> Result<(C, Refined), E> {
    let mut at = start;
    while let Some(next) = wider(&at.0)? {
        if !splits_pooled(&at.1, &next.1, n) {
            break;
        }
        at = next;
    }
    Ok(at)
}

/// Whether `other`'s noise ([`Refined::noise`]) is finite and at most 1 / `factor` of
/// `base`'s, while it flags at most `more_outliers` points more as outliers than `base`.
fn far_quieter(base: &Refined, other: &Refined, factor: f64, more_outliers: f64) -> bool {
    other.noise().is_finite()
        && other.noise() * factor <= base.noise()
        && other.outliers() as f64 <= base.outliers() as f64 + more_outliers
}

/// How well `structures` explain the rows of `points`: Σ_i min(d_i², τ²), d_i the row's
/// smallest residual among them (caller's units), the cost the hypotheses stage lowers swap by
/// swap on its seen rows ([`hypotheses`]). A row no structure explains within τ costs τ², as an
/// outlier does, so an answer cannot lower its cost by leaving rows out.
pub fn truncated_cost(points: &PointSet, structures: &[Structure], tau: f64) -> f64 {
    let prepared: Vec<_> = structures.iter().map(|s| s.model.prepared()).collect();
    (0..points.len())
        .map(|i| {
            let row = points.row(i);
            let d = prepared
                .iter()
                .map(|p| p.residual_capped(row, tau))
                .fold(tau, f64::min);
            d * d
        })
        .sum()
}

/// Of several answers refined from different clusterings of the same `points` (the first the
/// one a single start gives): the index of the first of least [`truncated_cost`] among those
/// with as many structures as the first, τ = `threshold` or [`OUTLIER_SIGMAS`] × the least σ
/// among them. 0 when `answers` holds one answer or none.
pub fn cheapest(points: &PointSet, answers: &[Refined], threshold: Option<f64>) -> usize {
    let Some(first) = answers.first() else {
        return 0;
    };
    let alike: Vec<usize> = (0..answers.len())
        .filter(|&i| answers[i].structures.len() == first.structures.len())
        .collect();
    if alike.len() < 2 {
        return 0;
    }
    let sigma = alike
        .iter()
        .map(|&i| answers[i].sigma)
        .fold(f64::INFINITY, f64::min);
    let tau = threshold
        .unwrap_or(OUTLIER_SIGMAS * sigma)
        .max(f64::MIN_POSITIVE);
    let mut best = (0, truncated_cost(points, &first.structures, tau));
    for &i in &alike[1..] {
        let cost = truncated_cost(points, &answers[i].structures, tau);
        if cost < best.1 {
            best = (i, cost);
        }
    }
    best.0
}

/// The family of models a model card's structures follow.
pub fn family_for(kind: Kind, name_hint: Option<Family>) -> Family {
    match (kind, name_hint) {
        (_, Some(f)) => f,
        (Kind::Points2d, None) => Family::Curves,
        (Kind::Correspondences, None) => Family::Fundamental,
        (Kind::Trajectories, None) => Family::Subspace,
    }
}

/// One group being refined.
struct Group {
    fit: geometry::Fit,
    /// The points `fit` was fitted on: a refit on the same points gives the same fit (fits are
    /// deterministic), so it is skipped.
    fitted_on: Vec<usize>,
    /// Whether `fit`'s type was chosen among the family's (else kept from an earlier fit).
    type_chosen: bool,
    /// Points it started with.
    start: usize,
    /// Degenerate: keeps its learned points, takes no others.
    frozen: bool,
}

impl Group {
    /// A learned group that follows no model: its robust fit explains less than
    /// [`OUTLIER_GROUP_INLIERS`] of its points, or its noise level exceeds
    /// [`OUTLIER_GROUP_SIGMAS`] × the fit's `sigma` (degenerate groups never do).
    fn follows_no_model(&self, sigma: f64) -> bool {
        let inliers = self.fit.inliers.iter().filter(|&&v| v).count();
        let explained = inliers as f64 >= OUTLIER_GROUP_INLIERS * self.start as f64
            && self.fit.sigma <= OUTLIER_GROUP_SIGMAS * sigma;
        !self.frozen && !explained
    }
}

/// `family`'s model fitted on the rows `idx` of `points`, its type chosen among the family's.
fn fit_rows(points: &PointSet, idx: &[usize], family: Family) -> geometry::Fit {
    let rows: Vec<&[f64]> = idx.iter().map(|&i| points.row(i)).collect();
    geometry::fit(family, &rows)
}

/// Each learned group of `labels` (in 0..k) fitted by `family`'s model on its points, side by
/// side on `threads`, and the fit's noise level σ ([`noise_level`]).
fn learned_groups(
    points: &PointSet,
    labels: &[usize],
    k: usize,
    family: Family,
    threads: &Threads,
) -> (Vec<Option<Group>>, f64) {
    let groups: Vec<Option<Group>> = threads.map_n(k, |j| {
        let idx: Vec<usize> = (0..points.len()).filter(|&i| labels[i] == j).collect();
        let fit = fit_rows(points, &idx, family);
        let frozen = matches!(fit.model, Model::Degenerate { .. });
        Some(Group {
            fit,
            start: idx.len(),
            fitted_on: idx,
            type_chosen: true,
            frozen,
        })
    });
    let sigma = noise_level(&groups);
    (groups, sigma)
}

/// The learned group that holds the outliers ([`outlier_group`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutlierGroup {
    /// Its label.
    pub group: usize,
    /// Whether it is the only group that follows no model (else the widest of several).
    pub sole: bool,
}

/// The learned group of `labels` (in 0..k) that holds the outliers, where a network trained
/// with the outliers as one more group formed it: the one group that follows no model of
/// `family` ([`Group::follows_no_model`]), or, when several do, the one whose noise level
/// exceeds [`OUTLIER_GROUP_SIGMAS`] × every other group's (a structure noisier than the median
/// also fails the noise test, but gross outliers spread tens of times wider). `None` for a
/// single group, when the groups' noise level is 0 (noise-free groups give no scale to judge a
/// spread by), when no group follows no model, or when several do and none stands out.
pub fn outlier_group(
    points: &PointSet,
    labels: &[usize],
    k: usize,
    family: Family,
    threads: &Threads,
) -> Option<OutlierGroup> {
    if k < 2 {
        return None;
    }
    threads.install(|| {
        let (groups, sigma) = learned_groups(points, labels, k, family, threads);
        if sigma <= 0.0 {
            return None;
        }
        let flagged: Vec<usize> = (0..k)
            .filter(|&j| {
                groups[j]
                    .as_ref()
                    .is_some_and(|g| g.follows_no_model(sigma))
            })
            .collect();
        match flagged[..] {
            [] => None,
            [group] => Some(OutlierGroup { group, sole: true }),
            _ => {
                let spread = |j: usize| {
                    groups[j]
                        .as_ref()
                        .filter(|g| !g.frozen && g.fit.sigma.is_finite())
                        .map_or(0.0, |g| g.fit.sigma)
                };
                let widest = flagged
                    .iter()
                    .copied()
                    .max_by(|&a, &b| spread(a).total_cmp(&spread(b)))?;
                let next = (0..k)
                    .filter(|&j| j != widest)
                    .map(spread)
                    .fold(0.0, f64::max);
                (spread(widest) > OUTLIER_GROUP_SIGMAS * next).then_some(OutlierGroup {
                    group: widest,
                    sole: false,
                })
            }
        }
    })
}

/// Refines a clustering of `points` (`labels` in 0..k, one per row) into structures of
/// `family`. `k_chosen`: `Some(k_max)` when K was chosen automatically among 1..=k_max, so
/// structures that are one may merge and structures may be added up to k_max in all; `None`
/// when the caller gave K, which merging never changes. `points` `[n, d]`, labels `[n]` ->
/// labels `[n]` (−1 for outliers) and one model per remaining label. Runs on the calling
/// thread; [`refine_on`] spreads it over a fit's threads.
pub fn refine(
    points: &PointSet,
    labels: &[usize],
    k: usize,
    family: Family,
    params: &RefineParams,
    k_chosen: Option<usize>,
) -> Refined {
    let threads = Threads::default();
    refine_on(points, labels, k, family, params, k_chosen, &threads)
}

/// [`refine`] on `threads`: each group's fit, each pair's joint fit and each point's
/// assignment are independent pieces, collected in order, so the answer is the same for any
/// thread count.
pub fn refine_on(
    points: &PointSet,
    labels: &[usize],
    k: usize,
    family: Family,
    params: &RefineParams,
    k_chosen: Option<usize>,
    threads: &Threads,
) -> Refined {
    threads.install(|| {
        let n = points.len();
        let keep_shrunk = k_chosen.is_none() && keeps_shrunk_structures(family);
        let members = |labels: &[i64], j: usize| -> Vec<usize> {
            (0..n).filter(|&i| labels[i] == j as i64).collect()
        };
        let fit_on = |idx: &[usize]| fit_rows(points, idx, family);
        let mut current: Vec<i64> = labels.iter().map(|&l| l as i64).collect();
        let (mut groups, sigma) = learned_groups(points, labels, k, family, threads);
        // Outlier groups are dissolved, when outliers may be answered.
        if params.outliers {
            for g in groups.iter_mut() {
                if g.as_ref().is_some_and(|g| g.follows_no_model(sigma)) {
                    *g = None;
                }
            }
        }
        let threshold = params
            .threshold
            .unwrap_or(OUTLIER_SIGMAS * sigma)
            .max(f64::MIN_POSITIVE);
        let stay = (params.stay * sigma).min(threshold);
        let margin = params.margin * sigma;
        if params.hypotheses && family != Family::Subspace {
            let live: Vec<Option<&Model>> = groups
                .iter()
                .map(|g| g.as_ref().filter(|g| !g.frozen).map(|g| &g.fit.model))
                .collect();
            let room = k_chosen.map_or(0, |k_max| {
                k_max.saturating_sub(live.iter().flatten().count())
            });
            for swap in hypotheses::swaps(points, &live, family, threshold, room, threads) {
                let group = Some(Group {
                    fit: swap.fit,
                    fitted_on: Vec::new(),
                    type_chosen: false,
                    start: (swap.share * n as f64).round() as usize,
                    frozen: false,
                });
                match swap.slot {
                    Some(j) => groups[j] = group,
                    None => groups.push(group),
                }
            }
        }
        // A refit keeps the model's type; a curve starts from its current model (its points
        // moved a little), any other model is fitted again.
        let refit_same_type = |idx: &[usize], model: &Model| {
            let rows: Vec<&[f64]> = idx.iter().map(|&i| points.row(i)).collect();
            geometry::refit_curve(model, &rows)
                .or_else(|| geometry::fit_type(model.type_name(), &rows))
                .unwrap_or_else(|| fit_on(idx))
        };
        // The rounds let a curve take the points within GROW_TAUS × τ of it: an arc fitted on
        // part of its curve extrapolates past τ at its ends, and would stop growing there.
        let round_threshold = match family {
            Family::Curves => GROW_TAUS * threshold,
            _ => threshold,
        };
        let reassign = |current: &[i64], groups: &[Option<Group>], outlier_radius: f64| {
            let radii = Radii {
                threshold: outlier_radius,
                stay,
                margin,
            };
            assign(points, current, groups, params.outliers, radii, threads)
        };
        let mut moved = false;
        for _ in 0..MAX_ITERATIONS {
            let next = reassign(&current, &groups, round_threshold);
            if next == current {
                break;
            }
            (current, moved) = (next, true);
            // The groups whose points changed, refitted side by side with their model's type.
            let mut changed: Vec<(usize, Vec<usize>)> = groups
                .iter()
                .enumerate()
                .filter_map(|(j, slot)| {
                    let g = slot.as_ref().filter(|g| !g.frozen)?;
                    let idx = members(&current, j);
                    (idx != g.fitted_on).then_some((j, idx))
                })
                .collect();
            let fits = threads.map(&mut changed, |(j, idx)| match &groups[*j] {
                Some(g) => refit_same_type(idx, &g.fit.model),
                None => fit_on(idx),
            });
            for ((j, idx), fit) in changed.into_iter().zip(fits) {
                let slot = &mut groups[j];
                let Some(g) = slot else { continue };
                let shrunk = 2 * idx.len() < g.start && !keep_shrunk;
                if shrunk || matches!(fit.model, Model::Degenerate { .. }) {
                    *slot = None;
                } else {
                    g.fit = fit;
                    g.fitted_on = idx;
                    // One candidate type: keeping it is choosing it.
                    g.type_chosen = family.candidates().len() == 1;
                }
            }
        }
        // Types, merges and the answer's models are settled on the points within τ.
        if moved && round_threshold != threshold {
            current = reassign(&current, &groups, threshold);
        }
        // The type of each structure, chosen again on its settled points (unmoved groups keep
        // their first fit, which was chosen on the same points). A group refitted on exactly
        // those points in the last round brings that fit as its own type's candidate.
        let mut settled: Vec<(usize, Vec<usize>)> = groups
            .iter()
            .enumerate()
            .filter_map(|(j, slot)| {
                let g = slot.as_ref().filter(|g| moved && !g.frozen)?;
                let idx = members(&current, j);
                (!g.type_chosen || idx != g.fitted_on).then_some((j, idx))
            })
            .collect();
        let fits = threads.map(&mut settled, |(j, idx)| match &groups[*j] {
            Some(g) if *idx == g.fitted_on => {
                let rows: Vec<&[f64]> = idx.iter().map(|&i| points.row(i)).collect();
                geometry::fit_knowing(family, &rows, &g.fit)
            }
            _ => fit_on(idx),
        });
        for ((j, idx), fit) in settled.into_iter().zip(fits) {
            let Some(g) = groups[j].as_mut() else {
                continue;
            };
            if !matches!(fit.model, Model::Degenerate { .. }) {
                g.fit = fit;
                g.fitted_on = idx;
                g.type_chosen = true;
            }
        }
        if k_chosen.is_some() && family != Family::Subspace {
            merge(
                points,
                &mut current,
                &mut groups,
                family,
                sigma,
                threshold,
                threads,
            );
        }
        // Points of dropped groups that the last round did not move.
        let current = reassign(&current, &groups, threshold);
        answer(points, current, groups, sigma)
    })
}

/// Whether a structure that shrinks below half its start is kept when the caller gave K: for
/// correspondences and curves (a plane or a curve that sheds the foreign points of its learned
/// group is still one the caller counted); motion subspaces drop it (measured: see the module
/// docs).
fn keeps_shrunk_structures(family: Family) -> bool {
    family != Family::Subspace
}

/// The fit's noise level: the median of the live, non-degenerate groups' own levels, over the
/// groups that measure one ([`NOISE_VOTE_POINTS`]; all of them when none does); 0 when none has
/// a level.
fn noise_level(groups: &[Option<Group>]) -> f64 {
    let levels = |min_points: usize| -> Vec<f64> {
        groups
            .iter()
            .flatten()
            .filter(|g| !g.frozen && g.fit.sigma.is_finite())
            .filter(|g| g.fitted_on.len() >= min_points * g.fit.model.min_points())
            .map(|g| g.fit.sigma)
            .collect()
    };
    let mut s = levels(NOISE_VOTE_POINTS);
    if s.is_empty() {
        s = levels(0);
    }
    if s.is_empty() {
        return 0.0;
    }
    s.sort_by(f64::total_cmp);
    s[(s.len() - 1) / 2]
}

/// The radii of one assignment, in the caller's units.
#[derive(Debug, Clone, Copy)]
struct Radii {
    /// Past it a point is an outlier (when outliers are allowed).
    threshold: f64,
    /// Within it a point keeps its structure.
    stay: f64,
    /// A point leaves its structure only for one nearer by more than this.
    margin: f64,
}

/// Every point to its nearest live structure (−1 past the threshold when outliers are
/// allowed), except that a point keeps its current live structure while its residual there is
/// within `stay`, or within `margin` of the nearest; points of frozen groups stay.
fn assign(
    points: &PointSet,
    current: &[i64],
    groups: &[Option<Group>],
    outliers: bool,
    radii: Radii,
    threads: &Threads,
) -> Vec<i64> {
    let live: Vec<(usize, geometry::Prepared)> = groups
        .iter()
        .enumerate()
        .filter_map(|(j, g)| {
            g.as_ref()
                .filter(|g| !g.frozen)
                .map(|g| (j, g.fit.model.prepared()))
        })
        .collect();
    let keeps = radii.stay > 0.0 || radii.margin > 0.0;
    threads.map_n(points.len(), |i| {
        let here = current[i];
        let frozen = here >= 0
            && groups
                .get(here as usize)
                .and_then(Option::as_ref)
                .is_some_and(|g| g.frozen);
        if frozen || live.is_empty() {
            return if frozen || !outliers { here } else { -1 };
        }
        let row = points.row(i);
        // The residual to the point's own live structure, where a radius may keep it there.
        let own = if keeps {
            live.iter()
                .find(|&&(j, _)| j as i64 == here)
                .map(|(_, m)| m.residual(row))
        } else {
            None
        };
        if own.is_some_and(|r| r <= radii.stay) {
            return here;
        }
        // The nearest structure; each residual capped at the nearest so far, which spares an
        // ellipse's foot-point search for the points far from it.
        let mut nearest = (live[0].0, f64::INFINITY);
        for (j, m) in &live {
            let r = m.residual_capped(row, nearest.1);
            if r < nearest.1 {
                nearest = (*j, r);
            }
        }
        if let Some(r) = own
            && radii.margin > 0.0
            && r - nearest.1 <= radii.margin
            && (!outliers || r <= radii.threshold)
        {
            return here;
        }
        let (j, r) = nearest;
        if outliers && (r.is_nan() || r > radii.threshold) {
            -1
        } else {
            j as i64
        }
    })
}

/// Merges pairs of live structures that one model fits together within [`MERGE_SIGMAS`] × σ,
/// best pair first, until no pair does. A pair is fitted jointly only where one of the two
/// structures' models already explains at least half of the other's points within
/// `threshold`: one model seen twice does (at least the model of its larger part), two
/// different ones do not, and the residuals cost far less than the fit.
fn merge(
    points: &PointSet,
    current: &mut [i64],
    groups: &mut [Option<Group>],
    family: Family,
    sigma: f64,
    threshold: f64,
    threads: &Threads,
) {
    if sigma <= 0.0 {
        return;
    }
    loop {
        let live: Vec<usize> = (0..groups.len())
            .filter(|&j| groups[j].as_ref().is_some_and(|g| !g.frozen))
            .collect();
        let mut pairs: Vec<(usize, usize)> = live
            .iter()
            .enumerate()
            .flat_map(|(a, &ja)| live[a + 1..].iter().map(move |&jb| (ja, jb)))
            .collect();
        // Whether the model of group `a` explains at least half of group `b`'s points.
        let explains = |a: usize, b: usize| {
            let Some(model) = groups[a].as_ref().map(|g| g.fit.model.prepared()) else {
                return false;
            };
            let (mut within, mut all) = (0usize, 0usize);
            for i in (0..points.len()).filter(|&i| current[i] == b as i64) {
                all += 1;
                within += usize::from(model.residual_capped(points.row(i), threshold) < threshold);
            }
            2 * within >= all
        };
        // Each pair's joint fit side by side; the best one that holds, first in pair order
        // among equals.
        let fits = threads.map(&mut pairs, |&mut (ja, jb)| {
            if !(explains(ja, jb) || explains(jb, ja)) {
                return None;
            }
            let rows: Vec<&[f64]> = (0..points.len())
                .filter(|&i| current[i] == ja as i64 || current[i] == jb as i64)
                .map(|i| points.row(i))
                .collect();
            let fit = geometry::fit(family, &rows);
            // On noise-free data every fit's σ is the floor set by its points' spread, and a
            // pair's points spread wider than either structure's: measure against that floor.
            let sigma = sigma.max(geometry::select::noise_floor(family, &rows));
            let ok = !matches!(fit.model, Model::Degenerate { .. })
                && fit.sigma <= MERGE_SIGMAS * sigma
                && fit.inliers.iter().filter(|&&v| v).count() * 10 >= rows.len() * 9;
            ok.then_some(fit)
        });
        let mut best: Option<(f64, usize, usize, geometry::Fit)> = None;
        for ((ja, jb), fit) in pairs.into_iter().zip(fits) {
            if let Some(fit) = fit
                && best.as_ref().is_none_or(|b| fit.sigma < b.0)
            {
                best = Some((fit.sigma, ja, jb, fit));
            }
        }
        let Some((_, ja, jb, fit)) = best else { return };
        for l in current.iter_mut() {
            if *l == jb as i64 {
                *l = ja as i64;
            }
        }
        let absorbed = groups[jb].take().map_or(0, |g| g.start);
        if let Some(g) = groups[ja].as_mut() {
            g.start += absorbed;
            g.fit = fit;
            g.fitted_on = (0..current.len())
                .filter(|&i| current[i] == ja as i64)
                .collect();
            g.type_chosen = true;
        }
    }
}

/// Compact labels 0..k over the groups that hold points, in their order, with each structure's
/// count and RMS residual.
fn answer(points: &PointSet, current: Vec<i64>, groups: Vec<Option<Group>>, sigma: f64) -> Refined {
    let mut renumber = vec![-1i64; groups.len()];
    let mut structures = Vec::new();
    for (j, g) in groups.into_iter().enumerate() {
        let Some(g) = g else { continue };
        let idx: Vec<usize> = (0..points.len())
            .filter(|&i| current[i] == j as i64)
            .collect();
        if idx.is_empty() {
            continue;
        }
        let label = structures.len();
        renumber[j] = label as i64;
        let rms = if g.frozen {
            0.0
        } else {
            let model = g.fit.model.prepared();
            let ss: f64 = idx
                .iter()
                .map(|&i| model.residual(points.row(i)).powi(2))
                .sum();
            (ss / idx.len() as f64).sqrt()
        };
        structures.push(Structure {
            label,
            model: g.fit.model,
            inliers: idx.len(),
            rms: if rms.is_finite() { rms } else { 0.0 },
        });
    }
    let labels = current
        .into_iter()
        .map(|l| if l < 0 { -1 } else { renumber[l as usize] })
        .collect();
    Refined {
        labels,
        structures,
        sigma,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Curves refined with the default parameters and K chosen (up to 8).
    fn curves_k_chosen(points: &PointSet, start: &[usize], k: usize) -> Refined {
        refine(
            points,
            start,
            k,
            Family::Curves,
            &RefineParams::default(),
            Some(8),
        )
    }

    /// Two noisy circles of radius 1 and 2 around (0, 0) and (10, 0), `m` points each, with
    /// deterministic noise of about `noise`.
    fn two_circles(m: usize, noise: f64) -> (PointSet, Vec<usize>) {
        let mut values = Vec::new();
        let mut labels = Vec::new();
        for i in 0..2 * m {
            let (c, r) = if i % 2 == 0 { (0.0, 1.0) } else { (10.0, 2.0) };
            let t = i as f64 * 0.7;
            let e = noise * (((i * 7919) % 101) as f64 / 50.0 - 1.0);
            values.extend([c + (r + e) * t.cos(), (r + e) * t.sin()]);
            labels.push(i % 2);
        }
        (
            PointSet::from_flat(Kind::Points2d, 2, values).unwrap(),
            labels,
        )
    }

    /// Circles of radius 1, 2 and 1.5 around (0, 0), (10, 0) and (0, 10), 60 points each spread
    /// evenly, interleaved (point i on circle i mod 3), with deterministic noise of about 0.01.
    fn three_circles() -> (PointSet, Vec<usize>) {
        let centres = [(0.0, 0.0, 1.0), (10.0, 0.0, 2.0), (0.0, 10.0, 1.5)];
        let (mut values, mut truth) = (Vec::new(), Vec::new());
        for i in 0..180 {
            let (cx, cy, r) = centres[i % 3];
            let t = (i / 3) as f64 * std::f64::consts::TAU / 60.0;
            let e = 0.01 * (((i * 7919) % 101) as f64 / 50.0 - 1.0);
            values.extend([cx + (r + e) * t.cos(), cy + (r + e) * t.sin()]);
            truth.push(i % 3);
        }
        (
            PointSet::from_flat(Kind::Points2d, 2, values).unwrap(),
            truth,
        )
    }

    /// A line, a circle and two ellipses, `m` points each, sent point by point in turn (point i
    /// on curve i mod 4), with deterministic noise of about 0.03 across each curve.
    fn four_curves_interleaved(m: usize) -> (PointSet, Vec<usize>) {
        let (mut values, mut truth) = (Vec::new(), Vec::new());
        for i in 0..4 * m {
            let t = (i / 4) as f64 * std::f64::consts::TAU / m as f64;
            let e = 0.03 * (((i * 7919) % 101) as f64 / 50.0 - 1.0);
            let (c, s) = (t.cos(), t.sin());
            values.extend(match i % 4 {
                0 => [-6.0 + 12.0 * (i / 4) as f64 / m as f64, -7.0 + e],
                1 => [4.0 + (2.0 + e) * c, 3.0 + (2.0 + e) * s],
                2 => [-4.0 + (3.0 + e) * c, 2.0 + (1.2 + e) * s],
                _ => [(1.5 + e) * c, -3.0 + (0.7 + e) * s],
            });
            truth.push(i % 4);
        }
        (
            PointSet::from_flat(Kind::Points2d, 2, values).unwrap(),
            truth,
        )
    }

    #[test]
    fn curves_sent_in_turn_are_all_seen_by_the_hypotheses() {
        // Past 500 points the hypotheses see one row of every run of n / 500: at 2000 points a
        // fixed stride of 4 would see the line alone, and its models took every structure's
        // place (k = 1 with three curves answered -1, K chosen).
        let (points, truth) = four_curves_interleaved(500);
        for k_chosen in [None, Some(8)] {
            let r = refine(
                &points,
                &truth,
                4,
                Family::Curves,
                &RefineParams::default(),
                k_chosen,
            );
            let outliers = r.labels.iter().filter(|&&l| l < 0).count();
            assert_eq!(r.structures.len(), 4, "{k_chosen:?}");
            assert!(outliers <= 60, "{k_chosen:?}: {outliers} outliers");
            let types: Vec<&str> = r.structures.iter().map(|s| s.model.type_name()).collect();
            assert_eq!(
                types,
                ["line", "circle", "ellipse", "ellipse"],
                "{k_chosen:?}"
            );
        }
    }

    /// [`two_circles`] (40 points each, noise 0.01) and two far points at (5, 8) and (-4, -6),
    /// started in groups 0 and 1: the points, the start labels and the circles' true labels.
    fn two_circles_and_two_far_points() -> (PointSet, Vec<usize>, Vec<usize>) {
        let (points, truth) = two_circles(40, 0.01);
        let mut values = points.values().to_vec();
        values.extend([5.0, 8.0, -4.0, -6.0]);
        let points = PointSet::from_flat(Kind::Points2d, 2, values).unwrap();
        let mut start = truth.clone();
        start.extend([0, 1]);
        (points, start, truth)
    }

    fn finite(refined: &Refined) -> bool {
        refined.sigma.is_finite()
            && refined.structures.iter().all(|s| {
                s.rms.is_finite()
                    && serde_json::to_string(&s.model)
                        .is_ok_and(|j| !j.contains("NaN") && !j.contains("null"))
            })
    }

    /// A circle of radius 2 around (0, 0), 120 points in order around it, noise about 0.01.
    fn one_circle() -> PointSet {
        let values = (0..120)
            .flat_map(|i| {
                let t = i as f64 * std::f64::consts::TAU / 120.0;
                let r = 2.0 + 0.01 * (((i * 7919) % 101) as f64 / 50.0 - 1.0);
                [r * t.cos(), r * t.sin()]
            })
            .collect();
        PointSet::from_flat(Kind::Points2d, 2, values).unwrap()
    }

    /// A unit circle as structure `label`, with `inliers` points at RMS `rms`.
    fn circle_structure(label: usize, inliers: usize, rms: f64) -> Structure {
        Structure {
            label,
            model: Model::Circle {
                cx: 0.0,
                cy: 0.0,
                r: 1.0,
            },
            inliers,
            rms,
        }
    }

    #[test]
    fn the_noise_of_an_answer_weighs_each_structure_by_its_points() {
        let structure = circle_structure;
        // Circles spend 3 points: RMS 1 on 12 points counts as 1 · √(12 / 9) = 2 / √3, and 4 on 51
        // as 4 · √(51 / 48).
        let answer = Refined {
            labels: vec![0; 63],
            structures: vec![structure(0, 12, 1.0), structure(1, 51, 4.0)],
            sigma: 1.0,
        };
        let (a, b) = (2.0 / 3f64.sqrt(), 4.0 * (51.0f64 / 48.0).sqrt());
        let want = ((12.0 * a.ln() + 51.0 * b.ln()) / 63.0).exp();
        assert!((answer.noise() - want).abs() < 1e-12, "{}", answer.noise());
        // A structure on just the points that determine it, a degenerate one, and one with no
        // finite RMS measure nothing.
        let mut extra = answer.clone();
        extra.structures.push(structure(2, 3, 0.0));
        extra.structures.push(Structure {
            model: Model::Degenerate {
                reason: "too few points".into(),
            },
            ..structure(3, 40, 0.0)
        });
        extra.structures.push(structure(4, 40, f64::INFINITY));
        assert_eq!(extra.noise(), answer.noise());
        assert!(
            !splits_pooled(&answer, &extra, 200),
            "as many measured structures, the same noise"
        );
        let none = Refined {
            labels: vec![-1; 3],
            structures: Vec::new(),
            sigma: 0.0,
        };
        assert_eq!(none.noise(), f64::INFINITY);
        assert!(
            !splits_pooled(&none, &none, 3),
            "nothing measured either way"
        );
    }

    #[test]
    fn splitting_goes_on_while_each_step_splits_and_stops_at_the_first_that_does_not() {
        let circle = circle_structure;
        // Answers of k = 1..=5 clusters, 120 points: each of k = 2 and 3 splits a pooled
        // structure (its noise falls by more than half); k = 4 halves one (same noise), and k = 5
        // would split again but is never reached.
        let answer = |k: usize, rms: f64| Refined {
            labels: (0..120).map(|i| (i % k) as i64).collect(),
            structures: (0..k).map(|l| circle(l, 120 / k, rms)).collect(),
            sigma: rms,
        };
        let noise = [8.0, 3.0, 1.0, 1.0, 0.1];
        let mut asked = Vec::new();
        let run = |last: usize, asked: &mut Vec<usize>| {
            split_while_pooled((1usize, answer(1, noise[0])), 120, |&k| {
                asked.push(k);
                Ok::<_, ()>((k < last).then(|| (k + 1, answer(k + 1, noise[k]))))
            })
            .unwrap()
        };
        let (k, got) = run(5, &mut asked);
        assert_eq!((k, got.structures.len(), got.sigma), (3, 3, 1.0));
        assert_eq!(
            asked,
            [1, 2, 3],
            "stops at the first step that does not split"
        );
        // Where the choice of K considered no more than 2, the k = 2 answer stands.
        asked.clear();
        let (k, _) = run(2, &mut asked);
        assert_eq!((k, asked.as_slice()), (2, &[1, 2][..]));
        // An error of a step is the caller's.
        let failed =
            split_while_pooled((1usize, answer(1, 8.0)), 120, |_| Err::<Option<_>, _>("no"));
        assert_eq!(failed.err(), Some("no"));
    }

    #[test]
    fn a_pooled_structure_is_split_and_a_halved_one_is_not() {
        let plain = RefineParams {
            hypotheses: false,
            ..RefineParams::default()
        };
        // Two circles held by one structure, and apart.
        let (points, truth) = two_circles(60, 0.01);
        let n = points.len();
        let pooled = refine(&points, &vec![0; n], 1, Family::Curves, &plain, Some(2));
        let apart = refine(&points, &truth, 2, Family::Curves, &plain, Some(2));
        assert_eq!((pooled.structures.len(), apart.structures.len()), (1, 2));
        assert!(apart.noise() * SPLIT_NOISE_FACTOR <= pooled.noise());
        assert!(splits_pooled(&pooled, &apart, n));
        assert!(
            !splits_pooled(&apart, &pooled, n),
            "fewer structures never split"
        );
        // Two structures that each held parts of both circles, against the circles apart: as
        // many structures, a fraction of the noise.
        let half = |label| Structure {
            label,
            inliers: n / 2,
            ..pooled.structures[0].clone()
        };
        let mixed = Refined {
            structures: vec![half(0), half(1)],
            ..pooled.clone()
        };
        assert!(splits_pooled(&mixed, &apart, n));
        assert!(!splits_pooled(&apart, &mixed, n));
        // Fewer structures are never a split, however much less noisy.
        let one_apart = Refined {
            structures: vec![apart.structures[0].clone()],
            ..apart.clone()
        };
        assert!(one_apart.noise() * SPLIT_NOISE_FACTOR <= mixed.noise());
        assert!(!splits_pooled(&mixed, &one_apart, n));
        // The same split flagging a tenth of the points as outliers besides is not kept.
        let mut flagging = apart.clone();
        for l in flagging.labels.iter_mut().step_by(10) {
            *l = -1;
        }
        assert!(!splits_pooled(&pooled, &flagging, n));
        // One circle in two halves keeps its noise: not a split.
        let circle = one_circle();
        let whole = refine(&circle, &vec![0; 120], 1, Family::Curves, &plain, None);
        let halves: Vec<usize> = (0..120).map(|i| usize::from(i >= 60)).collect();
        let halved = refine(&circle, &halves, 2, Family::Curves, &plain, None);
        assert_eq!(halved.structures.len(), 2);
        assert!(
            !splits_pooled(&whole, &halved, 120),
            "{} / {}",
            whole.noise(),
            halved.noise()
        );
    }

    #[test]
    fn misassigned_points_go_back_to_the_structure_they_fit() {
        let (points, truth) = two_circles(60, 0.01);
        // Ten points of the first circle start in the second's group.
        let mut start = truth.clone();
        for l in start.iter_mut().step_by(2).take(10) {
            *l = 1;
        }
        let r = curves_k_chosen(&points, &start, 2);
        let want: Vec<i64> = truth.iter().map(|&l| l as i64).collect();
        assert_eq!(r.labels, want);
        assert_eq!(r.structures.len(), 2);
        for (s, (cx, radius)) in r.structures.iter().zip([(0.0, 1.0), (10.0, 2.0)]) {
            match s.model {
                Model::Circle { cx: x, cy, r } => {
                    assert!((x - cx).abs() < 0.02 && cy.abs() < 0.02 && (r - radius).abs() < 0.02)
                }
                ref other => panic!("{other:?}"),
            }
            assert_eq!(s.inliers, 60);
        }
        assert!(finite(&r));
    }

    #[test]
    fn the_answer_is_the_same_on_any_number_of_threads() {
        let (points, _) = three_circles();
        // Mixed and split groups: rounds that move points, hypotheses and (K chosen) merging.
        let start: Vec<usize> = (0..180).map(|i| (i / 7 + i % 3) % 4).collect();
        for k_chosen in [Some(8), None] {
            for stay in [0.0, 1.0] {
                let run = |threads: &Threads| {
                    let params = RefineParams {
                        stay,
                        ..RefineParams::default()
                    };
                    refine_on(
                        &points,
                        &start,
                        4,
                        Family::Curves,
                        &params,
                        k_chosen,
                        threads,
                    )
                };
                let alone = run(&Threads::default());
                for count in [2, 3] {
                    let spread = run(&Threads::new(count).unwrap());
                    assert_eq!(spread, alone, "{count} threads, {k_chosen:?}, stay {stay}");
                }
                assert!(finite(&alone));
            }
        }
    }

    /// A line y = y0 as structure `label`.
    fn line_structure(label: usize, y0: f64) -> Structure {
        Structure {
            label,
            model: Model::Line {
                a: 0.0,
                b: 1.0,
                c: -y0,
            },
            inliers: 2,
            rms: 0.0,
        }
    }

    #[test]
    fn the_truncated_cost_counts_each_row_at_its_nearest_structure_up_to_tau() {
        // On y = 0; 1 off it; 3 off y = 10 (nearer than y = 0); 5 off both.
        let rows = vec![0.0, 0.0, 3.0, 1.0, 1.0, 7.0, 2.0, 5.0];
        let points = PointSet::from_flat(Kind::Points2d, 2, rows).unwrap();
        let lines = [line_structure(0, 0.0), line_structure(1, 10.0)];
        let cost = truncated_cost(&points, &lines, 2.0);
        assert!((cost - (0.0 + 1.0 + 4.0 + 4.0)).abs() < 1e-12, "{cost}");
        let cost = truncated_cost(&points, &lines, 4.0);
        assert!((cost - (0.0 + 1.0 + 9.0 + 16.0)).abs() < 1e-12, "{cost}");
        // No structure, or a degenerate one: every row costs tau^2, never NaN.
        assert_eq!(truncated_cost(&points, &[], 2.0), 16.0);
        let degenerate = Structure {
            model: Model::Degenerate {
                reason: "too few points".into(),
            },
            ..line_structure(0, 0.0)
        };
        assert_eq!(truncated_cost(&points, &[degenerate], 2.0), 16.0);
    }

    #[test]
    fn the_cheapest_answer_is_the_first_of_least_cost_among_those_with_as_many_structures() {
        // Rows on y = 0 and y = 10.
        let rows: Vec<f64> = (0..20)
            .flat_map(|i| [i as f64, if i % 2 == 0 { 0.0 } else { 10.0 }])
            .collect();
        let points = PointSet::from_flat(Kind::Points2d, 2, rows).unwrap();
        let answer = |lines: &[f64], sigma: f64| Refined {
            labels: vec![0; 20],
            structures: lines
                .iter()
                .enumerate()
                .map(|(j, &y)| line_structure(j, y))
                .collect(),
            sigma,
        };
        let right = answer(&[0.0, 10.0], 0.1);
        let wrong = answer(&[0.0, 5.0], 0.1);
        let one = answer(&[0.0], 0.1);
        assert_eq!(cheapest(&points, &[wrong.clone(), right.clone()], None), 1);
        assert_eq!(cheapest(&points, &[right.clone(), wrong.clone()], None), 0);
        // Equal costs keep the first.
        assert_eq!(cheapest(&points, &[right.clone(), right.clone()], None), 0);
        // Only answers with as many structures as the first compete.
        assert_eq!(cheapest(&points, &[one.clone(), right.clone()], None), 0);
        assert_eq!(
            cheapest(&points, &[wrong.clone(), one, right.clone()], None),
            2
        );
        // The caller's threshold sets tau. One line exact and one far off, against two lines
        // each 0.5 off their rows: at tau = 0.1 the half explained exactly costs less
        // (10 x 0.01 against 20 x 0.01), at tau = 10 the whole explained loosely does.
        let half = answer(&[0.0, 100.0], 0.1);
        let loose = answer(&[0.5, 9.5], 0.1);
        assert_eq!(
            cheapest(&points, &[loose.clone(), half.clone()], Some(0.1)),
            1
        );
        assert_eq!(cheapest(&points, &[half, loose], Some(10.0)), 1);
        assert_eq!(cheapest(&points, &[], None), 0);
        assert_eq!(cheapest(&points, &[wrong], None), 0);
    }

    /// A line y = y0 as a live group.
    fn line_group(y0: f64) -> Option<Group> {
        Some(Group {
            fit: geometry::Fit {
                model: Model::Line {
                    a: 0.0,
                    b: 1.0,
                    c: -y0,
                },
                rms: 0.0,
                inliers: Vec::new(),
                sigma: 0.1,
            },
            fitted_on: Vec::new(),
            type_chosen: true,
            start: 1,
            frozen: false,
        })
    }

    #[test]
    fn groups_fitted_on_too_few_points_do_not_vote_for_the_noise_level() {
        let group = |sigma: f64, points: usize| {
            let mut g = line_group(0.0);
            if let Some(g) = g.as_mut() {
                g.fit.sigma = sigma;
                g.fitted_on = (0..points).collect();
            }
            g
        };
        // A line is determined by 2 points: groups of 3 do not vote while one of 4 or more does.
        let groups = [group(1e-3, 3), group(0.5, 40), group(2e-3, 3)];
        assert_eq!(noise_level(&groups), 0.5);
        let groups = [
            group(1e-3, 3),
            group(0.5, 4),
            group(0.7, 40),
            group(2e-3, 3),
        ];
        assert_eq!(noise_level(&groups), 0.5);
        // None measures one: all vote, as before.
        let groups = [group(1e-3, 3), group(0.5, 2), group(2e-3, 3)];
        assert_eq!(noise_level(&groups), 2e-3);
        assert_eq!(noise_level(&[None, None]), 0.0);
    }

    /// An answer of unit circles of 50 inliers each with the given RMS, and `outliers` −1 labels.
    fn circles_answer(rms: &[f64], outliers: usize) -> Refined {
        let structure = |rms: f64| Structure {
            label: 0,
            model: Model::Circle {
                cx: 0.0,
                cy: 0.0,
                r: 1.0,
            },
            inliers: 50,
            rms,
        };
        Refined {
            labels: vec![-1; outliers],
            structures: rms.iter().map(|&r| structure(r)).collect(),
            sigma: 1.0,
        }
    }

    #[test]
    fn the_answer_k_chosen_would_give_replaces_a_given_k_only_with_k_far_quieter_structures() {
        let answer = circles_answer;
        let given = answer(&[10.0, 12.0, 9.0], 3);
        // k structures at a tenth of the noise, a few more outliers: replaces.
        assert!(replaces_given(
            &given,
            &answer(&[1.0, 1.2, 0.9], 30),
            3,
            200
        ));
        // Not k structures.
        assert!(!replaces_given(&given, &answer(&[1.0, 1.2], 30), 3, 200));
        assert!(!replaces_given(
            &given,
            &answer(&[1.0, 1.2, 0.9, 1.0], 30),
            3,
            200
        ));
        // Not half the noise.
        assert!(!replaces_given(
            &given,
            &answer(&[6.0, 6.0, 6.0], 3),
            3,
            200
        ));
        // Quiet by answering more than a fifth of the points -1.
        assert!(!replaces_given(
            &given,
            &answer(&[1.0, 1.2, 0.9], 3 + 41),
            3,
            200
        ));
        // A structure that measures no noise does not count.
        let mut bare = answer(&[1.0, 1.2, 0.9], 3);
        bare.structures[2].inliers = 3;
        assert!(!replaces_given(&given, &bare, 3, 200));
    }

    #[test]
    fn a_split_asks_less_quiet_than_a_replaced_k() {
        let answer = |rms: &[f64]| circles_answer(rms, 2);
        let base = answer(&[9.0, 9.0]);
        // 1.8 times quieter: a split (factor 1.7), not a replacement of a given k (factor 2).
        let quieter = answer(&[5.0, 5.0]);
        assert!(splits_pooled(&base, &quieter, 200));
        assert!(!replaces_given(&base, &quieter, 2, 200));
        // 1.6 times quieter: neither.
        let barely = answer(&[9.0 / 1.6, 9.0 / 1.6]);
        assert!(!splits_pooled(&base, &barely, 200));
        // 2.25 times quieter: both.
        let far = answer(&[4.0, 4.0]);
        assert!(splits_pooled(&base, &far, 200));
        assert!(replaces_given(&base, &far, 2, 200));
    }

    #[test]
    fn a_point_within_the_stay_radius_keeps_its_structure() {
        // Lines y = 0 and y = 1; every point starts with the line y = 1.
        let groups = [line_group(0.0), line_group(1.0)];
        let points =
            PointSet::from_flat(Kind::Points2d, 2, vec![0.0, 0.45, 0.0, 0.2, 0.0, -3.0]).unwrap();
        let current = [1, 1, 1];
        let threads = Threads::default();
        let radii = |stay: f64| Radii {
            threshold: 2.5,
            stay,
            margin: 0.0,
        };
        let with = |stay: f64| assign(&points, &current, &groups, true, radii(stay), &threads);
        // Nearest: the first two go to y = 0; the third is past the threshold from both lines.
        assert_eq!(with(0.0), [0, 0, -1]);
        // Within 0.6 of y = 1 the first stays (0.55 away), the second (0.8) does not.
        assert_eq!(with(0.6), [1, 0, -1]);
        assert_eq!(with(0.5), [0, 0, -1]);

        // An outlier (-1), a point of a dropped group (slot 2, None) and a point of a frozen
        // group (slot 3) at y = 0.45: the first two go to the nearest line whatever the radius,
        // the frozen group keeps its point.
        let mut frozen = line_group(0.45);
        frozen.as_mut().unwrap().frozen = true;
        let groups = [line_group(0.0), line_group(1.0), None, frozen];
        let points = PointSet::from_flat(Kind::Points2d, 2, [0.0, 0.45].repeat(3)).unwrap();
        for stay in [0.0, 0.6, 10.0] {
            let got = assign(&points, &[-1, 2, 3], &groups, true, radii(stay), &threads);
            assert_eq!(got, [0, 0, 3], "stay {stay}");
        }
    }

    #[test]
    fn a_point_leaves_its_structure_only_for_one_nearer_by_more_than_the_margin() {
        // Lines y = 0 and y = 1; every point starts with y = 1. At y = 0.45 the point is 0.55
        // from its line and 0.45 from the other (0.1 nearer); at y = 0.2, 0.6 nearer.
        let groups = [line_group(0.0), line_group(1.0)];
        let points = PointSet::from_flat(Kind::Points2d, 2, vec![0.0, 0.45, 0.0, 0.2]).unwrap();
        let threads = Threads::default();
        let with = |margin: f64, outliers: bool, threshold: f64| {
            let radii = Radii {
                threshold,
                stay: 0.0,
                margin,
            };
            assign(&points, &[1, 1], &groups, outliers, radii, &threads)
        };
        assert_eq!(with(0.0, true, 2.5), [0, 0]);
        assert_eq!(with(0.05, true, 2.5), [0, 0]);
        assert_eq!(with(0.2, true, 2.5), [1, 0]);
        assert_eq!(with(1.0, true, 2.5), [1, 1]);
        // The margin keeps no point past the outlier threshold: the first (0.55 from its line)
        // goes to the nearer line within it, the second to the nearer line too.
        assert_eq!(with(1.0, true, 0.5), [0, 0]);
        // Without outliers the threshold does not bound it.
        assert_eq!(with(1.0, false, 0.5), [1, 1]);
    }

    #[test]
    fn the_stay_radius_never_keeps_a_point_past_the_outlier_threshold() {
        // A caller's threshold below the stay radius: the far points are still outliers.
        let (points, start, truth) = two_circles_and_two_far_points();
        let params = RefineParams {
            threshold: Some(0.5),
            stay: 1e6,
            ..RefineParams::default()
        };
        let r = refine(&points, &start, 2, Family::Curves, &params, None);
        assert_eq!(&r.labels[80..], &[-1, -1]);
        let want: Vec<i64> = truth.iter().map(|&l| l as i64).collect();
        assert_eq!(&r.labels[..80], &want[..]);
    }

    #[test]
    fn a_learned_group_scattered_over_the_plane_is_the_outlier_group() {
        let (circles, labels) = two_circles(40, 0.02);
        let mut values: Vec<f64> = (0..circles.len())
            .flat_map(|i| circles.row(i).to_vec())
            .collect();
        let mut labels = labels;
        // 30 points scattered over the plane around the circles, as a third learned group.
        values.extend(scatter(30, 0));
        labels.extend([2; 30]);
        let points = PointSet::from_flat(Kind::Points2d, 2, values).unwrap();
        let threads = Threads::default();
        let found = outlier_group(&points, &labels, 3, Family::Curves, &threads);
        assert_eq!(
            found,
            Some(OutlierGroup {
                group: 2,
                sole: true
            })
        );
        // The two circles alone: no group is.
        let clean = outlier_group(&circles, &labels[..80], 2, Family::Curves, &threads);
        assert_eq!(clean, None);
    }

    /// `m` points scattered over the box x in [-1, 12], y in [-2, 10], deterministically.
    fn scatter(m: u64, salt: u64) -> Vec<f64> {
        (0..m)
            .flat_map(|i| {
                let u = ((i + salt).wrapping_mul(2_654_435_761) % 1000) as f64 / 1000.0;
                let v = ((i + salt).wrapping_mul(40_503) % 997) as f64 / 997.0;
                [-1.0 + 13.0 * u, -2.0 + 12.0 * v]
            })
            .collect()
    }

    #[test]
    fn of_several_groups_following_no_model_the_widest_by_far_holds_the_outliers() {
        // Two clean circles, a third circle five times noisier than they are (it fails the
        // noise test too), and 30 scattered points.
        let (circles, mut labels) = two_circles(40, 0.02);
        let mut values = circles.values().to_vec();
        for i in 0..40 {
            let t = i as f64 * 0.7;
            let e = 0.1 * (((i * 7919) % 101) as f64 / 50.0 - 1.0);
            values.extend([5.0 + (1.5 + e) * t.cos(), 8.0 + (1.5 + e) * t.sin()]);
            labels.push(2);
        }
        let with_noisy = values.clone();
        values.extend(scatter(30, 0));
        labels.extend([3; 30]);
        let threads = Threads::default();
        let points = PointSet::from_flat(Kind::Points2d, 2, values).unwrap();
        let found = outlier_group(&points, &labels, 4, Family::Curves, &threads);
        assert_eq!(
            found,
            Some(OutlierGroup {
                group: 3,
                sole: false
            })
        );
        // Two scattered groups of the same spread: neither stands out.
        let mut two = with_noisy;
        two.extend(scatter(30, 0));
        two.extend(scatter(30, 500));
        let mut two_labels = labels[..120].to_vec();
        two_labels.extend([3; 30]);
        two_labels.extend([4; 30]);
        let points = PointSet::from_flat(Kind::Points2d, 2, two).unwrap();
        assert_eq!(
            outlier_group(&points, &two_labels, 5, Family::Curves, &threads),
            None
        );
    }

    #[test]
    fn far_points_are_outliers_unless_outliers_are_off() {
        let (points, start, _) = two_circles_and_two_far_points();
        let r = curves_k_chosen(&points, &start, 2);
        assert_eq!(&r.labels[80..], &[-1, -1]);
        assert!(r.labels[..80].iter().all(|&l| l >= 0));
        let kept = RefineParams {
            outliers: false,
            threshold: None,
            ..RefineParams::default()
        };
        let r = refine(&points, &start, 2, Family::Curves, &kept, Some(8));
        assert!(r.labels.iter().all(|&l| l >= 0));
        // A caller's threshold in its own units: 100 keeps both far points.
        let wide = RefineParams {
            outliers: true,
            threshold: Some(100.0),
            ..RefineParams::default()
        };
        let r = refine(&points, &start, 2, Family::Curves, &wide, Some(8));
        assert!(r.labels.iter().all(|&l| l >= 0));
    }

    #[test]
    fn a_structure_split_in_two_and_two_mixed_in_one_are_repaired_by_hypotheses() {
        let (points, truth) = three_circles();
        // The first circle split over groups 0 and 1; the other two mixed in group 2. No model
        // of a learned group is the third circle, and reassignment alone cannot make one.
        let start: Vec<usize> = (0..180)
            .map(|i| match i % 3 {
                0 => (i / 3) % 2,
                _ => 2,
            })
            .collect();
        let params = RefineParams {
            outliers: false,
            ..RefineParams::default()
        };
        let without = RefineParams {
            hypotheses: false,
            ..params
        };
        let r = refine(&points, &start, 3, Family::Curves, &without, None);
        let agree = |labels: &[i64]| {
            // Agreement with the truth under the best matching of labels (3! of them).
            let perms = [
                [0, 1, 2],
                [0, 2, 1],
                [1, 0, 2],
                [1, 2, 0],
                [2, 0, 1],
                [2, 1, 0],
            ];
            perms
                .iter()
                .map(|p| (0..180).filter(|&i| labels[i] == p[truth[i]]).count())
                .max()
                .unwrap_or(0)
        };
        assert!(agree(&r.labels) < 150, "the case needs hypotheses");
        let r = refine(&points, &start, 3, Family::Curves, &params, None);
        assert_eq!(agree(&r.labels), 180, "{:?}", r.labels);
        assert_eq!(r.structures.len(), 3);
        for s in &r.structures {
            assert!(matches!(s.model, Model::Circle { .. }), "{:?}", s.model);
            assert!(s.rms < 0.02, "{}", s.rms);
        }
        assert!(finite(&r));
    }

    #[test]
    fn a_structure_no_group_holds_is_added_when_k_was_chosen() {
        // The learned clustering found two groups, the third circle split between them.
        let (points, truth) = three_circles();
        let start: Vec<usize> = (0..180)
            .map(|i| if truth[i] == 2 { (i / 3) % 2 } else { truth[i] })
            .collect();
        let params = RefineParams::default();
        let chosen = refine(&points, &start, 2, Family::Curves, &params, Some(8));
        assert_eq!(chosen.structures.len(), 3, "{:?}", chosen.structures);
        for s in &chosen.structures {
            assert!(matches!(s.model, Model::Circle { .. }), "{:?}", s.model);
            assert_eq!(s.inliers, 60);
        }
        for a in 0..180 {
            for b in 0..180 {
                assert_eq!(truth[a] == truth[b], chosen.labels[a] == chosen.labels[b]);
            }
        }
        // A K the caller gave stays, and a chosen K stays within the K the choice considered.
        let given = refine(&points, &start, 2, Family::Curves, &params, None);
        assert_eq!(given.structures.len(), 2);
        let capped = refine(&points, &start, 2, Family::Curves, &params, Some(2));
        assert_eq!(capped.structures.len(), 2);
        assert!(finite(&chosen) && finite(&given) && finite(&capped));
    }

    #[test]
    fn one_structure_split_in_two_is_merged() {
        let (points, truth) = two_circles(40, 0.01);
        // The first circle's points in two groups (0 and 2).
        let start: Vec<usize> = truth
            .iter()
            .enumerate()
            .map(|(i, &l)| if l == 0 && i % 4 == 0 { 2 } else { l })
            .collect();
        let r = curves_k_chosen(&points, &start, 3);
        assert_eq!(r.structures.len(), 2);
        let want: Vec<i64> = truth.iter().map(|&l| l as i64).collect();
        assert_eq!(r.labels, want);
    }

    #[test]
    fn a_noise_free_curve_split_into_arcs_is_merged() {
        // Exact points on one circle, in four arcs of 40 points: each arc's fit, and the fit of
        // two arcs together, leave residuals far below every noise floor, so the pair must merge
        // although the floor of σ grows with the spread of the points fitted.
        let values: Vec<f64> = (0..160)
            .flat_map(|i| {
                let t = std::f64::consts::TAU * i as f64 / 160.0;
                [400.0 + 80.0 * t.cos(), 500.0 + 80.0 * t.sin()]
            })
            .collect();
        let points = PointSet::from_flat(Kind::Points2d, 2, values).unwrap();
        let start: Vec<usize> = (0..160).map(|i| i / 40).collect();
        let r = curves_k_chosen(&points, &start, 4);
        assert_eq!(r.structures.len(), 1, "{:?}", r.structures);
        assert!(r.labels.iter().all(|&l| l == 0));
        assert!(finite(&r));
    }

    #[test]
    fn an_ellipse_split_into_a_long_and_a_short_arc_is_merged() {
        // An ellipse (semi-axes 150 and 60 px, tilted) with 1 px noise, its points in a 300 degree
        // arc and a 60 degree arc. The short arc's own ellipse extrapolates far from the long
        // arc; the long arc's ellipse explains the short arc's points.
        let mut s = 7u64;
        let mut noise = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s % 2001) as f64 / 1000.0 - 1.0
        };
        let (cx, cy, a, b, th) = (320.0, 240.0, 150.0, 60.0, 0.4f64);
        let mut values = Vec::new();
        let mut start = Vec::new();
        for i in 0..180 {
            let t = std::f64::consts::TAU * i as f64 / 180.0;
            let (u, v) = (a * t.cos(), b * t.sin());
            values.push(cx + u * th.cos() - v * th.sin() + noise());
            values.push(cy + u * th.sin() + v * th.cos() + noise());
            start.push(usize::from(i < 30));
        }
        let points = PointSet::from_flat(Kind::Points2d, 2, values).unwrap();
        let r = curves_k_chosen(&points, &start, 2);
        assert_eq!(r.structures.len(), 1, "{:?}", r.structures);
        assert!(r.labels.iter().all(|&l| l == 0));
    }

    #[test]
    fn a_caller_k_keeps_a_curve_that_shrank() {
        // A third group holding a seeded 30 % of both circles' points (and 10 % of the points in
        // the other circle's group): it loses more than half its points, and stays, a structure
        // the caller counted (dropping it left 2).
        let (points, truth) = two_circles(40, 0.01);
        let mut s = 10u64.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let start: Vec<usize> = truth
            .iter()
            .map(|&l| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                match s % 10 {
                    0..=2 => 2,
                    3 => 1 - l,
                    _ => l,
                }
            })
            .collect();
        let params = RefineParams {
            hypotheses: false,
            ..RefineParams::default()
        };
        let r = refine(&points, &start, 3, Family::Curves, &params, None);
        assert_eq!(r.structures.len(), 3, "{:?}", r.structures);
        assert!(finite(&r));
    }

    #[test]
    fn motion_subspaces_that_one_subspace_holds_are_not_merged() {
        // Two motions over 4 frames (rows of 8), each a rank-2 affine subspace (directions 0
        // and 1, directions 0 and 2), both inside one rank-3 affine subspace: one model fits
        // their union within the noise.
        let basis = [
            [1.0, 0.0, 0.9, 0.1, 0.8, 0.2, 0.7, 0.3],
            [0.0, 1.0, 0.1, 0.9, 0.2, 0.8, 0.3, 0.7],
            [0.0, 1.0, 0.0, 1.1, 0.1, 1.2, 0.1, 1.3],
        ];
        let (mut values, mut labels) = (Vec::new(), Vec::new());
        for i in 0..120 {
            let g = i % 2;
            let (u, v) = ((5 + (i * 37) % 97) as f64, (5 + (i * 53) % 89) as f64);
            for (d, (b0, bg)) in basis[0].iter().zip(&basis[1 + g]).enumerate() {
                let hash = ((i * 8 + d) as u64)
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407)
                    >> 33;
                let e = 0.05 * ((hash % 1000) as f64 / 500.0 - 1.0);
                values.push(100.0 + u * b0 + v * bg + e);
            }
            labels.push(g);
        }
        let points = PointSet::from_flat(Kind::Trajectories, 8, values).unwrap();
        let rows: Vec<&[f64]> = (0..points.len()).map(|i| points.row(i)).collect();
        let union = geometry::fit(Family::Subspace, &rows);
        assert!(union.inliers.iter().all(|&v| v), "one subspace holds both");
        let params = RefineParams {
            outliers: false,
            threshold: None,
            ..RefineParams::default()
        };
        let r = refine(&points, &labels, 2, Family::Subspace, &params, Some(8));
        assert_eq!(r.structures.len(), 2);
        let want: Vec<i64> = labels.iter().map(|&l| l as i64).collect();
        assert_eq!(r.labels, want);
    }

    /// Kind, row width, values, labels, K, family.
    type Case = (Kind, usize, Vec<f64>, Vec<usize>, usize, Family);

    #[test]
    fn degenerate_and_tiny_groups_never_give_nan_or_panic() {
        let cases: Vec<Case> = vec![
            // Two points, two groups.
            (
                Kind::Points2d,
                2,
                vec![0.0, 0.0, 1.0, 1.0],
                vec![0, 1],
                2,
                Family::Curves,
            ),
            // Coincident points.
            (
                Kind::Points2d,
                2,
                vec![3.0; 20],
                vec![0; 10],
                1,
                Family::Curves,
            ),
            // Collinear correspondences, too few for F.
            (
                Kind::Correspondences,
                4,
                (0..5)
                    .flat_map(|i| [i as f64, 0.0, i as f64 + 1.0, 0.0])
                    .collect(),
                vec![0, 0, 0, 1, 1],
                2,
                Family::Fundamental,
            ),
            (
                Kind::Correspondences,
                4,
                (0..6)
                    .flat_map(|i| [i as f64, 2.0 * i as f64, 1.0, 1.0])
                    .collect(),
                vec![0; 6],
                1,
                Family::Homography,
            ),
            // Identical tracks.
            (
                Kind::Trajectories,
                6,
                vec![1.0; 30],
                vec![0, 0, 1, 1, 1],
                2,
                Family::Subspace,
            ),
            // Huge values.
            (
                Kind::Points2d,
                2,
                vec![1e9, -1e9, -1e9, 1e9, 1e9, 1e9, 0.0, 0.0],
                vec![0, 0, 0, 0],
                1,
                Family::Curves,
            ),
        ];
        for (kind, dim, values, labels, k, family) in cases {
            let points = PointSet::from_flat(kind, dim, values).unwrap();
            for outliers in [true, false] {
                let params = RefineParams {
                    outliers,
                    ..RefineParams::default()
                };
                let r = refine(&points, &labels, k, family, &params, Some(8));
                assert_eq!(r.labels.len(), points.len(), "{kind} {family:?}");
                assert!(finite(&r), "{kind} {family:?}: {r:?}");
                let k = r.structures.len() as i64;
                assert!(r.labels.iter().all(|&l| (-1..k).contains(&l)));
                for (label, s) in r.structures.iter().enumerate() {
                    assert_eq!(s.label, label);
                    assert!(s.inliers > 0);
                }
            }
        }
    }
}
