//! The square kernels' embedding: `N` words per map, like the paper
//! kernels', from the Cholesky factors of the folded quadratic form.
//!
//! With square kernels (`b = (k, k)`, `k = 0..=K`, unit weights) the
//! distance is `d = Δᵀ M Δ` with `M = Σ_k A_k ⊗ A'_k`, `A_k = B_kᵀ B_k` and
//! `B_k` the 0/1 matrix of the boxes of half-width `k` clipped at the
//! border (`A_k[r][s]` counts the boxes that hold both cells). `M` is a sum
//! of Kronecker products, not one, so it has no separable factor like the
//! paper kernels'; but every `A_k` is centrosymmetric, so folding both
//! axes (`u = x[l] + x[J-1-l]`, `v = x[l] - x[J-1-l]`, the middle cell in
//! `u`, exactly as for the paper kernels) splits `M` into four blocks that
//! do not interact: even or odd along axis 1 times even or odd along axis
//! 2, of at most `8 x 8 = 64` cells. Each block `G` is positive definite
//! (the `k = 0` term is the identity), and its upper-triangular Cholesky
//! factor `R` (`Rᵀ R = G`) embeds the block's folded values `z` as `R z`.
//! The squared Euclidean distance of two embeddings is the CVM distance.
//!
//! The factors depend on the geometry and `K` only. They are computed in
//! f64 when the configuration is attached to a table
//! ([`super::Scorer::with_factors`], at start-up: up to 8 704 words, too
//! many for the `Scorer` that every firmware builds as a constant), and
//! stored two rows at a time in groups of three columns, so that the
//! per-map loop reads three inputs and the six coefficients of both rows
//! that use them with two `LDM`s (`padded_words`).
//!
//! # Formats and why nothing overflows
//!
//! `z` is in `Q(f)`, the factor in `Q(p)`, the embedding `E = R z` in
//! `Q(f + p - 32)`: one `round(r z / 2^32)` per term (`SMMLAR`). Every
//! sample lies in one folded count `v` of each block, so over a block
//! `Σ|v| <= S` (the map's sum), and `z` is `v` converted as the paper
//! kernels convert (`round((v << k) m / 2^32)`, within 1 of `v 2^f / S`;
//! raw: `v 2^f`, exact). Hence `Σ|z| <= X < 2^31` over a block, with
//! `X = 2^f + N` normalised (`f = 28`) and `X = N 65535 2^f` raw. `|R_ij| <= sqrt(G_jj)`, and `p` is the
//! finest with `sqrt(max G_jj) 2^p + 1/2 < 2^31 - 1`, so every partial sum
//! of a row is below `2^31 X / 2^32 + 32 < 2^30 + 32`. The embedding's
//! norm is at most `X sqrt(max M_ii) 2^(p-32)` (`|M_ij| <= sqrt(M_ii M_jj)`
//! for a positive definite `M`) plus the rounding, `√N (32 + X / 2^33)`,
//! and `f` and `p` are the finest for which that stays below `2^30`: every
//! word and every difference of two words fits `i32`, and a squared
//! distance (below `2^62`) fits the `i64` accumulator.
//!
//! # Accuracy
//!
//! Each word is within `s/2 + X / 2^33` units of the exact `R z 2^(p-32)`
//! (`s <= 64` rounded terms, and each coefficient rounded to `Q(p)`), and
//! the f64 Cholesky factor is exact to about `1e-14` of `G`. Against the
//! f64 brute force of Eq. 8 the distances meet the bound the paper kernels
//! meet (core-tests, `fixed_vs_f64`).

use crate::config::{MAX_CELLS, MAX_J};
use crate::tables::{pow2, round, sqrt};

/// Largest block of one folded axis (`ceil(16 / 2)`).
const MAX_H: usize = MAX_J.div_ceil(2);
/// Largest folded block of a map.
const MAX_BLOCK: usize = MAX_H * MAX_H;
/// Words of a packed upper triangle of `MAX_BLOCK` rows (the f64 Cholesky's
/// work space, on the stack of the one call that builds a table).
const MAX_TRI: usize = MAX_BLOCK * (MAX_BLOCK + 1) / 2;
/// Words of the scratch space the per-map path folds a map into: the
/// last group of a block's rows reads up to two words past the block.
pub const FOLD_WORDS: usize = MAX_CELLS + 4;
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

