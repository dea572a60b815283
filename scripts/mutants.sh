#!/usr/bin/env bash
# Mutation testing of the core (cvm-core) and the firmware logic (fw-app):
# cargo-mutants puts one small bug at a time into a copy of the code and
# runs the host tests against it; a mutant the tests do not notice is a
# "survivor". Too slow for every commit (scripts/test.sh does not run it);
# results and the survivors' explanations are in docs/mutants.md.
#
# usage: scripts/mutants.sh [pass...] [-- cargo-mutants options]
#   scripts/mutants.sh                      every pass, in the order below
#   scripts/mutants.sh stream embed         two passes
#   scripts/mutants.sh scorer -- --list     list one pass's mutants only
#   scripts/mutants.sh protocol -- --iterate
#                                           finish an interrupted pass
#                                           (skips mutants already caught)
#
# Passes (each its own cargo-mutants run and output directory):
#   fw-app    fw-app/src/sequence.rs and queue.rs, against fw-app-tests
#   acquire   fw-app/src/acquire.rs and driver.rs (frame acquisition,
#             the scan driver), against fw-app-tests
#   stream    cvm-core/src/stream/ (gradient, border rule, flags,
#             decisions, row summaries), against core-tests and
#             fw-app-tests
#   embed     the paper kernels' per-map passes in cvm-core/src/scorer/
#             (sum and largest sample, conversion, row and column passes)
#   scorer    normalisation, flags, score conversion, distances and the
#             gradient magnitude in cvm-core/src/scorer/
#   square    the square kernels' factors and per-map embedding,
#             cvm-core/src/scorer/square/ (its portable code: the
#             Cortex-M assembly is checked by the emulated board's tests)
#   protocol  the line encoders and CRC in cvm-core/src/protocol/
#   pipeline  cvm-core/src/pipeline.rs and settings.rs
#   decision  the power channel and the object labeller,
#             cvm-core/src/power.rs and objects.rs
#   tables    what is built once per configuration: factor tables,
#             formats, score units (tables.rs, config.rs, flags.rs and the
#             rest of scorer/ but square/), against core-tests and
#             fw-app-tests
#   parser    the line parsers in cvm-core/src/protocol/ (the rest of
#             the file), against those and dmap's tests
#   emufile   the emulated board's scan-file header, fw-app/src/emufile.rs,
#             against fw-app-tests and dmap's tests
#   rest      anything in both crates no pass above covers, against every
#             host test crate
#
# Environment:
#   MUTANTS_REV    commit to test (default HEAD: the committed tree, so a
#                  run can be quoted against a commit)
#   MUTANTS_OUT    where <pass>/mutants.out/ go (default target/mutants)
#   MUTANTS_STAGE  the staging workspace (default $TMPDIR/cvm-mutants-stage;
#                  its build cache is kept next to it, in .target)
#   MUTANTS_RE     only the mutants of these functions (a regex over
#                  names such as `Scorer::scale|reciprocal`), instead of
#                  the pass's own selection within its files
#   MUTANTS_TIMEOUT  test timeout in seconds (default 30 for the fw-app
#                  pass, whose tests take a second, 240 for the others)
#   MUTANTS_BUILD_TIMEOUT  seconds (default 600)
#   CARGO_BUILD_JOBS  cargo's parallelism per build (default 1)
#   MUTANTS_NEXTEST  1 (default when cargo-nextest is installed) runs each
#                  mutant's tests with nextest: in parallel, stopping at the
#                  first failure, so a caught mutant costs its first failing
#                  test instead of every test binary before it; 0 uses
#                  cargo test
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

rev=${MUTANTS_REV:-HEAD}
out=${MUTANTS_OUT:-$root/target/mutants}
stage=${MUTANTS_STAGE:-${TMPDIR:-/tmp}/cvm-mutants-stage}
export CARGO_BUILD_JOBS=${CARGO_BUILD_JOBS:-1}
export CARGO_TARGET_DIR=$stage.target

