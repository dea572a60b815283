//! The NUCLEO-H743ZI2 board.
//!
//! Two levels:
//!
//! - **Interrupts** (one priority, so none preempts another):
//!   - DRDY (EXTI9_5): samples LINE_SYNC, records the beam in the
//!     `Acquisition` log and, when a frame buffer is free and the SPI idle,
//!     starts reading the frame into it (`frame_reader`: CS low, SPI1 with
//!     DMA1 stream 1, the read's deadline on TIM13). Every edge is counted
//!     here, even while the SPI or the scoring side is busy.
//!   - End of the read (DMA1 stream 1: complete or error; TIM13: the
//!     deadline): CS high, the result (or overrun, DMA error, timeout) into
//!     the log, the scoring task woken.
//! - **Thread mode**: the scoring task (sequencing, `cvm_core::Pipeline`,
//!   lines into the bounded queue, watchdog feeding, idle end of scan) and
//!   the UART task (USART3 TX with DMA from the queue). The scoring task
//!   yields every few beams, so the UART task and the watchdog feed never
//!   wait for a backlog to be scored.
//!
//! D-cache: left disabled (only the I-cache is enabled), so DMA buffers in
//! AXI SRAM need no cache maintenance. DMA only touches statics in AXI SRAM
//! (frame buffers, the UART line buffer), never the DTCM stack.

mod clocks;
mod drdy;
mod frame_reader;
mod read_deadline;
mod resets;
mod tasks;

use core::cell::RefCell;

use cortex_m_rt::entry;
use cvm_core::Scorer;
use cvm_core::pipeline::{Pipeline, Settings};
use cvm_core::protocol::MAX_LINE;
use cvm_core::stream::{near_words, row_words_for};
use cvm_fw_app::acquire::Acquisition;
use cvm_fw_app::driver::ScanDriver;
use cvm_fw_app::queue::LineQueue;
use defmt::info;
use defmt_rtt as _;
use embassy_executor::Executor;
use embassy_stm32::exti::blocking::ExtiGroupMask;
use embassy_stm32::exti::{ExtiInput, TriggerEdge};
use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};
use embassy_stm32::interrupt::{InterruptExt, Priority as IrqPriority};

use embassy_stm32::peripherals::{self, IWDG1};
use embassy_stm32::time::Hertz;
use embassy_stm32::usart::UartTx;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{Peri, bind_interrupts, dma, interrupt, spi, usart};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, ThreadModeRawMutex};
use embassy_sync::signal::Signal;

use drdy::{DRDY_IO, DrdyIo};
use frame_reader::{FrameReader, READER};
use static_cell::StaticCell;
use tasks::{score_task, uart_task};

use crate::config::BEAM_LOG;
use crate::config::h743::FIRMWARE_VERSION;
use crate::config::h743::{
    BAUD, COLS, CORE, J1, J2, KEEP_RESERVE, MAX_COLS, MAX_DEFECT_LINES_PER_ROW,
    POWER_THRESHOLD_UNITS, QUEUE_BYTES, READ_TIMEOUT_US, ROWS, SCORES, SPI_DIV, SPI_HZ, SYSCLK_HZ,
    THRESHOLD_UNITS, WATCHDOG_US,
};
use crate::config::h743::{FRAME_BUFFERS, FRAME_SAMPLES};
use crate::frames::SampleBuffers;
use crate::sink::SharedQueue;

bind_interrupts!(struct Irqs {
    DMA1_STREAM2 => dma::InterruptHandler<peripherals::DMA1_CH2>;
});

/// The peripherals the board uses; `crate::pins!` (config.rs) fills it.
/// (SPI1's RX DMA, DMA1 stream 1, is driven by `frame_reader` directly.)
pub struct Pins {
    pub spi: Peri<'static, peripherals::SPI1>,
    pub sck: Peri<'static, peripherals::PA5>,
    pub miso: Peri<'static, peripherals::PA6>,
    pub cs: Peri<'static, peripherals::PD14>,
    pub drdy: Peri<'static, peripherals::PE9>,
    pub drdy_exti: Peri<'static, peripherals::EXTI9>,
    pub line_sync: Peri<'static, peripherals::PE11>,
    pub uart: Peri<'static, peripherals::USART3>,
    pub uart_tx: Peri<'static, peripherals::PD8>,
    pub uart_tx_dma: Peri<'static, peripherals::DMA1_CH2>,
    pub iwdg: Peri<'static, IWDG1>,
}

const CELLS: usize = CORE.geometry.cells();
const ROW_WORDS: usize = row_words_for(MAX_COLS, &CORE);

