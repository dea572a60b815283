//! The first pass over a frame, shared by both kernel sets: the sum of its
//! samples, the largest sample (whether the map saturated, and where the
//! spread channel's core is), and a copy of the samples in fast memory for
//! the passes that follow. On the Cortex-M the whole
//! blocks of a copy go through a hand-written loop (`sum/arm.rs`), the
//! rest (and everything elsewhere, `sum/portable.rs`) through the Rust
//! loops here.

use core::mem::MaybeUninit;

use crate::config::MAX_CELLS;

#[cfg(target_arch = "arm")]
mod arm;
#[cfg(target_arch = "arm")]
use arm::{BLOCKS, max2, sum_copy_blocks};
#[cfg(not(target_arch = "arm"))]
mod portable;
#[cfg(not(target_arch = "arm"))]
use portable::{BLOCKS, max2, sum_copy_blocks};

/// A copy of a frame's samples, made by [`sum_and_peak`] while it
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

/// The sum of all samples of a frame and its largest sample: the only
/// per-map quantities needed before the row pass (the map saturated when
/// the largest sample reaches the full scale; the spread channel's core is
/// centred on the first cell holding it). The sum is at most
/// `256 * 65535 < 2^24`: it cannot overflow. Also returns the samples to
/// embed: `copy`, filled on the way (one store per word read), or `frame`
/// itself when the frame is not word-aligned or longer than a map can be
/// (never in the firmware).
///
/// The frame is read as 32-bit words of two samples (sample order matters
/// for neither result): per word one `UXTAH` and one `ADD ..., LSR #16`
/// for the sum, and on the Cortex-M one `USUB16` and one `SEL` for the
/// running maximum of both halves, so two instructions per sample. The
/// words come in blocks of four, which the loop loads with one `LDM`.
#[inline(never)]
pub fn sum_and_peak<'a>(frame: &'a [u16], copy: &'a mut FrameCopy) -> (u32, u16, &'a [u16]) {
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
    let ((mut lo, hi, top2), copied) = match dst.get_mut(..words.len()) {
        Some(dst) if copying => (words_sum(words, dst), true),
        _ => (words_sum(words, &mut []), false),
    };
    let mut top = (top2 as u16).max((top2 >> 16) as u16);
    for &a in head.iter().chain(tail) {
        lo += a as u32;
        top = top.max(a);
    }
    let sum = lo + hi;
    if !copied {
        return (sum, top, frame);
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
    (sum, top, samples)
}

/// The low and high halves' sums and largest values of `words`,
/// copying them to `dst` on the way when it is as long as `words` (empty:
/// no copy). Two loops, so that the copying one has no per-word test.
#[inline(always)]
fn words_sum(words: &[u32], dst: &mut [MaybeUninit<u32>]) -> (u32, u32, u32) {
    let copying = dst.len() == words.len();
    // Where there is a block loop (`BLOCKS`), the whole blocks of a copy
    // go through it; the rest (and everything elsewhere) through the loops
    // below.
    let ((mut lo, mut hi, mut top), words, dst) = if BLOCKS && copying && words.len() >= 4 {
        let k = words.len() / 4 * 4;
        let (w4, wr) = words.split_at(k);
        let (d4, dr) = dst.split_at_mut(k);
        (sum_copy_blocks(w4, d4), wr, dr)
    } else {
        ((0u32, 0u32, 0u32), words, dst)
    };
    let mut add = |w: u32| {
        lo += w & 0xFFFF;
        hi += w >> 16;
        top = max2(w, top);
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
    (lo, hi, top)
}
