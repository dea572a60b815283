//! The folded factors of the paper kernels, built once (`const`): each
//! axis kernel folded into its even and odd block, their Cholesky
//! factors in f64, and those quantised to the `Q(p)` the passes use.

use crate::config::MAX_J;
use crate::scorer::embed::layout::{Factor, TRI};
use crate::tables::{Mat, abs, cholesky_psd, pivot_tolerance, pow2, round};

/// The real (unquantised) factor of one folded axis.
#[derive(Clone, Copy)]
pub struct RealFactor {
    pub h: usize,
    pub g: usize,
    pub even: Mat,
    pub odd: Mat,
    /// Largest entry magnitude of both blocks.
    pub max: f64,
}

/// Folds the axis kernel `k` (`j x j`) and factors its two blocks.
pub const fn real_factor(k: &Mat, j: usize) -> RealFactor {
    let h = j.div_ceil(2);
    let g = j / 2;
    let mut ke = [[0.0; MAX_J]; MAX_J];
    let mut ko = [[0.0; MAX_J]; MAX_J];
    // x = Mₑ u + Mₒ v inverts the fold: Mₑ[l][a] = Mₑ[j-1-l][a] = 1/2 for a < g
    // (1 for the middle cell), Mₒ[a][a] = 1/2, Mₒ[j-1-a][a] = -1/2. The
    // blocks are Mₑᵀ K Mₑ and Mₒᵀ K Mₒ.
    let mut a = 0;
    while a < h {
        let mut b = 0;
        while b < h {
            ke[a][b] = fold_entry(k, j, a, b, 1.0, 1.0);
            b += 1;
        }
        a += 1;
    }
    a = 0;
    while a < g {
        let mut b = 0;
        while b < g {
            ko[a][b] = fold_entry(k, j, a, b, -1.0, -1.0);
            b += 1;
        }
        a += 1;
    }
    // A pivot is zero relative to the whole kernel, not to its block: the
    // odd block of a 2-cell axis with paper kernels vanishes entirely.
    let tol = pivot_tolerance(k, j);
    let even = cholesky_psd(&ke, h, tol);
    let odd = cholesky_psd(&ko, g, tol);
    let me = max_abs(&even, h);
    let mo = max_abs(&odd, g);
    RealFactor {
        h,
        g,
        even,
        odd,
        max: if me > mo { me } else { mo },
    }
}

/// `(Mᵀ K M)[a][b]` for the fold column pair `a`, `b`; `sa`, `sb` are the
/// signs of the mirrored cells (+1 even, -1 odd).
const fn fold_entry(k: &Mat, j: usize, a: usize, b: usize, sa: f64, sb: f64) -> f64 {
    let (ca, wa) = column(j, a);
    let (cb, wb) = column(j, b);
    let mut s = 0.0;
    let mut p = 0;
    while p < 2 {
        let mut q = 0;
        while q < 2 {
            if p < ca && q < cb {
                let (ia, fa) = if p == 0 { (a, 1.0) } else { (j - 1 - a, sa) };
                let (ib, fb) = if q == 0 { (b, 1.0) } else { (j - 1 - b, sb) };
                s += wa * fa * wb * fb * k[ia][ib];
            }
            q += 1;
        }
        p += 1;
    }
    s
}

/// Cells and weight of fold column `a`: the middle cell of an odd axis
/// alone with weight 1, any other a mirrored pair with weight 1/2.
const fn column(j: usize, a: usize) -> (usize, f64) {
    if j % 2 == 1 && a == j / 2 {
        (1, 1.0)
    } else {
        (2, 0.5)
    }
}

const fn max_abs(r: &Mat, n: usize) -> f64 {
    let mut m = 0.0;
    let mut i = 0;
    while i < n {
        let mut l = 0;
        while l < n {
            if abs(r[i][l]) > m {
                m = abs(r[i][l]);
            }
            l += 1;
        }
        i += 1;
    }
    m
}

/// The largest `p <= 62` with every `round(R * 2^p)` below `2^31 - 1` in
/// magnitude, or `None` if even `p = 0` does not fit.
pub const fn precision(f: &RealFactor) -> Option<u32> {
    let mut p: i32 = 62;
    while p >= 0 {
        if f.max * pow2(p) + 0.5 < 2147483647.0 {
            return Some(p as u32);
        }
        p -= 1;
    }
    None
}

/// `round(R * 2^p)`, packed.
pub const fn quantise(f: &RealFactor, p: u32) -> Factor {
    Factor {
        h: f.h,
        g: f.g,
        even: pack(&f.even, f.h, p),
        odd: pack(&f.odd, f.g, p),
    }
}

const fn pack(r: &Mat, n: usize, p: u32) -> [i32; TRI] {
    let mut out = [0; TRI];
    let s = pow2(p as i32);
    let mut idx = 0;
    let mut l = 0;
    while l < n {
        let mut k = 0;
        while k <= l {
            out[idx] = round(r[k][l] * s) as i32;
            idx += 1;
            k += 1;
        }
        l += 1;
    }
    out
}
