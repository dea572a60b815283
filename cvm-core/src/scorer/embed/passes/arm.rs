//! The paper kernels' passes on the Cortex-M: calls into the generated
//! Thumb-2 of each axis length (`passes_arm.s`, written by the host test
//! `passes_asm`, which also runs it on a model of the instructions against
//! the arithmetic of `portable.rs`).

use core::mem::MaybeUninit;

use crate::config::MAX_J;
use crate::scorer::embed::layout::{Factor, Rows};
use crate::scorer::words::{copy_words, squared_difference};

/// The row pass (module docs of `passes`), its rows in the order of
/// [`Rows`].
#[inline(never)]
pub fn rows<const H: usize, const G: usize>(
    f2: &Factor,
    frame: &[u16],
    n_rows: usize,
    conv: (u32, i32),
    t: &mut Rows,
) {
    let (sh, m) = (conv.0 & 31, conv.1);
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
    let pass = generated::rows(j2);
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

/// The column pass (module docs of `passes`).
#[inline(never)]
pub fn cols<const H: usize, const G: usize, const DIFF: bool, const NEAR: bool>(
    f1: &Factor,
    t: &[[MaybeUninit<i32>; MAX_J]],
    e: &mut [i32],
    near: &mut [i32],
) -> u64 {
    cols_arm::<DIFF, NEAR>(H + G, f1, t, e, near)
}

/// The column pass through the generated Cortex-M passes for `j1`
/// (`passes_arm.s`). With `NEAR` the new map goes to `near` (DTCM on the
/// H743), the distance reads the old one in `e` three words per `LDM`,
/// and the new map is then copied to `e`, eight words per `LDM`/`STM`:
/// the fewest accesses to the row buffers, which are on the bus. Without,
/// the pass writes `e` itself, with `DIFF` summing the distance to the
/// map it overwrites on the way (fewer instructions, more loads).
#[inline(always)]
fn cols_arm<const DIFF: bool, const NEAR: bool>(
    j1: usize,
    f1: &Factor,
    t: &[[MaybeUninit<i32>; MAX_J]],
    e: &mut [i32],
    near: &mut [i32],
) -> u64 {
    let ctx = [f1.even.as_ptr() as u32, f1.odd.as_ptr() as u32];
    let (plain, diff) = (generated::cols(j1), generated::cols_diff(j1));
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
        let acc = if DIFF { squared_difference(e, near) } else { 0 };
        copy_words(near, e);
        acc
    } else if DIFF {
        unsafe { diff(t.as_ptr().cast(), e.as_mut_ptr(), n, &ctx) }
    } else {
        unsafe { plain(t.as_ptr().cast(), e.as_mut_ptr(), n, &ctx) };
        0
    }
}

/// The generated passes (`passes_arm.s`, written by the host test
/// `passes_asm`, which also runs them on a model of the instructions
/// against the arithmetic of `portable.rs`).
mod generated {
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
