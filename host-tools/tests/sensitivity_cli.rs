//! Issue #15, item 1 through the binary on the bundled example: `design`
//! states the sensitivity to moving sensor modes in the text summary
//! (±1 %, ±3 % and the advice) and every point in `--json`.

use crate::cli_common;
use cli_common::{dynocomp, example};

#[test]
fn design_states_sensitivity_in_text_and_json() {
    let (frf, idle) = (example("frf.uff"), example("idle.csv"));
    let img = cli_common::tmp("sensitivity-cli", "ex.dcimg");
    let img = img.to_str().unwrap();
    let base = ["design", "--frf", &frf, "--fs", "51200", "--idle", &idle, "--out", img];
    let (ok, out, err) = dynocomp(&base);
    assert!(ok, "{err}");
    for axis in ["x", "y", "z"] {
        let line = out
            .lines()
            .find(|l| l.starts_with(&format!("{axis} sensor modes moved")))
            .unwrap_or_else(|| panic!("no sensitivity line for {axis}:\n{out}"));
        assert!(
            line.contains("at −3 / −1 / 0 / +1 / +3 %")
                && line.contains("re-measure the FRF when the sensor modes may have moved by more than"),
            "{line}"
        );
    }
    let mut a = base.to_vec();
    a.push("--json");
    let (ok, out, err) = dynocomp(&a);
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    for ax in j["axes"].as_array().unwrap() {
        let s = &ax["sensitivity"];
        let pts = s["points"].as_array().unwrap();
        assert_eq!(pts.len(), dynocomp::design::sensitivity::SHIFTS_PCT.len(), "{s}");
        let at = |p: f64| pts.iter().find(|v| (v[0].as_f64().unwrap() - p).abs() < 1e-9).unwrap()[1].as_f64().unwrap();
        // The unshifted point is the design's predicted error; shifts only make it worse.
        assert!((at(0.0) - ax["predicted_error"].as_f64().unwrap()).abs() < 1e-12, "{ax}");
        for p in [-3.0, -1.0, 1.0, 3.0] {
            assert!(at(p) > at(0.0), "{p}: {s}");
        }
        assert!(at(3.0) > at(1.0) && at(-3.0) > at(-1.0), "{s}");
        let x = s["doubles_above_pct"].as_f64().unwrap();
        assert!(x > 0.0 && x < 5.0, "{s}");
        assert!(!s["sensor_modes_hz"].as_array().unwrap().is_empty());
    }
}
