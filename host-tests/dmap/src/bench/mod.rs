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

mod kernels;
mod measure;
mod report;
mod scan;

use anyhow::{Context, Result, bail};
use clap::Args;
use std::time::{Duration, Instant};

use crate::options::ScoringArgs;

pub use kernels::{Agreement, IMPLEMENTATIONS, Implementation, Kernels, Output, agreement};
pub use measure::{Measurement, machine, measure};
pub use report::{Report, TARGET_FIXED, TARGET_RATIO};
pub use scan::{SEED, SampleScan, synthetic_scan};

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
        targets_apply: report::targets_apply(args.geometry, &args.scoring),
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
            crate::fmt::fmt_num(args.seconds)
        ));
    }
    if args.json {
        crate::out::stdout(format!("{}\n", report.json(&args.scoring)).as_bytes())
    } else {
        crate::out::stdout(report.text().as_bytes())
    }
}
