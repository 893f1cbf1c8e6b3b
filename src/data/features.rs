//! Optional local-neighbourhood input features (beyond the paper).
//!
//! A purely per-point network sees the rest of the set only through Context Normalization's
//! mean and variance, so it cannot tell which curve a 2D point lies on. Appending the offsets to
//! the `k` nearest neighbours lets it see local direction and curvature, from which the curve's
//! parameters (which all its points share) can be inferred. With `k = 0` the input is the
//! paper's.

/// The `k` nearest other points of point `i` (nearest first, ties by index), by the first `dim`
/// values of each `stride`-long row of `points`; `cand` is scratch space.
fn nearest_others<'c>(
    points: &[f32],
    stride: usize,
    dim: usize,
    i: usize,
    k: usize,
    cand: &'c mut Vec<(f32, usize)>,
) -> &'c [(f32, usize)] {
    let n = points.len() / stride;
    let row = |j: usize| &points[j * stride..j * stride + dim];
    let p = row(i);
    cand.clear();
    cand.extend((0..n).filter(|&j| j != i).map(|j| {
        let d: f32 = p.iter().zip(row(j)).map(|(a, b)| (a - b) * (a - b)).sum();
        (d, j)
    }));
    let take = k.min(cand.len());
    if take > 0 && take < cand.len() {
        cand.select_nth_unstable_by(take - 1, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    }
    let nearest = &mut cand[..take];
    nearest.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    nearest
}

/// Points `[n, dim]` -> features `[n, dim * (1 + k)]`: each point followed by the offsets
/// (neighbour - point) to its `k` nearest other points, nearest first (ties by index); missing
/// neighbours (n - 1 < k) are zeros. Brute force, O(n^2 dim).
pub fn with_neighbors(points: &[f32], dim: usize, k: usize) -> Vec<f32> {
    if k == 0 {
        return points.to_vec();
    }
    let n = points.len() / dim;
    let mut out = Vec::with_capacity(n * dim * (1 + k));
    let mut cand: Vec<(f32, usize)> = Vec::with_capacity(n);
    for i in 0..n {
        let p = &points[i * dim..(i + 1) * dim];
        out.extend_from_slice(p);
        let nearest = nearest_others(points, dim, dim, i, k, &mut cand);
        for &(_, j) in nearest {
            out.extend(
                points[j * dim..(j + 1) * dim]
                    .iter()
                    .zip(p)
                    .map(|(q, a)| q - a),
            );
        }
        out.extend(std::iter::repeat_n(0.0, (k - nearest.len()) * dim));
    }
    out
}

/// The neighbourhood graph of a set for the network's graph layers: for every row of
/// `features` (`[n, stride]`, its first `dim` values the point), the point itself followed by its
/// `k - 1` nearest other points (ties by index), the row padded with the point itself when
/// `n < k`: -> `[n, k]` row-major indices. Brute force, O(n^2 dim).
pub fn knn_graph(features: &[f32], stride: usize, dim: usize, k: usize) -> Vec<usize> {
    let n = features.len() / stride;
    let mut out = Vec::with_capacity(n * k);
    let mut cand: Vec<(f32, usize)> = Vec::with_capacity(n);
    for i in 0..n {
        if k == 0 {
            break;
        }
        out.push(i);
        let nearest = nearest_others(features, stride, dim, i, k - 1, &mut cand);
        out.extend(nearest.iter().map(|&(_, j)| j));
        out.extend(std::iter::repeat_n(i, k - 1 - nearest.len()));
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
