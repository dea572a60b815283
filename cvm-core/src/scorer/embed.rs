//! The folded embedding of the paper kernels: tables (built once, `const`)
//! and the per-map passes (run for every beam).
//!
//! Each axis kernel `K` is centrosymmetric (`K[i][l] = K[J-1-i][J-1-l]`: a
//! box and its mirror image have the same size and weight), so the even and
//! the odd part of a vector under reversal do not interact:
//! `xᵀ K x = uᵀ Kₑ u + vᵀ Kₒ v` with `u[l] = x[l] + x[J-1-l]`,
//! `v[l] = x[l] - x[J-1-l]` (`l < J/2`, plus the middle cell in `u` when `J`
//! is odd). Folding the map on both axes (integer additions, exact) and
//! embedding each quarter with the Cholesky factors of the two half-size
//! blocks needs half the multiply-adds of `R1 x R2ᵀ`, and every block is at
//! most 8 x 8, so each block size gets its own fully unrolled code.

use crate::config::MAX_J;
use crate::tables::{Mat, abs, pow2, round, sqrt};

/// Largest block of a folded axis (`ceil(16 / 2)`).
pub const MAX_H: usize = MAX_J.div_ceil(2);
/// Words of a packed upper-triangular `MAX_H x MAX_H` block.
pub const TRI: usize = MAX_H * (MAX_H + 1) / 2;

/// The quantised factor of one folded axis: the even block (`h` cells, the
/// middle one included) and the odd block (`g` cells), each upper
/// triangular and packed row by row (`r[k][k..n]`), in `Q(p)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Factor {
    pub h: usize,
    pub g: usize,
    pub even: [i32; TRI],
    pub odd: [i32; TRI],
}

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
    let mut dmax = 0.0;
    let mut i = 0;
    while i < j {
        if k[i][i] > dmax {
            dmax = k[i][i];
        }
        i += 1;
    }
    let tol = dmax * 1e-12;
    let even = cholesky(&ke, h, tol);
    let odd = cholesky(&ko, g, tol);
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

