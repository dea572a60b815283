//! Exact EMD of map pairs, timed: the Rust side of `scripts/measure.sh emd-vs-pot`.
//!
//! Input: a scan-layout `.npy` of shape `(pairs, 2, J1, J2)` (position
//! `(p, 0)` and `(p, 1)` are the two maps of pair `p`). Output: a float64
//! `.npy` of shape `(pairs, 1, 3)` whose first value per pair is the EMD
//! (Euclidean ground distance, normalised maps); the timing goes to stdout.
//!
//! Usage: `cargo run --release -p dmap --example emd_pairs -- PAIRS.npy OUT.npy`

use anyhow::{Context, Result, bail};
use cvm_reference::{Emd, Ground};
use std::path::Path;
use std::time::Instant;

fn main() {
    if let Err(e) = run() {
        eprintln!("emd_pairs: error: {e:#}");
        std::process::exit(1);
    }
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, output] = args.as_slice() else {
        bail!("usage: emd_pairs PAIRS.npy OUT.npy");
    };
    let scan = dmap::npy::read_scan(Path::new(input))?;
    if scan.cols != 2 {
        bail!(
            "{input}: expected shape (pairs, 2, J1, J2), got {} columns",
            scan.cols
        );
    }
    let emd = Emd::new(scan.geometry, Ground::Euclid);
    let prepared: Vec<_> = (0..scan.rows)
        .map(|p| (emd.prepare(scan.map(p, 0)), emd.prepare(scan.map(p, 1))))
        .collect();
    // Warm-up pass so that allocation and page faults do not land in the timing.
    for (a, b) in prepared.iter().take(10) {
        std::hint::black_box(emd.distance(a, b));
    }
    let start = Instant::now();
    let values: Vec<f64> = prepared.iter().map(|(a, b)| emd.distance(a, b)).collect();
    let seconds = start.elapsed().as_secs_f64();
    let image: Vec<f64> = values.iter().flat_map(|&v| [v, 0.0, 0.0]).collect();
    dmap::npy::write_gradient(Path::new(output), scan.rows, 1, &image)
        .with_context(|| format!("writing {output}"))?;
    println!(
        "rust exact EMD: {} pairs of {}x{} maps in {seconds:.4} s ({:.1} us per pair, one thread)",
        scan.rows,
        scan.geometry.j1(),
        scan.geometry.j2(),
        1e6 * seconds / scan.rows as f64
    );
    Ok(())
}
