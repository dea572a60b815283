//! The square kernels' formats and factor table: the folded quadratic
//! form of each block, exact in integers, the finest formats for which
//! the bounds of the `square` module docs hold, and the f64 Cholesky
//! factor of each block, quantised and laid out as the per-map loop reads
//! it.

use crate::config::MAX_J;
use crate::scorer::square::blocks::{Blocks, MAX_BLOCK, MAX_H, padded_words};
use crate::tables::{pow2, round, sqrt};

/// Words of a packed upper triangle of `MAX_BLOCK` rows (the f64 Cholesky's
/// work space, on the stack of the one call that builds a table).
const MAX_TRI: usize = MAX_BLOCK * (MAX_BLOCK + 1) / 2;
/// Input format of normalised maps: the per-map reciprocal of the paper
/// kernels (`Scorer::scale`, exact for `f = 28` only).
const FRAC_NORM: i32 = 28;
/// Finest input format of raw maps: a folded count `|v| <= 4 65535 < 2^18`
/// shifted left by `f + 2` stays below `2^31`.
const MAX_FRAC_RAW: i32 = 11;
const I31: f64 = 2147483647.0;
const LIMIT_E: f64 = 1073741823.0; // 2^30 - 1
/// Relative slack on the f64 bounds (the Cholesky factor and the square
/// roots are computed, not exact).
const SLACK: f64 = 1.0 + 1e-9;

/// `A_k[r][s]` on an axis of `j` cells: the boxes of half-width `k`,
/// clipped at the border, that hold both cells.
const fn box_gram(j: usize, k: usize, r: usize, s: usize) -> i64 {
    let (lo, hi) = if r < s { (r, s) } else { (s, r) };
    let first = hi.saturating_sub(k);
    let last = if lo + k < j { lo + k } else { j - 1 };
    if last >= first {
        (last - first + 1) as i64
    } else {
        0
    }
}

/// Four times the folded entry `(Mᵀ A_k M)[a][c]` of one axis; `odd`
/// picks the odd block. Fold column `a` is the pair of cells `a` and
/// `J-1-a`, of weight 1/2 each (the mirrored one with the odd block's
/// sign), so four times the entry is an integer. The middle cell of an
/// odd axis, which the fold takes alone with weight 1, is its own mirror
/// image: as a pair with itself it gets the same 1/2 + 1/2.
const fn folded4(j: usize, k: usize, a: usize, c: usize, odd: bool) -> i64 {
    let sign = if odd { -1 } else { 1 };
    let (ma, mc) = (j - 1 - a, j - 1 - c);
    box_gram(j, k, a, c)
        + sign * (box_gram(j, k, a, mc) + box_gram(j, k, ma, c))
        + box_gram(j, k, ma, mc)
}

/// Sixteen times the entry of block `b` between cells `(p, q)` and
/// `(p', q')` of the block: an integer, exact in f64.
const fn block_entry16(g: &Blocks, kmax: usize, b: usize, cell: usize, other: usize) -> i64 {
    let (_, n2, odd1, odd2) = g.dims(b);
    // A block with no columns has no cells to ask about.
    let n2 = if n2 == 0 { 1 } else { n2 };
    let (p, q) = (cell / n2, cell % n2);
    let (p2, q2) = (other / n2, other % n2);
    let mut s = 0;
    let mut k = 0;
    while k <= kmax {
        s += folded4(g.j1, k, p, p2, odd1) * folded4(g.j2, k, q, q2, odd2);
        k += 1;
    }
    s
}

/// The largest diagonal entries of the blocks `G` and of `M`.
const fn diagonals(g: &Blocks, kmax: usize) -> (f64, f64) {
    let mut gmax = 0;
    let mut b = 0;
    while b < 4 {
        let (n1, n2, _, _) = g.dims(b);
        let mut c = 0;
        while c < n1 * n2 {
            let v = block_entry16(g, kmax, b, c, c);
            if v > gmax {
                gmax = v;
            }
            c += 1;
        }
        b += 1;
    }
    let mut mmax = 0;
    let mut r = 0;
    while r < g.j1 {
        let mut c = 0;
        while c < g.j2 {
            let mut v = 0;
            let mut k = 0;
            while k <= kmax {
                v += box_gram(g.j1, k, r, r) * box_gram(g.j2, k, c, c);
                k += 1;
            }
            if v > mmax {
                mmax = v;
            }
            c += 1;
        }
        r += 1;
    }
    (gmax as f64 / 16.0, mmax as f64)
}

/// The finest input format `f` and factor format `p` for which every bound
/// of the `square` module docs holds (`X` below 2^31, every partial sum
/// below 2^31, `‖E‖ < 2^30`); `None` if none does.
pub const fn formats(g: &Blocks, kmax: usize, normalise: bool) -> Option<(i32, u32)> {
    let n = (g.j1 * g.j2) as f64;
    let (gmax, mmax) = diagonals(g, kmax);
    let rmax = sqrt(gmax) * SLACK;
    let smax = g.j1.div_ceil(2) * g.j2.div_ceil(2);
    let mut f = if normalise { FRAC_NORM } else { MAX_FRAC_RAW };
    while f >= 0 {
        let scale = pow2(f);
        let x = if normalise {
            scale + n
        } else {
            n * 65535.0 * scale
        };
        if x < I31 {
            let mut p: i32 = 62;
            while p >= 0 && rmax * pow2(p) + 0.5 >= I31 {
                p -= 1;
            }
            while p >= 0 {
                let word = smax as f64 / 2.0 + x * pow2(-33);
                let e = x * sqrt(mmax) * SLACK * pow2(p - 32) + sqrt(n) * word;
                let partial = (rmax * pow2(p) + 0.5) * x * pow2(-32) + smax as f64 / 2.0;
                if e < LIMIT_E && partial < I31 {
                    return Some((f, p as u32));
                }
                p -= 1;
            }
        }
        f -= 1;
    }
    None
}

