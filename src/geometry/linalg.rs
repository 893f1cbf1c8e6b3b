//! Small dense linear algebra in f64, hand-written but for the matrix products of large Gram
//! matrices: what the estimators of this module need and nothing more.
//!
//! Matrices are row-major slices (`a[i * cols + j]`); 3 × 3 matrices are `[f64; 9]`.
//!
//! | function | method | use |
//! |---|---|---|
//! | [`sym_eigen`] | Householder tridiagonalisation + implicit QL (EISPACK `tred2`/`tql2`, as in JAMA) | scatter matrices: conics, subspaces (any size) |
//! | [`svd`] | one-sided Jacobi (Hestenes), m ≥ n | the rank-2 projection of F |
//! | [`null_vector`] | eigenvector of AᵀA for its smallest eigenvalue | the (normalised) DLT and 8-point systems A·h = 0 |
//! | [`solve`] | Gaussian elimination, partial pivoting | normal equations (Kåsa, Levenberg–Marquardt) |
//! | [`outer_gram`], [`inner_gram`] | A·Aᵀ and Aᵀ·A by matrixmultiply's dgemm (through ndarray) | the scatter and Gram matrices of motion subspaces |
//!
//! Everything here is deterministic and never panics on finite input; singular systems answer
//! `None`.

/// A·Aᵀ of the m × d row-major matrix `a`: m × m, row-major, symmetric.
pub fn outer_gram(a: &[f64], m: usize, d: usize) -> Vec<f64> {
    let view = ndarray::ArrayView2::from_shape((m, d), a).expect("outer_gram: bad shape");
    let mut out = ndarray::Array2::<f64>::zeros((m, m));
    ndarray::linalg::general_mat_mul(1.0, &view, &view.t(), 0.0, &mut out);
    symmetric(out.into_raw_vec_and_offset().0, m)
}

/// Aᵀ·A of the m × d row-major matrix `a`: d × d, row-major, symmetric.
pub fn inner_gram(a: &[f64], m: usize, d: usize) -> Vec<f64> {
    let view = ndarray::ArrayView2::from_shape((m, d), a).expect("inner_gram: bad shape");
    let mut out = ndarray::Array2::<f64>::zeros((d, d));
    ndarray::linalg::general_mat_mul(1.0, &view.t(), &view, 0.0, &mut out);
    symmetric(out.into_raw_vec_and_offset().0, d)
}

/// The n × n matrix `s` made exactly symmetric (its lower triangle copied up): a product's two
/// triangles may differ in round-off.
fn symmetric(mut s: Vec<f64>, n: usize) -> Vec<f64> {
    for i in 0..n {
        for j in 0..i {
            s[j * n + i] = s[i * n + j];
        }
    }
    s
}

/// A 3 × 3 matrix, row-major.
pub type Mat3 = [f64; 9];

/// The 3 × 3 identity.
pub const IDENTITY3: Mat3 = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];

/// `a · b` for 3 × 3 matrices.
pub fn mat3_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [0.0; 9];
    for i in 0..3 {
        for j in 0..3 {
            out[i * 3 + j] = (0..3).map(|k| a[i * 3 + k] * b[k * 3 + j]).sum();
        }
    }
    out
}

/// `aᵀ` for a 3 × 3 matrix.
pub fn mat3_transpose(a: &Mat3) -> Mat3 {
    [a[0], a[3], a[6], a[1], a[4], a[7], a[2], a[5], a[8]]
}

/// `a · v` for a 3 × 3 matrix and a 3-vector.
pub fn mat3_vec(a: &Mat3, v: [f64; 3]) -> [f64; 3] {
    [
        a[0] * v[0] + a[1] * v[1] + a[2] * v[2],
        a[3] * v[0] + a[4] * v[1] + a[5] * v[2],
        a[6] * v[0] + a[7] * v[1] + a[8] * v[2],
    ]
}

/// The determinant of a 3 × 3 matrix.
pub fn mat3_det(a: &Mat3) -> f64 {
    a[0] * (a[4] * a[8] - a[5] * a[7]) - a[1] * (a[3] * a[8] - a[5] * a[6])
        + a[2] * (a[3] * a[7] - a[4] * a[6])
}

