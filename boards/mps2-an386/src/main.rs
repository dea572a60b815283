//! The emulated board: QEMU `mps2-an386` (Cortex-M4F).
//!
//! Stands in for the H743 board where no hardware is at hand. Beams come
//! from a scan file on the host (semihosting; format in
//! `cvm_fw_app::emufile`), LINE_SYNC is synthesised on every `cols`-th beam,
//! result lines leave through CMSDK UART0, and the run ends with a
//! semihosting exit whose status says whether it succeeded. Between those,
//! the path is the H743's: `Acquisition` bookkeeping, the `cvm_fw_app`
//! runtime over its `ScanDriver` and `cvm_core::Pipeline` (with no pins
//! and no command channel), the prioritised `LineQueue` drained by a UART
//! task.
//!
//! The file has no deadline, so the board waits for the UART before each
//! beam and never drops a line: its bytes are the host's, exactly.
//! Instructions spent scoring are counted with SysTick and reported on the
//! host's stderr, off the UART stream.

#![no_std]
#![no_main]

mod cycles;
mod host;
mod uart;

use core::cell::RefCell;

use cortex_m_rt::entry;
use cvm_core::pipeline::{Boot, Pipeline, Settings};
use cvm_core::protocol::{MAX_LINE, ResetCause};
use cvm_core::scorer::MAX_FACTOR_WORDS;
use cvm_core::stream::{row_words, row_words_for};
use cvm_core::{MAX_J, Scorer};
use cvm_fw_app::acquire::Acquisition;
use cvm_fw_app::driver::ScanDriver;
use cvm_fw_app::emufile::{HEADER_LEN, ScanHeader};
use cvm_fw_app::frames::{Beams, SampleBuffers, SharedLog};
use cvm_fw_app::outputs::OutputLogic;
use cvm_fw_app::queue::{LineQueue, QueueSink, SharedQueue};
use cvm_fw_app::runtime::{NoPins, NoReplies, Runtime};
use embassy_executor::{Executor, Spawner};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::{NoopRawMutex, ThreadModeRawMutex};
use embassy_sync::signal::Signal;
use static_cell::{ConstStaticCell, StaticCell};

use config::{BEAM_LOG, FIRMWARE_VERSION, FRAME_BUFFERS, KEEP_RESERVE, MAX_COLS, QUEUE_BYTES};
use cycles::Stopwatch;
use host::{eprint, exit};
use semihosting::fs::File;
use semihosting::io::Read as _;

const ROW_WORDS: usize = row_words(MAX_COLS, MAX_J, MAX_J);

/// Exit statuses (QEMU's own exit status is the firmware's).
const EXIT_OK: u32 = 0;
const EXIT_INPUT: u32 = 2;
const EXIT_INTERNAL: u32 = 3;

type Queue = LineQueue<QUEUE_BYTES>;

static EXECUTOR: StaticCell<Executor> = StaticCell::new();
static QUEUE: SharedQueue<ThreadModeRawMutex, QUEUE_BYTES> =
    Mutex::new(RefCell::new(Queue::new(KEEP_RESERVE)));
/// Lines were queued (scoring -> UART task).
static KICK: Signal<ThreadModeRawMutex, ()> = Signal::new();
/// The queue ran empty (UART task -> scoring).
static DRAINED: Signal<ThreadModeRawMutex, ()> = Signal::new();
static FRAMES: SampleBuffers<FRAME_BUFFERS> = SampleBuffers::new();
static ROW_A: ConstStaticCell<[i32; ROW_WORDS]> = ConstStaticCell::new([0; ROW_WORDS]);
static ROW_B: ConstStaticCell<[i32; ROW_WORDS]> = ConstStaticCell::new([0; ROW_WORDS]);
static SCORER: StaticCell<Scorer> = StaticCell::new();
/// The square kernels' factor table, built at start-up for the scan's
/// configuration (unused with paper kernels).
static FACTORS: ConstStaticCell<[i32; MAX_FACTOR_WORDS]> =
    ConstStaticCell::new([0; MAX_FACTOR_WORDS]);
static VERSION: StaticCell<[u8; cvm_core::protocol::MAX_FW]> = StaticCell::new();

/// Fails the run with a one-line message on the host's stderr.
fn fail(status: u32, what: &str) -> ! {
    eprint(format_args!("cvm-fw (emulated): error: {what}\n"));
    exit(status)
}

#[entry]
fn main() -> ! {
    let Some(core) = cortex_m::Peripherals::take() else {
        fail(EXIT_INTERNAL, "core peripherals taken twice")
    };
    let executor = EXECUTOR.init(Executor::new());
    executor.run(|spawner| start(spawner, core.SYST))
}