passes=()
while [ $# -gt 0 ] && [ "$1" != "--" ]; do
    passes+=("$1")
    shift
done
[ "${1-}" = "--" ] && shift
[ ${#passes[@]} -gt 0 ] || passes=(fw-app acquire stream embed scorer square protocol pipeline decision tables parser emufile rest)

if ! cargo mutants --version >/dev/null 2>&1; then
    cargo install --locked cargo-mutants
fi
runner=()
if [ "${MUTANTS_NEXTEST:-$(cargo nextest --version >/dev/null 2>&1 && echo 1 || echo 0)}" = 1 ]; then
    # cargo-mutants tests the unmutated tree with the mutated package's own
    # tests, which cvm-core and fw-app do not have: not an error.
    runner=(--test-tool=nextest --cargo-test-arg=--no-tests=pass)
fi

# cargo-mutants mutates packages of one cargo workspace and runs that
# workspace's tests. cvm-core and fw-app are path dependencies of the host
# workspace (host-tests/), not members of it, and the repository root is
# the firmware workspace (cross-compiled). So the run uses a staging copy
# of the committed tree with one workspace at its root: members cvm-core,
# fw-app and the host crates, with the host workspace's settings and lock
# file. The crates' relative paths are unchanged, so every path dependency
# and every test that reads a file of the repository (docs/protocol.md,
# README.md)
# resolves inside the copy. cargo-mutants mutates the stage in place (see
# below), never the working tree.
commit=$(git rev-parse --verify "$rev^{commit}")
rm -rf "$stage"
mkdir -p "$stage"
git archive "$commit" cvm-core fw-app docs host-tests | tar -x -C "$stage"
rm -rf "$stage/host-tests/fuzz"
rm -f "$stage/host-tests/Cargo.toml"
mv "$stage/host-tests/Cargo.lock" "$stage/Cargo.lock"
host_members=$(git show "$commit:host-tests/Cargo.toml" |
    sed -n 's/^members = \[\(.*\)\]$/\1/p' | sed 's/"\([^"]*\)"/"host-tests\/\1"/g')
{
    echo '# Staging workspace for scripts/mutants.sh (generated).'
    echo '[workspace]'
    echo 'resolver = "3"'
    echo "members = [\"cvm-core\", \"fw-app\", $host_members]"
    echo
    git show "$commit:host-tests/Cargo.toml" | sed -n '/^\[workspace\.package\]/,$p'
} >"$stage/Cargo.toml"
# These run the firmware (the emulated board under QEMU, the H743 build on
# the chip model), which is not staged; the firmware comparisons cover
# what they would catch (docs/mutants.md).
rm -f "$stage/host-tests/dmap/tests/emulate.rs" "$stage/host-tests/dmap/tests/twin.rs" \
    "$stage/host-tests/dmap/tests/twin_reset.rs" "$stage/host-tests/dmap/tests/twin_input.rs" \
    "$stage/host-tests/dmap/tests/twin_link.rs" "$stage/host-tests/dmap/tests/threshold_zero.rs"

# Functions of each pass (cargo-mutants matches these against the
# mutant's name, e.g. "cvm-core/src/scorer/normalise.rs:72:5: replace Scorer::scale
# -> (u32, i32) with (0, 0)" or "replace + with - in rows").
fn_re() { printf '(replace|in) (%s)( |$)' "$1"; }
embed_fns='sum_and_peak|words_sum|copy_words|mul_hi_round|tri|rows|rows_model|cols|cols_model|max2|sum_copy_blocks|embed'
scorer_fns='Scorer::(normalise|normalise_power|converter|prepare|prepare_with|prepare_into|prepare_map|sum_pass|scale|distance|square_distance|to_score)|recip_sample|shr_sample|fill|squared_difference|squared_difference_blocks|reciprocal|magnitude'
protocol_fns='crc16|LineBuf::[a-z0-9_]+|encode_score|encode_header|encode_row|encode_end|end_fields|HeaderInfo<.*>::new'
core_tests=(--test-package cvm-core-tests --test-package cvm-fw-app-tests)
# The scorer's files but the square kernels' (the passes above split them
# by function); the Cortex-M variants are not compiled on the host.
paper_files=()
for f in scorer.rs scorer/{setup,formats,error,normalise,prepare,score,magnitude,sum,words,embed}.rs \
    scorer/{sum,words}/portable.rs scorer/embed/{factor,layout,passes}.rs scorer/embed/passes/portable.rs; do
    paper_files+=(--file "cvm-core/src/$f")
done
square_files=(--file cvm-core/src/scorer/square.rs --file 'cvm-core/src/scorer/square/**/*.rs')

status=0
baselined=
for pass in "${passes[@]}"; do
    case $pass in
    fw-app) args=(--timeout "${MUTANTS_TIMEOUT:-30}" --package cvm-fw-app --test-package cvm-fw-app-tests
        --file fw-app/src/sequence.rs --file fw-app/src/queue.rs) ;;
    acquire) args=(--timeout "${MUTANTS_TIMEOUT:-30}" --package cvm-fw-app --test-package cvm-fw-app-tests
        --file fw-app/src/acquire.rs --file fw-app/src/driver.rs) ;;
    stream) args=(--package cvm-core "${core_tests[@]}" --file "cvm-core/src/stream/*.rs") ;;
    embed) args=(--package cvm-core "${core_tests[@]}" "${paper_files[@]}"
        --re "$(fn_re "$embed_fns")") ;;
    scorer) args=(--package cvm-core "${core_tests[@]}" "${paper_files[@]}"
        --re "$(fn_re "$scorer_fns")") ;;
    square) args=(--package cvm-core "${core_tests[@]}" "${square_files[@]}") ;;
    protocol) args=(--package cvm-core "${core_tests[@]}" --file 'cvm-core/src/protocol/**/*.rs'
        --re "$(fn_re "$protocol_fns")") ;;
    pipeline) args=(--package cvm-core "${core_tests[@]}" --file cvm-core/src/pipeline.rs --file cvm-core/src/settings.rs) ;;
    decision) args=(--package cvm-core "${core_tests[@]}" --file cvm-core/src/power.rs
        --file cvm-core/src/objects.rs) ;;
    tables) args=(--package cvm-core "${core_tests[@]}" --file cvm-core/src/tables.rs
        --file cvm-core/src/config.rs --file cvm-core/src/flags.rs "${paper_files[@]}"
        --exclude-re "$(fn_re "$embed_fns|$scorer_fns")") ;;
    parser) args=(--package cvm-core "${core_tests[@]}" --test-package dmap
        --file 'cvm-core/src/protocol/**/*.rs' --exclude-re "$(fn_re "$protocol_fns")") ;;
    emufile) args=(--package cvm-fw-app --test-package cvm-fw-app-tests --test-package dmap
        --file fw-app/src/emufile.rs) ;;
    rest) args=(--package cvm-core --package cvm-fw-app --test-workspace=true
        --exclude 'fw-app/src/[a-z]*.rs' --exclude "cvm-core/src/stream/*.rs"
        --exclude cvm-core/src/pipeline.rs --exclude cvm-core/src/power.rs
        --exclude cvm-core/src/objects.rs --exclude cvm-core/src/tables.rs
        --exclude cvm-core/src/config.rs --exclude cvm-core/src/flags.rs
        --exclude cvm-core/src/scorer.rs --exclude 'cvm-core/src/scorer/**/*.rs'
        --exclude 'cvm-core/src/protocol/**/*.rs' --exclude cvm-core/src/settings.rs) ;;
    *)
        echo "unknown pass '$pass'" >&2
        exit 2
        ;;
    esac
    if [ -n "${MUTANTS_RE:-}" ]; then
        # Only the mutants of these functions (e.g. after a fix, those of
        # the survivors): replaces the pass's own function filter.
        for i in "${!args[@]}"; do
            [ "${args[$i]}" = --re ] && args[i + 1]="$(fn_re "$MUTANTS_RE")"
        done
        printf '%s\n' "${args[@]}" | grep -qx -e --re || args+=(--re "$(fn_re "$MUTANTS_RE")")
    fi
    case $pass in fw-app | acquire) ;; *) args=(--timeout "${MUTANTS_TIMEOUT:-240}" "${args[@]}") ;; esac
    # The unmutated tree is tested once per test set and invocation.
    tests_of_pass=$(printf '%s\n' "${args[@]}" | grep -A1 -e '--test-' | tr '\n' ' ')
    case " $baselined " in
    *" [$tests_of_pass] "*) args+=(--baseline=skip) ;;
    *) baselined="$baselined [$tests_of_pass]" ;;
    esac
    mkdir -p "$out/$pass"
    echo "== pass $pass: mutants of $commit -> $out/$pass/mutants.out" >&2
    # In place: the stage is this script's own copy, so nothing else sees
    # the mutated files, and one build cache serves every pass.
    s=0
    nice -n 19 cargo mutants \
        --dir "$stage" \
        --in-place \
        "${args[@]}" \
        "${runner[@]}" \
        --build-timeout "${MUTANTS_BUILD_TIMEOUT:-600}" \
        --output "$out/$pass" \
        "$@" || s=$?
    if [ -d "$out/$pass/mutants.out" ]; then
        echo "$commit" >"$out/$pass/mutants.out/commit"
    fi
    # cargo-mutants exits 2 when mutants were missed and 3 on timeouts: a
    # report, not a failure of this script. Anything else is.
    case $s in
    0 | 2 | 3) ;;
    *) status=$s ;;
    esac
done
exit $status
