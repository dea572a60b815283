#!/usr/bin/env bash
# Every measurement the docs quote, one subcommand each. Each installs what
# it needs (scripts/setup.sh) and builds what it runs.
usage() {
    cat >&2 <<'EOF'
usage: scripts/measure.sh WHAT [ARGS]
  icount                       instructions per beam, scoring path, emulated Cortex-M4 (QEMU
                               -icount): 9x9 and 15x15, paper and square kernels (emulation.md)
  profile [paper|square] [J]   instructions per beam by function, emulated Cortex-M4 (default
                               square 15; TOP=n functions, default 20) (emulation.md)
  twin-profile                 instructions per beam by stage, H743 release ELF on the chip
                               model, 9x9 and 15x15 (KERNELS=square, TOP=n) (twin.md)
  latency                      READY/REJECT latency: a 4 x 300 paper-sim part at 9x9 (53 us)
                               and 15x15 (146 us) on the chip model, REJECT's edge after
                               the last frame's read (firmware.md)
  store-boot                   start-up cost of the settings store, H743 release ELF (default
                               configuration) on the chip model, per bank-2 content (firmware.md)
  twin-cost [ARGS]             estimated cycles per beam on the H743 (the chip model's bus and
                               D-cache cost model; KERNELS, COLS, ROWS; ARGS go to
                               h743twin.cost, e.g. --dtcm ROW_A) (performance.md)
  objects LINES TRUTH [P]      the firmware's defect objects (O lines) against a truth mask,
                               P the scan pitch in um (default 334) (experiments.md)
  experiments [OUT_DIR]        the paper's experiments rerun, about 45 minutes (REUSE=1 keeps
                               scans and EMD scores already in OUT_DIR) (experiments.md)
  calibration-rule [OUT_DIR]   the calibration rules (exact medians, spread, tail, maxima)
                               against each other: thresholds, the firmware's objects on the
                               defective part and 20 unseen good parts per set-up, the tail
                               fit against them; simulates the scans OUT_DIR lacks
                               (experiments.md)
  emd-vs-pot [--pairs N]       exact EMD against POT's ot.emd2 (needs numpy, pot) (performance.md)
  soak [WORKDIR]               a full paper-sim scan on the emulated firmware against the host,
                               byte for byte, every position accounted for (reliability.md)
