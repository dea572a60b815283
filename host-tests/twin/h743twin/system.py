"""Clock, power and system peripherals (RM0433 §6-§8, §12, §49, §58).

Registers hold what the firmware writes; the ready flags the firmware polls
follow the enables the way the silicon's do once the oscillators and
regulators have settled (immediately: the model has no start-up times).
Offsets outside each model's list stop the run.
"""

from .core import Reset

HSI_HZ = 64_000_000
CSI_HZ = 4_000_000
HSE_HZ = 8_000_000  # the NUCLEO's ST-LINK MCO on PH0 (HSE bypass)
LSI_HZ = 32_000


class Registers:
    """A block of plain read/write registers at fixed offsets."""

    RESET = {}
    READ_ONLY = frozenset()  # offsets whose writes the chip ignores

    def __init__(self):
        self.r = dict(self.RESET)

    def read(self, off, size):
        word = off & ~3
        if word not in self.r:
            raise KeyError
        return self.r[word] >> (8 * (off & 3))

    def write(self, off, size, value):
        word = off & ~3
        if word not in self.r:
            raise KeyError
        if word in self.READ_ONLY:
            return
        if size < 4:
            shift = 8 * (off & 3)
            mask = ((1 << (8 * size)) - 1) << shift
            value = (self.r[word] & ~mask) | ((value << shift) & mask)
        self.r[word] = value & 0xFFFFFFFF
        self.written(word)

    def written(self, word):
        pass


# RCC_RSR reset flags.
RSR_LPWR = 1 << 30
RSR_WWDG1 = 1 << 28
RSR_IWDG1 = 1 << 26
RSR_SFT = 1 << 24
RSR_POR = 1 << 23
RSR_PIN = 1 << 22
RSR_BOR = 1 << 21
RSR_D2 = 1 << 20
RSR_D1 = 1 << 19
RSR_CPU = 1 << 17
RSR_RMVF = 1 << 16
POWER_ON_FLAGS = RSR_POR | RSR_PIN | RSR_BOR | RSR_D2 | RSR_D1 | RSR_CPU
# RM0433 §8.4 (reset source identification, the RCC_RSR table): the flags
# each reset the model produces sets. Every system reset also pulls NRST
# low (PINRSTF) and resets the CPU (CPURSTF); a brown-out sets BORRSTF
# without PORRSTF (VDD fell below the BOR threshold, not below the POR one).
RESET_FLAGS = {
    "power-on": POWER_ON_FLAGS,
    "pin": RSR_PIN | RSR_CPU,
    "bor": RSR_BOR | RSR_PIN | RSR_CPU,
    "software": RSR_SFT | RSR_PIN | RSR_CPU,
    "watchdog": RSR_IWDG1 | RSR_PIN | RSR_CPU,
}


