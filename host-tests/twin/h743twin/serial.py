"""SPI1 (RM0433 §50, the H7 SPI with FIFOs, TSIZE and CSTART) as a master,
and USART3 (RM0433 §48) as a transmitter; its receiver is in usart_rx.py.

SPI1: frames of DSIZE+1 bits take (DSIZE+1) SCK periods, SCK being the
kernel clock (PLL1 Q through D2CCIP1R) divided by 2^(MBR+1). Full duplex
shifts a frame when the TX FIFO holds one; receive-only (COMM = 10) shifts
until TSIZE frames are in. A frame that finds the RX FIFO full is lost with
OVR, unless MASRX is set, which suspends the clock (SUSP) until SUSPC or
CSTART. The slave's answer comes from the detector model.

Slave select (RM0433 §50.4, slave select management and error flags;
SPI_CR1, SPI_CFG2): the internal SS input is SSI when SSM = 1, else the
NSS pin (which a master with SSOE = 1 drives itself, so it never sees it
active); it is active when its level equals SSIOP. A master whose SS input is active while SPE is
set has a mode fault: MODF is set, SPE and MASTER are cleared (the SPI is
now a disabled slave, so CSTART starts nothing), and SPE cannot be set
again until MODF is cleared through IFCR.MODFC. A slave on this board
never sees a clock (the detector is a slave too): it shifts nothing.

USART3: a byte written to TDR (or by DMA while DMAT is set) moves to the
shift register when it is free and leaves it ten bit times later (8N1 at
the kernel clock divided by BRR); every byte is captured with its time.
"""

from .core import CLOCK_HZ, Stop
from .dma import REQ_SPI1_RX, REQ_SPI1_TX, REQ_USART3_TX
from .usart_rx import REQ_USART3_RX, Receiver

SPI1_IRQ = 35
USART3_IRQ = 39

# SPI_CR1
SPE, MASRX, CSTART, CSUSP, SSI = 1 << 0, 1 << 8, 1 << 9, 1 << 10, 1 << 12
# SPI_CFG2
MASTER, SSM, SSIOP, SSOE = 1 << 22, 1 << 26, 1 << 28, 1 << 29
# SPI_SR, and SPI_IFCR at the same positions
EOT, TXTF, OVR, MODF, SUSP = 1 << 3, 1 << 4, 1 << 6, 1 << 9, 1 << 11
IFCR_MASK = 0xFF8  # EOTC .. SUSPC


