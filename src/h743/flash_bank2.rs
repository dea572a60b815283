//! Bank 2 of the embedded flash, where the settings are kept
//! (`memory.x`, `SETTINGS`), at register level (RM0433 §4;
//! the register ledger: docs/registers.md, "FLASH bank 2").
//!
//! The code runs from bank 1, which stays readable while bank 2 erases or
//! programs, and every wait for an operation is an interrupt: the scoring task
//! keeps scoring (and feeding the watchdog) through a save, and the core
//! sleeps when it has nothing else to do: an operation's end (EOP, or an
//! error) raises the FLASH interrupt, which wakes the waiting task.
//!
//! - Program: unlock FLASH_KEYR2 (only when CR2 is locked: a key written
//!   to an unlocked bank is a bus error), clear the errors through
//!   FLASH_CCR2, set CR2.PG, write the flash word's eight 32-bit words
//!   (the write buffer programs the word when it is full), wait while
//!   SR2.QW, read the error flags, clear PG and lock.
//! - Erase: the same around CR2.SER with SNB, then START; both at the
//!   parallelism [`PSIZE`].
//! - Read: never by the CPU. A word whose programming a power cut
//!   interrupted has cells that do not match its ECC, and reading it is a
//!   double ECC error that the flash answers with a bus error: a bus fault
//!   for a CPU load. DMA1 stream 7, in memory-to-memory mode, copies the
//!   words into an AXI SRAM buffer instead; a double ECC error ends the
//!   transfer with TEIF (and sets SR2.DBECCERR), which is returned as
//!   [`Fault::Ecc`] and cleared. (`cvm_fw_app::flash_words` turns such a
//!   word into bytes the store sees as damaged.)

use core::sync::atomic::{Ordering, compiler_fence};

use core::future::poll_fn;
use core::task::Poll;
use cvm_fw_app::flash_words::{Fault, FlashWords, WORD};

use embassy_futures::yield_now;
use embassy_stm32::Peri;
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::pac;
use embassy_stm32::pac::dma::vals::{Dir, Dmdis, Fth, Pl, Size};
use embassy_stm32::peripherals::{DMA1_CH7, FLASH};
use embassy_sync::waitqueue::AtomicWaker;

use super::clocks::enable_clock;
use super::memory::Noload;

/// Bank 2's first byte and size (RM0433 §4: 1 MiB, eight 128 KiB sectors).
pub const BANK2: u32 = 0x0810_0000;
pub const BANK2_SIZE: u32 = 1 << 20;
pub const SECTOR: u32 = 128 * 1024;

/// DMA1 stream 7 (HISR/HIFCR, fourth stream) and its DMAMUX1 channel.
const STREAM: usize = 7;
const FLAGS: usize = 1;
const IN_FLAGS: usize = STREAM - 4;
/// DMAMUX1 request 0: no request; a memory-to-memory stream needs none.
const REQ_NONE: u8 = 0;

/// Words a DMA transfer copies at most (the AXI SRAM buffer).
const CHUNK_WORDS: usize = 64;

/// The DMA destination: AXI SRAM, which DMA1 reaches (not the DTCM stack).
#[unsafe(link_section = ".dma_buffers")]
static CHUNK: Noload<[u32; CHUNK_WORDS]> = Noload::new();

/// Error flags of FLASH_SR2 a program or erase can raise: WRPERR, PGSERR,
/// STRBERR, INCERR, OPERR.
const OP_ERRORS: u32 = (1 << 17) | (1 << 18) | (1 << 19) | (1 << 21) | (1 << 22);
/// Everything FLASH_CCR2 clears: EOP and every error flag.
const CLEAR_ALL: u32 = 0x0FEF_0000;
const DBECCERR: u32 = 1 << 26;
/// A single ECC error: the flash "corrects" the word, but a word whose
/// programming was cut (or repeated) can have several wrong cells that
/// look like one, and the corrected data are then wrong. On the store's
/// range it is a bad word like a double error.
const SNECCERR: u32 = 1 << 25;
/// FLASH_SR2's busy flags: BSY, WBNE (the write buffer holds part of a
/// flash word), QW.
const BSY: u32 = 1 << 0;
const WBNE: u32 = 1 << 1;
const QW: u32 = 1 << 2;

/// Erase and program parallelism, FLASH_CR2.PSIZE = 0b11 (x64): the
/// fastest, which the H743 allows over its whole supply range (unlike the
/// F4's, it has no VPP pin and no parallelism-by-voltage table). DS12110
/// gives a 128 KB sector erase at most 2 s at x64, against 4 s at x8 (the
/// reset value), and a flash word's programming at most 200 µs.
const PSIZE: u8 = 0b11;

/// Bank 2's settings range, through the flash interface and DMA1 stream 7.
pub struct Bank2 {
    /// The range's first address (a sector start in bank 2) and length.
    base: u32,
    len: u32,
    chunk: &'static mut [u32; CHUNK_WORDS],
}

