"""Bus cost model of the H743's per-beam scoring path, on the chip model:
`python3 -m h743twin.cost ELF J1 J2` (from host-tests/twin;
`scripts/measure.sh twin-cost` builds the ELFs and runs it for 9x9 and 15x15).

The chip model counts instructions (one cycle each, no wait states). This
script also counts every data load and store the scoring path makes (the
functions of h743twin.profile's scoring stages), by the memory and the
static it falls in, and adds a stall per access from the table below: the
estimated cycles per beam of the firmware as linked, and of the same
firmware with chosen statics moved to DTCM (`--dtcm NAME,...`: the same
accesses at DTCM cost). Instruction fetches cost no stall: from flash
they are taken to hit the M7's 16 KiB I-cache (enabled at start-up),
which holds the hot path; misses are not modelled.

Stall cycles per access at a 400 MHz core, D-cache off (the AXI bus
matrix and AHB run at 200 MHz; flash has 2 wait states at that clock; the
M7's write buffer absorbs most of a store's latency): these are the
model's assumptions, not measurements, and can be changed with
`--cost REGION=READ/WRITE`. Accesses are attributed to the scoring path
by the function of the instruction that makes them.

The accesses are found by decoding each instruction the scoring path runs
(Capstone) and computing its addresses from the registers before it runs,
not with Unicorn's memory hooks: a read hook on a load inside a Thumb IT
block leaves Unicorn's IT state set after the block, so that a later
instruction runs as if conditional (the
firmware then goes wrong, e.g. an invalid instruction at a branch).

The same accesses are also run through a model of the M7's D-cache
(dcache.py: 16 KiB, 4-way set associative, 32-byte lines, least
recently used replacement), as if the firmware enabled it with one MPU region making
`.dma_buffers` (the DMA's frame buffers and UART line) non-cacheable and
the ARMv7-M default attributes elsewhere: AXI SRAM and SRAM1-4
write-back with write-allocate, flash write-through, the TCMs and the
peripherals not cached. Every data access of the firmware goes through
the cache once the scan has started (what the rest of the firmware
evicts counts), and the stalls of the scoring path's accesses are added
up: none on a hit, a line fill on a miss (`LINE_COST`), a write-back
when a dirty line is evicted; accesses that are not cached keep their
cost from `COST`. The "D-cache on" row of the output is that estimate;
the line costs are assumptions like the others (`--line-cost
REGION=FILL/WRITEBACK`)."""

import argparse
import bisect
import sys

import capstone
from capstone import arm_const as csarm
from elftools.elf.elffile import ELFFile
from unicorn import UC_HOOK_CODE
from unicorn import arm_const as ucarm

from .dcache import DCache
from .machine import cycles_of_ms
from .profile import SCORING, add_scan_args, boot_for_scan, stage_of

REGIONS = (  # name, start, end
    ("ITCM", 0x0000_0000, 0x0001_0000),
    ("flash", 0x0800_0000, 0x0820_0000),
    ("DTCM", 0x2000_0000, 0x2002_0000),
    ("AXI SRAM", 0x2400_0000, 0x2408_0000),
    ("SRAM1-3", 0x3000_0000, 0x3004_8000),
    ("SRAM4", 0x3800_0000, 0x3801_0000),
    ("peripherals", 0x4000_0000, 0x6000_0000),
)
# Extra cycles per (read, write), beyond the instruction's own cycle.
COST = {
    "ITCM": (0, 0),
    "DTCM": (0, 0),
    "AXI SRAM": (6, 1),
    "SRAM1-3": (10, 2),
    "SRAM4": (10, 2),
    "flash": (10, 10),
    "peripherals": (12, 4),
}

# D-cache on: stall cycles per line fill (a miss, read or write: the cache
# allocates on both) and per write-back of a dirty line, beyond the
# instruction's own cycle. A fill is the uncached first-word latency plus
# the rest of the 32-byte line: 3 more 64-bit beats on AXI at 200 MHz, 7
# more 32-bit beats behind the AXI-AHB bridge, one 256-bit flash word.
LINE_COST = {
    "AXI SRAM": (12, 2),
    "SRAM1-3": (24, 4),
    "SRAM4": (24, 4),
    "flash": (12, 0),
}


def region_of(addr):
    for name, lo, hi in REGIONS:
        if lo <= addr < hi:
            return name
    return "other"


def short(name):
    """`_ZN6cvm_fw4h7435ROW_A17h...E` -> `h743::ROW_A` (the last two path
    components of a mangled Rust name, without the hash)."""
    if not name.startswith("_ZN"):
        return name
    parts, i = [], 3
    while i < len(name) and name[i].isdigit():
        j = i
        while name[j].isdigit():
            j += 1
        n = int(name[i:j])
        parts.append(name[j:j + n])
        i = j + n
    parts = [p for p in parts if not (p.startswith("h") and len(p) == 17)]
    return "::".join(parts[-2:])


