//! The square kernels' inner loops in Rust: the arithmetic of the
//! Cortex-M assembly, run on every other target.

/// The groups of four mirrored samples of rows `p` (`top`) and
/// `J1 - 1 - p` (`bot`), both `J2` long: for each `q < g2 = J2 / 2`, one
/// word of each block's row (`outs`: even-even, even-odd, odd-even,
/// odd-odd, each at least `g2` long) from `top[q]`, `top[J2-1-q]`,
/// `bot[q]`, `bot[J2-1-q]`.
#[inline(always)]
pub fn quads(top: &[u16], bot: &[u16], g2: usize, outs: [&mut [i32]; 4], (k, m): (u32, i32)) {
    let conv = |v: i32| smmulr(v << k, m);
    let j2 = top.len();
    let (tl, tr) = (
        top.get(..g2).unwrap_or(&[]),
        top.get(j2 - g2..).unwrap_or(&[]),
    );
    let (bl, br) = (
        bot.get(..g2).unwrap_or(&[]),
        bot.get(j2 - g2..).unwrap_or(&[]),
    );
    let [r00, r01, r10, r11] = outs;
    let samples = tl
        .iter()
        .zip(tr.iter().rev())
        .zip(bl.iter().zip(br.iter().rev()));
    let outs = r00
        .iter_mut()
        .zip(r01.iter_mut())
        .zip(r10.iter_mut().zip(r11.iter_mut()));
    for (((&a, &b), (&c, &d)), ((ee, eo), (oe, oo))) in samples.zip(outs) {
        let (s1, d1) = (a as i32 + b as i32, a as i32 - b as i32);
        let (s2, d2) = (c as i32 + d as i32, c as i32 - d as i32);
        *ee = conv(s1 + s2);
        *eo = conv(d1 + d2);
        *oe = conv(s1 - s2);
        *oo = conv(d1 - d2);
    }
}

/// `round(a b / 2^32)`, as one `SMMULR` computes it.
#[inline(always)]
pub fn smmulr(a: i32, b: i32) -> i32 {
    ((a as i64 * b as i64 + (1 << 31)) >> 32) as i32
}

/// The same arithmetic as `cvm_square_pairs`: one rounded product per
/// term, wrapping sums (which the bounds keep inside `i32`).
pub fn pairs_of_rows(table: &[i32], z: &mut [i32], pairs: usize) {
    let mac = |acc: i32, c: i32, v: i32| acc.wrapping_add(smmulr(c, v));
    let mut t = table.iter().copied();
    for p in 0..pairs {
        let i = 2 * p;
        // Past the table, as the assembly would read what follows it:
        // here zeros, so that a count of pairs too large shows.
        let (groups, diag) = (t.next().unwrap_or(0), t.next().unwrap_or(0));
        let mut a = smmulr(diag, z.get(i).copied().unwrap_or(0));
        let mut b = 0;
        for g in 0..groups.max(0) as usize {
            let j = i + 1 + 3 * g;
            let v: [i32; 3] = core::array::from_fn(|k| z.get(j + k).copied().unwrap_or(0));
            for &x in &v {
                a = mac(a, t.next().unwrap_or(0), x);
            }
            for &x in &v {
                b = mac(b, t.next().unwrap_or(0), x);
            }
        }
        if let Some(w) = z.get_mut(i) {
            *w = a;
        }
        if let Some(w) = z.get_mut(i + 1) {
            *w = b;
        }
    }
}
