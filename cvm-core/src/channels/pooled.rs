//! Pooled decisions: a small footprint of positions against the positions
//! around it, for defects too weak to decide on one difference.
//!
//! The power and spread channels decide each position on the central
//! differences of its two neighbours, which never compare the position
//! itself with its surroundings. A defect on one position (an absorber
//! that sends part of the beam out of the receiver, a faint halo) changes
//! that position's power `P` or spread `q` and little else, and one that
//! sits between two or four beams shares its change among them. The
//! matched decision for such a footprint `F` of `k` positions is the
//! difference between its mean and the mean of the `m` positions of a
//! ring `R` around it, which the engine's three-row window holds:
//!
//! - an absorber lowers the power: the *loss*
//!   `(mean_R(P) - mean_F(P)) / mean_R(P)`, 0 when the footprint is not
//!   darker than its ring;
//! - a halo raises the spread: the *raise* `mean_F(q) - mean_R(q)`, 0 when
//!   the footprint is not wider than its ring.
//!
//! With independent noise of `sigma` per position, either difference has
//! the noise `sigma sqrt(1/k + 1/m)`. Each value is scaled by
//! [`gain`]`(k, m) = sqrt((1 + 1/8) / (1/k + 1/m))`, so that every
//! footprint's value has the noise of one position against its eight
//! neighbours (gain 1) and one threshold serves them all; the largest
//! value over a position's footprints is the one it is decided on.
//!
//! # Fixed point
//!
//! - Means are integer quotients: `mean = floor(sum / n)`. A map's power
//!   is below `2^24` ([`MAX_CELLS`] cells of at most 65535), so a sum of
//!   at most [`MAX_POSITIONS`] = 12 powers is below `2^28` and each mean
//!   below `2^24`. Flooring a mean of powers of a few million moves it by
//!   less than one part in a million.
//! - The loss is `Q15` (`floor(2^15 d / mean_R)`, `d = mean_R - mean_F`,
//!   `d <= mean_R < 2^24`), exactly as the power channel's contrast is
//!   computed ([`crate::power`]): at most `2^15`.
//! - The raise is `Q16` like `q`: at most 65535.
//! - The gain is `Q14` ([`GAIN_FRAC`]), at most `gain(12, 12) =
//!   sqrt(27/4)`, that is 42566; `value = floor(difference * gain / 2^14)`.
//!   The product is below `2^16 * 42566 < 2^32`. A scaled loss is at most
//!   `2.6 * 2^15` and a scaled raise at most `2.6 * 65535`: both fit a
//!   `u32`.
//!
//! [`MAX_CELLS`]: crate::MAX_CELLS

use super::power::ratio_q15;

/// Fraction bits of [`gain`].
pub const GAIN_FRAC: u32 = 14;
/// The most positions a footprint or a ring may have.
pub const MAX_POSITIONS: u32 = 12;

/// `floor(sqrt(n))` for `n < 2^64`, at compile time: bisection on the
/// root, whose square stays below `2^64` for roots below `2^32`.
const fn isqrt64(n: u64) -> u64 {
    let (mut lo, mut hi) = (0u64, 1u64 << 32);
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if mid * mid <= n {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// `floor(2^14 sqrt((9/8) k m / (k + m)))`: the gain of a footprint of `k`
/// positions against a ring of `m`, `Q14`; 0 when either is 0 or above
/// [`MAX_POSITIONS`].
pub const fn gain(k: u32, m: u32) -> u32 {
    if k == 0 || m == 0 || k > MAX_POSITIONS || m > MAX_POSITIONS {
        return 0;
    }
    // 2^28 (9/8) k m / (k + m) = 9 * 2^25 k m / (k + m), below 2^64.
    let (k, m) = (k as u64, m as u64);
    isqrt64(9 * (1u64 << 25) * k * m / (k + m)) as u32
}

/// [`gain`] of every `k, m` up to [`MAX_POSITIONS`], built by the compiler.
const GAINS: [[u16; 13]; 13] = {
    let mut t = [[0u16; 13]; 13];
    let mut k = 0;
    while k <= 12 {
        let mut m = 0;
        while m <= 12 {
            t[k][m] = gain(k as u32, m as u32) as u16;
            m += 1;
        }
        k += 1;
    }
    t
};

fn gain_of(k: u32, m: u32) -> u32 {
    GAINS
        .get(k as usize)
        .and_then(|row| row.get(m as usize))
        .copied()
        .unwrap_or(0) as u32
}

fn mean(sum: u32, n: u32) -> u32 {
    sum.checked_div(n).unwrap_or(0)
}

/// The scaled loss of a footprint of `k` positions whose powers sum to
/// `sum_f` against a ring of `m` whose powers sum to `sum_r` (module doc):
/// `floor(floor(2^15 (mean_R - mean_F) / mean_R) gain(k, m) / 2^14)`, 0
/// when the footprint is not darker, the ring is dark, or `k` or `m` is 0
/// or above [`MAX_POSITIONS`].
pub fn loss(sum_f: u32, k: u32, sum_r: u32, m: u32) -> u32 {
    let g = gain_of(k, m);
    let (mf, mr) = (mean(sum_f, k), mean(sum_r, m));
    if g == 0 || mr <= mf || mr >= 1 << 24 {
        return 0;
    }
    // g < 2^16 and the ratio at most 2^15: the product fits.
    (ratio_q15(mr - mf, mr) as u32 * g) >> GAIN_FRAC
}

/// The scaled raise of a footprint of `k` positions whose spreads `q`
/// (`Q16`) sum to `sum_f` against a ring of `m` whose spreads sum to
/// `sum_r`: `floor((mean_F - mean_R) gain(k, m) / 2^14)`, 0 when the
/// footprint is not wider or `k` or `m` is 0 or above [`MAX_POSITIONS`].
pub fn raise(sum_f: u32, k: u32, sum_r: u32, m: u32) -> u32 {
    let g = gain_of(k, m);
    let (mf, mr) = (mean(sum_f, k), mean(sum_r, m));
    if g == 0 || mf <= mr {
        return 0;
    }
    // The means of `u16` spreads are at most 65535 and g < 2^16.
    ((mf - mr).min(u16::MAX as u32) * g) >> GAIN_FRAC
}
