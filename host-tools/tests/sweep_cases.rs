//! Cases kept from the random-set-up sweep (`examples/sweep.rs`,
//! `dynocomp::eval::sweep`), each against the simulator's truth.
//!
//! Seed 32 (default ranges, 25.6 kHz, 0.5 Hz lines): axis x's FRF starts
//! at 7 Hz. The order the fit chose bent below that first coherent line
//! (13 % from its value there at 0 Hz), which no line constrains, and the
//! axis was refused ("not flat below the FRF's first coherent line").
//! Among the orders the lines cannot tell apart the fit took one that is
//! flat there (`vf::vector_fit_accepting`). Since the edge surrogate below,
//! the fit's own order is flat there (no axis of the sweep needs that
//! choice now; `tests/fit_limits.rs` keeps it tested). The order held a real pole below the first coherent line, fitted
//! to the noise of the lines there: 1.27 % (3.0x the floor). Such a pole is
//! now dropped (`VfOptions::f_identified_hz`): 0.86 % (2.05x). A lightly
//! damped pair the fit parked above its lines for the mode at 4.9 kHz was
//! dropped as spurious, which bent the static gain; a damped pair now takes
//! its place (`vf::edge_surrogates`): 0.44 % (1.06x).
//!
//! Seed 78 (default ranges, 102.4 kHz, 4 Hz lines): axis x has a mode above
//! its lines; dropping the pair that stood for it left the static gain 1.3 %
//! off and the axis at 1.73 % (6.9x the floor), with the surrogate 0.30 %.

use dynocomp::eval::drift_sweep::{draw_drift, run_drift_case, DriftDesigned};
use dynocomp::eval::rates::{score_sim, RunOptions};
use dynocomp::eval::sweep::draw;
use dynocomp::fit::vf::{coherence_weights, vector_fit, VfOptions};
use dynocomp::fit::Term;
use dynocomp::simulate::{simulate_with, SimOutput};
use num_complex::Complex64;
use std::f64::consts::PI;

/// Largest relative move of `g` from its value at `f_first` between
/// f_first/8 and 0 Hz (the design's static check, computed here anew).
fn move_below(g: impl Fn(f64) -> Complex64, f_first: f64) -> f64 {
    let g0 = g(f_first);
    (0..=200).map(|i| f_first / 8.0 * i as f64 / 200.0).map(|f| (g(f) - g0).norm() / g0.norm()).fold(0.0, f64::max)
}

/// Axis `axis` of `s` designed with `run` and scored: its NRMSE over the
/// exact inverse's noise floor (printed with the floor and raw).
fn over_floor(name: &'static str, s: &SimOutput, run: &RunOptions, axis: usize) -> f64 {
    let a = score_sim(name, s, run).axes.swap_remove(axis);
    let e = a.comp_nrmse.clone().unwrap_or_else(|why| panic!("axis {axis} refused: {why}"));
    eprintln!(
        "axis {axis}: {:.3} % (floor {:.3} %, raw {:.3} %)",
        100.0 * e,
        100.0 * a.noise_floor,
        100.0 * a.raw_nrmse
    );
    e / a.noise_floor
}

/// The sweep's set-up `seed` simulated, checked to be the one drawn when
/// the test was written (kind, rate, line spacing).
fn simulated(seed: u64, drawn: (&str, f64, f64)) -> (&'static str, f64, SimOutput) {
    let (case, fs, kind) = draw(seed);
    assert_eq!((kind, fs, case.frf_df_hz), drawn, "the sweep's seed {seed} changed");
    let params = case.sim_params(fs);
    (case.name, fs, simulate_with(case.seed, &params, case.dynamometer(&params).unwrap()).unwrap())
}

