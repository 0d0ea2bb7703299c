//! The seed paper's numerics (`--method paper`) against analytic truth:
//! RFP + Gauss–Newton on a known rational function, the companion form,
//! the continuous Riccati equation, Tustin with prewarping, band
//! construction.

use dynocomp::design::paper::{
    self, companion_form, continuous_response, observability, solve_filter_care, tustin_prewarped, ContinuousSs,
    PaperDiagnostics,
};
use dynocomp::fit::rfp::{poly_eval, poly_from_roots, rfp_fit, RationalTf, RfpOptions};
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;
use std::f64::consts::PI;

/// Two lightly damped modes, unit static gain: G(s) = Σ w_i ω_i²/(s² + 2ζ_iω_i s + ω_i²).
fn two_mode(s: Complex64) -> Complex64 {
    [(700.0, 0.03, 0.2), (2500.0, 0.05, 0.8)]
        .iter()
        .map(|&(f, z, w): &(f64, f64, f64)| {
            let wn = 2.0 * PI * f;
            w * wn * wn / (s * s + 2.0 * z * wn * s + wn * wn)
        })
        .sum()
}

fn true_poles() -> Vec<Complex64> {
    let mut p = Vec::new();
    for (f, z) in [(700.0f64, 0.03f64), (2500.0, 0.05)] {
        let wn = 2.0 * PI * f;
        p.push(Complex64::new(-z * wn, wn * (1.0 - z * z).sqrt()));
        p.push(Complex64::new(-z * wn, -wn * (1.0 - z * z).sqrt()));
    }
    p
}

#[test]
fn rfp_and_gauss_newton_recover_the_poles_of_a_known_rational_function() {
    let freq: Vec<f64> = (0..=4000).step_by(2).map(f64::from).collect();
    let h: Vec<Complex64> = freq.iter().map(|f| two_mode(Complex64::new(0.0, 2.0 * PI * f))).collect();
    let w = vec![1.0; freq.len()];
    let fit =
        rfp_fit(&freq, &h, &w, &RfpOptions { nb: 2, na: 4, ..Default::default() }).unwrap_or_else(|e| panic!("{e:#}"));
    for t in true_poles() {
        let near = fit.tf.poles().unwrap().iter().map(|p| (p - t).norm() / t.norm()).fold(f64::INFINITY, f64::min);
        assert!(near < 1e-6, "pole {t} not recovered (closest relative distance {near:e})");
    }
    let worst = freq.iter().zip(&h).map(|(f, g)| ((fit.tf.frf(*f) - g) / g).norm()).fold(0.0, f64::max);
    assert!(worst < 1e-6, "worst relative error {worst:e}");
    assert!(fit.rfp_condition.is_finite() && fit.rfp_condition < 1e8, "condition {}", fit.rfp_condition);
}

#[test]
fn gauss_newton_reduces_the_output_error_that_the_linearized_rfp_misweights() {
    // Noisy lines: Levy's linearized error weights lines by |A(s)|², which is
    // large at high frequency, so the RFP estimate is not the output-error
    // optimum; the damped Gauss–Newton step must lower the output error and
    // bring the resonance closer to the truth.
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let noise = Normal::new(0.0, 0.02).unwrap();
    let freq: Vec<f64> = (1..=4000).step_by(4).map(f64::from).collect();
    let h: Vec<Complex64> = freq
        .iter()
        .map(|f| {
            let g = two_mode(Complex64::new(0.0, 2.0 * PI * f));
            g * Complex64::new(1.0 + noise.sample(&mut rng), noise.sample(&mut rng))
        })
        .collect();
    let w = vec![1.0; freq.len()];
    let fit = rfp_fit(&freq, &h, &w, &RfpOptions { nb: 2, na: 4, ..Default::default() }).unwrap();
    assert!(fit.iterations >= 1);
    assert!(fit.final_error < 0.97 * fit.initial_error, "GN {} vs RFP {}", fit.final_error, fit.initial_error);
    // the output-error optimum is near the noise floor (2 % relative noise)
    assert!(fit.final_error < 0.03, "final error {}", fit.final_error);
}

#[test]
fn companion_form_has_the_transfer_function_of_eq_1() {
    let tf = RationalTf {
        b: vec![1.5, -0.3, 0.2],
        a: poly_from_roots(&[Complex64::new(-0.1, 0.8), Complex64::new(-0.1, -0.8), Complex64::new(-0.4, 0.0)]),
        omega_scale: 1.0,
    };
    let ss = companion_form(&tf);
    for w in [0.0, 0.3, 0.8, 2.0] {
        let x = Complex64::new(0.0, w);
        let direct = poly_eval(&tf.b, x) / poly_eval(&tf.a, x);
        let via_ss = continuous_response(&ss, w);
        assert!((direct - via_ss).norm() < 1e-12 * direct.norm().max(1.0), "ω={w}: {direct} vs {via_ss}");
    }
    // equal orders: a direct term
    let tf2 = RationalTf { b: vec![0.5, 0.1, 2.0], a: vec![0.5, 0.3, 1.0], omega_scale: 1.0 };
    let ss2 = companion_form(&tf2);
    assert_eq!(ss2.d, 2.0);
    let x = Complex64::new(0.0, 0.7);
    assert!((poly_eval(&tf2.b, x) / poly_eval(&tf2.a, x) - continuous_response(&ss2, 0.7)).norm() < 1e-12);
}

