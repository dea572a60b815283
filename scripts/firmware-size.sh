#!/usr/bin/env bash
# Flash and RAM use of the NUCLEO-H743ZI2 firmware (release build), per
# section. Idempotent; installs llvm-size if missing.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
rustup target add thumbv7em-none-eabihf >/dev/null
command -v llvm-size >/dev/null || { apt-get update -qq && apt-get install -y -qq llvm >/dev/null; }
(cd "$root" && cargo build --release -q)
# Flash holds the code, the read-only data and the load images of .data
# and .dtcm_rodata (copied to RAM at start-up).
llvm-size -A "$root/target/thumbv7em-none-eabihf/release/cvm-fw" |
    grep -E '^\.(vector_table|text|rodata|data|dtcm_rodata|bss|uninit|dma_buffers|sram123|dtcm) ' |
    awk '{ print } $1 ~ /^\.(vector_table|text|rodata|data|dtcm_rodata)$/ { flash += $2 }
         END { printf "flash %d bytes (%.1f KB)\n", flash, flash / 1000 }'
