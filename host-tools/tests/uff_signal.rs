//! Issue #14: force records as UFF 58/58b time histories (function type 1):
//! written and read back, through `compensate`, and refused with a message
//! naming the file, dataset and record when they are wrong.

use dynocomp::io::signal::ChannelMap;
use dynocomp::io::signal::{read_all, SignalWriter};
use dynocomp::io::signal_csv::read_signal_csv;
use dynocomp::io::signal_file::{open_signal, SignalFormat};
use dynocomp::io::uff_signal::UffWriter;
use dynocomp::offline::compensate::compensate_record;
use std::path::{Path, PathBuf};

use crate::cli_common;
use crate::common;
use cli_common::{dynocomp, example, tmp};

/// Write `chans` (axes 0..n) as a UFF time-history file at `fs`.
fn write_uff(path: &Path, chans: &[Vec<f64>], fs: f64, binary: bool) {
    let mut bytes = Vec::new();
    {
        let axes: Vec<usize> = (0..chans.len()).collect();
        let mut w = UffWriter::new(&mut bytes, &axes, fs, binary).unwrap();
        let sl: Vec<&[f64]> = chans.iter().map(Vec::as_slice).collect();
        w.write_block(None, &sl).unwrap();
        w.finish().unwrap();
    }
    std::fs::write(path, bytes).unwrap();
}

fn signals(n: usize) -> Vec<Vec<f64>> {
    (0..3).map(|a| (0..n).map(|k| (((k * (a + 1)) as f64 * 0.01).sin() * 100.0) as f32 as f64).collect()).collect()
}

/// Binary 58b reads back bit for bit, ASCII 58 to the f32 value it came
/// from; the sample rate comes from the abscissa increment. A negative
/// response direction flips the sign (negative control: the values differ).
#[test]
fn time_histories_round_trip() {
    let x = signals(10_007);
    for binary in [true, false] {
        let p = tmp("uffrt", if binary { "b.uff" } else { "a.uff" });
        write_uff(&p, &x, 51200.0, binary);
        let (mut r, fmt) = open_signal(&p, None).unwrap();
        assert_eq!(fmt, if binary { SignalFormat::Uff58b } else { SignalFormat::Uff });
        assert_eq!(r.axes(), &[0, 1, 2]);
        assert_eq!(r.len_hint(), Some(10_007));
        assert!((r.declared_fs_hz().unwrap() - 51200.0).abs() < 1e-6);
        let (_, got) = read_all(&mut *r).unwrap();
        for (g, w) in got.iter().zip(&x) {
            assert_eq!(g.len(), w.len());
            for (a, b) in g.iter().zip(w) {
                if binary {
                    assert_eq!(a.to_bits(), b.to_bits());
                } else {
                    assert_eq!((*a as f32).to_bits(), (*b as f32).to_bits());
                }
            }
        }
    }
    // Direction -2 on the y dataset: read negated.
    let p = tmp("uffrt", "neg.uff");
    write_uff(&p, &x, 51200.0, false);
    let text = std::fs::read_to_string(&p).unwrap();
    let text = text.replace(
        "       DYN         1   2     HAMMER         1   2",
        "       DYN         1  -2     HAMMER         1  -2",
    );
    std::fs::write(&p, text).unwrap();
    let (mut r, _) = open_signal(&p, None).unwrap();
    let (_, got) = read_all(&mut *r).unwrap();
    assert!(got[1].iter().zip(&x[1]).all(|(a, b)| (*a as f32) == -(*b as f32)));
    assert!(got[0].iter().zip(&x[0]).all(|(a, b)| (*a as f32) == (*b as f32)));
}

