#!/usr/bin/env bash
# Maps per second through cvm_dmap.score(..., "cvm-fixed") against `dmap
# score` on the same scan and `dmap bench`, one thread, round after round;
# and cvm_dmap's exact EMD against POT's ot.emd2 on the same maps
# (docs/performance.md, "Python"). Builds and installs the package as
# scripts/python.sh does, in release (PY_PROFILE), and POT into its
# environment; arguments go to
# host-tests/python/bench.py (--rounds, --seconds, --threads).
set -euo pipefail
cd "$(dirname "$0")/.."
PY_PROFILE=release PY_INSTALL_ONLY=1 bash scripts/python.sh
venv=host-tests/target/py-venv
if ! "$venv/bin/python" -c "import ot" >/dev/null 2>&1; then
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check POT ||
        echo "bench-python: POT did not install; the EMD comparison is left out" >&2
fi
host=$(rustc -vV | sed -n 's/^host: //p')
exec "$venv/bin/python" host-tests/python/bench.py --dmap "host-tests/target/$host/release/dmap" "$@"
