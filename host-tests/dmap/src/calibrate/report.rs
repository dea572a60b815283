//! What `dmap calibrate` writes: the calibration file's JSON (both
//! channels' thresholds and the statistics behind them, per reference too)
//! and the one-line summary on standard error.

use std::path::Path;

use anyhow::Result;
use cvm_core::calibration::histogram::MANTISSA_BITS;
use cvm_core::calibration::{Channel, Rule as CoreRule, Statistics};
use cvm_core::{Config, Scorer, power, spread};
use serde_json::{Value, json};

use super::rule::Rule;
use crate::calibration_file::{FORMAT, VERSION, config_json};
use crate::fmt::fmt_num;

/// The spread rule as the file states it.
pub const RULE_TEXT: &str = "per channel, thr = Q_p + ceil(k * 1.4826 * MAD) + 1 over the channel's magnitudes of every position with data of every reference (integers: cvm in Q(q), power in Q15, spread in Q16), each magnitude taken as the representative of its histogram bin (exact below 2^(m+1), else 2^m bins per octave, the middle of the bin rounded up); median and MAD the lower medians (rank ceil(n/2)) of the representatives and of their distances from the median; Q_p the top of the bin of nearest rank ceil(p n), at most the exact maximum (the maximum for p = 1); k and p exact as k_milli/1000 and quantile_ppm/10^6; a power thr above 46340 or a spread thr above 92680 is recorded as 4294967295, off; defective when a channel's magnitude >= its thr";

/// The tail rule as the file states it.
pub const TAIL_RULE_TEXT: &str = "per channel, over the channel's magnitudes of every position with data of the S references (integers: cvm in Q(q), power in Q15, spread in Q16), each magnitude taken as the representative of its histogram bin (as for the spread rule) capped at the exact maximum: the tail starts at u, the top of the bin of nearest rank min(ceil((1 - f) n), n - 10) (at least 1) capped at the maximum; N_u magnitudes lie above u with excess sum E, scale s = E / N_u; thr = max(ceil(u + s ln(N_u / (rate S))), max + 1) (u when the log is <= 0), with log2 in Q24 by repeated squaring and ln 2 in Q32; rate and f exact as rate_ppm/10^6 and tail_ppm/10^6; the expected false positions per part at thr are (N_u / S) exp(-(thr - u) / s); a power thr above 46340 or a spread thr above 92680 is recorded as 4294967295, off; defective when a channel's magnitude >= its thr";

/// A threshold and how many positions reach it.
pub type Reach = (u32, usize);

/// One reference's part of the file.
pub struct Reference<'a> {
    pub path: &'a Path,
    pub rows: usize,
    pub cols: usize,
    /// Its own statistics.
    pub stats: Statistics,
    /// With more than one reference: per channel, the other references'
    /// threshold and how many of its positions reach it.
    /// (CVM, power, spread).
    pub others: Option<[Reach; 3]>,
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

/// The tail fit, the estimated rate and the smallest detected rise at the
/// channel's threshold (in its units; `null` when not defined).
fn tail(c: &Channel, to_units: &dyn Fn(u32) -> f64, off: bool) -> Value {
    let f = &c.tail;
    let scale = (f.count > 0).then(|| f.excess as f64 / f.count as f64 * to_units(1));
    json!({
        "tail": {
            "start": to_units(f.start),
            "positions": f.count,
            "scale": scale,
            "integers": {"start": f.start, "positions": f.count, "excess": f.excess},
        },
        "false_positions_per_part": c.rate_ppb.map(|r| r as f64 / 1e9),
        "rate_ppb": c.rate_ppb,
        "min_strength": (!off).then(|| to_units(c.min_strength)),
        "threshold_over_max": (!off && c.max > 0).then(|| c.threshold as f64 / c.max as f64),
    })
}

/// `a` with `b`'s fields added.
fn with(mut a: Value, b: Value) -> Value {
    if let (Some(a), Value::Object(b)) = (a.as_object_mut(), b) {
        a.extend(b);
    }
    a
}

