//! The NUCLEO-H743ZI2 board.
//!
//! Two levels:
//!
//! - **Interrupts** (one priority, so none preempts another):
//!   - DRDY (EXTI9_5, `drdy`): samples LINE_SYNC, records the beam in the
//!     `Acquisition` log and, when a frame buffer is free and the SPI idle,
//!     starts reading the frame into it (`frame_reader`: CS low, SPI1 with
//!     DMA1 stream 1, the read's deadline on TIM13). Every edge is counted
//!     here, even while the SPI or the scoring side is busy.
//!   - End of the read (DMA1 stream 1: complete or error; TIM13: the
//!     deadline): CS high, the result (or overrun, DMA error, timeout, mode
//!     fault) into the log, the scoring task woken.
//! - **Thread mode** (`tasks`, `commands`): the scoring task (steps of
//!   `cvm_fw_app::runtime`: sequencing, `cvm_core::Pipeline`, lines into
//!   the bounded queue, READY and REJECT, settings between scans; around
//!   them watchdog feeding and the idle end of a scan), the UART task
//!   (USART3 TX with DMA from the queues), the command task and the store
//!   task. The scoring task yields every few beams, so the UART task and
//!   the watchdog feed never wait for a backlog to be scored.
//!
//! What they share is in `resources`, which `main` hands to the tasks;
//! where the scoring side's memory lives, and why, in `scoring`. The
//! runtime drives READY and REJECT through `outputs` (TIM14 times
//! REJECT's pulses).
//!
//! D-cache: left disabled (only the I-cache is enabled), so DMA buffers in
//! AXI SRAM need no cache maintenance. DMA only touches statics in AXI SRAM
//! (frame buffers, the UART line buffer), never the DTCM stack.

mod clocks;
mod command_rx;
mod commands;
mod drdy;
mod failsafe;
mod flash_bank2;
mod frame_reader;
mod memory;
mod outputs;
mod pins;
mod read_deadline;
mod resets;
mod resources;
mod scoring;
mod settings_store;
mod tasks;

use cortex_m_rt::entry;
use cvm_core::command::Capacity;
use cvm_core::protocol::ResetCause;
use cvm_fw_app::control::Control;
use cvm_fw_app::outputs::OutputLogic;
use cvm_fw_app::runtime::Runtime;
use defmt::info;
use defmt_rtt as _;
use embassy_executor::Executor;
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::mode::Async;
use embassy_stm32::peripherals::{DMA1_CH2, IWDG1, PD8, USART3};
use embassy_stm32::usart::{self, UartTx};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{Peri, bind_interrupts, dma, interrupt};
use static_cell::StaticCell;

use crate::config::MAX_DEFECT_LINES_PER_ROW;
use crate::config::h743::{
    BAUD, COLS, CORE, FIRMWARE_VERSION, J1, J2, MAX_COLS, ROWS, SCORES, SPI_HZ, SYSCLK_HZ,
    THRESHOLD_UNITS, WATCHDOG_US,
};
use commands::{command_task, store_task};
use tasks::{score_task, uart_task};

/// What the command channel may set (docs/commands.md, "Settings"):
/// columns up to the row buffers' size, defect lines up to what the
/// queue's reserve is sized for, pulses up to TIM14's 16-bit count.
const CAPACITY: Capacity = Capacity {
    max_cols: MAX_COLS as u16,
    max_rows: u16::MAX,
    max_dcap: MAX_DEFECT_LINES_PER_ROW,
    max_pulse_us: 1 << 16,
};
const _: () = assert!(MAX_COLS <= u16::MAX as usize);

bind_interrupts!(struct Irqs {
    DMA1_STREAM2 => dma::InterruptHandler<DMA1_CH2>;
});

static EXECUTOR: StaticCell<Executor> = StaticCell::new();

