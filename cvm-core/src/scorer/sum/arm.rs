//! The Cortex-M loops of the sum pass: the whole blocks of four words of a
//! copied frame in one hand-written loop, and the saturation test of two
//! samples in one `UQSUB16`.

use core::mem::MaybeUninit;

/// Whether `sum_copy_blocks` does the whole blocks of a copy.
pub const BLOCKS: bool = true;

/// The loop of `words_sum` over whole blocks of four words
/// (`words.len() == dst.len()`, a non-zero multiple of 4): per block one
/// `LDM`, one `STM` (the copy) and per word `UXTAH`, `ADD ..., LSR #16`,
/// `UQSUB16`, `ORR`. Written by hand because the compiler, with the copy's
/// pointer as one more live register, spilled the sums to the stack.
#[inline(always)]
pub fn sum_copy_blocks(
    words: &[u32],
    dst: &mut [MaybeUninit<u32>],
    below2: u32,
) -> (u32, u32, u32) {
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
pub fn above2(w: u32, below2: u32) -> u32 {
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
