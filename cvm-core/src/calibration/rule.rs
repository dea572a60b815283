//! The calibration rule in integers: per channel,
//!
//! ```text
//! thr = Q_p + ceil(k * 1.4826 * MAD) + 1
//! ```
//!
//! over the histogram of the channel's magnitudes (see the module
//! [`crate::calibration`] for what `Q_p`, the median and the MAD are).
//! `k` and `p` are exact rationals, `k = K / 1000` and
//! `p = P / 1 000 000`, and 1.4826 is `14826 / 10000`, so the margin is
//! `ceil(K * 14826 * MAD / 10^7)`: `K * 14826 < 2^46` and `MAD < 2^32`,
//! so the product is checked in `u64` and a product past `u64::MAX`
//! (a margin above `2^40`) saturates the threshold to `u32::MAX` like any
//! other sum past it.

use super::histogram::{Histogram, bin_range};

/// MAD to the standard deviation of a normal distribution, 1.4826, as
/// `MAD_TO_SIGMA_NUM / MAD_TO_SIGMA_DEN`.
pub const MAD_TO_SIGMA_NUM: u64 = 14826;
pub const MAD_TO_SIGMA_DEN: u64 = 10_000;
/// `k` is in thousandths.
pub const K_DEN: u64 = 1000;
/// `p` is in millionths.
pub const P_DEN: u64 = 1_000_000;

/// The rule's parameters: the quantile `p` and the margin `k` in robust
/// standard deviations (1.4826 MAD).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rule {
    /// `p` in millionths, `1..=1_000_000` (`1_000_000`: the maximum; 0 is
    /// taken as the smallest rank, like any `p` below `1 / n`).
    pub quantile_ppm: u32,
    /// `k` in thousandths.
    pub k_milli: u32,
}

impl Rule {
    /// The device's rule: `p = 1` (the maximum), `k = 3`.
    pub const DEFAULT: Rule = Rule {
        quantile_ppm: P_DEN as u32,
        k_milli: 3000,
    };
}

impl Default for Rule {
    fn default() -> Self {
        Rule::DEFAULT
    }
}

/// One channel's statistics and threshold, integers in the channel's
/// format (`Q(q)` magnitudes or `Q15` power magnitudes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Channel {
    /// Positions counted.
    pub positions: u32,
    /// The largest magnitude, exact.
    pub max: u32,
    /// `Q_p`: the top of the bin holding the nearest-rank `p` quantile,
    /// at most `max` (so `max` itself for `p = 1`).
    pub quantile: u32,
    /// Lower median of the bins' representatives.
    pub median: u32,
    /// Lower median of the representatives' distances from `median`.
    pub mad: u32,
    /// `Q_p + ceil(k * 1.4826 * MAD) + 1`, saturating at `u32::MAX`
    /// (before the power channel's off rule).
    pub threshold: u32,
}

/// `ceil(k * 1.4826 * mad)`, saturating at `u64::MAX`.
pub fn margin(k_milli: u32, mad: u32) -> u64 {
    let den = K_DEN * MAD_TO_SIGMA_DEN;
    match (k_milli as u64 * MAD_TO_SIGMA_NUM).checked_mul(mad as u64) {
        Some(p) => p / den + u64::from(p % den != 0),
        None => u64::MAX,
    }
}

/// `q + margin + 1`, saturating at `u32::MAX`.
pub fn threshold(quantile: u32, k_milli: u32, mad: u32) -> u32 {
    let t = (quantile as u64)
        .saturating_add(margin(k_milli, mad))
        .saturating_add(1);
    t.min(u32::MAX as u64) as u32
}

/// The 1-based nearest rank of `p` among `n` values: `ceil(P n / 10^6)`,
/// clamped to `1..=n` (`n >= 1`).
pub fn quantile_rank(quantile_ppm: u32, n: u32) -> u32 {
    // P n < 2^64: exact.
    let r = (quantile_ppm as u64 * n as u64).div_ceil(P_DEN);
    r.clamp(1, n.max(1) as u64) as u32
}

/// The channel's statistics under `rule`, or `None` without values.
pub fn channel<const BINS: usize>(h: &Histogram<BINS>, rule: &Rule) -> Option<Channel> {
    if h.is_empty() {
        return None;
    }
    let n = h.len();
    let (mid, median) = h.median();
    let mad = h.mad(mid);
    let (_, top) = bin_range(h.bin_of_rank(quantile_rank(rule.quantile_ppm, n)));
    let quantile = top.min(h.max());
    Some(Channel {
        positions: n,
        max: h.max(),
        quantile,
        median,
        mad,
        threshold: threshold(quantile, rule.k_milli, mad),
    })
}
