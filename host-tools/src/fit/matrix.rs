//! The FRF matrix fitted with common poles (DESIGN.md, "Signal chain": the
//! dynamometer as one 3x3 system): matrix vector fitting.
//! [`matrix_vector_fit`] on a [`MatrixData`] gives a [`MatrixModel`]. A leaf of
//! the chain, beside the per-axis fit [`super::vf`].

use crate::numeric::parallel::map_on_threads;
use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector, Matrix3};
use num_complex::Complex64;
use std::f64::consts::PI;

use super::vf::{
    basis_row, best_surrogate, contributes, edge_pairs, kept_poles, lstsq, max_order_for, min_lines, n_cols,
    relocation_step, residues, sigma_zeros, spurious, starting_poles, to_model, Pole, VfOptions,
};
use super::{PoleResidueModel, Term};

/// Entries of the 3x3 matrix, row by row: entry `e` is G_ij with i = e / 3, j = e % 3.
pub const ENTRIES: usize = 9;

/// A 3x3 model with common poles: nine pole-residue models whose terms
/// have the same poles in the same order.
///
/// A mode of the dynamometer is one pole pair seen in every entry with its
/// own residue, so all nine entries share the poles:
///
/// G_ij(s) = d_ij + Σ_real r_ij/(s − p) + Σ_pairs [r_ij/(s − p) + r̄_ij/(s − p̄)],
///
/// s in rad/s, G in N/N.
#[derive(Clone, Debug, PartialEq)]
pub struct MatrixModel {
    /// G_ij as `entries[3i + j]` (channel i, force direction j).
    pub entries: Vec<PoleResidueModel>,
}

impl MatrixModel {
    /// Entry G_ij (channel i, force direction j).
    pub fn entry(&self, i: usize, j: usize) -> &PoleResidueModel {
        &self.entries[3 * i + j]
    }

    /// Ĝ(s) at the complex frequency `s` (rad/s), `[(i, j)]` = Ĝ_ij.
    pub fn eval_s(&self, s: Complex64) -> Matrix3<Complex64> {
        Matrix3::from_fn(|i, j| self.entry(i, j).eval_s(s))
    }

    /// Ĝ(j2πf) at `f_hz` (Hz).
    pub fn frf(&self, f_hz: f64) -> Matrix3<Complex64> {
        self.eval_s(Complex64::new(0.0, 2.0 * PI * f_hz))
    }

    /// The common terms' count.
    pub fn terms(&self) -> usize {
        self.entries[0].terms.len()
    }

    /// Model order: poles, a pair counting two (the same in every entry).
    pub fn order(&self) -> usize {
        self.entries[0].order()
    }

    /// Term `k`'s pole (rad/s; the one with Im > 0 for a pair) and whether
    /// it is a pair.
    pub fn pole(&self, k: usize) -> (Complex64, bool) {
        match self.entries[0].terms[k] {
            Term::Real { pole, .. } => (Complex64::new(pole, 0.0), false),
            Term::Pair { pole, .. } => (pole, true),
        }
    }

    /// Term `k`'s residue in every entry (rad/s; real for a real pole).
    pub fn residue(&self, k: usize) -> Matrix3<Complex64> {
        Matrix3::from_fn(|i, j| match self.entry(i, j).terms[k] {
            Term::Real { residue, .. } => Complex64::new(residue, 0.0),
            Term::Pair { residue, .. } => residue,
        })
    }

    /// Whether every pole has a negative real part.
    pub fn is_stable(&self) -> bool {
        self.entries[0].is_stable()
    }

    /// Natural frequencies (Hz) and damping ratios of the pairs, ascending.
    pub fn modes(&self) -> Vec<(f64, f64)> {
        self.entries[0].modes()
    }
}

/// The fit with its order search.
#[derive(Clone, Debug)]
pub struct MatrixFit {
    /// The chosen model.
    pub model: MatrixModel,
    /// Weighted RMS residual over all entries, sqrt(Σ w|Ĝ − G|² / Σ w|G|²).
    pub weighted_rms: f64,
    /// `(order, weighted_rms)` of every order tried.
    pub order_trace: Vec<(usize, f64)>,
}

