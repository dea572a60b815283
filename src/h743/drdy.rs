//! The DRDY interrupt: every rising edge of DRDY is one beam.

use core::cell::RefCell;

use embassy_stm32::exti::ExtiInput;
use embassy_stm32::exti::blocking::ExtiGroupMask;
use embassy_stm32::gpio::Input;
use embassy_stm32::interrupt;
use embassy_stm32::mode::Blocking;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;

use super::ACQ;
use super::frame_reader;

/// The DRDY line's EXTI mask and the LINE_SYNC input, for the interrupt.
pub struct DrdyIo {
    /// Kept so that the pin stays configured as the EXTI input.
    pub _drdy: ExtiInput<'static, Blocking>,
    pub mask: ExtiGroupMask,
    pub line_sync: Input<'static>,
}
pub static DRDY_IO: Mutex<CriticalSectionRawMutex, RefCell<Option<DrdyIo>>> =
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
