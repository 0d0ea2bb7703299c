//! The FRF matrix fitted with common poles (DESIGN.md, "Signal chain": the
//! dynamometer as one 3x3 system): matrix vector fitting.
//! [`matrix_vector_fit`] on a [`MatrixData`] gives a [`MatrixModel`]. A leaf of
//! the chain, beside the per-axis fit [`super::vf`].

use crate::numeric::parallel::map_on_threads;
use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector, Matrix3};
use num_complex::Complex64;
use std::f64::consts::PI;

use super::modes::{fn_hz, pole_at};
use super::vf::{
    basis_row, best_surrogate, contributes, edge_pairs, kept_poles, lstsq, max_order_for, min_lines, n_cols,
    relocation_step, residues, sigma_zeros, starting_poles, to_model, Pole, VfOptions,
};
use super::{lowest_identified_hz, spurious, within_bandwidth, PoleResidueModel, Term};

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
    /// Where close modes were split ([`MAX_SPLITS`]), the order search's
    /// own model (skimmed), for a chain that cannot take the split one.
    pub unsplit: Option<MatrixModel>,
    /// Pairs the split added.
    pub splits: usize,
    /// Lines (Hz) where [`seed_unfitted_modes`] added a pair that `model`
    /// holds, before the refinement moved it (`unsplit` is without them).
    pub seeded_hz: Vec<f64>,
    /// Natural frequencies (Hz) of the pairs [`drop_unsupported_pairs`]
    /// dropped from the chosen model, in the order dropped.
    pub dropped_hz: Vec<f64>,
    /// The same for `unsplit`.
    pub unsplit_dropped_hz: Vec<f64>,
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
/// the order search. Five orders (ten poles) past the best: on the seed
/// study's nine impact tests the least-BIC order is the one a search to
/// the maximum order finds, and σ̂² is within 1.1 % of that search's.
pub const BIC_PATIENCE: usize = 5;

/// Fit with the order chosen by the Bayesian information criterion, then
/// drop the terms that are spurious ([`super::spurious`]) or below
/// 10⁻³ of |G| in every entry, and refit the residues.
///
/// The order: 2, 4, … up to `opts.max_order` (as many at a time as the
/// machine has cores), until [`BIC_PATIENCE`] orders in a row have not
/// lowered the BIC of the best one; the order of least BIC among those
/// fitted is kept ([`MatrixData::bic`]). The per-axis fit's rule (stop
/// when the weighted error improves by less than a fraction) does not suit
/// the matrix: its weighted error is the measurement noise of nine FRFs,
/// and a mode that only some entries show lowers it by a fraction of a
/// percent, far less than the per-axis fit's 3 % tolerance yet far more
/// than the noise can explain (its gain in χ² is hundreds of times the
/// noise's per parameter). `opts.improvement_tol` is not used.
pub fn matrix_vector_fit(data: &MatrixData, opts: &VfOptions) -> Result<MatrixFit> {
    matrix_fit_stages(data, opts)?.finish(data, opts)
}

/// A common-pole fit up to its refinement: what [`matrix_vector_fit`]
/// does before [`refined`], so that a chain which cannot take the refined
/// model finishes the same fit without it instead of fitting again.
pub struct MatrixFitStages {
    /// The order search's model, split and pruned, pairs the lines do not
    /// support dropped.
    model: MatrixModel,
    dropped_hz: Vec<f64>,
    /// Where close modes were split: the order search's own model, its
    /// unsupported pairs dropped, and their frequencies (Hz).
    unsplit: Option<(MatrixModel, Vec<f64>)>,
    splits: usize,
    seeded_hz: Vec<f64>,
    order_trace: Vec<(usize, f64)>,
    /// The order search's noise scale σ̂² ([`MatrixData::bic`]).
    sigma2: f64,
}

/// [`matrix_vector_fit`] up to the refinement.
pub fn matrix_fit_stages(data: &MatrixData, opts: &VfOptions) -> Result<MatrixFitStages> {
    let lines = data.freq_hz.len();
    if lines < 8 {
        bail!("matrix vector fitting needs at least 8 frequency lines, got {lines}");
    }
    if data.h.iter().any(|h| h.len() != lines) || data.w.iter().any(|w| w.len() != lines) {
        bail!("matrix vector fitting: every entry needs one value and one weight per line ({lines})");
    }
    let orders: Vec<usize> = (2..=opts.max_order.min(max_order_for(lines))).step_by(2).collect();
    // Neighbouring orders cost about the same, so a batch's threads end
    // together.
    let batch = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut trace = Vec::new();
    let mut models: Vec<(usize, MatrixModel, f64)> = Vec::new();
    'search: for chunk in orders.chunks(batch) {
        let fits = map_on_threads(chunk, |order| fit_matrix_order(data, *order, opts));
        for (order, fit) in chunk.iter().zip(fits) {
            let m = match fit {
                Ok(m) => m,
                Err(e) if models.is_empty() => return Err(e),
                Err(_) => break 'search,
            };
            trace.push((*order, data.weighted_rms(&m)));
            models.push((*order, m.clone(), data.rss(&m)));
            let best = data.best_bic(&models);
            if models.len() - 1 - best >= BIC_PATIENCE {
                break 'search;
            }
        }
    }
    if !models.iter().any(|m| m.2.is_finite()) {
        bail!("matrix vector fitting failed at every order");
    }
    let best = data.best_bic(&models);
    let sigma2 = data.noise_scale(&models);
    let (order, model, rss) = models.swap_remove(best);
    let (split, splits) = split_close_modes(data, opts, (order, model.clone(), rss), sigma2);
    // Missing modes are seeded after the split, which fits close modes the
    // order search took as one pair: the residual beside such a pair is
    // theirs, not a missing mode's.
    let (split, seeded) =
        if opts.seed_unfitted { seed_unfitted_modes(data, split.1, split.2, sigma2) } else { (split.1, Vec::new()) };
    let finished = |m: MatrixModel| drop_unsupported_pairs(data, skim(data, opts.f_identified_hz, m)?, sigma2);
    let unsplit = match splits {
        0 => None,
        _ => Some(finished(model)?),
    };
    let (model, dropped_hz) = finished(split)?;
    let seeded_poles: Vec<Complex64> = seeded.iter().map(|s| s.1).collect();
    let model = prune_seeded(data, model, sigma2, &seeded_poles)?;
    let model = match splits {
        0 => model,
        _ => prune_close_pairs(data, model, sigma2)?,
    };
    // The seeded pairs the model still holds (a later drop may take one).
    let seeded_hz = seeded.iter().filter(|s| term_of_pole(&model, s.1).is_some()).map(|s| s.0).collect();
    Ok(MatrixFitStages { model, dropped_hz, unsplit, splits, seeded_hz, order_trace: trace, sigma2 })
}