/// The sizes of the four folded blocks of a `j1 x j2` map, in the order
/// the embedding stores them: (even, even), (even, odd), (odd, even),
/// (odd, odd) along (axis 1, axis 2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Blocks {
    pub j1: usize,
    pub j2: usize,
}

impl Blocks {
    /// Rows and columns of block `b` (0..4) and whether each axis is odd.
    pub const fn dims(&self, b: usize) -> (usize, usize, bool, bool) {
        let (odd1, odd2) = (b & 2 != 0, b & 1 != 0);
        let n1 = if odd1 {
            self.j1 / 2
        } else {
            self.j1.div_ceil(2)
        };
        let n2 = if odd2 {
            self.j2 / 2
        } else {
            self.j2.div_ceil(2)
        };
        (n1, n2, odd1, odd2)
    }

    /// Words of the factor table of this geometry.
    pub const fn table_words(&self) -> usize {
        let mut w = 0;
        let mut b = 0;
        while b < 4 {
            let (n1, n2, _, _) = self.dims(b);
            w += padded_words(n1 * n2);
            b += 1;
        }
        w
    }
}

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
/// of the module docs holds (`X` below 2^31, every partial sum below 2^31,
/// `‖E‖ < 2^30`); `None` if none does.
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

/// Folds the raw map `frame` (row-major, `j2` per row) on both axes into
/// the four blocks of `z`, one after the other, and converts each folded
/// count `v` (exact: `|v| <= S`, the sum of the map's samples) to `Q(f)`
/// as the paper kernels do: `round((v << k) m / 2^32)` with `(k, m)` from
/// `Scorer::scale` (normalised: error below 1; raw: `v 2^f`, exact). Each
/// group of four mirrored samples gives one word of each block.
#[inline(never)]
pub fn fold(g: &Blocks, frame: &[u16], (k, m): (u32, i32), z: &mut [i32]) {
    let (j1, j2) = (g.j1, g.j2);
    let (h1, g1, h2, g2) = (j1.div_ceil(2), j1 / 2, j2.div_ceil(2), j2 / 2);
    let k = k.min(31);
    let conv = |v: i32| smmulr(v << k, m);
    let Some((b00, rest)) = z.split_at_mut_checked(h1 * h2) else {
        return;
    };
    let Some((b01, rest)) = rest.split_at_mut_checked(h1 * g2) else {
        return;
    };
    let Some((b10, b11)) = rest.split_at_mut_checked(g1 * h2) else {
        return;
    };
    for p in 0..h1 {
        // Rows p and j1-1-p: the same row at the middle of an odd axis,
        // which has no odd part.
        let pm = j1 - 1 - p;
        let (Some(top), Some(bot)) = (
            frame.get(p * j2..p * j2 + j2),
            frame.get(pm * j2..pm * j2 + j2),
        ) else {
            return;
        };
        let (Some(r00), Some(r01)) = (
            b00.get_mut(p * h2..p * h2 + h2),
            b01.get_mut(p * g2..p * g2 + g2),
        ) else {
            return;
        };
        let (tl, tr) = (
            top.get(..g2).unwrap_or(&[]),
            top.get(j2 - g2..).unwrap_or(&[]),
        );
        if p == pm {
            let cols = tl
                .iter()
                .zip(tr.iter().rev())
                .zip(r00.iter_mut().zip(r01.iter_mut()));
            for ((&a, &b), (e, o)) in cols {
                let (a, b) = (a as i32, b as i32);
                *e = conv(a + b);
                *o = conv(a - b);
            }
            // The middle column of an odd axis 2: the one word of `r00`
            // past `g2` (none when the axis is even, `h2 = g2`).
            if let (Some(e), Some(&a)) = (r00.get_mut(g2), top.get(g2)) {
                *e = conv(a as i32);
            }
            continue;
        }
        let (Some(r10), Some(r11)) = (
            b10.get_mut(p * h2..p * h2 + h2),
            b11.get_mut(p * g2..p * g2 + g2),
        ) else {
            return;
        };
        quads(top, bot, g2, [&mut *r00, &mut *r01, &mut *r10, r11], (k, m));
        if let (Some(e), Some(o), Some(&a), Some(&c)) =
            (r00.get_mut(g2), r10.get_mut(g2), top.get(g2), bot.get(g2))
        {
            *e = conv(a as i32 + c as i32);
            *o = conv(a as i32 - c as i32);
        }
    }
}

