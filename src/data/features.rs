//! Optional local-neighbourhood input features (beyond the paper).
//!
//! A purely per-point network sees the rest of the set only through Context Normalization's
//! mean and variance, so it cannot tell which curve a 2D point lies on. Appending the offsets to
//! the `k` nearest neighbours lets it see local direction and curvature, from which the curve's
//! parameters (which all its points share) can be inferred. With `k = 0` the input is the
//! paper's.

/// For every point, its `k` nearest other points, nearest first, ties by index: exactly what
/// sorting all other points by (squared distance, index) gives. Points are the first `dim` values
/// of each `stride`-long row of `points`. -> `[n, min(k, n - 1)]` row-major indices.
///
/// A sweep over the points sorted by their first coordinate: from each point it walks outwards in
/// that order and stops in a direction once the first coordinate alone is farther than the k-th
/// best distance found. Exact (a squared distance is at least its first term, in floating point
/// too), and for 2D sets about sqrt(n) times less work than comparing all pairs (20000 points:
/// seconds to milliseconds).
pub(crate) fn nearest_all(points: &[f32], stride: usize, dim: usize, k: usize) -> Vec<usize> {
    use std::collections::BinaryHeap;
    let n = points.len() / stride;
    let take = k.min(n.saturating_sub(1));
    if take == 0 {
        return Vec::new();
    }
    let row = |i: usize| &points[i * stride..i * stride + dim];
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| row(a)[0].total_cmp(&row(b)[0]).then(a.cmp(&b)));
    let mut out = vec![0usize; n * take];
    // Max-heap of the best candidates so far, keyed by (squared distance, index); distances are
    // finite and non-negative, so their bit patterns order like their values.
    let mut heap: BinaryHeap<(u32, usize)> = BinaryHeap::with_capacity(take + 1);
    for (pos, &i) in order.iter().enumerate() {
        let p = row(i);
        heap.clear();
        let visit = |j: usize, heap: &mut BinaryHeap<(u32, usize)>| -> bool {
            let q = row(j);
            let dx = (p[0] - q[0]) * (p[0] - q[0]);
            if heap.len() == take && dx.to_bits() > heap.peek().map_or(u32::MAX, |t| t.0) {
                return false;
            }
            let d: f32 = p.iter().zip(q).map(|(a, b)| (a - b) * (a - b)).sum();
            let key = (d.to_bits(), j);
            if heap.len() < take {
                heap.push(key);
            } else if heap.peek().is_some_and(|&top| key < top) {
                heap.pop();
                heap.push(key);
            }
            true
        };
        for &j in &order[pos + 1..] {
            if !visit(j, &mut heap) {
                break;
            }
        }
        for &j in order[..pos].iter().rev() {
            if !visit(j, &mut heap) {
                break;
            }
        }
        for (slot, (_, j)) in out[i * take..(i + 1) * take]
            .iter_mut()
            .zip(std::mem::take(&mut heap).into_sorted_vec())
        {
            *slot = j;
        }
    }
    out
}

/// Points `[n, dim]` -> features `[n, dim * (1 + k)]`: each point followed by the offsets
/// (neighbour - point) to its `k` nearest other points, nearest first (ties by index); missing
/// neighbours (n - 1 < k) are zeros.
pub fn with_neighbors(points: &[f32], dim: usize, k: usize) -> Vec<f32> {
    if k == 0 {
        return points.to_vec();
    }
    let n = points.len() / dim;
    let nearest = nearest_all(points, dim, dim, k);
    let take = nearest.len() / n.max(1);
    let mut out = Vec::with_capacity(n * dim * (1 + k));
    for i in 0..n {
        let p = &points[i * dim..(i + 1) * dim];
        out.extend_from_slice(p);
        for &j in &nearest[i * take..(i + 1) * take] {
            out.extend(
                points[j * dim..(j + 1) * dim]
                    .iter()
                    .zip(p)
                    .map(|(q, a)| q - a),
            );
        }
        out.extend(std::iter::repeat_n(0.0, (k - take) * dim));
    }
    out
}

