//! K-means on embeddings, the residual curve r(K) and the choice of K (section 3.3 of the paper).
//!
//! - [`kmeans`]: Lloyd iterations (with Hamerly's distance bounds, which skip work without
//!   changing the result) from k-means++ seeds, several restarts, the lowest residual kept.
//!   Deterministic for a fixed seed: every K draws from its own stream derived from the seed, so
//!   a K's clustering does not depend on which other K were tried, unless the curve below needs
//!   it.
//! - The curve `r(K)` for K = 1, 2, ... is made to fall as the optimum does: where K's restarts
//!   end above K - 1's clustering, K is clustered again from K - 1's centres plus one more
//!   (`make_curve_fall`).
//! - `r(K) = sum_m sum_{i in C_m} ||z_i - mu_m||^2`.
//! - K selection ([`Selection`]):
//!   - `Sod`: the second-order difference of `l(K) = log r(K)`,
//!     `sod(K) = l(K-1) + l(K+1) - 2 l(K)`, maximised over `2 <= K <= k_max`. To judge `k_max`
//!     itself the curve is computed up to `k_max + 1` (capped at N).
//!   - `Silhouette`: the mean silhouette over `2 <= K <= k_max`, maximised. Exact (O(N^2) time,
//!     O(N K) memory) up to [`SILHOUETTE_EXACT_MAX`] points; beyond, on a seeded uniform sample of
//!     that many points, as scikit-learn's `sample_size` does.
//!   - `Fixed(K)`: K is given; only that K is clustered.
//! - A single structure (K = 1): neither SOD nor the silhouette can choose K = 1 (SOD has no
//!   `r(0)`, the silhouette is undefined for one cluster). Automatic selection returns K = 1 when
//!   `k_max = 1` or when the embeddings are collapsed, i.e. their mean squared distance to their
//!   mean, `r(1) / N`, is below `single_spread` (default 0.01; unit embeddings spread over several
//!   structures give values of 0.3 and more).

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::threads::Threads;

/// Points above which the silhouette is computed on a seeded sample of this many points.
pub const SILHOUETTE_EXACT_MAX: usize = 3000;

/// How K is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Selection {
    Sod,
    Silhouette,
    Fixed(usize),
}

impl Selection {
    pub fn name(&self) -> &'static str {
        match self {
            Selection::Sod => "sod",
            Selection::Silhouette => "silhouette",
            Selection::Fixed(_) => "fixed",
        }
    }
}

/// Invalid clustering parameters or input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ClusterError {
    #[error("k_max must be at least 1")]
    ZeroKMax,
    #[error("k = {k} is out of range: it must be between 1 and the number of points ({n})")]
    KOutOfRange { k: usize, n: usize },
    #[error("restarts must be at least 1")]
    ZeroRestarts,
    #[error("max_iter must be at least 1")]
    ZeroMaxIter,
    #[error("single_spread must be finite and non-negative")]
    BadSpread,
    #[error("embeddings must be a non-empty [n, dim] array of finite values")]
    BadEmbeddings,
}

/// Validated clustering parameters; build with [`ClusterParams::builder`].
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterParams {
    k_max: usize,
    selection: Selection,
    restarts: usize,
    max_iter: usize,
    seed: u64,
    single_spread: f64,
}

/// Builder for [`ClusterParams`] (defaults: k_max 8, SOD, 4 restarts, 100 iterations, seed 0).
#[derive(Debug, Clone)]
pub struct ClusterParamsBuilder(ClusterParams);

impl ClusterParams {
    pub fn builder() -> ClusterParamsBuilder {
        ClusterParamsBuilder(ClusterParams {
            k_max: 8,
            selection: Selection::Sod,
            restarts: 4,
            max_iter: 100,
            seed: 0,
            single_spread: 0.01,
        })
    }
    pub fn k_max(&self) -> usize {
        self.k_max
    }
    pub fn selection(&self) -> Selection {
        self.selection
    }
    pub fn seed(&self) -> u64 {
        self.seed
    }
}

