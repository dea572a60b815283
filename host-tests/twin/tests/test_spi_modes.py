"""SPI1's slave-select logic, mode fault and suspend/resume against RM0433
§50 (the H7 SPI), and the firmware's SPI1 register sequence played through
the model's registers: `cd host-tests/twin && python3 -m unittest discover -s tests`.

The sequence tests stand for the release firmware without needing its ELF:
the writes are those of `embassy_stm32::spi::Spi::new_blocking_rxonly`
(embassy-stm32 0.6.0, spi_v4 branch of `enable_and_init`) followed by
`FrameReader::new` and `FrameReader::start` in `src/h743/frame_reader.rs`.
"""

import unittest

from h743twin import system
from h743twin.core import CLOCK_HZ, Stop
from h743twin.dma import Dma, REQ_SPI1_RX, TCIF
from h743twin.serial import (CSTART, CSUSP, MASRX, MASTER, MODF, SPE, SSI, SSIOP, SSM,
                             SSOE, SUSP, Spi)
from test_model import pll_400, run_until, world

SPI1 = 0x4001_3000
RXDR = SPI1 + 0x30
COMM_RECEIVER = 2 << 17
DSIZE16 = 15
MBR_DIV8 = 2 << 28
RXDMAEN = 1 << 14
AFCNTR = 1 << 31
FRAME_CYCLES = 16 * CLOCK_HZ // 25_000_000  # 16 bits at 200 MHz / 8


class Slave:
    def __init__(self):
        self.n = 0

    def exchange(self, out, bits):
        self.n += 1
        return 0x1000 + self.n

    def unread(self):
        self.n -= 1


def make():
    bus, core = world()
    rcc = system.Rcc()
    pll_400(rcc)
    dma = Dma(bus, core.nvic)
    spi = Spi(bus, core.nvic, dma, rcc, Slave())
    bus.periphs.append((SPI1, 0x400, spi))
    return bus, core, dma, spi


def receive_only_master(spi, cfg2_extra, cr1_extra, masrx=0):
    spi.write(0x08, 4, DSIZE16 | MBR_DIV8)
    spi.write(0x0C, 4, COMM_RECEIVER | MASTER | cfg2_extra)
    spi.write(0x04, 4, 20)
    spi.write(0x00, 4, cr1_extra | (MASRX if masrx else 0))
    spi.write(0x00, 4, cr1_extra | (MASRX if masrx else 0) | SPE)
    spi.write(0x00, 4, cr1_extra | (MASRX if masrx else 0) | SPE | CSTART)


class SlaveSelect(unittest.TestCase):
    """RM0433 §50.4.7: with SSM = 1 the SS input is SSI; SSIOP = 1 makes
    the high level active, SSIOP = 0 the low level."""

    def check(self, cfg2_extra, cr1_extra, fault):
        bus, core, _, spi = make()
        receive_only_master(spi, cfg2_extra, cr1_extra)
        run_until(bus, core, 3 * FRAME_CYCLES)
        sr = spi.read(0x14, 4)
        self.assertEqual(bool(sr & MODF), fault, "MODF")
        self.assertEqual(spi.frames, 0 if fault else 3)
        self.assertEqual(bool(spi.read(0x00, 4) & SPE), not fault, "SPE")
        self.assertEqual(bool(spi.read(0x0C, 4) & MASTER), not fault, "MASTER")

    def test_ssi_high_active_high_is_a_mode_fault(self):
        # Today's firmware: SSM = 1, SSI = 1, SSIOP = 1 (embassy's default).
        self.check(SSM | SSIOP, SSI, fault=True)

    def test_ssi_low_active_high_streams(self):
        self.check(SSM | SSIOP, 0, fault=False)

    def test_ssi_high_active_low_streams(self):
        self.check(SSM, SSI, fault=False)

    def test_ssi_low_active_low_is_a_mode_fault(self):
        self.check(SSM, 0, fault=True)

    def test_ssoe_does_not_mask_the_software_input(self):
        # SSOE only makes the NSS pin an output; with SSM = 1 SSI still
        # decides (embassy sets SSOE, and the fault still happens).
        self.check(SSM | SSOE | SSIOP, SSI, fault=True)
        self.check(SSM | SSOE, SSI, fault=False)

    def test_hardware_select_follows_the_pin_unless_it_is_an_output(self):
        bus, core, _, spi = make()
        spi.nss_pin = 1
        receive_only_master(spi, 0, 0)   # SSIOP = 0: the low level is active
        self.assertFalse(spi.read(0x14, 4) & MODF, "pin high, active low: no fault")
        spi.drive_nss(0)
        self.assertTrue(spi.read(0x14, 4) & MODF, "pin pulled low while SPE = 1")
        self.assertFalse(spi.read(0x00, 4) & SPE)
        bus, core, _, spi = make()
        spi.nss_pin = 0
        receive_only_master(spi, SSOE, 0)
        self.assertFalse(spi.read(0x14, 4) & MODF, "SSOE: NSS is the master's output")

    def test_unwired_pin_stops_the_run(self):
        _, _, _, spi = make()
        with self.assertRaises(Stop):
            receive_only_master(spi, 0, 0)

    def test_slave_answers_in_slave_mode_only(self):
        # A slave (MASTER = 0) selected by SSI never faults; on this board
        # no master clocks it, so nothing shifts and CSTART starts nothing.
        bus, core, _, spi = make()
        spi.write(0x0C, 4, COMM_RECEIVER | SSM | SSIOP)
        spi.write(0x00, 4, SSI | SPE)
        spi.write(0x00, 4, SSI | SPE | CSTART)
        run_until(bus, core, 10 * FRAME_CYCLES)
        self.assertEqual(spi.frames, 0)
        self.assertFalse(spi.read(0x14, 4) & MODF)
        self.assertTrue(spi.read(0x00, 4) & SPE)


