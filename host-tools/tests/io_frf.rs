//! FRF import/export: pyuff-written UFF fixtures, CSV and UFF round trips,
//! one-line error messages for malformed input, and no panics on any input.

use std::path::{Path, PathBuf};

use dynocomp::frf::{AxisFrf, Frf};
use dynocomp::io::{frf_csv, read_frf, uff};
use num_complex::Complex64;
use proptest::prelude::*;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/uff").join(name)
}

/// Compare what we read with what pyuff was told to write.
fn assert_close(got: &Frf, want: &Frf, rtol: f64, what: &str) {
    assert_eq!(got.freq_hz.len(), want.freq_hz.len(), "{what}: number of lines");
    for (i, (a, b)) in got.freq_hz.iter().zip(&want.freq_hz).enumerate() {
        assert!((a - b).abs() <= 1e-9 * b.abs().max(1.0), "{what}: freq line {i}: {a} vs {b}");
    }
    let axes = |f: &Frf| f.axes.iter().map(|a| a.axis).collect::<Vec<_>>();
    assert_eq!(axes(got), axes(want), "{what}: axes");
    for (g, w) in got.axes.iter().zip(&want.axes) {
        let scale = w.frf.iter().map(|v| v.norm()).fold(0.0, f64::max);
        for (i, (a, b)) in g.frf.iter().zip(&w.frf).enumerate() {
            assert!((a - b).norm() <= rtol * scale, "{what}: axis {} line {i}: {a} vs {b}", g.axis);
        }
        assert_eq!(g.coherence.is_some(), w.coherence.is_some(), "{what}: coherence presence");
        if let (Some(gc), Some(wc)) = (&g.coherence, &w.coherence) {
            for (i, (a, b)) in gc.iter().zip(wc).enumerate() {
                assert!((a - b).abs() <= rtol, "{what}: axis {} coherence line {i}: {a} vs {b}", g.axis);
            }
        }
    }
}

fn check_fixture(name: &str, rtol: f64, axes: &[usize]) -> Frf {
    let uff_path = fixture(&format!("{name}.uff"));
    let got = uff::read_uff58(&uff_path).unwrap_or_else(|e| panic!("{e:#}"));
    let want = frf_csv::read_frf_csv(&fixture(&format!("{name}.expected.csv"))).unwrap_or_else(|e| panic!("{e:#}"));
    assert_eq!(got.axes.iter().map(|a| a.axis).collect::<Vec<_>>(), axes);
    assert_close(&got, &want, rtol, name);
    // The dispatcher picks the UFF reader by extension.
    assert_eq!(read_frf(&uff_path).unwrap(), got);
    got
}

#[test]
fn pyuff_ascii_double_three_axes_with_sign_flip_and_header_datasets() {
    // Datasets 151 and 164 in front are skipped; z was written with response
    // direction -3 and negated data: we must read +1 at DC, not -1.
    let f = check_fixture("ascii_double_xyz", 1e-10, &[0, 1, 2]);
    assert_eq!(f.freq_hz.len(), 129);
    assert_eq!(f.freq_hz[128], 1024.0);
    let z = f.axis(2).unwrap();
    assert!((z.frf[0] - Complex64::new(1.0, 0.0)).norm() < 1e-10, "z sign: {}", z.frf[0]);
    // Coherence is not flipped.
    assert!(z.coherence.as_ref().unwrap()[1..].iter().all(|&c| c > 0.4));
}

#[test]
fn pyuff_binary_double_with_sign_flip() {
    // pyuff writes n_bytes = points*8 for complex data (half the real size).
    let f = check_fixture("binary_double_xy", 1e-14, &[0, 1]);
    assert_eq!(f.freq_hz.len(), 257);
    assert_eq!(f.freq_hz[256], 4096.0);
    assert!((f.axis(1).unwrap().frf[0].re - 1.0).abs() < 1e-14);
}

#[test]
fn pyuff_ascii_single_precision() {
    let f = check_fixture("ascii_single_xz", 2e-5, &[0, 2]);
    assert!((f.axis(2).unwrap().frf[0].re - 1.0).abs() < 1e-5);
}

#[test]
fn pyuff_ascii_uneven_abscissa() {
    let f = check_fixture("ascii_uneven_y", 1e-10, &[1]);
    assert_eq!(f.freq_hz[1], 5.25);
}

#[test]
fn binary_single_precision_fixture() {
    check_fixture("binary_single_x", 1e-6, &[0]);
}

fn sample_frf(freq: Vec<f64>, coh_axes: &[usize], axes: &[usize]) -> Frf {
    let n = freq.len();
    Frf {
        axes: axes
            .iter()
            .map(|&axis| AxisFrf {
                axis,
                frf: (0..n)
                    .map(|i| {
                        let t = i as f64 * 0.37 + axis as f64;
                        Complex64::new(t.cos() / (1.0 + i as f64 * 1e-3), -t.sin() * 1e-7 * (i as f64 + 0.5))
                    })
                    .collect(),
                coherence: coh_axes
                    .contains(&axis)
                    .then(|| (0..n).map(|i| ((i * 7919 + axis) % 1000) as f64 / 999.0).collect()),
            })
            .collect(),
        freq_hz: freq,
        cross: Vec::new(),
    }
}

