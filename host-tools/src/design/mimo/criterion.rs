//! The predicted in-band error of each output axis of a 3x3 compensator
//! ([`crate::design::criterion`] with the crosstalk counted), and the choice
//! of q = (q_x, q_y, q_z) by it.

use anyhow::{bail, Result};
use nalgebra::DMatrix;
use num_complex::Complex64;
use serde::Serialize;
use std::f64::consts::PI;

use super::discrete::CMatrix3;
use crate::design::above_band::{out_of_band_lines, out_of_band_noise_factor};
use crate::design::criterion::{criterion_cells, criterion_grid, with_fit_uncertainty};
use crate::design::force_spectrum::{estimate_matrix, mean_force_matrix, CellSpectrum, ForceRecord};
use crate::fit::refine::FitCovariance;
use crate::frf::axis_name;
use crate::numeric::parallel::map_on_threads;
use crate::numeric::search::brent_min;

/// The lines of one output axis's criterion.
#[derive(Clone, Debug)]
pub struct RowGrid {
    /// The row's compensated band (Hz).
    pub band_hz: (f64, f64),
    /// Lines (Hz): [`criterion_grid`] of the band.
    pub freqs: Vec<f64>,
    /// Ĝ(j2πf) on the lines.
    pub g: Vec<CMatrix3>,
    /// Per force direction j and line, P_j(f)/P_i ([`MatrixCriterion`]).
    pub weight: [Vec<f64>; 3],
    /// The in-band power of force i, P_i (N²).
    pub force_power_n2: f64,
    /// The forces' mean F̄_j/√P_i ([`ForceWeights::mean_share`]), where
    /// the forces have one: then the first of `freqs` is a line at 0 Hz
    /// that carries it (its `weight` 0), counted in the distortion and the
    /// fit's part of J, not in the noise term.
    pub mean: Option<[f64; 3]>,
    /// The covariance of the fitted model's entries on the lines (entry
    /// e = 3m + j for Ĝ_mj), its own uncertainty
    /// ([`MatrixCriterion::with_fit_covariance`]); `None` where not known.
    pub fit_cov: Option<FitCovariance>,
}

/// The force spectra P_j(f) the criterion ([`MatrixCriterion`]) assumes.
///
/// By default the forces are flat, P_j(f) = F_j²/n on n lines for an RMS
/// F_j; with F_x = F_y = F_z this is DESIGN.md's criterion with every entry
/// of the row counted. With a representative record of the cut
/// ([`ForceWeights::Record`]) P_j(f) is the record's force spectrum
/// ([`crate::design::force_spectrum::estimate_matrix`]), with the
/// broadband share of [`crate::design::force_spectrum::MIN_BROADBAND_SHARE`].
#[derive(Clone, Debug)]
pub enum ForceWeights {
    /// Flat spectra of RMS F_j (N) in every row's band.
    Flat([f64; 3]),
    /// Per output axis i, the record's spectrum of every force direction
    /// on row i's cells ([`criterion_cells`] of its band); `level_only`:
    /// flat spectra of the record's in-band powers. `mean_n`: the record's
    /// mean force F̄ = Ĝ(0)⁻¹·ȳ (N), the cut's static force, which lies
    /// below every band and reaches the other axes through the static
    /// crosstalk.
    Record { spectra: Box<[[CellSpectrum; 3]; 3]>, level_only: bool, mean_n: [f64; 3] },
}

impl ForceWeights {
    /// The spectra of `record` (fx, fy, fz) through the inverse of the 3x3
    /// model `g`, on each row's cells: what [`ForceWeights::Record`] holds.
    pub fn from_record(
        record: &ForceRecord,
        g: &dyn Fn(f64) -> CMatrix3,
        bands_hz: [(f64, f64); 3],
        fs_hz: f64,
        r: [f64; 3],
        level_only: bool,
    ) -> Result<Self> {
        let mut channels: [&[f64]; 3] = [&[]; 3];
        for (c, ch) in record.channels.iter().enumerate() {
            let Some(ch) = ch else {
                bail!(
                    "{}: no column f{}: the 3x3 design's force record needs fx, fy and fz",
                    record.source,
                    axis_name(c)
                );
            };
            channels[c] = ch;
        }
        let mut spectra = Vec::with_capacity(3);
        for (i, band) in bands_hz.iter().enumerate() {
            let cells = criterion_cells(&[*band]);
            let s = estimate_matrix(channels, fs_hz, g, r, &cells)
                .map_err(|e| anyhow::anyhow!("{}: row {} of the 3x3 design: {e:#}", record.source, axis_name(i)))?;
            spectra.push(s);
        }
        let spectra: [[CellSpectrum; 3]; 3] = spectra.try_into().map_err(|_| anyhow::anyhow!("three rows expected"))?;
        let mean_n = mean_force_matrix(channels, g).map_err(|e| anyhow::anyhow!("{}: {e:#}", record.source))?;
        Ok(ForceWeights::Record { spectra: Box::new(spectra), level_only, mean_n })
    }

