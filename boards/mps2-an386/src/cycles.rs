//! Instruction counting with SysTick.
//!
//! Under `qemu-system-arm -icount shift=0` the virtual clock advances 1 ns
//! per instruction and SysTick, clocked by the 25 MHz core clock of
//! `mps2-an386`, decrements once every 40 instructions. Each measured
//! stretch is far shorter than the 24-bit counter's period, so a stretch is
//! the down-counter's difference modulo 2^24, with no interrupt involved.

use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;

pub const INSTRUCTIONS_PER_TICK: u64 = 40;
const MASK: u32 = 0x00FF_FFFF;

pub struct Stopwatch {
    syst: SYST,
    ticks: u64,
}

impl Stopwatch {
    pub fn new(mut syst: SYST) -> Stopwatch {
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(MASK);
        syst.clear_current();
        syst.disable_interrupt();
        syst.enable_counter();
        Stopwatch { syst, ticks: 0 }
    }

    fn now(&self) -> u32 {
        let _ = &self.syst;
        SYST::get_current()
    }

    /// Runs `f`, adding its duration to the total.
    pub fn time<T>(&mut self, f: impl FnOnce() -> T) -> T {
        let start = self.now();
        let r = f();
        let end = self.now();
        self.ticks += u64::from(start.wrapping_sub(end) & MASK);
        r
    }

    /// Instructions counted so far (valid under `-icount shift=0`).
    pub fn instructions(&self) -> u64 {
        self.ticks * INSTRUCTIONS_PER_TICK
    }
}