#[test]
fn csv_round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frf.csv");
    // Uneven lines, tiny and large values: shortest round-trip formatting.
    let freq: Vec<f64> = (0..300).map(|i| (i as f64).powf(1.3) * 0.1).collect();
    let mut frf = sample_frf(freq, &[2], &[0, 2]);
    frf.axes[0].frf[3] = Complex64::new(1e-300, -1.2345678901234567e200);
    frf_csv::write_frf_csv(&path, &frf).unwrap();
    assert_eq!(frf_csv::read_frf_csv(&path).unwrap(), frf);
    assert_eq!(read_frf(&path).unwrap(), frf);
    // Only the file itself in the directory (the temp file was renamed).
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn csv_accepts_semicolons_quotes_case_bom_blank_lines() {
    let text = "\u{feff}\"FREQ_HZ\";\"Y_RE\";\"Y_IM\"\r\n0;1;0\r\n\r\n10.5;0.5;-0.25\r\n";
    let f = frf_csv::parse_frf_csv(text, "eu.csv").unwrap();
    assert_eq!(f.freq_hz, vec![0.0, 10.5]);
    assert_eq!(f.axes.len(), 1);
    assert_eq!(f.axes[0].axis, 1);
    assert_eq!(f.axes[0].frf[1], Complex64::new(0.5, -0.25));
    assert!(f.axes[0].coherence.is_none());
}

#[test]
fn uff_round_trip_ascii_and_binary() {
    let dir = tempfile::tempdir().unwrap();
    // The simulator's lines: 0..4096 Hz, 4097 lines.
    let freq: Vec<f64> = (0..=4096).map(f64::from).collect();
    let frf = sample_frf(freq, &[0, 2], &[0, 1, 2]);
    for binary in [false, true] {
        let path = dir.path().join(if binary { "b.uff" } else { "a.uff" });
        uff::write_uff58(&path, &frf, binary).unwrap();
        let back = uff::read_uff58(&path).unwrap_or_else(|e| panic!("{e:#}"));
        if binary {
            assert_eq!(back, frf, "binary round trip is bit exact");
        } else {
            assert_close(&back, &frf, 1e-12, "ascii");
        }
        assert_eq!(read_frf(&path).unwrap(), back);
    }
    // A non-integer spacing survives (7 significant digits in record 7).
    let frf = sample_frf((0..513).map(|i| i as f64 * 0.78125).collect(), &[1], &[1]);
    let bytes = uff::uff58_to_bytes(&frf, false).unwrap();
    assert_close(&uff::parse_uff58(&bytes, "mem").unwrap(), &frf, 1e-12, "0.78125 Hz");
    // Content sniffing when the extension says nothing.
    let path = dir.path().join("frf.dat");
    std::fs::write(&path, &bytes).unwrap();
    assert_close(&read_frf(&path).unwrap(), &frf, 1e-12, "sniffed");
}

#[test]
fn writers_refuse_bad_frf_and_leave_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.uff");
    let uneven = sample_frf(vec![0.0, 1.0, 3.0], &[], &[0]);
    let e = format!("{:#}", uff::write_uff58(&path, &uneven, true).unwrap_err());
    assert!(e.contains("out.uff") && e.contains("evenly spaced") && e.contains("line 2 is 1 Hz"), "{e}");
    let mut nan = sample_frf(vec![0.0, 1.0], &[0], &[0]);
    nan.axes[0].frf[1].re = f64::NAN;
    let csv = dir.path().join("out.csv");
    let e = format!("{:#}", frf_csv::write_frf_csv(&csv, &nan).unwrap_err());
    assert!(e.contains("out.csv") && e.contains("not finite"), "{e}");
    let mut bad_coh = sample_frf(vec![0.0, 1.0], &[0], &[0]);
    bad_coh.axes[0].coherence.as_mut().unwrap()[0] = 1.5;
    assert!(uff::write_uff58(&path, &bad_coh, false).is_err());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "nothing left behind");
}

// ----- malformed CSV -------------------------------------------------------

fn csv_err(text: &str) -> String {
    let e = frf_csv::parse_frf_csv(text, "bad.csv").expect_err(text);
    let msg = format!("{e}");
    assert!(msg.contains("bad.csv"), "{msg}");
    assert!(!msg.contains('\n'), "one line: {msg}");
    msg
}

fn has(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "{msg:?} should contain {p:?}");
    }
}

