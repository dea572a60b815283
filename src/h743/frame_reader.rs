//! Detector frames over SPI1 with DMA1 stream 1, driven at register level.
//!
//! SPI1 runs as a receive-only master with 16-bit frames: the detector's
//! samples (MSB first on the bus) land in memory as native `u16`, so the
//! scoring side reads them without decoding. `CR1.MASRX` suspends the clock
//! instead of overrunning when the RX FIFO fills. Every way a read can go
//! wrong (an overrun, a DMA transfer error, a read that does not finish in
//! time, a mode fault) is a [`ReadError`] value, and the peripheral and the stream are
//! stopped and cleared before the next read, so one bad frame never wedges
//! acquisition. (embassy's SPI driver is not used for the transfer: its
//! `read` reports no error on this chip and its DMA handler panics on a
//! transfer error.)
//!
//! Reads run from interrupts, with no task in between: the DRDY interrupt
//! starts one ([`start`]); the end of the transfer (DMA1 stream 1), a
//! transfer error, or the read's deadline (TIM13, `read_deadline`) ends it
//! ([`end`]), releases CS, hands the result to the acquisition log and
//! wakes the scoring task. All three interrupts have the same priority, so
//! none preempts another, and the first to end a read makes the others'
//! late calls do nothing. (An acquisition task in its own interrupt
//! executor did the same with two wake-ups and two polls per beam:
//! docs/firmware.md, "SPI1 configuration and measured costs".)

use core::cell::RefCell;

use defmt::warn;
use embassy_stm32::Peri;
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::pac;
use embassy_stm32::pac::dma::vals::{Dir, Dmdis, Pl, Size};
use embassy_stm32::pac::spi::vals::{
    Comm, Cpha, Cpol, Fthlv, Lsbfirst, Master, Mbr, Sp, Ssiop, Ssom, Udrcfg, Udrdet,
};
use embassy_stm32::peripherals::{PA5, PA6, PD14, SPI1};
use embassy_stm32::spi;
use embassy_stm32::time::Hertz;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;

use super::clocks::enable_clock;
use super::read_deadline::{self, ReadDeadline};
use super::resources::{ACQ, BEAMS, CELLS, FRAMES};
use crate::config::h743::{READ_TIMEOUT_US, SPI_DIV, SPI_HZ};

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
    /// SPI1 saw its slave select active and left master mode (MODF).
    ModeFault,
}

/// How a read ended.
#[derive(Clone, Copy)]
enum ReadEnd {
    Complete,
    Error,
    /// The read's deadline ran out first (`read_deadline`).
    Timeout,
}

/// The reader, shared by the three interrupts that start and end reads;
/// [`install`] puts it here before DRDY is enabled.
static READER: Mutex<CriticalSectionRawMutex, RefCell<Option<FrameReader>>> =
    Mutex::new(RefCell::new(None));

/// Sets up SPI1, DMA1 stream 1 and TIM13 for reads from the detector
/// (SCK = `SPI_HZ`, CS idle high) and puts the reader where the
/// interrupts find it.
pub fn install(
    spi: Peri<'static, SPI1>,
    sck: Peri<'static, PA5>,
    miso: Peri<'static, PA6>,
    cs: Peri<'static, PD14>,
) {
    // embassy sets up the pins, the bus and the kernel clocks (the driver
    // is forgotten: its drop would turn SPI1 off); `configure` then writes
    // every register field the reads depend on.
    let mut cfg = spi::Config::default();
    cfg.frequency = Hertz(SPI_HZ);
    core::mem::forget(spi::Spi::new_blocking_rxonly(spi, sck, miso, cfg));
    let cs = Output::new(cs, Level::High, Speed::VeryHigh);
    let reader = FrameReader::new(SPI_DIV, READ_TIMEOUT_US, cs);
    READER.lock(|r| r.replace(Some(reader)));
}

/// The read's deadline (TIM13). Its vector can be entered with no expiry
/// behind it (a pend that raced `ReadDeadline::stop`), so the timer's own
/// flag decides, not the entry.
#[interrupt]
fn TIM8_UP_TIM13() {
    if read_deadline::take_expiry() {
        end(ReadEnd::Timeout);
    }
}

#[interrupt]
fn DMA1_STREAM1() {
    let dma = pac::DMA1;
    let isr = dma.isr(0).read();
    dma.ifcr(0).write(clear_flags);
    if isr.teif(STREAM) || isr.dmeif(STREAM) || isr.feif(STREAM) {
        end(ReadEnd::Error);
    } else if isr.tcif(STREAM) {
        end(ReadEnd::Complete);
    }
}

/// Starts reading the frame of the beam the acquisition log gave buffer
/// `buf` (DRDY interrupt).
pub fn start(buf: usize) {
    // SAFETY: `buf` is Filling: the acquisition side owns it until the
    // read ends and `read_done` hands it on.
    let samples = unsafe { FRAMES.buffer(buf) };
    let stale = READER.lock(|r| {
        let mut r = r.borrow_mut();
        let r = r.as_mut()?;
        // The log waits for the SPI before it gives out a buffer, so no
        // read is running; should one be, it ends as a timeout.
        let stale = r.end(ReadEnd::Timeout);
        r.start(buf, &mut samples[..CELLS]);
        stale
    });
    if let Some(ended) = stale {
        report(ended);
    }
}

