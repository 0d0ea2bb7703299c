//! `dynocomp design --method paper`, the band flags and `dynocomp compare`
//! through the binary, on the bundled example.

use dynocomp::io::image_file::read_image;
use dynocomp_core::image::DesignMethod;
use std::path::PathBuf;

use crate::cli_common;
use cli_common::{dynocomp, example};

fn tmp(name: &str) -> PathBuf {
    cli_common::tmp("paper-cli", name)
}

#[test]
fn paper_method_writes_a_paper_image_with_the_bands_and_diagnostics() {
    let out = tmp("paper.dcimg");
    let frf = example("frf.uff");
    let idle = example("idle.csv");
    let (ok, stdout, stderr) = dynocomp(&[
        "design",
        "--frf",
        &frf,
        "--fs",
        "51200",
        "--idle",
        &idle,
        "--out",
        out.to_str().unwrap(),
        "--method",
        "paper",
        "--paper-orders",
        "2:4",
        "--spindle-rpm",
        "33000",
        "--teeth",
        "4",
        "--harmonics",
        "1",
        "--json",
    ]);
    // (TPF 2.2 kHz, near the sensor modes: at the example's 1.1 kHz TPF the
    // paper's 2:4 fit of axis z is predicted worse than no compensation in
    // its bands, and design refuses it; see `never_worse_than_raw` below.)
    assert!(ok, "{stderr}");
    // The second design, against which the paper's is judged, says so.
    assert!(stderr.contains("designing the default method (vf, whole band, latency 4)"), "{stderr}");
    let img = read_image(&out).unwrap();
    assert_eq!(img.method, DesignMethod::Paper);
    assert_eq!(img.latency_samples, 0);
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(j["method"], "paper");
    let bands = j["bands"].as_array().unwrap();
    assert_eq!(bands.len(), 2, "static band and the TPF band: {bands:?}");
    assert!(bands.iter().any(|b| b["lo_hz"].as_f64().unwrap() <= 2200.0 && b["hi_hz"].as_f64().unwrap() >= 2200.0));
    for a in j["axes"].as_array().unwrap() {
        let p = &a["paper"];
        assert_eq!(p["observability_rank"], p["observability_dim"], "{p}");
        assert_eq!(p["prewarp_hz"].as_f64().unwrap(), 2200.0, "the TPF is the default prewarp frequency");
        assert!(a["predicted_error"].as_f64().unwrap() < a["raw_predicted_error"].as_f64().unwrap());
        assert!(p["care_residual"].as_f64().unwrap() < 1e-8);
        assert_eq!(a["model_order"], 4);
    }
}

#[test]
fn bad_paper_and_band_flags_fail_with_one_line_and_write_nothing() {
    let frf = example("frf.uff");
    let idle = example("idle.csv");
    for (extra, expect) in [
        (vec!["--method", "paper", "--latency", "4"], "--latency 4"),
        (vec!["--method", "paper", "--paper-orders", "8:6"], "--paper-orders `8:6`"),
        (vec!["--band", "5000:6000"], "5000.0..6000.0 Hz: starts above the usable band"),
        (vec!["--band", "800-1200"], "--band `800-1200`: expected LO:HI"),
        (vec!["--method", "paper", "--prewarp-hz", "30000"], "--prewarp-hz 30000"),
    ] {
        let out = tmp("bad.dcimg");
        let _ = std::fs::remove_file(&out);
        let mut args = vec!["design", "--frf", &frf, "--fs", "51200", "--idle", &idle, "--out", out.to_str().unwrap()];
        args.extend(extra.iter().copied());
        let (ok, _, stderr) = dynocomp(&args);
        assert!(!ok, "{extra:?} must fail");
        assert!(stderr.contains(expect), "{extra:?}: expected `{expect}` in: {stderr}");
        assert_eq!(stderr.lines().filter(|l| l.starts_with("error:")).count(), 1, "{stderr}");
        assert!(!out.exists(), "{extra:?} left an output file");
    }
}

