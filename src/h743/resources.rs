//! What the interrupts and the tasks share, in one place: the acquisition
//! log and the frame buffers, the two line queues, the command channel's
//! control, and the signals and flags between them. `main` hands the tasks
//! a [`Resources`] of references to them ([`take`]); interrupt handlers,
//! which take no arguments, name the statics. (A driver's own state, which
//! only its module and its interrupt touch, stays in that module: the
//! frame reader, DRDY's pins, the receive ring, REJECT's pulses, the
//! flash's waker; so does the scoring side's memory, `scoring`.)

use core::cell::RefCell;
use core::sync::atomic::{AtomicBool, Ordering};

use cvm_core::settings::KEYS;
use cvm_fw_app::control::Control;
use cvm_fw_app::frames::{SampleBuffers, SharedLog};
use cvm_fw_app::queue::{LineQueue, SharedQueue};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, ThreadModeRawMutex};
use embassy_sync::signal::Signal;
use static_cell::StaticCell;

use crate::config::BEAM_LOG;
use crate::config::h743::{CORE, FRAME_BUFFERS, FRAME_SAMPLES, KEEP_RESERVE, QUEUE_BYTES};

/// Samples per map, read into each frame buffer.
pub const CELLS: usize = CORE.geometry.cells();

/// Bytes of the reply queue: a `status` reply (16 lines, about 600
/// bytes) twice over, and then some.
pub const REPLY_BYTES: usize = 2048;
/// Room a request may need for its replies (`status`, the longest):
/// the reply queue's reserve, which [`take`] sets (a static built with it
/// would be an initial value in flash).
pub const REPLY_ROOM: usize = 768;

pub type Log = SharedLog<CriticalSectionRawMutex, FRAME_BUFFERS, BEAM_LOG>;
pub type Frames = SampleBuffers<FRAME_BUFFERS, FRAME_SAMPLES>;
pub type Queue = SharedQueue<ThreadModeRawMutex, QUEUE_BYTES>;
pub type Replies = SharedQueue<ThreadModeRawMutex, REPLY_BYTES>;
/// A wake-up between thread-mode tasks.
pub type Wake = Signal<ThreadModeRawMutex, ()>;
/// A `save`: its request's id and the values.
pub type Save = Signal<ThreadModeRawMutex, (u32, [u32; KEYS])>;

/// Beams and frame buffers, between the DRDY and end-of-read interrupts
/// and the scoring task.
pub static ACQ: Log = Mutex::new(RefCell::new(cvm_fw_app::acquire::Acquisition::new()));
/// Filled by DMA1, so in AXI SRAM (DMA1 cannot reach the TCMs); NOLOAD,
/// as every buffer is written before it is read.
#[unsafe(link_section = ".dma_buffers")]
pub static FRAMES: Frames = SampleBuffers::new();
/// Acquisition -> scoring: beam records are waiting.
pub static BEAMS: Signal<CriticalSectionRawMutex, ()> = Signal::new();

/// Result lines, scoring -> UART. Zero-initialised (`.bss`, not the whole
/// queue as `.data` in flash); [`take`] sets its reserve.
static QUEUE: Queue = Mutex::new(RefCell::new(LineQueue::<QUEUE_BYTES>::new(0)));
/// Replies, command and store tasks (and a calibration's end, from the
/// scoring task) -> UART.
static REPLIES: Replies = Mutex::new(RefCell::new(LineQueue::<REPLY_BYTES>::new(0)));
/// Scoring and command side -> UART: lines are waiting.
static KICK: Wake = Signal::new();
/// UART -> scoring and command side: room was made.
static ROOM: Wake = Signal::new();

/// Command task -> UART task and outputs (TIM14's interrupt too): a
/// commanded restart is coming. The UART sends replies only, so that no
/// result line is cut, and the outputs hold "not ready" and "reject": the
/// scan under way will not be reported, so nothing may say it passed.
pub static RESTARTING: AtomicBool = AtomicBool::new(false);
/// UART task -> command task: a line is being written.
static SENDING: AtomicBool = AtomicBool::new(false);

/// USART3's receiver -> command task: a line end, an error, or the
/// receive ring half full.
pub static RX_READY: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// Command task -> store task: a `save`.
static SAVE: Save = Signal::new();
/// The command channel's settings and state: the command and store tasks
/// change them, the scoring task takes them between scans.
static CONTROL: StaticCell<RefCell<Control>> = StaticCell::new();

/// The tasks' share of the statics above.
#[derive(Clone, Copy)]
pub struct Resources {
    pub log: &'static Log,
    pub frames: &'static Frames,
    pub beams: &'static Signal<CriticalSectionRawMutex, ()>,
    pub queue: &'static Queue,
    pub replies: &'static Replies,
    pub kick: &'static Wake,
    pub room: &'static Wake,
    pub restarting: &'static AtomicBool,
    pub sending: &'static AtomicBool,
    pub rx_ready: &'static Signal<CriticalSectionRawMutex, ()>,
    pub save: &'static Save,
    pub control: &'static RefCell<Control>,
}

/// The resources, once (`main`, before any task runs): `control` in its
/// cell, the queues' reserves set.
pub fn take(control: Control) -> Resources {
    let control: &'static RefCell<Control> = CONTROL.init(RefCell::new(control));
    QUEUE.lock(|q| q.borrow_mut().set_reserve(KEEP_RESERVE));
    REPLIES.lock(|q| q.borrow_mut().set_reserve(REPLY_ROOM));
    Resources {
        log: &ACQ,
        frames: &FRAMES,
        beams: &BEAMS,
        queue: &QUEUE,
        replies: &REPLIES,
        kick: &KICK,
        room: &ROOM,
        restarting: &RESTARTING,
        sending: &SENDING,
        rx_ready: &RX_READY,
        save: &SAVE,
        control,
    }
}

impl Resources {
    /// A commanded restart is coming (see [`RESTARTING`]).
    pub fn restarting(&self) -> bool {
        self.restarting.load(Ordering::Acquire)
    }
}
