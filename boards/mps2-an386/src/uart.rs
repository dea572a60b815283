//! CMSDK APB UART0 of `mps2-an386`, transmit side only (polled: QEMU sends
//! each byte to `-serial stdio` at once).

const BASE: usize = 0x4000_4000;
const DATA: *mut u32 = BASE as *mut u32;
const STATE: *const u32 = (BASE + 0x04) as *const u32;
const CTRL: *mut u32 = (BASE + 0x08) as *mut u32;
const BAUDDIV: *mut u32 = (BASE + 0x10) as *mut u32;

const STATE_TX_FULL: u32 = 1 << 0;
const CTRL_TX_ENABLE: u32 = 1 << 0;

pub struct Uart0(());

impl Uart0 {
    /// Enables the transmitter. Only one instance may exist.
    pub fn take() -> Uart0 {
        // SAFETY: fixed MMIO registers of the CMSDK UART; 16 is the smallest
        // divider the peripheral accepts.
        unsafe {
            BAUDDIV.write_volatile(16);
            CTRL.write_volatile(CTRL_TX_ENABLE);
        }
        Uart0(())
    }

    pub fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            // SAFETY: MMIO reads/writes of the UART's state and data registers.
            unsafe {
                while STATE.read_volatile() & STATE_TX_FULL != 0 {}
                DATA.write_volatile(u32::from(b));
            }
        }
    }
}
