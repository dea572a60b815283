//! `dmap bench`: maps scored per second, on this machine and one thread, by
//! every implementation of the gradient (Eq. 1): the literal f64 formula,
//! f64 summed-area tables ("fast CMD"), the f64 embedding, the firmware's
//! fixed-point pipeline and exact EMD.
//!
//! A map scored is its per-map work (normalisation, table or embedding)
//! plus its share of the gradient distances: two per position. Every
//! implementation scores a whole synthetic scan (a Gaussian spot that wanders
//! smoothly from beam to beam, detector noise, a few scattering positions)
//! with the border rule, so per-map figures include what a real scan costs.
//! Before timing, the implementations are run on a small sample of the same
//! scan and must agree ([`agreement`]): the figures are those of correct code.

use crate::listen::decode;
use crate::options::ScoringArgs;
use crate::stream::{DEFAULT_POWER_THRESHOLD, DEFAULT_THRESHOLD, VecSink};
use anyhow::{Context, Result, bail};
use clap::Args;
use cvm_core::{Pipeline, Position, PositionScore, Scorer, Settings};
use cvm_reference::{CvmConfig, CvmEmbedding, Emd, Geometry, Ground, Kernel, SummedAreaTable};
use cvm_sim::rng::{gaussian_pair, mix};
use std::hint::black_box;
use std::time::{Duration, Instant};

/// The implementations, in report order; the first five are the JSON keys
/// every consumer may rely on.
pub const IMPLEMENTATIONS: [Implementation; 6] = [
    Implementation::Brute,
    Implementation::Sat,
    Implementation::EmbedF64,
    Implementation::Fixed,
    Implementation::Emd,
    Implementation::FixedBatch,
];

/// Seed of the synthetic scan: fixed, so every run times the same maps.
pub const SEED: u64 = 0x5CA7_7E12;

/// Largest scan a timed run uses; faster implementations repeat it.
const MAX_ROWS: usize = 32;
const MAX_COLS: usize = 128;
/// Timed runs per implementation (the median is reported).
const RUNS: usize = 5;

#[derive(Args, Clone, Debug)]
pub struct BenchArgs {
    /// Detector geometry J1xJ2, each axis 1..=16
    #[arg(
        long,
        value_name = "J1xJ2",
        default_value = "15x15",
        value_parser = crate::cli_values::j1xj2
    )]
    pub geometry: (usize, usize),
    #[command(flatten)]
    pub scoring: ScoringArgs,
    /// Print one JSON object instead of the table
    #[arg(long)]
    pub json: bool,
    /// Time budget for all implementations together (calibration, warm-up and the timed runs)
    #[arg(long, default_value_t = 30.0, value_name = "S")]
    pub seconds: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Implementation {
    /// Eq. 8/9 literally: every LCD summed cell by cell, for every distance.
    Brute,
    /// A summed-area table per map, every LCD from four entries.
    Sat,
    /// The f64 embedding `R1 ã R2ᵀ` per map, squared Euclidean distances.
    EmbedF64,
    /// The firmware's path: `cvm_core::Pipeline` (streaming engine,
    /// decisions, line encoding) over the scan in raster order.
    Fixed,
    /// Exact EMD (transportation simplex), Euclidean ground distance.
    Emd,
    /// The core's scorer on a scan held in memory (`dmap::fixed`), without
    /// the streaming engine: shows what the engine itself costs.
    FixedBatch,
}

impl Implementation {
    pub fn key(self) -> &'static str {
        match self {
            Self::Brute => "brute",
            Self::Sat => "sat",
            Self::EmbedF64 => "embed_f64",
            Self::Fixed => "fixed",
            Self::Emd => "emd",
            Self::FixedBatch => "fixed_batch",
        }
    }

    fn label(self) -> &'static str {
        match self {
            Self::Brute => "f64 brute force (Eq. 8)",
            Self::Sat => "f64 summed-area tables",
            Self::EmbedF64 => "f64 embedding",
            Self::Fixed => "fixed point, firmware pipeline",
            Self::Emd => "exact EMD (Euclidean)",
            Self::FixedBatch => "fixed point, batch (no engine)",
        }
    }
}

/// A synthetic scan, raster order, `J1 * J2` counts per position.
#[derive(Clone, Debug)]
pub struct SampleScan {
    pub j1: usize,
    pub j2: usize,
    pub rows: usize,
    pub cols: usize,
    pub counts: Vec<u16>,
    pub values: Vec<f64>,
}

