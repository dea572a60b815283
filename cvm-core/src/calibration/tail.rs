//! The upper tail of a channel's defect-free magnitudes, fitted from its
//! histogram, and the threshold that keeps the expected number of false
//! positions per part at a target rate; in integers only, so the board and
//! `dmap calibrate` compute the same numbers.
//!
//! # The fit
//!
//! Peaks over a threshold with an exponential excess: over the `n`
//! magnitudes of `S` reference scans, each taken as the representative of
//! its histogram bin (capped at the exact maximum),
//!
//! - the tail starts at `u`, the top of the bin of the nearest-rank
//!   `1 - f` quantile (rank `ceil((1 - f) n)`, `f` the tail fraction, but
//!   at most `n - 10` and at least 1, so that a small calibration still
//!   fits ten values: [`super::rule::tail_rank`]), capped at the maximum;
//! - the tail is the `N_u` values above `u` (bins past `u`'s), `E` the sum
//!   of their excesses over `u`;
//! - above `u` a value exceeds `u + x` with probability
//!   `(N_u / n) exp(-x / s)`, `s = E / N_u` (the exponential's maximum
//!   likelihood scale).
//!
//! A part is a scan of `n / S` positions, so the expected number of its
//! positions at or above `t >= u` is `(N_u / S) exp(-(t - u) / s)`, and the
//! target of `a` false positions per part (`a = A / 10^6`) is met from
//!
//! ```text
//! t = u + s ln(N_u 10^6 / (A S))        (t = u when the log is <= 0)
//! thr = max(ceil(t), max + 1)
//! ```
//!
//! (the floor keeps every reference position below the threshold: a value
//! seen on a defect-free part is no extrapolation). Without a tail
//! (`N_u = 0`: every value in `u`'s bin) the threshold is `max + 1`.
//!
//! # Integers and their ranges
//!
//! - `E <= N_u (2^32 - 1) < 2^64`: a `u64` ([`Fit::excess`]).
//! - Logarithms are base 2 in `Q24` ([`log2_q24`]): the argument's bit
//!   length, and 24 fraction bits by repeated squaring of a `Q31`
//!   mantissa (`m^2 < 2^64`), truncated; error under `2^-23`.
//!   `ln x = log2 x * ln 2` with `ln 2` in `Q32` ([`LN2_Q32`]).
//! - `N_u 10^6 < 2^52` and `A S < 2^48`, so `|ln| < 37` and the margin
//!   `ceil(E ln_Q24 / (N_u 2^24))` has a numerator under `2^64 * 2^30`
//!   and a denominator under `2^56`: `u128`, then saturating to `u32`.
//! - The rate at a threshold ([`rate_ppb`]): `y = (thr - u) N_u / (E ln 2)`
//!   in `Q24` has a numerator under `2^32 2^32 2^56 = 2^120` and a
//!   denominator under `2^96`; `2^-y` is `2^-floor(y)` times the product
//!   of a fixed table of `2^(-2^-k)` in `Q32` ([`EXP2_NEG_Q32`]) over the
//!   fraction's bits (at most `2^32`, each product under `2^64`); the rate
//!   in false positions per `10^9` parts, `N_u 10^9 2^-y / S`, rounded up,
//!   has a numerator under `2^62 2^32` and a denominator `S 2^(32 + whole)`
//!   under `2^16 2^112` (`u128`; 0 past `whole = 80`).
//!
//! Nothing here can panic: no indexing, no division by a value that can
//! be 0, every shift below the width.

use super::histogram::{Histogram, bin_range, representative};

/// `ln 2` in `Q32`, rounded to nearest.
pub const LN2_Q32: u64 = 2_977_044_472;

/// Fraction bits of the logarithms.
pub const LOG_FRAC: u32 = 24;

/// `2^(-2^-(k+1))` in `Q32`, rounded to nearest, for `k` in `0..24`.
pub const EXP2_NEG_Q32: [u64; LOG_FRAC as usize] = [
    3_037_000_500,
    3_611_622_603,
    3_938_502_376,
    4_112_874_773,
    4_202_935_003,
    4_248_701_965,
    4_271_771_996,
    4_283_353_945,
    4_289_156_690,
    4_292_061_010,
    4_293_513_907,
    4_294_240_540,
    4_294_603_903,
    4_294_785_595,
    4_294_876_445,
    4_294_921_870,
    4_294_944_583,
    4_294_955_939,
    4_294_961_618,
    4_294_964_457,
    4_294_965_876,
    4_294_966_586,
    4_294_966_941,
    4_294_967_119,
];

/// The target `A` is in false positions per `RATE_DEN` parts.
pub const RATE_DEN: u64 = 1_000_000;
/// The estimate of [`rate_ppb`] is in false positions per `RATE_PPB_DEN`
/// parts.
pub const RATE_PPB_DEN: u64 = 1_000_000_000;

/// `floor(2^24 log2 x)` up to the squaring's truncation (0 for `x <= 1`).
pub fn log2_q24(x: u64) -> u64 {
    if x <= 1 {
        return 0;
    }
    // 1 <= e <= 63.
    let e = 63 - x.leading_zeros();
    // The mantissa in Q31: [2^31, 2^32).
    let mut m = if e >= 31 {
        x >> (e - 31)
    } else {
        x << (31 - e)
    };
    let mut frac: u64 = 0;
    for _ in 0..LOG_FRAC {
        // m < 2^32: m^2 < 2^64.
        m = m.wrapping_mul(m) >> 31;
        frac <<= 1;
        if m >= 1 << 32 {
            m >>= 1;
            frac |= 1;
        }
    }
    ((e as u64) << LOG_FRAC) | frac
}

