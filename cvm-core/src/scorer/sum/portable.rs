//! The sum pass's loops in Rust only, for targets without the Cortex-M's
//! DSP instructions.

use core::mem::MaybeUninit;

/// Whether `sum_copy_blocks` does the whole blocks of a copy: not here,
/// every word goes through the loops of `sum.rs`.
pub const BLOCKS: bool = false;

/// Never called (`BLOCKS` is false): nothing summed.
#[inline(always)]
pub fn sum_copy_blocks(
    _words: &[u32],
    _dst: &mut [MaybeUninit<u32>],
    _below2: u32,
) -> (u32, u32, u32) {
    (0, 0, 0)
}

/// Both 16-bit halves of `w` minus those of `below2`, saturating at 0:
/// non-zero iff a half of `w` exceeds the matching half of `below2`.
#[inline(always)]
pub fn above2(w: u32, below2: u32) -> u32 {
    (w & 0xFFFF).saturating_sub(below2 & 0xFFFF) | (w >> 16).saturating_sub(below2 >> 16)
}