/// The inverse of a 3 × 3 matrix by the adjugate, or `None` when it is singular to working
/// precision (|det| ≤ 1e-13 · ‖a‖³, Frobenius norm) or not finite.
pub fn mat3_inverse(a: &Mat3) -> Option<Mat3> {
    let norm = a.iter().map(|v| v * v).sum::<f64>().sqrt();
    let det = mat3_det(a);
    if !det.is_finite() || !norm.is_finite() || det.abs() <= 1e-13 * norm * norm * norm {
        return None;
    }
    let adj = [
        a[4] * a[8] - a[5] * a[7],
        a[2] * a[7] - a[1] * a[8],
        a[1] * a[5] - a[2] * a[4],
        a[5] * a[6] - a[3] * a[8],
        a[0] * a[8] - a[2] * a[6],
        a[2] * a[3] - a[0] * a[5],
        a[3] * a[7] - a[4] * a[6],
        a[1] * a[6] - a[0] * a[7],
        a[0] * a[4] - a[1] * a[3],
    ];
    Some(adj.map(|v| v / det))
}

/// The rotation by the axis-angle vector `w` (angle ‖w‖ radians about w/‖w‖), Rodrigues'
/// formula; the identity for w = 0.
pub fn rodrigues(w: [f64; 3]) -> Mat3 {
    let angle = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
    if angle < 1e-300 {
        return IDENTITY3;
    }
    let (x, y, z) = (w[0] / angle, w[1] / angle, w[2] / angle);
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        t * x * x + c,
        t * x * y - s * z,
        t * x * z + s * y,
        t * x * y + s * z,
        t * y * y + c,
        t * y * z - s * x,
        t * x * z - s * y,
        t * y * z + s * x,
        t * z * z + c,
    ]
}

/// Scales a 9-vector (a 3 × 3 matrix up to scale) to unit norm, with the sign that makes
/// `m[8] > 0`; when `m[8] == 0` exactly, the first non-zero entry is made positive. `None` for a
/// zero or non-finite input. This is the gauge of every homogeneous matrix this module returns.
pub fn unit_norm_sign(m: &Mat3) -> Option<Mat3> {
    let norm = m.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !(norm.is_finite() && norm > 0.0) {
        return None;
    }
    let pivot = if m[8] != 0.0 {
        m[8]
    } else {
        m.iter().copied().find(|v| *v != 0.0).unwrap_or(1.0)
    };
    let s = if pivot < 0.0 { -1.0 / norm } else { 1.0 / norm };
    Some(m.map(|v| v * s))
}

/// Symmetric eigen-decomposition of an n × n matrix (only the lower triangle is read).
#[derive(Debug, Clone)]
pub struct SymEigen {
    /// Eigenvalues, ascending.
    pub values: Vec<f64>,
    /// n × n, row-major; column j is the unit eigenvector of `values[j]`.
    pub vectors: Vec<f64>,
    pub n: usize,
}

impl SymEigen {
    /// Column `j` (the eigenvector of `values[j]`).
    pub fn vector(&self, j: usize) -> Vec<f64> {
        (0..self.n).map(|i| self.vectors[i * self.n + j]).collect()
    }
}

/// Eigen-decomposition of the symmetric n × n matrix `a` (row-major): Householder reduction to
/// a tridiagonal matrix, then implicit QL with Wilkinson-like shifts (EISPACK `tred2`/`tql2`,
/// the JAMA formulation). O(n³), backward stable; eigenvalues ascending.
pub fn sym_eigen(a: &[f64], n: usize) -> SymEigen {
    debug_assert_eq!(a.len(), n * n);
    if n == 0 {
        return SymEigen {
            values: Vec::new(),
            vectors: Vec::new(),
            n,
        };
    }
    // Symmetrise from the lower triangle so that callers may fill only that.
    let mut v = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            v[i * n + j] = a[i * n + j];
            v[j * n + i] = a[i * n + j];
        }
    }
    let mut d = vec![0.0; n];
    let mut e = vec![0.0; n];
    tred2(&mut v, &mut d, &mut e, n);
    tql2(&mut v, &mut d, &mut e, n);
    SymEigen {
        values: d,
        vectors: v,
        n,
    }
}

