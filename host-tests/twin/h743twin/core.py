"""The Cortex-M7 core of the model: Unicorn for the instruction set, this
module for what Unicorn leaves to its host in M-profile mode (exception
entry and return, the NVIC, the SCB registers the firmware touches, sleep
with WFE/WFI) and for the model's clock.

Time: one executed instruction is one cycle of a 400 MHz clock (the
firmware's core clock). That is the instruction count of the M7 ISA, not the
M7's timing: no dual issue, no wait states, no cache misses.
"""

import struct
from itertools import compress

from unicorn import (UC_ARCH_ARM, UC_ERR_EXCEPTION, UC_ERR_FETCH_UNMAPPED,
                     UC_ERR_INSN_INVALID, UC_ERR_READ_UNMAPPED, UC_ERR_WRITE_UNMAPPED,
                     UC_HOOK_BLOCK, UC_HOOK_CODE, UC_HOOK_INTR, UC_HOOK_MEM_UNMAPPED,
                     UC_MEM_FETCH_UNMAPPED, UC_MEM_WRITE_UNMAPPED, UC_MODE_MCLASS,
                     UC_MODE_THUMB, Uc, UcError)
from unicorn.arm_const import (UC_ARM_REG_BASEPRI, UC_ARM_REG_CONTROL,
                               UC_ARM_REG_FPSCR, UC_ARM_REG_LR, UC_ARM_REG_MSP,
                               UC_ARM_REG_PC, UC_ARM_REG_PRIMASK, UC_ARM_REG_PSP,
                               UC_ARM_REG_R0, UC_ARM_REG_R1, UC_ARM_REG_R2,
                               UC_ARM_REG_R3, UC_ARM_REG_R12, UC_ARM_REG_S0,
                               UC_ARM_REG_SP, UC_ARM_REG_XPSR, UC_CPU_ARM_CORTEX_M7)

from .pchook import add_noop_code_hook, del_noop_code_hook

CLOCK_HZ = 400_000_000
UNMAPPED = (UC_ERR_READ_UNMAPPED, UC_ERR_WRITE_UNMAPPED, UC_ERR_FETCH_UNMAPPED)

# Exception numbers.
HARDFAULT = 3
IRQ0 = 16
NUM_IRQS = 150

# Thumb opcodes the core watches for.
OP_WFE = 0xBF20
OP_WFI = 0xBF30
OP_SEV = 0xBF40
OP_CPSIE_I = 0xB662
# MSR PRIMASK, Rn (T1: 0xF380 | n, then SYSm 0x10): how the critical-section
# crate restores the interrupt mask, which may unmask interrupts.
OP_MSR_RN = 0xF380
OP_MSR_PRIMASK_2 = 0x8810
OP_DSB = (0xF3BF, 0x8F4F)  # DSB SY
OP_B_SELF = 0xE7FE

FRAME_REGS = (UC_ARM_REG_R0, UC_ARM_REG_R1, UC_ARM_REG_R2, UC_ARM_REG_R3,
              UC_ARM_REG_R12, UC_ARM_REG_LR)
FP_REGS = tuple(UC_ARM_REG_S0 + i for i in range(16))


class Stop(Exception):
    """The run cannot go on: an access to something the model does not
    model, a fault the model cannot deliver, or a limit reached."""


class BusFault(Stop):
    """A bus error answered to a CPU access (a flash word whose ECC is
    broken, ...): taken as a precise bus fault (`Core.take_fault`), not a
    stop. `addr`: the faulting address (BFAR)."""

    def __init__(self, msg, addr=None):
        super().__init__(msg)
        self.addr = addr


# SCB fault status (ARMv7-M B3.2.15-B3.2.17): CFSR's BusFault and
# UsageFault bits and HFSR.FORCED (a configurable fault escalated).
CFSR_IBUSERR = 1 << 8
CFSR_PRECISERR = 1 << 9
CFSR_IMPRECISERR = 1 << 10
CFSR_BFARVALID = 1 << 15
CFSR_UNDEFINSTR = 1 << 16
HFSR_FORCED = 1 << 30


class Reset(Exception):
    """The chip resets (watchdog, AIRCR.SYSRESETREQ)."""

    def __init__(self, cause):
        super().__init__(cause)
        self.cause = cause


