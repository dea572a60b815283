//! `dmap calibrate`: the defect thresholds of a scoring configuration (the
//! CVM channel's and the power channel's) from defect-free reference scans, scored with the firmware's arithmetic (the
//! fixed-point scorer `dmap stream` and `dmap score --distance cvm-fixed`
//! use), written as a calibration file that `dmap stream`, `dmap emulate`
//! and `dmap twin` apply with `--calibration` (docs/experiments.md,
//! "Calibration").
//!
//! The rule is the board's own (`cvm_core::calibration`, which the board
//! runs on live scans for `calibrate N`): each reference is scored, its
//! positions with data go into a `Calibrator`, and the references'
//! calibrators are merged, so the thresholds are those the board computes
//! from the same scans. Per channel, over the magnitudes of every
//! position with data of every reference (integers: the CVM gradient
//! magnitudes in the scorer's `Q(q)` format, the power magnitudes in
//! `Q15`, `cvm_core::power`), each taken as the representative of its
//! histogram bin (itself below 256, else the middle of a bin under 0.8 %
//! of the value wide),
//!
//! ```text
//! thr = Q_p + ceil(k * 1.4826 * MAD) + 1
//! ```
//!
//! `Q_p` the top of the bin of the nearest-rank `p` quantile, capped at the
//! exact maximum (default `p = 1`: the maximum itself), the median and
//! `MAD` the lower medians (rank `ceil(n / 2)`) of the representatives and
//! of their distances from the median (1.4826 MAD is the standard
//! deviation of a normal background), `k` the margin in those units
//! (default 3). `p` and `k` must be exact in millionths and thousandths:
//! the integers the board computes with. A position is defective when its
//! magnitude reaches `thr`, so with `p = 1` no reference position is. The
//! threshold in distance units is `thr * 2^-q`, which converts back to
//! exactly `thr`; the power threshold as a contrast is `thr * 2^-15`,
//! likewise exact. A power threshold above the largest magnitude
//! ([`power::POWER_MAX`], a reference with a dark neighbour) is recorded
//! as [`power::POWER_OFF`]: the channel is off.
//!
//! That is the spread rule (`--rule spread`, or `--k-mad`/`--quantile` given).
//! The default, `--rule tail` (the board's too), sets each threshold
//! instead where an exponential fit of the channel's upper tail (the top
//! `--tail-fraction` of the magnitudes, default 1 %, at least ten values)
//! expects `--rate` false positions per part (default 0.001), at least the
//! maximum plus one (`cvm_core::calibration::tail`). Either
//! way the file and the summary give, per channel, the tail fit, the false
//! positions per part it predicts at the threshold, and the smallest rise
//! above the median the threshold detects (`min_strength`).
//!
//! `--from-scores` is another thing: a rule in f64 with exact medians on
//! precomputed gradient images of any distance, for `dmap eval` only.
//!
//! The file records the scoring configuration (geometry, kernels, weights,
//! normalisation, full scale); applying it to any other configuration is
//! refused. Each channel has its entry in `"channels"` (`"cvm"`, `"power"`:
//! `threshold`, `thr`, `q`, and the statistics, also as `integers`).
//! Version 4 files name the rule and carry the tail fit; version 3 files
//! (the spread rule, before that) and version 2 files (the rule before
//! it, exact medians over every magnitude) are still applied, their
//! thresholds being the same kind of integer. Version 1 files, made before the power
//! channel, have no power entry and are refused with a request to
//! calibrate again: applying only half a calibration would leave the power
//! channel at a default the references never checked.

pub mod checks;
pub mod report;
pub mod rule;

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use cvm_core::calibration::{Calibrator, Rule as CoreRule, Statistics};
use cvm_core::{Config, PositionScore, Scorer, flags, power, spread};
use serde_json::json;

use crate::calibration_file::{FORMAT, VERSION};
use crate::fmt::fmt_num;
use crate::npy::ScanFile;
use crate::options::ScoringArgs;
use crate::settings;
use rule::{Options, Rule, RuleName, threshold_f64};

// `dmap eval --calibration` reads calibration files too.
pub use crate::calibration_file::{Calibration, eval_threshold};

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
    /// Rule that sets both channels' thresholds (default: the one whose parameters are given,
    /// else the board's, `cvm_core`'s Rule::DEFAULT: tail)
    #[arg(long, value_enum)]
    pub rule: Option<RuleName>,
    /// Spread rule: quantile of the reference magnitudes the threshold starts from (default 1:
    /// their maximum; a multiple of 0.000001)
    #[arg(long, value_name = "P")]
    pub quantile: Option<f64>,
    /// Spread rule: margin above the quantile, in robust standard deviations (1.4826 MAD) of the
    /// reference magnitudes (default 3; a multiple of 0.001)
    #[arg(long = "k-mad", alias = "k", value_name = "K")]
    pub k: Option<f64>,
    /// Tail rule: target false positions per part, per channel (default 0.001: one in 1000
    /// parts; a multiple of 0.000001)
    #[arg(long, value_name = "RATE")]
    pub rate: Option<f64>,
    /// Tail rule: share of the reference magnitudes fitted as the upper tail (default 0.01; a
    /// multiple of 0.000001)
    #[arg(long, value_name = "F")]
    pub tail_fraction: Option<f64>,
    /// The references are gradient images (`dmap score` output, any distance), not scans:
    /// the same rule in f64 on their magnitudes, for `dmap eval --calibration` only
    #[arg(long = "from-scores", alias = "scores")]
    pub scores: bool,
    /// Output calibration file (JSON; - for standard output)
    #[arg(short, long = "output", alias = "out", value_name = "CAL.json")]
    pub out: PathBuf,
}