#[test]
fn observability_rank_drops_on_a_pole_zero_cancellation() {
    // (s'+0.5) cancels: a 3rd-order companion form with only 2 observable modes
    let tf = RationalTf {
        b: poly_from_roots(&[Complex64::new(-0.5, 0.0)]),
        a: poly_from_roots(&[Complex64::new(-0.5, 0.0), Complex64::new(-0.1, 0.9), Complex64::new(-0.1, -0.9)]),
        omega_scale: 1.0,
    };
    let ss = companion_form(&tf);
    let (rank, cond) = observability(&ss.a, &ss.c).unwrap();
    assert_eq!(rank, 2, "condition {cond:e}");
    // without the cancellation: full rank
    let tf = RationalTf { b: poly_from_roots(&[Complex64::new(-0.7, 0.0)]), ..tf };
    let (rank, _) = observability(&companion_form(&tf).a, &companion_form(&tf).c).unwrap();
    assert_eq!(rank, 3);
}

#[test]
fn continuous_riccati_matches_scalar_and_double_integrator_closed_forms() {
    // scalar: 2aP − P²/r + q = 0 ⇒ P = r(a + √(a² + q/r))
    for (a, q, r) in [(-1.0f64, 2.0f64, 0.5f64), (0.0, 1e-2, 3.0), (0.5, 10.0, 0.01)] {
        let sol = solve_filter_care(
            &DMatrix::from_element(1, 1, a),
            &DVector::from_element(1, 1.0),
            &DMatrix::from_element(1, 1, q),
            r,
        )
        .unwrap();
        let p = r * (a + (a * a + q / r).sqrt());
        assert!((sol.p[(0, 0)] - p).abs() < 1e-10 * p, "a={a}: {} vs {p}", sol.p[(0, 0)]);
    }
    // double integrator, position measured: P12 = √(qr), P11 = √2 r^¾ q^¼, P22 = √2 r^¼ q^¾
    let (q, r) = (4.0f64, 0.25f64);
    let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]);
    let c = DVector::from_column_slice(&[1.0, 0.0]);
    let qm = DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 0.0, q]);
    let sol = solve_filter_care(&a, &c, &qm, r).unwrap();
    let truth = [2f64.sqrt() * r.powf(0.75) * q.powf(0.25), (q * r).sqrt(), 2f64.sqrt() * r.powf(0.25) * q.powf(0.75)];
    for (got, want) in [sol.p[(0, 0)], sol.p[(0, 1)], sol.p[(1, 1)]].iter().zip(truth) {
        assert!((got - want).abs() < 1e-10 * want, "{got} vs {want}");
    }
    // an undetectable pair (unobserved unstable mode) is rejected
    let a = DMatrix::from_row_slice(2, 2, &[-1.0, 0.0, 0.0, 0.5]);
    let c = DVector::from_column_slice(&[1.0, 0.0]);
    assert!(solve_filter_care(&a, &c, &DMatrix::identity(2, 2), 1.0).is_err());
}

#[test]
fn tustin_with_prewarping_is_exact_at_the_prewarp_frequency_and_warps_elsewhere() {
    // a lightly damped resonance at 3 kHz sampled at 20 kHz (strong warping)
    let wn = 2.0 * PI * 3000.0;
    let ss = ContinuousSs {
        a: DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -wn * wn, -2.0 * 0.05 * wn]),
        b: DVector::from_column_slice(&[0.0, wn * wn]),
        c: DVector::from_column_slice(&[1.0, 0.0]),
        d: 0.1,
    };
    let fs = 20_000.0;
    let fp = 3000.0;
    let disc = tustin_prewarped(&ss, 1.0 / fs, 2.0 * PI * fp).unwrap();
    let hd = disc.freq_response(fp, fs);
    let hc = continuous_response(&ss, 2.0 * PI * fp);
    assert!((hd - hc).norm() < 1e-9 * hc.norm(), "{hd} vs {hc}");
    // elsewhere H_d(e^{jωT}) = H_c(j·k·tan(ωT/2)), k = ω_p/tan(ω_pT/2)
    let k = 2.0 * PI * fp / (PI * fp / fs).tan();
    for f in [100.0, 1500.0, 6000.0] {
        let warped = k * (PI * f / fs).tan();
        let (a, b) = (disc.freq_response(f, fs), continuous_response(&ss, warped));
        assert!((a - b).norm() < 1e-9 * b.norm(), "f={f}: {a} vs {b}");
        // and it is not exact there (the warping is real)
        assert!((a - continuous_response(&ss, 2.0 * PI * f)).norm() > 1e-6 * b.norm() || f < 200.0);
    }
    assert!(tustin_prewarped(&ss, 1.0 / fs, 2.0 * PI * 10_000.0).is_err(), "prewarp at Nyquist must be refused");
}