/// `compensate` on the example as UFF 58b: the output is UFF 58b (format
/// follows the input) with the same values as the CSV path; `--output-format
/// csv` switches; a record at 48 kHz is refused naming the file.
#[test]
fn compensate_reads_and_writes_uff() {
    let img_path = tmp("uffcli", "img.dcimg");
    let mut img = common::image(1, 51200, 0);
    img.latency_samples = 2;
    std::fs::write(&img_path, common::bytes(&img)).unwrap();
    let rec = read_signal_csv(Path::new(&example("measured.csv"))).unwrap();
    let chans: Vec<Vec<f64>> = rec.channels.iter().map(|c| c.1.clone()).collect();
    let inp = tmp("uffcli", "measured.uff");
    write_uff(&inp, &chans, 51200.0, true);
    let out = tmp("uffcli", "out.uff");
    let run = |inp: &PathBuf, out: &PathBuf, extra: &[&str]| {
        let mut args = vec![
            "compensate",
            "--coeffs",
            img_path.to_str().unwrap(),
            "--input",
            inp.to_str().unwrap(),
            "--output",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        dynocomp(&args)
    };
    let (ok, _, err) = run(&inp, &out, &[]);
    assert!(ok, "{err}");
    let (mut r, fmt) = open_signal(&out, None).unwrap();
    assert_eq!(fmt, SignalFormat::Uff58b);
    let (_, got) = read_all(&mut *r).unwrap();
    let want = compensate_record(&img, &rec, false, "x").unwrap();
    for (a, g) in got.iter().enumerate() {
        let w = want.channel(a).unwrap();
        assert!(g.len() == w.len() && g.iter().zip(w).all(|(x, y)| x.to_bits() == y.to_bits()), "axis {a}");
    }
    let out_csv = tmp("uffcli", "out.csv");
    let (ok, _, err) = run(&inp, &out_csv, &["--output-format", "csv"]);
    assert!(ok, "{err}");
    let back = read_signal_csv(&out_csv).unwrap();
    assert_eq!(back.channel(2).unwrap(), want.channel(2).unwrap());
    // 48 kHz record against a 51.2 kHz image
    let slow = tmp("uffcli", "slow.uff");
    write_uff(&slow, &chans, 48000.0, false);
    let out2 = tmp("uffcli", "out2.uff");
    let (ok, _, err) = run(&slow, &out2, &[]);
    assert!(!ok);
    assert!(err.contains("slow.uff") && err.contains("sampling interval") && err.contains("48000"), "{err}");
    assert!(!out2.exists());
}

/// Broken files: truncated data, a non-number, and a file without any time
/// history name the file, dataset and record; `--channels` maps by ID line.
#[test]
fn bad_uff_records_are_refused_clearly() {
    let x = signals(100);
    let p = tmp("uffbad", "a.uff");
    write_uff(&p, &x[..1], 51200.0, false);
    let good = std::fs::read_to_string(&p).unwrap();
    // truncated: drop 5 data lines of the dataset
    let lines: Vec<&str> = good.lines().collect();
    let cut: String =
        lines[..lines.len() - 6].iter().chain(&lines[lines.len() - 1..]).map(|l| format!("{l}\n")).collect();
    std::fs::write(&p, cut).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(e.contains("a.uff") && e.contains("dataset #1") && e.contains("record 12"), "{e}");
    // not a number
    let bad = good.replacen("e+01", "e+0x", 1);
    std::fs::write(&p, bad).unwrap();
    let e = read(&p, None).unwrap_err();
    assert!(e.contains("a.uff") && e.contains("record 12") && e.contains("cannot read"), "{e}");
    // an FRF file has no time history
    let e = read(Path::new(&example("frf.uff")), None).unwrap_err();
    assert!(e.contains("no time history"), "{e}");
    // by name: the writer's ID line
    std::fs::write(&p, &good).unwrap();
    let m = ChannelMap::parse("fz=dynocomp compensated fx").unwrap();
    let (mut r, _) = open_signal(&p, Some(&m)).unwrap();
    assert_eq!(r.axes(), &[2]);
    assert_eq!(read_all(&mut *r).unwrap().1[0].len(), 100);
    assert!(read(&p, Some(&ChannelMap::parse("fz=other").unwrap())).is_err());
}

fn read(p: &Path, m: Option<&ChannelMap>) -> Result<usize, String> {
    let (mut r, _) = open_signal(p, m).map_err(|e| format!("{e:#}"))?;
    read_all(&mut *r).map(|(_, c)| c[0].len()).map_err(|e| format!("{e:#}"))
}

/// Units of the ordinate (record 9): a force in kN is scaled to N, one in
/// mN too, NONE reads as N, and a unit that is not a force (lbf, V) is
/// refused naming the file, dataset and record; N itself is unchanged
/// (the control).
#[test]
fn ordinate_units_are_checked_and_scaled() {
    let x = signals(50);
    let p = tmp("uffunits", "u.uff");
    write_uff(&p, &x[..1], 51200.0, false);
    let good = std::fs::read_to_string(&p).unwrap();
    let rec9 = good.lines().nth(10).unwrap().to_string();
    assert!(rec9.contains("Force") && rec9.contains(" N "), "record 9 is `{rec9}`");
    let with_unit = |u: &str| {
        let mut r9 = rec9.replacen(" N ", &format!(" {u} "), 1);
        while r9.len() > rec9.len() && r9.ends_with(' ') {
            r9.pop();
        }
        assert_eq!(r9.len(), rec9.len());
        std::fs::write(&p, good.replacen(&rec9, &r9, 1)).unwrap();
        open_signal(&p, None)
            .and_then(|(mut r, _)| read_all(&mut *r))
            .map(|(_, c)| c[0].clone())
            .map_err(|e| format!("{e:#}"))
    };
    let n = with_unit("N").unwrap();
    for (u, k) in [("kN", 1000.0), ("mN", 0.001)] {
        let got = with_unit(u).unwrap();
        assert!(got.iter().zip(&n).all(|(a, b)| *a == k * b), "{u}");
    }
    for u in ["lbf", "V"] {
        let e = with_unit(u).unwrap_err();
        assert!(e.contains("u.uff") && e.contains("dataset #1") && e.contains("record 9") && e.contains(u), "{e}");
    }
}

/// Fuzzing (issue #16, `fuzz/fuzz_targets/uff_signal.rs`): a foreign binary
/// dataset ("29b") whose header declares more ASCII lines than the file has,
/// or a byte count above i64::MAX (a backwards seek), made the index pass
/// spin forever. Both are refused naming the file, line and dataset; a
/// well-formed foreign dataset before a time history is still skipped
/// (control).
#[test]
fn foreign_binary_dataset_with_impossible_counts_is_refused() {
    let time = |dir: i64| {
        let mut s = format!("{:>6}\n{:>6}{:74}\n", -1, 58, "");
        for id in ["seed", "NONE", "NONE", "NONE", "NONE"] {
            s.push_str(&format!("{id:<80}\n"));
        }
        s.push_str(&format!(
            "{:>5}{:>10}{:>5}{:>10} {:>10}{:>10}{:>4} {:>10}{:>10}{:>4}\n",
            1, 1, 0, 0, "DYN", 1, dir, "HAMMER", 1, dir
        ));
        s.push_str(&format!("{:>10}{:>10}{:>10}{:>13.6e}{:>13.6e}{:>13.6e}\n", 4, 4, 1, 0.0, 1.0 / 51200.0, 0.0));
        for (spec, label, units) in [(17, "Time", "s"), (9, "Force", "N"), (0, "NONE", "NONE"), (0, "NONE", "NONE")] {
            s.push_str(&format!("{spec:>10}{:>5}{:>5}{:>5} {label:<20} {units:<20}\n", 0, 0, 0));
        }
        s.push_str("  1.0  2.0  3.0  4.0\n    -1\n");
        s
    };
    let foreign = |lines: &str, bytes: &str| {
        format!("    -1\n    29b     2     2 {lines:>11} {bytes:>11}     0     0\nheader\n\x01\x02\x03\x04\n    -1\n")
    };
    let cases = [
        ("lines", foreign("222222222222222222", "4"), Some("header lines")),
        ("bytes", foreign("1", "18446744073709551000"), Some("byte count")),
        ("ok", foreign("1", "5"), None),
    ];
    for (name, head, want) in cases {
        let p = tmp("uffskip", &format!("{name}.uff"));
        std::fs::write(&p, format!("{head}{}", time(1))).unwrap();
        // Run on a thread: before the fix the first two never returned.
        let (tx, rx) = std::sync::mpsc::channel();
        let q = p.clone();
        std::thread::spawn(move || {
            let r = open_signal(&q, None)
                .and_then(|(mut r, _)| read_all(&mut *r))
                .map(|(_, c)| c[0].clone())
                .map_err(|e| format!("{e:#}"));
            let _ = tx.send(r);
        });
        let got = rx
            .recv_timeout(std::time::Duration::from_secs(120))
            .unwrap_or_else(|_| panic!("{name}: the reader did not return"));
        match want {
            Some(w) => {
                let e = got.expect_err(name);
                assert!(
                    e.starts_with(&format!("{}: line 1: dataset #1 (29b)", p.display())) && e.contains(w),
                    "{name}: {e}"
                );
            }
            None => assert_eq!(got.unwrap(), vec![1.0, 2.0, 3.0, 4.0], "{name}"),
        }
    }
}

/// Write `chans` with `w` in blocks of `block` samples, times from `t0` if given.
fn write_blocks(w: &mut dyn SignalWriter, chans: &[Vec<f64>], t0: Option<f64>, block: usize) -> anyhow::Result<()> {
    let n = chans[0].len();
    let mut at = 0;
    while at < n {
        let m = block.min(n - at);
        let t: Option<Vec<f64>> = t0.map(|t0| (at..at + m).map(|k| t0 + k as f64 / 51200.0).collect());
        let sl: Vec<&[f64]> = chans.iter().map(|c| &c[at..at + m]).collect();
        w.write_block(t.as_deref(), &sl)?;
        at += m;
    }
    w.finish()
}

/// The in-place writer (a record of known length written at its offsets,
/// no spill) gives the same bytes as the streamed one, for ASCII and 58b,
/// record lengths around the four-values-per-line boundary, odd blocks, and
/// values whose text is shorter (NaN, inf) or has a three-digit exponent;
/// what it writes reads back. Negative control: a layout one byte off would
/// differ from the streamed bytes and fail to read.
#[test]
fn placed_writer_matches_the_streamed_one() {
    use std::io::{Read, Seek};
    let odd = [f64::NAN, f64::NEG_INFINITY, 1e-300, -1.5e200, 0.0, -0.0, 123.456];
    for binary in [false, true] {
        for n in [0usize, 1, 3, 4, 5, 4099] {
            for t0 in [None, Some(1.5e-3), Some(-2e-120)] {
                let mut chans = signals(n);
                // Odd values where the record is not read back (the reader
                // refuses non-finite values).
                if t0.is_some() {
                    for (k, v) in odd.iter().enumerate().take(n) {
                        chans[1][k] = *v;
                    }
                }
                let axes = [0, 1, 2];
                let mut streamed = Vec::new();
                {
                    let mut w = UffWriter::new(&mut streamed, &axes, 51200.0, binary).unwrap();
                    write_blocks(&mut w, &chans, t0, 1000).unwrap();
                }
                let mut file = tempfile::tempfile().unwrap();
                {
                    let mut w = UffWriter::placed(&file, n as u64, &axes, 51200.0, binary).unwrap();
                    write_blocks(&mut w, &chans, t0, 7).unwrap();
                }
                let mut placed = Vec::new();
                file.rewind().unwrap();
                file.read_to_end(&mut placed).unwrap();
                assert!(
                    placed == streamed,
                    "binary {binary}, n {n}, t0 {t0:?}: the in-place file differs from the streamed one"
                );
                if n > odd.len() && t0.is_none() {
                    let p = tmp("uffplaced", if binary { "b.uff" } else { "a.uff" });
                    std::fs::write(&p, &placed).unwrap();
                    let (mut r, _) = open_signal(&p, None).unwrap();
                    let (_, got) = read_all(&mut *r).unwrap();
                    assert_eq!(got[0].len(), n);
                    // 58b bit for bit; ASCII (13 significant digits) to the f32 value.
                    let (a, b) = (got[2][n - 1], chans[2][n - 1]);
                    assert!(
                        if binary { a.to_bits() == b.to_bits() } else { a as f32 == b as f32 },
                        "{a} read back for {b}"
                    );
                }
            }
        }
    }
}

/// The in-place writer refuses a record longer or shorter than announced
/// (the datasets' places depend on it) instead of writing a file whose
/// headers lie.
#[test]
fn placed_writer_refuses_a_length_other_than_announced() {
    let chans = signals(10);
    let file = tempfile::tempfile().unwrap();
    let mut w = UffWriter::placed(&file, 8, &[0, 1, 2], 51200.0, true).unwrap();
    let err = write_blocks(&mut w, &chans, None, 4).unwrap_err().to_string();
    assert!(err.contains("more than the 8 samples"), "{err}");
    let file = tempfile::tempfile().unwrap();
    let mut w = UffWriter::placed(&file, 12, &[0, 1, 2], 51200.0, false).unwrap();
    let err = write_blocks(&mut w, &chans, None, 4).unwrap_err().to_string();
    assert!(err.contains("after 10 of the 12 samples"), "{err}");
    // Control: the announced length is accepted.
    let file = tempfile::tempfile().unwrap();
    let mut w = UffWriter::placed(&file, 10, &[0, 1, 2], 51200.0, false).unwrap();
    write_blocks(&mut w, &chans, None, 4).unwrap();
}

/// Every refusal of the index pass (dataset framing, records 6 to 9, the
/// channel set), word for word: the messages name the file, line, dataset
/// and record as they always have.
#[test]
fn uff_refusals_word_for_word() {
    let x = signals(4);
    let p = tmp("uffexact", "e.uff");
    let s = p.display().to_string();
    let written = |chans: &[Vec<f64>], binary: bool| {
        write_uff(&p, chans, 51200.0, binary);
        std::fs::read(&p).unwrap()
    };
    let good = String::from_utf8(written(&x[..1], false)).unwrap();
    // Line `l` (1-based) of the one-dataset file replaced: 8 is record 6,
    // 9 record 7, 11 record 9.
    let line = |l: usize, new: &str| {
        let mut ls: Vec<String> = good.lines().map(str::to_string).collect();
        ls[l - 1] = new.to_string();
        ls.join("\n") + "\n"
    };
    let rec7 = good.lines().nth(8).unwrap().to_string();
    let rec7_with = |at: usize, new: &str| {
        let mut r = rec7.clone();
        r.replace_range(at..at + new.len(), new);
        line(9, &r)
    };
    let rec9 = good.lines().nth(10).unwrap().to_string();
    // Two channels of different lengths: dataset 1 of a 2-channel file of 4
    // samples, dataset 2 of one of 6.
    let datasets = |b: Vec<u8>| {
        let t = String::from_utf8(b).unwrap();
        let mut out = vec![String::new()];
        let mut open = false;
        for l in t.lines() {
            out.last_mut().unwrap().push_str(&format!("{l}\n"));
            if l.trim() == "-1" {
                if open {
                    out.push(String::new());
                }
                open = !open;
            }
        }
        out
    };
    let mismatch = datasets(written(&x[..2], false))[0].clone() + &datasets(written(&signals(6)[..2], false))[1];
    let mut bin = written(&x[..1], true);
    let bin_len = bin.len();
    bin.truncate(bin_len - 7);
    bin.extend_from_slice(b"junk\n    -1\n");
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (
            format!("hello\n{good}").into_bytes(),
            "{s}: line 1: expected a '    -1' line opening a dataset, found \"hello\"",
        ),
        (
            line(2, "    58b     1     2          12").into_bytes(),
            "{s}: line 2: dataset #1 (58, starting line 1), binary header: unsupported 58b header \
                \"58b     1     2          12\" (need byte order 1/2, IEEE 754, 11 ASCII lines)",
        ),
        (
            b"    -1\n  2412b     1     2          99         100\n".to_vec(),
            "{s}: line 1: dataset #1 (2412b): the file ends inside its 99 header lines",
        ),
        (
            b"    -1\n  2412b     1     2           0 18446744073709551615\n".to_vec(),
            "{s}: line 1: dataset #1 (2412b): binary byte count 18446744073709551615 out of range",
        ),
        (b"    -1\n   151\nmodel\n".to_vec(), "{s}: line 1: dataset #1 (151) is not closed by a '    -1' line"),
        (
            line(8, "x").into_bytes(),
            "{s}: line 8: dataset #1 (58, starting line 1), record 6: cannot read function type and directions",
        ),
        (line(9, "x").into_bytes(), "{s}: line 9: dataset #1 (58, starting line 1), record 7: cannot read data form"),
        (
            rec7_with(10, "        -1").into_bytes(),
            "{s}: line 9: dataset #1 (58, starting line 1), record 7: -1 data points",
        ),
        (
            bin,
            "{s}: line 14: dataset #1 (58, starting line 1), record 12: no closing '    -1' after \
                the 32 bytes of binary data record 7 declares",
        ),
        (
            rec7_with(20, "         0").into_bytes(),
            "{s}: line 9: dataset #1 (58, starting line 1), record 7: uneven abscissa: a time \
                history needs evenly spaced samples",
        ),
        (
            rec7_with(10, "         0").into_bytes(),
            "{s}: line 9: dataset #1 (58, starting line 1), record 7: no data points",
        ),
        (
            rec7_with(30, "          inf").into_bytes(),
            "{s}: line 9: dataset #1 (58, starting line 1), record 7: abscissa start inf s is not finite",
        ),
        (
            line(11, &rec9.replacen(" N  ", " lbf", 1)).into_bytes(),
            "{s}: line 11: dataset #1 (58, starting line 1), record 9: ordinate units \"lbf\" are \
                not a force in N (kN and mN are scaled)",
        ),
        (
            line(8, &good.lines().nth(7).unwrap().replacen("    1", "    4", 1)).into_bytes(),
            "{s}: no time history (dataset 58, function type 1) for fx, fy or fz; skipped: dataset \
                #1: function type 4 (give --channels fx=NAME,... if the response directions do not say \
                the axis)",
        ),
        (
            mismatch.into_bytes(),
            "{s}: dataset #1 (fx) has 4 points every 0.00001953125 s, dataset #2 (fy) 6 points every \
                0.00001953125 s: channels must match",
        ),
    ];
    let mut bad = Vec::new();
    for (k, (bytes, want)) in cases.iter().enumerate() {
        std::fs::write(&p, bytes).unwrap();
        let got = read(&p, None).map(|_| "accepted".to_string()).unwrap_or_else(|e| e);
        let want = want.replace("{s}", &s);
        if got != want {
            bad.push(format!("case {k}: {:?}", got.replace(&s, "{s}")));
        }
    }
    assert!(bad.is_empty(), "\n{}\n{good}", bad.join("\n"));
}