/// `2^(-y / 2^24)` in `Q32` (at most `2^32`), rounded down.
pub fn exp2_neg_q32(y: u64) -> u64 {
    let whole = y >> LOG_FRAC;
    if whole >= 64 {
        return 0;
    }
    exp2_neg_frac_q32(y) >> whole
}

/// `2^(-f / 2^24)` in `Q32` for the fraction `f` of `y` (its low 24
/// bits): in `(2^31, 2^32]`, rounded down once per set bit.
pub fn exp2_neg_frac_q32(y: u64) -> u64 {
    let mut m: u64 = 1 << 32;
    for (k, t) in EXP2_NEG_Q32.iter().enumerate() {
        // Entry k is the fraction's bit of weight 2^-(k+1).
        if (y >> (LOG_FRAC - 1 - k as u32)) & 1 == 1 {
            // m <= 2^32, t < 2^32: the product fits.
            m = m.wrapping_mul(*t) >> 32;
        }
    }
    m
}

/// A channel's tail: where it starts, how many values lie above, and the
/// sum of their excesses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Fit {
    /// `u`.
    pub start: u32,
    /// `N_u`, 0 when there is no tail.
    pub count: u32,
    /// `E`.
    pub excess: u64,
}

/// The tail above bin `b` (the bin of the `1 - f` quantile, see the
/// module): it starts at `b`'s top, capped at the maximum.
pub fn fit<const BINS: usize>(h: &Histogram<BINS>, b: usize) -> Fit {
    let max = h.max();
    let start = bin_range(b).1.min(max);
    let (mut count, mut excess) = (0u32, 0u64);
    for bin in b.saturating_add(1)..BINS {
        let c = h.count(bin);
        if c == 0 {
            continue;
        }
        // The bins are contiguous, so every representative is above start.
        let d = representative(bin).min(max).saturating_sub(start);
        // count + c <= n; E <= N_u (2^32 - 1) < 2^64 (module).
        count = count.saturating_add(c);
        excess = excess.saturating_add(c as u64 * d as u64);
    }
    if count == 0 || excess == 0 {
        return Fit {
            start: max,
            count: 0,
            excess: 0,
        };
    }
    Fit {
        start,
        count,
        excess,
    }
}

/// `ceil(s ln(N_u 10^6 / (A S)))` (0 when the log is not positive),
/// saturating at `u64::MAX`.
pub fn margin(f: &Fit, scans: u16, rate_ppm: u32) -> u64 {
    if f.count == 0 || f.excess == 0 {
        return 0;
    }
    let num = f.count as u64 * RATE_DEN;
    let den = u64::from(rate_ppm.max(1)) * u64::from(scans.max(1));
    let (ln_num, ln_den) = (log2_q24(num), log2_q24(den));
    if ln_num <= ln_den {
        return 0;
    }
    // log2 < 2^30 in Q24: the product with ln 2 fits a u64.
    let ln = ((ln_num - ln_den) * LN2_Q32) >> 32;
    let top = f.excess as u128 * ln as u128;
    let bottom = (f.count as u128) << LOG_FRAC;
    u64::try_from(top.div_ceil(bottom)).unwrap_or(u64::MAX)
}

/// The threshold for a target of `rate_ppm` false positions per million
/// parts: `max(u + margin, max + 1)`, saturating at `u32::MAX`.
pub fn threshold(f: &Fit, max: u32, scans: u16, rate_ppm: u32) -> u32 {
    let t = (f.start as u64).saturating_add(margin(f, scans, rate_ppm));
    let floor = max as u64 + 1;
    t.max(floor).min(u32::MAX as u64) as u32
}

/// The expected false positions per `10^9` parts at `thr`, rounded up:
/// `N_u 10^9 exp(-(thr - u) / s) / S` above the tail's start, the count of
/// values at or above `thr` (by their bins' representatives) per `10^9`
/// parts below it. `None` without a tail.
pub fn rate_ppb<const BINS: usize>(
    h: &Histogram<BINS>,
    f: &Fit,
    scans: u16,
    thr: u32,
) -> Option<u64> {
    if f.count == 0 || f.excess == 0 {
        return None;
    }
    let scans = u64::from(scans.max(1));
    if thr <= f.start {
        let mut at_or_above: u64 = 0;
        for bin in 0..BINS {
            if representative(bin).min(h.max()) >= thr {
                at_or_above = at_or_above.saturating_add(u64::from(h.count(bin)));
            }
        }
        return Some(at_or_above.saturating_mul(RATE_PPB_DEN).div_ceil(scans));
    }
    let x = u128::from(thr - f.start);
    let y = (x * u128::from(f.count)) << (LOG_FRAC + 32);
    // E > 0: not zero.
    let y = y.checked_div(u128::from(f.excess) * u128::from(LN2_Q32));
    let y = y.and_then(|y| u64::try_from(y).ok()).unwrap_or(u64::MAX);
    // 2^-y = m 2^-(32 + whole), up to the table's rounding; past 2^-80
    // the rate is 0 (the numerator is under 2^94 and S at least 1).
    let whole = y >> LOG_FRAC;
    if whole > 80 {
        return Some(0);
    }
    let m = exp2_neg_frac_q32(y);
    let top = u128::from(f.count) * u128::from(RATE_PPB_DEN) * u128::from(m);
    // S < 2^16, shifted by at most 112: under 2^128.
    let bottom = u128::from(scans) << (32 + whole);
    Some(u64::try_from(top.div_ceil(bottom)).unwrap_or(u64::MAX))
}
