//! The sampled-data relation of the 3x3 model ([`discretize_matrix`]; the
//! per-axis relation is [`crate::design::discretize`]), and its realization
//! as the plant of the Kalman design ([`plant_states`]).

use anyhow::{bail, Result};
use nalgebra::{Cholesky, DMatrix, DVector, Matrix3, SVD};
use num_complex::Complex64;
use serde::Serialize;
use std::f64::consts::PI;

use crate::design::discretize::{
    columns_at, fit_grid, MATCH_BAND_FRACTION, MATCH_SLACK, MATCH_TARGET, MAX_ADVANCE, MAX_CONDITION, MAX_FIR_TAPS,
    MAX_TERM_GAIN_RATIO, OUT_OF_BAND_WEIGHT,
};
use crate::fit::linalg::{sweeps, symmetric_eigenvalues, SVD_RECONSTRUCTION_TOL};
use crate::fit::matrix::MatrixModel;

/// A 3x3 complex matrix (an FRF matrix or a residue).
pub type CMatrix3 = Matrix3<Complex64>;

/// Largest force-error bound of the residues' dropped rank ([`plant_states`]):
/// a tenth of the discrete model's [`MATCH_TARGET`].
pub const RANK_TOL: f64 = 1e-4;

/// Largest accepted error of the plant's realization against the pole-residue
/// form (max_f ‖Ĝ⁻¹ΔM‖_F): the rank bound plus rounding.
pub const MAX_REALIZATION_ERROR: f64 = 2.0 * RANK_TOL;

/// The discrete 3x3 model: input F_k (N, x/y/z), output y_k (N).
///
/// With the common poles mapped exactly, ζ = e^{pT} (those below Nyquist),
/// every entry has the form of the per-axis model,
///
/// Ĝ_d(z) = z^D·M(z),  M(z) = d + Σ_real R/(z − ζ) + Σ_pairs [R/(z − ζ) + R̄/(z − ζ̄)] + Σ_{m=1..M} h_m z^{−m},
///
/// with 3x3 residues R, direct term d and taps h_m, and one advance D and
/// one tap count M for all nine entries (one state layout), fitted by
/// [`discretize_matrix`].
#[derive(Clone, Debug)]
pub struct DiscreteMatrixModel {
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Poles ζ (|ζ| < 1; the one with Im > 0 for a pair) and whether each is a pair.
    pub poles: Vec<(Complex64, bool)>,
    /// Residue of each pole (real for a real pole), N/N.
    pub residues: Vec<CMatrix3>,
    /// Direct term d (N/N).
    pub d: Matrix3<f64>,
    /// Taps h_1..h_M (N/N) on F_{k−1}..F_{k−M}.
    pub fir: Vec<Matrix3<f64>>,
    /// Advance D (samples).
    pub advance: usize,
}

impl DiscreteMatrixModel {
    /// The causal part M(z) at a complex point z.
    pub fn causal_z(&self, z: Complex64) -> CMatrix3 {
        let mut g = self.d.map(|v| Complex64::new(v, 0.0));
        for ((zeta, pair), r) in self.poles.iter().zip(&self.residues) {
            g += r / (z - zeta);
            if *pair {
                g += r.conjugate() / (z - zeta.conj());
            }
        }
        let zi = z.inv();
        let mut zm = zi;
        for h in &self.fir {
            g += h.map(|v| Complex64::new(v, 0.0)) * zm;
            zm *= zi;
        }
        g
    }

    /// Ĝ_d(e^{j2πf/fs}) = z^D·M(z) at `f_hz` (Hz).
    pub fn frf(&self, f_hz: f64) -> CMatrix3 {
        let z = Complex64::from_polar(1.0, 2.0 * PI * f_hz / self.fs_hz);
        self.causal_z(z) * z.powi(self.advance as i32)
    }

    /// Per channel i, the sum of the gains its terms reach on the unit
    /// circle, each alone (row 2-norms ‖·_i·‖): ‖R_i·‖/(1 − |ζ|) per real
    /// pole, 2‖R_i·‖/(1 − |ζ|) per pair, ‖d_i·‖ and ‖h_m,i·‖. The 3x3 form of
    /// [`crate::design::discretize::DiscreteModel::term_gain_sum`].
    pub fn term_gain_sums(&self) -> [f64; 3] {
        std::array::from_fn(|i| {
            let poles: f64 = self
                .poles
                .iter()
                .zip(&self.residues)
                .map(|((zeta, pair), r)| {
                    let k = if *pair { 2.0 } else { 1.0 };
                    k * r.row(i).norm() / (1.0 - zeta.norm()).max(f64::MIN_POSITIVE)
                })
                .sum();
            poles + self.d.row(i).norm() + self.fir.iter().map(|h| h.row(i).norm()).sum::<f64>()
        })
    }

