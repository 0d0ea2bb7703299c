#!/usr/bin/env bash
# RUSTC_WRAPPER of fuzz/smoke.sh: the coverage flags ($DYNOCOMP_FUZZ_FLAGS)
# go to this repository's crates (the readers under test and the targets),
# not to registry dependencies or build scripts.
set -euo pipefail
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
case "$src" in
    "" | */.cargo/registry/* | */.cargo/git/*) exec "$rustc" "$@" ;;
esac
[ "$name" = build_script_build ] && exec "$rustc" "$@"
# shellcheck disable=SC2086 # the flags are words
exec "$rustc" "$@" $DYNOCOMP_FUZZ_FLAGS
