//! The folded embedding of the paper kernels: tables (built once, `const`)
//! and the per-map passes (run for every beam).
//!
//! Each axis kernel `K` is centrosymmetric (`K[i][l] = K[J-1-i][J-1-l]`: a
//! box and its mirror image have the same size and weight), so the even and
//! the odd part of a vector under reversal do not interact:
//! `xᵀ K x = uᵀ Kₑ u + vᵀ Kₒ v` with `u[l] = x[l] + x[J-1-l]`,
//! `v[l] = x[l] - x[J-1-l]` (`l < J/2`, plus the middle cell in `u` when `J`
//! is odd). Folding the map on both axes (integer additions, exact) and
//! embedding each quarter with the Cholesky factors of the two half-size
//! blocks needs half the multiply-adds of `R1 x R2ᵀ`, and every block is at
//! most 8 x 8, so each axis length gets its own straight-line passes: on
//! the Cortex-M generated Thumb-2 (`embed/passes/passes_arm.s`, whose
//! accumulators stay in registers for a whole row), elsewhere the same
//! arithmetic in Rust (`embed/passes/portable.rs`).
//!
//! `layout` holds what the passes share (the quantised factor, the row
//! pass's output), `factor` builds the factors, `passes` picks the passes
//! of a geometry from the Cortex-M or the portable set, and [`embed`]
//! runs them on one map.

mod factor;
mod layout;
mod passes;

pub use factor::{RealFactor, precision, quantise, real_factor};
pub use layout::{Factor, MAX_H, TRI};
pub use passes::Passes;

use core::mem::MaybeUninit;

use crate::config::MAX_J;

use layout::Rows;

/// `E = R1' y R2'ᵀ` of a row-major frame (converted by `conv`), folded
/// along axis 2 in the row pass and along axis 1 in the column pass, stored
/// folded-column-major in `e` (`j1 * j2` words): `e[k * j1 + i]`, the even
/// columns of axis 2 first. With `diff`, returns the squared distance
/// between the map `e` held before and the new one (else 0). The
/// embedding is also written to `near` when it is at least as long as `e`
/// (else not). `passes` are those of `f1`'s and `f2`'s geometry.
#[allow(clippy::too_many_arguments)]
pub fn embed(
    passes: &Passes,
    f1: &Factor,
    f2: &Factor,
    frame: &[u16],
    conv: (u32, i32),
    e: &mut [i32],
    near: &mut [i32],
    diff: bool,
) -> u64 {
    let j1 = f1.h + f1.g;
    if frame.len() != j1 * (f2.h + f2.g) {
        return 0;
    }
    // The row pass's output, on the stack: in DTCM on the H743, where the
    // engine's own state is in AXI SRAM (one wait-stated store and load
    // per word of it otherwise). Not cleared: the row pass writes every
    // word the column pass reads.
    let mut t: Rows = [[MaybeUninit::uninit(); MAX_J]; MAX_J];
    let t = &mut t;
    (passes.rows)(f2, frame, j1, conv, t);
    // Even and odd rows of `t` are consecutive, like their chunks of `e`:
    // one call of the column pass (its coefficients are set up once).
    let words = j1 * (f2.h + f2.g);
    let (Some(t), Some(e)) = (t.get(..f2.h + f2.g), e.get_mut(..words)) else {
        return 0;
    };
    let (near, with_near) = match near.get_mut(..words) {
        Some(n) => (n, 2),
        None => (&mut [][..], 0),
    };
    // The column pass leaves the new map in `e` and, `with_near`, in `near`.
    let acc = (passes.cols[usize::from(diff) + with_near])(f1, t, e, near);
    if diff { acc } else { 0 }
}