    /// Whether some channel's terms cancel each other: its
    /// [`Self::term_gain_sums`] over [`MAX_TERM_GAIN_RATIO`] times its largest
    /// row norm ‖Ĝ_d,i·‖ over `band`. The least squares then balances huge
    /// residues of opposite sign (a fast pole against the taps), and the
    /// Kalman design's augmented plant measures a small difference of huge
    /// states.
    pub fn cancels_terms(&self, band: &[(f64, CMatrix3)]) -> bool {
        let mut peak = [0.0f64; 3];
        for (f, _) in band {
            let g = self.frf(*f);
            for (i, p) in peak.iter_mut().enumerate() {
                *p = p.max(g.row(i).norm());
            }
        }
        let sums = self.term_gain_sums();
        (0..3).any(|i| !(sums[i] <= MAX_TERM_GAIN_RATIO * peak[i]))
    }
}

/// How well the discrete model matches Ĝ over the compensated band.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct DiscreteMatch {
    /// max_f ‖Ĝ⁻¹(Ĝ_d − Ĝ)‖_F: the relative force error the mismatch causes.
    pub matrix: f64,
    /// Per entry max_f |Ĝ_d,ij/Ĝ_ij − 1| (`[i][j]`).
    pub entries: [[f64; 3]; 3],
    /// Per entry max_f |Ĝ_d,ij − Ĝ_ij|/‖Ĝ_i·‖, relative to the channel.
    pub entries_in_channel: [[f64; 3]; 3],
    /// Largest condition number of the rows' column-scaled least squares.
    pub condition: f64,
    /// FIR taps M.
    pub fir_taps: usize,
    /// Advance D (samples).
    pub advance: usize,
    /// Modes dropped because they lie above fs/2.
    pub modes_above_nyquist: usize,
}

/// max ‖Ĝ⁻¹(Ĝ_d − Ĝ)‖_F over the lines (`None` where Ĝ is singular).
pub fn matrix_mismatch(lines: &[(f64, CMatrix3)], other: impl Fn(f64) -> CMatrix3) -> Option<f64> {
    let mut worst = 0.0f64;
    for (f, g) in lines {
        let inv = g.try_inverse()?;
        worst = worst.max((inv * (other(*f) - g)).norm());
    }
    Some(worst)
}

/// The least squares of one row ([`discretize_matrix`]), for every advance and tap count.
struct RowProblem {
    /// Column scales.
    scale: Vec<f64>,
    /// Scaled Gram matrix AᵀA.
    gram: DMatrix<f64>,
    /// Per entry j and advance D: Aᵀb, bᵀb.
    rhs: Vec<Vec<(DVector<f64>, f64)>>,
    /// The scaled columns at z = 1, and Ĝ_ij(0) per entry.
    at_one: DVector<f64>,
    static_gain: [f64; 3],
}

impl RowProblem {
    fn new(
        cols: &[Vec<Complex64>],
        zs: &[Complex64],
        truth: &[CMatrix3],
        w: &[f64],
        at_one: &[Complex64],
        g0: [f64; 3],
        i: usize,
    ) -> Self {
        let (rows, ncol) = (cols.len(), cols[0].len());
        let mut a = DMatrix::<f64>::zeros(2 * rows, ncol);
        for (k, (c, wk)) in cols.iter().zip(w).enumerate() {
            for (col, v) in c.iter().enumerate() {
                a[(2 * k, col)] = wk * v.re;
                a[(2 * k + 1, col)] = wk * v.im;
            }
        }
        let scale: Vec<f64> = (0..ncol).map(|j| a.column(j).norm().max(f64::MIN_POSITIVE)).collect();
        for (j, s) in scale.iter().enumerate() {
            a.column_mut(j).scale_mut(1.0 / s);
        }
        let rhs = (0..3)
            .map(|j| {
                let mut b = DMatrix::<f64>::zeros(2 * rows, MAX_ADVANCE + 1);
                for (k, (z, wk)) in zs.iter().zip(w).enumerate() {
                    let mut gm = truth[k][(i, j)] * *wk;
                    for d in 0..=MAX_ADVANCE {
                        b[(2 * k, d)] = gm.re;
                        b[(2 * k + 1, d)] = gm.im;
                        gm /= z;
                    }
                }
                let atb = a.tr_mul(&b);
                (0..=MAX_ADVANCE).map(|d| (atb.column(d).into_owned(), b.column(d).norm_squared())).collect()
            })
            .collect();
        let at_one = DVector::from_iterator(ncol, at_one.iter().zip(&scale).map(|(v, s)| v.re / s));
        RowProblem { gram: a.tr_mul(&a), scale, rhs, at_one, static_gain: g0 }
    }

