//! Why the chip started, how often since power-on, and what it does when
//! the firmware panics.
//!
//! A panic logs its message over defmt, drives the outputs to their safe
//! state and resets the chip at once (instead of waiting for the
//! watchdog, or for ever before the watchdog runs). The next start reads the cause from RCC_RSR, logs it, clears the
//! flags and counts the start; both go into every header line (`rst`,
//! `boots`). A software reset is a panic or a debugger's reset request;
//! a pin reset is the reset button or the ST-LINK.

use core::mem::MaybeUninit;
use core::ptr::{addr_of_mut, read_volatile, write_volatile};

use cvm_core::protocol::ResetCause;
use embassy_stm32::pac;

/// Starts since power-on, in RAM that the start-up code neither zeroes nor
/// initialises (`.uninit`), so that it survives a warm reset. Its content
/// counts only while `magic` holds [`BOOT_MAGIC`]: after power-on the RAM
/// holds noise.
#[repr(C)]
struct BootCount {
    magic: u32,
    count: u32,
}

const BOOT_MAGIC: u32 = 0xB007_C0DE;

#[unsafe(link_section = ".uninit.cvm_boots")]
static mut BOOTS: MaybeUninit<BootCount> = MaybeUninit::uninit();

/// Counts this start: 1 after power-on (or when the count was not
/// kept), one more than before after any other reset.
pub fn count_boot(cause: ResetCause) -> u32 {
    // SAFETY: called once, from `main` before any task or interrupt
    // runs; every bit pattern is a valid `u32`, so reading the
    // uninitialised words is a read of noise, not undefined behaviour,
    // through volatile raw pointers.
    unsafe {
        let b = addr_of_mut!(BOOTS).cast::<BootCount>();
        let magic = read_volatile(addr_of_mut!((*b).magic));
        let count = read_volatile(addr_of_mut!((*b).count));
        let boots = if cause == ResetCause::PowerOn || magic != BOOT_MAGIC {
            1
        } else {
            count.saturating_add(1)
        };
        write_volatile(addr_of_mut!((*b).count), boots);
        write_volatile(addr_of_mut!((*b).magic), BOOT_MAGIC);
        boots
    }
}

/// Reads and clears the reset flags.
pub fn take_cause() -> ResetCause {
    let rcc = pac::RCC;
    let rsr = rcc.rsr().read();
    // Internal resets also pull NRST, so PINRSTF comes with every cause:
    // test it last. A power-on sets BORRSTF too (the supply rises through
    // the BOR threshold); BORRSTF alone is a brown-out: the supply dipped
    // while the board ran, perhaps in the middle of a part, so it is not
    // a clean start (`other`, and the outputs start not judged).
    let cause = if rsr.porrstf() {
        ResetCause::PowerOn
    } else if rsr.borrstf() {
        defmt::warn!("brown-out reset");
        ResetCause::Other
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
    super::failsafe::drive();
    defmt::error!("panic: {}", defmt::Display2Format(info));
    super::failsafe::stop()
}

#[defmt::panic_handler]
fn defmt_panic() -> ! {
    super::failsafe::stop()
}