#[test]
fn csv_errors_name_file_line_column_and_problem() {
    has(&csv_err(""), &["empty file"]);
    has(&csv_err("\n  \n"), &["empty file"]);
    has(&csv_err("freq_hz,x_re,x_im\n"), &["no data rows"]);
    has(&csv_err("freq_hz,x_re,x_im\n0,1,0\n10,1,0\n10,1,0\n"), &["line 4, column 1 (freq_hz)", "strictly ascending"]);
    has(&csv_err("freq_hz,x_re,x_im\n5,1,0\n2,1,0\n"), &["line 3", "strictly ascending"]);
    has(&csv_err("freq_hz,x_re,x_im\n-1,1,0\n"), &["line 2, column 1", "negative frequency"]);
    has(&csv_err("freq_hz,x_re,x_im\n0,NaN,0\n"), &["line 2, column 2 (x_re)", "not finite"]);
    has(&csv_err("freq_hz,x_re,x_im\n0,1,inf\n"), &["line 2, column 3 (x_im)", "not finite"]);
    has(&csv_err("freq_hz,x_re,x_im\n0,1,abc\n"), &["line 2, column 3 (x_im)", "cannot read \"abc\""]);
    has(&csv_err("freq_hz,x_re,x_im\n0,,0\n"), &["line 2, column 2 (x_re)", "empty value"]);
    has(&csv_err("freq_hz,x_re,y_im\n0,1,0\n"), &["line 1", "x_re", "no matching x_im"]);
    has(&csv_err("freq_hz,x_coh\n0,1\n"), &["line 1", "x_coh", "without x_re and x_im"]);
    has(
        &csv_err("freq_hz,x_re,x_im,x_coh\n0,1,0,0.5\n1,1,0,1.5\n"),
        &["line 3, column 4 (x_coh)", "coherence 1.5 outside [0, 1]"],
    );
    has(&csv_err("freq_hz,x_re,x_im,x_coh\n0,1,0,-0.1\n"), &["line 2, column 4", "outside [0, 1]"]);
    has(&csv_err("freq_hz,x_re,x_im\n0,1,0\n1,1\n"), &["line 3", "2 fields", "3 columns"]);
    has(&csv_err("freq_hz,x_re,x_im\n0,1,0,7\n"), &["line 2", "4 fields"]);
    has(&csv_err("freq_hz,fx_re,x_im\n0,1,0\n"), &["line 1, column 2", "unknown column name \"fx_re\""]);
    has(&csv_err("freq_hz,x_re,x_im,X_RE\n0,1,0,1\n"), &["line 1, column 4", "duplicate column x_re", "axis x"]);
    has(&csv_err("freq_hz,freq_hz,x_re,x_im\n0,0,1,0\n"), &["column 2", "duplicate column freq_hz"]);
    has(&csv_err("x_re,x_im\n1,0\n"), &["line 1", "missing column freq_hz"]);
    has(&csv_err("freq_hz\n1\n"), &["no FRF columns"]);
    let e = format!("{}", frf_csv::parse_frf_csv_bytes(b"freq_hz,x_re,x_im\n\xff,1,0\n", "bad.csv").unwrap_err());
    has(&e, &["bad.csv", "line 2", "UTF-8"]);
}

// ----- malformed UFF -------------------------------------------------------

/// A hand-made ASCII dataset 58. Line 1 of the block is the opening `-1`,
/// record 6 is line 8, record 7 line 9, records 8-11 lines 10-13, data from 14.
#[allow(clippy::too_many_arguments)]
fn ds58(
    ft: i64,
    rsp: i64,
    refd: i64,
    ord: i64,
    n: usize,
    spacing: i64,
    min: f64,
    inc: f64,
    specs: [i64; 3],
    data: &str,
) -> String {
    let mut s = String::from("    -1\n    58\n");
    for _ in 0..5 {
        s.push_str("NONE\n");
    }
    s.push_str(&format!(
        "{:>5}{:>10}{:>5}{:>10} {:>10}{:>10}{:>4} {:>10}{:>10}{:>4}\n",
        ft, 0, 0, 0, "NONE", 1, rsp, "NONE", 1, refd
    ));
    let e = |x: f64| format!("{:>13}", format!("{x:.5e}"));
    s.push_str(&format!("{:>10}{:>10}{:>10}{}{}{}\n", ord, n, spacing, e(min), e(inc), e(0.0)));
    for spec in [specs[0], specs[1], specs[2], 0] {
        s.push_str(&format!("{:>10}{:>5}{:>5}{:>5} {:<20} {:<20}\n", spec, 0, 0, 0, "NONE", "NONE"));
    }
    s.push_str(data);
    s.push_str("    -1\n");
    s
}

/// A good x FRF (3 lines, complex double, even 0/10/20 Hz).
fn frf_x() -> String {
    ds58(4, 1, 1, 6, 3, 1, 0.0, 10.0, [18, 9, 13], "  1.0 0.0  0.9 -0.1\n  0.8 -0.2\n")
}

fn coh_x(data: &str, n: usize) -> String {
    ds58(6, 1, 1, 4, n, 1, 0.0, 10.0, [18, 0, 0], data)
}

fn uff_err(bytes: &[u8]) -> String {
    let e = uff::parse_uff58(bytes, "bad.uff").expect_err(&String::from_utf8_lossy(bytes));
    let msg = format!("{e}");
    assert!(msg.contains("bad.uff"), "{msg}");
    assert!(!msg.contains('\n'), "one line: {msg}");
    msg
}

