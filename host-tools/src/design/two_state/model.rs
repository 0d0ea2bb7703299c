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

/// Largest damping ratio of a physical mode ([`pair`]):
/// [`crate::fit::MAX_MODE_DAMPING`].
pub const PHYSICAL_MAX_ZETA: f64 = crate::fit::MAX_MODE_DAMPING;

/// Smallest |modal share| of a physical mode relative to the model's
/// largest ([`pair`]); a pair with less is a background term of the fit.
pub const PHYSICAL_MIN_SHARE: f64 = 1e-3;

/// Whether term `i` of `m` is a physical mode: a pair with ζ ≤
/// [`PHYSICAL_MAX_ZETA`] and |modal share| ≥ [`PHYSICAL_MIN_SHARE`] × the
/// largest pair's. Real poles and other pairs are the fit's background: the
/// static compliance beyond the band, the roll-off below it, and poles the
/// fit placed to absorb noise.
pub fn is_physical(m: &PoleResidueModel, i: usize) -> bool {
    let largest = m
        .terms
        .iter()
        .filter_map(|t| match *t {
            Term::Pair { pole, residue } => Some(modal_share(pole, residue).norm()),
            Term::Real { .. } => None,
        })
        .fold(0.0, f64::max);
    match m.terms[i] {
        Term::Pair { pole, residue } => {
            let zeta = -pole.re / pole.norm();
            zeta <= PHYSICAL_MAX_ZETA && modal_share(pole, residue).norm() >= PHYSICAL_MIN_SHARE * largest
        }
        Term::Real { .. } => false,
    }
}

/// The same term with a zero residue (a background term of the other state).
fn silenced(t: Term) -> Term {
    match t {
        Term::Pair { pole, .. } => Term::Pair { pole, residue: Complex64::new(0.0, 0.0) },
        Term::Real { pole, .. } => Term::Real { pole, residue: 0.0 },
    }
}

/// Pair the modes of `before` and `after`; `axis` names the axis in
/// errors. Every physical mode must find a partner: [`pair_fading`] with no
/// mode allowed to fade.
pub fn pair(axis: &str, before: &PoleResidueModel, after: &PoleResidueModel) -> Result<TwoState> {
    pair_fading(axis, before, after, &|_| false, f64::INFINITY)
}

