//! The 3x3 FRF matrix on disk: FRF CSV `<i><j>_` columns, UFF58 reference
//! directions, several files merged into one matrix, the message of an
//! incomplete matrix, and direct-only files reading and writing exactly as
//! before the matrix existed. Expected values are written into the inputs
//! by hand (or are the pre-matrix reader's output), never taken from the
//! code under test.

use std::path::{Path, PathBuf};

use dynocomp::frf::{AxisFrf, CrossFrf, Frf, MatrixKind};
use dynocomp::io::frf_set::{merge_frf_files, parse_frf_file, FrfFile};
use dynocomp::io::{frf_csv, read_frf, read_frf_set, split_frf_list, uff};
use num_complex::Complex64;
use sha2::{Digest, Sha256};

fn c(re: f64, im: f64) -> Complex64 {
    Complex64::new(re, im)
}

fn has(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "{msg:?} should contain {p:?}");
    }
    assert!(!msg.contains('\n'), "one line: {msg}");
}

/// A known matrix: entry (i, j) at line k is (10i + j + 1 + k/4) − j(k + 1)/8·i·j, exact in binary.
fn known(i: usize, j: usize, k: usize) -> Complex64 {
    c((10 * i + j + 1) as f64 + k as f64 * 0.25, -((i * j) as f64) * (k + 1) as f64 * 0.125)
}

/// A complete matrix on `n` lines at 0, 8, 16, … Hz, coherence on the entries in `coh`.
fn full_matrix(n: usize, coh: &[(usize, usize)]) -> Frf {
    let freq = (0..n).map(|k| 8.0 * k as f64).collect();
    let vals = |i, j| (0..n).map(|k| known(i, j, k)).collect::<Vec<_>>();
    let cohv =
        |i: usize, j: usize| coh.contains(&(i, j)).then(|| (0..n).map(|k| ((k + i + j) % 5) as f64 * 0.25).collect());
    let axes = (0..3).map(|a| AxisFrf { axis: a, frf: vals(a, a), coherence: cohv(a, a) }).collect();
    let mut cross = Vec::new();
    for i in 0..3 {
        for j in 0..3 {
            if i != j {
                cross.push(CrossFrf { channel: i, direction: j, frf: vals(i, j), coherence: cohv(i, j) });
            }
        }
    }
    Frf { freq_hz: freq, axes, cross }
}

// ----- FRF CSV ---------------------------------------------------------------

#[test]
fn csv_matrix_columns_fill_the_entries_they_name() {
    // Written by hand: channel first, then hammer direction.
    let text = "freq_hz,xx_re,xx_im,xy_re,xy_im,xy_coh,zx_re,zx_im,yz_re,yz_im\n\
                0,1,0,0.01,0.02,0.5,-0.03,0,0.04,-0.05\n\
                10,1.5,-0.5,0.11,0.12,0.75,-0.13,0.5,0.14,-0.15\n";
    let f = frf_csv::parse_frf_csv(text, "m.csv").unwrap();
    assert_eq!(f.axes.len(), 1);
    assert_eq!(f.entry(0, 0).unwrap().frf, &[c(1.0, 0.0), c(1.5, -0.5)][..]);
    let xy = f.entry(0, 1).unwrap();
    assert_eq!(xy.frf, &[c(0.01, 0.02), c(0.11, 0.12)][..]);
    assert_eq!(xy.coherence, Some(&[0.5, 0.75][..]));
    assert_eq!(f.entry(2, 0).unwrap().frf[1], c(-0.13, 0.5), "zx = channel z, hammer x");
    assert_eq!(f.entry(1, 2).unwrap().frf[0], c(0.04, -0.05), "yz = channel y, hammer z");
    // Negative control: the transposed entries are absent, not aliased.
    assert!(f.entry(1, 0).is_none() && f.entry(0, 2).is_none() && f.entry(2, 1).is_none());
    assert!(f.entry(2, 0).unwrap().coherence.is_none());
    let st = f.matrix_status();
    assert_eq!(st.kind(), MatrixKind::Incomplete);
    assert!(f.matrix_at(0).is_none());
}

