"""USART3's receiver against RM0433 §48 (USART_ISR, ICR, RQR, CR3, the
RX FIFO, and the usart3_rx_dma request), worked out by hand:
`cd host-tests/twin && python3 -m unittest discover -s tests`."""

import os
import tempfile
import unittest

from h743twin import system
from h743twin.core import CLOCK_HZ
from h743twin.dma import Dma
from h743twin.serial import USART3_IRQ, Usart
from h743twin.usart_rx import REQ_USART3_RX, parse_requests
from test_model import pll_400, run_until, world

# ISR bits (RM0433 USART_ISR)
PE, FE, NE, ORE, IDLE, RXFNE, RXFF, RXFT = 1, 2, 4, 8, 16, 32, 1 << 24, 1 << 26
UE, RE, TE, IDLEIE, RXNEIE, FIFOEN = 1, 1 << 2, 1 << 3, 1 << 4, 1 << 5, 1 << 29
EIE, DMAR, OVRDIS = 1, 1 << 6, 1 << 12
# One 8N1 frame at 921600 baud, in 400 MHz core cycles: 10 / 921600 s.
FRAME = round(10 * 400_000_000 / 921_600)


class Rx(unittest.TestCase):
    def setUp(self):
        self.bus, self.core = world()
        rcc = system.Rcc()
        pll_400(rcc)
        self.bus.rcc = rcc
        self.dma = Dma(self.bus, self.core.nvic)
        self.u = Usart(self.bus, self.core.nvic, self.dma, rcc, lambda b, t: None)
        self.bus.add(0x4000_4800, 0x400, self.u)
        self.u.write(0x0C, 4, 108)  # 100 MHz kernel / 108: 0.5 % from 921600

    def on(self, cr1=0, cr3=0):
        self.u.write(0x08, 4, cr3)
        self.u.write(0x00, 4, UE | RE | TE | cr1)

    def isr(self):
        return self.u.read(0x1C, 4)

    def at(self, cycle):
        run_until(self.bus, self.core, cycle)

    def test_frame_is_ten_bit_times(self):
        self.assertEqual(CLOCK_HZ, 400_000_000)
        self.assertEqual(self.u.rx.frame_cycles(), 4340)

    def test_bytes_arrive_a_frame_apart_and_read_in_order(self):
        self.on(FIFOEN)
        self.u.rx.send(b"s,1")
        self.at(FRAME - 1)
        self.assertFalse(self.isr() & RXFNE, "nothing before the first stop bit")
        self.at(FRAME)
        self.assertTrue(self.isr() & RXFNE)
        self.at(3 * FRAME)
        self.assertEqual([self.u.read(0x24, 4) for _ in range(3)], list(b"s,1"))
        self.assertFalse(self.isr() & RXFNE)

    def test_overrun_without_fifo_keeps_the_first_byte(self):
        self.on(RXNEIE)
        self.u.rx.send(b"ab")
        self.at(2 * FRAME)
        self.assertTrue(self.isr() & ORE)
        self.assertEqual(self.u.rx.overruns, 1)
        self.assertTrue(self.core.nvic.line[USART3_IRQ], "RXNEIE with ORE")
        self.assertEqual(self.u.read(0x24, 4), ord("a"))
        self.assertTrue(self.isr() & ORE, "reading RDR does not clear ORE")
        self.u.write(0x20, 4, 1 << 3)  # ORECF
        self.assertFalse(self.isr() & ORE)
        self.assertFalse(self.isr() & RXFNE)

    def test_ovrdis_lets_the_new_byte_overwrite_rdr(self):
        self.on(0, OVRDIS)
        self.u.rx.send(b"ab")
        self.at(2 * FRAME)
        self.assertFalse(self.isr() & ORE)
        self.assertEqual(self.u.read(0x24, 4), ord("b"))

    def test_fifo_holds_sixteen_then_overruns(self):
        self.on(FIFOEN, 2 << 25)  # RXFTCFG = 1/2: 8 bytes
        self.u.rx.send(bytes(range(17)))
        self.at(7 * FRAME)
        self.assertFalse(self.isr() & RXFT)
        self.at(8 * FRAME)
        self.assertTrue(self.isr() & RXFT)
        self.at(16 * FRAME)
        self.assertTrue(self.isr() & RXFF)
        self.assertFalse(self.isr() & ORE)
        self.at(17 * FRAME)
        self.assertTrue(self.isr() & ORE)
        self.assertEqual([self.u.read(0x24, 4) for _ in range(16)], list(range(16)))
        self.assertFalse(self.isr() & (RXFNE | RXFF | RXFT))

    def test_error_flags_follow_the_byte_to_the_head_of_the_fifo(self):
        self.on(FIFOEN, EIE)
        self.u.rx.send(b"xyz", {1: "fe", 2: "ne"})
        self.at(3 * FRAME)
        self.assertFalse(self.isr() & (FE | NE), "the damaged bytes are not next yet")
        self.assertFalse(self.u.rx.irq())
        self.assertEqual(self.u.read(0x24, 4), ord("x"))
        self.assertEqual(self.isr() & (FE | NE), FE)
        self.assertTrue(self.u.rx.irq(), "EIE with FE")
        self.assertEqual(self.u.read(0x24, 4), ord("y"))
        self.assertEqual(self.isr() & (FE | NE), FE | NE, "flags stay until ICR clears them")
        self.u.write(0x20, 4, (1 << 1) | (1 << 2))  # FECF, NECF
        self.assertEqual(self.isr() & (FE | NE), 0)
        self.assertEqual(self.u.read(0x24, 4), ord("z"))

    def test_parity_error_and_its_clear(self):
        self.on()
        self.u.rx.send(b"p", {0: "pe"})
        self.at(FRAME)
        self.assertTrue(self.isr() & PE)
        self.u.write(0x20, 4, 1)  # PECF
        self.assertFalse(self.isr() & PE)

    def test_idle_once_after_a_burst(self):
        self.on(FIFOEN | IDLEIE)
        self.u.rx.send(b"ab")
        self.at(2 * FRAME + FRAME - 1)
        self.assertFalse(self.isr() & IDLE, "back-to-back bytes keep the line busy")
        self.at(3 * FRAME)
        self.assertTrue(self.isr() & IDLE)
        self.assertTrue(self.u.rx.irq())
        self.u.write(0x20, 4, 1 << 4)  # IDLECF
        self.at(10 * FRAME)
        self.assertFalse(self.isr() & IDLE, "not again without a new byte")

    def test_a_receiver_at_another_baud_rate_sees_framing_errors(self):
        self.u.write(0x0C, 4, 217)  # 460800 baud
        self.on()
        self.u.rx.send(b"a")
        self.at(FRAME)
        self.assertTrue(self.isr() & FE)

    def test_bytes_are_lost_while_the_receiver_is_off(self):
        self.u.write(0x00, 4, UE | TE)
        self.u.rx.send(b"a")
        self.at(FRAME)
        self.assertFalse(self.isr() & RXFNE)
        self.assertEqual(self.u.rx.lost_off, 1)

    def test_rxfrq_empties_the_receiver(self):
        self.on(FIFOEN)
        self.u.rx.send(b"abc")
        self.at(3 * FRAME)
        self.u.write(0x18, 4, 1 << 3)
        self.assertFalse(self.isr() & RXFNE)

    def test_dma_request_moves_bytes_to_memory(self):
        self.on(FIFOEN, DMAR)
        stream = 0x10 + 0x18  # stream 1
        self.dma.mux[1] = REQ_USART3_RX
        self.dma.write(stream + 0x04, 4, 4)              # NDTR
        self.dma.write(stream + 0x08, 4, 0x4000_4824)    # PAR: RDR
        self.dma.write(stream + 0x0C, 4, 0x2400_0000)    # M0AR: AXI SRAM
        self.dma.write(stream, 4, (1 << 10) | 1)         # MINC, EN; bytes, P2M
        self.u.rx.send(b"get,")
        self.at(4 * FRAME)
        self.assertEqual(self.core.uc.mem_read(0x2400_0000, 4), b"get,")
        self.assertEqual(self.dma.transfers, 4)
        self.assertFalse(self.isr() & RXFNE)


class RequestFile(unittest.TestCase):
    def parse(self, text):
        fd, path = tempfile.mkstemp()
        with os.fdopen(fd, "w") as f:
            f.write(text)
        try:
            return parse_requests(path)
        finally:
            os.unlink(path)

    def test_beams_bytes_and_damaged_bytes(self):
        got = self.parse("# status at beam 3\n3 532c31\n\n10 0a fe@0 ne@0\n12 00 pe@0\n")
        self.assertEqual(got, [(3, b"S,1", {}), (10, b"\n", {0: "ne"}), (12, b"\0", {0: "pe"})])

    def test_malformed_lines_are_refused(self):
        for bad in ("x 41\n", "1 4\n", "1 41 fe@1\n", "1 41 xx@0\n", "-1 41\n"):
            with self.subTest(line=bad), self.assertRaises(ValueError):
                self.parse(bad)


if __name__ == "__main__":
    unittest.main()