class ModeFault(unittest.TestCase):
    """RM0433 §50.4.13 (mode fault) and SPI_IFCR.MODFC."""

    def faulted(self):
        bus, core, dma, spi = make()
        receive_only_master(spi, SSM | SSIOP, SSI)
        return bus, core, spi

    def test_fault_raises_the_interrupt_when_enabled(self):
        bus, core, spi = self.faulted()
        self.assertFalse(core.nvic.line[35])
        spi.write(0x10, 4, MODF)   # MODFIE
        self.assertTrue(core.nvic.line[35])

    def test_spe_cannot_be_set_while_modf_is_set(self):
        bus, core, spi = self.faulted()
        spi.write(0x0C, 4, COMM_RECEIVER | MASTER | SSM)  # SSIOP = 0 now
        spi.write(0x00, 4, SSI | SPE)
        self.assertFalse(spi.read(0x00, 4) & SPE, "SPE held at 0 while MODF")
        spi.write(0x18, 4, MODF)   # MODFC
        self.assertFalse(spi.read(0x14, 4) & MODF)
        spi.write(0x00, 4, SSI | SPE)
        spi.write(0x00, 4, SSI | SPE | CSTART)
        run_until(bus, core, 2 * FRAME_CYCLES)
        self.assertEqual(spi.frames, 2, "recovered: MASTER re-armed, polarity fixed")

    def test_clearing_modf_does_not_restore_master(self):
        # Today's `stop()` clears MODF: the next read enables a slave.
        bus, core, spi = self.faulted()
        spi.write(0x18, 4, 0xFF8)
        spi.write(0x00, 4, SSI | MASRX | SPE)
        spi.write(0x00, 4, SSI | MASRX | SPE | CSTART)
        run_until(bus, core, 10 * FRAME_CYCLES)
        self.assertEqual(spi.frames, 0)
        self.assertFalse(spi.read(0x0C, 4) & MASTER)
        self.assertFalse(spi.read(0x14, 4) & MODF, "a slave has no mode fault")

    def test_ssi_raised_while_enabled_faults_at_once(self):
        bus, core, _, spi = make()
        receive_only_master(spi, SSM | SSIOP, 0)
        run_until(bus, core, FRAME_CYCLES)
        self.assertEqual(spi.frames, 1)
        spi.write(0x00, 4, SPE | SSI)
        self.assertTrue(spi.read(0x14, 4) & MODF)
        run_until(bus, core, 5 * FRAME_CYCLES)
        self.assertEqual(spi.frames, 1, "no clock after the fault")


class Suspend(unittest.TestCase):
    def test_masrx_suspension_resumes_on_suspc(self):
        bus, core, _, spi = make()
        receive_only_master(spi, SSM, SSI, masrx=1)
        run_until(bus, core, 12 * FRAME_CYCLES)
        self.assertEqual(len(spi.rx), 8, "16-byte RX FIFO of 16-bit frames")
        self.assertTrue(spi.read(0x14, 4) & SUSP)
        self.assertEqual([spi.read(0x30, 2) for _ in range(4)], [0x1001, 0x1002, 0x1003, 0x1004])
        spi.write(0x18, 4, SUSP)   # SUSPC
        self.assertFalse(spi.read(0x14, 4) & SUSP)
        run_until(bus, core, core.cycles + 4 * FRAME_CYCLES)
        self.assertEqual([spi.read(0x30, 2) for _ in range(8)], list(range(0x1005, 0x100D)),
                         "four more frames after SUSPC, none lost")
        self.assertFalse(spi.read(0x14, 4) & (1 << 6), "no OVR")

    def test_csusp_suspension_is_not_resumed_by_suspc(self):
        bus, core, _, spi = make()
        receive_only_master(spi, SSM, SSI)
        run_until(bus, core, 2 * FRAME_CYCLES)
        spi.write(0x00, 4, SSI | SPE | CSUSP)
        spi.write(0x18, 4, SUSP)
        run_until(bus, core, 6 * FRAME_CYCLES)
        self.assertEqual(spi.frames, 2)


