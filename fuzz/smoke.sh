#!/usr/bin/env bash
# Short smoke run of every fuzz target (CI, .ci/run): SECONDS per target
# (default 15) from the committed seeds, failing on any crash, timeout or
# out-of-memory. Needs nightly and cargo-fuzz.
set -euo pipefail
cd "$(dirname "$0")"
secs="${1:-15}"
# No sanitizer by default: the fuzzed code has no `unsafe` on the host (the
# core forbids it off the MCU, host-tools everywhere), so AddressSanitizer
# would only guard the standard library, at the cost of a slower build and
# 3.5-6x slower runs (docs/fuzzing.md). SANITIZER=address for ASan. The
# build goes where campaign.sh puts its own of the same sanitizer.
san=(-s "${SANITIZER:-none}")
if [ "${SANITIZER:-none}" != address ]; then
    san+=(--target-dir "${FUZZ_TARGET_DIR:-target-nosan}")
fi
cargo +nightly fuzz build "${san[@]}"
for t in $(cargo +nightly fuzz list); do
    echo "-- fuzz smoke: $t (${secs} s)"
    work="$(mktemp -d)"
    # Seeds are read-only input; new corpus entries go to a scratch dir.
    set +e
    cargo +nightly fuzz run "${san[@]}" "$t" "$work" "seeds/$t" -- \
        -max_total_time="$secs" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 >"$work.log" 2>&1
    status=$?
    set -e
    grep -E "^(#[0-9]+[[:space:]]+DONE|==[0-9]+== ERROR|SUMMARY|stat::number_of_executed_units)" "$work.log" || true
    if [ "$status" -ne 0 ]; then
        tail -n 40 "$work.log" >&2
        echo "fuzz target $t FAILED (exit $status); the input is in fuzz/artifacts/$t/" >&2
        rm -rf "$work" "$work.log"
        exit 1
    fi
    rm -rf "$work" "$work.log"
done
echo "fuzz smoke: all targets passed"