impl MatrixFitStages {
    /// The fit: refined where `opts.refine` ([`refined`]), a pair above the
    /// lines swapped in where `opts.above_band_swap` ([`above_band_swap`]),
    /// rank-one residues where `opts.rank_one_residues`
    /// ([`super::rank_one::rank_one_residues`]).
    pub fn finish(&self, data: &MatrixData, opts: &VfOptions) -> Result<MatrixFit> {
        let (unsplit, unsplit_dropped_hz) = match &self.unsplit {
            None => (None, Vec::new()),
            Some((m, dropped)) => (Some(refined(data, m.clone(), opts)?), dropped.clone()),
        };
        let model = refined(data, self.model.clone(), opts)?;
        let model = if opts.above_band_swap { above_band_swap(data, model, opts)? } else { model };
        let (model, unsplit) = if opts.rank_one_residues {
            let lines = super::rank_one::Lines { freq_hz: data.freq_hz, h: data.h, w: data.w };
            let held = |m: &MatrixModel| {
                super::rank_one::rank_one_residues(&lines, &m.entries, self.sigma2)
                    .map(|r| MatrixModel { entries: r.entries })
            };
            (held(&model)?, unsplit.as_ref().map(held).transpose()?)
        } else {
            (model, unsplit)
        };
        if !model.is_stable() {
            bail!("matrix vector fitting: the fitted model is unstable");
        }
        let weighted_rms = data.weighted_rms(&model);
        Ok(MatrixFit {
            weighted_rms,
            model,
            order_trace: self.order_trace.clone(),
            unsplit,
            splits: self.splits,
            seeded_hz: self.seeded_hz.clone(),
            dropped_hz: self.dropped_hz.clone(),
            unsplit_dropped_hz,
        })
    }
}

/// `model` refined to the maximum-likelihood model with its poles
/// ([`super::refine::refine_common`]: the common poles and every entry's
/// residues and direct term, terms an entry does without left out), where
/// `opts.refine`.
fn refined(data: &MatrixData, model: MatrixModel, opts: &VfOptions) -> Result<MatrixModel> {
    if !opts.refine {
        return Ok(model);
    }
    let f_low = lowest_identified_hz(data.freq_hz, opts.f_identified_hz);
    let entries: Vec<(&[Complex64], &[f64])> = (0..ENTRIES).map(|e| (data.h[e], data.w[e])).collect();
    let entries = super::refine::refine_common(data.freq_hz, &entries, &model.entries, f_low, opts.f_ceiling_hz)?;
    Ok(MatrixModel { entries })
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

    /// Mean weighted residual per real data point, in units of `sigma2`,
    /// on the lines within the half-power bandwidth of the pole `p` (rad/s,
    /// Im > 0): ω with |ω − Im p| ≤ −Re p. 0 without such lines.
    fn local_excess(&self, model: &MatrixModel, p: Complex64, sigma2: f64) -> f64 {
        let (mut sum, mut points) = (0.0, 0usize);
        for (k, f) in self.freq_hz.iter().enumerate() {
            if (2.0 * PI * f - p.im).abs() > -p.re {
                continue;
            }
            let g = model.frf(*f);
            for e in 0..ENTRIES {
                if self.w[e][k] > 0.0 {
                    sum += self.w[e][k] * (g[(e / 3, e % 3)] - self.h[e][k]).norm_sqr();
                    points += 2;
                }
            }
        }
        if points == 0 {
            0.0
        } else {
            sum / sigma2 / points as f64
        }
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

    /// The noise scale σ̂² of [`Self::bic`]: RSS/(N − p) of the
    /// lowest-residual fit of `fits` ((order, model, rss)).
    fn noise_scale(&self, fits: &[(usize, MatrixModel, f64)]) -> f64 {
        let n = self.points() as f64;
        fits.iter()
            .filter(|f| f.2.is_finite())
            .map(|f| f.2 / (n - (f.0 + ENTRIES * (f.0 + 1)) as f64).max(1.0))
            .fold(f64::INFINITY, f64::min)
    }

    /// Index of the least-BIC fit of `fits` ((order, model, rss)).
    fn best_bic(&self, fits: &[(usize, MatrixModel, f64)]) -> usize {
        let sigma2 = self.noise_scale(fits);
        let bic =
            |f: &(usize, MatrixModel, f64)| if f.2.is_finite() { self.bic(f.2, f.0, sigma2) } else { f64::INFINITY };
        (0..fits.len()).min_by(|&a, &b| bic(&fits[a]).total_cmp(&bic(&fits[b]))).unwrap_or(0)
    }
}

/// Most pole pairs [`split_close_modes`] adds.
pub const MAX_SPLITS: usize = 4;

/// Least mean χ² per real data point (in units of the order search's noise
/// scale) within a pole's half-power bandwidth for a split to be tried:
/// where the fit leaves no more than the noise, a second mode cannot help.
const SPLIT_EXCESS: f64 = 1.2;

/// Half the relative spacing of the two pairs a split starts from.
const SPLIT_SPACING: f64 = 0.005;

/// Close modes the order search fitted as one pair, each fitted as two.
///
/// Two modes a few tenths of a percent apart, seen in different channels
/// (the base's x and y translations on the machine table), overlap within
/// their half-power bandwidths. The relocation from linearly spaced
/// starting poles puts one pair there at every order, and spends the higher
/// orders' poles elsewhere; the one pair misses each mode by several percent
/// of |G| at its peak, where a milling force's tooth-passing harmonics lie.
/// Each pair is tried split into two at ω(1 ± [`SPLIT_SPACING`]) and
/// relocated from there ([`fit_matrix_from`]); the split of least
/// [`MatrixData::bic`] is kept if it lowers the BIC, with the order search's
/// noise scale `sigma2`, and the search repeats, up to [`MAX_SPLITS`]
/// times. `fit` is (order, model, RSS); returns the same after the splits,
/// and the pairs added.
fn split_close_modes(
    data: &MatrixData,
    opts: &VfOptions,
    fit: (usize, MatrixModel, f64),
    sigma2: f64,
) -> ((usize, MatrixModel, f64), usize) {
    let (mut order, mut model, mut rss) = fit;
    let mut splits = 0;
    let f_top = data.f_max();
    let w_scale = 2.0 * PI * f_top;
    // After the first round, only the pairs whose split lowered the BIC in
    // the round before: a split keeps every other pole, so a pair whose own
    // split did not help has the same fit around it as before.
    let mut promising: Option<Vec<Complex64>> = None;
    for _ in 0..MAX_SPLITS {
        let poles: Vec<(Complex64, bool)> = (0..model.terms()).map(|k| model.pole(k)).collect();
        let pairs: Vec<usize> = (0..poles.len())
            .filter(|&k| poles[k].1 && poles[k].0.im / (2.0 * PI) < f_top)
            .filter(|&k| {
                promising.as_ref().is_none_or(|ps| ps.iter().any(|q| (q - poles[k].0).norm() <= 1e-9 * q.norm()))
            })
            .filter(|&k| data.local_excess(&model, poles[k].0, sigma2) > SPLIT_EXCESS)
            .collect();
        let trials = map_on_threads(&pairs, |&k| {
            let (p, _) = poles[k];
            let mut start = poles.clone();
            start[k] = (Complex64::new(p.re, p.im * (1.0 - SPLIT_SPACING)), true);
            start.push((Complex64::new(p.re, p.im * (1.0 + SPLIT_SPACING)), true));
            let relocated = fit_matrix_from(data, &start, opts).ok()?;
            // The two pairs of the relocation nearest p, both within its
            // half-power bandwidth; every other pole stays where the order
            // search put it, so the split changes this mode alone.
            let mut near: Vec<Complex64> =
                (0..relocated.terms()).map(|t| relocated.pole(t)).filter(|q| q.1).map(|q| q.0).collect();
            near.sort_by(|a, b| (a - p).norm().total_cmp(&(b - p).norm()));
            let reach = 2.0 * (-p.re);
            if near.len() < 2 || !((near[1] - p).norm() <= reach) || (near[0] - near[1]).norm() < 1e-6 * p.norm() {
                return None;
            }
            let mut split: Vec<Pole> = poles
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != k)
                .map(|(_, (q, pair))| Pole { p: q / w_scale, pair: *pair })
                .collect();
            split.extend(near[..2].iter().map(|q| Pole { p: q / w_scale, pair: true }));
            let m = fit_residues(data, &split, w_scale).ok().filter(|m| m.is_stable())?;
            let r = data.rss(&m);
            r.is_finite().then_some((m, r, p))
        });
        let current = data.bic(rss, order, sigma2);
        let mut scored: Vec<(f64, MatrixModel, f64, Complex64)> =
            trials.into_iter().flatten().map(|(m, r, p)| (data.bic(r, order + 2, sigma2), m, r, p)).collect();
        let best =
            (0..scored.len()).min_by(|&a, &b| scored[a].0.total_cmp(&scored[b].0)).map(|i| scored.swap_remove(i));
        promising = Some(scored.iter().filter(|t| t.0 < current).map(|t| t.3).collect());
        match best {
            Some((bic, m, r, _)) if bic < current => {
                (order, model, rss) = (order + 2, m, r);
                splits += 1;
            }
            _ => break,
        }
    }
    ((order, model, rss), splits)
}