/// The measured matrix a fit reads: lines, and per entry (row by row) the
/// values and the weights.
///
/// Weights are each entry's coherence weights
/// ([`super::vf::coherence_weights`]), so each line counts by the inverse
/// variance of its H1 estimate.
pub struct MatrixData<'a> {
    /// Frequency lines (Hz).
    pub freq_hz: &'a [f64],
    /// G_ij per line, `h[3i + j]`.
    pub h: [&'a [Complex64]; ENTRIES],
    /// Weight of each line per entry (inverse variance, e.g. coherence weights).
    pub w: [&'a [f64]; ENTRIES],
}

impl MatrixData<'_> {
    fn f_max(&self) -> f64 {
        self.freq_hz.iter().fold(0.0f64, |m, f| m.max(*f))
    }

    /// sqrt(Σ_e Σ_k w|Ĝ − G|² / Σ_e Σ_k w|G|²) of `model`.
    pub fn weighted_rms(&self, model: &MatrixModel) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for (k, f) in self.freq_hz.iter().enumerate() {
            let g = model.frf(*f);
            for e in 0..ENTRIES {
                let (h, w) = (self.h[e][k], self.w[e][k]);
                num += w * (g[(e / 3, e % 3)] - h).norm_sqr();
                den += w * h.norm_sqr();
            }
        }
        (num / den).sqrt()
    }
}

/// One relocation of the common poles: the zeros of σ.
///
/// The poles are relocated by relaxed vector fitting
/// (Gustavsen & Semlyen 1999; Gustavsen 2006) with one weighting function
/// σ(s) for all entries, solved in the fast form of Deschrijver et al.
/// ("Macromodeling of multiport systems using a fast implementation of the
/// vector fitting method", IEEE MWCL 18(6), 2008): entry e's rows
/// √w·(Φ x_e − H_e·Φ x̃) = 0 are reduced by a QR factorization to the rows
/// R22,e x̃ = 0 that involve only σ's coefficients x̃; the reduced rows of
/// the nine entries and the relaxation row Re Σ_k σ(s_k) = K are stacked and
/// solved once. The new poles are the zeros of σ, unstable ones flipped.
fn relocate(s: &[Complex64], h: &[Vec<Complex64>], sw: &[Vec<f64>], poles: &[Pole]) -> Result<Vec<Pole>> {
    let n = n_cols(poles);
    let k = s.len();
    let m = n + 1;
    let rows: Vec<Vec<Complex64>> = s
        .iter()
        .map(|si| {
            let mut r = Vec::with_capacity(n);
            basis_row(*si, poles, &mut r);
            r.push(Complex64::new(1.0, 0.0));
            r
        })
        .collect();
    // Φ column by column: A is column-major, so each column is written
    // contiguously.
    let columns: Vec<Vec<Complex64>> = (0..m).map(|j| rows.iter().map(|r| r[j]).collect()).collect();
    let mut stacked = DMatrix::<f64>::zeros(ENTRIES * m + 1, m);
    let mut data_norm2 = 0.0;
    // One buffer for every entry's rows: each is written whole, then
    // factored in place.
    let mut a = DMatrix::<f64>::zeros(2 * k, 2 * m);
    for e in 0..ENTRIES {
        let hw: Vec<Complex64> = (0..k).map(|i| h[e][i] * sw[e][i]).collect();
        for v in &hw {
            data_norm2 += v.norm_sqr();
        }
        let (left, right) = a.as_mut_slice().split_at_mut(2 * k * m);
        let mut finite = true;
        for (j, phi) in columns.iter().enumerate() {
            let (cv, cu) = (&mut left[2 * k * j..2 * k * (j + 1)], &mut right[2 * k * j..2 * k * (j + 1)]);
            for (i, phi) in phi.iter().enumerate() {
                let v = phi * sw[e][i];
                (cv[2 * i], cv[2 * i + 1]) = (v.re, v.im);
                let u = -phi * hw[i];
                (cu[2 * i], cu[2 * i + 1]) = (u.re, u.im);
                finite &= v.re.is_finite() & v.im.is_finite() & u.re.is_finite() & u.im.is_finite();
            }
        }
        if !finite {
            bail!("matrix vector fitting: entry {e}'s least-squares rows are not finite (a pole on a measured line?)");
        }
        let r = crate::numeric::dense::qr_r_in_place(&mut a);
        // R22: the rows of σ's coefficients after eliminating entry e's own.
        stacked.view_mut((e * m, 0), (m, m)).copy_from(&r.view((m, m), (m, m)));
    }
    // Relaxation (Gustavsen 2006): Re Σ_k σ(s_k) = K, scaled like the data.
    let scale = data_norm2.sqrt() / k as f64;
    for j in 0..m {
        stacked[(ENTRIES * m, j)] = scale * rows.iter().map(|r| r[j].re).sum::<f64>();
    }
    let mut rhs = DVector::<f64>::zeros(ENTRIES * m + 1);
    rhs[ENTRIES * m] = scale * k as f64;
    let x = lstsq(stacked, rhs)?;
    let c_t: Vec<f64> = (0..n).map(|j| x[j]).collect();
    sigma_zeros(poles, &c_t, x[n])
}