#[test]
fn seed_32_x_gets_a_model_flat_below_its_first_coherent_line() {
    let (name, _, s) = simulated(32, ("default", 25_600.0, 0.5));
    let x = s.frf.axis(0).unwrap();
    let coh = x.coherence.as_deref();
    let first = s.frf.freq_hz.iter().zip(coh.unwrap()).find(|(_, c)| **c >= 0.9).map(|(f, _)| *f).unwrap();
    let weights = coherence_weights(&x.frf, coh);
    // The rule on the first coherent line alone: the drop of terms the
    // lines do not support (`VfOptions::drop_unsupported`) takes this pole
    // out as well, and is off here.
    let no_drop = VfOptions { drop_unsupported: false, ..Default::default() };
    let plain = vector_fit(&s.frf.freq_hz, &x.frf, &weights, &no_drop).unwrap();
    // Control: a real pole below the first coherent line, which the fit
    // that knows where the lines identify the model drops.
    let below = |m: &dynocomp::fit::PoleResidueModel| {
        m.terms.iter().any(|t| matches!(t, Term::Real { pole, .. } if pole.abs() / (2.0 * PI) < first))
    };
    assert!(below(&plain.model), "control: the plain fit has no real pole below {first} Hz");
    let opts = VfOptions { f_identified_hz: first, ..no_drop };
    let limited = vector_fit(&s.frf.freq_hz, &x.frf, &weights, &opts).unwrap();
    assert!(!below(&limited.model), "a real pole below {first} Hz was kept");
    let dropped = vector_fit(&s.frf.freq_hz, &x.frf, &weights, &Default::default()).unwrap();
    assert!(!below(&dropped.model), "a real pole below {first} Hz the lines do not support was kept");
    // That pole bends Ĝ below the first line, where the mean force is:
    // the plain fit moves 0.6 % there, the limited one 10x less.
    let (bend_plain, bend_limited) =
        (move_below(|f| plain.model.frf(f), first), move_below(|f| limited.model.frf(f), first));
    eprintln!(
        "first coherent line {first} Hz; below it the plain fit moves {bend_plain:.2e}, the limited {bend_limited:.2e}"
    );
    assert!(bend_limited < 1e-3 && bend_plain > 3e-3, "moves {bend_plain:.2e} plain, {bend_limited:.2e} limited");
    // The design: compensated, better than raw, within 1.3x of the exact
    // inverse's floor (the pole kept: 3.0x; the edge pair dropped: 2.05x).
    let res = score_sim(name, &s, &RunOptions::default());
    let a = &res.axes[0];
    let e = a.comp_nrmse.clone().unwrap_or_else(|why| panic!("axis x refused: {why}"));
    eprintln!("x: {:.3} % (raw {:.3} %, floor {:.3} %)", 100.0 * e, 100.0 * a.raw_nrmse, 100.0 * a.noise_floor);
    assert!(e < 0.1 * a.raw_nrmse, "x: {e} against raw {}", a.raw_nrmse);
    assert!(e <= 1.3 * a.noise_floor, "x: {e} against the floor {}", a.noise_floor);
}

#[test]
fn seed_78_x_keeps_a_surrogate_for_its_mode_above_the_lines() {
    let (name, _, s) = simulated(78, ("default", 102_400.0, 4.0));
    let x = s.frf.axis(0).unwrap();
    let f_top = *s.frf.freq_hz.last().unwrap();
    let g = |f: f64| s.dyno.axis(0).frf(f);
    assert!(
        s.dyno.axis(0).modes.iter().any(|m| m.fn_hz > f_top && m.residue > 0.02),
        "the case changed: no mode above the lines"
    );
    let opts = dynocomp::eval::rates::design_options(102_400.0, &RunOptions::default());
    let model = dynocomp::design::axis::fitted_model(&s.frf.freq_hz, x, &opts).unwrap();
    let edge: Vec<bool> = model
        .terms
        .iter()
        .map(|t| matches!(t, Term::Pair { pole, .. } if pole.norm() / (2.0 * PI) > 0.97 * f_top))
        .collect();
    let modes = model.modes();
    eprintln!("fitted modes (Hz, zeta): {modes:?}");
    assert!(edge.iter().any(|e| *e), "no pair above the lines stands for the mode there: {modes:?}");
    let static_error = |m: &dynocomp::fit::PoleResidueModel| (m.frf(0.0) / g(0.0) - 1.0).norm();
    // Control: the pair dropped, as the fit did before, moves the static
    // gain by a percent, where the mean cutting force is.
    let keep: Vec<bool> = edge.iter().map(|e| !e).collect();
    let weights = coherence_weights(&x.frf, x.coherence.as_deref());
    let dropped = dynocomp::fit::vf::refit_kept(&s.frf.freq_hz, &x.frf, &weights, &model, &keep).unwrap();
    let (kept_off, dropped_off) = (static_error(&model), static_error(&dropped));
    eprintln!("static gain off {kept_off:.2e} (pair dropped: {dropped_off:.2e})");
    assert!(kept_off < 1e-3 && dropped_off > 5e-3, "static gain off {kept_off:.2e}, dropped {dropped_off:.2e}");
    // The design against the truth: within 1.5x of the exact inverse's
    // floor (the pair dropped: 6.9x).
    let res = score_sim(name, &s, &RunOptions::default());
    let a = &res.axes[0];
    let e = a.comp_nrmse.clone().unwrap_or_else(|why| panic!("axis x refused: {why}"));
    eprintln!("x: {:.3} % (raw {:.3} %, floor {:.3} %)", 100.0 * e, 100.0 * a.raw_nrmse, 100.0 * a.noise_floor);
    assert!(e <= 1.5 * a.noise_floor, "x: {e} against the floor {}", a.noise_floor);
}