#[entry]
fn main() -> ! {
    // READY and REJECT to "not ready" and "reject" before anything else
    // (docs/firmware.md, "Fail-safe").
    failsafe::at_reset();
    memory::load_dtcm_rodata();
    let mut core = cortex_m::Peripherals::take()
        .unwrap_or_else(|| defmt::panic!("core peripherals taken twice"));
    core.SCB.enable_icache();
    let p = embassy_stm32::init(clocks::config());
    // init enables EXTI9_5 in the NVIC; DRDY must not interrupt before
    // the reader is installed (`drdy::enable`, at the end).
    interrupt::EXTI9_5.disable();
    resets::freeze_watchdog_in_debug();
    let cause = resets::take_cause();
    let boots = resets::count_boot(cause);
    memory::enable_sram123();
    let pins = pins::take(p);
    log_start(cause, boots);
    // The watchdog runs from here, through the store's start-up repair
    // (a sector erase: up to 2 s), which feeds it.
    let mut wdg = IndependentWatchdog::new(pins.iwdg, WATCHDOG_US);
    wdg.unleash();

    frame_reader::install(pins.spi, pins.sck, pins.miso, pins.cs);
    let uart = uart(pins.uart, pins.uart_tx, pins.uart_tx_dma);
    command_rx::enable(pins.uart_rx);
    // The settings record before the first scan: the scans and the
    // outputs start with the settings in effect.
    settings_store::open(pins.flash, pins.flash_dma);
    let (store, record, cut) = block_on_fed(settings_store::load(), &mut wdg);
    let boot = scoring::boot(cause, boots, store);
    let control = Control::new(
        scoring::compiled_settings(),
        boot,
        CAPACITY,
        (J1, J2),
        record,
    );
    let settings = *control.settings();
    info!("settings record: {}", store);
    let r = resources::take(control);
    let driver = scoring::scan_driver(settings);
    // A power-on is a clean start only when the flash shows nothing cut
    // short; otherwise the outputs start as after any other reset: not
    // judged (the header still says `por`).
    let start = if cut && cause == ResetCause::PowerOn {
        ResetCause::Other
    } else {
        cause
    };
    let outputs = OutputLogic::start(settings.outputs, start);
    let plc = outputs::PlcOutputs::new(pins.outputs, outputs.asserted(), &settings.outputs);
    let runtime = Runtime::new(driver, outputs, plc, Some(r.control));
    wdg.pet();
    drdy::enable(pins.drdy, pins.drdy_exti, pins.line_sync);

    let executor = EXECUTOR.init(Executor::new());
    executor.run(|spawner| {
        match (
            uart_task(uart, r),
            score_task(runtime, wdg, r),
            command_task(r),
            store_task(r),
        ) {
            (Ok(u), Ok(s), Ok(c), Ok(f)) => {
                spawner.spawn(u);
                spawner.spawn(s);
                spawner.spawn(c);
                spawner.spawn(f);
            }
            _ => defmt::panic!("thread tasks already running"),
        }
    })
}

/// Runs `f` to its end before the executor starts, feeding the watchdog
/// each time it waits (the store's flash waits return to here).
fn block_on_fed<F: core::future::Future>(
    f: F,
    wdg: &mut IndependentWatchdog<'_, IWDG1>,
) -> F::Output {
    let mut f = core::pin::pin!(f);
    let mut cx = core::task::Context::from_waker(core::task::Waker::noop());
    loop {
        if let core::task::Poll::Ready(v) = f.as_mut().poll(&mut cx) {
            return v;
        }
        wdg.pet();
        if flash_bank2::busy() {
            // An erase (up to 2 s) or a flash word: sleep until its end's
            // interrupt, or the time driver's next one (every 33 ms at
            // most), which feeds the watchdog again.
            cortex_m::asm::wfe();
        }
    }
}

/// USART3 at `BAUD`, transmit only (the ST-LINK's virtual COM port).
fn uart(
    uart: Peri<'static, USART3>,
    tx: Peri<'static, PD8>,
    dma: Peri<'static, DMA1_CH2>,
) -> UartTx<'static, Async> {
    let mut cfg = usart::Config::default();
    cfg.baudrate = BAUD;
    match UartTx::new(uart, tx, dma, Irqs, cfg) {
        Ok(u) => u,
        Err(_) => defmt::panic!("USART3 refuses {} baud", BAUD),
    }
}

fn log_start(cause: ResetCause, boots: u32) {
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
}