/// Householder tridiagonalisation: on return `d` is the diagonal, `e[1..]` the sub-diagonal and
/// `v` the accumulated orthogonal transform.
fn tred2(v: &mut [f64], d: &mut [f64], e: &mut [f64], n: usize) {
    let at = |i: usize, j: usize| i * n + j;
    for j in 0..n {
        d[j] = v[at(n - 1, j)];
    }
    for i in (1..n).rev() {
        let mut h = 0.0;
        let scale: f64 = d[..i].iter().map(|v| v.abs()).sum();
        if scale == 0.0 {
            e[i] = d[i - 1];
            for j in 0..i {
                d[j] = v[at(i - 1, j)];
                v[at(i, j)] = 0.0;
                v[at(j, i)] = 0.0;
            }
        } else {
            for dk in d[..i].iter_mut() {
                *dk /= scale;
                h += *dk * *dk;
            }
            let mut f = d[i - 1];
            let mut g = h.sqrt();
            if f > 0.0 {
                g = -g;
            }
            e[i] = scale * g;
            h -= f * g;
            d[i - 1] = f - g;
            for ej in e.iter_mut().take(i) {
                *ej = 0.0;
            }
            for j in 0..i {
                f = d[j];
                v[at(j, i)] = f;
                g = e[j] + v[at(j, j)] * f;
                for k in (j + 1)..i {
                    g += v[at(k, j)] * d[k];
                    e[k] += v[at(k, j)] * f;
                }
                e[j] = g;
            }
            f = 0.0;
            for j in 0..i {
                e[j] /= h;
                f += e[j] * d[j];
            }
            let hh = f / (h + h);
            for j in 0..i {
                e[j] -= hh * d[j];
            }
            for j in 0..i {
                f = d[j];
                g = e[j];
                for k in j..i {
                    v[at(k, j)] -= f * e[k] + g * d[k];
                }
                d[j] = v[at(i - 1, j)];
                v[at(i, j)] = 0.0;
            }
        }
        d[i] = h;
    }
    for i in 0..n - 1 {
        v[at(n - 1, i)] = v[at(i, i)];
        v[at(i, i)] = 1.0;
        let h = d[i + 1];
        if h != 0.0 {
            for k in 0..=i {
                d[k] = v[at(k, i + 1)] / h;
            }
            for j in 0..=i {
                let mut g = 0.0;
                for k in 0..=i {
                    g += v[at(k, i + 1)] * v[at(k, j)];
                }
                for k in 0..=i {
                    v[at(k, j)] -= g * d[k];
                }
            }
        }
        for k in 0..=i {
            v[at(k, i + 1)] = 0.0;
        }
    }
    for j in 0..n {
        d[j] = v[at(n - 1, j)];
        v[at(n - 1, j)] = 0.0;
    }
    v[at(n - 1, n - 1)] = 1.0;
    e[0] = 0.0;
}

/// √(x² + y²), by the plain formula where the squares cannot overflow or underflow, else by
/// `hypot` (several times slower).
#[inline]
fn fast_hypot(x: f64, y: f64) -> f64 {
    let m = x.abs().max(y.abs());
    if m > 1e-150 && m < 1e150 {
        (x * x + y * y).sqrt()
    } else {
        x.hypot(y)
    }
}

/// Implicit QL on the tridiagonal (d, e), accumulating into `v`; sorts ascending.
fn tql2(v: &mut [f64], d: &mut [f64], e: &mut [f64], n: usize) {
    let at = |i: usize, j: usize| i * n + j;
    for i in 1..n {
        e[i - 1] = e[i];
    }
    e[n - 1] = 0.0;
    let mut f = 0.0;
    let mut tst1: f64 = 0.0;
    let eps = f64::EPSILON;
    for l in 0..n {
        tst1 = tst1.max(d[l].abs() + e[l].abs());
        let mut m = l;
        while m < n - 1 && e[m].abs() > eps * tst1 {
            m += 1;
        }
        if m > l {
            // At most 60 QL sweeps per eigenvalue (it takes 2–3 in practice).
            for _ in 0..60 {
                let mut g = d[l];
                let mut p = (d[l + 1] - g) / (2.0 * e[l]);
                let mut r = fast_hypot(p, 1.0);
                if p < 0.0 {
                    r = -r;
                }
                d[l] = e[l] / (p + r);
                d[l + 1] = e[l] * (p + r);
                let dl1 = d[l + 1];
                let mut h = g - d[l];
                for di in d.iter_mut().skip(l + 2) {
                    *di -= h;
                }
                f += h;
                p = d[m];
                let mut c = 1.0;
                let mut c2 = c;
                let mut c3 = c;
                let el1 = e[l + 1];
                let mut s = 0.0;
                let mut s2 = 0.0;
                for i in (l..m).rev() {
                    c3 = c2;
                    c2 = c;
                    s2 = s;
                    g = c * e[i];
                    h = c * p;
                    r = fast_hypot(p, e[i]);
                    e[i + 1] = s * r;
                    s = e[i] / r;
                    c = p / r;
                    p = c * d[i] - s * g;
                    d[i + 1] = h + s * (c * g + s * d[i]);
                    for k in 0..n {
                        h = v[at(k, i + 1)];
                        v[at(k, i + 1)] = s * v[at(k, i)] + c * h;
                        v[at(k, i)] = c * v[at(k, i)] - s * h;
                    }
                }
                p = -s * s2 * c3 * el1 * e[l] / dl1;
                e[l] = s * p;
                d[l] = c * p;
                if !(e[l].abs() > eps * tst1) {
                    break;
                }
            }
        }
        d[l] += f;
        e[l] = 0.0;
    }
    // Selection sort, ascending, moving the vectors along.
    for i in 0..n.saturating_sub(1) {
        let mut k = i;
        for j in (i + 1)..n {
            if d[j] < d[k] {
                k = j;
            }
        }
        if k != i {
            d.swap(i, k);
            for r in 0..n {
                v.swap(at(r, i), at(r, k));
            }
        }
    }
}

