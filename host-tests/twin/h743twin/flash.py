"""The embedded flash interface (RM0433 §4) as a firmware uses it to keep
settings in bank 2: unlocking through FLASH_KEYR2, sector erase
(CR2.SER/SNB/START), programming by 256-bit flash words through the
bank's write buffer (CR2.PG, FW), the status flags (SR2.BSY, WBNE, QW,
EOP and the error flags) and their clearing through FLASH_CCR2, the
failing word of a double ECC error (FLASH_ECC_FA2R), and the flash
interrupt (EOPIE and the error interrupt enables).

Bank 2 (0x0810_0000, eight sectors of 128 KiB) is a byte array that
outlives resets (`Bank2`), so a reboot sees what was written, and that can
be loaded from and saved to a file, so a second run of the same image
does too. Bank 1 holds the code and stays plain memory; its registers
(FLASH_KEYR1, CR1, ...) are not modelled and stop the run.

What silicon does and the model follows:
* a wrong key sequence locks CR2 until the next reset and raises a bus
  error (the run stops, as for every bus fault);
* a write to bank 2 while CR2.PG = 0, or while an erase is under way, is
  a programming sequence error (PGSERR) and changes nothing;
* a write to another flash word while the write buffer holds part of one
  is an inconsistency error (INCERR): the partial word is dropped;
* a full write buffer (eight 32-bit words), or FW with a partial one,
  queues the word (QW, then BSY while it programs); bits only go from 1 to
  0; EOP when it is done;
* a flash word carries ECC over its 256 bits, so it can be programmed once
  per erase: programming it again leaves cells and ECC that do not agree,
  and reading that word is a double ECC error: SR2.DBECCERR is set,
  FLASH_ECC_FA2R holds the word's index in the bank, and the read is
  answered with a bus error. The model records such words. A CPU read of
  one stops the run (a bus fault); a DMA read ends in the stream's
  transfer error (`EccError`, which dma.py turns into TEIF), and the run
  goes on: that is how a firmware can read a flash that a power cut may
  have left with such a word.

Operation times are the datasheet's maximum for the parallelism that
FLASH_CR2.PSIZE selects when the operation starts (DS12110, table "Flash
memory programming": a 128 KB sector erase and a 256-bit flash word
program, per x8/x16/x32/x64; `erase_us`, `program_us`): a firmware must
budget the maximum, not the typical (ST's answer in the forum thread
"STM32H743 Flash EraseSector Reset Problem": x32 erases a sector in 1.1 s
typical, 2.2 s at most). An erase or program that starts with another
PSIZE than the product means (`FlashInterface.intended_psize`, the
model's `--psize`, x64 by default) stops the run: a slower parallelism
than intended is a firmware bug that would only show on a bench as a
watchdog reset during a save.

Power cuts: `Bank2.cut_at = N` ends the run at the N-th flash operation
(erase or flash-word program, counted from 1 across resets) with
`PowerCut`. The operation is left half done, the worst a cut can leave:
an erase has erased the first half of its sector, a program has written
the first half of its flash word (whose ECC is then wrong, as above).
"""

from .core import CLOCK_HZ, BusFault, Stop

BANK2_BASE = 0x0810_0000
BANK2_SIZE = 1 << 20
SECTOR = 128 << 10
WORD = 32  # bytes in a flash word (256 bits)
FLASH_IRQ = 4

KEY1, KEY2 = 0x4567_0123, 0xCDEF_89AB
# FLASH_CR2
LOCK, PG, SER, BER, FW, START = 1 << 0, 1 << 1, 1 << 2, 1 << 3, 1 << 6, 1 << 7
CR_RESET = 0x0000_0031  # LOCK, PSIZE = 64 bits
CR_IRQ_ENABLES = 0x0FFF_0000 & ~(1 << 20)  # EOPIE (16) .. CRCENDIE (27); bit 20 reserved
# FLASH_SR2
BSY, WBNE, QW = 1 << 0, 1 << 1, 1 << 2
EOP, WRPERR, PGSERR, STRBERR, INCERR, OPERR = 1 << 16, 1 << 17, 1 << 18, 1 << 19, 1 << 21, 1 << 22
RDPERR, RDSERR, SNECCERR, DBECCERR, CRCEND = 1 << 23, 1 << 24, 1 << 25, 1 << 26, 1 << 27
CLEARABLE = 0x0FEF_0000  # CCR2: CLR_EOP .. CLR_CRCEND, bit 20 reserved

