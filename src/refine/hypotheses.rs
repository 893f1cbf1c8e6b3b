//! Models beyond the learned groups: hypotheses proposed from small neighbourhoods of the input,
//! grown to every point they explain, and swapped in for a structure where the whole set is
//! explained better.
//!
//! A learned group that mixes two structures, or a structure the network spread over several
//! groups, starts refinement from a model no reassignment can repair: the points of the missed
//! structure never fit any live model. Structures are spatially coherent (the points of a curve,
//! the correspondences of a plane, the tracks of an object lie near one another), so the
//! neighbourhood of almost any point holds mostly one structure.
//!
//! **Proposal.** [`ANCHORS`] anchor points spread over the input (evenly in input order); the
//! s − 1 points nearest each anchor (Euclidean over the whole row, s = [`NEIGHBOURHOOD_FACTOR`] ×
//! the largest minimal sample of the family's types, at least [`MIN_NEIGHBOURHOOD`]); one
//! model of every type of the family fitted to that neighbourhood by plain least squares
//! ([`geometry::fit_plain`]: proposals need no robustness, the choice below weighs them on every
//! point), then fitted again [`GROW_ROUNDS`] times on every point within τ of it. Then
//! [`UNEXPLAINED_ANCHORS`] more, spread over the points no current model explains within τ, with
//! their neighbourhoods taken among those points alone: beside a dense structure, the nearest
//! points of a sparse structure's anchor are the dense one's (a 20-point circle crossing a
//! 400-point line), while among the unexplained points they are its own. A circle grown from
//! one of these also proposes the ellipse fitted on the points it explains, grown the same way:
//! a circle fitted on part of a missed ellipse explains that part and no more (a 300-point
//! ellipse beside a 1500-point circle was answered −1 but for the 63 points of one such arc).
//! Growing an ellipse from every circle hypothesis made refinement a fifth slower for no better
//! answer on the `lce` grid.
//!
//! **Choice.** With residuals r_h(x) and the outlier threshold τ, a set S of m models explains
//! the points at the truncated quadratic cost C(S) = Σᵢ min(min_{h∈S} r_h(xᵢ)², τ²). Starting
//! from the learned groups' models, the swap of one model of S for one hypothesis that lowers C
//! the most is made, while it lowers C by more than [`MIN_GAIN`] × τ² (the cost of that many
//! outliers), at most [`MAX_SWAPS`] times per pass: the local search of k-medoids (PAM), with
//! hypotheses as the candidate medoids. When the search changed the models, it proposes again
//! from the points the chosen ones leave unexplained (their anchors alone) and searches again,
//! up to [`REPROPOSALS`] times: the first proposals spread their unexplained anchors over what
//! the learned models missed, mostly the largest missed structure; once it is added, the
//! smaller ones are what is left. A hypothesis that is swapped in is fitted robustly
//! ([`geometry::fit_type`]) on the points it explains best, and takes the place of the structure
//! it replaced.
//!
//! **Added structures.** With a K the caller gave, m stays the number of structures the learned
//! clustering gave. When K was chosen automatically, a hypothesis may also join S as one more
//! structure, a move that competes with the swaps: its gain in C less a label cost of
//! max(3 × the family's largest minimal sample, 2 % of the points seen) × τ² ([`label_cost`]),
//! so that only a model explaining that many points no structure explains is added (a greedy
//! step of facility location with a label cost, as in PEARL's energy), and never past the
//! k_max the choice of K considered.
//!
//! Cost is bounded: proposals and the choice see at most [`MAX_ROWS`] points (one drawn from
//! each of as many equal runs of the input's rows); the refinement rounds that follow refit
//! every chosen model on all points.

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

use crate::data::PointSet;
use crate::geometry::{self, Family, Fit, Model};
use crate::threads::Threads;

