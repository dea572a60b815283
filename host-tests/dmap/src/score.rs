//! `dmap score`: the gradient image (Eq. 1) of a scan under one of the
//! distances, exact in f64 (or the firmware's fixed point, `cvm-fixed`).

use crate::npy::{GradientWriter, ScanFile, band_rows};
use crate::options::ScoringArgs;
use crate::out::Target;
use crate::settings::{blind_axes, flat_scan_warnings};
use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use cvm_reference::{CvmEmbedding, Emd, Ground, MapDistance, MeanDir};
use rayon::prelude::*;
use std::collections::VecDeque;
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
    /// Output gradient image .npy, float64 (rows, cols, 3); "-" for standard output
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

/// Map the scan, score it a band of rows at a time, write the gradient
/// image as the bands complete.
///
/// Memory: the scan is memory-mapped and read twice in file order (a check
/// of every sample, then the scoring), with the pages behind the current
/// band released; what is held is the band's prepared maps and gradient
/// (about 2^20 samples' worth, [`crate::npy::band_rows`]), whatever the
/// size of the scan.
pub fn run(args: &ScoreArgs) -> Result<()> {
    check_flags(args.distance, &args.scoring, args.ground)?;
    let target = Target::new(&args.output);
    if let Target::File(out) = &target {
        crate::out::refuse_inputs(out, &[&args.scan])?;
    }
    let scan = ScanFile::open(&args.scan)?;
    let scoring = Scoring::new(args.distance, &args.scoring, args.ground, &scan)?;
    scan.validate(scoring.counts())?;
    crate::out::write_target(&target, |out| {
        let mut w = GradientWriter::new(out, target.name(), scan.rows, scan.cols)?;
        scoring.score(&scan, &mut |band| w.push(band))?;
        w.finish()
    })?;
    // After the result, so that a failed run says one thing only.
    for w in &scoring.warnings {
        crate::out::warn(w);
    }
    Ok(())
}

/// `dmap score` on a scan already opened (a file or memory), without a
/// file to write: the flags checked, every sample checked, then the
/// gradient image handed to `push` a band of rows at a time (`(rows, cols,
/// 3)` in C order, bands in order). Returns the warnings `dmap score`
/// prints after its output.
pub fn score_scan(
    scan: &ScanFile,
    distance: DistanceArg,
    scoring: &ScoringArgs,
    ground: Option<GroundArg>,
    push: &mut dyn FnMut(&[f64]) -> Result<()>,
) -> Result<Vec<String>> {
    check_flags(distance, scoring, ground)?;
    let s = Scoring::new(distance, scoring, ground, scan)?;
    scan.validate(s.counts())?;
    s.score(scan, push)?;
    Ok(s.warnings)
}

/// A distance ready to score a scan, and what the user should know.
pub struct Scoring {
    method: Method,
    /// The configuration's and the scan's shape's warnings.
    pub warnings: Vec<String>,
}

impl Scoring {
    /// The distance for `scan`'s geometry (the configuration is checked
    /// before the samples are).
    pub fn new(
        distance: DistanceArg,
        scoring: &ScoringArgs,
        ground: Option<GroundArg>,
        scan: &ScanFile,
    ) -> Result<Self> {
        let (j1, j2) = (scan.geometry.j1(), scan.geometry.j2());
        let method = match distance {
            DistanceArg::Cvm => Method::Cvm(CvmEmbedding::new(&scoring.reference_config(j1, j2)?)),
            DistanceArg::CvmFixed => Method::Fixed(scoring.scorer(j1, j2)?),
            DistanceArg::Emd => {
                let ground = match ground.unwrap_or(GroundArg::Euclid) {
                    GroundArg::Euclid => Ground::Euclid,
                    GroundArg::L1 => Ground::L1,
                };
                Method::Emd(Emd::new(cvm_reference::Geometry::new(j1, j2)?, ground))
            }
            DistanceArg::MeanDir => Method::MeanDir(MeanDir(cvm_reference::Geometry::new(j1, j2)?)),
        };
        let mut warnings = match &method {
            Method::Cvm(_) | Method::Fixed(_) => scoring.warnings(j1, j2)?,
            Method::Emd(d) => blind_axes(j1, j2, |a, b| d.distance(&d.prepare(a), &d.prepare(b))),
            Method::MeanDir(d) => {
                blind_axes(j1, j2, |a, b| d.distance(&d.prepare(a), &d.prepare(b)))
            }
        };
        warnings.extend(flat_scan_warnings(scan.rows, scan.cols));
        Ok(Scoring { method, warnings })
    }

    /// Whether the samples must be counts (`cvm-fixed`, the firmware's input).
    pub fn counts(&self) -> bool {
        matches!(self.method, Method::Fixed(_))
    }

    /// Scores `scan` (samples already checked), handing the gradient image
    /// to `push` a band of rows at a time.
    pub fn score(&self, scan: &ScanFile, push: &mut dyn FnMut(&[f64]) -> Result<()>) -> Result<()> {
        match &self.method {
            Method::Cvm(d) => banded(scan, &Prepare(d), push),
            Method::Fixed(s) => banded(scan, &FixedPrepare(s), push),
            Method::Emd(d) => banded(scan, &Prepare(d), push),
            Method::MeanDir(d) => banded(scan, &Prepare(d), push),
        }
    }
}

/// The distance a run scores with (one per run: the size of the largest
/// variant does not matter).
#[allow(clippy::large_enum_variant)]
enum Method {
    Cvm(CvmEmbedding),
    Fixed(cvm_core::Scorer),
    Emd(Emd),
    MeanDir(MeanDir),
}

