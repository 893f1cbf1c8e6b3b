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
//!
//! Files: [`kmeans`] (Lloyd, k-means++, the falling curve), [`select`] (SOD), [`silhouette`]
//! (the silhouette, exact or sampled); this file holds the parameters, the answer and
//! [`cluster_on`], which ties them together.

mod kmeans;
mod select;
mod silhouette;

pub use kmeans::{KMeans, kmeans};
pub use select::sod_scores;
pub use silhouette::{silhouette, silhouettes, silhouettes_on};

use kmeans::make_curve_fall;
use select::argmax;
use silhouette::silhouette_scores;

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
    /// The same parameters with K chosen by `selection` (not fixed) among 1..=`k_max` (>= 1).
    pub fn with_chosen_k(&self, selection: Selection, k_max: usize) -> Self {
        Self {
            selection,
            k_max: k_max.max(1),
            ..self.clone()
        }
    }
    /// The same parameters with k-means seeded by `seed`.
    pub fn with_seed(&self, seed: u64) -> Self {
        Self {
            seed,
            ..self.clone()
        }
    }
    /// The same parameters with K fixed at `k` (>= 1; every other field was validated).
    pub fn with_fixed_k(&self, k: usize) -> Result<Self, ClusterError> {
        if k == 0 {
            return Err(ClusterError::KOutOfRange { k: 0, n: 0 });
        }
        Ok(Self {
            selection: Selection::Fixed(k),
            ..self.clone()
        })
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
    use rand::SeedableRng;
    use rand::rngs::ChaCha8Rng;

    use super::kmeans::*;
    use super::silhouette::*;
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
