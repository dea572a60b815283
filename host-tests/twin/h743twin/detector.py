"""The detector at the other end of the wiring (docs/firmware.md): one
frame per beam, announced by a DRDY rising edge on PE9, LINE_SYNC high on
PE11 around the DRDY edge of each row's first beam, the frame's samples
shifted out MSB first on MISO while the chip select PD14 is low, sample
index 0 at each falling edge of the chip select.

Faults (`--fault KIND@BEAM[:ARG[:ARG]]`, beams counted from 0):
  gap@B:MS           no DRDY for MS milliseconds before beam B
  burst@B:N:US       beams B..B+N-1 come US microseconds apart (faster than the SPI)
  sync-glitch@B      an extra LINE_SYNC on beam B (mid-row)
  sync-miss@B        no LINE_SYNC on beam B (a row start)
  overrun@B          the SPI loses a frame of beam B's read with OVR
  dma-error@B        beam B's SPI DMA transfer fails with a transfer error
  dma-stall@B        beam B's SPI DMA requests are never served (the read never completes)
  uart-busy@B:MS     the UART line is held busy for MS milliseconds from beam B
  halt@B:MS          a debugger halts the core for MS milliseconds at beam B
  wedge@B            the firmware is wedged at beam B (thread mode spins with interrupts off)
  drdy-miss@B        beam B raises no DRDY (the detector's frame is never announced)
  pin-reset@B        NRST is pulled at beam B (RCC_RSR: PINRSTF)
  bor@B              the supply dips below the BOR threshold at beam B (BORRSTF, PINRSTF)
  hardfault@B        the core takes an imprecise bus fault at beam B (escalated to HardFault)
  panic@B            the core is FORCED into core::panicking::panic at beam B (machine.py)
"""

from .core import CLOCK_HZ

SYNC_LEAD = 40    # LINE_SYNC rises 100 ns before DRDY
DRDY_WIDTH = 200  # DRDY and LINE_SYNC stay high 500 ns

KINDS = {"gap": 1, "burst": 2, "sync-glitch": 0, "sync-miss": 0, "overrun": 0,
         "dma-error": 0, "dma-stall": 0, "uart-busy": 1, "halt": 1, "wedge": 0,
         "drdy-miss": 0, "pin-reset": 0, "bor": 0, "hardfault": 0, "panic": 0}


def parse_fault(spec):
    """'kind@beam[:a[:b]]' -> (kind, beam, args)."""
    try:
        kind, rest = spec.split("@", 1)
        parts = rest.split(":")
        beam = int(parts[0])
        args = [float(a) for a in parts[1:]]
    except ValueError:
        raise ValueError(f"fault {spec!r}: expected KIND@BEAM[:ARG...]") from None
    if kind not in KINDS:
        raise ValueError(f"fault {spec!r}: unknown kind (one of {', '.join(KINDS)})")
    if len(args) != KINDS[kind]:
        raise ValueError(f"fault {spec!r}: {kind} takes {KINDS[kind]} argument(s) after the beam")
    if beam < 0:
        raise ValueError(f"fault {spec!r}: the beam must be >= 0")
    return kind, beam, args


class Scan:
    """Frames in bus order: rows x cols beams of `cells` 16-bit samples."""

    def __init__(self, rows, cols, j1, j2, samples):
        self.rows, self.cols, self.j1, self.j2 = rows, cols, j1, j2
        self.cells = j1 * j2
        self.samples = samples  # flat sequence of ints, raster then (j1, j2)
        if len(samples) != rows * cols * self.cells:
            raise ValueError("scan: sample count does not match its shape")

    def frame(self, k):
        c = self.cells
        return self.samples[k * c:(k + 1) * c]

    @staticmethod
    def read_raw(path):
        """The twin's scan file: 'CVMTWIN1', then rows, cols, j1, j2 as
        little-endian u32, then the samples as little-endian u16."""
        import struct
        with open(path, "rb") as f:
            data = f.read()
        if data[:8] != b"CVMTWIN1":
            raise ValueError(f"{path}: not a twin scan file")
        rows, cols, j1, j2 = struct.unpack_from("<4I", data, 8)
        n = rows * cols * j1 * j2
        samples = struct.unpack_from(f"<{n}H", data, 24)
        return Scan(rows, cols, j1, j2, samples)