/// One band-at-a-time way of scoring: per-map preparation of a row, and the
/// gradient of a position from its four neighbours' prepared maps.
trait Banded: Sync {
    type Prepared: Send + Sync;
    fn prepare_row(&self, scan: &ScanFile<'_>, row: usize) -> Result<Vec<Self::Prepared>>;
    fn gradient(
        &self,
        left: &Self::Prepared,
        right: &Self::Prepared,
        up: &Self::Prepared,
        down: &Self::Prepared,
    ) -> [f64; 3];
}

/// An f64 distance of the reference crate.
struct Prepare<'a, D>(&'a D);

impl<D> Banded for Prepare<'_, D>
where
    D: MapDistance + Sync,
    D::Prepared: Send + Sync,
{
    type Prepared = D::Prepared;
    fn prepare_row(&self, scan: &ScanFile<'_>, row: usize) -> Result<Vec<D::Prepared>> {
        let n = scan.geometry.cells();
        let mut samples = vec![0.0; scan.cols * n];
        scan.maps_f64(row * scan.cols, &mut samples)?;
        Ok(samples.par_chunks(n).map(|m| self.0.prepare(m)).collect())
    }
    fn gradient(
        &self,
        l: &D::Prepared,
        r: &D::Prepared,
        u: &D::Prepared,
        d: &D::Prepared,
    ) -> [f64; 3] {
        let g0 = self.0.distance(l, r);
        let g1 = self.0.distance(u, d);
        [g0, g1, (g0 * g0 + g1 * g1).sqrt()]
    }
}

/// The firmware's fixed point (`cvm-fixed`): the core's scorer, the same
/// per-position arithmetic as [`crate::fixed::score_scan`].
struct FixedPrepare<'a>(&'a cvm_core::Scorer);

impl Banded for FixedPrepare<'_> {
    type Prepared = Vec<i32>;
    fn prepare_row(&self, scan: &ScanFile<'_>, row: usize) -> Result<Vec<Vec<i32>>> {
        let n = scan.geometry.cells();
        let mut counts = vec![0u16; scan.cols * n];
        scan.maps_u16(row * scan.cols, &mut counts, &mut Vec::new())?;
        Ok(counts
            .par_chunks(n)
            .map_init(cvm_core::scorer::Scratch::new, |scratch, frame| {
                let mut state = vec![0i32; self.0.state_words()];
                // The length is the scorer's: the scan's geometry made it.
                let _ = self.0.prepare_with(frame, &mut state, scratch);
                state
            })
            .collect())
    }
    fn gradient(&self, l: &Vec<i32>, r: &Vec<i32>, u: &Vec<i32>, d: &Vec<i32>) -> [f64; 3] {
        // A missing neighbour at the border is the map itself; d(a, a) = 0.
        let g0 = if std::ptr::eq(l, r) {
            0
        } else {
            self.0.distance(l, r)
        };
        let g1 = if std::ptr::eq(u, d) {
            0
        } else {
            self.0.distance(u, d)
        };
        let mag = cvm_core::magnitude(g0, g1);
        [g0, g1, mag].map(|s| self.0.score_to_units(s))
    }
}

/// Eq. 1 with the border rule (a missing neighbour is the map itself), a
/// band of rows at a time: each map prepared once, held while a row next to
/// it is scored, then dropped.
fn banded<B: Banded>(
    scan: &ScanFile<'_>,
    b: &B,
    push: &mut dyn FnMut(&[f64]) -> Result<()>,
) -> Result<()> {
    let (rows, cols) = (scan.rows, scan.cols);
    let band = band_rows(cols, scan.geometry.cells());
    let mut window: VecDeque<Vec<B::Prepared>> = VecDeque::new();
    let mut first = 0;
    let mut out = Vec::new();
    for r0 in (0..rows).step_by(band) {
        let r1 = (r0 + band).min(rows);
        let (lo, hi) = (r0.saturating_sub(1), r1.min(rows - 1));
        while first < lo {
            window.pop_front();
            first += 1;
        }
        while first + window.len() <= hi {
            window.push_back(b.prepare_row(scan, first + window.len())?);
        }
        let at = |r: usize, c: usize| &window[r - first][c];
        out.clear();
        out.resize((r1 - r0) * cols * 3, 0.0);
        out.par_chunks_mut(3).enumerate().for_each(|(i, px)| {
            let (r, c) = (r0 + i / cols, i % cols);
            px.copy_from_slice(&b.gradient(
                at(r, c.saturating_sub(1)),
                at(r, (c + 1).min(cols - 1)),
                at(r.saturating_sub(1), c),
                at((r + 1).min(rows - 1), c),
            ));
        });
        if let Some(i) = out.iter().position(|x| !x.is_finite()) {
            bail!(
                "internal error: non-finite score at position ({}, {})",
                r0 + i / 3 / cols,
                i / 3 % cols
            );
        }
        push(&out)?;
    }
    Ok(())
}
/// Flags that only mean something for some distances are refused elsewhere,
/// so that nobody believes they changed a result.
pub fn check_flags(
    distance: DistanceArg,
    s: &ScoringArgs,
    ground: Option<GroundArg>,
) -> Result<()> {
    let cvm = matches!(distance, DistanceArg::Cvm | DistanceArg::CvmFixed);
    if ground.is_some() && distance != DistanceArg::Emd {
        bail!("--ground applies only to --distance emd");
    }
    if !cvm {
        let name = match distance {
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
