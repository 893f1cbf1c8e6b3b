//! The silhouette of a labelling: exact up to [`super::SILHOUETTE_EXACT_MAX`] points, else on a
//! seeded sample.

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

use super::{Points, SILHOUETTE_EXACT_MAX};
use crate::threads::Threads;

/// Mean silhouette of a labelling (Euclidean distances), exact on the given rows.
/// Needs at least two clusters; a point alone in its cluster scores 0.
pub fn silhouette(p: Points, labels: &[usize], k: usize) -> f64 {
    silhouettes(p, &[(labels, k)])[0]
}

/// Rows of one block of the silhouette: distances from every point to these rows are computed
/// together, one SIMD lane per row.
pub(super) const SIL_BLOCK: usize = 16;

/// For the rows `rows` (a range starting at a multiple of [`SIL_BLOCK`]), the sums of distances
/// from each row to the points of each cluster of every labelling: -> per labelling
/// `[rows.len(), k]`.
///
/// Distances are computed for a block of 16 rows against every point at once (the block held
/// transposed, so the inner loops run over 16 lanes), then added into per-cluster accumulators of
/// 16 lanes: no scattered single adds. The sums of a row do not depend on which block or thread
/// computed them.
pub(super) fn cluster_distance_sums(
    p: Points,
    labelings: &[(&[usize], usize)],
    rows: std::ops::Range<usize>,
) -> Vec<Vec<f32>> {
    const R: usize = SIL_BLOCK;
    let (n, dim) = (p.len(), p.dim);
    let mut out: Vec<Vec<f32>> = labelings
        .iter()
        .map(|&(_, k)| vec![0.0; rows.len() * k])
        .collect();
    let mut block = vec![[0f32; R]; dim];
    let mut dist = vec![[0f32; R]; n];
    let mut acc: Vec<[f32; R]> = Vec::new();
    for start in rows.clone().step_by(R) {
        let live = R.min(rows.end - start);
        for (e, lanes) in block.iter_mut().enumerate() {
            for (r, v) in lanes.iter_mut().enumerate() {
                *v = p.row(start + r.min(live - 1))[e];
            }
        }
        for (d, zj) in dist.iter_mut().zip(p.data.chunks_exact(dim)) {
            let mut sq = [0f32; R];
            for (lanes, &v) in block.iter().zip(zj) {
                for (s, &b) in sq.iter_mut().zip(lanes) {
                    *s += (b - v) * (b - v);
                }
            }
            for (o, s) in d.iter_mut().zip(&sq) {
                *o = s.sqrt();
            }
        }
        for (&(labels, k), out) in labelings.iter().zip(&mut out) {
            acc.clear();
            acc.resize(k, [0f32; R]);
            for (d, &l) in dist.iter().zip(labels) {
                for (a, &v) in acc[l].iter_mut().zip(d) {
                    *a += v;
                }
            }
            for r in 0..live {
                let row = &mut out[(start - rows.start + r) * k..][..k];
                for (o, a) in row.iter_mut().zip(&acc) {
                    *o = a[r];
                }
            }
        }
    }
    out
}

/// The mean silhouette of several labellings `(labels, k)` of the same rows, exact. All pairwise
/// distances are computed once for all labellings (O(N^2 dim) time) and summed into per-point,
/// per-cluster totals (O(N sum k) memory, never N^2); the rows are split over `threads`.
pub fn silhouettes_on(p: Points, labelings: &[(&[usize], usize)], threads: &Threads) -> Vec<f64> {
    let n = p.len();
    // f32 sums: at most SILHOUETTE_EXACT_MAX distances of at most 2 each.
    let blocks = n.div_ceil(SIL_BLOCK);
    let parts = threads.count().min(blocks).max(1);
    let per = blocks.div_ceil(parts) * SIL_BLOCK;
    let mut ranges: Vec<std::ops::Range<usize>> =
        (0..n).step_by(per).map(|a| a..(a + per).min(n)).collect();
    let pieces = threads.install(|| {
        threads.map(&mut ranges, |r| {
            cluster_distance_sums(p, labelings, r.clone())
        })
    });
    labelings
        .iter()
        .enumerate()
        .map(|(li, &(labels, k))| {
            let sums: Vec<f32> = pieces
                .iter()
                .flat_map(|piece| piece[li].iter().copied())
                .collect();
            let mut counts = vec![0usize; k];
            for &l in labels {
                counts[l] += 1;
            }
            let total: f64 = (0..n)
                .map(|i| {
                    let own = labels[i];
                    if counts[own] <= 1 {
                        return 0.0;
                    }
                    let row = &sums[i * k..(i + 1) * k];
                    let a = f64::from(row[own]) / (counts[own] - 1) as f64;
                    let b = (0..k)
                        .filter(|&c| c != own && counts[c] > 0)
                        .map(|c| f64::from(row[c]) / counts[c] as f64)
                        .fold(f64::INFINITY, f64::min);
                    if b.is_finite() && a.max(b) > 0.0 {
                        (b - a) / a.max(b)
                    } else {
                        0.0
                    }
                })
                .sum();
            total / n as f64
        })
        .collect()
}

/// [`silhouettes_on`] on the calling thread.
pub fn silhouettes(p: Points, labelings: &[(&[usize], usize)]) -> Vec<f64> {
    silhouettes_on(p, labelings, &Threads::default())
}

/// The silhouettes of several labellings `(labels, k)`, on one seeded sample of
/// [`SILHOUETTE_EXACT_MAX`] points when the set is larger.
pub(super) fn silhouette_scores(
    p: Points,
    labelings: &[(&[usize], usize)],
    seed: u64,
    threads: &Threads,
) -> Vec<f64> {
    let n = p.len();
    if n <= SILHOUETTE_EXACT_MAX {
        return silhouettes_on(p, labelings, threads);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5151);
    let mut idx: Vec<usize> = (0..n).collect();
    for i in 0..SILHOUETTE_EXACT_MAX {
        let j = rng.random_range(i..n);
        idx.swap(i, j);
    }
    idx.truncate(SILHOUETTE_EXACT_MAX);
    let data: Vec<f32> = idx.iter().flat_map(|&i| p.row(i).iter().copied()).collect();
    let sub_labels: Vec<Vec<usize>> = labelings
        .iter()
        .map(|(labels, _)| idx.iter().map(|&i| labels[i]).collect())
        .collect();
    let sub: Vec<(&[usize], usize)> = sub_labels
        .iter()
        .zip(labelings)
        .map(|(l, &(_, k))| (l.as_slice(), k))
        .collect();
    let sample = Points {
        data: &data,
        dim: p.dim,
    };
    silhouette_scores(sample, &sub, seed, threads)
}
