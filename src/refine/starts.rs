//! Other starts for motion subspaces: k-subspaces from seeds drawn over the tracks.
//!
//! Reassignment to a fixed point is a local search (k-subspaces): from the learned groups it
//! settles in the nearest minimum of the subspace cost. Where the network merged a small
//! object's tracks into another motion, that minimum has one subspace too few, since an affine
//! subspace of rank 4 holds a second motion that moves little within the noise.
//!
//! **Seeds.** The tracks of one object lie near one another in the 2F-dimensional track space,
//! so the [`NEIGHBOURHOOD`] tracks nearest a track (Euclidean, whole rows) mostly follow one
//! motion. A start draws k seed tracks as k-means++ does (Arthur and Vassilvitskii 2007): the
//! first uniformly, each next one with probability ∝ its squared distance to the nearest
//! subspace seeded so far; a seed's subspace is the plain rank-3 fit to its neighbourhood
//! ([`geometry::fit_plain`]).
//!
//! **Descent.** Every track goes to its nearest seed subspace, then plain rank-3 refits and
//! reassignment alternate for at most [`ROUNDS`] rounds. Seeds and descent see at most
//! [`MAX_ROWS`] tracks (evenly in input order). A start's cost is the truncated quadratic cost
//! C = Σᵢ min(min_j r_j(xᵢ)², τ²) of its subspaces over those tracks; the start of least cost is
//! returned, as labels of every track, for the full refinement to settle.

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

use std::borrow::Borrow;

use crate::data::PointSet;
use crate::geometry::{self, Model};

/// Tracks per seed neighbourhood (the seed included).
pub const NEIGHBOURHOOD: usize = 8;
/// Reassignment rounds of a start's descent, at most.
pub const ROUNDS: usize = 10;
/// Tracks the seeds and the descent see, at most.
pub const MAX_ROWS: usize = 400;

/// The least-cost labelling of `points` (tracks, `[n, 2F]`) into `k` subspaces among `count`
/// seeded starts, each descended by plain k-subspaces; `threshold` τ truncates the cost.
/// `None` also when fewer than k × [`NEIGHBOURHOOD`] tracks are seen, or τ is not positive.
/// `points` `[n, 2F]` -> labels `[n]` in 0..k, or `None` when no start gives k subspaces.
pub fn best_start(points: &PointSet, k: usize, count: usize, threshold: f64) -> Option<Vec<usize>> {
    let n = points.len();
    let seen: Vec<usize> = if n <= MAX_ROWS {
        (0..n).collect()
    } else {
        (0..MAX_ROWS).map(|i| i * n / MAX_ROWS).collect()
    };
    if k < 2 || seen.len() < k * NEIGHBOURHOOD || !(threshold.is_finite() && threshold > 0.0) {
        return None;
    }
    let rows: Vec<&[f64]> = seen.iter().map(|&i| points.row(i)).collect();
    let mut best: Option<(f64, Vec<Model>)> = None;
    for s in 0..count {
        let mut rng = ChaCha8Rng::seed_from_u64(0x5eed_0000 + s as u64);
        let Some(models) = seeded(&rows, k, &mut rng).map(|m| descend(&rows, m)) else {
            continue;
        };
        if models.len() < k {
            continue;
        }
        let c = cost(&rows, &models, threshold);
        if best.as_ref().is_none_or(|b| c < b.0) {
            best = Some((c, models));
        }
    }
    let (_, models) = best?;
    Some((0..n).map(|i| nearest(&models, points.row(i)).0).collect())
}

/// k seed subspaces, drawn k-means++-style; `None` when a neighbourhood gives no subspace.
/// rows `[n, 2F]` -> k models.
fn seeded(rows: &[&[f64]], k: usize, rng: &mut ChaCha8Rng) -> Option<Vec<Model>> {
    let n = rows.len();
    let mut models: Vec<Model> = Vec::with_capacity(k);
    let mut d2 = vec![f64::INFINITY; n];
    for _ in 0..k {
        let seed = if models.is_empty() {
            rng.random_range(0..n)
        } else {
            let total: f64 = d2.iter().sum();
            if !(total.is_finite() && total > 0.0) {
                return None;
            }
            let mut u = rng.random::<f64>() * total;
            let mut pick = n - 1;
            for (i, &w) in d2.iter().enumerate() {
                if u < w {
                    pick = i;
                    break;
                }
                u -= w;
            }
            pick
        };
        let model = geometry::fit_plain("subspace", &neighbourhood(rows, seed))?;
        for (i, row) in rows.iter().enumerate() {
            d2[i] = d2[i].min(model.residual(row).powi(2));
        }
        models.push(model);
    }
    Some(models)
}

