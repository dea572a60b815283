"""SRAM1-3 clock gating (RCC_AHB2ENR) for the CPU and DMA1, DMA1 reading
flash, TCIF on a stream disabled mid-transfer, and DMA1's memory-to-memory
mode reading bank 2 of the flash, whose double ECC errors are transfer
errors, against RM0433 §2.3, §4, §8.7 and §15.3:
`cd host-tests/twin && python3 -m unittest discover -s tests`."""

import struct
import unittest

from h743twin import system
from h743twin.bus import Bus
from h743twin.core import Core, Stop
from h743twin.dma import HTIF, M2M_CYCLES_PER_ITEM, REQ_SPI1_RX, REQ_USART3_TX, TCIF, TEIF, Dma
from h743twin.flash import BANK2_BASE, BANK2_SIZE, Bank2, Bank2Window, FlashInterface
from test_model import run_until, world

SRAM1 = 0x3000_0000
SRAM3 = 0x3004_0000
STREAM1 = 0x10 + 0x18
P2M_16 = (1 << 11) | (1 << 13) | (1 << 10) | 0x10 | 0x04 | 1   # PSIZE=MSIZE=16, MINC, TCIE, TEIE, EN
M2P_8 = (1 << 6) | (1 << 10) | 0x10 | 0x04 | 1                 # memory to peripheral, bytes


def program(base):
    """Vector table, then: r1 = base; r0 = [r1]; [r1 + 4] = r0; `b .`
    (llvm-mc, thumbv7em)."""
    lo, hi = base & 0xFFFF, base >> 16

    def movw_movt(op, imm):
        imm4, i, imm3, imm8 = imm >> 12, imm >> 11 & 1, imm >> 8 & 7, imm & 0xFF
        return struct.pack("<HH", op | i << 10 | imm4, imm3 << 12 | 1 << 8 | imm8)

    code = (movw_movt(0xF240, lo) + movw_movt(0xF2C0, hi)
            + bytes.fromhex("0868" "4860" "fee7"))
    return struct.pack("<2I", 0x2000_1000, 0x0800_0009) + code


def machine(base):
    bus = Bus()
    rcc = bus.add(0x5802_4400, 0x400, system.Rcc())
    bus.rcc = rcc
    rcc.on_ahb2enr = bus.sram_clocks_changed
    core = Core(bus)
    image = program(base)
    core.load([(0x0800_0000, image)])
    core.reset()
    bus.sram_clocks_changed()
    return bus, core, rcc


def run(core):
    core.run_until(2_000)


class SramClocks(unittest.TestCase):
    def test_sram1_read_with_its_clock_off_is_a_bus_fault(self):
        bus, core, rcc = machine(SRAM1)
        with self.assertRaises(Stop) as stop:
            run(core)
        self.assertIn("SRAM1 read at 0x30000000 while its clock is off", str(stop.exception))

    def test_each_block_follows_its_own_enable(self):
        bus, core, rcc = machine(SRAM3)
        rcc.write(0xDC, 4, (1 << 29) | (1 << 30))   # SRAM1EN, SRAM2EN only
        with self.assertRaises(Stop) as stop:
            run(core)
        self.assertIn("SRAM3", str(stop.exception))

    def test_enabled_sram_reads_and_writes(self):
        bus, core, rcc = machine(SRAM1)
        core.uc.mem_write(SRAM1, struct.pack("<I", 0xCAFE_F00D))
        rcc.write(0xDC, 4, 1 << 29)
        run(core)
        self.assertEqual(struct.unpack("<I", core.uc.mem_read(SRAM1 + 4, 4))[0], 0xCAFE_F00D)
        self.assertIsNone(bus.error)

    def test_clock_turned_off_again_faults_again(self):
        bus, core, rcc = machine(SRAM1)
        rcc.write(0xDC, 4, 1 << 29)
        rcc.write(0xDC, 4, 0)
        with self.assertRaises(Stop):
            run(core)


