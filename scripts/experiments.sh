#!/usr/bin/env bash
# Re-runs the experiments of docs/experiments.md with the dmap tools, with the
# simulator's realistic noise (shot, read, ADC, laser fluctuation and drift):
#  1. prototype preset (Tables 1 and 2): cvm (firmware fixed point), emd, --raw, and
#     cvm + power: the objects the firmware reports (O lines of dmap stream with both
#     channels' calibrated thresholds, read by scripts/fw_objects.py);
#  2. paper-sim preset with a 300 um detector spot (Fig. 3), and as the preset is,
#     also with raw maps scored in f64 (rawf: the fixed-point raw format is coarse);
#     cvm + power as for the prototype;
#  3. defect-free parts of each, other seeds: thresholds calibrated on seeds
#     11-15 (prototype) or 11-13 (paper-sim), false objects counted on seeds
#     21-30, which the calibration never saw; the defective part is seed 1.
# Usage: scripts/experiments.sh [OUT_DIR]   (default host-tests/target/experiments)
# REUSE=1 keeps simulated scans and EMD scores already in OUT_DIR (same seeds,
# same commands) instead of recomputing them; everything else is recomputed.
# Writes .npy/.json files and the numbers to OUT_DIR and the PNGs to docs/img/.
# About 45 minutes from scratch on the shared, loaded 2-core machine (nice 10).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-$root/host-tests/target/experiments}
img=$root/docs/img
mkdir -p "$out" "$img"
(cd "$root/host-tests" && nice -n 10 cargo build --release -q -j 1 -p dmap)
dmap=$root/host-tests/target/x86_64-unknown-linux-gnu/release/dmap
[ -x "$dmap" ] || dmap=$root/host-tests/target/release/dmap
cd "$out"
run() { echo "\$ dmap $*" >&2; nice -n 10 "$dmap" "$@"; }
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
  local n=$1 d=$2; shift 2
  local refs=()
  case $d in
    cvm) for r in "$@"; do refs+=("$r.npy"); done; run calibrate "${refs[@]}" -o "cal_${n}_$d.json" ;;
    raw) for r in "$@"; do refs+=("$r.npy"); done; run calibrate "${refs[@]}" --raw -o "cal_${n}_$d.json" ;;
    emd | rawf) for r in "$@"; do refs+=("${r}_$d.npy"); done; run calibrate --scores "${refs[@]}" -o "cal_${n}_$d.json" ;;
  esac
}
# One line per defective part: found/missed/false objects and, per defect,
# objects, truth and detected extent (rows x cols) and area.
objects() { # GRAD TRUTH CAL
  run eval "$1" --truth "$2" --calibration "$3" --json | jq -r '
    "threshold \(.threshold): \(.objects.found)/\(.objects.truth_objects) defects found, \(.objects.false_objects) false objects",
    (.objects.defects[] | "  truth rows \(.truth.rows) cols \(.truth.cols) area \(.truth.area) -> " +
      (if .found then "\(.objects) object(s), rows \(.detected.rows) cols \(.detected.cols) area \(.detected.area), error rows \(.size_error.rows*100|round) % cols \(.size_error.cols*100|round) % area \(.size_error.area*100|round) % (corrected rows \(.corrected_error.rows*100|round) % cols \(.corrected_error.cols*100|round) %), peak \(.peak)" else "missed, peak \(.peak)" end))'
}
false_objects() { # DIST CAL STEMS... -> "n n n ..."
  local d=$1 c=$2; shift 2
  local counts=()
  for t in "$@"; do
    counts+=("$(run eval "${t}_$d.npy" --truth "$t.truth.npy" --calibration "$c" --json | jq '.objects.false_objects')")
  done
  echo "false objects on unseen defect-free parts: ${counts[*]}"
}
# The objects as the firmware reports them: dmap stream with both channels' thresholds
# from the calibration, its O lines against the truth (and, from the S lines, each
# defect's peak magnitudes against the thresholds).
board_objects() { # STEM TRUTH CAL
  run stream "$1.npy" --scores --calibration "$3" > "$1.lines"
  python3 "$root/scripts/fw_objects.py" "$1.lines" "$2"
}
board_false() { # CAL STEMS... -> "n n n ..."
  local c=$1; shift
  local counts=()
  for t in "$@"; do
    run stream "$t.npy" --calibration "$c" > "$t.lines"
    counts+=("$(python3 "$root/scripts/fw_objects.py" "$t.lines" --count)")
  done
  echo "firmware objects on unseen defect-free parts: ${counts[*]}"
}
cal_seeds_p="11 12 13 14 15"
cal_seeds_s="11 12 13"
test_seeds="21 22 23 24 25 26 27 28 29 30"

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
  objects "proto_$d.npy" proto.truth.npy "cal_proto_$d.json"
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
    objects "${v}_$d.npy" "$v.truth.npy" "cal_${v}_$d.json"
    false_objects "$d" "cal_${v}_$d.json" $(for s in $tests; do echo "${v}_free_s$s"; done)
  done
  echo "-- $v, cvm + power (firmware objects, thresholds of cal_${v}_cvm.json)"
  board_objects "$v" "$v.truth.npy" "cal_${v}_cvm.json"
  board_false "cal_${v}_cvm.json" $(for s in $test_seeds; do echo "${v}_free_s$s"; done)
done
run render simblur_cvm.npy simblur_emd.npy simblur_rawf.npy --titles "CVM,EMD,CVM raw (f64)" --scale 1 -o "$img/simblur.png"
run render simblur_cvm.npy simblur_emd.npy simblur_rawf.npy --titles "CVM lower left,EMD lower left,raw lower left" --crop 244,19,21,51 --scale 4 --log -o "$img/simblur_lower_left.png"
run render sim_cvm.npy sim_rawf.npy --titles "CVM,CVM raw (f64)" --scale 1 -o "$img/sim.png"
# Background models (per column, per position) against the plain rule,
# docs/experiments.md "Calibration": numbers from the scores above.
if command -v python3 > /dev/null; then
  python3 "$root/scripts/background.py" proto 11,12,13,14,15 21,22,23,24,25,26,27,28,29,30 cvm
  python3 "$root/scripts/background.py" simblur 11,12,13 21,22,23,24,25,26,27,28,29,30 cvm
  python3 "$root/scripts/background.py" sim 11,12,13 21,22,23,24,25,26,27,28,29,30 cvm
fi
