//! Sensor modes above the compensated band, fitted to both FRFs at once.
//!
//! Such a mode shows in the band only as the tail of its response, so either
//! FRF alone pins it poorly: each fit trades the mode's frequency and modal
//! share against the direct term d in its own way, and interpolating two
//! such fits misses the set-up at every state in between. A loss of
//! workpiece mass changes modal masses, not stiffness, so both states share
//! each mode's modal share and d; [`fit_above_band_jointly`] fits them once.

use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;
use std::f64::consts::PI;

use crate::design::two_state::model::TwoState;
use crate::fit::modes::{fn_hz, pole_at, residue_of_share};
use crate::fit::{PoleResidueModel, Term};

/// Largest relative growth of the weighted misfit over both FRFs at which
/// the joint fit is kept (rule step 3).
pub const JOINT_TOLERANCE: f64 = 0.01;
/// Sweeps of the one-parameter-at-a-time pole refinement.
pub const SWEEPS: usize = 3;
/// Golden-section steps per parameter and sweep (the bracket shrinks to
/// 0.618^20 ≈ 7e-5 of its width).
const STEPS: usize = 20;
/// Relative half-width of the frequency bracket in each step.
pub const FREQ_SPAN: f64 = 0.05;
/// Relative half-width of the damping bracket in each step.
pub const ZETA_SPAN: f64 = 0.5;
/// Largest condition number of the column-scaled least-squares matrix.
const MAX_COND: f64 = 1e6;

/// What the joint fit did with one sensor mode above the compensated band.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct AboveBandMode {
    /// Natural frequency in the first / second state's own fit (Hz).
    pub fn_hz: (f64, f64),
    /// The same in the joint fit (Hz).
    pub joint_fn_hz: (f64, f64),
    /// The axis's weighted misfit over both FRFs, joint fit over separate
    /// fits (the same for all of an axis's above-band modes).
    pub misfit_growth: f64,
    /// Whether the joint fit was kept (for all of an axis's above-band
    /// modes or for none).
    pub joint: bool,
}

/// Both FRFs on their common lines, with the square roots of their weights.
pub struct Lines<'a> {
    freq_hz: &'a [f64],
    h: [&'a [Complex64]; 2],
    sw: [Vec<f64>; 2],
}

impl<'a> Lines<'a> {
    /// `frfs`: (H, coherence weights) of the first and the second FRF.
    pub fn new(freq_hz: &'a [f64], frfs: [(&'a [Complex64], &'a [f64]); 2]) -> Self {
        let sw = frfs.map(|(_, w)| w.iter().map(|v| v.max(0.0).sqrt()).collect());
        Lines { freq_hz, h: [frfs[0].0, frfs[1].0], sw }
    }
}

