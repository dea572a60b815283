//! The small dense linear algebra the embedding needs.

/// Relative size under which a Cholesky pivot counts as zero. The kernels'
/// matrices are either well conditioned (condition number about 711 for
/// paper kernels at J = 15) or exactly singular (a 2-cell axis), so any
/// threshold far between rounding noise (1e-16) and the smallest genuine
/// pivot works.
const PIVOT_TOL: f64 = 1e-10;

/// Cholesky factor of a symmetric positive semi-definite `n x n` matrix `k`
/// (row-major): upper triangular `R` with `K = R^T R`.
///
/// A pivot that vanishes (relative to the diagonal entry it came from) marks
/// a direction in the null space; its row of `R` is left zero, which is
/// exact for a semi-definite `K` because the rest of that pivot's column is
/// then zero too.
///
/// # Panics
/// If `k.len() != n * n`.
pub fn cholesky_psd(k: &[f64], n: usize) -> Vec<f64> {
    assert_eq!(k.len(), n * n, "matrix is not {n}x{n}");
    let mut r = vec![0.0; n * n];
    for i in 0..n {
        let mut pivot = k[i * n + i];
        for p in 0..i {
            pivot -= r[p * n + i] * r[p * n + i];
        }
        if pivot <= PIVOT_TOL * k[i * n + i].abs() {
            continue;
        }
        let rii = pivot.sqrt();
        r[i * n + i] = rii;
        for j in i + 1..n {
            let mut s = k[i * n + j];
            for p in 0..i {
                s -= r[p * n + i] * r[p * n + j];
            }
            r[i * n + j] = s / rii;
        }
    }
    r
}

/// `sum_b w[b] B_b^T B_b` on an axis of `len` cells, where `B_b` is the 0/1
/// box matrix (`B_b[j, i] = 1` iff cell `i` lies in the box of centre `j`
/// and size `b`) and `sizes` pairs each size with its weight.
pub(crate) fn axis_gram(len: usize, sizes: impl IntoIterator<Item = (usize, f64)>) -> Vec<f64> {
    let mut k = vec![0.0; len * len];
    for (b, w) in sizes {
        for j in 1..=len {
            let (lo, hi) = crate::box_range(j, b, len);
            for a in lo..=hi {
                for c in lo..=hi {
                    k[(a - 1) * len + c - 1] += w;
                }
            }
        }
    }
    k
}
