//! Optional local-neighbourhood input features (beyond the paper).
//!
//! A purely per-point network sees the rest of the set only through Context Normalization's
//! mean and variance, so it cannot tell which curve a 2D point lies on. Appending the offsets to
//! the `k` nearest neighbours lets it see local direction and curvature, from which the curve's
//! parameters (which all its points share) can be inferred. With `k = 0` the input is the
//! paper's.

/// Points `[n, dim]` -> features `[n, dim * (1 + k)]`: each point followed by the offsets
/// (neighbour - point) to its `k` nearest other points, nearest first (ties by index); missing
/// neighbours (n - 1 < k) are zeros. Brute force, O(n^2 dim).
pub fn with_neighbors(points: &[f32], dim: usize, k: usize) -> Vec<f32> {
    if k == 0 {
        return points.to_vec();
    }
    let n = points.len() / dim;
    let row = |i: usize| &points[i * dim..(i + 1) * dim];
    let mut out = Vec::with_capacity(n * dim * (1 + k));
    let mut cand: Vec<(f32, usize)> = Vec::with_capacity(n);
    for i in 0..n {
        let p = row(i);
        out.extend_from_slice(p);
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
        for &(_, j) in nearest.iter() {
            out.extend(row(j).iter().zip(p).map(|(q, a)| q - a));
        }
        out.extend(std::iter::repeat_n(0.0, (k - take) * dim));
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
}
