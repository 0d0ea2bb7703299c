//! Fitting a rational model G(s) to a measured FRF (DESIGN.md, step 1).
//!
//! The model is in real pole-residue form,
//! `G(s) = d + Σ_real r/(s − p) + Σ_pairs [r/(s − p) + r̄/(s − p̄)]`,
//! s in rad/s, G in N/N.

pub mod linalg;
pub mod line_noise;
pub mod matrix;
pub mod modes;
pub mod rank_one;
pub mod refine;
pub mod rfp;
pub mod seed;
pub mod vf;

use num_complex::Complex64;
use std::f64::consts::PI;

/// A pole of a fit in normalized frequency (rad/s over the fit's scale): a
/// real pole, or the representative (Im > 0) of a conjugate pair.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pole {
    pub(crate) p: Complex64,
    pub(crate) pair: bool,
}

/// One term of a pole-residue model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Term {
    /// A real pole `p` (rad/s, p < 0) with real residue `r` (rad/s).
    Real {
        /// Pole (rad/s).
        pole: f64,
        /// Residue (rad/s).
        residue: f64,
    },
    /// A complex-conjugate pair, represented by the pole with Im > 0.
    Pair {
        /// Pole with positive imaginary part (rad/s).
        pole: Complex64,
        /// Residue of `pole`; its conjugate belongs to the conjugate pole.
        residue: Complex64,
    },
}

/// A fitted sensor model G(s) in pole-residue form.
#[derive(Clone, Debug, PartialEq)]
pub struct PoleResidueModel {
    /// Pole-residue terms.
    pub terms: Vec<Term>,
    /// Direct term d (N/N).
    pub d: f64,
}

impl PoleResidueModel {
    /// The exact model of lightly damped modes given as (f_n Hz, ζ, share)
    /// triples, each share·ω²/(s² + 2ζωs + ω²) = ρ/(s − p) + c.c. with
    /// p = −ζω + jω_d, ρ = share·ω²/(2j·ω_d), ω_d = ω√(1 − ζ²).
    pub fn from_modes(modes: &[(f64, f64, f64)]) -> Self {
        let terms = modes
            .iter()
            .map(|&(f, z, share)| {
                let wn = 2.0 * PI * f;
                let wd = wn * (1.0 - z * z).sqrt();
                Term::Pair {
                    pole: Complex64::new(-z * wn, wd),
                    residue: Complex64::new(0.0, -share * wn * wn / (2.0 * wd)),
                }
            })
            .collect();
        PoleResidueModel { terms, d: 0.0 }
    }

    /// Model order (number of poles, counting a pair as two).
    pub fn order(&self) -> usize {
        self.terms.iter().map(|t| if matches!(t, Term::Real { .. }) { 1 } else { 2 }).sum()
    }

    /// G(s) at complex frequency `s` (rad/s).
    pub fn eval_s(&self, s: Complex64) -> Complex64 {
        let mut g = Complex64::new(self.d, 0.0);
        for t in &self.terms {
            match *t {
                Term::Real { pole, residue } => g += residue / (s - pole),
                Term::Pair { pole, residue } => g += residue / (s - pole) + residue.conj() / (s - pole.conj()),
            }
        }
        g
    }

    /// G(j·2π·f) at frequency `f_hz` (Hz).
    pub fn frf(&self, f_hz: f64) -> Complex64 {
        self.eval_s(Complex64::new(0.0, 2.0 * PI * f_hz))
    }

    /// Whether every pole has a negative real part.
    pub fn is_stable(&self) -> bool {
        self.terms.iter().all(|t| match t {
            Term::Real { pole, .. } => *pole < 0.0,
            Term::Pair { pole, .. } => pole.re < 0.0,
        })
    }

    /// Natural frequencies (Hz) and damping ratios of the pairs, ascending.
    pub fn modes(&self) -> Vec<(f64, f64)> {
        let mut m: Vec<(f64, f64)> = self
            .terms
            .iter()
            .filter_map(|t| match t {
                Term::Pair { pole, .. } => {
                    let wn = pole.norm();
                    Some((wn / (2.0 * PI), -pole.re / wn))
                }
                _ => None,
            })
            .collect();
        m.sort_by(|a, b| a.0.total_cmp(&b.0));
        m
    }
}

/// Damping below which a fitted pair is taken as spurious: no mounted
/// dynamometer or machine mode is that lightly damped (real ones: 1-6 %).
pub const MIN_MODE_DAMPING: f64 = 1e-3;
/// Largest damping ratio of a physical mode: a fitted pair more heavily
/// damped is a background term of the fit (the course of Ĝ below or above
/// the lines), not a mode.
pub const MAX_MODE_DAMPING: f64 = 0.2;
/// Near the band edge (above this fraction of f_max) a pair must be damped
/// at least [`EDGE_MODE_DAMPING`]: VF parks poles there to absorb the
/// truncation of out-of-band modes.
pub(crate) const EDGE_FRACTION: f64 = 0.97;
pub(crate) const EDGE_MODE_DAMPING: f64 = 5e-3;

/// The lowest identified line (Hz), the `f_low` of [`spurious`]: the first
/// line above 0 Hz, or `f_identified_hz` where that is higher (the impact
/// test's first coherent line).
pub(crate) fn lowest_identified_hz(freq_hz: &[f64], f_identified_hz: f64) -> f64 {
    freq_hz.iter().copied().find(|f| *f > 0.0).unwrap_or(0.0).max(f_identified_hz)
}

/// A term the data cannot identify (dropped by the fits' skim): a real pole or a
/// pair below the lowest identified line `f_low` (a near-integrator, or a
/// resonance no line saw, bending Ĝ where the mean force is), a pair damped
/// less than [`MIN_MODE_DAMPING`], or less than
/// [`EDGE_MODE_DAMPING`] above [`EDGE_FRACTION`] of `f_top` (Hz).
pub(crate) fn spurious(t: &Term, f_low: f64, f_top: f64) -> bool {
    match *t {
        Term::Real { pole, .. } => pole.abs() / (2.0 * PI) < f_low,
        Term::Pair { pole, .. } => {
            let wn = pole.norm();
            let zeta = -pole.re / wn;
            let f_n = wn / (2.0 * PI);
            f_n < f_low || zeta < MIN_MODE_DAMPING || (f_n > EDGE_FRACTION * f_top && zeta < EDGE_MODE_DAMPING)
        }
    }
}

/// Whether two pairs' poles (rad/s, Im > 0) are close modes: the damped
/// frequency of one lies within the other's half-power bandwidth,
/// |Im a − Im b| < max(−Re a, −Re b).
pub(crate) fn within_bandwidth(a: Complex64, b: Complex64) -> bool {
    (a.im - b.im).abs() < (-a.re).max(-b.re)
}

/// Relative RMS error of a model Ĝ(f) (f in Hz) against measured lines,
/// over the lines selected by `mask`: sqrt(mean(|Ĝ − G|² / |G|²)); NaN when
/// no line is selected.
pub fn relative_rms_error(model: impl Fn(f64) -> Complex64, freq_hz: &[f64], frf: &[Complex64], mask: &[bool]) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for ((f, g), m) in freq_hz.iter().zip(frf).zip(mask) {
        if *m && g.norm() > 0.0 {
            sum += (model(*f) - g).norm_sqr() / g.norm_sqr();
            n += 1;
        }
    }
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    }
}