class Detector:
    def __init__(self, machine, scan, period_us, start_ms, faults):
        self.m = machine
        self.scan = scan
        self.period = round(period_us * CLOCK_HZ / 1e6)
        # Pulses shorter than half the beam period, for very fast DRDY.
        self.width = max(1, min(DRDY_WIDTH, self.period // 2))
        self.lead = max(1, min(SYNC_LEAD, self.period // 4))
        self.faults = {}
        for kind, beam, args in faults:
            self.faults.setdefault(beam, []).append((kind, args))
        self.times = self._schedule(round(start_ms * CLOCK_HZ / 1e3))
        self.beam = -1          # the latest DRDY's beam
        self.frame = None
        self.index = 0
        self.cs_low = False
        self.sent = 0
        self.reads_without_cs = 0
        self.injected = {}
        self.done_at = self.times[-1] if self.times else 0
        # When the last sample of the latest frame was clocked out, and
        # of which beam (the firmware has the frame from then on).
        self.read_end = (-1, -1)

    def _schedule(self, t):
        times = []
        n = self.scan.rows * self.scan.cols
        burst_left = 0
        burst_period = self.period
        for k in range(n):
            for kind, args in self.faults.get(k, []):
                if kind == "gap":
                    t += round(args[0] * CLOCK_HZ / 1e3)
                elif kind == "burst":
                    burst_left, burst_period = int(args[0]), round(args[1] * CLOCK_HZ / 1e6)
            times.append(t)
            if burst_left > 0:
                burst_left -= 1
                t += burst_period
            else:
                t += self.period
        return times

    def start(self):
        for k, t in enumerate(self.times):
            self.m.bus.at(t - self.lead, lambda k=k: self._beam(k), owner="world")

    def _count(self, kind):
        self.injected[kind] = self.injected.get(kind, 0) + 1

    def _beam(self, k):
        m = self.m
        kinds = [kind for kind, _ in self.faults.get(k, [])]
        first = k % self.scan.cols == 0
        sync = (first and "sync-miss" not in kinds) or (not first and "sync-glitch" in kinds)
        for kind, args in self.faults.get(k, []):
            if kind in ("sync-miss", "sync-glitch", "gap", "burst"):
                self._count(kind)
            elif kind == "overrun":
                self._count(kind)
                m.spi.force_overrun += 1
            elif kind == "dma-error":
                self._count(kind)
                m.dma.inject_error(m.spi_rx_stream)
            elif kind == "dma-stall":
                self._count(kind)
                m.dma_stall(m.spi_rx_stream)
            elif kind == "uart-busy":
                self._count(kind)
                m.usart.busy_until = m.core.cycles + round(args[0] * CLOCK_HZ / 1e3)
            elif kind == "halt":
                self._count(kind)
                m.halt(round(args[0] * CLOCK_HZ / 1e3))
            elif kind == "wedge":
                self._count(kind)
                m.wedge()
            elif kind in ("hardfault", "panic"):
                self._count(kind)
                getattr(m, kind)()
            elif kind in ("pin-reset", "bor"):
                # The chip resets at this beam; the detector goes on (its
                # DRDY edge comes, into a chip that is booting).
                self._count(kind)
                reset = "pin" if kind == "pin-reset" else "bor"
                m.bus.at(m.core.cycles, lambda: m.raise_reset(reset), owner="world")
            elif kind == "drdy-miss":
                self._count(kind)
                # The beam passes without its edge (nor its LINE_SYNC).
                self.beam = k
                return
        if sync:
            m.pin("E", 11, 1)
        m.bus.at(m.core.cycles + self.lead, lambda: self._drdy(k), owner="world")

    def _drdy(self, k):
        self.beam = k
        self.frame = self.scan.frame(k)
        self.sent += 1
        self.m.pin("E", 9, 1)

        def fall():
            self.m.pin("E", 9, 0)
            self.m.pin("E", 11, 0)

        self.m.bus.at(self.m.core.cycles + self.width, fall, owner="world")

    # --- the SPI slave side
    def chip_select(self, level):
        low = not level
        if low and not self.cs_low:
            self.index = 0
        self.cs_low = low

    def exchange(self, out, bits):
        if not self.cs_low or self.frame is None:
            self.reads_without_cs += 1
            return (1 << bits) - 1
        if bits != 16 and bits != 8:
            return 0
        if bits == 16:
            v = self.frame[self.index] if self.index < len(self.frame) else 0
            self.index += 1
            if self.index == len(self.frame):
                self.read_end = (self.m.core.cycles, self.beam)
            return v
        # 8-bit frames: the two bytes of each sample, MSB first.
        s = self.index // 2
        v = self.frame[s] if s < len(self.frame) else 0
        b = (v >> 8) if self.index % 2 == 0 else (v & 0xFF)
        self.index += 1
        if self.index == 2 * len(self.frame):
            self.read_end = (self.m.core.cycles, self.beam)
        return b

    def unread(self):
        self.index = max(0, self.index - 1)