/// Offset of column `l` of a packed upper triangle stored column by
/// column (`R[0..=l][l]`).
const fn col_start(l: usize) -> usize {
    l * (l + 1) / 2
}

/// The folded axis matrices of every `k`, four times over (integers):
/// `[axis 1 even, axis 1 odd, axis 2 even, axis 2 odd][k][a][c]`.
type Folded = [[[[i16; MAX_H]; MAX_H]; MAX_J]; 4];

fn folded_axes(g: &Blocks, kmax: usize) -> Folded {
    let mut f = [[[[0i16; MAX_H]; MAX_H]; MAX_J]; 4];
    for (which, fk) in f.iter_mut().enumerate() {
        let (j, odd) = (if which < 2 { g.j1 } else { g.j2 }, which % 2 == 1);
        let n = if odd { j / 2 } else { j.div_ceil(2) };
        for (k, m) in fk.iter_mut().enumerate().take(kmax + 1) {
            for (a, row) in m.iter_mut().enumerate().take(n) {
                for (c, v) in row.iter_mut().enumerate().take(n) {
                    // |entry| <= 4 J: an i16.
                    *v = folded4(j, k, a, c, odd) as i16;
                }
            }
        }
    }
    f
}

/// Builds the factor table of geometry `g` with kernels up to `kmax` in
/// `Q(p)` into `out` (at least [`Blocks::table_words`] words). Runs once
/// per configuration, at start-up: the folded axis matrices of every `k`
/// (8 KB), then the f64 Cholesky of each block, column by column in a
/// packed triangle (16.6 KB), both on the stack. Returns false if `out`
/// is too short or a block is not positive definite (neither happens for
/// a geometry and `kmax` that [`formats`] accepted).
pub fn build(g: &Blocks, kmax: usize, p: u32, out: &mut [i32]) -> bool {
    let scale = pow2(p as i32);
    let kmax = kmax.min(MAX_J - 1);
    let folded = folded_axes(g, kmax);
    let mut at = 0;
    for b in 0..4 {
        let (n1, n2, odd1, odd2) = g.dims(b);
        let s = n1 * n2;
        let (f1, f2) = (&folded[odd1 as usize], &folded[2 + odd2 as usize]);
        // G[c][c'] of the block: cells c = (c / n2, c % n2).
        let entry = |c: usize, c2: usize| -> f64 {
            if n2 == 0 || c >= s {
                return 0.0;
            }
            let (p1, q1, p2, q2) = (c / n2, c % n2, c2 / n2, c2 % n2);
            let mut v = 0i64;
            for (a, b) in f1.iter().zip(f2).take(kmax + 1) {
                let x = a.get(p1).and_then(|r| r.get(p2)).copied().unwrap_or(0);
                let y = b.get(q1).and_then(|r| r.get(q2)).copied().unwrap_or(0);
                v += x as i64 * y as i64;
            }
            v as f64 / 16.0
        };
        let mut r = [0.0f64; MAX_TRI];
        for l in 0..s {
            let Some((done, rest)) = r.split_at_mut_checked(col_start(l)) else {
                return false;
            };
            let Some(col) = rest.get_mut(..=l) else {
                return false;
            };
            // R[i][l] = (G[i][l] - Σ_{m<i} R[m][i] R[m][l]) / R[i][i], then
            // R[l][l] = sqrt(G[l][l] - Σ_{m<l} R[m][l]²).
            for i in 0..l {
                let ci = done.get(col_start(i)..=col_start(i) + i).unwrap_or(&[]);
                let (head, tail) = col.split_at_mut(i);
                let dot: f64 = ci.iter().zip(head.iter()).map(|(x, y)| x * y).sum();
                let piv = ci.last().copied().unwrap_or(0.0);
                if let Some(v) = tail.first_mut() {
                    *v = (entry(i, l) - dot) / piv;
                }
            }
            let (head, last) = col.split_at_mut(l);
            let d = entry(l, l) - head.iter().map(|x| x * x).sum::<f64>();
            if d.is_nan() || d <= 0.0 {
                return false;
            }
            if let Some(v) = last.first_mut() {
                *v = sqrt(d);
            }
        }
        // `l >= i` at every call below; past the last column (the last
        // group's padding) `r` holds zeros, or ends.
        let q = |i: usize, l: usize| -> i32 {
            let v = r.get(col_start(l) + i).copied().unwrap_or(0.0);
            // Below 2^31 - 1 by the choice of `p`; saturating all the same.
            round(v * scale).clamp(i32::MIN as i64, i32::MAX as i64) as i32
        };
        let Some(block) = out.get_mut(at..at + padded_words(s)) else {
            return false;
        };
        let mut words = block.iter_mut();
        let mut put = |v: i32| {
            if let Some(w) = words.next() {
                *w = v;
            }
        };
        // Rows in pairs (see `padded_words`): the number of groups of
        // three columns, row i's diagonal, then per group row i's three
        // coefficients and row i+1's.
        for i in (0..s.saturating_sub(1)).step_by(2) {
            let groups = (s - i - 1).div_ceil(3);
            put(groups as i32);
            put(q(i, i));
            for gr in 0..groups {
                let j = i + 1 + 3 * gr;
                for row in [i, i + 1] {
                    for l in j..j + 3 {
                        put(q(row, l));
                    }
                }
            }
        }
        if s % 2 == 1 {
            put(q(s - 1, s - 1));
        }
        at += padded_words(s);
    }
    at == g.table_words()
}
