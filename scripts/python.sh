#!/usr/bin/env bash
# The Python package (host-tests/python, `cvm_dmap`): builds its abi3 wheel
# with maturin (`pip install ./host-tests/python`) into a virtual
# environment under host-tests/target/py-venv, builds the `dmap` binary the
# tests compare it with, and runs its pytest suite. Arguments go to pytest
# (`scripts/python.sh -k stream`); with PY_INSTALL_ONLY=1 it stops before
# them (scripts/bench-python.sh). Installs what it needs (maturin, NumPy,
# pytest, hypothesis) into the environment only; `python3 -m venv` itself
# comes from scripts/setup.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=host-tests/target/py-venv
py=$venv/bin/python
if ! "$py" -c "import sys" >/dev/null 2>&1; then
    rm -rf "$venv"
    python3 -m venv "$venv"
fi
if ! "$py" -c "import numpy, pytest, hypothesis" >/dev/null 2>&1 || [ ! -x "$venv/bin/maturin" ]; then
    "$py" -m pip install --quiet --disable-pip-version-check \
        maturin==1.16.0 numpy pytest hypothesis
fi
# The wheel is built in the host workspace's dev profile (PY_PROFILE,
# `release` to choose), which is the test profile's (host-tests/Cargo.toml):
# opt-level 2, debug assertions on. The `dmap` binary the tests compare it
# with is the one `cargo test` builds for dmap's tests: after `cargo test`
# (scripts/test.sh) it is not built again.
profile="${PY_PROFILE:-dev}"
target="${CARGO_TARGET_DIR:-$PWD/host-tests/target}"
host=$(rustc -vV | sed -n 's/^host: //p')
if [ "$profile" = dev ]; then
    (cd host-tests && cargo test --workspace --exclude cvm-dmap-py --lib --bins --tests --no-run --quiet)
    dmap="$target/$host/debug/dmap"
else
    (cd host-tests && cargo build --profile "$profile" --quiet -p dmap --bin dmap)
    dmap="$target/$host/$profile/dmap"
fi
# pip builds the wheel with the environment's maturin (no download of a
# build environment), in the host workspace's target folder.
PATH="$PWD/$venv/bin:$PATH" MATURIN_PEP517_ARGS="--profile $profile" \
    "$py" -m pip install --quiet --disable-pip-version-check \
    --no-build-isolation --no-deps --force-reinstall ./host-tests/python
[ "${PY_INSTALL_ONLY:-}" = 1 ] && exit 0
DMAP="$dmap" \
    "$py" -m pytest -q -p no:cacheprovider host-tests/python/tests "$@"
