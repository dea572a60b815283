"""Command line of the chip model: `python3 -m h743twin ELF [options]`.

Prints the bytes the firmware sends on USART3 to stdout as they come and the
model's counters as one JSON object on stderr (last line). An ELF or scan it
cannot load is one line on stderr and exit status 4."""

import argparse
import json
import sys

from .core import Stop
from .flash import ECC_MODES, PSIZE_NAMES, Bank2, PowerCut
from .usart_rx import LiveHost, parse_requests
from .detector import Detector, Scan, parse_fault
from .machine import Machine, cycles_of_ms


def main(argv=None):
    ap = argparse.ArgumentParser(prog="h743twin", description=__doc__)
    ap.add_argument("elf")
    ap.add_argument("--scan", help="scan in the twin's format (written by `dmap twin`)")
    ap.add_argument("--beam-us", type=float, default=200.0, help="DRDY period (default 200)")
    ap.add_argument("--start-ms", type=float, default=20.0, help="first beam after reset (default 20)")
    ap.add_argument("--fault", action="append", default=[], help="KIND@BEAM[:ARG...] (see detector.py)")
    ap.add_argument("--settle-ms", type=float, default=1500.0,
                    help="run at most this long after the last beam (default 1500)")
    ap.add_argument("--run-ms", type=float, help="without --scan: run this long")
    ap.add_argument("--debugger", action="store_true", help="a debugger is attached (DBGMCU freeze applies)")
    ap.add_argument("--scans", type=int, default=1, help="end lines to wait for (default 1)")
    ap.add_argument("--max-instructions", type=int, help="stop after this many instructions")
    ap.add_argument("--profile", action="store_true",
                    help="instructions per function from the first beam on (in the JSON)")
    ap.add_argument("--requests", help="what the host sends on USART3 and at which beams (usart_rx.py)")
    ap.add_argument("--stdin-requests", action="store_true",
                    help="also send on USART3 what arrives on standard input, as it arrives "
                         "(a live host: dmap console)")
    ap.add_argument("--flash", help="bank 2's contents: loaded if the file exists, saved at the end")
    ap.add_argument("--power-cut", type=int, metavar="N", help="cut power at the N-th flash operation")
    ap.add_argument("--psize", choices=["x8", "x16", "x32", "x64", "any"], default="x64",
                    help="the flash parallelism (FLASH_CR2.PSIZE) the firmware means: an erase or "
                         "program started with another stops the run (default x64, the fastest "
                         "the 3.3 V supply allows; any: no check)")
    ap.add_argument("--clock-drops", choices=["stop", "count", "keep"], default="stop",
                    help="a peripheral access within two bus clock cycles of its RCC enable is lost "
                         "on silicon: stop the run there (default), drop it, count it "
                         "(clock_enable_drops) and go on, or count it and let it through (keep: "
                         "to see an earlier firmware's other faults)")
    ap.add_argument("--ecc", choices=ECC_MODES, default="double",
                    help="what a flash word programmed twice or cut reads back as: a double ECC "
                         "error (bus error, DBECCERR; default), a single one corrected into wrong "
                         "data (SNECCERR, one bit flipped), or no error at all")
    args = ap.parse_args(argv)

    try:
        faults = [parse_fault(f) for f in args.fault]
        requests = parse_requests(args.requests) if args.requests else []
        bank2 = Bank2.load(args.flash) if args.flash else Bank2()
    except (ValueError, Stop) as e:
        print(f"h743twin: {e}", file=sys.stderr)
        return 2
    if requests and not args.scan:
        print("h743twin: --requests needs --scan (requests start at beams)", file=sys.stderr)
        return 2
    bank2.cut_at = args.power_cut
    # Whatever a damaged file makes the loaders raise is one line, not a
    # traceback.
    try:
        psize = None if args.psize == "any" else PSIZE_NAMES.index(args.psize)
        m = Machine(args.elf, debugger=args.debugger, bank2=bank2, psize=psize,
                    clock_drops_stop=args.clock_drops == "stop", ecc=args.ecc)
    except Exception as e:  # noqa: BLE001
        print(f"h743twin: cannot load the ELF {args.elf}: {type(e).__name__}: {e}", file=sys.stderr)
        return 4
    m.bus.clock_drops_keep = args.clock_drops == "keep"
    try:
        scan = Scan.read_raw(args.scan) if args.scan else None
    except Exception as e:  # noqa: BLE001
        print(f"h743twin: cannot load the scan {args.scan}: {type(e).__name__}: {e}", file=sys.stderr)
        return 4
    live = LiveHost(sys.stdin.buffer) if args.stdin_requests else None
    status = "time"
    error = None
    sent = 0

    def pump(final=False):
        # The UART bytes so far, out at each line's end (or every 4 KiB):
        # whoever reads sees lines as the firmware sends them, and an
        # interrupted run has shown what it got to.
        nonlocal sent
        if live is not None:
            live.deliver(m.usart.rx)
        n = len(m.uart)
        if n > sent and (final or n - sent >= 4096 or m.uart[n - 1][0] == 0x0A):
            sys.stdout.buffer.write(bytes(b for b, _ in m.uart[sent:n]))
            sys.stdout.flush()
            sent = n

    def pumping():
        pump()
        return False
    try:
        if scan is not None:
            det = Detector(m, scan, args.beam_us, args.start_ms, faults)
            m.attach(det)
            for beam, data, errors in requests:
                if beam >= len(det.times):
                    raise Stop(f"request at beam {beam}: the scan has {len(det.times)} beams")
                m.bus.at(det.times[beam], lambda d=data, e=errors: m.usart.rx.send(d, e), owner="host")
            if args.profile:
                # Boot first, then count: the profile is of the beams.
                m.run(max(det.times[0] - 1000, 0) if det.times else 0, pumping)
                m.start_profile()
            end = det.done_at + cycles_of_ms(args.settle_ms)

            out = bytearray()  # the UART's bytes so far, added to as they come

            def done():
                pump()
                if m.core.cycles <= det.done_at:
                    return False
                out.extend(b for b, _ in m.uart[len(out):])
                ends = out.count(b"\nE,") + (1 if out.startswith(b"E,") else 0)
                return ends >= args.scans and out.endswith(b"\n") and not m.usart.shifting
            status = m.run(end, done, args.max_instructions)
        else:
            status = m.run(cycles_of_ms(args.run_ms or 100.0), pumping, args.max_instructions)
    except PowerCut as e:
        status = "power cut"
        stats_note = str(e)
    except Stop as e:
        error = str(e)
    if args.flash:
        m.bank2.save(args.flash)
    pump(final=True)
    stats = m.stats()
    stats["status"] = "error" if error else status
    if status == "power cut":
        stats["power_cut"] = stats_note
    if error:
        stats["error"] = error
    print(json.dumps(stats), file=sys.stderr)
    return 3 if error else 0


if __name__ == "__main__":
    sys.exit(main())
