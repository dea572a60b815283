//! The square kernels' second per-map pass: each folded block times its
//! factor, in place.

use crate::scorer::square::blocks::{Blocks, PADDED_WORDS};
use crate::scorer::square::kernel::{pairs_of_rows, smmulr};

/// Embeds the folded blocks of `z` in place: block by block, `E = R z`,
/// word `i` of a block overwriting its input `z_i` once no later row needs
/// it. `table` holds [`Blocks::table_words`] words, `z` at least `N + 3`
/// ([`FOLD_WORDS`](crate::scorer::square::FOLD_WORDS)). Returns false (and
/// leaves `z` partly embedded) if either is too short.
pub fn embed(g: &Blocks, table: &[i32], z: &mut [i32]) -> bool {
    let n = g.j1 * g.j2;
    if z.len() < n + 3 {
        return false;
    }
    let (mut t, mut at) = (0, 0);
    for b in 0..4 {
        let (n1, n2, _, _) = g.dims(b);
        let s = n1 * n2;
        let Some(&words) = PADDED_WORDS.get(s) else {
            return false;
        };
        let (Some(zb), Some(tb)) = (z.get_mut(at..), table.get(t..t + words)) else {
            return false;
        };
        block(tb, zb, s);
        t += words;
        at += s;
    }
    true
}

/// One block of [`embed`] (nothing for `s = 0`; `table` holds the block's
/// `padded_words(s)` words and `z` its `s` words plus two, checked by the
/// caller): the pairs of rows, then the last row of an odd block.
#[inline(always)]
fn block(table: &[i32], z: &mut [i32], s: usize) {
    let pairs = s / 2;
    if pairs > 0 {
        pairs_of_rows(table, z, pairs);
    }
    if s % 2 == 1
        && let (Some(&r), Some(v)) = (table.last(), z.get_mut(s - 1))
    {
        *v = smmulr(r, *v);
    }
}