/// Upper-triangular `R` with `Rᵀ R = K` (semi-definite; a pivot at or below
/// `tol` gives a zero row).
const fn cholesky(k: &Mat, n: usize, tol: f64) -> Mat {
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

impl Factor {
    /// Largest coefficient magnitude.
    pub const fn max(&self) -> f64 {
        let mut m = 0.0;
        let mut i = 0;
        while i < TRI {
            let (a, b) = (abs(self.even[i] as f64), abs(self.odd[i] as f64));
            if a > m {
                m = a;
            }
            if b > m {
                m = b;
            }
            i += 1;
        }
        m
    }

    /// Frobenius norm of the block-diagonal coefficient matrix (at least its
    /// spectral norm).
    pub const fn frobenius(&self) -> f64 {
        let mut s = 0.0;
        let mut i = 0;
        while i < TRI {
            let (a, b) = (self.even[i] as f64, self.odd[i] as f64);
            s += a * a + b * b;
            i += 1;
        }
        sqrt(s)
    }
}

/// Folds every row of a row-major `j1 x j2` frame along axis 2 into `w`
/// (`w[i][0..h2]` even, `w[i][h2..j2]` odd part; exact integer sums and
/// differences of two samples). Returns the sum of all samples and the OR
/// of `a + off` over all samples (bit 16 set iff a sample reached the full
/// scale, see [`saturation_offset`]).
pub fn fold_rows(
    frame: &[u16],
    j1: usize,
    j2: usize,
    off: u32,
    w: &mut [[i32; MAX_J]; MAX_J],
) -> (u32, u32) {
    let (h2, g2) = (j2.div_ceil(2), j2 / 2);
    let mut sum = 0u32;
    let mut sat = 0u32;
    for (row, wr) in frame.chunks_exact(j2.max(1)).zip(w.iter_mut()).take(j1) {
        let (we, wo) = wr.split_at_mut(h2.min(MAX_J));
        let pairs = row.iter().zip(row.iter().rev()).take(g2);
        for (((&a, &b), e), o) in pairs.zip(we.iter_mut()).zip(wo.iter_mut()) {
            let (a, b) = (a as u32, b as u32);
            sat |= (a + off) | (b + off);
            sum += a + b;
            *e = (a + b) as i32;
            *o = a.wrapping_sub(b) as i32;
        }
        if j2 % 2 == 1 {
            // The middle cell is even.
            let a = row.get(g2).copied().unwrap_or(0) as u32;
            sat |= a + off;
            sum += a;
            if let Some(e) = we.get_mut(g2) {
                *e = a as i32;
            }
        }
    }
    (sum, sat)
}

/// `a + off` has bit 16 set iff `a >= full_scale` (`a <= 65535`).
pub const fn saturation_offset(full_scale: u16) -> u32 {
    0x1_0000 - full_scale as u32
}

/// `round(a * b / 2^32)`: one `SMMULR`.
#[inline(always)]
fn mul_hi_round(a: i32, b: i32) -> i32 {
    ((a as i64 * b as i64 + (1 << 31)) >> 32) as i32
}

/// `Σ_{l>=k} round(r[k][l] u[l] / 2^32)` for every `k` of the packed upper
/// triangular `N x N` block `r`: one `SMMLAR` per coefficient into `N`
/// 32-bit accumulators, column by column, so that the accumulators, one
/// input and the streamed coefficients fit the Cortex-M4's registers.
/// Each term is rounded (error at most 1/2), and the bounds of the
/// module docs keep every partial sum inside `i32`.
#[inline(always)]
fn tri<const N: usize>(r: &[i32; TRI], u: &[i32; N]) -> [i32; N] {
    let mut acc = [0i32; N];
    let mut idx = 0;
    for (l, &ul) in u.iter().enumerate() {
        for a in acc.iter_mut().take(l + 1) {
            *a = a.wrapping_add(mul_hi_round(r[idx % TRI], ul));
            idx += 1;
        }
    }
    acc
}

/// Row pass of one block (`N` folded columns from `c0`) over the `n_rows`
/// rows of `w`: converts the folded counts to `Q(f)`
/// (`round((v << k) * m / 2^32)`), applies the block and stores the result
/// transposed, `t[c0 + k][i]`.
#[inline(never)]
fn rows<const N: usize>(
    r: &[i32; TRI],
    w: &[[i32; MAX_J]; MAX_J],
    n_rows: usize,
    c0: usize,
    conv: (u32, i32),
    t: &mut [[i32; MAX_J]; MAX_J],
) {
    let Some(Ok(tb)) = t
        .get_mut(c0..c0 + N)
        .map(<&mut [[i32; MAX_J]; N]>::try_from)
    else {
        return;
    };
    let (sh, m) = (conv.0 & 31, conv.1);
    for (i, wr) in w.iter().take(n_rows).enumerate() {
        let Some(Ok(src)) = wr.get(c0..c0 + N).map(<&[i32; N]>::try_from) else {
            return;
        };
        let u: [i32; N] = core::array::from_fn(|l| mul_hi_round(src[l] << sh, m));
        let o = tri::<N>(r, &u);
        for (tk, &ok) in tb.iter_mut().zip(o.iter()) {
            tk[i & (MAX_J - 1)] = ok;
        }
    }
}

/// Column pass for an axis 1 of `H + G` cells: for every folded column
/// `k < n_cols`, folds `t[k]` along axis 1 (`t[l] ± t[H+G-1-l]`, exact),
/// applies the even and the odd block and stores the embedding in
/// `e[k * (H + G)..]` (even part first).
#[inline(never)]
fn cols<const H: usize, const G: usize>(
    f1: &Factor,
    t: &[[i32; MAX_J]; MAX_J],
    n_cols: usize,
    e: &mut [i32],
) {
    let j1 = H + G;
    for (tr, er) in t.iter().zip(e.chunks_exact_mut(j1.max(1))).take(n_cols) {
        let (de, dodd) = er.split_at_mut(H.min(er.len()));
        let (Ok(de), Ok(dodd)) = (
            <&mut [i32; H]>::try_from(de),
            <&mut [i32; G]>::try_from(dodd),
        ) else {
            return;
        };
        // Constant indices below MAX_J once unrolled: no bounds checks.
        let ue: [i32; H] = core::array::from_fn(|l| {
            if l < G {
                tr[l].wrapping_add(tr[(j1 - 1 - l) & (MAX_J - 1)])
            } else {
                tr[l]
            }
        });
        let uo: [i32; G] =
            core::array::from_fn(|l| tr[l].wrapping_sub(tr[(j1 - 1 - l) & (MAX_J - 1)]));
        *de = tri::<H>(&f1.even, &ue);
        *dodd = tri::<G>(&f1.odd, &uo);
    }
}

/// Runs `$pass::<n>($args)` for the runtime block size `n` (1 to 8).
macro_rules! by_size {
    ($n:expr, $pass:ident, $($arg:expr),*) => {
        match $n {
            1 => $pass::<1>($($arg),*),
            2 => $pass::<2>($($arg),*),
            3 => $pass::<3>($($arg),*),
            4 => $pass::<4>($($arg),*),
            5 => $pass::<5>($($arg),*),
            6 => $pass::<6>($($arg),*),
            7 => $pass::<7>($($arg),*),
            8 => $pass::<8>($($arg),*),
            _ => {}
        }
    };
}

/// `E = R1' y R2'ᵀ` of a map folded along axis 2 (`w`, converted by
/// `conv`), folded along axis 1 between the passes, stored
/// folded-column-major in `e` (`j1 * j2` words): `e[k * j1 + i]`.
pub fn embed(
    f1: &Factor,
    f2: &Factor,
    w: &[[i32; MAX_J]; MAX_J],
    conv: (u32, i32),
    t: &mut [[i32; MAX_J]; MAX_J],
    e: &mut [i32],
) {
    let j1 = f1.h + f1.g;
    let j2 = f2.h + f2.g;
    by_size!(f2.h, rows, &f2.even, w, j1, 0, conv, t);
    by_size!(f2.g, rows, &f2.odd, w, j1, f2.h, conv, t);
    let t = &*t;
    match j1 {
        1 => cols::<1, 0>(f1, t, j2, e),
        2 => cols::<1, 1>(f1, t, j2, e),
        3 => cols::<2, 1>(f1, t, j2, e),
        4 => cols::<2, 2>(f1, t, j2, e),
        5 => cols::<3, 2>(f1, t, j2, e),
        6 => cols::<3, 3>(f1, t, j2, e),
        7 => cols::<4, 3>(f1, t, j2, e),
        8 => cols::<4, 4>(f1, t, j2, e),
        9 => cols::<5, 4>(f1, t, j2, e),
        10 => cols::<5, 5>(f1, t, j2, e),
        11 => cols::<6, 5>(f1, t, j2, e),
        12 => cols::<6, 6>(f1, t, j2, e),
        13 => cols::<7, 6>(f1, t, j2, e),
        14 => cols::<7, 7>(f1, t, j2, e),
        15 => cols::<8, 7>(f1, t, j2, e),
        16 => cols::<8, 8>(f1, t, j2, e),
        _ => {}
    }
}
