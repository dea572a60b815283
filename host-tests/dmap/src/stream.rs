//! `dmap stream`: the firmware's pipeline (streaming engine and line
//! encoder, `cvm_core::Pipeline`) run on the host over a scan file, so that
//! host and firmware output can be compared byte for byte.

use crate::npy::ScanFile;
use crate::options::ScoringArgs;
use anyhow::{Result, bail};
use clap::Args;
use cvm_core::protocol::{LineSink, Priority};
use cvm_core::{Pipeline, Position, Scorer, Settings};
use std::path::PathBuf;

/// Most columns the host pipeline accepts (the engine's capacity is fixed
/// at compile time, as on the target).
pub const MAX_COLS: usize = 4096;

/// Default defect threshold, in distance units.
pub const DEFAULT_THRESHOLD: f64 = 0.5;
/// Default threshold of the power channel: a contrast of 0.1 between the
/// two neighbours' powers (one has 22 % more light than the other).
pub const DEFAULT_POWER_THRESHOLD: f64 = 0.1;

#[derive(Args, Clone, Debug)]
pub struct StreamArgs {
    /// Scan .npy, shape (rows, cols, J1, J2), integer counts 0..=65535
    pub scan: PathBuf,
    #[command(flatten)]
    pub scoring: ScoringArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// What the pipeline reports: shared by `stream` and `emulate`.
#[derive(Args, Clone, Debug, PartialEq)]
pub struct OutputArgs {
    /// Defect threshold on the gradient magnitude, in distance units (default 0.5 for
    /// normalised maps; required with --raw, whose distances are in counts)
    #[arg(long)]
    pub threshold: Option<f64>,
    /// Also emit every position's score (S lines)
    #[arg(long)]
    pub scores: bool,
    /// Threshold of the power channel: the contrast |P+ - P-| / (P+ + P-) of the two
    /// neighbours' powers (default 0.1; inf turns the channel off)
    #[arg(long, value_name = "C")]
    pub power_threshold: Option<f64>,
    /// List up to this many defective positions per row as D lines, the strongest (the row
    /// line has the full count; default 0: the object lines describe the defects)
    #[arg(long, default_value_t = 0)]
    pub max_defect_lines: u16,
    /// Both channels' thresholds from a calibration file (`dmap calibrate`), the same
    /// integers as the calibration's; refused unless these scoring options are the ones
    /// it was made for
    #[arg(long, value_name = "CAL.json", conflicts_with_all = ["threshold", "power_threshold"])]
    pub calibration: Option<PathBuf>,
    /// Full scale of the detector: a sample at or above it flags its map saturated
    /// (header `fs`; 4095 for a 12-bit ADC)
    #[arg(long, value_name = "N", default_value_t = u16::MAX,
          value_parser = clap::value_parser!(u16).range(1..))]
    pub full_scale: u16,
}

impl Default for OutputArgs {
    fn default() -> Self {
        OutputArgs {
            threshold: None,
            power_threshold: None,
            scores: false,
            max_defect_lines: 0,
            calibration: None,
            full_scale: u16::MAX,
        }
    }
}

impl OutputArgs {
    /// The threshold in distance units: the one given, or the default for
    /// normalised maps. Raw counts have no sensible default (their
    /// distances scale with the square of the counts), so `--raw` needs
    /// `--threshold`.
    pub fn threshold_units(&self, scoring: &ScoringArgs) -> Result<f64> {
        // `configure` has checked the calibration against the configuration.
        if let Some(path) = &self.calibration {
            return Ok(crate::calibrate::Calibration::load(path)?.threshold);
        }
        let t = match self.threshold {
            Some(t) => t,
            None if scoring.raw => bail!(
                "--raw compares raw counts, whose distances have no default scale: give --threshold (the default {DEFAULT_THRESHOLD} is for normalised maps)"
            ),
            None => DEFAULT_THRESHOLD,
        };
        if t.is_nan() || t < 0.0 {
            bail!(
                "--threshold must be a non-negative number, got {}",
                fmt_num(t)
            );
        }
        if t.is_infinite() {
            bail!("--threshold must be finite, got {t}");
        }
        Ok(t)
    }