impl SampleScan {
    pub fn cells(&self) -> usize {
        self.j1 * self.j2
    }

    pub fn maps(&self) -> usize {
        self.rows * self.cols
    }

    fn map(&self, r: usize, c: usize) -> &[f64] {
        let n = self.cells();
        &self.values[(r * self.cols + c) * n..(r * self.cols + c + 1) * n]
    }
}

/// The scan of `rows x cols` positions. Each position's map depends on the
/// seed and the position only, so a smaller scan is the top-left block of a
/// larger one.
///
/// A spot of about one cell's width whose centre moves smoothly with the
/// position, as the deflection of a smooth surface does; one position in
/// about 30 scatters (a wider, dimmer spot, as on a bubble); every cell gets
/// detector noise (Gaussian, clipped at zero counts).
pub fn synthetic_scan(j1: usize, j2: usize, rows: usize, cols: usize, seed: u64) -> SampleScan {
    let n = j1 * j2;
    let mut counts = Vec::with_capacity(rows * cols * n);
    for r in 0..rows {
        for c in 0..cols {
            let key = mix(seed ^ mix(((r as u64) << 32) | c as u64));
            let (rf, cf) = (r as f64, c as f64);
            let cy = (j1 as f64 - 1.0) * (0.5 + 0.2 * (0.11 * cf + 0.07 * rf).sin());
            let cx = (j2 as f64 - 1.0) * (0.5 + 0.2 * (0.09 * cf - 0.05 * rf).cos());
            let scatter = key.is_multiple_of(30);
            let (sigma, peak) = if scatter {
                (2.5, 4_000.0)
            } else {
                (0.9, 30_000.0)
            };
            for i in 0..n {
                let (y, x) = ((i / j2) as f64, (i % j2) as f64);
                let d2 = (y - cy).powi(2) + (x - cx).powi(2);
                let (g, _) = gaussian_pair(mix(key ^ (i as u64 + 1)));
                let v = peak * (-d2 / (2.0 * sigma * sigma)).exp() + 2.0 + 3.0 * g;
                counts.push(v.round().clamp(0.0, 65535.0) as u16);
            }
        }
    }
    let values = counts.iter().map(|&a| a as f64).collect();
    SampleScan {
        j1,
        j2,
        rows,
        cols,
        counts,
        values,
    }
}

/// What one pass of an implementation over a scan produced.
pub enum Output {
    /// `[g0, g1]` per position, distance units.
    Gradient(Vec<[f64; 2]>),
    /// Integer scores of the core's scorer.
    Scores(Vec<PositionScore>),
    /// The pipeline's result lines.
    Lines(Vec<u8>),
}

/// Eq. 1 with the border rule: every map prepared once, then two distances
/// per position.
fn gradient_f64<P>(
    scan: &SampleScan,
    prepare: impl Fn(&[f64]) -> P,
    distance: impl Fn(&P, &P) -> f64,
) -> Vec<[f64; 2]> {
    let (rows, cols) = (scan.rows, scan.cols);
    let mut prepared = Vec::with_capacity(rows * cols);
    for r in 0..rows {
        for c in 0..cols {
            prepared.push(prepare(scan.map(r, c)));
        }
    }
    let at = |r: usize, c: usize| &prepared[r * cols + c];
    let mut out = Vec::with_capacity(rows * cols);
    for r in 0..rows {
        for c in 0..cols {
            let g0 = distance(at(r, c.saturating_sub(1)), at(r, (c + 1).min(cols - 1)));
            let g1 = distance(at(r.saturating_sub(1), c), at((r + 1).min(rows - 1), c));
            out.push([g0, g1]);
        }
    }
    out
}

/// Everything the implementations need for one configuration, built once.
pub struct Kernels {
    config: CvmConfig,
    geometry: Geometry,
    list: Vec<Kernel>,
    embedding: CvmEmbedding,
    emd: Emd,
    scorer: Scorer,
}

impl Kernels {
    pub fn new(scoring: &ScoringArgs, j1: usize, j2: usize) -> Result<Self> {
        let config = scoring.reference_config(j1, j2)?;
        let scorer = scoring.scorer(j1, j2)?;
        let geometry = config.geometry();
        Ok(Kernels {
            list: config.kernels(),
            embedding: CvmEmbedding::new(&config),
            emd: Emd::new(geometry, Ground::Euclid),
            geometry,
            config,
            scorer,
        })
    }

