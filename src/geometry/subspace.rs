//! Trajectories under an affine camera: affine motion subspaces.
//!
//! A track of F frames is the 2F-vector x = [x₁, y₁, …, x_F, y_F]. Under an affine camera the
//! tracks of one rigid motion satisfy x = m + M·X (X the 3-D point): they lie in an affine
//! subspace of dimension ≤ 3 (a linear one of dimension ≤ 4); planar or degenerate motions give
//! 1–2.
//!
//! **Fit.** The (weighted) mean m of the group's tracks, then the principal directions of the
//! centred 2F × n block C: the eigenvectors of the scatter C·W·Cᵀ (2F × 2F) when n ≥ 2F, or,
//! for few tracks, of the Gram matrix W^½·CᵀC·W^½ (n × n) mapped back by C·W^½·v/√λ. The basis is
//! the top r unit eigenvectors (rows of length 2F, orthonormal).
//!
//! **Rank.** r ∈ [min(2, r_max), r_max], r_max = min(4, n − 2, 2F − 1), minimises the
//! GRIC-like criterion (Torr 1998, with data dimension D = 2F and manifold dimension r)
//! Σᵢ min(eᵢ(r)²/s², 2(D − r)) + ln(D)·r·n + ln(D·n)·(D + r(D − r)),
//! eᵢ(r) the distance of track i to the rank-r subspace and s the per-coordinate noise estimated
//! robustly from the rank-r_max residuals: s² = median eᵢ(r_max)² / median χ²(D − r_max). The
//! rank is chosen on all tracks (capped at 3, a rigid motion's affine rank), the subspace of
//! that rank is fitted robustly, and the rank is chosen again (up to 4) on its inliers alone:
//! a foreign group inside the tracks must not buy itself a dimension.
//!
//! **Residual.** The distance of a track to the affine subspace divided by √F: the RMS over
//! frames of the per-frame 2-D distance (pixels); with noise σ per coordinate it is ≈ √2·σ
//! (as for a 2-D point off a point).

use std::marker::PhantomData;

use super::linalg::{inner_gram, median, outer_gram, solve, sym_eigen, top_eigen};
use super::robust::{Estimator, Robust, SIGMA_FLOOR, evaluate, fit_robust};
use super::{GeometryError, Model};

/// Above this many coordinates (2F), or tracks where there are fewer tracks than coordinates,
/// the top directions come from orthogonal iteration ([`top_eigen`]) rather than a full
/// eigen-decomposition.
const FULL_EIGEN_MAX: usize = 16;
/// Highest rank tried.
pub const MAX_RANK: usize = 4;
/// The affine rank of one rigid motion under an affine camera: the rank of the robust fit
/// before the inliers may raise it.
pub const RIGID_RANK: usize = 3;

/// [`subspace_distance`] over the frames a track was seen in (`seen`, one flag per frame):
/// the distance of the seen coordinates to the subspace restricted to them, the track's
/// coefficients on the basis fitted by least squares on those coordinates alone, divided by
/// √(frames seen). INFINITY when the lengths disagree or the seen frames do not determine the
/// coefficients (fewer seen coordinates than basis rows, or a restricted basis without full
/// rank).
pub fn masked_subspace_distance(
    mean: &[f64],
    basis: &[Vec<f64>],
    row: &[f64],
    seen: &[bool],
) -> f64 {
    let d = mean.len();
    let r = basis.len();
    if row.len() != d || 2 * seen.len() != d || basis.iter().any(|b| b.len() != d) {
        return f64::INFINITY;
    }
    let coords: Vec<usize> = (0..d).filter(|&c| seen[c / 2]).collect();
    if coords.len() <= r {
        return f64::INFINITY;
    }
    // Normal equations G a = B_V y of the coefficients a, y = (row - mean) on the seen
    // coordinates V; G = B_V B_Vᵀ (r × r).
    let y: Vec<f64> = coords.iter().map(|&c| row[c] - mean[c]).collect();
    let mut g = vec![0.0; r * r];
    let mut b = vec![0.0; r];
    for i in 0..r {
        for j in i..r {
            let v: f64 = coords.iter().map(|&c| basis[i][c] * basis[j][c]).sum();
            g[i * r + j] = v;
            g[j * r + i] = v;
        }
        b[i] = coords.iter().zip(&y).map(|(&c, v)| basis[i][c] * v).sum();
    }
    let a = if r == 0 {
        Vec::new()
    } else if let Some(a) = solve(&g, &b, r) {
        a
    } else {
        return f64::INFINITY;
    };
    let e2: f64 = coords
        .iter()
        .zip(&y)
        .map(|(&c, v)| {
            let fitted: f64 = (0..r).map(|i| a[i] * basis[i][c]).sum();
            (v - fitted).powi(2)
        })
        .sum();
    let frames = coords.len() as f64 / 2.0;
    let out = (e2 / frames).sqrt();
    if out.is_finite() { out } else { f64::INFINITY }
}

