//! The geometry of the square kernels' four folded blocks and of their
//! factor table, as the per-map path reads it.

use crate::config::{MAX_CELLS, MAX_J};

/// Largest block of one folded axis (`ceil(16 / 2)`).
pub const MAX_H: usize = MAX_J.div_ceil(2);
/// Largest folded block of a map.
pub const MAX_BLOCK: usize = MAX_H * MAX_H;
/// Words of the scratch space the per-map path folds a map into: the
/// last group of a block's rows reads up to two words past the block.
pub const FOLD_WORDS: usize = MAX_CELLS + 4;

/// The sizes of the four folded blocks of a `j1 x j2` map, in the order
/// the embedding stores them: (even, even), (even, odd), (odd, even),
/// (odd, odd) along (axis 1, axis 2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Blocks {
    pub j1: usize,
    pub j2: usize,
}

impl Blocks {
    /// Rows and columns of block `b` (0..4) and whether each axis is odd.
    pub const fn dims(&self, b: usize) -> (usize, usize, bool, bool) {
        let (odd1, odd2) = (b & 2 != 0, b & 1 != 0);
        let n1 = if odd1 {
            self.j1 / 2
        } else {
            self.j1.div_ceil(2)
        };
        let n2 = if odd2 {
            self.j2 / 2
        } else {
            self.j2.div_ceil(2)
        };
        (n1, n2, odd1, odd2)
    }

    /// Words of the factor table of this geometry.
    pub const fn table_words(&self) -> usize {
        let mut w = 0;
        let mut b = 0;
        while b < 4 {
            let (n1, n2, _, _) = self.dims(b);
            w += padded_words(n1 * n2);
            b += 1;
        }
        w
    }
}

/// [`padded_words`] of every block size, for the per-map path.
pub const PADDED_WORDS: [usize; MAX_BLOCK + 1] = {
    let mut w = [0; MAX_BLOCK + 1];
    let mut s = 0;
    while s <= MAX_BLOCK {
        w[s] = padded_words(s);
        s += 1;
    }
    w
};

/// Words of the factor of a block of `s` cells as the embedding reads
/// it: for each pair of rows `(i, i+1)`, a count, row `i`'s diagonal and
/// `6 ceil((s - i - 1) / 3)` coefficients (groups of three columns of both
/// rows, zero past the block); then, for an odd `s`, the last diagonal.
pub const fn padded_words(s: usize) -> usize {
    let mut w = s % 2;
    let mut i = 0;
    while i + 1 < s {
        w += 2 + 6 * (s - i - 1).div_ceil(3);
        i += 2;
    }
    w
}