impl Bank2 {
    /// The range `base..base + len` of bank 2, or `None` if it is not
    /// whole sectors of bank 2. Takes FLASH and DMA1 stream 7, which
    /// nothing else may use, and may be called once (its DMA buffer).
    pub fn new(
        _flash: Peri<'static, FLASH>,
        _dma: Peri<'static, DMA1_CH7>,
        base: u32,
        len: u32,
    ) -> Option<Self> {
        let inside = base >= BANK2
            && base
                .checked_add(len)
                .is_some_and(|end| end <= BANK2 + BANK2_SIZE);
        if !inside || !(base - BANK2).is_multiple_of(SECTOR) || !len.is_multiple_of(SECTOR) {
            return None;
        }
        enable_clock(pac::RCC.ahb1enr(), |w| w.set_dma1en(true));
        // The lowest priority: an operation's end can wait for anything.
        interrupt::FLASH.set_priority(interrupt::Priority::P7);
        // SAFETY: the handler touches only FLASH_CR2's interrupt enables
        // and DONE.
        unsafe { interrupt::FLASH.enable() };
        pac::DMAMUX1
            .ccr(STREAM)
            .write(|w| w.set_dmareq_id(REQ_NONE));
        // SAFETY: `_dma` is DMA1 stream 7's only owner, and this buffer is
        // its only destination: one Bank2 takes it.
        let chunk = unsafe { CHUNK.take_zeroed() };
        Some(Bank2 { base, len, chunk })
    }

    /// Copies `words` words from `src` (bank 2) into the chunk buffer.
    async fn copy(&mut self, src: u32, words: usize) -> Result<(), Fault> {
        let dma = pac::DMA1;
        let st = dma.st(STREAM);
        st.cr().write(|_| {});
        while st.cr().read().en() {
            yield_now().await;
        }
        dma.ifcr(FLAGS).write(clear_stream_flags);
        clear_ecc();
        st.par().write_value(src);
        st.m0ar().write_value(self.chunk.as_mut_ptr() as u32);
        st.ndtr().write(|w| w.set_ndt(words as u16));
        st.fcr().write(|w| {
            w.set_dmdis(Dmdis::DISABLED);
            w.set_fth(Fth::FULL);
        });
        let cr = |w: &mut pac::dma::regs::Cr| {
            w.set_dir(Dir::MEMORY_TO_MEMORY);
            w.set_pinc(true);
            w.set_minc(true);
            w.set_psize(Size::BITS32);
            w.set_msize(Size::BITS32);
            w.set_pl(Pl::LOW);
        };
        st.cr().write(cr);
        compiler_fence(Ordering::SeqCst);
        st.cr().write(|w| {
            cr(w);
            w.set_en(true);
        });
        loop {
            let isr = dma.isr(FLAGS).read();
            if isr.teif(IN_FLAGS) || isr.dmeif(IN_FLAGS) || isr.feif(IN_FLAGS) {
                dma.ifcr(FLAGS).write(clear_stream_flags);
                return Err(read_fault());
            }
            if isr.tcif(IN_FLAGS) {
                dma.ifcr(FLAGS).write(clear_stream_flags);
                compiler_fence(Ordering::SeqCst);
                // A single-error word completes the transfer with data
                // that may be wrong: it fails the read all the same.
                if pac::FLASH.bank(1).sr().read().0 & SNECCERR != 0 {
                    return Err(read_fault());
                }
                return Ok(());
            }
            yield_now().await;
        }
    }
}

fn clear_stream_flags(w: &mut pac::dma::regs::Ixr) {
    w.set_tcif(IN_FLAGS, true);
    w.set_htif(IN_FLAGS, true);
    w.set_teif(IN_FLAGS, true);
    w.set_dmeif(IN_FLAGS, true);
    w.set_feif(IN_FLAGS, true);
}

/// What failed a read: an ECC error of bank 2 (SR2.DBECCERR, or
/// SNECCERR on a transfer that completed), or another bus error. The
/// failing word's address is read before the flags are cleared: clearing
/// them releases FLASH_ECC_FA2R for the next error.
fn read_fault() -> Fault {
    let bank = pac::FLASH.bank(1);
    let sr = bank.sr().read().0;
    let word = bank.far().read().fail_ecc_addr();
    bank.ccr()
        .write_value(pac::flash::regs::Ccr(sr & CLEAR_ALL));
    if sr & (DBECCERR | SNECCERR) != 0 {
        let double = sr & DBECCERR != 0;
        defmt::warn!(
            "settings flash: ECC error (double: {}) in flash word {}",
            double,
            word
        );
        Fault::Ecc
    } else {
        Fault::Read
    }
}

/// Clears ECC flags left by an earlier read, so that a flag seen after a
/// transfer is that transfer's.
fn clear_ecc() {
    pac::FLASH
        .bank(1)
        .ccr()
        .write_value(pac::flash::regs::Ccr(DBECCERR | SNECCERR));
}

/// Wakes the task waiting for bank 2's operation (the FLASH interrupt).
static DONE: AtomicWaker = AtomicWaker::new();