    /// Row i's share of the forces' mean, F̄_j/√P_i for the in-band power
    /// P_i of force i; `None` for flat forces, which have no mean.
    fn mean_share(&self, i: usize) -> Option<[f64; 3]> {
        match self {
            ForceWeights::Flat(_) => None,
            ForceWeights::Record { spectra, mean_n, .. } => {
                let p_i = spectra[i][i].total_n2();
                Some(mean_n.map(|m| m / p_i.sqrt())).filter(|w| p_i > 0.0 && w.iter().all(|v| v.is_finite()))
            }
        }
    }

    /// Row i's weights P_j(f)/P_i and P_i on `n` lines.
    fn row(&self, i: usize, n: usize) -> ([Vec<f64>; 3], f64) {
        let nf = n as f64;
        match self {
            ForceWeights::Flat(f) => (std::array::from_fn(|j| vec![(f[j] / f[i]).powi(2) / nf; n]), f[i] * f[i]),
            ForceWeights::Record { spectra, level_only, .. } => {
                let s = &spectra[i];
                let p: [f64; 3] = std::array::from_fn(|j| s[j].total_n2());
                // Force j's share of its own power per line, with the
                // broadband share (CellSpectrum::weights), scaled to force i's.
                let weight = std::array::from_fn(|j| {
                    if *level_only {
                        vec![p[j] / p[i] / nf; n]
                    } else {
                        s[j].weights().iter().map(|w| w * p[j] / p[i]).collect()
                    }
                });
                (weight, p[i])
            }
        }
    }
}

/// What J of every row needs.
///
/// For output axis i, a compensator H (3x3, or a per-axis one whose row i is
/// H_ii·e_iᵀ) on the plant Ĝ with declared latency L predicts
///
/// J_i = Σ_f Σ_j (P_j(f)/P_i)·|(H(e^{jω})·Ĝ(jω)·e^{jωL} − I)_ij|²
///     + (2/fs)·(W_i/P_i)·Σ_j R_j·mean_f |H_ij(e^{jω})|²,
///
/// ω = 2πf over the lines f of the row's compensated band of width W_i,
/// for uncorrelated forces with power P_j(f) (N²) in line f's cell, P_i the
/// in-band power of force i, and white measurement noise of variance R_j
/// on channel j: the distortion of force i, the crosstalk of the other
/// forces into it, and the amplified noise, relative to force i's variance.
/// A per-axis compensator's crosstalk terms are H_ii·Ĝ_ij, which the
/// per-axis prediction leaves out. √J_i is the predicted in-band error.
#[derive(Clone, Debug)]
pub struct MatrixCriterion {
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Per output axis its lines.
    pub rows: [RowGrid; 3],
    /// Measurement noise variance per channel R_j (N²).
    pub r: [f64; 3],
    /// Per output axis the lines above its band, from the band's top to
    /// fs/2 ([`out_of_band_lines`]); empty unless the design is quiet above
    /// its band ([`Self::quiet_above_band`]).
    pub above: [Vec<f64>; 3],
    /// Weight of the noise written above the band in the q criterion
    /// ([`Self::above_j`]).
    pub above_weight: f64,
}

/// A row's predicted error: √J and its distortion part alone (the noise
/// term left out), both fractions of force i's RMS, and the fitted model's
/// own uncertainty in the same terms.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct RowError {
    /// √J_i.
    pub error: f64,
    /// √(J_i without the noise term).
    pub distortion: f64,
    /// √J_fit,i, J_fit,i = Σ_f Σ_j (P_j(f)/P_i)·E|Σ_m H_im (Ĝ_mj − G_mj)|²:
    /// the error the impact tests' noise leaves in Ĝ, which `error`
    /// (computed on Ĝ) cannot see, the entries' errors correlated through
    /// the common poles ([`MatrixCriterion::with_fit_covariance`]); NaN
    /// where not known.
    pub fit: f64,
}

impl RowError {
    /// √(J + J_fit): the predicted error with the fit's uncertainty
    /// counted; `error` where that is not known.
    pub fn with_fit(&self) -> f64 {
        with_fit_uncertainty(self.error, self.fit)
    }
}