/// The groups of four mirrored samples of rows `p` (`top`) and
/// `J1 - 1 - p` (`bot`), both `J2` long: for each `q < g2 = J2 / 2`, one
/// word of each block's row (`outs`: even-even, even-odd, odd-even,
/// odd-odd, each at least `g2` long) from `top[q]`, `top[J2-1-q]`,
/// `bot[q]`, `bot[J2-1-q]`.
#[cfg(not(target_arch = "arm"))]
#[inline(always)]
fn quads(top: &[u16], bot: &[u16], g2: usize, outs: [&mut [i32]; 4], (k, m): (u32, i32)) {
    let conv = |v: i32| smmulr(v << k, m);
    let j2 = top.len();
    let (tl, tr) = (
        top.get(..g2).unwrap_or(&[]),
        top.get(j2 - g2..).unwrap_or(&[]),
    );
    let (bl, br) = (
        bot.get(..g2).unwrap_or(&[]),
        bot.get(j2 - g2..).unwrap_or(&[]),
    );
    let [r00, r01, r10, r11] = outs;
    let samples = tl
        .iter()
        .zip(tr.iter().rev())
        .zip(bl.iter().zip(br.iter().rev()));
    let outs = r00
        .iter_mut()
        .zip(r01.iter_mut())
        .zip(r10.iter_mut().zip(r11.iter_mut()));
    for (((&a, &b), (&c, &d)), ((ee, eo), (oe, oo))) in samples.zip(outs) {
        let (s1, d1) = (a as i32 + b as i32, a as i32 - b as i32);
        let (s2, d2) = (c as i32 + d as i32, c as i32 - d as i32);
        *ee = conv(s1 + s2);
        *eo = conv(d1 + d2);
        *oe = conv(s1 - s2);
        *oo = conv(d1 - d2);
    }
}

/// [`quads`] on the Cortex-M: `cvm_square_quads`, 26 instructions per
/// group of four words where the compiled loop, short of registers for
/// its eight pointers, took about 52.
#[cfg(target_arch = "arm")]
#[inline(always)]
fn quads(top: &[u16], bot: &[u16], g2: usize, outs: [&mut [i32]; 4], (k, m): (u32, i32)) {
    let j2 = top.len();
    let [r00, r01, r10, r11] = outs;
    let fits = g2 > 0
        && 2 * g2 <= j2
        && bot.len() == j2
        && r00.len() >= g2
        && r01.len() >= g2
        && r10.len() >= g2
        && r11.len() >= g2;
    if !fits {
        return;
    }
    let addr = |p: *const u8| p as usize as u32;
    let top_p = top.as_ptr();
    let ctx: [u32; 10] = [
        addr(top_p.cast()),
        addr(top_p.wrapping_add(j2 - 1).cast()),
        addr(bot.as_ptr().cast()).wrapping_sub(addr(top_p.cast())),
        addr(r00.as_ptr().cast()),
        addr(r01.as_ptr().cast()),
        addr(r10.as_ptr().cast()).wrapping_sub(addr(r00.as_ptr().cast())),
        addr(r11.as_ptr().cast()).wrapping_sub(addr(r01.as_ptr().cast())),
        k,
        m as u32,
        g2 as u32,
    ];
    // SAFETY: `g2` groups read `top[..g2]`, `top[j2-g2..]` and the same
    // words of `bot` (both `j2` long, `2 g2 <= j2`), and write the first
    // `g2` words of each of the four output rows (each that long), all
    // checked above; the function preserves the callee-saved registers.
    unsafe { square_arm::cvm_square_quads(&ctx) };
}

/// `round(a b / 2^32)`: one `SMMULR`.
#[inline(always)]
fn smmulr(a: i32, b: i32) -> i32 {
    #[cfg(target_arch = "arm")]
    {
        let r: i32;
        // SAFETY: one register-only instruction.
        unsafe {
            core::arch::asm!(
                "smmulr {r}, {a}, {b}",
                r = lateout(reg) r,
                a = in(reg) a,
                b = in(reg) b,
                options(pure, nomem, nostack, preserves_flags)
            );
        }
        r
    }
    #[cfg(not(target_arch = "arm"))]
    {
        ((a as i64 * b as i64 + (1 << 31)) >> 32) as i32
    }
}