/// A 58b dataset of another function type (skipped by its byte count)
/// whose record 7 declares more points than any file can hold is refused
/// naming record 7, instead of overflowing the byte count; control: the
/// same dataset with its true count is skipped and the time history after
/// it is read.
#[test]
fn a_skipped_58b_dataset_with_an_impossible_count_is_refused() {
    let p = tmp("uffhuge", "one.uff");
    write_uff(&p, &[vec![1.0, 2.0, 3.0, 4.0]], 51200.0, true);
    let one = std::fs::read(&p).unwrap();
    // Lines of the text header: record 6 (7th line after the "-1"), record 7.
    let text_end = one.windows(1).position(|w| w[0] == 0).unwrap_or(one.len());
    let head = String::from_utf8_lossy(&one[..text_end]).to_string();
    let lines: Vec<&str> = head.split('\n').collect();
    let (r6, r7) = (lines[7], lines[8]);
    let foreign = |count: &str| -> Vec<u8> {
        // Function type 4 (an FRF): not a time history, so its data are skipped.
        let r6_frf = format!("{:>5}{}", 4, &r6[5..]);
        let r7_count = format!("{:>10}{:>10}{}", &r7[..10].trim(), count, &r7[20..]);
        let mut b = one.clone();
        let s = String::from_utf8_lossy(&one[..text_end]).replacen(r6, &r6_frf, 1).replacen(r7, &r7_count, 1);
        b.splice(..text_end, s.into_bytes());
        b.extend_from_slice(&one);
        b
    };
    let read_back = |bytes: Vec<u8>| {
        std::fs::write(&p, bytes).unwrap();
        open_signal(&p, None).and_then(|(mut r, _)| read_all(&mut *r)).map(|(_, c)| c[0].clone())
    };
    let huge = read_back(foreign(" 4611686018427387904")).map_err(|e| format!("{e:#}")).unwrap_err();
    assert!(huge.contains("record 7") && huge.contains("more than any file holds"), "{huge}");
    assert_eq!(read_back(foreign("4")).unwrap(), vec![1.0, 2.0, 3.0, 4.0]);
}
