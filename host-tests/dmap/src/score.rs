//! `dmap score`: the gradient image (Eq. 1) of a scan under one of the
//! distances, exact in f64 (or the firmware's fixed point, `cvm-fixed`).

use crate::npy::{Scan, read_scan, write_gradient};
use crate::options::ScoringArgs;
use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use cvm_reference::{CvmEmbedding, Emd, Ground, MapDistance, MeanDir};
use rayon::prelude::*;
use std::path::PathBuf;

/// Distance between neighbouring deflection maps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum DistanceArg {
    /// Generalised Cramér-von Mises distance, exact f64 (per-map embedding)
    Cvm,
    /// The same in the firmware's fixed point, converted to f64 units
    CvmFixed,
    /// Exact earth mover's distance between the normalised maps
    Emd,
    /// Distance of the mean deflection directions
    MeanDir,
}

/// Ground distance between detector cells for `--distance emd`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum GroundArg {
    /// Euclidean distance between cell centres (cell units)
    Euclid,
    /// City-block distance between cell centres
    L1,
}

#[derive(Args, Clone, Debug)]
pub struct ScoreArgs {
    /// Scan .npy, shape (rows, cols, J1, J2)
    pub scan: PathBuf,
    /// Output gradient image .npy, float64 (rows, cols, 3)
    #[arg(short, long, value_name = "OUT.npy")]
    pub output: PathBuf,
    /// Distance between neighbouring maps
    #[arg(long, value_enum, default_value = "cvm")]
    pub distance: DistanceArg,
    #[command(flatten)]
    pub scoring: ScoringArgs,
    /// Ground distance for --distance emd (default euclid)
    #[arg(long, value_enum)]
    pub ground: Option<GroundArg>,
}

/// Read the scan, score it, write the gradient image.
pub fn run(args: &ScoreArgs) -> Result<()> {
    check_flags(args)?;
    let scan = read_scan(&args.scan)?;
    let image = score(&scan, args)?;
    write_gradient(&args.output, scan.rows, scan.cols, &image)
}

/// Flags that only mean something for some distances are refused elsewhere,
/// so that nobody believes they changed a result.
fn check_flags(args: &ScoreArgs) -> Result<()> {
    let cvm = matches!(args.distance, DistanceArg::Cvm | DistanceArg::CvmFixed);
    if args.ground.is_some() && args.distance != DistanceArg::Emd {
        bail!("--ground applies only to --distance emd");
    }
    if !cvm {
        let s = &args.scoring;
        let name = match args.distance {
            DistanceArg::Emd => "emd",
            _ => "mean-dir",
        };
        if s.raw {
            bail!("--raw applies only to the CVM distances: {name} compares normalised maps");
        }
        if s.weights.is_some() || s.bmax.is_some() || s.kernels != crate::options::KernelArg::Paper
        {
            bail!("--kernels, --weights and --bmax apply only to the CVM distances, not {name}");
        }
    }
    Ok(())
}

/// The gradient image of `scan`: `rows * cols * 3` values
/// `[g0, g1, magnitude]`, row-major.
pub fn score(scan: &Scan, args: &ScoreArgs) -> Result<Vec<f64>> {
    let g = scan.geometry;
    let image = match args.distance {
        DistanceArg::Cvm => {
            let config = args.scoring.reference_config(g.j1(), g.j2())?;
            gradient(scan, &CvmEmbedding::new(&config))
        }
        // --- cvm-fixed: dispatch to the fixed-point scorer (dmap::fixed) ---
        DistanceArg::CvmFixed => {
            let scorer = args.scoring.scorer(g.j1(), g.j2())?;
            let data = scan.to_u16()?;
            let scores = crate::fixed::score_scan(&scorer, scan.rows, scan.cols, &data);
            crate::fixed::to_image(&scorer, &scores)
        }
        // --- end cvm-fixed ---
        DistanceArg::Emd => {
            let ground = match args.ground.unwrap_or(GroundArg::Euclid) {
                GroundArg::Euclid => Ground::Euclid,
                GroundArg::L1 => Ground::L1,
            };
            gradient(scan, &Emd::new(g, ground))
        }
        DistanceArg::MeanDir => gradient(scan, &MeanDir(g)),
    };
    if let Some(i) = image.iter().position(|x| !x.is_finite()) {
        bail!(
            "internal error: non-finite score at position ({}, {})",
            i / 3 / scan.cols,
            i / 3 % scan.cols
        );
    }
    Ok(image)
}

/// Eq. 1 with the border rule (a missing neighbour is the map itself):
/// every map prepared once, rows scored in parallel.
fn gradient<D>(scan: &Scan, distance: &D) -> Vec<f64>
where
    D: MapDistance + Sync,
    D::Prepared: Send + Sync,
{
    let (rows, cols) = (scan.rows, scan.cols);
    let prepared: Vec<D::Prepared> = scan
        .data
        .par_chunks(scan.geometry.cells())
        .map(|m| distance.prepare(m))
        .collect();
    let at = |r: usize, c: usize| &prepared[r * cols + c];
    let mut image = vec![0.0; rows * cols * 3];
    image
        .par_chunks_mut(cols * 3)
        .enumerate()
        .for_each(|(r, line)| {
            for c in 0..cols {
                let left = at(r, c.saturating_sub(1));
                let right = at(r, (c + 1).min(cols - 1));
                let up = at(r.saturating_sub(1), c);
                let down = at((r + 1).min(rows - 1), c);
                let g0 = distance.distance(left, right);
                let g1 = distance.distance(up, down);
                line[c * 3..c * 3 + 3].copy_from_slice(&[g0, g1, (g0 * g0 + g1 * g1).sqrt()]);
            }
        });
    image
}