    pub fn scorer(&self) -> &Scorer {
        &self.scorer
    }

    /// The map the LCDs are taken of, as the configuration says.
    fn lcd_input(&self, raw: &[f64]) -> Vec<f64> {
        if self.config.normalises() {
            cvm_reference::normalise(raw).map
        } else {
            raw.to_vec()
        }
    }

    /// Eq. 9 with every LCD read from the two maps' tables.
    fn sat_distance(&self, t1: &SummedAreaTable, t2: &SummedAreaTable) -> f64 {
        let mut d = 0.0;
        for j1 in 1..=self.geometry.j1() {
            for j2 in 1..=self.geometry.j2() {
                for k in &self.list {
                    let diff = t1.lcd((j1, j2), (k.b1, k.b2)) - t2.lcd((j1, j2), (k.b1, k.b2));
                    d += k.w * diff * diff;
                }
            }
        }
        d
    }

    /// One pass of `imp` over `scan`. `scores` asks the pipeline for
    /// per-position score lines (for checking; the timed runs leave them
    /// off, as a scanner in production does).
    pub fn run(&self, imp: Implementation, scan: &SampleScan, scores: bool) -> Result<Output> {
        if (scan.j1, scan.j2) != (self.geometry.j1(), self.geometry.j2()) {
            bail!("scan geometry does not match the kernels");
        }
        Ok(match imp {
            Implementation::Brute => Output::Gradient(gradient_f64(
                scan,
                |m| m.to_vec(),
                |a, b| cvm_reference::cvm_brute(&self.config, a, b),
            )),
            Implementation::Sat => Output::Gradient(gradient_f64(
                scan,
                |m| SummedAreaTable::new(self.geometry, &self.lcd_input(m)),
                |a, b| self.sat_distance(a, b),
            )),
            Implementation::EmbedF64 => Output::Gradient(gradient_f64(
                scan,
                |m| self.embedding.embed(m),
                |a, b| self.embedding.distance(a, b),
            )),
            Implementation::Emd => Output::Gradient(gradient_f64(
                scan,
                |m| self.emd.prepare(m),
                |a, b| self.emd.distance(a, b),
            )),
            Implementation::FixedBatch => Output::Scores(crate::fixed::score_scan(
                &self.scorer,
                scan.rows,
                scan.cols,
                &scan.counts,
            )),
            Implementation::Fixed => Output::Lines(self.pipeline(scan, scores)?),
        })
    }

    /// The firmware's pipeline over the scan, beam by beam.
    fn pipeline(&self, scan: &SampleScan, scores: bool) -> Result<Vec<u8>> {
        if scan.cols > MAX_COLS {
            bail!("bench scans have at most {MAX_COLS} columns");
        }
        let settings = Settings {
            cols: scan.cols as u32,
            threshold: self.scorer.threshold_from_units(DEFAULT_THRESHOLD),
            power_threshold: cvm_core::power::threshold_from_units(DEFAULT_POWER_THRESHOLD),
            scores,
            max_defect_lines_per_row: 16,
            firmware_version: cvm_core::VERSION,
            reset_cause: cvm_core::protocol::ResetCause::PowerOn,
            boots: 1,
        };
        let n = scan.cells();
        let words = cvm_core::stream::row_words_for(scan.cols, self.scorer.config());
        let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
        let mut pipeline = Box::new(
            Pipeline::<MAX_COLS>::new(&self.scorer, settings, &mut a, &mut b)
                .map_err(|e| anyhow::anyhow!("pipeline refused the bench scan: {e}"))?,
        );
        let mut sink = VecSink::default();
        pipeline.begin(&mut sink);
        for (i, frame) in scan.counts.chunks_exact(n).enumerate() {
            let pos = Position {
                row: (i / scan.cols) as u32,
                col: (i % scan.cols) as u32,
            };
            pipeline.push(pos, frame, &mut sink);
        }
        pipeline.finish(0, &mut sink);
        Ok(sink.0)
    }

    /// Gradient magnitudes of an output, distance units, raster order.
    pub fn magnitudes(&self, out: &Output, scan: &SampleScan) -> Result<Vec<f64>> {
        Ok(match out {
            Output::Gradient(g) => g.iter().map(|[a, b]| a.hypot(*b)).collect(),
            Output::Scores(s) => s
                .iter()
                .map(|p| self.scorer.score_to_units(p.mag))
                .collect(),
            Output::Lines(lines) => {
                let dec = decode(&lines[..], 0)?;
                if !dec.errors.is_empty() {
                    bail!("pipeline output does not decode: {}", dec.errors[0]);
                }
                let [s] = dec.scans.as_slice() else {
                    bail!("pipeline output holds {} scans, not 1", dec.scans.len());
                };
                let img = s.image();
                if img.len() != scan.maps() * 3 {
                    bail!("pipeline output covers {} positions", img.len() / 3);
                }
                img.chunks_exact(3).map(|p| p[2]).collect()
            }
        })
    }
}