#[test]
fn uff_hand_made_reads_and_sign_rules() {
    let f = uff::parse_uff58((frf_x() + &coh_x("0.5 0.9 1.0\n", 3)).as_bytes(), "ok.uff").unwrap();
    assert_eq!(f.freq_hz, vec![0.0, 10.0, 20.0]);
    assert_eq!(f.axes[0].frf[2], Complex64::new(0.8, -0.2));
    assert_eq!(f.axes[0].coherence.as_deref(), Some(&[0.5, 0.9, 1.0][..]));
    // Negative response direction flips, so does a negative reference; both: no flip.
    for (rsp, refd, sign) in [(-1, 1, -1.0), (1, -1, -1.0), (-1, -1, 1.0), (1, 0, 1.0)] {
        let t = ds58(4, rsp, refd, 6, 1, 1, 0.0, 1.0, [18, 9, 13], "2.0 3.0\n");
        let f = uff::parse_uff58(t.as_bytes(), "ok.uff").unwrap();
        assert_eq!(f.axes[0].frf[0], Complex64::new(2.0 * sign, 3.0 * sign), "rsp {rsp} ref {refd}");
    }
    // Real single precision FRF, uneven abscissa, Fortran D exponents, CRLF.
    let t = ds58(4, 2, 2, 2, 2, 0, 0.0, 0.0, [18, 0, 0], "  1.0D+00  5.0E-01\r\n  2.5 0.25\r\n").replace('\n', "\r\n");
    let f = uff::parse_uff58(t.as_bytes(), "ok.uff").unwrap();
    assert_eq!(f.freq_hz, vec![1.0, 2.5]);
    assert_eq!(f.axes[0].axis, 1);
    assert_eq!(f.axes[0].frf, vec![Complex64::new(0.5, 0.0), Complex64::new(0.25, 0.0)]);
    // Touching fixed-width fields (E13.5 with 3-digit exponents).
    let t = ds58(4, 3, 3, 5, 1, 1, 0.0, 1.0, [18, 9, 13], "-1.23456e+100-2.00000e-100\n");
    let f = uff::parse_uff58(t.as_bytes(), "ok.uff").unwrap();
    assert_eq!(f.axes[0].frf[0], Complex64::new(-1.23456e100, -2e-100));
    // Other function types are skipped next to the FRF; a cross-axis FRF
    // is an off-diagonal entry, not a direct one.
    let t = ds58(4, 1, 2, 6, 3, 1, 0.0, 10.0, [18, 9, 13], "1 0 1 0 1 0\n")
        + &ds58(2, 1, 1, 4, 3, 1, 0.0, 10.0, [18, 0, 0], "1 1 1\n")
        + &frf_x();
    let f = uff::parse_uff58(t.as_bytes(), "ok.uff").unwrap();
    assert_eq!(f.axes.len(), 1);
    assert_eq!(f.cross.len(), 1);
}