/// Scoring tables, built by the compiler (in flash).
const TABLES: Scorer = match Scorer::new(&CORE) {
    Ok(s) => s,
    Err(_) => panic!("cvm-core refuses the configuration in config.rs"),
};

/// The square kernels' factor table (empty with the paper kernels, whose
/// factors the `Scorer` holds), built by `main` at start-up, in DTCM:
/// every map reads all of it (6 836 words at 15x15), without wait states
/// there. NOLOAD: `main` zeroes it before the build.
struct FactorTable(core::cell::UnsafeCell<[i32; FACTOR_WORDS]>);
// SAFETY: handed out once, by `main`, before any task runs.
unsafe impl Sync for FactorTable {}
const FACTOR_WORDS: usize = TABLES.factor_words();
#[unsafe(link_section = ".dtcm")]
static FACTORS: FactorTable = FactorTable(core::cell::UnsafeCell::new([0; FACTOR_WORDS]));

/// The tables the scorer reads, in DTCM: every map loads its factor
/// coefficients, which cost no wait state there and about 10 cycles each
/// from flash with the D-cache off (scripts/twin-cost.sh,
/// docs/performance.md). `.dtcm` is not loaded: `main` copies the tables
/// in before anything reads them.
struct DtcmScorer(core::cell::UnsafeCell<core::mem::MaybeUninit<Scorer>>);
// SAFETY: written once by `main` before any task runs, only read after.
unsafe impl Sync for DtcmScorer {}
#[unsafe(link_section = ".dtcm")]
static SCORER: DtcmScorer =
    DtcmScorer(core::cell::UnsafeCell::new(core::mem::MaybeUninit::uninit()));

/// The two row buffers. Both sit in AXI SRAM when they fit there beside
/// everything else (the output queue, the frame buffers and a reserve for
/// the rest of `.bss` and `.data`): every beam reads its slot's old map
/// and writes the new one, and SRAM1..3, behind the AXI-to-AHB bridge,
/// costs about twice the wait states (257 stall cycles per 9x9 beam at
/// 300 columns, scripts/twin-cost.sh). Otherwise (300 columns of 15x15
/// maps, 270 KB a row) row buffer B goes to SRAM1..3 (`.sram123`). A
/// configuration for which neither fits fails to link.
const ROWS_IN_AXI: bool = 2 * ROW_WORDS * 4
    <= AXI_SRAM_BYTES
        - QUEUE_BYTES
        - core::mem::size_of::<SampleBuffers<FRAME_BUFFERS, FRAME_SAMPLES>>()
        - AXI_OTHER_BYTES;
const AXI_SRAM_BYTES: usize = 512 * 1024;
/// The rest of AXI SRAM's statics: about 4 KB today (the UART line, the
/// acquisition log, the task futures, the rest of `.data`).
const AXI_OTHER_BYTES: usize = 16 * 1024;
const AXI_ROW_WORDS: usize = if ROWS_IN_AXI {
    2 * ROW_WORDS
} else {
    ROW_WORDS
};
const SRAM123_ROW_WORDS: usize = if ROWS_IN_AXI { 0 } else { ROW_WORDS };
struct RowBuffers<const W: usize>(core::cell::UnsafeCell<[i32; W]>);
// SAFETY: handed out once, by `main`, before any task runs.
unsafe impl<const W: usize> Sync for RowBuffers<W> {}
static ROWS_AXI: RowBuffers<AXI_ROW_WORDS> =
    RowBuffers(core::cell::UnsafeCell::new([0; AXI_ROW_WORDS]));
#[unsafe(link_section = ".sram123")]
static ROWS_SRAM123: RowBuffers<SRAM123_ROW_WORDS> =
    RowBuffers(core::cell::UnsafeCell::new([0; SRAM123_ROW_WORDS]));

/// The current row's last three maps, in DTCM: every map is written
/// here as well as to its row buffer, and the horizontal distances read
/// their two maps from here instead of from AXI SRAM or SRAM1..3
/// (`Engine::with_near`; about 3 500 stall cycles less per 15x15 beam by
/// scripts/twin-cost.sh). NOLOAD: every map is written before it is read.
struct NearMaps(core::cell::UnsafeCell<core::mem::MaybeUninit<[i32; NEAR_WORDS]>>);
// SAFETY: handed out once, by `main`, before any task runs.
unsafe impl Sync for NearMaps {}
const NEAR_WORDS: usize = near_words(&CORE);
#[unsafe(link_section = ".dtcm")]
static NEAR: NearMaps = NearMaps(core::cell::UnsafeCell::new(core::mem::MaybeUninit::uninit()));

