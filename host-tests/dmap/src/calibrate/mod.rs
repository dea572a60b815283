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

pub mod checks;
pub mod file;
pub mod rule;

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use cvm_core::{Config, Scorer, flags, power};
use serde_json::{Value, json};

use crate::fmt::fmt_num;
use crate::npy::ScanFile;
use crate::options::ScoringArgs;
use crate::settings;
use file::{FORMAT, VERSION, config_json};
use rule::{Rule, channel, power_thr, stats, threshold_f64};

// `dmap eval --calibration` reads calibration files too.
pub use file::{Calibration, eval_threshold};

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

/// Both channels' magnitudes of the positions of a scan that have data.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Magnitudes {
    /// CVM gradient magnitudes, `Q(q)`.
    pub cvm: Vec<u32>,
    /// Power magnitudes, `Q15`.
    pub power: Vec<u32>,
    /// The lowest and highest sample of the scan.
    pub samples: Option<checks::SampleRange>,
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
    let mut m = Magnitudes {
        samples: data
            .iter()
            .min()
            .zip(data.iter().max())
            .map(|(&lowest, &highest)| checks::SampleRange { lowest, highest }),
        ..Magnitudes::default()
    };
    for s in crate::fixed::score_scan(scorer, scan.rows, scan.cols, &data) {
        if s.flags & flags::NO_DATA == 0 {
            m.cvm.push(s.mag);
            m.power.push(u32::from(s.pmag));
        }
    }
    Ok(m)
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
    for (i, path) in a.refs.iter().enumerate() {
        let earlier: Vec<&Path> = a.refs[..i].iter().map(PathBuf::as_path).collect();
        checks::refuse_duplicate(path, &earlier)?;
        let scan = ScanFile::open(path)?;
        scan.validate(true)
            .with_context(|| format!("{}", path.display()))?;
        let g = (scan.geometry.j1(), scan.geometry.j2());
        if setup.is_none() {
            let config = settings::core_config(&a.scoring, a.full_scale, g.0, g.1)?;
            let scorer = settings::scorer(&config)?;
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
        if let Some(range) = m.samples {
            checks::refuse_unfit(path, (scan.rows, scan.cols), range, a.full_scale, &m.cvm)?;
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
    let mut warnings = Vec::new();
    for (i, (path, ..)) in per_ref.iter().enumerate() {
        if let Some(&(t, n)) = loo.get(i) {
            let others = fmt_num(scorer.score_to_units(t));
            warnings.extend(checks::outlier_warning(path, "CVM", n, &others));
        }
        if let Some(&(t, n)) = ploo.get(i) {
            let others = fmt_num(power::to_units(t));
            warnings.extend(checks::outlier_warning(path, "power", n, &others));
        }
    }
    if thr == u32::MAX {
        warnings.push(format!(
            "the CVM channel is off: its threshold is past the largest score (--k {} is too large)",
            fmt_num(a.k)
        ));
    }
    if pthr == power::POWER_OFF {
        warnings.push(
            "the power channel is off: its threshold is above every power magnitude (a reference with a dark neighbour, or --k too large)".into(),
        );
    }
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
    for w in &warnings {
        crate::out::warn(w);
    }
    Ok(())
}
