//! The outputs' safe state, and the paths that must end in it: the first
//! instructions after reset, a HardFault, an unexpected interrupt and a
//! panic (docs/firmware.md, "Fail-safe").
//!
//! READY is active high and REJECT active low, always (the command
//! channel refuses the other levels): a pin that nothing drives (in reset,
//! before it is configured, on an unpowered board) or a broken wire reads
//! low at the PLC's input, which is "not ready" and "reject". So the safe
//! state needs no settings: it is both pins low, and it can be driven
//! before the settings store is read, and from a fault handler that must
//! not trust any RAM.

use cvm_core::settings::Outputs;
use cvm_fw_app::outputs::level;
use embassy_stm32::pac;
use embassy_stm32::pac::gpio::vals::Moder;

use super::clocks::enable_clock;

/// The asserted levels, the only ones the settings hold (`Key::range`
/// refuses the others): READY high, REJECT low. The safe state ("not
/// ready", "reject") is then both pins low, as `drive` writes them.
pub const READY_ACTIVE_HIGH: bool = true;
pub const REJECT_ACTIVE_HIGH: bool = false;
const _: () = assert!(
    Outputs::DEFAULT.ready_high == READY_ACTIVE_HIGH
        && Outputs::DEFAULT.reject_high == REJECT_ACTIVE_HIGH
        && !level(false, READY_ACTIVE_HIGH)
        && !level(true, REJECT_ACTIVE_HIGH)
);

/// Port E: READY (PE14, D4) and REJECT (PE13, D3); port B: the LEDs that
/// mirror them, LD1 green (PB0) and LD3 red (PB14).
pub const READY_PIN: usize = 14;
pub const REJECT_PIN: usize = 13;
pub const READY_LED: usize = 0;
pub const REJECT_LED: usize = 14;

/// The first thing `main` does, before clocks, embassy's init and the
/// settings store: READY and REJECT driven low ("not ready", "reject"),
/// LD1 off, LD3 on. Until here they were Hi-Z, which reads the same.
/// `embassy_stm32::init` only enables the GPIO clocks again, and the
/// pins keep this state until `outputs::PlcOutputs` takes them over.
pub fn at_reset() {
    enable_clock(pac::RCC.ahb4enr(), |w| {
        w.set_gpioben(true);
        w.set_gpioeen(true);
    });
    drive();
    pac::GPIOE.moder().modify(|w| {
        w.set_moder(READY_PIN, Moder::OUTPUT);
        w.set_moder(REJECT_PIN, Moder::OUTPUT);
    });
    pac::GPIOB.moder().modify(|w| {
        w.set_moder(READY_LED, Moder::OUTPUT);
        w.set_moder(REJECT_LED, Moder::OUTPUT);
    });
}

/// The safe state through BSRR, one write per port: no read-modify-write,
/// so it is right whatever the interrupted code was doing to the ports.
pub fn drive() {
    pac::GPIOE.bsrr().write(|w| {
        w.set_br(READY_PIN, true);
        w.set_br(REJECT_PIN, true);
    });
    pac::GPIOB.bsrr().write(|w| {
        w.set_br(READY_LED, true);
        w.set_bs(REJECT_LED, true);
    });
}

/// The safe state, then a reset: a faulting or panicking firmware must
/// not leave READY up or a REJECT pulse unended until the watchdog.
pub fn stop() -> ! {
    drive();
    cortex_m::peripheral::SCB::sys_reset()
}

/// A bus, memory or usage fault, or an undefined instruction.
#[cortex_m_rt::exception]
unsafe fn HardFault(frame: &cortex_m_rt::ExceptionFrame) -> ! {
    // The pins first: the log may fault again.
    drive();
    defmt::error!("HardFault at pc {:#010x}", frame.pc());
    cortex_m::peripheral::SCB::sys_reset()
}

/// An interrupt the firmware enabled without a handler.
#[cortex_m_rt::exception]
unsafe fn DefaultHandler(irqn: i16) -> ! {
    drive();
    defmt::error!("unexpected interrupt {}", irqn);
    cortex_m::peripheral::SCB::sys_reset()
}
