//! `dmap stream`: the firmware's pipeline (streaming engine and line
//! encoder, `cvm_core::Pipeline`) run on the host over a scan file, so that
//! host and firmware output can be compared byte for byte.

use crate::npy::read_scan;
use crate::options::ScoringArgs;
use anyhow::{Context, Result, bail};
use clap::Args;
use cvm_core::protocol::{LineSink, Priority};
use cvm_core::{Pipeline, Position, Scorer, Settings};
use std::io::Write;
use std::path::PathBuf;

/// Most columns the host pipeline accepts (the engine's capacity is fixed
/// at compile time, as on the target).
pub const MAX_COLS: usize = 4096;

/// Default defect threshold, in distance units.
pub const DEFAULT_THRESHOLD: f64 = 0.5;

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
    /// Defect threshold on the gradient magnitude, in distance units
    #[arg(long, default_value_t = DEFAULT_THRESHOLD)]
    pub threshold: f64,
    /// Also emit every position's score (S lines)
    #[arg(long)]
    pub scores: bool,
    /// At most this many defect lines per row (the row line has the full count)
    #[arg(long, default_value_t = 16)]
    pub max_defect_lines: u16,
}

impl Default for OutputArgs {
    fn default() -> Self {
        OutputArgs {
            threshold: DEFAULT_THRESHOLD,
            scores: false,
            max_defect_lines: 16,
        }
    }
}

impl OutputArgs {
    pub fn settings(&self, scorer: &Scorer, cols: usize) -> Result<Settings> {
        if self.threshold.is_nan() || self.threshold < 0.0 {
            bail!(
                "--threshold must be a non-negative number, got {}",
                self.threshold
            );
        }
        if cols == 0 || cols > MAX_COLS {
            bail!("scan has {cols} columns; the pipeline supports 1..={MAX_COLS}");
        }
        Ok(Settings {
            cols: cols as u32,
            threshold: scorer.threshold_from_units(self.threshold),
            scores: self.scores,
            max_defect_lines_per_row: self.max_defect_lines,
            firmware_version: cvm_core::VERSION,
        })
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
    let words = cvm_core::stream::row_words(cols, n, 1);
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let mut pipeline = Box::new(
        Pipeline::<MAX_COLS>::new(scorer, settings, &mut a, &mut b)
            .map_err(|e| anyhow::anyhow!("pipeline refused the scan: {e:?}"))?,
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

pub fn run(args: &StreamArgs) -> Result<()> {
    let scan = read_scan(&args.scan)?;
    let (j1, j2) = (scan.geometry.j1(), scan.geometry.j2());
    let scorer = args.scoring.scorer(j1, j2)?;
    let settings = args.output.settings(&scorer, scan.cols)?;
    let data = scan
        .to_u16()
        .with_context(|| format!("{}", args.scan.display()))?;
    let out = stream_scan(&scorer, settings, scan.rows, &data)?;
    let mut stdout = std::io::stdout().lock();
    stdout.write_all(&out).context("writing to stdout")?;
    stdout.flush().context("writing to stdout")?;
    Ok(())
}