/// The joint fit of `ts`, or `ts` unchanged when the axis has no sensor
/// mode above `band_hz`; with what became of each such mode.
///
/// What the states share: each mode's modal share (its static gain,
/// ρ·2jω_d/ω_n², the quantity [`TwoState::at`] interpolates) and the direct
/// term (the static compliance of the modes beyond the FRF); each mode's
/// frequency and damping may move by its own amount. This is the physics of
/// the interpolation rule (1/ω_n² linear in added mass at constant
/// stiffness); it does not assume that all sensor modes move alike.
///
/// **Rule (stated).** Only if the first-state model has sensor modes
/// ([`crate::fit::modes::sensor_mode_indices`], not background terms of the
/// fit, [`TwoState::is_background`]) above the compensated band:
/// 1. One weighted least-squares problem over both FRFs' lines (each with
///    the coherence weights of its fit): the above-band modes' modal shares
///    and d are common unknowns, as are the modal shares of terms both
///    states already carry alike (the shared machine modes); every other
///    term has its own modal share per state. The poles are fixed in it
///    (`solve`).
/// 2. Each above-band mode's natural frequency and damping ratio, per
///    state, are refined to minimize that problem's residual (golden-section
///    search, one parameter at a time, [`SWEEPS`] sweeps; frequency within
///    ±[`FREQ_SPAN`], damping within ×(1 ± [`ZETA_SPAN`]) of the current
///    value in each step).
/// 3. The same refinement without the common unknowns (each state its own
///    above-band shares and d) gives the separate fits' best misfit. The
///    joint fit is kept if its weighted misfit Σ w|Ĝ − H|² over both FRFs'
///    lines exceeds the separate fits' by at most [`JOINT_TOLERANCE`], every
///    solve is well conditioned and every pole stays stable; otherwise both
///    states keep their own fits (those of
///    [`crate::design::two_state::model::pair`]), and `design` says so.
///
/// The test is over all lines, not a window around the mode: a changed
/// static gain forced into a common share is absorbed by the other terms
/// and shows across the band. Where the FRFs are too noisy to tell, the
/// joint fit is kept: the data then cannot say it is wrong.
pub fn fit_above_band_jointly(ts: &TwoState, lines: &Lines, band_hz: (f64, f64)) -> (TwoState, Vec<AboveBandMode>) {
    let sensors = crate::fit::modes::sensor_mode_indices(&ts.before);
    let above: Vec<usize> = sensors
        .into_iter()
        .filter(|&i| {
            !ts.is_background(i) && matches!(ts.before.terms[i], Term::Pair { pole, .. } if fn_hz(pole) > band_hz.1)
        })
        .collect();
    if above.is_empty() {
        return (ts.clone(), Vec::new());
    }
    let n = ts.before.terms.len();
    // Common to both states: the shared machine modes' shares in both
    // refinements; the above-band modes' shares and d in the joint one only.
    let machine: Vec<bool> = (0..n).map(|i| ts.before.terms[i] == ts.after.terms[i]).collect();
    let common: Vec<bool> = (0..n).map(|i| machine[i] || above.contains(&i)).collect();
    let separate = refine(ts, lines, &machine, false, &above);
    let joint = refine(ts, lines, &common, true, &above);
    let growth = match (&separate, &joint) {
        (Some((_, cs)), Some((_, cj))) => cj / cs,
        _ => f64::NAN,
    };
    // NaN (a solve refused) keeps the fits apart.
    let kept = growth <= 1.0 + JOINT_TOLERANCE;
    let report = above
        .iter()
        .map(|&i| AboveBandMode {
            fn_hz: (pair_fn_hz(&ts.before, i), pair_fn_hz(&ts.after, i)),
            joint_fn_hz: joint
                .as_ref()
                .map_or((f64::NAN, f64::NAN), |(j, _)| (pair_fn_hz(&j.before, i), pair_fn_hz(&j.after, i))),
            misfit_growth: growth,
            joint: kept,
        })
        .collect();
    match joint {
        Some((j, _)) if kept => (j, report),
        _ => (ts.clone(), report),
    }
}

fn pair_fn_hz(m: &PoleResidueModel, i: usize) -> f64 {
    match m.terms[i] {
        Term::Pair { pole, .. } => fn_hz(pole),
        Term::Real { pole, .. } => pole.abs() / (2.0 * PI),
    }
}

/// The pole of natural frequency `f_hz` and damping ratio `zeta`.
fn pole_of(f_hz: f64, zeta: f64) -> Complex64 {
    pole_at(2.0 * PI * f_hz, zeta)
}

/// State `st` (0 before, 1 after) of `t`.
fn state(t: &TwoState, st: usize) -> &PoleResidueModel {
    if st == 0 {
        &t.before
    } else {
        &t.after
    }
}

fn state_mut(t: &mut TwoState, st: usize) -> &mut PoleResidueModel {
    if st == 0 {
        &mut t.before
    } else {
        &mut t.after
    }
}

/// Step 2 of the rule: the above-band poles refined, one parameter at a
/// time, each step keeping the better of the bracket's optimum and the
/// current value. `None` if a solve is ill-conditioned.
fn refine(ts: &TwoState, lines: &Lines, common: &[bool], common_d: bool, above: &[usize]) -> Option<(TwoState, f64)> {
    let (mut cur, mut best) = solve(ts, lines, common, common_d)?;
    for _ in 0..SWEEPS {
        for &i in above {
            for st in 0..2 {
                for which in 0..2 {
                    let Term::Pair { pole, .. } = state(&cur, st).terms[i] else { return None };
                    let (f, z) = (fn_hz(pole), -pole.re / pole.norm());
                    let with = |v: f64| {
                        let mut t = cur.clone();
                        let p = if which == 0 { pole_of(v, z) } else { pole_of(f, v) };
                        state_mut(&mut t, st).terms[i] = Term::Pair { pole: p, residue: Complex64::new(0.0, 0.0) };
                        t
                    };
                    let cost = |v: f64| solve(&with(v), lines, common, common_d).map_or(f64::INFINITY, |s| s.1);
                    let (lo, hi) = if which == 0 {
                        (f * (1.0 - FREQ_SPAN), f * (1.0 + FREQ_SPAN))
                    } else {
                        (z * (1.0 - ZETA_SPAN), (z * (1.0 + ZETA_SPAN)).min(0.5))
                    };
                    let v = golden(lo, hi, cost);
                    if let Some((t, c)) = solve(&with(v), lines, common, common_d) {
                        if c < best {
                            (cur, best) = (t, c);
                        }
                    }
                }
            }
        }
    }
    (cur.before.is_stable() && cur.after.is_stable()).then_some((cur, best))
}

