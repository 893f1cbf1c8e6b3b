//! The serving forward pass: the network of [`super::EmbeddingNet`] computed on plain row-major
//! `f32` buffers, one matrix multiply per layer followed by one fused element-wise pass
//! (context norm, batch norm, ReLU and the residual add together), instead of burn's ~30
//! allocating element-wise passes per block. Training stays on burn; tests check this path
//! against the burn forward to 1e-4 on every shipped model (`tests/fused.rs`) and on random nets
//! here.
//!
//! The points are cut into tiles of [`TILE_ROWS`] rows. One pass over the tiles per layer does,
//! for each tile while it is in cache: the previous layer's normalisation (`h = max(h * a + c, 0)`,
//! where `a`, `c` fold context norm and the optional inference-mode batch norm into one scale and
//! shift per channel, plus the residual add after a block's second layer), this layer's matrix
//! multiply, and the tile's per-channel mean and squared deviations. The tiles' moments are merged
//! in tile order (Chan et al.'s pairwise update), which gives the set's mean and variance exactly
//! and the same bits whatever the number of threads. Context norm needs the whole set's moments,
//! so that merge is the only point where tiles wait for each other. In graph models a block's
//! first multiply also computes `G x`; the neighbourhood mean over the whole set is then added in
//! one more pass over the tiles before the moments are taken.

use burn::nn::{BatchNorm, Linear};
use burn::prelude::*;

use super::gemm::matmul;
use super::{EmbeddingNet, ModelError};
use crate::data::features::knn_graph;
use crate::threads::Threads;

/// Rows per tile: large enough that a tile's matrix multiply amortises packing the weights,
/// small enough that the tile stays in L2 cache (256 x 128 floats = 128 KiB).
pub const TILE_ROWS: usize = 256;

/// A dense layer as row-major `[d_in, d_out]` weights and an optional bias `[d_out]`.
#[derive(Debug, Clone)]
struct Dense {
    weight: Vec<f32>,
    bias: Option<Vec<f32>>,
    d_in: usize,
    d_out: usize,
}

/// Inference-mode batch norm as `y = x * scale + shift`, per channel.
#[derive(Debug, Clone)]
struct Affine {
    scale: Vec<f32>,
    shift: Vec<f32>,
}

#[derive(Debug, Clone)]
struct FusedBlock {
    l1: Dense,
    /// The graph aggregation's `G` (graph models only).
    agg: Option<Dense>,
    bn1: Option<Affine>,
    l2: Dense,
    bn2: Option<Affine>,
}

/// The embedding network's weights, ready for [`FusedNet::forward`].
#[derive(Debug, Clone)]
pub struct FusedNet {
    input: Dense,
    blocks: Vec<FusedBlock>,
    output: Dense,
    cn_epsilon: f64,
    /// Leading values of an input row that are the point (the graph is built on them).
    coord_dim: usize,
    /// Points per neighbourhood of the graph aggregation; 0 = none.
    graph_neighbors: usize,
}

/// The values of a tensor as `f32`, row-major.
fn values<const D: usize>(t: Tensor<D>, what: &str) -> Result<Vec<f32>, ModelError> {
    t.into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .map_err(|e| ModelError::Config(format!("{what}: cannot read weights: {e:?}")))
}

impl Dense {
    fn from_linear(lin: &Linear, what: &str) -> Result<Self, ModelError> {
        let w = lin.weight.val();
        let [d_in, d_out] = w.dims();
        let weight = values(w, what)?;
        let bias = lin
            .bias
            .as_ref()
            .map(|b| values(b.val(), what))
            .transpose()?;
        if weight.len() != d_in * d_out || bias.as_ref().is_some_and(|b| b.len() != d_out) {
            return Err(ModelError::Config(format!(
                "{what}: unexpected weight layout"
            )));
        }
        Ok(Self {
            weight,
            bias,
            d_in,
            d_out,
        })
    }