class Spi:
    FIFO_BYTES = 16

    def __init__(self, bus, nvic, dma, rcc, slave):
        self.bus = bus
        self.nvic = nvic
        self.dma = dma
        self.rcc = rcc
        self.slave = slave  # .exchange(tx, bits) -> rx
        self.cr1 = 0
        self.cr2 = 0
        self.cfg1 = 0x0007_0007
        self.cfg2 = 0
        self.ier = 0
        self.flags = 0  # EOT, TXTF, UDR, OVR, CRCE, TIFRE, MODF, TSERF, SUSP
        self.i2scfgr = 0
        self.crcpoly = 0x107
        self.tx = []
        self.rx = []
        self.active = False
        self.suspended = False
        self.done = 0
        self.busy_until = None
        self.resume_at = None   # while a word's end is handled: when it ended
        self.gen = 0
        self.frames = 0
        self.overruns = 0
        self.mode_faults = 0
        self.force_overrun = 0  # frames to lose with OVR (fault injection)
        # Level of the NSS pin (PA4/PA15/PG10 in AF5) when SSM = 0; None:
        # not wired on this board, and a run that needs it stops.
        self.nss_pin = None
        dma.register(REQ_SPI1_RX, self.rx_request)
        dma.register(REQ_SPI1_TX, self.tx_request)

    # --- geometry of a frame
    def bits(self):
        return (self.cfg1 & 0x1F) + 1

    def frame_bytes(self):
        b = self.bits()
        return 1 if b <= 8 else 2 if b <= 16 else 4

    def fifo_frames(self):
        return self.FIFO_BYTES // self.frame_bytes()

    def threshold(self):
        return ((self.cfg1 >> 5) & 0xF) + 1

    def sck_hz(self):
        return self.rcc.spi123_kernel_hz() / (2 << ((self.cfg1 >> 28) & 7))

    def comm(self):
        return (self.cfg2 >> 17) & 3

    def tsize(self):
        return self.cr2 & 0xFFFF

    # --- DMA request lines
    def rx_request(self):
        return bool(self.cfg1 >> 14 & 1) and len(self.rx) >= self.threshold()

    def tx_request(self):
        return bool(self.cfg1 >> 15 & 1) and self.txp()

    def txp(self):
        if not self.cr1 & 1:
            return False
        if self.tsize() and len(self.tx) + self.done >= self.tsize():
            return False
        return len(self.tx) < self.fifo_frames()

    # --- status
    def sr(self):
        sr = self.flags
        if len(self.rx) >= self.threshold():
            sr |= 1  # RXP
        if self.txp():
            sr |= 2  # TXP
        if sr & 3 == 3:
            sr |= 4  # DXP
        if not self.active and not self.tx:
            sr |= 1 << 12  # TXC
        if self.rx:
            lvl = min(len(self.rx), 3)
            sr |= lvl << 13
        if self.tsize():
            sr |= max(self.tsize() - self.done, 0) << 16
        return sr

    def update(self):
        self.nvic.set_line(SPI1_IRQ, bool(self.sr() & self.ier & 0x3FF))
        self.dma.poll(REQ_SPI1_RX)
        self.dma.poll(REQ_SPI1_TX)
        self.kick()

    # --- shifting
    def can_shift(self):
        if not (self.active and self.cr1 & SPE and self.cfg2 & MASTER) or self.suspended:
            return False
        if self.tsize() and self.done >= self.tsize():
            return False
        return self.comm() == 2 or bool(self.tx)

    def kick(self):
        if self.busy_until is not None or not self.can_shift():
            return
        cycles = max(1, round(self.bits() * CLOCK_HZ / self.sck_hz()))
        # A word that follows the one just shifted starts when that one
        # ended: the model gets here only at the core's next block
        # boundary, and SCK does not wait for the core.
        start = self.resume_at if self.resume_at is not None else self.bus.core.cycles
        self.busy_until = start + cycles
        self.gen += 1
        gen = self.gen
        due = self.busy_until
        self.bus.at(due, lambda: self.shifted(gen, due))

    def shifted(self, gen, due):
        if gen != self.gen:
            return
        self.busy_until = None
        self.resume_at = due
        try:
            self._shifted()
        finally:
            self.resume_at = None

    def _shifted(self):
        if not self.can_shift():
            return
        out = self.tx.pop(0) if self.comm() != 2 and self.tx else 0
        value = self.slave.exchange(out, self.bits()) & ((1 << self.bits()) - 1)
        self.frames += 1
        self.done += 1
        if self.force_overrun:
            self.force_overrun -= 1
            self.flags |= 1 << 6
            self.overruns += 1
        elif len(self.rx) < self.fifo_frames():
            self.rx.append(value)
        elif self.cr1 >> 8 & 1:  # MASRX: suspend instead of losing data
            self.done -= 1
            self.slave.unread()
            self.suspended = True
            self.flags |= 1 << 11
        else:
            self.flags |= 1 << 6  # OVR
            self.overruns += 1
        if self.tsize() and self.done >= self.tsize():
            self.flags |= (1 << 3) | (1 << 4)  # EOT, TXTF
            self.active = False
        self.update()

    def stop(self):
        self.active = False
        self.suspended = False
        self.gen += 1
        self.busy_until = None

    # --- registers
    def read(self, off, size):
        if off == 0x00:
            return self.cr1 | (0x200 if self.active else 0)
        if off == 0x04:
            return self.cr2
        if off == 0x08:
            return self.cfg1
        if off == 0x0C:
            return self.cfg2
        if off == 0x10:
            return self.ier
        if off == 0x14:
            return self.sr()
        if 0x30 <= off < 0x34:
            value = self.rx.pop(0) if self.rx else 0
            self.update()
            return value
        if off == 0x40:
            return self.crcpoly
        if off in (0x44, 0x48, 0x4C):
            return 0
        if off == 0x50:
            return self.i2scfgr
        raise KeyError

    def write(self, off, size, value):
        if off == 0x00:
            self._write_cr1(value)
        elif off == 0x04:
            self.cr2 = value
        elif off == 0x08:
            self._config_write("CFG1")
            self.cfg1 = value
        elif off == 0x0C:
            self._config_write("CFG2")
            self.cfg2 = value
        elif off == 0x10:
            self.ier = value
        elif off == 0x18:
            self.flags &= ~(value & IFCR_MASK)
            if value & SUSP and self.suspended and self.cr1 & SPE:
                # A master suspended by MASRX resumes when SUSP is cleared.
                self.suspended = False
        elif 0x20 <= off < 0x24:
            if len(self.tx) < self.fifo_frames():
                self.tx.append(value)
        elif off == 0x40:
            self.crcpoly = value
        elif off == 0x50:
            self.i2scfgr = value
        else:
            raise KeyError
        self.update()

    def _write_cr1(self, value):
        was_on = self.cr1 & SPE
        cr1 = value & ~(CSTART | CSUSP)
        if cr1 & SPE and not was_on and self.flags & MODF:
            cr1 &= ~SPE  # RM0433: SPE cannot be set while MODF is set
        self.cr1 = cr1
        if was_on and not cr1 & SPE:
            self._disabled()
        if cr1 & SPE and not was_on:
            self.done = 0
        if self._mode_fault():
            return
        if value & CSUSP:
            self.stop()
            self.flags |= SUSP
        if value & CSTART and self.cr1 & SPE and self.cfg2 & MASTER:
            self.active = True
            self.suspended = False

    def _disabled(self):
        """SPE cleared: the transfer ends and the FIFOs are flushed."""
        self.stop()
        self.tx.clear()
        self.rx.clear()
        self.flags &= ~SUSP
        self.done = 0

    def ss_active(self):
        """Whether the internal slave-select input is at its active level."""
        if self.cfg2 & SSM:
            level = bool(self.cr1 & SSI)
        elif self.cfg2 & MASTER and self.cfg2 & SSOE:
            return False  # NSS is the master's output, not an input
        elif self.nss_pin is None:
            raise Stop("SPI1 with hardware slave select (SSM = 0, SSOE = 0): "
                       "the NSS pin is not wired on this board")
        else:
            level = bool(self.nss_pin)
        return level == bool(self.cfg2 & SSIOP)

    def drive_nss(self, level):
        """The NSS pin changes level (a multi-master bus)."""
        self.nss_pin = level
        if self._mode_fault():
            self.update()

    def _mode_fault(self):
        """A master whose SS input is active while SPE is set: MODF."""
        if not (self.cr1 & SPE and self.cfg2 & MASTER and self.ss_active()):
            return False
        self.flags |= MODF
        self.mode_faults += 1
        self.cr1 &= ~SPE
        self.cfg2 &= ~MASTER
        self._disabled()
        return True

    def _config_write(self, name):
        if self.cr1 & 1:
            # RM0433: CFG1/CFG2 are write-protected while SPE = 1.
            raise Stop(f"SPI1 {name} written while SPE = 1 (ignored by the chip)")