/// Neighbourhoods proposed per fit, spread over every seen point.
pub const ANCHORS: usize = 32;
/// Points per neighbourhood, in units of the largest minimal sample of the family's types.
pub const NEIGHBOURHOOD_FACTOR: usize = 2;
/// More anchors among the points no current structure explains, whose neighbourhoods are taken
/// among those points alone.
pub const UNEXPLAINED_ANCHORS: usize = 16;
/// The smallest neighbourhood.
pub const MIN_NEIGHBOURHOOD: usize = 8;
/// Refits of a hypothesis on the points within τ of it.
pub const GROW_ROUNDS: usize = 2;
/// A swap is made when it lowers the cost by more than this many outliers' worth (τ² each).
pub const MIN_GAIN: f64 = 2.0;
/// Most swaps per pass of the search.
pub const MAX_SWAPS: usize = 12;
/// Passes of the search after the first, each proposing from the points the chosen models
/// leave unexplained.
pub const REPROPOSALS: usize = 2;
/// Neighbourhoods whose hypotheses are grown side by side, per thread.
pub const CHUNK_PER_THREAD: usize = 2;
/// Points the proposals and the choice see at most.
pub const MAX_ROWS: usize = 500;
/// Seed of the draw of the rows seen in a set of more than [`MAX_ROWS`] points.
const SEEN_ROWS_SEED: u64 = 500;

/// One model the search brings in: the slot of the structure it replaces (`None`: a structure
/// added), its fit, and the share of the points seen that it explains best (within τ).
pub struct Swap {
    pub slot: Option<usize>,
    pub fit: Fit,
    pub share: f64,
}

/// The swaps (and up to `may_add` added structures) that lower the cost of explaining
/// `points` by `current` (one model per slot, `None` for slots not to be touched), each
/// hypothesis fitted on neighbourhoods of `points` and grown within `threshold`.
/// `points` `[n, d]` -> the models brought in, at most one per slot. Proposals and their costs
/// run side by side on `threads` (call inside [`Threads::install`]), with the same answer on
/// any number of them.
pub fn swaps(
    points: &PointSet,
    current: &[Option<&Model>],
    family: Family,
    threshold: f64,
    may_add: usize,
    threads: &Threads,
) -> Vec<Swap> {
    let slots: Vec<usize> = (0..current.len())
        .filter(|&j| current[j].is_some())
        .collect();
    if slots.is_empty() || !(threshold.is_finite() && threshold > 0.0) {
        return Vec::new();
    }
    let rows = seen_rows(points.len());
    let tau2 = threshold * threshold;
    let cost_row = |model: &Model| -> Vec<f64> {
        let model = model.prepared();
        rows.iter()
            .map(|&i| model.residual_capped(points.row(i), threshold).powi(2))
            .collect()
    };
    // The pool: the current models first (pool index = position in `slots`), then hypotheses.
    let mut pool: Vec<Vec<f64>> = threads.map_n(slots.len(), |h| {
        cost_row(current[slots[h]].expect("live slot"))
    });
    // The seen rows no chosen model explains.
    let unexplained_by = |pool: &[Vec<f64>], chosen: &[usize]| -> Vec<usize> {
        (0..rows.len())
            .filter(|&k| chosen.iter().all(|&h| pool[h][k] >= tau2))
            .map(|k| rows[k])
            .collect()
    };
    let mut chosen: Vec<usize> = (0..slots.len()).collect();
    let unexplained = unexplained_by(&pool, &chosen);
    let mut hypotheses = propose(
        points,
        &rows,
        &unexplained,
        family,
        threshold,
        true,
        threads,
    );
    pool.extend(threads.map_n(hypotheses.len(), |i| cost_row(&hypotheses[i])));
    let search = Search {
        learned: slots.len(),
        may_add,
        label_cost: label_cost(family, rows.len()) * tau2,
        tau2,
    };
    for pass in 0..=REPROPOSALS {
        let before = chosen.clone();
        search.run(&pool, &mut chosen);
        if pass == REPROPOSALS || chosen == before {
            break;
        }
        // What the chosen models leave unexplained, proposed from again.
        let unexplained = unexplained_by(&pool, &chosen);
        let more = propose(
            points,
            &rows,
            &unexplained,
            family,
            threshold,
            false,
            threads,
        );
        if more.is_empty() {
            break;
        }
        pool.extend(threads.map_n(more.len(), |i| cost_row(&more[i])));
        hypotheses.extend(more);
    }
    let best = nearest_chosen(&pool, &chosen, tau2);
    let mut out = Vec::new();
    for (at, h) in moved(&chosen, slots.len()) {
        // The answer's fit of a model the search moved: robust, of its type, on the rows it
        // explains best. A learned model may come back in another structure's place.
        let mine: Vec<&[f64]> = (0..rows.len())
            .filter(|&k| best[k] == Some(at))
            .map(|k| points.row(rows[k]))
            .collect();
        let model = match h.checked_sub(slots.len()) {
            Some(i) => &hypotheses[i],
            None => current[slots[h]].expect("live slot"),
        };
        let Some(fit) = geometry::fit_type(model.type_name(), &mine) else {
            continue;
        };
        if !fit.model.is_degenerate() {
            out.push(Swap {
                slot: slots.get(at).copied(),
                fit,
                share: mine.len() as f64 / rows.len() as f64,
            });
        }
    }
    out
}

