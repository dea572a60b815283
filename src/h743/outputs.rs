//! READY and REJECT, the PLC's outputs (docs/firmware.md, "READY and
//! REJECT outputs"): two header pins, mirrored on the green and red user
//! LEDs, driven with single BSRR writes (atomic, so the DRDY input on the
//! same port is never disturbed). Which level each should have comes from
//! `cvm_fw_app::outputs`, which the runtime steps after every scoring step
//! and hands to these pins (`cvm_fw_app::runtime::Pins`). REJECT's pulses are
//! timed by TIM14 in one-pulse mode, its interrupt releasing the pin: the
//! scoring task only starts them and never waits for one.

use core::cell::Cell;
use core::sync::atomic::{AtomicU32, Ordering};

use cvm_core::settings::{Outputs, RejectMode};
use cvm_fw_app::outputs::{Asserted, Change, level};
use cvm_fw_app::runtime::Pins;
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::pac;
use embassy_stm32::pac::timer::vals::Urs;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;

use super::clocks::{APB1_TIMER_HZ, enable_clock};
use super::failsafe::{
    READY_ACTIVE_HIGH, READY_LED, READY_PIN, REJECT_ACTIVE_HIGH, REJECT_LED, REJECT_PIN,
};
use super::pins::OutputPins;
use super::resources::RESTARTING;
use crate::config::h743::OUTPUTS;

/// One TIM14 count per microsecond.
const PRESCALER: u32 = APB1_TIMER_HZ / 1_000_000;
const _: () = assert!(
    PRESCALER >= 1 && PRESCALER <= 1 << 16 && APB1_TIMER_HZ.is_multiple_of(1_000_000),
    "TIM14 must count whole microseconds"
);
const _: () = assert!(
    // (`checked_sub` rather than comparisons, which are trivially true
    // for the default of 0 and trip the absurd-comparison lint.)
    !matches!(OUTPUTS.reject_mode, RejectMode::Row) || OUTPUTS.pulse_us.checked_sub(1).is_some(),
    "row mode pulses REJECT: it needs a pulse width"
);
const _: () = assert!(
    (1u32 << 16).checked_sub(OUTPUTS.pulse_us).is_some(),
    "TIM14 counts at most 65 536 µs per pulse"
);

/// REJECT's pulses: still to start, and whether one is on.
#[derive(Clone, Copy)]
struct Pulses {
    left: u32,
    on: bool,
}

static PULSES: Mutex<CriticalSectionRawMutex, Cell<Pulses>> =
    Mutex::new(Cell::new(Pulses { left: 0, on: false }));

/// REJECT's pulse width in µs, which TIM14 follows (it changes between
/// scans, by the command channel). The asserted levels never change
/// (`failsafe`).
static PULSE_US: AtomicU32 = AtomicU32::new(OUTPUTS.pulse_us);

/// A commanded restart is coming ([`RESTARTING`]): the pins hold the
/// safe state the restart will leave them in.
fn held() -> bool {
    RESTARTING.load(Ordering::Acquire)
}

fn write_ready(asserted: bool) {
    let asserted = asserted && !held();
    let high = level(asserted, READY_ACTIVE_HIGH);
    pac::GPIOE.bsrr().write(|w| {
        w.set_bs(READY_PIN, high);
        w.set_br(READY_PIN, !high);
    });
    pac::GPIOB.bsrr().write(|w| {
        w.set_bs(READY_LED, asserted);
        w.set_br(READY_LED, !asserted);
    });
}

fn write_reject(asserted: bool) {
    let asserted = asserted || held();
    let high = level(asserted, REJECT_ACTIVE_HIGH);
    pac::GPIOE.bsrr().write(|w| {
        w.set_bs(REJECT_PIN, high);
        w.set_br(REJECT_PIN, !high);
    });
    pac::GPIOB.bsrr().write(|w| {
        w.set_bs(REJECT_LED, asserted);
        w.set_br(REJECT_LED, !asserted);
    });
}

/// Starts TIM14's one-shot count of the pulse width.
fn start_timer() {
    let t = pac::TIM14;
    let us = PULSE_US.load(Ordering::Relaxed).clamp(1, 1 << 16);
    t.arr().write(|w| w.set_arr((us - 1) as u16));
    t.cnt().write(|w| w.set_cnt(0));
    t.cr1().write(|w| {
        w.set_urs(Urs::COUNTER_ONLY);
        w.set_opm(true);
        w.set_cen(true);
    });
}

