//! Clustering losses on embeddings (section 3.2 of the paper).
//!
//! Every loss takes the embeddings of one set `z: [n, e]` (rows of unit length) and the one-hot
//! labels `y: [n, k]`, and returns a scalar tensor `[1]`. They work on any device; on an autodiff
//! device they carry gradients. All are invariant to permuting the points and renaming labels.
//!
//! - **L2Regression**: `||Y Y^T - Z Z^T||_F^2 / n^2`, computed in `O(n e k)` through
//!   `||Z^T Z||^2 - 2 ||Z^T Y||^2 + ||Y^T Y||^2` (the paper's identity), never forming `n x n`.
//! - **CrossEntropy**: mean over all pairs of the sigmoid cross-entropy of the logit `z_i . z_j`
//!   against `y_i . y_j`.
//! - **MaxInterMinIntra**: `-a log min_{m != n} ||mu_m - mu_n||^2 + (1 - a) log max_l s_l` with
//!   `s_l` the trace of cluster `l`'s covariance (the authors' code; `a = 0.6` there). With a single
//!   group the inter term is dropped.
//!
//! Normalising by `n^2` (L2, CE) keeps the loss scale independent of the set size; it changes
//! nothing but the effective learning rate, to which Adam is nearly invariant.

use burn::prelude::*;
use burn::tensor::activation::softplus;
use serde::{Deserialize, Serialize};

/// Guards the logarithms of MIMI against zero distances and scatters.
const LOG_EPS: f64 = 1e-6;

/// The training loss.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "name", rename_all = "snake_case")]
pub enum Loss {
    L2,
    CrossEntropy,
    Mimi { alpha: f64 },
}

impl Loss {
    /// Parses `l2`, `ce` / `cross_entropy`, or `mimi` (alpha given separately).
    pub fn parse(name: &str, alpha: f64) -> Option<Loss> {
        match name {
            "l2" => Some(Loss::L2),
            "ce" | "cross_entropy" => Some(Loss::CrossEntropy),
            "mimi" => Some(Loss::Mimi { alpha }),
            _ => None,
        }
    }

    pub fn short_name(&self) -> &'static str {
        match self {
            Loss::L2 => "l2",
            Loss::CrossEntropy => "ce",
            Loss::Mimi { .. } => "mimi",
        }
    }

    /// z: [n, e], y: [n, k] one-hot -> [1]
    pub fn compute(&self, z: Tensor<2>, y: Tensor<2>) -> Tensor<1> {
        match *self {
            Loss::L2 => l2_regression(z, y),
            Loss::CrossEntropy => cross_entropy(z, y),
            Loss::Mimi { alpha } => max_inter_min_intra(z, y, alpha),
        }
    }
}

/// One-hot encoding of labels in `0..k`: -> [n, k]
pub fn one_hot(labels: &[usize], k: usize, device: &Device) -> Tensor<2> {
    let mut data = vec![0f32; labels.len() * k];
    for (i, &l) in labels.iter().enumerate() {
        data[i * k + l] = 1.0;
    }
    Tensor::from_data(TensorData::new(data, [labels.len(), k]), device)
}

/// Squared Frobenius norm of a matrix: [a, b] -> [1]
fn frob2(m: Tensor<2>) -> Tensor<1> {
    m.square().sum()
}

/// `||Y Y^T - Z Z^T||_F^2 / n^2`. z: [n, e], y: [n, k] -> [1]
pub fn l2_regression(z: Tensor<2>, y: Tensor<2>) -> Tensor<1> {
    let n = z.dims()[0] as f64;
    let zt = z.clone().transpose();
    let yt = y.clone().transpose();
    let ztz = frob2(zt.clone().matmul(z));
    let zty = frob2(zt.matmul(y.clone()));
    let yty = frob2(yt.matmul(y));
    (ztz - zty.mul_scalar(2.0) + yty).div_scalar(n * n)
}

/// Mean sigmoid cross-entropy of logits `Z Z^T` against targets `Y Y^T`. z: [n, e], y: [n, k] -> [1]
pub fn cross_entropy(z: Tensor<2>, y: Tensor<2>) -> Tensor<1> {
    let logits = z.clone().matmul(z.transpose());
    let target = y.clone().matmul(y.transpose());
    // softplus(x) - t x is the stable form of -t log s(x) - (1 - t) log(1 - s(x)).
    (softplus(logits.clone(), 1.0) - target * logits).mean()
}