EOF
    exit 2
}
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
what=${1:-}
[ $# -gt 0 ] && shift

# The host tools, built once; `dmap` runs the release binary.
dmap_bin=
build_dmap() {
    (cd "$root/host-tests" && nice -n 10 cargo build --release -q -p dmap)
    dmap_bin=$root/host-tests/target/x86_64-unknown-linux-gnu/release/dmap
    [ -x "$dmap_bin" ] || dmap_bin=$root/host-tests/target/release/dmap
}
dmap() { "$dmap_bin" "$@"; }

# Scratch directories, removed on exit.
scratch_dirs=()
trap 'rm -rf "${scratch_dirs[@]}"' EXIT
scratch() { scratch_dirs+=("$(mktemp -d)"); }

# A scan of ROWS x COLS beams of a J x J detector from the middle of the
# paper-sim part (seeded, so every run scores the same maps).
sim_scan() { # OUT J ROWS COLS
    dmap simulate --preset paper-sim --detector "$2x$2" --rows "$3" --cols "$4" --seed 1 \
        -o "$1" --truth "${1%.npy}.truth.npy" >/dev/null 2>&1
}

# The square kernels build their factor table at start-up (about 80 ms at
# 15x15 on the H743): the chip model starts the scan after it.
twin_start_ms() { if [ "${KERNELS:-paper}" = paper ]; then echo 20; else echo 200; fi; }

# The H743 release ELF for a J x J scan of COLS x ROWS beams, into target/twin.
twin_elf() { # J COLS ROWS
    CVM_H743_SCAN="j1=$1 j2=$1 cols=$2 rows=$3 scores=1 kernels=${KERNELS:-paper}" \
        cargo build --release --target-dir "$root/target/twin" >&2
    echo "$root/target/twin/thumbv7em-none-eabihf/release/cvm-fw"
}

icount() {
    bash "$root/scripts/setup.sh"
    build_dmap
    local work j k line
    scratch
    work=${scratch_dirs[-1]}
    echo "| map | kernels | instructions per beam | beams |"
    echo "|---|---|---:|---:|"
    for j in 9 15; do
        sim_scan "$work/scan$j.npy" "$j" 30 40
        for k in paper square; do
            line=$(dmap emulate "$work/scan$j.npy" --kernels "$k" --scores --icount 2>&1 >/dev/null |
                grep instructions_per_beam)
            echo "| ${j}x${j} | $k | $(sed -E 's/.*instructions_per_beam=([0-9]+).*/\1/' <<<"$line") |" \
                "$(sed -E 's/.*beams=([0-9]+).*/\1/' <<<"$line") |"
        done
    done
}

# QEMU logs every translated block and every execution of one (-d
# in_asm,exec,nochain); a block's instructions count once per execution,
# under the function QEMU names for it. Two scans of 12 columns, 2 and 6
# rows: the difference divided by the 48 beams more is the cost per beam,
# without what the firmware does once (start-up, the scorer's tables).
profile() {
    local kernels=${1:-square} j=${2:-15} cols=12 rows work real
    case $kernels in paper | square) ;; *) echo "kernels: paper or square, not '$kernels'" >&2 && exit 2 ;; esac
    case $j in [1-9] | 1[0-6]) ;; *) echo "map size: 1 to 16, not '$j'" >&2 && exit 2 ;; esac
    bash "$root/scripts/setup.sh"
    build_dmap
    scratch
    work=${scratch_dirs[-1]}
    # dmap starts qemu-system-arm from PATH: this one logs the blocks to $CVM_TRACE.
    mkdir -p "$work/bin"
    real=$(command -v qemu-system-arm)
    printf '#!/bin/sh\nexec "%s" -d in_asm,exec,nochain -D "$CVM_TRACE" "$@"\n' "$real" >"$work/bin/qemu-system-arm"
    chmod +x "$work/bin/qemu-system-arm"
    for rows in 2 6; do
        sim_scan "$work/scan$rows.npy" "$j" "$rows" "$cols"
        # Without -icount the board's SysTick counts host time: its summary line is dropped.
        CVM_TRACE="$work/trace$rows" PATH="$work/bin:$PATH" \
            "$dmap_bin" emulate "$work/scan$rows.npy" --kernels "$kernels" --scores \
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
}

twin_profile() {
    bash "$root/scripts/setup.sh"
    local j elf
    for j in 9 15; do
        elf=$(twin_elf "$j" 12 6)
        (cd "$root/host-tests/twin" && python3 -m h743twin.profile "$elf" "$j" "$j" --top "${TOP:-0}" \
            --start-ms "$(twin_start_ms)")
        echo
    done
}

# REJECT's latency in part mode at the SPI-limit beam rates: 4 x 300
# paper-sim parts (the release width), the H743 release ELF built for
# them by `dmap twin`, the edge timed from the end of the last frame read.
latency() {
    bash "$root/scripts/setup.sh"
    build_dmap
    local work j p
    scratch
    work=${scratch_dirs[-1]}
    for j in 9 15; do
        p=$([ "$j" = 9 ] && echo 53 || echo 146)
        sim_scan "$work/s$j.npy" "$j" 4 300
        "$dmap_bin" twin "$work/s$j.npy" --beam-us "$p" --pins "$work/p$j.csv" \
            >"$work/o$j.txt" 2>"$work/e$j.txt"
        echo "${j}x${j} at $p us: $(grep -m1 '^E,' "$work/o$j.txt" | grep -o 'defects=[0-9]*,obj=[0-9]*'), $(grep -m1 'pin REJECT high' "$work/e$j.txt")"
    done
}

# The settings store at start-up: the default release ELF booted on the
# chip model until it takes beams, with an erased bank 2 and with the
# images `store_images` writes (one record; a full first page, the longest
# load; a full page whose next save was cut while erasing, which the load
# repairs with one erase).
store_boot() {
    bash "$root/scripts/setup.sh"
    (cd "$root" && cargo build --release -q)
    local work
    scratch
    work=${scratch_dirs[-1]}
    (cd "$root/host-tests" && cargo run -q --release -p cvm-fw-app-tests --example store_images -- "$work")
    (cd "$root/host-tests/twin" && python3 -m h743twin.bootcost \
        "$root/target/thumbv7em-none-eabihf/release/cvm-fw" \
        "$work/erased.bin" "$work/one.bin" "$work/full.bin" "$work/erase-cut.bin")
}