pub use super::seed::{ResidualWindow, EXCESS_WINDOW, MAX_SEEDS};

impl MatrixData<'_> {
    /// Per line, Σ_e w_e|Ĝ_e − H_e|² over the nine entries, and the real
    /// data points on it (two per entry of positive weight).
    pub fn line_residuals(&self, model: &MatrixModel) -> Vec<(f64, usize)> {
        self.freq_hz
            .iter()
            .enumerate()
            .map(|(k, f)| {
                let g = model.frf(*f);
                (0..ENTRIES).filter(|&e| self.w[e][k] > 0.0).fold((0.0, 0), |(sum, n), e| {
                    (sum + self.w[e][k] * (g[(e / 3, e % 3)] - self.h[e][k]).norm_sqr(), n + 2)
                })
            })
            .collect()
    }

    /// Windows where `model` leaves more χ² than the noise scale `sigma2`
    /// explains ([`super::seed::excess_windows`] over the nine entries'
    /// residuals per line), the largest excess first.
    pub fn residual_excess(&self, model: &MatrixModel, sigma2: f64) -> Vec<ResidualWindow> {
        super::seed::excess_windows(self.freq_hz, &self.line_residuals(model), sigma2)
    }
}

/// Modes the order search left out, each added as a pair where the fit's
/// residual over the nine entries exceeds the noise
/// ([`super::seed::seed_pairs`]), after the split: a window at a fitted
/// pair is the split's ([`split_close_modes`]), a second pair there is a
/// close mode, not a missing one. The BIC's penalty of a pair counts its
/// pole and nine complex residues. `rss` is `model`'s weighted residual;
/// returns the model and, per pair seeded, the line (Hz) and the pole
/// (rad/s).
fn seed_unfitted_modes(
    data: &MatrixData,
    model: MatrixModel,
    rss: f64,
    sigma2: f64,
) -> (MatrixModel, Vec<(f64, Complex64)>) {
    let w_scale = 2.0 * PI * data.f_max();
    let poles = |m: &MatrixModel| -> Vec<Pole> {
        (0..m.terms()).map(|k| m.pole(k)).map(|(p, pair)| Pole { p: p / w_scale, pair }).collect()
    };
    let residuals = |m: &MatrixModel| data.line_residuals(m);
    let refit = |with: &[Pole]| {
        let m = fit_residues(data, with, w_scale).ok().filter(|m| m.is_stable())?;
        let r = data.rss(&m);
        Some((m, r))
    };
    let seeding = super::seed::Seeding {
        freq_hz: data.freq_hz,
        w_scale,
        sigma2,
        pair_penalty: (2 + 2 * ENTRIES) as f64 * (data.points() as f64).ln(),
        skip_at_pairs: true,
        lowest_window_hz: 0.0,
        highest_peak_hz: f64::INFINITY,
        resolved_lines: 0.0,
        poles: &poles,
        residuals: &residuals,
        refit: &refit,
    };
    super::seed::seed_pairs(&seeding, model, rss)
}

/// Largest cluster of close pairs whose subsets are tried per entry.
const MAX_CLUSTER: usize = 4;

/// Per entry, the terms of each cluster of close pairs (each within
/// another's half-power bandwidth) that the entry's lines support.
///
/// Close pairs' columns are nearly collinear: in an entry that sees
/// neither mode (a channel the two modes do not move), the least squares
/// gives them large residues of opposite sign, fitted to the noise, and the
/// compensator's other rows pay for it through the inverse. Per entry, each
/// subset of a cluster's terms is fitted and the one of least BIC kept (the
/// residues of the others set to zero; the poles stay common). Terms left
/// with no residue in any entry are dropped.
fn prune_close_pairs(data: &MatrixData, model: MatrixModel, sigma2: f64) -> Result<MatrixModel> {
    let groups = close_clusters(&model);
    prune_per_entry(data, model, sigma2, &groups, 1)
}

