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
//! most 8 x 8, so each axis length gets its own straight-line passes: on
//! the Cortex-M generated Thumb-2 (`passes_arm.s`, whose accumulators stay
//! in registers for a whole row), elsewhere the same arithmetic in Rust
//! (`rows_model`, `cols_model`).

use core::mem::MaybeUninit;

use crate::config::{MAX_CELLS, MAX_J};
use crate::tables::{Mat, abs, cholesky_psd, pivot_tolerance, pow2, round};

/// Largest block of a folded axis (`ceil(16 / 2)`).
pub const MAX_H: usize = MAX_J.div_ceil(2);
/// Words of a packed upper-triangular `MAX_H x MAX_H` block.
pub const TRI: usize = MAX_H * (MAX_H + 1) / 2;

/// The row pass's output `T`, transposed (`t[k][i]`), in a fixed `MAX_J`
/// stride; only the words the row pass writes are read. On the Cortex-M
/// the detector rows take the words of a row of `t` in another order
/// (the top half at the even words, the bottom half from the last row up
/// at the odd ones), so that the column pass reads each pair of rows it
/// folds with one `LDRD`; the Rust passes keep `i` in order.
type Rows = [[MaybeUninit<i32>; MAX_J]; MAX_J];

/// The quantised factor of one folded axis: the even block (`h` cells, the
/// middle one included) and the odd block (`g` cells), each upper
/// triangular and packed column by column (`r[0..=l][l]`, the order
/// in which the passes stream them), in `Q(p)`.
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

/// A copy of a frame's samples, made by [`sum_and_saturation`] while it
/// reads them: on the H743 it is on the stack, in DTCM, so that the row
/// pass reads the samples without wait states from there instead of from
/// the DMA buffer in AXI SRAM. Uninitialised until copied into.
#[repr(C, align(4))]
pub struct FrameCopy([MaybeUninit<u16>; MAX_CELLS]);

impl FrameCopy {
    pub const fn new() -> FrameCopy {
        FrameCopy([MaybeUninit::uninit(); MAX_CELLS])
    }
}

impl Default for FrameCopy {
    fn default() -> Self {
        Self::new()
    }
}

/// The sum of all samples of a frame and whether a sample reached
/// `full_scale` (the saturation flag): the only per-map quantities needed
/// before the row pass. At most `256 * 65535 < 2^24`: the sum cannot
/// overflow. Also returns the samples to embed: `copy`, filled on the way
/// (one store per word read), or `frame` itself when the frame is not
/// word-aligned or longer than a map can be (never in the firmware), or
/// when the full scale is 0.
///
/// The frame is read as 32-bit words of two samples (sample order does not
/// matter for either result): per word one `UXTAH` and one `ADD ..., LSR
/// #16` for the sum, and on the Cortex-M one `UQSUB16` against
/// `full_scale - 1` in both halves and one `ORR` for the flag (a lane is
/// non-zero iff its sample is above `full_scale - 1`), so about two
/// instructions per sample instead of five. The words come in blocks of
/// four, which the compiler loads with one `LDM`.
#[inline(never)]
pub fn sum_and_saturation<'a>(
    frame: &'a [u16],
    full_scale: u16,
    copy: &'a mut FrameCopy,
) -> (u32, bool, &'a [u16]) {
    if full_scale == 0 {
        // Every sample reaches a full scale of 0 (a frame is never empty).
        let mut sum = 0u32;
        for &a in frame {
            sum += a as u32;
        }
        return (sum, true, frame);
    }
    let below = (full_scale - 1) as u32;
    let below2 = below | (below << 16);
    // SAFETY: every bit pattern is a valid `u32`; `align_to` only splits
    // off the unaligned ends.
    let (head, words, tail) = unsafe { frame.align_to::<u32>() };
    // The copy is word for word, so the frame must start on a word and
    // fit.
    let copying = head.is_empty() && frame.len() <= MAX_CELLS;
    // SAFETY: `FrameCopy` is 4-aligned and `MAX_CELLS` u16 long, i.e.
    // `MAX_CELLS / 2` words; a `MaybeUninit<u32>` may hold anything.
    // (`frame.len() <= MAX_CELLS` gives every word of `words` its slot.)
    let (_, dst, _) = unsafe { copy.0.align_to_mut::<MaybeUninit<u32>>() };
    let ((mut lo, hi, mut over), copied) = match dst.get_mut(..words.len()) {
        Some(dst) if copying => (words_sum(words, below2, dst), true),
        _ => (words_sum(words, below2, &mut []), false),
    };
    for &a in head.iter().chain(tail) {
        lo += a as u32;
        over |= (a as u32).saturating_sub(below);
    }
    let sum = lo + hi;
    let sat = over != 0;
    if !copied {
        return (sum, sat, frame);
    }
    if let (Some(&t), Some(d)) = (tail.first(), copy.0.get_mut(2 * words.len())) {
        d.write(t);
    }
    // SAFETY: the first `frame.len()` samples of the copy were written
    // above: `2 * words.len()` by the word loops (every word of `words`
    // has its slot, `frame.len() <= MAX_CELLS`), then the tail's one
    // sample (a `u16` slice starting on a word has at most one).
    let samples =
        unsafe { core::slice::from_raw_parts(copy.0.as_ptr().cast::<u16>(), frame.len()) };
    (sum, sat, samples)
}

