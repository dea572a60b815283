//! The square kernels' first per-map pass: a raw map folded on both axes
//! into its four blocks and converted to `Q(f)`.

use crate::scorer::square::blocks::Blocks;
use crate::scorer::square::kernel::{quads, smmulr};

/// Folds the raw map `frame` (row-major, `j2` per row) on both axes into
/// the four blocks of `z`, one after the other, and converts each folded
/// count `v` (exact: `|v| <= S`, the sum of the map's samples) to `Q(f)`
/// as the paper kernels do: `round((v << k) m / 2^32)` with `(k, m)` from
/// `Scorer::scale` (normalised: error below 1; raw: `v 2^f`, exact). Each
/// group of four mirrored samples gives one word of each block.
#[inline(never)]
pub fn fold(g: &Blocks, frame: &[u16], (k, m): (u32, i32), z: &mut [i32]) {
    let (j1, j2) = (g.j1, g.j2);
    let (h1, g1, h2, g2) = (j1.div_ceil(2), j1 / 2, j2.div_ceil(2), j2 / 2);
    let k = k.min(31);
    let conv = |v: i32| smmulr(v << k, m);
    let Some((b00, rest)) = z.split_at_mut_checked(h1 * h2) else {
        return;
    };
    let Some((b01, rest)) = rest.split_at_mut_checked(h1 * g2) else {
        return;
    };
    let Some((b10, b11)) = rest.split_at_mut_checked(g1 * h2) else {
        return;
    };
    for p in 0..h1 {
        // Rows p and j1-1-p: the same row at the middle of an odd axis,
        // which has no odd part.
        let pm = j1 - 1 - p;
        let (Some(top), Some(bot)) = (
            frame.get(p * j2..p * j2 + j2),
            frame.get(pm * j2..pm * j2 + j2),
        ) else {
            return;
        };
        let (Some(r00), Some(r01)) = (
            b00.get_mut(p * h2..p * h2 + h2),
            b01.get_mut(p * g2..p * g2 + g2),
        ) else {
            return;
        };
        let (tl, tr) = (
            top.get(..g2).unwrap_or(&[]),
            top.get(j2 - g2..).unwrap_or(&[]),
        );
        if p == pm {
            let cols = tl
                .iter()
                .zip(tr.iter().rev())
                .zip(r00.iter_mut().zip(r01.iter_mut()));
            for ((&a, &b), (e, o)) in cols {
                let (a, b) = (a as i32, b as i32);
                *e = conv(a + b);
                *o = conv(a - b);
            }
            // The middle column of an odd axis 2: the one word of `r00`
            // past `g2` (none when the axis is even, `h2 = g2`).
            if let (Some(e), Some(&a)) = (r00.get_mut(g2), top.get(g2)) {
                *e = conv(a as i32);
            }
            continue;
        }
        let (Some(r10), Some(r11)) = (
            b10.get_mut(p * h2..p * h2 + h2),
            b11.get_mut(p * g2..p * g2 + g2),
        ) else {
            return;
        };
        quads(top, bot, g2, [&mut *r00, &mut *r01, &mut *r10, r11], (k, m));
        if let (Some(e), Some(o), Some(&a), Some(&c)) =
            (r00.get_mut(g2), r10.get_mut(g2), top.get(g2), bot.get(g2))
        {
            *e = conv(a as i32 + c as i32);
            *o = conv(a as i32 - c as i32);
        }
    }
}
