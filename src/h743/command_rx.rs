//! USART3's receiver: the command channel's bytes, each with the errors
//! the receiver flagged for it, into a ring that the command task drains.
//!
//! Interrupt-driven rather than DMA: the receiver's error flags (framing,
//! noise, parity) belong to the byte at the head of its FIFO, and only a
//! handler that reads the flags before each byte can keep them with the
//! byte, which is what lets a damaged line be refused with its reason
//! (docs/commands.md, "Refusals"). At 921 600 baud a byte comes every
//! 10.9 µs; the handler costs about 60 instructions a byte and runs below
//! DRDY and the reads' ends, which preempt it.

use core::cell::RefCell;

use cvm_core::command::LinkError;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::pac;
use embassy_stm32::pac::gpio::vals::Moder;
use embassy_stm32::peripherals::PD9;
use embassy_stm32::{Peri, interrupt};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;

use super::resources::RX_READY;

/// Received bytes the ring holds: dozens of request lines, so that a
/// burst of requests waits here while the replies to earlier ones are
/// being sent.
pub const RING: usize = 2048;

/// One received item: a byte with the errors it arrived with, or an
/// overrun (bytes lost before the next one).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rx {
    Byte(u8, Option<LinkError>),
    Overrun,
}

/// A ring entry: the byte in bits 0..8, then what came with it; all
/// zeros, so that the ring starts in `.bss` rather than as 4 KB of
/// initial value in flash.
const FRAMING: u16 = 1 << 8;
const NOISE: u16 = 1 << 9;
const OVERRUN: u16 = 1 << 10;

fn pack(x: Rx) -> u16 {
    match x {
        Rx::Byte(b, None) => b as u16,
        Rx::Byte(b, Some(LinkError::Framing)) => b as u16 | FRAMING,
        Rx::Byte(b, Some(_)) => b as u16 | NOISE,
        Rx::Overrun => OVERRUN,
    }
}

fn unpack(e: u16) -> Rx {
    if e & OVERRUN != 0 {
        return Rx::Overrun;
    }
    let err = if e & FRAMING != 0 {
        Some(LinkError::Framing)
    } else if e & NOISE != 0 {
        Some(LinkError::Noise)
    } else {
        None
    };
    Rx::Byte(e as u8, err)
}

struct Ring {
    buf: [u16; RING],
    head: usize,
    len: usize,
    /// The ring filled up: its last slot holds an overrun, and what
    /// arrives is dropped until there is room again.
    full: bool,
}

impl Ring {
    const fn new() -> Self {
        Ring {
            buf: [0; RING],
            head: 0,
            len: 0,
            full: false,
        }
    }

    fn push(&mut self, x: Rx) {
        // The last slot is kept for the overrun, so that it comes in
        // order: after the bytes kept, before the first byte that follows
        // the loss (the line it damages is then refused `overrun`).
        if self.len + 1 >= RING {
            if !self.full {
                self.full = true;
                self.put(Rx::Overrun);
            }
            return;
        }
        self.full = false;
        self.put(x);
    }

    /// [`Ring::push`], and the entries held after it.
    fn push_len(&mut self, x: Rx) -> usize {
        self.push(x);
        self.len
    }

    fn put(&mut self, x: Rx) {
        if let Some(slot) = self.buf.get_mut((self.head + self.len) % RING) {
            *slot = pack(x);
            self.len += 1;
        }
    }

    fn pop(&mut self) -> Option<Rx> {
        if self.len == 0 {
            return None;
        }
        let x = self.buf.get(self.head).copied().map(unpack);
        self.head = (self.head + 1) % RING;
        self.len -= 1;
        x
    }
}

static RX: Mutex<CriticalSectionRawMutex, RefCell<Ring>> = Mutex::new(RefCell::new(Ring::new()));

/// The next received item, if any.
pub fn take() -> Option<Rx> {
    RX.lock(|r| r.borrow_mut().pop())
}

/// Bytes USART3's receive FIFO holds (RM0433: RXFIFO of 16 bytes).
const RX_FIFO: usize = 16;

#[interrupt]
fn USART3() {
    let u = pac::USART3;
    let mut wake = false;
    // The ring is locked per byte, not for the whole drain: DRDY and the
    // reads' ends keep preempting this handler between bytes.
    let push = |x: Rx| RX.lock(|r| r.borrow_mut().push_len(x));
    loop {
        if u.isr().read().ore() {
            // ORE: a byte came while the FIFO was full and was lost. The
            // FIFO's bytes arrived before it: they go first, then the
            // marker (which wakes the command task), so the line they end
            // is intact and the overrun damages the next one. Bytes that
            // arrive during this drain come after the marker.
            u.icr().write(|w| w.set_ore(true));
            for _ in 0..RX_FIFO {
                let Some((x, _)) = receive(u) else { break };
                push(x);
            }
            push(Rx::Overrun);
            wake = true;
            continue;
        }
        match receive(u) {
            Some((x, w)) => {
                let len = push(x);
                wake |= w || len >= RING / 2;
            }
            None => break,
        }
    }
    if wake {
        RX_READY.signal(());
    }
}

/// The byte at the head of the receive FIFO with its errors, and whether
/// the command task should look now (a line end or an error); `None`
/// when the FIFO is empty.
fn receive(u: pac::usart::Usart) -> Option<(Rx, bool)> {
    let isr = u.isr().read();
    if !isr.rxne() {
        return None;
    }
    // The flags are the head byte's: read them before the byte.
    let e = if isr.fe() {
        Some(LinkError::Framing)
    } else if isr.ne() || isr.pe() {
        Some(LinkError::Noise)
    } else {
        None
    };
    if e.is_some() {
        u.icr().write(|w| {
            w.set_fe(true);
            w.set_ne(true);
            w.set_pe(true);
        });
    }
    let b = u.rdr().read().dr() as u8;
    Some((Rx::Byte(b, e), b == b'\n' || e.is_some()))
}

/// Starts receiving on PD9 (USART3 RX, the ST-LINK's virtual COM port),
/// once `main` has configured USART3 for transmission (baud rate, frame
/// format and FIFO are shared).
pub fn enable(_rx: Peri<'static, PD9>) {
    // PD9 as alternate function 7 (USART3_RX), pulled up so that an
    // unconnected line idles high instead of reading breaks.
    let d = pac::GPIOD;
    d.pupdr()
        .modify(|w| w.set_pupdr(9, pac::gpio::vals::Pupdr::PULL_UP));
    d.afr(1).modify(|w| w.set_afr(1, 7));
    d.moder().modify(|w| w.set_moder(9, Moder::ALTERNATE));
    let u = pac::USART3;
    u.icr().write(|w| {
        w.set_fe(true);
        w.set_ne(true);
        w.set_pe(true);
        w.set_ore(true);
    });
    u.cr3().modify(|w| w.set_eie(true));
    u.cr1().modify(|w| {
        w.set_re(true);
        w.set_rxneie(true);
        w.set_peie(true);
    });
    let irq = interrupt::USART3;
    irq.set_priority(Priority::P6);
    // SAFETY: the handler touches only USART3's receiver and RX.
    unsafe { irq.enable() };
}