/// The low and high halves' sums and the saturation bits of `words`,
/// copying them to `dst` on the way when it is as long as `words` (empty:
/// no copy). Two loops, so that the copying one has no per-word test.
#[inline(always)]
fn words_sum(words: &[u32], below2: u32, dst: &mut [MaybeUninit<u32>]) -> (u32, u32, u32) {
    let copying = dst.len() == words.len();
    // On the Cortex-M the whole blocks of a copy go through the assembly
    // loop; the rest (and everything elsewhere) through the loops below.
    #[cfg(target_arch = "arm")]
    let ((mut lo, mut hi, mut over), words, dst) = if copying && words.len() >= 4 {
        let k = words.len() / 4 * 4;
        let (w4, wr) = words.split_at(k);
        let (d4, dr) = dst.split_at_mut(k);
        (sum_copy_blocks(w4, d4, below2), wr, dr)
    } else {
        ((0u32, 0u32, 0u32), words, dst)
    };
    #[cfg(not(target_arch = "arm"))]
    let (mut lo, mut hi, mut over) = (0u32, 0u32, 0u32);
    let mut add = |w: u32| {
        lo += w & 0xFFFF;
        hi += w >> 16;
        over |= above2(w, below2);
    };
    if copying {
        for (b, d) in words.chunks_exact(4).zip(dst.chunks_exact_mut(4)) {
            if let (&[w0, w1, w2, w3], [d0, d1, d2, d3]) = (b, d) {
                add(w0);
                add(w1);
                add(w2);
                add(w3);
                d0.write(w0);
                d1.write(w1);
                d2.write(w2);
                d3.write(w3);
            }
        }
        let done = words.len() / 4 * 4;
        for (w, d) in words.iter().zip(dst.iter_mut()).skip(done) {
            add(*w);
            d.write(*w);
        }
    } else {
        for &w in words {
            add(w);
        }
    }
    (lo, hi, over)
}