/// The drift sweep's case `seed`, checked to be the one drawn when the
/// test was written (kind, rate, line spacing): every axis designed for the
/// range, its figures printed (`eval::drift_sweep::DriftDesigned`).
fn drift_case(seed: u64, drawn: (&str, f64, f64)) -> Vec<DriftDesigned> {
    let c = draw_drift(seed);
    assert_eq!((c.kind, c.fs_hz, c.case.frf_df_hz), drawn, "the drift sweep's seed {seed} changed");
    let scores = run_drift_case(&c).unwrap();
    scores
        .into_iter()
        .map(|a| {
            let d = a.design.unwrap_or_else(|why| panic!("axis {} refused: {why}", a.axis));
            eprintln!(
                "axis {}: static gains {:.4} / {:.4}; drift {:.3} %, held {:.3} %, no drift {:.3} %; box two-state {:.3} %, single {:.3} %",
                a.axis,
                d.static_gains.0,
                d.static_gains.1,
                100.0 * d.offline_drift,
                100.0 * d.offline_held,
                100.0 * d.offline_no_drift,
                100.0 * d.box_two_state,
                100.0 * d.box_single
            );
            d
        })
        .collect()
}

/// `compensate --offline --drift` within 1.5x of the no-drift error (the
/// issue's target) on every axis, and the held smoother missing it on the
/// axes `controls` (the score sees the drift).
fn followed(d: &[DriftDesigned], controls: &[usize]) {
    for (a, d) in d.iter().enumerate() {
        assert!(d.offline_drift <= 1.5 * d.offline_no_drift, "axis {a}: {d:?}");
    }
    for &a in controls {
        assert!(d[a].offline_held > 1.5 * d[a].offline_no_drift, "control, axis {a}: {:?}", d[a]);
    }
}

/// Drift sweep seed 38 (`examples/drift_sweep.rs`, `dynocomp::eval::drift_sweep`):
/// a close sensor-mode pair at 51.2 kHz, 4 Hz lines, the sensor modes moving
/// +2.2 % during the cut. The first FRF's fit of z holds a mode at 5.3 kHz,
/// above the compensated band, that the second's does not; pairing every
/// physical mode in order refused the axis, and with it the whole two-state
/// image. A mode without a partner above the band now fades between the
/// states (`two_state::model::pair_fading`).
///
/// Judged against the truth: every axis is designed for the range and
/// followed by `compensate --offline --drift` within 1.5x of the same cut
/// without drift (the target), while the first FRF's smoother held
/// over the drift misses it on every axis (the control: the score sees the
/// drift).
#[test]
fn drift_seed_38_fades_a_mode_above_the_band_and_follows_the_drift() {
    let d = drift_case(38, ("close-pair", 51_200.0, 4.0));
    followed(&d, &[0, 1, 2]);
}

/// Drift sweep seed 1: default ranges at 51.2 kHz, 1 Hz lines, sensor modes
/// +2.9 %. The second FRF's fit of z, taken at the first state's order
/// with no check below the first coherent line (7 Hz), held a real pole at
/// 0.06 Hz and |Ĝ(0)| = 2.0; once that was left out, the order chosen sat
/// 1.3 % above its own low lines. The two-state box image then gave 2.6 %
/// against 0.85 % single-state: written and worse. The second fit is now
/// flat below the first coherent line, without poles there, and within its
/// noise on the low lines (`two_state::range::pair_second_state`).
///
/// Judged against the truth: the paired states keep the static gain (the
/// simulated drift is a mass change) within 0.5 %, z's two-state box image
/// is no worse than the single-state one, and every axis's drift smoother is
/// within 1.5x of the no-drift error. Control: y's held smoother misses it.
#[test]
fn drift_seed_1_keeps_the_static_gain_between_the_states() {
    let d = drift_case(1, ("default", 51_200.0, 1.0));
    followed(&d, &[1]);
    let z = &d[2];
    assert!((z.static_gains.1 / z.static_gains.0 - 1.0).abs() < 0.005, "z: {z:?}");
    assert!(z.box_two_state <= 1.02 * z.box_single, "z: {z:?}");
}

/// Drift sweep seed 23: clustered machine modes at 10.24 kHz, 0.5 Hz lines,
/// sensor modes −3.7 %. The first FRF's fit of x resolves a machine mode at
/// 709 Hz that the second's does not (380, 616, 709, 754, 892 Hz against
/// 380, 618, 755, 891 Hz), and pairing refused the axis and the image. A
/// mass change on the table leaves the machine's modes where they are: the
/// second state is fitted again with the first's machine poles
/// (`two_state::range::pair_second_state`), and pairs.
///
/// Judged against the truth: every axis is designed, and the drift smoother
/// is within 1.5x of the no-drift error on every axis; control: the held
/// smoother misses it on x and y (3.3 % and 5.0 % against 0.63 % and 0.32 %).
#[test]
fn drift_seed_23_fits_the_second_state_with_the_first_states_machine_poles() {
    let d = drift_case(23, ("machine-cluster", 10_240.0, 0.5));
    followed(&d, &[0, 1]);
}

