#!/usr/bin/env bash
# Instruction counts per sample on the emulated Cortex-M4F (issue #6):
# builds qemu/ (bin `icount`) for thumbv7em-none-eabihf with the firmware's
# code generation and runs it under QEMU with -icount shift=0 (1 ns of
# virtual time per instruction; method in qemu/src/bin/icount.rs).
# Needs qemu-system-arm (Debian: apt-get install qemu-system-arm).
set -euo pipefail
cd "$(dirname "$0")/../qemu"
target_dir="${CARGO_TARGET_DIR:-$PWD/../target}/qemu"
# The firmware's code generation (qemu/'s release profile, fat LTO): a fast
# host build's CARGO_PROFILE_* overrides (CI sets them) would count another.
# CI's clippy wrapper (.ci/run) lints the repository's host build, not this.
while read -r v; do unset "$v"; done < <(env | sed -n 's/^\(CARGO_PROFILE_[A-Z0-9_]*\)=.*/\1/p')
unset RUSTC_WORKSPACE_WRAPPER CLIPPY_ARGS
# RUSTFLAGS replaces the repository's firmware link flags (.cargo/config.toml
# adds defmt.x, which these programs do not use): only cortex-m-rt's link.x.
CARGO_TARGET_DIR="$target_dir" RUSTFLAGS="-C link-arg=-Tlink.x" \
    cargo build --release -q --target thumbv7em-none-eabihf --bin icount
exec qemu-system-arm -M mps2-an386 -cpu cortex-m4 -icount shift=0 \
    -semihosting-config enable=on,target=native -nographic -monitor none -serial none \
    -kernel "$target_dir/thumbv7em-none-eabihf/release/icount"
