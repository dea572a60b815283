"""Checks the memory layout of a built H743 ELF: `python3 -m h743twin.layout ELF`.

What only silicon would otherwise show: the vector table at the start of
flash, .bss and .data as single ranges inside AXI SRAM (the reset handler
zeroes and copies them with loops that stop only at their end symbols), the
stack in DTCM, the row buffers in AXI SRAM and SRAM1-3, every buffer a
DMA stream touches in memory DMA1 reaches, and the line encoder's tables
in DTCM with their load image in flash. Prints one line per check; exits 1
with the failed checks named.
"""

import sys

from elftools.elf.elffile import ELFFile

FLASH = (0x0800_0000, 0x0820_0000)
AXI = (0x2400_0000, 0x2408_0000)
SRAM123 = (0x3000_0000, 0x3004_8000)
DTCM = (0x2000_0000, 0x2002_0000)
DMA_REACHABLE = (AXI, SRAM123)


def inside(lo, hi, region):
    return region[0] <= lo <= hi <= region[1]


def check(path):
    with open(path, "rb") as f:
        elf = ELFFile(f)
        syms = {}
        objects = []
        for s in elf.get_section_by_name(".symtab").iter_symbols():
            syms[s.name] = s["st_value"]
            if s["st_info"]["type"] == "STT_OBJECT":
                objects.append((s.name, s["st_value"], s["st_size"]))
        sections = {s.name: (s["sh_addr"], s["sh_size"]) for s in elf.iter_sections()}

    def obj(part):
        found = [(n, a, z) for n, a, z in objects if part in n]
        if len(found) != 1:
            raise KeyError(f"expected one static named like {part!r}, found {len(found)}")
        return found[0]

    results = []

    def expect(name, ok, detail):
        results.append((name, bool(ok), detail))

    vt = sections.get(".vector_table", (None, 0))
    expect("vector table at the start of flash", vt[0] == FLASH[0], f"at {vt[0]:#x}" if vt[0] is not None else "missing")
    sbss, ebss = syms["__sbss"], syms["__ebss"]
    expect(".bss one range in AXI SRAM", sbss <= ebss and inside(sbss, ebss, AXI),
           f"__sbss {sbss:#x} __ebss {ebss:#x}")
    sdata, edata = syms["__sdata"], syms["__edata"]
    expect(".data one range in AXI SRAM", sdata <= edata and inside(sdata, edata, AXI),
           f"__sdata {sdata:#x} __edata {edata:#x}")
    stack = syms["_stack_start"]
    expect("stack in DTCM", DTCM[0] < stack <= DTCM[1], f"_stack_start {stack:#x}")
    for what, part in (("frame buffers", "FRAMES"), ("UART line buffer", "TX_LINE")):
        try:
            n, a, z = obj(part)
            expect(f"{what} reachable by DMA1", any(inside(a, a + z, r) for r in DMA_REACHABLE),
                   f"{part} at {a:#x}..{a + z:#x}")
        except KeyError as e:
            expect(f"{what} reachable by DMA1", False, str(e))
    # Row buffer A, and B too when both fit, in AXI SRAM; otherwise B in
    # SRAM1-3 (an empty static there when both are in AXI SRAM).
    for part, region, rname, may_be_empty in (("ROWS_AXI", AXI, "AXI SRAM", False),
                                              ("ROWS_SRAM123", SRAM123, "SRAM1-3", True)):
        try:
            n, a, z = obj(part)
            expect(f"row buffers {part} in {rname}", (z > 0 or may_be_empty) and inside(a, a + z, region),
                   f"{part} at {a:#x}..{a + z:#x}")
        except KeyError as e:
            expect(f"row buffers {part} in {rname}", may_be_empty,
                   "none: both row buffers in AXI SRAM" if may_be_empty else str(e))
    lo, hi, load = (syms.get(n) for n in ("__sdtcm_rodata", "__edtcm_rodata", "__sidtcm_rodata"))
    expect("line encoder's tables in DTCM, loaded from flash",
           None not in (lo, hi, load) and lo < hi and inside(lo, hi, DTCM) and inside(load, load + hi - lo, FLASH),
           f"{lo:#x}..{hi:#x} from {load:#x}" if None not in (lo, hi, load) else "symbols missing")
    for part in ("8protocol5frame5CRC16", "8protocol5score3B64"):
        try:
            n, a, z = obj(part)
            expect(f"{part} in .dtcm_rodata", lo is not None and lo <= a and a + z <= hi, f"at {a:#x}")
        except KeyError as e:
            expect(f"{part} in .dtcm_rodata", False, str(e))
    return results


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python3 -m h743twin.layout ELF", file=sys.stderr)
        return 2
    try:
        results = check(argv[0])
    except (OSError, KeyError) as e:
        print(f"layout: {argv[0]}: {e}", file=sys.stderr)
        return 1
    for name, ok, detail in results:
        print(f"{'ok  ' if ok else 'FAIL'} {name}: {detail}")
    failed = [n for n, ok, _ in results if not ok]
    if failed:
        print(f"layout: {argv[0]}: {len(failed)} check(s) failed: {'; '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