/// How far each implementation is from the f64 embedding on a sample, and
/// how far the EMD is from the independent min-cost-flow solver.
#[derive(Clone, Debug)]
pub struct Agreement {
    /// `(implementation, largest |difference| of a magnitude, allowed)`.
    pub deviations: Vec<(Implementation, f64, f64)>,
    /// Largest magnitude of the sample (CVM).
    pub max_magnitude: f64,
}

impl Agreement {
    pub fn ok(&self) -> bool {
        self.deviations.iter().all(|(_, d, tol)| d <= tol)
    }
}

/// Runs every implementation on `scan` and compares their gradient
/// magnitudes: the f64 CVM implementations with each other to 1e-9 of the
/// largest magnitude, the fixed-point ones within the core's stated accuracy
/// (`1e-5 M` plus score steps, README "Fixed point"), and EMD with the
/// reference crate's independent solver.
pub fn agreement(kernels: &Kernels, scan: &SampleScan) -> Result<Agreement> {
    let reference =
        kernels.magnitudes(&kernels.run(Implementation::EmbedF64, scan, true)?, scan)?;
    let m = reference.iter().fold(0.0f64, |a, &b| a.max(b));
    if m <= 0.0 || !m.is_finite() {
        bail!("the bench scan has no gradient to compare (largest magnitude {m})");
    }
    let step = (-(kernels.scorer.score_frac_bits() as f64)).exp2();
    let worst = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| {
                if x.is_nan() || y.is_nan() {
                    f64::INFINITY
                } else {
                    (x - y).abs()
                }
            })
            .fold(0.0f64, f64::max)
    };
    let mut deviations = Vec::new();
    for imp in IMPLEMENTATIONS {
        let tol = match imp {
            Implementation::EmbedF64 | Implementation::Emd => continue,
            Implementation::Brute | Implementation::Sat => 1e-9 * m,
            Implementation::Fixed | Implementation::FixedBatch => 1e-5 * m + 3.0 * step,
        };
        let got = kernels.magnitudes(&kernels.run(imp, scan, true)?, scan)?;
        deviations.push((imp, worst(&got, &reference), tol));
    }
    let emd = kernels.magnitudes(&kernels.run(Implementation::Emd, scan, true)?, scan)?;
    let independent = gradient_f64(
        scan,
        |m| kernels.emd.prepare(m),
        |a, b| kernels.emd.distance_independent(a, b),
    );
    let independent: Vec<f64> = independent.iter().map(|[a, b]| a.hypot(*b)).collect();
    let emd_max = independent.iter().fold(0.0f64, |a, &b| a.max(b));
    deviations.push((
        Implementation::Emd,
        worst(&emd, &independent),
        1e-9 * emd_max.max(1.0),
    ));
    Ok(Agreement {
        deviations,
        max_magnitude: m,
    })
}

/// One implementation's figure.
#[derive(Clone, Debug)]
pub struct Measurement {
    pub implementation: Implementation,
    /// Median over the timed runs.
    pub maps_per_s: f64,
    /// Scan shape of a run and how many times a run scores it.
    pub rows: usize,
    pub cols: usize,
    pub repeats: usize,
    pub runs: usize,
    /// Slowest and fastest run, maps per second.
    pub min: f64,
    pub max: f64,
}

fn timed(mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    let t = Instant::now();
    f()?;
    Ok(t.elapsed().as_secs_f64())
}