/// The minimum of `cost` on [lo, hi] by golden-section search: the middle
/// of the final bracket after [`STEPS`] reductions.
fn golden(lo: f64, hi: f64, cost: impl Fn(f64) -> f64) -> f64 {
    let end = crate::numeric::search::golden_bracket(&mut |v| cost(v), lo, hi, STEPS);
    0.5 * (end.lo + end.hi)
}

/// Step 1 of the rule: the modal shares and d of both states for the
/// poles of `ts`, by weighted least squares over both FRFs (the shares of
/// the terms `common` marks, and d if `common_d`, one unknown for both
/// states); with the residual Σ w|Ĝ − H|² over both. `None` if the
/// column-scaled matrix's condition number exceeds [`MAX_COND`] or the
/// solution is not finite.
fn solve(ts: &TwoState, lines: &Lines, common: &[bool], common_d: bool) -> Option<(TwoState, f64)> {
    let cols = Columns::new(ts, common, common_d);
    let (a, b) = cols.system(ts, lines);
    let (x, residual) = scaled_least_squares(a, &b)?;
    let models = [&ts.before, &ts.after];
    let build = |st: usize| PoleResidueModel {
        terms: models[st]
            .terms
            .iter()
            .enumerate()
            .map(|(i, t)| match *t {
                Term::Pair { pole, .. } => {
                    let c = Complex64::new(x[cols.term[i][st]], x[cols.term[i][st] + 1]);
                    Term::Pair { pole, residue: residue_of_share(pole, c) }
                }
                Term::Real { pole, .. } => Term::Real { pole, residue: x[cols.term[i][st]] },
            })
            .collect(),
        d: x[cols.d[st]],
    };
    Some((TwoState { before: build(0), after: build(1) }, residual))
}

/// The unknowns of [`solve`]: the first column of each term in each state
/// (2 for a pair: the real and the imaginary part of its modal share; 1 for
/// a real pole's residue; the same column in both states for a common
/// term), and of d in each state.
struct Columns {
    term: Vec<[usize; 2]>,
    d: [usize; 2],
    count: usize,
}

impl Columns {
    fn new(ts: &TwoState, common: &[bool], common_d: bool) -> Self {
        let n = ts.before.terms.len();
        let mut term = vec![[0usize; 2]; n];
        let mut cols = 0;
        for i in 0..n {
            let width = if matches!(ts.before.terms[i], Term::Pair { .. }) { 2 } else { 1 };
            term[i][0] = cols;
            cols += width;
            term[i][1] = if common[i] {
                term[i][0]
            } else {
                cols += width;
                cols - width
            };
        }
        let d = [cols, if common_d { cols } else { cols + 1 }];
        Columns { term, d, count: d[1] + 1 }
    }

