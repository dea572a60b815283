#!/usr/bin/env bash
# Flash and RAM use of the NUCLEO-H743ZI2 firmware (release build), per
# section. Idempotent; installs llvm-size if missing.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
rustup target add thumbv7em-none-eabihf >/dev/null
command -v llvm-size >/dev/null || { apt-get update -qq && apt-get install -y -qq llvm >/dev/null; }
(cd "$root" && cargo build --release -q)
llvm-size -A "$root/target/thumbv7em-none-eabihf/release/cvm-fw" | grep -E '^\.(vector_table|text|rodata|data|bss|uninit|sram123|dtcm) '