fn start(spawner: Spawner, syst: cortex_m::peripheral::SYST) {
    match (uart_task(uart::Uart0::take()), scan_task(syst)) {
        (Ok(u), Ok(s)) => {
            spawner.spawn(u);
            spawner.spawn(s);
        }
        _ => fail(EXIT_INTERNAL, "task pool exhausted"),
    }
}

/// Sends queued lines, one at a time, copied out under the queue's lock.
#[embassy_executor::task]
async fn uart_task(mut uart: uart::Uart0) {
    let mut line = [0u8; MAX_LINE];
    loop {
        match QUEUE.lock(|q| q.borrow_mut().pop_into(&mut line)) {
            Some(n) => uart.write(&line[..n]),
            None => {
                DRAINED.signal(());
                KICK.wait().await;
            }
        }
    }
}

/// Waits until the UART task has sent everything queued.
async fn drain() {
    while !QUEUE.lock(|q| q.borrow().is_empty()) {
        DRAINED.reset();
        KICK.signal(());
        DRAINED.wait().await;
    }
}

/// Opens the scan file named on the command line and reads its header.
fn open_scan() -> (File, ScanHeader) {
    let mut file = match host::open_scan() {
        Ok(f) => f,
        Err(what) => fail(EXIT_INPUT, what),
    };
    let mut head = [0u8; HEADER_LEN];
    if file.read_exact(&mut head).is_err() {
        fail(EXIT_INPUT, "scan file shorter than its header");
    }
    let header = match ScanHeader::parse(&head) {
        Ok(h) => h,
        Err(e) => fail(EXIT_INPUT, e.message()),
    };
    if header.cols as usize > MAX_COLS {
        fail(
            EXIT_INPUT,
            "more columns than the emulated board holds (1024)",
        );
    }
    (file, header)
}

/// The scoring side for the scan `header` describes: its tables (and the
/// square kernels' factors), the row buffers and the pipeline.
fn scan_driver(header: &ScanHeader) -> ScanDriver<'static, MAX_COLS> {
    let scorer: &'static Scorer = match Scorer::new(&header.config) {
        Ok(s) => match s.with_factors(FACTORS.take()) {
            Ok(s) => SCORER.init(s),
            Err(_) => fail(
                EXIT_INTERNAL,
                "the square kernels' factors could not be built",
            ),
        },
        Err(_) => fail(EXIT_INPUT, "the core refused the scoring configuration"),
    };
    let firmware_version: &'static str = match header.version() {
        Some(v) => {
            let buf = VERSION.init([0; cvm_core::protocol::MAX_FW]);
            buf[..v.len()].copy_from_slice(v.as_bytes());
            core::str::from_utf8(&buf[..v.len()]).unwrap_or(FIRMWARE_VERSION)
        }
        None => FIRMWARE_VERSION,
    };
    let settings = Settings {
        cols: header.cols,
        threshold: scorer.threshold_from_units(header.threshold_units),
        power_threshold: cvm_core::power::threshold_from_units(header.power_threshold_units),
        spread_threshold: cvm_core::spread::threshold_from_units(header.spread_threshold_units),
        scores: header.scores,
        max_defect_lines_per_row: header.max_defect_lines_per_row,
        rows: header.rows,
        outputs: cvm_core::settings::Outputs::DEFAULT,
        sources: [cvm_core::settings::Source::Default; cvm_core::settings::KEYS],
    };
    let words = row_words_for(header.cols as usize, scorer.config());
    let (Some(row_a), Some(row_b)) = (ROW_A.take().get_mut(..words), ROW_B.take().get_mut(..words))
    else {
        fail(
            EXIT_INPUT,
            "scan too wide for the board's row buffers with these kernels",
        )
    };
    let mut pipeline = match Pipeline::<MAX_COLS>::new(scorer, settings, row_a, row_b) {
        Ok(p) => p,
        Err(_) => fail(EXIT_INTERNAL, "pipeline refused its buffers"),
    };
    // QEMU starts the board from power-on, once per run; no settings record.
    pipeline.set_boot(Boot::power_on(firmware_version));
    ScanDriver::new(pipeline, header.cols, header.rows)
}