    /// The weighted system A x ≈ b over both FRFs' lines (real and
    /// imaginary parts as rows, each scaled by √w).
    fn system(&self, ts: &TwoState, lines: &Lines) -> (DMatrix<f64>, DVector<f64>) {
        let m = lines.freq_hz.len();
        let mut a = DMatrix::<f64>::zeros(4 * m, self.count);
        let mut b = DVector::<f64>::zeros(4 * m);
        for (st, model) in [&ts.before, &ts.after].iter().enumerate() {
            for (k, &f) in lines.freq_hz.iter().enumerate() {
                let (r, sw) = (2 * (st * m + k), lines.sw[st][k]);
                let s = Complex64::new(0.0, 2.0 * PI * f);
                let mut put = |c: usize, v: Complex64| {
                    a[(r, c)] += sw * v.re;
                    a[(r + 1, c)] += sw * v.im;
                };
                for (i, t) in model.terms.iter().enumerate() {
                    match *t {
                        Term::Pair { pole, .. } => {
                            // Shares c = 1 and c = j as residues ρ = c·ω_n²/(2jω_d).
                            let rho = residue_of_share(pole, Complex64::new(1.0, 0.0));
                            let basis = |q: Complex64| q / (s - pole) + q.conj() / (s - pole.conj());
                            put(self.term[i][st], basis(rho));
                            put(self.term[i][st] + 1, basis(rho * Complex64::i()));
                        }
                        Term::Real { pole, .. } => put(self.term[i][st], 1.0 / (s - pole)),
                    }
                }
                put(self.d[st], Complex64::new(1.0, 0.0));
                b[r] = sw * lines.h[st][k].re;
                b[r + 1] = sw * lines.h[st][k].im;
            }
        }
        (a, b)
    }
}

/// The least-squares solution of A x ≈ b with A's columns scaled to unit
/// norm, and its residual |A x − b|²; `None` if a column is zero or not
/// finite, the scaled matrix's condition number exceeds [`MAX_COND`] or the
/// solution is not finite.
///
/// It solves the normal equations of the column-scaled matrix (a few
/// columns against thousands of rows: far cheaper than an SVD of the tall
/// matrix, which the pole refinement would repeat hundreds of times); their
/// condition number is that of the tall matrix squared.
fn scaled_least_squares(mut a: DMatrix<f64>, b: &DVector<f64>) -> Option<(Vec<f64>, f64)> {
    let scale: Vec<f64> = (0..a.ncols()).map(|c| a.column(c).norm()).collect();
    if scale.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return None;
    }
    for (c, s) in scale.iter().enumerate() {
        a.column_mut(c).scale_mut(1.0 / s);
    }
    // No convergence within the iteration limit: no solution.
    let svd = crate::fit::linalg::svd(a.tr_mul(&a), "the joint two-state fit").ok()?;
    let (smax, smin) = (svd.singular_values.max(), svd.singular_values.min());
    if !(smin > 0.0 && smax / smin <= MAX_COND * MAX_COND) {
        return None;
    }
    let x = svd.solve(&a.tr_mul(b), 0.0).ok()?;
    let residual = (&a * &x - b).norm_squared();
    let x: Vec<f64> = x.iter().zip(&scale).map(|(v, s)| v / s).collect();
    if !(residual.is_finite() && x.iter().all(|v| v.is_finite())) {
        return None;
    }
    Some((x, residual))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The least squares recover a known pair of states exactly from
    /// noise-free FRFs (the shares and d common, the poles given), and the
    /// golden-section search finds a known minimum.
    #[test]
    fn the_joint_solve_recovers_known_states_and_golden_finds_a_minimum() {
        let before = PoleResidueModel {
            d: 0.01,
            ..PoleResidueModel::from_modes(&[(500.0, 0.03, -0.03), (2300.0, 0.025, 0.9), (4400.0, 0.045, 0.076)])
        };
        let after = PoleResidueModel {
            d: 0.01,
            ..PoleResidueModel::from_modes(&[(500.0, 0.03, -0.03), (2430.0, 0.025, 0.9), (4620.0, 0.045, 0.076)])
        };
        let freq: Vec<f64> = (1..=800).map(|k| k as f64 * 5.0).collect();
        let (h0, h1): (Vec<_>, Vec<_>) = freq.iter().map(|f| (before.frf(*f), after.frf(*f))).unzip();
        let w = vec![1.0; freq.len()];
        let lines = Lines::new(&freq, [(&h0, &w), (&h1, &w)]);
        let ts = TwoState { before: before.clone(), after: after.clone() };
        let (got, res) = solve(&ts, &lines, &[true, false, true], true).unwrap();
        assert!(res < 1e-20, "{res:e}");
        for (g, t) in [(&got.before, &before), (&got.after, &after)] {
            for f in [100.0, 2300.0, 3900.0] {
                assert!((g.frf(f) / t.frf(f) - 1.0).norm() < 1e-9, "{f}");
            }
        }
        let x = golden(0.0, 10.0, |v| (v - 3.7).powi(2));
        assert!((x - 3.7).abs() < 1e-3, "{x}");
    }
}