impl MatrixCriterion {
    /// The criterion of `g` over the bands `bands_hz` (one per output axis)
    /// for the forces `forces`.
    pub fn new(
        g: impl Fn(f64) -> CMatrix3,
        bands_hz: [(f64, f64); 3],
        fs_hz: f64,
        forces: &ForceWeights,
        r: [f64; 3],
    ) -> Self {
        let rows = std::array::from_fn(|i| {
            let band_hz = bands_hz[i];
            let mut freqs = criterion_grid(&[band_hz]);
            let (mut weight, force_power_n2) = forces.row(i, freqs.len());
            let mean = forces.mean_share(i);
            if mean.is_some() {
                freqs.insert(0, 0.0);
                for weight in &mut weight {
                    weight.insert(0, 0.0);
                }
            }
            let g = freqs.iter().map(|f| g(*f)).collect();
            RowGrid { band_hz, freqs, g, weight, force_power_n2, mean, fit_cov: None }
        });
        MatrixCriterion { fs_hz, rows, r, above: Default::default(), above_weight: 0.0 }
    }

    /// The criterion with the fitted model's covariance on each row's
    /// lines: `cov(freqs)` is that of the nine entries (e = 3m + j for
    /// Ĝ_mj) at `freqs` ([`crate::fit::refine::fit_covariance`]), asked
    /// once for every row's lines ([`Self::all_freqs`]); where it is `None`
    /// the rows stay without.
    pub fn with_fit_covariance(mut self, cov: impl FnOnce(&[f64]) -> Option<FitCovariance>) -> Self {
        let Some(all) = cov(&self.all_freqs()).filter(|c| c.own.len() == 9) else {
            return self;
        };
        let mut offset = 0;
        for row in &mut self.rows {
            let n = row.freqs.len();
            row.fit_cov = Some(all.at(offset..offset + n));
            offset += n;
        }
        self
    }

    /// The criterion with the noise written above each row's band counted
    /// in the q search with `weight` ([`Self::above_j`]; 0: in-band alone,
    /// no lines).
    pub fn quiet_above_band(mut self, weight: f64) -> Self {
        self.above_weight = weight;
        self.above = std::array::from_fn(|i| match weight > 0.0 {
            true => out_of_band_lines(self.rows[i].band_hz.1, self.fs_hz),
            false => Vec::new(),
        });
        self
    }

    /// Every row's lines above its band, row 0's first: where
    /// [`Self::above_j`] needs the compensator's response.
    pub fn above_freqs(&self) -> Vec<f64> {
        self.above.iter().flatten().copied().collect()
    }

    /// The weighted noise row i writes above its band, relative to force
    /// i's in-band power, for a 3x3 response `h` on [`Self::above_freqs`]:
    ///
    /// w·(2/fs)·(fs/2 − f_top,i)/P_i · Σ_j R_j·mean_f |H_ij(e^{jω})|²
    ///
    /// ([`crate::design::above_band::out_of_band_j`] with every channel's
    /// noise); 0 without lines.
    pub fn above_j(&self, i: usize, h: &[DMatrix<Complex64>]) -> f64 {
        let lines = &self.above[i];
        if lines.is_empty() {
            return 0.0;
        }
        let offset: usize = self.above[..i].iter().map(Vec::len).sum();
        let amp: f64 = h[offset..offset + lines.len()]
            .iter()
            .map(|h| (0..3).map(|j| self.r[j] * h[(i, j)].norm_sqr()).sum::<f64>())
            .sum();
        let row = &self.rows[i];
        let factor = out_of_band_noise_factor(row.band_hz.1, self.fs_hz, row.force_power_n2);
        self.above_weight * factor * amp / lines.len() as f64
    }

    /// Every row's lines, row 0's first: where a compensator's response is
    /// needed ([`Self::row_error`] reads its row's share).
    pub fn all_freqs(&self) -> Vec<f64> {
        self.rows.iter().flat_map(|r| r.freqs.iter().copied()).collect()
    }

    /// The noise factor (2/fs)·W_i/P_i of row i.
    fn noise(&self, i: usize) -> f64 {
        let (lo, hi) = self.rows[i].band_hz;
        2.0 / self.fs_hz * (hi - lo) / self.rows[i].force_power_n2
    }

