//! The failing cases from independent set-ups (`tests/fixtures/cases/`, a
//! copy of the project's shared cases): regression tests against their true
//! force, not the measure of success (that is the random sweep,
//! BENCHMARKS.md).

use dynocomp::design::axis::DesignOptions;
use dynocomp::design::image::build_image;
use dynocomp::design::latency::design_axes_choosing_latency;
use dynocomp::design::progress::Progress;
use dynocomp::io::signal_csv::read_signal_csv;
use dynocomp::metrics::accuracy;
use dynocomp::offline::compensate::compensate_record;
use std::path::{Path, PathBuf};

fn case(name: &str, file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/cases").join(name).join(file)
}

/// Machine modes clustered at 300-860 Hz on x and an anti-resonance near
/// 800-1000 Hz, 51.2 kHz: the box design gave up above 856 Hz (predicted and
/// delivered ~18 %) while the offline smoother reached 0.24 %. The fit holds a
/// real pole at 31.7 kHz, above Nyquist; mapped into the discrete model it
/// sat next to the FIR taps (z^−1), the least squares went ill-conditioned
/// (5.7e5, taps of ±570) and every q above 0.05 N² failed the Riccati check.
#[test]
fn clustered_machine_modes_the_box_design_compensates_x() {
    let fs = 51_200.0;
    let frf = dynocomp::io::read_frf(&case("clustered-machine-modes", "frf.uff")).unwrap();
    let idle = case("clustered-machine-modes", "idle.csv");
    let r = dynocomp::design::noise::noise_variances(Some(&idle), None, &frf).unwrap();
    let rv: Vec<f64> = frf.axes.iter().map(|a| r[a.axis].unwrap()).collect();
    let opts = DesignOptions { fs_hz: fs, ..Default::default() };
    let (results, choice) = design_axes_choosing_latency(&frf.freq_hz, &frf.axes, &rv, &opts, None, &Progress::none());
    let designs: Vec<_> = results.into_iter().map(|(d, _)| d.unwrap()).collect();
    let x = &designs[0];
    let (dm, fd) = x.discrete.as_ref().unwrap();
    assert!(fd.condition < 1e3, "x: discrete model's least squares condition {:.1e}", fd.condition);
    assert!(dm.fir.iter().all(|h| h.abs() < 10.0), "x: FIR taps {:?}", dm.fir);
    assert!(x.flat_band_hz.1 >= 4000.0, "x: flat only to {} Hz", x.flat_band_hz.1);
    assert!(x.predicted_error < 0.005, "x: predicted {:.2} %", 100.0 * x.predicted_error);
    // Delivered, against the case's true force (band-limited, latency removed).
    let image = build_image(&designs, fs as u32, choice.chosen, 5000.0, [0; 32]).unwrap();
    let measured = read_signal_csv(&case("clustered-machine-modes", "measured.csv")).unwrap();
    let truth = read_signal_csv(&case("clustered-machine-modes", "true.csv")).unwrap();
    let out = compensate_record(&image, &measured, false, "measured.csv").unwrap();
    let band = dynocomp::metrics::scoring_band_hz(fs);
    let comp = accuracy(out.channel(0).unwrap(), truth.channel(0).unwrap(), fs, band).nrmse;
    let raw = accuracy(measured.channel(0).unwrap(), truth.channel(0).unwrap(), fs, band).nrmse;
    eprintln!(
        "x: raw {:.2} %, compensated {:.3} %, predicted {:.3} %",
        100.0 * raw,
        100.0 * comp,
        100.0 * x.predicted_error
    );
    assert!(comp < 0.003, "x: {:.2} % NRMSE against the true force (target ≤ 0.3 %)", 100.0 * comp);
    // Negative control: the raw force is far off, so the score can see it.
    assert!(raw > 0.5, "raw x only {:.2} %", 100.0 * raw);
}

