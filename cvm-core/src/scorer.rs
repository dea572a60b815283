//! The fixed-point scorer: normalise a raw map, embed it once, and score a
//! pair of embedded maps in `O(J1*J2)`. The square kernels' embedding is
//! in the module `square`; what follows is the paper kernels'.
//!
//! # The folded embedding (paper kernels)
//!
//! `d = ‖R1 D R2ᵀ‖²_F` with `Ki = Riᵀ Ri` (docs/method.md §4). Each axis kernel
//! is centrosymmetric, so folding an axis (`u[l] = x[l] + x[J-1-l]`,
//! `v[l] = x[l] - x[J-1-l]`, the middle cell in `u`) splits it into an even
//! and an odd block of at most 8 x 8 that do not interact; the factors `R'`
//! are the Cholesky factors of those blocks (module `embed`). A map costs
//! about `J1 J2 (J1 + J2 + 4) / 4` multiply-adds instead of
//! `J1 J2 (J1 + J2 + 2) / 2` (450 instead of 810 at 9x9), and every block
//! size has its own fully unrolled code.
//!
//! Per map: the sample sum `S` (and the saturation flag) first; then the row
//! pass folds each detector row along axis 2, converts it to `Q(f)` and
//! applies `R2'`; the column pass folds each column of that along axis 1,
//! applies `R1'` and stores `E`. In the streaming engine the column pass
//! also sums `(old - new)²` over the words it overwrites, which is the
//! vertical gradient component ([`Scorer::prepare_map`]).
//!
//! # Where each part is
//!
//! | module | holds |
//! |---|---|
//! | `setup` | [`Scorer`]: the tables and formats of one configuration, built once |
//! | `formats` | the fixed-point formats and the proof that nothing overflows |
//! | `normalise` | how samples become `Q(f)` values: the per-map scale and its reciprocal |
//! | `sum` | the first pass over a frame: its sum, its saturation and a copy |
//! | `prepare` | the per-map work: one entry point for both kernel sets |
//! | `embed` | the paper kernels' folded embedding: factors and passes |
//! | `square` | the square kernels' embedding |
//! | `words` | whole-map word loops: the squared distance and the copy |
//! | `score` | distances as scores, and scores in real units |
//! | `magnitude` | the gradient magnitude of two scores |
//! | `error` | why a frame could not be scored |
//!
//! Where a loop has a Cortex-M version written in assembly, it and the
//! portable Rust version sit in two files, `arm.rs` and `portable.rs`,
//! beside the one module that selects between them by `target_arch`.

mod embed;
mod error;
mod formats;
mod normalise;
mod prepare;
mod score;
mod setup;
mod square;
mod sum;
mod words;

pub use crate::channels::magnitude::magnitude;
pub use error::FrameError;
pub use formats::{Bounds, Formats};
/// The reciprocal of the normalisation, exposed for its exhaustive test.
#[doc(hidden)]
pub use normalise::reciprocal_q60;
pub use prepare::{Prepared, Scratch};
pub use setup::{MAX_FACTOR_WORDS, Scorer};
/// The sum pass, exposed for the test that checks when it copies the frame.
#[doc(hidden)]
pub use sum::{FrameCopy, sum_and_peak};