/// A reference's scores (both channels, every position, the firmware's
/// arithmetic) and its lowest and highest sample.
pub struct Scored {
    pub scores: Vec<PositionScore>,
    pub samples: Option<checks::SampleRange>,
}

impl Scored {
    /// The CVM magnitudes (`Q(q)`) of the positions with data.
    pub fn cvm(&self) -> Vec<u32> {
        self.with_data().map(|s| s.mag).collect()
    }

    /// The power magnitudes (`Q15`) of the positions with data.
    pub fn power(&self) -> Vec<u32> {
        self.with_data().map(|s| u32::from(s.pmag)).collect()
    }

    /// The spread magnitudes (`Q16`) of the positions with data.
    pub fn spread(&self) -> Vec<u32> {
        self.with_data().map(|s| s.smag).collect()
    }

    fn with_data(&self) -> impl Iterator<Item = &PositionScore> {
        self.scores.iter().filter(|s| s.flags & flags::NO_DATA == 0)
    }

    /// The reference as one scan of a calibration: the board's calibrator
    /// fed its positions.
    pub fn calibrator(&self) -> Calibrator {
        let mut c = Calibrator::new();
        c.add_row(&self.scores);
        c.end_scan();
        c
    }
}

/// Every position's scores of a scan, in the firmware's arithmetic.
pub fn score(scorer: &Scorer, scan: &ScanFile) -> Result<Scored> {
    let n = scan.geometry.cells();
    let mut data = vec![0u16; scan.maps() * n];
    let mut scratch = Vec::new();
    // A row at a time: the f64 staging stays one row long.
    for (row, out) in data.chunks_mut(scan.cols * n).enumerate() {
        scan.maps_u16(row * scan.cols, out, &mut scratch)?;
    }
    let samples = data
        .iter()
        .min()
        .zip(data.iter().max())
        .map(|(&lowest, &highest)| checks::SampleRange { lowest, highest });
    let mut scores = crate::fixed::score_scan(scorer, scan.rows, scan.cols, &data);
    // Measured whatever the scan's spread setting, as the board measures
    // it during a calibration.
    crate::fixed::add_spread(scorer, scan.rows, scan.cols, &data, &mut scores);
    Ok(Scored { scores, samples })
}

/// `dmap calibrate --from-scores`: the rule on precomputed gradient images.
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

/// One reference, scored, and calibrated on its own.
struct Reference {
    path: PathBuf,
    rows: usize,
    cols: usize,
    cvm: Vec<u32>,
    power: Vec<u32>,
    spread: Vec<u32>,
    cal: Calibrator,
}

/// The references' calibrators merged, `except` one.
fn merged(refs: &[Reference], except: Option<usize>) -> Calibrator {
    let mut all = Calibrator::new();
    for (i, r) in refs.iter().enumerate() {
        if Some(i) != except {
            all.merge(&r.cal);
        }
    }
    all
}

fn statistics(c: &Calibrator, rule: &CoreRule) -> Result<Statistics> {
    c.statistics(rule)
        .map_err(|e| anyhow!("the references cannot calibrate: {e}"))
}

/// Scores the references and calibrates each on its own; refuses any
/// that cannot calibrate. Returns them with the scoring configuration.
fn references<'a>(
    a: &CalibrateArgs,
    open: &mut dyn FnMut(usize) -> Result<ScanFile<'a>>,
) -> Result<(Vec<Reference>, Config, Scorer)> {
    let mut refs = Vec::new();
    let mut setup: Option<(Config, Scorer, (usize, usize))> = None;
    for (i, path) in a.refs.iter().enumerate() {
        let scan = open(i)?;
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
        let scored = score(scorer, &scan)?;
        let cvm = scored.cvm();
        if cvm.is_empty() {
            bail!("{} has no position with data", path.display());
        }
        if let Some(range) = scored.samples {
            checks::refuse_unfit(path, (scan.rows, scan.cols), range, a.full_scale, &cvm)?;
        }
        refs.push(Reference {
            path: path.clone(),
            rows: scan.rows,
            cols: scan.cols,
            power: scored.power(),
            spread: scored.spread(),
            cal: scored.calibrator(),
            cvm,
        });
    }
    let Some((config, scorer, _)) = setup else {
        bail!("no reference scan given")
    };
    Ok((refs, config, scorer))
}

