//! Where a causal compensator is further from the force than the raw
//! measurement: a non-minimum-phase zero of the model Ĝ(s) in the
//! compensated band. A zero z = σ + jω with σ > 0 has no stable causal
//! inverse; the Kalman filter inverts |Ĝ| there but not its phase (it
//! reflects the zero to −σ + jω), and within a latency much shorter than
//! 1/σ the compensated system H·Ĝ is off the delay e^{−jωL/fs} by up to 2
//! near ω, where the raw measurement is off 1 by |Ĝ − 1|. The zero-phase
//! smoother of `compensate --offline` is not bound by causality.

use num_complex::Complex64;
use std::f64::consts::TAU;

use crate::fit::{PoleResidueModel, Term};
use crate::numeric::lti::StateSpace;

/// The zeros of `model` (rad/s), from its real modal realization (A, B, C,
/// d): a pair r/(s−p) + r̄/(s−p̄), p = σ + jω, r = a + jb, is the block
/// [[σ, ω], [−ω, σ]] with B = [1, 0]ᵀ and C = [2a, 2b]. With the relative
/// degree k the index of the first Markov parameter m_k (m₀ = d,
/// m_j = C·A^{j−1}·B) that is not negligible (|m_k|/ω_max^k above 1e-9 of
/// the largest of m₀..m₃ so scaled, ω_max the largest |pole|), the zeros
/// are the eigenvalues of A − B·m_k⁻¹·C·A^k but for the k of least modulus,
/// which are 0 (the zero dynamics; k = 0 is A − B·C/d). A fitted d is
/// often 1e-16 of the gain, so A − B·C/d alone would give zeros of noise.
/// Empty where the eigenvalue iteration fails.
pub fn zeros(model: &PoleResidueModel) -> Vec<Complex64> {
    let n: usize = model.terms.iter().map(|t| if matches!(t, Term::Pair { .. }) { 2 } else { 1 }).sum();
    if n == 0 || !model.d.is_finite() {
        return Vec::new();
    }
    let mut a = nalgebra::DMatrix::zeros(n, n);
    let mut b = nalgebra::DVector::zeros(n);
    let mut c = nalgebra::RowDVector::zeros(n);
    let mut i = 0;
    for t in &model.terms {
        match *t {
            Term::Real { pole, residue } => {
                a[(i, i)] = pole;
                b[i] = 1.0;
                c[i] = residue;
                i += 1;
            }
            Term::Pair { pole, residue } => {
                a[(i, i)] = pole.re;
                a[(i, i + 1)] = pole.im;
                a[(i + 1, i)] = -pole.im;
                a[(i + 1, i + 1)] = pole.re;
                b[i] = 1.0;
                c[i] = 2.0 * residue.re;
                c[i + 1] = 2.0 * residue.im;
                i += 2;
            }
        }
    }
    let w_max = model
        .terms
        .iter()
        .map(|t| match *t {
            Term::Real { pole, .. } => pole.abs(),
            Term::Pair { pole, .. } => pole.norm(),
        })
        .fold(1.0, f64::max);
    // C·A^j for j = 0..=3 and the Markov parameters m₀ = d, m_{j+1} = C·A^j·B.
    let mut ca = vec![c.clone()];
    for j in 0..3 {
        let next = &ca[j] * &a;
        ca.push(next);
    }
    let markov: Vec<f64> = std::iter::once(model.d).chain(ca.iter().take(3).map(|r| (r * &b)[0])).collect();
    let scaled: Vec<f64> = markov.iter().enumerate().map(|(k, m)| m.abs() / w_max.powi(k as i32)).collect();
    let top = scaled.iter().copied().fold(0.0, f64::max);
    let Some(k) = scaled.iter().position(|m| *m > 1e-9 * top) else { return Vec::new() };
    let m = if k == 0 { &a - &b * &c / model.d } else { &a - &b * &ca[k] / markov[k] };
    let Ok(mut ev) = crate::fit::linalg::eigenvalues(&m, "the zeros of the fitted model") else { return Vec::new() };
    ev.sort_by(|x, y| x.norm().total_cmp(&y.norm()));
    ev.split_off(k)
}

