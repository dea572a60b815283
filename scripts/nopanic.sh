#!/usr/bin/env bash
# Link-time proof that the per-beam path cannot panic (nopanic/): builds the
# image for thumbv7em-none-eabihf with the firmware's release profile; its
# panic handler calls an undefined symbol, so the link fails exactly when a
# panic is still reachable. On failure, lists the call sites that remain
# (needs llvm-objdump and llvm-addr2line; python3).
set -euo pipefail
cd "$(dirname "$0")/../nopanic"
root="$(cd .. && pwd)/"

log=$(mktemp)
trap 'rm -f "$log"' EXIT
if cargo build --release --target thumbv7em-none-eabihf 2>"$log"; then
    echo "nopanic: linked: no panic is reachable from the per-beam path" >&2
    exit 0
fi
if ! grep -q "undefined symbol: cvm_panic_path_reachable" "$log"; then
    cat "$log" >&2
    echo "nopanic: the check itself did not build (see above)" >&2
    exit 1
fi
grep -A3 "undefined symbol" "$log" >&2
echo "nopanic: FAILED: a panic is reachable from the per-beam path" >&2
if command -v llvm-objdump >/dev/null && command -v llvm-addr2line >/dev/null \
    && command -v python3 >/dev/null; then
    # Link once more with the symbol defined, to see where the calls are.
    RUSTFLAGS="-C link-arg=--defsym=cvm_panic_path_reachable=0" \
        cargo build --release --target thumbv7em-none-eabihf --target-dir target/diagnose 2>/dev/null
    elf=target/diagnose/thumbv7em-none-eabihf/release/cvm-nopanic
    llvm-objdump -d --no-show-raw-insn -C "$elf" >"$log"
    python3 panic_sites.py "$elf" "$log" "$root" >&2
fi
exit 1
