"""Instructions per beam of an H743 ELF by stage, on the chip model:
`python3 -m h743twin.profile ELF J1 J2 [--rows R --cols C --beam-us P]`.

Runs a random scan of the ELF's geometry (the ELF must be built for it:
`CVM_H743_SCAN="j1=.. j2=.. cols=.. rows=.."`), counts the instructions of
every function from the first beam on, and sums them by stage. Prints a
Markdown table; `scoring path` is what the emulated board's icount figures
cover (sequencing, frame to scores, line encoding and queueing)."""

import argparse
import random
import sys

from .core import Stop
from .detector import Detector, Scan
from .machine import Machine, cycles_of_ms

# (stage, substrings of function paths), first match wins.
STAGES = (
    ("sum and largest sample", ("sum_and_peak",)),
    ("spread channel's measure", ("cvm_core::spread",)),
    ("embedding: row pass", ("embed::rows", "cvm_rows_")),
    ("embedding: column pass", ("embed::cols", "embed::copy_words", "cvm_cols_")),
    ("embedding: square kernels' fold and factors", ("scorer::square", "cvm_square_")),
    ("distances", ("squared_difference", "square_distance", "sat_distance")),
    ("normalise, gradient, window", ("cvm_core::scorer", "cvm_core::stream", "magnitude")),
    ("defect objects", ("cvm_core::objects",)),
    ("sequencing", ("cvm_fw_app::driver", "cvm_fw_app::sequence", "cvm_fw_app::acquire")),
    ("line encoding and queue", ("cvm_core::protocol", "cvm_core::pipeline", "LineSink", "cvm_fw_app::queue",
                                 "QueueSink")),
    ("DRDY and SPI DMA interrupts", ("EXTI9_5", "DMA1_STREAM1", "frame_reader")),
    ("UART DMA", ("DMA1_STREAM2", "usart", "embassy_stm32::dma")),
    # The async task bodies (acquisition read, scoring loop, UART loop) are
    # inlined into the executor's poll of their task storage.
    ("task bodies", ("TaskStorage", "cvm_fw::h743::tasks")),
    ("executor, time, logging", ("embassy", "UART4", "TIM8_BRK_TIM12", "defmt", "critical_section",
                                 "PollFn", "poll_fn")),
    ("memcpy/memset, division", ("compiler_builtins", "__aeabi", "__udivmoddi4")),
)
SCORING = {"sum and largest sample", "spread channel's measure", "embedding: row pass",
           "embedding: column pass", "embedding: square kernels' fold and factors", "distances",
           "normalise, gradient, window", "defect objects", "sequencing", "line encoding and queue"}


def stage_of(name):
    for stage, keys in STAGES:
        if any(k in name for k in keys):
            return stage
    return "other"


def add_scan_args(ap):
    """The ELF, its geometry, and the random scan to run."""
    ap.add_argument("elf")
    ap.add_argument("j1", type=int)
    ap.add_argument("j2", type=int)
    ap.add_argument("--rows", type=int, default=6)
    ap.add_argument("--cols", type=int, default=12)
    ap.add_argument("--beam-us", type=float, default=400.0)
    ap.add_argument("--seed", type=int, default=1)
    # The square kernels' factor table is built at start-up: about 80 ms
    # at 15x15 (docs/firmware.md), after the default first beam.
    ap.add_argument("--start-ms", type=float, default=20.0, help="first beam after reset (default 20)")


def boot_for_scan(args):
    """A machine with the ELF booted up to just before the first beam of a
    random scan (`add_scan_args`), counting instructions per function."""
    rng = random.Random(args.seed)
    n = args.rows * args.cols * args.j1 * args.j2
    scan = Scan(args.rows, args.cols, args.j1, args.j2, [rng.randint(100, 4000) for _ in range(n)])
    m = Machine(args.elf)
    det = Detector(m, scan, args.beam_us, args.start_ms, [])
    m.attach(det)
    m.run(det.times[0] - 1000)
    m.start_profile()
    return m, det


def main(argv=None):
    ap = argparse.ArgumentParser(prog="h743twin.profile")
    add_scan_args(ap)
    ap.add_argument("--top", type=int, default=0, help="also list the N costliest functions")
    args = ap.parse_args(argv)
    try:
        m, det = boot_for_scan(args)
        # Up to the last beam plus the time to score and send it.
        m.run(det.done_at + cycles_of_ms(5))
    except Stop as e:
        print(f"profile: the run stopped: {e}", file=sys.stderr)
        return 1
    beams = det.sent
    by_stage = {}
    for name, count in m.core.profile.items():
        st = stage_of(name)
        by_stage[st] = by_stage.get(st, 0) + count
    total = sum(by_stage.values())
    scoring = sum(v for k, v in by_stage.items() if k in SCORING)
    print(f"| stage ({args.j1}x{args.j2}, {beams} beams) | instructions per beam |")
    print("|---|---:|")
    def num(x):
        return f"{x / beams:,.0f}".replace(",", " ")

    for stage, _ in STAGES + (("other", ()),):
        if stage in by_stage:
            print(f"| {stage} | {num(by_stage[stage])} |")
    print(f"| **scoring path** | **{num(scoring)}** |")
    print(f"| **all** | **{num(total)}** |")
    if args.top:
        print()
        for name, count in sorted(m.core.profile.items(), key=lambda kv: -kv[1])[:args.top]:
            print(f"{count / beams:10.1f}  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
