"""DMA1 and DMAMUX1 (RM0433 §15, §17): eight streams, each bound by its
DMAMUX channel to one peripheral request line.

A transfer moves one item per request, at once (the model has no bus
latency). Peripheral-to-memory and memory-to-peripheral streams with equal
peripheral and memory sizes are modelled; anything else stops the run. A
stream whose memory address is not reachable by DMA1 (ITCM, DTCM, flash
writes, SRAM1-3 while their clocks are off) gets a transfer error, as on
the chip. Flash is readable (RM0433 Fig. 1: DMA1 reaches the AXI bus
matrix, and flash sits on it). A stream disabled by software in the
middle of a transfer stops after the current item and sets TCIF (RM0433
§15.3, DMA transfer suspension); NDTR keeps what was left.

Memory-to-memory (DIR = 10, RM0433 §15.3, "memory-to-memory mode"; DMA1
does it as DMA2 does, both of its ports being on the bus matrix): the
stream needs no request and starts when EN is set; SxPAR is the source
and SxM0AR the destination, both in memory. Direct mode is not allowed:
the hardware sets FCR.DMDIS when EN is set; circular mode is not allowed
either (it stops the run here). The model moves the whole block
`M2M_CYCLES_PER_ITEM` cycles per item after EN, then clears EN and sets
TCIF (and HTIF). A bus error on either side is a transfer error: the
stream stops at that item (NDTR keeps what was left, the items before it
are written), EN is cleared and TEIF set. Reading a flash word whose ECC
reports a double error is such a bus error (flash.py, `EccError`).
"""

from .core import Stop
from .flash import BusError

STREAM_IRQS = (11, 12, 13, 14, 15, 16, 17, 47)
FLAG_SHIFT = (0, 6, 16, 22)
# Request ids of DMAMUX1 (RM0433 Table 121) for the peripherals modelled.
REQ_SPI1_RX = 37
REQ_SPI1_TX = 38
REQ_USART3_TX = 46

TCIF, HTIF, TEIF, DMEIF, FEIF = 0x20, 0x10, 0x08, 0x04, 0x01
M2M = 2               # SxCR.DIR: memory to memory
DMDIS = 1 << 2        # SxFCR: direct mode disabled (FIFO mode)
CIRC = 1 << 8
# The model's own time for one item of a memory-to-memory block (a read
# and a write on the AXI matrix); nothing about the firmware may rest on it.
M2M_CYCLES_PER_ITEM = 8


FLASH = (0x0800_0000, 0x0820_0000)
# SRAM1, SRAM2, SRAM3 and their RCC_AHB2ENR enable bits.
SRAM123 = ((0x3000_0000, 0x3002_0000, 29), (0x3002_0000, 0x3004_0000, 30),
           (0x3004_0000, 0x3004_8000, 31))


def dma_reachable(addr, length, write=True, rcc=None):
    """AXI SRAM, SRAM1-4 and the peripherals, and flash for reads; not the
    TCMs (RM0433 Fig. 1). SRAM1-3 answer only with their clocks on
    (RCC_AHB2ENR.SRAMxEN), when `rcc` is given."""
    end = addr + length
    if not write and FLASH[0] <= addr and end <= FLASH[1]:
        return True
    for lo, hi, bit in SRAM123:
        if lo <= addr and end <= hi:
            return rcc is None or rcc.enabled(0xDC, bit)
    for lo, hi in ((0x2400_0000, 0x2408_0000), (0x3800_0000, 0x3801_0000),
                   (0x4000_0000, 0x6000_0000)):
        if lo <= addr and end <= hi:
            return True
    return False


class Stream:
    def __init__(self):
        self.cr = 0
        self.ndtr = 0
        self.par = 0
        self.m0ar = 0
        self.m1ar = 0
        self.fcr = 0x21
        self.moved = 0  # items moved since enable
        self.total = 0


