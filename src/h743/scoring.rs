//! The scoring side's memory and its assembly: the tables, the row
//! buffers, the near maps and the scan driver, each placed in the RAM
//! bank that its access pattern calls for (why each goes where it goes,
//! with the stall cycles each choice saves: docs/performance.md and
//! docs/firmware.md, "SPI1 configuration and measured costs").

use core::sync::atomic::{AtomicBool, Ordering};

use cvm_core::Scorer;
use cvm_core::calibration::Calibrator;
use cvm_core::pipeline::{Boot, Pipeline, Settings};
use cvm_core::protocol::ResetCause;
use cvm_core::settings::{KEYS, Source, Store};
use cvm_core::stream::{near_words, row_words_for};
use cvm_fw_app::driver::ScanDriver;
use static_cell::ConstStaticCell;

use super::memory::Noload;
use crate::config::h743::{
    COLS, CORE, FIRMWARE_VERSION, FRAME_BUFFERS, FRAME_SAMPLES, MAX_COLS, MAX_DEFECT_LINES_PER_ROW,
    OUTPUTS, POWER_THRESHOLD_UNITS, QUEUE_BYTES, ROWS, SCORES, SPREAD_THRESHOLD_UNITS,
    THRESHOLD_UNITS,
};
use cvm_fw_app::frames::SampleBuffers;

const ROW_WORDS: usize = row_words_for(MAX_COLS, &CORE);

/// Scoring tables, built by the compiler (in flash).
const TABLES: Scorer = match Scorer::new(&CORE) {
    Ok(s) => s,
    Err(_) => panic!("cvm-core refuses the configuration in config.rs"),
};

/// The square kernels' factor table (empty with the paper kernels, whose
/// factors the `Scorer` holds), built at start-up, in DTCM: every map
/// reads all of it, without wait states there.
const FACTOR_WORDS: usize = TABLES.factor_words();
#[unsafe(link_section = ".dtcm")]
static FACTORS: Noload<[i32; FACTOR_WORDS]> = Noload::new();

/// The tables the scorer reads, in DTCM: every map loads its factor
/// coefficients, which cost no wait state there and several cycles each
/// from flash with the D-cache off.
#[unsafe(link_section = ".dtcm")]
static SCORER: Noload<Scorer> = Noload::new();

/// The two row buffers. Both sit in AXI SRAM when they fit there beside
/// everything else (the output queue, the frame buffers and a reserve for
/// the rest of `.bss` and `.data`): every beam reads its slot's old map
/// and writes the new one, and SRAM1..3, behind the AXI-to-AHB bridge,
/// costs about twice the wait states. Otherwise (300 columns of 15x15
/// maps, 270 KB a row) row buffer B goes to SRAM1..3 (`.sram123`). A
/// configuration for which neither fits fails to link.
const ROWS_IN_AXI: bool = 2 * ROW_WORDS * 4
    <= AXI_SRAM_BYTES
        - QUEUE_BYTES
        - core::mem::size_of::<SampleBuffers<FRAME_BUFFERS, FRAME_SAMPLES>>()
        - AXI_OTHER_BYTES;
const AXI_SRAM_BYTES: usize = 512 * 1024;
/// The rest of AXI SRAM's statics (the UART line, the acquisition log, the
/// task futures, the rest of `.data`), with a wide margin.
const AXI_OTHER_BYTES: usize = 16 * 1024;
const AXI_ROW_WORDS: usize = if ROWS_IN_AXI {
    2 * ROW_WORDS
} else {
    ROW_WORDS
};
const SRAM123_ROW_WORDS: usize = if ROWS_IN_AXI { 0 } else { ROW_WORDS };
static ROWS_AXI: ConstStaticCell<[i32; AXI_ROW_WORDS]> = ConstStaticCell::new([0; AXI_ROW_WORDS]);
#[unsafe(link_section = ".sram123")]
static ROWS_SRAM123: Noload<[i32; SRAM123_ROW_WORDS]> = Noload::new();