/// The sweep's seed 92 (clustered machine modes, 25.6 kHz, 1 Hz lines):
/// axis x's machine modes put a zero pair of Ĝ at 725 Hz in the right
/// half-plane. No causal compensator inverts it, and the box output on the
/// simulated cut is further from the true force than the raw measurement
/// (163 % against 118 % when this was written). The design says so
/// (`design::phase_limit`). `compensate --offline`, the zero-phase smoother
/// on the same design, is not bound by causality: measured against the
/// truth it is under a quarter of raw and of the box (16 % when this was
/// written; the floor is 0.29 %, which it does not reach either). Control: y and z of the same set-up have no such
/// zero, are not warned, and their box output is far better than raw.
#[test]
fn seed_92_x_has_a_non_minimum_phase_zero_that_is_named_and_smoothed_better_offline() {
    use dynocomp::design::axis::design_axis;
    use dynocomp::metrics::{accuracy, sample_variance};
    use dynocomp::offline::smoother::Smoother;
    let (name, fs, s) = simulated(92, ("machine-cluster", 25_600.0, 1.0));
    let res = score_sim(name, &s, &RunOptions::default());
    for a in &res.axes {
        let e = a.comp_nrmse.clone().unwrap_or_else(|why| panic!("axis {} refused: {why}", a.axis));
        eprintln!("axis {}: box {:.3} %, raw {:.3} %, {:?}", a.axis, 100.0 * e, 100.0 * a.raw_nrmse, a.phase_limits);
        if a.axis == 0 {
            assert_eq!(a.phase_limits.len(), 1, "{:?}", a.phase_limits);
            let z = &a.phase_limits[0];
            assert!((z.zero_hz.0 - 725.0).abs() < 15.0 && z.zero_hz.1 > 0.0, "{z:?}");
            assert!(e > a.raw_nrmse, "x: the warned limit is not seen on the record: {e} against {}", a.raw_nrmse);
        } else {
            assert!(a.phase_limits.is_empty() && e < 0.1 * a.raw_nrmse, "control axis {}: {e}", a.axis);
        }
    }
    // The zero-phase smoother of `compensate --offline` on x's design at
    // the image's latency, scored against the truth.
    let x = s.frf.axis(0).unwrap();
    let opts = dynocomp::eval::rates::design_options(fs, &RunOptions { lag: Some(res.latency), ..Default::default() });
    let d = design_axis(&s.frf.freq_hz, x, sample_variance(&s.idle[0]), &opts).unwrap();
    let (dm, _) = d.discrete.as_ref().unwrap();
    let smoothed = Smoother::shaped(dm, d.kalman.q, d.kalman.r, d.kalman.force_shape).unwrap().smooth(&s.measured[0]);
    let offline = accuracy(&smoothed, &s.truth[0], fs, res.band_hz).nrmse;
    eprintln!("x: compensate --offline {:.3} % (raw {:.3} %)", 100.0 * offline, 100.0 * res.axes[0].raw_nrmse);
    let (raw, on_box) = (res.axes[0].raw_nrmse, res.axes[0].comp_nrmse.clone().unwrap());
    assert!(offline < 0.25 * raw && offline < 0.25 * on_box, "x offline: {offline}");
}

/// The sweep's seed 48 (clustered machine modes, 25.6 kHz, 0.5 Hz lines):
/// axis x's coherence dips below 0.9 at its 736 Hz anti-resonance (|G|
/// 0.08 against 0.2-1 around it). The coherent band was the longest run of
/// coherent lines, 737-4096 Hz; the fit then had no line below 737 Hz, bent
/// there, and the axis was passed through raw ("not flat below the FRF's
/// first coherent line"). The band now runs across an anti-resonance
/// (`design::axis::coherent_band`): x is compensated to within 1.3x of the
/// exact inverse's floor (1.07x when this was written). Control: the dip
/// is in the data, the 11-line median coherence is under 0.9 there.
#[test]
fn seed_48_x_keeps_its_low_lines_across_an_anti_resonance() {
    let (name, fs, s) = simulated(48, ("machine-cluster", 25_600.0, 0.5));
    let x = s.frf.axis(0).unwrap();
    let c = x.coherence.as_ref().unwrap();
    let dip = s.frf.freq_hz.iter().enumerate().filter(|(_, f)| (**f - 736.0).abs() <= 2.0).any(|(i, _)| {
        let mut w = c[i - 5..=i + 5].to_vec();
        w.sort_by(f64::total_cmp);
        w[5] < 0.9
    });
    assert!(dip, "control: no coherence dip at 736 Hz");
    let res = score_sim(name, &s, &RunOptions::default());
    let a = &res.axes[0];
    let e = a.comp_nrmse.clone().unwrap_or_else(|why| panic!("axis x refused: {why}"));
    eprintln!(
        "x: {:.3} % (floor {:.3} %, raw {:.3} %) at {fs} Hz",
        100.0 * e,
        100.0 * a.noise_floor,
        100.0 * a.raw_nrmse
    );
    assert!(e <= 1.3 * a.noise_floor, "x: {e} against the floor {}", a.noise_floor);
}

