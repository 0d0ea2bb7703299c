//! Maximum-likelihood refinement of a fitted pole-residue model.
//!
//! Vector fitting's poles are the fixed point of a linearized problem (the
//! zeros of σ(s)), not the minimum of the weighted output error: on a noisy
//! impact test they stay off the true modes by more than the lines allow
//! (BENCHMARKS.md, "A random-set-up sweep": with the true poles and residues
//! by least squares the model error was several times smaller). With the
//! coherence weights w = γ²/((1 − γ²)|H|²), the inverse variance of the H1
//! estimate up to a constant, the weighted output error
//!
//!   E(θ) = Σ_k w_k |Ĝ(j2πf_k; θ) − H_k|²
//!
//! is the negative log-likelihood of Gaussian line errors, and its minimum
//! over poles, residues and the direct term jointly is the maximum-likelihood
//! model of that order. [`refine`] runs Levenberg–Marquardt (Moré 1978:
//! scaled columns, the damping adapted by the gain of each step) on E from
//! the vector fit's model over the pairs' poles, every residue and the
//! direct term, and keeps every term identifiable (no pole leaves the set
//! [`super::spurious`] allows). The poles of the background terms (real
//! poles, pairs damped more than [`MAX_MODE_DAMPING`]) stay where the fit
//! put them.
//!
//! On the random-set-up sweep (300 axes) this took the axes within 1.3x of
//! the exact inverse's noise floor from 205 to 227 (BENCHMARKS.md, "A
//! random-set-up sweep").

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;
use std::f64::consts::PI;

use super::{spurious, PoleResidueModel, Term, MAX_MODE_DAMPING};

/// Most Levenberg–Marquardt iterations.
const MAX_ITERATIONS: usize = 40;
/// Relative decrease of E below which the iteration has converged.
const CONVERGED: f64 = 1e-10;

/// The model's parameters in normalized frequency (s/ω_s): each term's pole
/// (real p, or Re/Im of a pair's upper pole), then its residue (real r, or
/// Re/Im of a pair's ρ), then d.
#[derive(Clone)]
struct Params {
    x: Vec<f64>,
    /// Per term: whether it is a pair.
    pairs: Vec<bool>,
}

impl Params {
    fn from_model(m: &PoleResidueModel, w_scale: f64) -> Params {
        let mut poles = Vec::new();
        let mut residues = Vec::new();
        let mut pairs = Vec::new();
        for t in &m.terms {
            match *t {
                Term::Real { pole, residue } => {
                    poles.push(pole / w_scale);
                    residues.push(residue / w_scale);
                    pairs.push(false);
                }
                Term::Pair { pole, residue } => {
                    poles.extend([pole.re / w_scale, pole.im / w_scale]);
                    residues.extend([residue.re / w_scale, residue.im / w_scale]);
                    pairs.push(true);
                }
            }
        }
        let mut x = poles;
        x.extend(residues);
        x.push(m.d);
        Params { x, pairs }
    }

    /// Number of pole parameters (the residues follow them).
    fn n_poles(&self) -> usize {
        self.pairs.iter().map(|p| if *p { 2 } else { 1 }).sum()
    }

    fn to_model(&self, w_scale: f64) -> PoleResidueModel {
        let np = self.n_poles();
        let (mut i, mut terms) = (0, Vec::with_capacity(self.pairs.len()));
        for &pair in &self.pairs {
            if pair {
                terms.push(Term::Pair {
                    pole: Complex64::new(self.x[i], self.x[i + 1]) * w_scale,
                    residue: Complex64::new(self.x[np + i], self.x[np + i + 1]) * w_scale,
                });
                i += 2;
            } else {
                terms.push(Term::Real { pole: self.x[i] * w_scale, residue: self.x[np + i] * w_scale });
                i += 1;
            }
        }
        PoleResidueModel { terms, d: self.x[2 * np] }
    }
}