/// The end of an operation (EOP) or its error: the interrupt sources are
/// masked again (the flags stay for `finish` to read) and the waiting task
/// woken. A flash word takes up to 200 µs at x64 and a sector erase up to
/// 2 s: waiting on the interrupt, the executor runs the other tasks or
/// sleeps meanwhile, where a loop of `yield_now` would poll for the whole
/// erase.
#[interrupt]
fn FLASH() {
    pac::FLASH
        .bank(1)
        .cr()
        .modify(|w| done_interrupts(w, false));
    DONE.wake();
}

fn done_interrupts(w: &mut pac::flash::regs::Cr, on: bool) {
    w.set_eopie(on);
    w.set_wrperrie(on);
    w.set_pgserrie(on);
    w.set_strberrie(on);
    w.set_incerrie(on);
    w.set_operrie(on);
}

/// Whether bank 2 is erasing or programming (`main` sleeps while it is).
pub fn busy() -> bool {
    pac::FLASH.bank(1).sr().read().0 & (QW | BSY) != 0
}

/// Until no operation is queued or running.
async fn idle() {
    poll_fn(|cx| {
        DONE.register(cx.waker());
        if busy() {
            Poll::Pending
        } else {
            Poll::Ready(())
        }
    })
    .await
}

/// Unlocks CR2 (when locked) and waits until no operation is queued.
async fn begin() {
    let bank = pac::FLASH.bank(1);
    if bank.cr().read().lock() {
        bank.keyr().write_value(0x4567_0123);
        bank.keyr().write_value(0xCDEF_89AB);
    }
    // Nothing runs here (`finish` waited for every operation): a poll,
    // not the interrupt, which is off between operations.
    while busy() {
        yield_now().await;
    }
    bank.ccr().write_value(pac::flash::regs::Ccr(CLEAR_ALL));
}

/// Waits until the queued operation is done (QW and BSY clear); its
/// error flags (cleared), then CR2 cleared and locked. A write buffer
/// still holding part of a flash word (WBNE) is forced out and counted
/// as an error: PG must not be cleared over it.
async fn finish() -> u32 {
    let bank = pac::FLASH.bank(1);
    idle().await;
    let mut partial = 0;
    if bank.sr().read().0 & WBNE != 0 {
        partial = WBNE;
        bank.cr().modify(|w| {
            w.set_fw(true);
            done_interrupts(w, true);
        });
        idle().await;
    }
    let errors = bank.sr().read().0 & OP_ERRORS | partial;
    bank.ccr().write_value(pac::flash::regs::Ccr(CLEAR_ALL));
    bank.cr().write(|w| w.set_lock(true));
    errors
}

impl FlashWords for Bank2 {
    const SECTOR: usize = SECTOR as usize;

    fn capacity(&self) -> usize {
        self.len as usize
    }

    async fn read(&mut self, offset: u32, buf: &mut [u8]) -> Result<(), Fault> {
        let mut src = self.base + offset;
        for part in buf.chunks_mut(CHUNK_WORDS * 4) {
            let words = part.len() / 4;
            self.copy(src, words).await?;
            for (out, w) in part.chunks_exact_mut(4).zip(self.chunk.iter()) {
                out.copy_from_slice(&w.to_le_bytes());
            }
            src += part.len() as u32;
        }
        Ok(())
    }

    async fn program(&mut self, offset: u32, word: &[u8; WORD]) -> Result<(), Fault> {
        let bank = pac::FLASH.bank(1);
        begin().await;
        bank.cr().write(|w| {
            w.set_pg(true);
            w.set_psize(PSIZE);
            done_interrupts(w, true);
        });
        cortex_m::asm::dsb();
        let dst = (self.base + offset) as *mut u32;
        for (i, w) in word.chunks_exact(4).enumerate() {
            let v = u32::from_le_bytes([w[0], w[1], w[2], w[3]]);
            // SAFETY: a word of bank 2 inside the settings range, which
            // the linker gives nothing else; CR2.PG routes the write to
            // the flash word's write buffer.
            unsafe { core::ptr::write_volatile(dst.add(i), v) };
        }
        cortex_m::asm::dsb();
        match finish().await {
            0 => Ok(()),
            e => Err(Fault::Program(e)),
        }
    }

    async fn erase(&mut self, offset: u32) -> Result<(), Fault> {
        let bank = pac::FLASH.bank(1);
        let snb = ((self.base + offset - BANK2) / SECTOR) as u8;
        begin().await;
        bank.cr().write(|w| {
            w.set_ser(true);
            w.set_psize(PSIZE);
            w.set_snb(snb);
            done_interrupts(w, true);
        });
        bank.cr().write(|w| {
            w.set_ser(true);
            w.set_psize(PSIZE);
            w.set_snb(snb);
            done_interrupts(w, true);
            w.set_start(true);
        });
        cortex_m::asm::dsb();
        match finish().await {
            0 => Ok(()),
            e => Err(Fault::Erase(e)),
        }
    }
}
