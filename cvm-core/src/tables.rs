//! Factor tables of the CVM quadratic form, built once per configuration
//! (docs/method.md §4), in f64 and `const`-evaluable so that a firmware can build
//! them at compile time and a bad configuration fails the build.
//!
//! With paper kernels and separable weights the distance is
//! `d = tr(Dᵀ K1 D K2) = ‖R1 D R2ᵀ‖²_F`, with
//! `K1 = Σ_b w1(b) B_bᵀ B_b` (`B_b` the 0/1 box matrix of half-width `b`) and
//! `K1 = R1ᵀ R1` its upper-triangular, semi-definite Cholesky factor.

use crate::config::{ConfigError, Kernels, MAX_J, Weights};

/// A `J x J` f64 matrix (only the leading `J x J` block is used).
pub type Mat = [[f64; MAX_J]; MAX_J];

/// First and last (0-based, inclusive) cell of the box of centre `j` and
/// half-width `h` on an axis of `n` cells: `[max(0, j-h), min(n-1, j+h)]`.
pub const fn box_range(j: usize, h: usize, n: usize) -> (usize, usize) {
    let lo = j.saturating_sub(h);
    let hi = if j + h < n { j + h } else { n - 1 };
    (lo, hi)
}

/// Per-axis weights `w(b)` for `b = 1..=n` (`out[b-1]`), and `n`, the number
/// of sizes on this axis. Errors on negative or non-finite weights.
pub const fn axis_weights(
    weights: &Weights,
    axis: usize,
    j: usize,
    bmax: usize,
) -> Result<([f64; MAX_J], usize), ConfigError> {
    let n = if bmax == 0 || bmax > j { j } else { bmax };
    let mut w = [0.0; MAX_J];
    let mut b = 0;
    while b < n {
        w[b] = match weights {
            Weights::Uniform => 1.0 / n as f64,
            Weights::Unit => 1.0,
            Weights::Separable { w1, w2 } => {
                let v = if axis == 0 { w1[b] } else { w2[b] };
                if !v.is_finite() || v < 0.0 {
                    return Err(ConfigError::Weights);
                }
                v
            }
        };
        b += 1;
    }
    Ok((w, n))
}

/// `K = Σ_{b=1..n} w(b) B_bᵀ B_b` for an axis of `j` cells.
pub const fn axis_kernel(j: usize, w: &[f64; MAX_J], n: usize) -> Mat {
    let mut k = [[0.0; MAX_J]; MAX_J];
    let mut b = 1;
    while b <= n {
        // (B_bᵀ B_b)[i][l] counts the boxes (one per centre) holding both i and l.
        let mut c = 0;
        while c < j {
            let (lo, hi) = box_range(c, b, j);
            let mut i = lo;
            while i <= hi {
                let mut l = lo;
                while l <= hi {
                    k[i][l] += w[b - 1];
                    l += 1;
                }
                i += 1;
            }
            c += 1;
        }
        b += 1;
    }
    k
}

/// Square root by Newton's method (core has no `f64::sqrt` in `no_std`).
pub const fn sqrt(x: f64) -> f64 {
    if x.is_nan() || x <= 0.0 {
        return 0.0;
    }
    let mut g = if x > 1.0 { x } else { 1.0 };
    let mut i = 0;
    while i < 200 {
        let next = 0.5 * (g + x / g);
        if next >= g {
            break;
        }
        g = next;
        i += 1;
    }
    g
}

/// Upper-triangular `R` with `Rᵀ R = K` for a positive semi-definite `K`.
/// A pivot at or below `tol` gives a zero row: that direction carries no
/// distance, e.g. an axis of exactly two cells with paper kernels, where
/// every box covers the whole axis. Callers pass a tolerance relative to
/// the largest diagonal entry of the whole kernel ([`pivot_tolerance`]).
pub const fn cholesky_psd(k: &Mat, n: usize, tol: f64) -> Mat {
    let mut r = [[0.0; MAX_J]; MAX_J];
    let mut i = 0;
    while i < n {
        let mut s = k[i][i];
        let mut m = 0;
        while m < i {
            s -= r[m][i] * r[m][i];
            m += 1;
        }
        if s > tol {
            let d = sqrt(s);
            r[i][i] = d;
            let mut l = i + 1;
            while l < n {
                let mut t = k[i][l];
                let mut m = 0;
                while m < i {
                    t -= r[m][i] * r[m][l];
                    m += 1;
                }
                r[i][l] = t / d;
                l += 1;
            }
        }
        i += 1;
    }
    r
}

/// Pivots below `1e-12` of the largest diagonal entry of `K` count as zero.
pub const fn pivot_tolerance(k: &Mat, n: usize) -> f64 {
    let mut dmax = 0.0;
    let mut i = 0;
    while i < n {
        if k[i][i] > dmax {
            dmax = k[i][i];
        }
        i += 1;
    }
    dmax * 1e-12
}

pub const fn abs(x: f64) -> f64 {
    if x < 0.0 { -x } else { x }
}

/// Round half away from zero (|x| well below 2^62).
pub const fn round(x: f64) -> i64 {
    if x >= 0.0 {
        (x + 0.5) as i64
    } else {
        -((-x + 0.5) as i64)
    }
}

pub const fn pow2(e: i32) -> f64 {
    let mut v = 1.0;
    let mut i = 0;
    if e >= 0 {
        while i < e {
            v *= 2.0;
            i += 1;
        }
    } else {
        while i < -e {
            v *= 0.5;
            i += 1;
        }
    }
    v
}

/// Frobenius norm of the leading `n x n` block.
pub const fn frobenius(r: &Mat, n: usize) -> f64 {
    let mut sum = 0.0;
    let mut i = 0;
    while i < n {
        let mut l = 0;
        while l < n {
            sum += r[i][l] * r[i][l];
            l += 1;
        }
        i += 1;
    }
    sqrt(sum)
}

/// Sum of the kernel weights, `Σ_b w(b)`, for the score range.
pub const fn weight_sum(
    kernels: &Kernels,
    w1: &[f64; MAX_J],
    n1: usize,
    w2: &[f64; MAX_J],
    n2: usize,
) -> f64 {
    match kernels {
        Kernels::Square { kmax } => *kmax as f64 + 1.0,
        Kernels::Paper { .. } => {
            let (mut s1, mut s2) = (0.0, 0.0);
            let mut b = 0;
            while b < n1 {
                s1 += w1[b];
                b += 1;
            }
            b = 0;
            while b < n2 {
                s2 += w2[b];
                b += 1;
            }
            s1 * s2
        }
    }
}
