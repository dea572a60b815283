#!/usr/bin/env bash
# The whole test suite: formatting, lints, firmware builds for both boards,
# and every host test (core against the f64 references, engine, protocol,
# firmware logic, the emulated firmware against the host bit for bit).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh

# Each step's wall time, printed as it ends and summed up at the end, so a
# slow step shows in CI's log (docs/performance.md, "Test command").
t0=$SECONDS
last=$SECONDS
times=()
name=""
mark() { [ -n "$name" ] && times+=("$(printf '%5d s  %s' $((SECONDS - last)) "$name")"); last=$SECONDS; }
step() { mark; name="$*"; printf '\n== %s\n' "$*" >&2; }

step "structure: no import circles, no oversized files or functions"
(cd scripts && python3 -m unittest -q tests.test_check_structure)
python3 scripts/check-structure.py

step "docs: every relative link and anchor resolves"
python3 scripts/check-links.py

step "format"
cargo fmt --all -- --check
for crate in host-tests host-tests/fuzz nopanic boards/mps2-an386; do
    (cd "$crate" && cargo fmt --all -- --check)
done

step "firmware: NUCLEO-H743ZI2 build and lints"
cargo build --release
cargo clippy --release --workspace -- -D warnings

step "firmware: the H743 release ELF's memory layout, and its boot on the chip model"
(cd host-tests/twin && python3 -m unittest discover -s tests &&
    python3 -m h743twin.layout ../../target/thumbv7em-none-eabihf/release/cvm-fw &&
    python3 -m h743twin.smoke ../../target/thumbv7em-none-eabihf/release/cvm-fw)

step "firmware: emulated board build and lints"
(cd boards/mps2-an386 && cargo build --release --target-dir ../../target/emulated &&
    cargo clippy --release --target-dir ../../target/emulated -- -D warnings)

step "host: lints"
(cd host-tests && cargo clippy --workspace --all-targets -- -D warnings &&
    cargo clippy -p dmap --no-default-features --lib -- -D warnings)

step "host: tests"
log=$(mktemp)
trap 'rm -f "$log"' EXIT
# The Python package is tested by pytest on its wheel (next step), which
# compiles it with maturin's features: left out here, pyo3 compiles once.
# Examples are not built here (the lints above check them): --lib --bins
# --tests, then the doc tests on their own (cargo takes --doc alone).
(cd host-tests && cargo test --workspace --exclude cvm-dmap-py --lib --bins --tests 2>&1 &&
    cargo test --workspace --exclude cvm-dmap-py --doc 2>&1) | tee "$log"

step "Python package: wheel built and installed in a venv, pytest against dmap"
pylog=$(mktemp)
trap 'rm -f "$log" "$pylog"' EXIT
bash scripts/python.sh 2>&1 | tee "$pylog"

step "panic-free per-beam path (link-time check)"
bash scripts/nopanic.sh

step "fuzz: every target for 10 s (the long runs: docs/reliability.md)"
bash scripts/fuzz.sh 10

step "link-check and fuzz crates: lints"
(cd nopanic && cargo clippy --release --target thumbv7em-none-eabihf -- -D warnings)
if ! rustup component list --toolchain nightly --installed | grep -q '^clippy'; then
    rustup component add clippy --toolchain nightly
fi
(cd host-tests/fuzz && cargo +nightly clippy --all-targets -- -D warnings)

# The last line: one count over every host test binary (cargo prints one
# line per binary, the last of which is often an empty doc-test run) and
# the Python package's pytest run (its last line, "N passed in T s").
mark
printf '\nstep times:\n' >&2
printf '  %s\n' "${times[@]}" >&2
printf '  %5d s  total\n' $((SECONDS - t0)) >&2
awk '/^test result:/ || FILENAME == ARGV[2] && /^[0-9]+ (passed|failed)/ {
         for (i = 1; i <= NF; i++) { if ($(i+1) ~ /^passed/) p += $i; if ($(i+1) ~ /^failed/) f += $i } }
     END { printf "\ntests: %d passed, %d failed\n", p, f }' "$log" "$pylog"
