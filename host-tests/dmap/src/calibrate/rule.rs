//! The options of the calibration rule and their exact integer form
//! (`cvm_core::calibration::Rule`, the rule itself), the power channel's
//! off rule, and the f64 rule `--scores` applies to precomputed scores.

use anyhow::{Result, bail};
use cvm_core::calibration::rule::{K_DEN, P_DEN};
use cvm_core::power;

use crate::fmt::fmt_num;

/// MAD to the standard deviation of a normal distribution.
pub const MAD_TO_SIGMA: f64 = 1.4826;

/// The rule's parameters as given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rule {
    pub quantile: f64,
    pub k: f64,
}

/// `v * den` when it is a whole number (to within the decimal's rounding
/// in f64) that fits a `u32`.
fn exact_units(v: f64, den: u64) -> Option<u32> {
    let scaled = v * den as f64;
    let whole = scaled.round();
    ((scaled - whole).abs() <= 1e-9 * whole.max(1.0) && (0.0..=u32::MAX as f64).contains(&whole))
        .then_some(whole as u32)
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

    /// The rule in the core's integers: `p` in millionths and `k` in
    /// thousandths, refused when not exactly that (the board computes with
    /// them, so a file must say exactly what it applied).
    pub fn exact(&self) -> Result<cvm_core::calibration::Rule> {
        self.check()?;
        let Some(quantile_ppm) = exact_units(self.quantile, P_DEN) else {
            bail!(
                "--quantile must be a multiple of 0.000001, got {}",
                fmt_num(self.quantile)
            );
        };
        let Some(k_milli) = exact_units(self.k, K_DEN) else {
            bail!(
                "--k must be a multiple of 0.001 and at most {}, got {}",
                u32::MAX as f64 / K_DEN as f64,
                fmt_num(self.k)
            );
        };
        Ok(cvm_core::calibration::Rule {
            quantile_ppm,
            k_milli,
        })
    }
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

/// `--scores`: a rule in f64 on precomputed magnitudes `m` (not empty),
/// for `dmap eval` only and not the board's: the nearest-rank quantile plus
/// `k * 1.4826 * MAD` with exact medians (mean of the middle two), and at
/// least the next number above the quantile.
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
    fn options_become_exact_rationals_or_are_refused() {
        let r = |quantile, k| Rule { quantile, k }.exact();
        let d = r(1.0, 3.0).unwrap();
        assert_eq!((d.quantile_ppm, d.k_milli), (1_000_000, 3000));
        assert_eq!(d, cvm_core::calibration::Rule::DEFAULT);
        let d = r(0.999, 2.5).unwrap();
        assert_eq!((d.quantile_ppm, d.k_milli), (999_000, 2500));
        let d = r(0.000001, 0.001).unwrap();
        assert_eq!((d.quantile_ppm, d.k_milli), (1, 1));
        assert_eq!(r(0.5, 0.0).unwrap().k_milli, 0);
        assert_eq!(r(1.0, 4294967.295).unwrap().k_milli, u32::MAX);
        for (q, k, needle) in [
            (0.9999995, 3.0, "--quantile must be a multiple"),
            (1.0, 0.0005, "--k must be a multiple"),
            (1.0, 4294967.296, "--k must be a multiple"),
            (1.0, 1e300, "--k must be a multiple"),
            (0.0, 3.0, "--quantile must be in (0, 1]"),
            (1.0, -1.0, "--k must be a finite number"),
        ] {
            let e = r(q, k).unwrap_err().to_string();
            assert!(e.contains(needle), "{q} {k}: {e}");
        }
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