#[test]
fn uff_errors_name_file_line_record_and_problem() {
    has(&uff_err(b""), &["empty file"]);
    has(&uff_err(b" \n\n"), &["empty file"]);
    has(&uff_err(b"hello\n"), &["line 1", "expected '    -1'"]);
    has(&uff_err(b"    -1\n"), &["line 1", "dataset number missing"]);
    has(&uff_err(b"    -1\n  abc\n    -1\n"), &["line 2", "expected a dataset number"]);
    // Only non-58 datasets, or only rotational reference directions: no FRF
    // at all (a cross FRF alone is an entry of the matrix, io_frf_matrix.rs).
    let t = "    -1\n   151\nmodel\n    -1\n";
    has(&uff_err(t.as_bytes()), &["no FRF found", "dataset #1 at line 1: type 151"]);
    let t = ds58(4, 1, 5, 6, 1, 1, 0.0, 1.0, [18, 9, 13], "1 0\n");
    has(&uff_err(t.as_bytes()), &["no FRF found", "reference direction 5 is not a translation"]);
    // Unclosed datasets.
    has(&uff_err(b"    -1\n   151\nmodel\n"), &["line 1", "dataset #1 (type 151)", "not closed"]);
    let t = frf_x();
    has(&uff_err(&t.as_bytes()[..t.len() - 7]), &["record 12", "not closed"]);
    // Cut inside record 8 (line 10): the header ends before record 9.
    has(&uff_err(&t.as_bytes()[..200]), &["dataset #1", "record 9", "file ends inside the dataset header"]);
    // Record 6 / 7 problems.
    let t = frf_x().replace("    4         0", "    x         y");
    has(&uff_err(t.as_bytes()), &["line 8", "record 6", "cannot read function type"]);
    let t = ds58(4, 1, 1, 7, 1, 1, 0.0, 1.0, [18, 9, 13], "1 0\n");
    has(&uff_err(t.as_bytes()), &["line 9", "record 7", "ordinate data type 7 not supported"]);
    let t = ds58(4, 1, 1, 6, 1, 3, 0.0, 1.0, [18, 9, 13], "1 0\n");
    has(&uff_err(t.as_bytes()), &["line 9", "record 7", "abscissa spacing 3"]);
    let t = ds58(4, 1, 1, 6, 0, 1, 0.0, 1.0, [18, 9, 13], "\n");
    has(&uff_err(t.as_bytes()), &["record 7", "no data"]);
    let t = ds58(4, 1, 1, 6, 2, 1, 0.0, -1.0, [18, 9, 13], "1 0 1 0\n");
    has(&uff_err(t.as_bytes()), &["line 9", "record 7", "increment", "strictly ascending"]);
    let t = ds58(4, 1, 1, 6, 999_999_999, 1, 0.0, 1.0, [18, 9, 13], "1 0\n");
    has(&uff_err(t.as_bytes()), &["record 7", "more than the file can hold"]);
    // Value count and content.
    let t = ds58(4, 1, 1, 6, 3, 1, 0.0, 1.0, [18, 9, 13], "1 0 1 0\n");
    has(&uff_err(t.as_bytes()), &["line 14", "record 12", "4 values", "declares 3 points (6 values)"]);
    let t = ds58(4, 1, 1, 6, 1, 1, 0.0, 1.0, [18, 9, 13], "1 0\n1 0\n");
    has(&uff_err(t.as_bytes()), &["line 15", "record 12", "more values"]);
    let t = ds58(4, 1, 1, 6, 2, 1, 0.0, 1.0, [18, 9, 13], "1 0\n NaN 0\n");
    has(&uff_err(t.as_bytes()), &["line 15", "record 12", "value 3 is NaN"]);
    let t = ds58(4, 1, 1, 6, 2, 1, 0.0, 1.0, [18, 9, 13], "1 0\n 1.0 zz\n");
    has(&uff_err(t.as_bytes()), &["line 15", "record 12", "cannot read \"zz\""]);
    // Uneven abscissa not ascending.
    let t = ds58(4, 1, 1, 6, 3, 0, 0.0, 0.0, [18, 9, 13], "0 1 0\n5 1 0\n5 1 0\n");
    has(&uff_err(t.as_bytes()), &["line 16", "record 12", "frequency 5 Hz", "strictly ascending"]);
    // Units: abscissa time, accelerance, label not Hz.
    let t = ds58(4, 1, 1, 6, 1, 1, 0.0, 1.0, [17, 9, 13], "1 0\n");
    has(&uff_err(t.as_bytes()), &["line 10", "record 8", "abscissa is time", "not frequency"]);
    let t = ds58(4, 1, 1, 6, 1, 1, 0.0, 1.0, [18, 12, 13], "1 0\n");
    has(&uff_err(t.as_bytes()), &["line 11", "record 9", "numerator is acceleration", "not a force"]);
    let t = ds58(4, 1, 1, 6, 1, 1, 0.0, 1.0, [18, 9, 13], "1 0\n").replace(
        "    0    0    0 NONE                 NONE                \n        13",
        "    0    0    0 NONE                 g/N                 \n        13",
    );
    has(&uff_err(t.as_bytes()), &["line 11", "record 9", "units \"g/N\"", "not a force"]);
    let t = ds58(4, 1, 1, 6, 1, 1, 0.0, 1.0, [18, 9, 13], "1 0\n").replacen(
        "NONE                 NONE",
        "Time                 s   ",
        1,
    );
    has(&uff_err(t.as_bytes()), &["line 10", "record 8", "units \"s\" are not Hz"]);
    // Coherence problems.
    let t = frf_x() + &coh_x("0.5 1.5 1.0\n", 3);
    has(
        &uff_err(t.as_bytes()),
        &["line 30", "dataset #2 (58, starting line 17)", "record 12", "coherence 1.5", "outside [0, 1]"],
    );
    let t = frf_x() + &coh_x("0.5 0.9\n", 2);
    has(&uff_err(t.as_bytes()), &["line 17: dataset #2 (coherence x)", "2 frequency lines", "dataset #1", "has 3"]);
    let t = ds58(6, 2, 2, 4, 1, 1, 0.0, 1.0, [18, 0, 0], "0.5\n") + &frf_x();
    has(&uff_err(t.as_bytes()), &["dataset #1", "coherence for axis y", "no FRF for axis y"]);
    let t = ds58(6, 1, 1, 6, 1, 1, 0.0, 1.0, [18, 0, 0], "0.5 0.1\n");
    has(&uff_err(t.as_bytes()), &["record 12", "non-zero imaginary part"]);
    // Axes with different lines; duplicate axis.
    let y = ds58(4, 2, 2, 6, 3, 1, 0.0, 20.0, [18, 9, 13], "1 0 1 0 1 0\n");
    has(
        &uff_err((frf_x() + &y).as_bytes()),
        &["dataset #2 (FRF y)", "frequency line 2 is 20 Hz", "10 Hz in dataset #1"],
    );
    has(
        &uff_err((frf_x() + &frf_x()).as_bytes()),
        &["line 17", "dataset #2", "second FRF for axis x", "dataset #1 at line 1", "duplicate axis"],
    );
    let t = frf_x() + &coh_x("1 1 1\n", 3) + &coh_x("1 1 1\n", 3);
    has(&uff_err(t.as_bytes()), &["dataset #3", "second coherence for axis x", "duplicate axis"]);
    // Junk between datasets.
    has(&uff_err((frf_x() + "garbage\n").as_bytes()), &["line 17", "expected '    -1'", "\"garbage\""]);
}

