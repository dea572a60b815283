#!/usr/bin/env bash
# The product's main job without a board: simulate a scan of a lens with
# known defects, run it through the firmware on the emulated Cortex-M board
# (QEMU mps2-an386), decode the firmware's UART lines, list the defect objects
# the firmware reported (sizes in mm), and draw the defect map.
#
#   scripts/demo.sh [OUT_DIR]     (default: out/demo)
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
out=${1:-out/demo}
threshold=${THRESHOLD:-0.5}
pitch_um=334   # the prototype preset's scan pitch
start=$(date +%s)
command -v python3 > /dev/null || { echo "demo.sh: needs python3 (standard library only) to match the objects with the truth" >&2; exit 1; }
bash scripts/setup.sh

echo "== building the host tools and the emulated firmware" >&2
(cd host-tests && cargo build --release -q -p dmap)
(cd boards/mps2-an386 && cargo build --release -q --target-dir ../../target/emulated)
elf=$root/target/emulated/thumbv7em-none-eabihf/release/cvm-fw
dmap=$root/host-tests/target/x86_64-unknown-linux-gnu/release/dmap
[ -x "$dmap" ] || dmap=$(find "$root/host-tests/target" -path '*/release/dmap' -type f | head -n 1)
mkdir -p "$out"

echo "== simulating the prototype part: 39x39 beams, 9x9 detector, two surface defects" >&2
"$dmap" simulate --preset prototype --seed 1 -o "$out/scan.npy" --truth "$out/truth.npy"

echo "== scoring on the emulated firmware (QEMU mps2-an386)" >&2
t0=$(date +%s.%N)
# -icount: QEMU counts instructions, and the firmware reports them per beam.
"$dmap" emulate "$out/scan.npy" --scores --threshold "$threshold" --elf "$elf" --icount \
    > "$out/uart.txt" 2> "$out/firmware.log"
cat "$out/firmware.log" >&2
t1=$(date +%s.%N)

echo "== decoding the UART lines" >&2
"$dmap" listen --input "$out/uart.txt" --pitch-um "$pitch_um" -o "$out/scores.npy" > "$out/listen.txt"
"$dmap" render "$out/scores.npy" -o "$out/defects.png" --titles "emulated firmware: CVM gradient magnitude" \
    --objects "$out/uart.txt" --pitch-um "$pitch_um"

# The same scan on the host pipeline must give the same bytes.
"$dmap" stream "$out/scan.npy" --scores --threshold "$threshold" > "$out/host.txt"
if cmp -s "$out/uart.txt" "$out/host.txt"; then same="identical"; else same="DIFFERENT"; fi

echo
echo "Summary"
echo "-------"
# The firmware's object lines (O) as dmap listen decodes them: one per defect, its
# extent and the defect's size, one position smaller on each side (Eq. 1's central
# differences reach one position out), in mm at the scan pitch.
sed -n '1,2p;/^  objects:/p;/^    object /p;/totals:/p;/line errors/p' "$out/listen.txt"
echo "the firmware's objects against the planted defects (truth rows/cols, reported extent, error before and after the correction):"
bash scripts/measure.sh objects "$out/uart.txt" "$out/truth.npy" "$pitch_um" > "$out/objects.txt"
cat "$out/objects.txt"
if grep -q '^2/2 defects found, 0 false objects, 2 objects' "$out/objects.txt"; then objects=ok; else objects=WRONG; fi
sed -n 's/.*beams=\([0-9]*\).*instructions_per_beam=\([0-9]*\).*/emulated Cortex-M4: \1 beams, \2 instructions per beam (normalise, embed, gradient, decide, encode)/p' "$out/firmware.log"
awk -v b="$(wc -c < "$out/uart.txt")" -v t="$t1" -v s="$t0" -v same="$same" \
    'BEGIN { printf "emulated firmware: %d UART bytes in %.1f s; host pipeline output: %s\n", b, t - s, same }'
echo "defect map: $out/defects.png   (score image: $out/scores.npy, lines: $out/uart.txt)"
echo "total time: $(( $(date +%s) - start )) s"
[ "$same" = identical ] && [ "$objects" = ok ]
