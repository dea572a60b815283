//! The unrolled passes of each geometry, from the Cortex-M set
//! (`passes/arm.rs`, generated Thumb-2) or the portable one
//! (`passes/portable.rs`, the same arithmetic in Rust). Both offer:
//!
//! * `rows::<H, G>(f2, frame, n_rows, (k, m), t)`, the row pass for an
//!   axis 2 of `H + G` cells over the first `n_rows` rows of a row-major
//!   frame: folds each row along axis 2 (`a[l] ± a[H+G-1-l]`, exact),
//!   converts the folded counts to `Q(f)` (`round((v << k) * m / 2^32)`),
//!   applies the even and the odd block and stores the results transposed,
//!   `t[k][i]` (even) and `t[H + k][i]` (odd): every `t[k][i]` with
//!   `k < H + G` and `i < n_rows` is written (on the Cortex-M with `i` in
//!   the order of [`Rows`]).
//! * `cols::<H, G, DIFF, NEAR>(f1, t, e, near)`, the column pass for an
//!   axis 1 of `H + G` cells: for every row `t[k]` (a folded column of the
//!   map), folds it along axis 1 (`t[l] ± t[H+G-1-l]`, exact), applies the
//!   even and the odd block and stores the embedding in the `k`-th chunk
//!   of `e` (even part first), and with `NEAR` in `near` too (as long as
//!   `e`). With `DIFF`, returns `Σ (old - new)²` over the overwritten
//!   words: the squared distance to the map `e` held before, for the price
//!   of one load, one subtraction and one `SMLAL` per word (wrapping, so
//!   that a buffer that held no map cannot make it panic; for two maps it
//!   cannot wrap).

use core::mem::MaybeUninit;

use crate::config::MAX_J;
use crate::scorer::embed::layout::{Factor, Rows};

#[cfg(target_arch = "arm")]
mod arm;
#[cfg(target_arch = "arm")]
use arm::{cols, rows};
#[cfg(not(target_arch = "arm"))]
mod portable;
#[cfg(not(target_arch = "arm"))]
use portable::{cols, rows};

/// A row pass (`rows` in the module docs).
type RowsFn = fn(&Factor, &[u16], usize, (u32, i32), &mut Rows);
/// A column pass (`cols` in the module docs).
type ColsFn = fn(&Factor, &[[MaybeUninit<i32>; MAX_J]], &mut [i32], &mut [i32]) -> u64;

/// The unrolled passes of one geometry, chosen when the tables are built.
/// A firmware whose `Scorer` is a compile-time constant references only
/// its own geometry's three passes, so the linker drops the other 45
/// (about 26 KB of flash); a dispatch at run time would keep them all.
#[derive(Clone, Copy)]
pub struct Passes {
    pub(super) rows: RowsFn,
    /// The column pass: `[diff as usize + 2 * near as usize]`, so that
    /// neither the distance nor the second copy costs a test per column.
    pub(super) cols: [ColsFn; 4],
}

impl Passes {
    /// The passes of a `j1 x j2` map (`None` outside `1..=16`).
    pub const fn new(j1: usize, j2: usize) -> Option<Passes> {
        let rows: RowsFn = match j2 {
            1 => rows::<1, 0>,
            2 => rows::<1, 1>,
            3 => rows::<2, 1>,
            4 => rows::<2, 2>,
            5 => rows::<3, 2>,
            6 => rows::<3, 3>,
            7 => rows::<4, 3>,
            8 => rows::<4, 4>,
            9 => rows::<5, 4>,
            10 => rows::<5, 5>,
            11 => rows::<6, 5>,
            12 => rows::<6, 6>,
            13 => rows::<7, 6>,
            14 => rows::<7, 7>,
            15 => rows::<8, 7>,
            16 => rows::<8, 8>,
            _ => return None,
        };
        macro_rules! cols_of {
            ($($j:literal => ($h:literal, $g:literal)),*) => {
                match j1 {
                    $($j => [
                        cols::<$h, $g, false, false> as ColsFn,
                        cols::<$h, $g, true, false> as ColsFn,
                        cols::<$h, $g, false, true> as ColsFn,
                        cols::<$h, $g, true, true> as ColsFn,
                    ],)*
                    _ => return None,
                }
            };
        }
        let cols = cols_of!(
            1 => (1, 0), 2 => (1, 1), 3 => (2, 1), 4 => (2, 2), 5 => (3, 2), 6 => (3, 3),
            7 => (4, 3), 8 => (4, 4), 9 => (5, 4), 10 => (5, 5), 11 => (6, 5), 12 => (6, 6),
            13 => (7, 6), 14 => (7, 7), 15 => (8, 7), 16 => (8, 8)
        );
        Some(Passes { rows, cols })
    }
}

/// Equal when built for the same geometry (the `Scorer`'s configuration
/// is compared as well).
impl PartialEq for Passes {
    fn eq(&self, other: &Self) -> bool {
        core::ptr::fn_addr_eq(self.rows, other.rows)
            && self
                .cols
                .iter()
                .zip(other.cols.iter())
                .all(|(&a, &b)| core::ptr::fn_addr_eq(a, b))
    }
}

impl core::fmt::Debug for Passes {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("Passes")
    }
}
