"""Memory map and peripheral dispatch of the STM32H743 (RM0433 §2.3).

Memories are plain Unicorn memory; SRAM1-3 answer only while their clocks
are on in RCC_AHB2ENR (RM0433 RCC_AHB2ENR.SRAMxEN: they come out of
reset with their clocks off), and an access with the clock off stops the run as
the bus fault it is on the chip. The private peripheral bus and the
peripheral space are MMIO: every access goes to the model that owns the
address, and an access that no model claims stops the run with the address
and the PC, so the model never returns made-up values.
"""

import heapq
import sys

from unicorn import (UC_HOOK_MEM_PROT, UC_MEM_FETCH_PROT, UC_MEM_WRITE_PROT, UC_PROT_ALL,
                     UC_PROT_NONE)
from unicorn.arm_const import UC_ARM_REG_PC

from .core import BusFault, Reset, Stop
from .flash import BANK2_BASE, BANK2_SIZE

MEMORIES = (
    ("ITCM", 0x0000_0000, 64 << 10),
    ("FLASH", 0x0800_0000, 2 << 20),
    ("DTCM", 0x2000_0000, 128 << 10),
    ("AXI SRAM", 0x2400_0000, 512 << 10),
    ("SRAM1-3", 0x3000_0000, 288 << 10),
    ("SRAM4", 0x3800_0000, 64 << 10),
    ("Backup SRAM", 0x3880_0000, 4 << 10),
)
# Name, base, size and RCC_AHB2ENR enable bit of the D2 SRAMs.
SRAM_CLOCKS = (("SRAM1", 0x3000_0000, 128 << 10, 29), ("SRAM2", 0x3002_0000, 128 << 10, 30),
               ("SRAM3", 0x3004_0000, 32 << 10, 31))
PERIPH_BASE = 0x4000_0000
PERIPH_SIZE = 0x2000_0000
PPB_BASE = 0xE000_0000
PPB_SIZE = 0x0010_0000


class Unmodelled(Stop):
    pass


# Register names for the clock-enable drop report (the others by offset).
TIMER_REGS = {0x00: "CR1", 0x04: "CR2", 0x0C: "DIER", 0x10: "SR", 0x14: "EGR", 0x18: "CCMR1",
              0x20: "CCER", 0x24: "CNT", 0x28: "PSC", 0x2C: "ARR", 0x34: "CCR1", 0x38: "CCR2"}


def register_name(peripheral, off):
    if peripheral.startswith("TIM") and off in TIMER_REGS:
        return TIMER_REGS[off]
    return f"{off:#05x}"


import os

TRACE = int(os.environ.get("H743TWIN_TRACE", "0"))