class DmaReach(unittest.TestCase):
    def setUp(self):
        self.bus, self.core = world()
        self.rcc = system.Rcc()
        self.bus.rcc = self.rcc
        self.dma = Dma(self.bus, self.core.nvic)
        self.fifo = [0x1234, 0xBEEF, 0x0001]
        self.out = []
        dma = self

        class Periph:
            def read(_, off, size):
                return dma.fifo.pop(0)

            def write(_, off, size, value):
                dma.out.append(value)

        self.bus.periphs.append((0x4001_3000, 0x400, Periph()))
        self.dma.register(REQ_SPI1_RX, lambda: bool(self.fifo))
        self.dma.register(REQ_USART3_TX, lambda: len(self.out) < 4)

    def start(self, req, mem, n, cr):
        self.dma.mux[1] = req
        self.dma.write(STREAM1 + 0x04, 4, n)
        self.dma.write(STREAM1 + 0x08, 4, 0x4001_3030)
        self.dma.write(STREAM1 + 0x0C, 4, mem)
        self.dma.write(STREAM1, 4, cr)
        return self.dma.read(0x00, 4) >> 6 & 0x3D

    def test_sram1_with_its_clock_off_is_a_transfer_error(self):
        self.assertEqual(self.start(REQ_SPI1_RX, SRAM1, 3, P2M_16) & TEIF, TEIF)
        self.assertEqual(self.dma.errors, 1)
        self.assertEqual(self.core.uc.mem_read(SRAM1, 2), bytes(2))

    def test_sram1_with_its_clock_on_is_written(self):
        self.rcc.write(0xDC, 4, 1 << 29)
        self.assertEqual(self.start(REQ_SPI1_RX, SRAM1, 3, P2M_16) & (TCIF | TEIF), TCIF)
        self.assertEqual(self.core.uc.mem_read(SRAM1, 6), bytes.fromhex("3412efbe0100"))

    def test_flash_is_read(self):
        self.core.uc.mem_write(0x0800_1000, b"CVM!")
        self.assertEqual(self.start(REQ_USART3_TX, 0x0800_1000, 4, M2P_8) & (TCIF | TEIF), TCIF)
        self.assertEqual(self.out, list(b"CVM!"))

    def test_flash_is_not_written(self):
        self.assertEqual(self.start(REQ_SPI1_RX, 0x0800_1000, 3, P2M_16) & TEIF, TEIF)


class StreamDisable(unittest.TestCase):
    def setUp(self):
        self.bus, self.core = world()
        self.dma = Dma(self.bus, self.core.nvic)
        self.fifo = [1, 2]

        class Rx:
            def read(_, off, size):
                return self.fifo.pop(0)

        self.bus.periphs.append((0x4001_3000, 0x400, Rx()))
        self.dma.register(REQ_SPI1_RX, lambda: bool(self.fifo))
        self.dma.mux[1] = REQ_SPI1_RX
        self.dma.write(STREAM1 + 0x04, 4, 10)
        self.dma.write(STREAM1 + 0x08, 4, 0x4001_3030)
        self.dma.write(STREAM1 + 0x0C, 4, 0x2400_0000)
        self.dma.write(STREAM1, 4, P2M_16)

    def flags(self):
        return self.dma.read(0x00, 4) >> 6 & 0x3D

    def test_software_disable_mid_transfer_sets_tcif(self):
        self.assertEqual(self.flags(), 0, "2 of 10 items: no flag yet")
        self.dma.write(STREAM1, 4, P2M_16 & ~1)
        self.assertEqual(self.flags(), TCIF)
        self.assertEqual(self.dma.read(STREAM1 + 0x04, 4), 8, "NDTR keeps what was left")
        self.assertTrue(self.core.nvic.line[12], "TCIE: the stream's interrupt")

    def test_disabling_a_finished_stream_sets_nothing_more(self):
        self.fifo.extend(range(8))
        self.dma.poll(REQ_SPI1_RX)
        self.dma.write(0x08, 4, TCIF << 6)   # LIFCR: clear TCIF1 (and HTIF1)
        self.dma.write(0x08, 4, 0x3D << 6)
        self.dma.write(STREAM1, 4, P2M_16 & ~1)
        self.assertEqual(self.flags(), 0)


STREAM7 = 0x10 + 7 * 0x18
HISR, HIFCR = 0x04, 0x0C
# DIR = memory to memory, PSIZE = MSIZE = 32 bits, PINC, MINC, EN
M2M_32 = (2 << 6) | (2 << 11) | (2 << 13) | (1 << 9) | (1 << 10) | 1
AXI = 0x2400_0100


