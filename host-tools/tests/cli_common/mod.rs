//! Helpers for tests that run the `dynocomp` binary on the bundled example.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

/// Path of a file of the bundled example (`data/example/`).
pub fn example(name: &str) -> String {
    format!("{}/../data/example/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// Run `dynocomp` with `args`: (success, stdout, stderr).
pub fn dynocomp(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_dynocomp")).args(args).output().expect("run dynocomp");
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into_owned(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// A path `name` in a per-test-binary, per-process temporary folder `tag`.
pub fn tmp(tag: &str, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("dynocomp-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}
