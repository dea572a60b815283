//! Loops over the words of whole prepared maps: the squared distance of
//! two maps and the copy of one. On the Cortex-M their whole blocks of
//! words go through hand-written loops (`words/arm.rs`); the words past
//! those, and everything elsewhere (`words/portable.rs`, which does no
//! block), through the Rust loops here.

#[cfg(target_arch = "arm")]
mod arm;
#[cfg(target_arch = "arm")]
use arm::{copy_blocks, squared_difference_blocks};
#[cfg(not(target_arch = "arm"))]
mod portable;
#[cfg(not(target_arch = "arm"))]
use portable::{copy_blocks, squared_difference_blocks};

/// `Σ (a - b)²` of two embeddings: `|a|, |b| < 2^30`, so each difference
/// fits `i32` and the sum (below `2^62`) fits `i64`: one `SUB` and one
/// `SMLAL` per word. Kept out of line so that its registers are not shared
/// with the square-kernel path.
#[inline(never)]
pub fn squared_difference(a: &[i32], b: &[i32]) -> u64 {
    let (mut acc, done) = squared_difference_blocks(a, b);
    for (&x, &y) in a.iter().zip(b).skip(done) {
        let d = x.wrapping_sub(y) as i64;
        acc = acc.wrapping_add(d * d);
    }
    acc as u64
}

/// `dst[..] = src[..]` (as long as the shorter), for the maps copied
/// between the near buffer and the row buffer: on the Cortex-M eight
/// words per `LDM`/`STM` pair, about half an instruction per word, where
/// a second store per word from the column pass cost two (its outputs are
/// spilled to the stack by then).
#[inline(never)]
pub fn copy_words(src: &[i32], dst: &mut [i32]) {
    let (src, dst) = copy_blocks(src, dst);
    for (d, &v) in dst.iter_mut().zip(src) {
        *d = v;
    }
}