#[test]
fn csv_x_re_means_xx_re() {
    let short = "freq_hz,x_re,x_im,x_coh,zy_re,zy_im\n0,1,0.5,0.9,0.1,0\n5,2,0.25,0.8,0.2,0\n";
    let long = short.replace("x_re,x_im,x_coh", "xx_re,xx_im,xx_coh");
    let a = frf_csv::parse_frf_csv(short, "a.csv").unwrap();
    let b = frf_csv::parse_frf_csv(&long, "b.csv").unwrap();
    assert_eq!(a, b);
    assert_eq!(a.axis(0).unwrap().frf, vec![c(1.0, 0.5), c(2.0, 0.25)]);
    // Negative control: yy is another entry.
    let other = frf_csv::parse_frf_csv(&short.replace("x_re,x_im,x_coh", "yy_re,yy_im,yy_coh"), "c.csv").unwrap();
    assert_ne!(other, a);
    assert_eq!(other.axes[0].axis, 1);
}

#[test]
fn csv_matrix_round_trip_is_exact_and_spelled_in_full() {
    let dir = tempfile::tempdir().unwrap();
    let mut frf = full_matrix(40, &[(0, 0), (1, 2), (2, 2)]);
    frf.cross[3].frf[7] = c(1e-300, -1.2345678901234567e200);
    let text = frf_csv::frf_csv_to_string(&frf).unwrap();
    assert!(
        text.starts_with(
            "freq_hz,xx_re,xx_im,xx_coh,xy_re,xy_im,xz_re,xz_im,yx_re,yx_im,yy_re,yy_im,yz_re,yz_im,yz_coh,\
             zx_re,zx_im,zy_re,zy_im,zz_re,zz_im,zz_coh\n"
        ),
        "{}",
        text.lines().next().unwrap()
    );
    let path = dir.path().join("m.csv");
    frf_csv::write_frf_csv(&path, &frf).unwrap();
    assert_eq!(read_frf(&path).unwrap(), frf);
    let st = frf.matrix_status();
    assert!(st.is_complete() && st.message().is_none());
    let g = frf.matrix_at(5).unwrap();
    for i in 0..3 {
        for j in 0..3 {
            assert_eq!(g[(i, j)], known(i, j, 5));
        }
    }
}

fn csv_err(text: &str) -> String {
    let e = frf_csv::parse_frf_csv(text, "bad.csv").expect_err(text);
    let msg = format!("{e:#}");
    assert!(msg.starts_with("bad.csv: "), "{msg}");
    msg
}

#[test]
fn csv_matrix_errors_name_line_column_and_entry() {
    has(
        &csv_err("freq_hz,x_re,x_im,xx_re,xx_im\n0,1,0,1,0\n"),
        &["line 1, column 4", "column 2 (x_re)", "same entry xx", "x_re means xx_re"],
    );
    has(&csv_err("freq_hz,xx_re,x_im\n0,1,0\n"), &["line 1, column 3", "same entry xx", "one spelling"]);
    has(
        &csv_err("freq_hz,xy_re,xy_im,XY_RE\n0,1,0,1\n"),
        &["line 1, column 4", "duplicate column xy_re (also column 2)", "entry xy (channel x, force y)"],
    );
    has(&csv_err("freq_hz,xy_re,yx_im\n0,1,0\n"), &["line 1", "xy_re (column 2) has no matching xy_im"]);
    has(&csv_err("freq_hz,x_re,x_im,zy_coh\n0,1,0,1\n"), &["line 1", "zy_coh (column 4) without zy_re and zy_im"]);
    has(&csv_err("freq_hz,xw_re,xw_im\n0,1,0\n"), &["line 1, column 2", "unknown column name \"xw_re\""]);
    has(&csv_err("freq_hz,xyz_re\n0,1\n"), &["column 2", "unknown column name"]);
    has(&csv_err("freq_hz,yz_re,yz_im\n0,1,x\n"), &["line 2, column 3 (yz_im)", "cannot read \"x\""]);
    has(&csv_err("freq_hz,yz_re,yz_im,yz_coh\n0,1,0,2\n"), &["line 2, column 4 (yz_coh)", "outside [0, 1]"]);
}

// ----- UFF 58 ----------------------------------------------------------------