/// A non-minimum-phase zero of the model in the compensated band, and the
/// lines around it where the box output is further from the force than the
/// raw measurement ([`phase_limit`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhaseLimit {
    /// The zero: frequency |Im z|/2π and real part Re z/2π (Hz, > 0).
    pub zero_hz: (f64, f64),
    /// The first and last line around the zero where |H·Ĝ·e^{jωL/fs} − 1|
    /// > |Ĝ − 1| (Hz).
    pub worse_hz: (f64, f64),
    /// At the line of the largest excess there: |H·Ĝ·e^{jωL/fs} − 1| and |Ĝ − 1|.
    pub errors: (f64, f64),
}

/// The non-minimum-phase zeros of `model` within `band_hz`, each with the
/// lines around it (within ±10 % of its frequency, on a 0.5 Hz grid) where
/// the compensator `h` at latency `lag` samples (rate `fs_hz`) leaves the
/// model further from the delay than no compensation leaves it from 1.
/// Only zeros whose excess there exceeds 0.1 (10 % of the force at that
/// frequency) are returned.
pub fn phase_limit(
    model: &PoleResidueModel,
    h: &StateSpace,
    lag: usize,
    fs_hz: f64,
    band_hz: (f64, f64),
) -> Vec<PhaseLimit> {
    let mut out = Vec::new();
    for z in zeros(model) {
        let f0 = z.im / TAU;
        if !(z.re > 0.0 && f0 > 0.0 && f0 >= band_hz.0 && f0 <= band_hz.1) {
            continue;
        }
        let (lo, hi) = ((0.9 * f0).max(band_hz.0), (1.1 * f0).min(band_hz.1));
        let grid: Vec<f64> = (0..).map(|k| lo + 0.5 * k as f64).take_while(|f| *f <= hi).collect();
        let hs = h.freq_responses(&grid, fs_hz);
        let errors: Vec<(f64, f64, f64)> = grid
            .iter()
            .zip(&hs)
            .map(|(&f, hk)| {
                let g = model.frf(f);
                let delay = Complex64::from_polar(1.0, TAU * f * lag as f64 / fs_hz);
                (f, (hk * g * delay - 1.0).norm(), (g - 1.0).norm())
            })
            .collect();
        let worse: Vec<&(f64, f64, f64)> = errors.iter().filter(|e| e.1 > e.2).collect();
        let Some(peak) = worse.iter().max_by(|a, b| (a.1 - a.2).total_cmp(&(b.1 - b.2))) else { continue };
        if peak.1 - peak.2 <= 0.1 {
            continue;
        }
        out.push(PhaseLimit {
            zero_hz: (f0, z.re / TAU),
            worse_hz: (worse[0].0, worse[worse.len() - 1].0),
            errors: (peak.1, peak.2),
        });
    }
    out.sort_by(|a, b| a.zero_hz.0.total_cmp(&b.zero_hz.0));
    out
}

/// What `compensate` with the box filter says of one [`PhaseLimit`] of
/// axis `name` (the image's sidecar keeps them).
pub fn compensate_note(name: &str, p: &PhaseLimit) -> String {
    format!(
        "warning: axis {name}: from {:.0} to {:.0} Hz this image's output is further from the force than the raw \
         measurement (a non-minimum-phase zero of the model at {:.0} Hz, which no causal filter inverts); \
         `compensate --offline` does much better there",
        p.worse_hz.0, p.worse_hz.1, p.zero_hz.0
    )
}

