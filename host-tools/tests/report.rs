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

/// The worded `<text>` elements of an SVG in the order drawn (titles,
/// captions, axis names, legend entries), numbers replaced by `#` so that
/// only the plot's structure is pinned, not the design's figures.
fn worded_texts(svg: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = svg;
    while let Some(i) = rest.find("<text") {
        let after = &rest[i..];
        let start = after.find('>').map_or(after.len(), |k| k + 1);
        let end = after.find("</text>").unwrap_or(after.len());
        let t = &after[start..end.max(start)];
        let mut s = String::new();
        for c in t.chars() {
            if c.is_ascii_digit() || (c == '.' && s.ends_with('#')) {
                if !s.ends_with('#') {
                    s.push('#');
                }
            } else {
                s.push(c);
            }
        }
        if s.chars().any(char::is_alphabetic) {
            out.push(s.trim().to_string());
        }
        rest = &after[end.max(1)..];
    }
    out
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
    // What the two plots say, in the order they draw it: panel by panel,
    // caption, axis names, then the legend's entries in drawing order.
    let fq = "Frequency (Hz)";
    let fit_texts = [
        "Axis x — measured FRF and fitted model (order #, fit error # % in the coherent band)",
        "Magnitude |G| (coherent band #–# Hz)",
        "|G| (dB re # N/N)",
        fq,
        "coherent band",
        "fitted model Ĝ",
        "measured G (on top)",
        "Phase ∠G (wrapped)",
        "Phase (°)",
        fq,
        "fitted model Ĝ",
        "measured G (on top)",
        "Residual |Ĝ − G| / |G| of the fit (%, log scale)",
        "residual (%)",
        fq,
        "residual",
        "Coherence γ² (coherent band #–# Hz)",
        "γ²",
        fq,
        "coherent band",
        "coherence γ²",
    ];
    assert_eq!(worded_texts(&fit), fit_texts);
    let comp_texts = [
        "Axis x — compensated response H·G (latency # samples removed), flat band of the measured G #–# Hz",
        "Magnitude, overview",
        "Magnitude (dB)",
        fq,
        "coherent band",
        "flat band, measured G (±# %, ±#°)",
        "coherent lines off the tolerances (measured)",
        "uncompensated |G|",
        "compensated |H·G|",
        "Magnitude ratio, zoom (tolerance ±# %)",
        "|H·G| (N/N)",
        fq,
        "±# % tolerance",
        "uncompensated |G|",
        "compensated |H·G| (measured G)",
        "|H·Ĝ| (fitted model)",
        "Phase, zoom (tolerance ±#°)",
        "Phase (°)",
        fq,
        "±#° tolerance",
        "uncompensated ∠G",
        "compensated ∠H·G (measured G)",
        "∠H·Ĝ (fitted model)",
    ];
    assert_eq!(worded_texts(&comp), comp_texts);
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

/// The one-screen summary of `design`, line by line: the image line, the
/// fitting bands, the table's header and one row per axis, then per axis its
/// discrete model and notes, then the sensitivity lines, then the legend.
/// Each line shows the design's own figures in its place.
#[test]
fn summary_text_lists_its_parts_in_order() {
    use dynocomp::design::bands::Band;
    use dynocomp::report::summary::render_summary;
    let sim = simulate(7, &SimParams::default()).unwrap();
    let opts = DesignOptions::default();
    let mut designs: Vec<_> =
        (0..2).map(|a| design_axis(&sim.frf.freq_hz, sim.frf.axis(a).unwrap(), 0.05, &opts).unwrap()).collect();
    // The summary only reads the bands and notes: set some to see where they go.
    designs[0].bands = vec![Band { lo_hz: 100.0, hi_hz: 250.0, label: "--band".into() }];
    designs[1].notes.push("a note of axis y".into());
    let sens: Vec<_> = designs.iter().map(|d| predict(d, &opts)).collect();
    let text = render_summary(&designs, &sens, 51_200.0, 4, "out.dcimg", 0x2a, "vf", None);
    let lines: Vec<&str> = text.lines().collect();

    let mut want: Vec<String> = vec![
        "image out.dcimg (id 0000002a): fs 51200 Hz, latency 4 samples (78.1 µs), method vf".into(),
        "fitting bands: 100–250 Hz (--band)".into(),
        "axis order fit err coherent (Hz)     Q (N²)    R (N²)  flat band (Hz)  noise   pred.     raw    match sec+fir"
            .into(),
    ];
    for d in &designs {
        // The row's columns (white space is folded below).
        let band = |b: (f64, f64)| format!("{:.0}-{:.0}", b.0, b.1);
        let pct = |v: f64, digits: usize| format!("{:.*}%", digits, 100.0 * v);
        let columns = [
            ["x", "y"][d.axis].to_string(),
            d.model.order().to_string(),
            pct(d.fit_nrmse, 2),
            band(d.coherent_band_hz),
            format!("{:.3e}", d.kalman.q),
            format!("{:.4}", d.kalman.r),
            band(d.flat_band_hz),
            format!("{:.2}", d.noise_gain),
            pct(d.predicted_error, 2),
            pct(d.raw_predicted_error, 2),
            pct(d.model_match, 3),
            format!("{}+{}", d.filter.sections().len(), d.filter.fir().len()),
        ];
        want.push(columns.join(" "));
    }
    let fit: Vec<String> = designs
        .iter()
        .map(|d| {
            let (fit, with) = (100.0 * d.fit_uncertainty, 100.0 * d.predicted_error_with_fit());
            format!("{} {fit:.2} % (pred. with it {with:.2} %)", ["x", "y"][d.axis])
        })
        .collect();
    want.push(format!(
        "fit uncertainty (the impact test's noise left in Ĝ, which pred. cannot see; more impacts lower it): {}",
        fit.join(", ")
    ));
    let offline: Vec<String> = designs
        .iter()
        .map(|d| format!("{} {:.2} %", ["x", "y"][d.axis], 100.0 * d.offline_predicted_with_fit()))
        .collect();
    want.push(format!(
        "compensate --offline on this image (zero-lag smoother of the same model and q, the fit's uncertainty \
         counted): {}; for a flat force: a cut, its power at low harmonics, gains less (`--force-prior spectrum \
         --force-record CUT.csv` predicts for it)",
        offline.join(", ")
    ));
    for d in &designs {
        let (dm, fd) = d.discrete.as_ref().expect("the default design has a discrete model");
        let above = fd.modes_above_nyquist;
        let tail = if above > 0 { format!(", {above} mode(s) above fs/2 fitted by their tail") } else { String::new() };
        let (lo, hi) = d.compensated_band_hz;
        let parts = [
            format!("{} discrete model: {}", ["x", "y"][d.axis], dm.method.name()),
            format!("(advance {} samples, {} FIR taps,", dm.advance, dm.fir.len()),
            format!("LS condition {:.1e}{tail});", fd.condition),
            format!("match {:.3} % over {lo:.0}-{hi:.0} Hz", 100.0 * d.model_match),
        ];
        want.push(parts.join(" "));
        want.extend(d.notes.iter().map(|n| format!("note: {n}")));
    }
    for (d, s) in designs.iter().zip(&sens) {
        let s = s.as_ref().expect("a sensitivity for every axis");
        want.push(dynocomp::design::sensitivity::summary_line(["x", "y"][d.axis], s));
    }
    want.push(
        "flat band: |H·Ĝ| within ±5 % and ±5° of the pure 4-sample delay (fitted model Ĝ); noise: white-noise gain; \
         pred.: predicted in-band RMS error for a flat force spectrum; raw: the same for no compensation; match: max \
         |Ĝ_d/Ĝ − 1| of the discrete model over the compensated band"
            .into(),
    );
    let fold = |s: &str| s.split_whitespace().collect::<Vec<_>>().join(" ");
    let got: Vec<String> = lines.iter().map(|l| fold(l)).collect();
    let want: Vec<String> = want.iter().map(|l| fold(l)).collect();
    assert_eq!(got, want, "summary:\n{text}");
}
