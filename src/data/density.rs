//! Density: a set read at the point spacing its model was trained on.
//!
//! A network that reads each point's k nearest neighbours sees a different local picture when the
//! same curves are sampled twice as densely: its k neighbours then span half the arc. The
//! network is not retrained for every density; the set is thinned to the training density
//! instead, and the points left out take the label of their nearest point that was read.
//!
//! The spacing s of a normalised set is the median, over its points, of the distance to the
//! k-th nearest other point. A model card records the training sets' spacing s₀ (same k). A set
//! with s < [`THIN_BELOW`] · s₀ is thinned: a seeded random subset of ⌈m · s / s₀⌉ of its m
//! points is kept, and again on that subset, until its spacing reaches [`THIN_BELOW`] · s₀ (for
//! points on noisy curves the spacing grows more slowly than the inverse of the density, since the
//! nearest neighbours of a dense set lie across the noise band too, so one step falls short),
//! never below [`MIN_READ`] points. A set within the tolerance of training, or sparser, is read
//! whole.
//!
//! **Sparser sets.** Thinning cannot make a set denser. A card may name a second network trained
//! on sparse sets ([`crate::registry::SparseNetwork`]); a set with s > `above` · s₀ is read whole
//! by that network instead ([`reading`]).

use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand::seq::SliceRandom;

use super::features::nearest_all;

/// Fewest points a thinned set keeps.
pub const MIN_READ: usize = 64;
/// A set whose spacing is below this share of the trained spacing is thinned.
pub const THIN_BELOW: f64 = 0.8;
/// Most thinning steps.
const MAX_STEPS: usize = 6;

