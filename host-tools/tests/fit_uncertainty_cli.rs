//! Issue #30, item 3 (honest predictions), through the binary on the
//! bundled example: `design` states the fitted model's own uncertainty
//! (`fit::refine::frf_variance`, checked against the spread of the fit
//! over impact tests in its unit test) and the predicted error with it, in
//! the text summary and in `--json`.

use crate::cli_common;
use cli_common::{design, example};

#[test]
fn design_states_the_fit_uncertainty_in_text_and_json() {
    let img = cli_common::tmp("fit-uncertainty-cli", "ex.dcimg");
    let run = |extra: &[&str]| {
        let (ok, out, err) = design(&example("frf.uff"), &example("idle.csv"), "51200", img.to_str().unwrap(), extra);
        assert!(ok, "{err}");
        out
    };
    let out = run(&[]);
    let line = out
        .lines()
        .find(|l| l.starts_with("fit uncertainty"))
        .unwrap_or_else(|| panic!("no fit uncertainty line:\n{out}"));
    for axis in ["x ", "y ", "z "] {
        assert!(line.contains(axis), "{line}");
    }
    let j: serde_json::Value = serde_json::from_str(&run(&["--json"])).unwrap();
    for ax in j["axes"].as_array().unwrap() {
        let fit = ax["fit_uncertainty"].as_f64().unwrap_or_else(|| panic!("{ax}"));
        let pred = ax["predicted_error"].as_f64().unwrap();
        let with = ax["predicted_error_with_fit"].as_f64().unwrap();
        // 4097 lines: the fit is known to a fraction of the
        // predicted error, not to nothing.
        assert!(fit > 1e-4 && fit < pred, "{ax}");
        assert!((with - pred.hypot(fit)).abs() < 1e-12, "{ax}");
    }
}