/// A hand-made ASCII dataset 58: function type, response and reference
/// direction, `n` complex double (type 6) or real double (type 4) values on
/// lines 0, 10, 20, … Hz, force units `units`.
fn ds58(ft: i64, rsp: i64, refd: i64, n: usize, units: &str, data: &str) -> String {
    let mut s = String::from("    -1\n    58\n");
    for _ in 0..5 {
        s.push_str("NONE\n");
    }
    s.push_str(&format!(
        "{:>5}{:>10}{:>5}{:>10} {:>10}{:>10}{:>4} {:>10}{:>10}{:>4}\n",
        ft, 0, 0, 0, "NONE", 1, rsp, "NONE", 1, refd
    ));
    let ord = if ft == 4 { 6 } else { 4 };
    let e = |x: f64| format!("{:>13}", format!("{x:.5e}"));
    s.push_str(&format!("{:>10}{:>10}{:>10}{}{}{}\n", ord, n, 1, e(0.0), e(10.0), e(0.0)));
    let (num, den) = if ft == 4 { ((9, units), (13, units)) } else { ((0, "NONE"), (0, "NONE")) };
    for (spec, u) in [(18, "Hz"), num, den, (0, "NONE")] {
        s.push_str(&format!("{:>10}{:>5}{:>5}{:>5} {:<20} {:<20}\n", spec, 0, 0, 0, "NONE", u));
    }
    s.push_str(data);
    s.push_str("    -1\n");
    s
}

fn uff_err(text: &str) -> String {
    let e = uff::parse_uff58(text.as_bytes(), "bad.uff").expect_err(text);
    let msg = format!("{e:#}");
    assert!(msg.starts_with("bad.uff: "), "{msg}");
    msg
}

#[test]
fn uff_reference_direction_is_the_force_direction_and_negative_directions_flip_the_frf() {
    // (response, reference) → entry, sign.
    for (rsp, refd, entry, sign) in [
        (1, 2, (0, 1), 1.0),
        (-1, 2, (0, 1), -1.0),
        (1, -2, (0, 1), -1.0),
        (-1, -2, (0, 1), 1.0),
        (3, 1, (2, 0), 1.0),
        (2, -3, (1, 2), -1.0),
        (2, 2, (1, 1), 1.0),
        (-2, 0, (1, 1), -1.0),
    ] {
        let t = ds58(4, rsp, refd, 2, "N", "2.0 3.0 -0.5 0.25\n") + &ds58(6, rsp, refd, 2, "NONE", "0.5 0.75\n");
        let f = uff::parse_uff58(t.as_bytes(), "ok.uff").unwrap();
        let e = f.entry(entry.0, entry.1).unwrap_or_else(|| panic!("rsp {rsp} ref {refd}: no entry {entry:?}"));
        assert_eq!(e.frf, &[c(2.0 * sign, 3.0 * sign), c(-0.5 * sign, 0.25 * sign)][..], "rsp {rsp} ref {refd}");
        assert_eq!(e.coherence, Some(&[0.5, 0.75][..]), "coherence is never flipped (rsp {rsp} ref {refd})");
        assert_eq!(f.entries().count(), 1, "rsp {rsp} ref {refd}");
        assert_eq!(f.has_cross(), entry.0 != entry.1);
    }
    // Rotational reference directions are skipped next to a translation.
    let t = ds58(4, 1, 4, 1, "N", "9 9\n") + &ds58(4, 1, 1, 1, "N", "1 0\n");
    let f = uff::parse_uff58(t.as_bytes(), "ok.uff").unwrap();
    assert_eq!((f.axes.len(), f.cross.len()), (1, 0));
    assert_eq!(f.axes[0].frf[0], c(1.0, 0.0));
}

#[test]
fn uff_matrix_round_trip_ascii_and_binary() {
    let frf = full_matrix(17, &[(0, 0), (0, 1), (2, 1), (2, 2)]);
    for binary in [false, true] {
        let bytes = uff::uff58_to_bytes(&frf, binary).unwrap();
        let back = uff::parse_uff58(&bytes, "m.uff").unwrap_or_else(|e| panic!("{e:#}"));
        if binary {
            assert_eq!(back, frf);
        } else {
            assert_eq!(back.freq_hz, frf.freq_hz);
            for (a, b) in back.entries().zip(frf.entries()) {
                assert_eq!(
                    (a.channel, a.direction, a.coherence.is_some()),
                    (b.channel, b.direction, b.coherence.is_some())
                );
                for (x, y) in a.frf.iter().zip(b.frf) {
                    assert!((x - y).norm() <= 1e-12 * y.norm(), "{x} vs {y}");
                }
            }
            assert_eq!(back.entries().count(), 9);
        }
    }
    // Record 6 of the xy FRF: response +1, reference +2.
    let text = String::from_utf8(uff::uff58_to_bytes(&frf, false).unwrap()).unwrap();
    let rec6: Vec<&str> = text.lines().filter(|l| l.contains("HAMMER")).collect();
    assert_eq!(rec6.len(), 9 + 4, "nine FRFs and four coherences");
    let xy = rec6[2].split_whitespace().collect::<Vec<_>>();
    assert_eq!((xy[0], xy[6], xy[9]), ("4", "1", "2"), "{}", rec6[2]);
}