    /// x: [n, d_in] -> out: [n, d_out] (bias added)
    fn forward(&self, x: &[f32], out: &mut [f32]) {
        matmul(x, self.d_in, &self.weight, self.d_out, out);
        if let Some(bias) = &self.bias {
            for row in out.chunks_exact_mut(self.d_out) {
                row.iter_mut().zip(bias).for_each(|(v, b)| *v += b);
            }
        }
    }
}

impl Affine {
    fn from_batch_norm(bn: &BatchNorm, what: &str) -> Result<Self, ModelError> {
        let gamma = values(bn.gamma.val(), what)?;
        let beta = values(bn.beta.val(), what)?;
        let mean = values(bn.running_mean.value(), what)?;
        let var = values(bn.running_var.value(), what)?;
        let scale: Vec<f32> = gamma
            .iter()
            .zip(&var)
            .map(|(g, v)| (f64::from(*g) / (f64::from(*v) + bn.epsilon).sqrt()) as f32)
            .collect();
        let shift = beta
            .iter()
            .zip(&mean)
            .zip(&scale)
            .map(|((b, m), s)| b - m * s)
            .collect();
        Ok(Self { scale, shift })
    }
}

/// Per-channel moments of a block of rows: count, mean and sum of squared deviations.
#[derive(Debug, Clone, PartialEq)]
struct Moments {
    count: f64,
    mean: Vec<f64>,
    m2: Vec<f64>,
}

impl Moments {
    /// Moments of the rows of h: [rows, w], by two passes (mean, then squared deviations).
    fn of(h: &[f32], w: usize) -> Self {
        let rows = h.len() / w;
        let mut acc = vec![0f32; w];
        for row in h.chunks_exact(w) {
            acc.iter_mut().zip(row).for_each(|(a, v)| *a += v);
        }
        let mean32: Vec<f32> = acc.iter().map(|a| a / rows.max(1) as f32).collect();
        acc.iter_mut().for_each(|a| *a = 0.0);
        for row in h.chunks_exact(w) {
            acc.iter_mut()
                .zip(row)
                .zip(&mean32)
                .for_each(|((a, v), m)| *a += (v - m) * (v - m));
        }
        Self {
            count: rows as f64,
            mean: mean32.iter().map(|&m| f64::from(m)).collect(),
            m2: acc.iter().map(|&a| f64::from(a)).collect(),
        }
    }

    /// The moments of the union of two disjoint blocks of rows (Chan et al.).
    fn merge(self, other: Self) -> Self {
        if self.count == 0.0 {
            return other;
        }
        let count = self.count + other.count;
        let wb = other.count / count;
        let cross = self.count * other.count / count;
        let mut mean = self.mean;
        let mut m2 = self.m2;
        for i in 0..mean.len() {
            let delta = other.mean[i] - mean[i];
            mean[i] += delta * wb;
            m2[i] += other.m2[i] + delta * delta * cross;
        }
        Self { count, mean, m2 }
    }

    /// Per channel, the scale `a` and shift `c` such that `h * a + c` is context norm over these
    /// rows (biased variance + `eps`) followed by `bn`, if any: -> (a [w], c [w])
    fn coefficients(&self, eps: f64, bn: Option<&Affine>) -> (Vec<f32>, Vec<f32>) {
        let n = self.count.max(1.0);
        let mut a: Vec<f32> = self
            .m2
            .iter()
            .map(|q| (1.0 / (q / n + eps).sqrt()) as f32)
            .collect();
        let mut c: Vec<f32> = a
            .iter()
            .zip(&self.mean)
            .map(|(a, m)| (-f64::from(*a) * m) as f32)
            .collect();
        if let Some(bn) = bn {
            for i in 0..a.len() {
                a[i] *= bn.scale[i];
                c[i] = c[i] * bn.scale[i] + bn.shift[i];
            }
        }
        (a, c)
    }
}