/// Pair the modes of `before` and `after`; `axis` names the axis in errors;
/// `may_fade(f_hz)`: whether a physical mode at natural frequency `f_hz`
/// that has no partner in the other state may fade between the states;
/// `nyquist_hz`: fs/2 of the discrete models made of the states (infinite
/// for none).
///
/// **Pairing (stated rule).** Only physical modes are paired
/// ([`is_physical`]): those of each model are sorted by natural frequency
/// and matched in that order, the most partners whose natural frequencies
/// differ by at most [`PAIR_TOLERANCE`] (relative) and whose damped
/// frequencies lie on the same side of `nyquist_hz` (a discrete model holds
/// a mode below Nyquist as a state and one above in its FIR taps, so a pair
/// across it would change the state layout between the states), and among
/// those the least Σ |ln(f₁/f₀)|. A mode left without a partner is one the two fits
/// resolved differently: a machine mode one fit split and the other did
/// not, or a mode beyond the FRF that no line constrains. Where `may_fade`
/// allows it, it joins its state's background; otherwise pairing fails with
/// a message naming the axis, the modes without a partner and both models'
/// physical modes. The background terms (real poles, heavily damped or
/// negligible pairs) are not modes of the set-up that a change of mass
/// moves, and the two fits place them where each fit's noise led it: each
/// state keeps its own, and the other state carries them with a zero
/// residue, so that in between ([`TwoState::at`]) the first state's
/// background fades out as the second's fades in. Machine-structure modes
/// that both FRFs measured alike are then shared
/// ([`crate::design::two_state::range::share_machine_modes`]), and sensor
/// modes above the compensated band fitted to both FRFs at once
/// ([`crate::design::two_state::joint`]).
pub fn pair_fading(
    axis: &str,
    before: &PoleResidueModel,
    after: &PoleResidueModel,
    may_fade: &dyn Fn(f64) -> bool,
    nyquist_hz: f64,
) -> Result<TwoState> {
    let split = |m: &PoleResidueModel| -> (Vec<Term>, Vec<Term>) {
        let (mut modes, mut background) = (Vec::new(), Vec::new());
        for (i, t) in m.terms.iter().enumerate() {
            if is_physical(m, i) {
                modes.push(*t)
            } else {
                background.push(*t)
            }
        }
        modes.sort_by(|a, b| term_fn_hz(a).total_cmp(&term_fn_hz(b)));
        (modes, background)
    };
    let (m0, mut b0) = split(before);
    let (m1, mut b1) = split(after);
    let f0: Vec<f64> = m0.iter().map(term_fn_hz).collect();
    let f1: Vec<f64> = m1.iter().map(term_fn_hz).collect();
    let below = |m: &[Term]| -> Vec<bool> { m.iter().map(|t| damped_hz(t) < nyquist_hz).collect() };
    let matched = match_in_order(&f0, &f1, &below(&m0), &below(&m1));
    let (mut paired0, mut paired1) = (vec![false; f0.len()], vec![false; f1.len()]);
    for &(i, j) in &matched {
        (paired0[i], paired1[j]) = (true, true);
    }
    let lone = |paired: &[bool]| -> Vec<usize> { (0..paired.len()).filter(|&i| !paired[i]).collect() };
    let (lone0, lone1) = (lone(&paired0), lone(&paired1));
    let stuck0: Vec<f64> = lone0.iter().map(|&i| f0[i]).filter(|f| !may_fade(*f)).collect();
    let stuck1: Vec<f64> = lone1.iter().map(|&i| f1[i]).filter(|f| !may_fade(*f)).collect();
    if !stuck0.is_empty() || !stuck1.is_empty() {
        let side = |which: &str, other: &str, f: &[f64]| match f.len() {
            0 => String::new(),
            n => format!(
                " {which} FRF's {} Hz {} no partner within ±{:.0} % in the {other};",
                list(f),
                if n == 1 { "has" } else { "have" },
                100.0 * PAIR_TOLERANCE
            ),
        };
        bail!(
            "axis {axis}: cannot pair the modes of the two FRFs:{}{} modes {} Hz / {} Hz (pairs with ζ ≤ {PHYSICAL_MAX_ZETA} and a modal share ≥ {PHYSICAL_MIN_SHARE:e} of the largest); a mode in the compensated band must be seen in both states: measure both states over the same band with the same resolution, or fix --max-order",
            side("the first", "second", &stuck0),
            side("the second", "first", &stuck1),
            list(&f0),
            list(&f1)
        );
    }
    b0.extend(lone0.iter().map(|&i| m0[i]));
    b1.extend(lone1.iter().map(|&i| m1[i]));
    let before_terms =
        matched.iter().map(|m| m0[m.0]).chain(b0.iter().copied()).chain(b1.iter().map(|t| silenced(*t))).collect();
    let after_terms =
        matched.iter().map(|m| m1[m.1]).chain(b0.iter().map(|t| silenced(*t))).chain(b1.iter().copied()).collect();
    Ok(TwoState {
        before: PoleResidueModel { terms: before_terms, d: before.d },
        after: PoleResidueModel { terms: after_terms, d: after.d },
    })
}

