#!/usr/bin/env bash
# Installs what the emulated board needs: the thumbv7em target and QEMU.
# Idempotent.
set -euo pipefail
rustup target add thumbv7em-none-eabihf >/dev/null
if ! command -v qemu-system-arm >/dev/null; then
    apt-get update -qq && apt-get install -y -qq qemu-system-arm >/dev/null
fi