class Rcc(Registers):
    RESET = {
        0x00: 0x0000_0025,  # CR: HSION, HSIRDY, HSIDIVF
        0x04: 0x4000_0000,  # HSICFGR
        0x08: 0,            # CRRCR
        0x0C: 0x2000_0000,  # CSICFGR
        0x10: 0,            # CFGR
        0x18: 0, 0x1C: 0, 0x20: 0,  # D1CFGR, D2CFGR, D3CFGR
        0x28: 0x0202_0200,  # PLLCKSELR
        0x2C: 0x01FF_0000,  # PLLCFGR
        0x30: 0x0101_0280, 0x34: 0,  # PLL1DIVR, PLL1FRACR
        0x38: 0x0101_0280, 0x3C: 0,
        0x40: 0x0101_0280, 0x44: 0,
        0x4C: 0, 0x50: 0, 0x54: 0, 0x58: 0,  # kernel clock selection
        0x60: 0, 0x64: 0, 0x68: 0,  # CIER, CIFR, CICR
        0x70: 0, 0x74: 0,  # BDCR, CSR
        0x7C: 0, 0x80: 0, 0x84: 0, 0x88: 0, 0x8C: 0, 0x90: 0, 0x94: 0,
        0x98: 0, 0x9C: 0,  # reset registers
        0xD0: POWER_ON_FLAGS,  # RSR
        0xD4: 0, 0xD8: 0, 0xDC: 0, 0xE0: 0, 0xE4: 0, 0xE8: 0, 0xEC: 0,
        0xF0: 0, 0xF4: 0,  # enables
        0x130: POWER_ON_FLAGS,  # C1_RSR
    }
    READ_ONLY = frozenset({0x08, 0x64})  # CRRCR, CIFR

    def __init__(self, rsr=POWER_ON_FLAGS):
        super().__init__()
        self.r[0xD0] = rsr
        self.r[0x130] = rsr
        self.on_ahb2enr = None  # fn() when the SRAM1-3 clocks may change

    def written(self, word):
        r = self.r
        if word == 0x00:
            cr = r[0]
            ready = 0
            for on, rdy in ((0, 2), (7, 8), (12, 13), (16, 17), (24, 25), (26, 27), (28, 29)):
                if cr >> on & 1:
                    ready |= 1 << rdy
            ready |= (1 << 14) | (1 << 15)  # D1CKRDY, D2CKRDY
            mask = sum(1 << b for b in (2, 8, 13, 14, 15, 17, 25, 27, 29))
            r[0] = (cr & ~mask) | ready
        elif word == 0x10:  # CFGR: the switch status follows SW at once
            sw = r[0x10] & 7
            r[0x10] = (r[0x10] & ~(7 << 3)) | (sw << 3)
        elif word == 0x74:  # CSR: LSIRDY follows LSION
            r[0x74] = (r[0x74] & ~2) | ((r[0x74] & 1) << 1)
        elif word == 0x70:  # BDCR: LSERDY follows LSEON
            r[0x70] = (r[0x70] & ~2) | ((r[0x70] & 1) << 1)
        elif word == 0xDC and self.on_ahb2enr is not None:
            self.on_ahb2enr()
        elif word == 0xD0:
            if r[0xD0] & RSR_RMVF:
                r[0xD0] = 0
                r[0x130] = 0

    def write(self, off, size, value):
        word = off & ~3
        cr = self.r[0]
        if word == 0x28 and size == 4:
            # DIVMx and PLLSRC are write-protected while their PLL runs.
            keep = 0
            for on, field in ((24, 0x3F << 4), (26, 0x3F << 12), (28, 0x3F << 20)):
                if cr >> on & 1:
                    keep |= field | 3
            value = (value & ~keep) | (self.r[0x28] & keep)
        if word in (0x30, 0x34) and cr >> 24 & 1 and size == 4:
            return  # PLL1DIVR/FRACR: ignored while PLL1 runs
        if off & ~3 == 0xD0 and value & RSR_RMVF:
            self.r[0xD0] = 0
            self.r[0x130] = 0
            return
        super().write(off, size, value)

    # --- clocks derived from the registers
    def pll_input_hz(self):
        src = self.r[0x28] & 3  # PLLSRC
        if src == 0:
            return HSI_HZ >> ((self.r[0] >> 3) & 3)
        if src == 1:
            return CSI_HZ
        if src == 2:
            return HSE_HZ
        return 0

    def pll1(self):
        """(P, Q, R) of PLL1 in Hz, or zeros while it is off."""
        if not self.r[0] >> 24 & 1:
            return (0, 0, 0)
        divm = (self.r[0x28] >> 4) & 0x3F
        if divm == 0:
            return (0, 0, 0)
        divr = self.r[0x30]
        n = (divr & 0x1FF) + 1
        vco = self.pll_input_hz() / divm * n
        p = ((divr >> 9) & 0x7F) + 1
        q = ((divr >> 16) & 0x7F) + 1
        rr = ((divr >> 24) & 0x7F) + 1
        return (vco / p, vco / q, vco / rr)

    def sysclk_hz(self):
        sws = (self.r[0x10] >> 3) & 7
        if sws == 0:
            return HSI_HZ >> ((self.r[0] >> 3) & 3)
        if sws == 1:
            return CSI_HZ
        if sws == 2:
            return HSE_HZ
        return self.pll1()[0]

    @staticmethod
    def _ahb_div(code):
        return 1 if code < 8 else (2, 4, 8, 16, 64, 128, 256, 512)[code - 8]

    @staticmethod
    def _apb_div(code):
        return 1 if code < 4 else (2, 4, 8, 16)[code - 4]

    def hclk_hz(self):
        d1 = self.r[0x18]
        core = self.sysclk_hz() / self._ahb_div((d1 >> 8) & 0xF)
        return core / self._ahb_div(d1 & 0xF)

    def pclk1_hz(self):
        return self.hclk_hz() / self._apb_div((self.r[0x1C] >> 4) & 7)

    def pclk2_hz(self):
        return self.hclk_hz() / self._apb_div((self.r[0x1C] >> 8) & 7)

    def pclk4_hz(self):
        return self.hclk_hz() / self._apb_div((self.r[0x20] >> 4) & 7)

    # The bus each RCC enable register's peripherals sit on (RM0433 §8,
    # the RCC_xxxENR registers): AHB1-4 at HCLK, APB1-4 at their PCLK.
    ENABLE_BUS = {0xD4: "AHB3", 0xD8: "AHB1", 0xDC: "AHB2", 0xE0: "AHB4", 0xE4: "APB3",
                  0xE8: "APB1", 0xEC: "APB1", 0xF0: "APB2", 0xF4: "APB4"}

    def bus_hz(self, reg):
        bus = self.ENABLE_BUS[reg]
        if bus == "APB1":
            return self.pclk1_hz()
        if bus == "APB2":
            return self.pclk2_hz()
        if bus == "APB4":
            return self.pclk4_hz()
        if bus == "APB3":
            return self.hclk_hz() / self._apb_div((self.r[0x18] >> 4) & 7)
        return self.hclk_hz()

    def apb1_timer_hz(self):
        """Timers on APB1 run at PCLK1, or twice PCLK1 when the APB1
        prescaler divides (RCC_CFGR.TIMPRE = 0)."""
        div = self._apb_div((self.r[0x1C] >> 4) & 7)
        return self.pclk1_hz() * (1 if div == 1 else 2)

    def spi123_kernel_hz(self):
        sel = (self.r[0x50] >> 12) & 7  # D2CCIP1R.SPI123SEL
        if sel == 0:
            return self.pll1()[1]
        raise KeyError  # another kernel source: not modelled

    def usart234578_kernel_hz(self):
        sel = self.r[0x54] & 7  # D2CCIP2R.USART234578SEL
        if sel == 0:
            return self.pclk1_hz()
        raise KeyError

    def enabled(self, reg, bit):
        return bool(self.r[reg] >> bit & 1)