# The scan is as wide as the default configuration's (300 columns; COLS and
# ROWS change that): a row buffer of a narrow scan would fit the D-cache,
# one of 300 maps does not.
twin_cost() {
    bash "$root/scripts/setup.sh"
    # The cost model decodes instructions with Capstone.
    if ! python3 -c "import capstone" >/dev/null 2>&1; then
        echo "measure: installing capstone" >&2
        python3 -m pip install --quiet --disable-pip-version-check capstone==5.0.7
    fi
    local cols=${COLS:-300} rows=${ROWS:-6} j elf
    for j in 9 15; do
        elf=$(twin_elf "$j" "$cols" "$rows")
        (cd "$root/host-tests/twin" && python3 -m h743twin.cost "$elf" "$j" "$j" \
            --cols "$cols" --rows "$rows" --start-ms "$(twin_start_ms)" "$@")
        echo
    done
}

# The firmware's objects against the truth: the lines decoded by `dmap
# listen --json` (every checksum checked), the truth components and the
# peaks near them from `dmap eval --json` on the decoded score images. Per
# truth component (in raster order of its first position) the objects
# whose bounding box meets the component's grown by one position (Eq. 1's
# reach: a position next to a defect scores, and the power channel fires
# around a dimmed beam rather than on it), their union's extent against the
# truth's, as detected and corrected by one position per side; objects
# meeting no component are false. Fails when the stream is damaged.
objects() { # LINES TRUTH [PITCH_UM]
    [ $# -ge 2 ] || usage
    [ -n "$dmap_bin" ] || build_dmap
    local work
    scratch
    work=${scratch_dirs[-1]}
    python3 - "$dmap_bin" "$1" "$2" "${3:-334}" "$work" <<'PY'
import json, math, subprocess, sys
dmap, lines, truth, pitch, work = sys.argv[1:]


def run(*args):
    done = subprocess.run([dmap, *args], capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"measure objects: dmap {args[0]} failed (status {done.returncode}):\n"
                 + (done.stderr or done.stdout))
    return json.loads(done.stdout)


listen = run("listen", "--input", lines, "--json", "--pitch-um", pitch, "-o", f"{work}/cvm.npy",
             "--power-output", f"{work}/power.npy")
header = listen["scans"][-1]["header"]
pthr = header["power_threshold"]
cvm, power = (run("eval", f"{work}/{image}.npy", "--truth", truth, "--threshold", str(t), "--pitch-um",
                  pitch, "--json")["objects"]["defects"]
              for image, t in (("cvm", header["threshold"]), ("power", 1e9 if pthr is None else pthr)))
objs = listen["objects"]
unobj = (listen["totals"] or {}).get("unobj", 0)


def chan(names):
    return "+".join(n for n in ("cvm", "power") if n in names) or "-"


def peak(v):
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.4g}"


used, found = set(), 0
for t, pw in zip(cvm, power):
    (r0, r1), (c0, c1), area = t["truth"]["rows"], t["truth"]["cols"], t["truth"]["area"]
    th, tw = r1 - r0 + 1, c1 - c0 + 1
    peaks = "" if not header["scores"] else (f" [peaks: cvm {peak(t['peak'])} vs thr {header['threshold']:.4g}, power {peak(pw['peak'])} vs "
             + ("off" if pthr is None else f"{pthr:.4f}") + "]")
    head = f"  truth rows {r0}-{r1} cols {c0}-{c1} ({th}x{tw}, area {area}) -> "
    hit = [o for o in objs if o["rows"][0] <= r1 + 1 and o["rows"][1] >= r0 - 1
           and o["cols"][0] <= c1 + 1 and o["cols"][1] >= c0 - 1]
    if not hit:
        print(head + "missed" + peaks)
        continue
    found += 1
    used.update(o["id"] for o in hit)
    o0, o1 = min(o["rows"][0] for o in hit), max(o["rows"][1] for o in hit)
    p0, p1 = min(o["cols"][0] for o in hit), max(o["cols"][1] for o in hit)
    h, w = o1 - o0 + 1, p1 - p0 + 1
    ch, cw = max(h - 2, 1), max(w - 2, 1)
    names = {n for o in hit for n in o["channels"]}
    print(head + f"{len(hit)} object(s), rows {o0}-{o1} cols {p0}-{p1} ({h}x{w}, area "
          f"{sum(o['area'] for o in hit)}), error rows {100 * (h - th) / th:+.0f} % cols "
          f"{100 * (w - tw) / tw:+.0f} % (corrected {ch}x{cw}: {100 * (ch - th) / th:+.0f} % / "
          f"{100 * (cw - tw) / tw:+.0f} %), channels {chan(names)}" + peaks)
false = [o for o in objs if o["id"] not in used]
print(f"{found}/{len(cvm)} defects found, {len(false)} false objects, {len(objs)} objects, "
      f"{unobj} defective position(s) outside every object")
for o in false:
    print(f"  false: rows {o['rows'][0]}-{o['rows'][1]} cols {o['cols'][0]}-{o['cols'][1]} "
          f"area {o['area']} channels {chan(o['channels'])}")
PY
}