/// The end of a pulse, or of the gap after it: the next phase starts.
#[interrupt]
fn TIM8_TRG_COM_TIM14() {
    let t = pac::TIM14;
    if !t.sr().read().uif() {
        return;
    }
    t.sr().write(|_| {});
    PULSES.lock(|p| {
        let mut s = p.get();
        if s.on {
            write_reject(false);
            s.on = false;
            // A gap as long as a pulse before the next, so that two
            // objects closed together make two pulses.
            if s.left > 0 {
                start_timer();
            }
        } else if s.left > 0 {
            s.left -= 1;
            s.on = true;
            write_reject(true);
            start_timer();
        }
        p.set(s);
    });
}

/// The outputs of the board, which the scoring task's runtime drives.
pub struct PlcOutputs(());

impl PlcOutputs {
    /// Configures the pins at their start-up levels `a` (the outputs'
    /// logic at its start: READY dropped after any start but power-on)
    /// and TIM14.
    pub fn new(pins: OutputPins, a: Asserted, o: &Outputs) -> Self {
        PULSE_US.store(o.pulse_us, Ordering::Relaxed);
        let lv = |b: bool| if b { Level::High } else { Level::Low };
        // Configured once and never dropped: a dropped `Output` would
        // return its pin to an input.
        core::mem::forget(Output::new(
            pins.ready,
            lv(level(a.ready, READY_ACTIVE_HIGH)),
            Speed::Low,
        ));
        core::mem::forget(Output::new(
            pins.reject,
            lv(level(a.reject, REJECT_ACTIVE_HIGH)),
            Speed::Low,
        ));
        core::mem::forget(Output::new(pins.ready_led, lv(a.ready), Speed::Low));
        core::mem::forget(Output::new(pins.reject_led, lv(a.reject), Speed::Low));
        enable_clock(pac::RCC.apb1lenr(), |w| w.set_tim14en(true));
        let t = pac::TIM14;
        t.cr1().write(|_| {});
        t.psc().write_value((PRESCALER - 1) as u16);
        t.arr()
            .write(|w| w.set_arr((o.pulse_us.clamp(1, 1 << 16) - 1) as u16));
        t.cr1().write(|w| w.set_urs(Urs::COUNTER_ONLY));
        t.egr().write(|w| w.set_ug(true));
        t.sr().write(|_| {});
        t.dier().write(|w| w.set_uie(true));
        let irq = interrupt::TIM8_TRG_COM_TIM14;
        // Below DRDY and the reads' ends (P5): a pulse edge may wait for
        // a read's end, never the reverse.
        irq.set_priority(interrupt::Priority::P6);
        // SAFETY: the handler touches only TIM14, GPIOB/E's BSRR and PULSES.
        unsafe { irq.enable() };
        PlcOutputs(())
    }
}

impl Pins for PlcOutputs {
    fn change(&mut self, change: Change) {
        let Change { now, pulses } = change;
        self.write(now);
        if pulses > 0 {
            PULSES.lock(|c| {
                let mut s = c.get();
                let idle = !s.on && s.left == 0 && !pac::TIM14.cr1().read().cen();
                s.left = s.left.saturating_add(pulses);
                if idle {
                    s.left -= 1;
                    s.on = true;
                    write_reject(true);
                    start_timer();
                }
                c.set(s);
            });
        }
    }

    /// The outputs' settings from the scan starting now on (levels, pulse
    /// width, mode): the pins are written again at their new levels.
    fn configure(&mut self, o: &Outputs, now: Asserted) {
        PULSE_US.store(o.pulse_us, Ordering::Relaxed);
        write_ready(now.ready);
        if !PULSES.lock(|p| p.get().on) {
            write_reject(now.reject && o.pulse_us == 0);
        }
    }
}

impl PlcOutputs {
    fn write(&self, now: Asserted) {
        write_ready(now.ready);
        // With pulses, REJECT belongs to the timer.
        if PULSE_US.load(Ordering::Relaxed) == 0 {
            write_reject(now.reject);
        }
    }
}