/// Calibrates a scan size for `imp` from a 2x2 probe, warms up on the scan
/// that will be timed, then reports the median of [`RUNS`] timed runs.
pub fn measure(kernels: &Kernels, imp: Implementation, budget: Duration) -> Result<Measurement> {
    let (j1, j2) = (kernels.geometry.j1(), kernels.geometry.j2());
    let probe = synthetic_scan(j1, j2, 2, 2, SEED);
    let pass = |scan: &SampleScan| -> Result<()> {
        black_box(kernels.run(imp, black_box(scan), false)?);
        Ok(())
    };
    pass(&probe)?;
    let per_map = (timed(|| pass(&probe))? / 4.0).max(1e-9);
    // Warm-up and calibration take about a sixth of the budget.
    let per_run = budget.as_secs_f64() * 5.0 / 6.0 / (RUNS + 1) as f64;
    let wanted = (per_run / per_map).max(4.0) as usize;
    let rows = (wanted / MAX_COLS).clamp(2, MAX_ROWS);
    let cols = (wanted / rows).clamp(2, MAX_COLS);
    let repeats = (wanted / (rows * cols)).clamp(1, 100_000);
    let scan = synthetic_scan(j1, j2, rows, cols, SEED);
    let maps = (scan.maps() * repeats) as f64;
    // As many timed runs as the budget holds, one at least.
    let one_run = per_map * (scan.maps() * repeats) as f64;
    let runs = ((per_run * RUNS as f64 / one_run) as usize).clamp(1, RUNS);
    let mut rates = Vec::with_capacity(runs);
    for i in 0..=runs {
        let t = timed(|| {
            for _ in 0..repeats {
                pass(&scan)?;
            }
            Ok(())
        })?;
        if i > 0 || runs == 1 {
            rates.push(maps / t.max(1e-12));
        }
        if runs == 1 {
            break;
        }
    }
    rates.sort_by(f64::total_cmp);
    Ok(Measurement {
        implementation: imp,
        maps_per_s: rates[rates.len() / 2],
        rows,
        cols,
        repeats,
        runs: rates.len(),
        min: rates[0],
        max: rates[rates.len() - 1],
    })
}

/// The machine: logical CPUs and the CPU model.
pub fn machine() -> (usize, String) {
    let nproc = std::thread::available_parallelism().map_or(1, |n| n.get());
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".to_string());
    (nproc, model)
}

/// Speed targets (issue "Benchmarks and speed targets"): paper kernels,
/// uniform weights, normalised 15x15 maps.
pub const TARGET_RATIO: f64 = 50.0;
pub const TARGET_FIXED: f64 = 300_000.0;

fn targets_apply(args: &BenchArgs) -> bool {
    args.geometry == (15, 15)
        && args
            .scoring
            .core_config(15, 15)
            .ok()
            .is_some_and(|c| c == cvm_core::Config::paper(c.geometry))
}

/// Everything a bench run found.
pub struct Report {
    pub geometry: (usize, usize),
    pub measurements: Vec<Measurement>,
    pub agreement: Agreement,
    pub targets_apply: bool,
}

impl Report {
    pub fn rate(&self, imp: Implementation) -> f64 {
        self.measurements
            .iter()
            .find(|m| m.implementation == imp)
            .map_or(f64::NAN, |m| m.maps_per_s)
    }

    fn ratio(&self) -> f64 {
        self.rate(Implementation::Fixed) / self.rate(Implementation::Sat)
    }

    fn verdicts(&self) -> Option<(bool, bool)> {
        self.targets_apply.then(|| {
            (
                self.ratio() >= TARGET_RATIO,
                self.rate(Implementation::Fixed) >= TARGET_FIXED,
            )
        })
    }

    pub fn json(&self, args: &BenchArgs) -> serde_json::Value {
        use serde_json::{Map, Value, json};
        let mut rates = Map::new();
        let mut samples = Map::new();
        for m in &self.measurements {
            rates.insert(m.implementation.key().into(), json!(m.maps_per_s));
            samples.insert(
                m.implementation.key().into(),
                json!({"rows": m.rows, "cols": m.cols, "repeats": m.repeats, "runs": m.runs,
                       "min_maps_per_s": m.min, "max_maps_per_s": m.max}),
            );
        }
        let agreement: Map<String, Value> = self
            .agreement
            .deviations
            .iter()
            .map(|(imp, d, tol)| {
                (
                    imp.key().to_string(),
                    json!({"max_abs_diff": d, "allowed": tol}),
                )
            })
            .collect();
        let (nproc, cpu) = machine();
        let targets = match self.verdicts() {
            Some((ratio_ok, rate_ok)) => json!({
                "fixed_over_sat_min": TARGET_RATIO, "fixed_min_maps_per_s": TARGET_FIXED,
                "fixed_over_sat_pass": ratio_ok, "fixed_rate_pass": rate_ok}),
            None => Value::Null,
        };
        let c = &args.scoring;
        json!({
            "geometry": format!("{}x{}", self.geometry.0, self.geometry.1),
            "maps_per_s": rates,
            "fixed_over_sat": self.ratio(),
            "targets": targets,
            "config": {"kernels": format!("{:?}", c.kernels).to_lowercase(),
                       "weights": c.weights.map(|w| format!("{w:?}").to_lowercase()),
                       "bmax": c.bmax, "raw": c.raw},
            "agreement": agreement,
            "samples": samples,
            "threads": 1,
            "machine": {"nproc": nproc, "cpu": cpu},
        })
    }

