#!/usr/bin/env bash
# The README's test command: installs what the tests need, then runs them all.
# - the thumbv7em-none-eabihf target and the llvm-tools component
#   (rust-toolchain.toml names both; rustup does not install them by itself
#   when the stable toolchain is already there; tests/firmware_layout.rs
#   reads the firmware's symbols with llvm-nm),
# - qemu-system-arm (Debian's package) for tests/qemu_bit_exact.rs, which
#   runs the kernel on an emulated Cortex-M4F and fails if QEMU is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

rustup target add thumbv7em-none-eabihf
rustup component add llvm-tools

if ! command -v qemu-system-arm >/dev/null 2>&1; then
    echo "test.sh: installing qemu-system-arm (Debian package)"
    sudo=""
    if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
    $sudo apt-get update -qq
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends qemu-system-arm
fi

cargo test --workspace "$@"