/// The positions of `chosen` (pool indices, the `learned` models first, one per position at the
/// start) that no longer hold the model they started with, and those of added structures:
/// (position, pool index). A learned model the search swapped out and later in again elsewhere
/// counts as moved; an added hypothesis whose pool index equals its position too.
fn moved(chosen: &[usize], learned: usize) -> Vec<(usize, usize)> {
    chosen
        .iter()
        .enumerate()
        .filter(|&(at, &h)| at >= learned || h != at)
        .map(|(at, &h)| (at, h))
        .collect()
}

/// The local search over a pool of models: swaps and additions while they lower the cost.
struct Search {
    /// Pool entries (and positions) of the learned models.
    learned: usize,
    /// Structures that may be added.
    may_add: usize,
    /// The cost of one added structure.
    label_cost: f64,
    /// τ².
    tau2: f64,
}

impl Search {
    /// The swap or addition that lowers the cost the most, while it lowers it by more than
    /// [`MIN_GAIN`] × τ², at most [`MAX_SWAPS`] times. pool: [h][rows] truncated squared
    /// residuals; `chosen`: pool indices, one per position.
    fn run(&self, pool: &[Vec<f64>], chosen: &mut Vec<usize>) {
        let enough = MIN_GAIN * self.tau2;
        for _ in 0..MAX_SWAPS {
            let swap = best_swap(pool, chosen);
            let add = best_add(pool, chosen, self.learned)
                .filter(|_| chosen.len() < self.learned + self.may_add)
                .map(|(h, gain)| (h, gain - self.label_cost));
            match (swap, add) {
                (_, Some((h, net))) if net > enough && swap.is_none_or(|s| net > s.2) => {
                    chosen.push(h);
                }
                (Some((at, h, gain)), _) if gain > enough => chosen[at] = h,
                _ => break,
            }
        }
    }
}