#[test]
fn uff_matrix_errors_name_the_datasets() {
    let frf12 = ds58(4, 1, 2, 1, "N", "1 0\n");
    has(
        &uff_err(&(frf12.clone() + &ds58(4, -1, 2, 1, "N", "1 0\n"))),
        &[
            "line 16",
            "dataset #2 is a second FRF for entry xy (channel x, force y)",
            "dataset #1 at line 1",
            "duplicate entry",
        ],
    );
    has(
        &uff_err(&(ds58(4, 1, 1, 1, "N", "1 0\n") + &ds58(6, 3, 2, 1, "NONE", "1\n"))),
        &["dataset #2 is a coherence for entry zy (channel z, force y) but the file has no FRF for entry zy"],
    );
    // Lines differ between entries (3 lines against 1).
    has(
        &uff_err(&(ds58(4, 1, 1, 1, "N", "1 0\n") + &ds58(4, 2, 1, 3, "N", "1 0 1 0 1 0\n"))),
        &["dataset #2 (FRF yx)", "3 frequency lines", "dataset #1 (FRF x, line 1) has 1"],
    );
    // Force units differ inside one file.
    has(
        &uff_err(&(ds58(4, 1, 1, 1, "N", "1 0\n") + &ds58(4, 2, 1, 1, "lbf", "1 0\n"))),
        &["line 16", "dataset #2 (entry yx (channel y, force x)) is in units lbf/lbf", "dataset #1 (line 1) in N/N"],
    );
    // Negative control: unlabelled units next to labelled ones are accepted.
    let ok = ds58(4, 1, 1, 1, "N", "1 0\n") + &ds58(4, 2, 1, 1, "NONE", "1 0\n");
    assert_eq!(uff::parse_uff58(ok.as_bytes(), "ok.uff").unwrap().cross.len(), 1);
}

// ----- direct-only files as before -------------------------------------------

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

/// Every f64 of a direct-only FRF as the hex digits of its bits (the format
/// of `fixtures/frf_legacy/reads.sha256`).
fn dump(f: &Frf) -> String {
    let mut s = String::new();
    for v in &f.freq_hz {
        s.push_str(&format!("freq {:016x}\n", v.to_bits()));
    }
    for a in &f.axes {
        s.push_str(&format!("axis {}\n", a.axis));
        for v in &a.frf {
            s.push_str(&format!("frf {:016x} {:016x}\n", v.re.to_bits(), v.im.to_bits()));
        }
        match &a.coherence {
            None => s.push_str("nocoh\n"),
            Some(cv) => cv.iter().for_each(|v| s.push_str(&format!("coh {:016x}\n", v.to_bits()))),
        }
    }
    s
}

/// The set the pre-matrix writers wrote into `fixtures/frf_legacy/sample*`.
fn legacy_sample() -> Frf {
    let freq: Vec<f64> = (0..33).map(|k| k as f64 * 7.8125).collect();
    let axes = (0..3)
        .map(|a| AxisFrf {
            axis: a,
            frf: (0..33)
                .map(|k| c(1.0 - k as f64 * 0.03125 + a as f64 * 0.5, -(k as f64) * 0.0078125 * (a as f64 + 1.0)))
                .collect(),
            coherence: (a != 1).then(|| (0..33).map(|k| 1.0 - (k % 8) as f64 * 0.0625).collect()),
        })
        .collect();
    Frf::direct(freq, axes)
}