/// The design's note on one [`PhaseLimit`] of axis `name` at latency `lag`
/// samples (rate `fs_hz`).
pub fn note(name: &str, p: &PhaseLimit, lag: usize, fs_hz: f64) -> String {
    let tau_ms = 1e3 / (TAU * p.zero_hz.1);
    format!(
        "WARNING: axis {name}: the model has a non-minimum-phase zero at {:.0} Hz (real part +{:.1} Hz), which no causal \
         compensator inverts: from {:.0} to {:.0} Hz the box output is further from the force than the raw measurement \
         (|H·Ĝ·e^(jωL) − 1| up to {:.2} where |Ĝ − 1| is {:.2}); a cut with its force there is compensated worse than not at \
         all, and the predicted errors, for a flat force spectrum, do not show it. A latency of the order of \
         1/(2π·{:.1} Hz) = {tau_ms:.1} ms ({:.0} samples, not {lag}) would be needed. `--force-prior spectrum \
         --force-record REC` (a representative cut) predicts for the cut's own spectrum, and refuses where compensation \
         does not pay; `compensate --offline`, not bound by causality, does much better there.",
        p.zero_hz.0,
        p.zero_hz.1,
        p.worse_hz.0,
        p.worse_hz.1,
        p.errors.0,
        p.errors.1,
        p.zero_hz.1,
        tau_ms * 1e-3 * fs_hz
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The zeros of a model built from known zeros: (s − z₁)(s − z̄₁)/((s − p₁)(s − p̄₁))
    /// written as d + pole-residue terms. Control: a minimum-phase zero is
    /// found with its negative real part.
    #[test]
    fn zeros_of_a_second_order_model_are_found() {
        for sigma in [30.0, -30.0] {
            let z = Complex64::new(sigma * TAU, 400.0 * TAU);
            let p = Complex64::new(-20.0 * TAU, 500.0 * TAU);
            // G = (s−z)(s−z̄)/((s−p)(s−p̄)) = 1 + r/(s−p) + r̄/(s−p̄),
            // r = (p−z)(p−z̄)/(p−p̄).
            let r = (p - z) * (p - z.conj()) / (p - p.conj());
            let m = PoleResidueModel { terms: vec![Term::Pair { pole: p, residue: r }], d: 1.0 };
            let g = |s: Complex64| (s - z) * (s - z.conj()) / ((s - p) * (s - p.conj()));
            let s = Complex64::new(0.0, TAU * 321.0);
            assert!((m.eval_s(s) - g(s)).norm() < 1e-9, "the model is G");
            let found = zeros(&m);
            assert_eq!(found.len(), 2);
            for w in [z, z.conj()] {
                assert!(found.iter().any(|f| (f - w).norm() < 1e-6 * w.norm()), "{found:?} lacks {w}");
            }
        }
    }

    /// A strictly proper model (d = 0, relative degree 2: two modes of
    /// shares summing to 1) has the zeros of its numerator, found with the
    /// zero dynamics of its second Markov parameter; d = 1e-16 (what a fit
    /// of exact data leaves) gives the same. Independent reference: the
    /// numerator's roots, s² + 2ζ̄ω̄s + ω̄² with the closed form of two modes.
    #[test]
    fn zeros_of_a_strictly_proper_model_are_found() {
        let (f1, z1, c1, f2, z2, c2) = (370.0, 0.05, 1.2, 422.0, 0.02, -0.2);
        let (w1, w2) = (TAU * f1, TAU * f2);
        // c1·w1²(s² + 2z2w2s + w2²) + c2·w2²(s² + 2z1w1s + w1²) = 0.
        let qa = c1 * w1 * w1 + c2 * w2 * w2;
        let qb = 2.0 * (c1 * w1 * w1 * z2 * w2 + c2 * w2 * w2 * z1 * w1);
        let qc = (c1 + c2) * w1 * w1 * w2 * w2;
        let disc = Complex64::new(qb * qb - 4.0 * qa * qc, 0.0).sqrt();
        let want = [(-qb + disc) / (2.0 * qa), (-qb - disc) / (2.0 * qa)];
        for d in [0.0, 1e-16] {
            let mut m = PoleResidueModel::from_modes(&[(f1, z1, c1), (f2, z2, c2)]);
            m.d = d;
            let found = zeros(&m);
            assert_eq!(found.len(), 2, "d = {d}: {found:?}");
            for w in want {
                assert!(found.iter().any(|f| (f - w).norm() < 1e-6 * w.norm()), "d = {d}: {found:?} lacks {w}");
            }
        }
    }
}
