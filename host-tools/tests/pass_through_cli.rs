//! An axis that cannot be compensated is passed through raw (#34): on the
//! bundled example with axis z's FRF ten times too large (a wrong
//! calibration on that channel, static gain 10 N/N), `design` writes the
//! image with x and y compensated and z passed through, and says so loudly
//! in the summary, on stderr, in `--json`, the report and the sidecar;
//! `compensate` (box filter and `--offline`) outputs the measured fz
//! unchanged. `--strict` refuses the image with the reason, and writes
//! nothing. Control: the intact FRF passes no axis through.

use crate::cli_common;

use cli_common::{dynocomp, example, tmp};
use dynocomp::io::signal_csv::read_signal_csv;

/// The example's FRF CSV with axis z's FRF scaled by `k`.
fn frf_with_z_scaled(path: &std::path::Path, k: f64) {
    let text = std::fs::read_to_string(example("frf.csv")).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let cols: Vec<&str> = header.split(',').collect();
    let scaled: Vec<bool> = cols.iter().map(|c| *c == "z_re" || *c == "z_im").collect();
    let mut out = format!("{header}\n");
    for l in lines {
        let v: Vec<String> = l
            .split(',')
            .zip(&scaled)
            .map(|(x, s)| if *s { format!("{}", x.parse::<f64>().unwrap() * k) } else { x.to_string() })
            .collect();
        out.push_str(&v.join(","));
        out.push('\n');
    }
    std::fs::write(path, out).unwrap();
}

fn column(path: &std::path::Path, axis: usize) -> Vec<f64> {
    read_signal_csv(path).unwrap().channel(axis).unwrap().to_vec()
}

#[test]
fn an_axis_that_cannot_be_compensated_is_passed_through_raw() {
    let p = |n: &str| tmp("pass-through", n);
    let frf = p("frf_z10.csv");
    frf_with_z_scaled(&frf, 10.0);
    let idle = example("idle.csv");
    let design = |out: &str, extra: &[&str]| {
        let mut a = vec!["design", "--frf", frf.to_str().unwrap(), "--fs", "51200", "--idle", &idle];
        let o = p(out);
        a.extend(["--out", o.to_str().unwrap()]);
        a.extend(extra);
        let r = dynocomp(&a);
        (r, o)
    };
    // --strict: refused with the axis and the reason, nothing written.
    let ((ok, _, err), strict) = design("strict.dcimg", &["--strict"]);
    assert!(!ok && err.contains("axis z") && err.contains("static gain"), "{err}");
    assert!(!strict.exists(), "--strict left an image");
    // Default: written, z passed through, loudly.
    let report = p("report");
    let ((ok, out, err), image) = design("c.dcimg", &["--report", report.to_str().unwrap()]);
    assert!(ok && image.exists(), "{err}");
    assert!(err.contains("WARNING: axis z is NOT COMPENSATED") && err.contains("static gain"), "{err}");
    assert!(out.contains("WARNING: axis z is NOT COMPENSATED"), "{out}");
    assert!(!out.contains("axis x is NOT") && !out.contains("axis y is NOT"), "{out}");
    let (ok, inspect, err) = dynocomp(&["inspect", image.to_str().unwrap()]);
    assert!(ok && inspect.contains("axis z: NOT COMPENSATED") && !inspect.contains("axis x: NOT"), "{inspect}{err}");
    let index = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(index.contains("NOT COMPENSATED, passed through raw"), "report");
    // The FRF figure of z says so in its title, and no figure shows a fit
    // error or band of the model z does not have.
    let svgs: Vec<String> = std::fs::read_dir(&report)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "svg"))
        .map(|p| std::fs::read_to_string(p).unwrap())
        .collect();
    assert!(svgs.iter().any(|s| s.contains("Axis z — NOT COMPENSATED")), "no FRF figure of z says it");
    assert!(
        svgs.iter().all(|s| !s.contains("NaN") && !s.contains("coherent band 0–0 Hz")),
        "a figure shows NaN or 0–0 Hz"
    );
    assert!(svgs.iter().any(|s| s.contains("Axis x — measured FRF and fitted model")), "control: x's title");
    let ((ok, json, err), _) = design("j.dcimg", &["--json"]);
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&json).unwrap();
    let passed: Vec<bool> = (0..3).map(|i| !j["axes"][i]["passed_through_raw"].is_null()).collect();
    assert_eq!(passed, [false, false, true], "{json}");
    // compensate: fz is the measured force, fx is compensated.
    let measured = example("measured.csv");
    let run = |extra: &[&str], out: &str| {
        let o = p(out);
        let mut a = vec!["compensate", "--coeffs", image.to_str().unwrap(), "--input", &measured];
        a.extend(["--output", o.to_str().unwrap()]);
        a.extend(extra);
        let (ok, _, err) = dynocomp(&a);
        assert!(ok, "{err}");
        (o, err)
    };
    let raw_z = column(std::path::Path::new(&measured), 2);
    let raw_x = column(std::path::Path::new(&measured), 0);
    for (extra, name) in [(&[][..], "box.csv"), (&["--offline"][..], "offline.csv")] {
        let (o, err) = run(extra, name);
        let (z, x) = (column(&o, 2), column(&o, 0));
        // The box path predicts the last L samples (look-ahead): all others exact.
        let n = z.len() - 8;
        let worst = (0..n).map(|k| (z[k] - raw_z[k]).abs()).fold(0.0, f64::max);
        let scale = raw_z.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(worst <= 1e-6 * scale, "{name}: fz differs from the measured force by {worst} N\n{err}");
        let moved = (0..n).map(|k| (x[k] - raw_x[k]).abs()).fold(0.0, f64::max);
        assert!(moved > 0.01 * scale, "control, {name}: fx should be compensated");
    }
    // Control: the intact FRF passes no axis through.
    let ok_image = p("ok.dcimg");
    let (ok, out, err) =
        cli_common::design(&example("frf.csv"), &example("idle.csv"), "51200", ok_image.to_str().unwrap(), &[]);
    assert!(ok && !out.contains("NOT COMPENSATED") && !err.contains("NOT COMPENSATED"), "{out}{err}");
}
