//! Issue #14: `compensate` streams the box path in blocks, bit-exact with
//! the whole-record path; `--report` draws what it did; bad input leaves no
//! output behind.

use dynocomp::io::signal_csv::{read_signal_csv, SignalRecord};
use dynocomp::offline::compensate::{compensate_matrix, compensate_record, StreamCompensator};
use dynocomp_core::image::CoeffImage;
use dynocomp_core::kernel::{AxisFilter, Section};

use crate::cli_common;
use crate::common;
use cli_common::{dynocomp, example, tmp};

/// A three-axis image with a resonant pair, a real pole and FIR taps per
/// axis (different per axis) and a declared latency of `latency` samples.
fn image(latency: u16) -> CoeffImage {
    let mut img = common::image(1, 51200, 0);
    img.latency_samples = latency;
    for (a, ax) in img.axes.iter_mut().enumerate() {
        let ax = ax.as_mut().unwrap();
        let (re, im) = (0.97 - 0.01 * a as f32, 0.08 + 0.02 * a as f32);
        let secs = [
            Section { delta: [re - 1.0, im, -im, re - 1.0], b: [1.0, 0.0], c: [0.3, -0.2 + 0.1 * a as f32] },
            Section::first_order(0.6, 1.0, 0.4),
        ];
        ax.filter = AxisFilter::with_fir(&secs, 0.7, &[0.1, -0.05 * a as f32]).unwrap();
    }
    img
}

fn record(n: usize) -> SignalRecord {
    SignalRecord {
        t_s: None,
        channels: (0..3)
            .map(|a| (a, (0..n).map(|k| ((k * (a + 2)) as f64 * 0.031).sin() * 80.0 + (k % 13) as f64).collect()))
            .collect(),
    }
}

