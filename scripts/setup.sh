#!/usr/bin/env bash
# Installs what the project needs on a fresh Debian machine with rustup:
# the Cortex-M target, rustfmt/clippy, QEMU for the emulated board, and the
# Python packages of the H743 chip model (Unicorn, pyelftools), Python's
# venv and libpython for the Python package (scripts/python.sh), and
# Chromium with its WebDriver for the console's browser test.
# Idempotent: does nothing that is already done.
set -euo pipefail

need_sudo() { if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi; }

if ! rustup target list --installed | grep -qx thumbv7em-none-eabihf; then
    echo "setup: adding the thumbv7em-none-eabihf target" >&2
    rustup target add thumbv7em-none-eabihf
fi
for c in rustfmt clippy; do
    if ! rustup component list --installed | grep -q "^$c"; then
        rustup component add "$c"
    fi
done
if ! command -v qemu-system-arm >/dev/null 2>&1; then
    echo "setup: installing qemu-system-arm" >&2
    need_sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive need_sudo apt-get install -y -qq qemu-system-arm >/dev/null
fi
if ! python3 -c "import venv, ensurepip" >/dev/null 2>&1; then
    echo "setup: installing python3-venv (the Python package's environment, scripts/python.sh)" >&2
    need_sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive need_sudo apt-get install -y -qq python3-venv >/dev/null
fi
# The Python package's crate (host-tests/python, PyO3) links its Rust test
# binary against libpython when `cargo test --workspace` includes it (the
# test command leaves it to pytest on the wheel): python3-dev has it.
if ! command -v python3-config >/dev/null 2>&1; then
    echo "setup: installing python3-dev (libpython, for the Python package's crate tests)" >&2
    need_sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive need_sudo apt-get install -y -qq python3-dev >/dev/null
fi
if ! python3 -c "import unicorn, elftools" >/dev/null 2>&1; then
    echo "setup: installing the chip model's Python packages (unicorn, pyelftools)" >&2
    python3 -m pip install --quiet --disable-pip-version-check unicorn==2.1.4 pyelftools==0.33
fi
if ! command -v chromium >/dev/null 2>&1 || ! command -v chromedriver >/dev/null 2>&1; then
    echo "setup: installing chromium and chromium-driver (dmap console's browser test)" >&2
    need_sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive need_sudo apt-get install -y -qq chromium chromium-driver >/dev/null
fi
