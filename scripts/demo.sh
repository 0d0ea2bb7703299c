#!/usr/bin/env bash
# The main job on the bundled example (a simulated 9257-class dynamometer,
# TPF 1.1 kHz): design a compensator from the impact-test FRF, compensate
# the recorded cutting forces with it, and score raw and compensated forces
# against the simulator's true force. Outputs go to out/.
set -euo pipefail
cd "$(dirname "$0")/.."
echo "building dynocomp (release; the first build takes a few minutes)" >&2
cargo build --release -p dynocomp --bin dynocomp --example score
tgt="${CARGO_TARGET_DIR:-target}"
bin="$tgt/release/dynocomp"
mkdir -p out
"$bin" design --frf data/example/frf.uff --fs 51200 --idle data/example/idle.csv \
    --out out/example.dcimg --report out/report
"$bin" inspect out/example.dcimg
"$bin" compensate --coeffs out/example.dcimg --input data/example/measured.csv --output out/compensated.csv \
    --report out/compensation --truth data/example/true_force.csv
"$tgt/release/examples/score" data/example/true_force.csv out/compensated.csv data/example/measured.csv 51200 4000
echo "reports: out/report/index.html (design), out/compensation/index.html (compensation)"
