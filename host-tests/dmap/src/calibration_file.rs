//! The calibration file `dmap calibrate` writes and `--calibration` reads:
//! its identity and version, the scoring configuration it was made for,
//! and each channel's threshold as the integer the firmware compares with.

use std::io::Read;
use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use cvm_core::{Config, Kernels, Scorer, Weights, power, spread};
use serde_json::{Value, json};

use crate::fmt::fmt_num;

/// Identifies a calibration file.
pub const FORMAT: &str = "dmap-calibration";
/// Version of the file layout. Version 2 added the power channel
/// (`channels.power`); version 3 made the thresholds with the streaming
/// rule the board runs (`cvm_core::calibration`: median and MAD from the
/// histogram's bins, `channels.*.integers`); version 4 names the rule that
/// set them (`rule.name`: `spread` or `tail`) and adds per channel the
/// tail fit, the estimated false positions per part and the smallest
/// detected rise (`tail`, `false_positions_per_part`, `min_strength`);
/// version 5 adds the spread channel (`channels.spread`, `Q16`). A
/// reader takes versions 2 to 5: a threshold is applied the same way
/// whichever rule made it, only the statistics beside it differ; a file
/// before version 5 leaves the spread channel off.
pub const VERSION: u64 = 5;
/// The oldest version a reader takes.
pub const OLDEST_VERSION: u64 = 2;

/// The scoring configuration as recorded in a calibration file.
pub fn config_json(c: &Config) -> Result<Value> {
    let (kernels, b) = match c.kernels {
        Kernels::Paper { bmax } => ("paper", bmax),
        Kernels::Square { kmax } => ("square", kmax),
    };
    let weights = match c.weights {
        Weights::Uniform => "uniform",
        Weights::Unit => "unit",
        Weights::Separable { .. } => bail!("separable weights cannot be calibrated"),
    };
    Ok(json!({
        "j1": c.geometry.j1,
        "j2": c.geometry.j2,
        "kernels": kernels,
        "b": b,
        "weights": weights,
        "normalise": c.normalise,
        "full_scale": c.full_scale,
    }))
}

/// One line per field in which a recorded configuration differs from the
/// run's.
pub fn config_differences(recorded: &Value, run: &Value) -> Vec<String> {
    let mut out = Vec::new();
    if let (Some(a), Some(b)) = (recorded.as_object(), run.as_object()) {
        for (key, want) in b {
            let got = a.get(key).unwrap_or(&Value::Null);
            if got != want {
                out.push(format!("{key}: calibrated {got}, this run {want}"));
            }
        }
        for key in a.keys().filter(|k| !b.contains_key(*k)) {
            out.push(format!("{key}: not a configuration field"));
        }
    } else {
        out.push("configuration is not a JSON object".into());
    }
    out
}

/// A calibration file, as read.
#[derive(Clone, Debug, PartialEq)]
pub struct Calibration {
    pub config: Value,
    /// The CVM channel's threshold, in distance units and as the scorer's integer.
    pub threshold: f64,
    pub thr: u32,
    pub q: i32,
    /// The power channel's threshold, a contrast and its `Q15` integer
    /// (at most [`power::POWER_MAX`], or [`power::POWER_OFF`]).
    pub power_threshold: f64,
    pub pthr: u32,
    /// The spread channel's threshold, a share of the power and its `Q16`
    /// integer (at most [`spread::SPREAD_MAX`], or [`spread::SPREAD_OFF`],
    /// which a file before version 5 gives).
    pub spread_threshold: f64,
    pub sthr: u32,
}

/// The most a calibration file is read of: one is about 2 KB, and a
/// device or a runaway pipe named by mistake must not fill the memory.
pub const MAX_FILE_BYTES: u64 = 1 << 20;

/// A calibration file's JSON, read once (a pipe or `/dev/stdin` cannot be
/// read twice), at most [`MAX_FILE_BYTES`], a leading UTF-8 byte order
/// mark (some editors write one) skipped.
fn read_json(path: &Path) -> Result<Value> {
    let p = path.display();
    let file = std::fs::File::open(path).with_context(|| format!("reading {p}"))?;
    if file.metadata().is_ok_and(|m| m.is_dir()) {
        bail!("{p}: is a directory, not a calibration file");
    }
    let mut bytes = Vec::new();
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .with_context(|| format!("reading {p}"))?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        bail!(
            "{p}: larger than {} KiB, not a calibration file (dmap calibrate writes about 2 KB)",
            MAX_FILE_BYTES >> 10
        );
    }
    let body = bytes.strip_prefix(b"\xef\xbb\xbf").unwrap_or(&bytes);
    serde_json::from_slice(body).with_context(|| format!("{p}: not a JSON calibration"))
}

impl Calibration {
    /// Reads and checks a calibration file's format.
    pub fn load(path: &Path) -> Result<Self> {
        Self::from_json(path, read_json(path)?)
    }

    /// A calibration file's text already in memory, read and checked as
    /// [`Calibration::load`] reads a file; `name` stands for the file in
    /// messages.
    pub fn from_text(name: &Path, text: &str) -> Result<Self> {
        let body = text.strip_prefix('\u{feff}').unwrap_or(text);
        let v = serde_json::from_str(body)
            .with_context(|| format!("{}: not a JSON calibration", name.display()))?;
        Self::from_json(name, v)
    }

