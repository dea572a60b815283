//! Timing one implementation: a scan sized to the budget, a warm-up, the
//! median of the timed runs.

use anyhow::Result;
use std::hint::black_box;
use std::time::{Duration, Instant};

use crate::bench::kernels::{Implementation, Kernels, MAX_COLS};
use crate::bench::scan::{SEED, SampleScan, synthetic_scan};

/// Largest scan a timed run uses; faster implementations repeat it.
const MAX_ROWS: usize = 32;
/// Timed runs per implementation (the median is reported).
pub const RUNS: usize = 5;

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
    let (j1, j2) = kernels.geometry();
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