    pub fn text(&self) -> String {
        use std::fmt::Write;
        let (nproc, cpu) = machine();
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{}x{} maps, one thread, {cpu} ({nproc} logical CPUs); median of up to {RUNS} runs",
            self.geometry.0, self.geometry.1
        );
        let _ = writeln!(
            s,
            "{:<46} {:>12} {:>11} {:>15}",
            "implementation", "maps/s", "us/map", "scan x repeats"
        );
        for m in &self.measurements {
            let _ = writeln!(
                s,
                "{:<46} {:>12.0} {:>11.3} {:>15}",
                format!("{} ({})", m.implementation.label(), m.implementation.key()),
                m.maps_per_s,
                1e6 / m.maps_per_s,
                format!("{}x{} x{}", m.rows, m.cols, m.repeats)
            );
        }
        let _ = writeln!(s, "fixed / sat: {:.1}x", self.ratio());
        match self.verdicts() {
            Some((ratio_ok, rate_ok)) => {
                let pf = |b: bool| if b { "PASS" } else { "FAIL" };
                let _ = writeln!(s, "target fixed >= {TARGET_RATIO}x sat: {}", pf(ratio_ok));
                let _ = writeln!(
                    s,
                    "target fixed >= {TARGET_FIXED:.0} maps/s: {}",
                    pf(rate_ok)
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "targets (>= {TARGET_RATIO}x sat, >= {TARGET_FIXED:.0} maps/s) apply to 15x15, paper kernels, uniform weights"
                );
            }
        }
        s
    }
}

/// Checks, then times every implementation within `args.seconds`.
pub fn bench(args: &BenchArgs) -> Result<Report> {
    if !(args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= 3600.0) {
        bail!("--seconds must be in (0, 3600], got {}", args.seconds);
    }
    let (j1, j2) = args.geometry;
    // A configuration blind to an axis scores the bench maps (nearly) 0,
    // and there is nothing to compare or time.
    if let Some(w) = args.scoring.warnings(j1, j2)?.first() {
        bail!("--geometry {j1}x{j2}: {w}; nothing to benchmark");
    }
    let kernels = Kernels::new(&args.scoring, j1, j2)?;
    // The top-left block of every timed scan (at least 2x2 positions).
    let sample = synthetic_scan(j1, j2, 2, 3, SEED);
    let agreement = agreement(&kernels, &sample).context("checking the implementations")?;
    if !agreement.ok() {
        let (imp, d, tol) = agreement
            .deviations
            .iter()
            .find(|(_, d, tol)| d > tol)
            .copied()
            .unwrap_or((Implementation::Brute, 0.0, 0.0));
        bail!(
            "{} disagrees with the reference on the bench sample (difference {d:e}, allowed {tol:e}); not timing it",
            imp.key()
        );
    }
    let budget = Duration::from_secs_f64(args.seconds / IMPLEMENTATIONS.len() as f64);
    let measurements = IMPLEMENTATIONS
        .iter()
        .map(|&imp| measure(&kernels, imp, budget))
        .collect::<Result<Vec<_>>>()?;
    Ok(Report {
        geometry: args.geometry,
        measurements,
        agreement,
        targets_apply: targets_apply(args),
    })
}

pub fn run(args: &BenchArgs) -> Result<()> {
    let start = Instant::now();
    let report = bench(args)?;
    let took = start.elapsed().as_secs_f64();
    // The smallest timed run of each implementation, and the check before
    // them, cost what they cost: say so when that exceeds the budget.
    if took > 1.5 * args.seconds + 0.5 {
        crate::out::warn(&format!(
            "the run took {took:.1} s, more than --seconds {}: the check of the implementations and one run of each on the smallest scan take that long here",
            crate::stream::fmt_num(args.seconds)
        ));
    }
    if args.json {
        crate::out::stdout(format!("{}\n", report.json(args)).as_bytes())
    } else {
        crate::out::stdout(report.text().as_bytes())
    }
}