class Pwr(Registers):
    RESET = {
        0x00: 0xF000_C000,  # CR1
        0x04: 0x0000_4000,  # CSR1: ACTVOS = scale 3, ACTVOSRDY below
        0x08: 0, 0x0C: 0x0000_0046,  # CR2, CR3 (SCUEN, LDOEN)
        0x10: 0,            # CPUCR
        0x18: 0x0000_4000,  # D3CR: VOS = scale 3
        0x20: 0, 0x24: 0, 0x28: 0,
    }
    READ_ONLY = frozenset({0x04})  # CSR1

    def __init__(self):
        super().__init__()
        self.settle()

    def settle(self):
        vos = (self.r[0x18] >> 14) & 3
        self.r[0x18] |= 1 << 13  # VOSRDY
        self.r[0x04] = (self.r[0x04] & ~(3 << 14)) | (vos << 14) | (1 << 13)  # ACTVOS, ACTVOSRDY

    def written(self, word):
        self.settle()


class Syscfg(Registers):
    RESET = {0x04: 0, 0x08: 0, 0x0C: 0, 0x10: 0, 0x14: 0,  # PMCR, EXTICR1-4
             0x20: 0, 0x24: 0, 0x28: 0, 0x2C: 0}  # CCCSR, CCVR, CCCR, PWRCR
    READ_ONLY = frozenset({0x24})  # CCVR

    def written(self, word):
        if word == 0x20:  # the compensation cell is ready once enabled
            cccsr = self.r[0x20]
            self.r[0x20] = (cccsr & ~(1 << 8)) | ((cccsr & 1) << 8)

    def exti_port(self, line):
        return (self.r[0x08 + 4 * (line // 4)] >> (4 * (line % 4))) & 0xF


class Dbgmcu(Registers):
    RESET = {0x00: 0x2003_6450,  # IDC: revision V, device 0x450
             0x04: 0, 0x34: 0, 0x3C: 0, 0x4C: 0, 0x54: 0}
    READ_ONLY = frozenset({0x00})  # IDC

    def iwdg1_frozen(self):
        return bool(self.r[0x54] >> 18 & 1)


class Gpio(Registers):
    """One GPIO port. Inputs are driven by the detector model; outputs are
    reported to listeners (chip select)."""

    RESET = {0x00: 0xFFFF_FFFF, 0x04: 0, 0x08: 0, 0x0C: 0, 0x10: 0, 0x14: 0,
             0x18: 0, 0x1C: 0, 0x20: 0, 0x24: 0}

    def __init__(self, name, reset=None):
        super().__init__()
        self.name = name
        if reset:
            self.r.update(reset)
        self.inputs = 0
        self.listeners = []  # fn(pin, level) on output changes
        self.observers = []  # fn() after every write (the pins' levels may change)

    def read(self, off, size):
        if off & ~3 == 0x10:
            return self.inputs | (self.r[0x14] & self.output_mask())
        if off & ~3 == 0x18:
            return 0
        return super().read(off, size)

    def output_mask(self):
        m = 0
        for pin in range(16):
            if (self.r[0] >> (2 * pin)) & 3 == 1:
                m |= 1 << pin
        return m

    def write(self, off, size, value):
        before = self.r[0x14]
        if off & ~3 == 0x18:  # BSRR
            if size < 4:
                value <<= 8 * (off & 3)
            odr = (before | (value & 0xFFFF)) & ~(value >> 16)
            self.r[0x14] = odr
        else:
            super().write(off, size, value)
        after = self.r[0x14]
        for pin in range(16):
            if (before ^ after) >> pin & 1:
                for fn in self.listeners:
                    fn(pin, after >> pin & 1)
        for fn in self.observers:
            fn()

    def level(self, pin):
        """What the pin drives (RM0433 §11.3): its ODR bit while MODER makes
        it a general-purpose output (01), except a 1 in open-drain (OTYPER)
        which only releases the line; "z" (Hi-Z) otherwise: input and
        analog modes (analog, 11, is every pin's reset state but the debug
        pins') drive nothing. Alternate functions are not recorded pins."""
        if self.mode(pin) != 1:
            return "z"
        bit = self.r[0x14] >> pin & 1
        if bit and self.r[0x04] >> pin & 1:
            return "z"
        return bit

    def mode(self, pin):
        return (self.r[0] >> (2 * pin)) & 3

    def drive(self, pin, level):
        if level:
            self.inputs |= 1 << pin
        else:
            self.inputs &= ~(1 << pin)


class Exti(Registers):
    """EXTI lines 0-15 for the CPU (RTSR1, FTSR1, SWIER1, CPUIMR1, CPUPR1)."""

    RESET = {0x00: 0, 0x04: 0, 0x08: 0, 0x0C: 0, 0x10: 0, 0x14: 0,
             0x20: 0, 0x24: 0, 0x28: 0, 0x2C: 0, 0x30: 0, 0x34: 0,
             0x40: 0, 0x44: 0, 0x48: 0, 0x4C: 0, 0x50: 0, 0x54: 0,
             0x80: 0, 0x84: 0, 0x88: 0, 0x90: 0, 0x94: 0, 0x98: 0,
             0xA0: 0, 0xA4: 0, 0xA8: 0}
    GROUPS = ((0, 0, 6), (1, 1, 7), (2, 2, 8), (3, 3, 9), (4, 4, 10),
              (5, 9, 23), (10, 15, 40))

    def __init__(self, nvic):
        super().__init__()
        self.nvic = nvic
        self.edges = 0

    def write(self, off, size, value):
        if off & ~3 == 0x88:  # CPUPR1: write 1 to clear
            self.r[0x88] &= ~value
            self.update()
            return
        super().write(off, size, value)
        self.update()

    def edge(self, line, rising):
        trig = self.r[0x00] if rising else self.r[0x04]
        if trig >> line & 1:
            self.r[0x88] |= 1 << line
            self.edges += 1
            self.update()

    def update(self):
        pr = self.r[0x88] & self.r[0x80]
        for lo, hi, irq in self.GROUPS:
            mask = ((1 << (hi + 1)) - 1) & ~((1 << lo) - 1)
            self.nvic.set_line(irq, bool(pr & mask))


class Iwdg:
    """IWDG1: key register, prescaler, reload; expiry resets the chip."""

    def __init__(self, bus, dbgmcu, debugger):
        self.bus = bus
        self.dbgmcu = dbgmcu
        self.debugger = debugger
        self.running = False
        self.unlocked = False
        self.pr = 0
        self.rlr = 0xFFF
        self.feeds = 0
        self.gen = 0
        self.expiry = None

    def period_cycles(self):
        from .core import CLOCK_HZ
        ticks = (4 << self.pr) * (self.rlr + 1)
        return int(ticks * CLOCK_HZ / LSI_HZ)

    def reload(self):
        self._arm(self.bus.core.cycles + self.period_cycles())

    def _arm(self, when):
        self.gen += 1
        gen = self.gen
        self.expiry = when

        def expire():
            if gen == self.gen:
                raise Reset("watchdog")

        self.bus.at(when, expire)

    def pause(self, until):
        """The counter stops until `until` (core halted, DBGMCU freeze)."""
        if not self.running or self.expiry is None:
            return
        left = self.expiry - self.bus.core.cycles
        self.gen += 1
        self.bus.at(until, lambda: self._arm(until + left))

    def read(self, off, size):
        if off == 0x04:
            return self.pr
        if off == 0x08:
            return self.rlr
        if off == 0x0C:
            return 0  # PVU, RVU, WVU: updates are instantaneous
        if off == 0x10:
            return 0xFFF
        raise KeyError

    def write(self, off, size, value):
        if off == 0x00:
            key = value & 0xFFFF
            if key == 0xCCCC:
                self.running = True
                self.reload()
            elif key == 0xAAAA:
                self.feeds += 1
                if self.running:
                    self.reload()
            elif key == 0x5555:
                self.unlocked = True
            else:
                self.unlocked = False
        elif off == 0x04:
            if self.unlocked:
                self.pr = value & 7
        elif off == 0x08:
            if self.unlocked:
                self.rlr = value & 0xFFF
        elif off == 0x10:
            pass  # window: not used
        else:
            raise KeyError


class Timer:
    """A general-purpose timer as the time driver and the read deadline use
    it: up-counting with prescaler, auto-reload, one-pulse mode (OPM), update
    and compare flags and interrupts."""

    def __init__(self, bus, nvic, irq, clock_hz, bits=32, channels=4):
        self.bus = bus
        self.nvic = nvic
        self.irq = irq
        self.clock_hz = clock_hz  # fn() -> timer kernel clock in Hz
        self.top = (1 << bits) - 1
        self.cr1 = 0
        self.cr2 = 0
        self.smcr = 0
        self.dier = 0
        self.sr = 0
        self.ccmr = [0, 0]
        self.ccer = 0
        self.psc = 0
        self.psc_active = 0
        self.arr = self.top
        self.ccr = [0, 0, 0, 0]
        self.cnt0 = 0
        self.t0 = 0
        self.gen = 0
        # TIM13 (one channel) has no CR2 or SMCR, TIM12 (two) no CCMR2
        # (RM0433's TIM12 and TIM13/TIM14 register maps); both have OR and TISEL.
        self.channels = channels
        self.other = {0x50: 0, 0x68: 0}

    def _has(self, off):
        if off in (0x04, 0x08):
            return self.channels > 1
        if off == 0x1C:
            return self.channels > 2
        if 0x34 <= off < 0x44:
            return (off - 0x34) // 4 < self.channels
        return True

    def tick_cycles(self):
        from .core import CLOCK_HZ
        hz = self.clock_hz()
        return CLOCK_HZ / hz * (self.psc_active + 1)

    def now(self):
        return self.bus.core.cycles

    def cnt(self):
        if not self.cr1 & 1:
            return self.cnt0
        ticks = int((self.now() - self.t0) / self.tick_cycles())
        return (self.cnt0 + ticks) % (self.arr + 1)

    def rebase(self):
        """Makes the current count the new origin (before any change)."""
        self.advance()
        self.cnt0 = self.cnt()
        self.t0 = self.now()

    def advance(self):
        """Sets the flags of every event between the origin and now."""
        if not self.cr1 & 1:
            return
        tick = self.tick_cycles()
        ticks = int((self.now() - self.t0) / tick)
        if ticks <= 0:
            return
        period = self.arr + 1
        start = self.cnt0
        one_shot = self.cr1 & (1 << 3) and start + ticks > self.arr
        if one_shot:
            # OPM: the update event clears CEN; the count stops at 0.
            ticks = period - start
        if start + ticks > self.arr:
            self.sr |= 1  # UIF
            self.psc_active = self.psc
        for ch in range(self.channels):
            c = self.ccr[ch]
            # The compare fires when the counter passes from c-1 to c.
            dist = (c - start) % period
            if 0 < dist <= ticks or (ticks >= period):
                self.sr |= 1 << (ch + 1)
        self.cnt0 = (start + ticks) % period
        self.t0 += ticks * tick
        if one_shot:
            self.cr1 &= ~1
        self.update_irq()

    def schedule(self):
        """Schedules the next event that can raise the interrupt."""
        self.gen += 1
        gen = self.gen
        if not self.cr1 & 1:
            return
        period = self.arr + 1
        cnt = self.cnt0
        dists = []
        if self.dier & 1:
            dists.append(period - cnt)
        for ch in range(self.channels):
            if self.dier >> (ch + 1) & 1:
                d = (self.ccr[ch] - cnt) % period
                dists.append(d if d else period)
        if not dists:
            return
        when = self.t0 + min(dists) * self.tick_cycles()

        def fire():
            if gen == self.gen:
                self.advance()
                self.schedule()

        self.bus.at(int(when) + 1, fire)

    def update_irq(self):
        self.nvic.set_line(self.irq, bool(self.sr & self.dier & 0x1F))

    def read(self, off, size):
        if not self._has(off):
            raise KeyError
        self.advance()
        if off == 0x00:
            return self.cr1
        if off == 0x04:
            return self.cr2
        if off == 0x08:
            return self.smcr
        if off == 0x0C:
            return self.dier
        if off == 0x10:
            return self.sr
        if off in (0x18, 0x1C):
            return self.ccmr[(off - 0x18) // 4]
        if off == 0x20:
            return self.ccer
        if off == 0x24:
            return self.cnt()
        if off == 0x28:
            return self.psc
        if off == 0x2C:
            return self.arr
        if 0x34 <= off < 0x44:
            return self.ccr[(off - 0x34) // 4]
        if off in self.other:
            return self.other[off]
        raise KeyError

    def write(self, off, size, value):
        if not self._has(off):
            raise KeyError
        self.rebase()
        if off == 0x00:
            self.cr1 = value & 0x3FF
        elif off == 0x04:
            self.cr2 = value
        elif off == 0x08:
            self.smcr = value
        elif off == 0x0C:
            self.dier = value
        elif off == 0x10:
            self.sr &= value  # rc_w0
        elif off == 0x14:
            if value & 1:  # UG: reload the prescaler, restart the count
                self.psc_active = self.psc
                self.cnt0 = 0
                if not self.cr1 & (1 << 2):  # URS = 0: UG sets UIF
                    self.sr |= 1
        elif off in (0x18, 0x1C):
            self.ccmr[(off - 0x18) // 4] = value
        elif off == 0x20:
            self.ccer = value
        elif off == 0x24:
            self.cnt0 = value & self.top
        elif off == 0x28:
            self.psc = value & 0xFFFF
        elif off == 0x2C:
            self.arr = value & self.top
        elif 0x34 <= off < 0x44:
            self.ccr[(off - 0x34) // 4] = value & self.top
        elif off in self.other:
            self.other[off] = value
        else:
            raise KeyError
        self.update_irq()
        self.schedule()