/// Drift sweep seed 32: a close sensor-mode pair at 25.6 kHz, 0.5 Hz lines,
/// the sensor modes moving +4.8 % during the cut. The first FRF's fit of z
/// bent 23 % below its first coherent line (7 Hz) through a real pole under
/// it, and the axis was passed through raw ("not flat below the FRF's first
/// coherent line"). That pole is now dropped (`VfOptions::f_identified_hz`):
/// every axis is designed for the range and followed within 1.5x of the
/// same cut without drift; the held smoother misses it on every axis (the
/// control).
#[test]
fn drift_seed_32_z_is_designed_without_a_pole_below_its_first_coherent_line() {
    let d = drift_case(32, ("close-pair", 25_600.0, 0.5));
    followed(&d, &[0, 1, 2]);
}

/// The sweep's seed 96 (a close sensor-mode pair, 51.2 kHz, 4 Hz lines):
/// vector fitting left the poles of axis y off the true modes by more than
/// its lines allow (268.65 Hz for 268.28, 2148.48 Hz for 2147.91), and the
/// box image gave 0.44 % against a floor of 0.10 % (4.5x). The fit is now
/// refined to the maximum-likelihood model of its order (`fit::refine`):
/// against the simulator's true response, the model's RMS relative error
/// over the scoring band is under 0.7x vector fitting's (0.56x when this was
/// written), and the design is within 2x of the exact inverse's floor
/// (1.65x). Control: the same fit and design unrefined, over 3x the floor.
#[test]
fn seed_96_y_poles_are_refined_to_the_lines() {
    let (name, fs, s) = simulated(96, ("close-pair", 51_200.0, 4.0));
    let y = s.frf.axis(1).unwrap();
    let band = dynocomp::eval::rates::scoring_band_hz(fs);
    let lines: Vec<f64> = (1..=400).map(|k| band * k as f64 / 400.0).collect();
    let model_error = |m: &dynocomp::fit::PoleResidueModel| {
        let sum: f64 = lines.iter().map(|f| (m.frf(*f) / s.dyno.axis(1).frf(*f) - 1.0).norm_sqr()).sum();
        (sum / lines.len() as f64).sqrt()
    };
    let opts = dynocomp::eval::rates::design_options(fs, &RunOptions::default());
    let refined = dynocomp::design::axis::fitted_model(&s.frf.freq_hz, y, &opts).unwrap();
    let plain_opts = dynocomp::eval::rates::design_options(fs, &RunOptions { refine_fit: false, ..Default::default() });
    let plain = dynocomp::design::axis::fitted_model(&s.frf.freq_hz, y, &plain_opts).unwrap();
    let (e_refined, e_plain) = (model_error(&refined), model_error(&plain));
    eprintln!("model error against the true G: refined {e_refined:.2e}, vector fitting alone {e_plain:.2e}");
    assert!(e_plain > 1.5e-3, "control: vector fitting's model is {e_plain:.2e} from the truth");
    assert!(e_refined < 0.7 * e_plain, "refined {e_refined:.2e} against {e_plain:.2e}");
    let scored = |run: &RunOptions| over_floor(name, &s, run, 1);
    let (refined, plain) =
        (scored(&RunOptions::default()), scored(&RunOptions { refine_fit: false, ..Default::default() }));
    assert!(refined <= 2.0, "y at {refined:.2}x the floor");
    assert!(plain > 3.0, "control: y unrefined at {plain:.2}x the floor");
}

