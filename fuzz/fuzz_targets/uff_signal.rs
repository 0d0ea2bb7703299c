//! UFF 58 / 58b time-history reader (`host-tools/src/io/uff_signal.rs`, the
//! force records `compensate` reads): arbitrary bytes never panic; an
//! accepted record is written back with the project's writer (`UffWriter`,
//! binary 58b and ASCII 58) and reads back with the same axes, length and
//! sample rate (the header's 7 significant digits of Δt) and the same values
//! (58b: bit for bit; ASCII: the writer's 13 significant digits), and the
//! in-place writer (`UffWriter::placed`) gives the same bytes; a rejected
//! input's error names the file and a place in it.
//!
//! The reader takes a path: the bytes go to a scratch file in /dev/shm.
#![no_main]

use dynocomp::io::signal::{read_all, SignalReader, SignalWriter};
use dynocomp::io::uff_signal::{UffReader, UffWriter};
use dynocomp_fuzz::{assert_names_place, scratch_path};
use libfuzzer_sys::fuzz_target;

/// Axes, declared sample rate and channels of the record at `path`.
/// Errors as their one-line context chain.
fn read(path: &std::path::Path) -> Result<(Vec<usize>, Option<f64>, Vec<Vec<f64>>), String> {
    let mut r = UffReader::open(path, None).map_err(|e| format!("{e:#}"))?;
    let (axes, fs) = (r.axes().to_vec(), r.declared_fs_hz());
    let (_, channels) = read_all(&mut r).map_err(|e| format!("{e:#}"))?;
    Ok((axes, fs, channels))
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()) || (a - b).abs() <= rel * a.abs().max(b.abs())
}

fn check_roundtrip(axes: &[usize], fs: f64, channels: &[Vec<f64>], binary: bool) {
    let mut bytes = Vec::new();
    {
        let mut w = UffWriter::new(&mut bytes, axes, fs, binary).expect("writer");
        let slices: Vec<&[f64]> = channels.iter().map(Vec::as_slice).collect();
        w.write_block(None, &slices).expect("an accepted record is writable");
        w.finish().expect("an accepted record is writable");
    }
    // The in-place writer (record length known, positioned writes) gives
    // the same bytes.
    let placed_path = scratch_path("placed.uff");
    {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(&placed_path)
            .expect("scratch file");
        let n = channels.first().map_or(0, Vec::len) as u64;
        let mut w = UffWriter::placed(&file, n, axes, fs, binary).expect("writer");
        let slices: Vec<&[f64]> = channels.iter().map(Vec::as_slice).collect();
        w.write_block(None, &slices).expect("an accepted record is writable in place");
        w.finish().expect("an accepted record is writable in place");
    }
    let placed = std::fs::read(&placed_path).expect("scratch file");
    let _ = std::fs::remove_file(&placed_path);
    assert!(placed == bytes, "the in-place UFF writer differs from the streamed one (binary {binary})");
    let path = scratch_path("roundtrip.uff");
    std::fs::write(&path, &bytes).expect("scratch file");
    let back =
        read(&path).unwrap_or_else(|e| panic!("written UFF time history (binary {binary}) does not read back: {e}"));
    let _ = std::fs::remove_file(&path);
    assert_eq!(back.0, axes, "axes");
    let fs_back = back.1.expect("the writer declares the rate");
    assert!(close(fs_back, fs, 2e-6), "sample rate {fs} read back as {fs_back}");
    assert_eq!(back.2.len(), channels.len());
    let rel = if binary { 0.0 } else { 1e-12 };
    for (x, y) in back.2.iter().zip(channels) {
        assert_eq!(x.len(), y.len(), "record length");
        for (p, q) in x.iter().zip(y) {
            // ASCII: 13 significant digits; values below the normal range
            // keep fewer, so compare those absolutely.
            assert!(
                close(*p, *q, rel) || (!binary && (p - q).abs() <= f64::MIN_POSITIVE),
                "value {q} read back as {p}"
            );
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let path = scratch_path("signal.uff");
    std::fs::write(&path, data).expect("scratch file");
    let source = path.display().to_string();
    let result = read(&path);
    let _ = std::fs::remove_file(&path);
    match result {
        Ok((axes, fs, channels)) => {
            let fs = fs.expect("a UFF time history declares its rate (Δt)");
            for binary in [true, false] {
                check_roundtrip(&axes, fs, &channels, binary);
            }
        }
        Err(e) => assert_names_place(&e, &source),
    }
});