/// The Cortex-M loop of [`words_sum`] over whole blocks of four words
/// (`words.len() == dst.len()`, a non-zero multiple of 4): per block one
/// `LDM`, one `STM` (the copy) and per word `UXTAH`, `ADD ..., LSR #16`,
/// `UQSUB16`, `ORR`. Written by hand because the compiler, with the copy's
/// pointer as one more live register, spilled the sums to the stack.
#[cfg(target_arch = "arm")]
#[inline(always)]
fn sum_copy_blocks(words: &[u32], dst: &mut [MaybeUninit<u32>], below2: u32) -> (u32, u32, u32) {
    let (mut lo, mut hi, mut over) = (0u32, 0u32, 0u32);
    let n = words.len().min(dst.len()) / 4;
    if n == 0 {
        return (lo, hi, over);
    }
    // SAFETY: reads `4 n` words from `words` and writes `4 n` to `dst`,
    // both at least that long; registers only otherwise.
    unsafe {
        core::arch::asm!(
            "2:",
            "ldm {src}!, {{r0, r1, r2, r3}}",
            "stm {dst}!, {{r0, r1, r2, r3}}",
            "uxtah {lo}, {lo}, r0",
            "add {hi}, {hi}, r0, lsr #16",
            "uqsub16 r0, r0, {b}",
            "orr {over}, {over}, r0",
            "uxtah {lo}, {lo}, r1",
            "add {hi}, {hi}, r1, lsr #16",
            "uqsub16 r1, r1, {b}",
            "orr {over}, {over}, r1",
            "uxtah {lo}, {lo}, r2",
            "add {hi}, {hi}, r2, lsr #16",
            "uqsub16 r2, r2, {b}",
            "orr {over}, {over}, r2",
            "uxtah {lo}, {lo}, r3",
            "add {hi}, {hi}, r3, lsr #16",
            "uqsub16 r3, r3, {b}",
            "orr {over}, {over}, r3",
            "subs {n}, {n}, #1",
            "bne 2b",
            src = inout(reg) words.as_ptr() => _,
            dst = inout(reg) dst.as_mut_ptr() => _,
            n = inout(reg) n => _,
            lo = inout(reg) lo,
            hi = inout(reg) hi,
            over = inout(reg) over,
            b = in(reg) below2,
            // r0-r3 hold the four words: `LDM`/`STM` order their register
            // lists by number, so the list is written in that order.
            out("r0") _,
            out("r1") _,
            out("r2") _,
            out("r3") _,
            options(nostack)
        );
    }
    (lo, hi, over)
}

/// Both 16-bit halves of `w` minus those of `below2`, saturating at 0
/// (`UQSUB16`): non-zero iff a half of `w` exceeds the matching half of
/// `below2`.
#[inline(always)]
fn above2(w: u32, below2: u32) -> u32 {
    #[cfg(target_arch = "arm")]
    {
        let r: u32;
        // SAFETY: a pure register operation (`UQSUB16` is part of the
        // Cortex-M4/M7 DSP extension of thumbv7em).
        unsafe {
            core::arch::asm!(
                "uqsub16 {r}, {w}, {b}",
                r = lateout(reg) r,
                w = in(reg) w,
                b = in(reg) below2,
                options(pure, nomem, nostack, preserves_flags)
            );
        }
        r
    }
    #[cfg(not(target_arch = "arm"))]
    {
        (w & 0xFFFF).saturating_sub(below2 & 0xFFFF) | (w >> 16).saturating_sub(below2 >> 16)
    }
}

/// `round(a * b / 2^32)`: one `SMMULR`.
#[cfg(not(target_arch = "arm"))]
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
#[cfg(not(target_arch = "arm"))]
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

