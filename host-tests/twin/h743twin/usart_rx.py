"""USART3's receiver (RM0433 §48): what a host sends on the ST-LINK's
virtual COM port, as the firmware reads it.

A byte arrives ten bit times (8N1) after the previous one ended, at the
host's baud rate; a receiver set to another rate (more than 3 % off) gets
it with a framing error, as silicon would sample garbage. Bytes arriving
while UE or RE is clear are lost. The receiver holds one byte (RDR), or
16 with the FIFO on (CR1.FIFOEN, which embassy sets on the H7): a byte
that finds it full is lost and sets ORE, unless CR3.OVRDIS, which without
the FIFO lets the new byte overwrite RDR without ORE (with the FIFO the
byte is lost, silently). A byte received with a framing error or noise
sets FE or NE when it becomes the next byte to read (at once without the
FIFO); PE likewise. ICR clears PE, FE, NE, ORE, IDLE (PECF, FECF, NECF,
ORECF, IDLECF); reading RDR takes the next byte; RQR.RXFRQ empties the
receiver. IDLE is set once the line has stayed quiet for a frame after a
byte, and not again until another byte arrives.

Flags: RXNE/RXFNE (bit 5), RXFF (24), RXFT (26, at the CR3.RXFTCFG level).
Interrupt (USART3, 39): RXNEIE with RXFNE or ORE, IDLEIE with IDLE, PEIE
with PE, CR3.EIE with FE, NE or ORE, CR3.RXFTIE with RXFT, CR1.RXFFIE
with RXFF. DMA request (DMAMUX1 input 45, usart3_rx_dma): CR3.DMAR with
RXFNE.
"""

from .core import CLOCK_HZ

REQ_USART3_RX = 45
HOST_BAUD = 921_600  # the firmware's BAUD (src/config.rs)

PE, FE, NE, ORE, IDLE, RXFNE = 1 << 0, 1 << 1, 1 << 2, 1 << 3, 1 << 4, 1 << 5
RXFF, RXFT = 1 << 24, 1 << 26
ERROR_FLAGS = {"pe": PE, "fe": FE, "ne": NE}
ICR_RX = PE | FE | NE | ORE | IDLE  # PECF, FECF, NECF, ORECF, IDLECF
RXFT_LEVELS = (2, 4, 8, 12, 14, 16, 16, 16)  # CR3.RXFTCFG: 1/8 .. full of 16


