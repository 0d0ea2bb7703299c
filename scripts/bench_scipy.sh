#!/usr/bin/env bash
# scipy reference for the offline compensator (issue #6), in one run:
# designs the bundled example's image, exports its compensators for scipy,
# times our `compensate` (in memory) and scipy's sosfilt / lfilter / dlsim on
# the same filter and data, reports the ratios, and checks scipy's output of
# the same filter against `dynocomp compensate` (independent f64 reference).
# Needs python3 with venv; installs numpy and scipy into a venv (VENV, default
# target/bench-venv). Figures: BENCHMARKS.md.
set -euo pipefail
cd "$(dirname "$0")/.."
tgt="${CARGO_TARGET_DIR:-target}"
venv="${VENV:-$tgt/bench-venv}"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install -q numpy scipy
fi
cargo build --release -q -p dynocomp --bin dynocomp --example sos_export
work="$tgt/bench-scipy"
mkdir -p "$work"
"$tgt/release/dynocomp" design --frf data/example/frf.uff --fs 51200 --idle data/example/idle.csv \
    --out "$work/example.dcimg"
"$tgt/release/dynocomp" compensate --coeffs "$work/example.dcimg" --input data/example/measured.csv \
    --output "$work/compensated_raw.csv" --raw-timing
"$tgt/release/examples/sos_export" "$work/example.dcimg" data/example/measured.csv "$work/filters.json" \
    | tee "$work/ours.txt"
"$venv/bin/python" scripts/bench_scipy.py "$work/filters.json" data/example/measured.csv \
    "$work/compensated_raw.csv" "$work/ours.txt"
