#!/usr/bin/env bash
# Fuzzes every mesh reader and the model file loader for a bounded time: a test-like command,
# not run in CI.
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]   (default: 60 s for each of medit gmsh_v22 gmsh_v41 vtk model)
#
# Uses cargo-fuzz (libFuzzer; needs a nightly toolchain, or RUSTC_BOOTSTRAP=1 on stable) when it
# is installed: each target starts from its seeds (fuzz/seeds/<target>, committed) and its growing
# corpus (fuzz/corpus/<target>, ignored by git); crashes land in fuzz/artifacts/<target>. Without
# cargo-fuzz it falls back to the in-process mutation campaigns of the tests: the fem-core one for
# the readers (`cargo test -p fem-core --release --test fuzz_readers -- --ignored long_campaign`)
# and latent-sim's mutation test for `model`, with about 300 cases a second.
#
# Every input must end in a valid mesh or a typed error with file, line and reason (a model or a
# typed error for `model`, whose simulator is then built and stepped once); a panic, a malformed
# error, an allocation of 512 MB or more, RSS over 1 GB or 10 s on one input is a failure. Exits
# non-zero when any target fails.
set -euo pipefail

seconds=${1:-60}
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(medit gmsh_v22 gmsh_v41 vtk model)
fi
root=$(cd "$(dirname "$0")/.." && pwd)

if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "cargo-fuzz not found (cargo install cargo-fuzz): running the in-process campaigns instead" >&2
    cd "$root"
    readers=false
    for target in "${targets[@]}"; do
        case $target in
            model)
                PROPTEST_CASES=$((seconds * 300)) cargo test -p latent-sim --release --test unit -- \
                    mutated_files_never_panic
                ;;
            *) readers=true ;;
        esac
    done
    if $readers; then
        FUZZ_SECONDS=$seconds cargo test -p fem-core --release --test fuzz_readers -- \
            --ignored long_campaign --nocapture
    fi
    exit
fi

# libFuzzer's instrumentation needs nightly flags; stable can be told to allow them.
if cargo +nightly --version >/dev/null 2>&1; then
    fuzz=(cargo +nightly fuzz)
else
    echo "no nightly toolchain: using stable with RUSTC_BOOTSTRAP=1" >&2
    export RUSTC_BOOTSTRAP=1
    fuzz=(cargo fuzz)
fi

cd "$root/fuzz"
"${fuzz[@]}" build

failed=()
for target in "${targets[@]}"; do
    mkdir -p "corpus/$target"
    log="$root/fuzz/target/fuzz-$target.log"
    echo "== $target: ${seconds} s"
    # A model file is larger than a mesh seed.
    max_len=8192
    if [ "$target" = model ]; then max_len=16384; fi
    if "${fuzz[@]}" run "$target" "corpus/$target" "seeds/$target" -- \
        -max_total_time="$seconds" -max_len="$max_len" -rss_limit_mb=1024 -malloc_limit_mb=512 -timeout=10 \
        -print_final_stats=1 >"$log" 2>&1; then
        runs=$(grep -Eo 'stat::number_of_executed_units: *[0-9]+' "$log" | grep -Eo '[0-9]+$' || echo "?")
        units=$(find "corpus/$target" -type f | wc -l)
        echo "   ok: $runs inputs, none ended other than in a mesh or a typed error; corpus $units files"
    else
        echo "   FAILED: see $log and fuzz/artifacts/$target/" >&2
        tail -n 30 "$log" >&2
        failed+=("$target")
    fi
done

if [ ${#failed[@]} -gt 0 ]; then
    echo "fuzz targets failed: ${failed[*]}" >&2
    exit 1
fi
