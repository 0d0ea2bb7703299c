//! The declared latency through the binary (`crate::design::latency`): without
//! `--latency` the summary and `--json` say how it was chosen; with it, the
//! given latency is kept and nothing is chosen. The choice itself (a longer
//! latency where the flat band falls short, with its negative control) is
//! tested end to end in `e2e_rates.rs`.

use crate::cli_common;
use cli_common::{dynocomp, example};

#[test]
fn design_states_how_the_latency_was_chosen() {
    let (frf, idle) = (example("frf.uff"), example("idle.csv"));
    let img = cli_common::tmp("latency-cli", "ex.dcimg");
    let img = img.to_str().unwrap();
    let base = ["design", "--frf", &frf, "--fs", "51200", "--idle", &idle, "--out", img, "--json"];
    let (ok, out, err) = dynocomp(&base);
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    // The bundled example is flat to its band's top at 4 samples on every
    // axis, but each axis writes more noise above the band than its in-band
    // error (`latency::ABOVE_BAND_SHORT`): 6 and 8 are designed too, the
    // reason names the noise, and no discrete model is refitted up to
    // Nyquist (nothing fell short in the band).
    let c = &j["latency_choice"];
    assert_eq!(c["tried"].as_array().unwrap().len(), 3, "{c}");
    assert!(c["reason"].as_str().unwrap().contains("of noise above the band, more than its"), "{c}");
    assert_eq!(c["fit_to_nyquist"], serde_json::json!([false, false, false]), "{c}");
    assert_eq!(j["latency_samples"], c["chosen"], "{c}");
    let kept = c["tried"].as_array().unwrap().iter().find(|t| t["latency"] == c["chosen"]).unwrap();
    for (p, ax) in kept["predicted_error"].as_array().unwrap().iter().zip(j["axes"].as_array().unwrap()) {
        assert_eq!(p, &ax["predicted_error"], "{c}");
    }
    // The criterion q is chosen for holds the in-band error and the noise
    // above the band: never below the in-band error.
    for t in c["tried"].as_array().unwrap() {
        for (e, k) in t["predicted_error"].as_array().unwrap().iter().zip(t["predicted_criterion"].as_array().unwrap())
        {
            assert!(k.as_f64().unwrap() >= e.as_f64().unwrap(), "{t}");
        }
    }
    // Control: with the exact inverse above the band (no noise above it in
    // the criterion) 4 is kept after one round.
    let mut inverse = base.to_vec();
    inverse.extend(["--above-band", "inverse"]);
    let (ok, out, err) = dynocomp(&inverse);
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    let c = &j["latency_choice"];
    assert_eq!(j["latency_samples"], 4, "{c}");
    assert_eq!(c["tried"].as_array().unwrap().len(), 1, "{c}");
    assert_eq!(c["reason"], "", "{c}");
    assert_eq!(c["tried"][0]["predicted_error"], c["tried"][0]["predicted_criterion"], "{c}");
    // A given latency is the image's, and nothing is chosen.
    let mut given = base.to_vec();
    given.extend(["--latency", "6"]);
    let (ok, out, err) = dynocomp(&given);
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(j["latency_samples"], 6);
    assert!(j.get("latency_choice").is_none(), "{j}");
}

/// Above the 8 samples the design chooses by itself, the bundled example's
/// compensators do not verify in f32 (measured: x and z from 10 samples, x
/// from 12). The refusal, or the pass-through warning, says so and what to
/// give instead. Control: at 8 every axis is compensated, without the hint.
#[test]
fn a_latency_beyond_the_chosen_ones_that_does_not_verify_says_what_to_do() {
    let (frf, idle) = (example("frf.uff"), example("idle.csv"));
    let img = cli_common::tmp("latency-cli", "long.dcimg");
    let img = img.to_str().unwrap();
    let run = |latency: &str| {
        let _ = std::fs::remove_file(img);
        dynocomp(&["design", "--frf", &frf, "--fs", "51200", "--idle", &idle, "--out", img, "--latency", latency])
    };
    let hint = "above the 8 samples the design chooses by itself, this axis's compensator does not verify in f32; \
                omit --latency or give 8 or less";
    let (ok, _, err) = run("12");
    assert!(!ok && err.contains(&format!("--latency 12: {hint}")), "{err}");
    assert!(!std::path::Path::new(img).exists());
    let (ok, _, err) = run("10");
    assert!(ok && err.contains("axis x is NOT COMPENSATED") && err.contains(&format!("--latency 10: {hint}")), "{err}");
    let (ok, out, err) = run("8");
    assert!(ok && !err.contains("NOT COMPENSATED") && !err.contains(hint), "{err}\n{out}");
}

