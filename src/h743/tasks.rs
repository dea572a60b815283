//! The two tasks, both in thread mode: scoring and UART. (Frames are read
//! from interrupts: `frame_reader`.)

use core::sync::atomic::Ordering;

use cvm_core::protocol::MAX_LINE;
use cvm_fw_app::driver::ScanDriver;
use cvm_fw_app::frames::Beams;
use cvm_fw_app::queue::QueueSink;
use cvm_fw_app::runtime::Runtime;
use defmt::{error, info, warn};
use embassy_stm32::mode::Async;
use embassy_stm32::peripherals::IWDG1;
use embassy_stm32::usart::UartTx;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_time::{Duration, Instant, with_timeout};

use super::memory::Noload;
use super::outputs::PlcOutputs;
use super::resources::{CELLS, Resources};
use crate::config::h743::{FEED_MS, IDLE_END_MS, MAX_COLS, SCORE_BURST};

/// The scoring side of this board: the runtime over its scan driver (in
/// DTCM), READY and REJECT.
pub type BoardRuntime = Runtime<'static, 'static, MAX_COLS, PlcOutputs>;

/// The DMA source of the line being sent: in AXI SRAM, which DMA1
/// reaches, not on the DTCM stack, which it does not.
#[unsafe(link_section = ".dma_buffers")]
static TX_LINE: Noload<[u8; MAX_LINE]> = Noload::new();

/// Sends queued lines with DMA.
#[embassy_executor::task]
pub async fn uart_task(mut uart: UartTx<'static, Async>, r: Resources) {
    let mut errors: u32 = 0;
    // SAFETY: this task is TX_LINE's only user, and its pool holds one.
    let line = unsafe { TX_LINE.take_zeroed() };
    loop {
        // Replies first: they are few and short, and a host waits for them.
        // Before a commanded restart, replies only: a result line begun
        // now would be cut.
        let n = r
            .replies
            .lock(|q| q.borrow_mut().pop_into(line))
            .or_else(|| {
                if r.restarting() {
                    None
                } else {
                    r.queue.lock(|q| q.borrow_mut().pop_into(line))
                }
            });
        let Some(n) = n else {
            r.kick.wait().await;
            continue;
        };
        r.room.signal(());
        // Set and cleared with no await between pop and write: the
        // command task sees a line in flight exactly while it is.
        r.sending.store(true, Ordering::Release);
        let written = uart.write(&line[..n]).await;
        r.sending.store(false, Ordering::Release);
        if written.is_err() {
            errors = errors.wrapping_add(1);
            warn!(
                "USART3 TX error ({} so far): a result line was lost",
                errors
            );
        }
    }
}

/// Waits until the queue has its keep reserve free: scoring waits for the
/// UART while acquisition keeps counting beams.
async fn wait_for_room(wdg: &mut IndependentWatchdog<'static, IWDG1>, r: Resources) {
    while !r.queue.lock(|q| q.borrow().keep_room()) {
        r.kick.signal(());
        let _ = with_timeout(Duration::from_millis(FEED_MS), r.room.wait()).await;
        wdg.pet();
    }
}

/// Scores the beams as they come: the runtime's steps, with the waits
/// for queue room, the watchdog's feeding, a yield every few beams and
/// the idle end of a scan around them.
#[embassy_executor::task]
pub async fn score_task(
    mut runtime: BoardRuntime,
    mut wdg: IndependentWatchdog<'static, IWDG1>,
    r: Resources,
) {
    let mut beams = Beams {
        log: r.log,
        bufs: r.frames,
        cells: CELLS,
    };
    let mut burst = 0u32;
    let mut lines = QueueSink(r.queue);
    let mut replies = QueueSink(r.replies);
    let mut last_beam = Instant::now();
    let mut idle_ended = true;
    let mut reported = r.log.lock(|a| *a.borrow().counts());

    loop {
        let _ = with_timeout(Duration::from_millis(FEED_MS), r.beams.wait()).await;
        wdg.pet();

        loop {
            wait_for_room(&mut wdg, r).await;
            let now = Instant::now();
            let Some(finished) = runtime.step(&mut beams, &mut lines, &mut replies) else {
                break;
            };
            last_beam = now;
            idle_ended = false;
            if finished {
                // The end line, and a calibration's reply, are queued.
                r.kick.signal(());
                report_scan(runtime.driver(), r);
            }
            // Most beams queue no line (lines come per row): waking the
            // UART task then would only have it find the queue empty.
            if !r.queue.lock(|q| q.borrow().is_empty()) {
                r.kick.signal(());
            }
            // A backlog of beams must not keep the UART task and the
            // watchdog feed waiting: yield every SCORE_BURST steps.
            burst += 1;
            if burst >= SCORE_BURST {
                burst = 0;
                wdg.pet();
                embassy_futures::yield_now().await;
            }
        }

        if !idle_ended && last_beam.elapsed() >= Duration::from_millis(IDLE_END_MS) {
            loop {
                wait_for_room(&mut wdg, r).await;
                let (more, finished) = runtime.end_of_data(&mut beams, &mut lines, &mut replies);
                r.kick.signal(());
                if finished {
                    warn!("no beam for {} ms: scan ended early", IDLE_END_MS);
                    report_scan(runtime.driver(), r);
                }
                if !more {
                    break;
                }
            }
            idle_ended = true;
        }

        let now = r.log.lock(|a| *a.borrow().counts());
        if now.overruns != reported.overruns || now.spi_errors != reported.spi_errors {
            warn!(
                "acquisition: {} overruns, {} SPI/DMA errors so far",
                now.overruns, now.spi_errors
            );
        }
        reported = now;
    }
}

fn report_scan(driver: &ScanDriver<'static, MAX_COLS>, r: Resources) {
    let Some((t, dropped)) = driver.last_scan() else {
        return;
    };
    let s = driver.sequence_counts();
    let a = r.log.lock(|a| *a.borrow().counts());
    let q = r.queue.lock(|q| *q.borrow().counts());
    // A defmt message masks interrupts while it is encoded and written,
    // for longer the more values it carries; interrupts are served between
    // messages. A read that ends while they are held off is taken late,
    // and the next beam is lost if it comes before: hence several short
    // messages (docs/firmware.md, "Beam rate"; the figures in "SPI1
    // configuration and measured costs").
    info!(
        "scan done: rows {} frames {} missing {}",
        t.rows, t.frames, t.missing
    );
    info!(
        "scan done: defects {} dark {} sat {}",
        t.defects, t.dark, t.saturated
    );
    info!(
        "scan done: rejected {} extra {} misplaced {}",
        t.rejected, t.extra, t.misplaced
    );
    info!("scan done: dropped lines {}", dropped);
    info!(
        "since start: beams {} overruns {} spi errors {}",
        a.drdy, a.overruns, a.spi_errors
    );
    info!(
        "since start: short rows {} misplaced {} extra beams {}",
        s.short_rows, s.misplaced, s.extra
    );
    info!(
        "since start: sync missing {} sync extra {} queue high water {} B",
        s.sync_missing, s.sync_extra, q.high_water
    );
    if q.dropped_keep > 0 {
        error!(
            "{} keep lines dropped: the queue reserve is too small",
            q.dropped_keep
        );
    }
}
