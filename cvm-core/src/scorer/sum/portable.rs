//! The sum pass's loops in Rust only, for targets without the Cortex-M's
//! DSP instructions.

use core::mem::MaybeUninit;

/// Whether `sum_copy_blocks` does the whole blocks of a copy: not here,
/// every word goes through the loops of `sum.rs`.
pub const BLOCKS: bool = false;

/// Never called (`BLOCKS` is false): nothing summed.
#[inline(always)]
pub fn sum_copy_blocks(_words: &[u32], _dst: &mut [MaybeUninit<u32>]) -> (u32, u32, u32) {
    (0, 0, 0)
}

/// The larger of each 16-bit half of `w` and `m`.
#[inline(always)]
pub fn max2(w: u32, m: u32) -> u32 {
    (w & 0xFFFF).max(m & 0xFFFF) | (w >> 16).max(m >> 16) << 16
}