/// The spacing of `points` `[n, dim]` (normalised): the median distance from a point to its k-th
/// nearest other point (0 for fewer than k + 1 points).
pub fn spacing(points: &[f32], dim: usize, k: usize) -> f64 {
    let n = points.len() / dim.max(1);
    if k == 0 || n <= k {
        return 0.0;
    }
    let nearest = nearest_all(points, dim, dim, k);
    let mut d: Vec<f64> = (0..n)
        .map(|i| {
            let j = nearest[i * k + k - 1];
            let (p, q) = (
                &points[i * dim..(i + 1) * dim],
                &points[j * dim..(j + 1) * dim],
            );
            p.iter()
                .zip(q)
                .map(|(a, b)| f64::from(a - b).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    d.sort_by(f64::total_cmp);
    d[(n - 1) / 2]
}

/// How a model reads a set ([`reading`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reading {
    /// Every row, by the card's networks.
    Whole,
    /// A sorted seeded subset of the rows, by the card's networks: the set is denser than the
    /// training sets.
    Thinned(Vec<usize>),
    /// Every row, by the card's network for sparse sets.
    Sparse,
}

/// How a model trained at spacing `trained` with `k` neighbours reads `points` `[n, dim]`:
/// by its network for sparse sets when the set's spacing exceeds `sparse_above` × `trained`, or
/// it has no more than k points (cards with such a network), else thinned ([`thin`]) or whole.
pub fn reading(
    points: &[f32],
    dim: usize,
    k: usize,
    trained: f64,
    sparse_above: Option<f64>,
    seed: u64,
) -> Reading {
    if trained.is_nan() || trained <= 0.0 {
        return Reading::Whole;
    }
    // No k-th neighbour: sparser than any spacing.
    let n = points.len() / dim.max(1);
    if sparse_above.is_some() && k > 0 && n <= k {
        return Reading::Sparse;
    }
    let s = spacing(points, dim, k);
    if sparse_above.is_some_and(|above| s > above * trained) {
        return Reading::Sparse;
    }
    thin_from(points, dim, k, trained, seed, s).map_or(Reading::Whole, Reading::Thinned)
}

/// The rows to read of `points` `[n, dim]` for a model trained at spacing `trained` with `k`
/// neighbours: `None` to read them all, else a sorted seeded random subset.
pub fn thin(points: &[f32], dim: usize, k: usize, trained: f64, seed: u64) -> Option<Vec<usize>> {
    thin_from(points, dim, k, trained, seed, spacing(points, dim, k))
}

/// [`thin`] of a set whose spacing is `whole`.
fn thin_from(
    points: &[f32],
    dim: usize,
    k: usize,
    trained: f64,
    seed: u64,
    whole: f64,
) -> Option<Vec<usize>> {
    let n = points.len() / dim.max(1);
    if trained.is_nan() || trained <= 0.0 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut rows: Vec<usize> = (0..n).collect();
    for _ in 0..MAX_STEPS {
        if rows.len() <= MIN_READ {
            break;
        }
        let s = if rows.len() == n {
            whole
        } else {
            let subset: Vec<f32> = rows
                .iter()
                .flat_map(|&i| &points[i * dim..(i + 1) * dim])
                .copied()
                .collect();
            spacing(&subset, dim, k)
        };
        if s.is_nan() || s <= 0.0 || s >= THIN_BELOW * trained {
            break;
        }
        let keep = ((rows.len() as f64 * s / trained).ceil() as usize).clamp(MIN_READ, rows.len());
        rows.shuffle(&mut rng);
        rows.truncate(keep);
        rows.sort_unstable();
    }
    (rows.len() < n).then_some(rows)
}

/// For every row of `points` `[n, dim]`, the position in `read` (sorted row indices) of its
/// nearest read row (a read row: itself): -> `[n]`.
pub fn nearest_read(points: &[f32], dim: usize, read: &[usize]) -> Vec<usize> {
    let n = points.len() / dim.max(1);
    let row = |i: usize| &points[i * dim..(i + 1) * dim];
    // Read rows sorted by their first coordinate, swept outwards from each query as in
    // `nearest_all`: exact, and far less work than every pair.
    let mut order: Vec<usize> = (0..read.len()).collect();
    order.sort_by(|&a, &b| row(read[a])[0].total_cmp(&row(read[b])[0]));
    let xs: Vec<f32> = order.iter().map(|&a| row(read[a])[0]).collect();
    (0..n)
        .map(|i| {
            if let Ok(pos) = read.binary_search(&i) {
                return pos;
            }
            let p = row(i);
            let start = xs.partition_point(|&x| x < p[0]);
            let mut best = (f32::INFINITY, 0usize);
            let mut visit = |o: usize| -> bool {
                let a = order[o];
                let dx = xs[o] - p[0];
                if dx * dx > best.0 {
                    return false;
                }
                let d: f32 = p
                    .iter()
                    .zip(row(read[a]))
                    .map(|(u, v)| (u - v) * (u - v))
                    .sum();
                if d < best.0 || (d == best.0 && a < best.1) {
                    best = (d, a);
                }
                true
            };
            for o in start..order.len() {
                if !visit(o) {
                    break;
                }
            }
            for o in (0..start).rev() {
                if !visit(o) {
                    break;
                }
            }
            best.1
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `m` points evenly on the unit circle.
    fn circle(m: usize) -> Vec<f32> {
        (0..m)
            .flat_map(|i| {
                let t = i as f32 / m as f32 * std::f32::consts::TAU;
                [t.cos(), t.sin()]
            })
            .collect()
    }

    #[test]
    fn spacing_halves_when_the_density_doubles() {
        let (a, b) = (spacing(&circle(100), 2, 4), spacing(&circle(200), 2, 4));
        assert!((a / b - 2.0).abs() < 0.01, "{a} {b}");
    }

    #[test]
    fn a_denser_set_is_thinned_to_the_trained_spacing_and_a_sparser_one_read_whole() {
        let trained = spacing(&circle(100), 2, 4);
        let dense = circle(400);
        let rows = thin(&dense, 2, 4, trained, 7).unwrap();
        // Evenly spaced points thin in one step: 400 * s(400) / s(100) = 100.
        assert!((99..=101).contains(&rows.len()), "{}", rows.len());
        assert!(rows.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(thin(&dense, 2, 4, trained, 7), Some(rows.clone()));
        assert_ne!(thin(&dense, 2, 4, trained, 8), Some(rows));
        assert_eq!(thin(&circle(100), 2, 4, trained, 7), None);
        assert_eq!(thin(&circle(80), 2, 4, trained, 7), None);
        // Within the tolerance: read whole.
        assert_eq!(thin(&circle(120), 2, 4, trained, 7), None);
        // Never below the floor.
        assert_eq!(
            thin(&dense, 2, 4, trained * 100.0, 7).unwrap().len(),
            MIN_READ
        );
        // No trained spacing, or a degenerate one: read whole.
        assert_eq!(thin(&dense, 2, 4, 0.0, 7), None);
        assert_eq!(thin(&dense, 2, 4, f64::NAN, 7), None);
    }

    #[test]
    fn a_much_sparser_set_goes_to_the_sparse_network_where_there_is_one() {
        let trained = spacing(&circle(100), 2, 4);
        let read = |m: usize, above: Option<f64>| reading(&circle(m), 2, 4, trained, above, 7);
        // 40 points: spacing 2.5 x training's.
        assert_eq!(read(40, Some(1.05)), Reading::Sparse);
        assert_eq!(read(40, Some(3.0)), Reading::Whole);
        assert_eq!(read(40, None), Reading::Whole);
        // At the training density, or within the threshold: whole, by the card's networks.
        assert_eq!(read(100, Some(1.05)), Reading::Whole);
        assert_eq!(read(90, Some(1.2)), Reading::Whole);
        // Denser: thinned exactly as `thin` does, whatever the threshold.
        let thinned = thin(&circle(400), 2, 4, trained, 7).unwrap();
        assert_eq!(read(400, Some(1.05)), Reading::Thinned(thinned));
        // No training spacing: whole.
        assert_eq!(
            reading(&circle(40), 2, 4, 0.0, Some(1.05), 7),
            Reading::Whole
        );
        // Too few points to have a k-th neighbour: sparser than any threshold.
        assert_eq!(read(4, Some(3.0)), Reading::Sparse);
        assert_eq!(read(4, None), Reading::Whole);
    }

    #[test]
    fn nearest_read_matches_brute_force() {
        let pts: Vec<f32> = (0..300).map(|v| ((v * 37) % 101) as f32 / 7.0).collect();
        let read: Vec<usize> = (0..150).filter(|i| i % 3 == 0).collect();
        let got = nearest_read(&pts, 2, &read);
        for i in 0..150 {
            let d = |a: usize| -> f32 {
                (0..2)
                    .map(|c| (pts[i * 2 + c] - pts[read[a] * 2 + c]).powi(2))
                    .sum()
            };
            let best = (0..read.len()).map(d).fold(f32::INFINITY, f32::min);
            assert_eq!(d(got[i]), best, "row {i}");
            if i % 3 == 0 {
                assert_eq!(read[got[i]], i);
            }
        }
    }
}
