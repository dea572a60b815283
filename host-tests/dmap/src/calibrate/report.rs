//! What `dmap calibrate` writes: the calibration file's JSON (both
//! channels' thresholds and the statistics behind them, per reference too)
//! and the one-line summary on standard error.

use std::path::Path;

use anyhow::Result;
use cvm_core::calibration::histogram::MANTISSA_BITS;
use cvm_core::calibration::{Channel, Rule as CoreRule, Statistics};
use cvm_core::{Config, Scorer, power};
use serde_json::{Value, json};

use super::file::{FORMAT, VERSION, config_json};
use super::rule::Rule;
use crate::fmt::fmt_num;

/// The rule as the file states it.
pub const RULE_TEXT: &str = "per channel, thr = Q_p + ceil(k * 1.4826 * MAD) + 1 over the channel's magnitudes of every position with data of every reference (integers: cvm in Q(q), power in Q15), each magnitude taken as the representative of its histogram bin (exact below 2^(m+1), else 2^m bins per octave, the middle of the bin rounded up); median and MAD the lower medians (rank ceil(n/2)) of the representatives and of their distances from the median; Q_p the top of the bin of nearest rank ceil(p n), at most the exact maximum (the maximum for p = 1); k and p exact as k_milli/1000 and quantile_ppm/10^6; a power thr above 46340 is recorded as 4294967295, off; defective when a channel's magnitude >= its thr";

/// One reference's part of the file.
pub struct Reference<'a> {
    pub path: &'a Path,
    pub rows: usize,
    pub cols: usize,
    /// Its own statistics.
    pub stats: Statistics,
    /// With more than one reference: per channel, the other references'
    /// threshold and how many of its positions reach it.
    pub others: Option<((u32, usize), (u32, usize))>,
}

/// A channel's statistics in its units (`to_units`) and as integers.
fn channel(c: &Channel, to_units: &dyn Fn(u32) -> f64) -> Value {
    json!({
        "positions": c.positions,
        "max": to_units(c.max),
        "quantile_value": to_units(c.quantile),
        "median": to_units(c.median),
        "mad": to_units(c.mad),
        "integers": {"max": c.max, "quantile": c.quantile, "median": c.median, "mad": c.mad},
    })
}

/// The calibration file.
pub fn document(
    config: &Config,
    scorer: &Scorer,
    rule: &Rule,
    exact: &CoreRule,
    st: &Statistics,
    refs: &[Reference],
) -> Result<Value> {
    let units = |v: u32| scorer.score_to_units(v);
    let (thr, pthr) = (st.cvm.threshold, st.power.threshold);
    let mut cvm = channel(&st.cvm, &units);
    cvm["threshold"] = json!(units(thr));
    cvm["thr"] = json!(thr);
    cvm["q"] = json!(scorer.score_frac_bits());
    let mut pow = channel(&st.power, &power::to_units);
    pow["threshold"] = json!(power::to_units(pthr));
    pow["thr"] = json!(pthr);
    pow["q"] = json!(power::POWER_FRAC);
    let references: Vec<Value> = refs
        .iter()
        .map(|r| {
            let mut v = channel(&r.stats.cvm, &units);
            v["file"] = json!(r.path.display().to_string());
            v["rows"] = json!(r.rows);
            v["cols"] = json!(r.cols);
            v["power"] = channel(&r.stats.power, &power::to_units);
            if let Some(((t, n), (pt, pn))) = r.others {
                v["others_threshold"] = json!(units(t));
                v["at_or_above_others_threshold"] = json!(n);
                v["power"]["others_threshold"] = json!(power::to_units(pt));
                v["power"]["at_or_above_others_threshold"] = json!(pn);
            }
            v
        })
        .collect();
    Ok(json!({
        "format": FORMAT,
        "version": VERSION,
        "config": config_json(config)?,
        "rule": {
            "text": RULE_TEXT,
            "quantile": rule.quantile,
            "k": rule.k,
            "quantile_ppm": exact.quantile_ppm,
            "k_milli": exact.k_milli,
            "m": MANTISSA_BITS,
        },
        "scans": st.scans,
        "channels": {"cvm": cvm, "power": pow},
        "references": references,
    }))
}

/// The summary line: both channels' statistics and thresholds.
pub fn summary(scorer: &Scorer, st: &Statistics, refs: usize) -> String {
    let units = |v: u32| fmt_num(scorer.score_to_units(v));
    let punits = |v: u32| fmt_num(power::to_units(v));
    let (c, p) = (&st.cvm, &st.power);
    format!(
        "dmap calibrate: {} positions of {refs} reference(s): max {}, median {}, MAD {} -> threshold {} (integer {} in Q({})); power: max {}, median {}, MAD {} -> threshold {}",
        c.positions,
        units(c.max),
        units(c.median),
        units(c.mad),
        units(c.threshold),
        c.threshold,
        scorer.score_frac_bits(),
        punits(p.max),
        punits(p.median),
        punits(p.mad),
        if p.threshold == power::POWER_OFF {
            "off (above every power magnitude)".to_string()
        } else {
            format!("{} (integer {} in Q15)", punits(p.threshold), p.threshold)
        }
    )
}
