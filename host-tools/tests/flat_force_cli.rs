//! `simulate --flat-force N` makes the force `design`'s predicted error is
//! for, so a user can check a prediction end to end: on it, the prediction
//! with the fit's uncertainty (`--json`'s `predicted_error_with_fit`) is
//! within 0.67-1.5x of what `compensate --truth` measures, on every axis.
//! The negative control is the same image on the same dynamometer's milling
//! cut (the same seed, so the same impact test and image): its force is not
//! the assumed one, and z measures more than 1.5 times its prediction.

use crate::cli_common;
use cli_common::{compensated_nrmse, dynocomp, tmp};

#[test]
fn the_prediction_holds_on_the_flat_force_it_is_for() {
    let dir = tmp("flat-force", "cli");
    std::fs::create_dir_all(&dir).unwrap();
    let p = |n: &str| dir.join(n).display().to_string();
    let sim = |out: &str, extra: &[&str]| {
        let mut a =
            vec!["simulate", "--dyno", "diagonal", "--out", out, "--fs", "25600", "--duration", "0.5", "--seed", "1"];
        a.extend(extra);
        let (ok, _, err) = dynocomp(&a);
        assert!(ok, "{err}");
        err
    };
    // An RMS that is not a force is refused by name, and nothing is written.
    for bad in ["-5", "nan", "0"] {
        let (ok, _, err) = dynocomp(&["simulate", "--out", &p("bad"), "--flat-force", bad]);
        assert!(!ok && err.contains("--flat-force") && err.contains("must be finite and > 0"), "{bad}: {err}");
        assert!(!dir.join("bad").exists(), "{bad}: wrote output");
    }
    let err = sim(&p("flat"), &["--flat-force", "100", "--adc-range", "32000", "--adc-bits", "20"]);
    assert!(err.contains("flat force: 100 N RMS per axis, flat spectrum 10-4000 Hz"), "{err}");
    sim(&p("cut"), &[]);
    // truth.json names the force, and gives a cut's frequencies only to a cut.
    let truth = |rec: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(rec).join("truth.json")).unwrap()).unwrap()
    };
    let (flat, cut) = (truth("flat"), truth("cut"));
    assert_eq!(flat["force"], "flat noise");
    assert!(flat.get("tooth_passing_hz").is_none() && flat.get("spindle_hz").is_none(), "{flat}");
    assert_eq!(cut["force"], "milling");
    assert!(cut["tooth_passing_hz"].as_f64().is_some_and(|f| f > 0.0), "{cut}");
    let (ok, json, err) = dynocomp(&[
        "design",
        "--frf",
        &p("flat/frf.uff"),
        "--fs",
        "25600",
        "--idle",
        &p("flat/idle.csv"),
        "--out",
        &p("c.dcimg"),
        "--json",
    ]);
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&json).unwrap();
    let predicted: Vec<f64> =
        (0..3).map(|i| j["axes"][i]["predicted_error_with_fit"].as_f64().expect("a prediction per axis")).collect();
    let measured = |rec: &str| {
        let (ok, _, err) = dynocomp(&[
            "compensate",
            "--coeffs",
            &p("c.dcimg"),
            "--input",
            &p(&format!("{rec}/measured.csv")),
            "--truth",
            &p(&format!("{rec}/true_force.csv")),
            "--output",
            &p(&format!("{rec}/out.csv")),
        ]);
        assert!(ok && !err.contains("clipped"), "{err}");
        let m = compensated_nrmse(&err);
        [0, 1, 2].map(|i| predicted[i] / m[i])
    };
    let on_flat = measured("flat");
    eprintln!("predicted / measured, flat force: {on_flat:.2?}");
    assert!(on_flat.iter().all(|r| (0.67..=1.5).contains(r)), "{on_flat:?}");
    let on_cut = measured("cut");
    eprintln!("predicted / measured, milling cut: {on_cut:.2?}");
    assert!(on_cut[2] < 0.67, "{on_cut:?}");
}
