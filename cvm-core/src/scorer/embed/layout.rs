//! The data the paper kernels' passes share: the quantised factor of a
//! folded axis, as the passes stream it, and the row pass's output.

use core::mem::MaybeUninit;

use crate::config::MAX_J;

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
pub type Rows = [[MaybeUninit<i32>; MAX_J]; MAX_J];

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
