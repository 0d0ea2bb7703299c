//! Build script of `dynocomp-core`.
//!
//! Only for the firmware (feature `firmware` on a bare-metal ARM target): put the repository's
//! `memory.x` (STM32G474RE map with the coefficient slots) on the linker
//! search path so cortex-m-rt's `link.x` finds it, and rebuild when it
//! changes. For every other target (host builds and tests) it does nothing.

use std::env;
use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let target = env::var("TARGET").unwrap_or_default();
    let firmware = env::var_os("CARGO_FEATURE_FIRMWARE").is_some();
    if !(firmware && target.starts_with("thumb") && target.contains("-none-")) {
        // Host builds, and bare-metal builds of the core alone (e.g. the
        // QEMU kernel test), bring their own memory map.
        return;
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let memory_x = manifest.join("memory.x");
    std::fs::copy(&memory_x, out.join("memory.x")).expect("copy memory.x to OUT_DIR");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
}