/// Residues and direct terms of every entry at the poles `poles`
/// (normalized by `w_scale`), each entry's own weighted least squares: at
/// the final poles these are the model's residues.
fn fit_residues(data: &MatrixData, poles: &[Pole], w_scale: f64) -> Result<MatrixModel> {
    let s: Vec<Complex64> = data.freq_hz.iter().map(|f| Complex64::new(0.0, 2.0 * PI * f / w_scale)).collect();
    let entries = (0..ENTRIES)
        .map(|e| {
            let sw: Vec<f64> = data.w[e].iter().map(|w| w.sqrt()).collect();
            let (c, d) = residues(&s, data.h[e], &sw, poles)?;
            Ok(to_model(poles, &c, d, w_scale))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(MatrixModel { entries })
}

/// Fit the matrix from the starting poles `poles` (rad/s; Im > 0 for a
/// pair) as [`fit_matrix_order`] does from its linearly spaced ones.
pub fn fit_matrix_from(data: &MatrixData, poles: &[(Complex64, bool)], opts: &VfOptions) -> Result<MatrixModel> {
    let w_scale = 2.0 * PI * data.f_max();
    let start = poles.iter().map(|(p, pair)| Pole { p: p / w_scale, pair: *pair }).collect();
    relocate_from(data, start, opts)
}

/// Fit the matrix at a fixed (even) order: relocation on every
/// `opts.decimate`-th line ([`relocation_step`]), at most `opts.iterations`
/// times, then the residues on all lines.
pub fn fit_matrix_order(data: &MatrixData, order: usize, opts: &VfOptions) -> Result<MatrixModel> {
    let f_max = data.f_max();
    if f_max <= 0.0 {
        bail!("matrix vector fitting needs positive frequencies");
    }
    let lines = data.freq_hz.len();
    if lines < min_lines(order) {
        bail!("matrix vector fitting at order {order} needs at least {} lines, got {lines}", min_lines(order));
    }
    let poles = starting_poles(data.freq_hz, f_max, order);
    relocate_from(data, poles, opts)
}

/// Relocate the common poles from `poles` (normalized by 2π·f_max) at most
/// `opts.iterations` times, then fit the residues on all lines.
fn relocate_from(data: &MatrixData, mut poles: Vec<Pole>, opts: &VfOptions) -> Result<MatrixModel> {
    let lines = data.freq_hz.len();
    let order = n_cols(&poles);
    let w_scale = 2.0 * PI * data.f_max();
    let step = relocation_step(lines, order, opts.decimate);
    let idx: Vec<usize> = (0..lines).step_by(step).collect();
    let s: Vec<Complex64> = idx.iter().map(|&i| Complex64::new(0.0, 2.0 * PI * data.freq_hz[i] / w_scale)).collect();
    let h: Vec<Vec<Complex64>> = (0..ENTRIES).map(|e| idx.iter().map(|&i| data.h[e][i]).collect()).collect();
    let sw: Vec<Vec<f64>> = (0..ENTRIES).map(|e| idx.iter().map(|&i| data.w[e][i].sqrt()).collect()).collect();
    for _ in 0..opts.iterations {
        let new = relocate(&s, &h, &sw, &poles)?;
        let moved = new.len() != poles.len()
            || new.iter().zip(&poles).any(|(a, b)| (a.p - b.p).norm() > 1e-9 * b.p.norm().max(1e-3));
        poles = new;
        if !moved {
            break;
        }
    }
    fit_residues(data, &poles, w_scale)
}

/// Orders without a better [`MatrixData::bic`] after the best one that end
/// the order search.
pub const BIC_PATIENCE: usize = 30;

/// Fit with the order chosen by the Bayesian information criterion, then
/// drop the terms that are spurious ([`super::vf::spurious`]) or below
/// 10⁻³ of |G| in every entry, and refit the residues.
///
/// The order: 2, 4, … up to `opts.max_order` (fitted in parallel), until
/// [`BIC_PATIENCE`] orders in a row have not lowered the BIC of the best
/// one; the order of least BIC is kept ([`MatrixData::bic`]). The per-axis fit's rule (stop
/// when the weighted error improves by less than a fraction) does not suit
/// the matrix: its weighted error is the measurement noise of nine FRFs,
/// and a mode that only some entries show lowers it by a fraction of a
/// percent, far less than the per-axis fit's 3 % tolerance yet far more
/// than the noise can explain (its gain in χ² is hundreds of times the
/// noise's per parameter). `opts.improvement_tol` is not used.
pub fn matrix_vector_fit(data: &MatrixData, opts: &VfOptions) -> Result<MatrixFit> {
    let lines = data.freq_hz.len();
    if lines < 8 {
        bail!("matrix vector fitting needs at least 8 frequency lines, got {lines}");
    }
    if data.h.iter().any(|h| h.len() != lines) || data.w.iter().any(|w| w.len() != lines) {
        bail!("matrix vector fitting: every entry needs one value and one weight per line ({lines})");
    }
    let orders: Vec<usize> = (2..=opts.max_order.min(max_order_for(lines))).step_by(2).collect();
    // Highest order first: the cost grows with the order, so the threads
    // end together.
    let descending: Vec<usize> = orders.iter().rev().copied().collect();
    let mut fits = map_on_threads(&descending, |order| fit_matrix_order(data, *order, opts));
    fits.reverse();
    let mut trace = Vec::new();
    let mut models: Vec<(usize, MatrixModel, f64)> = Vec::new();
    for (order, fit) in orders.into_iter().zip(fits) {
        let m = match fit {
            Ok(m) => m,
            Err(e) if models.is_empty() => return Err(e),
            Err(_) => break,
        };
        trace.push((order, data.weighted_rms(&m)));
        models.push((order, m.clone(), data.rss(&m)));
        let best = data.best_bic(&models);
        if models.len() - 1 - best >= BIC_PATIENCE {
            break;
        }
    }
    if !models.iter().any(|m| m.2.is_finite()) {
        bail!("matrix vector fitting failed at every order");
    }
    let best = data.best_bic(&models);
    let model = skim(data, opts.f_identified_hz, models.swap_remove(best).1)?;
    if !model.is_stable() {
        bail!("matrix vector fitting: the fitted model is unstable");
    }
    Ok(MatrixFit { weighted_rms: data.weighted_rms(&model), model, order_trace: trace })
}

impl MatrixData<'_> {
    /// The weighted residual Σ_e Σ_k w|Ĝ − G|² of `model`.
    pub fn rss(&self, model: &MatrixModel) -> f64 {
        let mut sum = 0.0;
        for (k, f) in self.freq_hz.iter().enumerate() {
            let g = model.frf(*f);
            for e in 0..ENTRIES {
                sum += self.w[e][k] * (g[(e / 3, e % 3)] - self.h[e][k]).norm_sqr();
            }
        }
        sum
    }

    /// Real data points: two per line of positive weight in every entry.
    fn points(&self) -> usize {
        self.w.iter().map(|w| 2 * w.iter().filter(|v| **v > 0.0).count()).sum()
    }

    /// BIC = RSS/σ̂² + p·ln N of a fit with residual `rss` and `order`
    /// poles: p = order + 9·(order + 1) real parameters (the poles, and per
    /// entry its residues and direct term), N = [`Self::points`], and σ̂² the
    /// noise scale RSS/(N − p) of the lowest-residual fit of `fits`
    /// (coherence weights are the inverse variances up to a factor, which
    /// σ̂² carries).
    fn bic(&self, rss: f64, order: usize, sigma2: f64) -> f64 {
        let n = self.points() as f64;
        let p = (order + ENTRIES * (order + 1)) as f64;
        rss / sigma2 + p * n.ln()
    }

    /// Index of the least-BIC fit of `fits` ((order, model, rss)).
    fn best_bic(&self, fits: &[(usize, MatrixModel, f64)]) -> usize {
        let n = self.points() as f64;
        let sigma2 = fits
            .iter()
            .filter(|f| f.2.is_finite())
            .map(|f| f.2 / (n - (f.0 + ENTRIES * (f.0 + 1)) as f64).max(1.0))
            .fold(f64::INFINITY, f64::min);
        let bic =
            |f: &(usize, MatrixModel, f64)| if f.2.is_finite() { self.bic(f.2, f.0, sigma2) } else { f64::INFINITY };
        (0..fits.len()).min_by(|&a, &b| bic(&fits[a]).total_cmp(&bic(&fits[b]))).unwrap_or(0)
    }
}

/// `model` without the terms `keep` leaves out, its residues and direct
/// terms fitted again to `data` with the remaining poles fixed (the matrix
/// form of [`super::vf::refit_kept`]).
pub fn refit_kept(data: &MatrixData, model: &MatrixModel, keep: &[bool]) -> Result<MatrixModel> {
    let w_scale = 2.0 * PI * data.f_max();
    fit_residues(data, &kept_poles(&model.entries[0].terms, keep, w_scale), w_scale)
}

/// Drop the terms that are spurious (a real pole below `f_identified_hz`,
/// [`VfOptions::f_identified_hz`], among others) or negligible in every
/// entry, and refit the residues of the rest; a spurious pair at the band
/// edge that the lines need gives way to a damped surrogate, as in the
/// per-axis fit ([`super::vf::best_surrogate`]).
///
/// Below the impact test's first coherent line the lines carry next to no
/// weight, and a real pole fitted to their noise bends every entry between
/// there and 0 Hz, where the mean cutting force is: through the crosstalk
/// of a large mean force, a bias on another axis.
fn skim(data: &MatrixData, f_identified_hz: f64, model: MatrixModel) -> Result<MatrixModel> {
    let f_top = data.f_max();
    let f_low = data.freq_hz.iter().copied().find(|f| *f > 0.0).unwrap_or(0.0).max(f_identified_hz);
    let terms = &model.entries[0].terms;
    let needed: Vec<bool> = (0..model.terms())
        .map(|k| (0..ENTRIES).any(|e| contributes(&model.entries[e].terms[k], data.freq_hz, data.h[e])))
        .collect();
    let keep: Vec<bool> = terms.iter().zip(&needed).map(|(t, n)| *n && !spurious(t, f_low, f_top)).collect();
    if keep.iter().all(|k| *k) {
        return Ok(model);
    }
    let w_scale = 2.0 * PI * f_top;
    let kept = kept_poles(terms, &keep, w_scale);
    let edge = edge_pairs(terms, &needed, &keep, f_top);
    if edge.is_empty() {
        return fit_residues(data, &kept, w_scale);
    }
    let fit = |poles: &[Pole]| fit_residues(data, poles, w_scale);
    match best_surrogate(&kept, &edge, w_scale, fit, |m| data.weighted_rms(m)) {
        Some(m) => Ok(m),
        None => fit_residues(data, &kept, w_scale),
    }
}