/// An affine subspace: mean and orthonormal basis rows (length 2F each).
#[derive(Debug, Clone, PartialEq)]
pub struct SubspaceParams {
    pub mean: Vec<f64>,
    pub basis: Vec<Vec<f64>>,
}

/// Distance of `row` to the affine subspace (mean, basis), divided by √F (F = len / 2);
/// INFINITY when the lengths disagree.
pub fn subspace_distance(mean: &[f64], basis: &[Vec<f64>], row: &[f64]) -> f64 {
    let d = mean.len();
    if row.len() != d || d < 2 || basis.iter().any(|b| b.len() != d) {
        return f64::INFINITY;
    }
    // |c|² less the squared coordinates of the centred track c on the basis rows (they are
    // orthonormal), both from one pass with c formed on the fly: no allocation on this path,
    // which every reassignment takes for every track and structure. Round-off in the
    // difference is about 1e-16 |c|², far below any noise level.
    if basis.len() > MAX_RANK {
        // Not a fitted model (fits stop at MAX_RANK): projections removed one at a time.
        let mut c: Vec<f64> = row.iter().zip(mean).map(|(x, m)| x - m).collect();
        for b in basis {
            let p: f64 = c.iter().zip(b).map(|(x, y)| x * y).sum();
            c.iter_mut().zip(b).for_each(|(x, y)| *x -= p * y);
        }
        return (c.iter().map(|v| v * v).sum::<f64>() / (d / 2) as f64).sqrt();
    }
    let (c2, coords) = centred_projections(mean, basis, row);
    let coords = &coords[..basis.len()];
    let mut e2 = c2 - coords.iter().map(|p| p * p).sum::<f64>();
    if e2 < EXACT_BELOW * c2 {
        // Near the subspace the difference cancels: what the coordinates leave, summed.
        e2 = leftover2(mean, basis, row, coords);
    }
    (e2 / (d / 2) as f64).sqrt()
}

/// A squared distance below this share of the centred track's squared norm is summed from what
/// the projections leave rather than taken as a difference (which would keep only about
/// 1e-16 / EXACT_BELOW of its digits).
const EXACT_BELOW: f64 = 1e-8;

/// |c − Σ_k p_k b_k|² for the centred track c = row − mean and its coordinates `coords` on the
/// `basis` rows (as many as `coords`): the squared distance, summed term by term.
fn leftover2(mean: &[f64], basis: &[Vec<f64>], row: &[f64], coords: &[f64]) -> f64 {
    let d = row.len();
    let whole = d - d % LANES;
    let mut acc = [0.0f64; LANES];
    for o in (0..whole).step_by(LANES) {
        let mut c = [0.0f64; LANES];
        for l in 0..LANES {
            c[l] = row[o + l] - mean[o + l];
        }
        for (p, b) in coords.iter().zip(basis) {
            let b = &b[o..o + LANES];
            for l in 0..LANES {
                c[l] -= p * b[l];
            }
        }
        for l in 0..LANES {
            acc[l] += c[l] * c[l];
        }
    }
    let mut e2: f64 = acc.iter().sum();
    for j in whole..d {
        let mut c = row[j] - mean[j];
        for (p, b) in coords.iter().zip(basis) {
            c -= p * b[j];
        }
        e2 += c * c;
    }
    e2
}

/// Lanes of the one-pass sums in [`centred_projections`].
const LANES: usize = 8;