/// The scoring side's state (sequencer, engine, the rows of results), in
/// DTCM: the scoring task reads and writes it for every beam, which in the
/// task's future (AXI SRAM) cost about 450 stall cycles per beam
/// (scripts/twin-cost.sh). NOLOAD: `main` writes it before any task runs.
struct DriverCell(core::cell::UnsafeCell<core::mem::MaybeUninit<ScanDriver<'static, MAX_COLS>>>);
// SAFETY: written once by `main`, then used by the scoring task only.
unsafe impl Sync for DriverCell {}
#[unsafe(link_section = ".dtcm")]
static DRIVER: DriverCell =
    DriverCell(core::cell::UnsafeCell::new(core::mem::MaybeUninit::uninit()));

type Acq = Acquisition<FRAME_BUFFERS, BEAM_LOG>;
type Queue = LineQueue<QUEUE_BYTES>;

static ACQ: Mutex<CriticalSectionRawMutex, RefCell<Acq>> = Mutex::new(RefCell::new(Acq::new()));
#[unsafe(link_section = ".dma_buffers")]
static FRAMES: SampleBuffers<FRAME_BUFFERS, FRAME_SAMPLES> = SampleBuffers::new();
/// Zero-initialised (`.bss`, not 48 KB of `.data` in flash); `main` sets
/// its reserve before any task runs.
static QUEUE: SharedQueue<QUEUE_BYTES> = Mutex::new(RefCell::new(Queue::new(0)));
/// The DMA source of the line being sent (AXI SRAM, not the DTCM stack).
struct TxLine(core::cell::UnsafeCell<[u8; MAX_LINE]>);
// SAFETY: only the UART task touches it.
unsafe impl Sync for TxLine {}
#[unsafe(link_section = ".dma_buffers")]
static TX_LINE: TxLine = TxLine(core::cell::UnsafeCell::new([0; MAX_LINE]));

/// Acquisition -> scoring: beam records are waiting.
static BEAMS: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// Scoring -> UART: lines are waiting. UART -> scoring: room was made.
static KICK: Signal<ThreadModeRawMutex, ()> = Signal::new();
static ROOM: Signal<ThreadModeRawMutex, ()> = Signal::new();

static EXECUTOR: StaticCell<Executor> = StaticCell::new();

/// Copies `.dtcm_rodata` (the line encoder's tables) from its load image
/// in flash to DTCM, which the reset handler does not initialise.
fn load_dtcm_rodata() {
    unsafe extern "C" {
        static __sidtcm_rodata: u32;
        static mut __sdtcm_rodata: u32;
        static mut __edtcm_rodata: u32;
    }
    // SAFETY: the linker script places the section in DTCM, word-aligned,
    // with a load image of the same length in flash; nothing reads it
    // before this copy (the encoder runs in the tasks).
    unsafe {
        let src = &raw const __sidtcm_rodata;
        let dst = &raw mut __sdtcm_rodata;
        let words = (&raw mut __edtcm_rodata).offset_from(dst) as usize;
        core::ptr::copy_nonoverlapping(src, dst, words);
    }
}

#[entry]
fn main() -> ! {
    load_dtcm_rodata();
    let mut core = cortex_m::Peripherals::take()
        .unwrap_or_else(|| defmt::panic!("core peripherals taken twice"));
    core.SCB.enable_icache();
    let p = embassy_stm32::init(clocks::config());
    // init enables EXTI9_5 in the NVIC; DRDY must not interrupt before
    // DRDY_IO is set (enabled again at the end of this function).
    interrupt::EXTI9_5.disable();
    resets::freeze_watchdog_in_debug();
    let cause = resets::take_cause();
    let boots = resets::count_boot(cause);
    // SRAM1..3 hold row buffer B; their clocks are off after reset.
    embassy_stm32::pac::RCC.ahb2enr().modify(|w| {
        w.set_sram1en(true);
        w.set_sram2en(true);
        w.set_sram3en(true);
    });
    let pins = crate::pins!(p);

    info!("reset cause: {}, start {} since power-on", cause, boots);
    info!(
        "{} start: {}x{} maps, {} cols x {} rows, kernels {}, threshold {} units, scores {}, SPI {} Hz, UART {} baud, core {} Hz",
        FIRMWARE_VERSION,
        J1,
        J2,
        COLS,
        ROWS,
        match CORE.kernels {
            cvm_core::Kernels::Paper { .. } => "paper",
            cvm_core::Kernels::Square { .. } => "square",
        },
        THRESHOLD_UNITS,
        SCORES,
        SPI_HZ,
        BAUD,
        SYSCLK_HZ
    );

    // embassy sets up SPI1's pins, bus and kernel clocks; the transfers are
    // frame_reader's.
    let mut spi_cfg = spi::Config::default();
    spi_cfg.frequency = Hertz(SPI_HZ);
    let spi = spi::Spi::new_blocking_rxonly(pins.spi, pins.sck, pins.miso, spi_cfg);
    core::mem::forget(spi);
    let cs = Output::new(pins.cs, Level::High, Speed::VeryHigh);
    let reader = FrameReader::new(SPI_DIV, READ_TIMEOUT_US, cs);
    READER.lock(|r| r.replace(Some(reader)));

    let mut uart_cfg = usart::Config::default();
    uart_cfg.baudrate = BAUD;
    let uart = match UartTx::new(pins.uart, pins.uart_tx, pins.uart_tx_dma, Irqs, uart_cfg) {
        Ok(u) => u,
        Err(_) => defmt::panic!("USART3 refuses {} baud", BAUD),
    };

    // SAFETY: handed out here, once, before any task runs. The square
    // kernels' f64 factorisation runs before the watchdog starts.
    let factors = unsafe { &mut *FACTORS.0.get() };
    factors.fill(0);
    let Ok(tables) = TABLES.with_factors(factors) else {
        defmt::panic!("the square kernels' factors cannot be built")
    };

    let mut wdg = IndependentWatchdog::new(pins.iwdg, WATCHDOG_US);
    wdg.unleash();

    QUEUE.lock(|q| q.borrow_mut().set_reserve(KEEP_RESERVE));
    // SAFETY: written here, once, before any task runs; read-only after.
    let scorer: &'static Scorer = unsafe { (*SCORER.0.get()).write(tables) };
    // SAFETY: the row buffers are handed out here, once, before any task runs.
    let (axi, sram123) = unsafe { (&mut *ROWS_AXI.0.get(), &mut *ROWS_SRAM123.0.get()) };
    // SRAM1..3 is NOLOAD: start from a known state.
    sram123.fill(0);
    let (row_a, rest) = axi.split_at_mut(ROW_WORDS);
    let row_b = if ROWS_IN_AXI { rest } else { sram123 };
    let settings = Settings {
        cols: COLS as u32,
        threshold: scorer.threshold_from_units(THRESHOLD_UNITS),
        power_threshold: cvm_core::power::threshold_from_units(POWER_THRESHOLD_UNITS),
        scores: SCORES,
        max_defect_lines_per_row: MAX_DEFECT_LINES_PER_ROW,
        firmware_version: FIRMWARE_VERSION,
        reset_cause: cause,
        boots,
    };
    // SAFETY: handed out here, once, before any task runs; `.dtcm` is
    // NOLOAD, so it is cleared first (an `i32` may hold any bits, but a
    // known start keeps runs reproducible).
    let near: &mut [i32; NEAR_WORDS] = unsafe {
        let p = NEAR.0.get().cast::<[i32; NEAR_WORDS]>();
        core::ptr::write_bytes(p, 0, 1);
        &mut *p
    };
    let pipeline = match Pipeline::<MAX_COLS>::with_near(scorer, settings, row_a, row_b, near) {
        Ok(p) => p,
        Err(e) => defmt::panic!("pipeline refused its buffers: {}", e),
    };
    // SAFETY: written here, once, before any task runs; only the scoring
    // task uses it after.
    let driver = unsafe { (*DRIVER.0.get()).write(ScanDriver::new(pipeline, COLS as u32, ROWS)) };

    let drdy = ExtiInput::new_blocking(pins.drdy, pins.drdy_exti, Pull::Down, TriggerEdge::Rising);
    let mask = ExtiGroupMask::new(&[&drdy]);
    let line_sync = Input::new(pins.line_sync, Pull::Down);
    DRDY_IO.lock(|io| {
        io.replace(Some(DrdyIo {
            _drdy: drdy,
            mask,
            line_sync,
        }))
    });

    interrupt::EXTI9_5.set_priority(IrqPriority::P5);
    // SAFETY: the handler only touches the mutex-protected statics above.
    unsafe { interrupt::EXTI9_5.enable() };

    let executor = EXECUTOR.init(Executor::new());
    executor.run(|spawner| match (uart_task(uart), score_task(driver, wdg)) {
        (Ok(u), Ok(s)) => {
            spawner.spawn(u);
            spawner.spawn(s);
        }
        _ => defmt::panic!("thread tasks already running"),
    })
}
