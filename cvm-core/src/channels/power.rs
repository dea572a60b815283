//! The power channel: how much the beam's power changes across a position.
//!
//! Normalisation (Eq. 5) makes the distance blind to light that a defect
//! removes from the beam without reshaping what is left (a small bubble
//! scattering part of the beam off the detector, an absorbing inclusion).
//! The map's power `P` (its sample sum) is computed for the normalisation
//! anyway, so this channel costs two contrasts and an integer square root
//! per position (docs/method.md §6).
//!
//! Per position, in the two directions of Eq. 1, the Michelson contrast of
//! the two neighbours' powers, `c = |P(+) - P(-)| / (P(+) + P(-))` (0 when
//! both are dark), with the border rule of the distance: a missing
//! neighbour is replaced by the position itself. The magnitude is
//! `sqrt(c0² + c1²)`. A contrast of 0.01 is a 2 % change of power from one
//! neighbour to the other.
//!
//! # Fixed point
//!
//! Contrasts and magnitudes are `Q15` integers (`POWER_FRAC` = 15): `c` in
//! `[0, 1]` is `floor(c 2^15)` in `0..=32768`, exactly (long division in
//! base 2^7, below); the magnitude `floor(sqrt(c0² + c1²))` of the two
//! integers is at most `floor(32768 sqrt 2) = 46340`, so every power value
//! fits a `u16`. Powers are below `256 * 65535 < 2^24`, so `P(+) + P(-)`
//! is below `2^25` and no step overflows `u32`.

/// Fraction bits of the power channel's values.
pub const POWER_FRAC: u32 = 15;
/// Largest power magnitude: `floor(sqrt(2) * 2^15)`.
pub const POWER_MAX: u32 = 46340;
/// A power threshold above every magnitude: the channel never fires.
pub const POWER_OFF: u32 = u32::MAX;

/// `floor(2^15 |a - b| / (a + b))`, 0 when `a + b = 0`; exact for powers
/// below `2^24`.
pub fn contrast(a: u32, b: u32) -> u16 {
    ratio_q15(a.abs_diff(b), a.saturating_add(b))
}

/// `floor(2^15 d / s)` for `d <= s < 2^25`, exact; 0 when `s = 0`, at most
/// `2^15`. The contrast's quotient, and the pooled loss's
/// ([`crate::channels::pooled`]).
pub(crate) fn ratio_q15(d: u32, s: u32) -> u16 {
    if s == 0 {
        return 0;
    }
    // d <= s < 2^25: each step shifts the remainder (below s) by at most
    // 7 bits, so it stays below 2^32; 7 + 7 + 1 = 15 quotient bits.
    let mut r = d;
    let mut q: u32 = 0;
    for bits in [7u32, 7, 1] {
        r <<= bits;
        q = (q << bits) | (r / s);
        r %= s;
    }
    q.min(1 << POWER_FRAC) as u16
}

/// `floor(sqrt(c0² + c1²))`, exact, at most [`POWER_MAX`].
pub fn magnitude(c0: u16, c1: u16) -> u16 {
    let c0 = (c0 as u32).min(1 << POWER_FRAC);
    let c1 = (c1 as u32).min(1 << POWER_FRAC);
    // At most 2^31: no overflow.
    isqrt(c0 * c0 + c1 * c1).min(POWER_MAX) as u16
}

/// `floor(sqrt(s))`: Newton's iteration on integers from a power of two at
/// or above the root. Each step `x -> (x + s/x) / 2` stays at or above
/// `floor(sqrt(s))` and decreases until it stops, which is at the floor of
/// the root; from at most twice the root that takes at most six steps
/// (about 30 instructions, against about 80 for the general 64-bit
/// magnitude). The spread channel's magnitude uses it too.
pub(crate) fn isqrt(s: u32) -> u32 {
    if s < 2 {
        return s;
    }
    let bits = 32 - s.leading_zeros();
    // 2^ceil(bits/2) >= sqrt(s); at most 2^16, so x + s/x <= 2^17.
    let mut x = 1u32 << bits.div_ceil(2);
    loop {
        let Some(q) = s.checked_div(x) else {
            return x;
        };
        let y = (x + q) >> 1;
        if y >= x {
            return x;
        }
        x = y;
    }
}

/// The smallest `Q15` threshold at or above `t` (a contrast; 0 for `t <= 0`,
/// [`POWER_OFF`] for `t` above every magnitude or NaN).
pub fn threshold_from_units(t: f64) -> u32 {
    fixed_threshold(t, POWER_FRAC, POWER_MAX, POWER_OFF)
}

/// The smallest threshold with `frac` fraction bits at or above `t`: 0
/// for `t <= 0`, `off` for `t` above `max` (no magnitude reaches it) or
/// NaN. The power and spread channels' thresholds are both made so.
pub(crate) fn fixed_threshold(t: f64, frac: u32, max: u32, off: u32) -> u32 {
    if t.is_nan() {
        return off;
    }
    let v = t * (1u32 << frac) as f64;
    if v <= 0.0 {
        0
    } else if v > max as f64 {
        off
    } else {
        let fl = v as u32;
        if (fl as f64) < v { fl + 1 } else { fl }
    }
}

/// A `Q15` power value as a contrast.
pub fn to_units(p: u32) -> f64 {
    p as f64 / (1u32 << POWER_FRAC) as f64
}
