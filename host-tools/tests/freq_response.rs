//! The compensator's frequency response on a grid (`StateSpace::freq_responses`,
//! a Hessenberg reduction once, then O(n²) per point) against an analytic
//! truth: A = T·diag(λ)·T⁻¹ with known poles, so H(z) = Σ (cᵀT)ᵢ(T⁻¹b)ᵢ/(z − λᵢ) + d
//! exactly, independent of either solver. The per-point LU
//! (`freq_response`) is held to the same truth.

use dynocomp::numeric::lti::StateSpace;
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;

/// Deterministic values in [-1, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// A system with real poles `poles`, a random similarity T = I + 0.3·R
/// (well conditioned, not orthogonal), and its analytic response.
fn system(poles: &[f64], seed: u64) -> (StateSpace, impl Fn(Complex64) -> Complex64) {
    let n = poles.len();
    let mut g = Lcg(seed);
    let t = DMatrix::<f64>::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 } + 0.3 * g.next() / (n as f64).sqrt());
    let t_inv = t.clone().try_inverse().expect("T invertible");
    let a = &t * DMatrix::from_diagonal(&DVector::from_column_slice(poles)) * &t_inv;
    let b = DVector::<f64>::from_fn(n, |_, _| g.next());
    let c = DVector::<f64>::from_fn(n, |_, _| g.next());
    let d = 0.25;
    let ct = t.transpose() * &c;
    let bt = &t_inv * &b;
    let p = poles.to_vec();
    let truth = move |z: Complex64| (0..n).map(|i| ct[i] * bt[i] / (z - p[i])).sum::<Complex64>() + d;
    (StateSpace { a, b, c, d }, truth)
}

/// Largest |H − truth| over the grid, relative to max |truth|.
fn worst_error(h: &[Complex64], truth: &dyn Fn(Complex64) -> Complex64, freqs: &[f64], fs: f64) -> f64 {
    let t: Vec<Complex64> =
        freqs.iter().map(|f| truth(Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f / fs))).collect();
    let peak = t.iter().map(|v| v.norm()).fold(0.0, f64::max);
    h.iter().zip(&t).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max) / peak
}

#[test]
fn grid_response_matches_the_analytic_response() {
    let fs = 10_240.0;
    let freqs: Vec<f64> = (0..=997).map(|i| 0.5 * fs * i as f64 / 997.0).collect();
    for (n, seed) in [(1usize, 1u64), (2, 2), (7, 3), (30, 4), (45, 5)] {
        // Poles spread over (−0.95, 0.999): one close to z = 1, where the
        // response peaks sharply near f = 0.
        let poles: Vec<f64> = (0..n).map(|i| if i == 0 { 0.999 } else { -0.95 + 1.9 * i as f64 / n as f64 }).collect();
        let (ss, truth) = system(&poles, seed);
        let grid = ss.freq_responses(&freqs, fs);
        let lu: Vec<Complex64> = freqs.iter().map(|f| ss.freq_response(*f, fs)).collect();
        let e_grid = worst_error(&grid, &truth, &freqs, fs);
        let e_lu = worst_error(&lu, &truth, &freqs, fs);
        eprintln!("n = {n}: grid {e_grid:.1e}, LU {e_lu:.1e}");
        assert!(e_grid < 1e-11, "n = {n}: Hessenberg grid response {e_grid:.1e} from the analytic one");
        assert!(e_lu < 1e-11, "n = {n}: per-point LU {e_lu:.1e} from the analytic one");
        // Negative control: a pole moved by 1e-12 is seen at this tolerance.
        let mut moved = poles.clone();
        moved[0] -= 1e-12;
        let (ss_moved, _) = system(&moved, seed);
        let e_moved = worst_error(&ss_moved.freq_responses(&freqs, fs), &truth, &freqs, fs);
        eprintln!("n = {n}: pole moved 1e-12: {e_moved:.1e}");
        assert!(e_moved > 1e-10, "n = {n}: a pole moved by 1e-12 went unseen ({e_moved:.1e})");
    }
}

#[test]
fn a_pole_on_the_grid_gives_nan_not_a_number_that_looks_right() {
    // A pole at z = −1 (f = fs/2) and one at z = 1 (f = 0): zI − A is singular there.
    let (ss, _) = system(&[1.0, 0.5, -1.0], 9);
    let h = ss.freq_responses(&[0.0, 1000.0, 5120.0], 10_240.0);
    assert!(h[1].is_finite(), "off the poles the response is finite: {}", h[1]);
    for (i, f) in [(0usize, 0.0), (2, 5120.0)] {
        // Rounding may leave the pivot a few ulps from zero: then the
        // response is huge rather than NaN. Either says "singular".
        assert!(!h[i].is_finite() || h[i].norm() > 1e12, "at {f} Hz, on a pole: {}", h[i]);
    }
    // An empty state: only the direct term.
    let d_only = StateSpace { a: DMatrix::zeros(0, 0), b: DVector::zeros(0), c: DVector::zeros(0), d: 0.5 };
    assert_eq!(d_only.freq_responses(&[0.0, 100.0], 1000.0), vec![Complex64::new(0.5, 0.0); 2]);
}

