//! Clock tree of the NUCLEO-H743ZI2 build.
//!
//! The source is the ST-LINK's 8 MHz MCO on PH0 (HSE in bypass mode,
//! solder bridge SB45 as shipped): crystal-accurate, so the UART's baud
//! rate does not drift with temperature as the HSI's would.
//! PLL1: 8 MHz / 1 * 100 = 800 MHz VCO; P / 2 = 400 MHz core; Q / 4 =
//! 200 MHz SPI1 kernel clock (SCK = 200 MHz / 2^k). AHB 200 MHz, APB1..4
//! 100 MHz: USART3's kernel clock (PCLK1) is 100 MHz, and the time driver's
//! timer runs at 200 MHz, an exact multiple of the 1 MHz tick.

use embassy_stm32::rcc::*;
use embassy_stm32::time::Hertz;

pub const HSE_HZ: u32 = 8_000_000;
/// The APB1 timers' kernel clock: PCLK1 (100 MHz) times 2, as RM0433
/// doubles it whenever the APB1 prescaler divides (`TIMPRE` = 0).
pub const APB1_TIMER_HZ: u32 = 200_000_000;

pub fn config() -> embassy_stm32::Config {
    let mut config = embassy_stm32::Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(HSE_HZ),
        mode: HseMode::Bypass,
    });
    config.rcc.csi = true;
    config.rcc.pll1 = Some(Pll {
        source: PllSource::HSE,
        prediv: PllPreDiv::DIV1,
        mul: PllMul::MUL100,
        fracn: None,
        divp: Some(PllDiv::DIV2),
        divq: Some(PllDiv::DIV4),
        divr: None,
    });
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.ahb_pre = AHBPrescaler::DIV2;
    config.rcc.apb1_pre = APBPrescaler::DIV2;
    config.rcc.apb2_pre = APBPrescaler::DIV2;
    config.rcc.apb3_pre = APBPrescaler::DIV2;
    config.rcc.apb4_pre = APBPrescaler::DIV2;
    config.rcc.voltage_scale = VoltageScale::Scale1;
    config
}

/// Sets a peripheral's clock enable in `reg` (an RCC `...ENR` register)
/// and returns once the enable has taken effect. RM0433 (RCC, "peripheral
/// clock enable") gives the enable two cycles of the peripheral's bus
/// clock after the write reaches RCC, and RCC sits on AHB4 in D3 while the
/// timers are on APB1 in D2: a register write issued right after the
/// enable can reach a peripheral that is not clocked yet and be lost (a
/// lost TIM14 prescaler makes a 500 µs REJECT pulse 2.5 µs). Reading the
/// register back cannot complete before the write has landed, and the DSB
/// keeps every later access behind that read.
pub fn enable_clock<T: Copy>(
    reg: embassy_stm32::pac::common::Reg<T, embassy_stm32::pac::common::RW>,
    set: impl FnOnce(&mut T),
) {
    reg.modify(set);
    let _ = reg.read();
    cortex_m::asm::dsb();
}