/// The `r` largest eigenpairs of the symmetric positive semi-definite d × d matrix `s`
/// (row-major, full): block orthogonal iteration V ← orth(S·V) with a Rayleigh–Ritz step, from
/// a deterministic start (the r columns of S of largest norm), until the residual
/// ‖S·V − V·(VᵀSV)‖ falls below 1e-12 of ‖VᵀSV‖ or 60 iterations. O(d²·r) an iteration instead
/// of [`sym_eigen`]'s O(d³): for the top few directions of a large scatter matrix. Converges
/// at the rate λ_{r+1}/λ_r: fast across a signal/noise gap; inside a cluster of equal
/// eigenvalues the vectors stay a (correct) basis of the cluster only to the tolerance reached.
/// Eigenvalues descending, vectors unit and orthogonal.
pub fn top_eigen(s: &[f64], d: usize, r: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    let r = r.min(d);
    if r == 0 {
        return (Vec::new(), Vec::new());
    }
    // S·v for each vector v of a block, as one product V·S (S is symmetric).
    let sv = ndarray::ArrayView2::from_shape((d, d), s).expect("top_eigen: bad shape");
    let times = |v: &[Vec<f64>]| -> Vec<Vec<f64>> {
        let flat: Vec<f64> = v.iter().flatten().copied().collect();
        let block = ndarray::ArrayView2::from_shape((v.len(), d), &flat).expect("block");
        let mut out = ndarray::Array2::<f64>::zeros((v.len(), d));
        ndarray::linalg::general_mat_mul(1.0, &block, &sv, 0.0, &mut out);
        out.rows().into_iter().map(|row| row.to_vec()).collect()
    };
    // Start: the columns of S (= S·eᵢ) of largest norm, then the unit vectors, orthonormalised.
    let mut order: Vec<usize> = (0..d).collect();
    let col_norm: Vec<f64> = (0..d)
        .map(|j| (0..d).map(|i| s[i * d + j] * s[i * d + j]).sum::<f64>())
        .collect();
    order.sort_by(|&a, &b| col_norm[b].total_cmp(&col_norm[a]));
    let candidates = order
        .iter()
        .map(|&j| (0..d).map(|i| s[i * d + j]).collect::<Vec<f64>>())
        .chain((0..d).map(|j| (0..d).map(|i| if i == j { 1.0 } else { 0.0 }).collect()));
    let mut v = orthonormal_basis(candidates, r);
    let mut t = vec![0.0; r * r];
    for _ in 0..60 {
        let w = times(&v);
        // T = Vᵀ S V and the residual S V − V T.
        for a in 0..r {
            for b in 0..r {
                t[a * r + b] = v[a].iter().zip(&w[b]).map(|(x, y)| x * y).sum();
            }
        }
        let t_norm = t.iter().map(|x| x * x).sum::<f64>().sqrt();
        let mut res = 0.0;
        for b in 0..r {
            for i in 0..d {
                let proj: f64 = (0..r).map(|a| v[a][i] * t[a * r + b]).sum();
                res += (w[b][i] - proj).powi(2);
            }
        }
        if !(t_norm > 0.0) || res.sqrt() <= 1e-12 * t_norm {
            break;
        }
        let next = orthonormal_basis(w.into_iter().chain(v.clone()), r);
        v = next;
    }
    // Rayleigh–Ritz: rotate V by the eigenvectors of T (recomputed for the final V).
    let w = times(&v);
    for a in 0..r {
        for b in 0..r {
            t[a * r + b] = 0.5
                * (v[a].iter().zip(&w[b]).map(|(x, y)| x * y).sum::<f64>()
                    + v[b].iter().zip(&w[a]).map(|(x, y)| x * y).sum::<f64>());
        }
    }
    let e = sym_eigen(&t, r);
    let mut values = Vec::with_capacity(r);
    let mut vectors = Vec::with_capacity(r);
    for k in (0..r).rev() {
        values.push(e.values[k].max(0.0));
        let mut x = vec![0.0; d];
        for (a, va) in v.iter().enumerate() {
            let c = e.vectors[a * r + k];
            x.iter_mut().zip(va).for_each(|(xi, vi)| *xi += c * vi);
        }
        vectors.push(x);
    }
    (values, vectors)
}