/// The 3x3 compensator's grid response, entry by entry, against the same
/// analytic truth: a 3-input, 3-output system A = T·diag(λ)·T⁻¹ whose entry
/// (i, j) is Σ_k (C T)_ik (T⁻¹ B)_kj / (z − λ_k) + D_ij. Negative control: a
/// pole moved by 1e-9 shows.
#[test]
fn the_3x3_grid_response_matches_the_analytic_response() {
    use dynocomp::numeric::lti::MimoStateSpace;
    let fs = 25_600.0;
    let freqs: Vec<f64> = (0..=400).map(|i| 0.5 * fs * i as f64 / 400.0).collect();
    let n = 12;
    let poles: Vec<f64> = (0..n).map(|i| if i == 0 { 0.999 } else { -0.9 + 1.8 * i as f64 / n as f64 }).collect();
    let mut g = Lcg(9);
    let t = DMatrix::<f64>::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 } + 0.3 * g.next() / (n as f64).sqrt());
    let t_inv = t.clone().try_inverse().expect("T invertible");
    let build = |poles: &[f64]| &t * DMatrix::from_diagonal(&DVector::from_column_slice(poles)) * &t_inv;
    let b = DMatrix::<f64>::from_fn(n, 3, |_, _| g.next());
    let c = DMatrix::<f64>::from_fn(3, n, |_, _| g.next());
    let d = DMatrix::<f64>::from_fn(3, 3, |i, j| 0.1 * (i + 2 * j) as f64);
    let (ct, bt) = (&c * &t, &t_inv * &b);
    let truth = |i: usize, j: usize, z: Complex64| {
        (0..n).map(|k| ct[(i, k)] * bt[(k, j)] / (z - poles[k])).sum::<Complex64>() + d[(i, j)]
    };
    let ss = MimoStateSpace { a: build(&poles), b: b.clone(), c: c.clone(), d: d.clone() };
    let h = ss.freq_responses(&freqs, fs);
    let mut moved = poles.clone();
    moved[0] += 1e-9;
    let h_moved = MimoStateSpace { a: build(&moved), b, c, d: d.clone() }.freq_responses(&freqs, fs);
    for i in 0..3 {
        for j in 0..3 {
            let entry: Vec<Complex64> = h.iter().map(|m| m[(i, j)]).collect();
            let e = worst_error(&entry, &|z| truth(i, j, z), &freqs, fs);
            assert!(e < 1e-11, "entry ({i}, {j}): {e:.1e} from the analytic response");
            let wrong: Vec<Complex64> = h_moved.iter().map(|m| m[(i, j)]).collect();
            assert!(
                worst_error(&wrong, &|z| truth(i, j, z), &freqs, fs) > 1e-8,
                "entry ({i}, {j}): a moved pole is invisible"
            );
        }
    }
}

/// The 3x3 white-noise gains against the impulse responses summed directly
/// (Parseval: Σ_j Σ_k h_ij[k]², each input's impulse simulated apart).
#[test]
fn the_3x3_white_noise_gains_are_the_impulse_responses_energy() {
    use dynocomp::numeric::lti::MimoStateSpace;
    let mut g = Lcg(21);
    let n = 6;
    let a = DMatrix::<f64>::from_fn(n, n, |i, j| if i == j { 0.9 - 0.1 * i as f64 } else { 0.02 * g.next() });
    let ss = MimoStateSpace {
        a,
        b: DMatrix::from_fn(n, 3, |_, _| g.next()),
        c: DMatrix::from_fn(3, n, |_, _| g.next()),
        d: DMatrix::from_fn(3, 3, |_, _| g.next()),
    };
    let gains = ss.white_noise_gains().expect("stable");
    let mut energy = [0.0f64; 3];
    for j in 0..3 {
        let input: Vec<DVector<f64>> =
            (0..2000).map(|k| DVector::from_fn(3, |i, _| if k == 0 && i == j { 1.0 } else { 0.0 })).collect();
        for y in ss.simulate(&input) {
            for i in 0..3 {
                energy[i] += y[i] * y[i];
            }
        }
    }
    for i in 0..3 {
        assert!(
            (gains[i] - energy[i].sqrt()).abs() < 1e-9 * gains[i],
            "output {i}: {} against {}",
            gains[i],
            energy[i].sqrt()
        );
    }
    // Negative control: an unstable system has no gain (its Gramian's norm
    // overflows before its entries do; that must not read as convergence),
    // nor has its SISO part.
    let mut bad = ss.clone();
    bad.a[(0, 0)] = 1.01;
    assert!(bad.white_noise_gains().is_none());
    let siso = StateSpace { a: bad.a.clone(), b: bad.b.column(0).into_owned(), c: bad.c.row(0).transpose(), d: 0.0 };
    assert!(siso.white_noise_gain().is_none(), "SISO: {:?}", siso.white_noise_gain());
}
