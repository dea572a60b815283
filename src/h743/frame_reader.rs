//! Detector frames over SPI1 with DMA1 stream 1, driven at register level.
//!
//! SPI1 runs as a receive-only master with 16-bit frames: the detector's
//! samples (MSB first on the bus) land in memory as native `u16`, so the
//! scoring side reads them without decoding. `CR1.MASRX` suspends the clock
//! instead of overrunning when the RX FIFO fills. Every way a read can go
//! wrong (an overrun, a DMA transfer error, a read that does not finish in
//! time) is a [`ReadError`] value, and the peripheral and the stream are
//! stopped and cleared before the next read, so one bad frame never wedges
//! acquisition. (embassy's SPI driver is not used for the transfer: its
//! `read` reports no error on this chip and its DMA handler panics on a
//! transfer error.)

use embassy_stm32::interrupt;
use embassy_stm32::pac;
use embassy_stm32::pac::dma::vals::{Dir, Dmdis, Pl, Size};
use embassy_stm32::pac::spi::vals::{Comm, Fthlv, Master, Mbr};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::signal::Signal;

use super::read_deadline::ReadDeadline;

/// DMA1 stream 1 (and DMAMUX1 channel 1), in LISR/LIFCR.
const STREAM: usize = 1;
/// DMAMUX1 request line of SPI1 RX (RM0433 Table 121).
const REQ_SPI1_RX: u8 = 37;

#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum ReadError {
    /// A frame was lost in the SPI (OVR).
    Overrun,
    /// DMA transfer, direct-mode or FIFO error.
    Dma,
    /// The frame did not arrive in time (the SPI or the DMA stalled).
    Timeout,
}

#[derive(Clone, Copy)]
pub(super) enum DmaEnd {
    Complete,
    Error,
    /// The read's deadline ran out first (`read_deadline`).
    Timeout,
}

pub(super) static DMA_END: Signal<CriticalSectionRawMutex, DmaEnd> = Signal::new();

#[interrupt]
fn DMA1_STREAM1() {
    let dma = pac::DMA1;
    let isr = dma.isr(0).read();
    dma.ifcr(0).write(clear_flags);
    if isr.teif(STREAM) || isr.dmeif(STREAM) || isr.feif(STREAM) {
        DMA_END.signal(DmaEnd::Error);
    } else if isr.tcif(STREAM) {
        DMA_END.signal(DmaEnd::Complete);
    }
}

fn clear_flags(w: &mut pac::dma::regs::Ixr) {
    w.set_tcif(STREAM, true);
    w.set_htif(STREAM, true);
    w.set_teif(STREAM, true);
    w.set_dmeif(STREAM, true);
    w.set_feif(STREAM, true);
}

/// SPI1 configured once; then one [`FrameReader::read`] per frame.
pub struct FrameReader {
    counts: ReadCounts,
    deadline: ReadDeadline,
}

/// Failed reads since start-up, by cause.
#[derive(Clone, Copy, Debug, Default, defmt::Format)]
pub struct ReadCounts {
    pub overruns: u32,
    pub dma_errors: u32,
    pub timeouts: u32,
}

impl FrameReader {
    /// Takes SPI1 over from the pins' set-up (`embassy_stm32::spi::Spi`
    /// configured the pins, the kernel clock and the bus clock) with SCK =
    /// kernel clock / `div`; a read that takes more than `timeout_us`
    /// microseconds is a [`ReadError::Timeout`].
    pub fn new(div: Mbr, timeout_us: u32) -> Self {
        pac::RCC.ahb1enr().modify(|w| w.set_dma1en(true));
        let spi = pac::SPI1;
        spi.cr1().modify(|w| w.set_spe(false));
        spi.cfg1().modify(|w| {
            w.set_dsize(16 - 1);
            w.set_fthlv(Fthlv::ONE_FRAME);
            w.set_rxdmaen(true);
            w.set_txdmaen(false);
            w.set_mbr(div);
        });
        spi.cfg2().modify(|w| {
            w.set_comm(Comm::RECEIVER);
            w.set_master(Master::MASTER);
            w.set_ssm(true);
            // Keep SCK driven (idle low) between frames, not floating.
            w.set_afcntr(true);
        });
        spi.cr1().modify(|w| {
            w.set_ssi(true);
            w.set_masrx(true);
        });
        pac::DMAMUX1
            .ccr(STREAM)
            .write(|w| w.set_dmareq_id(REQ_SPI1_RX));
        let irq = interrupt::DMA1_STREAM1;
        use embassy_stm32::interrupt::InterruptExt;
        irq.set_priority(interrupt::Priority::P5);
        // SAFETY: the handler above only touches DMA1's flags and a signal.
        unsafe { irq.enable() };
        FrameReader {
            counts: ReadCounts::default(),
            deadline: ReadDeadline::new(timeout_us),
        }
    }

