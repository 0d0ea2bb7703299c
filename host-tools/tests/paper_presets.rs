//! Issue #13: the seed paper's experiments (simulator presets on its
//! 9257A-like set-up) through the paper's method with band-fitting and
//! automatic orders, scored against the simulator's true force in the
//! DESIGN.md convention (NRMSE = RMS error / std of the truth), restricted to
//! the fitting bands as the paper's claims are.
//!
//! Target (issue #13): on every preset and axis, an image is written with
//! no flags beyond the preset's band flags, and the compensated error in the
//! bands is below the raw error there.

use std::cmp::Ordering;

use dynocomp::eval::reproduce::{evaluate, preset_bands, simulate_preset, Method};
use dynocomp::metrics::accuracy_in_bands;
use dynocomp::simulate::presets::{preset, NAMES};

/// Records long enough for ≥ 20 tooth periods at TPF 83 Hz and the whole
/// sweep of a chirp (its rate follows the record length), short enough for CI.
fn duration(name: &str) -> f64 {
    if name.starts_with("cut") {
        0.25
    } else {
        0.3
    }
}

#[test]
fn every_preset_paper_method_with_band_fitting_beats_raw_in_the_bands_on_every_axis() {
    let mut failures = Vec::new();
    for name in NAMES {
        let p = preset(name).unwrap();
        let s = simulate_preset(&p, 1, Some(duration(name))).unwrap();
        let bands = preset_bands(&p, &s.frf).unwrap();
        for o in evaluate(&s, &bands, &Method::PaperBandFitted) {
            match &o.result {
                Ok(sc) => {
                    eprintln!(
                        "{name} axis {}: orders {}, fit {:.2} %, in bands raw {:.2} % → compensated {:.2} % (0-4 kHz: {:.2} % → {:.2} %)",
                        o.axis,
                        sc.orders,
                        100.0 * sc.fit_error,
                        100.0 * sc.raw_in_bands,
                        100.0 * sc.comp_in_bands,
                        100.0 * sc.raw_full,
                        100.0 * sc.comp_full
                    );
                    if sc.comp_in_bands.partial_cmp(&sc.raw_in_bands) != Some(Ordering::Less) {
                        failures.push(format!(
                            "{name} axis {}: compensated {:.2} % ≥ raw {:.2} % in the bands",
                            o.axis,
                            100.0 * sc.comp_in_bands,
                            100.0 * sc.raw_in_bands
                        ));
                    }
                }
                Err(e) => failures.push(format!("{name} axis {}: no image: {e}", o.axis)),
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn the_in_band_check_fails_on_a_wrong_estimate_and_the_presets_need_compensation() {
    // Negative control of the check above: the measured force delayed by
    // 10 samples (0.2 ms, 20° at 277 Hz) is an estimate worse than the raw
    // force in the bands, and the check catches it.
    let p = preset("cut-2").unwrap();
    let s = simulate_preset(&p, 1, Some(0.25)).unwrap();
    let bands = preset_bands(&p, &s.frf).unwrap();
    let ranges: Vec<(f64, f64)> = bands.iter().map(|b| (b.lo_hz, b.hi_hz)).collect();
    let fs = s.params.fs_hz;
    for a in 0..3 {
        let raw = accuracy_in_bands(&s.measured[a], &s.truth[a], fs, &ranges).nrmse;
        let mut late = vec![s.measured[a][0]; 10];
        late.extend_from_slice(&s.measured[a][..s.measured[a].len() - 10]);
        let wrong = accuracy_in_bands(&late, &s.truth[a], fs, &ranges).nrmse;
        assert!(
            wrong.partial_cmp(&raw) != Some(Ordering::Less),
            "axis {a}: a delayed raw force ({:.2} %) passed as better than raw ({:.2} %)",
            100.0 * wrong,
            100.0 * raw
        );
        // At TPF 277 Hz the raw force is visibly off in the bands (the paper's
        // "more relevant distortions at higher TPF"), so beating it means something.
        assert!(raw > 0.03, "axis {a}: raw in-band error only {:.2} %", 100.0 * raw);
    }
}
