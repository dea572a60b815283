"""Boots a built H743 ELF on the chip model: `python3 -m h743twin.smoke ELF`.

First without a detector. Passes when the firmware gets through
its reset path and `embassy_stm32::init` without touching anything the
model does not model, runs its core at 400 MHz, freezes the watchdog under
a debugger, unleashes it and keeps feeding it, and the chip never resets.

Then with DRDY edges every 0.25 us from 10 us after reset for 2 ms, through
the whole start-up: the firmware must come up the same way and take DRDY
interrupts only as beams (no interrupt storm from an edge that arrives
before its handler is ready)."""

import sys

from .core import Stop
from .detector import Detector, Scan
from .machine import Machine, cycles_of_ms

RUN_MS = 300


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python3 -m h743twin.smoke ELF", file=sys.stderr)
        return 2
    m = Machine(argv[0])
    try:
        m.run(cycles_of_ms(RUN_MS))
    except Stop as e:
        print(f"smoke: {argv[0]}: the run stopped: {e}", file=sys.stderr)
        return 1
    s = m.stats()
    problems = []
    if s["resets"]:
        problems.append(f"resets {s['resets']}")
    if not s["watchdog_running"]:
        problems.append("the watchdog was never started")
    if s["watchdog_feeds"] < RUN_MS // 200:
        problems.append(f"only {s['watchdog_feeds']} watchdog feeds in {RUN_MS} ms")
    if not s["iwdg_frozen_in_debug"]:
        problems.append("the watchdog is not frozen under a debugger (DBGMCU_APB4FZ1.IWDG1)")
    if s["hardfaults"] or s["lockups"]:
        problems.append(f"{s['hardfaults']} HardFault(s), {s['lockups']} lockup(s): {s['fault']}")
    if s["sysclk_hz"] != 400e6:
        problems.append(f"core clock {s['sysclk_hz'] / 1e6} MHz, not 400")
    print(f"smoke: {argv[0]}: {s['instructions']} instructions in {RUN_MS} ms, "
          f"{s['watchdog_feeds']} watchdog feeds, {s['interrupts']} interrupts, "
          f"core clock {s['sysclk_hz'] / 1e6:.0f} MHz")
    problems += early_edges(argv[0])
    if problems:
        print(f"smoke: {argv[0]}: " + "; ".join(problems), file=sys.stderr)
        return 1
    return 0


def early_edges(elf):
    """DRDY edges every 0.25 us from 10 us after reset for 2 ms (a detector
    that does not wait for the board), then the board runs on."""
    beams = 8000
    scan = Scan(1, beams, 1, 1, [1000] * beams)
    m = Machine(elf)
    det = Detector(m, scan, 0.25, 0.01, [])
    m.attach(det)
    try:
        status = m.run(cycles_of_ms(RUN_MS), lambda: m.core.nvic.taken[23] > 2 * beams,
                       max_instructions=60_000_000)
    except Stop as e:
        return [f"with early DRDY edges the run stopped: {e}"]
    s = m.stats()
    drdy_irqs = s["irq_counts"].get("23", 0)
    problems = []
    if status != "time":
        problems.append(f"with early DRDY edges the run ended on '{status}' after {s['cycles'] / 4e5:.3f} ms")
    if s["resets"]:
        problems.append(f"with early DRDY edges: resets {s['resets']}")
    if drdy_irqs > beams:
        problems.append(f"with early DRDY edges: {drdy_irqs} DRDY interrupts for {beams} edges (a storm)")
    if s["watchdog_feeds"] < RUN_MS // 200:
        problems.append(f"with early DRDY edges: only {s['watchdog_feeds']} watchdog feeds")
    print(f"smoke: {elf}: {beams} DRDY edges from 10 us after reset: {drdy_irqs} DRDY interrupts, "
          f"{s['watchdog_feeds']} watchdog feeds")
    return problems


if __name__ == "__main__":
    sys.exit(main())