    /// The three entries' coefficients (unscaled) with `taps` taps and
    /// advance `advance`, and the condition number; `None` when
    /// ill-conditioned.
    fn solve(&self, base: usize, taps: usize, advance: usize) -> Result<Option<([Vec<f64>; 3], f64)>> {
        let n = base + taps;
        let g = self.gram.view((0, 0), (n, n)).into_owned();
        let eig = symmetric_eigenvalues(&g, "the discrete 3x3 model's least squares")?;
        let (lmin, lmax) = (eig.min(), eig.max());
        let condition = (lmax / lmin).sqrt();
        if !(lmin > 0.0 && condition < MAX_CONDITION) {
            return Ok(None);
        }
        let Some(chol) = Cholesky::new(g) else { return Ok(None) };
        let v = self.at_one.rows(0, n).into_owned();
        let gv = chol.solve(&v);
        let denom = v.dot(&gv);
        if !(denom > 0.0) {
            return Ok(None);
        }
        let mut out: [Vec<f64>; 3] = Default::default();
        for (j, o) in out.iter_mut().enumerate() {
            let atb = self.rhs[j][advance].0.rows(0, n).into_owned();
            let mut x = chol.solve(&atb);
            // min ‖Ax − b‖ subject to vᵀx = Ĝ_ij(0) (the static gain exact).
            x -= &gv * ((v.dot(&x) - self.static_gain[j]) / denom);
            *o = x.iter().zip(&self.scale).map(|(v, s)| v / s).collect();
            if !o.iter().all(|v| v.is_finite()) {
                return Ok(None);
            }
        }
        Ok(Some((out, condition)))
    }
}

/// The discrete model of `model` at `fs_hz` matched over `band_hz`, with its
/// match over the band.
///
/// Each entry is
/// the least-squares fit of Ĝ_ij(j2πf) on the unit circle over the grid of
/// the per-axis fit ([`crate::design::discretize`]), under the constraint
/// Ĝ_d,ij(1) = Ĝ_ij(0) (the static gain exact). The lines of row i are
/// weighted by 1/‖Ĝ_i·(j2πf)‖ (one fifth outside the compensated band): an
/// entry's error counts relative to the channel it appears in, so a small
/// cross entry is fitted to the precision of its channel, not to its own
/// size (which would chase its near-zeros). (D, M) is the least complex pair
/// whose matrix match max_f ‖Ĝ⁻¹(Ĝ_d − Ĝ)‖_F is below
/// [`MATCH_TARGET`], or within `MATCH_SLACK` of the best: the error of
/// the compensated force the model's mismatch alone causes.
pub fn discretize_matrix(
    model: &MatrixModel,
    fs_hz: f64,
    band_hz: (f64, f64),
) -> Result<(DiscreteMatrixModel, DiscreteMatch)> {
    let (poles, above) = discrete_poles(model, fs_hz);
    let base = poles.iter().map(|(_, pair)| if *pair { 2 } else { 1 }).sum::<usize>() + 1;
    let grid = fit_grid(&model.entries[0], fs_hz, band_hz, MATCH_BAND_FRACTION);
    let truth: Vec<CMatrix3> = grid.iter().map(|f| model.frf(*f)).collect();
    if let Some(k) = truth.iter().position(|g| g.try_inverse().is_none() || !g.iter().all(|v| v.is_finite())) {
        bail!("discrete 3x3 model: the fitted model is singular or not finite at {:.1} Hz; refit the FRF", grid[k]);
    }
    let rows = row_problems(model, &poles, &grid, &truth, fs_hz, band_hz);
    let band: Vec<(f64, CMatrix3)> =
        grid.iter().zip(&truth).filter(|(f, _)| **f >= band_hz.0 && **f <= band_hz.1).map(|(f, g)| (*f, *g)).collect();
    let (tried, cancelling) = fit_every_layout(&rows, &poles, base, fs_hz, &band)?;
    if tried.is_empty() && cancelling > 0 {
        bail!("discrete 3x3 model: every well-conditioned unit-circle fit cancels terms of more than {MAX_TERM_GAIN_RATIO:.0e} times its response against each other (a fast pole against the FIR taps); lower --max-order");
    }
    let (dm, err, condition) = least_complex_good_fit(tried)?;
    let m = DiscreteMatch {
        matrix: err,
        condition,
        fir_taps: dm.fir.len(),
        advance: dm.advance,
        modes_above_nyquist: above,
        ..Default::default()
    };
    let m = entry_match(m, &dm, &band);
    Ok((dm, m))
}