/// Cluster means and covariance traces. z: [n, e], y: [n, k] -> ([k, e], [k])
fn cluster_stats(z: Tensor<2>, y: Tensor<2>) -> (Tensor<2>, Tensor<1>) {
    let [n, e] = z.dims();
    let k = y.dims()[1];
    let counts = y.clone().sum_dim(0).clamp_min(1.0); // [1, k]
    let mu = y.clone().transpose().matmul(z.clone()) / counts.clone().transpose(); // [k, e]
    let diff = z.reshape([n, 1, e]) - mu.clone().reshape([1, k, e]); // [n, k, e]
    let sq = diff.square().sum_dim(2).reshape([n, k]); // [n, k]
    let scatter = (sq * y).sum_dim(0) / counts; // [1, k]
    (mu, scatter.reshape([k]))
}

/// MaxInterMinIntra. z: [n, e], y: [n, k] -> [1]
pub fn max_inter_min_intra(z: Tensor<2>, y: Tensor<2>, alpha: f64) -> Tensor<1> {
    let k = y.dims()[1];
    let device = z.device();
    let (mu, scatter) = cluster_stats(z, y);
    let intra = (scatter.max() + LOG_EPS).log().mul_scalar(1.0 - alpha);
    if k < 2 {
        return intra;
    }
    let sq = mu.clone().square().sum_dim(1); // [k, 1]
    let dist = sq.clone() + sq.transpose() - mu.clone().matmul(mu.transpose()).mul_scalar(2.0);
    // The diagonal is pushed out of the way of the minimum; 1e6 dwarfs any distance of unit vectors.
    let off_diag = dist + Tensor::<2>::eye(k, &device).mul_scalar(1e6);
    let inter = (off_diag.min().clamp_min(0.0) + LOG_EPS)
        .log()
        .mul_scalar(-alpha);
    inter + intra
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::cpu_device;

    /// Unit rows from a fixed pattern: [n, e]
    fn unit_rows(n: usize, e: usize, salt: usize) -> Vec<f32> {
        let mut v: Vec<f32> = (0..n * e)
            .map(|i| (((i + salt) * 7919 % 211) as f32 / 105.0) - 1.0)
            .collect();
        for row in v.chunks_mut(e) {
            let len = row.iter().map(|x| x * x).sum::<f32>().sqrt();
            row.iter_mut().for_each(|x| *x /= len);
        }
        v
    }

    fn scalar(t: Tensor<1>) -> f64 {
        t.into_data().try_to_vec::<f32>().unwrap()[0] as f64
    }

    fn eval(loss: Loss, z: &[f32], n: usize, e: usize, labels: &[usize], k: usize) -> f64 {
        let d = cpu_device();
        let zt = Tensor::<2>::from_data(TensorData::new(z.to_vec(), [n, e]), &d);
        scalar(loss.compute(zt, one_hot(labels, k, &d)))
    }

    const LOSSES: [Loss; 3] = [Loss::L2, Loss::CrossEntropy, Loss::Mimi { alpha: 0.6 }];

    #[test]
    fn l2_matches_the_pairwise_definition() {
        let (n, e) = (7, 3);
        let z = unit_rows(n, e, 1);
        let labels = [0, 1, 1, 2, 0, 2, 1];
        let mut want = 0.0;
        for i in 0..n {
            for j in 0..n {
                let dot: f32 = (0..e).map(|c| z[i * e + c] * z[j * e + c]).sum();
                let t = if labels[i] == labels[j] { 1.0 } else { 0.0 };
                want += (t - dot as f64).powi(2);
            }
        }
        want /= (n * n) as f64;
        let got = eval(Loss::L2, &z, n, e, &labels, 3);
        assert!((got - want).abs() < 1e-5, "{got} vs {want}");
    }

    #[test]
    fn cross_entropy_matches_the_pairwise_definition() {
        let (n, e) = (5, 2);
        let z = unit_rows(n, e, 2);
        let labels = [0, 0, 1, 1, 0];
        let mut want = 0.0;
        for i in 0..n {
            for j in 0..n {
                let x: f64 = (0..e).map(|c| (z[i * e + c] * z[j * e + c]) as f64).sum();
                let s = 1.0 / (1.0 + (-x).exp());
                let t = if labels[i] == labels[j] { 1.0 } else { 0.0 };
                want -= t * s.ln() + (1.0 - t) * (1.0 - s).ln();
            }
        }
        want /= (n * n) as f64;
        let got = eval(Loss::CrossEntropy, &z, n, e, &labels, 2);
        assert!((got - want).abs() < 1e-5, "{got} vs {want}");
    }

    #[test]
    fn mimi_by_hand() {
        // Two groups in 2D: A = {(1,0), (0,1)}, B = {(-1,0)}.
        // mu_A = (0.5, 0.5), tr cov A = 0.5; mu_B = (-1, 0), tr cov B = 0.
        // ||mu_A - mu_B||^2 = 2.25 + 0.25 = 2.5.
        let z = [1.0, 0.0, 0.0, 1.0, -1.0, 0.0];
        let a = 0.6;
        let want = -a * (2.5f64 + LOG_EPS).ln() + (1.0 - a) * (0.5f64 + LOG_EPS).ln();
        let got = eval(Loss::Mimi { alpha: a }, &z, 3, 2, &[0, 0, 1], 2);
        assert!((got - want).abs() < 1e-5, "{got} vs {want}");
        // A single group: only the intra term.
        let one = eval(Loss::Mimi { alpha: a }, &z, 3, 2, &[0, 0, 0], 1);
        let mu = [0.0f64, 1.0 / 3.0];
        let tr = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)]
            .iter()
            .map(|&(x, y): &(f64, f64)| (x - mu[0]).powi(2) + (y - mu[1]).powi(2))
            .sum::<f64>()
            / 3.0;
        assert!((one - (1.0 - a) * (tr + LOG_EPS).ln()).abs() < 1e-5);
    }

    #[test]
    fn invariant_to_point_permutation_and_label_renaming() {
        let (n, e) = (12, 4);
        let z = unit_rows(n, e, 3);
        let labels = [0, 1, 2, 0, 1, 2, 2, 2, 0, 1, 1, 0];
        let perm = [5, 3, 11, 0, 7, 1, 9, 2, 10, 4, 8, 6];
        let zp: Vec<f32> = perm
            .iter()
            .flat_map(|&i| z[i * e..(i + 1) * e].to_vec())
            .collect();
        let rename = [2, 0, 1];
        let lp: Vec<usize> = perm.iter().map(|&i| rename[labels[i]]).collect();
        for loss in LOSSES {
            let a = eval(loss, &z, n, e, &labels, 3);
            let b = eval(loss, &zp, n, e, &lp, 3);
            assert!((a - b).abs() < 1e-5, "{loss:?}: {a} vs {b}");
        }
    }

    #[test]
    fn gradients_match_finite_differences() {
        let (n, e, k) = (8, 3, 3);
        let z = unit_rows(n, e, 4);
        let labels = [0, 1, 2, 0, 1, 2, 0, 1];
        let ad = cpu_device().autodiff();
        for loss in LOSSES {
            let zt = Tensor::<2>::from_data(TensorData::new(z.clone(), [n, e]), &ad).require_grad();
            let value = loss.compute(zt.clone(), one_hot(&labels, k, &ad));
            let grads = value.backward();
            let g: Vec<f32> = zt.grad(&grads).unwrap().into_data().try_to_vec().unwrap();
            let h = 1e-3f32;
            for idx in 0..n * e {
                let mut plus = z.clone();
                plus[idx] += h;
                let mut minus = z.clone();
                minus[idx] -= h;
                let fd = (eval(loss, &plus, n, e, &labels, k)
                    - eval(loss, &minus, n, e, &labels, k))
                    / (2.0 * h as f64);
                let tol = 2e-3 + 2e-2 * fd.abs();
                assert!(
                    (g[idx] as f64 - fd).abs() < tol,
                    "{loss:?} at {idx}: {} vs {fd}",
                    g[idx]
                );
            }
        }
    }

    #[test]
    fn perfect_embeddings_score_better_than_mixed_ones() {
        // Three groups on orthogonal axes versus the same points with labels shuffled.
        let z = [
            1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0,
            1.0,
        ];
        for loss in LOSSES {
            let good = eval(loss, &z, 6, 3, &[0, 0, 1, 1, 2, 2], 3);
            let bad = eval(loss, &z, 6, 3, &[0, 1, 2, 0, 1, 2], 3);
            assert!(good < bad, "{loss:?}: {good} !< {bad}");
        }
        assert!(eval(Loss::L2, &z, 6, 3, &[0, 0, 1, 1, 2, 2], 3).abs() < 1e-6);
    }
}