/// For the centred track c = row − mean: (|c|², the coordinates c·b of c on each basis row),
/// in one pass over the track with [`LANES`] partial sums per quantity. `basis` holds at most
/// [`MAX_RANK`] rows of the track's length (coordinates past its length are 0).
fn centred_projections(mean: &[f64], basis: &[Vec<f64>], row: &[f64]) -> (f64, [f64; MAX_RANK]) {
    let d = row.len();
    let r = basis.len().min(MAX_RANK);
    let mut acc = [[0.0f64; LANES]; MAX_RANK];
    let mut acc_c = [0.0f64; LANES];
    let whole = d - d % LANES;
    for o in (0..whole).step_by(LANES) {
        let mut c = [0.0f64; LANES];
        for l in 0..LANES {
            c[l] = row[o + l] - mean[o + l];
            acc_c[l] += c[l] * c[l];
        }
        for (a, b) in acc.iter_mut().zip(&basis[..r]) {
            let b = &b[o..o + LANES];
            for l in 0..LANES {
                a[l] += c[l] * b[l];
            }
        }
    }
    let mut c2: f64 = acc_c.iter().sum();
    let mut coords = [0.0f64; MAX_RANK];
    for (p, a) in coords.iter_mut().zip(&acc) {
        *p = a.iter().sum();
    }
    for j in whole..d {
        let c = row[j] - mean[j];
        c2 += c * c;
        for (p, b) in coords.iter_mut().zip(&basis[..r]) {
            *p += c * b[j];
        }
    }
    (c2, coords)
}

/// (mean, basis rows, eigenvalues descending) of [`principal`].
type Principal = (Vec<f64>, Vec<Vec<f64>>, Vec<f64>);

/// The weighted mean, the top `max_rank` principal directions (unit, orthogonal) and the
/// largest eigenvalues of the weighted scatter, descending (all of them for small blocks, the
/// top `max_rank` for large ones).
/// `Err` when the weighted tracks all coincide.
fn principal(
    tracks: &[&[f64]],
    weights: &[f64],
    max_rank: usize,
) -> Result<Principal, GeometryError> {
    let d = tracks.first().map_or(0, |t| t.len());
    let active: Vec<usize> = (0..tracks.len()).filter(|&i| weights[i] > 0.0).collect();
    let sw: f64 = active.iter().map(|&i| weights[i]).sum();
    if active.is_empty() || !(sw > 0.0) {
        return Err(GeometryError::NoWeightedTrajectories);
    }
    let mut mean = vec![0.0; d];
    for &i in &active {
        for (m, x) in mean.iter_mut().zip(tracks[i]) {
            *m += weights[i] * x;
        }
    }
    mean.iter_mut().for_each(|m| *m /= sw);
    // Centred, √w-scaled tracks: row i of the m × d block, in one buffer.
    let mut flat = Vec::with_capacity(active.len() * d);
    for &i in &active {
        let s = weights[i].sqrt();
        flat.extend(tracks[i].iter().zip(&mean).map(|(x, m)| s * (x - m)));
    }
    let m = active.len();
    let (values, basis): (Vec<f64>, Vec<Vec<f64>>) = if m >= d {
        top_directions(&inner_gram(&flat, m, d), d, max_rank)
    } else {
        let (values, vectors) = top_directions(&outer_gram(&flat, m, d), m, max_rank);
        let centred: Vec<&[f64]> = flat.chunks_exact(d.max(1)).collect();
        let mut basis: Vec<Vec<f64>> = Vec::new();
        for v in vectors {
            let mut u = vec![0.0; d];
            for (c, vi) in centred.iter().zip(&v) {
                for (uj, cj) in u.iter_mut().zip(*c) {
                    *uj += vi * cj;
                }
            }
            // Re-orthogonalise against the previous directions (round-off), then normalise.
            for b in &basis {
                let p: f64 = u.iter().zip(b).map(|(x, y)| x * y).sum();
                u.iter_mut().zip(b).for_each(|(x, y)| *x -= p * y);
            }
            let n = u.iter().map(|x| x * x).sum::<f64>().sqrt();
            if !(n > 0.0) {
                break;
            }
            u.iter_mut().for_each(|x| *x /= n);
            basis.push(u);
        }
        (values, basis)
    };
    let top = values.first().copied().unwrap_or(0.0);
    let magnitude = mean.iter().map(|v| v.abs()).fold(0.0, f64::max);
    if !(top > 0.0) || top.sqrt() <= 1e-12 * magnitude * sw.sqrt() {
        return Err(GeometryError::CoincidentTrajectories);
    }
    // Directions of (numerically) zero variance carry no information: drop them.
    let useful = values.iter().take_while(|&&v| v > 1e-24 * top).count();
    let mut basis = basis;
    basis.truncate(useful.max(1));
    Ok((mean, basis, values))
}