    /// Checks the calibration `v` read from `path` (named in messages).
    fn from_json(path: &Path, v: Value) -> Result<Self> {
        let p = path.display();
        if v["format"] != FORMAT {
            bail!("{p}: not a calibration file (no \"format\": \"{FORMAT}\")");
        }
        if v["version"] == 1 {
            bail!(
                "{p}: calibration file version 1 has no power-channel threshold (made before the power channel): run dmap calibrate again"
            );
        }
        if !v["version"]
            .as_u64()
            .is_some_and(|n| (OLDEST_VERSION..=VERSION).contains(&n))
        {
            bail!(
                "{p}: calibration file version {} (this dmap reads {OLDEST_VERSION} to {VERSION})",
                v["version"]
            );
        }
        if v["config"]["scores"] == "precomputed" {
            bail!(
                "{p} was calibrated on precomputed scores (dmap calibrate --scores): it has no scoring configuration to check, so only dmap eval takes it"
            );
        }
        let ch = &v["channels"]["cvm"];
        let threshold = ch["threshold"]
            .as_f64()
            .filter(|t| t.is_finite() && *t >= 0.0)
            .ok_or_else(|| anyhow!("{p}: channels.cvm.threshold missing or not a number >= 0"))?;
        let thr = ch["thr"]
            .as_u64()
            .and_then(|t| u32::try_from(t).ok())
            .ok_or_else(|| anyhow!("{p}: channels.cvm.thr missing or not a u32"))?;
        let q = ch["q"]
            .as_i64()
            .and_then(|t| i32::try_from(t).ok())
            .ok_or_else(|| anyhow!("{p}: channels.cvm.q missing or not an integer"))?;
        if !v["config"].is_object() {
            bail!("{p}: no scoring configuration recorded");
        }
        // The integer and its format are the calibration; the threshold in
        // units is `thr * 2^-q` exactly (JSON's decimal, read back, may be
        // an ulp away), and must agree with the recorded one.
        if !(-64..=64).contains(&q) {
            bail!("{p}: channels.cvm.q {q} is not a score format");
        }
        let exact = f64::from(thr) * 2f64.powi(-q);
        if (exact - threshold).abs() > 1e-12 * exact.max(f64::MIN_POSITIVE) {
            bail!(
                "{p}: threshold {} is not the integer {thr} in Q({q}) ({})",
                fmt_num(threshold),
                fmt_num(exact)
            );
        }
        let threshold = exact;
        let pch = &v["channels"]["power"];
        let power_threshold = pch["threshold"]
            .as_f64()
            .filter(|t| t.is_finite() && *t >= 0.0)
            .ok_or_else(|| anyhow!("{p}: channels.power.threshold missing or not a number >= 0"))?;
        let pthr = pch["thr"]
            .as_u64()
            .and_then(|t| u32::try_from(t).ok())
            .filter(|&t| power_thr(t) == t)
            .ok_or_else(|| {
                anyhow!(
                    "{p}: channels.power.thr missing or not a power threshold (0..={} or {} for off)",
                    power::POWER_MAX,
                    power::POWER_OFF
                )
            })?;
        if pch["q"] != power::POWER_FRAC {
            bail!(
                "{p}: channels.power.q must be {} (Q15 contrasts)",
                power::POWER_FRAC
            );
        }
        let pexact = power::to_units(pthr);
        if (pexact - power_threshold).abs() > 1e-12 * pexact.max(f64::MIN_POSITIVE) {
            bail!(
                "{p}: power threshold {} is not the integer {pthr} in Q15 ({})",
                fmt_num(power_threshold),
                fmt_num(pexact)
            );
        }
        debug_assert_eq!(power::threshold_from_units(pexact), pthr);
        let sthr = if v["version"].as_u64().is_some_and(|n| n >= 5) {
            spread_channel(&p, &v["channels"]["spread"])?
        } else {
            spread::SPREAD_OFF
        };
        Ok(Calibration {
            config: v["config"].clone(),
            threshold,
            thr,
            q,
            power_threshold: pexact,
            pthr,
            spread_threshold: spread::to_units(sthr),
            sthr,
        })
    }

    /// The threshold in distance units for a run with core configuration
    /// `config` and its scorer; refuses any other configuration than the
    /// one calibrated, and a threshold that would not be `thr` exactly.
    pub fn threshold_for(&self, path: &Path, config: &Config, scorer: &Scorer) -> Result<f64> {
        let diff = config_differences(&self.config, &config_json(config)?);
        if !diff.is_empty() {
            bail!(
                "{} was calibrated for another scoring configuration ({}); calibrate again with these options",
                path.display(),
                diff.join("; ")
            );
        }
        if scorer.score_frac_bits() != self.q
            || scorer.threshold_from_units(self.threshold) != self.thr
        {
            bail!(
                "{}: threshold {} is not the integer {} in this scorer's Q({}) format",
                path.display(),
                fmt_num(self.threshold),
                self.thr,
                scorer.score_frac_bits()
            );
        }
        Ok(self.threshold)
    }
}

