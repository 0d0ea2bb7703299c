//! `design`'s stage lines on stderr: each axis as it starts ("axis y
//! (2/3): fitting …"), each candidate latency as its round starts, and each
//! axis as it is designed in a round, with counts that match what was done.

use crate::cli_common;
use cli_common::{dynocomp, example, tmp};

/// The lines of `err` that contain `needle`.
fn lines_with<'a>(err: &'a str, needle: &str) -> Vec<&'a str> {
    err.lines().filter(|l| l.contains(needle)).collect()
}

/// The index of the first line of `err` that contains `needle`.
fn first(err: &str, needle: &str) -> usize {
    err.lines().position(|l| l.contains(needle)).unwrap_or_else(|| panic!("no line with {needle:?}:\n{err}"))
}

const AXES: [&str; 3] = ["axis x (1/3)", "axis y (2/3)", "axis z (3/3)"];

/// `dynocomp design` of the bundled example's FRF at `fs` (Hz) with `more`
/// arguments, into an image named `name`: its stderr (the run must succeed).
fn design(name: &str, fs: &str, more: &[&str]) -> String {
    let (frf, img) = (example("frf.uff"), tmp("design-progress", name));
    let mut args = vec!["design", "--frf", &frf, "--fs", fs, "--out", img.to_str().unwrap()];
    args.extend(more);
    let (ok, _, err) = dynocomp(&args);
    assert!(ok, "{err}");
    err
}

/// The example at 10.24 kHz falls short at latency 4 (its sensor modes sit
/// near Nyquist): latencies 6 and 8 are tried and the discrete models are
/// fitted up to Nyquist; every round reports every axis once. Control: at
/// 51.2 kHz with the exact inverse above the band the default is enough,
/// and only candidate 1 is designed.
#[test]
fn design_reports_each_axis_and_candidate_latency() {
    let err = design("ex10k.dcimg", "10240", &["--noise-variance", "0.05"]);
    for a in AXES {
        assert_eq!(lines_with(&err, &format!("{a}: fitting 4097 FRF lines")).len(), 1, "{a}:\n{err}");
    }
    assert_eq!(lines_with(&err, "(candidate 1 of up to 3)").len(), 1, "{err}");
    let c1 = first(&err, "latency 4 samples (candidate 1 of up to 3): designing 3 axes");
    let c2 = first(&err, "latency 6 samples (candidate 2/3): ");
    let c3 = first(&err, "latency 8 samples (candidate 3/3): ");
    let nyq = first(&err, "latency 8 samples (chosen): fitting the discrete models up to Nyquist");
    assert!(c1 < c2 && c2 < c3 && c3 < nyq, "rounds out of order:\n{err}");
    for a in AXES {
        // Fitted before its first round; designed once per round, in it.
        assert!(first(&err, &format!("{a}: fitting")) < c1, "{a}:\n{err}");
        for (stage, start, end) in [
            ("latency 4: predicted error", c1, c2),
            ("latency 6: predicted error", c2, c3),
            ("latency 8: predicted error", c3, nyq),
            ("latency 8, fitted up to Nyquist: predicted error", nyq, usize::MAX),
        ] {
            let needle = format!("{a} at {stage}");
            assert_eq!(lines_with(&err, &needle).len(), 1, "{needle}:\n{err}");
            let at = first(&err, &needle);
            assert!(start < at && at < end, "{needle} outside its round:\n{err}");
        }
    }

    // Control: the default latency is enough at 51.2 kHz for the exact
    // inverse above the band (the quiet default tries 6 and 8 there for the
    // noise it writes above the band, `tests/latency_cli.rs`).
    let idle = example("idle.csv");
    let err = design("ex.dcimg", "51200", &["--idle", &idle, "--above-band", "inverse"]);
    assert_eq!(lines_with(&err, "(candidate").len(), 1, "{err}");
    assert!(err.contains("(candidate 1 of up to 3)"), "{err}");
    for a in AXES {
        assert_eq!(lines_with(&err, &format!("{a} at latency 4: predicted error")).len(), 1, "{a}:\n{err}");
        assert!(lines_with(&err, &format!("{a} at latency 6")).is_empty(), "{a}:\n{err}");
    }
}

/// A given latency: each axis starts and is designed once, at that latency,
/// and no candidate is tried.
#[test]
fn design_at_a_given_latency_reports_each_axis_once() {
    let idle = example("idle.csv");
    let err = design("given.dcimg", "51200", &["--idle", &idle, "--latency", "6"]);
    assert!(lines_with(&err, "(candidate").is_empty(), "{err}");
    for a in AXES {
        let start = format!("{a}: fitting 4097 FRF lines and designing at latency 6");
        let done = format!("{a} at latency 6: predicted error");
        assert_eq!(lines_with(&err, &start).len(), 1, "{start}:\n{err}");
        assert_eq!(lines_with(&err, &done).len(), 1, "{done}:\n{err}");
        assert!(first(&err, &start) < first(&err, &done), "{a}:\n{err}");
    }
}