/// Per entry, each pair [`seed_unfitted_modes`] added (`seeded`, its pole
/// in rad/s) kept or left out by the BIC ([`prune_per_entry`]): a weak
/// mode that a few impacts barely support is seen in some entries only,
/// and in the others its residue would follow the noise.
fn prune_seeded(data: &MatrixData, model: MatrixModel, sigma2: f64, seeded: &[Complex64]) -> Result<MatrixModel> {
    let groups: Vec<Vec<usize>> = seeded.iter().filter_map(|p| term_of_pole(&model, *p)).map(|k| vec![k]).collect();
    prune_per_entry(data, model, sigma2, &groups, 0)
}

/// The term of `model` whose pole is `p` (rad/s; to rounding), if any.
fn term_of_pole(model: &MatrixModel, p: Complex64) -> Option<usize> {
    (0..model.terms()).find(|&k| (model.pole(k).0 - p).norm() <= 1e-9 * p.norm())
}

/// Clusters of close pairs (connected components of "within another's
/// half-power bandwidth"), of two to [`MAX_CLUSTER`] terms.
fn close_clusters(model: &MatrixModel) -> Vec<Vec<usize>> {
    let terms = model.terms();
    let poles: Vec<(Complex64, bool)> = (0..terms).map(|k| model.pole(k)).collect();
    let close = |a: usize, b: usize| {
        let (pa, pb) = (poles[a].0, poles[b].0);
        poles[a].1 && poles[b].1 && within_bandwidth(pa, pb)
    };
    // Clusters: connected components of `close`.
    let mut cluster: Vec<usize> = (0..terms).collect();
    for a in 0..terms {
        for b in a + 1..terms {
            if close(a, b) {
                let (ca, cb) = (cluster[a], cluster[b]);
                cluster.iter_mut().filter(|c| **c == cb).for_each(|c| *c = ca);
            }
        }
    }
    (0..terms)
        .map(|c| (0..terms).filter(|&k| cluster[k] == c).collect::<Vec<_>>())
        .filter(|g| g.len() > 1 && g.len() <= MAX_CLUSTER)
        .collect()
}

/// Per entry, the subset of each group of terms `groups` (of at least
/// `least` terms) of least BIC, the residues of the others set to zero (the
/// poles stay common); terms left with no residue in any entry are dropped.
fn prune_per_entry(
    data: &MatrixData,
    model: MatrixModel,
    sigma2: f64,
    groups: &[Vec<usize>],
    least: u32,
) -> Result<MatrixModel> {
    if groups.is_empty() {
        return Ok(model);
    }
    let terms = model.terms();
    let w_scale = 2.0 * PI * data.f_max();
    let s: Vec<Complex64> = data.freq_hz.iter().map(|f| Complex64::new(0.0, 2.0 * PI * f / w_scale)).collect();
    let ln_n = (data.points() as f64).ln();
    let mut out = model.clone();
    for e in 0..ENTRIES {
        let sw: Vec<f64> = data.w[e].iter().map(|w| w.sqrt()).collect();
        let fit = |keep: &[bool]| -> Result<(PoleResidueModel, f64)> {
            let kept = kept_poles(&model.entries[e].terms, keep, w_scale);
            let (c, d) = residues(&s, data.h[e], &sw, &kept)?;
            let m = to_model(&kept, &c, d, w_scale);
            let rss = data
                .freq_hz
                .iter()
                .enumerate()
                .map(|(k, f)| data.w[e][k] * (m.frf(*f) - data.h[e][k]).norm_sqr())
                .sum();
            Ok((m, rss))
        };
        let mut keep = vec![true; terms];
        for g in groups {
            let mut best: Option<(f64, u32)> = None;
            for subset in (0..(1u32 << g.len())).filter(|s| s.count_ones() >= least) {
                for (bit, &k) in g.iter().enumerate() {
                    keep[k] = subset & (1 << bit) != 0;
                }
                let (_, rss) = fit(&keep)?;
                let bic = rss / sigma2 + 2.0 * f64::from(subset.count_ones()) * ln_n;
                if best.is_none_or(|(b, _)| bic < b) {
                    best = Some((bic, subset));
                }
            }
            let subset = best.map_or(0, |b| b.1);
            for (bit, &k) in g.iter().enumerate() {
                keep[k] = subset & (1 << bit) != 0;
            }
        }
        let (m, _) = fit(&keep)?;
        // Back to the common terms: zero residues where dropped.
        let mut fitted = m.terms.into_iter();
        let entry = &mut out.entries[e];
        for (k, t) in entry.terms.iter_mut().enumerate() {
            *t = if keep[k] {
                fitted.next().expect("one fitted term per kept pole")
            } else {
                match *t {
                    Term::Real { pole, .. } => Term::Real { pole, residue: 0.0 },
                    Term::Pair { pole, .. } => Term::Pair { pole, residue: Complex64::new(0.0, 0.0) },
                }
            };
        }
        entry.d = m.d;
    }
    let nonzero = |t: &Term| match *t {
        Term::Real { residue, .. } => residue != 0.0,
        Term::Pair { residue, .. } => residue.norm() > 0.0,
    };
    let used: Vec<bool> = (0..terms).map(|k| out.entries.iter().any(|e| nonzero(&e.terms[k]))).collect();
    for e in &mut out.entries {
        let mut k = 0;
        e.terms.retain(|_| {
            k += 1;
            used[k - 1]
        });
    }
    Ok(out)
}