/// The eigenvalues (descending: all of them for n ≤ [`FULL_EIGEN_MAX`], else the top `r`) and
/// the top `r` unit eigenvectors of the symmetric n × n matrix `s`: a full decomposition for
/// small matrices; orthogonal iteration for large ones, where a full one would cost O(n³) and
/// only the top directions are needed.
fn top_directions(s: &[f64], n: usize, r: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    if n > FULL_EIGEN_MAX {
        return top_eigen(s, n, r.min(n));
    }
    let e = sym_eigen(s, n);
    let values = e.values.iter().rev().map(|v| v.max(0.0)).collect();
    let vectors = (0..r.min(n)).map(|k| e.vector(n - 1 - k)).collect();
    (values, vectors)
}

/// Squared distances of the tracks to (mean, basis[..r]) for every r in 0..=basis.len():
/// `out[r][i]`.
fn residuals_by_rank(tracks: &[&[f64]], mean: &[f64], basis: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let r = basis.len().min(MAX_RANK);
    let mut out = vec![Vec::with_capacity(tracks.len()); r + 1];
    for t in tracks {
        let (c2, coords) = centred_projections(mean, &basis[..r], t);
        let mut left = c2;
        out[0].push(left);
        for (k, p) in coords[..r].iter().enumerate() {
            left -= p * p;
            if left < EXACT_BELOW * c2 {
                // Near the subspace: what the projections leave, summed (as subspace_distance).
                left = leftover2(mean, &basis[..=k], t, &coords[..=k]);
            }
            out[k + 1].push(left);
        }
    }
    out
}

/// Median of χ²(k) (Wilson–Hilferty).
fn chi2_median(k: usize) -> f64 {
    let k = k as f64;
    k * (1.0 - 2.0 / (9.0 * k)).powi(3)
}

/// The rank of the tracks by the criterion of the module docs; `scale` is the residual
/// scale that floors the noise.
fn select_rank(tracks: &[&[f64]], scale: f64) -> Result<usize, GeometryError> {
    let n = tracks.len();
    let d = tracks[0].len();
    let r_max = MAX_RANK.min(n.saturating_sub(2)).min(d - 1).max(1);
    let (mean, basis, _) = principal(tracks, &vec![1.0; n], r_max)?;
    let r_max = r_max.min(basis.len());
    let r_min = 2.min(r_max);
    if r_min == r_max {
        return Ok(r_max);
    }
    let res = residuals_by_rank(tracks, &mean, &basis);
    let mut top = res[r_max].clone();
    let floor = (SIGMA_FLOOR * scale).powi(2) * (d / 2) as f64;
    let s2 = (median(&mut top) / chi2_median(d - r_max)).max(floor);
    let (nf, df) = (n as f64, d as f64);
    let criterion = |r: usize| -> f64 {
        let cap = 2.0 * (d - r) as f64;
        let fit: f64 = res[r].iter().map(|e2| (e2 / s2).min(cap)).sum();
        fit + df.ln() * r as f64 * nf + (df * nf).ln() * (df + (r * (d - r)) as f64)
    };
    Ok((r_min..=r_max)
        .min_by(|&a, &b| criterion(a).total_cmp(&criterion(b)))
        .unwrap_or(r_min))
}

/// The subspace of a fixed rank. Points are the tracks (2F values each).
pub struct SubspaceEstimator<'a> {
    pub rank: usize,
    rows: PhantomData<&'a [f64]>,
}

impl SubspaceEstimator<'_> {
    /// The estimator of rank `rank`.
    pub fn new(rank: usize) -> Self {
        Self {
            rank,
            rows: PhantomData,
        }
    }
}

impl<'a> Estimator for SubspaceEstimator<'a> {
    type Point = &'a [f64];
    type Params = SubspaceParams;

