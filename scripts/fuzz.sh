#!/usr/bin/env bash
# Runs every fuzz target of host-tests/fuzz for SECONDS each (default 30),
# one after another, and prints each target's executions. Any crash, panic,
# leak, out-of-memory or timeout stops the script with a non-zero status;
# the input that caused it is in host-tests/fuzz/artifacts/<target>/.
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]
#
# New inputs go to host-tests/fuzz/target/corpus/<target> (not committed);
# the committed seeds in host-tests/fuzz/corpus/<target> are read only.
# Needs the nightly toolchain; installs cargo-fuzz when it is missing.
set -euo pipefail
cd "$(dirname "$0")/../host-tests/fuzz"

secs="${1:-30}"
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(line_decoder npy_reader engine acquisition command record)
fi

if ! rustup toolchain list | grep -q '^nightly'; then
    echo "fuzz: installing the nightly toolchain" >&2
    rustup toolchain install nightly --profile minimal
fi
if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
    echo "fuzz: installing cargo-fuzz" >&2
    cargo install cargo-fuzz --locked
fi

cargo +nightly fuzz build
for t in "${targets[@]}"; do
    work="target/corpus/$t"
    mkdir -p "$work" "corpus/$t"
    log="target/fuzz-$t.log"
    echo "fuzz: $t for ${secs}s" >&2
    if ! cargo +nightly fuzz run "$t" "$work" "corpus/$t" -- \
        -max_total_time="$secs" -timeout=20 -rss_limit_mb=2048 -print_final_stats=1 \
        >"$log" 2>&1; then
        tail -n 60 "$log" >&2
        echo "fuzz: $t FAILED (log: host-tests/fuzz/$log, input: host-tests/fuzz/artifacts/$t/)" >&2
        exit 1
    fi
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
    echo "fuzz: $t ok: ${execs:-?} executions in ${secs}s, no crash" >&2
done
