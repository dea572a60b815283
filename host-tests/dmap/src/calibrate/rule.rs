//! The options of the calibration rules and their exact integer form
//! (`cvm_core::calibration::Rule`, the rules themselves), the power
//! channel's off rule, and the f64 rule `--from-scores` applies to precomputed
//! scores.

use anyhow::{Result, bail};
use clap::ValueEnum;
use cvm_core::calibration::Rule as CoreRule;
use cvm_core::calibration::rule::{DEFAULT_RATE_PPM, DEFAULT_TAIL_PPM, K_DEN, P_DEN};
use cvm_core::calibration::tail::RATE_DEN;

use crate::fmt::fmt_num;

/// MAD to the standard deviation of a normal distribution.
pub const MAD_TO_SIGMA: f64 = 1.4826;

/// Which rule sets the thresholds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum RuleName {
    /// thr = Q_p + ceil(k * 1.4826 * MAD) + 1 (--quantile, --k-mad)
    Spread,
    /// The threshold at which an exponential fit of the upper tail expects --rate false
    /// positions per part (--rate, --tail-fraction)
    Tail,
}

impl RuleName {
    /// The rule the board uses, `cvm_core`'s `Rule::DEFAULT`.
    pub fn default_rule() -> Self {
        match CoreRule::DEFAULT {
            CoreRule::Spread { .. } => RuleName::Spread,
            CoreRule::Tail { .. } => RuleName::Tail,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            RuleName::Spread => "spread",
            RuleName::Tail => "tail",
        }
    }
}

/// The rule's parameters as given (or their defaults).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rule {
    pub name: RuleName,
    pub quantile: f64,
    pub k: f64,
    /// Target false positions per part.
    pub rate: f64,
    /// Share of the magnitudes the tail fit takes.
    pub tail: f64,
}

/// The options as typed: the rule and each parameter, if given.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Options {
    pub name: Option<RuleName>,
    pub quantile: Option<f64>,
    pub k: Option<f64>,
    pub rate: Option<f64>,
    pub tail: Option<f64>,
}

/// `v * den` when it is a whole number (to within the decimal's rounding
/// in f64) that fits a `u32`.
fn exact_units(v: f64, den: u64) -> Option<u32> {
    let scaled = v * den as f64;
    let whole = scaled.round();
    ((scaled - whole).abs() <= 1e-9 * whole.max(1.0) && (0.0..=u32::MAX as f64).contains(&whole))
        .then_some(whole as u32)
}

/// A target rate of false positions per part in `(0, 1]` as the board
/// takes it, in millionths, when it is an exact multiple of one.
pub fn rate_ppm(rate: f64) -> Option<u32> {
    if !(rate.is_finite() && rate > 0.0 && rate <= 1.0) {
        return None;
    }
    exact_units(rate, P_DEN).filter(|&u| u > 0)
}

impl Rule {
    /// The rule of `o`: `--rule`, else the one whose parameters are given,
    /// else the board's; the other parameters at their defaults. Refuses a
    /// parameter of the other rule.
    pub fn from_options(o: &Options) -> Result<Self> {
        let spread = o.quantile.is_some() || o.k.is_some();
        let tail = o.rate.is_some() || o.tail.is_some();
        let name = match (o.name, spread, tail) {
            (Some(name), _, _) => name,
            (None, true, false) => RuleName::Spread,
            (None, false, true) => RuleName::Tail,
            (None, true, true) => bail!(
                "--quantile and --k-mad belong to the spread rule, --rate and --tail-fraction to the tail rule: give the parameters of one (and --rule)"
            ),
            (None, false, false) => RuleName::default_rule(),
        };
        let foreign: &[(&str, bool)] = match name {
            RuleName::Spread => &[
                ("--rate", o.rate.is_some()),
                ("--tail-fraction", o.tail.is_some()),
            ],
            RuleName::Tail => &[
                ("--quantile", o.quantile.is_some()),
                ("--k-mad", o.k.is_some()),
            ],
        };
        if let Some((flag, _)) = foreign.iter().find(|(_, given)| *given) {
            bail!(
                "{flag} is not a parameter of the {} rule (--rule {}); give --rule {}",
                name.as_str(),
                name.as_str(),
                if name == RuleName::Spread {
                    "tail"
                } else {
                    "spread"
                }
            );
        }
        let rule = Rule {
            name,
            quantile: o.quantile.unwrap_or(1.0),
            k: o.k.unwrap_or(3.0),
            rate: o.rate.unwrap_or(DEFAULT_RATE_PPM as f64 / RATE_DEN as f64),
            tail: o.tail.unwrap_or(DEFAULT_TAIL_PPM as f64 / P_DEN as f64),
        };
        rule.check()?;
        Ok(rule)
    }

