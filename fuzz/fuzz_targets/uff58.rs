//! UFF 58 / 58b FRF reader (`host-tools/src/io/uff.rs`), direct and cross
//! entries (response and reference directions): arbitrary bytes never
//! panic; the reader with units agrees with the plain one; an accepted FRF
//! that the writer can export (evenly spaced lines) reads back from both
//! ASCII and binary 58 with the same entries and values (binary: exact;
//! ASCII: the writer's 13 significant digits; frequencies: the header's
//! E13.6 f0 and Δf); a rejected input's error names the file and a place in it.
#![no_main]

use dynocomp::frf::Frf;
use dynocomp::io::uff::{parse_uff58, parse_uff58_units, uff58_to_bytes};
use dynocomp_fuzz::assert_names_place;
use libfuzzer_sys::fuzz_target;

const SOURCE: &str = "fuzz.uff";

fn close(a: f64, b: f64, rel: f64, abs: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) + abs
}

fn check_roundtrip(frf: &Frf, binary: bool) {
    let Ok(bytes) = uff58_to_bytes(frf, binary) else {
        // Uneven lines (the CSV-only case) are refused by the writer.
        return;
    };
    let back = parse_uff58(&bytes, "roundtrip.uff")
        .unwrap_or_else(|e| panic!("written UFF 58 (binary {binary}) does not read back: {e:#}"));
    assert_eq!(back.freq_hz.len(), frf.freq_hz.len());
    let n = frf.freq_hz.len();
    let span = frf.freq_hz[n - 1].abs().max(frf.freq_hz[0].abs());
    for (a, b) in back.freq_hz.iter().zip(&frf.freq_hz) {
        // f0 and Δf are written with 7 significant digits.
        assert!(close(*a, *b, 2e-6, 2e-6 * span), "frequency {b} read back as {a}");
    }
    assert_eq!(back.axes.len(), frf.axes.len());
    assert_eq!(back.cross.len(), frf.cross.len());
    let rel = if binary { 0.0 } else { 1e-12 };
    for (x, y) in back.entries().zip(frf.entries()) {
        assert_eq!((x.channel, x.direction), (y.channel, y.direction));
        assert_eq!(x.coherence.is_some(), y.coherence.is_some());
        for (p, q) in x.frf.iter().zip(y.frf) {
            assert!(close(p.re, q.re, rel, 0.0) && close(p.im, q.im, rel, 0.0), "FRF value {q} read back as {p}");
        }
        if let (Some(p), Some(q)) = (x.coherence, y.coherence) {
            for (p, q) in p.iter().zip(q) {
                assert!(close(*p, *q, rel, 0.0), "coherence {q} read back as {p}");
            }
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let with_units = parse_uff58_units(data, SOURCE);
    match parse_uff58(data, SOURCE) {
        Ok(frf) => {
            let (same, units) = with_units.expect("the reader with units accepts what the plain one does");
            assert_eq!(same, frf);
            if let Some(u) = units {
                assert!(u.contains('/') && !u.contains('\n'), "units label {u:?}");
            }
            check_roundtrip(&frf, true);
            check_roundtrip(&frf, false);
        }
        Err(e) => {
            assert!(with_units.is_err(), "the reader with units accepts what the plain one refuses");
            assert_names_place(&format!("{e:#}"), SOURCE)
        }
    }
});