/// Seed 137 (modes above the band, 51.2 kHz, 4 Hz lines), one of the seeds
/// 100-199 first run to check the per-axis seeding (`fit::seed`): axis x's
/// fit left out a mode its lines hold, and the design gave 8.2 % (36x the
/// floor). With a pair seeded where the residual exceeds the impact test's
/// noise, 0.33 % (1.44x).
#[test]
fn seed_137_x_gets_a_pair_where_its_fit_left_a_mode_out() {
    let (name, fs, s) = simulated(137, ("above-band", 51_200.0, 4.0));
    let x = s.frf.axis(0).unwrap();
    let opts = dynocomp::eval::rates::design_options(fs, &RunOptions::default());
    let seeded = dynocomp::design::axis::fitted_model(&s.frf.freq_hz, x, &opts).unwrap();
    let unseeded_opts =
        dynocomp::eval::rates::design_options(fs, &RunOptions { seed_fit: false, ..Default::default() });
    let unseeded = dynocomp::design::axis::fitted_model(&s.frf.freq_hz, x, &unseeded_opts).unwrap();
    // The true modes in the band that a fit holds a pole for (within 2 % of
    // its frequency): the seeded fit holds one more.
    let band = dynocomp::eval::rates::scoring_band_hz(fs);
    let true_modes: Vec<f64> = s.dyno.axis(0).modes.iter().map(|m| m.fn_hz).filter(|f| *f <= band).collect();
    let held = |m: &dynocomp::fit::PoleResidueModel| {
        let fitted = m.modes();
        true_modes.iter().filter(|t| fitted.iter().any(|(f, _)| (f / *t - 1.0).abs() <= 0.02)).count()
    };
    eprintln!("true modes in band {true_modes:?}; fitted {:?} seeded, {:?} not", seeded.modes(), unseeded.modes());
    assert!(
        held(&seeded) > held(&unseeded),
        "seeded fit holds {} true modes, unseeded {}",
        held(&seeded),
        held(&unseeded)
    );
    // The summary names the line seeded, within 5 % of the mode left out
    // (388 Hz); control: none without seeding.
    let idle = &s.idle[0];
    let mean = idle.iter().sum::<f64>() / idle.len() as f64;
    let r = idle.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / idle.len() as f64;
    let note = |opts: &dynocomp::design::axis::DesignOptions| {
        let d = dynocomp::design::axis::design_axis(&s.frf.freq_hz, x, r, opts).unwrap();
        d.notes.into_iter().find(|n| n.contains("pole pairs added near"))
    };
    let named = note(&opts).expect("the summary names the seeded pair");
    eprintln!("{named}");
    let hz: f64 = named.split("added near ").nth(1).and_then(|t| t.split(' ').next()).unwrap().parse().unwrap();
    assert!((hz / 388.0 - 1.0).abs() <= 0.05, "{named}");
    assert!(note(&unseeded_opts).is_none(), "control: a seeded pair named without seeding");
    let scored = |run: &RunOptions| over_floor(name, &s, run, 0);
    let (with, without) =
        (scored(&RunOptions::default()), scored(&RunOptions { seed_fit: false, ..Default::default() }));
    assert!(with <= 2.0, "x at {with:.2}x the floor");
    assert!(without > 10.0, "control: x without seeding at {without:.2}x the floor");
}

/// Seed 99 (machine-cluster, 51.2 kHz, 4 Hz lines), first run in the sweep
/// of seeds 0-99: axis y's fit held a real pole at 17 Hz and pairs at 3100
/// and 3485 Hz where the true axis has no mode. The lines did not support
/// them (BIC), but the order search compares whole fits, and the 17 Hz pole
/// took Ĝ(0) 0.8 % off, below the first coherent line (8 Hz) where no line
/// checks it: 1.17 % against the truth, 5.5x the floor. With the terms the
/// lines do not support dropped (`VfOptions::drop_unsupported`), 1.18x.
#[test]
fn seed_99_y_drops_the_terms_its_lines_do_not_support() {
    let (name, fs, s) = simulated(99, ("machine-cluster", 51_200.0, 4.0));
    let y = s.frf.axis(1).unwrap();
    let kept_opts = RunOptions { drop_unsupported: false, ..Default::default() };
    let fit = |run: &RunOptions| {
        let opts = dynocomp::eval::rates::design_options(fs, run);
        dynocomp::design::axis::fitted_model(&s.frf.freq_hz, y, &opts).unwrap()
    };
    let (dropped, kept) = (fit(&RunOptions::default()), fit(&kept_opts));
    // The static gain against the true chain's (sensor and analog front end).
    let g0 = s.dyno.axis(1).frf(0.0) * s.params.anti_alias.analog_frf(0.0);
    let off = |m: &dynocomp::fit::PoleResidueModel| (m.frf(0.0) / g0 - 1.0).norm();
    eprintln!("Ĝ(0) off {:.2e} with the drop, {:.2e} without", off(&dropped), off(&kept));
    assert!(off(&dropped) < 2e-3, "Ĝ(0) off {:.2e}", off(&dropped));
    assert!(off(&kept) > 5e-3, "control: Ĝ(0) off only {:.2e} with every term kept", off(&kept));
    let (with, without) = (over_floor(name, &s, &RunOptions::default(), 1), over_floor(name, &s, &kept_opts, 1));
    assert!(with <= 1.5, "y at {with:.2}x the floor");
    assert!(without > 4.0, "control: y with every term kept at {without:.2}x the floor");
}

