//! Link-time proof that nothing reachable from the per-beam path can panic.
//!
//! `_start` runs that path the way the firmware does, every input hidden
//! from the optimiser behind `black_box`: a frame buffer's samples →
//! `Pipeline::push` (normalise → embed → window → gradient → decision →
//! encode) or `mark_missing`, `begin` and `finish`, for paper and square
//! kernels, normalised or raw, with a calibrator attached or not (armed,
//! taking rows, and its result); and around it the scoring side's loop,
//! `cvm_fw_app::runtime`: DRDY/buffer accounting, LINE_SYNC sequencing,
//! the output queue, settings taken from the command channel's control
//! between scans, READY and REJECT's logic and a scan's report to the
//! control (a calibration's end and reply). The panic handler calls `cvm_panic_path_reachable`, which no
//! object defines: after LTO and dead-code removal the link succeeds only
//! if no panic call is left anywhere in the image.
#![no_std]
#![no_main]

use core::hint::black_box;
use core::panic::PanicInfo;

use core::cell::RefCell;
use cvm_core::Scorer;
use cvm_core::calibration::{Calibrator, Rule};
use cvm_core::config::{Config, Geometry, Kernels, MAX_J, Weights};
use cvm_core::pipeline::{Pipeline, Settings};
use cvm_core::protocol::{LineSink, MAX_LINE, Priority};
use cvm_core::scorer::MAX_FACTOR_WORDS;
use cvm_core::stream::{Position, row_words};

use cvm_core::command::Capacity;
use cvm_core::settings::{KEYS, Outputs, Store};
use cvm_fw_app::acquire::Acquisition;
use cvm_fw_app::control::Control;
use cvm_fw_app::driver::{CountingSink, ScanDriver};
use cvm_fw_app::frames::{Beams, SampleBuffers, SharedLog};
use cvm_fw_app::outputs::{Asserted, Change};
use cvm_fw_app::queue::LineQueue;
use cvm_fw_app::runtime::Runtime;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::NoopRawMutex;

unsafe extern "C" {
    /// Defined nowhere: a reference to it is a link error naming it.
    fn cvm_panic_path_reachable() -> !;
}

#[panic_handler]
fn panic(_: &PanicInfo) -> ! {
    unsafe { cvm_panic_path_reachable() }
}

/// The firmware's geometry and capacity (docs/method.md §5: 300 columns, 15x15).
const MAX_COLS: usize = 300;
const WORDS: usize = row_words(MAX_COLS, MAX_J, MAX_J);
const CELLS: usize = MAX_J * MAX_J;

const fn scorer(cfg: Config) -> Scorer {
    match Scorer::new(&cfg) {
        Ok(s) => s,
        Err(_) => panic!("configuration refused"),
    }
}

const fn config(kernels: Kernels, normalise: bool) -> Config {
    let g = match Geometry::new(15, 15) {
        Ok(g) => g,
        Err(_) => panic!("geometry refused"),
    };
    Config {
        geometry: g,
        kernels,
        weights: Weights::Uniform,
        normalise,
        full_scale: 4095,
    }
}

static PAPER: Scorer = scorer(config(Kernels::Paper { bmax: 0 }, true));
static SQUARE: Scorer = scorer(config(Kernels::Square { kmax: 14 }, false));

static mut ROW_A: [i32; WORDS] = [0; WORDS];
static mut ROW_B: [i32; WORDS] = [0; WORDS];
/// The current row's last three maps (`Pipeline::with_near`); handed out
/// whole or empty, as the
/// optimiser cannot tell, so both ways are linked.
static mut NEAR: [i32; 3 * CELLS] = [0; 3 * CELLS];
/// The square kernels' factor table, built at start-up (its f64
/// factorisation is checked here too).
static mut FACTORS: [i32; MAX_FACTOR_WORDS] = [0; MAX_FACTOR_WORDS];
static mut QUEUE: LineQueue<8192> = LineQueue::new(4096);
static mut BUS: [[u16; CELLS]; 2] = [[0; CELLS]; 2];
static mut CALIBRATOR: Calibrator = Calibrator::new();
static mut REPLIES: LineQueue<8192> = LineQueue::new(1024);
/// The frame buffers the runtime reads through `frames::Beams`.
static SAMPLES: SampleBuffers<2, CELLS> = SampleBuffers::new();

const CAPACITY: Capacity = Capacity {
    max_cols: MAX_COLS as u16,
    max_rows: u16::MAX,
    max_dcap: 16,
    max_pulse_us: 1 << 16,
};

/// READY and REJECT, as the H743 writes them: opaque here.
struct Pins;

impl cvm_fw_app::runtime::Pins for Pins {
    fn change(&mut self, change: Change) {
        black_box(change);
    }

    fn configure(&mut self, settings: &Outputs, now: Asserted) {
        black_box((settings, now));
    }
}

/// The output queue as the line sink, as on the boards.
struct Sink<'q>(&'q mut LineQueue<8192>);

impl LineSink for Sink<'_> {
    fn line(&mut self, line: &[u8], priority: Priority) {
        self.0.push(line, priority);
    }
}

impl CountingSink for Sink<'_> {
    fn dropped(&self) -> u32 {
        self.0.dropped()
    }
}