    /// J_i ([`MatrixCriterion`]) for the response `h(k, j)` = H_ij on line k of row
    /// i's grid and latency `lag`; the fit's part only `with_fit` (NaN
    /// otherwise).
    fn j(&self, i: usize, lag: usize, with_fit: bool, h: impl Fn(usize, usize) -> Complex64) -> RowError {
        let row = &self.rows[i];
        let fit_cov = row.fit_cov.as_ref().filter(|_| with_fit);
        let mean_lines = usize::from(row.mean.is_some());
        let n = (row.freqs.len() - mean_lines) as f64;
        let (mut dist, mut amp, mut fit) = (0.0, 0.0, 0.0);
        // (H·Ĝ)_ij on line k for H's row `hr`.
        let gain =
            |hr: &[Complex64; 3], k: usize, j: usize| (0..3).map(|m| hr[m] * row.g[k][(m, j)]).sum::<Complex64>();
        let identity = |j: usize| if i == j { 1.0 } else { 0.0 };
        if let Some(m) = row.mean {
            // Line 0 carries the mean forces, which act together:
            // |Σ_j (H·Ĝ − I)_ij·F̄_j|²/P_i at 0 Hz.
            let hr = [h(0, 0), h(0, 1), h(0, 2)];
            dist += (0..3).map(|j| (gain(&hr, 0, j) - identity(j)) * m[j]).sum::<Complex64>().norm_sqr();
            if let Some(cov) = fit_cov {
                let terms: Vec<(usize, Complex64)> = (0..9).map(|e| (e, hr[e / 3] * m[e % 3])).collect();
                fit += cov.combination_variance(0, &terms);
            }
        }
        for (k, f) in row.freqs.iter().enumerate().skip(mean_lines) {
            let delay = Complex64::from_polar(1.0, 2.0 * PI * f * lag as f64 / self.fs_hz);
            let hr = [h(k, 0), h(k, 1), h(k, 2)];
            for j in 0..3 {
                let e = gain(&hr, k, j) * delay - identity(j);
                dist += row.weight[j][k] * e.norm_sqr();
                amp += self.r[j] * hr[j].norm_sqr();
                if let Some(cov) = fit_cov {
                    let terms = [(j, hr[0]), (3 + j, hr[1]), (6 + j, hr[2])];
                    fit += row.weight[j][k] * cov.combination_variance(k, &terms);
                }
            }
        }
        let fit = if fit_cov.is_some() { fit.sqrt() } else { f64::NAN };
        RowError { error: (dist + self.noise(i) * amp / n).sqrt(), distortion: dist.sqrt(), fit }
    }

    /// Row i's error for a 3x3 response `h` on [`Self::all_freqs`].
    pub fn row_error(&self, i: usize, lag: usize, h: &[DMatrix<Complex64>]) -> RowError {
        self.row(i, lag, true, h)
    }

    /// √J_i alone for a 3x3 response `h` on [`Self::all_freqs`], without
    /// the fit's part: what the q search compares, candidate by candidate.
    pub fn row_prediction(&self, i: usize, lag: usize, h: &[DMatrix<Complex64>]) -> f64 {
        self.row(i, lag, false, h).error
    }

    fn row(&self, i: usize, lag: usize, with_fit: bool, h: &[DMatrix<Complex64>]) -> RowError {
        let offset: usize = self.rows[..i].iter().map(|r| r.freqs.len()).sum();
        self.j(i, lag, with_fit, |k, j| h[offset + k][(i, j)])
    }

    /// Row i's error without compensation (H = I, no latency).
    pub fn raw(&self, i: usize) -> RowError {
        self.j(i, 0, true, |_, j| Complex64::new(if i == j { 1.0 } else { 0.0 }, 0.0))
    }

    /// Row i's error for a per-axis compensator with response `h_ii` on
    /// row i's lines (it reads channel i only).
    pub fn per_axis(&self, i: usize, lag: usize, h_ii: &[Complex64]) -> RowError {
        self.j(i, lag, true, |k, j| if i == j { h_ii[k] } else { Complex64::new(0.0, 0.0) })
    }

    /// Row i's error counting only the direct entry: the per-axis design's
    /// own prediction, which ignores the crosstalk (for comparison).
    pub fn direct_only(&self, i: usize, lag: usize, h_ii: &[Complex64]) -> RowError {
        let mut diag = self.clone();
        for g in &mut diag.rows[i].g {
            *g = CMatrix3::from_fn(|a, b| if a == b { g[(a, b)] } else { Complex64::new(0.0, 0.0) });
        }
        diag.per_axis(i, lag, h_ii)
    }
}

/// The q search's outcome (see [`choose_q`]).
#[derive(Clone, Debug, Default, Serialize)]
pub struct QSearch {
    /// Chosen q per force axis (N²/sample).
    pub q: [f64; 3],
    /// √J_i at the chosen q.
    pub predicted: [f64; 3],
    /// Passes of coordinate descent run.
    pub passes: usize,
    /// Largest |Δ log10 q_i| of the last pass (decades).
    pub last_step_decades: f64,
    /// Largest relative change of √J_i over the last pass.
    pub last_change: f64,
    /// Designs evaluated.
    pub evaluations: usize,
    /// Candidates better than the best so far that were refused because the
    /// offline smoother's Riccati equation cannot take their q.
    pub refused: usize,
}