#[test]
fn direct_only_files_read_and_write_as_before() {
    let legacy = fixtures().join("frf_legacy");
    let sums = std::fs::read_to_string(legacy.join("reads.sha256")).unwrap();
    let mut n = 0;
    for line in sums.lines() {
        let (name, want) = line.split_once(' ').unwrap();
        let f = read_frf(&fixtures().join("uff").join(name)).unwrap_or_else(|e| panic!("{e:#}"));
        assert!(f.cross.is_empty(), "{name}");
        assert_eq!(f.matrix_status().kind(), MatrixKind::DirectOnly, "{name}");
        let got = format!("{:x}", Sha256::digest(dump(&f).as_bytes()));
        assert_eq!(got, want, "{name} reads differently from the pre-matrix reader");
        // Negative control: one bit of one value changes the digest.
        let mut g = f.clone();
        g.axes[0].frf[1].re = f64::from_bits(g.axes[0].frf[1].re.to_bits() ^ 1);
        assert_ne!(format!("{:x}", Sha256::digest(dump(&g).as_bytes())), want);
        n += 1;
    }
    assert_eq!(n, 10, "five UFF fixtures and their expected CSVs");
    let s = legacy_sample();
    let read = |name: &str| std::fs::read(legacy.join(name)).unwrap();
    assert_eq!(frf_csv::frf_csv_to_string(&s).unwrap().as_bytes(), &read("sample.csv")[..]);
    assert_eq!(uff::uff58_to_bytes(&s, false).unwrap(), read("sample_ascii.uff"));
    assert_eq!(uff::uff58_to_bytes(&s, true).unwrap(), read("sample_binary.uff"));
}

// ----- several files, one matrix ---------------------------------------------

/// Column j of `full_matrix`: the file of hammer direction j.
fn column(frf: &Frf, j: usize) -> Frf {
    Frf {
        freq_hz: frf.freq_hz.clone(),
        axes: frf.axes.iter().filter(|a| a.axis == j).cloned().collect(),
        cross: frf.cross.iter().filter(|x| x.direction == j).cloned().collect(),
    }
}

#[test]
fn one_file_per_hammer_direction_merges_into_the_matrix() {
    let dir = tempfile::tempdir().unwrap();
    let frf = full_matrix(9, &[(0, 0), (1, 0), (2, 2), (0, 2)]);
    let paths: Vec<PathBuf> = ["hx.csv", "hy.uff", "hz.uff"].iter().map(|n| dir.path().join(n)).collect();
    frf_csv::write_frf_csv(&paths[0], &column(&frf, 0)).unwrap();
    uff::write_uff58(&paths[1], &column(&frf, 1), true).unwrap();
    uff::write_uff58(&paths[2], &column(&frf, 2), true).unwrap();
    let merged = read_frf_set(&paths).unwrap_or_else(|e| panic!("{e:#}"));
    assert_eq!(merged, frf);
    // In any order.
    let rev: Vec<PathBuf> = paths.iter().rev().cloned().collect();
    assert_eq!(read_frf_set(&rev).unwrap(), frf);
    // One path reads as read_frf does.
    assert_eq!(read_frf_set(&paths[1..2]).unwrap(), read_frf(&paths[1]).unwrap());
    // Two directions only: an incomplete matrix, and the message says so.
    let two = read_frf_set(&paths[..2]).unwrap();
    assert_eq!(
        two.matrix_status().message().unwrap(),
        "cross FRFs missing: xz, yz (direct FRFs missing: zz); crosstalk is not compensated, the design is per axis \
         from the direct FRFs"
    );
}

fn file(source: &str, frf: Frf, units: Option<&str>) -> FrfFile {
    FrfFile { source: source.to_string(), frf, units: units.map(str::to_string) }
}

