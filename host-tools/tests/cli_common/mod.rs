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
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `dynocomp simulate` of the plate dynamometer's named set-up `preset`
/// (`--dyno-preset`) at `fs` (Hz) into `out`, with `extra` options
/// (duration, seed, ...): (success, stdout, stderr).
pub fn simulate_plate(out: &str, preset: &str, fs: &str, extra: &[&str]) -> (bool, String, String) {
    let mut a = vec!["simulate", "--out", out, "--dyno", "plate", "--dyno-preset", preset, "--fs", fs];
    a.extend(extra);
    dynocomp(&a)
}

/// `dynocomp design` of the FRF file(s) `frf` with the idle record `idle`
/// at `fs` (Hz) into the image `out`, with `extra` options: (success,
/// stdout, stderr).
pub fn design(frf: &str, idle: &str, fs: &str, out: &str, extra: &[&str]) -> (bool, String, String) {
    let mut a = vec!["design", "--frf", frf, "--fs", fs, "--idle", idle, "--out", out];
    a.extend(extra);
    dynocomp(&a)
}

/// Run `dynocomp` with `args` and `input` on its stdin (fed from a thread,
/// so a large input cannot deadlock against the output): (success, stderr,
/// whether all of `input` was taken; the binary may stop reading at an
/// error).
pub fn dynocomp_piped(args: &[&str], input: Vec<u8>) -> (bool, String, bool) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_dynocomp"))
        .args(args)
        .stdin(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run dynocomp");
    let mut stdin = child.stdin.take().expect("stdin");
    let feeder = std::thread::spawn(move || std::io::Write::write_all(&mut stdin, &input).is_ok());
    let out = child.wait_with_output().expect("wait for dynocomp");
    let fed = feeder.join().expect("feeder thread");
    (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned(), fed)
}

/// A path `name` in a per-test-binary, per-process temporary folder `tag`.
/// The first call of a process removes the folders of test processes that
/// have ended (`dynocomp-TAG-PID` with no /proc/PID), so runs do not pile up.
pub fn tmp(tag: &str, name: &str) -> PathBuf {
    static SWEPT: std::sync::Once = std::sync::Once::new();
    SWEPT.call_once(sweep_ended_runs);
    let dir = std::env::temp_dir().join(format!("dynocomp-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// Remove `dynocomp-*-PID` folders in the temporary folder whose process has
/// ended. Only where /proc tells which processes live (Linux).
fn sweep_ended_runs() {
    let proc = std::path::Path::new("/proc");
    if !proc.join("self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) else { return };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(pid) = name.strip_prefix("dynocomp-").and_then(|r| r.rsplit_once('-')).map(|(_, p)| p.to_string())
        else {
            continue;
        };
        if pid.parse::<u32>().is_ok() && !proc.join(&pid).exists() && e.path().is_dir() {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// NRMSE (fractions) per axis of `compensate --truth`'s "compensated" lines.
pub fn compensated_nrmse(stderr: &str) -> [f64; 3] {
    let v: Vec<f64> = ["fx", "fy", "fz"]
        .iter()
        .map(|a| {
            let line = stderr.lines().find(|l| l.starts_with(&format!("{a}: NRMSE"))).expect("an NRMSE line per axis");
            let rest = line.split("compensated ").nth(1).expect("compensated figure");
            rest.split(' ').next().unwrap().parse::<f64>().unwrap() / 100.0
        })
        .collect();
    [v[0], v[1], v[2]]
}