/// The random sweep's seed 26 (clustered machine modes, 10.24 kHz), written
/// as the simulator's files and designed through the binary for its cut's
/// spectrum: the summary says what a look-ahead past the box's would reach
/// on x, and `--json` carries it (`latency_choice.look_ahead`; the figures
/// against the truth are in `sweep_cases.rs`), and the report draws it.
/// Control: the same design for a flat force says nothing of longer
/// look-aheads.
#[test]
fn a_cut_the_box_cannot_follow_gets_the_look_ahead_it_would_need() {
    use dynocomp::simulate::{files::write_outputs, simulate_with};
    let (case, fs, kind) = dynocomp::eval::sweep::draw(26);
    assert_eq!((kind, fs), ("machine-cluster", 10_240.0), "the sweep's seed 26 changed");
    let params = case.sim_params(fs);
    let sim = simulate_with(case.seed, &params, case.dynamometer(&params).unwrap()).unwrap();
    let dir = cli_common::tmp("latency-cli", "seed26");
    std::fs::create_dir_all(&dir).unwrap();
    write_outputs(&dir, &sim).unwrap();
    let file = |n: &str| dir.join(n).to_str().unwrap().to_string();
    let (frf, idle, rec, img) = (file("frf.uff"), file("idle.csv"), file("measured.csv"), file("c.dcimg"));
    let base = ["design", "--frf", &frf, "--fs", "10240", "--idle", &idle, "--out", &img];
    let cut = [&base[..], &["--force-prior", "spectrum", "--force-record", &rec]].concat();
    let (ok, out, err) = dynocomp(&cut);
    assert!(ok, "{err}");
    let line = out
        .lines()
        .chain(err.lines())
        .find(|l| l.starts_with("axis x: the box filter (latency"))
        .unwrap_or_else(|| panic!("no look-ahead line:\n{out}\n{err}"));
    assert!(
        line.contains("would predict") && line.contains("is 32 samples (3.12 ms), past the 8 the box runs"),
        "{line}"
    );
    // The report draws it (x only).
    let report = file("report");
    let (ok, _, err) = dynocomp(&[&cut[..], &["--report", &report]].concat());
    assert!(ok, "{err}");
    let svg = std::fs::read_to_string(dir.join("report/x_look_ahead.svg")).unwrap();
    assert!(svg.contains("predicted error against look-ahead"), "x_look_ahead.svg");
    assert!(!dir.join("report/y_look_ahead.svg").exists(), "control: y has no look-ahead figure");
    let index = std::fs::read_to_string(dir.join("report/index.html")).unwrap();
    assert!(index.contains("x_look_ahead.svg") && index.contains("is 32 samples (3.12 ms)"), "index.html");
    let (ok, out, err) = dynocomp(&[&cut[..], &["--json"]].concat());
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    let l = &j["latency_choice"]["look_ahead"];
    assert_eq!(l.as_array().map(Vec::len), Some(1), "{l}");
    assert_eq!(l[0]["axis"], 0, "{l}");
    assert_eq!(l[0]["tried"][1][0], 32, "{l}");
    // Control: a flat force.
    let (ok, out, err) = dynocomp(&base);
    assert!(ok, "{err}");
    assert!(!out.contains("longer look-ahead") && !err.contains("longer look-ahead"), "{out}\n{err}");
}
