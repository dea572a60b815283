//! The two tasks, both in thread mode: scoring and UART. (Frames are read
//! from interrupts: `frame_reader`.)

use core::cell::RefCell;
use core::sync::atomic::Ordering;

use cvm_core::calibration::Progress;
use cvm_core::command::Refusal;
use cvm_core::protocol::{LineSink, MAX_LINE, Priority};
use cvm_core::verdict::Ahead;
use cvm_fw_app::control::Control;
use cvm_fw_app::driver::{CountingSink, ScanDriver};
use defmt::{error, info, warn};
use embassy_stm32::mode::Async;
use embassy_stm32::peripherals::IWDG1;
use embassy_stm32::usart::UartTx;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_time::{Duration, Instant, with_timeout};

use super::commands::{CHANGED, REPLIES};
use super::memory::Noload;
use super::outputs::PlcOutputs;
use super::shared::{ACQ, BEAMS, CELLS, FRAMES, KICK, QUEUE, RESTARTING, ROOM, SENDING};
use crate::config::h743::{FEED_MS, IDLE_END_MS, MAX_COLS, SCORE_BURST};
use crate::frames::Samples;
use crate::sink::QueueSink;

/// The DMA source of the line being sent: in AXI SRAM, which DMA1
/// reaches, not on the DTCM stack, which it does not.
#[unsafe(link_section = ".dma_buffers")]
static TX_LINE: Noload<[u8; MAX_LINE]> = Noload::new();

/// Sends queued lines with DMA.
#[embassy_executor::task]
pub async fn uart_task(mut uart: UartTx<'static, Async>) {
    let mut errors: u32 = 0;
    // SAFETY: this task is TX_LINE's only user, and its pool holds one.
    let line = unsafe { TX_LINE.take_zeroed() };
    loop {
        // Replies first: they are few and short, and a host waits for them.
        // Before a commanded restart, replies only: a result line begun
        // now would be cut.
        let n = REPLIES.lock(|q| q.borrow_mut().pop_into(line)).or_else(|| {
            if RESTARTING.load(Ordering::Acquire) {
                None
            } else {
                QUEUE.lock(|q| q.borrow_mut().pop_into(line))
            }
        });
        let Some(n) = n else {
            KICK.wait().await;
            continue;
        };
        ROOM.signal(());
        // Set and cleared with no await between pop and write: the
        // command task sees a line in flight exactly while it is.
        SENDING.store(true, Ordering::Release);
        let written = uart.write(&line[..n]).await;
        SENDING.store(false, Ordering::Release);
        if written.is_err() {
            errors = errors.wrapping_add(1);
            warn!(
                "USART3 TX error ({} so far): a result line was lost",
                errors
            );
        }
    }
}

/// The scoring task's sink: lines to the UART queue, and the pipeline's
/// news ahead of them to READY and REJECT, so that the pins move before
/// the lines that report the same verdict are encoded.
struct PinSink<'a>(
    &'a mut QueueSink<{ crate::config::h743::QUEUE_BYTES }>,
    &'a mut PlcOutputs,
);

impl LineSink for PinSink<'_> {
    fn line(&mut self, line: &[u8], priority: Priority) {
        self.0.line(line, priority);
    }

    fn ahead(&mut self, news: Ahead) {
        self.1.ahead(news);
    }
}

impl CountingSink for PinSink<'_> {
    fn dropped(&self) -> u32 {
        self.0.dropped()
    }
}

/// Waits until the queue has its keep reserve free: scoring waits for the
/// UART while acquisition keeps counting beams.
async fn wait_for_room(wdg: &mut IndependentWatchdog<'static, IWDG1>) {
    while !QUEUE.lock(|q| q.borrow().keep_room()) {
        KICK.signal(());
        let _ = with_timeout(Duration::from_millis(FEED_MS), ROOM.wait()).await;
        wdg.pet();
    }
}