class Nvic:
    """NVIC and the SCB's system-handler state (RM0433 / ARMv7-M B3.4)."""

    def __init__(self, core):
        self.core = core
        self.enabled = [False] * NUM_IRQS
        self.pending = [False] * NUM_IRQS
        self.prio = [0] * NUM_IRQS
        self.taken = [0] * NUM_IRQS  # entries, for the counters
        self.line = [False] * NUM_IRQS  # interrupt request lines (levels)
        self.active = []  # exception numbers, innermost last

    def set_line(self, irq, level):
        """A peripheral's request line: a rising level pends the interrupt;
        a level still high when its handler returns pends it again."""
        if level and not self.line[irq]:
            self.pend(irq)
        self.line[irq] = level

    def pend(self, irq):
        self.pending[irq] = True
        self.core.request_check()

    def priority_of(self, exc):
        if exc == HARDFAULT:
            return -1
        if exc >= IRQ0:
            return self.prio[exc - IRQ0] >> 4  # four priority bits
        raise Stop(f"exception {exc} is not modelled")

    def current_priority(self):
        p = 256
        for exc in self.active:
            p = min(p, self.priority_of(exc))
        uc = self.core.uc
        if uc.reg_read(UC_ARM_REG_PRIMASK) & 1:
            p = min(p, 0)
        basepri = uc.reg_read(UC_ARM_REG_BASEPRI) & 0xFF
        if basepri:
            p = min(p, basepri >> 4)
        return p

    def next_irq(self):
        """The pending, enabled interrupt to take now, or None."""
        # The lowest-numbered of the most urgent (interrupts pend seldom:
        # only the pending ones are looked at).
        best = None
        enabled, prio = self.enabled, self.prio
        for irq in compress(range(NUM_IRQS), self.pending):
            if enabled[irq]:
                if best is None or (prio[irq] >> 4) < (prio[best] >> 4):
                    best = irq
        if best is None:
            return None
        if (self.prio[best] >> 4) < self.current_priority():
            return best
        return None

    def any_pending_enabled(self):
        return any(p and e for p, e in zip(self.pending, self.enabled))

    # --- registers at 0xE000E100.. (ISER, ICER, ISPR, ICPR, IABR, IPR)
    def read(self, off, size):
        if 0x100 <= off < 0x180 or 0x180 <= off < 0x200:
            return self._bits(self.enabled, (off & 0x7F) // 4)
        if 0x200 <= off < 0x300:
            return self._bits(self.pending, (off & 0x7F) // 4)
        if 0x300 <= off < 0x380:
            active = [False] * NUM_IRQS
            for exc in self.active:
                if exc >= IRQ0:
                    active[exc - IRQ0] = True
            return self._bits(active, (off - 0x300) // 4)
        if 0x400 <= off < 0x400 + NUM_IRQS:
            n = off - 0x400
            return sum(self.prio[n + i] << (8 * i) for i in range(size) if n + i < NUM_IRQS)
        raise KeyError

    def write(self, off, size, value):
        if 0x100 <= off < 0x180:
            self._set(self.enabled, (off - 0x100) // 4, value, True)
        elif 0x180 <= off < 0x200:
            self._set(self.enabled, (off - 0x180) // 4, value, False)
        elif 0x200 <= off < 0x280:
            self._set(self.pending, (off - 0x200) // 4, value, True)
        elif 0x280 <= off < 0x300:
            self._set(self.pending, (off - 0x280) // 4, value, False)
            for irq in range(NUM_IRQS):  # a line still high pends again
                if self.line[irq]:
                    self.pending[irq] = True
        elif 0x400 <= off < 0x400 + NUM_IRQS:
            n = off - 0x400
            for i in range(size):
                if n + i < NUM_IRQS:
                    self.prio[n + i] = (value >> (8 * i)) & 0xF0
        else:
            raise KeyError
        self.core.request_check()

    @staticmethod
    def _bits(arr, word):
        v = 0
        for b in range(32):
            n = word * 32 + b
            if n < NUM_IRQS and arr[n]:
                v |= 1 << b
        return v

    @staticmethod
    def _set(arr, word, value, state):
        for b in range(32):
            n = word * 32 + b
            if value >> b & 1 and n < NUM_IRQS:
                arr[n] = state


class Scb:
    """The SCB and core registers the firmware uses (ARMv7-M B3.2, the
    Cortex-M7 cache maintenance registers). Anything else stops the run."""

    CPUID = 0x411FC272  # Cortex-M7 r1p2

    def __init__(self, core):
        self.core = core
        self.regs = {
            0xD08: 0x0800_0000,  # VTOR: the boot address BOOT_ADD0 (flash)
            0xD0C: 0xFA050000,   # AIRCR
            0xD10: 0,            # SCR
            0xD14: 0x00000200,   # CCR: STKALIGN
            0xD18: 0, 0xD1C: 0, 0xD20: 0,  # SHPR1-3
            0xD24: 0,            # SHCSR
            0xD28: 0, 0xD2C: 0,  # CFSR, HFSR (write 1 to clear)
            0xD34: 0, 0xD38: 0, 0xD3C: 0,  # MMFAR, BFAR, AFSR
            0xD88: 0,            # CPACR
            0xD84: 0,            # CSSELR
            0xF34: 0xC0000000,   # FPCCR (ASPEN, LSPEN)
            0xF38: 0,            # FPCAR
            0xDF0: 0, 0xDFC: 0,  # DHCSR, DEMCR
        }

    def read(self, off, size):
        if off == 0xD00:
            return self.CPUID
        if off == 0xD04:  # ICSR
            act = self.core.nvic.active[-1] if self.core.nvic.active else 0
            return act
        if off == 0xD80:  # CCSIDR (selected by CSSELR)
            # 32 KiB 4-way I-cache / 32 KiB 4-way D-cache, 32-byte lines.
            return (0x3 << 3) | (0xFF << 13) | 1
        if off == 0xD78:  # CLIDR
            return 0x09000003
        if off == 0xD7C:  # CTR
            return 0x8303C003
        if off in self.regs:
            return self.regs[off]
        raise KeyError

    def write(self, off, size, value):
        if off == 0xD0C:  # AIRCR
            if value >> 16 != 0x05FA:
                return
            if value & 0x4:
                raise Reset("software")
            self.regs[off] = (self.regs[off] & ~0x700) | (value & 0x700)
            return
        if off == 0xD04:  # ICSR: PENDSVSET and friends are not used
            if value:
                raise Stop(f"ICSR write {value:#x} (PendSV/NMI/SysTick pend) is not modelled")
            return
        if off == 0xF00:  # STIR: software-triggered interrupt
            irq = value & 0x1FF
            if irq >= NUM_IRQS:
                raise Stop(f"STIR names interrupt {irq}, which this chip does not have")
            self.core.nvic.pend(irq)
            return
        if 0xF50 <= off <= 0xF78:  # cache maintenance: no caches are modelled
            return
        if off in (0xD28, 0xD2C):  # CFSR, HFSR: write 1 to clear
            self.regs[off] &= ~value
            return
        if off in self.regs:
            self.regs[off] = value
            return
        raise KeyError


class Core:
    """Unicorn plus exceptions, sleep and the model clock."""

    MAX_SLICE = 20_000

    def __init__(self, bus):
        self.bus = bus
        self.nvic = Nvic(self)
        self.scb = Scb(self)
        self.cycles = 0
        self.instructions = 0
        self.deadline = 0
        self.event = False       # the WFE event register
        self.sleeping = False
        self.check = False       # an interrupt may have to be taken
        self.irq_entries = 0
        self.wfe = 0
        self.fault = None        # the latest fault, as text
        self.hardfaults = 0      # HardFault entries
        self.lockups = 0         # faults inside the HardFault handler
        self.pending_fault = None  # a bus fault raised inside an MMIO callback
        self.block_counts = {}
        self.on_exception = None  # callback(exc) for counters
        self.uc = None
        self.last_block = (0, 0)
        self.profile = None  # {function: instructions} when profiling
        self.symbolize = None  # fn(address) -> function name

    # --- set-up
    def load(self, image):
        """image: list of (address, bytes) to write; the memory map comes
        from the bus."""
        uc = Uc(UC_ARCH_ARM, UC_MODE_THUMB | UC_MODE_MCLASS)
        uc.ctl_set_cpu_model(UC_CPU_ARM_CORTEX_M7)
        self.uc = uc
        self.bus.attach(self)
        for addr, data in image:
            uc.mem_write(addr, data)
        uc.hook_add(UC_HOOK_BLOCK, self._on_block)
        uc.hook_add(UC_HOOK_INTR, self._on_intr)
        uc.hook_add(UC_HOOK_MEM_UNMAPPED, self._on_unmapped)
        self.unmapped = None
        return uc

    def watch_opcodes(self, text_ranges):
        """Code hooks on the few instructions whose effect Unicorn does not
        show: SEV, and CPSIE I and MSR PRIMASK (an interrupt may be taken
        once they have run), DSB (the bus's posted writes have landed);
        `b .` (a core stuck for good, after a panic:
        fast-forward to the next event) is found by the block hook."""
        for start, data in text_ranges:
            for i in range(0, len(data) - 1, 2):
                hw = data[i] | data[i + 1] << 8
                msr = (hw & 0xFFF0 == OP_MSR_RN and i + 3 < len(data)
                       and data[i + 2] | data[i + 3] << 8 == OP_MSR_PRIMASK_2)
                dsb = (hw == OP_DSB[0] and i + 3 < len(data)
                       and data[i + 2] | data[i + 3] << 8 == OP_DSB[1])
                if hw in (OP_SEV, OP_CPSIE_I) or msr:
                    a = start + i
                    self.uc.hook_add(UC_HOOK_CODE, self._on_watched, begin=a, end=a)
                elif dsb:
                    a = start + i
                    self.uc.hook_add(UC_HOOK_CODE, self._on_dsb, begin=a, end=a)

    def _on_dsb(self, uc, addr, size, _):
        self.bus.barrier()

    def _on_watched(self, uc, addr, size, _):
        hw = struct.unpack("<H", uc.mem_read(addr, 2))[0]
        if hw == OP_SEV:
            self.event = True
        elif hw == OP_CPSIE_I or hw & 0xFFF0 == OP_MSR_RN:
            # Takes effect after this instruction: stop at the block's end,
            # where a pending interrupt is taken if the mask is now clear.
            # (Without this, an interrupt that became pending inside a
            # critical section waited for the model's next event or time
            # slice, up to 20 000 cycles, after the section ended.)
            self.request_check()

    def reset(self):
        uc = self.uc
        vtor = 0x08000000
        sp, pc = struct.unpack("<II", uc.mem_read(vtor, 8))
        for r in range(16):
            pass
        uc.reg_write(UC_ARM_REG_MSP, sp)
        uc.reg_write(UC_ARM_REG_SP, sp)
        uc.reg_write(UC_ARM_REG_CONTROL, 0)
        uc.reg_write(UC_ARM_REG_PRIMASK, 0)
        uc.reg_write(UC_ARM_REG_BASEPRI, 0)
        uc.reg_write(UC_ARM_REG_XPSR, 0x01000000)
        uc.reg_write(UC_ARM_REG_LR, 0xFFFFFFFF)
        self.pc = pc | 1
        self.nvic.__init__(self)
        self.scb.__init__(self)
        self.event = False
        self.sleeping = False
        self.track_pc()

    def request_check(self):
        """Stops the run at the next block boundary. (Never emu_stop from a
        memory or code hook: Unicorn then restarts the current instruction,
        and a store to a peripheral would happen twice.)"""
        self.check = True
        self.deadline = 0

    # --- hooks
    def _on_block(self, uc, addr, size, _):
        n = self.block_counts.get((addr, size))
        if n is None:
            n = count_thumb(bytes(uc.mem_read(addr, size)))
            if size == 2 and n == 1 and struct.unpack("<H", uc.mem_read(addr, 2))[0] == OP_B_SELF:
                n = -1
            self.block_counts[(addr, size)] = n
        if self.profile is not None and n > 0:
            name = self.symbolize(addr)
            self.profile[name] = self.profile.get(name, 0) + n
        if n < 0:
            # `b .`: nothing changes until an interrupt or a reset.
            self.sleeping = "stuck"
            uc.emu_stop()
            return
        if self.cycles >= self.deadline:
            # Stopped from its block hook, Unicorn has not run the block: it
            # runs (and is counted) when the run resumes.
            uc.emu_stop()
            return
        self.cycles += n
        self.instructions += n
        self.last_block = (addr, size)

    def _on_intr(self, uc, intno, _):
        if intno == 8:  # exception return (EXC_RETURN loaded into PC)
            self._exception_return(uc.reg_read(UC_ARM_REG_PC))
            return
        pc = uc.reg_read(UC_ARM_REG_PC)
        if intno == 1:  # undefined instruction
            self.take_fault(pc, CFSR_UNDEFINSTR, f"undefined instruction at {pc:#010x}")
        else:  # (never raise from a hook: the bus carries it out of emu_start)
            self.bus._fail(Stop(f"CPU exception {intno} at {pc:#010x} is not modelled"))
        self.request_check()

    # --- faults
    def bus_fault(self, e):
        """From an MMIO callback: the access got a bus error. Stops Unicorn
        at once, before the instruction completes, with PC at it (checked:
        the load's register keeps its value); `run_until` then takes it."""
        self.pending_fault = (CFSR_PRECISERR | CFSR_BFARVALID, str(e), e.addr)
        self.uc.emu_stop()

    # --- the exact PC, for a while after each reset
    # Inside an MMIO callback Unicorn's PC is the start of the translated
    # block, not the accessing instruction. The clock-enable delay counts
    # instructions between two accesses, so for PRECISE_CYCLES after each
    # reset (the start-up code, which enables the peripherals) a code hook
    # covers every instruction; then it goes, and an enable is judged per
    # block (`insn_pc`). A code hook makes Unicorn write each instruction's
    # address to PC before it runs, so while the hook is there PC is the
    # accessing instruction's address. That write is all the hook is for:
    # its callback is a native function without effect (pchook.py), so
    # no Python runs per instruction (a Python callback that recorded the
    # address made the model about twice as slow over a short scan).
    PRECISE_CYCLES = 100 * CLOCK_HZ // 1000
    CODE_RANGE = (0x0000_0000, 0x080F_FFFF)  # ITCM and flash bank 1

    def track_pc(self):
        """From a reset: the exact PC for the next PRECISE_CYCLES."""
        self.untrack_pc()
        self.precise_until = self.cycles + self.PRECISE_CYCLES
        self.pc_hook = add_noop_code_hook(self.uc, *self.CODE_RANGE)

    def untrack_pc(self):
        if getattr(self, "pc_hook", None) is not None:
            del_noop_code_hook(self.uc, self.pc_hook)
            self.pc_hook = None
            try:  # retranslate without the hook's calls
                self.uc.ctl_remove_cache(self.CODE_RANGE[0], self.CODE_RANGE[1] + 1)
            except Exception:  # noqa: BLE001 (older Unicorn: the calls stay, unused)
                pass

    def insn_pc(self):
        """The accessing instruction's address while the code hook is
        there, else the start of its block."""
        return self.uc.reg_read(UC_ARM_REG_PC)

    def take_fault(self, pc, cfsr, detail, bfar=None):
        """A fault at the instruction at `pc` (its address is stacked: the
        handler returns to it), or an imprecise one taken at `pc`. With
        SHCSR's BusFault and UsageFault handlers disabled (the reset state,
        which the firmware keeps) it escalates to HardFault, exception 3
        (ARMv7-M B1.5.8: HFSR.FORCED); CFSR says which fault, BFAR where.
        A fault inside the HardFault handler is a lockup: the core stops
        executing until a reset (the watchdog's)."""
        if self.scb.regs[0xD24] & (7 << 16):
            raise Stop(f"{detail}: SHCSR enables a configurable fault handler, not modelled")
        self.fault = detail
        self.scb.regs[0xD28] |= cfsr
        self.scb.regs[0xD2C] |= HFSR_FORCED
        if bfar is not None:
            self.scb.regs[0xD38] = bfar
        if HARDFAULT in self.nvic.active:
            self.lockups += 1
            self.sleeping = "stuck"
            return
        self.hardfaults += 1
        self.pc = pc | 1
        self.enter(HARDFAULT)

    # --- running
    def run_until(self, limit):
        """Runs the CPU until `limit` cycles, a sleep, or a check request."""
        uc = self.uc
        if getattr(self, "pc_hook", None) is not None and self.cycles >= self.precise_until:
            self.untrack_pc()
        self.deadline = min(limit, self.cycles + self.MAX_SLICE)
        self.check = False
        try:
            uc.emu_start(self.pc, 0xFFFFFFFF)
        except UcError as e:
            pc = uc.reg_read(UC_ARM_REG_PC)
            if e.errno in UNMAPPED:
                # A precise bus fault: PC is the faulting instruction's (checked).
                self._uncount_from(pc)
                kind, addr = self.unmapped or ("access", None)
                self.take_fault(pc, CFSR_IBUSERR if e.errno == UC_ERR_FETCH_UNMAPPED
                                else CFSR_PRECISERR | CFSR_BFARVALID,
                                f"bus fault: {kind} of unmapped address "
                                f"{addr if addr is None else f'{addr:#010x}'} at pc {pc:#010x}",
                                None if e.errno == UC_ERR_FETCH_UNMAPPED else addr)
                self.unmapped = None
                return
            if e.errno == UC_ERR_INSN_INVALID:
                hw = struct.unpack("<H", uc.mem_read(pc - 2, 2))[0]
                if hw != OP_WFE:
                    # PC is the undefined instruction's own (UDF, an
                    # encoding Unicorn does not know): a UsageFault.
                    self._uncount_from(pc)
                    self.take_fault(pc, CFSR_UNDEFINSTR, f"undefined instruction at {pc:#010x}")
                    return
                if hw == OP_WFE:
                    self._uncount_after(pc)
                    self.pc = pc | 1
                    self.wfe += 1
                    if self.event:
                        self.event = False
                    else:
                        self.sleeping = "wfe"
                    return
            if e.errno == UC_ERR_EXCEPTION:
                raise Stop(f"unhandled CPU exception at {pc:#010x}: {e}")
            if self.bus.error is not None:
                raise self.bus.error  # a memory hook said why
            raise Stop(f"{e} at pc {pc:#010x}") from None
        if self.pending_fault is not None:
            cfsr, detail, bfar = self.pending_fault
            self.pending_fault = None
            pc = uc.reg_read(UC_ARM_REG_PC)
            self._uncount_from(pc)
            self.take_fault(pc, cfsr, detail, bfar)
            return
        self.pc = uc.reg_read(UC_ARM_REG_PC) | 1
        if self.sleeping == "stuck":
            return
        hw = struct.unpack("<H", uc.mem_read(self.pc - 3, 2))[0]
        if hw == OP_WFI:
            self._uncount_after(self.pc & ~1)
            self.sleeping = "wfi"

    def cycle_at(self, pc):
        """The model cycle of the instruction at `pc` in the running block.
        The block hook counts a block whole when it starts, so `cycles` is
        the block's end; the instructions after `pc` have not run yet.
        (Used where a few cycles matter: the clock-enable delay.)"""
        addr, size = self.last_block
        if self.uc is None or not addr <= pc < addr + size:
            return self.cycles
        return self.cycles - count_thumb(bytes(self.uc.mem_read(pc, addr + size - pc))) + 1

    def _uncount_from(self, pc):
        """The block stopped at the instruction at `pc`, which did not run."""
        addr, size = self.last_block
        if addr <= pc < addr + size:
            rest = count_thumb(bytes(self.uc.mem_read(pc, addr + size - pc)))
            self.cycles -= rest
            self.instructions -= rest

    def _on_unmapped(self, uc, access, addr, size, value, _):
        self.unmapped = ({UC_MEM_WRITE_UNMAPPED: "write", UC_MEM_FETCH_UNMAPPED: "fetch"}
                         .get(access, "read"), addr)
        return False

    def _uncount_after(self, pc):
        """The block that was counted whole stopped at `pc` (after a WFE or
        WFI): its instructions from `pc` on have not run yet."""
        addr, size = self.last_block
        if addr < pc < addr + size:
            rest = count_thumb(bytes(self.uc.mem_read(pc, addr + size - pc)))
            self.cycles -= rest
            self.instructions -= rest
            if self.profile is not None and rest:
                name = self.symbolize(addr)
                self.profile[name] = self.profile.get(name, 0) - rest

    def wake_if_pending(self):
        """Takes the interrupt that may be taken now; returns True if one was."""
        irq = self.nvic.next_irq()
        if irq is None:
            return False
        self.enter(IRQ0 + irq)
        return True

    def enter(self, exc):
        uc = self.uc
        if exc >= IRQ0:
            self.nvic.pending[exc - IRQ0] = False
            self.nvic.taken[exc - IRQ0] += 1
        self.irq_entries += 1
        xpsr = uc.reg_read(UC_ARM_REG_XPSR)
        in_thread = not self.nvic.active
        control = uc.reg_read(UC_ARM_REG_CONTROL)
        use_psp = in_thread and control & 2
        sp = uc.reg_read(UC_ARM_REG_PSP if use_psp else UC_ARM_REG_MSP)
        # Extended (FP) frame: 8 core words, s0-s15, FPSCR, one reserved.
        words = [uc.reg_read(r) for r in FRAME_REGS]
        words.append(self.pc & ~1)
        frame_xpsr = xpsr & ~(1 << 9)
        fp = [uc.reg_read(r) & 0xFFFFFFFF for r in FP_REGS]
        fp += [uc.reg_read(UC_ARM_REG_FPSCR), 0]
        size = 4 * (8 + 18)
        new_sp = sp - size
        if new_sp & 4:
            new_sp -= 4
            frame_xpsr |= 1 << 9
        words.append(frame_xpsr | 0x01000000)
        uc.mem_write(new_sp, struct.pack("<8I", *[w & 0xFFFFFFFF for w in words]))
        uc.mem_write(new_sp + 32, struct.pack("<18I", *fp))
        if use_psp:
            uc.reg_write(UC_ARM_REG_PSP, new_sp)
        else:
            uc.reg_write(UC_ARM_REG_MSP, new_sp)
        exc_return = 0xFFFFFFE1 if not in_thread else (0xFFFFFFED if use_psp else 0xFFFFFFE9)
        self.nvic.active.append(exc)
        uc.reg_write(UC_ARM_REG_CONTROL, control & ~2 & ~4)
        uc.reg_write(UC_ARM_REG_SP, uc.reg_read(UC_ARM_REG_MSP))
        uc.reg_write(UC_ARM_REG_LR, exc_return)
        uc.reg_write(UC_ARM_REG_XPSR, 0x01000000 | exc)
        vtor = self.scb.regs[0xD08]
        vector = struct.unpack("<I", uc.mem_read(vtor + 4 * exc, 4))[0]
        self.pc = vector | 1
        uc.reg_write(UC_ARM_REG_PC, self.pc)
        self.event = True
        self.sleeping = False
        if self.on_exception:
            self.on_exception(exc)

    def _exception_return(self, exc_return):
        uc = self.uc
        if not self.nvic.active:
            raise Stop(f"exception return {exc_return:#x} outside a handler")
        exc = self.nvic.active.pop()
        if exc >= IRQ0 and self.nvic.line[exc - IRQ0]:
            self.nvic.pending[exc - IRQ0] = True
        to_psp = (exc_return & 0xF) == 0xD
        fp_frame = not exc_return & 0x10
        reg = UC_ARM_REG_PSP if to_psp else UC_ARM_REG_MSP
        sp = uc.reg_read(UC_ARM_REG_MSP if self.nvic.active or not to_psp else reg)
        if to_psp:
            sp = uc.reg_read(UC_ARM_REG_PSP)
        else:
            sp = uc.reg_read(UC_ARM_REG_MSP)
        words = struct.unpack("<8I", uc.mem_read(sp, 32))
        for r, v in zip(FRAME_REGS, words):
            uc.reg_write(r, v)
        size = 32
        if fp_frame:
            fp = struct.unpack("<18I", uc.mem_read(sp + 32, 72))
            for r, v in zip(FP_REGS, fp):
                uc.reg_write(r, v)
            uc.reg_write(UC_ARM_REG_FPSCR, fp[16])
            size += 72
        xpsr = words[7]
        if xpsr & (1 << 9):
            size += 4
        sp += size
        uc.reg_write(reg, sp)
        control = uc.reg_read(UC_ARM_REG_CONTROL)
        if not self.nvic.active and to_psp:
            uc.reg_write(UC_ARM_REG_CONTROL, control | 2)
            uc.reg_write(UC_ARM_REG_SP, sp)
        else:
            uc.reg_write(UC_ARM_REG_SP, uc.reg_read(UC_ARM_REG_MSP))
        uc.reg_write(UC_ARM_REG_XPSR, xpsr & ~(1 << 9))
        uc.reg_write(UC_ARM_REG_PC, words[6] | 1)
        self.pc = words[6] | 1
        self.event = True
        # A pending interrupt may now be taken (tail-chaining).
        self.request_check()


def count_thumb(code):
    """Instructions in a block of Thumb code: a halfword whose top five bits
    are 0b11101, 0b11110 or 0b11111 starts a 32-bit instruction."""
    n = 0
    i = 0
    while i + 1 < len(code):
        hw = code[i] | code[i + 1] << 8
        i += 4 if (hw >> 11) in (0x1D, 0x1E, 0x1F) else 2
        n += 1
    return n