#[test]
fn uff_binary_errors() {
    let frf = sample_frf((0..8).map(f64::from).collect(), &[], &[0]);
    let good = uff::uff58_to_bytes(&frf, true).unwrap();
    assert_eq!(uff::parse_uff58(&good, "ok.uff").unwrap(), frf);
    // Truncated binary data.
    has(&uff_err(&good[..good.len() - 20]), &["record 12", "128 bytes of binary data", "only"]);
    // Data longer than record 7 says: no closing -1 where expected.
    let t = String::from_utf8_lossy(&good).into_owned();
    let bad = t.replacen("         6         8", "         6         7", 1);
    has(
        &uff_err(bad.as_bytes()),
        &["record 12", "no closing '    -1' after the 112 bytes", "58b header says 128 bytes"],
    );
    // Unknown float format / byte order.
    let h = "    58b     1     2          11";
    assert!(t.contains(h));
    has(
        &uff_err(t.replacen(h, "    58b     1     3          11", 1).as_bytes()),
        &["line 2", "binary header", "floating point format 3"],
    );
    has(&uff_err(t.replacen(h, "    58b     7     2          11", 1).as_bytes()), &["line 2", "byte order 7"]);
    has(&uff_err(t.replacen(h, "    58b     1     2           9", 1).as_bytes()), &["line 2", "9 ASCII lines"]);
    // NaN in binary: named by byte offset.
    let mut nan = good.clone();
    let start = good.len() - 7 - 128;
    nan[start + 8..start + 16].copy_from_slice(&f64::NAN.to_le_bytes());
    has(&uff_err(&nan), &["record 12 (binary value 2 at byte offset", "is NaN"]);
    // Big endian and a line break before the closing -1 (seen in the wild).
    let mut be = good[..start].to_vec();
    let be_hdr = String::from_utf8_lossy(&be).replacen(h, "    58b     2     2          11", 1);
    be = be_hdr.into_bytes();
    for c in good[start..start + 128].chunks(8) {
        let v = f64::from_le_bytes(c.try_into().unwrap());
        be.extend_from_slice(&v.to_be_bytes());
    }
    be.extend_from_slice(b"\n    -1\n");
    assert_eq!(uff::parse_uff58(&be, "be.uff").unwrap(), frf);
}

// ----- round trip through pyuff's reader (optional, needs Python) ---------

/// Writes our UFF output and its expected CSV into $DYNOCOMP_UFF_EXPORT_DIR
/// for `make_fixtures.py --check-ours DIR`; does nothing when it is unset.
#[test]
fn export_for_pyuff_check() {
    let Some(dir) = std::env::var_os("DYNOCOMP_UFF_EXPORT_DIR") else {
        return;
    };
    let dir = PathBuf::from(dir);
    std::fs::create_dir_all(&dir).unwrap();
    let frf = sample_frf((0..=256).map(|i| i as f64 * 16.0).collect(), &[0, 2], &[0, 1, 2]);
    for (name, binary) in [("ours_ascii", false), ("ours_binary", true)] {
        uff::write_uff58(&dir.join(format!("{name}.uff")), &frf, binary).unwrap();
        frf_csv::write_frf_csv(&dir.join(format!("{name}.expected.csv")), &frf).unwrap();
    }
}

// ----- no panics ----------------------------------------------------------

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn parsers_never_panic_on_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let _ = uff::parse_uff58(&bytes, "fuzz");
        let _ = frf_csv::parse_frf_csv_bytes(&bytes, "fuzz");
        let _ = uff::looks_like_uff(&bytes);
    }

    #[test]
    fn csv_parser_never_panics_on_csv_like_text(text in "(freq_hz|x_re|x_im|x_coh|y_re|1|-2.5e3|NaN|,|;|\n| |\"){0,60}") {
        let _ = frf_csv::parse_frf_csv(&text, "fuzz");
    }

    #[test]
    fn uff_parser_never_panics_on_mutated_files(
        binary in any::<bool>(),
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..8),
        cut in any::<prop::sample::Index>(),
        do_cut in any::<bool>(),
    ) {
        let frf = sample_frf((0..6).map(f64::from).collect(), &[0], &[0, 2]);
        let mut bytes = uff::uff58_to_bytes(&frf, binary).unwrap();
        for (i, b) in edits {
            let k = i.index(bytes.len());
            bytes[k] = b;
        }
        if do_cut {
            bytes.truncate(cut.index(bytes.len() + 1));
        }
        let _ = uff::parse_uff58(&bytes, "fuzz");
    }

    #[test]
    fn csv_round_trip_any_values(
        vals in proptest::collection::vec((-1e300f64..1e300, -1e-300f64..1e-300, 0.0f64..=1.0), 1..20),
    ) {
        let freq: Vec<f64> = (0..vals.len()).map(|i| i as f64 * 0.1).collect();
        let frf = Frf {
            freq_hz: freq,
            axes: vec![AxisFrf {
                axis: 1,
                frf: vals.iter().map(|v| Complex64::new(v.0, v.1)).collect(),
                coherence: Some(vals.iter().map(|v| v.2).collect()),
            }],
            cross: Vec::new(),
        };
        let text = frf_csv::frf_csv_to_string(&frf).unwrap();
        prop_assert_eq!(frf_csv::parse_frf_csv(&text, "rt").unwrap(), frf);
    }
}

