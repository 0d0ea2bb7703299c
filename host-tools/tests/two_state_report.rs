//! What a two-state design tells its reader, through the binary: the summary
//! table leads with the error to expect over the range (the worst case, as
//! recomputed here from the `--json` candidates), and the report's FRF plot
//! judges each measured FRF against the model at its own state (misfits
//! recomputed here from the sidecar's two states and the FRF files).

use crate::cli_common;
use cli_common::dynocomp;
use dynocomp::offline::sidecar::ModelSidecar;

/// The error a reader sees first in the summary table for `axis`: the value
/// under the first of the `worst*` / `pred.` headers (right-aligned columns:
/// the header and the value end in the same character column).
fn first_error_column(summary: &str, axis: &str) -> Option<f64> {
    let lines: Vec<Vec<char>> = summary.lines().map(|l| l.chars().collect()).collect();
    let header = lines.iter().find(|l| l.starts_with(&['a', 'x', 'i', 's']))?;
    let h: String = header.iter().collect();
    let at = ["worst*", "pred."].iter().filter_map(|k| h.find(k).map(|i| (i, k.len()))).min()?;
    let end = h[..at.0].chars().count() + at.1;
    let row = lines.iter().find(|l| l.iter().collect::<String>().starts_with(&format!("{axis} ")))?;
    let start = row[..end].iter().rposition(|c| c.is_whitespace())? + 1;
    row[start..end].iter().collect::<String>().trim_end_matches('%').parse().ok()
}

/// Whether every axis's first error column shows `expected[axis]` (%, two decimals).
fn table_shows(summary: &str, expected: &[(String, f64)]) -> Result<(), String> {
    for (axis, pct) in expected {
        let shown = first_error_column(summary, axis).ok_or(format!("axis {axis}: no error column"))?;
        if (shown - pct).abs() > 0.0051 {
            return Err(format!("axis {axis}: table shows {shown} %, the worst case over the range is {pct:.3} %"));
        }
    }
    Ok(())
}

#[test]
fn two_state_summary_and_frf_plot_show_what_to_expect() {
    let dir = cli_common::tmp("two-state-report", "sim");
    let d = |f: &str| dir.join(f).to_str().unwrap().to_string();
    let sim = ["simulate", "--seed", "3", "--drift-percent", "4", "--duration", "0.05", "--idle-duration", "0.2"];
    let (ok, _, err) = dynocomp(&[&sim[..], &["--out", &d("")]].concat());
    assert!(ok, "{err}");
    let (frf, after, idle) = (d("frf.uff"), d("frf_after.uff"), d("idle.csv"));
    let two = ["design", "--fs", "51200", "--idle", &idle, "--frf", &frf, "--frf", &after];
    let (img, rep) = (d("two.dcimg"), d("rep"));
    let (ok, text, err) = dynocomp(&[&two[..], &["--out", &img, "--report", &rep]].concat());
    assert!(ok, "{err}");
    let (ok, json, err) = dynocomp(&[&two[..], &["--out", &d("two_json.dcimg"), "--json"]].concat());
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&json).unwrap();

    // The worst case of the chosen candidate, from its errors over the range
    // states and on both measured FRFs.
    let mut expected = Vec::new();
    for ax in j["axes"].as_array().unwrap() {
        let s = ax["chosen_state"].as_f64().unwrap();
        let cands = ax["candidates"].as_array().unwrap();
        let best = cands.iter().position(|c| c[0].as_f64() == Some(s)).unwrap();
        let errors = cands[best][2].as_array().unwrap().iter().map(|e| e.as_f64().unwrap());
        let measured = &ax["measured_frf_errors"][best];
        let worst = errors.chain([measured[0].as_f64().unwrap(), measured[1].as_f64().unwrap()]).fold(0.0, f64::max);
        assert_eq!(ax["expected_error"].as_f64(), Some(worst), "{ax}");
        assert_eq!(ax["worst_case_error"].as_f64(), Some(worst), "existing field kept");
        assert!(ax["predicted_error"].as_f64().unwrap() < worst, "the chosen state alone predicts less");
        expected.push((ax["axis"].as_str().unwrap().to_string(), 100.0 * worst));
    }
    table_shows(&text, &expected).unwrap_or_else(|e| panic!("{e}\n{text}"));
    assert!(text.contains("worst*: predicted in-band RMS error") && text.contains("pred.@s: the same at the image's"));
    let index = std::fs::read_to_string(dir.join("rep/index.html")).unwrap();
    table_shows(&index, &expected).unwrap_or_else(|e| panic!("report: {e}"));
    // Control: a single-state design's table leads with its own prediction,
    // far below what the range costs.
    let (ok, one, err) =
        dynocomp(&["design", "--fs", "51200", "--idle", &idle, "--frf", &frf, "--out", &d("one.dcimg")]);
    assert!(ok, "{err}");
    assert!(table_shows(&one, &expected).is_err(), "control: {one}");

    // The FRF plot: each FRF against the model at its own state.
    let side: ModelSidecar =
        serde_json::from_str(&std::fs::read_to_string(d("two.dcimg.model.json")).unwrap()).unwrap();
    let (b0, b1) = (std::fs::read(&frf).unwrap(), std::fs::read(&after).unwrap());
    let (f0, f1) = (
        dynocomp::io::parse_frf(std::path::Path::new(&frf), &b0).unwrap(),
        dynocomp::io::parse_frf(std::path::Path::new(&after), &b1).unwrap(),
    );
    for (k, axis) in side.axes.iter().enumerate() {
        let name = axis.axis.as_str();
        let ts = axis.two_state.as_ref().unwrap().states("sidecar", name).unwrap();
        let svg = std::fs::read_to_string(dir.join(format!("rep/{name}_frf_fit.svg"))).unwrap();
        for label in
            ["measured G, first FRF", "measured G, second FRF", "model at s = 0", "model at s = 1", "(the image"]
        {
            assert!(svg.contains(label), "{name}: {label}");
        }
        // The coherent band and the two misfits the title states.
        let band_txt = svg.split("coherent band ").nth(1).unwrap().split(" Hz").next().unwrap();
        let (lo, hi) = band_txt.split_once('–').unwrap();
        let band = (lo.parse::<f64>().unwrap(), hi.parse::<f64>().unwrap());
        let title = svg.split("(misfit ").nth(1).unwrap();
        let shown: Vec<f64> =
            title.split(" % in the").next().unwrap().split(" % / ").map(|v| v.parse().unwrap()).collect();
        let misfit = |m: &dynocomp::fit::PoleResidueModel, g: &dynocomp::frf::AxisFrf| {
            let (mut sum, mut n) = (0.0, 0);
            for (f, g) in f0.freq_hz.iter().zip(&g.frf) {
                if *f >= band.0 && *f <= band.1 {
                    sum += ((m.frf(*f) - g).norm() / g.norm()).powi(2);
                    n += 1;
                }
            }
            100.0 * (sum / n as f64).sqrt()
        };
        let (g0, g1) = (&f0.axes[k], &f1.axes[k]);
        let own = [misfit(&ts.at(0.0), g0), misfit(&ts.at(1.0), g1)];
        let crossed = [misfit(&ts.at(1.0), g0), misfit(&ts.at(0.0), g1)];
        eprintln!("axis {name}: misfit shown {shown:?}, own state {own:?}, other state {crossed:?}");
        for i in 0..2 {
            assert!((shown[i] - own[i]).abs() < 0.006, "{name}: FRF {i} drawn against its own state's model");
            // Control: against the other state's model the fit cannot be judged.
            assert!(crossed[i] > 3.0 * own[i], "{name}: the states differ visibly");
        }
    }
}