/// Embeds the folded blocks of `z` in place: block by block, `E = R z`,
/// word `i` of a block overwriting its input `z_i` once no later row needs
/// it. `table` holds [`Blocks::table_words`] words, `z` at least
/// `N + 3` ([`FOLD_WORDS`]). Returns false (and leaves `z` partly embedded) if
/// either is too short.
pub fn embed(g: &Blocks, table: &[i32], z: &mut [i32]) -> bool {
    let n = g.j1 * g.j2;
    if z.len() < n + 3 {
        return false;
    }
    let (mut t, mut at) = (0, 0);
    for b in 0..4 {
        let (n1, n2, _, _) = g.dims(b);
        let s = n1 * n2;
        let Some(&words) = PADDED_WORDS.get(s) else {
            return false;
        };
        let (Some(zb), Some(tb)) = (z.get_mut(at..), table.get(t..t + words)) else {
            return false;
        };
        block(tb, zb, s);
        t += words;
        at += s;
    }
    true
}

/// [`padded_words`] of every block size, for the per-map path.
const PADDED_WORDS: [usize; MAX_BLOCK + 1] = {
    let mut w = [0; MAX_BLOCK + 1];
    let mut s = 0;
    while s <= MAX_BLOCK {
        w[s] = padded_words(s);
        s += 1;
    }
    w
};

/// Words of the factor of a block of `s` cells as the embedding reads
/// it: for each pair of rows `(i, i+1)`, a count, row `i`'s diagonal and
/// `6 ceil((s - i - 1) / 3)` coefficients (groups of three columns of both
/// rows, zero past the block); then, for an odd `s`, the last diagonal.
const fn padded_words(s: usize) -> usize {
    let mut w = s % 2;
    let mut i = 0;
    while i + 1 < s {
        w += 2 + 6 * (s - i - 1).div_ceil(3);
        i += 2;
    }
    w
}

/// One block of [`embed`] (nothing for `s = 0`; `table` holds the block's
/// `padded_words(s)` words and `z` its `s` words plus two, checked by the
/// caller): the pairs of rows, then the last row of an odd block.
#[inline(always)]
fn block(table: &[i32], z: &mut [i32], s: usize) {
    let pairs = s / 2;
    if pairs > 0 {
        pairs_of_rows(table, z, pairs);
    }
    if s % 2 == 1
        && let (Some(&r), Some(v)) = (table.last(), z.get_mut(s - 1))
    {
        *v = smmulr(r, *v);
    }
}

#[cfg(target_arch = "arm")]
#[inline(always)]
fn pairs_of_rows(table: &[i32], z: &mut [i32], pairs: usize) {
    // SAFETY: `table` holds the records of `pairs` pairs of rows, and `z`
    // the `2 pairs` words they write plus every word their groups read
    // (at most two past the block, which `embed` checked it has); the
    // function preserves the callee-saved registers (AAPCS).
    unsafe {
        square_arm::cvm_square_pairs(table.as_ptr(), z.as_mut_ptr(), pairs);
    }
}

/// The same arithmetic as `cvm_square_pairs`: one rounded product per
/// term, wrapping sums (which the bounds keep inside `i32`).
#[cfg(not(target_arch = "arm"))]
fn pairs_of_rows(table: &[i32], z: &mut [i32], pairs: usize) {
    let mac = |acc: i32, c: i32, v: i32| acc.wrapping_add(smmulr(c, v));
    let mut t = table.iter().copied();
    for p in 0..pairs {
        let i = 2 * p;
        // Past the table, as the assembly would read what follows it:
        // here zeros, so that a count of pairs too large shows.
        let (groups, diag) = (t.next().unwrap_or(0), t.next().unwrap_or(0));
        let mut a = smmulr(diag, z.get(i).copied().unwrap_or(0));
        let mut b = 0;
        for g in 0..groups.max(0) as usize {
            let j = i + 1 + 3 * g;
            let v: [i32; 3] = core::array::from_fn(|k| z.get(j + k).copied().unwrap_or(0));
            for &x in &v {
                a = mac(a, t.next().unwrap_or(0), x);
            }
            for &x in &v {
                b = mac(b, t.next().unwrap_or(0), x);
            }
        }
        if let Some(w) = z.get_mut(i) {
            *w = a;
        }
        if let Some(w) = z.get_mut(i + 1) {
            *w = b;
        }
    }
}