impl ClusterParamsBuilder {
    pub fn k_max(mut self, k_max: usize) -> Self {
        self.0.k_max = k_max;
        self
    }
    pub fn selection(mut self, selection: Selection) -> Self {
        self.0.selection = selection;
        self
    }
    pub fn restarts(mut self, restarts: usize) -> Self {
        self.0.restarts = restarts;
        self
    }
    pub fn max_iter(mut self, max_iter: usize) -> Self {
        self.0.max_iter = max_iter;
        self
    }
    pub fn seed(mut self, seed: u64) -> Self {
        self.0.seed = seed;
        self
    }
    pub fn single_spread(mut self, spread: f64) -> Self {
        self.0.single_spread = spread;
        self
    }
    pub fn build(self) -> Result<ClusterParams, ClusterError> {
        let p = self.0;
        if p.k_max == 0 {
            return Err(ClusterError::ZeroKMax);
        }
        if let Selection::Fixed(0) = p.selection {
            return Err(ClusterError::KOutOfRange { k: 0, n: 0 });
        }
        if p.restarts == 0 {
            return Err(ClusterError::ZeroRestarts);
        }
        if p.max_iter == 0 {
            return Err(ClusterError::ZeroMaxIter);
        }
        if !(p.single_spread.is_finite() && p.single_spread >= 0.0) {
            return Err(ClusterError::BadSpread);
        }
        Ok(p)
    }
}

/// One k-means solution.
#[derive(Debug, Clone, PartialEq)]
pub struct KMeans {
    pub labels: Vec<usize>,
    /// Row-major `[k, dim]`.
    pub centroids: Vec<f64>,
    pub residual: f64,
}

/// The clustering of a set with its chosen K.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Clustering {
    /// Per point, in `0..k`, numbered by first appearance in input order.
    pub labels: Vec<usize>,
    pub k: usize,
    pub selection: Selection,
    /// `(K, r(K))` for every K clustered, ascending.
    pub residuals: Vec<(usize, f64)>,
    /// `(K, score)`: the SOD value or the mean silhouette of every K that was a candidate.
    pub scores: Vec<(usize, f64)>,
    /// Points per cluster, indexed by label.
    pub cluster_sizes: Vec<usize>,
}

/// A row-major `[n, dim]` view of embeddings.
#[derive(Debug, Clone, Copy)]
pub struct Points<'a> {
    data: &'a [f32],
    dim: usize,
}

impl<'a> Points<'a> {
    pub fn new(data: &'a [f32], dim: usize) -> Result<Self, ClusterError> {
        if dim == 0
            || data.is_empty()
            || !data.len().is_multiple_of(dim)
            || data.iter().any(|v| !v.is_finite())
        {
            return Err(ClusterError::BadEmbeddings);
        }
        Ok(Self { data, dim })
    }
    pub fn len(&self) -> usize {
        self.data.len() / self.dim
    }
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }
    fn row(&self, i: usize) -> &[f32] {
        &self.data[i * self.dim..(i + 1) * self.dim]
    }
}

fn sq_dist(a: &[f32], c: &[f64]) -> f64 {
    a.iter().zip(c).map(|(&x, &y)| (x as f64 - y).powi(2)).sum()
}

