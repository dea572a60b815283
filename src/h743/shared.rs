//! What the interrupts and the two tasks share: the acquisition log, the
//! frame buffers, the output queue and the signals between them.

use core::cell::RefCell;
use core::sync::atomic::AtomicBool;

use cvm_fw_app::acquire::Acquisition;
use cvm_fw_app::queue::LineQueue;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, ThreadModeRawMutex};
use embassy_sync::signal::Signal;

use crate::config::BEAM_LOG;
use crate::config::h743::{CORE, FRAME_BUFFERS, FRAME_SAMPLES, QUEUE_BYTES};
use crate::frames::SampleBuffers;
use crate::sink::SharedQueue;

/// Samples per map, read into each frame buffer.
pub const CELLS: usize = CORE.geometry.cells();

type Acq = Acquisition<FRAME_BUFFERS, BEAM_LOG>;

/// Beams and frame buffers, between the DRDY and end-of-read interrupts
/// and the scoring task.
pub static ACQ: Mutex<CriticalSectionRawMutex, RefCell<Acq>> = Mutex::new(RefCell::new(Acq::new()));
/// Filled by DMA1, so in AXI SRAM (DMA1 cannot reach the TCMs); NOLOAD,
/// as every buffer is written before it is read.
#[unsafe(link_section = ".dma_buffers")]
pub static FRAMES: SampleBuffers<FRAME_BUFFERS, FRAME_SAMPLES> = SampleBuffers::new();
/// Zero-initialised (`.bss`, not the whole queue as `.data` in flash); `main` sets
/// its reserve before any task runs.
pub static QUEUE: SharedQueue<QUEUE_BYTES> =
    Mutex::new(RefCell::new(LineQueue::<QUEUE_BYTES>::new(0)));

/// Acquisition -> scoring: beam records are waiting.
pub static BEAMS: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// Scoring -> UART: lines are waiting.
pub static KICK: Signal<ThreadModeRawMutex, ()> = Signal::new();
/// UART -> scoring: room was made.
pub static ROOM: Signal<ThreadModeRawMutex, ()> = Signal::new();

/// Command task -> UART task and outputs: a commanded restart is coming.
/// The UART sends replies only, so that no result line is cut, and the
/// outputs hold "not ready" and "reject": the scan under way will not be
/// reported, so nothing may say it passed.
pub static RESTARTING: AtomicBool = AtomicBool::new(false);

/// UART task -> command task: a line is being written.
pub static SENDING: AtomicBool = AtomicBool::new(false);