/// The first `r` vectors of `candidates` that are not (numerically) in the span of the ones
/// before, orthonormalised by modified Gram–Schmidt (twice, for orthogonality to round-off).
fn orthonormal_basis(candidates: impl Iterator<Item = Vec<f64>>, r: usize) -> Vec<Vec<f64>> {
    let mut basis: Vec<Vec<f64>> = Vec::with_capacity(r);
    for mut x in candidates {
        if basis.len() == r {
            break;
        }
        let before = x.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !(before > 0.0) || !before.is_finite() {
            continue;
        }
        for _ in 0..2 {
            for b in &basis {
                let p: f64 = x.iter().zip(b).map(|(u, v)| u * v).sum();
                x.iter_mut().zip(b).for_each(|(u, v)| *u -= p * v);
            }
        }
        let after = x.iter().map(|v| v * v).sum::<f64>().sqrt();
        if after > 1e-10 * before {
            x.iter_mut().for_each(|v| *v /= after);
            basis.push(x);
        }
    }
    basis
}

/// A thin singular value decomposition `a = u · diag(s) · vᵀ` of an m × n matrix, m ≥ n.
#[derive(Debug, Clone)]
pub struct Svd {
    /// m × n, row-major, orthonormal columns (a column is zero where its `s` is zero).
    pub u: Vec<f64>,
    /// n singular values, descending.
    pub s: Vec<f64>,
    /// n × n, row-major, orthogonal; column j is the right singular vector of `s[j]`.
    pub v: Vec<f64>,
    pub m: usize,
    pub n: usize,
}

impl Svd {
    /// Right singular vector j (column j of v).
    pub fn right(&self, j: usize) -> Vec<f64> {
        (0..self.n).map(|i| self.v[i * self.n + j]).collect()
    }
}

/// SVD of the m × n matrix `a` (row-major, m ≥ n) by one-sided Jacobi rotations (Hestenes):
/// columns are rotated pairwise until all are mutually orthogonal to relative precision ε;
/// the singular values are then their norms. Accurate in the small singular values too, which
/// is what null vectors need.
pub fn svd(a: &[f64], m: usize, n: usize) -> Svd {
    debug_assert!(m >= n && a.len() == m * n);
    // Work on columns: w[j] is column j of a (length m), vt[j] column j of v.
    let mut w: Vec<Vec<f64>> = (0..n)
        .map(|j| (0..m).map(|i| a[i * n + j]).collect())
        .collect();
    let mut vt: Vec<Vec<f64>> = (0..n)
        .map(|j| (0..n).map(|i| if i == j { 1.0 } else { 0.0 }).collect())
        .collect();
    // Columns below ε·‖a‖ are zero to working precision: rotating them against the others only
    // stirs round-off (and would never converge).
    let frob2: f64 = a.iter().map(|v| v * v).sum();
    let negligible = f64::EPSILON * f64::EPSILON * frob2;
    for _sweep in 0..60 {
        let mut rotated = false;
        for p in 0..n {
            for q in (p + 1)..n {
                let (alpha, beta, gamma) = w[p]
                    .iter()
                    .zip(&w[q])
                    .fold((0.0, 0.0, 0.0), |(a, b, g), (x, y)| {
                        (a + x * x, b + y * y, g + x * y)
                    });
                if gamma == 0.0
                    || alpha <= negligible
                    || beta <= negligible
                    || gamma.abs() <= f64::EPSILON * (alpha * beta).sqrt()
                {
                    continue;
                }
                rotated = true;
                let zeta = (beta - alpha) / (2.0 * gamma);
                let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
                let c = 1.0 / (1.0 + t * t).sqrt();
                let s = c * t;
                let (lo, hi) = w.split_at_mut(q);
                for (x, y) in lo[p].iter_mut().zip(hi[0].iter_mut()) {
                    let (xp, yq) = (*x, *y);
                    *x = c * xp - s * yq;
                    *y = s * xp + c * yq;
                }
                let (lo, hi) = vt.split_at_mut(q);
                for (x, y) in lo[p].iter_mut().zip(hi[0].iter_mut()) {
                    let (xp, yq) = (*x, *y);
                    *x = c * xp - s * yq;
                    *y = s * xp + c * yq;
                }
            }
        }
        if !rotated {
            break;
        }
    }
    let norms: Vec<f64> = w
        .iter()
        .map(|c| c.iter().map(|x| x * x).sum::<f64>().sqrt())
        .collect();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| norms[j].total_cmp(&norms[i]));
    let mut u = vec![0.0; m * n];
    let mut v = vec![0.0; n * n];
    let mut s = vec![0.0; n];
    for (k, &j) in order.iter().enumerate() {
        s[k] = norms[j];
        if norms[j] > 0.0 {
            for i in 0..m {
                u[i * n + k] = w[j][i] / norms[j];
            }
        }
        for i in 0..n {
            v[i * n + k] = vt[j][i];
        }
    }
    Svd { u, s, v, m, n }
}

