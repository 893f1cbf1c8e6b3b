//! Single-precision matrix multiply for the serving forward pass: ndarray's safe
//! `general_mat_mul`, which runs matrixmultiply's sgemm kernels on the calling thread (the
//! forward pass splits rows across threads itself). At N = 1000, 128 x 128 on one AVX-512 core
//! (`cargo bench --bench core`): about 165 GFLOP/s, against about 115 for the `gemm` crate that
//! burn-flex uses.

use ndarray::linalg::general_mat_mul;
use ndarray::{ArrayView2, ArrayViewMut2};

/// out = a b, all row-major, on the calling thread: a: [n, k], b: [k, m] -> out: [n, m]
/// (overwritten).
///
/// # Panics
/// If the slice lengths do not match the shapes (a programming error, not an input error).
pub fn matmul(a: &[f32], k: usize, b: &[f32], m: usize, out: &mut [f32]) {
    assert!(
        k > 0 && m > 0 && a.len().is_multiple_of(k),
        "matmul: bad shapes"
    );
    let n = a.len() / k;
    let shape = "matmul: bad shapes";
    let a = ArrayView2::from_shape((n, k), a).expect(shape);
    let b = ArrayView2::from_shape((k, m), b).expect(shape);
    let mut c = ArrayViewMut2::from_shape((n, m), out).expect(shape);
    general_mat_mul(1.0, &a, &b, 0.0, &mut c);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The textbook triple loop.
    fn naive(a: &[f32], k: usize, b: &[f32], m: usize) -> Vec<f32> {
        let n = a.len() / k;
        let mut out = vec![0f32; n * m];
        for i in 0..n {
            for j in 0..m {
                out[i * m + j] = (0..k).map(|p| a[i * k + p] * b[p * m + j]).sum();
            }
        }
        out
    }

    #[test]
    fn small_product_by_hand() {
        // [1 2; 3 4; 5 6] x [1 0 2; 0 1 3]
        let mut out = vec![f32::NAN; 9];
        matmul(
            &[1., 2., 3., 4., 5., 6.],
            2,
            &[1., 0., 2., 0., 1., 3.],
            3,
            &mut out,
        );
        assert_eq!(out, vec![1., 2., 8., 3., 4., 18., 5., 6., 28.]);
    }

    #[test]
    fn product_equals_the_triple_loop() {
        for (n, k, m) in [(1, 3, 2), (130, 7, 5), (1000, 33, 17)] {
            let a: Vec<f32> = (0..n * k).map(|i| ((i * 37) % 11) as f32 - 5.0).collect();
            let b: Vec<f32> = (0..k * m).map(|i| ((i * 13) % 7) as f32 * 0.5).collect();
            let mut out = vec![f32::NAN; n * m];
            matmul(&a, k, &b, m, &mut out);
            assert_eq!(out, naive(&a, k, &b, m), "n {n}, k {k}, m {m}");
        }
    }
}
