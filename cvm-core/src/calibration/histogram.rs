//! The log-binned histogram a calibration collects each channel's
//! magnitudes in: exact for small values, a fixed relative resolution
//! above, the exact maximum and count beside it.
//!
//! # Bins
//!
//! With `M` = [`MANTISSA_BITS`], a value `v` of bit length `L` (0 for
//! `v = 0`) goes to the bin of `v` with its lowest `s = max(L - M - 1, 0)`
//! bits cleared: bin `(s << M) + (v >> s)`. Values below `2^(M+1)` have a
//! bin of their own (`s = 0`); above, each octave `[2^e, 2^(e+1))` has
//! `2^M` bins of width `2^(e - M)`, a relative width under `2^-M`. The bin
//! indices are contiguous: a histogram of `B`-bit values has
//! [`bins`]`(B) = (B + 1 - M) 2^M` of them.
//!
//! A bin stands for its *representative* `lo + floor(w / 2)`, `lo` its
//! lowest value and `w` its width (`lo` itself when `w = 1`): the middle of
//! the bin, rounded up. The median and the MAD of a calibration are those
//! of the representatives, which is what makes them computable from the
//! counts alone (docs/experiments.md, "Calibration").
//!
//! # Counts
//!
//! Every count is at most the total, a `u32`; a value that would take the
//! total past `u32::MAX` is not added and marks the histogram as having
//! lost one, so no count can wrap.

/// Mantissa bits of the bins: relative bin width at most `2^-7` (0.8 %),
/// exact below `2^8 = 256`. With 6 bits the prototype's CVM MAD came out
/// 4.6 % low (its median is nine MADs, so a bin there is a tenth of a MAD
/// wide); with 7, 0.6 % high (docs/experiments.md, "Calibration").
pub const MANTISSA_BITS: u32 = 7;

/// Bins of a histogram of values below `2^value_bits` (`value_bits` in
/// `M + 1..=32`).
pub const fn bins(value_bits: u32) -> usize {
    ((value_bits + 1 - MANTISSA_BITS) << MANTISSA_BITS) as usize
}

/// The bin of `v`.
#[inline]
pub const fn bin_of(v: u32) -> usize {
    let len = u32::BITS - v.leading_zeros();
    let s = len.saturating_sub(MANTISSA_BITS + 1);
    ((s << MANTISSA_BITS) + (v >> s)) as usize
}

/// The lowest and highest value of bin `b` (both `u32::MAX` past the last
/// bin of 32-bit values).
pub const fn bin_range(b: usize) -> (u32, u32) {
    if b >= bins(u32::BITS) {
        return (u32::MAX, u32::MAX);
    }
    // b < 2^11: no truncation.
    let b = b as u32;
    let e = b >> MANTISSA_BITS;
    if e <= 1 {
        return (b, b);
    }
    // s <= 31 - M: the shifts stay inside 32 bits, and lo + 2^s - 1 is at
    // most 2^32 - 1.
    let s = e - 1;
    let top = (b & ((1 << MANTISSA_BITS) - 1)) | (1 << MANTISSA_BITS);
    let lo = top << s;
    (lo, lo + ((1u32 << s) - 1))
}

/// The value bin `b` stands for: its middle, rounded up.
pub const fn representative(b: usize) -> u32 {
    let (lo, hi) = bin_range(b);
    // hi - lo < 2^26: no overflow.
    lo + ((hi - lo + 1) >> 1)
}

/// A histogram of `u32` values in `BINS` bins ([`bins`]), with their exact
/// count and maximum.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Histogram<const BINS: usize> {
    counts: [u32; BINS],
    n: u32,
    max: u32,
    lost: bool,
}

impl<const BINS: usize> Default for Histogram<BINS> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const BINS: usize> Histogram<BINS> {
    pub const fn new() -> Self {
        Histogram {
            counts: [0; BINS],
            n: 0,
            max: 0,
            lost: false,
        }
    }