/// Row pass for an axis 2 of `H + G` cells over the first `n_rows` rows of
/// a row-major frame: folds each row along axis 2 (`a[l] ± a[H+G-1-l]`,
/// exact), converts the folded counts to `Q(f)`
/// (`round((v << k) * m / 2^32)`), applies the even and the odd block and
/// stores the results transposed, `t[k][i]` (even) and `t[H + k][i]`
/// (odd): every `t[k][i]` with `k < H + G` and `i < n_rows` is written
/// (on the Cortex-M with `i` in the order of [`Rows`]).
#[inline(never)]
fn rows<const H: usize, const G: usize>(
    f2: &Factor,
    frame: &[u16],
    n_rows: usize,
    conv: (u32, i32),
    t: &mut Rows,
) {
    let (sh, m) = (conv.0 & 31, conv.1);
    #[cfg(target_arch = "arm")]
    {
        let j2 = H + G;
        let n = n_rows.min(MAX_J).min(frame.len() / j2.max(1));
        // Two calls: the top half of the rows into the even words of each
        // row of `t`, the bottom half, from the last row up, into the odd
        // words, so that the rows the column pass folds together are
        // adjacent (one `LDRD`).
        let top = n.div_ceil(2);
        let stride = 2 * j2 as u32;
        let ctx = |stride: u32| {
            [
                f2.even.as_ptr() as u32,
                f2.odd.as_ptr() as u32,
                m as u32,
                sh,
                stride,
            ]
        };
        let pass = arm::rows(j2);
        if top > 0 {
            // SAFETY: the generated pass for `j2` reads `top * j2` samples
            // of `frame` from its first row down and the factor's
            // `TRI`-word blocks, and writes word `2 i` of `t[k]` for
            // `k < j2 <= MAX_J`, `i < top`, `2 i < n <= MAX_J`; it
            // preserves the callee-saved registers (AAPCS).
            unsafe { pass(frame.as_ptr(), t.as_mut_ptr().cast(), top, &ctx(stride)) };
        }
        if n > top {
            // SAFETY: as above, from row `n - 1` up (a negative stride) for
            // `n - top` rows, each to word `2 i + 1 < n` of `t[k]`.
            unsafe {
                pass(
                    frame.as_ptr().add((n - 1) * j2),
                    t.as_mut_ptr().cast::<i32>().add(1),
                    n - top,
                    &ctx(stride.wrapping_neg()),
                )
            };
        }
    }
    #[cfg(not(target_arch = "arm"))]
    rows_model::<H, G>(f2, frame, n_rows, (sh, m), t);
}

/// The row pass in Rust: what the generated Cortex-M pass computes
/// (`passes_arm.s`), run on every other target.
#[cfg(not(target_arch = "arm"))]
#[inline(always)]
fn rows_model<const H: usize, const G: usize>(
    f2: &Factor,
    frame: &[u16],
    n_rows: usize,
    (sh, m): (u32, i32),
    t: &mut Rows,
) {
    let j2 = H + G;
    let (te, to) = t.split_at_mut(H);
    let (Some(Ok(te)), Some(Ok(to))) = (
        te.get_mut(..H)
            .map(<&mut [[MaybeUninit<i32>; MAX_J]; H]>::try_from),
        to.get_mut(..G)
            .map(<&mut [[MaybeUninit<i32>; MAX_J]; G]>::try_from),
    ) else {
        return;
    };
    for (i, row) in frame.chunks_exact(j2.max(1)).take(n_rows).enumerate() {
        let Some(Ok(row)) = row.get(..j2).map(<&[u16]>::try_from) else {
            return;
        };
        let row: &[u16] = row;
        // Constant indices below the row's length once unrolled.
        let at = |l: usize| row.get(l).copied().unwrap_or(0) as i32;
        let ue: [i32; H] = core::array::from_fn(|l| {
            let v = if l < G { at(l) + at(j2 - 1 - l) } else { at(l) };
            mul_hi_round(v << sh, m)
        });
        let oe = tri::<H>(&f2.even, &ue);
        for (tk, &v) in te.iter_mut().zip(oe.iter()) {
            tk[i & (MAX_J - 1)].write(v);
        }
        let uo: [i32; G] =
            core::array::from_fn(|l| mul_hi_round((at(l) - at(j2 - 1 - l)) << sh, m));
        let oo = tri::<G>(&f2.odd, &uo);
        for (tk, &v) in to.iter_mut().zip(oo.iter()) {
            tk[i & (MAX_J - 1)].write(v);
        }
    }
}

/// Column pass for an axis 1 of `H + G` cells: for every row `t[k]` (a
/// folded column of the map), folds it along axis 1 (`t[l] ± t[H+G-1-l]`,
/// exact), applies the even and the odd block and stores the embedding in
/// the `k`-th chunk of `e` (even part first), and with `NEAR` in `near`
/// too (as long as `e`).
///
/// With `DIFF`, returns `Σ (old - new)²` over the overwritten words: the
/// squared distance to the map `e` held before, for the price of one load,
/// one subtraction and one `SMLAL` per word (wrapping, so that a buffer
/// that held no map cannot make it panic; for two maps it cannot wrap).
#[inline(never)]
fn cols<const H: usize, const G: usize, const DIFF: bool, const NEAR: bool>(
    f1: &Factor,
    t: &[[MaybeUninit<i32>; MAX_J]],
    e: &mut [i32],
    near: &mut [i32],
) -> u64 {
    #[cfg(target_arch = "arm")]
    return cols_arm::<DIFF, NEAR>(H + G, f1, t, e, near);
    #[cfg(not(target_arch = "arm"))]
    {
        let acc = cols_model::<H, G, DIFF, NEAR>(f1, t, e, near);
        if NEAR {
            copy_words(near, e);
        }
        acc
    }
}