    /// The power channel's threshold, a contrast: the calibration's (its
    /// `Q15` integer over `2^15`, which converts back to exactly that
    /// integer), the one given, or the default ([`f64::INFINITY`] turns the
    /// channel off).
    pub fn power_threshold_units(&self) -> Result<f64> {
        if let Some(path) = &self.calibration {
            return Ok(crate::calibrate::Calibration::load(path)?.power_threshold);
        }
        let t = self.power_threshold.unwrap_or(DEFAULT_POWER_THRESHOLD);
        if t.is_nan() || t < 0.0 {
            bail!(
                "--power-threshold must be a non-negative contrast (inf: off), got {}",
                fmt_num(t)
            );
        }
        Ok(t)
    }

    /// What the scorer makes of the threshold when it is not what was
    /// asked: above every score it can report, or rounded up by more than
    /// 1 % to its integer format.
    pub fn threshold_warnings(&self, scorer: &Scorer, units: f64) -> Vec<String> {
        let thr = scorer.threshold_from_units(units);
        let effective = scorer.score_to_units(thr);
        let step = scorer.score_to_units(1);
        let q = scorer.score_frac_bits();
        if thr == u32::MAX && units > effective {
            vec![format!(
                "--threshold {} is above the largest score the scorer reports ({} in its Q({q}) format): no position can be a defect",
                fmt_num(units),
                fmt_num(effective)
            )]
        } else if effective > units * 1.01 {
            vec![format!(
                "--threshold {} becomes {} in the scorer's Q({q}) format (one score step is {} distance units)",
                fmt_num(units),
                fmt_num(effective),
                fmt_num(step)
            )]
        } else {
            Vec::new()
        }
    }

    /// The pipeline's settings for a scan of `cols` columns, with the
    /// threshold given or the default ([`Self::threshold_units`] checks it).
    pub fn settings(&self, scorer: &Scorer, cols: usize) -> Result<Settings> {
        let t = self.threshold.unwrap_or(DEFAULT_THRESHOLD);
        if t.is_nan() || t < 0.0 || t.is_infinite() {
            bail!(
                "--threshold must be a finite non-negative number, got {}",
                fmt_num(t)
            );
        }
        if cols == 0 || cols > MAX_COLS {
            bail!("scan has {cols} columns; the pipeline supports 1..={MAX_COLS}");
        }
        Ok(Settings {
            cols: cols as u32,
            threshold: scorer.threshold_from_units(t),
            power_threshold: cvm_core::power::threshold_from_units(self.power_threshold_units()?),
            scores: self.scores,
            max_defect_lines_per_row: self.max_defect_lines,
            firmware_version: cvm_core::VERSION,
            reset_cause: cvm_core::protocol::ResetCause::PowerOn,
            boots: 1,
        })
    }
}

/// The core's configuration of a `stream`, `emulate` or `twin` run on
/// `j1 x j2` maps: the scoring options and the full scale.
pub fn core_config(
    scoring: &ScoringArgs,
    output: &OutputArgs,
    j1: usize,
    j2: usize,
) -> Result<cvm_core::Config> {
    Ok(cvm_core::Config {
        full_scale: output.full_scale,
        ..scoring.core_config(j1, j2)?
    })
}

/// The scorer, settings and warnings of a `stream` or `emulate` run on a
/// scan of `j1 x j2` maps and `cols` columns.
pub fn configure(
    scoring: &ScoringArgs,
    output: &OutputArgs,
    j1: usize,
    j2: usize,
    cols: usize,
) -> Result<(Scorer, Settings, Vec<String>)> {
    let scorer = crate::fixed::scorer(&core_config(scoring, output, j1, j2)?)
        .map_err(|e| anyhow::anyhow!("fixed-point scorer refused the configuration: {e}"))?;
    if let Some(path) = &output.calibration {
        // Refuses a calibration made for another configuration.
        crate::calibrate::threshold_units(path, &core_config(scoring, output, j1, j2)?)?;
    }
    let units = output.threshold_units(scoring)?;
    let settings = OutputArgs {
        threshold: Some(units),
        ..output.clone()
    }
    .settings(&scorer, cols)?;
    let mut warnings = scoring.warnings(j1, j2)?;
    warnings.extend(output.threshold_warnings(&scorer, units));
    Ok((scorer, settings, warnings))
}

