"""The STM32H743 as the firmware sees it: core, memories, the peripherals
of the board layer, and the detector wired to them; the run loop that
advances the model clock from event to event."""

import struct

from elftools.elf.elffile import ELFFile
from unicorn.arm_const import (UC_ARM_REG_LR, UC_ARM_REG_PC, UC_ARM_REG_PRIMASK, UC_ARM_REG_R0,
                               UC_ARM_REG_R1, UC_ARM_REG_R2)

from . import system
from .bus import Bus
from .core import CFSR_IMPRECISERR, CLOCK_HZ, Core, Reset, Stop
from .dma import STREAM_IRQS, Dma, Dmamux
from .flash import BANK2_BASE, BANK2_SIZE, FLASH_IRQ, PSIZE_X64, Bank2, Bank2Window, FlashInterface
from .serial import Spi, Usart

# The embassy time driver runs on TIM12 (time-driver-any picks it on this chip).
TIM12_IRQ = 43
TIM13_IRQ = 44
# REJECT's pulse timer (TIM8_TRG_COM_TIM14).
TIM14_IRQ = 45
GPIO_PORTS = "ABCDEFGHIJK"
# Pull-ups/downs and modes of the debug pins after reset (RM0433 §11.4).
GPIO_RESET = {"A": {0x00: 0xABFF_FFFF, 0x08: 0x0C00_0000, 0x0C: 0x6400_0000},
              "B": {0x00: 0xFFFF_FEBF, 0x08: 0x0000_00C0, 0x0C: 0x0000_0100}}
WEDGE_ADDR = 0x0000_0000  # ITCM: unused by the firmware
# Output pins whose every change is recorded (docs/firmware.md's wiring):
# the PLC's outputs on the Zio connector and the LEDs that mirror them.
RECORDED_PINS = {("E", 14): "READY", ("E", 13): "REJECT", ("B", 0): "LD1", ("B", 14): "LD3"}


