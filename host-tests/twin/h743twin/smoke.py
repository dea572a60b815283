"""Boots a built H743 ELF on the chip model without a detector:
`python3 -m h743twin.smoke ELF`. Passes when the firmware gets through
its reset path and `embassy_stm32::init` without touching anything the
model does not model, runs its core at 400 MHz, freezes the watchdog under
a debugger, unleashes it and keeps feeding it, and the chip never resets."""

import sys

from .core import Stop
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
    if s["sysclk_hz"] != 400e6:
        problems.append(f"core clock {s['sysclk_hz'] / 1e6} MHz, not 400")
    print(f"smoke: {argv[0]}: {s['instructions']} instructions in {RUN_MS} ms, "
          f"{s['watchdog_feeds']} watchdog feeds, {s['interrupts']} interrupts, "
          f"core clock {s['sysclk_hz'] / 1e6:.0f} MHz")
    if problems:
        print(f"smoke: {argv[0]}: " + "; ".join(problems), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