/// The null vector of a homogeneous system A·x = 0 given as rows of N values: the right
/// singular vector of the smallest singular value, with all N singular values (descending).
///
/// Computed from the eigen-decomposition of AᵀA ([`sym_eigen`]), accumulated row by row
/// (N(N+1)/2 multiply-adds a row, no copy of A): this squares A's condition number, which is
/// harmless for the Hartley-normalised DLT and 8-point systems it serves (their geometric
/// refinement then polishes the answer), but it resolves singular values only down to
/// ~1e-8 of the largest. `None` for fewer rows than N − 1 or non-finite rows.
pub fn null_vector<const N: usize>(rows: &[[f64; N]]) -> Option<([f64; N], [f64; N])> {
    if rows.len() + 1 < N || rows.iter().flatten().any(|v| !v.is_finite()) {
        return None;
    }
    let mut ata = vec![0.0; N * N];
    for r in rows {
        for i in 0..N {
            let ri = r[i];
            if ri == 0.0 {
                continue;
            }
            for (a, rj) in ata[i * N..i * N + i + 1].iter_mut().zip(r.iter()) {
                *a += ri * rj;
            }
        }
    }
    let e = sym_eigen(&ata, N);
    let mut x = [0.0; N];
    for (i, xi) in x.iter_mut().enumerate() {
        *xi = e.vectors[i * N];
    }
    let mut s = [0.0; N];
    for (k, sk) in s.iter_mut().enumerate() {
        *sk = e.values[N - 1 - k].max(0.0).sqrt();
    }
    Some((x, s))
}

