//! The paper kernels' passes in Rust: what the generated Cortex-M passes
//! (`passes_arm.s`) compute, run on every other target, term by term in
//! the same order with the same rounding.

use core::mem::MaybeUninit;

use crate::config::MAX_J;
use crate::scorer::embed::layout::{Factor, Rows, TRI};
use crate::scorer::words::copy_words;

/// The row pass (module docs of `passes`).
#[inline(never)]
pub fn rows<const H: usize, const G: usize>(
    f2: &Factor,
    frame: &[u16],
    n_rows: usize,
    conv: (u32, i32),
    t: &mut Rows,
) {
    let (sh, m) = (conv.0 & 31, conv.1);
    rows_model::<H, G>(f2, frame, n_rows, (sh, m), t);
}

/// The column pass (module docs of `passes`).
#[inline(never)]
pub fn cols<const H: usize, const G: usize, const DIFF: bool, const NEAR: bool>(
    f1: &Factor,
    t: &[[MaybeUninit<i32>; MAX_J]],
    e: &mut [i32],
    near: &mut [i32],
) -> u64 {
    let acc = cols_model::<H, G, DIFF, NEAR>(f1, t, e, near);
    if NEAR {
        copy_words(near, e);
    }
    acc
}

/// The row pass in Rust: what the generated Cortex-M pass computes
/// (`passes_arm.s`), run on every other target.
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

/// The column pass in Rust: what the generated Cortex-M pass computes,
/// run on every other target.
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
/// overflow proof (module `formats` of the scorer) keep every partial sum
/// inside `i32`.
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