class Dma:
    def __init__(self, bus, nvic):
        self.bus = bus
        self.nvic = nvic
        self.streams = [Stream() for _ in range(8)]
        self.isr = [0, 0]
        self.mux = [0] * 16
        self.sources = {}  # request id -> fn() -> bool (request active)
        self.transfers = 0
        self.errors = 0
        self.fail_next = {}  # stream -> inject a transfer error at next item
        self.stalled = set()  # streams whose requests are not served
        self.serving = False
        self.again = set()

    # --- requests from peripherals
    def register(self, req, active):
        self.sources[req] = active

    def poll(self, req):
        """The peripheral's request line for `req` may be active: serve it.
        A peripheral access made by a transfer can raise another request;
        that one is served after the transfer, not inside it."""
        if self.serving:
            self.again.add(req)
            return
        self.serving = True
        try:
            self._serve(req)
            while self.again:
                self._serve(self.again.pop())
        finally:
            self.serving = False

    def _serve(self, req):
        for n, s in enumerate(self.streams):
            if s.cr & 1 and (s.cr >> 6) & 3 != M2M and (self.mux[n] & 0xFF) == req and n not in self.stalled:
                active = self.sources.get(req)
                while s.cr & 1 and active and active():
                    self._move(n, s)
                return

    def _move(self, n, s):
        size = 1 << ((s.cr >> 11) & 3)
        msize = 1 << ((s.cr >> 13) & 3)
        if size != msize:
            raise Stop(f"DMA1 stream {n}: packing (PSIZE {size} != MSIZE {msize}) is not modelled")
        direction = (s.cr >> 6) & 3
        mem = s.m0ar + (s.moved * size if s.cr >> 10 & 1 else 0)
        per = s.par + (s.moved * size if s.cr >> 9 & 1 else 0)
        if direction not in (0, 1):
            raise Stop(f"DMA1 stream {n}: memory-to-memory is not modelled")
        reachable = dma_reachable(mem, size, write=direction == 0, rcc=self.bus.rcc)
        if self.fail_next.pop(n, False) or not reachable:
            self._error(n, s)
            return
        uc = self.bus.core.uc
        if direction == 0:  # peripheral to memory
            value = self._per_read(per, size)
            uc.mem_write(mem, value.to_bytes(size, "little"))
        else:
            value = int.from_bytes(bytes(uc.mem_read(mem, size)), "little")
            self._per_write(per, size, value)
        s.moved += 1
        s.ndtr -= 1
        self.transfers += 1
        if s.ndtr == s.total // 2:
            self._flag(n, HTIF)
        if s.ndtr == 0:
            if s.cr >> 8 & 1:  # circular
                s.ndtr = s.total
                s.moved = 0
            else:
                s.cr &= ~1
            self._flag(n, TCIF)

    # --- memory to memory
    def _start_m2m(self, n, s):
        if s.cr & CIRC:
            raise Stop(f"DMA1 stream {n}: circular mode in memory-to-memory is not allowed (RM0433 §15.3)")
        size, msize = 1 << ((s.cr >> 11) & 3), 1 << ((s.cr >> 13) & 3)
        if size != msize:
            raise Stop(f"DMA1 stream {n}: packing (PSIZE {size} != MSIZE {msize}) is not modelled")
        s.fcr |= DMDIS
        cr, total = s.cr, s.ndtr
        self.bus.at(self.bus.core.cycles + M2M_CYCLES_PER_ITEM * max(total, 1),
                    lambda: self._m2m(n, s, cr))

    def _m2m(self, n, s, cr):
        """The block of the stream started with `cr`, if it is still running."""
        if not s.cr & 1 or s.cr != cr:
            return
        size = 1 << ((s.cr >> 11) & 3)
        while s.ndtr:
            src = s.par + (s.moved * size if s.cr >> 9 & 1 else 0)
            dst = s.m0ar + (s.moved * size if s.cr >> 10 & 1 else 0)
            try:
                value = self._mem_read(src, size)
                self._mem_write(dst, size, value)
            except BusError:
                self._error(n, s)
                return
            s.moved += 1
            s.ndtr -= 1
            self.transfers += 1
            if s.ndtr == s.total // 2:
                self._flag(n, HTIF)
        s.cr &= ~1
        self._flag(n, TCIF)

    def _mem_read(self, addr, size):
        """An item read by the stream's source port: a model on the bus
        (bank 2's window, a peripheral) or plain memory."""
        base, model = self.bus._find(addr)
        if model is not None:
            read = getattr(model, "dma_read", model.read)
            return read(addr - base, size) & ((1 << (8 * size)) - 1)
        if not dma_reachable(addr, size, write=False, rcc=self.bus.rcc):
            raise BusError(f"DMA1 read of {addr:#010x}: not reachable")
        return int.from_bytes(bytes(self.bus.core.uc.mem_read(addr, size)), "little")

    def _mem_write(self, addr, size, value):
        base, model = self.bus._find(addr)
        if model is not None:
            model.write(addr - base, size, value)
        elif dma_reachable(addr, size, write=True, rcc=self.bus.rcc):
            self.bus.core.uc.mem_write(addr, value.to_bytes(size, "little"))
        else:
            raise BusError(f"DMA1 write of {addr:#010x}: not reachable")

    def _per_read(self, addr, size):
        base, model = self.bus._find(addr)
        if model is None:
            raise Stop(f"DMA read of unmodelled peripheral address {addr:#010x}")
        return model.read(addr - base, size) & ((1 << (8 * size)) - 1)

    def _per_write(self, addr, size, value):
        base, model = self.bus._find(addr)
        if model is None:
            raise Stop(f"DMA write to unmodelled peripheral address {addr:#010x}")
        model.write(addr - base, size, value)

    def _error(self, n, s):
        s.cr &= ~1
        self.errors += 1
        self._flag(n, TEIF)

    def inject_error(self, n):
        """The next item of stream n fails with a transfer error."""
        self.fail_next[n] = True

    def _flag(self, n, flag):
        self.isr[n // 4] |= flag << FLAG_SHIFT[n % 4]
        self._update(n)

    def _flags(self, n):
        return (self.isr[n // 4] >> FLAG_SHIFT[n % 4]) & 0x3D

    def _update(self, n):
        s = self.streams[n]
        f = self._flags(n)
        enabled = ((TCIF if s.cr & 0x10 else 0) | (HTIF if s.cr & 0x08 else 0)
                   | (TEIF if s.cr & 0x04 else 0) | (DMEIF if s.cr & 0x02 else 0)
                   | (FEIF if s.fcr & 0x80 else 0))
        self.nvic.set_line(STREAM_IRQS[n], bool(f & enabled))

    # --- registers: DMA1 at 0x40020000
    def read(self, off, size):
        if off in (0x00, 0x04):
            return self.isr[off // 4]
        if off in (0x08, 0x0C):
            return 0
        n, reg = divmod(off - 0x10, 0x18)
        if 0 <= n < 8:
            s = self.streams[n]
            return (s.cr, s.ndtr, s.par, s.m0ar, s.m1ar, s.fcr)[reg // 4]
        raise KeyError

    def write(self, off, size, value):
        if off in (0x08, 0x0C):
            self.isr[off // 4 - 2] &= ~value
            for n in range(4 * (off // 4 - 2), 4 * (off // 4 - 2) + 4):
                self._update(n)
            return
        n, reg = divmod(off - 0x10, 0x18)
        if not 0 <= n < 8:
            raise KeyError
        s = self.streams[n]
        if reg == 0:
            was = s.cr & 1
            s.cr = value
            if was and not value & 1:
                self.stalled.discard(n)  # a disabled stream starts afresh
                if s.ndtr:
                    self._flag(n, TCIF)
            if value & 1 and not was:
                s.total = s.ndtr
                s.moved = 0
                self._update(n)
                if (value >> 6) & 3 == M2M:
                    self._start_m2m(n, s)
                else:
                    self.poll(self.mux[n] & 0xFF)
            self._update(n)
        elif s.cr & 1:
            raise Stop(f"DMA1 stream {n}: register {reg * 4:#x} written while enabled")
        elif reg == 4:
            s.ndtr = value & 0xFFFF
        elif reg == 8:
            s.par = value
        elif reg == 12:
            s.m0ar = value
        elif reg == 16:
            s.m1ar = value
        elif reg == 20:
            s.fcr = value
        else:
            raise KeyError


class Dmamux:
    """DMAMUX1 at 0x40020800: channels 0-7 feed DMA1 streams 0-7."""

    def __init__(self, dma):
        self.dma = dma
        self.other = {0x80: 0, 0x84: 0, 0x140: 0, 0x144: 0}

    def read(self, off, size):
        if off < 0x40:
            return self.dma.mux[off // 4]
        if off in self.other:
            return self.other[off]
        if 0x100 <= off < 0x120:
            return 0
        raise KeyError

    def write(self, off, size, value):
        if off < 0x40:
            self.dma.mux[off // 4] = value
        elif off in self.other or 0x100 <= off < 0x120:
            pass
        else:
            raise KeyError