/// Seed 140 (default, 10.24 kHz, 2 Hz lines), from the sweep's seeds 100-199:
/// axis y's fit was seeded with a pair at 252 Hz that ended 1 line wide
/// (ζ = 0.2 %), 34 % below the nearest true mode (382 Hz); y went from
/// 1.02x to 1.45x its floor. A seeded pair is now tried only as wide as
/// three lines (`VfOptions::seed_resolved_lines`).
#[test]
fn seed_140_y_gets_no_pair_narrower_than_its_lines() {
    let (name, fs, s) = simulated(140, ("default", 10_240.0, 2.0));
    let any_width = RunOptions { seed_resolved_lines: 0.0, ..Default::default() };
    let seeded = |run: &RunOptions| {
        let opts = dynocomp::eval::rates::design_options(fs, run);
        let idle = &s.idle[1];
        let mean = idle.iter().sum::<f64>() / idle.len() as f64;
        let r = idle.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / idle.len() as f64;
        dynocomp::design::axis::design_axis(&s.frf.freq_hz, s.frf.axis(1).unwrap(), r, &opts).unwrap().seeded_hz
    };
    let (resolved, narrow) = (seeded(&RunOptions::default()), seeded(&any_width));
    eprintln!("seeded {resolved:?} Hz; with any width {narrow:?} Hz");
    assert!(resolved.is_empty(), "seeded at {resolved:?} Hz");
    assert!(narrow.iter().any(|f| (f / 252.0 - 1.0).abs() < 0.02), "control: no seed near 252 Hz ({narrow:?})");
    let (with, without) = (over_floor(name, &s, &RunOptions::default(), 1), over_floor(name, &s, &any_width, 1));
    assert!(with <= 1.15, "y at {with:.2}x the floor");
    assert!(without > 1.3, "control: y with any seed width at {without:.2}x the floor");
}

/// Seed 52 (default, 25.6 kHz, 0.5 Hz lines): at latency 4 axis y's q was
/// chosen mostly for the noise written above the band (the quiet design's
/// criterion), and y ended 1.67x its floor. Where a design writes more
/// noise above the band than its in-band error, longer latencies are now
/// tried too (`latency::ABOVE_BAND_SHORT`): at the latency kept y is within
/// 1.3x, and the output as written stays within 1.1x of a perfect
/// band-limited estimate. Control: the same case at the fixed latency 4.
#[test]
fn seed_52_y_looks_further_ahead_where_the_noise_above_the_band_dominates() {
    let (name, _fs, s) = simulated(52, ("default", 25_600.0, 0.5));
    let chosen = dynocomp::eval::rates::score_sim(name, &s, &RunOptions::default());
    let y = &chosen.axes[1];
    let e = y.comp_nrmse.clone().unwrap();
    let w = y.as_written.unwrap();
    eprintln!(
        "latency {}: y {:.3} % ({:.2}x the floor), as written {:.2} % (perfect {:.2} %)",
        chosen.latency,
        100.0 * e,
        e / y.noise_floor,
        100.0 * w.output.nrmse,
        100.0 * w.perfect.nrmse
    );
    assert!(chosen.latency > 4, "latency {} kept", chosen.latency);
    assert!(e / y.noise_floor <= 1.3, "y at {:.2}x the floor", e / y.noise_floor);
    assert!(w.output.nrmse <= 1.1 * w.perfect.nrmse, "as written {:.2} %", 100.0 * w.output.nrmse);
    let at4 = over_floor(name, &s, &RunOptions { lag: Some(4), ..Default::default() }, 1);
    assert!(at4 > 1.5, "control: y at the fixed latency 4 at {at4:.2}x the floor");
}

/// Seed 5 (clustered machine modes, 25.6 kHz, 1 Hz lines), designed for
/// its cut's force spectrum (`--force-prior spectrum`): axis y's model has a
/// non-minimum-phase zero at 846 Hz, which no causal filter inverts, and
/// its box filter leaves 13.7 % (predicted 13.3 %), while `compensate
/// --offline` on the same image reaches 0.16 %. The design predicts that
/// (0.14 %, with the fit's uncertainty; `AxisDesign::offline_predicted`),
/// so the summary names y for the smoother (under
/// `OFFLINE_MUCH_BETTER` of the box filter's prediction). Against the
/// truth: every axis's offline prediction within 0.67-1.5x of the
/// smoother's NRMSE, and on y the smoother under a quarter of the box
/// filter's error. Control: x and z, where the smoother measures within
/// 1.1x of the box filter, are not named.
#[test]
fn seed_5_y_is_named_for_the_offline_smoother_its_box_filter_cannot_match() {
    use dynocomp::design::mimo::OFFLINE_MUCH_BETTER;
    let (case, fs, kind) = draw(5);
    assert_eq!((kind, fs, case.frf_df_hz), ("machine-cluster", 25_600.0, 1.0), "the sweep's seed 5 changed");
    let run = RunOptions { force_spectrum: true, score_offline: true, ..RunOptions::default() };
    let res = dynocomp::eval::rates::run_case(&case, fs, &run).unwrap();
    let named = |a: &dynocomp::eval::rates::AxisScore| a.offline_predicted < OFFLINE_MUCH_BETTER * a.predicted_with_fit;
    for a in &res.axes {
        eprintln!(
            "axis {}: box {:.3} % (predicted {:.3} %), offline {:.3} % (predicted {:.3} %), named {}",
            a.axis,
            100.0 * a.comp_nrmse.clone().unwrap(),
            100.0 * a.predicted_with_fit,
            100.0 * a.offline_nrmse,
            100.0 * a.offline_predicted,
            named(a)
        );
    }
    for a in &res.axes {
        let ratio = a.offline_predicted / a.offline_nrmse;
        assert!((1.0 / 1.5..=1.5).contains(&ratio), "axis {}: offline predicted / measured {ratio:.2}", a.axis);
    }
    let y = &res.axes[1];
    assert!(named(y), "y not named for the smoother");
    assert!(y.offline_nrmse < 0.25 * y.comp_nrmse.clone().unwrap(), "y: the smoother gains less than 4x");
    for a in [&res.axes[0], &res.axes[2]] {
        assert!(a.offline_nrmse > 0.9 * a.comp_nrmse.clone().unwrap(), "control: axis {} gains offline", a.axis);
        assert!(!named(a), "control: axis {} named", a.axis);
        assert!(a.look_ahead.is_empty(), "control: axis {} looked further ahead", a.axis);
    }
    // Longer look-aheads (`design::look_ahead`): y's non-minimum-phase zero
    // at 846 Hz needs hundreds of samples; none up to 64 halves the box's
    // error, predicted or measured.
    let box_y = y.comp_nrmse.clone().unwrap();
    look_ahead_against_the_truth(y);
    assert_eq!(y.look_ahead.iter().map(|l| l.0).collect::<Vec<_>>(), [16, 32, 64]);
    for (l, p, m) in &y.look_ahead {
        assert!(*p > 0.5 * y.predicted_with_fit && *m > 0.5 * box_y, "y at {l}: {p} predicted, {m} measured");
    }
}

