//! Cases kept from the random-set-up sweep (`examples/sweep.rs`,
//! `dynocomp::eval::sweep`), each against the simulator's truth.
//!
//! Seed 32 (default ranges, 25.6 kHz, 0.5 Hz lines): axis x's FRF starts
//! at 7 Hz. The order the fit would choose bends below that first coherent
//! line (13 % from its value there at 0 Hz), which no line constrains, and
//! the axis was refused ("not flat below the FRF's first coherent line").
//! Among the orders the lines cannot tell apart the fit now takes one that
//! is flat there (`vf::vector_fit_accepting`), and the axis is compensated.

use dynocomp::eval::rates::{score_sim, RunOptions};
use dynocomp::eval::sweep::draw;
use dynocomp::fit::vf::{coherence_weights, vector_fit};
use dynocomp::simulate::simulate_with;
use num_complex::Complex64;

/// Largest relative move of `g` from its value at `f_first` between
/// f_first/8 and 0 Hz (the design's static check, computed here anew).
fn move_below(g: impl Fn(f64) -> Complex64, f_first: f64) -> f64 {
    let g0 = g(f_first);
    (0..=200).map(|i| f_first / 8.0 * i as f64 / 200.0).map(|f| (g(f) - g0).norm() / g0.norm()).fold(0.0, f64::max)
}

#[test]
fn seed_32_x_gets_a_model_flat_below_its_first_coherent_line() {
    let (case, fs, kind) = draw(32);
    assert_eq!((kind, fs, case.frf_df_hz), ("default", 25_600.0, 0.5), "the sweep's seed 32 changed");
    let params = case.sim_params(fs);
    let s = simulate_with(case.seed, &params, case.dynamometer(&params).unwrap()).unwrap();
    let x = s.frf.axis(0).unwrap();
    // Control: the fit's own choice of order bends below the first coherent line.
    let coh = x.coherence.as_deref();
    let first = s.frf.freq_hz.iter().zip(coh.unwrap()).find(|(_, c)| **c >= 0.9).map(|(f, _)| *f).unwrap();
    let weights = coherence_weights(&x.frf, coh);
    let plain = vector_fit(&s.frf.freq_hz, &x.frf, &weights, &Default::default()).unwrap();
    let bend = move_below(|f| plain.model.frf(f), first);
    eprintln!("first coherent line {first} Hz; the fit's own order moves {:.1} % below it", 100.0 * bend);
    assert!(bend > 0.05, "control: the unconstrained choice should bend below {first} Hz, moved {bend}");
    // The design: compensated, better than raw, within 4x of the exact inverse's floor.
    let res = score_sim(case.name, &s, &RunOptions::default());
    let a = &res.axes[0];
    let e = a.comp_nrmse.clone().unwrap_or_else(|why| panic!("axis x refused: {why}"));
    eprintln!("x: {:.3} % (raw {:.3} %, floor {:.3} %)", 100.0 * e, 100.0 * a.raw_nrmse, 100.0 * a.noise_floor);
    assert!(e < 0.1 * a.raw_nrmse, "x: {e} against raw {}", a.raw_nrmse);
    assert!(e <= 4.0 * a.noise_floor, "x: {e} against the floor {}", a.noise_floor);
}