/// Weighted residuals sw_k (Ĝ(s_k) − H_k), real and imaginary parts
/// interleaved, and, if `jac` is given, their Jacobian (2K × params).
fn residuals(
    p: &Params,
    s: &[Complex64],
    h: &[Complex64],
    sw: &[f64],
    mut jac: Option<&mut DMatrix<f64>>,
) -> DVector<f64> {
    let np = p.n_poles();
    let k = s.len();
    let mut e = DVector::zeros(2 * k);
    for (row, ((&sk, hk), &w)) in s.iter().zip(h).zip(sw).enumerate() {
        let mut g = Complex64::new(p.x[2 * np], 0.0);
        let put = |col: usize, v: Complex64, jac: &mut Option<&mut DMatrix<f64>>| {
            if let Some(j) = jac.as_deref_mut() {
                j[(2 * row, col)] = w * v.re;
                j[(2 * row + 1, col)] = w * v.im;
            }
        };
        let mut i = 0;
        for &pair in &p.pairs {
            if pair {
                let pole = Complex64::new(p.x[i], p.x[i + 1]);
                let rho = Complex64::new(p.x[np + i], p.x[np + i + 1]);
                let a = 1.0 / (sk - pole);
                let b = 1.0 / (sk - pole.conj());
                g += rho * a + rho.conj() * b;
                let j = Complex64::new(0.0, 1.0);
                put(i, rho * a * a + rho.conj() * b * b, &mut jac);
                put(i + 1, j * rho * a * a - j * rho.conj() * b * b, &mut jac);
                put(np + i, a + b, &mut jac);
                put(np + i + 1, j * a - j * b, &mut jac);
                i += 2;
            } else {
                let a = 1.0 / (sk - p.x[i]);
                g += p.x[np + i] * a;
                put(i, p.x[np + i] * a * a, &mut jac);
                put(np + i, a, &mut jac);
                i += 1;
            }
        }
        put(2 * np, Complex64::new(1.0, 0.0), &mut jac);
        let r = (g - hk) * w;
        e[2 * row] = r.re;
        e[2 * row + 1] = r.im;
    }
    e
}