/// The poles mapped exactly, ζ = e^{pT}, of those below Nyquist (a pair
/// above it, or a real pole whose corner |p|/2π is, is left to the taps:
/// its tail in the band, as per axis), with whether each is a pair; and how
/// many were left.
fn discrete_poles(model: &MatrixModel, fs_hz: f64) -> (Vec<(Complex64, bool)>, usize) {
    let t = 1.0 / fs_hz;
    let nyq = PI * fs_hz;
    let poles: Vec<(Complex64, bool)> = (0..model.terms())
        .filter_map(|k| {
            let (p, pair) = model.pole(k);
            let below = if pair { p.im < nyq } else { p.re.abs() < nyq };
            below.then_some(((p * t).exp(), pair))
        })
        .collect();
    let above = model.terms() - poles.len();
    (poles, above)
}

/// Each output row's least-squares problem on the unit circle over `grid`,
/// its lines weighted by 1/‖Ĝ_i·‖ (one fifth outside the band; module doc),
/// under the exact static gain.
fn row_problems(
    model: &MatrixModel,
    poles: &[(Complex64, bool)],
    grid: &[f64],
    truth: &[CMatrix3],
    fs_hz: f64,
    band_hz: (f64, f64),
) -> Vec<RowProblem> {
    let zs: Vec<Complex64> = grid.iter().map(|f| Complex64::from_polar(1.0, 2.0 * PI * f / fs_hz)).collect();
    let cols: Vec<Vec<Complex64>> = zs.iter().map(|z| columns_at(poles, *z)).collect();
    let at_one = columns_at(poles, Complex64::new(1.0, 0.0));
    let g0 = model.frf(0.0).map(|v| v.re);
    (0..3)
        .map(|i| {
            let w: Vec<f64> = grid
                .iter()
                .zip(truth)
                .map(|(f, g)| {
                    let inside = *f >= band_hz.0 && *f <= band_hz.1;
                    let norm = g.row(i).iter().map(|v| v.norm_sqr()).sum::<f64>().sqrt();
                    (if inside { 1.0 } else { OUT_OF_BAND_WEIGHT }) / norm
                })
                .collect();
            RowProblem::new(&cols, &zs, truth, &w, &at_one, [g0[(i, 0)], g0[(i, 1)], g0[(i, 2)]], i)
        })
        .collect()
}

/// A fitted layout: the model, its matrix mismatch and the worst condition
/// of its rows.
type Layout = (DiscreteMatrixModel, f64, f64);

/// Every layout (advance D, taps M) whose three rows solve well enough and
/// do not cancel terms ([`DiscreteMatrixModel::cancels_terms`]): the model,
/// its matrix mismatch over `band` and the worst condition; and how many
/// layouts cancelled terms.
fn fit_every_layout(
    rows: &[RowProblem],
    poles: &[(Complex64, bool)],
    base: usize,
    fs_hz: f64,
    band: &[(f64, CMatrix3)],
) -> Result<(Vec<Layout>, usize)> {
    let mut tried = Vec::new();
    let mut cancelling = 0;
    for advance in 0..=MAX_ADVANCE {
        for taps in advance.saturating_sub(1)..=MAX_FIR_TAPS {
            let mut coef: Vec<[Vec<f64>; 3]> = Vec::with_capacity(3);
            let mut condition = 0.0f64;
            for row in rows {
                match row.solve(base, taps, advance)? {
                    Some((c, k)) => {
                        coef.push(c);
                        condition = condition.max(k);
                    }
                    None => break,
                }
            }
            if coef.len() < 3 {
                continue;
            }
            let dm = assemble(fs_hz, poles, &coef, taps, advance);
            if dm.cancels_terms(band) {
                cancelling += 1;
                continue;
            }
            let Some(err) = matrix_mismatch(band, |f| dm.frf(f)) else { continue };
            tried.push((dm, err, condition));
        }
    }
    Ok((tried, cancelling))
}

/// The least complex layout (D + M) whose mismatch is below
/// [`MATCH_TARGET`] or within [`MATCH_SLACK`] of the best.
fn least_complex_good_fit(tried: Vec<Layout>) -> Result<Layout> {
    let best_err = tried.iter().map(|t| t.1).fold(f64::INFINITY, f64::min);
    if !best_err.is_finite() {
        bail!("discrete 3x3 model: every unit-circle fit was ill-conditioned (condition > {MAX_CONDITION:.0e}); two fitted modes may coincide: lower --max-order");
    }
    let good_enough = MATCH_TARGET.max(MATCH_SLACK * best_err);
    let cost = |t: &Layout| t.0.advance + t.0.fir.len();
    tried
        .into_iter()
        .filter(|t| t.1 <= good_enough)
        .min_by(|a, b| cost(a).cmp(&cost(b)).then(a.1.total_cmp(&b.1)))
        .ok_or_else(|| anyhow::anyhow!("discrete 3x3 model: no fit within reach of the best"))
}

