//! The `design --report DIR` output: one SVG per axis and plot, and an
//! index.html that shows the summary and references every plot.

use dynocomp::design::axis::{design_axis, DesignOptions};
use dynocomp::design::sensitivity::predict;
use dynocomp::report::design::write_report;
use dynocomp::simulate::{simulate, SimParams};
use std::path::PathBuf;

/// Number of coordinate pairs in the longest `points="…"` (polyline) or
/// `d="…"` (path) attribute of an SVG.
fn longest_polyline(svg: &str) -> usize {
    let mut best = 0;
    for key in ["points=\"", " d=\""] {
        let mut rest = svg;
        while let Some(i) = rest.find(key) {
            let after = &rest[i + key.len()..];
            let end = after.find('"').unwrap_or(after.len());
            let attr = &after[..end];
            let n = attr.matches(',').count();
            best = best.max(n);
            rest = &after[end..];
        }
    }
    best
}

fn check_svg(path: &PathBuf, must_contain: &[&str]) -> String {
    let s = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let t = s.trim_start();
    assert!(t.starts_with("<svg") || t.starts_with("<?xml"), "{}: does not start like an SVG", path.display());
    assert!(s.trim_end().ends_with("</svg>"), "{}: not closed by </svg>", path.display());
    assert_eq!(s.matches("<svg").count(), 1, "{}: one svg element", path.display());
    assert!(s.contains("<text"), "{}: no text elements", path.display());
    for m in must_contain {
        assert!(s.contains(m), "{}: missing {m:?}", path.display());
    }
    // balanced text elements (a crude well-formedness check)
    assert_eq!(s.matches("<text").count(), s.matches("</text>").count(), "{}", path.display());
    s
}

#[test]
fn report_writes_svgs_and_index() {
    let sim = simulate(7, &SimParams::default()).unwrap();
    let opts = DesignOptions::default();
    let d = design_axis(&sim.frf.freq_hz, sim.frf.axis(0).unwrap(), 0.05, &opts).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    // a directory that does not exist yet: write_report creates it
    let dir = tmp.path().join("out").join("report");
    let summary = "axis x: summary <with> & special \"chars\"\nsecond line";
    let files =
        write_report(&dir, &sim.frf, std::slice::from_ref(&d), &[predict(&d, &opts)], opts.fs_hz, summary).unwrap();

    let names: Vec<String> = files.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    for n in ["x_frf_fit.svg", "x_compensated.svg", "x_poles.svg", "index.html"] {
        assert!(names.iter().any(|m| m == n), "{n} not among {names:?}");
    }
    assert_eq!(names.last().unwrap(), "index.html");
    for f in &files {
        assert!(f.is_file(), "{} missing", f.display());
        assert_eq!(f.parent().unwrap(), dir);
    }
    // no temporary files left behind
    let listed: Vec<String> =
        std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(listed.len(), files.len(), "unexpected files in the report dir: {listed:?}");

    let n_lines = sim.frf.freq_hz.len();
    let fit = check_svg(
        &dir.join("x_frf_fit.svg"),
        &["Axis x", "Frequency (Hz)", "measured G (on top)", "fitted model", "Residual", "Coherence"],
    );
    assert!(longest_polyline(&fit) > n_lines / 4, "FRF plot has no long line");
    let comp = check_svg(
        &dir.join("x_compensated.svg"),
        &["Axis x", "Frequency (Hz)", "uncompensated |G|", "tolerance", "flat band"],
    );
    assert!(longest_polyline(&comp) > n_lines / 4, "compensated plot has no long line");
    let poles =
        check_svg(&dir.join("x_poles.svg"), &["Axis x", "Re z", "Im z", "unit circle", "compensator", "fitted model"]);
    assert!(longest_polyline(&poles) > 100, "pole map has no unit circle");
    assert!(poles.contains("<circle"), "pole map has no model poles");
    // The sensitivity curve, one point per shift of −5…+5 %, on a log scale.
    let sens = check_svg(
        &dir.join("x_sensitivity.svg"),
        &["Axis x", "Sensor-mode shift", "predicted error", "twice the nominal", "log scale"],
    );
    assert!(
        longest_polyline(&sens) >= dynocomp::design::sensitivity::SHIFTS_PCT.len(),
        "sensitivity plot has no curve"
    );

    let html = std::fs::read_to_string(dir.join("index.html")).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(html.contains("<pre>") && html.contains("</pre>"));
    // Every caption sentence starts with a capital (the page reads as prose).
    let lower = dynocomp::report::page::lowercase_caption_sentences(&html);
    assert!(lower.is_empty(), "caption sentences start in lowercase: {lower:?}");
    // The summary wraps instead of running off the page's edge.
    assert!(html.contains("white-space: pre-wrap"), "the summary does not wrap");
    assert!(
        html.contains("axis x: summary &lt;with&gt; &amp; special &quot;chars&quot;\nsecond line"),
        "summary not escaped/shown"
    );
    for f in &files {
        let n = f.file_name().unwrap().to_string_lossy();
        if n.ends_with(".svg") {
            assert!(html.contains(&format!("<img src=\"{n}\"")), "index.html does not embed {n}");
        }
    }

    // writing again over an existing report succeeds and leaves the same files
    let again =
        write_report(&dir, &sim.frf, std::slice::from_ref(&d), &[predict(&d, &opts)], opts.fs_hz, summary).unwrap();
    assert_eq!(again, files);

    // a write that fails midway removes the files this run created: make the
    // third plot's destination an (existing) directory so its rename fails
    let dir2 = tmp.path().join("failing");
    std::fs::create_dir_all(dir2.join("x_poles.svg")).unwrap();
    std::fs::write(dir2.join("x_frf_fit.svg"), "old").unwrap();
    let err = write_report(&dir2, &sim.frf, std::slice::from_ref(&d), &[predict(&d, &opts)], opts.fs_hz, summary)
        .unwrap_err();
    assert!(format!("{err:#}").contains("x_poles.svg"), "{err:#}");
    let mut left: Vec<String> =
        std::fs::read_dir(&dir2).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    left.sort();
    assert_eq!(left, ["x_frf_fit.svg", "x_poles.svg"], "files created by the failed run were not removed");

    if let Ok(keep) = std::env::var("DYNOCOMP_KEEP_REPORT") {
        let keep = PathBuf::from(keep);
        std::fs::create_dir_all(&keep).unwrap();
        for f in &files {
            std::fs::copy(f, keep.join(f.file_name().unwrap())).unwrap();
        }
    }
}

#[test]
fn report_error_names_missing_axis_and_writes_nothing() {
    let sim = simulate(3, &SimParams::default()).unwrap();
    let opts = DesignOptions::default();
    let d = design_axis(&sim.frf.freq_hz, sim.frf.axis(0).unwrap(), 0.05, &opts).unwrap();
    let mut frf = sim.frf.clone();
    frf.axes.retain(|a| a.axis != 0);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("r");
    let err = write_report(&dir, &frf, std::slice::from_ref(&d), &[predict(&d, &opts)], opts.fs_hz, "s").unwrap_err();
    assert!(format!("{err:#}").contains("axis x"), "{err:#}");
    assert!(!dir.exists(), "report dir created although nothing was written");
}
