//! The command channel on the board: the command task (received lines to
//! `cvm_fw_app::control`, replies into their own queue, which the UART
//! task sends between result lines), the store task (writes to flash
//! without holding up requests), and the restart.
//!
//! Both tasks run in thread mode beside the scoring task and never hold
//! it: a request is a few thousand instructions at most, the settings it
//! changes rest in the control until the scoring task's runtime takes them
//! between scans, and flash writes yield while the flash is busy. Replies have a queue of their own, so
//! no reply takes room that result lines rely on, and a flood of requests
//! waits in the receive ring (then overruns, refused as such) instead of
//! delaying a beam.

use core::sync::atomic::Ordering;

use cvm_core::command::{Event, IDLE_GAP_MS, LineReader, LinkError, Refusal};
use cvm_fw_app::control::Effect;
use cvm_fw_app::queue::QueueSink;
use embassy_time::{Duration, Timer, with_timeout};

use super::command_rx::{self, Rx};
use super::resources::Resources;
use super::settings_store;

/// Waits until a request's replies fit the reply queue.
async fn wait_for_reply_room(r: Resources) {
    while !r.replies.lock(|q| q.borrow().keep_room()) {
        r.kick.signal(());
        r.room.wait().await;
    }
}

#[embassy_executor::task]
pub async fn command_task(r: Resources) {
    let control = r.control;
    let mut reader = LineReader::new();
    let mut sink = QueueSink(r.replies);
    loop {
        // A damaged line ends at an idle gap too: its `\n` may have been
        // lost with the overrun, and the next request must not be joined
        // to it (docs/commands.md, "Framing").
        if reader.damaged_pending() {
            let gap = Duration::from_millis(IDLE_GAP_MS as u64);
            if with_timeout(gap, r.rx_ready.wait()).await.is_err() {
                if let Some(Event::Damaged(e)) = reader.idle() {
                    wait_for_reply_room(r).await;
                    control.borrow_mut().damaged(e.refusal(), &mut sink);
                    r.kick.signal(());
                }
                continue;
            }
        } else {
            r.rx_ready.wait().await;
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
                        wait_for_reply_room(r).await;
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
            r.kick.signal(());
            match effect {
                Effect::None => {}
                Effect::Save { id, values } => r.save.signal((id, values)),
                Effect::Reset => restart(r).await,
            }
            // One request at a time, then the scoring task's turn.
            embassy_futures::yield_now().await;
        }
    }
}

#[embassy_executor::task]
pub async fn store_task(r: Resources) {
    let mut sink = QueueSink(r.replies);
    loop {
        let (id, values) = r.save.wait().await;
        let ok = settings_store::save(&values).await.is_ok();
        r.control.borrow_mut().saved(id, ok, &mut sink);
        r.kick.signal(());
    }
}

/// Restarts once the `reset` reply has left and the line on the wire is
/// whole: no result line starts after the request (`RESTARTING`), the
/// reply queue is drained and the UART task is between lines, then the
/// UART's FIFO has its time (a longest line's, 280 bytes at 921 600 baud
/// take 3.04 ms, with room to spare).
async fn restart(r: Resources) -> ! {
    r.restarting.store(true, Ordering::Release);
    super::failsafe::drive();
    while !r.replies.lock(|q| q.borrow().is_empty()) || r.sending.load(Ordering::Acquire) {
        r.kick.signal(());
        Timer::after(Duration::from_micros(500)).await;
    }
    Timer::after(Duration::from_millis(4)).await;
    defmt::info!("restart requested on the command channel");
    cortex_m::peripheral::SCB::sys_reset()
}