/// Solves the n × n system `a · x = b` (row-major) by Gaussian elimination with partial
/// pivoting. `None` when a pivot is zero or below 1e-14 × the largest entry of `a` (singular to
/// working precision), or when the answer is not finite.
pub fn solve(a: &[f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    debug_assert!(a.len() == n * n && b.len() == n);
    let mut m = a.to_vec();
    let mut x = b.to_vec();
    let scale = m.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    for k in 0..n {
        let p = (k..n).max_by(|&i, &j| m[i * n + k].abs().total_cmp(&m[j * n + k].abs()))?;
        if !(m[p * n + k].abs() > 1e-14 * scale) {
            return None;
        }
        if p != k {
            for j in 0..n {
                m.swap(k * n + j, p * n + j);
            }
            x.swap(k, p);
        }
        for i in (k + 1)..n {
            let f = m[i * n + k] / m[k * n + k];
            if f == 0.0 {
                continue;
            }
            for j in k..n {
                m[i * n + j] -= f * m[k * n + j];
            }
            x[i] -= f * x[k];
        }
    }
    for k in (0..n).rev() {
        let s: f64 = ((k + 1)..n).map(|j| m[k * n + j] * x[j]).sum();
        x[k] = (x[k] - s) / m[k * n + k];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Eigen-decomposition of a symmetric 2 × 2 matrix [[p, q], [q, r]]: (larger eigenvalue,
/// smaller eigenvalue, angle of the larger one's eigenvector from +x in (−π/2, π/2]).
pub fn sym2_eigen(p: f64, q: f64, r: f64) -> (f64, f64, f64) {
    let mean = 0.5 * (p + r);
    let radius = (0.5 * (p - r)).hypot(q);
    let angle = 0.5 * (2.0 * q).atan2(p - r);
    (mean + radius, mean - radius, angle)
}

/// √(x² + y²) without `hypot`'s overflow guard (several times faster; the fits keep
/// coordinates within ±1e150, so the squares stay finite; elsewhere an overflow gives an
/// infinite distance, which is the right answer far away).
#[inline]
pub fn norm2(x: f64, y: f64) -> f64 {
    (x * x + y * y).sqrt()
}

/// The median of `values` (reorders them; the mean of the two middle values for even lengths;
/// NaN sorts last, so one NaN among many does not spread). 0 for an empty slice.
pub fn median(values: &mut [f64]) -> f64 {
    let n = values.len();
    if n == 0 {
        return 0.0;
    }
    let mid = n / 2;
    let (lower, upper, _) = values.select_nth_unstable_by(mid, f64::total_cmp);
    let hi = *upper;
    if n % 2 == 1 {
        hi
    } else {
        let lo = lower.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lo + hi)
    }
}

#[cfg(test)]
mod tests {
    use super::super::testutil::Rng;
    use super::*;

    fn random_matrix(rng: &mut Rng, m: usize, n: usize) -> Vec<f64> {
        (0..m * n).map(|_| rng.normal()).collect()
    }

    #[test]
    fn sym_eigen_reconstructs_random_symmetric_matrices() {
        let mut rng = Rng::new(1);
        for n in [1, 2, 3, 5, 9, 20, 60] {
            let b = random_matrix(&mut rng, n, n);
            let a: Vec<f64> = (0..n * n)
                .map(|k| {
                    let (i, j) = (k / n, k % n);
                    b[i * n + j] + b[j * n + i]
                })
                .collect();
            let e = sym_eigen(&a, n);
            assert!(e.values.windows(2).all(|w| w[0] <= w[1]), "ascending");
            for i in 0..n {
                for j in 0..n {
                    // V Λ Vᵀ = A and Vᵀ V = I.
                    let rec: f64 = (0..n)
                        .map(|k| e.vectors[i * n + k] * e.values[k] * e.vectors[j * n + k])
                        .sum();
                    assert!(
                        (rec - a[i * n + j]).abs() < 1e-10 * n as f64,
                        "n={n} A[{i},{j}]"
                    );
                    let dot: f64 = (0..n)
                        .map(|k| e.vectors[k * n + i] * e.vectors[k * n + j])
                        .sum();
                    let want = if i == j { 1.0 } else { 0.0 };
                    assert!((dot - want).abs() < 1e-12, "n={n} orthonormal");
                }
            }
        }
    }

    #[test]
    fn gram_products_match_the_triple_loop() {
        let mut rng = Rng::new(6);
        for (m, d) in [(1, 1), (3, 7), (40, 9), (17, 120)] {
            let a = random_matrix(&mut rng, m, d);
            let (outer, inner) = (outer_gram(&a, m, d), inner_gram(&a, m, d));
            for (n, got, at) in [
                (
                    m,
                    &outer,
                    &(|i: usize, k: usize| a[i * d + k]) as &dyn Fn(usize, usize) -> f64,
                ),
                (d, &inner, &|i: usize, k: usize| a[k * d + i]),
            ] {
                let len = if n == m { d } else { m };
                for i in 0..n {
                    for j in 0..n {
                        let want: f64 = (0..len).map(|k| at(i, k) * at(j, k)).sum();
                        assert!((got[i * n + j] - want).abs() < 1e-12 * (1.0 + want.abs()));
                        assert_eq!(got[i * n + j], got[j * n + i]);
                    }
                }
            }
        }
    }

    #[test]
    fn top_eigen_matches_sym_eigen() {
        let mut rng = Rng::new(4);
        // A scatter with a clear top 3 (signal) over a noise floor, and one of exact rank 2.
        for (n, d, signal, noise) in [(200, 60, 3, 0.1), (100, 10, 2, 0.0)] {
            let dirs = random_matrix(&mut rng, signal, d);
            let mut s = vec![0.0; d * d];
            for _ in 0..n {
                let mut x: Vec<f64> = (0..d).map(|_| noise * rng.normal()).collect();
                for k in 0..signal {
                    let c = (10.0 - k as f64) * rng.normal();
                    x.iter_mut()
                        .zip(&dirs[k * d..(k + 1) * d])
                        .for_each(|(xi, di)| *xi += c * di);
                }
                for i in 0..d {
                    for j in 0..d {
                        s[i * d + j] += x[i] * x[j];
                    }
                }
            }
            let full = sym_eigen(&s, d);
            let (values, vectors) = top_eigen(&s, d, signal);
            for k in 0..signal {
                let want = full.values[d - 1 - k];
                assert!(
                    (values[k] - want).abs() < 1e-9 * want,
                    "{k}: {} vs {want}",
                    values[k]
                );
                let dot: f64 = vectors[k]
                    .iter()
                    .zip(full.vector(d - 1 - k))
                    .map(|(a, b)| a * b)
                    .sum();
                assert!((dot.abs() - 1.0).abs() < 1e-9, "{k}: {dot}");
            }
        }
    }

    #[test]
    fn sym_eigen_handles_diagonal_zero_and_repeated() {
        let e = sym_eigen(&[3.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 2.0], 3);
        assert_eq!(e.values, vec![1.0, 2.0, 3.0]);
        let e = sym_eigen(&[0.0; 16], 4);
        assert!(e.values.iter().all(|v| *v == 0.0));
        let e = sym_eigen(&[2.0, 0.0, 0.0, 2.0], 2);
        assert_eq!(e.values, vec![2.0, 2.0]);
    }

    #[test]
    fn svd_reconstructs_and_orders() {
        let mut rng = Rng::new(2);
        for (m, n) in [(3, 3), (9, 9), (40, 9), (5, 2)] {
            let a = random_matrix(&mut rng, m, n);
            let d = svd(&a, m, n);
            assert!(d.s.windows(2).all(|w| w[0] >= w[1]));
            for i in 0..m {
                for j in 0..n {
                    let rec: f64 = (0..n)
                        .map(|k| d.u[i * n + k] * d.s[k] * d.v[j * n + k])
                        .sum();
                    assert!((rec - a[i * n + j]).abs() < 1e-12 * (m as f64), "({m},{n})");
                }
            }
            for i in 0..n {
                for j in 0..n {
                    let vv: f64 = (0..n).map(|k| d.v[k * n + i] * d.v[k * n + j]).sum();
                    let uu: f64 = (0..m).map(|k| d.u[k * n + i] * d.u[k * n + j]).sum();
                    let want = if i == j { 1.0 } else { 0.0 };
                    assert!((vv - want).abs() < 1e-12 && (uu - want).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn svd_of_rank_deficient_matrix_has_exact_zero_singular_values() {
        // Rank 2: third column = first + second.
        let a = [1.0, 2.0, 3.0, 4.0, 5.0, 9.0, -1.0, 0.5, -0.5, 2.0, 2.0, 4.0];
        let d = svd(&a, 4, 3);
        assert!(d.s[2] < 1e-14 * d.s[0], "{:?}", d.s);
    }

    #[test]
    fn null_vector_of_tall_system() {
        let mut rng = Rng::new(3);
        let x_true = [0.3, -0.2, 0.5, 0.1, 0.7, -0.4, 0.2, 0.1, 0.25];
        // Rows orthogonal to x_true: random rows minus their projection.
        let nrm: f64 = x_true.iter().map(|v| v * v).sum();
        let rows: Vec<[f64; 9]> = (0..50)
            .map(|_| {
                let mut r = [0.0; 9];
                for v in r.iter_mut() {
                    *v = rng.normal();
                }
                let d: f64 = r.iter().zip(&x_true).map(|(a, b)| a * b).sum::<f64>() / nrm;
                for (v, t) in r.iter_mut().zip(&x_true) {
                    *v -= d * t;
                }
                r
            })
            .collect();
        let (x, s) = null_vector(&rows).unwrap();
        let cos: f64 = x.iter().zip(&x_true).map(|(a, b)| a * b).sum::<f64>() / nrm.sqrt();
        assert!((cos.abs() - 1.0).abs() < 1e-14, "{cos}");
        // Through AᵀA a zero singular value comes out at ≲ 1e-8 of the largest.
        assert!(s[8] < 1e-7 * s[0] && s[7] > 0.1 * s[0] / 9.0, "{s:?}");
        assert!(null_vector::<9>(&rows[..3]).is_none());
    }

    #[test]
    fn solve_and_inverse() {
        let a = [4.0, 1.0, 2.0, 1.0, 3.0, 0.5, 2.0, 0.5, 5.0];
        let x = solve(&a, &[1.0, 2.0, 3.0], 3).unwrap();
        let back = mat3_vec(&a, [x[0], x[1], x[2]]);
        assert!((back[0] - 1.0).abs() < 1e-14 && (back[2] - 3.0).abs() < 1e-14);
        let inv = mat3_inverse(&a).unwrap();
        let id = mat3_mul(&a, &inv);
        for (v, w) in id.iter().zip(IDENTITY3.iter()) {
            assert!((v - w).abs() < 1e-14);
        }
        assert!(solve(&[1.0, 2.0, 2.0, 4.0], &[1.0, 1.0], 2).is_none());
        assert!(mat3_inverse(&[1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 1.0, 1.0]).is_none());
        assert!(mat3_inverse(&[0.0; 9]).is_none());
    }

    #[test]
    fn median_and_sign_gauge() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(&mut []), 0.0);
        assert_eq!(median(&mut [1.0, f64::INFINITY, 2.0]), 2.0);
        let m = unit_norm_sign(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -2.0]).unwrap();
        assert_eq!(m[8], 1.0);
        let m = unit_norm_sign(&[0.0, -3.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 0.0]).unwrap();
        assert!((m[1] - 0.6).abs() < 1e-15);
        assert!(unit_norm_sign(&[0.0; 9]).is_none());
    }

    #[test]
    fn sym2_eigen_angle() {
        // Major direction at 30°.
        let t = 30f64.to_radians();
        let (c, s) = (t.cos(), t.sin());
        let (p, q, r) = (4.0 * c * c + s * s, 3.0 * c * s, 4.0 * s * s + c * c);
        let (l1, l2, a) = sym2_eigen(p, q, r);
        assert!((l1 - 4.0).abs() < 1e-14 && (l2 - 1.0).abs() < 1e-14 && (a - t).abs() < 1e-14);
    }
}