/// The rows proposals and the choice see: all, or [`MAX_ROWS`] spread over the input, one
/// drawn from each of [`MAX_ROWS`] equal runs of consecutive rows (seeded, so a set is always
/// seen the same way). A fixed stride would alias with a repeating row order: every fourth row
/// of four curves sent point by point in turn is one curve.
fn seen_rows(n: usize) -> Vec<usize> {
    if n <= MAX_ROWS {
        return (0..n).collect();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(SEEN_ROWS_SEED);
    (0..MAX_ROWS)
        .map(|k| rng.random_range(k * n / MAX_ROWS..(k + 1) * n / MAX_ROWS))
        .collect()
}

/// Hypotheses of every type of `family`, each fitted on one neighbourhood and grown within
/// `threshold` over the `rows` of `points`: the neighbourhoods of [`ANCHORS`] anchors among
/// `rows` (when `spread_over_all`), then of [`UNEXPLAINED_ANCHORS`] among the `unexplained`
/// rows, taken among those alone. A neighbourhood that a hypothesis of the same type already
/// explains gives none (it would give that one again). The hypotheses are the same on any
/// number of threads.
fn propose(
    points: &PointSet,
    rows: &[usize],
    unexplained: &[usize],
    family: Family,
    threshold: f64,
    spread_over_all: bool,
    threads: &Threads,
) -> Vec<Model> {
    let types = family.candidates();
    let size = (NEIGHBOURHOOD_FACTOR * family.largest_sample()).max(MIN_NEIGHBOURHOOD);
    if rows.len() < size {
        return Vec::new();
    }
    // (anchor, the rows its neighbourhood is taken among), each spread evenly in input order.
    let spread = |among: &[usize], count: usize| -> Vec<usize> {
        if among.len() < size {
            return Vec::new();
        }
        let count = count.min(among.len());
        (0..count).map(|a| among[a * among.len() / count]).collect()
    };
    let over_all = spread(rows, if spread_over_all { ANCHORS } else { 0 });
    // Anchors from this one on are among the unexplained rows.
    let first_unexplained = over_all.len();
    let starts: Vec<(usize, &[usize])> = over_all
        .into_iter()
        .map(|a| (a, rows))
        .chain(
            spread(unexplained, UNEXPLAINED_ANCHORS)
                .into_iter()
                .map(|a| (a, unexplained)),
        )
        .collect();
    let anchors = starts.len();
    let hoods: Vec<Vec<usize>> = threads.map_n(anchors, |a| {
        let (anchor, among) = starts[a];
        neighbourhood(points, among, anchor, size)
    });
    let known = |out: &[Model], hood: &[usize], name: &str| {
        out.iter().any(|m| {
            m.type_name() == name && {
                let m = m.prepared();
                hood.iter()
                    .all(|&i| m.residual_capped(points.row(i), threshold) < threshold)
            }
        })
    };
    // Neighbourhoods in chunks: the hypotheses no earlier one explains are grown side by side,
    // then taken in order, each again only if none taken before it explains its neighbourhood
    // (what one pass in order would take; on more threads a few are grown and not taken).
    let chunk = if threads.count() > 1 {
        CHUNK_PER_THREAD * threads.count()
    } else {
        1
    };
    let mut out: Vec<Model> = Vec::new();
    for first in (0..anchors).step_by(chunk) {
        let mut todo: Vec<(usize, usize)> = (first..(first + chunk).min(anchors))
            .flat_map(|a| (0..types.len()).map(move |t| (a, t)))
            .filter(|&(a, t)| !known(&out, &hoods[a], types[t]))
            .collect();
        let grown = threads.map(&mut todo, |&mut (a, t)| {
            let Some(model) = grow(points, rows, types[t], &hoods[a], threshold) else {
                return Vec::new();
            };
            // An arc of a missed curve grown as a circle proposes the ellipse of the points it
            // explains.
            let richer = richer(family, types[t])
                .filter(|_| a >= first_unexplained)
                .and_then(|name| {
                    let within = explained(points, rows, &model, threshold);
                    (within.len() > hoods[a].len())
                        .then(|| grow(points, rows, name, &within, threshold))
                        .flatten()
                });
            std::iter::once(model).chain(richer).collect::<Vec<_>>()
        });
        // Only the models taken in this chunk can explain what those before it did not.
        let before = out.len();
        for ((a, t), models) in todo.into_iter().zip(grown) {
            if !known(&out[before..], &hoods[a], types[t]) {
                out.extend(models);
            }
        }
    }
    out
}

/// `anchor` and the `size` − 1 rows nearest it among `rows` (Euclidean over the whole row).
fn neighbourhood(points: &PointSet, rows: &[usize], anchor: usize, size: usize) -> Vec<usize> {
    let p = points.row(anchor);
    let mut by_distance: Vec<(f64, usize)> = rows
        .iter()
        .map(|&i| {
            let q = points.row(i);
            let d2: f64 = p.iter().zip(q).map(|(a, b)| (a - b) * (a - b)).sum();
            (d2, i)
        })
        .collect();
    let size = size.min(by_distance.len());
    by_distance.select_nth_unstable_by(size - 1, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    by_distance[..size].iter().map(|&(_, i)| i).collect()
}

/// A model of `type_name` fitted on `hood` by plain least squares ([`geometry::fit_plain`]),
/// then again on the `rows` within `threshold` of it, [`GROW_ROUNDS`] times; `None` when `hood`
/// does not determine one.
fn grow(
    points: &PointSet,
    rows: &[usize],
    type_name: &str,
    hood: &[usize],
    threshold: f64,
) -> Option<Model> {
    let fit_on = |idx: &[usize]| {
        let r: Vec<&[f64]> = idx.iter().map(|&i| points.row(i)).collect();
        geometry::fit_plain(type_name, &r)
    };
    let mut model = fit_on(hood)?;
    for _ in 0..GROW_ROUNDS {
        let within = explained(points, rows, &model, threshold);
        if within.len() <= hood.len() {
            break;
        }
        match fit_on(&within) {
            Some(m) => model = m,
            None => break,
        }
    }
    Some(model)
}

/// The type a grown hypothesis of `type_name` is fitted again as, on the points it explains: a
/// circle's ellipse (a circle fitted on part of an ellipse explains that part, the ellipse
/// fitted on it more). Lines are not (a circle through a segment is a line's worse twin), nor
/// planes (a fundamental matrix through a plane's correspondences is degenerate).
fn richer(family: Family, type_name: &str) -> Option<&'static str> {
    (family == Family::Curves && type_name == "circle").then_some("ellipse")
}

/// The `rows` closer than `threshold` to `model`.
fn explained(points: &PointSet, rows: &[usize], model: &Model, threshold: f64) -> Vec<usize> {
    let model = model.prepared();
    rows.iter()
        .copied()
        .filter(|&i| model.residual_capped(points.row(i), threshold) < threshold)
        .collect()
}

/// The swap (position in `chosen`, pool index, gain) that lowers the cost the most, over every
/// position and every pool entry not chosen; `None` when nothing is left to try (ties go to the
/// first position, then the first pool entry). pool: [h][rows] truncated squared residuals.
///
/// One pass over the rows per pool entry h prices its swap into every position at once (as
/// FastPAM does): with f_i and s_i the best and second-best chosen costs of row i, and o_i the
/// position giving f_i, swapping h (costs c_i) in for position a gains
/// Σ_i max(f_i − c_i, 0) + Σ_{i: o_i = a} [(f_i − min(c_i, s_i)) − max(f_i − c_i, 0)]:
/// a row keeps its best cost unless its owner leaves, when it falls back to its second best.
fn best_swap(pool: &[Vec<f64>], chosen: &[usize]) -> Option<(usize, usize, f64)> {
    let n = pool.first().map_or(0, Vec::len);
    let m = chosen.len();
    if m == 0 {
        return None;
    }
    // The best and second-best chosen cost of every row, and which position gives the best.
    let mut first = vec![f64::INFINITY; n];
    let mut second = vec![f64::INFINITY; n];
    let mut owner = vec![0usize; n];
    for (at, &h) in chosen.iter().enumerate() {
        for (i, &c) in pool[h].iter().enumerate() {
            if c < first[i] {
                second[i] = first[i];
                first[i] = c;
                owner[i] = at;
            } else if c < second[i] {
                second[i] = c;
            }
        }
    }
    debug_assert!(pool.iter().all(|costs| costs.len() == n));
    // gains[h * m + at]: the gain of swapping pool entry h in for position at (chosen entries'
    // are never read).
    let mut gains = vec![0.0; pool.len() * m];
    for (h, costs) in pool.iter().enumerate() {
        if chosen.contains(&h) {
            continue;
        }
        let to = &mut gains[h * m..(h + 1) * m];
        let mut shared = 0.0;
        for i in 0..n {
            let (c, f) = (costs[i], first[i]);
            let kept = (f - c).max(0.0);
            shared += kept;
            to[owner[i]] += (f - c.min(second[i])) - kept;
        }
        to.iter_mut().for_each(|g| *g += shared);
    }
    let mut best: Option<(usize, usize, f64)> = None;
    for at in 0..m {
        for h in (0..pool.len()).filter(|h| !chosen.contains(h)) {
            let gain = gains[h * m + at];
            if best.is_none_or(|b| gain > b.2) {
                best = Some((at, h, gain));
            }
        }
    }
    best
}

/// The price of one more structure, in outliers' worth (units of τ²): 3 × the family's largest
/// minimal sample, or 2 % of the `rows` seen if more. A structure is added only where it
/// explains that many points that no current structure does.
fn label_cost(family: Family, rows: usize) -> f64 {
    (3 * family.largest_sample()).max(rows / 50) as f64
}

/// The hypothesis (pool index `from` on) whose addition to `chosen` lowers the cost the most,
/// with that gain; `None` when every one is chosen. pool: [h][rows] truncated squared residuals.
fn best_add(pool: &[Vec<f64>], chosen: &[usize], from: usize) -> Option<(usize, f64)> {
    let n = pool.first().map_or(0, Vec::len);
    let first: Vec<f64> = (0..n)
        .map(|i| {
            chosen
                .iter()
                .map(|&h| pool[h][i])
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    let mut best: Option<(usize, f64)> = None;
    for (h, costs) in pool.iter().enumerate().skip(from) {
        if chosen.contains(&h) {
            continue;
        }
        let gain: f64 = costs
            .iter()
            .zip(&first)
            .map(|(&c, &f)| (f - c).max(0.0))
            .sum();
        if best.is_none_or(|b| gain > b.1) {
            best = Some((h, gain));
        }
    }
    best
}

/// For each row, the position in `chosen` whose model explains it best, when within τ (its
/// cost below `tau2`).
fn nearest_chosen(pool: &[Vec<f64>], chosen: &[usize], tau2: f64) -> Vec<Option<usize>> {
    let n = pool.first().map_or(0, Vec::len);
    (0..n)
        .map(|i| {
            chosen
                .iter()
                .enumerate()
                .map(|(at, &h)| (at, pool[h][i]))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .filter(|&(_, c)| c < tau2)
                .map(|(at, _)| at)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_swap_that_lowers_the_cost_most_is_found() {
        // Three rows, costs truncated at 4: the chosen model (0) explains row 0, hypothesis 1
        // rows 0 and 1 roughly, hypothesis 2 rows 1 and 2 exactly.
        let pool = vec![
            vec![0.0, 4.0, 4.0],
            vec![1.0, 1.0, 4.0],
            vec![4.0, 0.0, 0.0],
        ];
        // Cost 8; 6 with hypothesis 1 instead, 4 with hypothesis 2.
        assert_eq!(best_swap(&pool, &[0]), Some((0, 2, 4.0)));
        // Cost 5 with 0 and 1 chosen; 0 and 2 explain every row.
        assert_eq!(best_swap(&pool, &[0, 1]), Some((1, 2, 5.0)));
        assert_eq!(
            nearest_chosen(&pool, &[2, 1], 4.0),
            vec![Some(1), Some(0), Some(0)]
        );
        // Nothing left to try.
        assert_eq!(best_swap(&pool[..1], &[0]), None);
    }

    /// The gain of swapping `h` in for position `at` by its definition: the cost of every row
    /// before, less the cost with `at` replaced by `h`.
    fn swap_gain_by_definition(pool: &[Vec<f64>], chosen: &[usize], at: usize, h: usize) -> f64 {
        let cost = |set: &[usize]| -> f64 {
            (0..pool[0].len())
                .map(|i| {
                    set.iter()
                        .map(|&h| pool[h][i])
                        .fold(f64::INFINITY, f64::min)
                })
                .sum()
        };
        let mut set = chosen.to_vec();
        set[at] = h;
        cost(chosen) - cost(&set)
    }

    #[test]
    fn every_swap_is_priced_as_its_definition_does() {
        use rand::rngs::ChaCha8Rng;
        use rand::{RngExt, SeedableRng};
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for round in 0..20 {
            let (entries, rows, tau2) = (12 + round, 150, 4.0);
            // Entries that explain runs of rows, as models do, and ties between copies.
            let mut pool: Vec<Vec<f64>> = (0..entries)
                .map(|_| {
                    let start = rng.random_range(0..rows);
                    let len = rng.random_range(5..60);
                    (0..rows)
                        .map(|i| {
                            let inside = (i + rows - start) % rows < len;
                            let r: f64 = rng.random_range(0.0..3.0);
                            if inside { (r * r).min(tau2) } else { tau2 }
                        })
                        .collect()
                })
                .collect();
            pool.push(pool[3].clone());
            let copy = pool.len() - 1;
            let chosen: Vec<usize> = (0..1 + round % 6).collect();
            let (at, h, gain) = best_swap(&pool, &chosen).expect("a swap to try");
            // Its gain is the definition's, and no swap gains more by the definition.
            assert!((gain - swap_gain_by_definition(&pool, &chosen, at, h)).abs() < 1e-9);
            for other_at in 0..chosen.len() {
                for other in (0..pool.len()).filter(|o| !chosen.contains(o)) {
                    let g = swap_gain_by_definition(&pool, &chosen, other_at, other);
                    assert!(g <= gain + 1e-9, "round {round}: {g} beats {gain}");
                }
            }
            // A copy of an entry never wins over the entry itself (ties go to the first).
            assert!(h != copy || chosen.contains(&3), "round {round}");
        }
    }

    #[test]
    fn a_learned_model_swapped_back_in_elsewhere_is_moved() {
        // Three learned models (pool 0..3), hypotheses from 3 on.
        assert!(moved(&[0, 1, 2], 3).is_empty());
        assert_eq!(moved(&[0, 4, 2], 3), vec![(1, 4)]);
        // Model 0 out for hypothesis 5, then back in place of model 2.
        assert_eq!(moved(&[5, 1, 0], 3), vec![(0, 5), (2, 0)]);
        // An added structure (position 3) whose hypothesis was swapped for learned model 1.
        assert_eq!(moved(&[0, 6, 2, 1], 3), vec![(1, 6), (3, 1)]);
    }

    #[test]
    fn an_added_structure_is_moved_even_where_its_pool_index_is_its_position() {
        // One learned model (pool 0); the first hypothesis (pool 1) added at position 1.
        assert_eq!(moved(&[0, 1], 1), vec![(1, 1)]);
        // Two learned models and hypotheses 2 and 3 added at positions 2 and 3.
        assert_eq!(moved(&[0, 1, 2, 3], 2), vec![(2, 2), (3, 3)]);
    }

    /// A dense line (y = 0, 400 points), a dense circle (radius 5 around (0, 8), 150 points)
    /// and a sparse circle crossing the line (radius 3 around (4, 1.5), 20 points), in that
    /// order, with deterministic noise of about 0.01.
    fn a_sparse_circle_beside_dense_curves() -> PointSet {
        let noise = |i: usize| 0.01 * (((i * 7919) % 101) as f64 / 50.0 - 1.0);
        let mut values = Vec::new();
        for i in 0..400 {
            values.extend([-30.0 + 60.0 * i as f64 / 400.0, noise(i)]);
        }
        for (first, m, (cx, cy, r)) in [(400, 150, (0.0, 8.0, 5.0)), (550, 20, (4.0, 1.5, 3.0))] {
            for j in 0..m {
                let t = j as f64 * std::f64::consts::TAU / m as f64;
                let r = r + noise(first + j);
                values.extend([cx + r * t.cos(), cy + r * t.sin()]);
            }
        }
        PointSet::from_flat(crate::data::Kind::Points2d, 2, values).unwrap()
    }

    #[test]
    fn a_sparse_curve_beside_dense_ones_is_proposed_from_the_points_no_model_explains() {
        let points = a_sparse_circle_beside_dense_curves();
        let rows: Vec<usize> = (0..points.len()).collect();
        let (line, circle) = (
            Model::Line {
                a: 0.0,
                b: 1.0,
                c: 0.0,
            },
            Model::Circle {
                cx: 0.0,
                cy: 8.0,
                r: 5.0,
            },
        );
        let threshold = 0.05;
        let unexplained: Vec<usize> = rows
            .iter()
            .copied()
            .filter(|&i| {
                [&line, &circle]
                    .iter()
                    .all(|m| m.residual(points.row(i)) >= threshold)
            })
            .collect();
        assert!(unexplained.iter().all(|&i| i >= 550), "{unexplained:?}");
        // How many of the sparse circle's points the best hypothesis explains.
        let best = |hypotheses: &[Model]| {
            hypotheses
                .iter()
                .map(|h| explained(&points, &(550..570).collect::<Vec<_>>(), h, threshold).len())
                .max()
                .unwrap_or(0)
        };
        let one = Threads::default();
        // Among every row, the nearest rows of an anchor on the sparse circle are the line's.
        let among_all = propose(&points, &rows, &[], Family::Curves, threshold, true, &one);
        assert!(best(&among_all) < 15, "{}", best(&among_all));
        let with = propose(
            &points,
            &rows,
            &unexplained,
            Family::Curves,
            threshold,
            true,
            &one,
        );
        assert_eq!(best(&with), 20);
        // And the search swaps it in for a second copy of the line.
        let swapped = swaps(
            &points,
            &[Some(&line), Some(&line), Some(&circle)],
            Family::Curves,
            threshold,
            0,
            &one,
        );
        assert_eq!(swapped.len(), 1);
        let Model::Circle { cx, cy, r } = swapped[0].fit.model else {
            panic!("{:?}", swapped[0].fit.model);
        };
        assert!((cx - 4.0).abs() < 0.01 && (cy - 1.5).abs() < 0.01 && (r - 3.0).abs() < 0.01);
    }

    #[test]
    fn large_sets_are_seen_evenly_and_tiny_ones_propose_nothing() {
        // One row from each run of 10, seeded: the same rows every time, never on a period.
        let rows = seen_rows(10 * MAX_ROWS);
        assert_eq!(rows.len(), MAX_ROWS);
        assert!(
            rows.iter().enumerate().all(|(k, &r)| r / 10 == k),
            "{rows:?}"
        );
        assert_eq!(rows, seen_rows(10 * MAX_ROWS));
        let offsets: std::collections::BTreeSet<usize> = rows.iter().map(|r| r % 10).collect();
        assert_eq!(offsets.len(), 10, "every offset within a run is drawn");
        assert_eq!(seen_rows(3), vec![0, 1, 2]);
        let three = PointSet::from_flat(
            crate::data::Kind::Points2d,
            2,
            vec![0.0, 0.0, 1.0, 0.0, 2.0, 0.0],
        )
        .unwrap();
        let one = Threads::default();
        assert!(
            propose(
                &three,
                &[0, 1, 2],
                &[0, 1, 2],
                Family::Curves,
                0.1,
                true,
                &one
            )
            .is_empty()
        );
        let line = Model::Line {
            a: 0.0,
            b: 1.0,
            c: 0.0,
        };
        assert!(swaps(&three, &[Some(&line)], Family::Curves, 0.1, 2, &one).is_empty());
        assert!(swaps(&three, &[Some(&line)], Family::Curves, f64::NAN, 2, &one).is_empty());
    }
}