/// h = max(h * a + c, 0), per channel: h: [rows, w]
fn scale_relu(h: &mut [f32], a: &[f32], c: &[f32]) {
    for row in h.chunks_exact_mut(a.len()) {
        for ((v, a), c) in row.iter_mut().zip(a).zip(c) {
            *v = (*v * a + c).max(0.0);
        }
    }
}

/// x += max(h * a + c, 0), per channel: x, h: [rows, w]
fn residual_scale_relu(x: &mut [f32], h: &[f32], a: &[f32], c: &[f32]) {
    for (xr, hr) in x.chunks_exact_mut(a.len()).zip(h.chunks_exact(a.len())) {
        for (((xv, hv), a), c) in xr.iter_mut().zip(hr).zip(a).zip(c) {
            *xv += (hv * a + c).max(0.0);
        }
    }
}

/// `f` over every tile (in parallel on `threads`), the tiles' moments merged in tile order.
fn tile_moments(
    threads: &Threads,
    tiles: &mut [Tile<'_>],
    f: impl Fn(&mut Tile<'_>) -> Moments + Sync + Send,
) -> Moments {
    let parts = threads.map(tiles, f);
    parts
        .into_iter()
        .reduce(Moments::merge)
        .expect("at least one tile")
}

/// A tile's rows of every buffer of the forward pass.
struct Tile<'a> {
    /// The input features: [rows, d].
    points: &'a [f32],
    /// The residual stream: [rows, w].
    x: &'a mut [f32],
    /// A block's first and second layer: [rows, w] each.
    h: &'a mut [f32],
    h2: &'a mut [f32],
    /// The embeddings: [rows, e].
    z: &'a mut [f32],
    /// A graph block's `G x`: [rows, w] (empty without graph aggregation).
    g: &'a mut [f32],
}

/// The buffers of one forward pass, row-major over the whole set.
struct Buffers {
    x: Vec<f32>,
    h: Vec<f32>,
    h2: Vec<f32>,
    z: Vec<f32>,
    g: Vec<f32>,
}

impl Buffers {
    /// Cuts the buffers (and `points`, `[n, d]`) into tiles of [`TILE_ROWS`] rows.
    fn tiles<'a>(&'a mut self, points: &'a [f32], d: usize, w: usize, e: usize) -> Vec<Tile<'a>> {
        let gw = if self.g.is_empty() { 0 } else { w };
        let mut g = self.g.chunks_mut((TILE_ROWS * gw).max(1));
        points
            .chunks(TILE_ROWS * d)
            .zip(self.x.chunks_mut(TILE_ROWS * w))
            .zip(self.h.chunks_mut(TILE_ROWS * w))
            .zip(self.h2.chunks_mut(TILE_ROWS * w))
            .zip(self.z.chunks_mut(TILE_ROWS * e))
            .map(|((((points, x), h), h2), z)| Tile {
                points,
                x,
                h,
                h2,
                z,
                g: if gw == 0 {
                    Default::default()
                } else {
                    g.next().unwrap_or_default()
                },
            })
            .collect()
    }
}

/// h[i] += the mean over the neighbourhood of point i of g's rows, per channel, for the rows of
/// one tile starting at row `start`; returns the tile's moments of h. The neighbours are summed
/// in the graph's order (the point first), as the burn forward does.
/// h: [rows, w], g: [n, w], graph: [n, k]
fn add_neighbourhood_mean(
    h: &mut [f32],
    start: usize,
    g: &[f32],
    graph: &[usize],
    w: usize,
) -> Moments {
    let k = graph.len() / (g.len() / w).max(1);
    let inv = 1.0 / k as f32;
    let mut sum = vec![0f32; w];
    for (r, row) in h.chunks_exact_mut(w).enumerate() {
        let i = start + r;
        sum.iter_mut().for_each(|s| *s = 0.0);
        for &j in &graph[i * k..(i + 1) * k] {
            sum.iter_mut()
                .zip(&g[j * w..(j + 1) * w])
                .for_each(|(s, v)| *s += v);
        }
        row.iter_mut().zip(&sum).for_each(|(v, s)| *v += s * inv);
    }
    Moments::of(h, w)
}

impl FusedNet {
    /// Copies the weights of a burn network.
    pub fn from_net(net: &EmbeddingNet) -> Result<Self, ModelError> {
        let blocks = net
            .blocks
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let bn = |bn: &Option<BatchNorm>, what: &str| {
                    bn.as_ref()
                        .map(|bn| Affine::from_batch_norm(bn, &format!("blocks.{i}.{what}")))
                        .transpose()
                };
                Ok(FusedBlock {
                    l1: Dense::from_linear(&b.l1, &format!("blocks.{i}.l1"))?,
                    agg: b
                        .agg
                        .as_ref()
                        .map(|g| Dense::from_linear(g, &format!("blocks.{i}.agg")))
                        .transpose()?,
                    bn1: bn(&b.bn1, "bn1")?,
                    l2: Dense::from_linear(&b.l2, &format!("blocks.{i}.l2"))?,
                    bn2: bn(&b.bn2, "bn2")?,
                })
            })
            .collect::<Result<_, ModelError>>()?;
        Ok(Self {
            input: Dense::from_linear(&net.input, "input")?,
            blocks,
            output: Dense::from_linear(&net.output, "output")?,
            cn_epsilon: net.cn_epsilon,
            coord_dim: net.coord_dim,
            graph_neighbors: net.graph_neighbors,
        })
    }

    /// Values per input point.
    pub fn input_dim(&self) -> usize {
        self.input.d_in
    }

    /// Embedding dimension E.
    pub fn embed_dim(&self) -> usize {
        self.output.d_out
    }

    /// points: [n, d] row-major -> embeddings [n, e] row-major, each row of unit length.
    /// The result does not depend on `threads`, bit for bit.
    pub fn forward(&self, points: &[f32], threads: &Threads) -> Vec<f32> {
        threads.install(|| self.forward_tiles(points, threads))
    }

    /// [`FusedNet::forward`], on the threads it runs on.
    fn forward_tiles(&self, points: &[f32], threads: &Threads) -> Vec<f32> {
        let (d, w, e) = (self.input.d_in, self.input.d_out, self.output.d_out);
        let n = points.len() / d;
        let eps = self.cn_epsilon;
        let graph = if self.graph_neighbors > 0 {
            knn_graph(points, d, self.coord_dim.min(d), self.graph_neighbors)
        } else {
            Vec::new()
        };
        let mut buf = Buffers {
            x: vec![0f32; n * w],
            h: vec![0f32; n * w],
            h2: vec![0f32; n * w],
            z: vec![0f32; n * e],
            g: if graph.is_empty() {
                Vec::new()
            } else {
                vec![0f32; n * w]
            },
        };
        // A block's first multiply (from the tile's residual stream x), and for graph blocks
        // `G x` too: the moments then wait for the neighbourhood max over the whole set.
        let first_multiply = |b: &FusedBlock, t: &mut Tile<'_>| match &b.agg {
            None => {
                b.l1.forward(t.x, t.h);
                Some(Moments::of(t.h, w))
            }
            Some(agg) => {
                b.l1.forward(t.x, t.h);
                agg.forward(t.x, t.g);
                None
            }
        };
        // Finishes `first_multiply` for graph blocks: h += neighbourhood mean of G x.
        let finish = |buf: &mut Buffers, part: Option<Moments>| -> Moments {
            if let Some(m) = part {
                return m;
            }
            let g = &buf.g;
            let mut rows: Vec<(usize, &mut [f32])> = buf
                .h
                .chunks_mut(TILE_ROWS * w)
                .enumerate()
                .map(|(i, h)| (i * TILE_ROWS, h))
                .collect();
            threads
                .map(&mut rows, |(start, h)| {
                    add_neighbourhood_mean(h, *start, g, &graph, w)
                })
                .into_iter()
                .reduce(Moments::merge)
                .expect("at least one tile")
        };
        // Input layer, then the first block's first multiply.
        let first = self.blocks.first();
        let part = merged(threads.map(&mut buf.tiles(points, d, w, e), |t| {
            self.input.forward(t.points, t.x);
            match first {
                Some(b) => first_multiply(b, t),
                None => Some(Moments::of(&[], w)),
            }
        }));
        let mut moments = finish(&mut buf, part);
        for (i, block) in self.blocks.iter().enumerate() {
            let (a, c) = moments.coefficients(eps, block.bn1.as_ref());
            moments = tile_moments(threads, &mut buf.tiles(points, d, w, e), |t| {
                scale_relu(t.h, &a, &c);
                block.l2.forward(t.h, t.h2);
                Moments::of(t.h2, w)
            });
            let (a, c) = moments.coefficients(eps, block.bn2.as_ref());
            let next = self.blocks.get(i + 1);
            let part = merged(threads.map(&mut buf.tiles(points, d, w, e), |t| {
                residual_scale_relu(t.x, t.h2, &a, &c);
                match next {
                    Some(b) => first_multiply(b, t),
                    None => Some(Moments::of(&[], w)),
                }
            }));
            moments = finish(&mut buf, part);
        }
        threads.map(&mut buf.tiles(points, d, w, e), |t| {
            self.output.forward(t.x, t.z);
            for row in t.z.chunks_exact_mut(e) {
                let norm = row.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
                row.iter_mut().for_each(|v| *v /= norm);
            }
        });
        buf.z
    }
}

