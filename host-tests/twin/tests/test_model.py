"""Unit tests of the chip model's parts against RM0433 behaviour worked out
by hand: `cd host-tests/twin && python3 -m unittest discover -s tests`."""

import struct
import unittest

from h743twin import system
from h743twin.bus import Bus
from h743twin.core import CLOCK_HZ, Core, Nvic, Reset, Stop, count_thumb
from h743twin.dma import Dma, REQ_SPI1_RX
from h743twin.serial import Spi, Usart


class FakeUc:
    def __init__(self):
        self.mem = {}
        self.regs = {}

    def reg_read(self, r):
        return self.regs.get(r, 0)

    def mem_write(self, addr, data):
        for i, b in enumerate(data):
            self.mem[addr + i] = b

    def mem_read(self, addr, n):
        return bytes(self.mem.get(addr + i, 0) for i in range(n))

    def emu_stop(self):
        pass


class FakeCore:
    def __init__(self):
        self.cycles = 0
        self.deadline = 1 << 62
        self.uc = FakeUc()
        self.nvic = Nvic(self)
        self.checks = 0

    def request_check(self):
        self.checks += 1


def world():
    bus = Bus()
    core = FakeCore()
    bus.core = core
    return bus, core


def run_until(bus, core, cycle):
    while bus.events and bus.events[0][0] <= cycle:
        core.cycles = bus.events[0][0]
        bus.fire_due()
    core.cycles = cycle


def pll_400(rcc):
    """The firmware's clock tree: HSE 8 MHz / 1 * 100, P / 2, Q / 4, APB / 2."""
    rcc.write(0x28, 4, (1 << 4) | 2)             # DIVM1 = 1, PLLSRC = HSE
    rcc.write(0x30, 4, 99 | (1 << 9) | (3 << 16))  # N = 100, P = 2, Q = 4
    rcc.write(0x00, 4, rcc.r[0] | (1 << 16) | (1 << 24))  # HSEON, PLL1ON
    rcc.write(0x10, 4, 3)                          # SW = PLL1
    rcc.write(0x18, 4, 0x8)                        # HPRE / 2
    rcc.write(0x1C, 4, 0x40)                       # D2PPRE1 / 2


class Thumb(unittest.TestCase):
    def test_counts_16_and_32_bit_instructions(self):
        # movs r0,#1 (16) ; ldr.w r0,[r1] (32: 0xF8D1 0x0000) ; bx lr (16)
        code = bytes.fromhex("0120" "d1f80000" "7047")
        self.assertEqual(count_thumb(code), 3)


class Interrupts(unittest.TestCase):
    # Vector table (SP, reset, 14 unused, IRQ0) and, from 0x44 on (llvm-mc,
    # thumbv7em):
    #   reset:  cpsid i; movw r1, #0xE100; movt r1, #0xE000; movs r2, #1
    #           str r2, [r1]            @ NVIC_ISER0: IRQ0 enabled
    #           str r2, [r1, #0x100]    @ NVIC_ISPR0: IRQ0 pending, masked
    #           b 1f
    #   1:      movs r3, #10
    #   2:      subs r3, #1; bne 2b     @ a few blocks with PRIMASK set
    #           movs r0, #0; msr primask, r0; b 3f
    #   3:      movs r4, #1
    #   4:      adds r5, #1; b 4b
    #   irq0:   movw r1, #0; movt r1, #0x2000; str r4, [r1]; bx lr
    CODE = bytes.fromhex(
        "72b64ef20011cef2000101220a60c1f80021ffe70a23013bfdd1002080f31088"
        "ffe701240135fde740f20001c2f200010c607047")

    def test_pending_interrupt_is_taken_when_msr_primask_unmasks_it(self):
        # The critical-section crate ends a section with MSR PRIMASK, not
        # CPSIE I: the interrupt must come right after it (r4 still 0), not
        # at the model's next time slice (20 000 cycles on).
        image = (struct.pack("<2I", 0x2000_1000, 0x0800_0045) + bytes(14 * 4)
                 + struct.pack("<I", 0x0800_006D) + self.CODE)
        core = Core(Bus())
        core.load([(0x0800_0000, image)])
        core.watch_opcodes([(0x0800_0000, image)])
        core.reset()
        entered = None
        while core.cycles < 30_000:
            core.run_until(30_000)
            if core.wake_if_pending() and entered is None:
                entered = core.cycles
        self.assertIsNotNone(entered)
        self.assertLess(entered, 100)
        self.assertEqual(core.uc.mem_read(0x2000_0000, 4), bytes(4))


