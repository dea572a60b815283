//! How a frame's samples become `Q(f)` values: the per-map scale of
//! normalised and raw maps, and the exact reciprocal it needs without a
//! 64-bit division.

use crate::channels::flags;
use crate::scorer::error::FrameError;
use crate::scorer::setup::Scorer;
use crate::tables::pow2;

impl Scorer {
    /// Normalises `frame` (Eq. 5) into `x` (`J1 * J2` values, row-major) in
    /// `Q(f)` and returns its flags ([`flags::DARK`], [`flags::SATURATED`]).
    pub fn normalise(&self, frame: &[u16], x: &mut [i32]) -> Result<u8, FrameError> {
        self.normalise_power(frame, x).map(|(fl, _)| fl)
    }

    /// [`Scorer::normalise`], also returning the map's sample sum.
    fn normalise_power(&self, frame: &[u16], x: &mut [i32]) -> Result<(u8, u32), FrameError> {
        let n = self.cells();
        let (Some(frame), Some(x)) = (frame.get(..n), x.get_mut(..n)) else {
            return Err(FrameError::Length);
        };
        if frame.len() != n {
            return Err(FrameError::Length);
        }
        let (fl, sum, conv) = self.converter(frame);
        match conv {
            Conv::Zero => x.fill(0),
            Conv::Recip(r) => fill(x, frame, |a| recip_sample(a, r)),
            Conv::Shl(s) => fill(x, frame, |a| (a as i32) << s),
        }
        Ok((fl, sum))
    }

    /// Flags and sample sum of a frame, and how its samples become `Q(f)` values.
    fn converter(&self, frame: &[u16]) -> (u8, u32, Conv) {
        let mut fl = 0;
        let mut sum: u32 = 0;
        let mut peak: u16 = 0;
        for &a in frame {
            // At most 256 * 65535 < 2^24: no overflow.
            sum += a as u32;
            peak = peak.max(a);
        }
        if peak >= self.config.full_scale {
            fl |= flags::SATURATED;
        }
        if sum == 0 {
            fl |= flags::DARK;
        }
        let conv = if self.config.normalise {
            if sum == 0 {
                Conv::Zero
            } else {
                // One division per map, then a multiply per sample.
                Conv::Recip((1u64 << (32 + self.frac as u32)) / sum as u64)
            }
        } else {
            // `frac >= 0` (see `Scorer::new`).
            Conv::Shl(self.frac as u32)
        };
        (fl, sum, conv)
    }

    /// How the folded counts `v` of a map with sample sum `sum` become
    /// `Q(f)` values: `y = round((v << k) * m / 2^32)`, returned as `(k, m)`.
    ///
    /// Normalised (`y ≈ v 2^f / S`): `k` puts `S' = S << k` in
    /// `[2^30, 2^31)` (so `|v << k| <= S' < 2^31`) and
    /// `m = floor(2^(32+f) / S') <= 2^30`, so `|y - v 2^f / S| < 1`. A dark
    /// map gets `m = 0`. Raw (`y = v 2^f`): `k = f + 2`, `m = 2^30`, exact.
    pub(super) fn scale(&self, sum: u32) -> (u32, i32) {
        let f = self.frac;
        if self.config.normalise {
            if sum == 0 {
                return (0, 0);
            }
            let k = sum.leading_zeros().saturating_sub(1);
            let s = sum << k;
            (k, reciprocal(self.scale_num, f, s))
        } else {
            // `f >= 0` (see `Scorer::new`), so `k = f + 2 <= 30`.
            ((f + 2) as u32, 1 << 30)
        }
    }
}

/// `floor(2^(32+f) / s)` for `s` in `[2^30, 2^31)` and `f = 28` (the only
/// format of normalised paper-kernel maps), without a 64-bit division (a
/// library call on the Cortex-M4): a single-precision estimate
/// (`num = 2^(32+f)` as `f32`), refined once through its exact remainder,
/// then at most one step down. Exact for every `s`, checked exhaustively
/// (`reciprocal_is_exact_for_every_sum` in core-tests, 2^30 cases), so the
/// host and the target agree however `f32` rounds.
#[inline(always)]
fn reciprocal(num: f32, f: i32, s: u32) -> i32 {
    let n = 1i64 << (32 + f).clamp(0, 60);
    // Within 2^-22 of the quotient (at most 2^30): off by at most 2^9.
    let mut m = (num / s as f32) as i32 as i64;
    let r = n - m * s as i64;
    // |r| < 2^41: its top bits over those of s give the correction to
    // within one (only `f32 <-> i32` conversions, single instructions);
    // truncation leaves the remainder at most one `s` below 0, never at or
    // above `s` (the exhaustive check counts both).
    let c = ((r >> 20) as i32 as f32 / (s >> 20) as f32) as i32 as i64;
    m += c;
    if r - c * (s as i64) < 0 {
        m -= 1;
    }
    m as i32
}

/// [`reciprocal`] as the scorer calls it for normalised paper-kernel maps
/// (`f = 28`), for the exhaustive test.
#[doc(hidden)]
pub fn reciprocal_q60(s: u32) -> i32 {
    reciprocal(pow2(60) as f32, 28, s)
}

/// How samples become `Q(f)` values for one frame.
#[derive(Clone, Copy)]
enum Conv {
    /// A dark map, normalised: all zero.
    Zero,
    /// Normalised: `round(a * recip / 2^32)`, `recip = floor(2^(32+f) / Σa)`.
    Recip(u64),
    /// Raw (`f >= 0` always): `a << f`.
    Shl(u32),
}

/// `round(a * 2^f / S)`: `a <= S`, so `a * recip + 2^31 <= 2^(32+f) + 2^31 < 2^57`.
/// Rounding (not truncating) keeps `Σx` within `N/2` of `2^f` instead of
/// biasing every map's mass low.
#[inline(always)]
fn recip_sample(a: u16, recip: u64) -> i32 {
    ((a as u64 * recip + (1 << 31)) >> 32) as i32
}

#[inline(always)]
fn fill(x: &mut [i32], frame: &[u16], f: impl Fn(u16) -> i32) {
    for (xv, &a) in x.iter_mut().zip(frame) {
        *xv = f(a);
    }
}