/// `m` with each entry's largest relative error over `band`, and its error
/// relative to its channel's row norm.
fn entry_match(mut m: DiscreteMatch, dm: &DiscreteMatrixModel, band: &[(f64, CMatrix3)]) -> DiscreteMatch {
    for (f, g) in band {
        let gd = dm.frf(*f);
        for i in 0..3 {
            let norm = g.row(i).iter().map(|v| v.norm_sqr()).sum::<f64>().sqrt();
            for j in 0..3 {
                m.entries[i][j] = m.entries[i][j].max((gd[(i, j)] / g[(i, j)] - 1.0).norm());
                m.entries_in_channel[i][j] = m.entries_in_channel[i][j].max((gd[(i, j)] - g[(i, j)]).norm() / norm);
            }
        }
    }
    m
}

/// The discrete model from the rows' coefficients (per pole its residue's
/// real and, for a pair, imaginary part, then d, then the taps).
fn assemble(
    fs_hz: f64,
    poles: &[(Complex64, bool)],
    coef: &[[Vec<f64>; 3]],
    taps: usize,
    advance: usize,
) -> DiscreteMatrixModel {
    let at = |col: usize| Matrix3::from_fn(|i, j| coef[i][j][col]);
    let mut residues = Vec::with_capacity(poles.len());
    let mut col = 0;
    for (_, pair) in poles {
        if *pair {
            let (re, im) = (at(col), at(col + 1));
            residues.push(Matrix3::from_fn(|i, j| Complex64::new(re[(i, j)], im[(i, j)])));
            col += 2;
        } else {
            residues.push(at(col).map(|v| Complex64::new(v, 0.0)));
            col += 1;
        }
    }
    let d = at(col);
    let fir = (0..taps).map(|m| at(col + 1 + m)).collect();
    DiscreteMatrixModel { fs_hz, poles: poles.to_vec(), residues, d, fir, advance }
}

/// The poles' part of a discrete 3x3 model as real states ([`plant_states`]):
/// x[k+1] = A x[k] + B F_k, M(z) = C (zI − A)⁻¹ B + d + Σ h_m z^{−m}.
#[derive(Clone, Debug)]
pub struct PlantStates {
    /// State transition (n × n).
    pub a: DMatrix<f64>,
    /// Force input (n × 3).
    pub b: DMatrix<f64>,
    /// Output (3 × n).
    pub c: DMatrix<f64>,
    /// Rank kept of each pole's residue.
    pub ranks: Vec<usize>,
    /// The dropped triplets' force-error bound ([`plant_states`]).
    pub dropped_bound: f64,
    /// max_f ‖Ĝ⁻¹(M_ss − M)‖_F over the band: the realization against the
    /// pole-residue form.
    pub error: f64,
}

/// One rank-1 term σ·u·vᴴ of a residue.
struct Triplet {
    pole: usize,
    sigma: f64,
    u: [Complex64; 3],
    v: [Complex64; 3],
    /// Its force-error bound over the band ([`plant_states`]).
    bound: f64,
}

/// One rank-one term of a residue: singular value σ, output vector u and input vector v (R = Σ σ·u·vᴴ).
type RankOne = (f64, [Complex64; 3], [Complex64; 3]);

/// The SVD of a residue (R = Σ σ_k u_k v_kᴴ, σ descending), its
/// factors checked against R. nalgebra's SVD loses accuracy where R has
/// small nonzero singular values (dimforge/nalgebra#1172): a residue of
/// singular values 0.48, 5.3e-4 and 1.5e-4 came back 1.6e-4 of ‖R‖ off,
/// and its realization [`plant_states`] 1.9e-3 off the pole-residue form.
/// There faer's SVD is taken, checked the same way.
fn residue_svd(r: &CMatrix3, real: bool) -> Result<Vec<RankOne>> {
    let miss = |t: &[RankOne]| residue_miss(t, r);
    let first = nalgebra_svd(r, real)?;
    if miss(&first) <= SVD_RECONSTRUCTION_TOL {
        return Ok(first);
    }
    let second = faer_svd(r, real)?;
    let off = miss(&second);
    if !(off <= SVD_RECONSTRUCTION_TOL) {
        bail!("the SVD of a 3x3 residue misses it by {off:.1e} of its norm (limit {SVD_RECONSTRUCTION_TOL:.0e})");
    }
    Ok(second)
}

