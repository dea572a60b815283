//! The inner loops of the square kernels' passes, with one interface:
//! `quads` (one word of each block from four mirrored samples),
//! `pairs_of_rows` (two rows of a block's factor times its folded values)
//! and `smmulr` (`round(a b / 2^32)`). On the Cortex-M they are
//! hand-written assembly (`kernel/arm.rs`), elsewhere the same arithmetic
//! in Rust (`kernel/portable.rs`).

#[cfg(target_arch = "arm")]
mod arm;
#[cfg(target_arch = "arm")]
pub use arm::{pairs_of_rows, quads, smmulr};
#[cfg(not(target_arch = "arm"))]
mod portable;
#[cfg(not(target_arch = "arm"))]
pub use portable::{pairs_of_rows, quads, smmulr};