class MemoryToMemory(unittest.TestCase):
    """Stream 7 copies bank 2 of the flash into AXI SRAM, as the settings
    store's flash driver does (src/h743/flash_bank2.rs)."""

    def setUp(self):
        self.bus, self.core = world()
        self.bus.rcc = system.Rcc()
        self.dma = Dma(self.bus, self.core.nvic)
        self.bank = Bank2()
        self.bank.data[0x40:0x80] = bytes(range(0x40))
        self.flash = FlashInterface(self.bus, self.core.nvic, self.bank)
        self.bus.periphs.append((BANK2_BASE, BANK2_SIZE, Bank2Window(self.flash)))
        self.t = 0

    def flags(self):
        return self.dma.read(HISR, 4) >> 22 & 0x3D

    def start(self, src, words, cr=M2M_32):
        self.dma.write(STREAM7 + 0x04, 4, words)
        self.dma.write(STREAM7 + 0x08, 4, src)
        self.dma.write(STREAM7 + 0x0C, 4, AXI)
        self.dma.write(STREAM7, 4, cr)

    def wait(self, cycles):
        self.t += cycles
        run_until(self.bus, self.core, self.t)

    def test_a_block_is_copied_after_its_time_without_a_request(self):
        self.start(BANK2_BASE + 0x40, 16)
        self.assertEqual(self.flags(), 0, "nothing moved at once")
        self.assertEqual(self.dma.read(STREAM7 + 0x14, 4) & 0x04, 0x04, "FCR.DMDIS set by the hardware")
        self.wait(16 * M2M_CYCLES_PER_ITEM)
        self.assertEqual(self.flags(), TCIF | HTIF)
        self.assertEqual(self.dma.read(STREAM7, 4) & 1, 0, "EN cleared at the end")
        self.assertEqual(self.dma.read(STREAM7 + 0x04, 4), 0)
        self.assertEqual(bytes(self.core.uc.mem_read(AXI, 0x40)), bytes(range(0x40)))
        self.assertEqual(self.bank.dma_reads, 16)
        self.assertFalse(self.core.nvic.line[47], "no interrupt enable: no interrupt")
        self.dma.write(HIFCR, 4, 0x3D << 22)
        self.assertEqual(self.flags(), 0)

    def test_a_word_with_a_double_ecc_error_is_a_transfer_error(self):
        self.bank.bad_ecc.add(3)   # bytes 0x60..0x7F
        self.start(BANK2_BASE + 0x40, 16)
        self.wait(16 * M2M_CYCLES_PER_ITEM)
        self.assertEqual(self.flags(), TEIF | HTIF, "half the block went before the error")
        self.assertEqual(self.dma.read(STREAM7, 4) & 1, 0, "EN cleared by the error")
        self.assertEqual(self.dma.read(STREAM7 + 0x04, 4), 8, "stopped at the bad word's first item")
        self.assertEqual(bytes(self.core.uc.mem_read(AXI, 0x20)), bytes(range(0x20)), "the good word before it")
        self.assertTrue(self.flash.read(0x110, 4) & (1 << 26), "SR2.DBECCERR")
        self.assertEqual(self.flash.read(0x160, 4), 3, "FLASH_ECC_FA2R: the word's index")
        self.assertEqual(self.bank.ecc_errors, 1)
        self.flash.write(0x114, 4, 1 << 26)
        self.assertFalse(self.flash.read(0x110, 4) & (1 << 26), "cleared through CCR2")
        with self.assertRaises(Stop):
            self.flash.mem_read(0x60, 4)   # the CPU: a bus fault

    def test_a_stream_disabled_before_its_end_moves_nothing_more(self):
        self.start(BANK2_BASE + 0x40, 16)
        self.dma.write(STREAM7, 4, M2M_32 & ~1)
        self.wait(16 * M2M_CYCLES_PER_ITEM)
        self.assertEqual(self.dma.read(STREAM7 + 0x04, 4), 16)
        self.assertEqual(bytes(self.core.uc.mem_read(AXI, 4)), bytes(4))

    def test_dtcm_is_no_destination(self):
        self.dma.write(STREAM7 + 0x04, 4, 4)
        self.dma.write(STREAM7 + 0x08, 4, BANK2_BASE)
        self.dma.write(STREAM7 + 0x0C, 4, 0x2000_0000)
        self.dma.write(STREAM7, 4, M2M_32)
        self.wait(4 * M2M_CYCLES_PER_ITEM)
        self.assertEqual(self.flags(), TEIF)

    def test_circular_mode_is_not_allowed(self):
        with self.assertRaises(Stop):
            self.start(BANK2_BASE, 4, M2M_32 | (1 << 8))


class PostedWrites(unittest.TestCase):
    """The write-buffer ordering check (bus.posted_write): unpending TIM13's
    interrupt (NVIC_ICPR1 bit 12) right after a write to TIM13."""

    TIM13 = 0x4000_1C00
    ICPR1 = 0xE000_E284

    def setUp(self):
        self.bus, self.core = world()
        self.bus.add(self.TIM13, 0x400, system.Timer(self.bus, self.core.nvic, 44, lambda: 200e6, bits=16,
                                                     channels=1))
        self.bus.irq_owner = {44: self.TIM13}

    def clear_sr(self):
        self.bus._write(self.core.uc, self.TIM13 + 0x10 - 0x4000_0000, 4, 0, 0x4000_0000)

    def unpend(self):
        self.bus.core_write(self.ICPR1, 4, 1 << 12)

    def test_unpend_right_after_the_write_is_recorded(self):
        self.clear_sr()
        self.unpend()
        self.assertEqual([irq for irq, _, _ in self.bus.unordered_unpends], [44])

    def test_read_back_orders_it(self):
        self.clear_sr()
        self.bus._read(self.core.uc, self.TIM13 + 0x10 - 0x4000_0000, 4, 0x4000_0000)
        self.unpend()
        self.assertEqual(self.bus.unordered_unpends, [])

    def test_dsb_orders_it(self):
        self.clear_sr()
        self.bus.barrier()
        self.unpend()
        self.assertEqual(self.bus.unordered_unpends, [])

    def test_another_interrupts_unpend_is_not_concerned(self):
        self.clear_sr()
        self.bus.core_write(self.ICPR1, 4, 1 << 13)
        self.assertEqual(self.bus.unordered_unpends, [])


if __name__ == "__main__":
    unittest.main()