/// The maximum-likelihood model near `model` on the lines (`freq_hz`, `h`)
/// with weights `weights` (module doc): Levenberg–Marquardt over every
/// pole, residue and the direct term, from `model`. A step is taken only
/// if it lowers E and leaves every term identifiable on lines from `f_low`
/// to the last (no term [`spurious`] that was not so before, no pair
/// collapsing to a real pole, every pole stable). Returns `model` itself
/// where no step lowers E; an error only for lines it cannot use.
pub fn refine(
    freq_hz: &[f64],
    h: &[Complex64],
    weights: &[f64],
    model: &PoleResidueModel,
    f_low: f64,
) -> Result<PoleResidueModel> {
    if freq_hz.len() != h.len() || h.len() != weights.len() {
        bail!("refinement: {} lines, {} FRF values and {} weights", freq_hz.len(), h.len(), weights.len());
    }
    let f_top = freq_hz.iter().fold(0.0f64, |m, f| m.max(*f));
    if !(f_top > 0.0) || model.terms.is_empty() {
        return Ok(model.clone());
    }
    let w_scale = 2.0 * PI * f_top;
    let s: Vec<Complex64> = freq_hz.iter().map(|f| Complex64::new(0.0, 2.0 * PI * f / w_scale)).collect();
    let sw: Vec<f64> = weights.iter().map(|w| w.max(0.0).sqrt()).collect();
    let was_spurious: Vec<bool> = model.terms.iter().map(|t| spurious(t, f_low, f_top)).collect();
    let valid = |p: &Params| {
        let m = p.to_model(w_scale);
        m.is_stable()
            && p.x.iter().all(|v| v.is_finite())
            && m.terms.iter().zip(&was_spurious).all(|(t, was)| {
                *was || (!spurious(t, f_low, f_top) && !matches!(t, Term::Pair { pole, .. } if pole.im <= 0.0))
            })
    };
    let mut p = Params::from_model(model, w_scale);
    let n = p.x.len();
    // The background terms' poles (real poles, and pairs damped more than
    // a mode, MAX_MODE_DAMPING) stay where the fit put them: they stand for
    // the course of Ĝ below and above the lines (a corner near 0 Hz, the
    // modes above the band), which the lines barely identify. Moved, a
    // real pole followed the noise of the first lines and bent Ĝ at 0 Hz
    // (sweep seed 99 y: 0.8 → 2.4 % off there), and a pair at 85 Hz with
    // ζ = 0.91 went to 12 kHz, where the discrete model at 10.24 kHz could
    // no longer match it (seed 1006 y: the match 1.2e-3 → 2.6e-2).
    let mut fixed = vec![false; n];
    let mut i = 0;
    for t in &model.terms {
        let (background, width) = match *t {
            Term::Real { .. } => (true, 1),
            Term::Pair { pole, .. } => (-pole.re / pole.norm() > MAX_MODE_DAMPING, 2),
        };
        fixed[i..i + width].fill(background);
        i += width;
    }
    let mut jac = DMatrix::<f64>::zeros(2 * s.len(), n);
    let mut e = residuals(&p, &s, h, &sw, Some(&mut jac));
    let mut cost = e.norm_squared();
    if !cost.is_finite() {
        return Ok(model.clone());
    }
    let mut lambda = 1e-3;
    for _ in 0..MAX_ITERATIONS {
        // Columns scaled to unit norm (Moré's scaling): the damping then
        // acts alike on poles, residues and d.
        let norms: Vec<f64> = (0..n).map(|j| jac.column(j).norm().max(f64::MIN_POSITIVE)).collect();
        for (j, nj) in norms.iter().enumerate() {
            let scale = if fixed[j] { 0.0 } else { 1.0 / nj };
            jac.column_mut(j).scale_mut(scale);
        }
        let mut a = jac.tr_mul(&jac);
        let g = jac.tr_mul(&e);
        for j in (0..n).filter(|&j| fixed[j]) {
            a[(j, j)] = 1.0;
        }
        let mut stepped = None;
        while lambda < 1e12 {
            let mut damped = a.clone();
            for j in 0..n {
                damped[(j, j)] += lambda;
            }
            let Some(chol) = damped.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let delta = chol.solve(&(-&g));
            let mut trial = p.clone();
            for j in 0..n {
                trial.x[j] += delta[j] / norms[j];
            }
            if valid(&trial) {
                let e_trial = residuals(&trial, &s, h, &sw, None);
                let c = e_trial.norm_squared();
                if c < cost {
                    stepped = Some((trial, c));
                    lambda = (lambda / 3.0).max(1e-12);
                    break;
                }
            }
            lambda *= 4.0;
        }
        let Some((trial, c)) = stepped else { break };
        let gain = (cost - c) / cost;
        p = trial;
        cost = c;
        e = residuals(&p, &s, h, &sw, Some(&mut jac));
        if gain < CONVERGED {
            break;
        }
    }
    Ok(p.to_model(w_scale))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::vf::{coherence_weights, weighted_rms};

    /// Lines every `df` Hz to 4096 Hz of `truth` plus deterministic,
    /// pseudo-random complex noise of `noise` (absolute).
    fn lines(truth: &PoleResidueModel, df: f64, noise: f64, seed: u64) -> (Vec<f64>, Vec<Complex64>) {
        let mut st = seed;
        let mut next = || {
            st = st.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((st >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 3.464
        };
        let freq: Vec<f64> = (1..=(4096.0 / df) as usize).map(|k| k as f64 * df).collect();
        let h = freq.iter().map(|f| truth.frf(*f) + Complex64::new(next(), next()) * noise).collect();
        (freq, h)
    }

    fn truth() -> PoleResidueModel {
        let mut m = PoleResidueModel::from_modes(&[(310.0, 0.03, 0.12), (520.0, 0.04, -0.1), (2600.0, 0.02, 0.9)]);
        m.d = 1.0 - m.frf(0.0).re;
        m
    }

    /// Largest relative error of the poles of `m` against `truth`'s, pair by
    /// pair in frequency order.
    fn pole_error(m: &PoleResidueModel, truth: &PoleResidueModel) -> f64 {
        let poles = |m: &PoleResidueModel| {
            let mut v: Vec<Complex64> = m
                .terms
                .iter()
                .filter_map(|t| if let Term::Pair { pole, .. } = t { Some(*pole) } else { None })
                .collect();
            v.sort_by(|a, b| a.im.total_cmp(&b.im));
            v
        };
        let (a, b) = (poles(m), poles(truth));
        assert_eq!(a.len(), b.len());
        a.iter().zip(&b).map(|(x, y)| (x - y).norm() / y.norm()).fold(0.0, f64::max)
    }

    /// From poles off by 1-2 % (as vector fitting leaves them on a noisy
    /// test), the refinement returns to within the noise of the true
    /// poles on exact lines, and lowers the weighted error on noisy ones.
    /// Negative control: the residues refitted alone at the displaced poles
    /// stay far from the truth.
    #[test]
    fn the_refinement_moves_displaced_poles_back_to_the_truth() {
        let t = truth();
        let mut start = t.clone();
        for (k, term) in start.terms.iter_mut().enumerate() {
            if let Term::Pair { pole, .. } = term {
                *pole *= Complex64::new(1.0 + 0.01 * (k as f64 + 1.0), 0.005);
            }
        }
        let (freq, h) = lines(&t, 1.0, 0.0, 1);
        let w = coherence_weights(&h, None);
        let keep = vec![true; start.terms.len()];
        let control = crate::fit::vf::refit_kept(&freq, &h, &w, &start, &keep).unwrap();
        assert!(pole_error(&control, &t) > 5e-3, "control keeps the displaced poles");
        let refined = refine(&freq, &h, &w, &control, 1.0).unwrap();
        assert!(pole_error(&refined, &t) < 1e-7, "exact lines: poles {:.1e} off", pole_error(&refined, &t));
        assert!(weighted_rms(&refined, &freq, &h, &w) < 1e-7);
        assert!(weighted_rms(&control, &freq, &h, &w) > 1e-3, "control misfits the lines");

        let (freq, h) = lines(&t, 1.0, 0.01, 7);
        let w = coherence_weights(&h, None);
        let control = crate::fit::vf::refit_kept(&freq, &h, &w, &start, &keep).unwrap();
        let refined = refine(&freq, &h, &w, &control, 1.0).unwrap();
        assert!(weighted_rms(&refined, &freq, &h, &w) < weighted_rms(&control, &freq, &h, &w));
        assert!(pole_error(&refined, &t) < 2e-3, "noisy lines: poles {:.1e} off", pole_error(&refined, &t));
    }

    /// A step that would make a term spurious (here: damping driven below
    /// the least a real mode has, to follow a narrow spike) is not taken.
    #[test]
    fn no_step_makes_a_term_spurious() {
        let t = truth();
        let (freq, mut h) = lines(&t, 1.0, 0.0, 1);
        // A one-line spike at 1500 Hz and a pair the fit put there.
        h[1499] += Complex64::new(0.5, 0.0);
        let mut m = t.clone();
        m.terms.push(Term::Pair {
            pole: Complex64::new(-0.002 * 2.0 * PI * 1500.0, 2.0 * PI * 1500.0),
            residue: Complex64::new(0.0, -1.0),
        });
        let w = coherence_weights(&h, None);
        let refined = refine(&freq, &h, &w, &m, 1.0).unwrap();
        assert!(refined.terms.iter().all(|term| !spurious(term, 1.0, 4096.0)), "{:?}", refined.modes());
        assert!(weighted_rms(&refined, &freq, &h, &w) <= weighted_rms(&m, &freq, &h, &w));
    }

    /// The background terms' poles (a real pole, a pair damped more than a
    /// mode) stay where they were, while the modes' poles move to the
    /// lines; their residues are refined all the same.
    #[test]
    fn background_poles_stay_where_the_fit_put_them() {
        let t = truth();
        let (freq, h) = lines(&t, 1.0, 0.01, 3);
        let w = coherence_weights(&h, None);
        let mut start = t.clone();
        for term in start.terms.iter_mut() {
            if let Term::Pair { pole, .. } = term {
                *pole *= Complex64::new(1.01, 0.0);
            }
        }
        start.terms.push(Term::Real { pole: -2.0 * PI * 40.0, residue: 0.5 });
        let wn = 2.0 * PI * 9000.0;
        start.terms.push(Term::Pair {
            pole: Complex64::new(-0.9 * wn, wn * 0.19f64.sqrt()),
            residue: Complex64::new(100.0, 0.0),
        });
        let keep = vec![true; start.terms.len()];
        let start = crate::fit::vf::refit_kept(&freq, &h, &w, &start, &keep).unwrap();
        let refined = refine(&freq, &h, &w, &start, 1.0).unwrap();
        let pole = |t: &Term| match *t {
            Term::Real { pole, .. } => Complex64::new(pole, 0.0),
            Term::Pair { pole, .. } => pole,
        };
        for (a, b) in start.terms.iter().zip(&refined.terms) {
            let background = matches!(a, Term::Real { .. }) || -pole(a).re / pole(a).norm() > MAX_MODE_DAMPING;
            let moved = (pole(a) - pole(b)).norm() / pole(a).norm();
            if background {
                assert_eq!(pole(a), pole(b), "a background pole moved");
            } else {
                assert!(moved > 1e-3, "a mode's pole stayed: {moved:.1e}");
            }
        }
        assert!(weighted_rms(&refined, &freq, &h, &w) < weighted_rms(&start, &freq, &h, &w));
    }
}