class Receiver:
    def __init__(self, usart, host_baud=HOST_BAUD):
        self.usart = usart
        self.bus = usart.bus
        self.host_baud = host_baud
        self.fifo = []       # (byte, error flags)
        self.flags = 0       # PE, FE, NE, ORE, IDLE
        self.idle_armed = False
        self.line = []       # bytes the host has yet to put on the line
        self.line_busy = False
        self.gen = 0
        self.received = 0
        self.overruns = 0
        self.lost_off = 0    # arrived while UE or RE was clear
        usart.dma.register(REQ_USART3_RX, self.rx_request)

    # --- the host side
    def send(self, data, errors=None):
        """The host starts sending `data` now (after what it sent before);
        `errors`: {index: 'fe' | 'ne' | 'pe'} bytes that arrive damaged."""
        errors = errors or {}
        for i, b in enumerate(data):
            self.line.append((b & 0xFF, ERROR_FLAGS[errors[i]] if i in errors else 0))
        if not self.line_busy:
            self._next()

    def frame_cycles(self):
        return round(10 * CLOCK_HZ / self.host_baud)

    def _next(self):
        if not self.line:
            self.line_busy = False
            return
        self.line_busy = True
        byte, err = self.line.pop(0)
        self.bus.at(self.bus.core.cycles + self.frame_cycles(), lambda: self._arrive(byte, err))

    def _arrive(self, byte, err):
        self._land(byte, err)
        self.gen += 1
        gen = self.gen
        # The next byte first: one that follows back to back keeps the line busy.
        self._next()
        self.bus.at(self.bus.core.cycles + self.frame_cycles(), lambda: self._quiet(gen))
        self.usart.update()

    def _quiet(self, gen):
        if gen == self.gen and self.idle_armed:
            self.idle_armed = False
            self.flags |= IDLE
            self.usart.update()

    def _land(self, byte, err):
        u = self.usart
        cr1 = u.r[0]
        if not (cr1 & 1 and cr1 >> 2 & 1):
            self.lost_off += 1
            return
        if self._baud_off():
            err |= FE
        self.received += 1
        self.idle_armed = True
        full = len(self.fifo) >= self.capacity()
        if full:
            if u.r[0x08] >> 12 & 1:  # OVRDIS
                if self.capacity() == 1:
                    self.fifo[0] = (byte, err)
                    self._head_flags()
                return
            self.flags |= ORE
            self.overruns += 1
            return
        self.fifo.append((byte, err))
        if len(self.fifo) == 1:
            self._head_flags()

    def _baud_off(self):
        brr = self.usart.r[0x0C]
        if brr < 16:
            return True
        baud = self.usart.rcc.usart234578_kernel_hz() / brr
        return abs(baud - self.host_baud) > 0.03 * self.host_baud

    def _head_flags(self):
        if self.fifo:
            self.flags |= self.fifo[0][1]

    # --- the firmware side
    def capacity(self):
        return 16 if self.usart.r[0] >> 29 & 1 else 1

    def isr(self):
        v = self.flags
        if self.fifo:
            v |= RXFNE
        if len(self.fifo) >= self.capacity():
            v |= RXFF
        if len(self.fifo) >= RXFT_LEVELS[self.usart.r[0x08] >> 25 & 7] and self.capacity() > 1:
            v |= RXFT
        return v

    def rdr(self):
        if not self.fifo:
            return 0
        byte, _ = self.fifo.pop(0)
        self._head_flags()
        self.usart.update()
        return byte

    def clear(self, icr):
        self.flags &= ~(icr & ICR_RX)

    def flush(self):
        """RQR.RXFRQ: the unread bytes are dropped."""
        self.fifo = []

    def irq(self):
        cr1, cr3, isr = self.usart.r[0], self.usart.r[0x08], self.isr()
        return bool((cr1 >> 5 & 1 and isr & (RXFNE | ORE))
                    or (cr1 >> 4 & 1 and isr & IDLE)
                    or (cr1 >> 8 & 1 and isr & PE)
                    or (cr3 & 1 and isr & (FE | NE | ORE))
                    or (cr3 >> 28 & 1 and isr & RXFT)
                    or (cr1 >> 31 & 1 and isr & RXFF))

    def rx_request(self):
        return bool(self.usart.r[0x08] >> 6 & 1) and bool(self.fifo)


class LiveHost:
    """A host that sends as it likes (`--stdin-requests`, for `dmap
    console`): what arrives on `stream` (standard input) is read by a
    thread and put on the line, in the order it came, at the model time
    when the run next looks (`deliver`), as a host typing at the port."""

    def __init__(self, stream):
        import os
        import queue
        import threading
        self.queue = queue.Queue()
        fd = stream.fileno()

        def read():
            while True:
                try:
                    data = os.read(fd, 4096)
                except OSError:
                    return
                if not data:
                    return
                self.queue.put(data)
        threading.Thread(target=read, daemon=True).start()

    def deliver(self, rx):
        while not self.queue.empty():
            rx.send(self.queue.get_nowait())


def parse_requests(path):
    """A file of what the host sends and when: one line per burst,
    `BEAM HEX [KIND@INDEX ...]`, BEAM the beam (from 0) at whose DRDY the
    host starts, HEX the bytes, KIND@INDEX a byte received with a framing
    error (fe), noise (ne) or a parity error (pe). `#` starts a comment."""
    out = []
    with open(path) as f:
        for n, raw in enumerate(f, 1):
            line = raw.split("#", 1)[0].split()
            if not line:
                continue
            try:
                beam, data = int(line[0]), bytes.fromhex(line[1] if len(line) > 1 else "")
                errors = {}
                for e in line[2:]:
                    kind, idx = e.split("@")
                    if kind not in ERROR_FLAGS or not 0 <= int(idx) < len(data):
                        raise ValueError(e)
                    errors[int(idx)] = kind
            except (ValueError, IndexError) as e:
                raise ValueError(f"{path}:{n}: not `BEAM HEX [KIND@INDEX ...]` ({e})") from None
            if beam < 0:
                raise ValueError(f"{path}:{n}: negative beam")
            out.append((beam, data, errors))
    return out
