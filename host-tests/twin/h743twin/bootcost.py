"""What the settings store costs at start-up, on the chip model:
`python3 -m h743twin.bootcost ELF FLASH...`.

For each bank-2 file (the chip model's `--flash` format; a missing file is
an erased bank), boots the ELF and stops when `main` enables the DRDY
interrupt again (`drdy::enable`, its last step before the tasks run: from
then on beams are taken). Prints a Markdown table: the instructions and
model cycles from reset to that point, the instructions of the store's
own code among them (sequential-storage, the store, the record, the
bank-2 driver), what the store read (DMA words of bank 2, double ECC
errors) and the flash operations it made (an erase when it repairs a cut
erase), and the deepest the stack has been by then."""

import argparse
import os
import sys

from .core import Stop
from .flash import Bank2
from .machine import Machine

EXTI9_5 = 23
# The store's functions (paths in the ELF's symbols).
STORE = ("sequential_storage", "settings_store", "flash_bank2", "flash_words", "cvm_core::record", "crc::")


def store_instructions(profile):
    return sum(n for name, n in profile.items() if any(k in name for k in STORE))


def boot(elf, path):
    """(instructions, store instructions, cycles, stack bytes used, bank)
    from reset until DRDY is enabled."""
    bank = Bank2.load(path)
    m = Machine(elf, bank2=bank)
    m.start_profile()
    # embassy's init enables EXTI9_5, `main` disables it until the frame
    # reader is installed, then enables it: on, off, on.
    seen = []

    def ready():
        on = m.core.nvic.enabled[EXTI9_5]
        if not seen or seen[-1] != on:
            seen.append(on)
        return seen[-3:] == [True, False, True]

    # A repair erases a sector: up to 4 s at the datasheet's maximum (x8,
    # flash.ERASE_MAX_US); 10 s is beyond any start-up.
    status = m.run(m.core.cycles + 4_000_000_000, ready)
    if status != "done":
        raise Stop(f"{path}: DRDY was not enabled within 10 s ({status})")
    lo, hi = m.stack
    return (m.core.instructions, store_instructions(m.core.profile), m.core.cycles,
            hi - lo - m.stack_free(), bank)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="h743twin.bootcost")
    ap.add_argument("elf")
    ap.add_argument("flash", nargs="+", help="bank 2 files (missing: erased)")
    args = ap.parse_args(argv)
    print("| bank 2 | instructions to DRDY on | of which the store's | model cycles "
          "| bank-2 words read (DMA) | double ECC errors | flash operations | stack used |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    try:
        for path in args.flash:
            n, own, cycles, stack, bank = boot(args.elf, path)
            print(f"| {os.path.basename(path)} | {n:,} | {own:,} | {cycles:,} | {bank.dma_reads:,} | {bank.ecc_errors} "
                  f"| {bank.ops} | {stack:,} |".replace(",", " "))
    except Stop as e:
        print(f"bootcost: the run stopped: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