/// The rule's entry of the file.
fn rule_json(rule: &Rule, exact: &CoreRule) -> Value {
    match *exact {
        CoreRule::Spread {
            quantile_ppm,
            k_milli,
        } => json!({
            "name": "spread",
            "text": RULE_TEXT,
            "quantile": rule.quantile,
            "k": rule.k,
            "quantile_ppm": quantile_ppm,
            "k_milli": k_milli,
            "m": MANTISSA_BITS,
        }),
        CoreRule::Tail { rate_ppm, tail_ppm } => json!({
            "name": "tail",
            "text": TAIL_RULE_TEXT,
            "rate": rule.rate,
            "tail_fraction": rule.tail,
            "rate_ppm": rate_ppm,
            "tail_ppm": tail_ppm,
            "m": MANTISSA_BITS,
        }),
    }
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
    let mut cvm = with(channel(&st.cvm, &units), tail(&st.cvm, &units, false));
    cvm["threshold"] = json!(units(thr));
    cvm["thr"] = json!(thr);
    cvm["q"] = json!(scorer.score_frac_bits());
    let off = pthr == power::POWER_OFF;
    let mut pow = with(
        channel(&st.power, &power::to_units),
        tail(&st.power, &power::to_units, off),
    );
    pow["threshold"] = json!(power::to_units(pthr));
    pow["thr"] = json!(pthr);
    pow["q"] = json!(power::POWER_FRAC);
    let sthr = st.spread.threshold;
    let off = sthr == spread::SPREAD_OFF;
    let mut spr = with(
        channel(&st.spread, &spread::to_units),
        tail(&st.spread, &spread::to_units, off),
    );
    spr["threshold"] = json!(spread::to_units(sthr));
    spr["thr"] = json!(sthr);
    spr["q"] = json!(spread::SPREAD_FRAC);
    let references: Vec<Value> = refs
        .iter()
        .map(|r| {
            let mut v = channel(&r.stats.cvm, &units);
            v["file"] = json!(r.path.display().to_string());
            v["rows"] = json!(r.rows);
            v["cols"] = json!(r.cols);
            v["power"] = channel(&r.stats.power, &power::to_units);
            v["spread"] = channel(&r.stats.spread, &spread::to_units);
            if let Some([(t, n), (pt, pn), (sp, sn)]) = r.others {
                v["others_threshold"] = json!(units(t));
                v["at_or_above_others_threshold"] = json!(n);
                v["power"]["others_threshold"] = json!(power::to_units(pt));
                v["power"]["at_or_above_others_threshold"] = json!(pn);
                v["spread"]["others_threshold"] = json!(spread::to_units(sp));
                v["spread"]["at_or_above_others_threshold"] = json!(sn);
            }
            v
        })
        .collect();
    Ok(json!({
        "format": FORMAT,
        "version": VERSION,
        "config": config_json(config)?,
        "rule": rule_json(rule, exact),
        "scans": st.scans,
        "channels": {"cvm": cvm, "power": pow, "spread": spr},
        "references": references,
    }))
}

/// A channel's estimate: false positions per part at its threshold and
/// the smallest rise above the median it detects.
fn estimate(c: &Channel, to_units: &dyn Fn(u32) -> String, off: bool) -> String {
    if off {
        return "off: no false position, nothing detected".into();
    }
    let rate = match c.rate_ppb {
        Some(0) => "under 1e-9".to_string(),
        Some(r) => fmt_num(r as f64 / 1e9),
        None => "unknown (no magnitude above the tail's start)".to_string(),
    };
    format!(
        "estimated false positions per part {rate}, detects a rise of {} above the median ({} x the references' maximum)",
        to_units(c.min_strength),
        if c.max > 0 {
            fmt_num(c.threshold as f64 / c.max as f64)
        } else {
            "-".into()
        }
    )
}

/// The summary: the three channels' statistics and thresholds, then per channel
/// the estimated false-reject rate and the smallest detected rise, then the
/// thresholds as the settings `thr`, `pthr` and `sthr`.
pub fn summary(scorer: &Scorer, st: &Statistics, refs: usize) -> String {
    let units = |v: u32| fmt_num(scorer.score_to_units(v));
    let punits = |v: u32| fmt_num(power::to_units(v));
    let sunits = |v: u32| fmt_num(spread::to_units(v));
    let (c, p, sp) = (&st.cvm, &st.power, &st.spread);
    let off = p.threshold == power::POWER_OFF;
    let soff = sp.threshold == spread::SPREAD_OFF;
    format!(
        "dmap calibrate: {} positions of {refs} reference(s): max {}, median {}, MAD {} -> threshold {} (integer {} in Q({})); power: max {}, median {}, MAD {} -> threshold {}; spread: max {}, median {}, MAD {} -> threshold {}\nCVM: {}\npower: {}\nspread: {}\nsettings: thr={} pthr={} sthr={} (as `dmap sensor set`, `--set` and CVM_H743_SCAN take them)",
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
        if off {
            "off (above every power magnitude)".to_string()
        } else {
            format!("{} (integer {} in Q15)", punits(p.threshold), p.threshold)
        },
        sunits(sp.max),
        sunits(sp.median),
        sunits(sp.mad),
        if soff {
            "off (above every spread magnitude)".to_string()
        } else {
            format!("{} (integer {} in Q16)", sunits(sp.threshold), sp.threshold)
        },
        estimate(c, &units, false),
        estimate(p, &punits, off),
        estimate(sp, &sunits, soff),
        c.threshold,
        p.threshold,
        sp.threshold,
    )
}