# DS12110 "Flash memory programming", maximum values, indexed by PSIZE
# (00 x8, 01 x16, 10 x32, 11 x64): t_ERASE128KB (one 128 KB sector) and
# t_PROG (one 256-bit flash word), in µs. The x32 erase (2.2 s max, 1.1 s
# typical) is also ST's figure in the forum thread quoted above.
ERASE_MAX_US = (4_000_000.0, 3_600_000.0, 2_200_000.0, 2_000_000.0)
PROGRAM_MAX_US = (580.0, 360.0, 260.0, 200.0)
PSIZE_NAMES = ("x8", "x16", "x32", "x64")
# The product's parallelism: the fastest, which the NUCLEO's 3.3 V supply
# allows (DS12110 programs at every parallelism from 1.62 V to 3.6 V; the
# H743 has no external VPP requirement for x64, unlike the F4/F7).
PSIZE_X64 = 3


def erase_us(psize, sectors=1):
    """A bank erase (BER) counts as its eight sectors."""
    return ERASE_MAX_US[psize] * sectors


def program_us(psize):
    return PROGRAM_MAX_US[psize]


# What a broken flash word (programmed twice, or cut while programming)
# reads back as: a double error (DBECCERR, bus error: the default), a
# single error that the ECC "corrects" into wrong data (SNECCERR), or
# cells that pass the ECC unnoticed (nothing). h743twin --ecc.
ECC_MODES = ("double", "single", "none")


class ParallelismError(Stop):
    """An erase or program started with a PSIZE the product does not mean."""


class PowerCut(Stop):
    """The run ends here: power was cut during a flash operation."""


class BusError(Exception):
    """A bus error answered to a DMA master (dma.py: the stream's transfer
    error)."""


class EccError(BusError):
    """A DMA read of a flash word with a double ECC error: the bus error
    the flash answers the DMA master with."""


