//! The Cortex-M loops of the sum pass: the whole blocks of four words of a
//! copied frame in one hand-written loop, and the larger sample of two
//! pairs in one `USUB16` and one `SEL`.

use core::mem::MaybeUninit;

/// Whether `sum_copy_blocks` does the whole blocks of a copy.
pub const BLOCKS: bool = true;

/// The loop of `words_sum` over whole blocks of four words
/// (`words.len() == dst.len()`, a non-zero multiple of 4): per block one
/// `LDM`, one `STM` (the copy) and per word `UXTAH`, `ADD ..., LSR #16`
/// (the sums), `USUB16`, `SEL` (the running maximum of each half, as
/// [`max2`]). Written by hand because the compiler, with the copy's
/// pointer as one more live register, spilled the sums to the stack.
#[inline(always)]
pub fn sum_copy_blocks(words: &[u32], dst: &mut [MaybeUninit<u32>]) -> (u32, u32, u32) {
    let (mut lo, mut hi, mut top) = (0u32, 0u32, 0u32);
    let n = words.len().min(dst.len()) / 4;
    if n == 0 {
        return (lo, hi, top);
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
            "usub16 {t}, r0, {top}",
            "sel {top}, r0, {top}",
            "uxtah {lo}, {lo}, r1",
            "add {hi}, {hi}, r1, lsr #16",
            "usub16 {t}, r1, {top}",
            "sel {top}, r1, {top}",
            "uxtah {lo}, {lo}, r2",
            "add {hi}, {hi}, r2, lsr #16",
            "usub16 {t}, r2, {top}",
            "sel {top}, r2, {top}",
            "uxtah {lo}, {lo}, r3",
            "add {hi}, {hi}, r3, lsr #16",
            "usub16 {t}, r3, {top}",
            "sel {top}, r3, {top}",
            "subs {n}, {n}, #1",
            "bne 2b",
            src = inout(reg) words.as_ptr() => _,
            dst = inout(reg) dst.as_mut_ptr() => _,
            n = inout(reg) n => _,
            lo = inout(reg) lo,
            hi = inout(reg) hi,
            top = inout(reg) top,
            // `USUB16` only sets the GE flags that `SEL` reads.
            t = out(reg) _,
            // r0-r3 hold the four words: `LDM`/`STM` order their register
            // lists by number, so the list is written in that order.
            out("r0") _,
            out("r1") _,
            out("r2") _,
            out("r3") _,
            options(nostack)
        );
    }
    (lo, hi, top)
}

/// The larger of each 16-bit half of `w` and `m`: `USUB16` sets the
/// halves' GE flags where `w`'s half is at least `m`'s, `SEL` takes those
/// halves from `w` and the others from `m`. Two instructions for two
/// samples.
#[inline(always)]
pub fn max2(w: u32, m: u32) -> u32 {
    let r: u32;
    // SAFETY: register operations only (`USUB16` and `SEL` are part of
    // the Cortex-M4/M7 DSP extension of thumbv7em); `t` is an output
    // written before `w` and `m` are read again, so it gets a register of
    // its own.
    unsafe {
        core::arch::asm!(
            "usub16 {t}, {w}, {m}",
            "sel {r}, {w}, {m}",
            t = out(reg) _,
            r = lateout(reg) r,
            w = in(reg) w,
            m = in(reg) m,
            options(pure, nomem, nostack)
        );
    }
    r
}