/// Pole pairs the lines do not support, dropped one at a time (backward
/// elimination by the Bayesian information criterion of
/// [`MatrixData::bic`]).
///
/// The order search compares whole fits: the best order's fit can hold
/// lightly damped pairs that follow only the noise of some cross entries,
/// and each such pair is an inverse's near-zero the compensator pays for.
/// A pair costs 2 + 2·9 real parameters (its pole, and a complex residue
/// per entry); it goes where the rise of the weighted residual from
/// refitting every residue without it, ΔRSS/σ̂², is below 20·ln N. The pair
/// of least rise goes first, and the rises are computed again after each
/// drop. The rise of every pair comes from one QR of each entry's
/// least-squares system: for min‖b − A x‖ and the columns K of a term,
/// ΔRSS = x̂_Kᵀ [(AᵀA)⁻¹_KK]⁻¹ x̂_K (the partial F statistic's numerator);
/// the model kept is refitted exactly ([`refit_kept`]). Returns the model
/// and the natural frequencies (Hz) of the pairs dropped.
pub fn drop_unsupported_pairs(data: &MatrixData, model: MatrixModel, sigma2: f64) -> Result<(MatrixModel, Vec<f64>)> {
    let penalty = (2 + 2 * ENTRIES) as f64 * (data.points() as f64).ln();
    let mut model = model;
    let mut dropped = Vec::new();
    if !(sigma2 > 0.0 && sigma2.is_finite()) {
        return Ok((model, dropped));
    }
    loop {
        let rises = pair_rises(data, &model)?;
        let best = rises.iter().enumerate().filter_map(|(k, r)| r.map(|r| (k, r))).min_by(|a, b| a.1.total_cmp(&b.1));
        let Some((k, rise)) = best else { break };
        if !(rise / sigma2 < penalty) {
            break;
        }
        let (p, _) = model.pole(k);
        let keep: Vec<bool> = (0..model.terms()).map(|t| t != k).collect();
        model = refit_kept(data, &model, &keep)?;
        dropped.push(p.norm() / (2.0 * PI));
    }
    Ok((model, dropped))
}

/// Per term of `model`, the rise Σ_e ΔRSS_e of the weighted residual from
/// refitting every entry's residues and direct term without it
/// ([`drop_unsupported_pairs`]); `None` for a real pole.
fn pair_rises(data: &MatrixData, model: &MatrixModel) -> Result<Vec<Option<f64>>> {
    let w_scale = 2.0 * PI * data.f_max();
    let poles = kept_poles(&model.entries[0].terms, &vec![true; model.terms()], w_scale);
    let n = n_cols(&poles);
    let s: Vec<Complex64> = data.freq_hz.iter().map(|f| Complex64::new(0.0, 2.0 * PI * f / w_scale)).collect();
    let mut row = Vec::with_capacity(n);
    let basis: Vec<Vec<Complex64>> = s
        .iter()
        .map(|si| {
            basis_row(*si, &poles, &mut row);
            row.clone()
        })
        .collect();
    // Each pair's first column.
    let mut columns = Vec::new();
    let mut j = 0;
    for p in &poles {
        columns.push(p.pair.then_some(j));
        j += if p.pair { 2 } else { 1 };
    }
    let entries: Vec<usize> = (0..ENTRIES).collect();
    let per_entry = map_on_threads(&entries, |&e| -> Result<Vec<Option<f64>>> {
        let k = s.len();
        // [A | b], weighted, A's columns equilibrated (ΔRSS does not depend
        // on the columns' scale).
        let mut a = DMatrix::<f64>::zeros(2 * k, n + 2);
        for i in 0..k {
            let w = data.w[e][i].sqrt();
            for (c, v) in basis[i].iter().enumerate() {
                (a[(2 * i, c)], a[(2 * i + 1, c)]) = ((v * w).re, (v * w).im);
            }
            a[(2 * i, n)] = w;
            let b = data.h[e][i] * w;
            (a[(2 * i, n + 1)], a[(2 * i + 1, n + 1)]) = (b.re, b.im);
        }
        if a.iter().any(|v| !v.is_finite()) {
            bail!("matrix vector fitting: entry {e}'s least-squares rows are not finite");
        }
        for c in 0..=n {
            let norm = a.column(c).norm();
            if norm > 0.0 {
                a.column_mut(c).scale_mut(1.0 / norm);
            }
        }
        let r_aug = crate::numeric::dense::qr_r_in_place(&mut a);
        let r = r_aug.view((0, 0), (n + 1, n + 1)).into_owned();
        let z = r_aug.view((0, n + 1), (n + 1, 1)).into_owned();
        let Some(x) = r.solve_upper_triangular(&z) else { return Ok(vec![None; columns.len()]) };
        let Some(r_inv) = r.solve_upper_triangular(&DMatrix::identity(n + 1, n + 1)) else {
            return Ok(vec![None; columns.len()]);
        };
        Ok(columns
            .iter()
            .map(|c| {
                let j = (*c)?;
                // (AᵀA)⁻¹_KK = R⁻¹_K· (R⁻¹_K·)ᵀ for the rows K = {j, j+1}.
                let (u, v) = (r_inv.row(j), r_inv.row(j + 1));
                let (s11, s12, s22) = (u.dot(&u), u.dot(&v), v.dot(&v));
                let det = s11 * s22 - s12 * s12;
                let (x1, x2) = (x[j], x[j + 1]);
                let rise = (s22 * x1 * x1 - 2.0 * s12 * x1 * x2 + s11 * x2 * x2) / det;
                rise.is_finite().then_some(rise.max(0.0))
            })
            .collect())
    });
    let mut total = vec![Some(0.0); columns.len()];
    for rises in per_entry {
        for (t, r) in total.iter_mut().zip(rises?) {
            *t = match (*t, r) {
                (Some(a), Some(b)) => Some(a + b),
                _ => None,
            };
        }
    }
    for (t, c) in total.iter_mut().zip(&columns) {
        if c.is_none() {
            *t = None;
        }
    }
    Ok(total)
}

/// Natural frequencies, as multiples of the last line's, of the pair tried
/// above the lines in place of a pair in the band's top part
/// ([`above_band_swap`]).
const ABOVE_BAND_FREQUENCY: [f64; 7] = [1.05, 1.15, 1.3, 1.5, 1.75, 2.0, 2.5];
/// Damping ratios of that pair.
const ABOVE_BAND_DAMPING: [f64; 3] = [0.01, 0.025, 0.05];

/// Lowest fraction of the last line's frequency at which a pair may give
/// way to one above the lines ([`above_band_swap`]).
const SWAP_FROM_FRACTION: f64 = 0.6;