/// The column pass through the generated Cortex-M passes for `j1`
/// (`passes_arm.s`). With `NEAR` the new map goes to `near` (DTCM on the
/// H743), the distance reads the old one in `e` three words per `LDM`,
/// and the new map is then copied to `e`, eight words per `LDM`/`STM`:
/// the fewest accesses to the row buffers, which are on the bus. Without,
/// the pass writes `e` itself, with `DIFF` summing the distance to the
/// map it overwrites on the way (fewer instructions, more loads).
#[cfg(target_arch = "arm")]
#[inline(always)]
fn cols_arm<const DIFF: bool, const NEAR: bool>(
    j1: usize,
    f1: &Factor,
    t: &[[MaybeUninit<i32>; MAX_J]],
    e: &mut [i32],
    near: &mut [i32],
) -> u64 {
    let ctx = [f1.even.as_ptr() as u32, f1.odd.as_ptr() as u32];
    let (plain, diff) = (arm::cols(j1), arm::cols_diff(j1));
    let j1 = j1.max(1);
    let mut n = t.len().min(MAX_J).min(e.len() / j1);
    if NEAR {
        n = n.min(near.len() / j1);
    }
    let words = n * j1;
    let (Some(e), Some(near)) = (
        e.get_mut(..words),
        near.get_mut(..if NEAR { words } else { 0 }),
    ) else {
        return 0;
    };
    if n == 0 {
        return 0;
    }
    // SAFETY (every call): the pass reads `j1` initialised words (written
    // by the row pass) of each of the first `n` rows of `t` and the
    // factor's blocks, writes `n * j1` words at its second argument (and
    // reads them first, `diff`), which holds as many, and preserves the
    // callee-saved registers (AAPCS).
    if NEAR {
        unsafe { plain(t.as_ptr().cast(), near.as_mut_ptr(), n, &ctx) };
        let acc = if DIFF {
            super::squared_difference(e, near)
        } else {
            0
        };
        copy_words(near, e);
        acc
    } else if DIFF {
        unsafe { diff(t.as_ptr().cast(), e.as_mut_ptr(), n, &ctx) }
    } else {
        unsafe { plain(t.as_ptr().cast(), e.as_mut_ptr(), n, &ctx) };
        0
    }
}

