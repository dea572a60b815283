#!/usr/bin/env bash
# Re-runs the paper's experiments with the dmap tools (see docs/experiments.md):
# Table 1 and Table 2 on the `prototype` preset, the Fig. 3 comparison on
# `paper-sim` (as the preset is, and with a blurred detector spot).
# Usage: scripts/experiments.sh [OUT_DIR]   (default host-tests/target/experiments)
# Writes .npy files and the printed numbers to OUT_DIR and the PNGs to docs/img/.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-$root/host-tests/target/experiments}
img=$root/docs/img
mkdir -p "$out" "$img"
(cd "$root/host-tests" && cargo build --release -q -p dmap)
dmap=$root/host-tests/target/x86_64-unknown-linux-gnu/release/dmap
[ -x "$dmap" ] || dmap=$root/host-tests/target/release/dmap
cd "$out"
run() { echo "\$ dmap $*"; "$dmap" "$@"; }

echo "== Table 1 and 2: prototype preset (39x39, 9x9, cylindrical lens, two rough patches)"
run simulate --preset prototype -o proto.npy
run simulate --preset prototype --defect-free -o proto_free.npy
for d in emd cvm; do
  run score proto.npy --distance "$d" -o "proto_$d.npy"
  run score proto_free.npy --distance "$d" -o "proto_free_$d.npy"
  run eval "proto_$d.npy" --truth proto.truth.npy
  run eval "proto_$d.npy" --truth proto.truth.npy --json
  # The defect-free part: no defect positions, so only the background statistics mean anything.
  run eval "proto_free_$d.npy" --truth proto_free.truth.npy --threshold 1e9 | grep "defect-free:"
done
run render proto_emd.npy proto_cvm.npy proto_free_emd.npy proto_free_cvm.npy proto.truth.npy \
  --titles "EMD,CVM,EMD defect-free,CVM defect-free,truth" --scale 6 -o "$img/prototype.png"

echo "== Fig. 3: paper-sim preset (300x300, 15x15, double-convex lens, nine bubbles)"
for v in sim simblur; do
  extra=()
  [ "$v" = simblur ] && extra=(--spot-um 300)
  run simulate --preset paper-sim "${extra[@]}" -o "$v.npy"
  for d in emd cvm; do
    t0=$SECONDS
    run score "$v.npy" --distance "$d" -o "${v}_$d.npy"
    echo "($d score took $((SECONDS - t0)) s)"
    run eval "${v}_$d.npy" --truth "$v.truth.npy"
  done
  run render "${v}_emd.npy" "${v}_cvm.npy" --titles "EMD,CVM" --scale 1 -o "$img/${v}.png"
  # Bubble groups, left to right r = 83, 167, 334 um.
  run render "${v}_emd.npy" "${v}_cvm.npy" --titles "EMD lower left,CVM lower left" --crop 244,19,21,51 --scale 4 --log -o "$img/${v}_lower_left.png"
  run render "${v}_emd.npy" "${v}_cvm.npy" --titles "EMD centre,CVM centre" --crop 139,124,21,51 --scale 4 --log -o "$img/${v}_centre.png"
  run render "${v}_emd.npy" "${v}_cvm.npy" --titles "EMD upper right,CVM upper right" --crop 34,229,21,51 --scale 4 --log -o "$img/${v}_upper_right.png"
done