class Machine:
    # Model settings (h743twin's options); class defaults so that a machine
    # built without __init__ (the tests' bare_machine) has them too.
    psize = PSIZE_X64        # the parallelism the product means (--psize; None: any)
    clock_drops_stop = True  # an access lost to the clock-enable delay stops the run
    ecc = "double"           # what a broken flash word reads as (--ecc, flash.ECC_MODES)

    def __init__(self, elf_path, debugger=False, bank2=None, psize=PSIZE_X64,
                 clock_drops_stop=True, ecc="double"):
        self.ecc = ecc
        self.debugger = debugger
        self.bank2 = bank2
        self.psize = psize
        self.clock_drops_stop = clock_drops_stop
        self.bus = Bus()
        self.core = Core(self.bus)
        self.elf_path = elf_path
        self.image, self.text = load_elf(elf_path)
        self.core.load(self.image)
        self.core.watch_opcodes(self.text)
        self.stack = stack_range(elf_path)
        if self.stack:
            # Painted once, at power-on: the lowest word that no longer
            # holds the pattern is the deepest the stack has reached.
            lo, hi = self.stack
            self.core.uc.mem_write(lo, STACK_PAINT * ((hi - lo) // 4))
        self.uart = []          # (byte, cycle)
        self.resets = []        # (cause, cycle)
        self.pin_edges = []     # (cycle, name, level, beam, read end), every recorded pin change
        self.detector = None
        self.halted_until = 0
        self.spi_rx_stream = 1
        self.panics = 0
        self._build(system.POWER_ON_FLAGS)
        self.core.reset()
        for name in RECORDED_PINS.values():  # at power-on, every pin is Hi-Z
            self._record_pin(name, "z")

    # --- the chip's peripherals, built anew at every reset
    def _build(self, rsr):
        bus, nvic = self.bus, self.core.nvic
        bus.periphs = []
        bus.clocks = {}
        bus.enabling = {}
        bus.clock_drops_stop = self.clock_drops_stop
        self.rcc = bus.add(0x5802_4400, 0x400, system.Rcc(rsr))
        bus.rcc = self.rcc
        self.rcc.on_ahb2enr = bus.sram_clocks_changed
        bus.sram_clocks_changed()  # off after every reset
        self.pwr = bus.add(0x5802_4800, 0x400, system.Pwr())
        if getattr(self, "bank2", None) is None:
            self.bank2 = Bank2()  # kept across resets: see flash.py
        self.flash = bus.add(0x5200_2000, 0x1000, FlashInterface(bus, nvic, self.bank2, self.psize, self.ecc))
        bus.add(BANK2_BASE, BANK2_SIZE, Bank2Window(self.flash))
        self.syscfg = bus.add(0x5800_0400, 0x400, system.Syscfg(), clock=(0xF4, 1, "SYSCFG"))
        self.exti = bus.add(0x5800_0000, 0x400, system.Exti(nvic))
        self.dbgmcu = bus.add(0x5C00_1000, 0x400, system.Dbgmcu())
        self.gpio = {}
        for i, port in enumerate(GPIO_PORTS):
            g = system.Gpio(port, GPIO_RESET.get(port))
            self.gpio[port] = bus.add(0x5802_0000 + 0x400 * i, 0x400, g,
                                      clock=(0xE0, i, f"GPIO{port}"))
        self.iwdg = bus.add(0x5800_4800, 0x400, system.Iwdg(bus, self.dbgmcu, self.debugger))
        self.tim12 = bus.add(0x4000_1800, 0x400, system.Timer(
            bus, nvic, TIM12_IRQ, self.rcc.apb1_timer_hz, bits=16, channels=2), clock=(0xE8, 6, "TIM12"))
        self.tim13 = bus.add(0x4000_1C00, 0x400, system.Timer(
            bus, nvic, TIM13_IRQ, self.rcc.apb1_timer_hz, bits=16, channels=1), clock=(0xE8, 7, "TIM13"))
        self.tim14 = bus.add(0x4000_2000, 0x400, system.Timer(
            bus, nvic, TIM14_IRQ, self.rcc.apb1_timer_hz, bits=16, channels=1), clock=(0xE8, 8, "TIM14"))
        self.dma = bus.add(0x4002_0000, 0x400, Dma(bus, nvic), clock=(0xD8, 0, "DMA1"))
        bus.add(0x4002_0800, 0x400, Dmamux(self.dma))
        slave = self.detector if self.detector else NoSlave()
        self.spi = bus.add(0x4001_3000, 0x400, Spi(bus, nvic, self.dma, self.rcc, slave),
                           clock=(0xF0, 12, "SPI1"))
        self.usart = bus.add(0x4000_4800, 0x400, Usart(
            bus, nvic, self.dma, self.rcc, lambda b, t: self.uart.append((b, t))),
            clock=(0xE8, 18, "USART3"))
        self.gpio["D"].listeners.append(self._gpiod_changed)
        for port in {p for p, _ in RECORDED_PINS}:
            self.gpio[port].observers.append(lambda port=port: self._observe(port))
        bus.posted = {}
        bus.irq_owner = {TIM12_IRQ: 0x4000_1800, TIM13_IRQ: 0x4000_1C00, TIM14_IRQ: 0x4000_2000, 35: 0x4001_3000,
                         39: 0x4000_4800, FLASH_IRQ: 0x5200_2000, **{irq: 0x4002_0000 for irq in STREAM_IRQS}}

    def _gpiod_changed(self, pin, level):
        if pin == 14 and self.detector:
            self.detector.chip_select(level)

    def _observe(self, port):
        """Records every change of a recorded pin's level (0, 1, "z")."""
        for (p, pin), name in RECORDED_PINS.items():
            if p == port:
                self._record_pin(name, self.gpio[port].level(pin))

    def _record_pin(self, name, level):
        last = self.__dict__.setdefault("pin_level", {})
        if last.get(name, "none") == level:
            return
        last[name] = level
        det = self.detector
        beam = det.beam if det else -1
        read_end = getattr(det, "read_end", (-1, -1))
        self.__dict__.setdefault("pin_edges", []).append((self.core.cycles, name, level, beam, read_end))

    def start_profile(self):
        """Counts instructions per function from now on."""
        self.core.symbolize = symbolizer(self.elf_path)
        self.core.profile = {}

    def attach(self, detector):
        self.detector = detector
        self.spi.slave = detector
        detector.start()

    # --- pins driven from outside
    def pin(self, port, pin, level):
        g = self.gpio[port]
        old = g.inputs >> pin & 1
        g.drive(pin, level)
        if old != level and self.syscfg.exti_port(pin) == GPIO_PORTS.index(port):
            self.exti.edge(pin, rising=bool(level))

    # --- faults that act on the core
    def halt(self, cycles):
        """A debugger halts the core; the watchdog keeps counting unless
        DBGMCU freezes it."""
        self.halted_until = self.core.cycles + cycles
        if self.dbgmcu.iwdg1_frozen():
            self.iwdg.pause(self.halted_until)

    def wedge(self):
        self.core.uc.mem_write(WEDGE_ADDR, struct.pack("<H", 0xE7FE))
        self.core.uc.reg_write(UC_ARM_REG_PRIMASK, 1)
        self.core.pc = WEDGE_ADDR | 1
        self.core.uc.reg_write(UC_ARM_REG_PC, self.core.pc)
        self.core.sleeping = False

    def hardfault(self):
        """An imprecise bus fault (a buffered write that the bus answered
        with an error, ARMv7-M B3.2.15: IMPRECISERR) taken at the current
        instruction boundary; with BusFault disabled it escalates to
        HardFault."""
        core = self.core
        core.take_fault(core.pc & ~1, CFSR_IMPRECISERR, f"injected imprecise bus fault at pc {core.pc & ~1:#010x}")
        core.request_check()

    def panic(self):
        """A FORCED entry into the firmware's panic path: the core calls
        `core::panicking::panic("")` at the current instruction, as an
        `unwrap()` or an assertion failing there would (the location "":0:0,
        16 zero bytes of flash), so the firmware's own #[panic_handler] runs.
        Not a fault the silicon makes: a way into a path the firmware does
        not otherwise take on the model."""
        sym, zeros = panic_entry(self.elf_path, self.image)
        uc, core = self.core.uc, self.core
        uc.reg_write(UC_ARM_REG_R0, zeros)
        uc.reg_write(UC_ARM_REG_R1, 0)
        uc.reg_write(UC_ARM_REG_R2, zeros)
        uc.reg_write(UC_ARM_REG_LR, core.pc | 1)
        core.pc = sym | 1
        uc.reg_write(UC_ARM_REG_PC, core.pc)
        core.sleeping = False
        self.panics += 1

    def dma_stall(self, stream):
        self.dma.stalled.add(stream)

    # --- reset
    @staticmethod
    def raise_reset(cause):
        """From an event: the chip resets (caught by `run`)."""
        raise Reset(cause)

    def reset(self, cause):
        self.resets.append((cause, self.core.cycles))
        # A reset returns every pin to analog mode: Hi-Z until the firmware
        # makes it an output again (what the PLC then reads is its pull).
        for name in RECORDED_PINS.values():
            self._record_pin(name, "z")
        # The flags add to those not yet cleared (RMVF): RCC_RSR is reset
        # by a power-on reset only.
        flags = system.RESET_FLAGS[cause] | self.rcc.r[0xD0]
        self.bus.drop_chip_events()
        self.bus.error = None
        self.halted_until = 0
        self._build(flags)
        self.core.reset()

    # --- running
    def run(self, until_cycles, done=None, max_instructions=None):
        """Runs until the model clock reaches `until_cycles`, done(), or
        `max_instructions` executed."""
        core, bus = self.core, self.bus
        while core.cycles < until_cycles:
            if done is not None and done():
                return "done"
            if max_instructions is not None and core.instructions >= max_instructions:
                return "instruction limit"
            try:
                bus.fire_due()
                if bus.error:
                    raise bus.error
                if self.halted_until > core.cycles:
                    nxt = bus.next_event()
                    core.cycles = min(self.halted_until, nxt if nxt is not None else self.halted_until)
                    continue
                if core.sleeping:
                    if core.wake_if_pending():
                        pass
                    elif core.sleeping == "wfe" and core.event:
                        core.event = False
                        core.sleeping = False
                    else:
                        nxt = bus.next_event()
                        if nxt is None:
                            return "idle"
                        core.cycles = max(core.cycles, min(nxt, until_cycles))
                        continue
                else:
                    core.wake_if_pending()
                nxt = bus.next_event()
                core.run_until(min(nxt, until_cycles) if nxt is not None else until_cycles)
                if bus.error:
                    raise bus.error
            except Reset as r:
                self.reset(r.cause)
        return "time"


class NoSlave:
    def exchange(self, out, bits):
        return (1 << bits) - 1

    def chip_select(self, level):
        pass

    def unread(self):
        pass


def symbolizer(path):
    """fn(address) -> the name of the function that holds it (demangled
    roughly: the path without the hash), cached per address."""
    import bisect

    with open(path, "rb") as f:
        elf = ELFFile(f)
        funcs = sorted((s["st_value"] & ~1, s["st_size"], s.name)
                       for s in elf.get_section_by_name(".symtab").iter_symbols()
                       if s["st_info"]["type"] == "STT_FUNC" and s["st_size"])
    starts = [a for a, _, _ in funcs]
    cache = {}

    def name_of(addr):
        hit = cache.get(addr)
        if hit is None:
            i = bisect.bisect_right(starts, addr) - 1
            if i >= 0 and addr < funcs[i][0] + funcs[i][1]:
                hit = demangle(funcs[i][2])
            else:
                hit = f"?{addr:#x}"
            cache[addr] = hit
        return hit

    return name_of


def demangle(sym):
    """Legacy Rust mangling (_ZN...E) to a path, without the hash."""
    if not sym.startswith("_ZN"):
        return sym
    parts, i = [], 3
    while i < len(sym) and sym[i].isdigit():
        j = i
        while sym[j].isdigit():
            j += 1
        n = int(sym[i:j])
        parts.append(sym[j:j + n])
        i = j + n
    if parts and parts[-1].startswith("h") and len(parts[-1]) == 17:
        parts.pop()
    path = "::".join(parts)
    for a, b in (("$LT$", "<"), ("$GT$", ">"), ("$u20$", " "), ("$RF$", "&"),
                 ("$C$", ","), ("..", "::"), ("$u7b$", "{"), ("$u7d$", "}")):
        path = path.replace(a, b)
    return path


def load_elf(path):
    """PT_LOAD segments at their load (physical) addresses, and the
    executable ones' bytes for the opcode scan."""
    image, text = [], []
    with open(path, "rb") as f:
        elf = ELFFile(f)
        for seg in elf.iter_segments():
            if seg["p_type"] != "PT_LOAD" or not seg["p_filesz"]:
                continue
            data = seg.data()
            image.append((seg["p_paddr"], data))
            if seg["p_flags"] & 1:
                text.append((seg["p_paddr"], data))
    return image, text


STACK_PAINT = b"\xa5\x5a\xc3\x3c"


def panic_entry(path, image):
    """(address of `core::panicking::panic`, address of 16 zero bytes in
    flash) of the ELF."""
    with open(path, "rb") as f:
        symtab = ELFFile(f).get_section_by_name(".symtab")
        syms = [s["st_value"] for s in symtab.iter_symbols()
                if s["st_info"]["type"] == "STT_FUNC" and s.name.endswith("4core9panicking5panic")]
    if not syms:
        raise Stop("panic: the ELF has no core::panicking::panic")
    for addr, data in image:
        if 0x0800_0000 <= addr < 0x0810_0000:
            i = data.find(bytes(16))
            while i >= 0 and (addr + i) % 4:
                i = data.find(bytes(16), i + 1)
            if i >= 0:
                return syms[0] & ~1, addr + i
    raise Stop("panic: no 16 zero bytes in flash for the panic's location")


def stack_range(path):
    """(_stack_end, _stack_start) of a cortex-m-rt ELF whose memory map
    bounds the stack (the H743's: DTCM above `.dtcm`), or None."""
    with open(path, "rb") as f:
        symtab = ELFFile(f).get_section_by_name(".symtab")
        if symtab is None:
            return None
        ends = [symtab.get_symbol_by_name(n) for n in ("_stack_end", "_stack_start")]
        if not all(ends):
            return None
        lo, hi = (e[0]["st_value"] for e in ends)
    return (lo, hi) if lo < hi else None


def _stack_free(self):
    """Bytes of the stack never written since power-on, or None."""
    if not self.stack:
        return None
    lo, hi = self.stack
    data = bytes(self.core.uc.mem_read(lo, hi - lo))
    free = 0
    while free < len(data) and data[free:free + 4] == STACK_PAINT:
        free += 4
    return free


def cycles_of_ms(ms):
    return round(ms * CLOCK_HZ / 1e3)


__all__ = ["Machine", "Stop", "cycles_of_ms"]


def _stats(self):
    core = self.core
    det = self.detector
    s = {
        "clock_hz": CLOCK_HZ,
        "cycles": core.cycles,
        "instructions": core.instructions,
        "pc": core.pc,
        "interrupts": core.irq_entries,
        "irq_counts": {str(i): n for i, n in enumerate(core.nvic.taken) if n},
        "wfe": core.wfe,
        "dma_transfers": self.dma.transfers,
        "dma_errors": self.dma.errors,
        "spi_frames": self.spi.frames,
        "spi_overruns": self.spi.overruns,
        "uart_bytes": len(self.uart),
        "watchdog_feeds": self.iwdg.feeds,
        "watchdog_running": self.iwdg.running,
        "iwdg_frozen_in_debug": self.dbgmcu.iwdg1_frozen(),
        "resets": [{"cause": c, "ms": round(t * 1e3 / CLOCK_HZ, 3)} for c, t in self.resets],
        "exti_edges": self.exti.edges,
        "spi_mode_faults": self.spi.mode_faults,
        "uart_rx_bytes": self.usart.rx.received,
        "uart_rx_overruns": self.usart.rx.overruns,
        "uart_rx_lost_while_off": self.usart.rx.lost_off,
        "flash_operations": self.bank2.ops,
        "flash_double_programs": self.bank2.double_programs,
        "flash_ecc_errors": self.bank2.ecc_errors,
        "flash_ecc_mode": self.ecc,
        "flash_dma_reads": self.bank2.dma_reads,
        # Interrupts unpended while a write to their peripheral may still
        # be in the write buffer (no read-back, no DSB): see bus.posted_write.
        "unordered_unpends": len(self.bus.unordered_unpends),
        # Accesses lost to the clock-enable delay (bus._check_clock).
        "clock_enable_drops": [
            {**d, "pc": f"{d['pc']:#010x}", "enable_pc": f"{d['enable_pc']:#010x}",
             "offset": f"{d['offset']:#05x}", "us": round(d["cycle"] * 1e6 / CLOCK_HZ, 3),
             **({"value": f"{d['value']:#x}"} if "value" in d else {})}
            for d in self.bus.clock_drops],
        "sysclk_hz": self.rcc.sysclk_hz(),
        "fault": core.fault,
        "hardfaults": core.hardfaults,
        "lockups": core.lockups,
        "panics_forced": self.panics,
        "rcc_rsr": f"{self.rcc.r[0xD0]:#010x}",
        "stack_bytes": self.stack[1] - self.stack[0] if self.stack else None,
        "stack_free_bytes": self.stack_free(),
    }
    if core.profile is not None:
        s["profile"] = dict(sorted(core.profile.items(), key=lambda kv: -kv[1]))
    if det is not None:
        s["beams"] = det.sent
        s["faults_injected"] = det.injected
        s["spi_reads_without_cs"] = det.reads_without_cs
    cols = det.scan.cols if det is not None else 0
    # Each edge with the latest DRDY's beam and the end of the latest
    # frame read (the time its last sample was clocked, and its beam).
    s["pins"] = [{"us": round(t * 1e6 / CLOCK_HZ, 3), "pin": name, "level": level,
                  "beam": beam, "row": beam // cols if cols and beam >= 0 else -1,
                  "read_end_us": round(r[0] * 1e6 / CLOCK_HZ, 3) if r[0] >= 0 else -1,
                  "read_beam": r[1]}
                 for t, name, level, beam, r in self.pin_edges]
    s["lines"] = uart_lines(self.uart)
    return s


def uart_lines(uart):
    """The header and end lines sent on USART3, each with the time of
    its last byte (µs): what a test lines the pins' timeline up with."""
    out, start = [], 0
    for i, (b, t) in enumerate(uart):
        if b != 0x0A:
            continue
        line = bytes(x for x, _ in uart[start:i])
        start = i + 1
        if line[:2] in (b"H,", b"E,"):
            out.append({"us": round(t * 1e6 / CLOCK_HZ, 3), "line": line.decode("ascii", "replace")})
    return out


Machine.stats = _stats
Machine.stack_free = _stack_free