#[cfg(target_arch = "arm")]
mod square_arm {
    // `(table, z, pairs) -> table'`: for each pair of rows `(i, i+1)`,
    // `z[i]` and `z[i+1]` from the record (count, diagonal, groups): one
    // `LDM` of three inputs and one of six coefficients per group, six
    // `SMMLAR`s. Outputs are stored after the group loop, where no later
    // row reads them. r0 the table, r1 the row's first input (pushed with
    // r2, the pairs left, while the groups run), r2 the groups, r3 and lr
    // the two rows' sums, r4-r12 one group.
    core::arch::global_asm!(
        ".section .text.cvm_square_pairs,\"ax\",%progbits",
        ".global cvm_square_pairs",
        ".type cvm_square_pairs,%function",
        ".p2align 2",
        ".thumb_func",
        "cvm_square_pairs:",
        "    push {{r4, r5, r6, r7, r8, r9, r10, r11, lr}}",
        "1:",
        "    push {{r1, r2}}",
        "    ldm r0!, {{r2, r4}}",
        "    ldr r5, [r1], #4",
        "    smmulr r3, r4, r5",
        "    mov lr, #0",
        "2:",
        "    ldm r1!, {{r4, r5, r6}}",
        "    ldm r0!, {{r7, r8, r9, r10, r11, r12}}",
        "    smmlar r3, r7, r4, r3",
        "    smmlar r3, r8, r5, r3",
        "    smmlar r3, r9, r6, r3",
        "    smmlar lr, r10, r4, lr",
        "    smmlar lr, r11, r5, lr",
        "    smmlar lr, r12, r6, lr",
        "    subs r2, r2, #1",
        "    bne 2b",
        "    pop {{r1, r2}}",
        "    str r3, [r1], #4",
        "    str lr, [r1], #4",
        "    subs r2, r2, #1",
        "    bne 1b",
        "    pop {{r4, r5, r6, r7, r8, r9, r10, r11, pc}}",
        ".size cvm_square_pairs, . - cvm_square_pairs",
    );

    // `(ctx)`: the groups of `quads`. `ctx` holds the top row's first
    // and last sample, the bottom row's offset from the top (bytes), the
    // even-even and even-odd output rows, the odd-even and odd-odd rows'
    // offsets from those (bytes), `k`, `m` and the number of groups. Per
    // group: four `LDRH`, the eight sums and differences (each second one
    // as `s - 2 b`, which needs no spare register), four conversions
    // (`LSL`, `SMMULR`) and four stores.
    core::arch::global_asm!(
        ".section .text.cvm_square_quads,\"ax\",%progbits",
        ".global cvm_square_quads",
        ".type cvm_square_quads,%function",
        ".p2align 2",
        ".thumb_func",
        "cvm_square_quads:",
        "    push {{r4, r5, r6, r7, r8, r9, r10, r11, lr}}",
        "    ldm r0, {{r0, r1, r2, r3, r4, r5, r6, r7, r8, r9}}",
        "1:",
        "    ldrh r10, [r0, r2]",
        "    ldrh r11, [r1, r2]",
        "    ldrh r12, [r0], #2",
        "    ldrh lr, [r1], #-2",
        "    add r12, r12, lr",
        "    sub lr, r12, lr, lsl #1",
        "    add r10, r10, r11",
        "    sub r11, r10, r11, lsl #1",
        "    add r12, r12, r10",
        "    sub r10, r12, r10, lsl #1",
        "    add lr, lr, r11",
        "    sub r11, lr, r11, lsl #1",
        "    lsl r12, r12, r7",
        "    smmulr r12, r12, r8",
        "    lsl r10, r10, r7",
        "    smmulr r10, r10, r8",
        "    lsl lr, lr, r7",
        "    smmulr lr, lr, r8",
        "    lsl r11, r11, r7",
        "    smmulr r11, r11, r8",
        "    str r10, [r3, r5]",
        "    str r12, [r3], #4",
        "    str r11, [r4, r6]",
        "    str lr, [r4], #4",
        "    subs r9, r9, #1",
        "    bne 1b",
        "    pop {{r4, r5, r6, r7, r8, r9, r10, r11, pc}}",
        ".size cvm_square_quads, . - cvm_square_quads",
    );

    unsafe extern "C" {
        pub fn cvm_square_pairs(table: *const i32, z: *mut i32, pairs: usize) -> *const i32;
        pub fn cvm_square_quads(ctx: *const [u32; 10]);
    }
}
