"""CPU faults go through the vector table to HardFault, as on silicon
(ARMv7-M B1.5: a precise BusFault on a data access, an instruction fetch
bus error, an undefined instruction's UsageFault; with their handlers
disabled in SHCSR, the reset state, each escalates to HardFault,
exception 3: the frame is stacked with the faulting instruction's address,
IPSR = 3, PC = the vector at VTOR + 0x0C; HFSR.FORCED, CFSR says which,
BFAR where). RM0433 §4 (ECC): a double error in a flash word read by the
CPU "is reported as a bus error" to the master, after SR.DBECCERR and
ECC_FAR are set. A fault inside the HardFault handler locks the core up
(B1.5.15): nothing runs until a reset.
`cd host-tests/twin && python3 -m unittest discover -s tests`."""

import struct
import unittest

from unicorn.arm_const import UC_ARM_REG_MSP, UC_ARM_REG_R0, UC_ARM_REG_XPSR

from h743twin import flash, system
from h743twin.bus import Bus
from h743twin.core import (CFSR_BFARVALID, CFSR_IMPRECISERR, CFSR_PRECISERR, CFSR_UNDEFINSTR,
                           HARDFAULT, HFSR_FORCED, Core)
from h743twin.flash import BANK2_BASE, Bank2, Bank2Window, FlashInterface

CODE = 0x0800_0040
HANDLER = 0x0800_0060


def machine(code, handler=bytes.fromhex("fee7")):
    """Vector table (SP, reset at CODE, HardFault at HANDLER), the code,
    the handler (`b .` unless given)."""
    bus = Bus()
    rcc = bus.add(0x5802_4400, 0x400, system.Rcc())
    bus.rcc = rcc
    core = Core(bus)
    vectors = struct.pack("<4I", 0x2000_1000, CODE | 1, 0, HANDLER | 1) + bytes(0x30)
    image = vectors + code.ljust(HANDLER - CODE, b"\0") + handler
    core.load([(0x0800_0000, image)])
    core.reset()
    rcc.on_ahb2enr = bus.sram_clocks_changed
    return bus, core


def stacked_pc(core):
    return struct.unpack("<8I", core.uc.mem_read(core.uc.reg_read(UC_ARM_REG_MSP), 32))[6]


# movw r1, #lo; movt r1, #hi; movs r0, #7; ldr r0, [r1]; movs r0, #9; b .
def load_from(addr):
    def mov(op, imm):
        imm4, i, imm3, imm8 = imm >> 12, imm >> 11 & 1, imm >> 8 & 7, imm & 0xFF
        return struct.pack("<HH", op | i << 10 | imm4, imm3 << 12 | 1 << 8 | imm8)
    return mov(0xF240, addr & 0xFFFF) + mov(0xF2C0, addr >> 16) + bytes.fromhex("0720" "0868" "0920" "fee7")


LDR_AT = CODE + 10


class HardFault(unittest.TestCase):
    def test_a_read_of_unmapped_memory_is_a_precise_bus_fault(self):
        bus, core = machine(load_from(0x6000_0000))  # FMC bank 1: nothing there
        core.run_until(2_000)
        self.assertEqual(core.nvic.active, [HARDFAULT])
        self.assertEqual(core.uc.reg_read(UC_ARM_REG_XPSR) & 0x1FF, 3, "IPSR")
        self.assertEqual(core.pc & ~1, HANDLER)
        self.assertEqual(stacked_pc(core), LDR_AT, "the faulting load's address is stacked")
        self.assertEqual(core.uc.reg_read(UC_ARM_REG_R0), 7, "the load did not complete")
        self.assertEqual(core.scb.regs[0xD28], CFSR_PRECISERR | CFSR_BFARVALID)
        self.assertEqual(core.scb.regs[0xD2C], HFSR_FORCED)
        self.assertEqual(core.scb.regs[0xD38], 0x6000_0000, "BFAR")
        self.assertEqual(core.hardfaults, 1)
        self.assertIsNone(bus.error, "not a stop of the run")

    def test_an_undefined_instruction_is_a_usage_fault(self):
        bus, core = machine(bytes.fromhex("0720" "00de" "fee7"))  # movs r0, #7; udf #0
        core.run_until(2_000)
        self.assertEqual(core.nvic.active, [HARDFAULT])
        self.assertEqual(stacked_pc(core), CODE + 2)
        self.assertEqual(core.scb.regs[0xD28], CFSR_UNDEFINSTR)

    def test_a_cpu_read_of_a_word_with_a_double_ecc_error(self):
        bus, core = machine(load_from(BANK2_BASE + 0x40))
        bank = Bank2()
        bank.bad_ecc.add(2)
        f = FlashInterface(bus, core.nvic, bank)
        bus.add(0x5200_2000, 0x1000, f)
        bus.add(BANK2_BASE, flash.BANK2_SIZE, Bank2Window(f))
        core.run_until(2_000)
        self.assertEqual(core.nvic.active, [HARDFAULT])
        self.assertEqual(stacked_pc(core), LDR_AT)
        self.assertEqual(core.uc.reg_read(UC_ARM_REG_R0), 7)
        self.assertEqual(core.scb.regs[0xD38], BANK2_BASE + 0x40)
        self.assertTrue(f.read(0x110, 4) & flash.DBECCERR, "SR2.DBECCERR")
        self.assertEqual(f.read(0x160, 4), 2, "ECC_FA2R: the word's index")

    def test_a_fault_inside_the_handler_locks_the_core_up(self):
        bus, core = machine(load_from(0x6000_0000), handler=load_from(0x6000_0000))
        core.run_until(2_000)
        core.run_until(4_000)
        self.assertEqual((core.hardfaults, core.lockups), (1, 1))
        self.assertEqual(core.sleeping, "stuck", "nothing runs until a reset")

    def test_an_injected_imprecise_fault_is_taken_at_the_next_instruction(self):
        # hardfault@B: the model's way to make the core take a bus fault
        # at a chosen time (an imprecise one: a buffered write answered
        # with an error; the stacked address is where the core was).
        bus, core = machine(bytes.fromhex("fee7"))
        core.run_until(100)
        core.take_fault(core.pc & ~1, CFSR_IMPRECISERR, "injected")
        self.assertEqual(core.nvic.active, [HARDFAULT])
        self.assertEqual(stacked_pc(core), CODE)
        self.assertEqual(core.scb.regs[0xD28], CFSR_IMPRECISERR)
        self.assertEqual(core.scb.regs[0xD38], 0, "imprecise: no BFAR")

    def test_cfsr_and_hfsr_clear_by_writing_one(self):
        bus, core = machine(bytes.fromhex("0720" "00de" "fee7"))
        core.run_until(2_000)
        core.scb.write(0xD28, 4, CFSR_UNDEFINSTR)
        core.scb.write(0xD2C, 4, HFSR_FORCED)
        self.assertEqual((core.scb.read(0xD28, 4), core.scb.read(0xD2C, 4)), (0, 0))


if __name__ == "__main__":
    unittest.main()
