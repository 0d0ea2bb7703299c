#!/usr/bin/env bash
# RUSTC_WRAPPER of fuzz/smoke.sh: the coverage flags ($DYNOCOMP_FUZZ_FLAGS)
# go to this repository's crates (the readers under test and the targets),
# not to registry dependencies (wherever CARGO_HOME puts them) or build
# scripts.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd -P)"
rustc="$1"
shift
src=""
name=""
prev=""
for a in "$@"; do
    [ "$prev" = "--crate-name" ] && name="$a"
    case "$a" in *.rs) src="$a" ;; esac
    prev="$a"
done
# The crate root as an absolute path (cargo passes some relative to its
# working directory).
case "$src" in
    "") exec "$rustc" "$@" ;;
    /*) ;;
    *) src="$(pwd)/$src" ;;
esac
case "$(cd "$(dirname "$src")" 2>/dev/null && pwd -P)/" in
    "$repo"/*) ;;
    *) exec "$rustc" "$@" ;;
esac
[ "$name" = build_script_build ] && exec "$rustc" "$@"
# shellcheck disable=SC2086 # the flags are words
exec "$rustc" "$@" $DYNOCOMP_FUZZ_FLAGS