/// The order-preserving matching of the sorted frequencies `f0` and `f1`
/// with the most pairs within [`PAIR_TOLERANCE`] on the same side of
/// Nyquist (`below0`, `below1`) and, among those, the least Σ |ln(f₁/f₀)|
/// (dynamic programming over both lists); the matched index pairs in order.
fn match_in_order(f0: &[f64], f1: &[f64], below0: &[bool], below1: &[bool]) -> Vec<(usize, usize)> {
    let (n, m) = (f0.len(), f1.len());
    // best[i][j]: (pairs, −cost) of the best matching of f0[i..] and f1[j..].
    let mut best = vec![vec![(0usize, 0.0f64); m + 1]; n + 1];
    let better = |a: (usize, f64), b: (usize, f64)| a.0 > b.0 || (a.0 == b.0 && a.1 > b.1);
    let close = |i: usize, j: usize| ((f1[j] - f0[i]) / f0[i]).abs() <= PAIR_TOLERANCE && below0[i] == below1[j];
    for i in (0..n).rev() {
        for j in (0..m).rev() {
            let mut b = best[i + 1][j];
            if better(best[i][j + 1], b) {
                b = best[i][j + 1];
            }
            if close(i, j) {
                let t = best[i + 1][j + 1];
                let with = (t.0 + 1, t.1 - (f1[j] / f0[i]).ln().abs());
                if better(with, b) {
                    b = with;
                }
            }
            best[i][j] = b;
        }
    }
    let mut out = Vec::new();
    let (mut i, mut j) = (0, 0);
    while i < n && j < m {
        if close(i, j) {
            let t = best[i + 1][j + 1];
            if best[i][j] == (t.0 + 1, t.1 - (f1[j] / f0[i]).ln().abs()) {
                out.push((i, j));
                i += 1;
                j += 1;
                continue;
            }
        }
        if best[i][j] == best[i + 1][j] {
            i += 1;
        } else {
            j += 1;
        }
    }
    out
}

/// Damped frequency of a pair, Im p/2π, and |p|/2π of a real pole (Hz):
/// where the discrete model's fit ([`crate::design::discretize`]) compares
/// it with Nyquist.
fn damped_hz(t: &Term) -> f64 {
    match *t {
        Term::Pair { pole, .. } => pole.im / (2.0 * std::f64::consts::PI),
        Term::Real { pole, .. } => pole.abs() / (2.0 * std::f64::consts::PI),
    }
}

/// Natural frequency of a term (Hz): |p|/2π.
pub fn term_fn_hz(t: &Term) -> f64 {
    match *t {
        Term::Pair { pole, .. } => fn_hz(pole),
        Term::Real { pole, .. } => pole.abs() / (2.0 * std::f64::consts::PI),
    }
}

impl TwoState {
    /// Two states as [`pair`] made them, checked again (a model sidecar read
    /// back): as many terms of the same kinds in the same order, and each
    /// pair's partner within [`PAIR_TOLERANCE`] of its frequency (a
    /// background pair's partner is the same pole).
    pub fn checked(axis: &str, before: PoleResidueModel, after: PoleResidueModel) -> Result<TwoState> {
        if before.terms.len() != after.terms.len() {
            bail!("axis {axis}: the two states have {} and {} terms", before.terms.len(), after.terms.len());
        }
        for (a, b) in before.terms.iter().zip(&after.terms) {
            let ok = match (*a, *b) {
                (Term::Pair { pole: p0, .. }, Term::Pair { pole: p1, .. }) => {
                    ((fn_hz(p1) - fn_hz(p0)) / fn_hz(p0)).abs() <= PAIR_TOLERANCE
                }
                (Term::Real { .. }, Term::Real { .. }) => true,
                _ => false,
            };
            if !ok {
                bail!(
                    "axis {axis}: the two states' terms at {:.0} Hz and {:.0} Hz are not partners",
                    term_fn_hz(a),
                    term_fn_hz(b)
                );
            }
        }
        Ok(TwoState { before, after })
    }

    /// Whether term `i` is a background term of one state ([`pair`]): the
    /// same pole in both states and a zero residue in one.
    pub fn is_background(&self, i: usize) -> bool {
        match (self.before.terms[i], self.after.terms[i]) {
            (Term::Pair { pole: p0, residue: r0 }, Term::Pair { pole: p1, residue: r1 }) => {
                p0 == p1 && (r0.norm() == 0.0 || r1.norm() == 0.0)
            }
            (Term::Real { pole: p0, residue: r0 }, Term::Real { pole: p1, residue: r1 }) => {
                p0 == p1 && (r0 == 0.0 || r1 == 0.0)
            }
            _ => false,
        }
    }
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