class Bus:
    def __init__(self):
        self.periphs = []  # (base, size, model)
        self.core = None
        self.error = None
        self.events = []
        self.seq = 0
        self.accesses = 0
        self.clocks = {}
        self.rcc = None
        # Posted writes (see `posted_write`): peripheral base -> pc of a
        # write not yet known to have landed; interrupt -> its peripheral.
        self.posted = {}
        self.irq_owner = {}
        self.unordered_unpends = []  # (irq, pc of the NVIC write, pc of the peripheral write)
        # The clock-enable delay (see `_enable_written`): (RCC register,
        # bit) -> (cycle the enable takes effect, pc of the RCC write), and
        # every access that came before it.
        self.enabling = {}
        self.clock_drops = []
        self.clock_drops_stop = True  # a drop stops the run (h743twin --clock-drops)
        # An access within the delay is counted but let through (`keep`:
        # to see what else an earlier firmware does, past this rule).
        self.clock_drops_keep = False

    def add(self, base, size, model, clock=None):
        """`clock`: (RCC enable register offset, bit, name) that must be set
        for the peripheral's registers to answer (RM0433 §8.5)."""
        self.periphs.append((base, size, model))
        if clock is not None:
            self.clocks[base] = clock
        return model

    def _check_clock(self, base, addr, uc, access, value=None):
        """Whether an access to a clock-gated peripheral reaches it. With
        the enable bit clear the run stops; with the bit set too recently
        (the clock-enable delay) the access is lost: counted, and the run
        stops unless `clock_drops_stop` is off."""
        clock = self.clocks.get(base)
        if clock is None or self.rcc is None:
            return True
        reg, bit, name = clock
        pc = self._pc(uc)
        if not self.rcc.enabled(reg, bit):
            raise Stop(f"{name} register {addr:#010x} accessed while its clock is off "
                       f"(RCC register {reg:#x} bit {bit}) at pc {pc:#010x}")
        pending = self.enabling.get((reg, bit))
        if pending is None:
            return True
        effective, enable_pc, enable_cycle = pending
        now = self.core.cycle_at(pc)
        if now >= effective:
            del self.enabling[(reg, bit)]
            return True
        off = addr - base
        drop = {"peripheral": name, "register": register_name(name, off), "offset": off,
                "access": access, "pc": pc, "enable_pc": enable_pc,
                "cycles_after_enable": now - enable_cycle, "cycle": now}
        if value is not None:
            drop["value"] = value
        self.clock_drops.append(drop)
        if self.clock_drops_keep:
            return True
        if self.clock_drops_stop:
            raise Stop(f"clock-enable delay: {access} of {name}_{drop['register']} ({addr:#010x}"
                       + (f" <- {value:#x}" if value is not None else "")
                       + f") at pc {pc:#010x}, {now - enable_cycle} cycles after its RCC enable "
                       f"(pc {enable_pc:#010x}); the clock starts {effective - enable_cycle} cycles "
                       "(two bus clock cycles) after the enable lands, so silicon loses this "
                       "access: read the enable register back first (h743twin --clock-drops count "
                       "to go on with the access dropped)")
        return False

    def _enable_written(self, word, before, uc):
        """RM0433 §8 (RCC, peripheral clock enable): a peripheral's clock
        starts two cycles of its bus clock after the enable bit is set;
        an access before then is lost. The delay runs from the RCC write;
        a read of RCC after it (the read-back the HAL and embassy do)
        cannot complete before the write has landed and the clock runs,
        so it ends every pending delay (`_rcc_read`)."""
        rising = self.rcc.r[word] & ~before
        if not rising or word not in self.rcc.ENABLE_BUS:
            return
        pc = self._pc(uc)
        now = self.core.cycle_at(pc)
        # Model cycles are instructions: the delay in instructions at the
        # current core clock (8 at 400 MHz with APB1 at 100 MHz).
        delay = -(-2 * self.rcc.sysclk_hz() // self.rcc.bus_hz(word))
        for bit in range(32):
            if rising >> bit & 1:
                self.enabling[(word, bit)] = (now + int(delay), pc, now)

    def _pc(self, uc):
        exact = getattr(self.core, "insn_pc", None)
        return exact() if exact else uc.reg_read(UC_ARM_REG_PC)

    def _rcc_read(self):
        self.enabling.clear()

    def attach(self, core):
        self.core = core
        uc = core.uc
        for name, base, size in MEMORIES:
            if name == "FLASH":
                # Bank 2 goes through the flash interface's model
                # (flash.py): its writes program, its reads check ECC.
                uc.mem_map(base, size - BANK2_SIZE)
                uc.mmio_map(BANK2_BASE, BANK2_SIZE, self._read, BANK2_BASE, self._write, BANK2_BASE)
            else:
                uc.mem_map(base, size)
        uc.mmio_map(PERIPH_BASE, PERIPH_SIZE, self._read, PERIPH_BASE,
                    self._write, PERIPH_BASE)
        uc.mmio_map(PPB_BASE, PPB_SIZE, self._read, PPB_BASE, self._write, PPB_BASE)
        uc.hook_add(UC_HOOK_MEM_PROT, self._on_gated)

    def sram_clocks_changed(self):
        """Applies RCC_AHB2ENR.SRAMxEN to SRAM1-3 (all off without an RCC)."""
        for _, base, size, bit in SRAM_CLOCKS:
            on = self.rcc is not None and self.rcc.enabled(0xDC, bit)
            self.core.uc.mem_protect(base, size, UC_PROT_ALL if on else UC_PROT_NONE)

    def _on_gated(self, uc, access, addr, size, value, _):
        name = next((n for n, base, sz, _ in SRAM_CLOCKS if base <= addr < base + sz), "memory")
        kind = {UC_MEM_WRITE_PROT: "write", UC_MEM_FETCH_PROT: "fetch"}.get(access, "read")
        self._fail(Stop(f"bus fault: {name} {kind} at {addr:#010x} while its clock is off "
                        f"(RCC_AHB2ENR.{name}EN = 0) at pc {uc.reg_read(UC_ARM_REG_PC):#010x}"))
        return False

    # --- the model clock's event queue
    def at(self, cycle, fn, owner="chip"):
        """Calls fn() when the model clock reaches `cycle`. Events of the
        chip are dropped at a reset; those of the world outside are not."""
        self.seq += 1
        heapq.heappush(self.events, (cycle, self.seq, fn, owner))
        if self.core is not None and cycle < self.core.deadline:
            self.core.deadline = cycle  # stops at the next block boundary

    def next_event(self):
        return self.events[0][0] if self.events else None

    def fire_due(self):
        while self.events and self.events[0][0] <= self.core.cycles:
            _, _, fn, _ = heapq.heappop(self.events)
            fn()

    def drop_chip_events(self):
        self.events = [e for e in self.events if e[3] != "chip"]
        heapq.heapify(self.events)

    # --- MMIO
    def _find(self, addr):
        for base, size, model in self.periphs:
            if base <= addr < base + size:
                return base, model
        return None, None

    def _read(self, uc, offset, size, region):
        addr = region + offset
        if TRACE and self.accesses < TRACE:
            v = self._read_inner(uc, offset, size, region)
            print(f"R {addr:#010x} -> {v:#x} pc {uc.reg_read(UC_ARM_REG_PC):#010x} t {self.core.cycles}", file=sys.stderr)
            return v
        return self._read_inner(uc, offset, size, region)

    def _read_inner(self, uc, offset, size, region):
        addr = region + offset
        try:
            self.accesses += 1
            if region == PPB_BASE:
                return self.core_read(addr, size)
            base, model = self._find(addr)
            if model is None:
                raise KeyError
            if not self._check_clock(base, addr, uc, "read"):
                return 0  # the peripheral did not answer: the bus reads 0
            self.landed(base)
            if model is self.rcc:
                self._rcc_read()
            return model.read(addr - base, size) & ((1 << (8 * size)) - 1)
        except BusFault as e:
            self.core.bus_fault(e)
        except KeyError:
            self._fail(Unmodelled(f"read of unmodelled register {addr:#010x} "
                                  f"({size} bytes) at pc {uc.reg_read(UC_ARM_REG_PC):#010x}"))
        except (Stop, Reset) as e:
            self._fail(e)
        return 0

    def _write(self, uc, offset, size, value, region):
        addr = region + offset
        if TRACE and self.accesses < TRACE:
            print(f"W {addr:#010x} <- {value:#x} pc {uc.reg_read(UC_ARM_REG_PC):#010x} t {self.core.cycles}", file=sys.stderr)
        try:
            self.accesses += 1
            if region == PPB_BASE:
                self.core_write(addr, size, value)
                return
            base, model = self._find(addr)
            if model is None:
                raise KeyError
            if not self._check_clock(base, addr, uc, "write", value):
                return
            self.posted_write(base, uc.reg_read(UC_ARM_REG_PC))
            if model is self.rcc:
                word = (addr - base) & ~3
                before = model.r.get(word, 0)
                model.write(addr - base, size, value)
                self._enable_written(word, before, uc)
                return
            model.write(addr - base, size, value)
        except BusFault as e:
            self.core.bus_fault(e)
        except KeyError:
            self._fail(Unmodelled(f"write of {value:#x} to unmodelled register {addr:#010x} "
                                  f"({size} bytes) at pc {uc.reg_read(UC_ARM_REG_PC):#010x}"))
        except (Stop, Reset) as e:
            self._fail(e)

    # --- the M7's write buffer, as an ordering check
    # A store to a peripheral leaves the core through the AXI/AHB/APB
    # bridges and lands later; a store to the NVIC does not wait for it.
    # Clearing a peripheral's flag and then unpending its interrupt can
    # thus see the flag still set and the interrupt pend again (ARM's
    # Cortex-M7 programming guidance: a DSB, or a read back from the
    # peripheral, in between). The model applies writes at once, so it
    # cannot show the race; it records every unpend that lacks the ordering.
    def posted_write(self, base, pc):
        self.posted[base] = pc

    def landed(self, base):
        """A read from the peripheral: its earlier writes have landed."""
        self.posted.pop(base, None)

    def barrier(self):
        self.posted.clear()

    def unpend(self, irq, pc):
        base = self.irq_owner.get(irq)
        if base is not None and base in self.posted:
            self.unordered_unpends.append((irq, pc, self.posted[base]))

    def _fail(self, e):
        if self.error is None:
            self.error = e
        self.core.deadline = 0

    def core_read(self, addr, size):
        off = addr - 0xE000_E000
        if 0x100 <= off < 0x500:
            return self.core.nvic.read(off, size)
        if 0xD00 <= off < 0xF80:
            return self.core.scb.read(off, size)
        if off == 0x004:  # ICTR: interrupt lines in groups of 32
            return 4
        raise KeyError

    def core_write(self, addr, size, value):
        off = addr - 0xE000_E000
        if 0x280 <= off < 0x300 and self.irq_owner:  # NVIC_ICPRn
            pc = self.core.uc.reg_read(UC_ARM_REG_PC)
            for bit in range(32):
                if value >> bit & 1:
                    self.unpend(32 * ((off - 0x280) // 4) + bit, pc)
        if 0x100 <= off < 0x500:
            self.core.nvic.write(off, size, value)
        elif 0xD00 <= off < 0xF80:
            self.core.scb.write(off, size, value)
        else:
            raise KeyError
