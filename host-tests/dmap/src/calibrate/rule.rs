//! The calibration rule and its robust statistics: per channel, over the
//! magnitudes `m` of every defect-free reference position,
//! `thr = Q_p(m) + ceil(k * 1.4826 * MAD(m)) + 1` (integers, the firmware's
//! formats), and its f64 twin for precomputed scores.

use anyhow::{Result, bail};
use cvm_core::power;

use crate::fmt::fmt_num;

/// MAD to the standard deviation of a normal distribution.
pub const MAD_TO_SIGMA: f64 = 1.4826;

/// The rule's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rule {
    pub quantile: f64,
    pub k: f64,
}

impl Rule {
    pub fn check(&self) -> Result<()> {
        if !(self.quantile.is_finite() && self.quantile > 0.0 && self.quantile <= 1.0) {
            bail!(
                "--quantile must be in (0, 1], got {}",
                fmt_num(self.quantile)
            );
        }
        if !(self.k.is_finite() && self.k >= 0.0) {
            bail!("--k must be a finite number >= 0, got {}", fmt_num(self.k));
        }
        Ok(())
    }
}

/// Robust statistics of integer magnitudes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stats {
    pub n: usize,
    pub max: u32,
    pub median: f64,
    pub mad: f64,
    /// The rule's quantile.
    pub quantile: u32,
}

/// Median of sorted values (mean of the middle two for an even count).
fn median_sorted(v: &[f64]) -> f64 {
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// Statistics of `m` (not empty) for `rule`.
pub fn stats(m: &[u32], rule: &Rule) -> Stats {
    let mut s: Vec<u32> = m.to_vec();
    s.sort_unstable();
    let f: Vec<f64> = s.iter().map(|&x| f64::from(x)).collect();
    let median = median_sorted(&f);
    let mut dev: Vec<f64> = f.iter().map(|x| (x - median).abs()).collect();
    dev.sort_unstable_by(f64::total_cmp);
    let mad = median_sorted(&dev);
    // Nearest rank: the smallest value with at least p n values at or below it.
    let rank = ((rule.quantile * s.len() as f64).ceil() as usize).clamp(1, s.len());
    Stats {
        n: s.len(),
        max: s[s.len() - 1],
        median,
        mad,
        quantile: s[rank - 1],
    }
}

/// The rule's integer threshold from the statistics (saturating).
pub fn threshold(st: &Stats, rule: &Rule) -> u32 {
    let margin = (rule.k * MAD_TO_SIGMA * st.mad).ceil();
    let t = f64::from(st.quantile) + margin + 1.0;
    if t >= f64::from(u32::MAX) {
        u32::MAX
    } else {
        t as u32
    }
}

/// The power channel's threshold from the rule's: itself when a magnitude
/// can reach it, else [`power::POWER_OFF`] (both convert to a contrast and
/// back exactly).
pub fn power_thr(thr: u32) -> u32 {
    if thr <= power::POWER_MAX {
        thr
    } else {
        power::POWER_OFF
    }
}

/// One channel's calibration over references' magnitudes `all` (one list
/// per reference): the pooled statistics, the threshold (after `fix`) and,
/// with more than one reference, per reference the threshold of the
/// others and how many of its positions reach that.
pub fn channel(
    all: &[Vec<u32>],
    rule: &Rule,
    fix: fn(u32) -> u32,
) -> (Stats, u32, Vec<(u32, usize)>) {
    let pooled: Vec<u32> = all.iter().flatten().copied().collect();
    let st = stats(&pooled, rule);
    let thr = fix(threshold(&st, rule));
    let mut loo = Vec::new();
    if all.len() > 1 {
        for i in 0..all.len() {
            let others: Vec<u32> = all
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .flat_map(|(_, m)| m.iter().copied())
                .collect();
            let t = fix(threshold(&stats(&others, rule), rule));
            loo.push((t, all[i].iter().filter(|&&x| x >= t).count()));
        }
    }
    (st, thr, loo)
}

/// The rule in f64 on magnitudes `m` (not empty): the quantile plus
/// `k * 1.4826 * MAD`, and at least the next number above the quantile.
pub fn threshold_f64(m: &[f64], rule: &Rule) -> (f64, f64, f64, f64) {
    let mut s: Vec<f64> = m.to_vec();
    s.sort_unstable_by(f64::total_cmp);
    let median = median_sorted(&s);
    let mut dev: Vec<f64> = s.iter().map(|x| (x - median).abs()).collect();
    dev.sort_unstable_by(f64::total_cmp);
    let mad = median_sorted(&dev);
    let rank = ((rule.quantile * s.len() as f64).ceil() as usize).clamp(1, s.len());
    let q = s[rank - 1];
    let mut t = q + rule.k * MAD_TO_SIGMA * mad;
    if t <= q {
        // The next f64 above q (scores are >= 0).
        t = if q > 0.0 {
            f64::from_bits(q.to_bits() + 1)
        } else {
            f64::from_bits(1)
        };
    }
    (t, s[s.len() - 1], median, mad)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rule_on_hand_made_magnitudes() {
        // 1..=9 and 100: median 5.5, deviations 4.5 3.5 2.5 1.5 .5 .5 1.5 2.5 3.5 94.5,
        // MAD 2.5; k = 2: margin ceil(2 * 1.4826 * 2.5) = 8.
        let m = [1, 2, 3, 4, 5, 6, 7, 8, 9, 100];
        let r = Rule {
            quantile: 1.0,
            k: 2.0,
        };
        let s = stats(&m, &r);
        assert_eq!((s.max, s.median, s.mad, s.quantile), (100, 5.5, 2.5, 100));
        assert_eq!(threshold(&s, &r), 109);
        let r9 = Rule {
            quantile: 0.9,
            k: 0.0,
        };
        assert_eq!(threshold(&stats(&m, &r9), &r9), 10);
        assert_eq!(threshold(&stats(&[u32::MAX], &r), &r), u32::MAX);
    }

    #[test]
    fn power_threshold_above_every_magnitude_is_off() {
        assert_eq!(power_thr(0), 0);
        assert_eq!(power_thr(power::POWER_MAX), power::POWER_MAX);
        assert_eq!(power_thr(power::POWER_MAX + 1), power::POWER_OFF);
        // Both kinds convert to a contrast and back exactly.
        for t in [0, 1, 3277, power::POWER_MAX, power::POWER_OFF] {
            assert_eq!(power::threshold_from_units(power::to_units(t)), t);
        }
    }
}