#[test]
fn compare_reports_every_method_per_axis_and_failures_as_rows() {
    let dir = tmp("compare");
    let (ok, stdout, stderr) = dynocomp(&[
        "compare",
        "--frf",
        &example("frf.uff"),
        "--fs",
        "51200",
        "--idle",
        &example("idle.csv"),
        "--spindle-rpm",
        "16500",
        "--teeth",
        "4",
        "--harmonics",
        "3",
        "--out-dir",
        dir.to_str().unwrap(),
        "--json",
    ]);
    assert!(ok, "{stderr}");
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let axes = j["axes"].as_array().unwrap();
    assert_eq!(axes.len(), 3);
    for ax in axes {
        let rows = ax["rows"].as_array().unwrap();
        let names: Vec<&str> = rows.iter().map(|r| r["method"].as_str().unwrap()).collect();
        assert_eq!(
            names,
            [
                "paper, whole band",
                "paper, band-fitted",
                "paper, parallel",
                "default (vf), whole band",
                "default (vf), band-weighted"
            ]
        );
        for r in rows {
            // a row either has a diagnostic or all its figures
            match r["diagnostic"].as_str() {
                Some(d) => assert!(!d.is_empty() && r["order"].is_null()),
                None => {
                    assert!(r["order"].as_u64().unwrap() > 0);
                    assert!(r["compensated_error_in_band"].as_f64().unwrap().is_finite());
                    assert!(r["noise_gain"].as_f64().unwrap() <= 30.0 + 1e-9);
                }
            }
        }
        // the default method designs on every axis of the example
        assert!(rows[3]["diagnostic"].is_null(), "{}", rows[3]);
        let name = ax["axis"].as_str().unwrap();
        // Progress: every method of the table said when it started and how
        // it ended, as the table has it (verified, or failed with a diagnostic).
        for r in rows {
            let m = r["method"].as_str().unwrap();
            if m == "paper, band-fitted" && r["design_time_s"].as_f64() == Some(0.0) {
                continue; // refused before any design (no bands)
            }
            let outcome = if r["diagnostic"].is_null() { "verified" } else { "failed" };
            assert!(stderr.contains(&format!("axis {name}: {m}…")), "{name}: no start line for `{m}`:\n{stderr}");
            let end = format!("axis {name}: {m}: {outcome} in ");
            assert!(stderr.contains(&end), "{name}: no `{end}` line:\n{stderr}");
        }
        assert!(stderr.contains(&format!("axis {name}: probing ")), "{name}: the order search said nothing");
        let svg = std::fs::read_to_string(dir.join(format!("{name}_compare.svg"))).unwrap();
        assert!(svg.contains("<svg") && svg.contains("fitting bands"));
        // Every method is in the plot's key, a failed one marked as such.
        for r in rows {
            let m = r["method"].as_str().unwrap();
            let shown = if r["diagnostic"].is_null() { m.to_string() } else { format!("{m}: FAILED") };
            assert!(svg.contains(&shown), "{name}: `{shown}` missing from the plot's key");
        }
    }
    // Failure rows of the table stay short; compare.json has the message.
    let table = std::fs::read_to_string(dir.join("compare.txt")).unwrap();
    for l in table.lines().filter(|l| l.contains("FAILED")) {
        assert!(l.chars().count() < 200, "failure row too long: {l}");
    }
    assert!(dir.join("compare.json").exists() && dir.join("compare.txt").exists());
}

