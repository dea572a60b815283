//! The command channel on the board: the command task (received lines to
//! `cvm_fw_app::control`, replies into their own queue, which the UART
//! task sends between result lines), the store task (writes to flash
//! without holding up requests), and the restart.
//!
//! Both tasks run in thread mode beside the scoring task and never hold
//! it: a request is a few thousand instructions at most, settings reach
//! the scan driver through one flag it reads per step, and flash writes
//! yield while the flash is busy. Replies have a queue of their own, so
//! no reply takes room that result lines rely on, and a flood of requests
//! waits in the receive ring (then overruns, refused as such) instead of
//! delaying a beam.

use core::cell::RefCell;
use core::sync::atomic::{AtomicBool, Ordering};

use cvm_core::command::{Event, IDLE_GAP_MS, LineReader, LinkError, Refusal};
use cvm_core::settings::KEYS;
use cvm_fw_app::control::{Control, Effect};
use cvm_fw_app::queue::LineQueue;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;
use embassy_sync::signal::Signal;
use embassy_time::{Duration, Timer, with_timeout};

use super::command_rx::{self, RX_READY, Rx};
use super::settings_store;
use super::shared::{KICK, RESTARTING, ROOM, SENDING};
use crate::sink::{QueueSink, SharedQueue};

/// Bytes of the reply queue: a `status` reply (16 lines, about 600
/// bytes) twice over, and then some.
pub const REPLY_BYTES: usize = 2048;
/// Room a request may need for its replies (`status`, the longest):
/// the reply queue's reserve, which `main` sets (a static built with it
/// would be an initial value in flash).
pub const REPLY_ROOM: usize = 768;

pub static REPLIES: SharedQueue<REPLY_BYTES> =
    Mutex::new(RefCell::new(LineQueue::<REPLY_BYTES>::new(0)));

/// Command side -> scoring task: the control has settings or a
/// calibration for the scan driver.
pub static CHANGED: AtomicBool = AtomicBool::new(true);

/// Command task -> store task: a `save` (its id and the values).
static SAVE: Signal<ThreadModeRawMutex, (u32, [u32; KEYS])> = Signal::new();

/// Waits until a request's replies fit the reply queue.
async fn wait_for_reply_room() {
    while !REPLIES.lock(|q| q.borrow().keep_room()) {
        KICK.signal(());
        ROOM.wait().await;
    }
}

#[embassy_executor::task]
pub async fn command_task(control: &'static RefCell<Control>) {
    let mut reader = LineReader::new();
    let mut sink = QueueSink(&REPLIES);
    loop {
        // A damaged line ends at an idle gap too: its `\n` may have been
        // lost with the overrun, and the next request must not be joined
        // to it (docs/commands.md, "Framing").
        if reader.damaged_pending() {
            let gap = Duration::from_millis(IDLE_GAP_MS as u64);
            if with_timeout(gap, RX_READY.wait()).await.is_err() {
                if let Some(Event::Damaged(e)) = reader.idle() {
                    wait_for_reply_room().await;
                    control.borrow_mut().damaged(e.refusal(), &mut sink);
                    KICK.signal(());
                }
                continue;
            }
        } else {
            RX_READY.wait().await;
        }
        while let Some(rx) = command_rx::take() {
            let effect = match rx {
                Rx::Overrun => {
                    reader.error(LinkError::Overrun);
                    continue;
                }
                Rx::Byte(b, e) => {
                    if let Some(e) = e {
                        reader.error(e);
                    }
                    // Replies are written only once there is room for
                    // them; the bytes of a line cost nothing meanwhile.
                    if b == b'\n' {
                        wait_for_reply_room().await;
                    }
                    let mut c = control.borrow_mut();
                    match reader.push(b) {
                        None => continue,
                        Some(Event::Line(l)) => c.line(l, &mut sink),
                        Some(Event::TooLong) => {
                            c.damaged(Refusal::TooLong, &mut sink);
                            Effect::None
                        }
                        Some(Event::Damaged(e)) => {
                            c.damaged(e.refusal(), &mut sink);
                            Effect::None
                        }
                    }
                }
            };
            CHANGED.store(true, Ordering::Release);
            KICK.signal(());
            match effect {
                Effect::None => {}
                Effect::Save { id, values } => SAVE.signal((id, values)),
                Effect::Reset => restart().await,
            }
            // One request at a time, then the scoring task's turn.
            embassy_futures::yield_now().await;
        }
    }
}

#[embassy_executor::task]
pub async fn store_task(control: &'static RefCell<Control>) {
    let mut sink = QueueSink(&REPLIES);
    loop {
        let (id, values) = SAVE.wait().await;
        let ok = settings_store::save(&values).await.is_ok();
        control.borrow_mut().saved(id, ok, &mut sink);
        CHANGED.store(true, Ordering::Release);
        KICK.signal(());
    }
}

/// Restarts once the `reset` reply has left and the line on the wire is
/// whole: no result line starts after the request ([`RESTARTING`]), the
/// reply queue is drained and the UART task is between lines, then the
/// UART's FIFO has its time (a longest line's, 280 bytes at 921 600 baud
/// take 3.04 ms, with room to spare).
async fn restart() -> ! {
    RESTARTING.store(true, Ordering::Release);
    super::failsafe::drive();
    while !REPLIES.lock(|q| q.borrow().is_empty()) || SENDING.load(Ordering::Acquire) {
        KICK.signal(());
        Timer::after(Duration::from_micros(500)).await;
    }
    Timer::after(Duration::from_millis(4)).await;
    defmt::info!("restart requested on the command channel");
    cortex_m::peripheral::SCB::sys_reset()
}
