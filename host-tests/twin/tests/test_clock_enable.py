"""The clock-enable delay (RM0433 §8, RCC: peripheral clock enable).

RM0433 describes each peripheral clock enable as synchronised: once the
enable bit is set in an RCC_xxxENR register, the peripheral's clock starts
two cycles of its bus clock later ("the enable bit has a synchronization
mechanism ... 2 peripheral clock cycles delay before the clock be
active"), and until then the peripheral does not take register accesses;
software must wait before touching it. ST's HAL (`__HAL_RCC_xxx_CLK_ENABLE`)
and embassy-stm32 (`rcc/mod.rs`, `enable_and_reset`) read the enable
register back (and embassy adds a DSB) for that reason: the read cannot
complete before the write has landed in RCC.

The model: an access to a clock-gated peripheral fewer than
2 x (core clock / bus clock) instructions after the RCC write that set its
enable bit is lost (a write changes nothing, a read answers 0), recorded
in `bus.clock_drops` (the counters' `clock_enable_drops`), and stops the
run unless `bus.clock_drops_stop` is off (h743twin --clock-drops count).
A read of RCC after the enable ends the delay. At the firmware's clocks
(400 MHz core, APB1 at 100 MHz) that is 8 instructions for TIM12-14 and
USART3.
`cd host-tests/twin && python3 -m unittest discover -s tests`."""

import struct
import unittest

from h743twin import system
from h743twin.bus import Bus
from h743twin.core import Core, Stop
from test_model import pll_400

TIM14 = 0x4000_2000


def program(middle):
    """Vector table, then (llvm-mc, thumbv7em):
        movw r0, #0x44E8; movt r0, #0x5802   @ RCC_APB1LENR
        movw r1, #0x2000; movt r1, #0x4000   @ TIM14
        ldr r2, [r0]; orr r2, r2, #0x100; str r2, [r0]   @ TIM14EN
        <middle>
        movs r3, #199; str r3, [r1, #0x28]   @ TIM14_PSC = 199
        b ."""
    code = bytes.fromhex("44f2e840" "c5f60200" "42f20001" "c4f20001"
                         "0268" "42f48072" "0260") + middle + bytes.fromhex("c723" "8b62" "fee7")
    return struct.pack("<2I", 0x2000_1000, 0x0800_0009) + code


READ_BACK = bytes.fromhex("0268")          # ldr r2, [r0]
DSB = bytes.fromhex("bff34f8f")            # dsb sy
NOP = bytes.fromhex("00bf")


def machine(middle, stop=False, clocks=pll_400):
    bus = Bus()
    rcc = bus.add(0x5802_4400, 0x400, system.Rcc())
    bus.rcc = rcc
    clocks(rcc)
    core = Core(bus)
    tim = bus.add(TIM14, 0x400, system.Timer(bus, core.nvic, 45, rcc.apb1_timer_hz, bits=16, channels=1),
                  clock=(0xE8, 8, "TIM14"))
    bus.clock_drops_stop = stop
    core.load([(0x0800_0000, program(middle))])
    core.reset()
    rcc.on_ahb2enr = bus.sram_clocks_changed
    return bus, core, tim


class ClockEnableDelay(unittest.TestCase):
    def test_a_write_right_after_the_enable_is_lost(self):
        # PSC is written two instructions after TIM14EN: six short of the
        # two APB1 cycles (8 instructions at 400 / 100 MHz).
        bus, core, tim = machine(b"")
        core.run_until(2_000)
        self.assertEqual(tim.psc, 0, "the prescaler write is lost")
        [drop] = bus.clock_drops
        self.assertEqual((drop["peripheral"], drop["register"], drop["access"], drop["value"]),
                         ("TIM14", "PSC", "write", 199))
        self.assertEqual(drop["cycles_after_enable"], 2)
        self.assertEqual(drop["pc"], 0x0800_0022, "the store's own address")

    def test_the_read_back_of_the_enable_register_makes_it_effective(self):
        bus, core, tim = machine(READ_BACK)
        core.run_until(2_000)
        self.assertEqual(tim.psc, 199)
        self.assertEqual(bus.clock_drops, [])

    def test_a_dsb_alone_does_not_wait_for_the_clock(self):
        # The DSB waits for the RCC write to land; the two bus cycles run
        # from there (the model applies the write at once).
        bus, core, tim = machine(DSB)
        core.run_until(2_000)
        self.assertEqual(tim.psc, 0)
        self.assertEqual(len(bus.clock_drops), 1)

    def test_two_bus_cycles_later_the_write_lands(self):
        # 6 NOPs + movs: the store is the 8th instruction after the enable.
        bus, core, tim = machine(NOP * 6)
        core.run_until(2_000)
        self.assertEqual(tim.psc, 199)
        bus, core, tim = machine(NOP * 5)
        core.run_until(2_000)
        self.assertEqual(tim.psc, 0, "the 7th instruction is still too early")

    def test_the_delay_follows_the_bus_clock(self):
        # At reset every clock is HSI (64 MHz, no dividers): two APB1
        # cycles are two instructions, so the store (2nd after) lands.
        bus, core, tim = machine(b"", clocks=lambda rcc: None)
        core.run_until(2_000)
        self.assertEqual(tim.psc, 199)

    def test_a_drop_stops_the_run_by_default(self):
        bus, core, tim = machine(b"", stop=True)
        core.run_until(2_000)
        self.assertIsInstance(bus.error, Stop, "the run loop raises it")
        self.assertIn("TIM14_PSC", str(bus.error))
        self.assertIn("2 cycles after its RCC enable", str(bus.error))

    def test_keep_counts_the_access_and_lets_it_through(self):
        # `--clock-drops keep`: an earlier firmware's other faults can be
        # seen past this one (tests/twin_failsafe.rs's FAILSAFE_MODEL_ARGS).
        bus, core, tim = machine(b"")
        bus.clock_drops_keep = True
        core.run_until(2_000)
        self.assertEqual(tim.psc, 199)
        self.assertEqual(len(bus.clock_drops), 1)


if __name__ == "__main__":
    unittest.main()
