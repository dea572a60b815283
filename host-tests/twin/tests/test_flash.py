"""Bank 2's flash interface against RM0433 §4 (FLASH_KEYR2, CR2, SR2,
CCR2, programming by 256-bit flash words, sector erase), worked out by
hand: `cd host-tests/twin && python3 -m unittest discover -s tests`."""

import os
import tempfile
import unittest

from unicorn.arm_const import UC_ARM_REG_R0

from h743twin import flash
from h743twin.core import Stop
from h743twin.flash import BANK2_BASE, Bank2, Bank2Window, FlashInterface, PowerCut
import test_memory_dma
from test_model import run_until, world

KEYR2, CR2, SR2, CCR2 = 0x104, 0x10C, 0x110, 0x114
LOCK, PG, SER, FW, START = 1, 2, 4, 1 << 6, 1 << 7
BSY, WBNE, QW, EOP = 1, 2, 4, 1 << 16
PGSERR, INCERR, SNECCERR, DBECCERR = 1 << 18, 1 << 21, 1 << 25, 1 << 26
FA2R = 0x160
EOPIE = 1 << 16
X64 = 3 << 4  # CR2.PSIZE: the product's parallelism (the model's default)
PROGRAM = round(flash.program_us(3) * 400)   # cycles at 400 MHz
ERASE = round(flash.erase_us(3) * 400)
SECTOR = 128 << 10


class CpuThroughTheBus(unittest.TestCase):
    """The core's loads and stores at 0x0810_0000 reach the flash model."""

    def machine(self):
        bus, core, _ = test_memory_dma.machine(BANK2_BASE)
        bank = Bank2()
        bank.data[0:4] = bytes.fromhex("efbeadde")
        f = FlashInterface(bus, core.nvic, bank)
        bus.add(0x5200_2000, 0x1000, f)
        bus.add(BANK2_BASE, flash.BANK2_SIZE, Bank2Window(f))
        return core, f, bank

    def test_a_load_reads_the_cells_and_a_store_without_pg_is_refused(self):
        # The program: r0 = [0x0810_0000]; [0x0810_0004] = r0; `b .`
        core, f, bank = self.machine()
        core.run_until(2_000)
        self.assertEqual(core.uc.reg_read(UC_ARM_REG_R0), 0xDEAD_BEEF)
        self.assertEqual(f.read(SR2, 4), PGSERR, "a store with PG = 0")
        self.assertEqual(bank.data[4:8], b"\xff" * 4)

    def test_a_store_with_pg_fills_the_write_buffer(self):
        core, f, bank = self.machine()
        f.write(KEYR2, 4, 0x4567_0123)
        f.write(KEYR2, 4, 0xCDEF_89AB)
        f.write(CR2, 4, X64 | PG)
        core.run_until(2_000)
        self.assertEqual(f.read(SR2, 4), WBNE)
        self.assertEqual(f.buf_word, 0)


