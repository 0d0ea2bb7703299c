//! The paired modal models of one axis in two states ([`pair`]), and the
//! model in between ([`TwoState::at`]).

use anyhow::{bail, Result};
use num_complex::Complex64;

use crate::fit::modes::{fn_hz, modal_share, pole_at};
use crate::fit::{PoleResidueModel, Term};

/// Largest relative difference of the natural frequencies of two paired modes.
pub const PAIR_TOLERANCE: f64 = 0.15;

/// The paired models of one axis in its two states.
#[derive(Clone, Debug, PartialEq)]
pub struct TwoState {
    /// State 0 (before).
    pub before: PoleResidueModel,
    /// State 1 (after), its terms in the order of their partners in `before`.
    pub after: PoleResidueModel,
}

fn list(f: &[f64]) -> String {
    f.iter().map(|v| format!("{v:.0}")).collect::<Vec<_>>().join(", ")
}

/// Pair the modes of `before` and `after`; `axis` names the
/// axis in errors.
///
/// **Pairing (stated rule).** The complex pairs of the two fitted models are
/// sorted by natural frequency and matched in that order; the two models
/// must have as many pairs and as many real poles, and each matched pair's
/// natural frequencies may differ by at most [`PAIR_TOLERANCE`] (relative).
/// Otherwise pairing fails with a message naming the axis and the modes.
/// Real poles are matched in ascending order of their value. Machine-structure
/// modes that both FRFs measured alike are then shared
/// ([`crate::design::two_state::range::share_machine_modes`]), and sensor
/// modes above the compensated band fitted to both FRFs at once
/// ([`crate::design::two_state::joint`]).
pub fn pair(axis: &str, before: &PoleResidueModel, after: &PoleResidueModel) -> Result<TwoState> {
    type Split = (Vec<(Complex64, Complex64)>, Vec<(f64, f64)>);
    let split = |m: &PoleResidueModel| -> Split {
        let mut pairs = Vec::new();
        let mut reals = Vec::new();
        for t in &m.terms {
            match *t {
                Term::Pair { pole, residue } => pairs.push((pole, residue)),
                Term::Real { pole, residue } => reals.push((pole, residue)),
            }
        }
        pairs.sort_by(|a, b| a.0.norm().total_cmp(&b.0.norm()));
        reals.sort_by(|a, b| a.0.total_cmp(&b.0));
        (pairs, reals)
    };
    let (p0, r0) = split(before);
    let (p1, r1) = split(after);
    let f0: Vec<f64> = p0.iter().map(|p| fn_hz(p.0)).collect();
    let f1: Vec<f64> = p1.iter().map(|p| fn_hz(p.0)).collect();
    if p0.len() != p1.len() {
        bail!(
            "axis {axis}: cannot pair the modes of the two FRFs: the first has {} modes ({} Hz), the second {} ({} Hz); measure both states over the same band or fix --max-order",
            p0.len(),
            list(&f0),
            p1.len(),
            list(&f1)
        );
    }
    if r0.len() != r1.len() {
        bail!(
            "axis {axis}: cannot pair the two FRFs' models: {} real poles in the first, {} in the second",
            r0.len(),
            r1.len()
        );
    }
    for (a, b) in f0.iter().zip(&f1) {
        if ((b - a) / a).abs() > PAIR_TOLERANCE {
            bail!(
                "axis {axis}: cannot pair mode {a:.0} Hz (first FRF) with {b:.0} Hz (second FRF): {:+.1} % apart, more than ±{:.0} %",
                100.0 * (b / a - 1.0),
                100.0 * PAIR_TOLERANCE
            );
        }
    }
    let model = |pairs: &[(Complex64, Complex64)], reals: &[(f64, f64)], d: f64| PoleResidueModel {
        terms: pairs
            .iter()
            .map(|&(pole, residue)| Term::Pair { pole, residue })
            .chain(reals.iter().map(|&(pole, residue)| Term::Real { pole, residue }))
            .collect(),
        d,
    };
    Ok(TwoState { before: model(&p0, &r0, before.d), after: model(&p1, &r1, after.d) })
}

impl TwoState {
    /// The model at state s ∈ [0, 1] (0 = before, 1 = after): per pair,
    /// 1/ω_n² linear in s (linear in added mass at constant stiffness), the
    /// damping ratio ζ linear, and the residue linear as a modal share
    /// (ρ·2jω_d/ω_n², the r of r·ω²/(s² + 2ζωs + ω²): the static gain the mode
    /// contributes, which a change of mass keeps; interpolating ρ itself would
    /// bend the static gain by ~0.1 % in the middle of a 5 % shift); real poles
    /// and their residues linear; the direct term linear.
    pub fn at(&self, s: f64) -> PoleResidueModel {
        let lin = |a: f64, b: f64| a + s * (b - a);
        let terms = self
            .before
            .terms
            .iter()
            .zip(&self.after.terms)
            .map(|(a, b)| match (*a, *b) {
                (Term::Pair { pole: p0, residue: r0 }, Term::Pair { pole: p1, residue: r1 }) => {
                    let (w0, w1) = (p0.norm(), p1.norm());
                    let (z0, z1) = (-p0.re / w0, -p1.re / w1);
                    let w = 1.0 / lin(1.0 / (w0 * w0), 1.0 / (w1 * w1)).sqrt();
                    let z = lin(z0, z1);
                    let (c0, c1) = (modal_share(p0, r0), modal_share(p1, r1));
                    let pole = pole_at(w, z);
                    Term::Pair { pole, residue: (c0 + (c1 - c0) * s) * w * w / (2.0 * Complex64::i() * pole.im) }
                }
                (Term::Real { pole: p0, residue: r0 }, Term::Real { pole: p1, residue: r1 }) => {
                    Term::Real { pole: lin(p0, p1), residue: lin(r0, r1) }
                }
                _ => unreachable!("pair() orders both models alike"),
            })
            .collect();
        PoleResidueModel { terms, d: lin(self.before.d, self.after.d) }
    }
}