class Bank2:
    """The cells of bank 2: they survive resets, and runs through a file."""

    def __init__(self):
        self.data = bytearray(b"\xff" * BANK2_SIZE)
        self.programmed = set()  # flash words programmed since their erase
        self.bad_ecc = set()     # flash words whose ECC does not match their cells
        self.ops = 0             # erases and programs, across resets
        self.cut_at = None
        self.double_programs = 0
        self.ecc_errors = 0      # reads (CPU or DMA) of words whose ECC is wrong
        self.dma_reads = 0       # DMA reads (items) of bank 2

    @staticmethod
    def load(path):
        """A bank from a file saved by `save` (a missing file: erased)."""
        b = Bank2()
        try:
            with open(path, "rb") as f:
                raw = f.read()
        except FileNotFoundError:
            return b
        if len(raw) != BANK2_SIZE + BANK2_SIZE // WORD:
            raise Stop(f"{path}: not a bank 2 image ({len(raw)} bytes)")
        b.data[:] = raw[:BANK2_SIZE]
        state = raw[BANK2_SIZE:]
        for w, s in enumerate(state):
            if s & 1:
                b.programmed.add(w)
            if s & 2:
                b.bad_ecc.add(w)
        return b

    def save(self, path):
        """The cells, then one byte per flash word: bit 0 programmed since
        its erase, bit 1 ECC wrong (both invisible in the cells' values)."""
        state = bytearray(BANK2_SIZE // WORD)
        for w in self.programmed:
            state[w] |= 1
        for w in self.bad_ecc:
            state[w] |= 2
        with open(path, "wb") as f:
            f.write(bytes(self.data) + bytes(state))

    def operation(self):
        """One more erase or program starts; True if the power goes now."""
        self.ops += 1
        return self.cut_at is not None and self.ops >= self.cut_at

    def erase(self, sector, upto=SECTOR):
        lo = sector * SECTOR
        self.data[lo:lo + upto] = b"\xff" * upto
        for w in range(lo // WORD, (lo + upto) // WORD):
            self.programmed.discard(w)
            self.bad_ecc.discard(w)

    def program(self, word, buf, upto=WORD):
        """Cells only go from 1 to 0; a second program breaks the ECC."""
        lo = word * WORD
        for i in range(upto):
            self.data[lo + i] &= buf[i]
        if word in self.programmed:
            self.double_programs += 1
            self.bad_ecc.add(word)
        elif upto < WORD:
            self.bad_ecc.add(word)
        self.programmed.add(word)


class FlashInterface:
    """FLASH registers at 0x5200_2000: ACR, and bank 2's KEYR2, CR2, SR2,
    CCR2; and bank 2's memory window (`memory()`), which writes go through."""

    def __init__(self, bus, nvic, bank, intended_psize=PSIZE_X64, ecc="double"):
        self.bus = bus
        # What a broken word (programmed twice, cut) reads as (ECC_MODES).
        self.ecc = ecc
        # None: any parallelism is accepted (the run only times it).
        self.intended_psize = intended_psize
        self.nvic = nvic
        self.bank = bank
        self.acr = 0x0000_0037  # 7 wait states, WRHIGHFREQ 3
        self.cr = CR_RESET
        self.flags = 0          # EOP and the error flags
        self.key_step = 0
        self.key_locked = False  # a wrong key sequence: locked until reset
        self.buf_word = None    # flash word the write buffer holds part of
        self.buf = bytearray(b"\xff" * WORD)
        self.buf_filled = set()
        self.queued = False     # QW: a word or an erase is queued or running
        self.busy = False       # BSY: it is running
        self.erasing = False
        self.ops = 0
        self.far = 0            # FLASH_ECC_FA2R: the last double-ECC word's index

    # --- registers
    def sr(self):
        v = self.flags
        if self.busy:
            v |= BSY
        if self.queued:
            v |= QW
        if self.buf_word is not None:
            v |= WBNE
        return v

    def read(self, off, size):
        if off == 0x00:
            return self.acr
        if off == 0x10C:
            return self.cr
        if off == 0x110:
            return self.sr()
        if off in (0x104, 0x114):
            return 0  # write-only
        if off == 0x160:
            return self.far
        raise KeyError

    def write(self, off, size, value):
        if off == 0x00:
            self.acr = value & 0x3F
        elif off == 0x104:
            self._key(value)
        elif off == 0x10C:
            self._cr(value)
        elif off == 0x110:
            pass  # SR2 is read-only: flags clear through CCR2
        elif off == 0x114:
            self.flags &= ~(value & CLEARABLE)
            if value & (SNECCERR | DBECCERR):
                # RM0433 FLASH_ECC_FA2R: the failing address is reset when
                # its flag is cleared through CCR2.
                self.far = 0
            self.update()
        else:
            raise KeyError

    def _key(self, value):
        if self.key_locked or not self.cr & LOCK:
            self._bad_key()
        if self.key_step == 0 and value == KEY1:
            self.key_step = 1
        elif self.key_step == 1 and value == KEY2:
            self.key_step = 0
            self.cr &= ~LOCK
        else:
            self._bad_key()

    def _bad_key(self):
        self.key_locked = True
        self.cr |= LOCK
        raise Stop("FLASH_KEYR2: wrong key sequence (CR2 locked until reset, bus error)")

    def _cr(self, value):
        if self.cr & LOCK:
            return  # CR2 ignores writes while locked
        start = value & START and not self.cr & START
        self.cr = value & ~START
        if value & LOCK:
            self.cr |= LOCK
        if start and not self.queued:
            if self.cr & SER or self.cr & BER:
                self._erase()
        elif start:
            self.flags |= PGSERR
        if value & FW and self.buf_word is not None:
            self.cr &= ~FW
            self._queue_word()
        self.update()

    # --- the bank 2 window
    def mem_read(self, off, size, dma=False):
        word = off // WORD
        if dma:
            self.bank.dma_reads += 1
        if word in self.bank.bad_ecc and self.ecc != "double":
            return self._mis_read(off, size, word)
        if word in self.bank.bad_ecc:
            self.flags |= DBECCERR
            self.far = word & 0x7FFF
            self.bank.ecc_errors += 1
            self.update()
            where = f"flash word {BANK2_BASE + word * WORD:#010x}"
            if dma:
                raise EccError(f"double ECC error reading {where}")
            raise BusFault(f"bus fault: double ECC error reading {where} "
                           "(programmed twice, or cut while programming, since its erase)",
                           BANK2_BASE + off)
        return int.from_bytes(self.bank.data[off:off + size], "little")

    def _mis_read(self, off, size, word):
        """A broken word whose cells and ECC happen to differ by one bit
        ("single": the ECC "corrects" it, wrongly: SNECCERR, ECC_FA2R, the
        read completes with one bit flipped, bit 0 of the word's first
        byte) or not at all ("none": the cells are read as they are)."""
        value = int.from_bytes(self.bank.data[off:off + size], "little")
        self.bank.ecc_errors += 1
        if self.ecc == "single":
            self.flags |= SNECCERR
            self.far = word & 0x7FFF
            self.update()
            if off % WORD == 0:
                value ^= 1
        return value

    def mem_write(self, off, size, value):
        word = off // WORD
        if not self.cr & PG or self.erasing or self.cr & LOCK:
            self.flags |= PGSERR
            self.update()
            return
        if self.buf_word is not None and self.buf_word != word:
            self.flags |= INCERR
            self._drop_buffer()
            self.update()
            return
        if self.buf_word is None:
            if self.queued:
                raise Stop("FLASH bank 2 written while QW2 is set: the chip's second buffer is not modelled")
            self.buf_word = word
        for i in range(size):
            self.buf[off % WORD + i] = value >> (8 * i) & 0xFF
            self.buf_filled.add(off % WORD + i)
        if len(self.buf_filled) == WORD:
            self._queue_word()
        self.update()

    def _drop_buffer(self):
        self.buf_word = None
        self.buf = bytearray(b"\xff" * WORD)
        self.buf_filled = set()

    def psize(self):
        return self.cr >> 4 & 3

    def _check_psize(self, what):
        psize, want = self.psize(), self.intended_psize
        if want is not None and psize != want:
            raise ParallelismError(
                f"FLASH_CR2.PSIZE = {psize:02b} ({PSIZE_NAMES[psize]}) when {'an' if what == 'erase' else 'a'} {what} starts, "
                f"the product means {want:02b} ({PSIZE_NAMES[want]}): at the datasheet's maximum "
                f"this {what} takes {self._duration(what, psize) / 1e3:g} ms instead of "
                f"{self._duration(what, want) / 1e3:g} ms (h743twin --psize to change what is meant)")

    def _duration(self, what, psize):
        if what == "program":
            return program_us(psize)
        return erase_us(psize, 8 if self.cr & BER else 1)

    def _queue_word(self):
        self._check_psize("program")
        word, buf = self.buf_word, bytes(self.buf)
        self._drop_buffer()
        self._operation(self._duration("program", self.psize()),
                        lambda half: self.bank.program(word, buf, WORD // 2 if half else WORD))

    def _erase(self):
        self._check_psize("erase")
        sectors = range(8) if self.cr & BER else [self.cr >> 8 & 7]
        self.erasing = True

        def done(half):
            for s in sectors:
                self.bank.erase(s, SECTOR // 2 if half else SECTOR)
            self.erasing = False
        self._operation(self._duration("erase", self.psize()), done)

    def _operation(self, us, apply):
        """`apply(half)`: the operation's effect, whole or (power cut) half."""
        self.ops += 1
        if self.bank.operation():
            apply(True)
            raise PowerCut(f"power cut at flash operation {self.bank.ops}")
        self.queued = self.busy = True
        end = self.bus.core.cycles + round(us * CLOCK_HZ / 1e6)

        def finish():
            apply(False)
            self.queued = self.busy = False
            self.flags |= EOP
            self.update()
        self.bus.at(end, finish)

    def update(self):
        irq = self.sr() & self.cr & CR_IRQ_ENABLES
        self.nvic.set_line(FLASH_IRQ, bool(irq))


class Bank2Window:
    """Bank 2's addresses on the bus, handed to the flash interface."""

    def __init__(self, flash):
        self.flash = flash

    def read(self, off, size):
        return self.flash.mem_read(off, size)

    def dma_read(self, off, size):
        return self.flash.mem_read(off, size, dma=True)

    def write(self, off, size, value):
        self.flash.mem_write(off, size, value)