/// The seed of K's random stream.
fn stream_seed(seed: u64, k: usize) -> u64 {
    seed ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

/// Squared distance in f32, the embeddings' own precision (sums and residuals stay in f64).
fn sq_dist32(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// k-means++ seeding: [k, dim] centroids.
fn kmeans_pp(p: Points, k: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
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
fn lloyd(p: Points, k: usize, mut centroids: Vec<f64>, max_iter: usize) -> KMeans {
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

/// Mean silhouette of a labelling (Euclidean distances), exact on the given rows.
/// Needs at least two clusters; a point alone in its cluster scores 0.
pub fn silhouette(p: Points, labels: &[usize], k: usize) -> f64 {
    silhouettes(p, &[(labels, k)])[0]
}

/// Rows of one block of the silhouette: distances from every point to these rows are computed
/// together, one SIMD lane per row.
const SIL_BLOCK: usize = 16;

/// For the rows `rows` (a range starting at a multiple of [`SIL_BLOCK`]), the sums of distances
/// from each row to the points of each cluster of every labelling: -> per labelling
/// `[rows.len(), k]`.
///
/// Distances are computed for a block of 16 rows against every point at once (the block held
/// transposed, so the inner loops run over 16 lanes), then added into per-cluster accumulators of
/// 16 lanes: no scattered single adds. The sums of a row do not depend on which block or thread
/// computed them.
fn cluster_distance_sums(
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
fn silhouette_scores(
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

/// Relabels clusters by first appearance in input order, so equal partitions give equal labels.
fn canonical(labels: &[usize], k: usize) -> (Vec<usize>, Vec<usize>) {
    let mut map = vec![usize::MAX; k];
    let mut next = 0;
    let mut out = Vec::with_capacity(labels.len());
    for &l in labels {
        if map[l] == usize::MAX {
            map[l] = next;
            next += 1;
        }
        out.push(map[l]);
    }
    let mut sizes = vec![0usize; next];
    for &l in &out {
        sizes[l] += 1;
    }
    (out, sizes)
}

/// SOD scores `(K, sod(K))` for the inner points of the curve.
pub fn sod_scores(residuals: &[(usize, f64)]) -> Vec<(usize, f64)> {
    let floor = residuals.first().map_or(0.0, |r| r.1) * 1e-9 + 1e-12;
    let l: Vec<f64> = residuals.iter().map(|&(_, r)| (r + floor).ln()).collect();
    (1..residuals.len().saturating_sub(1))
        .map(|i| (residuals[i].0, l[i - 1] + l[i + 1] - 2.0 * l[i]))
        .collect()
}

fn argmax(scores: &[(usize, f64)]) -> Option<usize> {
    scores
        .iter()
        .fold(None, |best: Option<(usize, f64)>, &(k, s)| match best {
            Some((_, b)) if b >= s => best,
            _ => Some((k, s)),
        })
        .map(|b| b.0)
}

/// Makes the residual curve fall as the optimum it estimates does (`r(K) <= r(K - 1)`): where the
/// best of K's restarts ends above the clustering kept for K - 1 (every k-means++ restart can miss,
/// and tight clusters make it likelier), K is clustered again from K - 1's centres plus the point
/// farthest from its centre. That start costs at most r(K - 1) and Lloyd's iterations never raise
/// the cost, so the result is kept when lower. `runs[i]` holds K = i + 1; a curve that already
/// falls is left untouched, so K's clustering is its own restarts' unless they lost to K - 1's.
fn make_curve_fall(p: Points, runs: &mut [KMeans], max_iter: usize) {
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

/// Clusters embeddings, choosing K as `params` says, on the calling thread.
pub fn cluster(p: Points, params: &ClusterParams) -> Result<Clustering, ClusterError> {
    cluster_on(p, params, &Threads::default())
}

/// [`cluster`], the k-means of the candidate K run in parallel on `threads` (each K has its own
/// seeded stream, so the answer does not depend on the threads).
pub fn cluster_on(
    p: Points,
    params: &ClusterParams,
    threads: &Threads,
) -> Result<Clustering, ClusterError> {
    let n = p.len();
    let (seed, restarts, iters) = (params.seed, params.restarts, params.max_iter);
    let run = |k: usize| kmeans(p, k, restarts, iters, seed);
    let (chosen, residuals, scores) = match params.selection {
        Selection::Fixed(k) => {
            if k == 0 || k > n {
                return Err(ClusterError::KOutOfRange { k, n });
            }
            let km = run(k);
            let r = vec![(k, km.residual)];
            (km, r, vec![])
        }
        selection => {
            let k_max = params.k_max.min(n);
            let top = match selection {
                Selection::Sod => (k_max + 1).min(n),
                _ => k_max,
            };
            let mut runs: Vec<KMeans> = threads.install(|| threads.map_range(1..=top, run));
            make_curve_fall(p, &mut runs, iters);
            let residuals: Vec<(usize, f64)> = runs
                .iter()
                .enumerate()
                .map(|(i, r)| (i + 1, r.residual))
                .collect();
            let scores: Vec<(usize, f64)> = match selection {
                Selection::Sod => sod_scores(&residuals)
                    .into_iter()
                    .filter(|s| s.0 <= k_max)
                    .collect(),
                _ => {
                    let labelings: Vec<(&[usize], usize)> = (2..=k_max)
                        .map(|k| (runs[k - 1].labels.as_slice(), k))
                        .collect();
                    (2..=k_max)
                        .zip(silhouette_scores(p, &labelings, seed, threads))
                        .collect()
                }
            };
            let single = k_max == 1 || residuals[0].1 / (n as f64) < params.single_spread;
            let k = if single {
                1
            } else {
                argmax(&scores).unwrap_or(k_max)
            };
            (runs.swap_remove(k - 1), residuals, scores)
        }
    };
    let k = chosen.centroids.len() / p.dim;
    let (labels, cluster_sizes) = canonical(&chosen.labels, k);
    Ok(Clustering {
        k: cluster_sizes.len(),
        labels,
        selection: params.selection,
        residuals,
        scores,
        cluster_sizes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `k` tight blobs of `m` points around well-separated 2D centres.
    fn blobs(k: usize, m: usize) -> (Vec<f32>, Vec<usize>) {
        let mut data = Vec::new();
        let mut labels = Vec::new();
        for i in 0..m {
            for c in 0..k {
                let angle = c as f32 * std::f32::consts::TAU / k as f32;
                let jitter = ((i * 31 + c * 17) % 13) as f32 / 13.0 * 0.05;
                data.push(angle.cos() * 3.0 + jitter);
                data.push(angle.sin() * 3.0 - jitter);
                labels.push(c);
            }
        }
        (data, labels)
    }

    fn params(sel: Selection) -> ClusterParams {
        ClusterParams::builder()
            .selection(sel)
            .seed(9)
            .build()
            .unwrap()
    }

    #[test]
    fn a_curve_that_rises_is_made_to_fall_and_one_that_falls_is_untouched() {
        let (data, truth) = blobs(3, 20);
        let p = Points::new(&data, 2).unwrap();
        let mut runs: Vec<KMeans> = (1..=3).map(|k| kmeans(p, k, 4, 100, 0)).collect();
        let before = runs.clone();
        make_curve_fall(p, &mut runs, 100);
        assert_eq!(runs, before, "a falling curve is left as it is");
        // A K = 3 clustering that lost every restart: all points in one cluster, two empty
        // centres far away, so r(3) = r(1) > r(2).
        let mean = before[0].centroids.clone();
        let bad = KMeans {
            labels: vec![0; p.len()],
            centroids: [mean, vec![50.0, 50.0], vec![-50.0, 50.0]].concat(),
            residual: before[0].residual,
        };
        assert!(bad.residual > before[1].residual);
        runs[2] = bad;
        make_curve_fall(p, &mut runs, 100);
        assert!(
            runs[2].residual <= runs[1].residual,
            "{} > {}",
            runs[2].residual,
            runs[1].residual
        );
        // Restarted from K = 2's centres plus the farthest point, it finds the three blobs.
        assert_eq!(runs[2].centroids.len(), 3 * 2);
        let pairs: std::collections::BTreeSet<(usize, usize)> = truth
            .iter()
            .copied()
            .zip(runs[2].labels.iter().copied())
            .collect();
        assert_eq!(pairs.len(), 3, "one cluster per blob: {pairs:?}");
        assert!(
            (runs[2].residual - before[2].residual).abs() <= 1e-6 * before[2].residual.max(1.0)
        );
    }

    #[test]
    fn kmeans_by_hand() {
        // Two pairs: {0, 1} around 0.5 and {10, 12} around 11; r = 0.25*2 + 1*2 = 2.5.
        let data = [0.0f32, 1.0, 10.0, 12.0];
        let km = kmeans(Points::new(&data, 1).unwrap(), 2, 3, 50, 1);
        assert!((km.residual - 2.5).abs() < 1e-9);
        assert_eq!(km.labels[0], km.labels[1]);
        assert_eq!(km.labels[2], km.labels[3]);
        assert_ne!(km.labels[0], km.labels[2]);
        // r(1) = sum of squared deviations from the mean 5.75.
        let one = kmeans(Points::new(&data, 1).unwrap(), 1, 1, 50, 1);
        let want: f64 = data.iter().map(|&v| (v as f64 - 5.75).powi(2)).sum();
        assert!((one.residual - want).abs() < 1e-9);
    }

    #[test]
    fn sod_and_silhouette_find_the_blobs() {
        for k in 2..=5 {
            let (data, truth) = blobs(k, 20);
            let p = Points::new(&data, 2).unwrap();
            for sel in [Selection::Sod, Selection::Silhouette] {
                let c = cluster(p, &params(sel)).unwrap();
                assert_eq!(c.k, k, "{sel:?}");
                assert_eq!(crate::metrics::error_rate(&truth, &c.labels), 0.0);
            }
        }
    }

    #[test]
    fn residual_curve_is_non_increasing_and_sizes_add_up() {
        let (data, _) = blobs(3, 30);
        let c = cluster(Points::new(&data, 2).unwrap(), &params(Selection::Sod)).unwrap();
        assert_eq!(c.residuals.len(), 9); // K = 1..k_max + 1
        for w in c.residuals.windows(2) {
            assert!(w[1].1 <= w[0].1 + 1e-9, "{:?}", c.residuals);
        }
        assert_eq!(c.cluster_sizes.iter().sum::<usize>(), 90);
        assert_eq!(
            c.scores.iter().map(|s| s.0).collect::<Vec<_>>(),
            (2..=8).collect::<Vec<_>>()
        );
    }

    #[test]
    fn deterministic_and_invariant_to_point_order() {
        let (data, _) = blobs(4, 25);
        let p = Points::new(&data, 2).unwrap();
        let a = cluster(p, &params(Selection::Sod)).unwrap();
        let b = cluster(p, &params(Selection::Sod)).unwrap();
        assert_eq!(a, b);
        // The same answer when the K run in parallel.
        let two = Threads::new(2).unwrap();
        for sel in [Selection::Sod, Selection::Silhouette, Selection::Fixed(4)] {
            assert_eq!(
                cluster_on(p, &params(sel), &two).unwrap(),
                cluster(p, &params(sel)).unwrap()
            );
        }
        // Reversed rows give the same partition (labels compared up to renaming).
        let rev: Vec<f32> = data.chunks(2).rev().flatten().copied().collect();
        let c = cluster(Points::new(&rev, 2).unwrap(), &params(Selection::Sod)).unwrap();
        let back: Vec<usize> = c.labels.iter().rev().copied().collect();
        assert_eq!(crate::metrics::error_rate(&a.labels, &back), 0.0);
    }

    #[test]
    fn single_structure_and_caps() {
        let data: Vec<f32> = (0..40).map(|i| 1.0 + (i % 5) as f32 * 1e-3).collect();
        let c = cluster(Points::new(&data, 2).unwrap(), &params(Selection::Sod)).unwrap();
        assert_eq!(c.k, 1);
        assert_eq!(c.labels, vec![0; 20]);
        // k_max is capped at N.
        let three = [0.0f32, 0.0, 5.0, 5.0, 10.0, 0.0];
        let c = cluster(
            Points::new(&three, 2).unwrap(),
            &params(Selection::Silhouette),
        )
        .unwrap();
        assert!(c.k <= 3 && c.residuals.len() == 3);
        assert_eq!(
            cluster(
                Points::new(&three, 2).unwrap(),
                &params(Selection::Fixed(4))
            ),
            Err(ClusterError::KOutOfRange { k: 4, n: 3 })
        );
    }

    #[test]
    fn silhouette_by_hand() {
        // Clusters {0, 1} and {4}: point 0: a = 1, b = 4 -> 0.75; point 1: a = 1, b = 3 -> 2/3;
        // point 4 alone -> 0. Mean = (0.75 + 0.6667) / 3.
        let data = [0.0f32, 1.0, 4.0];
        let s = silhouette(Points::new(&data, 1).unwrap(), &[0, 0, 1], 2);
        assert!((s - (0.75 + 2.0 / 3.0) / 3.0).abs() < 1e-6);
    }

    /// The definition, one point and one labelling at a time.
    fn silhouette_reference(p: Points, labels: &[usize], k: usize) -> f64 {
        let n = p.len();
        let dist = |i: usize, j: usize| -> f64 {
            p.row(i)
                .iter()
                .zip(p.row(j))
                .map(|(a, b)| f64::from(a - b).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let mut total = 0.0;
        for i in 0..n {
            let mean_to = |c: usize| {
                let others: Vec<usize> = (0..n).filter(|&j| j != i && labels[j] == c).collect();
                (!others.is_empty())
                    .then(|| others.iter().map(|&j| dist(i, j)).sum::<f64>() / others.len() as f64)
            };
            let Some(a) = mean_to(labels[i]) else {
                continue;
            };
            let b = (0..k)
                .filter(|&c| c != labels[i])
                .filter_map(mean_to)
                .fold(f64::INFINITY, f64::min);
            total += (b - a) / a.max(b);
        }
        total / n as f64
    }

    #[test]
    fn silhouettes_of_several_labellings_match_the_definition() {
        let (data, truth) = blobs(3, 20);
        let p = Points::new(&data, 2).unwrap();
        let n = truth.len();
        let shuffled: Vec<usize> = (0..n).map(|i| (i * 7) % 4).collect();
        let split: Vec<usize> = truth
            .iter()
            .enumerate()
            .map(|(i, &t)| t * 2 + i % 2)
            .collect();
        // More than 32 clusters takes the plain accumulation path.
        let many: Vec<usize> = (0..n).map(|i| i % 40).collect();
        let labelings: Vec<(&[usize], usize)> =
            vec![(&truth, 3), (&shuffled, 4), (&split, 6), (&many, 40)];
        let got = silhouettes(p, &labelings);
        for (&(labels, k), s) in labelings.iter().zip(&got) {
            let want = silhouette_reference(p, labels, k);
            assert!((s - want).abs() < 1e-6, "k {k}: {s} vs {want}");
        }
        assert!(got[0] > 0.9 && got[1] < 0.1, "{got:?}");
    }

    #[test]
    fn silhouettes_do_not_depend_on_threads() {
        // 1000 points: several 16-row blocks per thread and a ragged last block.
        let data: Vec<f32> = (0..1003 * 5)
            .map(|i| ((i * 7919 % 2003) as f32 / 1001.5) - 1.0)
            .collect();
        let p = Points::new(&data, 5).unwrap();
        let a: Vec<usize> = (0..1003).map(|i| i % 3).collect();
        let b: Vec<usize> = (0..1003).map(|i| (i * 13 / 7) % 7).collect();
        let labelings: Vec<(&[usize], usize)> = vec![(&a, 3), (&b, 7)];
        let one = silhouettes(p, &labelings);
        for t in [2, 3] {
            let pool = Threads::new(t).unwrap();
            assert_eq!(one, silhouettes_on(p, &labelings, &pool), "{t} threads");
        }
        let want = silhouette_reference(p, &b, 7);
        assert!((one[1] - want).abs() < 1e-5, "{} vs {want}", one[1]);
    }

    /// Plain Lloyd (every distance every iteration), the reference for the bounded one.
    fn lloyd_reference(p: Points, k: usize, mut centroids: Vec<f64>) -> Vec<usize> {
        let mut labels = vec![usize::MAX; p.len()];
        loop {
            let next: Vec<usize> = (0..p.len())
                .map(|i| {
                    (0..k)
                        .min_by(|&a, &b| {
                            sq_dist(p.row(i), &centroids[a * p.dim..(a + 1) * p.dim]).total_cmp(
                                &sq_dist(p.row(i), &centroids[b * p.dim..(b + 1) * p.dim]),
                            )
                        })
                        .unwrap()
                })
                .collect();
            if next == labels {
                return labels;
            }
            labels = next;
            let mut sums = vec![0f64; k * p.dim];
            let mut counts = vec![0usize; k];
            for (i, &l) in labels.iter().enumerate() {
                counts[l] += 1;
                for (s, &v) in sums[l * p.dim..].iter_mut().zip(p.row(i)) {
                    *s += f64::from(v);
                }
            }
            for c in 0..k {
                assert!(counts[c] > 0, "reference hit an empty cluster");
                for s in &mut sums[c * p.dim..(c + 1) * p.dim] {
                    *s /= counts[c] as f64;
                }
            }
            centroids = sums;
        }
    }

    #[test]
    fn bounded_lloyd_matches_plain_lloyd() {
        // Overlapping groups, so that many points change cluster over several iterations.
        let data: Vec<f32> = (0..600 * 4)
            .map(|i| {
                let group = (i / 4) % 5;
                ((i * 7919 % 1009) as f32 / 504.5 - 1.0) + group as f32 * 0.6
            })
            .collect();
        let p = Points::new(&data, 4).unwrap();
        for k in [2, 3, 5, 8] {
            let mut rng = ChaCha8Rng::seed_from_u64(k as u64);
            let init = kmeans_pp(p, k, &mut rng);
            let want = lloyd_reference(p, k, init.clone());
            let got = lloyd(p, k, init, 1000);
            assert_eq!(got.labels, want, "k {k}");
            let residual: f64 = (0..p.len())
                .map(|i| {
                    let l = got.labels[i];
                    sq_dist(p.row(i), &got.centroids[l * p.dim..(l + 1) * p.dim])
                })
                .sum();
            assert!((got.residual - residual).abs() <= 1e-9 * residual);
        }
    }

    #[test]
    fn sod_by_hand() {
        // log r: 0, -2, -2.5, -2.7 -> sod(2) = 0 - 2.5 + 4 = 1.5, sod(3) = -2 - 2.7 + 5 = 0.3.
        let r: Vec<(usize, f64)> = [0.0, -2.0, -2.5, -2.7]
            .iter()
            .enumerate()
            .map(|(i, l)| (i + 1, f64::exp(*l)))
            .collect();
        let s = sod_scores(&r);
        assert_eq!(s.len(), 2);
        assert!((s[0].1 - 1.5).abs() < 1e-6 && (s[1].1 - 0.3).abs() < 1e-6);
        assert_eq!(argmax(&s), Some(2));
    }

    #[test]
    fn rejects_bad_params() {
        assert_eq!(
            ClusterParams::builder().k_max(0).build(),
            Err(ClusterError::ZeroKMax)
        );
        assert_eq!(
            ClusterParams::builder().restarts(0).build(),
            Err(ClusterError::ZeroRestarts)
        );
        assert!(Points::new(&[1.0, f32::NAN], 1).is_err());
        assert!(Points::new(&[1.0, 2.0, 3.0], 2).is_err());
    }
}