def objects_of(path):
    with open(path, "rb") as f:
        elf = ELFFile(f)
        objs = sorted((s["st_value"], s["st_size"], s.name)
                      for s in elf.get_section_by_name(".symtab").iter_symbols()
                      if s["st_info"]["type"] == "STT_OBJECT" and s["st_size"])
        syms = {s.name: s["st_value"] for s in elf.get_section_by_name(".symtab").iter_symbols()}
    if "__sdma_buffers" not in syms or "__edma_buffers" not in syms:
        sys.exit(f"h743twin.cost: {path} has no .dma_buffers bounds (__sdma_buffers, __edma_buffers)")
    dma = (syms["__sdma_buffers"], syms["__edma_buffers"])
    starts = [a for a, _, _ in objs]

    def name_of(addr):
        i = bisect.bisect_right(starts, addr) - 1
        if i >= 0 and addr < objs[i][0] + objs[i][1]:
            return short(objs[i][2])
        return None

    return name_of, dma


# Capstone register names -> Unicorn registers.
UC_REG = {f"r{i}": getattr(ucarm, f"UC_ARM_REG_R{i}") for i in range(13)}
UC_REG.update({"sb": ucarm.UC_ARM_REG_R9, "sl": ucarm.UC_ARM_REG_R10, "fp": ucarm.UC_ARM_REG_R11,
               "ip": ucarm.UC_ARM_REG_R12, "sp": ucarm.UC_ARM_REG_SP, "lr": ucarm.UC_ARM_REG_LR,
               "pc": ucarm.UC_ARM_REG_PC})
MULTI_LOAD = ("ldm", "pop", "vldm", "vpop")
MULTI_STORE = ("stm", "push", "vstm", "vpush")


def condition_holds(cc, xpsr):
    """Whether an instruction with condition `cc` (Capstone) runs under
    the flags of `xpsr`."""
    n, z, c, v = (xpsr >> 31) & 1, (xpsr >> 30) & 1, (xpsr >> 29) & 1, (xpsr >> 28) & 1
    table = {
        csarm.ARM_CC_EQ: z, csarm.ARM_CC_NE: not z, csarm.ARM_CC_HS: c, csarm.ARM_CC_LO: not c,
        csarm.ARM_CC_MI: n, csarm.ARM_CC_PL: not n, csarm.ARM_CC_VS: v, csarm.ARM_CC_VC: not v,
        csarm.ARM_CC_HI: c and not z, csarm.ARM_CC_LS: (not c) or z, csarm.ARM_CC_GE: n == v,
        csarm.ARM_CC_LT: n != v, csarm.ARM_CC_GT: (not z) and n == v,
        csarm.ARM_CC_LE: z or n != v,
    }
    return bool(table.get(cc, True))


class Accesses:
    """The data accesses of an instruction, decoded once per address:
    `(kind, write, ...)` with `kind` "mem" (one operand `[base, index,
    disp]`, `words` accesses) or "multi" (a register list from a base
    register, ascending or descending)."""

    def __init__(self, uc):
        self.uc = uc
        self.md = capstone.Cs(capstone.CS_ARCH_ARM, capstone.CS_MODE_THUMB | capstone.CS_MODE_MCLASS)
        self.md.detail = True
        self.cache = {}

    def decode(self, addr, size):
        insn = next(self.md.disasm(bytes(self.uc.mem_read(addr, size)), addr), None)
        if insn is None:
            return (None, [])
        m = insn.mnemonic.split(".")[0]
        ops = insn.operands
        out = []
        if m.startswith(MULTI_LOAD) or m.startswith(MULTI_STORE):
            write = m.startswith(MULTI_STORE)
            regs = [o for o in ops if o.type == csarm.ARM_OP_REG]
            if m.startswith(("push", "pop", "vpush", "vpop")):
                base, listed = "sp", regs
            else:
                base, listed = insn.reg_name(regs[0].reg), regs[1:]
            words = sum(2 if insn.reg_name(o.reg).startswith("d") else 1 for o in listed)
            down = m.startswith(("push", "vpush")) or m.endswith("db")
            out.append(("multi", write, base, down, words))
        else:
            for o in ops:
                if o.type != csarm.ARM_OP_MEM:
                    continue
                write = m.startswith(("st", "vst"))
                words = 2 if m.startswith(("ldrd", "strd")) else 1
                if m.startswith(("vldr", "vstr")) and insn.reg_name(ops[0].reg).startswith("d"):
                    words = 2
                base = insn.reg_name(o.mem.base) if o.mem.base else None
                index = insn.reg_name(o.mem.index) if o.mem.index else None
                scale = 1 << o.shift.value if o.shift.type == csarm.ARM_SFT_LSL else 1
                if m.startswith("tbh"):
                    scale = 2
                out.append(("mem", write, base, index, scale, o.mem.disp, words))
        return (insn.cc, out)

    def of(self, addr, size):
        """[(address, write, words)] of the instruction at `addr`, from the
        registers now (before it runs); empty when its condition fails."""
        d = self.cache.get(addr)
        if d is None:
            d = self.decode(addr, size)
            self.cache[addr] = d
        cc, acc = d
        if not acc:
            return []
        uc = self.uc
        if cc not in (None, csarm.ARM_CC_AL, csarm.ARM_CC_INVALID) and not condition_holds(
                cc, uc.reg_read(ucarm.UC_ARM_REG_XPSR)):
            return []
        res = []
        for a in acc:
            if a[0] == "multi":
                _, write, base, down, words = a
                b = uc.reg_read(UC_REG[base])
                res.append((b - 4 * words if down else b, write, words))
            else:
                _, write, base, index, scale, disp, words = a
                b = ((addr + 4) & ~3) if base == "pc" else uc.reg_read(UC_REG[base]) if base else 0
                i = uc.reg_read(UC_REG[index]) * scale if index else 0
                res.append(((b + i + disp) & 0xFFFFFFFF, write, words))
        return res