/// Ends the read in progress, if any, as `how` says (DMA and TIM13
/// interrupts). Out of line: inlined into both handlers it doubles in
/// flash.
#[inline(never)]
fn end(how: ReadEnd) {
    if let Some(ended) = READER.lock(|r| r.borrow_mut().as_mut().and_then(|r| r.end(how))) {
        report(ended);
    }
}

/// An ended read's result to the acquisition log; wakes the scoring task.
fn report((buf, result): (usize, Result<(), ReadError>)) {
    ACQ.lock(|a| a.borrow_mut().read_done(buf, result.is_ok()));
    BEAMS.signal(());
    if let Err(e) = result {
        lost(e);
    }
}

/// Logs a lost frame with the failure counts so far. Out of line, once
/// for the three interrupts: a rare path. The counts are read here rather
/// than returned by every `end`, where the larger value cost every beam a
/// memcpy.
#[cold]
#[inline(never)]
fn lost(e: ReadError) {
    let counts = READER.lock(|r| r.borrow().as_ref().map(|r| r.counts));
    warn!("frame lost: {} ({})", e, counts.unwrap_or_default());
}

fn clear_flags(w: &mut pac::dma::regs::Ixr) {
    w.set_tcif(STREAM, true);
    w.set_htif(STREAM, true);
    w.set_teif(STREAM, true);
    w.set_dmeif(STREAM, true);
    w.set_feif(STREAM, true);
}

fn clear_spi_flags(w: &mut pac::spi::regs::Ifcr) {
    w.set_eotc(true);
    w.set_txtfc(true);
    w.set_udrc(true);
    w.set_ovrc(true);
    w.set_crcec(true);
    w.set_tifrec(true);
    w.set_modfc(true);
    w.set_tserfc(true);
    w.set_suspc(true);
}

/// Writes every SPI1 field a read depends on, whole registers, so that
/// nothing is inherited from `embassy_stm32::spi` (which leaves SSIOP
/// active-high, SSOE set, COMM full-duplex, SSI clear and SPE set) or from
/// a mode fault (which clears MASTER and SPE). Leaves SPE = 0 and RXDMAEN
/// = 0: each read sets them (docs/firmware.md, "SPI1 configuration and
/// measured costs").
fn configure(div: Mbr) {
    let spi = pac::SPI1;
    // SPE = 0 first: CFG1 and CFG2 ignore writes while it is set. SSI = 1
    // is the inactive level of the internal slave select once CFG2 below
    // makes it active-low; a master whose slave select is active raises
    // MODF as soon as SPE is set.
    spi.cr1().write(|w| {
        w.set_ssi(true);
        w.set_masrx(true);
    });
    // A fault left over from before (embassy's own configuration, or the
    // one this call recovers from) would keep MASTER from sticking.
    spi.ifcr().write(clear_spi_flags);
    spi.cfg1().write(|w| {
        w.set_dsize(16 - 1);
        w.set_fthlv(Fthlv::ONE_FRAME);
        // Slave-only fields, at their reset values.
        w.set_udrcfg(Udrcfg::CONSTANT);
        w.set_udrdet(Udrdet::START_OF_FRAME);
        w.set_rxdmaen(false);
        w.set_txdmaen(false);
        // CRC off; CRCSIZE at its reset value.
        w.set_crcsize(8 - 1);
        w.set_crcen(false);
        w.set_mbr(div);
    });
    spi.cfg2().write(|w| {
        w.set_mssi(0);
        w.set_midi(0);
        w.set_ioswp(false);
        w.set_comm(Comm::RECEIVER);
        w.set_sp(Sp::MOTOROLA);
        w.set_master(Master::MASTER);
        // Mode 0, MSB first: the detector's samples as native `u16`.
        w.set_lsbfirst(Lsbfirst::MSBFIRST);
        w.set_cpha(Cpha::FIRST_EDGE);
        w.set_cpol(Cpol::IDLE_LOW);
        // Software slave select, active low, held inactive by SSI = 1;
        // the NSS pin is neither read nor driven (CS is a GPIO).
        w.set_ssm(true);
        w.set_ssiop(Ssiop::ACTIVE_LOW);
        w.set_ssoe(false);
        w.set_ssom(Ssom::ASSERTED);
        // Keep SCK driven (idle low) between frames, not floating.
        w.set_afcntr(true);
    });
    spi.cr2().write(|_| {});
    // No SPI1 interrupt: the DMA stream and TIM13 end every read.
    spi.ier().write(|_| {});
    // SPI, not I2S.
    spi.i2scfgr().write(|_| {});
}

/// SPI1 configured once; then one [`FrameReader::start`] and one
/// [`FrameReader::end`] per frame.
struct FrameReader {
    div: Mbr,
    counts: ReadCounts,
    deadline: ReadDeadline,
    cs: Output<'static>,
    /// The buffer being filled.
    reading: Option<usize>,
}