class Flash(unittest.TestCase):
    def setUp(self):
        self.bus, self.core = world()
        self.bank = Bank2()
        self.f = FlashInterface(self.bus, self.core.nvic, self.bank)
        self.mem = Bank2Window(self.f)
        self.t = 0

    def unlock(self):
        self.f.write(KEYR2, 4, 0x4567_0123)
        self.f.write(KEYR2, 4, 0xCDEF_89AB)

    def sr(self):
        return self.f.read(SR2, 4)

    def wait(self, cycles):
        self.t += cycles
        run_until(self.bus, self.core, self.t)

    def program_word(self, off, words):
        for i, w in enumerate(words):
            self.mem.write(off + 4 * i, 4, w)

    def test_reset_state_is_locked(self):
        self.assertEqual(self.f.read(CR2, 4), 0x31)
        self.assertEqual(self.sr(), 0)
        self.f.write(CR2, 4, X64 | PG)
        self.assertEqual(self.f.read(CR2, 4), 0x31, "CR2 ignores writes while locked")

    def test_key_sequence_unlocks(self):
        self.unlock()
        self.assertFalse(self.f.read(CR2, 4) & LOCK)
        self.f.write(CR2, 4, LOCK)
        self.assertTrue(self.f.read(CR2, 4) & LOCK)

    def test_wrong_key_locks_until_reset(self):
        self.f.write(KEYR2, 4, 0x4567_0123)
        with self.assertRaises(Stop):
            self.f.write(KEYR2, 4, 0x1234_5678)
        with self.assertRaises(Stop):
            self.unlock()
        self.assertTrue(self.f.read(CR2, 4) & LOCK)

    def test_write_without_pg_is_a_sequence_error(self):
        self.unlock()
        self.mem.write(0, 4, 0)
        self.assertEqual(self.sr(), PGSERR)
        self.assertEqual(self.bank.data[:4], b"\xff" * 4)
        self.f.write(CCR2, 4, PGSERR)
        self.assertEqual(self.sr(), 0)

    def test_eight_words_program_one_flash_word(self):
        self.unlock()
        self.f.write(CR2, 4, X64 | PG | EOPIE)
        self.program_word(0x40, [0x1111_1111 * k for k in range(7)])
        self.assertEqual(self.sr(), WBNE, "seven words: the buffer waits")
        self.mem.write(0x40 + 28, 4, 0x0102_0304)
        self.assertEqual(self.sr(), QW | BSY)
        self.assertFalse(self.core.nvic.line[flash.FLASH_IRQ])
        self.wait(PROGRAM)
        self.assertEqual(self.sr(), EOP)
        self.assertTrue(self.core.nvic.line[flash.FLASH_IRQ], "EOPIE with EOP")
        self.assertEqual(self.mem.read(0x40 + 28, 4), 0x0102_0304)
        self.assertEqual(self.mem.read(0x44, 4), 0x1111_1111)
        self.f.write(SR2, 4, EOP)
        self.assertEqual(self.sr(), EOP, "SR2 is read-only")
        self.f.write(CCR2, 4, EOP)
        self.assertEqual(self.sr(), 0)
        self.assertFalse(self.core.nvic.line[flash.FLASH_IRQ])

    def test_another_word_before_the_buffer_is_full_is_an_inconsistency(self):
        self.unlock()
        self.f.write(CR2, 4, X64 | PG)
        self.mem.write(0x00, 4, 0)
        self.mem.write(0x20, 4, 0)
        self.assertEqual(self.sr(), INCERR, "the partial word is dropped, WBNE clear")
        self.wait(10 * PROGRAM)
        self.assertEqual(self.bank.data[:0x40], b"\xff" * 0x40)
        self.assertEqual(self.bank.ops, 0)

    def test_force_write_programs_a_partial_word(self):
        self.unlock()
        self.f.write(CR2, 4, X64 | PG)
        self.mem.write(0x08, 4, 0x0000_0000)
        self.f.write(CR2, 4, X64 | PG | FW)
        self.assertEqual(self.sr(), QW | BSY)
        self.wait(PROGRAM)
        self.assertEqual(bytes(self.bank.data[:0x20]), b"\xff" * 8 + b"\0" * 4 + b"\xff" * 20)

    def test_programming_twice_without_erase_fails_on_read(self):
        self.unlock()
        self.f.write(CR2, 4, X64 | PG)
        self.program_word(0, [0xFFFF_0000] * 8)
        self.wait(PROGRAM)
        self.assertEqual(self.mem.read(0, 4), 0xFFFF_0000)
        self.program_word(0, [0x0000_FFFF] * 8)
        self.wait(PROGRAM)
        self.assertEqual(self.bank.double_programs, 1)
        self.assertEqual(self.bank.data[:4], b"\0\0\0\0", "cells only go from 1 to 0")
        with self.assertRaises(Stop):
            self.mem.read(0, 4)
        self.assertTrue(self.sr() & DBECCERR)
        self.assertEqual(self.mem.read(0x20, 4), 0xFFFF_FFFF, "the next word is unharmed")

    def test_sector_erase_clears_the_sector_and_its_ecc(self):
        self.unlock()
        self.f.write(CR2, 4, X64 | PG)
        self.program_word(SECTOR + 0x100, [0] * 8)
        self.wait(PROGRAM)
        self.program_word(2 * SECTOR, [0] * 8)
        self.wait(PROGRAM)
        self.program_word(SECTOR + 0x100, [0] * 8)
        self.wait(PROGRAM)
        self.f.write(CR2, 4, X64 | SER | (1 << 8))
        self.f.write(CR2, 4, X64 | SER | (1 << 8) | START)
        self.assertEqual(self.sr() & (QW | BSY), QW | BSY)
        self.assertFalse(self.f.read(CR2, 4) & START, "START reads back as 0 once taken")
        self.mem.write(0, 4, 0)
        self.assertTrue(self.sr() & PGSERR, "no programming while an erase runs")
        self.wait(ERASE)
        self.assertEqual(self.sr() & (QW | BSY | EOP), EOP)
        self.assertEqual(self.mem.read(SECTOR + 0x100, 4), 0xFFFF_FFFF)
        self.assertEqual(self.mem.read(2 * SECTOR, 4), 0, "sector 2 untouched")
        self.f.write(CR2, 4, X64 | PG)
        self.program_word(SECTOR + 0x100, [0x1234_5678] * 8)
        self.wait(PROGRAM)
        self.assertEqual(self.mem.read(SECTOR + 0x11C, 4), 0x1234_5678)

    def test_power_cut_at_the_nth_operation_leaves_it_half_done(self):
        self.unlock()
        self.bank.cut_at = 2
        self.f.write(CR2, 4, X64 | PG)
        self.program_word(0, [0] * 8)
        self.wait(PROGRAM)
        with self.assertRaises(PowerCut):
            self.program_word(0x20, [0] * 8)
        self.assertEqual(bytes(self.bank.data[0x20:0x40]), b"\0" * 16 + b"\xff" * 16)
        self.assertIn(1, self.bank.bad_ecc, "a torn flash word reads as an ECC error")
        self.assertEqual(self.bank.ops, 2)

    def test_power_cut_during_an_erase(self):
        self.bank.data[:] = b"\0" * len(self.bank.data)
        self.unlock()
        self.bank.cut_at = 1
        self.f.write(CR2, 4, X64 | SER | (3 << 8))
        with self.assertRaises(PowerCut):
            self.f.write(CR2, 4, X64 | SER | (3 << 8) | START)
        lo = 3 * SECTOR
        self.assertEqual(self.bank.data[lo:lo + SECTOR // 2], b"\xff" * (SECTOR // 2))
        self.assertEqual(self.bank.data[lo + SECTOR // 2:lo + SECTOR], b"\0" * (SECTOR // 2))

    def test_bank_survives_a_new_interface_and_a_file(self):
        self.unlock()
        self.f.write(CR2, 4, X64 | PG)
        self.program_word(0x60, [0xCAFE_F00D] * 8)
        self.wait(PROGRAM)
        again = FlashInterface(self.bus, self.core.nvic, self.bank)  # after a reset
        self.assertEqual(again.read(CR2, 4) & LOCK, LOCK)
        self.assertEqual(again.mem_read(0x60, 4), 0xCAFE_F00D)
        fd, path = tempfile.mkstemp()
        os.close(fd)
        try:
            self.bank.save(path)
            loaded = Bank2.load(path)
        finally:
            os.unlink(path)
        self.assertEqual(loaded.data, self.bank.data)
        self.assertEqual(loaded.programmed, {3})
        self.assertEqual(Bank2.load(path).data, b"\xff" * (1 << 20), "a missing file: erased")

    def test_window_is_bank_2(self):
        self.assertEqual(BANK2_BASE, 0x0810_0000)
        self.assertEqual(flash.BANK2_SIZE, 8 * SECTOR)


class Parallelism(unittest.TestCase):
    """DS12110, table "Flash memory programming": the time of a 128 KB
    sector erase (t_ERASE128KB) and of a 256-bit flash word program
    (t_PROG) depends on the program/erase parallelism, FLASH_CR2.PSIZE
    ("program/erase parallelism x8 / x16 / x32 / x64"), and software must
    budget the maximum column: ST's answer in the forum thread "STM32H743
    Flash EraseSector Reset Problem" ("a software should take into
    consideration the maximum value we put in datasheet and not typical"),
    x32 erasing a sector in 1.1 s typical, 2.2 s at most. The maxima used:
    erase 4 / 3.6 / 2.2 / 2 s, program 580 / 360 / 260 / 200 µs.
    RM0433 §4 (FLASH_CR2.PSIZE2): PSIZE selects how many bits the
    interface programs or erases in parallel; nothing else changes."""

    def setUp(self):
        self.bus, self.core = world()
        self.bank = Bank2()

    def flash(self, intended):
        f = FlashInterface(self.bus, self.core.nvic, self.bank, intended_psize=intended)
        f.write(KEYR2, 4, 0x4567_0123)
        f.write(KEYR2, 4, 0xCDEF_89AB)
        return f

    def busy_for(self, f, start):
        """Cycles from `start()` until SR2.QW falls."""
        t0 = self.core.cycles
        start()
        self.assertTrue(f.read(SR2, 4) & QW)
        end = self.bus.events[-1][0]
        run_until(self.bus, self.core, end - 1)
        self.assertTrue(f.read(SR2, 4) & QW, "still running a cycle before its end")
        run_until(self.bus, self.core, end)
        self.assertFalse(f.read(SR2, 4) & QW)
        return end - t0

    def test_erase_and_program_take_the_datasheet_maximum_per_psize(self):
        erase_s = {0: 4.0, 1: 3.6, 2: 2.2, 3: 2.0}
        program_us = {0: 580, 1: 360, 2: 260, 3: 200}
        for psize in range(4):
            f = self.flash(None)
            p = psize << 4
            took = self.busy_for(f, lambda: (f.write(CR2, 4, p | SER | (2 << 8)),
                                             f.write(CR2, 4, p | SER | (2 << 8) | START)))
            self.assertEqual(took, round(erase_s[psize] * 400_000_000), flash.PSIZE_NAMES[psize])
            f.write(CR2, 4, p | PG)
            word = 0x100 + psize * 0x20
            took = self.busy_for(f, lambda: [f.mem_write(word + 4 * i, 4, 0) for i in range(8)])
            self.assertEqual(took, program_us[psize] * 400, flash.PSIZE_NAMES[psize])

    def test_an_erase_with_another_parallelism_than_intended_stops_the_run(self):
        f = self.flash(flash.PSIZE_X64)
        f.write(CR2, 4, SER | (1 << 8))  # PSIZE left at 00 (x8): the CR2 written whole
        with self.assertRaises(flash.ParallelismError) as e:
            f.write(CR2, 4, SER | (1 << 8) | START)
        self.assertIn("PSIZE = 00 (x8)", str(e.exception))
        self.assertIn("4000 ms instead of 2000 ms", str(e.exception))
        self.assertEqual(self.bank.ops, 0, "the erase did not start")

    def test_a_program_with_another_parallelism_than_intended_stops_the_run(self):
        f = self.flash(flash.PSIZE_X64)
        f.write(CR2, 4, PG | (2 << 4))  # x32
        for i in range(7):
            f.mem_write(4 * i, 4, 0)
        with self.assertRaises(flash.ParallelismError):
            f.mem_write(28, 4, 0)

    def test_the_default_intended_parallelism_is_x64(self):
        f = FlashInterface(self.bus, self.core.nvic, self.bank)
        self.assertEqual(f.intended_psize, 3)
        self.assertEqual(flash.CR_RESET >> 4 & 3, 3, "PSIZE's reset value is x64 too")


class BrokenWords(unittest.TestCase):
    """RM0433 §4 (FLASH error correction code): each 256-bit flash word
    carries an ECC that corrects a single error and detects a double one.
    A single error is corrected on the fly: the read completes, SNECCERR
    is set and FLASH_ECC_FAxR records the word (an interrupt with
    SNECCERRIE); a double error sets DBECCERR, records the word, and the
    read gets a bus error. The failing-address field "is reset when the
    flag error ... is reset" through CCR (CLR_SNECCERR/CLR_DBECCERR).
    A word programmed twice or cut mid-program has cells and ECC that
    disagree by any number of bits: it can read as a double error, as a
    single error "corrected" into wrong data (the correction flips a bit
    that was right), or pass unnoticed. `--ecc` picks which."""

    def flash(self, ecc):
        bus, core = world()
        bank = Bank2()
        bank.data[0x40:0x44] = bytes.fromhex("78563412")
        bank.programmed.add(2)
        bank.bad_ecc.add(2)
        return FlashInterface(bus, core.nvic, bank, ecc=ecc), bank

    def test_double_is_a_bus_error(self):
        f, bank = self.flash("double")
        with self.assertRaises(Stop):
            f.mem_read(0x40, 4)
        self.assertEqual((f.read(SR2, 4) & (SNECCERR | DBECCERR), f.read(FA2R, 4)), (DBECCERR, 2))

    def test_single_corrects_into_wrong_data(self):
        f, bank = self.flash("single")
        self.assertEqual(f.mem_read(0x40, 4), 0x1234_5679, "one bit flipped, no bus error")
        self.assertEqual(f.mem_read(0x44, 4), 0xFFFF_FFFF, "the rest of the word as its cells")
        self.assertEqual((f.read(SR2, 4) & (SNECCERR | DBECCERR), f.read(FA2R, 4)), (SNECCERR, 2))
        self.assertEqual(f.mem_read(0x40, 4, dma=True), 0x1234_5679, "DMA reads the same")

    def test_none_reads_the_cells_without_a_flag(self):
        f, bank = self.flash("none")
        self.assertEqual(f.mem_read(0x40, 4), 0x1234_5678)
        self.assertEqual((f.read(SR2, 4), f.read(FA2R, 4)), (0, 0))

    def test_clearing_the_flag_clears_the_failing_address(self):
        for ecc, flag in (("single", SNECCERR), ("double", DBECCERR)):
            f, bank = self.flash(ecc)
            try:
                f.mem_read(0x40, 4)
            except Stop:
                pass
            self.assertEqual(f.read(FA2R, 4), 2, "read it before clearing the flag")
            f.write(CCR2, 4, flag)
            self.assertEqual((f.read(SR2, 4), f.read(FA2R, 4)), (0, 0), ecc)

    def test_the_default_is_a_double_error(self):
        bus, core = world()
        self.assertEqual(FlashInterface(bus, core.nvic, Bank2()).ecc, "double")


if __name__ == "__main__":
    unittest.main()