    fn min_points(&self) -> usize {
        self.rank + 1
    }

    fn fit(&self, points: &[&'a [f64]], weights: &[f64]) -> Result<SubspaceParams, GeometryError> {
        let (mean, basis, _) = principal(points, weights, self.rank)?;
        Ok(SubspaceParams { mean, basis })
    }

    fn refine(&self, params: SubspaceParams, _: &[&'a [f64]], _: &[f64]) -> SubspaceParams {
        params
    }

    fn residual(&self, p: &SubspaceParams, row: &&'a [f64]) -> f64 {
        subspace_distance(&p.mean, &p.basis, row)
    }
}

/// The per-frame RMS spread of the tracks about their mean (pixels): the residual's scale.
fn track_scale(tracks: &[&[f64]]) -> f64 {
    let d = tracks[0].len();
    let n = tracks.len() as f64;
    let mean: Vec<f64> = (0..d)
        .map(|j| tracks.iter().map(|t| t[j]).sum::<f64>() / n)
        .collect();
    let ss: f64 = tracks
        .iter()
        .map(|t| {
            t.iter()
                .zip(&mean)
                .map(|(x, m)| (x - m).powi(2))
                .sum::<f64>()
        })
        .sum();
    (ss / (n * (d / 2) as f64)).sqrt()
}

/// Fits the affine subspace of the tracks robustly, its rank chosen as in the module docs.
/// Tracks must be validated (same even length ≥ 4, finite).
pub fn fit_subspace(tracks: &[&[f64]]) -> Result<Robust<SubspaceParams>, GeometryError> {
    let n = tracks.len();
    if n < 3 {
        return Err(GeometryError::TooFewTrajectories { n, min: 3 });
    }
    let scale = track_scale(tracks);
    // A first rank on all tracks, at most the rigid-motion rank 3: a higher one would let the
    // subspace swallow a foreign group (its offset is one more direction).
    let rank = select_rank(tracks, scale)?.min(RIGID_RANK);
    let est = SubspaceEstimator::new(rank);
    let robust = fit_robust(&est, tracks, scale)?;
    // The rank once more, on the inliers alone (up to MAX_RANK).
    let inl: Vec<&[f64]> = tracks
        .iter()
        .zip(&robust.inliers)
        .filter(|(_, v)| **v)
        .map(|(t, _)| *t)
        .collect();
    if inl.len() < 3 {
        return Ok(robust);
    }
    let final_rank = select_rank(&inl, scale)?;
    if final_rank == rank {
        return Ok(robust);
    }
    let est2 = SubspaceEstimator::new(final_rank);
    let w: Vec<f64> = robust
        .inliers
        .iter()
        .map(|&v| if v { 1.0 } else { 0.0 })
        .collect();
    match est2.fit(tracks, &w) {
        Ok(p) => Ok(evaluate(&est2, p, tracks, scale)),
        Err(_) => Ok(robust),
    }
}

/// The wire model.
pub fn subspace_model(p: &SubspaceParams) -> Model {
    Model::Subspace {
        rank: p.basis.len(),
        mean: p.mean.clone(),
        basis: p.basis.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::super::testutil::{Rng, assert_sane, is_degenerate, rotation, view};
    use super::super::{Family, Model, fit, fit_type};
    use super::*;

    /// `n` tracks of one rigid motion under an affine camera over `frames` frames: a 3-D
    /// point cloud (spread `depth` in z) rotating and translating, image = s·(first two rows of
    /// R_f)·X + t_f (pixels), noise σ per coordinate.
    fn rigid_tracks(
        rng: &mut Rng,
        n: usize,
        frames: usize,
        depth: f64,
        sigma: f64,
        seed_motion: f64,
    ) -> Vec<Vec<f64>> {
        let points: Vec<[f64; 3]> = (0..n)
            .map(|_| {
                [
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    depth * rng.range(-1.0, 1.0),
                ]
            })
            .collect();
        let cams: Vec<([f64; 9], [f64; 2])> = (0..frames)
            .map(|f| {
                let a = f as f64 / frames as f64;
                let r = rotation([0.3 * a + seed_motion, -0.5 * a, 0.2 * a * seed_motion]);
                (r, [320.0 + 40.0 * a, 240.0 - 25.0 * a])
            })
            .collect();
        points
            .iter()
            .map(|x| {
                let mut row = Vec::with_capacity(2 * frames);
                for (r, t) in &cams {
                    for k in 0..2 {
                        let v = 150.0
                            * (r[k * 3] * x[0] + r[k * 3 + 1] * x[1] + r[k * 3 + 2] * x[2])
                            + t[k];
                        row.push(v + sigma * rng.normal());
                    }
                }
                row
            })
            .collect()
    }

    fn rank_of(m: &Model) -> usize {
        match m {
            Model::Subspace { rank, basis, mean } => {
                assert_eq!(*rank, basis.len());
                for (i, b) in basis.iter().enumerate() {
                    assert_eq!(b.len(), mean.len());
                    for (j, c) in basis.iter().enumerate() {
                        let dot: f64 = b.iter().zip(c).map(|(x, y)| x * y).sum();
                        let want = if i == j { 1.0 } else { 0.0 };
                        assert!((dot - want).abs() < 1e-10, "basis not orthonormal");
                    }
                }
                *rank
            }
            m => panic!("{m:?}"),
        }
    }

    /// Over the frames a track was seen in, a track of the subspace is on it whatever its
    /// other values; a track off it is not; too few seen coordinates give INFINITY, never NaN.
    #[test]
    fn masked_distance_reads_only_the_seen_frames() {
        // Rank 2 in 8 coordinates (4 frames): x moves by u, y by w, frame to frame.
        let mean = vec![1.0, 2.0, 1.0, 2.0, 1.0, 2.0, 1.0, 2.0];
        let s = 0.5;
        let basis = [
            vec![0.0, 0.0, s, 0.0, 2.0 * s, 0.0, 3.0 * s, 0.0],
            vec![0.0, 0.0, 0.0, s, 0.0, 2.0 * s, 0.0, 3.0 * s],
        ];
        let norm = |b: &Vec<f64>| b.iter().map(|v| v * v).sum::<f64>().sqrt();
        let basis: Vec<Vec<f64>> = basis
            .iter()
            .map(|b| b.iter().map(|v| v / norm(b)).collect())
            .collect();
        let on = [1.0, 2.0, 3.0, 1.0, 5.0, 0.0, 7.0, -1.0];
        let seen = [true, true, true, true];
        assert!(subspace_distance(&mean, &basis, &on) < 1e-12);
        assert!(masked_subspace_distance(&mean, &basis, &on, &seen) < 1e-12);
        // Frame 2 unseen, garbage there: still on it.
        let mut hidden = on;
        hidden[4] = 1e6;
        hidden[5] = -3e5;
        let partly = [true, true, false, true];
        assert!(masked_subspace_distance(&mean, &basis, &hidden, &partly) < 1e-9);
        assert!(subspace_distance(&mean, &basis, &hidden) > 1e3);
        // Off it in a seen frame.
        let mut off = on;
        off[6] += 4.0;
        let d = masked_subspace_distance(&mean, &basis, &off, &partly);
        assert!(d > 0.1 && d.is_finite(), "{d}");
        // One seen frame: 2 coordinates for 2 coefficients determine nothing.
        assert_eq!(
            masked_subspace_distance(&mean, &basis, &on, &[true, false, false, false]),
            f64::INFINITY
        );
        // Wrong lengths.
        assert_eq!(
            masked_subspace_distance(&mean, &basis, &on[..6], &partly),
            f64::INFINITY
        );
        assert_eq!(
            masked_subspace_distance(&mean, &basis, &on, &[true, true]),
            f64::INFINITY
        );
    }

    #[test]
    fn noise_free_rigid_motion_has_zero_residual() {
        for frames in [5, 30] {
            let mut rng = Rng::new(frames as u64);
            let rows = rigid_tracks(&mut rng, 100, frames, 0.5, 0.0, 0.1);
            let fit = fit(Family::Subspace, &view(&rows));
            assert_sane(&fit, rows.len());
            assert!(fit.rms < 1e-9, "F = {frames}: rms {}", fit.rms);
            assert_eq!(rank_of(&fit.model), 3, "F = {frames}");
            assert!(fit.inliers.iter().all(|&v| v));
        }
    }

    #[test]
    fn noisy_rigid_motion() {
        for frames in [5, 30] {
            let mut rng = Rng::new(100 + frames as u64);
            let rows = rigid_tracks(&mut rng, 200, frames, 0.5, 1.0, 0.2);
            let fit = fit(Family::Subspace, &view(&rows));
            assert_sane(&fit, rows.len());
            let r = rank_of(&fit.model);
            assert!((2..=4).contains(&r), "F = {frames}: rank {r}");
            // Residual per frame ≈ √(2(D − r)/D)·σ ≤ √2.
            assert!(fit.rms < 1.5, "F = {frames}: rms {}", fit.rms);
            assert!(fit.inliers.iter().filter(|&&v| v).count() >= 195);
        }
    }

    #[test]
    fn planar_motion_has_lower_rank() {
        // Points on a plane z = 0 translating only: x = m + a·X + b·Y (rank 2).
        let mut rng = Rng::new(7);
        let rows = rigid_tracks(&mut rng, 80, 6, 0.0, 0.0, 0.0);
        let fit = fit_type("subspace", &view(&rows)).unwrap();
        assert!(rank_of(&fit.model) <= 2);
        assert!(fit.rms < 1e-9);
    }

    #[test]
    fn ten_percent_foreign_tracks() {
        let mut rng = Rng::new(8);
        let mut rows = rigid_tracks(&mut rng, 90, 8, 0.5, 0.5, 0.1);
        // Tracks of another, independent motion.
        rows.extend(
            rigid_tracks(&mut rng, 10, 8, 0.5, 0.5, 1.3)
                .into_iter()
                .map(|mut r| {
                    for (j, v) in r.iter_mut().enumerate() {
                        *v += 30.0 * (j as f64 * 0.7).sin();
                    }
                    r
                }),
        );
        let fit = fit(Family::Subspace, &view(&rows));
        assert_sane(&fit, rows.len());
        assert!(
            fit.inliers[90..].iter().all(|&v| !v),
            "{:?}",
            &fit.inliers[90..]
        );
        assert!(fit.inliers[..90].iter().filter(|&&v| v).count() >= 87);
        let clean = rigid_tracks(&mut Rng::new(8), 90, 8, 0.5, 0.5, 0.1);
        let truth = fit_type("subspace", &view(&clean)).unwrap();
        assert!(fit.rms < truth.rms * 1.2, "{} vs {}", fit.rms, truth.rms);
    }

    #[test]
    fn few_tracks_use_the_gram_matrix() {
        // 6 tracks of 30 frames: n < 2F.
        let mut rng = Rng::new(9);
        let rows = rigid_tracks(&mut rng, 6, 30, 0.5, 0.0, 0.1);
        let fit = fit_type("subspace", &view(&rows)).unwrap();
        assert_sane(&fit, rows.len());
        assert!(fit.rms < 1e-9, "{}", fit.rms);
        assert!(rank_of(&fit.model) <= 4);
    }

    #[test]
    fn many_tracks_but_fewer_than_coordinates_take_the_top_of_the_gram_matrix() {
        // 40 tracks of 60 frames (16 < n < 2F): the Gram matrix's top directions by orthogonal
        // iteration, exact on noise-free tracks and within the noise on noisy ones.
        let mut rng = Rng::new(12);
        let clean = rigid_tracks(&mut rng, 40, 60, 0.5, 0.0, 0.1);
        let fit = fit_type("subspace", &view(&clean)).unwrap();
        assert_sane(&fit, clean.len());
        assert!(fit.rms < 1e-9, "{}", fit.rms);
        let noisy = rigid_tracks(&mut Rng::new(12), 40, 60, 0.5, 0.5, 0.1);
        let fit = fit_type("subspace", &view(&noisy)).unwrap();
        assert_sane(&fit, noisy.len());
        // Per-frame 2-D distance of noise 0.5 per coordinate, less what rank 3-4 absorbs.
        assert!(fit.rms > 0.4 && fit.rms < 0.75, "{}", fit.rms);
    }

    #[test]
    fn degenerate_subspaces() {
        let two = vec![vec![1.0, 2.0, 3.0, 4.0], vec![2.0, 3.0, 4.0, 5.0]];
        let same = vec![vec![1.0, 2.0, 3.0, 4.0]; 10];
        let odd = vec![vec![1.0, 2.0, 3.0]; 10];
        let one_frame = vec![vec![1.0, 2.0]; 10];
        for rows in [&two, &same, &odd, &one_frame] {
            let fit = fit(Family::Subspace, &view(rows));
            assert!(is_degenerate(&fit), "{fit:?}");
            assert_sane(&fit, rows.len());
        }
    }

    #[test]
    fn distance_divides_by_root_f() {
        let mean = vec![0.0; 4];
        let basis = vec![vec![1.0, 0.0, 0.0, 0.0]];
        // Off by (0, 3, 0, 4): distance 5 over F = 2 frames.
        let d = subspace_distance(&mean, &basis, &[7.0, 3.0, 0.0, 4.0]);
        assert!((d - 5.0 / 2f64.sqrt()).abs() < 1e-15);
        assert_eq!(subspace_distance(&mean, &basis, &[1.0, 2.0]), f64::INFINITY);
    }

    #[test]
    fn distance_is_what_the_basis_leaves_at_every_rank() {
        // Coordinate axes of R^6 as the basis, offset mean: the distance is the norm of the
        // coordinates past the rank, for the fitted ranks (up to MAX_RANK) and beyond.
        let mean = [1.0, -2.0, 0.5, 3.0, 0.0, 4.0];
        let row = [2.0, 0.0, 3.5, 7.0, 5.0, 16.0];
        let centred: Vec<f64> = row.iter().zip(&mean).map(|(x, m)| x - m).collect();
        for rank in 0..=5 {
            let basis: Vec<Vec<f64>> = (0..rank)
                .map(|k| (0..6).map(|j| if j == k { 1.0 } else { 0.0 }).collect())
                .collect();
            let left: f64 = centred[rank..].iter().map(|c| c * c).sum();
            let want = (left / 3.0).sqrt();
            let d = subspace_distance(&mean, &basis, &row);
            assert!((d - want).abs() < 1e-12, "rank {rank}: {d} against {want}");
        }
    }

    #[test]
    fn one_pass_distances_match_projections_removed_one_at_a_time() {
        // Random orthonormal bases (Gram–Schmidt) of every fitted rank in lengths around the
        // one-pass lanes, tracks at pixel offsets of hundreds with small and zero residuals.
        let mut rng = Rng::new(11);
        for d in [4, 6, 8, 10, 16, 22, 40, 62] {
            for rank in 1..=MAX_RANK.min(d - 1) {
                let mut basis: Vec<Vec<f64>> = Vec::new();
                while basis.len() < rank {
                    let mut v: Vec<f64> = (0..d).map(|_| rng.normal()).collect();
                    for b in &basis {
                        let p: f64 = v.iter().zip(b).map(|(x, y)| x * y).sum();
                        v.iter_mut().zip(b).for_each(|(x, y)| *x -= p * y);
                    }
                    let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
                    basis.push(v.iter().map(|x| x / n).collect());
                }
                let mean: Vec<f64> = (0..d).map(|_| rng.range(0.0, 1000.0)).collect();
                for noise in [0.0, 0.5, 30.0] {
                    let mut row = mean.clone();
                    for b in &basis {
                        let a = rng.range(-300.0, 300.0);
                        row.iter_mut().zip(b).for_each(|(x, y)| *x += a * y);
                    }
                    row.iter_mut().for_each(|x| *x += noise * rng.normal());
                    let mut c: Vec<f64> = row.iter().zip(&mean).map(|(x, m)| x - m).collect();
                    for b in &basis {
                        let p: f64 = c.iter().zip(b).map(|(x, y)| x * y).sum();
                        c.iter_mut().zip(b).for_each(|(x, y)| *x -= p * y);
                    }
                    let want = (c.iter().map(|v| v * v).sum::<f64>() / (d / 2) as f64).sqrt();
                    let got = subspace_distance(&mean, &basis, &row);
                    // Exact near the subspace (noise 0), to round-off elsewhere.
                    assert!(
                        got.is_finite() && (got - want).abs() < 1e-9 + 1e-7 * want,
                        "d {d} rank {rank} noise {noise}: {got} against {want}"
                    );
                }
            }
        }
    }
}