/// The [`NEIGHBOURHOOD`] rows nearest `rows[seed]`, nearest first (ties by index).
/// rows `[n, 2F]` (n ≥ [`NEIGHBOURHOOD`]) -> `[NEIGHBOURHOOD, 2F]`.
fn neighbourhood<'a>(rows: &[&'a [f64]], seed: usize) -> Vec<&'a [f64]> {
    let centre = rows[seed];
    let mut by_distance: Vec<(f64, usize)> = rows
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let d: f64 = r.iter().zip(centre).map(|(a, b)| (a - b).powi(2)).sum();
            (d, i)
        })
        .collect();
    let order = |a: &(f64, usize), b: &(f64, usize)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
    by_distance.select_nth_unstable_by(NEIGHBOURHOOD - 1, order);
    by_distance[..NEIGHBOURHOOD].sort_by(order);
    by_distance[..NEIGHBOURHOOD]
        .iter()
        .map(|&(_, i)| rows[i])
        .collect()
}

/// Plain k-subspaces from `models`: assign, refit, until no row moves or [`ROUNDS`] rounds.
/// A subspace left with fewer than [`NEIGHBOURHOOD`] rows is dropped. rows `[n, 2F]` -> at most
/// `models.len()` models.
fn descend(rows: &[&[f64]], mut models: Vec<Model>) -> Vec<Model> {
    let mut labels: Vec<usize> = Vec::new();
    for _ in 0..ROUNDS {
        let next: Vec<usize> = rows.iter().map(|r| nearest(&models, r).0).collect();
        if next == labels {
            break;
        }
        labels = next;
        models = (0..models.len())
            .filter_map(|j| {
                let members: Vec<&[f64]> = rows
                    .iter()
                    .zip(&labels)
                    .filter(|(_, l)| **l == j)
                    .map(|(r, _)| *r)
                    .collect();
                (members.len() >= NEIGHBOURHOOD)
                    .then(|| geometry::fit_plain("subspace", &members))
                    .flatten()
            })
            .collect();
        if models.is_empty() {
            break;
        }
    }
    models
}

/// The nearest model to `row` and its residual.
fn nearest<M: Borrow<Model>>(models: &[M], row: &[f64]) -> (usize, f64) {
    models
        .iter()
        .enumerate()
        .map(|(j, m)| (j, m.borrow().residual(row)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, f64::INFINITY))
}

/// Σ over `rows` of min(r², τ²) / τ², r the residual to the nearest of `models` and τ =
/// `threshold` (in units of τ², so that no τ overflows it). rows `[n, 2F]` -> a number in
/// [0, n].
pub fn cost<M: Borrow<Model>>(rows: &[&[f64]], models: &[M], threshold: f64) -> f64 {
    rows.iter()
        .map(|r| {
            let e = nearest(models, r).1 / threshold;
            if e.is_finite() { (e * e).min(1.0) } else { 1.0 }
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::Kind;
    use crate::data::motion::{MotionGenerator, MotionParams};

    #[test]
    fn the_best_start_separates_clean_motions() {
        let params = MotionParams {
            frames: [12, 12],
            motions: [3, 3],
            points: [50, 50],
            noise: [0.3, 0.3],
            ..MotionParams::default()
        };
        let sample = MotionGenerator::new(5, params).unwrap().sample("s").sample;
        let labels = best_start(&sample.points, 3, 8, 5.0).unwrap();
        let error = crate::metrics::error_rate(&sample.labels, &labels);
        assert!(error < 0.05, "error {error}");
        // The same starts give the same answer.
        assert_eq!(best_start(&sample.points, 3, 8, 5.0), Some(labels));
    }

    #[test]
    fn starts_see_at_most_max_rows_and_need_a_neighbourhood_per_subspace() {
        let params = MotionParams {
            frames: [8, 8],
            motions: [2, 2],
            points: [300, 300],
            noise: [0.3, 0.3],
            ..MotionParams::default()
        };
        let sample = MotionGenerator::new(6, params).unwrap().sample("s").sample;
        let n = sample.points.len();
        assert!(n > MAX_ROWS);
        // Every track is labelled, from subspaces found on the rows seen.
        let labels = best_start(&sample.points, 2, 4, 5.0).unwrap();
        assert_eq!(labels.len(), n);
        assert!(labels.iter().all(|&l| l < 2));
        // More subspaces than the rows seen can seed: no start, at once.
        assert_eq!(
            best_start(&sample.points, MAX_ROWS / NEIGHBOURHOOD + 1, 4, 5.0),
            None
        );
        // Exactly one neighbourhood per subspace.
        let rows = sample
            .points
            .select(&(0..2 * NEIGHBOURHOOD).collect::<Vec<_>>())
            .unwrap();
        if let Some(labels) = best_start(&rows, 2, 4, 5.0) {
            assert!(labels.iter().all(|&l| l < 2));
        }
    }

    #[test]
    fn too_few_or_identical_tracks_give_no_start_and_no_panic() {
        let few = PointSet::from_flat(Kind::Trajectories, 6, (0..60).map(f64::from).collect());
        assert_eq!(best_start(&few.unwrap(), 2, 4, 1.0), None);
        let same = PointSet::from_flat(Kind::Trajectories, 6, vec![1.0; 6 * 40]).unwrap();
        assert_eq!(best_start(&same, 2, 4, 1.0), None);
        let wide = PointSet::from_flat(Kind::Trajectories, 6, (0..240).map(f64::from).collect());
        assert_eq!(best_start(&wide.unwrap(), 2, 4, f64::NAN), None);
    }
}