/// The current row's last three maps, in DTCM: every map is written
/// here as well as to its row buffer, and the horizontal distances read
/// their two maps from here instead of from AXI SRAM or SRAM1..3
/// (`Engine::with_near`).
const NEAR_WORDS: usize = near_words(&CORE);
#[unsafe(link_section = ".dtcm")]
static NEAR: Noload<[i32; NEAR_WORDS]> = Noload::new();

/// The scoring side's state (sequencer, engine, the rows of results), in
/// DTCM: the scoring task reads and writes it for every beam, which in the
/// task's future (AXI SRAM) would stall on every access.
#[unsafe(link_section = ".dtcm")]
static DRIVER: Noload<ScanDriver<'static, MAX_COLS>> = Noload::new();

/// The command channel's calibrator (24 KB of histograms), in AXI SRAM:
/// it takes each finished row only while a calibration runs.
static CALIBRATOR: ConstStaticCell<Calibrator> = ConstStaticCell::new(Calibrator::new());

/// The statics above are handed out by [`scan_driver`] only, once.
static TAKEN: AtomicBool = AtomicBool::new(false);

/// The compiled settings (docs/firmware.md, "Build-time configuration").
pub fn compiled_settings() -> Settings {
    Settings {
        cols: COLS as u32,
        threshold: TABLES.threshold_from_units(THRESHOLD_UNITS),
        power_threshold: cvm_core::power::threshold_from_units(POWER_THRESHOLD_UNITS),
        spread_threshold: cvm_core::spread::threshold_from_units(SPREAD_THRESHOLD_UNITS),
        scores: SCORES,
        max_defect_lines_per_row: MAX_DEFECT_LINES_PER_ROW,
        rows: ROWS,
        outputs: OUTPUTS,
        sources: [Source::Default; KEYS],
    }
}

/// This start: the firmware, the reset's cause, the boot count and what
/// the settings store gave.
pub fn boot(cause: ResetCause, boots: u32, store: Store) -> Boot {
    Boot {
        firmware: FIRMWARE_VERSION,
        reset_cause: cause,
        boots,
        store,
    }
}

/// Builds the scoring side in its memory: the square kernels' factors
/// (an f64 factorisation: before the watchdog starts), the scorer's tables
/// in DTCM, the row buffers, the pipeline and the scan driver, which
/// starts with `settings`. Out of line: inlined into `main`, the
/// factors' build is no longer folded away for the paper kernels, and
/// the square kernels' f64 factorisation (about 13 KB) is linked.
#[inline(never)]
pub fn scan_driver(settings: Settings) -> &'static mut ScanDriver<'static, MAX_COLS> {
    if TAKEN.swap(true, Ordering::Relaxed) {
        defmt::panic!("the scoring side is built once");
    }
    // SAFETY (all `take*` below): `TAKEN` lets this code run once, and
    // nothing else touches these statics; each is an integer array where
    // zeroed.
    let factors = unsafe { FACTORS.take_zeroed() };
    let Ok(tables) = TABLES.with_factors(factors) else {
        defmt::panic!("the square kernels' factors cannot be built")
    };
    let scorer: &'static Scorer = unsafe { SCORER.take() }.write(tables);
    let axi = ROWS_AXI.take();
    let sram123 = unsafe { ROWS_SRAM123.take_zeroed() };
    let (row_a, rest) = axi.split_at_mut(ROW_WORDS);
    let row_b = if ROWS_IN_AXI { rest } else { sram123 };
    let near = unsafe { NEAR.take_zeroed() };
    // Built inside the static's `write`, never as a named local: the
    // pipeline is most of the driver's 35 KB, and each copy of it that
    // the compiler keeps on the way is stack that the scans need (the
    // boot test checks 4 KiB to spare).
    let driver = unsafe { DRIVER.take() }.write(ScanDriver::new(
        match Pipeline::<MAX_COLS>::with_near(scorer, settings, row_a, row_b, near) {
            Ok(p) => p,
            Err(e) => defmt::panic!("pipeline refused its buffers: {}", e),
        },
        settings.cols,
        settings.rows,
    ));
    driver.attach_calibrator(CALIBRATOR.take());
    driver
}