soak() {
    local work t0 s lines bytes want
    work=$(mkdir -p "${1:-$root/target/soak}" && cd "${1:-$root/target/soak}" && pwd)
    t0=$(date +%s)
    step() { printf '\n== soak: %s\n' "$*" >&2; }
    step "build dmap (release)"
    build_dmap
    if [ ! -f "$work/scan.npy" ]; then
        step "simulate the paper-sim scan"
        s=$(date +%s)
        dmap simulate --preset paper-sim -o "$work/scan.npy" --truth "$work/truth.npy"
        echo "soak: simulated in $(($(date +%s) - s)) s" >&2
    fi
    step "host pipeline (dmap stream --scores)"
    s=$(date +%s)
    dmap stream "$work/scan.npy" --scores >"$work/host.lines"
    echo "soak: host stream in $(($(date +%s) - s)) s" >&2
    step "emulated firmware (dmap emulate --scores)"
    s=$(date +%s)
    dmap emulate "$work/scan.npy" --scores >"$work/firmware.lines"
    echo "soak: emulated firmware in $(($(date +%s) - s)) s" >&2
    step "compare"
    if ! cmp "$work/host.lines" "$work/firmware.lines"; then
        echo "soak: FAILED: the emulated firmware's output differs from the host's" >&2
        exit 1
    fi
    lines=$(wc -l <"$work/firmware.lines")
    bytes=$(wc -c <"$work/firmware.lines")
    echo "soak: byte-identical ($lines lines, $bytes bytes)" >&2
    step "decode and account (dmap listen)"
    dmap listen --input "$work/firmware.lines" -o "$work/image.npy" | tee "$work/summary.txt" >&2
    want="scores: 90000 positions with data, 0 without data"
    grep -q "$want" "$work/summary.txt" || { echo "soak: FAILED: expected '$want'" >&2 && exit 1; }
    grep -q "totals: rows 300 frames 90000 missing 0 .* rejected 0 extra 0 bad 0 clipped 0 misplaced 0 dropped 0" \
        "$work/summary.txt" || { echo "soak: FAILED: end-of-scan totals" >&2 && exit 1; }
    grep -q "^line errors: 0$" "$work/summary.txt" || { echo "soak: FAILED: damaged lines" >&2 && exit 1; }
    if grep -q "^  problem" "$work/summary.txt"; then
        echo "soak: FAILED: decoder problems" >&2
        exit 1
    fi
    echo "soak: ok: 90000 of 90000 positions scored, identical on host and emulated firmware," \
        "in $(($(date +%s) - t0)) s" >&2
}

