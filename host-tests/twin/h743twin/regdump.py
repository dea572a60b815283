"""The registers the firmware sets up, as the chip model holds them a
while after reset: `python3 -m h743twin.regdump ELF [MS]` (default 40 ms).

One line per register, `NAME ADDRESS VALUE`, in the form a probe-rs read
gives on a board (docs/firmware.md, bench checklist), so that the two can
be compared line by line; docs/registers.md quotes these values."""

import sys

from .core import Stop
from .machine import Machine, cycles_of_ms

# (name, peripheral base, offset)
REGISTERS = (
    [("SPI1_" + n, 0x4001_3000, o) for n, o in (("CR1", 0), ("CR2", 4), ("CFG1", 8), ("CFG2", 0xC),
                                                ("IER", 0x10), ("SR", 0x14))]
    + [("DMAMUX1_C1CR", 0x4002_0800, 4), ("DMAMUX1_C2CR", 0x4002_0800, 8),
       ("DMA1_S1FCR", 0x4002_0000, 0x10 + 0x18 + 0x14)]
    + [("TIM13_" + n, 0x4000_1C00, o) for n, o in (("CR1", 0), ("DIER", 0xC), ("PSC", 0x28), ("ARR", 0x2C))]
    + [("TIM12_" + n, 0x4000_1800, o) for n, o in (("CR1", 0), ("DIER", 0xC), ("PSC", 0x28), ("ARR", 0x2C))]
    + [("USART3_" + n, 0x4000_4800, o) for n, o in (("CR1", 0), ("CR2", 4), ("CR3", 8), ("BRR", 0xC),
                                                    ("PRESC", 0x2C))]
    + [("RCC_" + n, 0x5802_4400, o) for n, o in (
        ("CR", 0), ("CFGR", 0x10), ("D1CFGR", 0x18), ("D2CFGR", 0x1C), ("D3CFGR", 0x20),
        ("PLLCKSELR", 0x28), ("PLLCFGR", 0x2C), ("PLL1DIVR", 0x30), ("D2CCIP1R", 0x50),
        ("D2CCIP2R", 0x54), ("RSR", 0xD0), ("AHB1ENR", 0xD8), ("AHB2ENR", 0xDC), ("AHB4ENR", 0xE0),
        ("APB1LENR", 0xE8), ("APB2ENR", 0xF0), ("APB4ENR", 0xF4))]
    + [("PWR_" + n, 0x5802_4800, o) for n, o in (("CR1", 0), ("CSR1", 4), ("CR3", 0xC), ("D3CR", 0x18))]
    + [("FLASH_ACR", 0x5200_2000, 0), ("SYSCFG_EXTICR3", 0x5800_0400, 0x10),
       ("SYSCFG_CCCSR", 0x5800_0400, 0x20), ("EXTI_RTSR1", 0x5800_0000, 0),
       ("EXTI_CPUIMR1", 0x5800_0000, 0x80), ("IWDG1_PR", 0x5800_4800, 4), ("IWDG1_RLR", 0x5800_4800, 8),
       ("DBGMCU_CR", 0x5C00_1000, 4), ("DBGMCU_APB4FZ1", 0x5C00_1000, 0x54)]
    + [(f"GPIO{p}_{n}", 0x5802_0000 + 0x400 * "ABCDEFGHIJK".index(p), o)
       for p in "ADE" for n, o in (("MODER", 0), ("OSPEEDR", 8), ("PUPDR", 0xC), ("AFRL", 0x20),
                                   ("AFRH", 0x24))]
)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) not in (1, 2):
        print("usage: python3 -m h743twin.regdump ELF [MS]", file=sys.stderr)
        return 2
    m = Machine(argv[0])
    try:
        m.run(cycles_of_ms(float(argv[1]) if len(argv) == 2 else 40.0))
    except Stop as e:
        print(f"regdump: {argv[0]}: the run stopped: {e}", file=sys.stderr)
        return 1
    models = {base: model for base, _, model in m.bus.periphs}
    for name, base, off in REGISTERS:
        print(f"{name:16} {base + off:#010x} {models[base].read(off, 4):#010x}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
