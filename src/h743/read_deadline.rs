//! The deadline of one frame read, on TIM13 (otherwise unused).
//!
//! A one-shot count of `READ_TIMEOUT_US` microseconds starts with every
//! read and is stopped when the read ends; if it runs out first, its
//! interrupt (in `frame_reader`, beside the other two that end reads) asks
//! [`take_expiry`] and ends the read as a timeout. A hardware timer
//! instead of embassy-time's `with_timeout` because the read finishes long
//! before its deadline nearly always: `with_timeout` queued an alarm per
//! frame that still fired after the read and woke the acquisition task for
//! nothing (docs/firmware.md, "SPI1 configuration and measured costs");
//! starting and stopping TIM13 costs a few register writes.

use embassy_stm32::interrupt;
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::pac;
use embassy_stm32::pac::timer::vals::Urs;

use super::clocks::{APB1_TIMER_HZ, enable_clock};

/// One count per microsecond.
const PRESCALER: u32 = APB1_TIMER_HZ / 1_000_000;
const _: () = assert!(
    PRESCALER >= 1 && PRESCALER <= 1 << 16 && APB1_TIMER_HZ.is_multiple_of(1_000_000),
    "TIM13 must count whole microseconds"
);

/// Whether the deadline ran out since the last [`ReadDeadline::stop`]; if
/// so, clears it. For TIM13's interrupt: an entry without UIF is a pend
/// that raced the end of the previous read and must not end this one.
pub fn take_expiry() -> bool {
    let t = pac::TIM13;
    if !t.sr().read().uif() {
        return false;
    }
    // One-shot: the update event has already cleared CEN.
    t.cr1().write(|_| {});
    t.sr().write(|_| {});
    true
}

/// TIM13, set up for reads of at most `timeout_us` microseconds.
pub struct ReadDeadline(());

impl ReadDeadline {
    /// `timeout_us` is at least 1 and at most 65 536 (16-bit counter).
    /// The caller sets the interrupt's priority and enables it.
    pub fn new(timeout_us: u32) -> Self {
        enable_clock(pac::RCC.apb1lenr(), |w| w.set_tim13en(true));
        let t = pac::TIM13;
        t.cr1().write(|_| {});
        t.psc().write_value((PRESCALER - 1) as u16);
        t.arr()
            .write(|w| w.set_arr((timeout_us.clamp(1, 1 << 16) - 1) as u16));
        // URS: the UG below loads the prescaler without an interrupt.
        t.cr1().write(|w| w.set_urs(Urs::COUNTER_ONLY));
        t.egr().write(|w| w.set_ug(true));
        t.sr().write(|_| {});
        t.dier().write(|w| w.set_uie(true));
        ReadDeadline(())
    }

    /// Starts the count from 0.
    pub fn start(&mut self) {
        let t = pac::TIM13;
        t.cnt().write(|w| w.set_cnt(0));
        t.cr1().write(|w| {
            w.set_urs(Urs::COUNTER_ONLY);
            w.set_opm(true);
            w.set_cen(true);
        });
    }

    /// Stops the count and drops an expiry that raced the end of the read.
    pub fn stop(&mut self) {
        let t = pac::TIM13;
        t.cr1().write(|w| w.set_urs(Urs::COUNTER_ONLY));
        t.sr().write(|_| {});
        // The read-back makes the flag clear reach TIM13 before the NVIC
        // write: the M7 may otherwise complete the NVIC write first, and
        // the timer's line, still high, would pend the interrupt again.
        let _ = t.sr().read();
        interrupt::TIM8_UP_TIM13.unpend();
    }
}
