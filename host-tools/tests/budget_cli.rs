//! The box's CPU budget through the binary on the bundled example
//! (issue #16): `design` prints the predicted load and keeps the default
//! 60 % limit; with a limit the design cannot meet it still writes the image,
//! marks it offline-only and says so loudly; `inspect` shows the load (text
//! and JSON); `flash` refuses the offline-only image before touching a probe.

use crate::cli_common;
use cli_common::{dynocomp, example};

fn tmp(name: &str) -> std::path::PathBuf {
    cli_common::tmp("budget-cli", name)
}

fn inspect_json(img: &str) -> serde_json::Value {
    let (ok, out, err) = dynocomp(&["inspect", img, "--json"]);
    assert!(ok, "{err}");
    serde_json::from_str(&out).unwrap()
}

#[test]
fn over_the_load_limit_the_image_is_offline_only_and_flash_refuses_it() {
    let (frf, idle) = (example("frf.uff"), example("idle.csv"));
    let design = |img: &str, extra: &[&str]| {
        let mut a = vec!["design", "--frf", &frf, "--fs", "51200", "--idle", &idle, "--out", img];
        a.extend_from_slice(extra);
        dynocomp(&a)
    };

    // Default limit (60 %): fits, runs in the box, the load is printed.
    let ok_img = tmp("fits.dcimg");
    let ok_img = ok_img.to_str().unwrap();
    let (ok, out, err) = design(ok_img, &[]);
    assert!(ok, "{err}");
    assert!(out.contains("box CPU load at 51200 Hz:") && !out.contains("OVER THE LIMIT"), "{out}");
    let j = inspect_json(ok_img);
    assert_eq!(j["offline_only"], false);
    assert_eq!(j["runs_in_box"], true);
    assert_eq!(j["box_load"]["fits"], true);
    let pct = j["box_load"]["load_pct"][1].as_f64().unwrap();
    assert!(pct > 0.0 && pct <= 60.0, "{j}");
    let (ok, out, _) = dynocomp(&["inspect", ok_img]);
    assert!(ok && out.contains("box CPU load at 51200 Hz:"), "{out}");

    // A 20 % limit: the interrupt's fixed part and three axis calls alone
    // are predicted above it, so no realization fits.
    let heavy = tmp("heavy.dcimg");
    let heavy = heavy.to_str().unwrap();
    let (ok, out, err) = design(heavy, &["--max-load", "20"]);
    assert!(ok, "{err}");
    assert!(
        err.contains("OFFLINE-ONLY IMAGE") && err.contains("exceeds the limit of 20 %") && err.contains("run it up to"),
        "{err}"
    );
    assert!(out.contains("OVER THE LIMIT: offline-only image"), "{out}");
    let j = inspect_json(heavy);
    assert_eq!(j["offline_only"], true);
    assert_eq!(j["runs_in_box"], false);
    // inspect states the load against the box's own 60 %; it is above the
    // declared 20 %.
    assert!(j["box_load"]["load_pct"][1].as_f64().unwrap() > 20.0, "{j}");
    let (ok, _, err) = dynocomp(&["flash", heavy, "--probe", "--dry-run"]);
    assert!(!ok);
    assert!(
        err.contains("heavy.dcimg") && err.contains("offline-only image") && err.trim().lines().count() == 1,
        "{err}"
    );

    // A limit above the box's own is refused, and nothing is written.
    let none = tmp("none.dcimg");
    let (ok, _, err) = design(none.to_str().unwrap(), &["--max-load", "75"]);
    assert!(!ok && err.contains("--max-load 75") && err.trim().lines().count() == 1, "{err}");
    assert!(!none.exists());
}
