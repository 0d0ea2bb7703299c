#!/usr/bin/env bash
# Long fuzzing campaign of one target (docs/fuzzing.md): runs it until RUNS
# executions (default 10^7), one target at a time, niced, and keeps the
# libFuzzer log in fuzz/logs/<target>.log (nice 19 unless NICE=N).
#   bash fuzz/campaign.sh TARGET [RUNS] [EXTRA_CORPUS_DIR...]
# MAX_TIME=S caps the wall time (seconds) when 10^7 does not fit.
# MAX_LEN=B caps the input length; the UFF targets default to 8 KiB (their
# committed seeds are complete files within it; longer inputs only repeat
# data lines and cost a parse and two write-backs each).
# SANITIZER=none builds without AddressSanitizer (into FUZZ_TARGET_DIR,
# default target-nosan, so the ASan build stays cached): the code under test
# has no `unsafe` (the core forbids it off the MCU; host-tools has none), so
# ASan only guards the standard library there, and costs 1.5-2x in speed.
# FORK=N runs N libFuzzer worker processes (-fork=N) on the one corpus; the
# executions counted (and stopped at RUNS) are the workers' total.
# The working corpus is fuzz/corpus/TARGET (not committed), seeded from
# fuzz/seeds/TARGET; extra read-only corpus dirs (e.g. local vendor files)
# may follow.
set -euo pipefail
cd "$(dirname "$0")"
target="$1"
runs="${2:-10000000}"
shift $(( $# >= 2 ? 2 : 1 ))
mkdir -p "corpus/$target" logs "seeds/$target"
case "$target" in
    uff58|uff_signal) max_len="${MAX_LEN:-8192}" ;;
    *) max_len="${MAX_LEN:-}" ;;
esac
san=()
if [ "${SANITIZER:-address}" != address ]; then
    san=(-s "$SANITIZER" --target-dir "${FUZZ_TARGET_DIR:-target-nosan}")
fi
start=$(date +%s)
set +e
nice -n "${NICE:-19}" cargo +nightly fuzz run "${san[@]}" "$target" "corpus/$target" "seeds/$target" "$@" -- \
    -runs="$runs" ${FORK:+-fork=$FORK} ${MAX_TIME:+-max_total_time=$MAX_TIME} ${max_len:+-max_len=$max_len} -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 \
    > "logs/$target.log" 2>&1
rc=$?
set -e
end=$(date +%s)
echo "target=$target sanitizer=${SANITIZER:-address} rc=$rc wall_s=$((end - start)) corpus_files=$(ls "corpus/$target" | wc -l)" | tee -a "logs/$target.log"
grep -E "^#[0-9]+.*(DONE|cov:)" "logs/$target.log" | tail -1
grep -E "stat::number_of_executed_units|stat::peak_rss_mb" "logs/$target.log" || true
exit $rc
