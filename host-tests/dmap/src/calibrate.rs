//! `dmap calibrate`: the defect thresholds of a scoring configuration (the
//! CVM channel's and the power channel's) from defect-free reference scans, scored with the firmware's arithmetic (the
//! fixed-point scorer `dmap stream` and `dmap score --distance cvm-fixed`
//! use), written as a calibration file that `dmap stream`, `dmap emulate`
//! and `dmap twin` apply with `--calibration` (docs/experiments.md,
//! "Calibration").
//!
//! The rule, the same for each channel: with `m` the channel's magnitudes
//! of every position of every reference (integers: the CVM gradient
//! magnitudes in the scorer's `Q(q)` format, the power magnitudes in `Q15`,
//! `cvm_core::power`),
//!
//! ```text
//! thr = Q_p(m) + ceil(k * 1.4826 * MAD(m)) + 1
//! ```
//!
//! `Q_p` the nearest-rank `p` quantile (default `p = 1`, the maximum),
//! `MAD` the median absolute deviation from the median (1.4826 MAD is the
//! standard deviation of a normal background), `k` the margin in those
//! units (default 3). A position is defective when its magnitude reaches
//! `thr`, so with `p = 1` no reference position is. The threshold in
//! distance units is `thr * 2^-q`, which converts back to exactly `thr`;
//! the power threshold as a contrast is `thr * 2^-15`, likewise exact. A
//! power threshold above the largest magnitude ([`power::POWER_MAX`], a
//! reference with a dark neighbour) is recorded as [`power::POWER_OFF`]:
//! the channel is off.
//!
//! The file records the scoring configuration (geometry, kernels, weights,
//! normalisation, full scale); applying it to any other configuration is
//! refused. Each channel has its entry in `"channels"` (`"cvm"`, `"power"`:
//! `threshold`, `thr`, `q`). Version 1 files, made before the power
//! channel, have no power entry and are refused with a request to
//! calibrate again: applying only half a calibration would leave the power
//! channel at a default the references never checked.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use cvm_core::{Config, Kernels, Scorer, Weights, flags, power};
use serde_json::{Value, json};

use crate::npy::ScanFile;
use crate::options::ScoringArgs;
use crate::stream::fmt_num;

/// Identifies a calibration file.
pub const FORMAT: &str = "dmap-calibration";
/// Version of the file layout; a reader refuses other versions. Version 2
/// added the power channel (`channels.power`).
pub const VERSION: u64 = 2;
/// MAD to the standard deviation of a normal distribution.
pub const MAD_TO_SIGMA: f64 = 1.4826;

#[derive(Args, Clone, Debug)]
pub struct CalibrateArgs {
    /// Defect-free reference scans (.npy, rows x cols x J1 x J2, u16 counts), all of one geometry
    #[arg(value_name = "REF.npy", required = true)]
    pub refs: Vec<PathBuf>,
    #[command(flatten)]
    pub scoring: ScoringArgs,
    /// Full scale of the detector the calibration is for (a sample at or above it flags its map saturated)
    #[arg(long, value_name = "N", default_value_t = u16::MAX,
          value_parser = clap::value_parser!(u16).range(1..))]
    pub full_scale: u16,
    /// Quantile of the reference magnitudes the threshold starts from (1 = their maximum)
    #[arg(long, value_name = "P", default_value_t = 1.0)]
    pub quantile: f64,
    /// Margin above the quantile, in robust standard deviations (1.4826 MAD) of the reference magnitudes
    #[arg(long, value_name = "K", default_value_t = 3.0)]
    pub k: f64,
    /// The references are gradient images (`dmap score` output, any distance), not scans:
    /// the same rule in f64 on their magnitudes, for `dmap eval --calibration` only
    #[arg(long)]
    pub scores: bool,
    /// Output calibration file (JSON; - for standard output)
    #[arg(short, long, value_name = "CAL.json")]
    pub out: PathBuf,
}

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

/// Both channels' magnitudes of the positions of a scan that have data.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Magnitudes {
    /// CVM gradient magnitudes, `Q(q)`.
    pub cvm: Vec<u32>,
    /// Power magnitudes, `Q15`.
    pub power: Vec<u32>,
}

