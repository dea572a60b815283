#!/usr/bin/env bash
# Estimated cycles per beam of the H743 release firmware's scoring path on
# the chip model: instructions plus the bus cost model of
# scripts/twin-cost.py (accesses by memory and static, stall cycles per
# access), for 9x9 and 15x15 maps with paper kernels
# (`KERNELS=square` for the square kernels). Extra arguments go to
# twin-cost.py (e.g. `--dtcm ROW_A` to cost a static as if in DTCM).
# Builds the ELF for each geometry into target/twin like twin-profile.sh.
# The scan is as wide as the default configuration's (300 columns, 6
# rows; COLS and ROWS change that): a row buffer of a narrow scan would
# fit the D-cache, one of 300 maps does not.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# The cost model decodes instructions with Capstone (see twin-cost.py).
if ! python3 -c "import capstone" >/dev/null 2>&1; then
    echo "twin-cost: installing capstone" >&2
    python3 -m pip install --quiet --disable-pip-version-check capstone==5.0.7
fi
# The square kernels build their factor table at start-up (about 80 ms at
# 15x15): the scan starts after it.
start_ms=20
[ "${KERNELS:-paper}" = paper ] || start_ms=200
cols=${COLS:-300}
rows=${ROWS:-6}
for j in 9 15; do
    CVM_H743_SCAN="j1=$j j2=$j cols=$cols rows=$rows scores=true kernels=${KERNELS:-paper}" \
        cargo build --release --target-dir target/twin >&2
    python3 scripts/twin-cost.py target/twin/thumbv7em-none-eabihf/release/cvm-fw "$j" "$j" \
        --cols "$cols" --rows "$rows" --start-ms "$start_ms" "$@"
    echo
done