class Rcc(unittest.TestCase):
    def test_pll1_and_bus_clocks(self):
        rcc = system.Rcc()
        pll_400(rcc)
        p, q, _ = rcc.pll1()
        self.assertEqual((p, q), (400e6, 200e6))
        self.assertEqual(rcc.sysclk_hz(), 400e6)
        self.assertEqual(rcc.pclk1_hz(), 100e6)
        self.assertEqual(rcc.apb1_timer_hz(), 200e6)
        self.assertEqual(rcc.r[0x10] >> 3 & 7, 3, "SWS follows SW")
        self.assertTrue(rcc.r[0] >> 25 & 1, "PLL1RDY follows PLL1ON")

    def test_divm_is_write_protected_while_the_pll_runs(self):
        rcc = system.Rcc()
        pll_400(rcc)
        rcc.write(0x28, 4, 0)
        self.assertEqual(rcc.r[0x28] & 0x3F3, (1 << 4) | 2)
        rcc.write(0x30, 4, 0)
        self.assertEqual(rcc.pll1()[0], 400e6)

    def test_reset_flags_clear_with_rmvf(self):
        rcc = system.Rcc()
        self.assertTrue(rcc.read(0xD0, 4) & system.RSR_POR)
        rcc.write(0xD0, 4, system.RSR_RMVF)
        self.assertEqual(rcc.read(0xD0, 4), 0)


class Exti(unittest.TestCase):
    def test_rising_edge_pends_until_cleared_by_writing_one(self):
        bus, core = world()
        exti = system.Exti(core.nvic)
        exti.edge(9, rising=True)
        self.assertEqual(exti.read(0x88, 4), 0, "no trigger selected: no pending bit")
        exti.write(0x00, 4, 1 << 9)   # RTSR1
        exti.write(0x80, 4, 1 << 9)   # CPUIMR1
        exti.edge(9, rising=False)
        self.assertEqual(exti.read(0x88, 4), 0, "falling edge ignored")
        exti.edge(9, rising=True)
        self.assertEqual(exti.read(0x88, 4), 1 << 9)
        self.assertTrue(core.nvic.line[23] and core.nvic.pending[23], "EXTI9_5 requested")
        exti.write(0x88, 4, 1 << 9)
        self.assertEqual(exti.read(0x88, 4), 0)
        self.assertFalse(core.nvic.line[23])


class Nvics(unittest.TestCase):
    def test_line_still_high_pends_again_after_clear(self):
        _, core = world()
        nvic = core.nvic
        nvic.set_line(23, True)
        nvic.write(0x280, 4, 1 << 23)   # ICPR0
        self.assertTrue(nvic.pending[23], "a request line still high pends again")
        nvic.set_line(23, False)
        nvic.write(0x280, 4, 1 << 23)
        self.assertFalse(nvic.pending[23])

    def test_most_urgent_enabled_interrupt_is_taken(self):
        _, core = world()
        nvic = core.nvic
        for irq, prio in ((23, 0x50), (12, 0x60), (52, 0x40)):
            nvic.write(0x400 + irq, 1, prio)
            nvic.pend(irq)
        self.assertIsNone(nvic.next_irq(), "nothing enabled")
        nvic.write(0x100, 4, (1 << 23) | (1 << 12))
        self.assertEqual(nvic.next_irq(), 23)
        nvic.write(0x104, 4, 1 << (52 - 32))
        self.assertEqual(nvic.next_irq(), 52)


