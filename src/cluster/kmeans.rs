//! K-means: k-means++ seeds, Lloyd iterations with Hamerly's bounds, several restarts, and the
//! residual curve made to fall as the optimum does.

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

use super::Points;

/// One k-means solution.
#[derive(Debug, Clone, PartialEq)]
pub struct KMeans {
    pub labels: Vec<usize>,
    /// Row-major `[k, dim]`.
    pub centroids: Vec<f64>,
    pub residual: f64,
}

pub(super) fn sq_dist(a: &[f32], c: &[f64]) -> f64 {
    a.iter().zip(c).map(|(&x, &y)| (x as f64 - y).powi(2)).sum()
}

/// The seed of K's random stream.
pub(super) fn stream_seed(seed: u64, k: usize) -> u64 {
    seed ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

/// Squared distance in f32, the embeddings' own precision (sums and residuals stay in f64).
pub(super) fn sq_dist32(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// k-means++ seeding: [k, dim] centroids.
pub(super) fn kmeans_pp(p: Points, k: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let n = p.len();
    let mut centroids: Vec<f64> = Vec::with_capacity(k * p.dim);
    let first = rng.random_range(0..n);
    centroids.extend(p.row(first).iter().map(|&v| v as f64));
    let mut d2: Vec<f32> = (0..n).map(|i| sq_dist32(p.row(i), p.row(first))).collect();
    for _ in 1..k {
        let total: f64 = d2.iter().map(|&d| f64::from(d)).sum();
        let pick = if total > 0.0 {
            let mut target = rng.random_range(0.0..total);
            let mut pick = n - 1;
            for (i, &d) in d2.iter().enumerate() {
                let d = f64::from(d);
                if target < d {
                    pick = i;
                    break;
                }
                target -= d;
            }
            pick
        } else {
            rng.random_range(0..n)
        };
        centroids.extend(p.row(pick).iter().map(|&v| v as f64));
        let new = p.row(pick);
        for (i, d) in d2.iter_mut().enumerate() {
            *d = d.min(sq_dist32(p.row(i), new));
        }
    }
    centroids
}

/// Lloyd iterations from the given centroids until assignments stop changing.
///
/// Hamerly's bounds skip most distance computations once the clusters settle, without changing
/// what Lloyd computes: every point keeps an upper bound on the distance to its own centroid and
/// a lower bound on the distance to any other; when the upper bound is below both the lower bound
/// and half the distance from its centroid to the nearest other centroid, its nearest centroid
/// cannot have changed. The bounds follow the centroids' moves. Centroid sums are updated only
/// for the points that change cluster.
pub(super) fn lloyd(p: Points, k: usize, mut centroids: Vec<f64>, max_iter: usize) -> KMeans {
    let (n, dim) = (p.len(), p.dim);
    let mut labels = vec![usize::MAX; n];
    // upper[i] >= |z_i - own centroid|, lower[i] <= |z_i - any other centroid|.
    let mut upper = vec![f32::INFINITY; n];
    let mut lower = vec![0f32; n];
    let mut near = vec![0f32; k * dim];
    let mut half = vec![0f32; k];
    let mut sums = vec![0f64; k * dim];
    let mut counts = vec![0usize; k];
    let add = |sums: &mut [f64], c: usize, row: &[f32], sign: f64| {
        for (s, &v) in sums[c * dim..(c + 1) * dim].iter_mut().zip(row) {
            *s += sign * f64::from(v);
        }
    };
    for _ in 0..max_iter {
        near.iter_mut()
            .zip(&centroids)
            .for_each(|(f, &c)| *f = c as f32);
        for c in 0..k {
            half[c] = (0..k)
                .filter(|&o| o != c)
                .map(|o| sq_dist32(&near[c * dim..(c + 1) * dim], &near[o * dim..(o + 1) * dim]))
                .fold(f32::INFINITY, f32::min)
                .sqrt()
                * 0.5;
        }
        let mut changed = false;
        for (i, row) in p.data.chunks_exact(dim).enumerate() {
            let own = labels[i];
            if own != usize::MAX {
                let bound = half[own].max(lower[i]);
                if upper[i] <= bound {
                    continue;
                }
                upper[i] = sq_dist32(row, &near[own * dim..(own + 1) * dim]).sqrt();
                if upper[i] <= bound {
                    continue;
                }
            }
            let (mut best, mut d1, mut d2) = (0, f32::INFINITY, f32::INFINITY);
            for (c, centroid) in near.chunks_exact(dim).enumerate() {
                let d = sq_dist32(row, centroid);
                if d < d1 {
                    (best, d2, d1) = (c, d1, d);
                } else if d < d2 {
                    d2 = d;
                }
            }
            upper[i] = d1.sqrt();
            lower[i] = d2.sqrt();
            if own != best {
                if own != usize::MAX {
                    add(&mut sums, own, row, -1.0);
                    counts[own] -= 1;
                }
                add(&mut sums, best, row, 1.0);
                counts[best] += 1;
                labels[i] = best;
                changed = true;
            }
        }
        if !changed {
            break;
        }
        for c in 0..k {
            if counts[c] == 0 {
                // An empty cluster takes the point farthest from its centroid.
                let far = (0..n)
                    .filter(|&i| counts[labels[i]] > 1)
                    .map(|i| {
                        let l = labels[i];
                        (i, sq_dist32(p.row(i), &near[l * dim..(l + 1) * dim]))
                    })
                    .max_by(|a, b| a.1.total_cmp(&b.1))
                    .map_or(0, |(i, _)| i);
                let from = labels[far];
                add(&mut sums, from, p.row(far), -1.0);
                counts[from] -= 1;
                add(&mut sums, c, p.row(far), 1.0);
                counts[c] = 1;
                labels[far] = c;
                (upper[far], lower[far]) = (0.0, 0.0);
            }
        }
        // New centroids, and how far each moved: the bounds widen by that much.
        let mut moved = vec![0f32; k];
        for c in 0..k {
            let mean = &mut centroids[c * dim..(c + 1) * dim];
            let mut shift = 0f64;
            for (m, s) in mean.iter_mut().zip(&sums[c * dim..(c + 1) * dim]) {
                let v = s / counts[c] as f64;
                shift += (v - *m) * (v - *m);
                *m = v;
            }
            // Rounded up so that f32 bounds stay bounds.
            moved[c] = (shift.sqrt() * (1.0 + 1e-6) + 1e-7) as f32;
        }
        let (mut far1, mut m1, mut m2) = (0, 0f32, 0f32);
        for (c, &m) in moved.iter().enumerate() {
            if m > m1 {
                (far1, m2, m1) = (c, m1, m);
            } else if m > m2 {
                m2 = m;
            }
        }
        for i in 0..n {
            let l = labels[i];
            upper[i] += moved[l];
            lower[i] -= if l == far1 { m2 } else { m1 };
        }
    }
    let residual = (0..n)
        .map(|i| sq_dist(p.row(i), &centroids[labels[i] * dim..(labels[i] + 1) * dim]))
        .sum();
    KMeans {
        labels,
        centroids,
        residual,
    }
}

/// k-means with k-means++ seeding and `restarts` restarts; the lowest residual is kept.
/// Requires `1 <= k <= n`.
pub fn kmeans(p: Points, k: usize, restarts: usize, max_iter: usize, seed: u64) -> KMeans {
    let mut rng = ChaCha8Rng::seed_from_u64(stream_seed(seed, k));
    let mut best: Option<KMeans> = None;
    for _ in 0..restarts.max(1) {
        let init = kmeans_pp(p, k, &mut rng);
        let run = lloyd(p, k, init, max_iter);
        if best.as_ref().is_none_or(|b| run.residual < b.residual) {
            best = Some(run);
        }
    }
    best.expect("at least one restart")
}

/// Makes the residual curve fall as the optimum it estimates does (`r(K) <= r(K - 1)`): where the
/// best of K's restarts ends above the clustering kept for K - 1 (every k-means++ restart can miss,
/// and tight clusters make it likelier), K is clustered again from K - 1's centres plus the point
/// farthest from its centre. That start costs at most r(K - 1) and Lloyd's iterations never raise
/// the cost, so the result is kept when lower. `runs[i]` holds K = i + 1; a curve that already
/// falls is left untouched, so K's clustering is its own restarts' unless they lost to K - 1's.
pub(super) fn make_curve_fall(p: Points, runs: &mut [KMeans], max_iter: usize) {
    for i in 1..runs.len() {
        let prev = &runs[i - 1];
        if runs[i].residual <= prev.residual {
            continue;
        }
        let dim = p.dim;
        let cost = |j: usize| {
            let c = prev.labels[j];
            sq_dist(p.row(j), &prev.centroids[c * dim..(c + 1) * dim])
        };
        let far = (0..p.len())
            .max_by(|&a, &b| cost(a).total_cmp(&cost(b)))
            .expect("k <= n, so n >= 1");
        let mut init = prev.centroids.clone();
        init.extend(p.row(far).iter().map(|&v| f64::from(v)));
        let warm = lloyd(p, i + 1, init, max_iter);
        if warm.residual < runs[i].residual {
            runs[i] = warm;
        }
    }
}
