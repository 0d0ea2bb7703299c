//! Each numerical stage of the design against an independent truth.

use dynocomp::design::discretize::{discretize, DiscreteModel, Discretization};
use dynocomp::design::kalman::{self, solve_filter_dare};
use dynocomp::fit::vf::{coherence_weights, vector_fit, VfOptions};
use dynocomp::fit::PoleResidueModel;
use dynocomp::numeric::lti::StateSpace;
use dynocomp::realize::modal::realize;
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;

/// A modal model with unit DC gain from (f_n Hz, ζ, weight) triples.
fn modal(modes: &[(f64, f64, f64)]) -> PoleResidueModel {
    PoleResidueModel::from_modes(modes)
}

#[test]
fn vector_fitting_recovers_known_modes_including_a_pair_closer_than_the_line_spacing() {
    // 1 Hz lines; two modes 0.6 Hz apart near 1.5 kHz, plus a machine mode
    // and the dynamometer mode
    let truth = modal(&[(310.0, 0.03, 0.08), (1500.0, 0.02, 0.05), (1500.6, 0.02, 0.04), (2600.0, 0.04, 0.83)]);
    let freq: Vec<f64> = (0..=4096).map(f64::from).collect();
    let h: Vec<Complex64> = freq.iter().map(|f| truth.frf(*f)).collect();
    let w = coherence_weights(&h, None);
    let fit = vector_fit(&freq, &h, &w, &VfOptions::default()).unwrap_or_else(|e| panic!("{e:#}"));
    // the fit reproduces the response to well below measurement accuracy
    let worst = freq.iter().zip(&h).map(|(f, g)| ((fit.model.frf(*f) - g) / g).norm()).fold(0.0, f64::max);
    assert!(worst < 1e-4, "worst relative fit error {worst:e}");
    // every pole is a real structural pole: no spurious lightly damped pair
    for (f, z) in fit.model.modes() {
        assert!(z >= 1e-3, "spurious lightly damped pole at {f:.1} Hz, ζ = {z:e}");
    }
    // the separate modes are recovered (the close pair as one or two poles
    // near 1500 Hz, whichever matches the data)
    for target in [310.0, 2600.0] {
        let near = fit.model.modes().iter().map(|m| (m.0 - target).abs()).fold(f64::INFINITY, f64::min);
        assert!(near < 0.5, "mode at {target} Hz not recovered (closest {near:.2} Hz away)");
    }
    assert!(fit.model.modes().iter().any(|m| (m.0 - 1500.3).abs() < 2.0), "close pair near 1500 Hz lost");
    assert!(fit.model.is_stable());
}

#[test]
fn filter_dare_matches_the_scalar_closed_form() {
    // P = a²P − a²P²/(P + r) + q  ⇔  P² + (r − a²r − q)P − q·r = 0
    for (a, q, r) in [(0.9f64, 0.5f64, 2.0f64), (1.0, 1e-3, 0.05), (0.2, 3.0, 1e-2)] {
        let b = r - a * a * r - q;
        let p_true = (-b + (b * b + 4.0 * q * r).sqrt()) / 2.0;
        let sol = solve_filter_dare(
            &DMatrix::from_element(1, 1, a),
            &DVector::from_element(1, 1.0),
            &DMatrix::from_element(1, 1, q),
            r,
        )
        .unwrap();
        assert!((sol.p[(0, 0)] - p_true).abs() < 1e-10 * p_true, "a={a} q={q} r={r}: {} vs {p_true}", sol.p[(0, 0)]);
    }
}

#[test]
fn random_walk_kalman_gain_matches_the_steady_state_formula() {
    // A pure gain sensor (G = 1, no modes) with a random-walk force: the
    // Kalman filter is the scalar one above with a = 1, and the compensator
    // is F̂[k] = F̂[k−1] + K (y[k] − F̂[k−1]) with K = P/(P + r).
    let model =
        DiscreteModel { fs_hz: 51_200.0, method: Discretization::Foh, terms: vec![], d: 1.0, fir: vec![], advance: 0 };
    let (q, r): (f64, f64) = (0.3, 0.05);
    let d = kalman::design(&model, q, r, 0).unwrap();
    let b = -q;
    let p = (-b + (b * b + 4.0 * q * r).sqrt()) / 2.0;
    let k = p / (p + r);
    assert!((d.compensator.d - k).abs() < 1e-12, "direct term {} vs K {k}", d.compensator.d);
    // its only pole is 1 − K
    assert!((d.closed_loop_radius - (1.0 - k)).abs() < 1e-12);
}

#[test]
fn realization_reproduces_the_dense_transfer_function() {
    // A compensator from a realistic model, with a fixed lag (nilpotent chain)
    // (the unit-circle fit: an advance and FIR taps make a longer delay chain)
    let model = modal(&[(250.0, 0.03, 0.1), (2300.0, 0.04, 0.9)]);
    let (dm, _) = discretize(&model, 51_200.0, Discretization::Fit, (0.0, 4000.0)).unwrap();
    assert!(dm.advance > 0 && !dm.fir.is_empty(), "the fit should use its advance and taps here");
    for lag in [0usize, 3, 6] {
        let d = kalman::design(&dm, 200.0, 0.05, lag).unwrap();
        let ss: &StateSpace = &d.compensator;
        let real = realize(ss).unwrap();
        let mut worst: f64 = 0.0;
        let mut peak: f64 = 0.0;
        for i in 0..=500 {
            let f = 25_600.0 * i as f64 / 500.0;
            let a = ss.freq_response(f, 51_200.0);
            peak = peak.max(a.norm());
            worst = worst.max((real.freq_response(f, 51_200.0) - a).norm());
        }
        // f64 realization error must be negligible against f32 rounding of
        // the coefficients (~6e-8) and the f32 verification limit (1e-4).
        assert!(worst < 1e-6 * peak, "lag {lag}: realization error {:.1e} of peak", worst / peak);
        assert!(real.fir.len() <= dynocomp_core::kernel::MAX_FIR);
    }
}

#[test]
fn white_noise_gain_is_exact_where_a_frequency_grid_is_not() {
    // H(z) = d + b·c/(z − a): Σ h_k² = d² + (b c)²/(1 − a²) (geometric series).
    for (a, b, c, d) in [(0.5f64, 1.0f64, 2.0f64, 0.3f64), (0.9996, 0.02, 1.0, 1.0), (-0.7, 1.0, -1.5, 0.0)] {
        let ss = StateSpace {
            a: DMatrix::from_element(1, 1, a),
            b: DVector::from_element(1, b),
            c: DVector::from_element(1, c),
            d,
        };
        let truth = (d * d + (b * c).powi(2) / (1.0 - a * a)).sqrt();
        let got = ss.white_noise_gain().unwrap();
        assert!((got - truth).abs() < 1e-9 * truth, "a={a}: {got} vs {truth}");
        // Negative control: the 512-point midpoint rule misses the narrow
        // peak of the pole at 0.9996 by more than 1 %.
        let grid = dynocomp::design::criterion::noise_gain(|f| ss.freq_response(f, 51_200.0), 51_200.0);
        if a > 0.999 {
            assert!((grid - truth).abs() > 1e-2 * truth, "grid {grid} vs {truth}");
        }
    }
    // An unstable A has no finite gain.
    let ss = StateSpace {
        a: DMatrix::from_element(1, 1, 1.01),
        b: DVector::from_element(1, 1.0),
        c: DVector::from_element(1, 1.0),
        d: 0.0,
    };
    assert!(ss.white_noise_gain().is_none());
}