class DmaTests(unittest.TestCase):
    def setUp(self):
        self.bus, self.core = world()
        self.dma = Dma(self.bus, self.core.nvic)
        self.fifo = [0x1234, 0xBEEF, 0x0001]

        class Rx:
            def read(_, off, size):
                return self.fifo.pop(0)

        self.bus.periphs.append((0x4001_3000, 0x400, Rx()))
        self.dma.register(REQ_SPI1_RX, lambda: bool(self.fifo))
        self.dma.mux[1] = REQ_SPI1_RX

    def start(self, mem):
        st = 0x10 + 0x18 * 1
        self.dma.write(st + 0x04, 4, 3)            # NDTR
        self.dma.write(st + 0x08, 4, 0x4001_3030)  # PAR
        self.dma.write(st + 0x0C, 4, mem)          # M0AR
        # P2M, PSIZE = MSIZE = 16 bits, MINC, TCIE, TEIE, EN
        self.dma.write(st, 4, (1 << 11) | (1 << 13) | (1 << 10) | 0x10 | 0x04 | 1)

    def test_peripheral_to_memory_with_increment(self):
        self.start(0x2400_0000)
        mem = self.core.uc.mem_read(0x2400_0000, 6)
        self.assertEqual(mem, bytes.fromhex("3412efbe0100"))
        self.assertEqual(self.dma.read(0x00, 4) >> 6 & 0x3D, 0x20 | 0x10, "TCIF1 and HTIF1")
        self.assertEqual(self.dma.read(0x10 + 0x18, 4) & 1, 0, "the stream disables itself")
        self.assertTrue(self.core.nvic.line[12])

    def test_memory_dma_cannot_reach_is_a_transfer_error(self):
        self.start(0x2000_0000)  # DTCM
        self.assertEqual(self.dma.read(0x00, 4) >> 6 & 0x08, 0x08, "TEIF1")
        self.assertEqual(self.dma.errors, 1)


class SpiTests(unittest.TestCase):
    def make(self, masrx):
        bus, core = world()
        rcc = system.Rcc()
        pll_400(rcc)
        rcc.write(0x50, 4, 0)  # SPI123SEL = PLL1 Q (200 MHz)
        dma = Dma(bus, core.nvic)

        class Slave:
            n = 0

            def exchange(s, out, bits):
                s.n += 1
                return 0x1000 + s.n

            def unread(s):
                s.n -= 1

        spi = Spi(bus, core.nvic, dma, rcc, Slave())
        spi.write(0x08, 4, 15 | (2 << 28))          # DSIZE 16 bits, MBR / 8: 25 MHz
        # Receive-only master, software slave select (SSM) held inactive
        # (SSI = 1, SSIOP = 0: active low).
        spi.write(0x0C, 4, (2 << 17) | (1 << 22) | (1 << 26))
        spi.write(0x04, 4, 20)                       # TSIZE
        ssi = 1 << 12
        spi.write(0x00, 4, ssi | 1 | (masrx << 8))
        spi.write(0x00, 4, ssi | 1 | (masrx << 8) | (1 << 9))
        return bus, core, spi

    def test_frame_time_follows_sck(self):
        bus, core, spi = self.make(masrx=1)
        frame = 16 * CLOCK_HZ // 25_000_000  # 256 cycles
        run_until(bus, core, frame - 1)
        self.assertEqual(spi.frames, 0)
        run_until(bus, core, frame)
        self.assertEqual(spi.frames, 1)
        self.assertEqual(spi.read(0x30, 2), 0x1001)

    def test_words_follow_each_other_when_the_model_is_late(self):
        # The model handles an event only at the core's next block boundary,
        # here 100 cycles late every time; SCK does not wait for the core, so
        # the fourth word still ends at 4 x 256 cycles.
        bus, core, spi = self.make(masrx=1)
        while bus.events and bus.events[0][0] <= 4 * 256:
            core.cycles = bus.events[0][0] + 100
            bus.fire_due()
        self.assertEqual(core.cycles, 4 * 256 + 100)
        self.assertEqual(spi.frames, 4)
        self.assertEqual(spi.busy_until, 5 * 256)

    def test_masrx_suspends_instead_of_overrunning(self):
        bus, core, spi = self.make(masrx=1)
        run_until(bus, core, 40 * 256)
        self.assertEqual(len(spi.rx), 8, "16-byte FIFO of 16-bit frames")
        self.assertTrue(spi.read(0x14, 4) >> 11 & 1, "SUSP")
        self.assertFalse(spi.read(0x14, 4) >> 6 & 1, "no OVR")

    def test_overrun_without_masrx(self):
        bus, core, spi = self.make(masrx=0)
        run_until(bus, core, 40 * 256)
        sr = spi.read(0x14, 4)
        self.assertTrue(sr >> 6 & 1, "OVR")
        self.assertTrue(sr >> 3 & 1, "EOT after TSIZE frames")
        self.assertEqual(spi.overruns, 20 - 8)


