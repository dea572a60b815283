//! The implementations of the gradient that `dmap bench` times, one
//! configuration's worth of tables built once, and the check that they
//! agree before any is timed.

use anyhow::{Result, bail};
use cvm_core::{Pipeline, Position, PositionScore, Scorer};
use cvm_reference::{CvmConfig, CvmEmbedding, Emd, Geometry, Ground, Kernel, SummedAreaTable};

use crate::bench::scan::SampleScan;
use crate::listen::decode;
use crate::options::{OutputArgs, ScoringArgs};
use crate::stream::VecSink;

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

/// Most columns of a bench scan: the pipeline's capacity here, and the
/// width of the largest timed scan.
pub const MAX_COLS: usize = 128;

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

    pub(super) fn label(self) -> &'static str {
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

    /// The detector geometry `(J1, J2)`.
    pub fn geometry(&self) -> (usize, usize) {
        (self.geometry.j1(), self.geometry.j2())
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
        // The default thresholds, as `dmap stream` would run it.
        let settings = OutputArgs {
            scores,
            max_defect_lines: 16,
            ..OutputArgs::default()
        }
        .settings(&self.scorer, (scan.rows, scan.cols))?;
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