#[embassy_executor::task]
async fn scan_task(syst: cortex_m::peripheral::SYST) {
    let (mut file, header) = open_scan();
    let mut driver = scan_driver(&header);

    let cells = header.config.geometry.cells();
    let n = 2 * cells;
    // The board's only task fills the log and scores it.
    let log: SharedLog<NoopRawMutex, FRAME_BUFFERS, BEAM_LOG> =
        Mutex::new(core::cell::RefCell::new(Acquisition::new()));
    let mut beams = Beams {
        log: &log,
        bufs: &FRAMES,
        cells,
    };
    let outputs = OutputLogic::start(driver.settings().outputs, ResetCause::PowerOn);
    let mut runtime = Runtime::new(&mut driver, outputs, NoPins, None);
    let mut stopwatch = Stopwatch::new(syst);
    let mut beam: u64 = 0;
    let mut sink = QueueSink(&QUEUE);
    let mut replies = NoReplies;

    let Ok(file_len) = file.metadata().map(|m| m.len() as usize) else {
        fail(EXIT_INPUT, "cannot size the scan file")
    };
    let data = file_len.saturating_sub(HEADER_LEN);
    if data % n != 0 {
        fail(EXIT_INPUT, "scan file ends inside a frame");
    }
    let beams_in_file = (data / n) as u64;

    while beam < beams_in_file {
        // The "DRDY" of the next beam: LINE_SYNC on each row's first beam.
        let sync = beam.is_multiple_of(u64::from(header.cols));
        let Some(buf) = log.lock(|a| a.borrow_mut().drdy(sync)) else {
            fail(
                EXIT_INTERNAL,
                "no free frame buffer although scoring keeps up",
            );
        };
        // SAFETY: `buf` is Filling: the acquisition side owns it.
        let bytes = unsafe { FRAMES.bytes(buf, cells) };
        if file.read_exact(bytes).is_err() {
            fail(EXIT_INPUT, "reading the scan file failed");
        }
        log.lock(|a| a.borrow_mut().read_done(buf, true));
        beam += 1;
        // The beam just read is the log's one record: steps until it is
        // scored.
        loop {
            drain().await;
            stopwatch.time(|| runtime.step(&mut beams, &mut sink, &mut replies));
            if !runtime.driver().busy() {
                break;
            }
        }
    }

    loop {
        drain().await;
        let (more, _) = stopwatch.time(|| runtime.end_of_data(&mut beams, &mut sink, &mut replies));
        if !more {
            break;
        }
    }
    drain().await;

    let spi_errors = log.lock(|a| a.borrow().counts().spi_errors);
    finish(&driver, &stopwatch, beam, spi_errors)
}

/// Reports the run on the host's stderr and exits: successfully when no
/// line was dropped and no beam lost.
fn finish(
    driver: &ScanDriver<'static, MAX_COLS>,
    stopwatch: &Stopwatch,
    beam: u64,
    spi_errors: u32,
) -> ! {
    let seq = *driver.sequence_counts();
    let q = QUEUE.lock(|q| *q.borrow().counts());
    let instr = stopwatch.instructions();
    let per_beam = instr.checked_div(beam).unwrap_or(0);
    eprint(format_args!(
        "cvm-fw (emulated): beams={beam} scans={} placed={} lost={} extra={} sync_missing={} sync_extra={} \
         short_rows={} misplaced={} lines={} dropped={} scoring_instructions={instr} instructions_per_beam={per_beam}\n",
        seq.scans_finished,
        seq.placed,
        seq.lost,
        seq.extra,
        seq.sync_missing,
        seq.sync_extra,
        seq.short_rows,
        seq.misplaced,
        q.accepted,
        q.dropped_scores + q.dropped_keep,
    ));
    let ok = q.dropped_keep == 0 && q.dropped_scores == 0 && spi_errors == 0;
    exit(if ok { EXIT_OK } else { EXIT_INTERNAL })
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    eprint(format_args!("cvm-fw (emulated): panic: {info}\n"));
    exit(101)
}

/// The board's sizes; the ones both boards share are
/// `cvm_fw_app::sizing`'s.
mod config {
    pub use cvm_fw_app::sizing::{BEAM_LOG, keep_reserve, queue_fits};

    /// Announced in the header line when the scan file names no version.
    pub const FIRMWARE_VERSION: &str = concat!("cvm-fw-", env!("CARGO_PKG_VERSION"));

    /// Columns the emulated board's row buffers hold (16x16 maps).
    pub const MAX_COLS: usize = 1024;
    /// Output queue of the emulated board: a whole row of score lines of
    /// the widest scan fits besides the keep reserve, so with the board's
    /// back-pressure nothing is ever dropped.
    pub const QUEUE_BYTES: usize = 128 * 1024;
    pub const KEEP_RESERVE: usize = keep_reserve(MAX_COLS);
    const _: () = assert!(queue_fits(QUEUE_BYTES, MAX_COLS));
    /// Frame buffers: the scan file is read one beam at a time, so one is
    /// filled while the other is scored.
    pub const FRAME_BUFFERS: usize = 2;
}
