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
    // axis: 4 is kept and no longer latency is designed.
    assert_eq!(j["latency_samples"], 4, "{}", j["latency_choice"]);
    let c = &j["latency_choice"];
    assert_eq!(c["chosen"], 4, "{c}");
    assert_eq!(c["tried"].as_array().unwrap().len(), 1, "{c}");
    assert_eq!(c["reason"], "", "{c}");
    // Nothing fell short, so no discrete model was refitted up to Nyquist.
    assert_eq!(c["fit_to_nyquist"], serde_json::json!([false, false, false]), "{c}");
    let pred = c["tried"][0]["predicted_error"].as_array().unwrap();
    for (p, ax) in pred.iter().zip(j["axes"].as_array().unwrap()) {
        assert_eq!(p, &ax["predicted_error"], "{c}");
    }
    // A given latency is the image's, and nothing is chosen.
    let mut given = base.to_vec();
    given.extend(["--latency", "6"]);
    let (ok, out, err) = dynocomp(&given);
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(j["latency_samples"], 6);
    assert!(j.get("latency_choice").is_none(), "{j}");
}
