#!/usr/bin/env bash
# The Python package's tests (python/): a venv under target/ (never the
# system Python) with pinned build and test tools, one release build of the
# extension (`pip install ./python`, maturin), pytest, and the quickstart
# notebook executed. Called by scripts/test.sh; runs alone too.
# Needs python3 >= 3.10 with the venv module (Debian: python3-venv).
set -euo pipefail
cd "$(dirname "$0")/.."

tgt="${CARGO_TARGET_DIR:-target}"
# Absolute, so that PATH below holds for a CARGO_TARGET_DIR given either way.
case "$tgt" in /*) ;; *) tgt="$PWD/$tgt" ;; esac
venv="$tgt/python-venv"
py="${PYTHON:-python3}"
if [ ! -x "$venv/bin/python" ]; then
    "$py" -m venv "$venv" || {
        echo "error: $py -m venv failed: install Python >= 3.10 with its venv module (Debian: python3-venv)" >&2
        exit 1
    }
fi
# Pinned: the build backend, the test runner, the notebook's kernel and
# plots (numpy 2.4 is the last release for Python 3.11).
"$venv/bin/python" -m pip install -q --disable-pip-version-check \
    maturin==1.16.0 pytest==9.2.0 numpy==2.4.6 matplotlib==3.11.2 \
    nbclient==0.11.0 nbformat==5.11.1 ipykernel==7.4.0

# The build backend runs the venv's `maturin`.
export PATH="$venv/bin:$PATH"

# One release build of the extension, in the root's cargo target directory
# although python/ is outside the root workspace (its own Cargo.lock): the
# dependencies both locks pin alike are built once (in a clean CI run,
# after the 3x3 tests' release build, the extension took 140 s instead of
# 228 s in a directory of its own). The tests need the same bits, not the speed: the
# package's fat-LTO profile (python/Cargo.toml) is overridden here for
# build time (pip and maturin pass the environment on to cargo).
# PYTHON_EXT_PROFILE=package keeps it.
t0=$(date +%s)
# Called from scripts/test.sh, it also drops the test build's debug
# assertions and overflow checks (the package's profile has neither), and
# CI's clippy wrapper (.ci/run lints the root workspace, not the extension).
fast=(CARGO_PROFILE_RELEASE_LTO=false CARGO_PROFILE_RELEASE_CODEGEN_UNITS=16
    CARGO_PROFILE_RELEASE_DEBUG_ASSERTIONS=false CARGO_PROFILE_RELEASE_OVERFLOW_CHECKS=false)
[ "${PYTHON_EXT_PROFILE:-fast}" = package ] && fast=(-u CARGO_PROFILE_RELEASE_DEBUG_ASSERTIONS -u CARGO_PROFILE_RELEASE_OVERFLOW_CHECKS
    -u CARGO_PROFILE_RELEASE_LTO -u CARGO_PROFILE_RELEASE_CODEGEN_UNITS -u CARGO_PROFILE_RELEASE_DEBUG)
env -u RUSTC_WORKSPACE_WRAPPER -u CLIPPY_ARGS "${fast[@]}" CARGO_TARGET_DIR="$tgt" "$venv/bin/python" -m pip install -q --disable-pip-version-check \
    --no-build-isolation --force-reinstall --no-deps ./python
echo "python: built and installed the extension in $(( $(date +%s) - t0 )) s"

# The tests compare against the CLI's own outputs: the same release binary
# the demo builds (or DYNOCOMP_BIN, a `dynocomp` built already).
if [ -z "${DYNOCOMP_BIN:-}" ]; then
    cargo build --release -q -p dynocomp --bin dynocomp
    export DYNOCOMP_BIN="$tgt/release/dynocomp"
fi
"$venv/bin/python" -m pytest -q python/tests
"$venv/bin/python" python/examples/run_notebook.py python/examples/quickstart.ipynb