/// ‖R − Σ σ_k u_k v_kᴴ‖_F / ‖R‖_F of the terms `t` of an SVD of `r`.
fn residue_miss(t: &[RankOne], r: &CMatrix3) -> f64 {
    let mut sum = CMatrix3::zeros();
    for (sigma, u, v) in t {
        sum += CMatrix3::from_fn(|i, j| u[i] * *sigma * v[j]);
    }
    (sum - r).norm() / r.norm().max(f64::MIN_POSITIVE)
}

/// faer's SVD of a residue, as [`nalgebra_svd`] returns it.
fn faer_svd(r: &CMatrix3, real: bool) -> Result<Vec<RankOne>> {
    let fail = |e: faer::linalg::svd::SvdError| anyhow::anyhow!("the SVD of a 3x3 residue failed ({e:?})");
    let c = |v: f64| Complex64::new(v, 0.0);
    if real {
        let m = faer::Mat::<f64>::from_fn(3, 3, |i, j| r[(i, j)].re);
        let svd = m.svd().map_err(fail)?;
        let (u, v, s) = (svd.U(), svd.V(), svd.S().column_vector());
        Ok((0..3).map(|k| (s[k], [0, 1, 2].map(|i| c(u[(i, k)])), [0, 1, 2].map(|j| c(v[(j, k)])))).collect())
    } else {
        let m = faer::Mat::<Complex64>::from_fn(3, 3, |i, j| r[(i, j)]);
        let svd = m.svd().map_err(fail)?;
        let (u, v, s) = (svd.U(), svd.V(), svd.S().column_vector());
        // R = U S Vᴴ: the input row of term k is the conjugate of V's column k.
        Ok((0..3).map(|k| (s[k].re, [0, 1, 2].map(|i| u[(i, k)]), [0, 1, 2].map(|j| v[(j, k)].conj()))).collect())
    }
}

/// nalgebra's SVD of a residue, with an iteration limit.
fn nalgebra_svd(r: &CMatrix3, real: bool) -> Result<Vec<RankOne>> {
    let eps = f64::EPSILON;
    let limit = sweeps(3);
    let fail = || anyhow::anyhow!("the SVD of a 3x3 residue did not converge within {limit} sweeps");
    if real {
        let svd = SVD::try_new(r.map(|v| v.re), true, true, eps, limit).ok_or_else(fail)?;
        let (u, vt) = (svd.u.ok_or_else(fail)?, svd.v_t.ok_or_else(fail)?);
        let c = |v: f64| Complex64::new(v, 0.0);
        Ok((0..3)
            .map(|k| (svd.singular_values[k], [0, 1, 2].map(|i| c(u[(i, k)])), [0, 1, 2].map(|j| c(vt[(k, j)]))))
            .collect())
    } else {
        let svd = SVD::try_new(*r, true, true, eps, limit).ok_or_else(fail)?;
        let (u, vt) = (svd.u.ok_or_else(fail)?, svd.v_t.ok_or_else(fail)?);
        // R = Σ σ_k u_k (vᴴ)_k: v_t's rows are the vᴴ rows.
        Ok((0..3)
            .map(|k| (svd.singular_values[k], [0, 1, 2].map(|i| u[(i, k)]), [0, 1, 2].map(|j| vt[(k, j)])))
            .collect())
    }
}