/// The column pass in Rust: what the generated Cortex-M pass computes,
/// run on every other target.
#[cfg(not(target_arch = "arm"))]
#[inline(always)]
fn cols_model<const H: usize, const G: usize, const DIFF: bool, const NEAR: bool>(
    f1: &Factor,
    t: &[[MaybeUninit<i32>; MAX_J]],
    e: &mut [i32],
    near: &mut [i32],
) -> u64 {
    let j1 = H + G;
    let mut acc = 0u64;
    // With `NEAR` the new map goes to `near` (as long as `e`; `cols`
    // copies it to `e` after), while the distance still reads the old one
    // in `e`.
    let mut near = near.chunks_exact_mut(j1.max(1));
    for (tr, er) in t.iter().zip(e.chunks_exact_mut(j1.max(1))) {
        let (de, dodd) = er.split_at_mut(H.min(er.len()));
        let (Ok(de), Ok(dodd)) = (
            <&mut [i32; H]>::try_from(de),
            <&mut [i32; G]>::try_from(dodd),
        ) else {
            return acc;
        };
        // Constant indices below MAX_J once unrolled: no bounds checks.
        // SAFETY: `l < j1`, and the row pass wrote the first `j1` words of
        // every row of `t` that `embed` hands to this pass.
        let tr = |l: usize| unsafe { tr[l & (MAX_J - 1)].assume_init() };
        let ue: [i32; H] = core::array::from_fn(|l| {
            if l < G {
                tr(l).wrapping_add(tr(j1 - 1 - l))
            } else {
                tr(l)
            }
        });
        let uo: [i32; G] = core::array::from_fn(|l| tr(l).wrapping_sub(tr(j1 - 1 - l)));
        let (ne, no) = (tri::<H>(&f1.even, &ue), tri::<G>(&f1.odd, &uo));
        if DIFF {
            // Two fixed-length loops: fully unrolled, one SMLAL per word.
            for k in 0..H {
                let d = de[k].wrapping_sub(ne[k]) as i64;
                acc = acc.wrapping_add(d.wrapping_mul(d) as u64);
            }
            for k in 0..G {
                let d = dodd[k].wrapping_sub(no[k]) as i64;
                acc = acc.wrapping_add(d.wrapping_mul(d) as u64);
            }
        }
        if NEAR {
            let Some(nr) = near.next() else {
                return acc;
            };
            let (ve, vo) = nr.split_at_mut(H.min(nr.len()));
            if let (Ok(ve), Ok(vo)) = (<&mut [i32; H]>::try_from(ve), <&mut [i32; G]>::try_from(vo))
            {
                *ve = ne;
                *vo = no;
            }
        } else {
            *de = ne;
            *dodd = no;
        }
    }
    acc
}

/// The generated Cortex-M passes (`passes_arm.s`, written by the host test
/// `passes_asm`, which also runs them on a model of the instructions
/// against the arithmetic of `rows_model` and `cols_model`).
#[cfg(target_arch = "arm")]
mod arm {
    core::arch::global_asm!(include_str!("passes_arm.s"), options(raw));

    /// `(frame, t, rows, [even, odd, m, sh, stride])`.
    pub type RowsPass = unsafe extern "C" fn(*const u16, *mut i32, usize, *const [u32; 5]);
    /// `(t, out, rows, [even, odd])`.
    pub type ColsPass = unsafe extern "C" fn(*const i32, *mut i32, usize, *const [u32; 2]);
    /// `(t, e, rows, [even, odd]) -> distance`.
    pub type ColsDiffPass =
        unsafe extern "C" fn(*const i32, *mut i32, usize, *const [u32; 2]) -> u64;

    macro_rules! passes {
        ($($j:literal => $rows:ident, $cols:ident, $diff:ident;)*) => {
            unsafe extern "C" {
                $(
                    fn $rows(frame: *const u16, t: *mut i32, n: usize, ctx: *const [u32; 5]);
                    fn $cols(t: *const i32, out: *mut i32, n: usize, ctx: *const [u32; 2]);
                    fn $diff(t: *const i32, e: *mut i32, n: usize, ctx: *const [u32; 2]) -> u64;
                )*
            }
            /// The row pass of an axis of `j` cells (`j` is a constant
            /// where it is called: one direct call, one symbol linked).
            #[inline(always)]
            pub fn rows(j: usize) -> RowsPass {
                match j {
                    $($j => $rows,)*
                    _ => cvm_rows_1,
                }
            }
            /// The column pass of an axis of `j` cells.
            #[inline(always)]
            pub fn cols(j: usize) -> ColsPass {
                match j {
                    $($j => $cols,)*
                    _ => cvm_cols_1,
                }
            }
            /// The column pass with the distance to the map it overwrites.
            #[inline(always)]
            pub fn cols_diff(j: usize) -> ColsDiffPass {
                match j {
                    $($j => $diff,)*
                    _ => cvm_cols_diff_1,
                }
            }
        };
    }
    passes! {
        1 => cvm_rows_1, cvm_cols_1, cvm_cols_diff_1;
        2 => cvm_rows_2, cvm_cols_2, cvm_cols_diff_2;
        3 => cvm_rows_3, cvm_cols_3, cvm_cols_diff_3;
        4 => cvm_rows_4, cvm_cols_4, cvm_cols_diff_4;
        5 => cvm_rows_5, cvm_cols_5, cvm_cols_diff_5;
        6 => cvm_rows_6, cvm_cols_6, cvm_cols_diff_6;
        7 => cvm_rows_7, cvm_cols_7, cvm_cols_diff_7;
        8 => cvm_rows_8, cvm_cols_8, cvm_cols_diff_8;
        9 => cvm_rows_9, cvm_cols_9, cvm_cols_diff_9;
        10 => cvm_rows_10, cvm_cols_10, cvm_cols_diff_10;
        11 => cvm_rows_11, cvm_cols_11, cvm_cols_diff_11;
        12 => cvm_rows_12, cvm_cols_12, cvm_cols_diff_12;
        13 => cvm_rows_13, cvm_cols_13, cvm_cols_diff_13;
        14 => cvm_rows_14, cvm_cols_14, cvm_cols_diff_14;
        15 => cvm_rows_15, cvm_cols_15, cvm_cols_diff_15;
        16 => cvm_rows_16, cvm_cols_16, cvm_cols_diff_16;
    }
}