/// Most coordinate-descent passes.
pub const MAX_PASSES: usize = 4;
/// A pass that moves no log10 q_i by more than this (decades) ends the search.
pub const STEP_TOL_DECADES: f64 = 0.02;
/// The line search's resolution per coordinate and pass, relative to its
/// half-width: Brent's method ([`brent_min`]) stops when the bracket around
/// the best point is about 4/3 of this, 0.016 of the half-width, as 10
/// golden-section reductions left it.
const LINE_TOL: f64 = 0.012;
/// Most evaluations per coordinate and pass: the 12 of those 10 golden
/// reductions.
const LINE_EVALS: usize = 12;
/// The predicted error (√J, relative) an axis without a finite one counts
/// as in [`search_merit`]: far above any compensator worth having (raw
/// errors are 0.2-2).
const J_CAP: f64 = 1e3;

/// The q search's figure of merit for one candidate: Σ_i ln min(√J_i,
/// [`J_CAP`]), an axis with no finite √J (the design fails, or output i's
/// noise gain is over the limit) counted at the cap. The sum of logs weighs
/// the same relative gain equally on every axis, so an axis with a small
/// error is not sacrificed for a large one; each axis later takes its 3x3
/// row only where that row predicts less than its per-axis row.
pub fn search_merit(j: &[f64; 3]) -> f64 {
    j.iter().map(|&v| if v.is_finite() && v > 0.0 { v.min(J_CAP) } else { J_CAP }.ln()).sum()
}

/// Choose q by the predicted error of each output axis: `eval(q)` is √J_i
/// per axis (∞ where the design fails or output i's noise gain is over the
/// limit).
///
/// 1. A joint scan q = R·10^k (k = −2..14, the per-axis scan's decades, on
///    threads), and the combination of each axis's best decade in it.
/// 2. From the best of these by [`search_merit`], coordinate descent: each
///    log10 q_i in turn, with the others fixed, is refined by Brent's method
///    ([`brent_min`]) on the merit on ±1 decade (±0.5, ±0.25 in later passes). Where the
///    best is a point of the joint scan, an axis's own best may lie many
///    decades away, so the first pass scans each log10 q_i over the same
///    decades (on threads) before its line search.
/// 3. The search keeps the best candidate it has evaluated, so it never
///    ends on a point worse than its start: the combination of per-axis
///    decades is itself only a candidate, since q_j (j ≠ i) moves J_i
///    through how the filter shares the channels between the forces, and
///    a combination can put an axis over the noise-gain limit.
/// 4. A candidate becomes the best only if `accept(q)`: the design passes
///    whether the rest of the chain can take that q (the offline smoother's
///    Riccati equation, [`crate::design::mimo`]). Each refusal is counted.
///
/// q_i mainly sets the bandwidth of force i's estimate, so the passes
/// settle quickly: the search stops after a pass that moves no q_i by more
/// than [`STEP_TOL_DECADES`], or after [`MAX_PASSES`].
pub fn choose_q(
    eval: &(dyn Fn([f64; 3]) -> [f64; 3] + Sync),
    accept: &dyn Fn([f64; 3]) -> bool,
    r: [f64; 3],
) -> Result<QSearch> {
    let base = r.map(|v| v.log10());
    let on_threads = |points: &[[f64; 3]]| map_on_threads(points, |lq| eval(q_of(*lq)));
    let scan: Vec<[f64; 3]> = (-2..=14).map(|k| base.map(|b| b + k as f64)).collect();
    let scanned = on_threads(&scan);
    let mut per_axis: [Option<(f64, f64)>; 3] = [None; 3];
    for (lq, j) in scan.iter().zip(&scanned) {
        for i in 0..3 {
            if j[i].is_finite() && per_axis[i].is_none_or(|b| j[i] < b.1) {
                per_axis[i] = Some((lq[i], j[i]));
            }
        }
    }
    let mut combined = [0.0; 3];
    for i in 0..3 {
        let Some((l, _)) = per_axis[i] else {
            bail!("no q gives the 3x3 compensator a finite predicted error on axis {i} within the noise-gain limit");
        };
        combined[i] = l;
    }
    let mut best =
        BestCandidate { lq: combined, j: [f64::INFINITY; 3], merit: f64::INFINITY, evaluated: 0, refused: 0, accept };
    for (lq, j) in scan.into_iter().zip(scanned) {
        best.offer(lq, j);
    }
    let run = |lq: [f64; 3], best: &mut BestCandidate| {
        let j = eval(q_of(lq));
        if best.offer(lq, j) {
            search_merit(&j)
        } else {
            search_merit(&[f64::INFINITY; 3])
        }
    };
    run(combined, &mut best);
    let from_combination = best.lq == combined;
    let mut out = QSearch::default();
    let mut width = 1.0;
    for pass in 1..=MAX_PASSES {
        let (start_lq, start_j) = (best.lq, best.j);
        for i in 0..3 {
            if pass == 1 && !from_combination {
                let line: Vec<[f64; 3]> = (-2..=14)
                    .map(|k| {
                        let mut t = best.lq;
                        t[i] = base[i] + k as f64;
                        t
                    })
                    .collect();
                let js = on_threads(&line);
                for (lq, j) in line.into_iter().zip(js) {
                    best.offer(lq, j);
                }
            }
            let (centre, at_centre) = (best.lq, best.merit);
            let mut f = |x: f64| {
                let mut t = centre;
                t[i] = x;
                run(t, &mut best)
            };
            let bracket = (centre[i] - width, centre[i] + width);
            brent_min(&mut f, bracket, (centre[i], at_centre), LINE_TOL * width, LINE_EVALS);
        }
        width *= 0.5;
        out.passes = pass;
        out.last_step_decades = (0..3).map(|i| (best.lq[i] - start_lq[i]).abs()).fold(0.0, f64::max);
        out.last_change = (0..3).map(|i| (best.j[i] / start_j[i] - 1.0).abs()).fold(0.0, f64::max);
        if out.last_step_decades < STEP_TOL_DECADES {
            break;
        }
    }
    if !best.merit.is_finite() {
        bail!(
            "no q gives the 3x3 compensator a finite predicted error that the offline smoother's Riccati equation \
             can also take ({} candidates refused); design per axis with --per-axis",
            best.refused
        );
    }
    out.q = q_of(best.lq);
    out.predicted = best.j;
    out.evaluations = best.evaluated;
    out.refused = best.refused;
    Ok(out)
}

