#!/usr/bin/env bash
# Short smoke run of every fuzz target (CI, .ci/run): SECONDS per target
# (default 15) from the committed seeds, one target per core at a time
# (SMOKE_JOBS=N to change), failing on any crash, timeout or
# out-of-memory. SMOKE_BUILD_ONLY=1 builds the targets and stops (CI builds
# them in the background while the tests run). Needs a nightly toolchain, not cargo-fuzz: the targets are
# built with the flags `cargo fuzz build -s none` passes to cargo (rust-fuzz/
# cargo-fuzz, src/project.rs: SanitizerCoverage with inline 8-bit counters,
# PC table, compare tracing and stack depth, `--cfg fuzzing`, debug
# assertions, release with line tables) and the libFuzzer binaries run directly. Installing
# cargo-fuzz from source took several minutes of every CI run. Two things
# differ, for build time: 16 codegen units instead of cargo-fuzz's one (a
# 6-second smoke gains nothing from the faster executions), and the flags
# reach only this repository's crates (fuzz/instrument.sh), not registry
# dependencies: the build took 176-186 s instead of 232 s. The edges
# counted fell by 0-8 % on nine targets and by 18 % on signal_csv (memchr,
# ryu) and sidecar (serde_json): edges of the dependencies, no longer
# instrumented.
set -euo pipefail
cd "$(dirname "$0")"
secs="${1:-15}"
# No sanitizer: the fuzzed code has no `unsafe` on the host (the core
# forbids it off the MCU, host-tools everywhere), so AddressSanitizer would
# only guard the standard library, at the cost of a slower build and
# 3.5-6x slower runs (docs/fuzzing.md). Campaigns with ASan: campaign.sh.
triple="$(rustc +nightly -vV | sed -n 's/^host: //p')"
tgt="${FUZZ_SMOKE_TARGET_DIR:-target-smoke}"
flags=(
    -Cpasses=sancov-module
    -Cllvm-args=-sanitizer-coverage-level=4
    -Cllvm-args=-sanitizer-coverage-inline-8bit-counters
    -Cllvm-args=-sanitizer-coverage-pc-table
    -Cllvm-args=-sanitizer-coverage-trace-compares
    --cfg fuzzing
    -Cllvm-args=-simplifycfg-branch-fold-threshold=0
    -Cllvm-args=-sanitizer-coverage-stack-depth
    -Cdebug-assertions
    -Ccodegen-units=16
)
# instrument.sh, the RUSTC_WRAPPER, adds the flags to this repository's
# crates but not their build scripts; --target keeps any RUSTFLAGS of the
# caller off build scripts and proc macros (as cargo-fuzz does).
DYNOCOMP_FUZZ_FLAGS="${flags[*]}" RUSTC_WRAPPER="$PWD/instrument.sh" cargo +nightly build --manifest-path Cargo.toml --release \
    --config 'profile.release.debug="line-tables-only"' --target "$triple" --target-dir "$tgt" --bins
[ "${SMOKE_BUILD_ONLY:-0}" = 1 ] && { echo "fuzz smoke: targets built"; exit 0; }
targets=$(sed -n 's/^name = "\(.*\)"$/\1/p' Cargo.toml | grep -v '^dynocomp-fuzz$')
[ -n "$targets" ] || { echo "fuzz smoke: no [[bin]] targets found in fuzz/Cargo.toml" >&2; exit 1; }
# One libFuzzer process per core at a time (each is single-threaded); each
# target's summary is printed when it ends, in the order of Cargo.toml.
jobs="${SMOKE_JOBS:-$(nproc)}"
logs="$(mktemp -d)"
run_one() {
    local t="$1" work status
    work="$(mktemp -d)"
    mkdir -p "artifacts/$t"
    # Seeds are read-only input; new corpus entries go to a scratch dir.
    set +e
    "$tgt/$triple/release/$t" -artifact_prefix="artifacts/$t/" "$work" "seeds/$t" \
        -max_total_time="$secs" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 >"$logs/$t.log" 2>&1
    status=$?
    set -e
    rm -rf "$work"
    echo "$status" >"$logs/$t.status"
}
running=0
for t in $targets; do
    run_one "$t" &
    running=$((running + 1))
    if [ "$running" -ge "$jobs" ]; then wait -n || true; running=$((running - 1)); fi
done
wait
failed=0
for t in $targets; do
    echo "-- fuzz smoke: $t (${secs} s)"
    grep -E "^(#[0-9]+[[:space:]]+DONE|==[0-9]+== ERROR|SUMMARY|stat::number_of_executed_units)" "$logs/$t.log" || true
    status="$(cat "$logs/$t.status" 2>/dev/null || echo 1)"
    if [ "$status" -ne 0 ]; then
        tail -n 40 "$logs/$t.log" >&2
        echo "fuzz target $t FAILED (exit $status); the input is in fuzz/artifacts/$t/" >&2
        failed=1
    fi
done
rm -rf "$logs"
[ "$failed" = 0 ] || exit 1
echo "fuzz smoke: all targets passed"