def main(argv=None):
    ap = argparse.ArgumentParser(prog="h743twin.cost")
    add_scan_args(ap)
    ap.add_argument("--dtcm", default="", help="statics (substrings) to cost as if in DTCM")
    ap.add_argument("--cost", action="append", default=[], help="REGION=READ/WRITE stall cycles")
    ap.add_argument("--line-cost", action="append", default=[],
                    help="REGION=FILL/WRITEBACK stall cycles with the D-cache on")
    args = ap.parse_args(argv)
    for table, opts in ((COST, args.cost), (LINE_COST, args.line_cost)):
        for c in opts:
            k, v = c.split("=")
            r, w = v.split("/")
            table[k] = (int(r), int(w))
    moved = [s for s in args.dtcm.split(",") if s]

    m, det = boot_for_scan(args)
    func_of = m.core.symbolize
    obj_of, (dma_lo, dma_hi) = objects_of(args.elf)
    scoring_block = {}
    counts = {}  # (region, object, is_write) -> accesses
    cached_stall = {}  # (region, object) -> stall cycles with the D-cache on
    dcache = DCache(LINE_COST, region_of)
    started = [False]

    def in_scoring(addr):
        hit = scoring_block.get(addr)
        if hit is None:
            hit = stage_of(func_of(addr)) in SCORING
            scoring_block[addr] = hit
        return hit

    acc = Accesses(m.core.uc)

    def on_code(uc, addr, size, data):
        scoring = in_scoring(addr)
        if scoring:
            started[0] = True
        elif not started[0]:
            return
        for a, write, words in acc.of(addr, size):
            for k in range(words):
                w = a + 4 * k
                reg = region_of(w)
                if reg in LINE_COST and not dma_lo <= w < dma_hi:
                    s = dcache.access(w, write, reg)
                else:
                    s = COST.get(reg, (0, 0))[1 if write else 0]
                if not scoring:
                    continue
                obj = obj_of(w) or ("stack" if reg == "DTCM" else reg)
                key = (reg, obj, write)
                counts[key] = counts.get(key, 0) + 1
                cached_stall[(reg, obj)] = cached_stall.get((reg, obj), 0) + s

    m.core.uc.hook_add(UC_HOOK_CODE, on_code, begin=REGIONS[1][1], end=REGIONS[1][2] - 1)
    m.run(det.done_at + cycles_of_ms(5))
    beams = det.sent
    instr = sum(v for k, v in m.core.profile.items() if stage_of(k) in SCORING)

    by_obj = {}
    for (reg, obj, w), c in counts.items():
        e = by_obj.setdefault((reg, obj), [0, 0])
        e[1 if w else 0] += c

    def num(x):
        return f"{x:,.0f}".replace(",", " ")

    print(f"Scoring path, {args.j1}x{args.j2}, {beams} beams: {num(instr / beams)} instructions per beam")
    print()
    print("| memory | static | reads per beam | writes per beam "
          "| stall cycles per beam, D-cache off | D-cache on |")
    print("|---|---|---:|---:|---:|---:|")
    stall = 0.0
    stall_moved = 0.0
    stall_cached = 0.0
    for (reg, obj), (r, w) in sorted(by_obj.items(), key=lambda kv: -(kv[1][0] + kv[1][1])):
        cr, cw = COST.get(reg, (0, 0))
        s = (r * cr + w * cw) / beams
        sc = cached_stall.get((reg, obj), 0) / beams
        stall += s
        stall_cached += sc
        if not any(x in obj for x in moved):
            stall_moved += s
        if (r + w) / beams >= 1:
            print(f"| {reg} | {obj} | {num(r / beams)} | {num(w / beams)} | {num(s)} | {num(sc)} |")
    ipb = instr / beams
    print()
    print("| placement | instructions per beam | estimated cycles per beam |")
    print("|---|---:|---:|")
    print(f"| as linked, D-cache off | {num(ipb)} | {num(ipb + stall)} |")
    if moved:
        print(f"| with {', '.join(moved)} in DTCM | {num(ipb)} | {num(ipb + stall_moved)} |")
    print(f"| as linked, D-cache on, `.dma_buffers` not cacheable | {num(ipb)} | {num(ipb + stall_cached)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
