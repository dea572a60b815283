"""The chip model records every change of the READY and REJECT pins and of
the LEDs that mirror them (GPIO ODR and BSRR writes), with the time and the
last beam, and their fall when a reset returns the pins to inputs."""

import types
import unittest

from test_svd import bare_machine

GPIOB, GPIOE = 0x5802_0400, 0x5802_1000
MODER, ODR, BSRR = 0x00, 0x14, 0x18


class Pins(unittest.TestCase):
    def setUp(self):
        m = bare_machine()
        m.pin_edges = []
        m.resets = []
        m.detector = types.SimpleNamespace(beam=41)
        self.m = m
        # PE13, PE14 and PB0 as outputs (MODER = 01).
        e = m.gpio["E"]
        e.write(MODER, 4, (e.read(MODER, 4) & ~(0xF << 26)) | (0b0101 << 26))
        b = m.gpio["B"]
        b.write(MODER, 4, (b.read(MODER, 4) & ~0b11) | 0b01)
        m.pin_edges.clear()  # the z -> 0 of each new output (see HiZ)

    def edges(self):
        return [(name, level, beam) for _, name, level, beam, _ in self.m.pin_edges]

    def test_bsrr_and_odr_changes_are_recorded_once(self):
        e, b = self.m.gpio["E"], self.m.gpio["B"]
        self.m.core.cycles = 4000  # 10 us
        e.write(BSRR, 4, 1 << 14)          # READY high
        e.write(BSRR, 4, 1 << 14)          # no change: no edge
        b.write(BSRR, 4, 1 << 0)           # LD1 on
        self.m.detector.beam = 42
        e.write(ODR, 4, e.read(ODR, 4) | 1 << 13)   # REJECT high through ODR
        e.write(BSRR, 4, 1 << (16 + 13))   # REJECT low
        e.write(BSRR, 4, 1 << 9)           # PE9 (DRDY's pin) is not recorded
        self.assertEqual(self.edges(), [("READY", 1, 41), ("LD1", 1, 41),
                                        ("REJECT", 1, 42), ("REJECT", 0, 42)])
        self.assertEqual(self.m.pin_edges[0][0], 4000)

    def test_a_reset_releases_the_outputs_that_were_high(self):
        e = self.m.gpio["E"]
        e.write(BSRR, 4, 1 << 14)
        self.m.pin_edges.clear()
        self.m.core.cycles = 8000
        self.m.core.reset = lambda: None
        self.m.reset("watchdog")
        # Every recorded output goes Hi-Z (LD3, PB14, was never an output).
        self.assertEqual(self.edges(), [("READY", "z", 41), ("REJECT", "z", 41), ("LD1", "z", 41)])
        self.assertEqual(self.m.pin_edges[0][0], 8000)


class HiZ(unittest.TestCase):
    def setUp(self):
        m = bare_machine()
        m.pin_edges = []
        m.resets = []
        m.detector = types.SimpleNamespace(beam=-1)
        self.m = m

    def levels(self, name):
        return [level for _, n, level, _, _ in self.m.pin_edges if n == name]

    def test_a_pin_is_z_until_its_moder_makes_it_an_output(self):
        e = self.m.gpio["E"]
        self.m._observe("E")
        self.assertEqual(self.levels("READY"), ["z"], "analog at reset")
        e.write(BSRR, 4, 1 << 14)  # ODR set first: still not driven
        self.assertEqual(self.levels("READY"), ["z"])
        e.write(MODER, 4, (e.read(MODER, 4) & ~(3 << 28)) | (1 << 28))
        self.assertEqual(self.levels("READY"), ["z", 1], "output: the ODR level")
        e.write(MODER, 4, e.read(MODER, 4) & ~(3 << 28))  # input mode
        self.assertEqual(self.levels("READY"), ["z", 1, "z"])

    def test_open_drain_high_is_z(self):
        e = self.m.gpio["E"]
        e.write(0x04, 4, 1 << 13)  # OTYPER: open-drain
        e.write(MODER, 4, (e.read(MODER, 4) & ~(3 << 26)) | (1 << 26))
        e.write(BSRR, 4, 1 << 13)
        e.write(BSRR, 4, 1 << (16 + 13))
        self.assertEqual(self.levels("REJECT"), ["z", 0, "z", 0])


if __name__ == "__main__":
    unittest.main()


class UartLines(unittest.TestCase):
    def test_header_and_end_lines_with_their_last_bytes_time(self):
        from h743twin.machine import CLOCK_HZ, uart_lines
        # One byte every 4 000 cycles (10 µs at 400 MHz): the header's
        # '\n' is byte 5 (50 µs), the end line's byte 26 (260 µs); the
        # row line between them is left out.
        sent = b"H,a*1\nR,x\nE,verdict=good*2\n"
        uart = [(b, i * CLOCK_HZ // 100_000) for i, b in enumerate(sent)]
        self.assertEqual(uart_lines(uart), [{"us": 50.0, "line": "H,a*1"},
                                            {"us": 260.0, "line": "E,verdict=good*2"}])
