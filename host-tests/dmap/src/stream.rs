//! `dmap stream`: the firmware's pipeline (streaming engine and line
//! encoder, `cvm_core::Pipeline`) run on the host over a scan file, so that
//! host and firmware output can be compared byte for byte.

use crate::npy::ScanFile;
use crate::options::ScoringArgs;
use crate::settings::{MAX_COLS, resolve_with};
use anyhow::{Result, bail};
use clap::Args;
use cvm_core::protocol::{LineSink, Priority};
use cvm_core::{Pipeline, Position, Scorer, Settings};
use std::path::PathBuf;

// The tests, and listen's and eval's code, import these from here.
pub use crate::options::OutputArgs;

#[derive(Args, Clone, Debug)]
pub struct StreamArgs {
    /// Scan .npy, shape (rows, cols, J1, J2), integer counts 0..=65535
    pub scan: PathBuf,
    #[command(flatten)]
    pub scoring: ScoringArgs,
    #[command(flatten)]
    pub output: OutputArgs,
    /// Announce the settings as loaded from a board's settings record in
    /// flash: the header's `src` is `f` for every key and its `store` is
    /// `ok`, as a board that starts with the settings it saved sends it
    /// (and `dmap twin`, whose firmware gets the run's settings that way);
    /// the rest of the output is the same
    #[arg(long)]
    pub from_flash: bool,
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
    (settings, boot): (Settings, cvm_core::Boot),
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
    pipeline.set_boot(boot);
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

/// `dmap stream` on a scan already opened (a file or memory), its
/// calibration (if `output.calibration` names one) read by `load`: the
/// run's settings resolved and every sample checked, then the lines
/// handed to `emit` as they come; `from_flash`: the header says the
/// settings came from a settings record (`--from-flash`). Returns the
/// warnings `dmap stream` prints after its lines.
pub fn stream_with(
    scan: &ScanFile,
    (scoring, output, from_flash): (&ScoringArgs, &OutputArgs, bool),
    load: &dyn Fn(&std::path::Path) -> Result<crate::calibrate::Calibration>,
    emit: &mut dyn FnMut(&[u8]) -> Result<()>,
) -> Result<Vec<String>> {
    let (j1, j2) = (scan.geometry.j1(), scan.geometry.j2());
    let mut run = resolve_with(scoring, output, load, (j1, j2), (scan.rows, scan.cols))?;
    // The host's start: power-on, no record; `--from-flash` says the
    // settings came from one.
    let mut boot = cvm_core::Boot::power_on(cvm_core::VERSION);
    if from_flash {
        run.settings.sources = [cvm_core::settings::Source::Flash; cvm_core::settings::KEYS];
        boot.store = cvm_core::settings::Store::Loaded;
    }
    // Every sample is checked before the first line goes out.
    scan.validate(true)?;
    stream_mapped(&run.scorer, (run.settings, boot), scan, emit)?;
    Ok(run.warnings)
}

pub fn run(args: &StreamArgs) -> Result<()> {
    let scan = ScanFile::open(&args.scan)?;
    let warnings = stream_with(
        &scan,
        (&args.scoring, &args.output, args.from_flash),
        &|path| crate::calibrate::Calibration::load(path),
        &mut |bytes| crate::out::stdout(bytes),
    )?;
    // After the lines, so that a failed run says one thing only.
    for w in &warnings {
        crate::out::warn(w);
    }
    Ok(())
}
