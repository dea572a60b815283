"""Reset causes and RCC_RSR (RM0433 §8.4.x, "reset source identification":
the table of RCC_RSR flags each reset source sets). Every system reset
drives NRST low, so PINRSTF comes with all of them, and resets the CPU
(CPURSTF); a power-on reset sets PORRSTF, BORRSTF, PINRSTF, D1RSTF,
D2RSTF and CPURSTF; a brown-out (VDD below the BOR threshold but not the
POR one) sets BORRSTF and PINRSTF without PORRSTF; the watchdog adds
IWDG1RSTF, a software reset (AIRCR.SYSRESETREQ) SFTRSTF. The flags stay
set until software writes RMVF ("cleared by writing RMVF"), so they add
up across resets that come before the firmware clears them.
RAM: RM0433 says nothing of SRAM content after a BOR; the model keeps it as
after any warm reset (a BOR reset does not power the SRAMs down; their
content is not guaranteed either: the firmware must not trust it).
`cd host-tests/twin && python3 -m unittest discover -s tests`."""

import types
import unittest

from h743twin import system
from h743twin.system import (RSR_BOR, RSR_CPU, RSR_D1, RSR_D2, RSR_IWDG1, RSR_PIN, RSR_POR,
                             RSR_RMVF, RSR_SFT)
from test_svd import bare_machine


class ResetFlags(unittest.TestCase):
    def setUp(self):
        m = bare_machine()
        m.resets, m.pin_edges = [], []
        m.detector = types.SimpleNamespace(beam=3)
        m.core.reset = lambda: None
        self.m = m

    def rsr(self):
        return self.m.rcc.read(0xD0, 4)

    def clear(self):
        self.m.rcc.write(0xD0, 4, RSR_RMVF)

    def test_power_on(self):
        self.assertEqual(self.rsr(), RSR_POR | RSR_PIN | RSR_BOR | RSR_D1 | RSR_D2 | RSR_CPU)

    def test_each_cause_sets_its_flags(self):
        for cause, flags in (("pin", RSR_PIN | RSR_CPU),
                             ("bor", RSR_BOR | RSR_PIN | RSR_CPU),
                             ("watchdog", RSR_IWDG1 | RSR_PIN | RSR_CPU),
                             ("software", RSR_SFT | RSR_PIN | RSR_CPU)):
            self.clear()
            self.m.reset(cause)
            self.assertEqual(self.rsr(), flags, cause)
            self.assertFalse(self.rsr() & RSR_POR, f"{cause}: never PORRSTF")
            self.assertEqual(self.m.rcc.read(0x130, 4), flags, f"{cause}: RCC_C1_RSR")

    def test_flags_add_up_until_rmvf(self):
        self.m.reset("watchdog")
        self.assertEqual(self.rsr(), system.POWER_ON_FLAGS | RSR_IWDG1)
        self.clear()
        self.m.reset("bor")
        self.m.reset("pin")
        self.assertEqual(self.rsr(), RSR_BOR | RSR_PIN | RSR_CPU)

    def test_a_brown_out_keeps_the_ram(self):
        m = self.m
        m.core.uc.mem_write(0x2400_0000, b"kept")
        m.reset("bor")
        self.assertEqual(bytes(m.core.uc.mem_read(0x2400_0000, 4)), b"kept")


class Events(unittest.TestCase):
    def test_reset_and_fault_events_are_beam_counted_kinds(self):
        from h743twin.detector import parse_fault
        for kind in ("pin-reset", "bor", "hardfault", "panic"):
            self.assertEqual(parse_fault(f"{kind}@7"), (kind, 7, []))
            with self.assertRaises(ValueError):
                parse_fault(f"{kind}@7:1")


if __name__ == "__main__":
    unittest.main()