/// The tiles' moments merged in tile order, or None when the tiles left them to a later pass.
fn merged(parts: Vec<Option<Moments>>) -> Option<Moments> {
    parts
        .into_iter()
        .collect::<Option<Vec<Moments>>>()
        .and_then(|p| p.into_iter().reduce(Moments::merge))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{ModelConfig, cpu_device};

    fn points(n: usize, d: usize, salt: usize) -> Vec<f32> {
        (0..n * d)
            .map(|i| (((i * 7919 + salt * 104_729) % 2003) as f32 / 1001.5) - 1.0)
            .collect()
    }

    fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
    }

    #[test]
    fn matches_the_burn_forward() {
        let device = cpu_device();
        for (seed, batch_norm, neighbors, graph_neighbors) in [
            (1, false, 0, 0),
            (2, true, 0, 0),
            (3, false, 2, 0),
            (4, false, 0, 6),
            (5, true, 3, 4),
        ] {
            let cfg = ModelConfig {
                input_dim: 4,
                width: 32,
                depth: 3,
                embed_dim: 5,
                batch_norm,
                cn_epsilon: 1e-3,
                neighbors,
                graph_neighbors,
            };
            let net = cfg.init_seeded(&device, seed).unwrap();
            let fused = FusedNet::from_net(&net).unwrap();
            assert_eq!(fused.input_dim(), cfg.feature_dim());
            assert_eq!(fused.embed_dim(), 5);
            for n in [1, 2, 37, TILE_ROWS, 2 * TILE_ROWS + 45] {
                let x = points(n, cfg.feature_dim(), n);
                let want = net.embed(&x, cfg.feature_dim(), &device);
                let one = fused.forward(&x, &Threads::new(1).unwrap());
                let diff = max_abs_diff(&want, &one);
                assert!(
                    diff < 1e-4,
                    "seed {seed}, bn {batch_norm}, graph {graph_neighbors}, n {n}: {diff}"
                );
                // Bit-identical whatever the threads.
                for threads in [2, 3] {
                    assert_eq!(one, fused.forward(&x, &Threads::new(threads).unwrap()));
                }
            }
        }
    }

    #[test]
    fn batch_norm_running_statistics_are_folded_in() {
        // Non-trivial running statistics and affine parameters, set by hand.
        let device = cpu_device();
        let cfg = ModelConfig {
            input_dim: 2,
            width: 8,
            depth: 1,
            embed_dim: 3,
            batch_norm: true,
            cn_epsilon: 1e-3,
            neighbors: 0,
            graph_neighbors: 0,
        };
        let mut net = cfg.init_seeded(&device, 9).unwrap();
        let set = |v: Vec<f32>| Tensor::<1>::from_data(TensorData::new(v, [8]), &device);
        let bn = net.blocks[0].bn1.as_mut().unwrap();
        bn.running_mean =
            burn::module::RunningState::new(set((0..8).map(|i| i as f32 * 0.1).collect()));
        bn.running_var =
            burn::module::RunningState::new(set((0..8).map(|i| 0.5 + i as f32).collect()));
        bn.gamma =
            burn::module::Param::from_tensor(set((0..8).map(|i| 1.0 - i as f32 * 0.2).collect()));
        bn.beta =
            burn::module::Param::from_tensor(set((0..8).map(|i| i as f32 * 0.3 - 1.0).collect()));
        let fused = FusedNet::from_net(&net).unwrap();
        let x = points(50, 2, 4);
        let diff = max_abs_diff(
            &net.embed(&x, 2, &device),
            &fused.forward(&x, &Threads::default()),
        );
        assert!(diff < 1e-4, "{diff}");
    }

    #[test]
    fn context_norm_coefficients_by_hand() {
        // One channel with values 1, 3, 5: mean 3, variance 8/3.
        let m = Moments::of(&[1.0, 3.0, 5.0], 1);
        let (a, c) = m.coefficients(0.0, None);
        let s = 1.0 / (8.0f32 / 3.0).sqrt();
        assert!((a[0] - s).abs() < 1e-6 && (c[0] + 3.0 * s).abs() < 1e-6);
        // With batch norm y * 2 + 1 after it.
        let bn = Affine {
            scale: vec![2.0],
            shift: vec![1.0],
        };
        let (a, c) = m.coefficients(0.0, Some(&bn));
        assert!((a[0] - 2.0 * s).abs() < 1e-6 && (c[0] - (1.0 - 6.0 * s)).abs() < 1e-6);
        // A large common offset does not spoil the variance (deviations, not E[x^2] - mean^2).
        let (a, _) = Moments::of(&[1e4 + 1.0, 1e4 + 3.0, 1e4 + 5.0], 1).coefficients(0.0, None);
        assert!((a[0] - s).abs() < 1e-3, "{}", a[0]);
    }

    #[test]
    fn merged_moments_equal_the_moments_of_the_union() {
        // Two channels over 5 rows, split 2 + 3 and 4 + 1.
        let h = [1.0, -2.0, 3.0, 0.5, 5.0, 4.0, 10.0, -1.0, 2.0, 2.0];
        let all = Moments::of(&h, 2);
        assert!((all.mean[0] - 4.2).abs() < 1e-6 && (all.mean[1] - 0.7).abs() < 1e-6);
        // Channel 0: 1, 3, 5, 10, 2 -> squared deviations from 4.2 sum to 50.8.
        assert!((all.m2[0] - 50.8).abs() < 1e-4, "{:?}", all.m2);
        for cut in [2, 4] {
            let merged = Moments::of(&h[..cut * 2], 2).merge(Moments::of(&h[cut * 2..], 2));
            assert_eq!(merged.count, 5.0);
            for c in 0..2 {
                assert!((merged.mean[c] - all.mean[c]).abs() < 1e-6);
                assert!(
                    (merged.m2[c] - all.m2[c]).abs() < 1e-5,
                    "{merged:?} vs {all:?}"
                );
            }
        }
    }
}