    pub fn counts(&self) -> ReadCounts {
        self.counts
    }

    /// Reads `buf.len()` samples (at most 65535). `buf` must be in memory
    /// that DMA1 reaches (the `.dma_buffers` section: AXI SRAM).
    pub async fn read(&mut self, buf: &mut [u16]) -> Result<(), ReadError> {
        let spi = pac::SPI1;
        let st = pac::DMA1.st(STREAM);
        let n = buf.len().min(u16::MAX as usize) as u16;
        DMA_END.reset();
        st.par().write_value(spi.rxdr16().as_ptr() as u32);
        st.m0ar().write_value(buf.as_mut_ptr() as u32);
        st.ndtr().write(|w| w.set_ndt(n));
        st.fcr().write(|w| w.set_dmdis(Dmdis::ENABLED));
        st.cr().write(|w| {
            w.set_dir(Dir::PERIPHERAL_TO_MEMORY);
            w.set_psize(Size::BITS16);
            w.set_msize(Size::BITS16);
            w.set_minc(true);
            w.set_pl(Pl::VERY_HIGH);
            w.set_tcie(true);
            w.set_teie(true);
            w.set_dmeie(true);
            w.set_en(true);
        });
        spi.cr2().modify(|w| w.set_tsize(n));
        spi.cr1().modify(|w| w.set_spe(true));
        self.deadline.start();
        spi.cr1().modify(|w| w.set_cstart(true));

        let end = DMA_END.wait().await;
        let overrun = spi.sr().read().ovr();
        self.stop();
        let result = match end {
            DmaEnd::Timeout => Err(ReadError::Timeout),
            DmaEnd::Error => Err(ReadError::Dma),
            DmaEnd::Complete if overrun => Err(ReadError::Overrun),
            DmaEnd::Complete => Ok(()),
        };
        match result {
            Err(ReadError::Overrun) => self.counts.overruns = self.counts.overruns.wrapping_add(1),
            Err(ReadError::Dma) => self.counts.dma_errors = self.counts.dma_errors.wrapping_add(1),
            Err(ReadError::Timeout) => self.counts.timeouts = self.counts.timeouts.wrapping_add(1),
            Ok(()) => {}
        }
        result
    }

    /// Ends the transfer whatever its state: SPE = 0 aborts a running or
    /// suspended transfer and flushes the FIFOs (RM0433 §50.4.9), the
    /// stream is disabled, and every flag of both is cleared.
    fn stop(&mut self) {
        self.deadline.stop();
        let spi = pac::SPI1;
        let dma = pac::DMA1;
        spi.cr1().modify(|w| w.set_spe(false));
        dma.st(STREAM).cr().modify(|w| w.set_en(false));
        // EN reads 1 until the stream has finished its current item.
        for _ in 0..64 {
            if !dma.st(STREAM).cr().read().en() {
                break;
            }
        }
        dma.ifcr(0).write(clear_flags);
        spi.ifcr().write(|w| {
            w.set_eotc(true);
            w.set_txtfc(true);
            w.set_ovrc(true);
            w.set_suspc(true);
            w.set_udrc(true);
            w.set_modfc(true);
            w.set_tifrec(true);
        });
        DMA_END.reset();
    }
}