/// Both channels' magnitudes of every position of a scan with data, in the
/// firmware's arithmetic.
pub fn magnitudes(scorer: &Scorer, scan: &ScanFile) -> Result<Magnitudes> {
    let n = scan.geometry.cells();
    let mut data = vec![0u16; scan.maps() * n];
    let mut scratch = Vec::new();
    // A row at a time: the f64 staging stays one row long.
    for (row, out) in data.chunks_mut(scan.cols * n).enumerate() {
        scan.maps_u16(row * scan.cols, out, &mut scratch)?;
    }
    let mut m = Magnitudes::default();
    for s in crate::fixed::score_scan(scorer, scan.rows, scan.cols, &data) {
        if s.flags & flags::NO_DATA == 0 {
            m.cvm.push(s.mag);
            m.power.push(u32::from(s.pmag));
        }
    }
    Ok(m)
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
fn channel(all: &[Vec<u32>], rule: &Rule, fix: fn(u32) -> u32) -> (Stats, u32, Vec<(u32, usize)>) {
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
fn config_differences(recorded: &Value, run: &Value) -> Vec<String> {
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
}

impl Calibration {
    /// Reads and checks a calibration file's format.
    pub fn load(path: &Path) -> Result<Self> {
        let p = path.display();
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {p}"))?;
        let v: Value =
            serde_json::from_str(&text).with_context(|| format!("{p}: not a JSON calibration"))?;
        if v["format"] != FORMAT {
            bail!("{p}: not a calibration file (no \"format\": \"{FORMAT}\")");
        }
        if v["version"] == 1 {
            bail!(
                "{p}: calibration file version 1 has no power-channel threshold (made before the power channel): run dmap calibrate again"
            );
        }
        if v["version"] != VERSION {
            bail!(
                "{p}: calibration file version {} (this dmap reads {VERSION})",
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
        Ok(Calibration {
            config: v["config"].clone(),
            threshold,
            thr,
            q,
            power_threshold: pexact,
            pthr,
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

/// The threshold in distance units of `--calibration PATH` for a run of
/// `scoring` plus `full_scale` on `j1 x j2` maps (checked as
/// [`Calibration::threshold_for`] does).
pub fn threshold_units(path: &Path, config: &Config) -> Result<f64> {
    let scorer = crate::fixed::scorer(config)
        .map_err(|e| anyhow!("fixed-point scorer refused the configuration: {e}"))?;
    Calibration::load(path)?.threshold_for(path, config, &scorer)
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

/// `dmap calibrate --scores`: the rule on precomputed gradient images.
fn run_scores(a: &CalibrateArgs, rule: &Rule) -> Result<()> {
    let mut all = Vec::new();
    let mut refs = Vec::new();
    for path in &a.refs {
        let img = crate::npy::read_gradient(path)?;
        let m: Vec<f64> = img
            .data
            .chunks_exact(3)
            .map(|p| p[2])
            .filter(|v| !v.is_nan())
            .collect();
        if m.is_empty() {
            bail!("{} has no position with a score", path.display());
        }
        let (_, max, median, mad) = threshold_f64(&m, rule);
        refs.push(
            json!({"file": path.display().to_string(), "max": max, "median": median, "mad": mad}),
        );
        all.extend(m);
    }
    let (t, max, median, mad) = threshold_f64(&all, rule);
    let doc = json!({
        "format": FORMAT,
        "version": VERSION,
        "config": {"scores": "precomputed"},
        "rule": {
            "text": "threshold = Q_p(m) + k * 1.4826 * MAD(m) over the magnitudes m of all reference positions (f64); defective when magnitude >= threshold",
            "quantile": rule.quantile,
            "k": rule.k,
        },
        "channels": {"scores": {"threshold": t, "positions": all.len(), "max": max, "median": median, "mad": mad}},
        "references": refs,
    });
    let text = format!(
        "{}\n",
        serde_json::to_string_pretty(&doc).context("encoding the calibration")?
    );
    crate::out::write_target(&crate::out::Target::new(&a.out), |w| {
        w.write_all(text.as_bytes()).map_err(|e| anyhow!("{e}"))
    })?;
    let _ = writeln!(
        std::io::stderr(),
        "dmap calibrate: {} scores of {} reference(s): max {}, median {}, MAD {} -> threshold {}",
        all.len(),
        a.refs.len(),
        fmt_num(max),
        fmt_num(median),
        fmt_num(mad),
        fmt_num(t)
    );
    Ok(())
}

/// The threshold `dmap eval --calibration` applies: the CVM channel of a
/// calibration made on scans, or that of one made on precomputed scores.
pub fn eval_threshold(path: &Path) -> Result<f64> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let v: Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a JSON calibration", path.display()))?;
    if v["format"] == FORMAT && v["config"]["scores"] == "precomputed" {
        return v["channels"]["scores"]["threshold"]
            .as_f64()
            .ok_or_else(|| anyhow!("{}: channels.scores.threshold missing", path.display()));
    }
    Ok(Calibration::load(path)?.threshold)
}

pub fn run(a: &CalibrateArgs) -> Result<()> {
    let rule = Rule {
        quantile: a.quantile,
        k: a.k,
    };
    rule.check()?;
    if a.out.as_os_str() != "-" {
        let inputs: Vec<&Path> = a.refs.iter().map(PathBuf::as_path).collect();
        crate::out::refuse_inputs(&a.out, &inputs)?;
    }
    if a.scores {
        return run_scores(a, &rule);
    }
    let mut all = Vec::new();
    let mut per_ref = Vec::new();
    let mut setup: Option<(Config, Scorer, (usize, usize))> = None;
    for path in &a.refs {
        let scan = ScanFile::open(path)?;
        scan.validate(true)
            .with_context(|| format!("{}", path.display()))?;
        let g = (scan.geometry.j1(), scan.geometry.j2());
        if setup.is_none() {
            let config = Config {
                full_scale: a.full_scale,
                ..a.scoring.core_config(g.0, g.1)?
            };
            let scorer = crate::fixed::scorer(&config)
                .map_err(|e| anyhow!("fixed-point scorer refused the configuration: {e}"))?;
            setup = Some((config, scorer, g));
        }
        let Some((_, scorer, g0)) = &setup else {
            unreachable!()
        };
        if g != *g0 {
            bail!(
                "{} has {}x{} maps, the first reference {}x{}: calibrate one detector geometry at a time",
                path.display(),
                g.0,
                g.1,
                g0.0,
                g0.1
            );
        }
        let m = magnitudes(scorer, &scan)?;
        if m.cvm.is_empty() {
            bail!("{} has no position with data", path.display());
        }
        per_ref.push((
            path.clone(),
            scan.rows,
            scan.cols,
            stats(&m.cvm, &rule),
            stats(&m.power, &rule),
        ));
        all.push(m);
    }
    let Some((config, scorer, _)) = setup else {
        bail!("no reference scan given")
    };
    let (cvm_all, pow_all): (Vec<Vec<u32>>, Vec<Vec<u32>>) =
        all.into_iter().map(|m| (m.cvm, m.power)).unzip();
    let (st, thr, loo) = channel(&cvm_all, &rule, |t| t);
    let (pst, pthr, ploo) = channel(&pow_all, &rule, power_thr);
    let units = scorer.score_to_units(thr);
    debug_assert_eq!(scorer.threshold_from_units(units), thr);
    let punits = power::to_units(pthr);
    debug_assert_eq!(power::threshold_from_units(punits), pthr);
    let to_units = |v: f64| v * scorer.score_to_units(1);
    let pto_units = |v: f64| v * power::to_units(1);
    let refs: Vec<Value> = per_ref
        .iter()
        .enumerate()
        .map(|(i, (path, rows, cols, s, ps))| {
            let mut r = json!({
                "file": path.display().to_string(),
                "rows": rows,
                "cols": cols,
                "max": to_units(f64::from(s.max)),
                "median": to_units(s.median),
                "mad": to_units(s.mad),
                "power": {
                    "max": pto_units(f64::from(ps.max)),
                    "median": pto_units(ps.median),
                    "mad": pto_units(ps.mad),
                },
            });
            if let Some((t, n)) = loo.get(i) {
                r["others_threshold"] = json!(scorer.score_to_units(*t));
                r["at_or_above_others_threshold"] = json!(n);
            }
            if let Some((t, n)) = ploo.get(i) {
                r["power"]["others_threshold"] = json!(power::to_units(*t));
                r["power"]["at_or_above_others_threshold"] = json!(n);
            }
            r
        })
        .collect();
    let doc = json!({
        "format": FORMAT,
        "version": VERSION,
        "config": config_json(&config)?,
        "rule": {
            "text": "per channel, thr = Q_p(m) + ceil(k * 1.4826 * MAD(m)) + 1 over the channel's magnitudes m of all reference positions (integers: cvm in Q(q), power in Q15; a power thr above 46340 is recorded as 4294967295, off); defective when a channel's magnitude >= its thr",
            "quantile": rule.quantile,
            "k": rule.k,
        },
        "channels": {
            "cvm": {
                "threshold": units,
                "thr": thr,
                "q": scorer.score_frac_bits(),
                "positions": st.n,
                "max": to_units(f64::from(st.max)),
                "quantile_value": to_units(f64::from(st.quantile)),
                "median": to_units(st.median),
                "mad": to_units(st.mad),
            },
            "power": {
                "threshold": punits,
                "thr": pthr,
                "q": power::POWER_FRAC,
                "positions": pst.n,
                "max": pto_units(f64::from(pst.max)),
                "quantile_value": pto_units(f64::from(pst.quantile)),
                "median": pto_units(pst.median),
                "mad": pto_units(pst.mad),
            }
        },
        "references": refs,
    });
    let text = format!(
        "{}\n",
        serde_json::to_string_pretty(&doc).context("encoding the calibration")?
    );
    let target = crate::out::Target::new(&a.out);
    crate::out::write_target(&target, |w| {
        w.write_all(text.as_bytes()).map_err(|e| anyhow!("{e}"))
    })?;
    let _ = writeln!(
        std::io::stderr(),
        "dmap calibrate: {} positions of {} reference(s): max {}, median {}, MAD {} -> threshold {} (integer {} in Q({})); power: max {}, median {}, MAD {} -> threshold {}",
        st.n,
        a.refs.len(),
        fmt_num(to_units(f64::from(st.max))),
        fmt_num(to_units(st.median)),
        fmt_num(to_units(st.mad)),
        fmt_num(units),
        thr,
        scorer.score_frac_bits(),
        fmt_num(pto_units(f64::from(pst.max))),
        fmt_num(pto_units(pst.median)),
        fmt_num(pto_units(pst.mad)),
        if pthr == power::POWER_OFF {
            "off (above every power magnitude)".to_string()
        } else {
            format!("{} (integer {pthr} in Q15)", fmt_num(punits))
        }
    );
    Ok(())
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