class UsartTests(unittest.TestCase):
    def test_bytes_leave_ten_bit_times_apart(self):
        bus, core = world()
        rcc = system.Rcc()
        pll_400(rcc)
        out = []
        u = Usart(bus, core.nvic, Dma(bus, core.nvic), rcc, lambda b, t: out.append((b, t)))
        u.write(0x0C, 4, 100_000_000 // 921_600)  # BRR = 108
        u.write(0x00, 4, 1 | (1 << 3))             # UE, TE
        u.write(0x28, 1, ord("H"))
        u.write(0x28, 1, ord("\n"))
        run_until(bus, core, 10 ** 6)
        byte = round(10 * CLOCK_HZ / (100e6 / 108))
        self.assertEqual(out, [(ord("H"), byte), (ord("\n"), 2 * byte)])
        self.assertTrue(u.read(0x1C, 4) >> 6 & 1, "TC once the last byte is out")


class OnePulseTimer(unittest.TestCase):
    def test_update_event_stops_the_count_and_raises_the_interrupt(self):
        # The read deadline: 1 MHz counts (200 MHz / 200), ARR = 99, OPM:
        # the update event comes after 100 us = 40 000 core cycles.
        bus, core = world()
        t = system.Timer(bus, core.nvic, 44, lambda: 200e6, bits=16)
        t.write(0x28, 4, 199)              # PSC
        t.write(0x2C, 4, 99)               # ARR
        t.write(0x00, 4, 1 << 2)           # URS
        t.write(0x14, 4, 1)                # UG: loads PSC, no UIF (URS)
        self.assertEqual(t.read(0x10, 4), 0)
        t.write(0x0C, 4, 1)                # UIE
        t.write(0x24, 4, 0)
        t.write(0x00, 4, (1 << 3) | (1 << 2) | 1)  # OPM, URS, CEN
        run_until(bus, core, 40_000 - 400)
        self.assertFalse(core.nvic.pending[44])
        self.assertEqual(t.read(0x24, 4), 99)
        run_until(bus, core, 40_001)
        self.assertTrue(core.nvic.pending[44])
        self.assertEqual(t.read(0x10, 4) & 1, 1, "UIF")
        self.assertEqual(t.read(0x00, 4) & 1, 0, "OPM clears CEN")
        run_until(bus, core, 200_000)
        self.assertEqual(t.read(0x24, 4), 0, "the count stays stopped at 0")

    def test_stopped_before_the_deadline_nothing_fires(self):
        bus, core = world()
        t = system.Timer(bus, core.nvic, 44, lambda: 200e6, bits=16)
        t.write(0x28, 4, 199)
        t.write(0x2C, 4, 99)
        t.write(0x00, 4, 1 << 2)
        t.write(0x14, 4, 1)
        t.write(0x0C, 4, 1)
        t.write(0x00, 4, (1 << 3) | (1 << 2) | 1)
        run_until(bus, core, 20_000)
        t.write(0x00, 4, 1 << 2)           # CEN = 0 halfway
        run_until(bus, core, 400_000)
        self.assertFalse(core.nvic.pending[44])
        self.assertEqual(t.read(0x10, 4), 0)


class Watchdog(unittest.TestCase):
    def test_expiry_resets_unless_fed(self):
        bus, core = world()
        iwdg = system.Iwdg(bus, system.Dbgmcu(), debugger=False)
        iwdg.write(0x00, 4, 0x5555)
        iwdg.write(0x04, 4, 3)        # prescaler / 32
        iwdg.write(0x08, 4, 999)      # 1000 ticks: 1 s at 32 kHz
        iwdg.write(0x00, 4, 0xCCCC)
        run_until(bus, core, CLOCK_HZ // 2)
        iwdg.write(0x00, 4, 0xAAAA)   # fed at 0.5 s
        run_until(bus, core, CLOCK_HZ)   # 1 s: not expired
        with self.assertRaises(Reset) as r:
            run_until(bus, core, CLOCK_HZ * 3 // 2 + 1)
        self.assertEqual(r.exception.cause, "watchdog")


class ClockGating(unittest.TestCase):
    def test_register_access_with_the_clock_off_stops_the_run(self):
        bus, core = world()
        rcc = system.Rcc()
        bus.rcc = rcc
        bus.add(0x4001_3000, 0x400, object(), clock=(0xF0, 12, "SPI1"))
        with self.assertRaises(Stop):
            bus._check_clock(0x4001_3000, 0x4001_3000, core.uc, "read")
        rcc.write(0xF0, 4, 1 << 12)
        self.assertTrue(bus._check_clock(0x4001_3000, 0x4001_3000, core.uc, "read"))


if __name__ == "__main__":
    unittest.main()