/// An axis's longer look-aheads against the truth: each prediction within
/// 0.8-1.25x of its f64 fixed-lag smoother's NRMSE, the scoring checked on
/// the box design's own f64 filter (within 1 % of the image's NRMSE).
/// Returns the shortest latency predicted to halve the box's error.
fn look_ahead_against_the_truth(a: &dynocomp::eval::rates::AxisScore) -> Option<usize> {
    let comp = a.comp_nrmse.clone().unwrap();
    eprintln!(
        "axis {}: box {:.3} % (f64 {:.3} %), look-ahead {:?}",
        a.axis,
        100.0 * comp,
        100.0 * a.box_f64_nrmse,
        a.look_ahead
    );
    assert!(
        (a.box_f64_nrmse / comp - 1.0).abs() < 0.01,
        "the f64 scoring is off the image's: {} against {comp}",
        a.box_f64_nrmse
    );
    for (l, p, m) in &a.look_ahead {
        assert!((0.8..=1.25).contains(&(p / m)), "axis {} at {l}: predicted {p} against {m} measured", a.axis);
    }
    a.look_ahead.iter().find(|(_, p, _)| *p < 0.5 * a.predicted_with_fit).map(|l| l.0)
}

/// Seed 26 (clustered machine modes, 10.24 kHz, 2 Hz lines), designed for
/// its cut's spectrum: the box leaves x at 17 % (its non-minimum-phase zero
/// near 775 Hz), `--offline` reaches 1 %. The design predicts that 32
/// samples (3.1 ms) would halve the box's error, and the f64 fixed-lag
/// smoother at 32 does (7.0 %); at 16, neither the prediction nor the
/// measurement halves it. Control: the box's own prediction is not within
/// 1.25x of the error at 32, so a copy of it would fail.
#[test]
fn seed_26_x_names_the_look_ahead_that_would_halve_the_box_error() {
    let (case, fs, kind) = draw(26);
    assert_eq!((kind, fs, case.frf_df_hz), ("machine-cluster", 10_240.0, 2.0), "the sweep's seed 26 changed");
    let run = RunOptions { force_spectrum: true, ..RunOptions::default() };
    let res = dynocomp::eval::rates::run_case(&case, fs, &run).unwrap();
    let x = &res.axes[0];
    let box_x = x.comp_nrmse.clone().unwrap();
    assert!(box_x > 0.1, "x: the box reaches {box_x}, no longer the case kept");
    assert_eq!(look_ahead_against_the_truth(x), Some(32));
    let at = |l: usize| x.look_ahead.iter().find(|t| t.0 == l).unwrap().2;
    assert!(at(32) < 0.5 * box_x, "32 samples measure {} against the box's {box_x}", at(32));
    assert!(at(16) > 0.5 * box_x, "16 samples measure {} against the box's {box_x}", at(16));
    assert!(!(0.8..=1.25).contains(&(x.predicted_with_fit / at(32))), "control: the box's prediction fits 32 too");
    for a in [&res.axes[1], &res.axes[2]] {
        assert!(a.look_ahead.is_empty(), "control: axis {} looked further ahead", a.axis);
    }
}
