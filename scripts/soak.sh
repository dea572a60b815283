#!/usr/bin/env bash
# Soak: the firmware on the emulated board (QEMU) processes a full paper-sim
# scan (300 x 300 positions of 15 x 15 maps) with every position's score on
# the link, and its output must equal the host pipeline's byte for byte,
# with all 90,000 positions accounted for (decoded with `dmap listen`).
#
#   scripts/soak.sh [WORKDIR]      (default target/soak; the scan is reused)
#
# Not part of scripts/test.sh: it runs for several minutes.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
work=$(mkdir -p "${1:-target/soak}" && cd "${1:-target/soak}" && pwd)

step() { printf '\n== soak: %s\n' "$*" >&2; }
t0=$(date +%s)
elapsed() { echo "$(($(date +%s) - t0)) s"; }

step "build dmap (release)"
(cd host-tests && cargo build --release -p dmap)
dmap() { (cd "$root/host-tests" && cargo run -q --release -p dmap -- "$@"); }

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
grep -q "$want" "$work/summary.txt" || { echo "soak: FAILED: expected '$want'" >&2; exit 1; }
grep -q "totals: rows 300 frames 90000 missing 0 .* rejected 0 extra 0 bad 0 clipped 0 misplaced 0 dropped 0" \
    "$work/summary.txt" || { echo "soak: FAILED: end-of-scan totals" >&2; exit 1; }
grep -q "^line errors: 0$" "$work/summary.txt" || { echo "soak: FAILED: damaged lines" >&2; exit 1; }
if grep -q "^  problem" "$work/summary.txt"; then
    echo "soak: FAILED: decoder problems" >&2
    exit 1
fi
echo "soak: ok: 90000 of 90000 positions scored, identical on host and emulated firmware, in $(elapsed)" >&2