#[test]
fn paper_compensator_inverts_a_known_sensor_in_band() {
    // G(s) = ωn²/(s² + 2ζωn s + ωn²), 2 kHz, ζ = 0.05, in rescaled frequency.
    let w0 = 2.0 * PI * 4000.0;
    let wn = 2.0 * PI * 2000.0 / w0;
    let tf = RationalTf { b: vec![wn * wn], a: vec![wn * wn, 2.0 * 0.05 * wn, 1.0], omega_scale: w0 };
    let fs = 51_200.0;
    let mut diag = PaperDiagnostics::default();
    let d = paper::design(&tf, fs, 1e7, 0.05, 1000.0, &mut diag).unwrap_or_else(|e| panic!("{e:#}"));
    assert_eq!(diag.observability_rank, 3);
    assert!(diag.care_residual < 1e-8);
    // H·G ≈ 1 up to 1 kHz (the truth is the analytic G, not the design's model)
    for f in [50.0, 300.0, 1000.0] {
        let g = {
            let s = Complex64::new(0.0, 2.0 * PI * f / w0);
            tf.b[0] / (s * s + tf.a[1] * s + tf.a[0])
        };
        let e = (d.compensator.freq_response(f, fs) * g - 1.0).norm();
        assert!(e < 0.05, "f={f}: |HG − 1| = {e}");
    }
    // a too-small q cannot follow the force: error at 1 kHz is large
    let slow = paper::design(&tf, fs, 1e-6, 0.05, 1000.0, &mut diag).unwrap();
    let g = {
        let s = Complex64::new(0.0, 2.0 * PI * 1000.0 / w0);
        tf.b[0] / (s * s + tf.a[1] * s + tf.a[0])
    };
    assert!((slow.compensator.freq_response(1000.0, fs) * g - 1.0).norm() > 0.3);
}

/// The fit's refusals, word for word: orders, too few lines, an
/// ill-conditioned linear problem.
#[test]
fn rfp_refusals_word_for_word() {
    let freq: Vec<f64> = (0..200).map(|k| 10.0 * (k + 1) as f64).collect();
    let h: Vec<Complex64> = freq.iter().map(|&f| two_mode(Complex64::new(0.0, 2.0 * PI * f))).collect();
    let ones = vec![1.0; freq.len()];
    let few: Vec<f64> = (0..freq.len()).map(|k| if k < 5 { 1.0 } else { 0.0 }).collect();
    // Twenty lines within a millihertz: the powers of x are nearly equal columns.
    let close: Vec<f64> = (0..20).map(|k| 1000.0 + 5e-5 * k as f64).collect();
    let hc: Vec<Complex64> = close.iter().map(|&f| two_mode(Complex64::new(0.0, 2.0 * PI * f))).collect();
    let fit = |f: &[f64], h: &[Complex64], w: &[f64], nb, na| {
        rfp_fit(f, h, w, &RfpOptions { nb, na, ..Default::default() })
            .map(|_| "accepted".to_string())
            .unwrap_or_else(|e| format!("{e:#}"))
    };
    let cases = [
        (
            fit(&freq, &h, &ones, 0, 0),
            "--paper-orders 0:0: need 1 ≤ denominator order and numerator order ≤ denominator order",
        ),
        (
            fit(&freq, &h, &ones, 5, 4),
            "--paper-orders 5:4: need 1 ≤ denominator order and numerator order ≤ denominator order",
        ),
        (
            fit(&freq, &h, &few, 2, 4),
            "5 weighted lines cannot determine 7 coefficients of a 2:4 fit: widen the bands or lower the orders",
        ),
        (
            fit(&close, &hc, &[1.0; 20], 4, 6),
            "rational fraction polynomial fit 4:6 over 1000–1000 Hz is ill-conditioned: condition \
                number inf (limit 1e12); lower the orders or fit narrower bands (--band, --spindle-rpm)",
        ),
    ];
    let bad: Vec<String> =
        cases.iter().enumerate().filter(|(_, (g, w))| g != w).map(|(k, (g, _))| format!("case {k}: {g:?}")).collect();
    assert!(bad.is_empty(), "\n{}", bad.join("\n"));
}
