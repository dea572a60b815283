#!/usr/bin/env bash
# Runs every fuzz target of host-tests/fuzz for SECONDS each (default 30),
# as many at once as the machine has cores (FUZZ_JOBS), and prints each
# target's executions. Any crash, panic,
# leak, out-of-memory or timeout ends the script with a non-zero status;
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

# One target alone: its corpus, its log, its verdict (status 1 on a find).
run_one() {
    local t="$1" work="target/corpus/$1" log="target/fuzz-$1.log"
    mkdir -p "$work" "corpus/$t"
    echo "fuzz: $t for ${secs}s" >&2
    if ! cargo +nightly fuzz run "$t" "$work" "corpus/$t" -- \
        -max_total_time="$secs" -timeout=20 -rss_limit_mb=2048 -print_final_stats=1 \
        >"$log" 2>&1; then
        tail -n 60 "$log" >&2
        echo "fuzz: $t FAILED (log: host-tests/fuzz/$log, input: host-tests/fuzz/artifacts/$t/)" >&2
        return 1
    fi
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
    echo "fuzz: $t ok: ${execs:-?} executions in ${secs}s, no crash" >&2
}

# As many targets at once as there are cores (FUZZ_JOBS to choose): each
# target is one process and gets its SECONDS of its own.
jobs="${FUZZ_JOBS:-$(nproc)}"
failed=0
running=0
for t in "${targets[@]}"; do
    run_one "$t" &
    running=$((running + 1))
    if [ "$running" -ge "$jobs" ]; then
        wait -n || failed=1
        running=$((running - 1))
    fi
done
while [ "$running" -gt 0 ]; do
    wait -n || failed=1
    running=$((running - 1))
done
exit "$failed"
