#!/usr/bin/env bash
# Instructions per beam of the H743 release firmware on the chip model, by
# stage, for 9x9 and 15x15 maps with paper kernels
# (`KERNELS=square` for the square kernels) (docs/twin.md). Builds
# the ELF for each geometry into target/twin (cargo's own caching).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# The square kernels build their factor table at start-up (about 80 ms at
# 15x15): the scan starts after it.
start_ms=20
[ "${KERNELS:-paper}" = paper ] || start_ms=200
for j in 9 15; do
    CVM_H743_SCAN="j1=$j j2=$j cols=12 rows=6 scores=true kernels=${KERNELS:-paper}" \
        cargo build --release --target-dir target/twin >&2
    elf=target/twin/thumbv7em-none-eabihf/release/cvm-fw
    (cd host-tests/twin && python3 -m h743twin.profile "../../$elf" "$j" "$j" --top "${TOP:-0}" \
        --start-ms "$start_ms")
    echo
done
