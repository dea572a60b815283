//! Why the chip started, and what it does when the firmware panics.
//!
//! A panic logs its message over defmt and resets the chip at once
//! (instead of waiting for the watchdog, or for ever before the watchdog
//! runs). The next start reads the cause from RCC_RSR, logs it and clears
//! the flags.

use embassy_stm32::pac;

#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum ResetCause {
    PowerOn,
    Watchdog,
    /// A software reset: after a panic, or a debugger's reset request.
    Software,
    /// The NRST pin (the reset button, or the ST-LINK).
    Pin,
    Other,
}

/// Reads and clears the reset flags.
pub fn take_cause() -> ResetCause {
    let rcc = pac::RCC;
    let rsr = rcc.rsr().read();
    // Internal resets also pull NRST, so PINRSTF comes with every cause:
    // test it last.
    let cause = if rsr.porrstf() || rsr.borrstf() {
        ResetCause::PowerOn
    } else if rsr.iwdg1rstf() || rsr.wwdg1rstf() {
        ResetCause::Watchdog
    } else if rsr.sftrstf() {
        ResetCause::Software
    } else if rsr.pinrstf() {
        ResetCause::Pin
    } else {
        ResetCause::Other
    };
    rcc.rsr().write(|w| w.set_rmvf(true));
    cause
}

/// Freezes the independent watchdog while a debugger halts the core, so
/// that a probe-rs session does not reset the board at a breakpoint.
pub fn freeze_watchdog_in_debug() {
    pac::DBGMCU.apb4fzr1().modify(|w| w.set_iwdg1(true));
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    cortex_m::peripheral::SCB::sys_reset()
}

#[defmt::panic_handler]
fn defmt_panic() -> ! {
    cortex_m::peripheral::SCB::sys_reset()
}
