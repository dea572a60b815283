#!/usr/bin/env bash
# Instructions per beam of the firmware's scoring path on the emulated
# Cortex-M4F (QEMU mps2-an386, -icount shift=0), for 9x9 and 15x15 maps with
# paper and square kernels. Prints a Markdown table. Idempotent; installs
# what it needs (thumbv7em target, qemu-system-arm).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bash "$root/scripts/emulate-setup.sh"
(cd "$root/host-tests" && cargo build -q --release -p dmap)
dmap="$root/host-tests/target/x86_64-unknown-linux-gnu/release/dmap"
[ -x "$dmap" ] || dmap="$root/host-tests/target/release/dmap"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

# A 40 x 30 scan of random counts for a J x J detector.
make_scan() {
    python3 "$root/scripts/random_scan.py" "$1" "$2" 30 40
}

echo "| map | kernels | instructions per beam | beams |"
echo "|---|---|---:|---:|"
for j in 9 15; do
    make_scan "$work/scan$j.npy" "$j"
    for k in paper square; do
        line="$("$dmap" emulate "$work/scan$j.npy" --kernels "$k" --scores --icount 2>&1 >/dev/null | grep instructions_per_beam)"
        ipb="$(sed -E 's/.*instructions_per_beam=([0-9]+).*/\1/' <<<"$line")"
        beams="$(sed -E 's/.*beams=([0-9]+).*/\1/' <<<"$line")"
        echo "| ${j}x${j} | $k | $ipb | $beams |"
    done
done