emd_vs_pot() {
    local m
    for m in numpy ot; do
        python3 -c "import $m" 2>/dev/null ||
            { echo "emd-vs-pot: Python module $m is not installed; install both with \`pip install numpy pot\`" >&2 && exit 1; }
    done
    (cd "$root/host-tests" && cargo build --release -q -p dmap --example emd_pairs)
    python3 - "$root/host-tests" "$@" <<'PY'
"""Builds random pairs of 9x9 and 15x15 deflection maps of two kinds, dense
(every cell lit, the worst case) and beam-like (a few-cell spot and the same
spot slightly moved and noised, as neighbouring scan positions are), scores
them with the emd_pairs example, then with ot.emd2 and the Euclidean
cell-centre cost matrix, and prints both timings and the largest relative
disagreement."""
import argparse
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np
import ot

HOST = pathlib.Path(sys.argv[1])


def dense_pairs(rng, n, j):
    return rng.integers(0, 65536, size=(n, 2, j, j)).astype(np.float64)


def beam_pairs(rng, n, j):
    out = np.zeros((n, 2, j, j))
    y, x = np.mgrid[0:j, 0:j]
    for p in range(n):
        c = rng.uniform(2, j - 3, size=2)
        for k in range(2):
            cc = c + (rng.normal(0, 0.7, size=2) if k else 0)
            spot = 4000 * np.exp(-((y - cc[0]) ** 2 + (x - cc[1]) ** 2) / (2 * 0.8**2))
            out[p, k] = np.floor(spot + rng.poisson(0.3, size=(j, j)))
    return out


ap = argparse.ArgumentParser(prog="measure.sh emd-vs-pot")
ap.add_argument("--pairs", type=int, default=200)
ap.add_argument("--seed", type=int, default=1)
args = ap.parse_args(sys.argv[2:])
rng = np.random.default_rng(args.seed)
exe = next((HOST / "target").glob("*/release/examples/emd_pairs"))
print(f"{'maps':>6} {'kind':>6} {'pairs':>6} {'rust us/pair':>13} {'POT us/pair':>12} {'max rel diff':>13}")
with tempfile.TemporaryDirectory() as tmp:
    for j in (9, 15):
        for kind, make in (("dense", dense_pairs), ("beam", beam_pairs)):
            pairs = make(rng, args.pairs, j)
            src, dst = pathlib.Path(tmp, "pairs.npy"), pathlib.Path(tmp, "out.npy")
            np.save(src, pairs)
            line = subprocess.run([exe, src, dst], check=True, capture_output=True, text=True).stdout
            rust_us = float(line.split("(")[1].split(" us")[0])
            ours = np.load(dst)[:, 0, 0]
            cells = np.array([(a, b) for a in range(j) for b in range(j)], dtype=np.float64)
            cost = ot.dist(cells, cells, metric="euclidean")
            hists = [(p[0].ravel() / p[0].sum(), p[1].ravel() / p[1].sum()) for p in pairs]
            t0 = time.perf_counter()
            pot = np.array([ot.emd2(a, b, cost, numItermax=10_000_000) for a, b in hists])
            pot_us = 1e6 * (time.perf_counter() - t0) / len(hists)
            rel = np.max(np.abs(ours - pot) / np.maximum(np.abs(pot), 1e-300))
            print(f"{j:>3}x{j:<2} {kind:>6} {len(hists):>6} {rust_us:>13.1f} {pot_us:>12.1f} {rel:>13.2e}")
PY
}