/// q (N²/sample) from log10 q.
fn q_of(lq: [f64; 3]) -> [f64; 3] {
    lq.map(|v| 10f64.powf(v))
}

/// The best accepted candidate (log10 q, √J) a search has evaluated, by
/// [`search_merit`]; how many it has evaluated, and how many better ones
/// `accept` refused.
struct BestCandidate<'a> {
    lq: [f64; 3],
    j: [f64; 3],
    merit: f64,
    evaluated: usize,
    refused: usize,
    accept: &'a dyn Fn([f64; 3]) -> bool,
}

impl BestCandidate<'_> {
    /// Offer a candidate; false if it was better and refused.
    fn offer(&mut self, lq: [f64; 3], j: [f64; 3]) -> bool {
        self.evaluated += 1;
        let merit = search_merit(&j);
        if merit < self.merit {
            if !(self.accept)(q_of(lq)) {
                self.refused += 1;
                return false;
            }
            (self.lq, self.j, self.merit) = (lq, j, merit);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record of a cut with a mean force, through a static 3x3 plant with
    /// crosstalk c_ij: the per-axis row H_ii = 1/G_ii leaves
    /// e_i = Σ_{j≠i} (c_ij/G_ii)·F_j, the mean force's share included, and the
    /// row's prediction √J_i must match that error in time, RMS error over
    /// the standard deviation of F_i (the forces are tones inside the band,
    /// so the band-limited truth is the force). Control: the criterion from
    /// the same record with its mean removed is short of that truth by more
    /// than half.
    #[test]
    fn the_record_s_mean_force_counts_through_the_static_crosstalk() {
        let fs = 25_600.0;
        let n = 1 << 16;
        let c = [[1.0, 0.03, -0.02], [0.02, 1.0, 0.04], [0.01, 0.03, 1.0]];
        let mean = [300.0, 100.0, 600.0];
        // Tones on the record's bins inside the band, 40 per force.
        let mut seed = 7u64;
        let mut uniform = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let tones: Vec<Vec<(f64, f64, f64)>> = (0..3)
            .map(|_| {
                (0..40)
                    .map(|_| {
                        let bin = (20.0 + 3000.0 * uniform()) / fs * n as f64;
                        (bin.round() * fs / n as f64, 10.0 + 20.0 * uniform(), 2.0 * PI * uniform())
                    })
                    .collect()
            })
            .collect();
        let force: Vec<Vec<f64>> = (0..3)
            .map(|j| {
                (0..n)
                    .map(|t| {
                        let time = t as f64 / fs;
                        mean[j] + tones[j].iter().map(|(f, a, ph)| a * (2.0 * PI * f * time + ph).sin()).sum::<f64>()
                    })
                    .collect()
            })
            .collect();
        let measured = |with_mean: bool| -> [Vec<f64>; 3] {
            std::array::from_fn(|i| {
                (0..n)
                    .map(|t| (0..3).map(|j| c[i][j] * (force[j][t] - if with_mean { 0.0 } else { mean[j] })).sum())
                    .collect()
            })
        };
        let g = |_: f64| CMatrix3::from_fn(|a, b| Complex64::new(c[a][b], 0.0));
        let bands = [(10.0, 4000.0); 3];
        let r = [1e-9; 3];
        let criterion = |with_mean: bool| {
            let record = ForceRecord { source: "test".into(), channels: measured(with_mean).map(Some) };
            let forces = ForceWeights::from_record(&record, &g, bands, fs, r, false).unwrap();
            MatrixCriterion::new(g, bands, fs, &forces, r)
        };
        let (with_mean, without) = (criterion(true), criterion(false));
        for i in 0..3 {
            let truth = {
                let e: Vec<f64> =
                    (0..n).map(|t| (0..3).filter(|j| *j != i).map(|j| c[i][j] / c[i][i] * force[j][t]).sum()).collect();
                let rms = (e.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
                let m = force[i].iter().sum::<f64>() / n as f64;
                let sd = (force[i].iter().map(|v| (v - m).powi(2)).sum::<f64>() / n as f64).sqrt();
                rms / sd
            };
            let h = vec![Complex64::new(1.0 / c[i][i], 0.0); with_mean.rows[i].freqs.len()];
            let predicted = with_mean.per_axis(i, 0, &h).error;
            assert!((predicted / truth - 1.0).abs() < 0.05, "axis {i}: predicted {predicted:.4} against {truth:.4}");
            let h = vec![Complex64::new(1.0 / c[i][i], 0.0); without.rows[i].freqs.len()];
            let blind = without.per_axis(i, 0, &h).error;
            eprintln!("axis {i}: time {truth:.4}, predicted {predicted:.4}, without the mean {blind:.4}");
            assert!(blind < 0.5 * truth, "control, axis {i}: without the mean {blind:.4} against {truth:.4}");
        }
    }

    /// J_fit against its closed form: on a diagonal plant Ĝ = 2I with flat,
    /// equal forces and entry errors that are independent (no shared part),
    /// a per-axis row H = h·e_i gives J_fit,i = |h|²·Σ_j v_ij and no
    /// compensation (H = I) gives Σ_j v_ij, for entry variances v_mj that
    /// differ per entry (so a wrong entry or row shows). With a shared part
    /// s_mj (a pole common to the entries), row i of H = [a, b, c] gives
    /// Σ_j |a s_0j + b s_1j + c s_2j|² on top. Control: without the
    /// covariance the term is unknown (NaN) and the prediction with it is
    /// the prediction alone.
    #[test]
    fn the_fit_term_counts_the_variance_of_every_entry_of_the_row() {
        let g = |_: f64| CMatrix3::from_fn(|a, b| Complex64::new(if a == b { 2.0 } else { 0.0 }, 0.0));
        let bands = [(100.0, 1000.0); 3];
        let forces = ForceWeights::Flat([100.0; 3]);
        let v = |m: usize, j: usize| 1e-6 * (1 + 3 * m + j) as f64;
        let sh = |m: usize, j: usize| Complex64::new(1e-3 * (m + 1) as f64, -1e-3 * j as f64);
        let plain = MatrixCriterion::new(g, bands, 25600.0, &forces, [0.05; 3]);
        let cov = |shared: bool| {
            move |freqs: &[f64]| {
                Some(FitCovariance {
                    own: (0..9).map(|e| vec![v(e / 3, e % 3); freqs.len()]).collect(),
                    shared: (0..9)
                        .map(|e| {
                            let s = if shared { sh(e / 3, e % 3) } else { Complex64::new(0.0, 0.0) };
                            vec![vec![s]; freqs.len()]
                        })
                        .collect(),
                })
            }
        };
        let crit = plain.clone().with_fit_covariance(cov(false));
        let h = Complex64::new(0.3, 0.4);
        for i in 0..3 {
            let n = crit.rows[i].freqs.len();
            let row: f64 = (0..3).map(|j| v(i, j)).sum();
            let per = crit.per_axis(i, 0, &vec![h; n]);
            assert!((per.fit - (h.norm_sqr() * row).sqrt()).abs() < 1e-12 * per.fit, "{per:?}");
            assert!((per.with_fit() - per.error.hypot(per.fit)).abs() < 1e-15);
            let raw = crit.raw(i);
            assert!((raw.fit - row.sqrt()).abs() < 1e-12 * raw.fit, "{raw:?}");
            let without = plain.per_axis(i, 0, &vec![h; n]);
            assert!(without.fit.is_nan() && without.with_fit() == without.error);
            assert_eq!(without.error, per.error, "the prediction itself does not change");
        }
        let shared = plain.with_fit_covariance(cov(true));
        let hr = [Complex64::new(0.5, 0.1), Complex64::new(-0.2, 0.3), Complex64::new(0.1, -0.4)];
        let freqs = shared.all_freqs();
        let hs: Vec<DMatrix<Complex64>> = freqs.iter().map(|_| DMatrix::from_fn(3, 3, |_, m| hr[m])).collect();
        for i in 0..3 {
            let want: f64 = (0..3)
                .map(|j| {
                    let own: f64 = (0..3).map(|m| hr[m].norm_sqr() * v(m, j)).sum();
                    own + (0..3).map(|m| hr[m] * sh(m, j)).sum::<Complex64>().norm_sqr()
                })
                .sum();
            let got = shared.row_error(i, 0, &hs).fit;
            assert!((got - want.sqrt()).abs() < 1e-12 * got, "row {i}: {got} against {}", want.sqrt());
        }
    }

    /// A q landscape where each axis's best decade alone is known, but
    /// their combination is not a compensator: √J_i = 10⁻³(1 + (log10 q_i
    /// − o_i)²) with o = (2, 9, 2) decades, and output y over its noise-gain
    /// limit (∞) wherever q_y is more than 3 decades above q_x or q_z, as
    /// where the plate's y row needs the other forces' estimates to take
    /// part of its channel. The search ends on a valid q no worse, by its
    /// merit, than any point of its joint scan, with each axis near the best
    /// it can have under the limit: x and z at their optima, y at the limit's
    /// edge. Control: the combination of per-axis best decades, where the
    /// search used to start and end, is refused on y. Then with q_x refused
    /// above 10^1.5 by `accept`, the search ends below it.
    #[test]
    fn the_q_search_keeps_a_valid_candidate_where_the_per_axis_decades_combine_to_none() {
        let optimum = [2.0, 9.0, 2.0];
        let eval = |q: [f64; 3]| {
            let lq = q.map(f64::log10);
            if lq[1] - lq[0].min(lq[2]) > 3.0 {
                return [1e-3 * (1.0 + (lq[0] - 2.0).powi(2)), f64::INFINITY, 1e-3 * (1.0 + (lq[2] - 2.0).powi(2))];
            }
            [0, 1, 2].map(|i| 1e-3 * (1.0 + (lq[i] - optimum[i]).powi(2)))
        };
        let combined = eval([1e2, 1e9, 1e2]);
        assert!(combined[1].is_infinite(), "control: the per-axis decades combine to a refused y ({combined:?})");
        let found = choose_q(&eval, &|_| true, [1.0; 3]).unwrap();
        assert!(found.predicted.iter().all(|j| j.is_finite()), "{found:?}");
        assert_eq!(eval(found.q), found.predicted, "the reported error is the chosen q's");
        let best_scan = (-2..=14).map(|k| search_merit(&eval([10f64.powi(k); 3]))).fold(f64::INFINITY, f64::min);
        assert!(search_merit(&found.predicted) <= best_scan, "{found:?} against the scan's best merit {best_scan}");
        let lq = found.q.map(f64::log10);
        assert!((lq[0] - 2.0).abs() < 0.6 && (lq[2] - 2.0).abs() < 0.6, "x and z near their optima: {lq:?}");
        assert!(lq[1] - lq[0].min(lq[2]) > 2.5, "y near the limit's edge: {lq:?}");
        assert_eq!(found.refused, 0);
        // Where the rest of the chain cannot take q_x above 10^1.5 (as the
        // offline smoother's Riccati equation may not), the search ends below
        // it and counts what it refused; the search above is the control.
        let accept = |q: [f64; 3]| q[0] <= 10f64.powf(1.5);
        let held = choose_q(&eval, &accept, [1.0; 3]).unwrap();
        assert!(accept(held.q) && held.refused > 0, "{held:?}");
        assert!(held.predicted.iter().all(|j| j.is_finite()), "{held:?}");
        assert!(!accept(found.q), "control: unrefused, q_x goes above 10^1.5 ({:?})", found.q);
    }
}
