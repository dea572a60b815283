//! The DRDY interrupt: every rising edge of DRDY is one beam.

use core::cell::RefCell;

use embassy_stm32::Peri;
use embassy_stm32::exti::blocking::ExtiGroupMask;
use embassy_stm32::exti::{ExtiInput, TriggerEdge};
use embassy_stm32::gpio::{Input, Pull};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::mode::Blocking;
use embassy_stm32::peripherals::{EXTI9, PE9, PE11};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;

use super::frame_reader;
use super::resources::ACQ;

/// The DRDY line's EXTI mask and the LINE_SYNC input, for the interrupt.
struct DrdyIo {
    /// Kept so that the pin stays configured as the EXTI input.
    _drdy: ExtiInput<'static, Blocking>,
    mask: ExtiGroupMask,
    line_sync: Input<'static>,
}
static DRDY_IO: Mutex<CriticalSectionRawMutex, RefCell<Option<DrdyIo>>> =
    Mutex::new(RefCell::new(None));
/// DRDY is PE9: EXTI line 9.
const DRDY_LINE: usize = 9;

#[interrupt]
fn EXTI9_5() {
    // Clear DRDY's pending bit first, whatever happens next: a pending bit
    // left set re-enters this handler for ever.
    embassy_stm32::pac::EXTI
        .pr(0)
        .write(|w| w.set_line(DRDY_LINE, true));
    DRDY_IO.lock(|io| {
        let io = io.borrow();
        let Some(io) = io.as_ref() else { return };
        io.mask.clear();
        let sync = io.line_sync.is_high();
        if let Some(buf) = ACQ.lock(|a| a.borrow_mut().drdy(sync)) {
            frame_reader::start(buf);
        }
    });
}

/// Configures DRDY (rising edges) and LINE_SYNC and lets the interrupt
/// run: the last step of the start-up, once the reader is installed.
pub fn enable(
    drdy: Peri<'static, PE9>,
    exti: Peri<'static, EXTI9>,
    line_sync: Peri<'static, PE11>,
) {
    let drdy = ExtiInput::new_blocking(drdy, exti, Pull::Down, TriggerEdge::Rising);
    let mask = ExtiGroupMask::new(&[&drdy]);
    let line_sync = Input::new(line_sync, Pull::Down);
    DRDY_IO.lock(|io| {
        io.replace(Some(DrdyIo {
            _drdy: drdy,
            mask,
            line_sync,
        }))
    });
    interrupt::EXTI9_5.set_priority(Priority::P5);
    // SAFETY: the handler only touches mutex-protected statics.
    unsafe { interrupt::EXTI9_5.enable() };
}
