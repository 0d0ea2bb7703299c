//! Issue #15, item 1: the design's predicted error for shifted sensor modes
//! (`dynocomp::design::sensitivity`) against the MEASURED error of the same filter on
//! a simulated set-up whose true sensor modes are shifted: the record is
//! measured with the shifted dynamometer (`simulate::drift::shift_sensor_modes`),
//! compensated through the unshifted design's coefficient image (latency
//! removed) and scored against the band-limited truth (NRMSE, the project's
//! convention).
//!
//! The prediction declares a flat force spectrum of `force_rms` in the
//! compensated band, so the record that checks it carries such a force:
//! white noise low-passed at the band's top (the compensated band), RMS
//! `force_rms`. Milling cuts are printed beside it (`--nocapture`) but not
//! held to the prediction: their force sits on harmonic lines, not flat.
//! Target (issue): predicted and measured agree within a factor 1.5 at
//! ±1 % and ±3 %.

use crate::sim_common;

use dynocomp::design::axis::{design_axis, DesignOptions};
use dynocomp::metrics::sample_variance;
use dynocomp::simulate::{milling_force, SimOutput};

use sim_common::FS;
const FORCE_RMS: f64 = 100.0;
/// Issue target: predicted within this factor of measured.
const FACTOR: f64 = 1.5;
const SHIFTS_PCT: [f64; 4] = [-3.0, -1.0, 1.0, 3.0];

fn sim(seed: u64, rpm: f64) -> SimOutput {
    sim_common::sim(seed, rpm, 4)
}

/// (seed·10 + axis, shift %, predicted, measured on the flat force, measured on the milling cut).
fn table(seed: u64, rpm: f64) -> Vec<(u64, f64, f64, f64, f64)> {
    let s = sim(seed, rpm);
    let p = &s.params;
    let opts = DesignOptions { fs_hz: FS, lag: 4, force_rms: FORCE_RMS, ..Default::default() };
    let fine_len = p.anti_alias.fine_len(p.n_samples(), p.oversample);
    let f_fine = FS * p.oversample as f64;
    let milling = milling_force(&p.milling, f_fine, fine_len);
    let mut rows = Vec::new();
    for (a, cut) in milling.iter().enumerate() {
        let d = design_axis(&s.frf.freq_hz, s.frf.axis(a).unwrap(), sample_variance(&s.idle[a]), &opts)
            .unwrap_or_else(|e| panic!("axis {a}: {e:#}"));
        let sens = dynocomp::design::sensitivity::predict(&d, &opts).expect("sensitivity");
        // The unshifted point is the design's own predicted error (same criterion, same filter).
        assert!(
            (sens.nominal - d.predicted_error).abs() <= 1e-9 * d.predicted_error,
            "axis {a}: {} vs {}",
            sens.nominal,
            d.predicted_error
        );
        let flat = sim_common::flat_force(fine_len, f_fine, d.compensated_band_hz.1, FORCE_RMS, 77 + a as u64);
        for pct in std::iter::once(0.0).chain(SHIFTS_PCT) {
            let pred = sens.at(pct).expect("point");
            let m_flat = sim_common::measured_shifted(&s, &d, &flat, pct);
            let m_mill = sim_common::measured_shifted(&s, &d, cut, pct);
            eprintln!(
                "seed {seed} axis {a} shift {pct:+.0} %: predicted {:.2} %, measured flat {:.2} % (ratio {:.2}), milling {:.2} %",
                100.0 * pred,
                100.0 * m_flat,
                pred / m_flat,
                100.0 * m_mill
            );
            rows.push((seed * 10 + a as u64, pct, pred, m_flat, m_mill));
        }
    }
    rows
}

#[test]
fn predicted_sensitivity_agrees_with_measured_error() {
    let mut rows = table(3, 20_000.0);
    rows.extend(table(4, 6_000.0));
    let mut worst: f64 = 1.0;
    for &(a, pct, pred, m_flat, _) in rows.iter().filter(|r| r.1 != 0.0) {
        let ratio = pred / m_flat;
        worst = worst.max(ratio.max(1.0 / ratio));
        assert!(
            (1.0 / FACTOR..=FACTOR).contains(&ratio),
            "axis {a} shift {pct:+} %: predicted {pred:.4}, measured {m_flat:.4} (ratio {ratio:.2})"
        );
    }
    eprintln!("worst factor between predicted and measured at ±1/±3 %: {worst:.2}");
    // Negative control: the nominal prediction (no shift) used at ±1 % and
    // ±3 % is far outside the factor, so the check above can fail.
    for &(a, pct, _, m_flat, _) in rows.iter().filter(|r| r.1 != 0.0) {
        let nominal = rows.iter().find(|r| r.0 == a && r.1 == 0.0).map(|r| r.2).unwrap();
        let wrong = nominal / m_flat;
        assert!(
            wrong < 1.0 / FACTOR,
            "axis {a} shift {pct:+} %: the unshifted prediction {nominal:.4} is within the factor of {m_flat:.4}"
        );
    }
}