    pub fn clear(&mut self) {
        *self = Self::new();
    }

    /// Counts `v`; a value past the last bin or beyond the total's range
    /// is not counted and marks the histogram ([`Histogram::lost`]).
    #[inline]
    pub fn add(&mut self, v: u32) {
        let (Some(n), Some(c)) = (self.n.checked_add(1), self.counts.get_mut(bin_of(v))) else {
            self.lost = true;
            return;
        };
        // c <= n - 1 before: it cannot wrap.
        *c = c.wrapping_add(1);
        self.n = n;
        self.max = self.max.max(v);
    }

    /// Adds `other`'s values; what would take the total past `u32::MAX`
    /// is left out and marks the histogram.
    pub fn merge(&mut self, other: &Self) {
        let Some(n) = self.n.checked_add(other.n) else {
            self.lost = true;
            return;
        };
        for (c, o) in self.counts.iter_mut().zip(other.counts.iter()) {
            // Each is at most its total, and the totals' sum fits.
            *c = c.wrapping_add(*o);
        }
        self.n = n;
        self.max = self.max.max(other.max);
        self.lost |= other.lost;
    }

    /// Values counted.
    pub fn len(&self) -> u32 {
        self.n
    }

    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The largest value counted (0 when none).
    pub fn max(&self) -> u32 {
        self.max
    }

    /// Whether a value could not be counted.
    pub fn lost(&self) -> bool {
        self.lost
    }

    /// The count of bin `b` (0 past the last).
    pub fn count(&self, b: usize) -> u32 {
        self.counts.get(b).copied().unwrap_or(0)
    }

    /// The bin holding the value of 1-based rank `rank` in ascending order
    /// (`rank` in `1..=len`; the last non-empty bin for a larger one).
    pub fn bin_of_rank(&self, rank: u32) -> usize {
        let mut seen: u32 = 0;
        let mut last = 0;
        for (b, &c) in self.counts.iter().enumerate() {
            if c == 0 {
                continue;
            }
            last = b;
            // seen + c <= n: no wrap.
            seen = seen.wrapping_add(c);
            if seen >= rank {
                return b;
            }
        }
        last
    }

    /// The lower median (rank `ceil(n / 2)`) of the representatives: its
    /// bin and value.
    pub fn median(&self) -> (usize, u32) {
        let b = self.bin_of_rank(self.n.div_ceil(2));
        (b, representative(b))
    }

    /// The lower median (rank `ceil(n / 2)`) of the representatives'
    /// absolute deviations from the representative of bin `mid` (the
    /// median's). The deviations grow both ways from `mid`, so walking
    /// outwards and always taking the side with the smaller deviation
    /// visits them in ascending order: one pass over the bins.
    pub fn mad(&self, mid: usize) -> u32 {
        let centre = representative(mid);
        let rank = self.n.div_ceil(2);
        // Bins `up..` and `..down` are still to visit.
        let (mut up, mut down) = (mid, mid);
        let mut seen: u32 = 0;
        let mut last = 0;
        loop {
            let du = (up < BINS).then(|| representative(up).wrapping_sub(centre));
            let dd = (down > 0).then(|| centre.wrapping_sub(representative(down.wrapping_sub(1))));
            let (b, dev) = match (du, dd) {
                (Some(u), Some(d)) if d < u => {
                    down = down.wrapping_sub(1);
                    (down, d)
                }
                (Some(u), _) => {
                    up = up.wrapping_add(1);
                    (up.wrapping_sub(1), u)
                }
                (None, Some(d)) => {
                    down = down.wrapping_sub(1);
                    (down, d)
                }
                (None, None) => return last,
            };
            let c = self.count(b);
            if c == 0 {
                continue;
            }
            last = dev;
            seen = seen.wrapping_add(c);
            if seen >= rank {
                return dev;
            }
        }
    }
}