/// `dst[..] = src[..]` (as long as the shorter), for the maps copied
/// between the near buffer and the row buffer: on the Cortex-M eight
/// words per `LDM`/`STM` pair, about half an instruction per word, where
/// a second store per word from the column pass cost two (its outputs are
/// spilled to the stack by then).
#[inline(never)]
pub(crate) fn copy_words(src: &[i32], dst: &mut [i32]) {
    #[cfg(target_arch = "arm")]
    let (src, dst) = {
        let blocks = src.len().min(dst.len()) / 8;
        if blocks > 0 {
            // SAFETY: reads `8 blocks` words of `src` and writes as many to
            // `dst`, both at least that long; r0-r5, r12 and lr are
            // declared clobbered.
            unsafe {
                core::arch::asm!(
                    "2:",
                    "ldm {src}!, {{r0, r1, r2, r3, r4, r5, r12, lr}}",
                    "stm {dst}!, {{r0, r1, r2, r3, r4, r5, r12, lr}}",
                    "subs {n}, {n}, #1",
                    "bne 2b",
                    src = inout(reg) src.as_ptr() => _,
                    dst = inout(reg) dst.as_mut_ptr() => _,
                    n = inout(reg) blocks => _,
                    out("r0") _,
                    out("r1") _,
                    out("r2") _,
                    out("r3") _,
                    out("r4") _,
                    out("r5") _,
                    out("r12") _,
                    out("lr") _,
                    options(nostack)
                );
            }
        }
        (
            src.get(blocks * 8..).unwrap_or(&[]),
            dst.get_mut(blocks * 8..).unwrap_or(&mut []),
        )
    };
    for (d, &v) in dst.iter_mut().zip(src) {
        *d = v;
    }
}

/// A row pass (see [`rows`]).
type RowsFn = fn(&Factor, &[u16], usize, (u32, i32), &mut Rows);
/// A column pass (see [`cols`]).
type ColsFn = fn(&Factor, &[[MaybeUninit<i32>; MAX_J]], &mut [i32], &mut [i32]) -> u64;

/// The unrolled passes of one geometry, chosen when the tables are built.
/// A firmware whose `Scorer` is a compile-time constant references only
/// its own geometry's three passes, so the linker drops the other 45
/// (about 26 KB of flash); a dispatch at run time would keep them all.
#[derive(Clone, Copy)]
pub struct Passes {
    rows: RowsFn,
    /// The column pass: `[diff as usize + 2 * near as usize]`, so that
    /// neither the distance nor the second copy costs a test per column.
    cols: [ColsFn; 4],
}