/// The neighbourhood graph of a set for the network's graph layers: for every row of
/// `features` (`[n, stride]`, its first `dim` values the point), the point itself followed by its
/// `k - 1` nearest other points (ties by index), the row padded with the point itself when
/// `n < k`: -> `[n, k]` row-major indices.
pub fn knn_graph(features: &[f32], stride: usize, dim: usize, k: usize) -> Vec<usize> {
    let n = features.len() / stride;
    if k == 0 {
        return Vec::new();
    }
    let nearest = nearest_all(features, stride, dim, k - 1);
    let take = nearest.len() / n.max(1);
    let mut out = Vec::with_capacity(n * k);
    for i in 0..n {
        out.push(i);
        out.extend_from_slice(&nearest[i * take..(i + 1) * take]);
        out.extend(std::iter::repeat_n(i, k - 1 - take));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_by_hand() {
        // Points on a line at 0, 1, 3 (1D).
        let f = with_neighbors(&[0.0, 1.0, 3.0], 1, 2);
        assert_eq!(f, vec![0.0, 1.0, 3.0, 1.0, -1.0, 2.0, 3.0, -2.0, -3.0]);
        // More neighbours than points: zero padding.
        let g = with_neighbors(&[0.0, 0.0, 1.0, 0.0], 2, 2);
        assert_eq!(
            g,
            vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0]
        );
        assert_eq!(with_neighbors(&[1.0, 2.0], 1, 0), vec![1.0, 2.0]);
    }

    #[test]
    fn permutation_equivariant() {
        let pts = [0.0f32, 0.0, 2.0, 0.5, 0.3, 1.0, -1.0, 0.7];
        let f = with_neighbors(&pts, 2, 2);
        let rev: Vec<f32> = pts.chunks(2).rev().flatten().copied().collect();
        let g = with_neighbors(&rev, 2, 2);
        let back: Vec<f32> = g.chunks(6).rev().flatten().copied().collect();
        assert_eq!(f, back);
    }

    /// All other points sorted by (squared distance, index): the definition.
    fn brute_force(points: &[f32], dim: usize, k: usize) -> Vec<usize> {
        let n = points.len() / dim;
        let row = |i: usize| &points[i * dim..(i + 1) * dim];
        let take = k.min(n.saturating_sub(1));
        (0..n)
            .flat_map(|i| {
                let mut all: Vec<(f32, usize)> = (0..n)
                    .filter(|&j| j != i)
                    .map(|j| {
                        let d: f32 = row(i)
                            .iter()
                            .zip(row(j))
                            .map(|(a, b)| (a - b) * (a - b))
                            .sum();
                        (d, j)
                    })
                    .collect();
                all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                all.into_iter()
                    .take(take)
                    .map(|(_, j)| j)
                    .collect::<Vec<_>>()
            })
            .collect()
    }

    #[test]
    fn sweep_equals_brute_force_with_ties() {
        // Points on a coarse lattice: many equal distances and equal first coordinates.
        for dim in [1, 2, 3] {
            let pts: Vec<f32> = (0..300 * dim)
                .map(|i| ((i * 7919 + i / dim * 13) % 11) as f32 * 0.5 - 2.0)
                .collect();
            for k in [1, 4, 16] {
                assert_eq!(
                    nearest_all(&pts, dim, dim, k),
                    brute_force(&pts, dim, k),
                    "dim {dim}, k {k}"
                );
            }
        }
        // Fewer points than neighbours; a single point.
        assert_eq!(
            nearest_all(&[0.0, 2.0, 1.0], 1, 1, 5),
            vec![2, 1, 2, 0, 0, 1]
        );
        assert!(nearest_all(&[1.0], 1, 1, 3).is_empty());
    }

    #[test]
    fn graph_by_hand() {
        // 1D points 0, 1, 3 inside rows of stride 2 (the second value is ignored).
        let rows = [0.0f32, 9.0, 1.0, -9.0, 3.0, 0.0];
        assert_eq!(knn_graph(&rows, 2, 1, 2), vec![0, 1, 1, 0, 2, 1]);
        assert_eq!(knn_graph(&rows, 2, 1, 3), vec![0, 1, 2, 1, 0, 2, 2, 1, 0]);
        // More neighbours than points: padded with the point itself.
        assert_eq!(knn_graph(&rows[..4], 2, 1, 3), vec![0, 1, 0, 1, 0, 1]);
        assert!(knn_graph(&rows, 2, 1, 0).is_empty());
    }

    #[test]
    fn graph_is_permutation_equivariant() {
        let pts = [0.0f32, 0.0, 2.0, 0.5, 0.3, 1.0, -1.0, 0.7, 0.1, 0.1];
        let n = pts.len() / 2;
        let g = knn_graph(&pts, 2, 2, 3);
        let rev: Vec<f32> = pts.chunks(2).rev().flatten().copied().collect();
        let h = knn_graph(&rev, 2, 2, 3);
        for i in 0..n {
            let mapped: Vec<usize> = h[(n - 1 - i) * 3..(n - i) * 3]
                .iter()
                .map(|&j| n - 1 - j)
                .collect();
            assert_eq!(mapped, g[i * 3..(i + 1) * 3]);
        }
    }
}