#[unsafe(no_mangle)]
pub extern "C" fn _start() -> ! {
    // SAFETY: `_start` runs once and is the only user of `FACTORS`.
    let factors = unsafe { &mut *core::ptr::addr_of_mut!(FACTORS) };
    let square = match black_box(SQUARE.clone()).with_factors(factors) {
        Ok(s) => s,
        Err(_) => loop {
            black_box(());
        },
    };
    let scorer: &Scorer = if black_box(true) { &PAPER } else { &square };
    let settings = Settings {
        cols: black_box(300),
        threshold: black_box(1 << 20),
        power_threshold: black_box(3277),
        // Any value: off, measured only, or deciding.
        spread_threshold: black_box(6554),
        scores: black_box(true),
        max_defect_lines_per_row: black_box(8),
        rows: black_box(100),
        outputs: cvm_core::settings::Outputs::DEFAULT,
        sources: [cvm_core::settings::Source::Default; cvm_core::settings::KEYS],
    };
    let boot = cvm_core::Boot {
        firmware: "nopanic",
        reset_cause: cvm_core::protocol::ResetCause::Watchdog,
        boots: black_box(2),
        store: cvm_core::settings::Store::Empty,
    };
    // SAFETY: `_start` runs once and is the only user of these statics.
    let (row_a, row_b, near, queue, bus, calibrator, replies) = unsafe {
        (
            &mut *core::ptr::addr_of_mut!(ROW_A),
            &mut *core::ptr::addr_of_mut!(ROW_B),
            &mut *core::ptr::addr_of_mut!(NEAR),
            &mut *core::ptr::addr_of_mut!(QUEUE),
            &mut *core::ptr::addr_of_mut!(BUS),
            &mut *core::ptr::addr_of_mut!(CALIBRATOR),
            &mut *core::ptr::addr_of_mut!(REPLIES),
        )
    };
    let near = near.get_mut(..black_box(0)).unwrap_or_default();
    let Ok(mut pipeline) = Pipeline::<MAX_COLS>::with_near(scorer, settings, row_a, row_b, near)
    else {
        loop {
            black_box(());
        }
    };
    pipeline.set_boot(boot);
    if black_box(true) {
        pipeline.attach_calibrator(calibrator);
    }
    let mut sink = Sink(queue);
    let mut line = [0u8; MAX_LINE];

    // The per-beam path on its own.
    loop {
        let samples: &[u16] = black_box(&bus[0][..]);
        let n = black_box(scorer.cells());
        let pos = Position {
            row: black_box(0),
            col: black_box(0),
        };
        match black_box(0u8) {
            0 => {
                if let Some(frame) = samples.get(..n) {
                    black_box(pipeline.push(pos, frame, &mut sink));
                } else {
                    black_box(pipeline.mark_missing(pos, &mut sink));
                }
            }
            1 => pipeline.begin(&mut sink),
            2 => {
                black_box(pipeline.finish(black_box(0), &mut sink));
            }
            3 => break,
            4 => {
                if let Some(c) = pipeline.calibrator_mut() {
                    c.arm(black_box(5));
                }
            }
            5 => {
                let rule = if black_box(true) {
                    Rule::Spread {
                        quantile_ppm: black_box(1_000_000),
                        k_milli: black_box(3000),
                    }
                } else {
                    Rule::Tail {
                        rate_ppm: black_box(1000),
                        tail_ppm: black_box(10_000),
                    }
                };
                if let Some(c) = pipeline.calibrator() {
                    black_box(c.progress());
                    black_box(c.finish(&rule).ok());
                }
            }
            _ => {
                black_box(sink.0.pop_into(&mut line));
            }
        }
    }

    // The scoring side's loop as the boards run it: the runtime's steps
    // over the shared log, frame buffers and queue, with the command
    // channel's control and the outputs' logic and pins.
    let log: SharedLog<NoopRawMutex, 2, 64> = Mutex::new(RefCell::new(Acquisition::new()));
    let mut beams = Beams {
        log: &log,
        bufs: &SAMPLES,
        cells: black_box(CELLS),
    };
    let control = RefCell::new(Control::new(
        settings,
        cvm_core::Boot {
            store: black_box(Store::Loaded),
            ..boot
        },
        black_box(CAPACITY),
        (15, 15),
        black_box(Some([0; KEYS])),
    ));
    let mut driver = ScanDriver::new(pipeline, black_box(300), black_box(300));
    let outputs = cvm_fw_app::outputs::OutputLogic::start(
        black_box(cvm_core::Outputs::DEFAULT),
        black_box(cvm_core::protocol::ResetCause::PowerOn),
    );
    let mut runtime = Runtime::new(&mut driver, outputs, Pins, Some(&control));
    let mut replies = Sink(replies);
    loop {
        match black_box(0u8) {
            0 => {
                black_box(log.lock(|a| {
                    a.try_borrow_mut()
                        .ok()
                        .and_then(|mut a| a.drdy(black_box(false)))
                }));
            }
            1 => log.lock(|a| {
                if let Ok(mut a) = a.try_borrow_mut() {
                    a.read_done(black_box(0), black_box(true));
                }
            }),
            2 => {
                if sink.0.keep_room() {
                    black_box(runtime.step(&mut beams, &mut sink, &mut replies));
                }
            }
            3 => {
                black_box(runtime.end_of_data(&mut beams, &mut sink, &mut replies));
            }
            _ => {
                black_box(sink.0.pop_into(&mut line));
                black_box(replies.0.pop_into(&mut line));
            }
        }
    }
}
