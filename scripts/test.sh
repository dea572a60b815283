#!/usr/bin/env bash
# The whole test suite: formatting, lints, firmware builds for both boards,
# and every host test (core against the f64 references, engine, protocol,
# firmware logic, the emulated firmware against the host bit for bit).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh

step() { printf '\n== %s\n' "$*" >&2; }

step "format"
cargo fmt --all -- --check
(cd host-tests && cargo fmt --all -- --check)

step "firmware: NUCLEO-H743ZI2 build and lints"
cargo build --release
cargo clippy --release --workspace -- -D warnings

step "firmware: emulated board build and lints"
cargo build --release --no-default-features --features emulated
cargo clippy --release --no-default-features --features emulated --workspace -- -D warnings

step "host: lints"
(cd host-tests && cargo clippy --workspace --all-targets -- -D warnings)

step "host: tests"
(cd host-tests && cargo test --workspace)