# The experiments of docs/experiments.md with the simulator's realistic noise
# (shot, read, ADC, laser fluctuation and drift):
#  1. prototype preset (Tables 1 and 2): cvm (firmware fixed point), emd, raw,
#     and cvm + power: the objects the firmware reports (O lines of dmap
#     stream with both channels' calibrated thresholds, `objects` above);
#  2. paper-sim preset with a 300 um detector spot (Fig. 3), and as the preset
#     is, also with raw maps scored in f64 (rawf: the fixed-point raw format is
#     coarse); cvm + power as for the prototype;
#  3. defect-free parts of each, other seeds: thresholds calibrated on seeds
#     11-15 (prototype) or 11-13 (paper-sim), false objects counted on seeds
#     21-30, which the calibration never saw; the defective part is seed 1.
# Writes .npy/.json files and the numbers to OUT_DIR (default
# host-tests/target/experiments) and the PNGs to docs/img/.
experiments() {
    local out=${1:-$root/host-tests/target/experiments} img=$root/docs/img
    mkdir -p "$out" "$img"
    out=$(cd "$out" && pwd)
    build_dmap
    cd "$out"
    run() { echo "\$ dmap $*" >&2; nice -n 10 "$dmap_bin" "$@"; }
    have() { [ "${REUSE:-0}" = 1 ] && [ -f "$1" ]; }
    sim() { local o=$1; shift; have "$o" || run simulate --threads 2 "$@" -o "$o" 2>&1 | sed -n 1p >&2; }
    score() { # SCAN DIST -> SCAN_DIST.npy (cvm = firmware fixed point, raw = the same without Eq. 5, rawf = raw in f64)
        local s=$1 d=$2 o=${1%.npy}_$2.npy
        case $d in
            cvm) run score "$s" --distance cvm-fixed -o "$o" ;;
            raw) run score "$s" --distance cvm-fixed --raw -o "$o" ;;
            rawf) run score "$s" --distance cvm --raw -o "$o" ;;
            emd) have "$o" || run score "$s" --distance emd -o "$o" ;;
        esac 2>/dev/null
    }
    calibrate() { # NAME DIST REF_STEMS... -> cal_NAME_DIST.json
        local n=$1 d=$2 r
        shift 2
        local refs=()
        case $d in
            cvm) for r in "$@"; do refs+=("$r.npy"); done; run calibrate "${refs[@]}" -o "cal_${n}_$d.json" ;;
            raw) for r in "$@"; do refs+=("$r.npy"); done; run calibrate "${refs[@]}" --raw -o "cal_${n}_$d.json" ;;
            emd | rawf) for r in "$@"; do refs+=("${r}_$d.npy"); done; run calibrate --from-scores "${refs[@]}" -o "cal_${n}_$d.json" ;;
        esac
    }
    # One line per defective part: found/missed/false objects and, per defect,
    # objects, truth and detected extent (rows x cols) and area.
    eval_objects() { # GRAD TRUTH CAL
        run eval "$1" --truth "$2" --calibration "$3" --json | jq -r '
    "threshold \(.threshold): \(.objects.found)/\(.objects.truth_objects) defects found, \(.objects.false_objects) false objects",
    (.objects.defects[] | "  truth rows \(.truth.rows) cols \(.truth.cols) area \(.truth.area) -> " +
      (if .found then "\(.objects) object(s), rows \(.detected.rows) cols \(.detected.cols) area \(.detected.area), error rows \(.size_error.rows*100|round) % cols \(.size_error.cols*100|round) % area \(.size_error.area*100|round) % (corrected rows \(.corrected_error.rows*100|round) % cols \(.corrected_error.cols*100|round) %), peak \(.peak)" else "missed, peak \(.peak)" end))'
    }
    false_objects() { # DIST CAL STEMS... -> "n n n ..."
        local d=$1 c=$2 t
        shift 2
        local counts=()
        for t in "$@"; do
            counts+=("$(run eval "${t}_$d.npy" --truth "$t.truth.npy" --calibration "$c" --json | jq '.objects.false_objects')")
        done
        echo "false objects on unseen defect-free parts: ${counts[*]}"
    }
    # The objects as the firmware reports them: dmap stream with both channels'
    # thresholds from the calibration, its O lines against the truth.
    board_objects() { # STEM TRUTH CAL
        run stream "$1.npy" --scores --calibration "$3" >"$1.lines"
        objects "$1.lines" "$2"
    }
    board_false() { # CAL STEMS... -> "n n n ..."
        local c=$1 t
        shift
        local counts=()
        for t in "$@"; do
            run stream "$t.npy" --calibration "$c" >"$t.lines"
            counts+=("$(dmap listen --input "$t.lines" --json | jq '.objects | length')")
        done
        echo "firmware objects on unseen defect-free parts: ${counts[*]}"
    }
    local cal_seeds_p="11 12 13 14 15" cal_seeds_s="11 12 13" test_seeds="21 22 23 24 25 26 27 28 29 30"
    local s f d v extra dists tests

    echo "== prototype preset (39x39, 9x9, cylindrical lens, two rough patches), realistic noise"
    sim proto.npy --preset prototype
    for s in $cal_seeds_p $test_seeds; do sim "proto_free_s$s.npy" --preset prototype --defect-free --seed "$s"; done
    for f in proto proto_free_s*[0-9].npy; do
        f=${f%.npy}
        for d in cvm emd raw; do score "$f.npy" "$d"; done
    done
    for d in cvm emd raw; do
        echo "-- prototype, $d"
        calibrate proto "$d" $(for s in $cal_seeds_p; do echo "proto_free_s$s"; done)
        run eval "proto_$d.npy" --truth proto.truth.npy --calibration "cal_proto_$d.json" | sed -n 1,4p
        eval_objects "proto_$d.npy" proto.truth.npy "cal_proto_$d.json"
        false_objects "$d" "cal_proto_$d.json" $(for s in $test_seeds; do echo "proto_free_s$s"; done)
    done
    echo "-- prototype, cvm + power (firmware objects, thresholds of cal_proto_cvm.json)"
    board_objects proto proto.truth.npy cal_proto_cvm.json
    board_false cal_proto_cvm.json $(for s in $test_seeds; do echo "proto_free_s$s"; done)
    run render proto_emd.npy proto_cvm.npy proto_free_s21_emd.npy proto_free_s21_cvm.npy proto.truth.npy \
        --titles "EMD,CVM,EMD defect-free,CVM defect-free,truth" --scale 6 -o "$img/prototype.png"

    echo "== paper-sim preset (300x300, 15x15, double-convex lens, nine bubbles), realistic noise"
    for v in simblur sim; do
        extra=()
        [ "$v" = simblur ] && extra=(--spot-um 300)
        echo "-- $v ${extra[*]}"
        sim "$v.npy" --preset paper-sim "${extra[@]}"
        for s in $cal_seeds_s $test_seeds; do sim "${v}_free_s$s.npy" --preset paper-sim "${extra[@]}" --defect-free --seed "$s"; done
        dists="cvm raw rawf"
        # EMD of a 300x300x15x15 scan takes minutes: the defective part, the
        # calibration parts and two unseen parts, on the blurred run only.
        [ "$v" = simblur ] && dists="cvm raw rawf emd"
        for d in $dists; do
            score "$v.npy" "$d"
            for s in $cal_seeds_s; do score "${v}_free_s$s.npy" "$d"; done
            tests=$test_seeds
            [ "$d" = emd ] && tests="21 22"
            for s in $tests; do score "${v}_free_s$s.npy" "$d"; done
            echo "-- $v, $d"
            calibrate "$v" "$d" $(for s in $cal_seeds_s; do echo "${v}_free_s$s"; done)
            run eval "${v}_$d.npy" --truth "$v.truth.npy" --calibration "cal_${v}_$d.json" | sed -n 1,4p
            eval_objects "${v}_$d.npy" "$v.truth.npy" "cal_${v}_$d.json"
            false_objects "$d" "cal_${v}_$d.json" $(for s in $tests; do echo "${v}_free_s$s"; done)
        done
        echo "-- $v, cvm + power (firmware objects, thresholds of cal_${v}_cvm.json)"
        board_objects "$v" "$v.truth.npy" "cal_${v}_cvm.json"
        board_false "cal_${v}_cvm.json" $(for s in $test_seeds; do echo "${v}_free_s$s"; done)
    done
    run render simblur_cvm.npy simblur_emd.npy simblur_rawf.npy --titles "CVM,EMD,CVM raw (f64)" --scale 1 -o "$img/simblur.png"
    run render simblur_cvm.npy simblur_emd.npy simblur_rawf.npy --titles "CVM lower left,EMD lower left,raw lower left" \
        --crop 244,19,21,51 --scale 4 --log -o "$img/simblur_lower_left.png"
    run render sim_cvm.npy sim_rawf.npy --titles "CVM,CVM raw (f64)" --scale 1 -o "$img/sim.png"
    for v in proto simblur sim; do
        s=11,12,13
        [ "$v" = proto ] && s=11,12,13,14,15
        background "$v" "$s" 21,22,23,24,25,26,27,28,29,30 cvm
    done
    calibration_rule "$out"
}