/// `model`, or the model in which one pair in the band's top part
/// (natural frequency above [`SWAP_FROM_FRACTION`] of the last line) gives
/// way to a pair above the lines, whichever fits the lines better after
/// refinement. The two have as many parameters, so the lower weighted
/// residual is the higher likelihood.
///
/// Modes above the impact test's last line reach into the band as a
/// residual flexibility that grows towards the top. Pole relocation can
/// settle on a damped pair inside the band for it: it follows the lines as
/// well within their noise, but it bends Ĝ against the true G near the
/// band's top, where every compensator distorts most, and the fit's
/// variance cannot show it.
fn above_band_swap(data: &MatrixData, model: MatrixModel, opts: &VfOptions) -> Result<MatrixModel> {
    let f_top = data.f_max();
    let w_scale = 2.0 * PI * f_top;
    let terms = &model.entries[0].terms;
    let mut best: Option<(f64, MatrixModel)> = None;
    for k in 0..terms.len() {
        let (p, pair) = model.pole(k);
        let f_n = fn_hz(p);
        if !pair || f_n < SWAP_FROM_FRACTION * f_top || f_n > f_top {
            continue;
        }
        let keep: Vec<bool> = (0..terms.len()).map(|t| t != k).collect();
        let kept = kept_poles(terms, &keep, w_scale);
        // Normalized by w_scale, the last line is at 1.
        for m in ABOVE_BAND_FREQUENCY {
            for zeta in ABOVE_BAND_DAMPING {
                let mut poles = kept.clone();
                poles.push(Pole { p: pole_at(m, zeta), pair: true });
                let Ok(c) = fit_residues(data, &poles, w_scale) else { continue };
                let r = data.rss(&c);
                if r.is_finite() && best.as_ref().is_none_or(|(b, _)| r < *b) {
                    best = Some((r, c));
                }
            }
        }
    }
    let Some((_, candidate)) = best else { return Ok(model) };
    let Ok(candidate) = refined(data, candidate, opts) else { return Ok(model) };
    let (before, after) = (data.rss(&model), data.rss(&candidate));
    Ok(if after < before && candidate.is_stable() { candidate } else { model })
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
    let f_low = lowest_identified_hz(data.freq_hz, f_identified_hz);
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

/// `truth` on the lines `freq` (Hz) with complex noise of RMS `noise`
/// (uniform, seeded by `seed`), weights 1/noise²: the tests' impact test.
#[cfg(test)]
pub(crate) fn noisy_lines(
    truth: &MatrixModel,
    noise: f64,
    freq: Vec<f64>,
    seed: u64,
) -> (Vec<f64>, Vec<Vec<Complex64>>, Vec<f64>) {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut uniform = move || rng.random_range(-0.5..0.5);
    let h: Vec<Vec<Complex64>> = (0..ENTRIES)
        .map(|e| {
            freq.iter()
                .map(|f| {
                    let n = Complex64::new(uniform(), uniform()) * (noise * 12f64.sqrt() / 2f64.sqrt());
                    truth.frf(*f)[(e / 3, e % 3)] + n
                })
                .collect()
        })
        .collect();
    let w = vec![1.0 / (noise * noise); freq.len()];
    (freq, h, w)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The nine entries `h` on the lines `freq`, every entry weighted by `w`.
    fn shared_weights<'a>(freq: &'a [f64], h: &'a [Vec<Complex64>], w: &'a [f64]) -> MatrixData<'a> {
        MatrixData { freq_hz: freq, h: std::array::from_fn(|e| h[e].as_slice()), w: std::array::from_fn(|_| w) }
    }

    /// Lines (Hz), the nine measured entries, the weights, the two poles
    /// and the true model of [`close_modes`].
    type CloseModes = (Vec<f64>, Vec<Vec<Complex64>>, Vec<f64>, [Complex64; 2], MatrixModel);

    /// Two modes 0.8 % apart (211.6 and 213.4 Hz, 4 % damping), the first
    /// seen only in G_xx, the second only in G_yy; every other entry holds
    /// a direct term alone. Measured on 1 Hz lines to 1 kHz with complex
    /// noise of RMS `noise` (deterministic), weights 1/noise².
    fn close_modes(noise: f64) -> CloseModes {
        let pole = |f: f64, zeta: f64| pole_at(2.0 * PI * f, zeta);
        let poles = [pole(211.6, 0.04), pole(213.4, 0.035)];
        let mut truth_terms = Vec::new();
        for e in 0..ENTRIES {
            let d = if e % 4 == 0 { 1.0 } else { 0.02 };
            let terms = poles
                .iter()
                .enumerate()
                .map(|(k, p)| {
                    let seen = (e == 0 && k == 0) || (e == 4 && k == 1);
                    let r = if seen { Complex64::new(0.0, -0.08 * p.im) } else { Complex64::new(0.0, 0.0) };
                    Term::Pair { pole: *p, residue: r }
                })
                .collect();
            truth_terms.push(PoleResidueModel { terms, d });
        }
        let truth = MatrixModel { entries: truth_terms };
        let (freq, h, w) = measured(&truth, noise);
        (freq, h, w, poles, truth)
    }

    /// `truth` measured on 1 Hz lines to 1 kHz with complex noise of RMS
    /// `noise` (deterministic), weights 1/noise².
    fn measured(truth: &MatrixModel, noise: f64) -> (Vec<f64>, Vec<Vec<Complex64>>, Vec<f64>) {
        noisy_lines(truth, noise, (1..=1000).map(f64::from).collect(), 7)
    }

    /// The close modes' truth with a third pair at 600 Hz (2 % damping) of
    /// residue `c`·ω in G_zz alone (peak |G| ≈ c/ζ), measured with noise
    /// 2·10⁻³, and the model with all three poles fitted to the lines.
    fn third_pair(c: f64) -> (Vec<f64>, Vec<Vec<Complex64>>, Vec<f64>, MatrixModel) {
        let (_, _, _, _, mut truth) = close_modes(2e-3);
        let w = 2.0 * PI * 600.0;
        let p = Complex64::new(-0.02 * w, w * (1.0f64 - 0.02 * 0.02).sqrt());
        for (e, entry) in truth.entries.iter_mut().enumerate() {
            let r = if e == 8 { Complex64::new(0.0, -c * p.im) } else { Complex64::new(0.0, 0.0) };
            entry.terms.push(Term::Pair { pole: p, residue: r });
        }
        let (freq, h, wt) = measured(&truth, 2e-3);
        let data = shared_weights(&freq, &h, &wt);
        let fitted = refit_kept(&data, &truth, &[true; 3]).unwrap();
        (freq.clone(), h.clone(), wt.clone(), fitted)
    }

    /// A pair the lines do not show (no residue at 600 Hz in any entry) is
    /// dropped, the two close modes stay; each pair's rise from the one QR
    /// equals the rise of refitting without it. Negative control: the same
    /// pair seen in G_zz at 4x the noise at its peak stays.
    #[test]
    fn pairs_the_lines_do_not_support_are_dropped() {
        for (c, drops) in [(0.0, true), (4e-4, false)] {
            let (freq, h, w, fitted) = third_pair(c);
            let data = shared_weights(&freq, &h, &w);
            let rises = pair_rises(&data, &fitted).unwrap();
            let full = data.rss(&fitted);
            for (k, rise) in rises.iter().enumerate() {
                let keep: Vec<bool> = (0..3).map(|t| t != k).collect();
                let refit = data.rss(&refit_kept(&data, &fitted, &keep).unwrap()) - full;
                let rise = rise.expect("a pair");
                assert!((rise - refit).abs() <= 1e-6 * refit.abs() + 1e-6, "term {k}: {rise} against {refit}");
            }
            let (kept, dropped) = drop_unsupported_pairs(&data, fitted, 0.5).unwrap();
            if drops {
                assert_eq!(dropped.len(), 1, "{dropped:?}");
                assert!((dropped[0] - 600.0).abs() < 1.0, "{dropped:?}");
                assert_eq!(kept.terms(), 2);
                assert!(kept.modes().iter().all(|(f, _)| (*f - 212.5).abs() < 2.0), "{:?}", kept.modes());
            } else {
                assert!(dropped.is_empty(), "control: the seen pair was dropped: {dropped:?}");
                assert_eq!(kept.terms(), 3);
            }
        }
    }

    /// A pair at (`f`, ζ) Hz with residue `c`·ω in the entries `seen`.
    fn pair_in(f: f64, zeta: f64, c: f64, seen: &[usize]) -> Vec<Term> {
        let w = 2.0 * PI * f;
        let pole = pole_at(w, zeta);
        (0..ENTRIES)
            .map(|e| {
                let r = if seen.contains(&e) { Complex64::new(0.0, -c * w) } else { Complex64::new(0.0, 0.0) };
                Term::Pair { pole, residue: r }
            })
            .collect()
    }

    /// Modes at 300 (ζ 0.03) and 700 Hz (ζ 0.025) in the direct entries
    /// (direct term 1), a direct term of 0.02 in the cross entries.
    fn two_direct_modes() -> MatrixModel {
        let diag = [0, 4, 8];
        let mut truth = MatrixModel {
            entries: (0..ENTRIES)
                .map(|e| PoleResidueModel { terms: Vec::new(), d: if diag.contains(&e) { 1.0 } else { 0.02 } })
                .collect(),
        };
        truth.add(pair_in(300.0, 0.03, 0.05, &diag));
        truth.add(pair_in(700.0, 0.025, 0.04, &diag));
        truth
    }

    impl MatrixModel {
        /// One term per entry added, `terms` row by row.
        fn add(&mut self, terms: Vec<Term>) {
            for (entry, t) in self.entries.iter_mut().zip(terms) {
                entry.terms.push(t);
            }
        }
    }

    /// Modes at 300 and 700 Hz in the direct entries and, where `above`, a
    /// one at 1370 Hz (above the last line, 1 kHz) in G_xx and G_zx.
    /// Given the model with the best damped pair inside the band in its
    /// place (750-990 Hz, ζ 0.05-0.4), [`above_band_swap`] moves that pair
    /// above the lines: the residual falls, and Ĝ at 800-1000 Hz comes three
    /// times closer to the true G. Negative control: without the mode above the
    /// lines, the model of the true poles stays as it is.
    #[test]
    fn a_damped_pair_standing_in_for_a_mode_above_the_lines_moves_above_them() {
        for above in [true, false] {
            let mut truth = two_direct_modes();
            if above {
                truth.add(pair_in(1370.0, 0.03, 0.05, &[0, 6]));
            }
            let (freq, h, w) = measured(&truth, 2e-3);
            let data = shared_weights(&freq, &h, &w);
            let w_scale = 2.0 * PI * data.f_max();
            let pole = |f: f64, zeta: f64| Pole { p: pole_at(2.0 * PI * f / w_scale, zeta), pair: true };
            let true_poles = vec![pole(300.0, 0.03), pole(700.0, 0.025)];
            // With the mode above: the best stand-in inside the band, its
            // frequency and damping on a grid, its residues fitted.
            let model = match above {
                false => fit_residues(&data, &true_poles, w_scale).unwrap(),
                true => (0..=12)
                    .flat_map(|i| [0.05, 0.1, 0.2, 0.4].map(|z| (750.0 + 20.0 * f64::from(i), z)))
                    .map(|(f, z)| {
                        let mut poles = true_poles.clone();
                        poles.push(pole(f, z));
                        fit_residues(&data, &poles, w_scale).unwrap()
                    })
                    .min_by(|a, b| data.rss(a).total_cmp(&data.rss(b)))
                    .unwrap(),
            };
            let swapped = above_band_swap(&data, model.clone(), &VfOptions::default()).unwrap();
            let top_error = |m: &MatrixModel| {
                (800..=1000).map(f64::from).map(|f| (m.frf(f) - truth.frf(f)).norm()).fold(0.0, f64::max)
            };
            if above {
                let modes = swapped.modes();
                assert!(modes.iter().any(|(f, _)| *f > 1000.0), "{modes:?}");
                assert!(!modes.iter().any(|(f, z)| (600.0..1000.0).contains(f) && *z > 0.04), "{modes:?}");
                assert!(data.rss(&swapped) < data.rss(&model));
                let (before, after) = (top_error(&model), top_error(&swapped));
                eprintln!("top error {before:.2e} -> {after:.2e}, modes {modes:?}");
                assert!(after < before / 3.0, "{before:.2e} -> {after:.2e}");
            } else {
                assert_eq!(swapped, model, "control: the true poles gave way");
            }
        }
    }

    /// Per entry, the close pair's terms the lines support: G_xx keeps the
    /// mode it sees and drops the other, G_yy the reverse, G_zx (neither)
    /// keeps one; the pruned model stays within the noise of the truth.
    /// Negative control: unpruned, G_xx carries the second mode's term.
    #[test]
    fn close_pairs_keep_per_entry_the_terms_its_lines_support() {
        let noise = 2e-3;
        let (freq, h, w, poles, truth) = close_modes(noise);
        let data = shared_weights(&freq, &h, &w);
        let w_scale = 2.0 * PI * data.f_max();
        let both: Vec<Pole> = poles.iter().map(|p| Pole { p: p / w_scale, pair: true }).collect();
        let full = fit_residues(&data, &both, w_scale).unwrap();
        let pruned = prune_close_pairs(&data, full.clone(), 0.5).unwrap();
        let residue = |m: &MatrixModel, e: usize, k: usize| match m.entries[e].terms[k] {
            Term::Pair { residue, .. } => residue.norm(),
            Term::Real { residue, .. } => residue.abs(),
        };
        assert!(residue(&pruned, 0, 0) > 0.0 && residue(&pruned, 0, 1) == 0.0);
        assert!(residue(&pruned, 4, 1) > 0.0 && residue(&pruned, 4, 0) == 0.0);
        assert!(residue(&full, 0, 1) > 0.0, "control: the unpruned G_xx has no second term");
        // An entry that sees neither mode keeps one term (the fit without
        // the split had one there too).
        assert_eq!((0..2).filter(|&k| residue(&pruned, 6, k) > 0.0).count(), 1);
        // The kept terms still fit the truth to the noise.
        let worst = (180..=250).map(f64::from).map(|f| (pruned.frf(f) - truth.frf(f)).norm()).fold(0.0, f64::max);
        assert!(worst < 3.0 * noise, "{worst:.2e}");
    }

    /// The order search stops [`BIC_PATIENCE`] orders past its best and
    /// keeps the order an exhaustive search to the maximum order finds:
    /// every order fitted, the least BIC with σ̂² from all of them. The
    /// control: the search did stop early, so the two differ in what they
    /// saw (σ̂² from fewer fits).
    #[test]
    fn the_order_search_stops_past_its_best_and_keeps_the_exhaustive_choice() {
        let (freq, h, w, _) = third_pair(0.05);
        let data = shared_weights(&freq, &h, &w);
        let opts = VfOptions { max_order: 40, iterations: 20, ..VfOptions::default() };
        let fit = matrix_vector_fit(&data, &opts).unwrap();
        let searched: Vec<usize> = fit.order_trace.iter().map(|t| t.0).collect();
        let all: Vec<usize> = (2..=40).step_by(2).collect();
        assert!(searched.len() < all.len(), "control: the search fitted every order {searched:?}");
        let fits = |orders: &[usize]| -> Vec<(usize, MatrixModel, f64)> {
            orders
                .iter()
                .map(|&o| {
                    let m = fit_matrix_order(&data, o, &opts).unwrap();
                    let r = data.rss(&m);
                    (o, m, r)
                })
                .collect()
        };
        let (prefix, exhaustive) = (fits(&searched), fits(&all));
        let chosen = |f: &[(usize, MatrixModel, f64)]| f[data.best_bic(f)].0;
        assert_eq!(chosen(&prefix), chosen(&exhaustive));
        // Three pairs in the truth: the order chosen holds at least them.
        assert!(chosen(&prefix) >= 6, "order {}", chosen(&prefix));
        let best = data.best_bic(&prefix);
        assert!(searched.len() - 1 - best >= BIC_PATIENCE, "stopped {searched:?} with the best at {best}");
    }

    /// A chain that cannot take the refined model finishes the same order
    /// search without the refinement: the model equals a plain fit from
    /// scratch. The control: the refined model differs from it, so the
    /// comparison can see which one it got.
    #[test]
    fn the_fit_finished_without_refinement_is_the_plain_fit() {
        let (freq, h, w, _) = third_pair(0.05);
        let data = shared_weights(&freq, &h, &w);
        let opts = VfOptions { max_order: 16, iterations: 20, ..VfOptions::default() };
        let plain = VfOptions { refine: false, ..opts.clone() };
        let stages = matrix_fit_stages(&data, &opts).unwrap();
        let (refined, finished) = (stages.finish(&data, &opts).unwrap(), stages.finish(&data, &plain).unwrap());
        let scratch = matrix_vector_fit(&data, &plain).unwrap();
        let gap =
            |a: &MatrixModel, b: &MatrixModel| freq.iter().map(|f| (a.frf(*f) - b.frf(*f)).norm()).fold(0.0, f64::max);
        assert_eq!(gap(&finished.model, &scratch.model), 0.0);
        assert_eq!(finished.weighted_rms, scratch.weighted_rms);
        assert!(gap(&refined.model, &scratch.model) > 1e-9, "control: the refinement changed nothing");
    }

    /// Modes at 300 and 700 Hz in the direct entries and, where `weak`, one
    /// at 480 Hz (ζ 0.02) seen in G_xx and G_yx at ten times the noise at its
    /// peak. Given the fit of the two strong poles alone, the window of
    /// largest excess lies at the weak mode, and [`seed_unfitted_modes`]
    /// adds one pair there that takes the residual down to the noise;
    /// [`prune_seeded`] keeps it in G_xx and G_yx only. Negative control:
    /// without the weak mode nothing is added.
    #[test]
    fn a_mode_the_fit_left_out_is_seeded_where_the_residual_exceeds_the_noise() {
        for weak in [true, false] {
            let mut truth = two_direct_modes();
            truth.add(pair_in(480.0, 0.02, if weak { 4e-4 } else { 0.0 }, &[0, 3]));
            let (freq, h, w) = measured(&truth, 2e-3);
            let data = shared_weights(&freq, &h, &w);
            let strong = refit_kept(&data, &truth, &[true, true, false]).unwrap();
            let rss = data.rss(&strong);
            // Unit weights per complex value of the noise: σ² 0.5 per real point.
            let sigma2 = 0.5;
            let top = data.residual_excess(&strong, sigma2)[0];
            let before = rss / sigma2 / data.points() as f64;
            let (seeded_model, seeded) = seed_unfitted_modes(&data, strong, rss, sigma2);
            let seeded_rss = data.rss(&seeded_model);
            if !weak {
                assert!(seeded.is_empty(), "control: a pair was seeded without a missing mode: {seeded:?}");
                assert_eq!(seeded_model.terms(), 2);
                continue;
            }
            assert!((top.peak_hz - 480.0).abs() <= 5.0, "largest excess at {:?}", top);
            assert_eq!(seeded.len(), 1, "{seeded:?}");
            assert!((seeded[0].0 - 480.0).abs() <= 5.0, "seeded at {} Hz", seeded[0].0);
            assert_eq!(seeded_model.terms(), 3);
            let chi2 = seeded_rss / sigma2 / data.points() as f64;
            assert!(chi2 < 1.05 && before > 1.05, "χ² per point {before} before the seed, {chi2} after");
            let pruned = prune_seeded(&data, seeded_model, sigma2, &[seeded[0].1]).unwrap();
            let k = term_of_pole(&pruned, seeded[0].1).expect("the seeded term");
            let seen: Vec<usize> = (0..ENTRIES)
                .filter(|&e| matches!(pruned.entries[e].terms[k], Term::Pair { residue, .. } if residue.norm() > 0.0))
                .collect();
            assert_eq!(seen, vec![0, 3]);
        }
    }
}