class FirmwareSequence(unittest.TestCase):
    """SPI1 and DMA1 stream 1 as the firmware drives them for one frame of
    20 samples; the frame lands in memory or it does not."""

    MEM = 0x2400_0000
    N = 20

    def embassy_init(self, spi):
        # Spi::new_blocking_rxonly: IFCR all ones, then CFG2 with SSOE,
        # SSM (no NSS pin), MASTER, full duplex, AFCNTR and SSIOP =
        # active high (Config::default), CFG1 8-bit frames, CR1 SSI = 0, SPE.
        spi.write(0x18, 4, 0xFFFF_FFFF)
        spi.write(0x0C, 4, SSOE | SSM | MASTER | AFCNTR | SSIOP)
        spi.write(0x08, 4, 7 | MBR_DIV8)
        spi.write(0x04, 4, 0)
        spi.write(0x00, 4, SPE)
        self.assertFalse(spi.read(0x14, 4) & MODF, "embassy's own set-up is sound")

    def modify(self, spi, off, clear, set_):
        spi.write(off, 4, (spi.read(off, 4) & ~clear) | set_)

    def reader_new(self, spi, cfg2_extra=0, cfg2_clear=0):
        self.modify(spi, 0x00, SPE, 0)
        self.modify(spi, 0x08, 0x1F | (0xF << 5) | (7 << 28), DSIZE16 | RXDMAEN | MBR_DIV8)
        self.modify(spi, 0x0C, (3 << 17) | cfg2_clear,
                    COMM_RECEIVER | MASTER | SSM | AFCNTR | cfg2_extra)
        self.modify(spi, 0x00, 0, SSI | MASRX)

    def read_frame(self, bus, core, dma, spi):
        dma.mux[1] = REQ_SPI1_RX
        st = 0x10 + 0x18
        dma.write(st + 0x08, 4, RXDR)
        dma.write(st + 0x0C, 4, self.MEM)
        dma.write(st + 0x04, 4, self.N)
        dma.write(st, 4, (1 << 11) | (1 << 13) | (1 << 10) | (3 << 16) | 0x10 | 0x04 | 0x02 | 1)
        self.modify(spi, 0x04, 0xFFFF, self.N)
        self.modify(spi, 0x00, 0, SPE)
        self.modify(spi, 0x00, 0, CSTART)
        run_until(bus, core, core.cycles + 2 * self.N * FRAME_CYCLES)
        return dma.read(0x00, 4) >> 6 & 0x3D, dma.read(st + 0x04, 4)

    def samples(self, core):
        data = core.uc.mem_read(self.MEM, 2 * self.N)
        return [data[i] | data[i + 1] << 8 for i in range(0, len(data), 2)]

    def test_todays_sequence_loses_every_frame(self):
        bus, core, dma, spi = make()
        self.embassy_init(spi)
        self.reader_new(spi)
        flags, ndtr = self.read_frame(bus, core, dma, spi)
        self.assertEqual((flags, ndtr), (0, self.N), "no item moved, no flag")
        self.assertEqual(spi.frames, 0)
        self.assertTrue(spi.read(0x14, 4) & MODF)
        self.assertFalse(spi.read(0x0C, 4) & MASTER)
        self.assertEqual(self.samples(core), [0] * self.N)

    def test_corrected_sequence_streams(self):
        # SSIOP written explicitly to active low, so SSI = 1 is inactive.
        bus, core, dma, spi = make()
        self.embassy_init(spi)
        self.reader_new(spi, cfg2_clear=SSIOP)
        flags, ndtr = self.read_frame(bus, core, dma, spi)
        self.assertEqual((flags & TCIF, ndtr), (TCIF, 0))
        self.assertEqual(self.samples(core), [0x1001 + i for i in range(self.N)])
        self.assertFalse(spi.read(0x14, 4) & MODF)


if __name__ == "__main__":
    unittest.main()