/// A number for a message: plain when short, in exponent form when huge
/// or tiny (never 300 digits).
pub fn fmt_num(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() || (1e-4..1e12).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Collects lines in memory.
#[derive(Default)]
pub struct VecSink(pub Vec<u8>);

impl LineSink for VecSink {
    fn line(&mut self, line: &[u8], _priority: Priority) {
        self.0.extend_from_slice(line);
    }
}

/// Runs the pipeline over a whole scan in raster order and returns its lines.
pub fn stream_scan(
    scorer: &Scorer,
    settings: Settings,
    rows: usize,
    data: &[u16],
) -> Result<Vec<u8>> {
    let n = scorer.cells();
    let cols = settings.cols as usize;
    if data.len() != rows * cols * n {
        bail!(
            "scan data has {} samples, expected {rows}x{cols}x{n}",
            data.len()
        );
    }
    let words = cvm_core::stream::row_words_for(cols, scorer.config());
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let mut pipeline = Box::new(
        Pipeline::<MAX_COLS>::new(scorer, settings, &mut a, &mut b)
            .map_err(|e| anyhow::anyhow!("pipeline refused the scan: {e}"))?,
    );
    let mut sink = VecSink::default();
    pipeline.begin(&mut sink);
    for (i, frame) in data.chunks_exact(n).enumerate() {
        let pos = Position {
            row: (i / cols) as u32,
            col: (i % cols) as u32,
        };
        pipeline.push(pos, frame, &mut sink);
    }
    pipeline.finish(0, &mut sink);
    Ok(sink.0)
}

/// Runs the pipeline over a mapped scan a row at a time, handing its lines
/// to `emit` as they come (in pieces of about 64 KiB): memory does not grow
/// with the scan.
pub fn stream_mapped(
    scorer: &Scorer,
    settings: Settings,
    scan: &ScanFile,
    emit: &mut dyn FnMut(&[u8]) -> Result<()>,
) -> Result<()> {
    let n = scorer.cells();
    let cols = settings.cols as usize;
    if cols != scan.cols || n != scan.geometry.cells() {
        bail!("the settings do not match the scan");
    }
    if scan.rows > u32::MAX as usize {
        bail!(
            "scan has {} rows, more than a position can number",
            scan.rows
        );
    }
    let words = cvm_core::stream::row_words_for(cols, scorer.config());
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let mut pipeline = Box::new(
        Pipeline::<MAX_COLS>::new(scorer, settings, &mut a, &mut b)
            .map_err(|e| anyhow::anyhow!("pipeline refused the scan: {e}"))?,
    );
    let mut sink = VecSink::default();
    pipeline.begin(&mut sink);
    let (mut counts, mut scratch) = (vec![0u16; cols * n], Vec::new());
    for row in 0..scan.rows {
        scan.maps_u16(row * cols, &mut counts, &mut scratch)?;
        for (col, frame) in counts.chunks_exact(n).enumerate() {
            let pos = Position {
                row: row as u32,
                col: col as u32,
            };
            pipeline.push(pos, frame, &mut sink);
        }
        if sink.0.len() >= 1 << 16 {
            emit(&sink.0)?;
            sink.0.clear();
        }
    }
    pipeline.finish(0, &mut sink);
    emit(&sink.0)
}

pub fn run(args: &StreamArgs) -> Result<()> {
    let scan = ScanFile::open(&args.scan)?;
    let (j1, j2) = (scan.geometry.j1(), scan.geometry.j2());
    let (scorer, settings, warnings) = configure(&args.scoring, &args.output, j1, j2, scan.cols)?;
    // Every sample is checked before the first line goes out.
    scan.validate(true)?;
    stream_mapped(&scorer, settings, &scan, &mut |bytes| {
        crate::out::stdout(bytes)
    })?;
    // After the lines, so that a failed run says one thing only.
    for w in warnings
        .iter()
        .chain(&crate::score::flat_scan_warnings(scan.rows, scan.cols))
    {
        crate::out::warn(w);
    }
    Ok(())
}