/// Failed reads since start-up, by cause.
#[derive(Clone, Copy, Debug, Default, defmt::Format)]
pub struct ReadCounts {
    pub overruns: u32,
    pub dma_errors: u32,
    pub timeouts: u32,
    pub mode_faults: u32,
}

impl FrameReader {
    /// Takes SPI1 over from the pins' set-up (`embassy_stm32::spi::Spi`
    /// configured the pins, the kernel clock and the bus clock) with SCK =
    /// kernel clock / `div`; a read that takes more than `timeout_us`
    /// microseconds is a [`ReadError::Timeout`]; `cs` is the detector's
    /// chip select (high: idle).
    fn new(div: Mbr, timeout_us: u32, cs: Output<'static>) -> Self {
        enable_clock(pac::RCC.ahb1enr(), |w| w.set_dma1en(true));
        configure(div);
        pac::DMAMUX1
            .ccr(STREAM)
            .write(|w| w.set_dmareq_id(REQ_SPI1_RX));
        let deadline = ReadDeadline::new(timeout_us);
        // The deadline's interrupt has the DMA stream's priority: neither
        // preempts the other.
        for irq in [interrupt::DMA1_STREAM1, interrupt::TIM8_UP_TIM13] {
            irq.set_priority(interrupt::Priority::P5);
            // SAFETY: the handlers above only touch DMA1's flags, TIM13
            // and the mutex-protected reader and acquisition log.
            unsafe { irq.enable() };
        }
        FrameReader {
            div,
            counts: ReadCounts::default(),
            deadline,
            cs,
            reading: None,
        }
    }

    /// Asserts CS and starts reading `samples.len()` samples (at most
    /// 65535) into buffer `buf`, `samples`, which must be in memory that
    /// DMA1 reaches (the `.dma_buffers` section: AXI SRAM).
    fn start(&mut self, buf: usize, samples: &mut [u16]) {
        let spi = pac::SPI1;
        let st = pac::DMA1.st(STREAM);
        let n = samples.len().min(u16::MAX as usize) as u16;
        self.cs.set_low();
        // RM0433's order: the SPI's DMA request, then the stream, then SPE.
        spi.cfg1().modify(|w| w.set_rxdmaen(true));
        st.par().write_value(spi.rxdr16().as_ptr() as u32);
        st.m0ar().write_value(samples.as_mut_ptr() as u32);
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
        self.reading = Some(buf);
    }

    /// Ends the read in progress as `how` says: stops SPI1, the stream and
    /// the deadline, releases CS, counts a failure. Returns the buffer and
    /// the result, or `None` when no read was running.
    fn end(&mut self, how: ReadEnd) -> Option<(usize, Result<(), ReadError>)> {
        let buf = self.reading.take()?;
        let sr = pac::SPI1.sr().read();
        self.stop();
        self.cs.set_high();
        if sr.modf() {
            // MODF cleared SPE and MASTER; `stop` cleared the flag.
            configure(self.div);
        }
        let overrun = sr.ovr();
        let result = match how {
            _ if sr.modf() => Err(ReadError::ModeFault),
            ReadEnd::Timeout => Err(ReadError::Timeout),
            ReadEnd::Error => Err(ReadError::Dma),
            ReadEnd::Complete if overrun => Err(ReadError::Overrun),
            ReadEnd::Complete => Ok(()),
        };
        match result {
            Err(ReadError::Overrun) => self.counts.overruns = self.counts.overruns.wrapping_add(1),
            Err(ReadError::Dma) => self.counts.dma_errors = self.counts.dma_errors.wrapping_add(1),
            Err(ReadError::Timeout) => self.counts.timeouts = self.counts.timeouts.wrapping_add(1),
            Err(ReadError::ModeFault) => {
                self.counts.mode_faults = self.counts.mode_faults.wrapping_add(1)
            }
            Ok(()) => {}
        }
        Some((buf, result))
    }

    /// Ends the transfer whatever its state, in RM0433's close order for
    /// an SPI with DMA: the stream off, then SPE = 0 (which aborts a
    /// running or suspended transfer and flushes the FIFOs), then the SPI's
    /// DMA request off; then every flag of both is cleared.
    fn stop(&mut self) {
        self.deadline.stop();
        let spi = pac::SPI1;
        let dma = pac::DMA1;
        dma.st(STREAM).cr().modify(|w| w.set_en(false));
        // EN reads 1 until the stream has finished its current item.
        for _ in 0..64 {
            if !dma.st(STREAM).cr().read().en() {
                break;
            }
        }
        spi.cr1().modify(|w| w.set_spe(false));
        spi.cfg1().modify(|w| w.set_rxdmaen(false));
        dma.ifcr(0).write(clear_flags);
        spi.ifcr().write(clear_spi_flags);
        // The read-back completes the flag clear at the DMA before the
        // NVIC write below: otherwise the stream's line could pend the
        // interrupt again after it. An end the other interrupt raised
        // meanwhile is for this read.
        let _ = dma.isr(0).read();
        interrupt::DMA1_STREAM1.unpend();
    }
}