    pub fn check(&self) -> Result<()> {
        if !(self.quantile.is_finite() && self.quantile > 0.0 && self.quantile <= 1.0) {
            bail!(
                "--quantile must be in (0, 1], got {}",
                fmt_num(self.quantile)
            );
        }
        if !(self.k.is_finite() && self.k >= 0.0) {
            bail!(
                "--k-mad must be a finite number >= 0, got {}",
                fmt_num(self.k)
            );
        }
        if !(self.rate.is_finite() && self.rate > 0.0 && self.rate <= 1.0) {
            bail!(
                "--rate must be in (0, 1] false positions per part, got {}",
                fmt_num(self.rate)
            );
        }
        if !(self.tail.is_finite() && self.tail > 0.0 && self.tail <= 1.0) {
            bail!(
                "--tail-fraction must be in (0, 1], got {}",
                fmt_num(self.tail)
            );
        }
        Ok(())
    }

    /// The rule in the core's integers: `p`, the rate and the tail share
    /// in millionths and `k` in thousandths, refused when not exactly that
    /// (the board computes with them, so a file must say exactly what it
    /// applied).
    pub fn exact(&self) -> Result<CoreRule> {
        self.check()?;
        let micro = |v: f64, flag: &str| {
            exact_units(v, P_DEN).filter(|&u| u > 0).ok_or_else(|| {
                anyhow::anyhow!("{flag} must be a multiple of 0.000001, got {}", fmt_num(v))
            })
        };
        Ok(match self.name {
            RuleName::Spread => {
                let quantile_ppm = micro(self.quantile, "--quantile")?;
                let Some(k_milli) = exact_units(self.k, K_DEN) else {
                    bail!(
                        "--k-mad must be a multiple of 0.001 and at most {}, got {}",
                        u32::MAX as f64 / K_DEN as f64,
                        fmt_num(self.k)
                    );
                };
                CoreRule::Spread {
                    quantile_ppm,
                    k_milli,
                }
            }
            RuleName::Tail => CoreRule::Tail {
                rate_ppm: micro(self.rate, "--rate")?,
                tail_ppm: micro(self.tail, "--tail-fraction")?,
            },
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

/// `--from-scores`: a rule in f64 on precomputed magnitudes `m` (not empty),
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
    use crate::calibration_file::{power_thr, spread_thr};
    use cvm_core::{power, spread};

    #[test]
    fn options_become_exact_rationals_or_are_refused() {
        let r = |quantile, k| {
            Rule::from_options(&Options {
                name: Some(RuleName::Spread),
                quantile: Some(quantile),
                k: Some(k),
                ..Options::default()
            })
            .and_then(|r| r.exact())
        };
        let spread = |r: CoreRule| match r {
            CoreRule::Spread {
                quantile_ppm,
                k_milli,
            } => (quantile_ppm, k_milli),
            CoreRule::Tail { .. } => panic!("{r:?}"),
        };
        let d = r(1.0, 3.0).unwrap();
        assert_eq!(spread(d), (1_000_000, 3000));
        assert_eq!(d, CoreRule::SPREAD);
        assert_eq!(spread(r(0.999, 2.5).unwrap()), (999_000, 2500));
        assert_eq!(spread(r(0.000001, 0.001).unwrap()), (1, 1));
        assert_eq!(spread(r(0.5, 0.0).unwrap()).1, 0);
        assert_eq!(spread(r(1.0, 4294967.295).unwrap()).1, u32::MAX);
        for (q, k, needle) in [
            (0.9999995, 3.0, "--quantile must be a multiple"),
            (1.0, 0.0005, "--k-mad must be a multiple"),
            (1.0, 4294967.296, "--k-mad must be a multiple"),
            (1.0, 1e300, "--k-mad must be a multiple"),
            (0.0, 3.0, "--quantile must be in (0, 1]"),
            (1.0, -1.0, "--k-mad must be a finite number"),
        ] {
            let e = r(q, k).unwrap_err().to_string();
            assert!(e.contains(needle), "{q} {k}: {e}");
        }
    }

    #[test]
    fn tail_options_become_millionths_and_the_rules_do_not_mix() {
        let o = |rate, tail| Options {
            name: Some(RuleName::Tail),
            rate,
            tail,
            ..Options::default()
        };
        let exact = |o: Options| Rule::from_options(&o).and_then(|r| r.exact());
        assert_eq!(exact(o(None, None)).unwrap(), CoreRule::TAIL);
        assert_eq!(
            exact(o(Some(0.000002), Some(0.05))).unwrap(),
            CoreRule::Tail {
                rate_ppm: 2,
                tail_ppm: 50_000
            }
        );
        for (rate, tail, needle) in [
            (
                Some(0.0000015),
                None,
                "--rate must be a multiple of 0.000001",
            ),
            (Some(0.0), None, "--rate must be in (0, 1]"),
            (Some(2.0), None, "--rate must be in (0, 1]"),
            (None, Some(0.0), "--tail-fraction must be in (0, 1]"),
            (None, Some(1e-7), "--tail-fraction must be a multiple"),
        ] {
            let e = exact(o(rate, tail)).unwrap_err().to_string();
            assert!(e.contains(needle), "{rate:?} {tail:?}: {e}");
        }
        let mixed = Options {
            k: Some(2.0),
            ..o(None, None)
        };
        let e = exact(mixed).unwrap_err().to_string();
        assert!(
            e.contains("--k-mad is not a parameter of the tail rule"),
            "{e}"
        );
        let mixed = Options {
            name: Some(RuleName::Spread),
            rate: Some(0.01),
            ..Options::default()
        };
        let e = exact(mixed).unwrap_err().to_string();
        assert!(
            e.contains("--rate is not a parameter of the spread rule"),
            "{e}"
        );
        // Without --rule: the one whose parameters are given, else the
        // board's; never both.
        let board = exact(Options::default()).unwrap();
        assert_eq!(board, CoreRule::DEFAULT);
        let implied = |o: Options| Rule::from_options(&o).map(|r| r.name);
        let k = Options {
            k: Some(2.0),
            ..Options::default()
        };
        assert_eq!(implied(k).unwrap(), RuleName::Spread);
        let rate = Options {
            rate: Some(0.01),
            ..Options::default()
        };
        assert_eq!(implied(rate).unwrap(), RuleName::Tail);
        let both = Options {
            k: Some(2.0),
            ..rate
        };
        let e = implied(both).unwrap_err().to_string();
        assert!(e.contains("give the parameters of one"), "{e}");
    }

    #[test]
    fn spread_threshold_above_every_magnitude_is_off() {
        assert_eq!(spread_thr(0), 0);
        assert_eq!(spread_thr(spread::SPREAD_MAX), spread::SPREAD_MAX);
        assert_eq!(spread_thr(spread::SPREAD_MAX + 1), spread::SPREAD_OFF);
        // Each converts to a share of the power and back exactly.
        for t in [0, 1, 6554, spread::SPREAD_MAX, spread::SPREAD_OFF] {
            assert_eq!(spread::threshold_from_units(spread::to_units(t)), t);
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