#[test]
fn never_worse_than_raw_a_paper_design_predicted_worse_is_refused_and_nothing_written() {
    // The example's axis z with the paper's 2:4 orders around the 1.1 kHz
    // TPF: predicted 5.3 % in its bands against 3.0 % uncompensated.
    let out = tmp("worse.dcimg");
    let _ = std::fs::remove_file(&out);
    let (ok, _, stderr) = dynocomp(&[
        "design",
        "--frf",
        &example("frf.uff"),
        "--fs",
        "51200",
        "--idle",
        &example("idle.csv"),
        "--out",
        out.to_str().unwrap(),
        "--method",
        "paper",
        "--paper-orders",
        "2:4",
        "--spindle-rpm",
        "16500",
        "--teeth",
        "4",
        "--harmonics",
        "1",
    ]);
    assert!(!ok, "a design worse than raw was written");
    assert!(
        stderr.contains("axis z") && stderr.contains("worse than no compensation") && stderr.contains("uncompensated"),
        "{stderr}"
    );
    assert!(
        stderr.contains("--paper-orders") && stderr.contains("--method vf"),
        "the message says what to try: {stderr}"
    );
    assert!(!out.exists(), "an image was left behind");
    // Positive control: the default method on the whole band writes it.
    // With these bands the default method's fit takes an order flat below
    // the first coherent line (the plain choice is 9 % off at 0 Hz on axis
    // x, `design::MAX_STATIC_ERROR`), and every band-fitted axis predicts
    // more error than the default design: the image carries the default
    // design on every axis, and says so.
    let (ok, _, stderr) = dynocomp(&[
        "design",
        "--frf",
        &example("frf.uff"),
        "--fs",
        "51200",
        "--idle",
        &example("idle.csv"),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok && out.exists(), "{stderr}");
    let (ok, _, stderr) = dynocomp(&[
        "design",
        "--frf",
        &example("frf.uff"),
        "--fs",
        "51200",
        "--idle",
        &example("idle.csv"),
        "--out",
        out.to_str().unwrap(),
        "--spindle-rpm",
        "16500",
        "--teeth",
        "4",
        "--harmonics",
        "1",
    ]);
    assert!(ok && out.exists(), "{stderr}");
    assert_eq!(stderr.matches("the image carries the default design for this axis").count(), 3, "{stderr}");
}

#[test]
fn paper_orders_are_chosen_per_axis_with_the_reason_and_forced_orders_still_hold() {
    // The paper's Table 2 test 2 (TPF 277 Hz) on its 9257A-like set-up: at the
    // paper's 6:8 one axis's fit is too far from the FRF (or, on other
    // set-ups, the augmented system is not observable in floating point);
    // without --paper-orders every axis gets orders that work, and says why.
    let dir = tmp("preset-cut-2");
    let d = dir.to_str().unwrap();
    let (ok, _, stderr) =
        dynocomp(&["simulate", "--preset", "cut-2", "--duration", "0.1", "--idle-duration", "0.2", "--out", d]);
    assert!(ok, "{stderr}");
    assert!(stderr.contains("--spindle-rpm 4150 --teeth 4"), "simulate says how to design it: {stderr}");
    let frf = dir.join("frf.uff");
    let idle = dir.join("idle.csv");
    let out = dir.join("paper.dcimg");
    let args = |extra: &[&str]| -> Vec<String> {
        let mut v: Vec<String> = [
            "design",
            "--frf",
            frf.to_str().unwrap(),
            "--idle",
            idle.to_str().unwrap(),
            "--fs",
            "51200",
            "--method",
            "paper",
            "--spindle-rpm",
            "4150",
            "--teeth",
            "4",
            "--out",
            out.to_str().unwrap(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        v.extend(extra.iter().map(|s| s.to_string()));
        v
    };
    let run = |v: Vec<String>| dynocomp(&v.iter().map(String::as_str).collect::<Vec<_>>());
    let _ = std::fs::remove_file(&out);
    let (ok, stdout, stderr) = run(args(&["--paper-orders", "6:8"]));
    assert!(!ok && !out.exists(), "the paper's fixed 6:8 should fail here (the issue's finding): {stdout}");
    assert!(stderr.contains("not observable") || stderr.contains("above the limit of 15 %"), "{stderr}");
    let (ok, stdout, stderr) = run(args(&[]));
    assert!(ok && out.exists(), "{stderr}");
    for axis in ["x", "y", "z"] {
        assert!(
            stdout.contains(&format!("axis {axis}: paper orders")) && stdout.contains("chosen automatically"),
            "{stdout}"
        );
    }
}

#[test]
fn a_fit_beyond_the_fit_error_limit_is_refused_whatever_it_predicts() {
    // Orders far too low for the example's 0-4 kHz FRF: the paper's 1:2 fit
    // cannot follow two resonances, and the design stops on the fit error.
    let out = tmp("badfit.dcimg");
    let _ = std::fs::remove_file(&out);
    let (ok, _, stderr) = dynocomp(&[
        "design",
        "--frf",
        &example("frf.uff"),
        "--fs",
        "51200",
        "--idle",
        &example("idle.csv"),
        "--out",
        out.to_str().unwrap(),
        "--method",
        "paper",
        "--paper-orders",
        "1:2",
        "--band",
        "10:3000",
    ]);
    assert!(!ok && !out.exists(), "{stderr}");
    assert!(stderr.contains("from the measured FRF") && stderr.contains("limit of 15 %"), "{stderr}");
    // Positive control: the same band with the orders chosen is written.
    let (ok, _, stderr) = dynocomp(&[
        "design",
        "--frf",
        &example("frf.uff"),
        "--fs",
        "51200",
        "--idle",
        &example("idle.csv"),
        "--out",
        out.to_str().unwrap(),
        "--method",
        "paper",
        "--band",
        "10:3000",
    ]);
    assert!(ok && out.exists(), "{stderr}");
}