/// Sensor modes moved by +2.5 % between two FRFs, 25.6 kHz; the record
/// drifts from state 0 at 0.05 s to state 1 at its end. The first FRF's z
/// fit holds a heavily damped pair at 1988 Hz (ζ 0.5, modal share −0.0065)
/// and the second's a pair at 1669 Hz, neither a mode of the true z axis;
/// pairing every fitted pair in frequency order refused the axis. Only
/// physical modes are paired now, the background terms of each fit fade
/// between the states.
///
/// Judged against the case's true force: the two-state box image on the
/// drifting record is no worse than the first FRF's single-state image, and
/// the drift smoother follows the drift better than the single-state
/// smoother. The single-state results are the negative control (the score
/// sees a model that does not follow the drift).
#[test]
fn two_state_z_pairs_physical_modes_and_follows_the_drift() {
    use dynocomp::design::two_state::range::{design_axes_over_range, RangeOutcome};
    use dynocomp::offline::drift::{smooth_drifting, DriftSmoothing};
    let fs = 25_600.0;
    let before = dynocomp::io::read_frf(&case("two-state-z", "before.csv")).unwrap();
    let after = dynocomp::io::read_frf(&case("two-state-z", "after.csv")).unwrap();
    let idle = case("two-state-z", "idle.csv");
    let r = dynocomp::design::noise::noise_variances(Some(&idle), None, &before).unwrap();
    let opts = DesignOptions { fs_hz: fs, ..Default::default() };
    let ranges: Vec<_> = design_axes_over_range(&before.freq_hz, &before.axes, &after.axes, &r, &opts)
        .into_iter()
        .map(|x| match x.unwrap() {
            RangeOutcome::Range(rd) => *rd,
            RangeOutcome::Held(h) => panic!("axis {}: states not paired: {}", h.design.axis, h.why),
        })
        .collect();
    let z = &ranges[2];
    // The paired physical modes of z: the machine mode and the sensor mode.
    let paired: Vec<usize> = (0..z.states.before.terms.len()).filter(|&i| !z.states.is_background(i)).collect();
    let modes: Vec<(f64, f64)> = paired
        .iter()
        .filter_map(|&i| match (z.states.before.terms[i], z.states.after.terms[i]) {
            (dynocomp::fit::Term::Pair { pole: p0, .. }, dynocomp::fit::Term::Pair { pole: p1, .. }) => {
                Some((p0.norm() / std::f64::consts::TAU, p1.norm() / std::f64::consts::TAU))
            }
            _ => None,
        })
        .collect();
    eprintln!("z paired modes {modes:?}");
    assert!(modes.iter().any(|m| (m.0 - 3450.0).abs() < 50.0 && (m.1 / m.0 - 1.025).abs() < 0.01), "{modes:?}");
    assert!(modes.iter().all(|m| (m.0 - 1988.0).abs() > 20.0 && (m.0 - 1669.0).abs() > 20.0), "{modes:?}");

    let measured = read_signal_csv(&case("two-state-z", "measured_drift.csv")).unwrap();
    let truth = read_signal_csv(&case("two-state-z", "true.csv")).unwrap();
    let band = dynocomp::metrics::scoring_band_hz(fs);
    let score = |out: &[f64]| accuracy(out, truth.channel(2).unwrap(), fs, band).nrmse;
    let two: Vec<_> = ranges.iter().map(|rd| rd.candidates[rd.best].design.clone()).collect();
    let single: Vec<_> = ranges.iter().map(|rd| rd.candidates[0].design.clone()).collect();
    let box_z = |designs: &[dynocomp::design::axis::AxisDesign]| {
        let image = build_image(designs, fs as u32, opts.lag, 5000.0, [0; 32]).unwrap();
        score(compensate_record(&image, &measured, false, "measured_drift.csv").unwrap().channel(2).unwrap())
    };
    let (two_box, single_box) = (box_z(&two), box_z(&single));
    // The drift smoother with both states, and with state 0 held (the
    // single-state smoother on the same model and settings).
    let d0 = &z.candidates[0].design;
    let chosen = &z.candidates[z.best].design;
    let (dm0, _) = d0.discrete.as_ref().unwrap();
    let settings = DriftSmoothing {
        fs_hz: fs,
        interval_s: (0.05, measured.channel(2).unwrap().len() as f64 / fs),
        band_hz: d0.compensated_band_hz,
        structure: (dm0.fir.len(), dm0.advance),
        q: chosen.kalman.q,
        r: chosen.kalman.r,
    };
    let y = measured.channel(2).unwrap();
    let drift = score(&smooth_drifting(y, &|s| z.states.at(s), &settings).unwrap());
    let held = score(&smooth_drifting(y, &|_| z.states.at(0.0), &settings).unwrap());
    eprintln!(
        "z: box two-state {:.3} % / single-state {:.3} %; smoother drift {:.3} % / held {:.3} %",
        100.0 * two_box,
        100.0 * single_box,
        100.0 * drift,
        100.0 * held
    );
    assert!(
        two_box <= single_box * 1.02,
        "two-state box z {:.3} % vs single-state {:.3} %",
        100.0 * two_box,
        100.0 * single_box
    );
    assert!(drift < 0.6 * held, "drift smoother z {:.3} % vs held state 0 {:.3} %", 100.0 * drift, 100.0 * held);
    assert!(drift < 0.005, "drift smoother z {:.3} %", 100.0 * drift);
}