#[embassy_executor::task]
pub async fn score_task(
    driver: &'static mut ScanDriver<'static, MAX_COLS>,
    mut wdg: IndependentWatchdog<'static, IWDG1>,
    mut plc: PlcOutputs,
    control: &'static RefCell<Control>,
) {
    let mut frames = Samples {
        bufs: &FRAMES,
        cells: CELLS,
        release: |b: usize| ACQ.lock(|a| a.borrow_mut().release(b)),
    };
    let mut burst = 0u32;
    let mut sink = QueueSink(&QUEUE);
    let mut last_beam = Instant::now();
    let mut idle_ended = true;
    let mut reported = ACQ.lock(|a| *a.borrow().counts());

    loop {
        let _ = with_timeout(Duration::from_millis(FEED_MS), BEAMS.wait()).await;
        wdg.pet();

        loop {
            wait_for_room(&mut wdg).await;
            let rec = if driver.busy() {
                None
            } else {
                ACQ.lock(|a| a.borrow_mut().take_next())
            };
            if rec.is_none() && !driver.busy() {
                break;
            }
            last_beam = Instant::now();
            idle_ended = false;
            if CHANGED.load(Ordering::Acquire) {
                CHANGED.store(false, Ordering::Release);
                take_control(driver, control);
            }
            let finished = driver.step(rec, &mut frames, &mut PinSink(&mut sink, &mut plc));
            if driver.take_applied() {
                plc.configure(&driver.settings().outputs);
            }
            let _ = driver.take_closed();
            plc.step(driver.progress());
            if finished {
                scan_ended(driver, control);
            }
            // Most beams queue no line (lines come per row): waking the
            // UART task then would only have it find the queue empty.
            if !QUEUE.lock(|q| q.borrow().is_empty()) {
                KICK.signal(());
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
                wait_for_room(&mut wdg).await;
                let (more, finished) =
                    driver.end_of_data(&mut frames, &mut PinSink(&mut sink, &mut plc));
                let _ = driver.take_closed();
                plc.step(driver.progress());
                KICK.signal(());
                if finished {
                    warn!("no beam for {} ms: scan ended early", IDLE_END_MS);
                    scan_ended(driver, control);
                }
                if !more {
                    break;
                }
            }
            idle_ended = true;
        }

        let now = ACQ.lock(|a| *a.borrow().counts());
        if now.overruns != reported.overruns || now.spi_errors != reported.spi_errors {
            warn!(
                "acquisition: {} overruns, {} SPI/DMA errors so far",
                now.overruns, now.spi_errors
            );
        }
        reported = now;
    }
}

/// Settings the command channel changed go to the scan driver, which
/// applies them when the next scan starts.
fn take_control(driver: &mut ScanDriver<'static, MAX_COLS>, control: &RefCell<Control>) {
    let mut c = control.borrow_mut();
    if let Some(s) = c.take_changed() {
        driver.request(s);
    }
    if let Some(n) = c.calibration_to_arm()
        && let Some(cal) = driver.calibrator_mut()
    {
        cal.arm(n);
    }
}

/// A scan ended: the command channel's last-scan report, and the end
/// of a calibration whose last scan it was (its reply goes out, its
/// thresholds reach the driver with the next step).
fn scan_ended(driver: &mut ScanDriver<'static, MAX_COLS>, control: &RefCell<Control>) {
    let mut c = control.borrow_mut();
    if let Some((t, _)) = driver.last_scan() {
        c.scan_ended(&t, driver.progress().verdict);
    }
    if let Some(cal) = driver.calibrator_mut()
        && let Progress::Done { .. } = cal.progress()
    {
        let mut replies = QueueSink(&REPLIES);
        match cal.finish(&c.calibration_rule()) {
            Ok(result) => c.calibrated(&result, &mut replies),
            Err(_) => c.calibration_failed(Refusal::NoResult, &mut replies),
        }
        cal.disarm();
        CHANGED.store(true, Ordering::Release);
        KICK.signal(());
    }
    drop(c);
    report_scan(driver);
}

fn report_scan(driver: &ScanDriver<'static, MAX_COLS>) {
    let Some((t, dropped)) = driver.last_scan() else {
        return;
    };
    let s = driver.sequence_counts();
    let a = ACQ.lock(|a| *a.borrow().counts());
    let q = QUEUE.lock(|q| *q.borrow().counts());
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