#[test]
fn merge_refuses_duplicates_other_lines_and_other_units_naming_both_files() {
    let frf = full_matrix(9, &[]);
    let (hx, hy) = (column(&frf, 0), column(&frf, 1));
    let err = |files: &[FrfFile]| format!("{:#}", merge_frf_files(files).unwrap_err());
    // The same column twice.
    has(
        &err(&[file("hx.uff", hx.clone(), None), file("hx2.uff", hx.clone(), None)]),
        &["hx2.uff: holds entry xx (direct FRF, channel x, force x), which hx.uff holds too", "one file only"],
    );
    // One cross entry in two files.
    let mut extra = hy.clone();
    extra.cross.insert(0, hx.cross[0].clone());
    has(
        &err(&[file("hx.uff", hx.clone(), None), file("hy.uff", extra, None)]),
        &["hy.uff: holds entry yx (cross FRF", "hx.uff"],
    );
    // Other number of lines.
    let short = column(&full_matrix(5, &[]), 1);
    has(
        &err(&[file("hx.uff", hx.clone(), None), file("hy.uff", short, None)]),
        &["hy.uff: 5 lines from 0 to 32 Hz, but hx.uff has 9 lines from 0 to 64 Hz", "same frequency lines"],
    );
    // Same count, one line moved.
    let mut moved = hy.clone();
    moved.freq_hz[4] = 33.0;
    has(
        &err(&[file("hx.uff", hx.clone(), None), file("hy.uff", moved, None)]),
        &["hy.uff: frequency line 5 is 33 Hz, but 32 Hz in hx.uff", "same span and resolution"],
    );
    // Units.
    has(
        &err(&[file("hx.csv", hx.clone(), Some("N/N")), file("hy.uff", hy.clone(), Some("lbf/lbf"))]),
        &["hy.uff: FRFs in units lbf/lbf, but hx.csv has them in N/N", "as N/N"],
    );
    // Negative controls: within tolerance, and unlabelled units, merge.
    let mut close = hy.clone();
    close.freq_hz[4] += 32.0 * 1e-9;
    assert!(merge_frf_files(&[file("hx.uff", hx.clone(), Some("N/N")), file("hy.uff", close, None)]).is_ok());
    assert!(merge_frf_files(&[]).is_err());
}

#[test]
fn parse_frf_file_keeps_the_units_label() {
    let t = ds58(4, 1, 1, 1, "lbf", "1 0\n");
    let f = parse_frf_file(Path::new("a.uff"), t.as_bytes()).unwrap();
    assert_eq!(f.units.as_deref(), Some("lbf/lbf"));
    let f = parse_frf_file(Path::new("a.csv"), b"freq_hz,x_re,x_im\n0,1,0\n").unwrap();
    assert_eq!(f.units.as_deref(), Some("N/N"));
    let f = parse_frf_file(Path::new("a.uff"), ds58(4, 1, 1, 1, "NONE", "1 0\n").as_bytes()).unwrap();
    assert_eq!(f.units, None);
}

#[test]
fn frf_list_splits_on_commas() {
    assert_eq!(
        split_frf_list("hx.uff,hy.uff,hz.uff").unwrap(),
        vec![PathBuf::from("hx.uff"), "hy.uff".into(), "hz.uff".into()]
    );
    assert_eq!(split_frf_list("dir with space/a.uff").unwrap(), vec![PathBuf::from("dir with space/a.uff")]);
    has(
        &format!("{:#}", split_frf_list("a.uff,,b.uff").unwrap_err()),
        &["--frf a.uff,,b.uff", "file name 2 of 3 is empty"],
    );
    has(&format!("{:#}", split_frf_list("a.uff,").unwrap_err()), &["file name 2 of 2 is empty"]);
    has(&format!("{:#}", split_frf_list("").unwrap_err()), &["file name 1 of 1 is empty"]);
    has(&format!("{:#}", split_frf_list("a.uff,b.uff,a.uff").unwrap_err()), &["a.uff is named twice"]);
}

#[test]
fn matrix_status_names_what_is_missing() {
    let full = full_matrix(3, &[]);
    assert_eq!(full.matrix_status().kind(), MatrixKind::Complete);
    assert_eq!(full.matrix_status().message(), None);
    let mut part = full.clone();
    part.cross.retain(|x| (x.channel, x.direction) != (0, 1) && (x.channel, x.direction) != (2, 0));
    let st = part.matrix_status();
    assert_eq!(st.kind(), MatrixKind::Incomplete);
    assert_eq!(st.missing(), vec![(0, 1), (2, 0)]);
    assert_eq!(
        st.message().unwrap(),
        "cross FRFs missing: xy, zx; crosstalk is not compensated, the design is per axis from the direct FRFs"
    );
    let direct = Frf::direct(full.freq_hz.clone(), full.axes.clone());
    assert_eq!(direct.matrix_status().kind(), MatrixKind::DirectOnly);
    assert!(!direct.has_cross());
    assert_eq!(
        direct.matrix_status().message().unwrap(),
        "only direct FRFs: crosstalk is not compensated, the design is per axis"
    );
    let mut xz = direct.clone();
    xz.axes.remove(1);
    assert_eq!(
        xz.matrix_status().message().unwrap(),
        "only direct FRFs (direct FRFs missing: yy): crosstalk is not compensated, the design is per axis"
    );
}