class Usart:
    def __init__(self, bus, nvic, dma, rcc, on_byte):
        self.bus = bus
        self.nvic = nvic
        self.dma = dma
        self.rcc = rcc
        self.on_byte = on_byte  # fn(byte, cycle)
        self.r = {0x00: 0, 0x04: 0, 0x08: 0, 0x0C: 0, 0x10: 0, 0x14: 0, 0x2C: 0}
        self.fifo = []       # bytes waiting (TDR, or the TX FIFO when FIFOEN)
        self.shifting = False
        self.tc = True
        self.busy_until = 0  # fault injection: the line is held until then
        self.bytes = 0
        dma.register(REQ_USART3_TX, self.tx_request)
        self.rx = Receiver(self)  # usart_rx.py

    def enabled(self):
        return self.r[0] & 1 and self.r[0] >> 3 & 1

    def capacity(self):
        return 16 if self.r[0] >> 29 & 1 else 1

    def txe(self):
        """TXE, or TXFNF in FIFO mode: room for one more byte."""
        return len(self.fifo) < self.capacity()

    def tx_request(self):
        return bool(self.r[0x08] >> 7 & 1) and self.enabled() and self.txe()

    def isr(self):
        v = 0
        if self.txe():
            v |= 1 << 7
        if not self.fifo:
            v |= 1 << 23  # TXFE
        if self.tc:
            v |= 1 << 6
        v |= (1 << 21) | (1 << 22) if self.enabled() else 0  # TEACK, REACK
        return v | self.rx.isr()

    def byte_cycles(self):
        brr = self.r[0x0C]
        if brr < 16:
            raise Stop(f"USART3 BRR {brr} is not a valid divider")
        if self.r[0] >> 15 & 1:
            raise Stop("USART3 oversampling by 8 is not modelled")
        baud = self.rcc.usart234578_kernel_hz() / brr
        return round(10 * CLOCK_HZ / baud)

    def start_shift(self):
        if self.shifting or not self.fifo or not self.enabled():
            return
        now = self.bus.core.cycles
        if now < self.busy_until:
            self.bus.at(self.busy_until, self.start_shift)
            return
        byte = self.fifo.pop(0)
        self.shifting = True
        self.tc = False
        end = now + self.byte_cycles()

        def done():
            self.shifting = False
            self.bytes += 1
            self.on_byte(byte, end)
            if not self.fifo:
                self.tc = True
            self.start_shift()
            self.update()

        self.bus.at(end, done)
        self.update()

    def update(self):
        cr1 = self.r[0]
        irq = (cr1 >> 7 & 1 and self.txe()) or (cr1 >> 6 & 1 and self.tc) or self.rx.irq()
        self.nvic.set_line(USART3_IRQ, bool(irq))
        self.dma.poll(REQ_USART3_TX)
        self.dma.poll(REQ_USART3_RX)

    def read(self, off, size):
        if off == 0x1C:
            return self.isr()
        if off == 0x24:
            return self.rx.rdr()
        if off in (0x18, 0x20, 0x28):
            return 0
        if off in self.r:
            return self.r[off]
        raise KeyError

    def write(self, off, size, value):
        if off == 0x28:
            if not self.enabled():
                raise Stop("USART3 TDR written while the transmitter is off")
            if self.txe():
                self.fifo.append(value & 0xFF)
            self.start_shift()
        elif off == 0x20:  # ICR
            if value >> 6 & 1:
                self.tc = False
            self.rx.clear(value)
        elif off == 0x18:
            if value >> 3 & 1:  # RQR.RXFRQ
                self.rx.flush()
        elif off in self.r:
            self.r[off] = value
            self.start_shift()
        else:
            raise KeyError
        self.update()