# The calibration rules against each other (experiments.md, "Calibration"
# and "Thresholds from a target rate"): the streaming spread rule (the
# board's), the rule before it (exact medians over every magnitude), the
# tail rule, and an extreme-value fit of the references' maxima; the
# references, defective parts and unseen parts (seeds 21-40) of
# `experiments`, simulated here when OUT_DIR lacks them.
calibration_rule() { # [OUT_DIR]
    local out=${1:-$root/host-tests/target/experiments} v s opts
    mkdir -p "$out"
    out=$(cd "$out" && pwd)
    [ -n "$dmap_bin" ] || build_dmap
    for v in proto simblur sim; do
        case $v in
            proto) opts=(--preset prototype) ;;
            simblur) opts=(--preset paper-sim --spot-um 300) ;;
            *) opts=(--preset paper-sim) ;;
        esac
        for s in 1 11 12 13 14 15 $(seq 21 40); do
            local o="$out/${v}_free_s$s.npy" more=(--defect-free --seed "$s")
            [ "$s" = 1 ] && o="$out/$v.npy" more=()
            [ "$v" != proto ] && { [ "$s" = 14 ] || [ "$s" = 15 ]; } && continue
            [ -f "$o" ] || nice -n 10 "$dmap_bin" simulate --threads 2 "${opts[@]}" "${more[@]}" -o "$o" 2>&1 | sed -n 1p >&2
        done
        # One scattering disc, two positions across, per share; the
        # preset's defects moved off the raster (prototype: a patch at
        # 11 mm; paper-sim: one bubble at 60 mm, on a 41x41 raster).
        case $v in
            proto) more=(--scratch 11,11,11.5,11.5 2,2,2) ;;
            simblur) more=(--bubble 60,0,5,0.1 --rows 41 --cols 41 --center-mm 10,10 10,10,2) ;;
            *) continue ;;
        esac
        for s in 0.05 0.1 0.2 0.3; do
            local o="$out/${v}_halo$s.npy" last=$(( ${#more[@]} - 1 ))
            [ -f "$o" ] || nice -n 10 "$dmap_bin" simulate --threads 2 "${opts[@]}" "${more[@]:0:$last}" \
                "--scatter=${more[$last]},$s" --seed 2 -o "$o" 2>&1 | sed -n 1p >&2
        done
    done
    python3 "$root/scripts/calibration_rule.py" "$dmap_bin" "$out"
}

# Background models against the plain calibration rule (experiments.md,
# "Calibration"): reads PREFIX_free_sSEED_DIST.npy (gradient images of
# defect-free parts), PREFIX_DIST.npy and PREFIX.truth.npy. For the plain
# magnitude, the magnitude less a per-column background (median of each
# column over the calibration parts) and less a per-position background
# (mean over them), applies the rule max + 3 * 1.4826 * MAD (f64, exact
# medians: the rule before the streaming one) on the
# calibration parts and counts positions at or above it on the unseen parts
# and on the defective part.
background() { # PREFIX CAL_SEEDS TEST_SEEDS DIST
    python3 - "$@" <<'PY'
import array, ast, struct, sys


def load(p):
    b = open(p, "rb").read()
    hl = struct.unpack("<H", b[8:10])[0]
    h = ast.literal_eval(b[10:10 + hl].decode())
    a = array.array("d")
    a.frombytes(b[10 + hl:])
    r, c = h["shape"][:2]
    return r, c, [a[i * 3 + 2] for i in range(r * c)]


def loadmask(p):
    b = open(p, "rb").read()
    hl = struct.unpack("<H", b[8:10])[0]
    return [x != 0 for x in b[10 + hl:]]


def med(v):
    v = sorted(v)
    n = len(v)
    return v[n // 2] if n % 2 else (v[n // 2 - 1] + v[n // 2]) / 2


def rule(v, k=3):
    m = med(v)
    mad = med([abs(x - m) for x in v])
    return max(v) + k * 1.4826 * mad, max(v), m, mad


pre, cal, test, dist = sys.argv[1], sys.argv[2].split(","), sys.argv[3].split(","), sys.argv[4]
R = [load(f"{pre}_free_s{s}_{dist}.npy") for s in cal]
r, c, _ = R[0]
bg = [med([x[2][i * c + j] for x in R for i in range(r)]) for j in range(c)]
pp = [sum(x[2][k] for x in R) / len(R) for k in range(r * c)]
for name, f in [("plain", lambda v, k: v[k]), ("column", lambda v, k: v[k] - bg[k % c]),
                ("position", lambda v, k: v[k] - pp[k])]:
    allv = [f(x[2], k) for x in R for k in range(r * c)]
    thr, mx, m, mad = rule(allv)
    fo = []
    for s in test:
        _, _, v = load(f"{pre}_free_s{s}_{dist}.npy")
        fo.append(sum(1 for k in range(r * c) if f(v, k) >= thr))
    _, _, v = load(f"{pre}_{dist}.npy")
    t = loadmask(f"{pre}.truth.npy")
    hit = sum(1 for k in range(r * c) if t[k] and f(v, k) >= thr)
    fa = sum(1 for k in range(r * c) if (not t[k]) and f(v, k) >= thr)
    print(f"{pre} {dist} {name:8s} thr {thr:.4g} (max {mx:.4g} median {m:.4g} MAD {mad:.3g}); "
          f"positions >= thr on unseen free parts {fo}; defective part: truth positions >= thr "
          f"{hit}/{sum(t)}, others {fa}")
PY
}

case $what in
    icount) icount ;;
    profile) profile "$@" ;;
    twin-profile) twin_profile ;;
    latency) latency ;;
    store-boot) store_boot ;;
    twin-cost) twin_cost "$@" ;;
    objects) objects "$@" ;;
    experiments) experiments "$@" ;;
    calibration-rule) calibration_rule "$@" ;;
    emd-vs-pot) emd_vs_pot "$@" ;;
    soak) soak "$@" ;;
    *) usage ;;
esac