/// Realize the poles' part of `dm`, checked over `band` ((f, Ĝ(j2πf)) lines
/// of the compensated band).
///
/// The poles' part of M is realized with real states whose
/// residues are factored by rank: R = Σ_k σ_k u_k v_kᴴ (SVD); a physical
/// mode's residue is rank 1 (G = Σ_r c_r b_rᵀ·f_r(s)), two states per pair.
/// Each kept triplet of a pair is one complex state x\[k+1\] = ζ x\[k\] + β F_k
/// with β = s·v_kᴴ and output 2 Re(γ x), γ = σ_k u_k/s, s = |1 − ζ| (so that
/// a state is about the size of a force, as in [`crate::design::kalman`]),
/// held as (Re x, Im x); a real pole's triplet is one real state. A
/// triplet is dropped when it is negligible: the dropped triplets' bound
/// Σ max_f ‖Ĝ⁻¹‖_F·σ_k·(|z − ζ|⁻¹ + |z − ζ̄|⁻¹) on the force error they
/// cause stays below [`RANK_TOL`]. The realization is checked against the
/// pole-residue form over the band.
pub fn plant_states(dm: &DiscreteMatrixModel, band: &[(f64, CMatrix3)]) -> Result<PlantStates> {
    let inv_norm: Vec<(Complex64, f64)> = band
        .iter()
        .map(|(f, g)| {
            let z = Complex64::from_polar(1.0, 2.0 * PI * f / dm.fs_hz);
            (z, g.try_inverse().map_or(f64::INFINITY, |i| i.norm()))
        })
        .collect();
    let mut triplets = Vec::new();
    for (k, ((zeta, pair), r)) in dm.poles.iter().zip(&dm.residues).enumerate() {
        for (sigma, u, v) in residue_svd(r, !pair)? {
            let bound = inv_norm
                .iter()
                .map(|(z, gi)| {
                    let reach = (z - zeta).inv().norm() + if *pair { (z - zeta.conj()).inv().norm() } else { 0.0 };
                    gi * sigma * reach
                })
                .fold(0.0, f64::max);
            triplets.push(Triplet { pole: k, sigma, u, v, bound });
        }
    }
    // Drop the least important triplets while their summed bound stays
    // below RANK_TOL.
    triplets.sort_by(|a, b| a.bound.total_cmp(&b.bound));
    let mut dropped_bound = 0.0;
    let mut first_kept = triplets.len();
    for (idx, t) in triplets.iter().enumerate() {
        if dropped_bound + t.bound > RANK_TOL {
            first_kept = idx;
            break;
        }
        dropped_bound += t.bound;
    }
    let mut kept: Vec<&Triplet> = triplets[first_kept..].iter().collect();
    kept.sort_by(|a, b| a.pole.cmp(&b.pole).then(b.sigma.total_cmp(&a.sigma)));
    let n: usize = kept.iter().map(|t| if dm.poles[t.pole].1 { 2 } else { 1 }).sum();
    let (mut a, mut b, mut c) = (DMatrix::zeros(n, n), DMatrix::zeros(n, 3), DMatrix::zeros(3, n));
    let mut ranks = vec![0; dm.poles.len()];
    let mut i = 0;
    for t in &kept {
        let (zeta, pair) = dm.poles[t.pole];
        ranks[t.pole] += 1;
        let s = (Complex64::new(1.0, 0.0) - zeta).norm().max(1e-12);
        let beta = t.v.map(|v| v * s);
        let gamma = t.u.map(|u| u * t.sigma / s);
        if pair {
            a[(i, i)] = zeta.re;
            a[(i, i + 1)] = -zeta.im;
            a[(i + 1, i)] = zeta.im;
            a[(i + 1, i + 1)] = zeta.re;
            for j in 0..3 {
                b[(i, j)] = beta[j].re;
                b[(i + 1, j)] = beta[j].im;
                c[(j, i)] = 2.0 * gamma[j].re;
                c[(j, i + 1)] = -2.0 * gamma[j].im;
            }
            i += 2;
        } else {
            a[(i, i)] = zeta.re;
            for j in 0..3 {
                b[(i, j)] = beta[j].re;
                c[(j, i)] = gamma[j].re;
            }
            i += 1;
        }
    }
    let mut plant = PlantStates { a, b, c, ranks, dropped_bound, error: 0.0 };
    plant.error = realization_error(&plant, dm, band);
    if !(plant.error <= MAX_REALIZATION_ERROR) {
        bail!(
            "discrete 3x3 model: its state-space realization is {:.1e} from the pole-residue form (limit {MAX_REALIZATION_ERROR:.0e})",
            plant.error
        );
    }
    Ok(plant)
}

