#!/usr/bin/env bash
# Instructions per beam by function of the emulated board's firmware
# (QEMU mps2-an386, Cortex-M4F), for one map size and kernel set:
#
#   scripts/emulate-profile.sh [paper|square] [J]     (default: square 15)
#
# QEMU logs every translated block and every execution of one (-d
# in_asm,exec,nochain); a block's instructions count once per execution,
# under the function QEMU names for it. Everything the firmware runs is
# counted (reading the scan file, the scoring path, the UART), on two
# random scans of 12 columns, 2 and 6 rows: the difference divided by the
# 48 beams more is the cost per beam, without what the firmware does once
# (start-up, building the scorer's tables). The functions of the scoring
# path add up to about what `scripts/emulate-icount.sh` measures with the
# board's SysTick. TOP=n lists n functions (default 20). Idempotent;
# installs what it needs (thumbv7em target, qemu-system-arm).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
kernels=${1:-square}
j=${2:-15}
case $kernels in paper | square) ;; *)
    echo "kernels: paper or square, not '$kernels'" >&2
    exit 2
    ;;
esac
case $j in [1-9] | 1[0-6]) ;; *)
    echo "map size: 1 to 16, not '$j'" >&2
    exit 2
    ;;
esac
bash "$root/scripts/emulate-setup.sh"
(cd "$root/host-tests" && cargo build -q --release -p dmap)
dmap="$root/host-tests/target/x86_64-unknown-linux-gnu/release/dmap"
[ -x "$dmap" ] || dmap="$root/host-tests/target/release/dmap"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

cols=12
# A random scan of `rows` x 12 maps of J x J.
scan() {
    python3 "$root/scripts/random_scan.py" "$work/scan$1.npy" "$j" "$1" "$cols"
}

# dmap starts qemu-system-arm from PATH: this one logs the blocks to
# $CVM_TRACE.
mkdir -p "$work/bin"
real="$(command -v qemu-system-arm)"
printf '#!/bin/sh\nexec "%s" -d in_asm,exec,nochain -D "$CVM_TRACE" "$@"\n' "$real" \
    >"$work/bin/qemu-system-arm"
chmod +x "$work/bin/qemu-system-arm"
for rows in 2 6; do
    scan "$rows"
    # (The board's own summary line is dropped: without -icount its
    # SysTick counts host time, not instructions.)
    CVM_TRACE="$work/trace$rows" PATH="$work/bin:$PATH" \
        "$dmap" emulate "$work/scan$rows.npy" --kernels "$kernels" --scores \
        2> >(grep -v '^cvm-fw (emulated):' >&2) >/dev/null
done

python3 - "$work/trace2" "$work/trace6" "$((4 * cols))" "${TOP:-20}" "$kernels" "$j" <<'PY'
import collections, re, sys
short, long, beams, top, kernels, j = sys.argv[1:]
beams, top = int(beams), int(top)
insn = re.compile(r"^0x([0-9a-f]+):")
execd = re.compile(r"^Trace \d+: \S+ \[[0-9a-f]+/([0-9a-f]+)/[0-9a-f]+/[0-9a-f]+\] ?(.*)$")


def demangle(sym):
    """Rust's legacy mangling (_ZN...17h<hash>E) to a path, hash dropped."""
    if not (sym.startswith("_ZN") and sym.endswith("E")):
        return sym
    parts, i, body = [], 0, sym[3:-1]
    while i < len(body) and body[i].isdigit():
        k = i
        while body[k].isdigit():
            k += 1
        n = int(body[i:k])
        parts.append(body[k:k + n])
        i = k + n
    if parts and re.fullmatch(r"h[0-9a-f]{16}", parts[-1]):
        parts.pop()
    out = "::".join(parts)
    for a, b in (("$LT$", "<"), ("$GT$", ">"), ("$u20$", " "), ("$u7b$", "{"),
                 ("$u7d$", "}"), ("$C$", ","), ("$RF$", "&"), ("..", "::")):
        out = out.replace(a, b)
    return out or sym


def profile(trace):
    """Instructions executed per function."""
    size, runs, name = {}, collections.Counter(), {}
    start, n = None, 0
    with open(trace, errors="replace") as f:
        for line in f:
            if line.startswith("IN:"):
                start, n = None, 0
            elif m := insn.match(line):
                start = int(m.group(1), 16) if start is None else start
                n += 1
                size[start] = n  # a block translated again replaces the old
            elif m := execd.match(line):
                pc = int(m.group(1), 16)
                runs[pc] += 1
                name[pc] = m.group(2).strip() or hex(pc)
    per = collections.Counter()
    for pc, k in runs.items():
        per[demangle(name[pc])] += k * size.get(pc, 0)
    return per


per = profile(long)
per.subtract(profile(short))
total = sum(per.values())
print(f"{j}x{j} {kernels} kernels: {total / beams:,.0f} instructions per beam in all\n")
print("| function | instructions per beam |")
print("|---|---:|")
for fn, k in per.most_common(top):
    print(f"| `{fn}` | {k / beams:,.0f} |")
PY