/// Stream `rec` through in blocks of `block` samples.
fn streamed(img: &CoeffImage, rec: &SignalRecord, raw: bool, block: usize) -> Vec<Vec<f64>> {
    let axes: Vec<usize> = rec.channels.iter().map(|c| c.0).collect();
    let mut c = StreamCompensator::new(img, &axes, raw, "test").unwrap();
    let mut out = vec![Vec::new(); axes.len()];
    let n = rec.len();
    let mut s = 0;
    while s < n {
        let e = (s + block).min(n);
        let blk: Vec<Vec<f64>> = rec.channels.iter().map(|ch| ch.1[s..e].to_vec()).collect();
        c.push(&blk, &mut out).unwrap();
        s = e;
    }
    c.finish(&mut out).unwrap();
    out
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// Any block cutting, latency removed or kept: the streamed outputs are the
/// whole-record outputs bit for bit and as many as the input. Negative
/// control: the same comparison tells the kept-latency output from the
/// aligned one.
#[test]
fn streaming_is_bit_exact_with_the_whole_record() {
    let rec = record(20_011);
    for latency in [0u16, 4] {
        let img = image(latency);
        for raw in [false, true] {
            let want = compensate_record(&img, &rec, raw, "test").unwrap();
            for block in [1, 3, 4, 5, 4096, 8192, 20_011, 50_000] {
                let got = streamed(&img, &rec, raw, block);
                for (a, g) in got.iter().enumerate() {
                    assert!(
                        same_bits(g, want.channel(a).unwrap()),
                        "latency {latency}, raw {raw}, block {block}, axis {a}"
                    );
                }
            }
        }
    }
    let img = image(4);
    let aligned = streamed(&img, &rec, false, 4096);
    let raw = compensate_record(&img, &rec, true, "test").unwrap();
    assert!(!same_bits(&aligned[0], raw.channel(0).unwrap()));
}

/// The 3x3 image's filter streams the same way: any block cutting, latency
/// removed or kept, the outputs of the whole-record path
/// (`compensate_matrix`) bit for bit. Negative control: feeding the
/// channels in another order (the filter mixes them) gives other bits. A
/// record without all three channels is refused.
#[test]
fn a_3x3_image_streams_bit_exact_with_the_whole_record() {
    let bytes = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../fuzz/images/matrix.dcimg")).unwrap();
    let img = dynocomp_core::image::MatrixImage::parse(&bytes).unwrap();
    assert!(img.latency_samples > 0);
    let rec = record(20_011);
    let run = |rec: &SignalRecord, raw: bool, block: usize| {
        let mut c = StreamCompensator::matrix(&img, &[0, 1, 2], raw, "test").unwrap();
        let mut out = vec![Vec::new(); 3];
        for s in (0..rec.len()).step_by(block) {
            let e = (s + block).min(rec.len());
            let blk: Vec<Vec<f64>> = rec.channels.iter().map(|ch| ch.1[s..e].to_vec()).collect();
            c.push(&blk, &mut out).unwrap();
        }
        c.finish(&mut out).unwrap();
        out
    };
    for raw in [false, true] {
        let want = compensate_matrix(&img, &rec, raw, "test").unwrap();
        for block in [1, 5, 4096, 8192, 50_000] {
            let got = run(&rec, raw, block);
            for (a, g) in got.iter().enumerate() {
                assert!(same_bits(g, want.channel(a).unwrap()), "raw {raw}, block {block}, axis {a}");
            }
        }
    }
    let mut swapped = rec.clone();
    let (x, y) = (swapped.channels[0].1.clone(), swapped.channels[1].1.clone());
    swapped.channels[0].1 = y;
    swapped.channels[1].1 = x;
    let want = compensate_matrix(&img, &rec, false, "test").unwrap();
    assert!(!same_bits(&run(&swapped, false, 4096)[2], want.channel(2).unwrap()), "control: order made no difference");
    let e = StreamCompensator::matrix(&img, &[0, 1], false, "rec.csv").err().unwrap().to_string();
    assert!(e.contains("rec.csv") && e.contains("fx, fy and fz together"), "{e}");
}

/// `compensate` of the example's measured force with image(4), `--report`
/// and `--truth` (a file of the example) and `extra` flags: (success,
/// stderr, output, report folder).
fn compensate_example_with_report(
    tag: &str,
    truth: &str,
    extra: &[&str],
) -> (bool, String, std::path::PathBuf, std::path::PathBuf) {
    let img_path = tmp(tag, "img.dcimg");
    std::fs::write(&img_path, common::bytes(&image(4))).unwrap();
    let (out, rep) = (tmp(tag, "out.csv"), tmp(tag, "report"));
    let (inp, tr) = (example("measured.csv"), example(truth));
    let mut args =
        vec!["compensate", "--coeffs", img_path.to_str().unwrap(), "--input", &inp, "--output", out.to_str().unwrap()];
    args.extend(["--report", rep.to_str().unwrap(), "--truth", &tr]);
    args.extend_from_slice(extra);
    let (ok, _, err) = dynocomp(&args);
    (ok, err, out, rep)
}

/// The CLI on the bundled example: output equal (as f64 read back) to the
/// whole-record path on the same input; the report exists with three plots
/// per axis and states an NRMSE that is below the measured force's.
#[test]
fn cli_streams_the_example_and_reports() {
    let (ok, err, out, rep) =
        compensate_example_with_report("stream", "measured.csv", &["--spindle-rpm", "16500", "--teeth", "4"]);
    assert!(ok, "{err}");
    let input = read_signal_csv(std::path::Path::new(&example("measured.csv"))).unwrap();
    let want = compensate_record(&image(4), &input, false, "x").unwrap();
    let got = read_signal_csv(&out).unwrap();
    assert_eq!(
        got.t_s.as_ref().map(|t| t.iter().map(|v| v.to_bits()).collect::<Vec<_>>()),
        input.t_s.map(|t| t.iter().map(|v| v.to_bits()).collect())
    );
    for a in 0..3 {
        assert!(same_bits(got.channel(a).unwrap(), want.channel(a).unwrap()), "axis {a}");
    }
    for f in ["index.html", "x_overview.svg", "y_zoom.svg", "z_spectrum.svg"] {
        assert!(rep.join(f).is_file(), "{f} missing");
    }
    let html = std::fs::read_to_string(rep.join("index.html")).unwrap();
    assert!(
        html.contains("NRMSE") && html.contains("TPF") || html.contains("tooth-passing frequency 1100.0 Hz"),
        "{html}"
    );
    // The truth here is the measured force itself: its NRMSE must read 0.
    assert!(err.contains("NRMSE measured 0.000 %"), "{err}");
}

/// Malformed input: one line naming the file and line, non-zero exit, no
/// output file; a time column at another rate than the image's is refused
/// after streaming, and again nothing is left behind.
#[test]
fn bad_input_leaves_nothing_behind() {
    let img_path = tmp("streambad", "img.dcimg");
    std::fs::write(&img_path, common::bytes(&image(4))).unwrap();
    let bad = tmp("streambad", "bad.csv");
    let mut text = String::from("t_s,fx\n");
    for k in 0..20_000 {
        text.push_str(&format!("{},{}\n", k as f64 / 51200.0, k % 7));
    }
    text.push_str("0.5,abc\n");
    std::fs::write(&bad, &text).unwrap();
    let out = tmp("streambad", "out.csv");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        img_path.to_str().unwrap(),
        "--input",
        bad.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(err.contains("bad.csv: line 20002, column 2") && err.lines().count() == 1, "{err}");
    assert!(!out.exists());
    let slow = tmp("streambad", "slow.csv");
    let text: String = std::iter::once("t_s,fx\n".to_string())
        .chain((0..20_000).map(|k| format!("{},{}\n", k as f64 / 48000.0, k % 7)))
        .collect();
    std::fs::write(&slow, text).unwrap();
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        img_path.to_str().unwrap(),
        "--input",
        slow.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(err.contains("48000.000 Hz") && err.contains("51200"), "{err}");
    assert!(!out.exists());
    // positive control: the same record at the image's rate passes
    let fine = tmp("streambad", "fine.csv");
    let text: String = std::iter::once("t_s,fx\n".to_string())
        .chain((0..20_000).map(|k| format!("{},{}\n", k as f64 / 51200.0, k % 7)))
        .collect();
    std::fs::write(&fine, text).unwrap();
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        img_path.to_str().unwrap(),
        "--input",
        fine.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(out.exists());
}

/// A long record's overview stays small: min/max envelopes, not points
/// (the overview SVG of 2 M samples is below 1 MB, and about the size of
/// that of 200 k samples).
#[test]
fn report_size_does_not_grow_with_the_record() {
    let img_path = tmp("streamlong", "img.dcimg");
    std::fs::write(&img_path, common::bytes(&image(4))).unwrap();
    let mut sizes = Vec::new();
    for n in [200_000usize, 2_000_000] {
        let inp = tmp("streamlong", &format!("in{n}.csv"));
        let mut text = String::with_capacity(n * 12);
        text.push_str("fx\n");
        for k in 0..n {
            text.push_str(&format!("{:.3}\n", (k as f64 * 0.135).sin() * 100.0));
        }
        std::fs::write(&inp, text).unwrap();
        let rep = tmp("streamlong", &format!("rep{n}"));
        let out = tmp("streamlong", &format!("out{n}.csv"));
        let (ok, _, err) = dynocomp(&[
            "compensate",
            "--coeffs",
            img_path.to_str().unwrap(),
            "--input",
            inp.to_str().unwrap(),
            "--output",
            out.to_str().unwrap(),
            "--report",
            rep.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        sizes.push(std::fs::metadata(rep.join("x_overview.svg")).unwrap().len());
    }
    assert!(sizes[1] < 1_000_000 && sizes[1] < 2 * sizes[0], "{sizes:?}");
}

/// The report's NRMSE against `--truth` is the project's one figure: band
/// min(4 kHz, 0.4 fs) (4 kHz at 51.2 kHz), as `examples/score.rs` computes
/// it from the written output and the simulator's true force. Negative
/// control: the same figures in a wider band (the image's flat band or
/// fs/2) read differently, so the comparison can tell the bands apart.
#[test]
fn report_nrmse_uses_the_scoring_band() {
    let (ok, err, out, rep) = compensate_example_with_report("band", "true_force.csv", &[]);
    assert!(ok, "{err}");
    let truth = read_signal_csv(std::path::Path::new(&example("true_force.csv"))).unwrap();
    let meas = read_signal_csv(std::path::Path::new(&example("measured.csv"))).unwrap();
    let comp = read_signal_csv(&out).unwrap();
    let fig = |est: &[f64], t: &[f64], band: f64| {
        format!("{:.3} %", 100.0 * dynocomp::metrics::accuracy(est, t, 51200.0, band).nrmse)
    };
    for (a, name) in ["x", "y", "z"].iter().enumerate() {
        let line = err
            .lines()
            .find(|l| l.starts_with(&format!("f{name}: NRMSE")))
            .unwrap_or_else(|| panic!("no NRMSE line for f{name}: {err}"));
        let t = truth.channel(a).unwrap();
        let (c, m) = (comp.channel(a).unwrap(), meas.channel(a).unwrap());
        let want =
            format!("f{name}: NRMSE measured {}, compensated {} (band 4000 Hz;", fig(m, t, 4000.0), fig(c, t, 4000.0));
        assert!(line.starts_with(&want), "report: {line}\nscore: {want}");
        assert_ne!(fig(c, t, 4000.0), fig(c, t, 25600.0), "axis {name}: the band makes no difference here");
    }
    let html = std::fs::read_to_string(rep.join("index.html")).unwrap();
    assert!(html.contains("both low-passed at 4000 Hz"), "the page states another band");
    let lower = dynocomp::report::page::lowercase_caption_sentences(&html);
    assert!(lower.is_empty(), "caption sentences start in lowercase: {lower:?}");
}

/// Outputs too large for memory spill beside the output, not to the
/// system's temporary folder (often a small RAM disk): with TMPDIR pointing
/// nowhere, a UFF 58b output (spilled per channel) is still written.
/// Control: an output folder that does not exist is refused, naming it.
#[test]
fn uff_output_spills_beside_the_output() {
    let img_path = tmp("spilldir", "img.dcimg");
    std::fs::write(&img_path, common::bytes(&image(4))).unwrap();
    let input = tmp("spilldir", "in.csv");
    let text: String = std::iter::once("t_s,fx\n".to_string())
        .chain((0..20_000).map(|k| format!("{},{}\n", k as f64 / 51200.0, k % 7)))
        .collect();
    std::fs::write(&input, text).unwrap();
    let run = |out: &std::path::Path| {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_dynocomp"))
            .args([
                "compensate",
                "--coeffs",
                img_path.to_str().unwrap(),
                "--input",
                input.to_str().unwrap(),
                "--output",
                out.to_str().unwrap(),
                "--output-format",
                "uff58b",
            ])
            .env("TMPDIR", "/nonexistent-dynocomp-tmp")
            .output()
            .unwrap();
        (o.status.success(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let out = tmp("spilldir", "out.uff");
    let (ok, err) = run(&out);
    assert!(ok, "{err}");
    assert!(std::fs::metadata(&out).unwrap().len() > 20_000 * 8, "output too short");
    let missing = tmp("spilldir", "no-such-folder").join("out.uff");
    let (ok, err) = run(&missing);
    assert!(!ok && err.contains("no-such-folder") && err.trim().lines().count() == 1, "{err}");
}

/// `--truth` without `--report` scores the record: one NRMSE line per axis
/// (band-limited and as written), the same as with a report, and no report
/// folder. Control: without `--truth` there is no NRMSE line.
#[test]
fn truth_alone_prints_the_scores() {
    let img_path = tmp("truthonly", "img.dcimg");
    std::fs::write(&img_path, common::bytes(&image(4))).unwrap();
    let out = tmp("truthonly", "out.csv");
    let (inp, tr) = (example("measured.csv"), example("true_force.csv"));
    let base =
        ["compensate", "--coeffs", img_path.to_str().unwrap(), "--input", &inp, "--output", out.to_str().unwrap()];
    let (ok, _, err) = dynocomp(&[&base[..], &["--truth", &tr]].concat());
    assert!(ok, "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.contains("NRMSE measured")).collect();
    assert_eq!(lines.len(), 3, "{err}");
    assert!(lines.iter().all(|l| l.contains("as written")), "{err}");
    let (_, with_report, _, rep) = compensate_example_with_report("truthrep", "true_force.csv", &[]);
    for l in &lines {
        assert!(with_report.contains(l), "`{l}` differs from the report's lines: {with_report}");
    }
    // The report's plots: the error split at the band edge, the spectra in
    // the band and up to Nyquist with the band marked.
    let read = |d: &std::path::Path, f: &str| std::fs::read_to_string(d.join(f)).unwrap();
    let overview = read(&rep, "x_overview.svg");
    assert!(overview.contains("error in the band") && overview.contains("error above"), "error panels missing");
    let spectrum = read(&rep, "x_spectrum.svg");
    assert!(spectrum.contains("compensated band") && spectrum.contains("up to Nyquist"), "band not marked");
    // Control: without a truth, no NRMSE line and no error panels.
    let rep2 = tmp("truthonly", "report");
    let (ok, _, err) = dynocomp(&[&base[..], &["--report", rep2.to_str().unwrap()]].concat());
    assert!(ok && !err.contains("NRMSE"), "{err}");
    assert!(!read(&rep2, "x_overview.svg").contains("error in the band"));
}