/// max_f ‖Ĝ⁻¹(C(zI − A)⁻¹B + d + Σ h_m z^{−m} − M(z))‖_F over `band`.
fn realization_error(p: &PlantStates, dm: &DiscreteMatrixModel, band: &[(f64, CMatrix3)]) -> f64 {
    let ss =
        crate::numeric::lti::MimoStateSpace { a: p.a.clone(), b: p.b.clone(), c: p.c.clone(), d: DMatrix::zeros(3, 3) };
    let freqs: Vec<f64> = band.iter().map(|b| b.0).collect();
    let h = ss.freq_responses(&freqs, dm.fs_hz);
    let mut poles_only = dm.clone();
    poles_only.d = Matrix3::zeros();
    poles_only.fir.clear();
    let mut worst = 0.0f64;
    for ((f, g), hs) in band.iter().zip(&h) {
        let z = Complex64::from_polar(1.0, 2.0 * PI * f / dm.fs_hz);
        let want = poles_only.causal_z(z);
        let got = Matrix3::from_fn(|i, j| hs[(i, j)]);
        let e = g.try_inverse().map_or(f64::INFINITY, |gi| (gi * (got - want)).norm());
        worst = worst.max(if e.is_nan() { f64::INFINITY } else { e });
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A model with one slow pair (ζ = 0.99 e^{±j0.3}) in row 0 and an
    /// identity direct term; with `fast` ≠ 0 also a fast real pole at
    /// ζ = 0.065 of residue `fast` in entry (0, 1), nearly cancelled by taps.
    fn model(fast: f64) -> DiscreteMatrixModel {
        let zeta = Complex64::from_polar(0.99, 0.3);
        let mut r = CMatrix3::zeros();
        r[(0, 0)] = Complex64::new(0.0, -0.005);
        let mut poles = vec![(zeta, true)];
        let mut residues = vec![r];
        let mut fir = Vec::new();
        if fast != 0.0 {
            let mut rf = CMatrix3::zeros();
            rf[(0, 1)] = Complex64::new(fast, 0.0);
            poles.push((Complex64::new(0.065, 0.0), false));
            residues.push(rf);
            // ρ/(z − ζ) = ρ(z⁻¹ + ζ z⁻² + ζ² z⁻³ + …): four taps cancel
            // its first four terms, which leaves ρζ⁴ z⁻⁵/(1 − ζ z⁻¹).
            for m in 0..4 {
                let mut h = Matrix3::zeros();
                h[(0, 1)] = -fast * 0.065f64.powi(m);
                fir.push(h);
            }
        }
        DiscreteMatrixModel { fs_hz: 25_600.0, poles, residues, d: Matrix3::identity(), fir, advance: 0 }
    }

    /// Lines 100-4000 Hz (the values are not read).
    fn band() -> Vec<(f64, CMatrix3)> {
        (1..=40).map(|k| (100.0 * f64::from(k), CMatrix3::identity())).collect()
    }

    /// A fast pole whose residue of 1e5 is cancelled by a tap is refused;
    /// control: the same layout with a residue of 10 (term gains under
    /// the limit) is kept, and so is the model without it.
    #[test]
    fn cancelling_terms_are_told_from_a_plain_fit() {
        let huge = model(1e5);
        assert!(huge.cancels_terms(&band()), "{:?}", huge.term_gain_sums());
        let small = model(10.0);
        assert!(!small.cancels_terms(&band()), "{:?}", small.term_gain_sums());
        let plain = model(0.0);
        assert!(!plain.cancels_terms(&band()), "{:?}", plain.term_gain_sums());
        // Rows 1 and 2 hold only the direct term: their sum is its norm.
        assert_eq!(plain.term_gain_sums()[1], 1.0);
    }

    /// A residue of one strong and two weak directions, as a refined fit
    /// of a random plate gave it (sweep of `simulate --dyno plate --seed
    /// 302`, 3591 Hz: singular values 0.48, 5.3e-4, 1.5e-4, entries to
    /// full precision). Its factors rebuild it to rounding, they are
    /// orthonormal, and Σσ² = ‖R‖²_F. The control: nalgebra's SVD
    /// alone misses it, so the check is what catches it.
    #[test]
    fn a_residue_with_small_singular_values_is_factored_to_rounding() {
        let c = Complex64::new;
        // Column by column.
        let r = CMatrix3::from_column_slice(&[
            c(0.0013354940378383323, -0.0016802044860387802),
            c(-0.0019674880396093153, 0.0034537005873705572),
            c(0.010827675375582843, -0.017231096760985845),
            c(-0.0005378541518914119, 0.0014538467703469422),
            c(0.0012041295614724232, -0.001813963248653594),
            c(-0.006890474387493265, 0.010728815757484494),
            c(-0.027663626768348906, 0.044115768785111066),
            c(0.04742431120634967, -0.07545246873816114),
            c(-0.24815461978109465, 0.39547022006387333),
        ]);
        let rebuilt = |t: &[RankOne]| residue_miss(t, &r);
        let plain = nalgebra_svd(&r, false).unwrap();
        assert!(rebuilt(&plain) > 1e-8, "control: nalgebra's SVD rebuilt it to {:.1e}", rebuilt(&plain));
        let checked = residue_svd(&r, false).unwrap();
        assert!(rebuilt(&checked) < 1e-14, "{:.1e}", rebuilt(&checked));
        let energy: f64 = checked.iter().map(|t| t.0 * t.0).sum();
        assert!((energy / r.norm_squared() - 1.0).abs() < 1e-14);
        // The factors are orthonormal: Σσ_k u_k v_k is an SVD, not just a sum.
        for a in &checked {
            for b in &checked {
                let same = if std::ptr::eq(a, b) { 1.0 } else { 0.0 };
                let uu: Complex64 = (0..3).map(|i| a.1[i].conj() * b.1[i]).sum();
                let vv: Complex64 = (0..3).map(|j| a.2[j] * b.2[j].conj()).sum();
                assert!((uu - same).norm() < 1e-14 && (vv - same).norm() < 1e-14, "{uu} {vv}");
            }
        }
        assert!(
            checked[1].0 > 1e-4 && checked[2].0 > 1e-5 && checked[0].0 > checked[1].0 && checked[1].0 > checked[2].0
        );
    }
}