/// The rule a run's options choose.
pub fn rule(a: &CalibrateArgs) -> Result<Rule> {
    Rule::from_options(&Options {
        name: a.rule,
        quantile: a.quantile,
        k: a.k,
        rate: a.rate,
        tail: a.tail_fraction,
    })
}

pub fn run(a: &CalibrateArgs) -> Result<()> {
    let rule = rule(a)?;
    if a.out.as_os_str() != "-" {
        let inputs: Vec<&Path> = a.refs.iter().map(PathBuf::as_path).collect();
        crate::out::refuse_inputs(&a.out, &inputs)?;
    }
    if a.scores {
        if rule.name != RuleName::Spread {
            bail!("--from-scores applies the spread rule only (--rule spread)");
        }
        return run_scores(a, &rule);
    }
    let out = calibrate_with(a, &rule, &mut |i| {
        let earlier: Vec<&Path> = a.refs[..i].iter().map(PathBuf::as_path).collect();
        checks::refuse_duplicate(&a.refs[i], &earlier)?;
        ScanFile::open(&a.refs[i])
    })?;
    let target = crate::out::Target::new(&a.out);
    crate::out::write_target(&target, |w| {
        w.write_all(out.text.as_bytes()).map_err(|e| anyhow!("{e}"))
    })?;
    let _ = writeln!(std::io::stderr(), "{}", out.summary);
    for w in &out.warnings {
        crate::out::warn(w);
    }
    Ok(())
}

/// What a calibration makes: the file's text, the summary line and the
/// warnings `dmap calibrate` prints.
pub struct Outcome {
    pub text: String,
    pub summary: String,
    pub warnings: Vec<String>,
}

/// `dmap calibrate` (not `--from-scores`) on references that `open` gives, the
/// `i`-th named `a.refs[i]` in the file and in messages, without writing
/// anything.
pub fn calibrate_with<'a>(
    a: &CalibrateArgs,
    rule: &Rule,
    open: &mut dyn FnMut(usize) -> Result<ScanFile<'a>>,
) -> Result<Outcome> {
    let exact = rule.exact()?;
    let (refs, config, scorer) = references(a, open)?;
    let st = statistics(&merged(&refs, None), &exact)?;
    // Leave one out: per reference, both channels' thresholds of the
    // others and how many of its own positions reach them.
    let mut loo = Vec::new();
    if refs.len() > 1 {
        for (i, r) in refs.iter().enumerate() {
            let o = statistics(&merged(&refs, Some(i)), &exact)?;
            let reach = |m: &[u32], t: u32| m.iter().filter(|&&x| x >= t).count();
            loo.push([
                (o.cvm.threshold, reach(&r.cvm, o.cvm.threshold)),
                (o.power.threshold, reach(&r.power, o.power.threshold)),
                (o.spread.threshold, reach(&r.spread, o.spread.threshold)),
            ]);
        }
    }
    let mut warnings = Vec::new();
    for (r, &[(t, n), (pt, pn), (st_, sn)]) in refs.iter().zip(&loo) {
        let others = fmt_num(scorer.score_to_units(t));
        warnings.extend(checks::outlier_warning(&r.path, "CVM", n, &others));
        let others = fmt_num(power::to_units(pt));
        warnings.extend(checks::outlier_warning(&r.path, "power", pn, &others));
        let others = fmt_num(spread::to_units(st_));
        warnings.extend(checks::outlier_warning(&r.path, "spread", sn, &others));
    }
    let (thr, pthr) = (st.cvm.threshold, st.power.threshold);
    if thr == u32::MAX {
        warnings.push(format!(
            "the CVM channel is off: its threshold is past the largest score ({})",
            match rule.name {
                RuleName::Spread => format!("--k-mad {} is too large", fmt_num(rule.k)),
                RuleName::Tail => "the references' tail is too wide".into(),
            }
        ));
    }
    if pthr == power::POWER_OFF {
        warnings.push(
            "the power channel is off: its threshold is above every power magnitude (a reference with a dark neighbour, or a rule too strict)".into(),
        );
    }
    if st.spread.threshold == spread::SPREAD_OFF {
        warnings.push(
            "the spread channel is off: its threshold is above every spread magnitude (a rule too strict)".into(),
        );
    }
    let per_ref: Vec<report::Reference> = refs
        .iter()
        .enumerate()
        .map(|(i, r)| {
            Ok(report::Reference {
                path: &r.path,
                rows: r.rows,
                cols: r.cols,
                stats: statistics(&r.cal, &exact)?,
                others: loo.get(i).copied(),
            })
        })
        .collect::<Result<_>>()?;
    let doc = report::document(&config, &scorer, rule, &exact, &st, &per_ref)?;
    let text = format!(
        "{}\n",
        serde_json::to_string_pretty(&doc).context("encoding the calibration")?
    );
    Ok(Outcome {
        text,
        summary: report::summary(&scorer, &st, refs.len()),
        warnings,
    })
}