impl Passes {
    /// The passes of a `j1 x j2` map (`None` outside `1..=16`).
    pub const fn new(j1: usize, j2: usize) -> Option<Passes> {
        let rows: RowsFn = match j2 {
            1 => rows::<1, 0>,
            2 => rows::<1, 1>,
            3 => rows::<2, 1>,
            4 => rows::<2, 2>,
            5 => rows::<3, 2>,
            6 => rows::<3, 3>,
            7 => rows::<4, 3>,
            8 => rows::<4, 4>,
            9 => rows::<5, 4>,
            10 => rows::<5, 5>,
            11 => rows::<6, 5>,
            12 => rows::<6, 6>,
            13 => rows::<7, 6>,
            14 => rows::<7, 7>,
            15 => rows::<8, 7>,
            16 => rows::<8, 8>,
            _ => return None,
        };
        macro_rules! cols_of {
            ($($j:literal => ($h:literal, $g:literal)),*) => {
                match j1 {
                    $($j => [
                        cols::<$h, $g, false, false> as ColsFn,
                        cols::<$h, $g, true, false> as ColsFn,
                        cols::<$h, $g, false, true> as ColsFn,
                        cols::<$h, $g, true, true> as ColsFn,
                    ],)*
                    _ => return None,
                }
            };
        }
        let cols = cols_of!(
            1 => (1, 0), 2 => (1, 1), 3 => (2, 1), 4 => (2, 2), 5 => (3, 2), 6 => (3, 3),
            7 => (4, 3), 8 => (4, 4), 9 => (5, 4), 10 => (5, 5), 11 => (6, 5), 12 => (6, 6),
            13 => (7, 6), 14 => (7, 7), 15 => (8, 7), 16 => (8, 8)
        );
        Some(Passes { rows, cols })
    }
}

/// Equal when built for the same geometry (the `Scorer`'s configuration
/// is compared as well).
impl PartialEq for Passes {
    fn eq(&self, other: &Self) -> bool {
        core::ptr::fn_addr_eq(self.rows, other.rows)
            && self
                .cols
                .iter()
                .zip(other.cols.iter())
                .all(|(&a, &b)| core::ptr::fn_addr_eq(a, b))
    }
}

impl core::fmt::Debug for Passes {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("Passes")
    }
}

/// `E = R1' y R2'ᵀ` of a row-major frame (converted by `conv`), folded
/// along axis 2 in the row pass and along axis 1 in the column pass, stored
/// folded-column-major in `e` (`j1 * j2` words): `e[k * j1 + i]`, the even
/// columns of axis 2 first. With `diff`, returns the squared distance
/// between the map `e` held before and the new one (else 0). The
/// embedding is also written to `near` when it is at least as long as `e`
/// (else not). `passes` are those of `f1`'s and `f2`'s geometry.
#[allow(clippy::too_many_arguments)]
pub fn embed(
    passes: &Passes,
    f1: &Factor,
    f2: &Factor,
    frame: &[u16],
    conv: (u32, i32),
    e: &mut [i32],
    near: &mut [i32],
    diff: bool,
) -> u64 {
    let j1 = f1.h + f1.g;
    if frame.len() != j1 * (f2.h + f2.g) {
        return 0;
    }
    // The row pass's output, on the stack: in DTCM on the H743, where the
    // engine's own state is in AXI SRAM (one wait-stated store and load
    // per word of it otherwise). Not cleared: the row pass writes every
    // word the column pass reads.
    let mut t: Rows = [[MaybeUninit::uninit(); MAX_J]; MAX_J];
    let t = &mut t;
    (passes.rows)(f2, frame, j1, conv, t);
    // Even and odd rows of `t` are consecutive, like their chunks of `e`:
    // one call of the column pass (its coefficients are set up once).
    let words = j1 * (f2.h + f2.g);
    let (Some(t), Some(e)) = (t.get(..f2.h + f2.g), e.get_mut(..words)) else {
        return 0;
    };
    let (near, with_near) = match near.get_mut(..words) {
        Some(n) => (n, 2),
        None => (&mut [][..], 0),
    };
    // The column pass leaves the new map in `e` and, `with_near`, in `near`.
    let acc = (passes.cols[usize::from(diff) + with_near])(f1, t, e, near);
    if diff { acc } else { 0 }
}
