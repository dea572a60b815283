//! The calibration rules in integers. Per channel, over the histogram of
//! the channel's magnitudes (see the module [`crate::calibration`] for
//! what `Q_p`, the median and the MAD are), either the spread rule
//!
//! ```text
//! thr = Q_p + ceil(k * 1.4826 * MAD) + 1
//! ```
//!
//! or the tail rule ([`super::tail`]): the threshold at which an
//! exponential fit of the upper tail expects a target rate of false
//! positions per part, at least the maximum plus one.
//!
//! Spread rule: `k` and `p` are exact rationals, `k = K / 1000` and
//! `p = P / 1 000 000`, and 1.4826 is `14826 / 10000`, so the margin is
//! `ceil(K * 14826 * MAD / 10^7)`: `K * 14826 < 2^46` and `MAD < 2^32`,
//! so the product is checked in `u64` and a product past `u64::MAX`
//! (a margin above `2^40`) saturates the threshold to `u32::MAX` like any
//! other sum past it.
//!
//! Whichever rule sets the threshold, each channel also reports the tail
//! fit and the false-position rate it predicts there
//! ([`Channel::rate_ppb`]), and the smallest rise above the median the
//! threshold detects ([`Channel::min_strength`]).

use super::histogram::{Histogram, bin_range};
use super::tail::{self, Fit};

/// MAD to the standard deviation of a normal distribution, 1.4826, as
/// `MAD_TO_SIGMA_NUM / MAD_TO_SIGMA_DEN`.
pub const MAD_TO_SIGMA_NUM: u64 = 14826;
pub const MAD_TO_SIGMA_DEN: u64 = 10_000;
/// `k` is in thousandths.
pub const K_DEN: u64 = 1000;
/// `p` is in millionths.
pub const P_DEN: u64 = 1_000_000;

/// How a channel's threshold is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rule {
    /// `thr = Q_p + ceil(k * 1.4826 * MAD) + 1`.
    Spread {
        /// `p` in millionths, `1..=1_000_000` (`1_000_000`: the maximum;
        /// 0 is taken as the smallest rank, like any `p` below `1 / n`).
        quantile_ppm: u32,
        /// `k` in thousandths.
        k_milli: u32,
    },
    /// The exponential tail fit's threshold for a target rate
    /// ([`super::tail`]).
    Tail {
        /// Target false positions per million parts (0 is taken as 1).
        rate_ppm: u32,
        /// The tail's share of the magnitudes, in millionths.
        tail_ppm: u32,
    },
}

/// The tail fit's default share: the top 1 % of the magnitudes.
pub const DEFAULT_TAIL_PPM: u32 = 10_000;
/// The default target: one false position in 1000 parts.
pub const DEFAULT_RATE_PPM: u32 = 1000;

impl Rule {
    /// The spread rule's defaults: `p = 1` (the maximum), `k = 3`.
    pub const SPREAD: Rule = Rule::Spread {
        quantile_ppm: P_DEN as u32,
        k_milli: 3000,
    };
    /// The tail rule's defaults: one false position in 1000 parts, the
    /// top 1 % fitted.
    pub const TAIL: Rule = Rule::Tail {
        rate_ppm: DEFAULT_RATE_PPM,
        tail_ppm: DEFAULT_TAIL_PPM,
    };
    /// The device's rule (`calibrate N`) and `dmap calibrate`'s default:
    /// the tail rule, which left no false object on 20 unseen defect-free
    /// parts of each measured set-up, where the spread rule left three on
    /// one of them (docs/experiments.md, "Thresholds from a target rate").
    pub const DEFAULT: Rule = Rule::TAIL;

    /// The share of the magnitudes the tail fit takes.
    pub fn tail_ppm(&self) -> u32 {
        match *self {
            Rule::Spread { .. } => DEFAULT_TAIL_PPM,
            Rule::Tail { tail_ppm, .. } => tail_ppm,
        }
    }
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
    /// at most `max` (so `max` itself for `p = 1`); for the tail rule
    /// the tail's start `u` (its `p = 1 - f`).
    pub quantile: u32,
    /// Lower median of the bins' representatives.
    pub median: u32,
    /// Lower median of the representatives' distances from `median`.
    pub mad: u32,
    /// The threshold, saturating at `u32::MAX` (before the power channel's
    /// off rule): `Q_p + ceil(k * 1.4826 * MAD) + 1` (spread rule), or the
    /// tail fit's (tail rule).
    pub threshold: u32,
    /// The upper tail's fit (with the rule's tail share, 1 % for the
    /// spread rule).
    pub tail: Fit,
    /// Expected false positions per `10^9` parts at `threshold` by the
    /// fit, rounded up ([`tail::rate_ppb`]); `None` without a tail.
    pub rate_ppb: Option<u64>,
    /// The smallest rise above the median that reaches the threshold:
    /// `threshold - median` (a defect must add at least this to a
    /// median position's magnitude to be detected).
    pub min_strength: u32,
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

/// The fewest values the tail fit takes when there are more: with 10 the
/// scale's standard error is under a third of it.
pub const MIN_TAIL_VALUES: u32 = 10;

/// The 1-based rank the tail starts from: the nearest rank of `1 - f`
/// (`f = tail_ppm / 10^6`), at most `n - MIN_TAIL_VALUES`, at least 1.
pub fn tail_rank(tail_ppm: u32, n: u32) -> u32 {
    let keep = (P_DEN as u32).saturating_sub(tail_ppm.min(P_DEN as u32));
    quantile_rank(keep, n)
        .min(n.saturating_sub(MIN_TAIL_VALUES))
        .max(1)
}

/// The channel's statistics under `rule` over `scans` scans, or `None`
/// without values.
pub fn channel<const BINS: usize>(h: &Histogram<BINS>, rule: &Rule, scans: u16) -> Option<Channel> {
    if h.is_empty() {
        return None;
    }
    let n = h.len();
    let (mid, median) = h.median();
    let mad = h.mad(mid);
    let fit = tail::fit(h, h.bin_of_rank(tail_rank(rule.tail_ppm(), n)));
    let (quantile, threshold) = match *rule {
        Rule::Spread {
            quantile_ppm,
            k_milli,
        } => {
            let (_, top) = bin_range(h.bin_of_rank(quantile_rank(quantile_ppm, n)));
            let quantile = top.min(h.max());
            (quantile, threshold(quantile, k_milli, mad))
        }
        Rule::Tail { rate_ppm, .. } => (fit.start, tail::threshold(&fit, h.max(), scans, rate_ppm)),
    };
    Some(Channel {
        positions: n,
        max: h.max(),
        quantile,
        median,
        mad,
        threshold,
        tail: fit,
        rate_ppb: tail::rate_ppb(h, &fit, scans, threshold),
        min_strength: threshold.saturating_sub(median),
    })
}
