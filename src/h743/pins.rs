//! The peripherals and pins the board uses (NUCLEO-H743ZI2 Zio connector
//! names in docs/firmware.md's wiring table). Moving a signal to another
//! pin means changing its type here and the line that takes it.

use embassy_stm32::Peri;
use embassy_stm32::Peripherals;
use embassy_stm32::peripherals::{
    DMA1_CH2, DMA1_CH7, EXTI9, FLASH, IWDG1, PA5, PA6, PB0, PB14, PD8, PD9, PD14, PE9, PE11, PE13,
    PE14, SPI1, USART3,
};

/// READY and REJECT (`outputs`) and the user LEDs that mirror them.
pub struct OutputPins {
    pub ready: Peri<'static, PE14>,
    pub reject: Peri<'static, PE13>,
    pub ready_led: Peri<'static, PB0>,
    pub reject_led: Peri<'static, PB14>,
}

/// (SPI1's RX DMA, DMA1 stream 1, is driven by `frame_reader` directly.)
pub struct Pins {
    pub spi: Peri<'static, SPI1>,
    pub sck: Peri<'static, PA5>,
    pub miso: Peri<'static, PA6>,
    pub cs: Peri<'static, PD14>,
    pub drdy: Peri<'static, PE9>,
    pub drdy_exti: Peri<'static, EXTI9>,
    pub line_sync: Peri<'static, PE11>,
    pub uart: Peri<'static, USART3>,
    pub uart_tx: Peri<'static, PD8>,
    pub uart_tx_dma: Peri<'static, DMA1_CH2>,
    pub uart_rx: Peri<'static, PD9>,
    pub iwdg: Peri<'static, IWDG1>,
    pub outputs: OutputPins,
    /// The settings store: bank 2's flash interface, and DMA1 stream 7 to
    /// read bank 2 (`flash_bank2`).
    pub flash: Peri<'static, FLASH>,
    pub flash_dma: Peri<'static, DMA1_CH7>,
}

pub fn take(p: Peripherals) -> Pins {
    Pins {
        spi: p.SPI1,
        sck: p.PA5,  // D13
        miso: p.PA6, // D12
        cs: p.PD14,  // D10
        drdy: p.PE9, // D6, EXTI9 (EXTI9_5 interrupt)
        drdy_exti: p.EXTI9,
        line_sync: p.PE11, // D5
        uart: p.USART3,
        uart_tx: p.PD8, // ST-LINK VCP, the result lines and replies
        uart_tx_dma: p.DMA1_CH2,
        uart_rx: p.PD9, // ST-LINK VCP, the requests (`command_rx`)
        iwdg: p.IWDG1,
        outputs: OutputPins {
            ready: p.PE14,      // D4
            reject: p.PE13,     // D3
            ready_led: p.PB0,   // LD1, green
            reject_led: p.PB14, // LD3, red
        },
        flash: p.FLASH,
        flash_dma: p.DMA1_CH7,
    }
}