/// The spread channel's `Q16` threshold of a version 5 file's
/// `channels.spread` (`p` names the file in messages): the integer, its
/// format, and the share it must equal exactly.
fn spread_channel(p: &impl std::fmt::Display, ch: &Value) -> Result<u32> {
    let units = ch["threshold"]
        .as_f64()
        .filter(|t| t.is_finite() && *t >= 0.0)
        .ok_or_else(|| anyhow!("{p}: channels.spread.threshold missing or not a number >= 0"))?;
    let sthr = ch["thr"]
        .as_u64()
        .and_then(|t| u32::try_from(t).ok())
        .filter(|&t| spread_thr(t) == t)
        .ok_or_else(|| {
            anyhow!(
                "{p}: channels.spread.thr missing or not a spread threshold (0..={} or {} for off)",
                spread::SPREAD_MAX,
                spread::SPREAD_OFF
            )
        })?;
    if ch["q"] != spread::SPREAD_FRAC {
        bail!(
            "{p}: channels.spread.q must be {} (Q16 shares)",
            spread::SPREAD_FRAC
        );
    }
    let exact = spread::to_units(sthr);
    if (exact - units).abs() > 1e-12 * exact.max(f64::MIN_POSITIVE) {
        bail!(
            "{p}: spread threshold {} is not the integer {sthr} in Q16 ({})",
            fmt_num(units),
            fmt_num(exact)
        );
    }
    Ok(sthr)
}

/// The threshold `dmap eval --calibration` applies: the CVM channel of a
/// calibration made on scans, or that of one made on precomputed scores.
pub fn eval_threshold(path: &Path) -> Result<f64> {
    let v = read_json(path)?;
    if v["format"] == FORMAT && v["config"]["scores"] == "precomputed" {
        return v["channels"]["scores"]["threshold"]
            .as_f64()
            .ok_or_else(|| anyhow!("{}: channels.scores.threshold missing", path.display()));
    }
    Ok(Calibration::from_json(path, v)?.threshold)
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

/// The spread channel's threshold from the rule's: itself when a
/// magnitude can reach it, else [`spread::SPREAD_OFF`].
pub fn spread_thr(thr: u32) -> u32 {
    if thr <= spread::SPREAD_MAX {
        thr
    } else {
        spread::SPREAD_OFF
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file of `version` with the given spread channel (none: absent).
    fn doc(version: u64, spread: Option<Value>) -> Value {
        let mut v = json!({
            "format": FORMAT,
            "version": version,
            "config": {"j1": 5, "j2": 5},
            "channels": {
                "cvm": {"threshold": 0.5, "thr": 1u32 << 20, "q": 21},
                "power": {"threshold": 3277.0 / 32768.0, "thr": 3277, "q": 15},
            },
        });
        if let Some(sp) = spread {
            v["channels"]["spread"] = sp;
        }
        v
    }

    fn load(v: Value) -> Result<Calibration> {
        Calibration::from_json(Path::new("cal.json"), v)
    }

    #[test]
    fn the_spread_channel_from_version_5_and_off_before() {
        let sp = json!({"threshold": 6554.0 / 65536.0, "thr": 6554, "q": 16});
        let c = load(doc(5, Some(sp.clone()))).unwrap();
        assert_eq!((c.sthr, c.spread_threshold), (6554, 6554.0 / 65536.0));
        // Before version 5: off, whatever the file holds.
        for version in [2, 3, 4] {
            let c = load(doc(version, Some(sp.clone()))).unwrap();
            assert_eq!(c.sthr, spread::SPREAD_OFF, "{version}");
            assert_eq!(
                spread::threshold_from_units(c.spread_threshold),
                spread::SPREAD_OFF
            );
        }
        // Off is a threshold; a missing, tampered or other-format one is refused.
        let off = json!({"threshold": spread::to_units(u32::MAX), "thr": u32::MAX, "q": 16});
        assert_eq!(load(doc(5, Some(off))).unwrap().sthr, spread::SPREAD_OFF);
        for (sp, needle) in [
            (None, "channels.spread.threshold missing"),
            (
                Some(json!({"threshold": 1.0, "thr": 92681, "q": 16})),
                "not a spread threshold",
            ),
            (
                Some(json!({"threshold": 100.5 / 65536.0, "thr": 100, "q": 16})),
                "is not the integer 100 in Q16",
            ),
            (
                Some(json!({"threshold": 100.0 / 65536.0, "thr": 100, "q": 15})),
                "channels.spread.q must be 16",
            ),
        ] {
            let e = load(doc(5, sp)).unwrap_err().to_string();
            assert!(e.contains(needle), "{e}");
        }
    }

    #[test]
    fn differences_name_the_fields() {
        let a = json!({"j1": 9, "j2": 9, "normalise": true});
        let b = json!({"j1": 9, "j2": 9, "normalise": false});
        assert_eq!(
            config_differences(&a, &b),
            vec!["normalise: calibrated true, this run false".to_string()]
        );
        assert!(config_differences(&a, &a).is_empty());
    }
}