/// Header, row and whole-file refusals of the CSV and UFF 58 readers, word
/// for word (the tests above check the parts of each message).
#[test]
fn frf_refusals_word_for_word() {
    let csv = |t: &str| format!("{:#}", frf_csv::parse_frf_csv(t, "bad.csv").unwrap_err());
    let uff = |t: &str| format!("{:#}", uff::parse_uff58(t.as_bytes(), "bad.uff").unwrap_err());
    let cases = [
        (csv(""), "bad.csv: empty file (expected a header row starting with freq_hz)"),
        (csv("freq_hz,x_re,x_im\n"), "bad.csv: no data rows after the header (line 1)"),
        (
            csv("freq_hz,freq_hz,x_re,x_im\n0,0,1,0\n"),
            "bad.csv: line 1, column 2: duplicate column freq_hz (also column 1)",
        ),
        (
            csv("freq_hz,fx_re,x_im\n0,1,0\n"),
            "bad.csv: line 1, column 2: unknown column name \"fx_re\" (expected freq_hz, then \
                <a>_re, <a>_im and optionally <a>_coh for a = x, y, z, or <i><j>_re, <i><j>_im, \
                <i><j>_coh for channel i and force direction j)",
        ),
        (
            csv("freq_hz,x_re,x_im,xx_im\n0,1,0,0\n"),
            "bad.csv: line 1, column 4: column xx_im and column 2 (x_re) are the same entry xx (x_re \
                means xx_re): give each entry once, in one spelling",
        ),
        (
            csv("freq_hz,xy_re,xy_im,xy_re\n0,1,0,0\n"),
            "bad.csv: line 1, column 4: duplicate column xy_re (also column 2): entry xy (channel x, \
                force y) given twice",
        ),
        (csv("x_re,x_im\n1,0\n"), "bad.csv: line 1: missing column freq_hz in the header"),
        (csv("freq_hz,x_re,y_im\n0,1,0\n"), "bad.csv: line 1: column x_re (column 2) has no matching x_im column"),
        (csv("freq_hz,y_im\n0,1\n"), "bad.csv: line 1: column y_im (column 2) has no matching y_re column"),
        (csv("freq_hz,z_coh\n0,1\n"), "bad.csv: line 1: column z_coh (column 2) without z_re and z_im columns"),
        (
            csv("freq_hz\n1\n"),
            "bad.csv: line 1: no FRF columns in the header (expected x_re/x_im, y_re/y_im or \
                z_re/z_im, or <i><j>_re/<i><j>_im)",
        ),
        (csv("freq_hz;x_re;x_im\n0;1\n"), "bad.csv: line 2: 2 fields, but the header has 3 columns"),
        (csv("freq_hz,x_re,x_im\n0,\"\",0\n"), "bad.csv: line 2, column 2 (x_re): empty value"),
        (csv("freq_hz,x_re,x_im\n0,1,abc\n"), "bad.csv: line 2, column 3 (x_im): cannot read \"abc\" as a number"),
        (
            csv("freq_hz,x_re,x_im\n0,1,inf\n"),
            "bad.csv: line 2, column 3 (x_im): value inf is not finite (NaN or infinite)",
        ),
        (csv("freq_hz,x_re,x_im\n-1,1,0\n"), "bad.csv: line 2, column 1 (freq_hz): negative frequency -1 Hz"),
        (
            csv("freq_hz,x_re,x_im\n5,1,0\n5,1,0\n"),
            "bad.csv: line 3, column 1 (freq_hz): frequency 5 Hz is not greater than the previous \
                line's 5 Hz (frequencies must be strictly ascending)",
        ),
        (
            csv("freq_hz\tx_re\tx_im\tx_coh\n0\t1\t0\t1.5\n"),
            "bad.csv: line 2, column 4 (x_coh): coherence 1.5 outside [0, 1]",
        ),
        (uff("hello\n"), "bad.uff: line 1: expected '    -1' opening a UFF dataset, found \"hello\""),
        (uff("    -1\n"), "bad.uff: line 1: the file ends after '-1' (dataset number missing)"),
        (uff("    -1\n  abc\n    -1\n"), "bad.uff: line 2: expected a dataset number after '-1', found \"abc\""),
        (
            uff("    -1\n   151\nmodel\n    -1\n"),
            "bad.uff: no FRF found (dataset 58 with function type 4 and response direction ±1, ±2 or \
                ±3); skipped dataset #1 at line 1: type 151",
        ),
        (
            uff(&frf_x()[..200]),
            "bad.uff: line 10: dataset #1 (58, starting line 1), record 9: the file ends inside the \
                dataset header",
        ),
        (
            uff(&(frf_x().lines().take(5).map(|l| format!("{l}\n")).collect::<String>() + "    -1\n")),
            "bad.uff: line 6: dataset #1 (58, starting line 1), record 4: the dataset ends ('-1') \
                before its 11 header records",
        ),
        (
            uff(&frf_x().replace("    4         0", "    x         y")),
            concat!(
                "bad.uff: line 8: dataset #1 (58, starting line 1), record 6: cannot read function type, ",
                "response direction and reference direction from \"x         y    0         0       NONE   …\""
            ),
        ),
        (
            uff(&ds58(4, 1, 1, 7, 1, 1, 0.0, 1.0, [18, 9, 13], "1 0\n")),
            "bad.uff: line 9: dataset #1 (58, starting line 1), record 7: ordinate data type 7 not \
                supported (2/4 = real single/double, 5/6 = complex single/double)",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 1, 3, 0.0, 1.0, [18, 9, 13], "1 0\n")),
            "bad.uff: line 9: dataset #1 (58, starting line 1), record 7: abscissa spacing 3 is \
                neither 0 (uneven) nor 1 (even)",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 0, 1, 0.0, 1.0, [18, 9, 13], "\n")),
            "bad.uff: line 9: dataset #1 (58, starting line 1), record 7: number of data points is 0: no data",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 999_999_999, 1, 0.0, 1.0, [18, 9, 13], "1 0\n")),
            "bad.uff: line 9: dataset #1 (58, starting line 1), record 7: 999999999 data points \
                declared, more than the file can hold",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 3, 1, 0.0, 1.0, [18, 9, 13], "1 0 1 0\n")),
            "bad.uff: line 14: dataset #1 (58, starting line 1), record 12: 4 values, but record 7 \
                declares 3 points (6 values)",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 1, 1, 0.0, 1.0, [18, 9, 13], "1 0\n1 0\n")),
            "bad.uff: line 15: dataset #1 (58, starting line 1), record 12: more values than the 1 \
                points declared in record 7 (2 values)",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 2, 1, 0.0, 1.0, [18, 9, 13], "1 0\n 1.0 zz\n")),
            "bad.uff: line 15: dataset #1 (58, starting line 1), record 12: cannot read \"zz\" as a number",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 2, 1, 0.0, 1.0, [18, 9, 13], "1 0\n NaN 0\n")),
            "bad.uff: line 15: dataset #1 (58, starting line 1), record 12: value 3 is NaN (values \
                must be finite)",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 2, 1, -1.0, 1.0, [18, 9, 13], "1 0 1 0\n")),
            "bad.uff: line 9: dataset #1 (58, starting line 1), record 7: abscissa minimum -1 Hz is \
                not a non-negative frequency",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 2, 1, 0.0, -1.0, [18, 9, 13], "1 0 1 0\n")),
            "bad.uff: line 9: dataset #1 (58, starting line 1), record 7: abscissa increment -1 Hz \
                must be positive (frequencies strictly ascending)",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 2, 0, 0.0, 0.0, [18, 9, 13], "-1 1 0\n2 1 0\n")),
            "bad.uff: line 14: dataset #1 (58, starting line 1), record 12: negative frequency -1 Hz",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 2, 0, 0.0, 0.0, [18, 9, 13], "5 1 0\n5 1 0\n")),
            "bad.uff: line 15: dataset #1 (58, starting line 1), record 12: frequency 5 Hz is not \
                greater than the previous point's 5 Hz (frequencies must be strictly ascending)",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 1, 1, 0.0, 1.0, [17, 9, 13], "1 0\n")),
            "bad.uff: line 10: dataset #1 (58, starting line 1), record 8: the abscissa is time \
                (specific data type 17), not frequency",
        ),
        (
            uff(&ds58(4, 1, 1, 6, 1, 1, 0.0, 1.0, [18, 9, 12], "1 0\n")),
            "bad.uff: line 12: dataset #1 (58, starting line 1), record 10: the FRF denominator is \
                acceleration (specific data type 12), not a force: dynocomp needs the dynamometer's \
                force/force FRF (N/N)",
        ),
        (
            uff(&(frf_x() + &coh_x("0.5 1.5 1.0\n", 3))),
            "bad.uff: line 30: dataset #2 (58, starting line 17), record 12: coherence 1.5 at point \
                2 (10 Hz) outside [0, 1]",
        ),
        (
            uff(&ds58(6, 1, 1, 6, 1, 1, 0.0, 1.0, [18, 0, 0], "0.5 0.1\n")),
            "bad.uff: line 14: dataset #1 (58, starting line 1), record 12: coherence at point 1 has \
                a non-zero imaginary part 0.1",
        ),
        (
            uff(&ds58(4, 1, 5, 6, 1, 1, 0.0, 1.0, [18, 9, 13], "1 0\n")),
            "bad.uff: no FRF found (dataset 58 with function type 4 and response direction ±1, ±2 or \
                ±3); skipped dataset #1 at line 1: reference direction 5 is not a translation (±1/±2/±3)",
        ),
        (
            uff(&ds58(4, 7, 1, 6, 1, 1, 0.0, 1.0, [18, 9, 13], "1 0\n")),
            "bad.uff: no FRF found (dataset 58 with function type 4 and response direction ±1, ±2 or \
                ±3); skipped dataset #1 at line 1: response direction 7 is not a translation (±1/±2/±3)",
        ),
        (
            uff(&(frf_x() + &frf_x())),
            "bad.uff: line 17: dataset #2 is a second FRF for axis x (the first is dataset #1 at \
                line 1): duplicate axis",
        ),
        (
            uff(&(frf_x() + &ds58(4, 2, 2, 6, 3, 1, 0.0, 20.0, [18, 9, 13], "1 0 1 0 1 0\n"))),
            "bad.uff: line 17: dataset #2 (FRF y): frequency line 2 is 20 Hz, but 10 Hz in dataset \
                #1 (FRF x, line 1): all datasets must share the same frequency lines",
        ),
        (
            uff(&(frf_x() + &coh_x("0.5 0.9\n", 2))),
            "bad.uff: line 17: dataset #2 (coherence x): 2 frequency lines, but dataset #1 (FRF x, \
                line 1) has 3: all datasets must share the same frequency lines",
        ),
        (
            uff(&(ds58(6, 2, 2, 4, 1, 1, 0.0, 1.0, [18, 0, 0], "0.5\n") + &frf_x())),
            "bad.uff: line 1: dataset #1 is a coherence for axis y but the file has no FRF for axis y",
        ),
    ];
    let bad: Vec<String> =
        cases.iter().enumerate().filter(|(_, (g, w))| g != w).map(|(k, (g, _))| format!("case {k}: {g:?}")).collect();
    assert!(bad.is_empty(), "\n{}", bad.join("\n"));
}
