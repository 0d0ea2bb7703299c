//! Rank-one residues of the common-pole fit (a leaf of [`super::matrix`]).
//!
//! A simple pole p_k of a linear structure is seen in the 3x3 matrix with
//! the residue R_k = c_k b_kᵀ: the mode's output column (how much each
//! channel reads of it) times its input row (how much each force direction
//! drives it). For a state-space model with distinct eigenvalues,
//! R_k = (C v_k)(w_kᵀ B) with v_k, w_k the right and left eigenvectors, so
//! this holds with any damping. The free fit spends 18 real parameters
//! per pair on R_k (nine complex entries); the rank-one form spends 10
//! (c_k, b_k ∈ ℂ³ less one complex scale), and every entry then shares
//! what the others measure of the mode, so an entry the impact test
//! measures poorly (a weak direct entry, an anti-resonance) borrows the
//! mode's shape from the entries measured well.
//!
//! [`rank_one_residues`] fits the residues at fixed poles by alternating
//! least squares (c given b, then b given c, each linear), on each entry's
//! weighted least-squares problem compressed by one QR factorization
//! (‖A_e x − h_e‖² = ‖R_e x − z_e‖² + ρ_e²). A pair keeps free residues
//! where a likelihood-ratio test rejects rank one ([`FREEING_DROP`]): two
//! modes the lines cannot tell apart (a repeated pole, whose residue has
//! rank two), a pair that stands for several modes outside the lines, or
//! one that took up a mode the fit dropped. Real poles and the direct
//! terms stay free in every entry.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;
use std::f64::consts::PI;

use super::vf::{basis_row, lstsq, n_cols, to_model, Pole};
use super::{PoleResidueModel, Term};

/// Entries of the 3x3 matrix, row by row (as [`super::matrix::ENTRIES`]).
const ENTRIES: usize = 9;

/// The measured matrix: lines (Hz), and per entry (row by row, G_ij at
/// 3i + j) the values and their weights (inverse variances up to σ̂²), as
/// [`super::matrix::MatrixData`] holds them.
pub struct Lines<'a> {
    /// Frequency lines (Hz).
    pub freq_hz: &'a [f64],
    /// G_ij per line.
    pub h: [&'a [Complex64]; ENTRIES],
    /// Weight of each line per entry.
    pub w: [&'a [f64]; ENTRIES],
}

/// Most alternating least-squares sweeps.
const MAX_SWEEPS: usize = 200;
/// Relative decrease of the residual below which the sweeps have converged.
const CONVERGED: f64 = 1e-10;
/// Drop of the weighted residual, in units of σ̂², above which a pair's
/// residues are freed: free residues add 8 real parameters (18 − 10), and
/// under the rank-one hypothesis the drop is σ̂²·χ²₈, which exceeds 32 with
/// probability 10⁻⁴. The BIC's 8·ln N (about 90 here) held pairs whose
/// misfit was real (a neighbouring mode the fit dropped): on the seed
/// study the 3x3 design's median went 1.69x → 1.78x the floor with it,
/// 1.62x with this test (BENCHMARKS.md, "Rank-one residues").
pub const FREEING_DROP: f64 = 32.0;

/// The rank-one fit of a model ([`rank_one_residues`]).
#[derive(Clone, Debug)]
pub struct RankOne {
    /// The model's entries (row by row): the poles of the input, rank-one
    /// residues on every pair but those in `free`.
    pub entries: Vec<PoleResidueModel>,
    /// Terms (indices into the model's terms) whose residues stay free.
    pub free: Vec<usize>,
    /// Weighted residual Σ w|Ĝ − G|² of `model`.
    pub rss: f64,
    /// The same with free residues on every pair, at the same poles.
    pub rss_free: f64,
}

/// Each entry's weighted least squares at fixed poles, compressed: R_e
/// (m × m, m = the basis columns and d) and z_e with
/// ‖A_e x − h_e‖² = ‖R_e x − z_e‖² + ρ_e².
struct Compressed {
    r: Vec<DMatrix<f64>>,
    z: Vec<DVector<f64>>,
    rho2: Vec<f64>,
    /// Per term: its first basis column and whether it is a pair.
    cols: Vec<(usize, bool)>,
    m: usize,
    /// Per entry and basis column: held at zero, the column of a term the
    /// entry does without in the input model (a residue exactly zero).
    held: Vec<Vec<bool>>,
}

fn compress(data: &Lines, poles: &[Pole], w_scale: f64) -> Result<Compressed> {
    let n = n_cols(poles);
    let m = n + 1;
    let lines = data.freq_hz.len();
    let mut row = Vec::with_capacity(n);
    let mut cols = Vec::with_capacity(poles.len());
    let mut c = 0;
    for p in poles {
        cols.push((c, p.pair));
        c += if p.pair { 2 } else { 1 };
    }
    let (mut r, mut z, mut rho2) = (Vec::new(), Vec::new(), Vec::new());
    for e in 0..ENTRIES {
        let mut a = DMatrix::<f64>::zeros(2 * lines, m + 1);
        for (i, f) in data.freq_hz.iter().enumerate() {
            let w = data.w[e][i].max(0.0).sqrt();
            basis_row(Complex64::new(0.0, 2.0 * PI * f / w_scale), poles, &mut row);
            for (j, v) in row.iter().enumerate() {
                a[(2 * i, j)] = (v * w).re;
                a[(2 * i + 1, j)] = (v * w).im;
            }
            a[(2 * i, n)] = w;
            let h = data.h[e][i] * w;
            (a[(2 * i, m)], a[(2 * i + 1, m)]) = (h.re, h.im);
        }
        if a.iter().any(|v| !v.is_finite()) {
            bail!("rank-one residues: entry {e}'s least-squares rows are not finite");
        }
        let rr = crate::numeric::dense::qr_r_in_place(&mut a);
        r.push(rr.view((0, 0), (m, m)).into_owned());
        z.push(rr.view((0, m), (m, 1)).column(0).into_owned());
        rho2.push(rr[(m, m)].powi(2));
    }
    Ok(Compressed { r, z, rho2, cols, m, held: vec![vec![false; m]; ENTRIES] })
}

/// The parameters of every entry: the rank-one pairs' c_k (per row) and
/// b_k (per column), and each entry's own coefficients x_e (the basis
/// columns of its free terms and d; those of rank-one pairs are unused).
#[derive(Clone)]
struct State {
    c: Vec<[Complex64; 3]>,
    b: Vec<[Complex64; 3]>,
    own: Vec<DVector<f64>>,
}

impl Compressed {
    /// Entry e's coefficients under `s` with rank-one terms `rank1`.
    fn coefficients(&self, s: &State, rank1: &[Option<usize>], e: usize) -> DVector<f64> {
        let (i, j) = (e / 3, e % 3);
        let mut x = s.own[e].clone();
        for (t, slot) in rank1.iter().enumerate() {
            if let Some(q) = slot {
                let v = s.c[*q][i] * s.b[*q][j];
                let col = self.cols[t].0;
                (x[col], x[col + 1]) = (v.re, v.im);
            }
        }
        x
    }

    fn rss(&self, s: &State, rank1: &[Option<usize>]) -> f64 {
        (0..ENTRIES)
            .map(|e| (&self.r[e] * self.coefficients(s, rank1, e) - &self.z[e]).norm_squared() + self.rho2[e])
            .sum()
    }

    /// Columns of the entries' own coefficients: everything but the
    /// rank-one pairs' basis columns.
    fn own_columns(&self, rank1: &[Option<usize>], e: usize) -> Vec<usize> {
        let mut used: Vec<bool> = self.held[e].iter().map(|h| !h).collect();
        for (t, slot) in rank1.iter().enumerate() {
            if slot.is_some() {
                let col = self.cols[t].0;
                used[col] = false;
                used[col + 1] = false;
            }
        }
        (0..self.m).filter(|c| used[*c]).collect()
    }

    /// One half sweep: the vectors of one side (`rows`: the c_k of row
    /// `line`, else the b_k of column `line`) and the own coefficients of
    /// that line's three entries, with the other side held.
    fn solve_line(&self, s: &mut State, rank1: &[Option<usize>], rows: bool, line: usize) -> Result<()> {
        let entry = |k: usize| if rows { 3 * line + k } else { 3 * k + line };
        let own: [Vec<usize>; 3] = std::array::from_fn(|k| self.own_columns(rank1, entry(k)));
        let offset: [usize; 3] = [0, own[0].len(), own[0].len() + own[1].len()];
        let q1 = s.c.len();
        let n_unknown = 2 * q1 + own.iter().map(Vec::len).sum::<usize>();
        let mut a = DMatrix::<f64>::zeros(3 * self.m, n_unknown);
        let mut rhs = DVector::<f64>::zeros(3 * self.m);
        for k in 0..3 {
            let e = if rows { 3 * line + k } else { 3 * k + line };
            // x_e = M θ: map the unknowns to the entry's basis columns.
            let mut map = DMatrix::<f64>::zeros(self.m, n_unknown);
            for (t, slot) in rank1.iter().enumerate() {
                let Some(q) = slot else { continue };
                let col = self.cols[t].0;
                // r = u·v with u unknown, v held: Re r = u_r v_r − u_i v_i,
                // Im r = u_r v_i + u_i v_r.
                let v = if rows { s.b[*q][k] } else { s.c[*q][k] };
                map[(col, 2 * q)] = v.re;
                map[(col, 2 * q + 1)] = -v.im;
                map[(col + 1, 2 * q)] = v.im;
                map[(col + 1, 2 * q + 1)] = v.re;
            }
            for (o, col) in own[k].iter().enumerate() {
                map[(*col, 2 * q1 + offset[k] + o)] = 1.0;
            }
            a.view_mut((k * self.m, 0), (self.m, n_unknown)).copy_from(&(&self.r[e] * map));
            rhs.rows_mut(k * self.m, self.m).copy_from(&self.z[e]);
        }
        let theta = lstsq(a, rhs)?;
        for q in 0..q1 {
            let u = Complex64::new(theta[2 * q], theta[2 * q + 1]);
            if rows {
                s.c[q][line] = u;
            } else {
                s.b[q][line] = u;
            }
        }
        for k in 0..3 {
            let e = if rows { 3 * line + k } else { 3 * k + line };
            for (o, col) in own[k].iter().enumerate() {
                s.own[e][*col] = theta[2 * q1 + offset[k] + o];
            }
        }
        Ok(())
    }

    /// Alternating least squares from `s` to convergence; the residual.
    fn sweeps(&self, s: &mut State, rank1: &[Option<usize>]) -> Result<f64> {
        let mut last = self.rss(s, rank1);
        for _ in 0..MAX_SWEEPS {
            for line in 0..3 {
                self.solve_line(s, rank1, true, line)?;
            }
            for line in 0..3 {
                self.solve_line(s, rank1, false, line)?;
            }
            // The scale between c_k and b_k is free: ‖b_k‖ = 1.
            for q in 0..s.c.len() {
                let nb = s.b[q].iter().map(|v| v.norm_sqr()).sum::<f64>().sqrt();
                if nb > 0.0 {
                    s.b[q].iter_mut().for_each(|v| *v /= nb);
                    s.c[q].iter_mut().for_each(|v| *v *= nb);
                }
            }
            let now = self.rss(s, rank1);
            let done = !(last - now > CONVERGED * last);
            last = now;
            if done {
                break;
            }
        }
        Ok(last)
    }
}

/// R ≈ c bᵀ of a 3x3 complex residue by alternating (power) iteration.
fn rank_one_of(r: &[[Complex64; 3]; 3]) -> ([Complex64; 3], [Complex64; 3]) {
    let col = (0..3).max_by(|&a, &b| {
        let n = |j: usize| (0..3).map(|i| r[i][j].norm_sqr()).sum::<f64>();
        n(a).total_cmp(&n(b))
    });
    let col = col.unwrap_or(0);
    let mut c: [Complex64; 3] = std::array::from_fn(|i| r[i][col]);
    let mut b = [Complex64::new(0.0, 0.0); 3];
    for _ in 0..30 {
        let cc: f64 = c.iter().map(|v| v.norm_sqr()).sum();
        if !(cc > 0.0) {
            break;
        }
        b = std::array::from_fn(|j| (0..3).map(|i| c[i].conj() * r[i][j]).sum::<Complex64>() / cc);
        let bb: f64 = b.iter().map(|v| v.norm_sqr()).sum();
        if !(bb > 0.0) {
            break;
        }
        c = std::array::from_fn(|i| (0..3).map(|j| r[i][j] * b[j].conj()).sum::<Complex64>() / bb);
    }
    (c, b)
}

/// `model`'s poles with rank-one residues where the lines allow it
/// (module doc), on `data` with noise scale `sigma2` (the σ̂² of the order
/// search, the weights being inverse variances up to it).
///
/// Pairs within each other's half-power bandwidth keep free residues.
/// From the others all rank one, greedily: the pair whose free residues
/// lower the residual most is freed while that drop exceeds
/// [`FREEING_DROP`]·σ̂². Residues the input model holds at exactly zero (a
/// term an entry does without) stay zero where the pair is free.
pub fn rank_one_residues(data: &Lines, model: &[PoleResidueModel], sigma2: f64) -> Result<RankOne> {
    if !(sigma2 > 0.0 && sigma2.is_finite()) {
        bail!("rank-one residues need a positive noise scale, got {sigma2}");
    }
    let f_max = data.freq_hz.iter().fold(0.0f64, |m, f| m.max(*f));
    let w_scale = 2.0 * PI * f_max;
    let poles: Vec<Pole> = model[0]
        .terms
        .iter()
        .map(|t| match *t {
            Term::Real { pole, .. } => Pole { p: Complex64::new(pole / w_scale, 0.0), pair: false },
            Term::Pair { pole, .. } => Pole { p: pole / w_scale, pair: true },
        })
        .collect();
    if model.len() != ENTRIES || model.iter().any(|m| m.terms.len() != poles.len()) {
        bail!("rank-one residues need nine entries with the same terms");
    }
    let mut z = compress(data, &poles, w_scale)?;
    for (e, entry) in model.iter().enumerate() {
        for (t, term) in entry.terms.iter().enumerate() {
            let zero = match term {
                Term::Real { residue, .. } => *residue == 0.0,
                Term::Pair { residue, .. } => residue.norm() == 0.0,
            };
            let (col, pair) = z.cols[t];
            z.held[e][col] = zero;
            if pair {
                z.held[e][col + 1] = zero;
            }
        }
    }
    // Each entry's own least squares with the held columns at zero.
    let free_x: Vec<DVector<f64>> = (0..ENTRIES)
        .map(|e| {
            let cols: Vec<usize> = (0..z.m).filter(|c| !z.held[e][*c]).collect();
            let a = z.r[e].select_columns(&cols);
            let mut x = DVector::zeros(z.m);
            if let Ok(v) = lstsq(a, z.z[e].clone()) {
                for (k, c) in cols.iter().enumerate() {
                    x[*c] = v[k];
                }
            }
            x
        })
        .collect();
    let rss_free: f64 = (0..ENTRIES).map(|e| (&z.r[e] * &free_x[e] - &z.z[e]).norm_squared() + z.rho2[e]).sum();
    let pairs: Vec<usize> = (0..poles.len()).filter(|t| poles[*t].pair).collect();
    let penalty = sigma2 * FREEING_DROP;

    // Start: rank one of each pair's free residue (normalized frequency).
    let start = |free: &[usize]| -> (Vec<Option<usize>>, State) {
        let mut rank1 = vec![None; poles.len()];
        let (mut c, mut b) = (Vec::new(), Vec::new());
        for &t in &pairs {
            if free.contains(&t) {
                continue;
            }
            let col = z.cols[t].0;
            let r: [[Complex64; 3]; 3] = std::array::from_fn(|i| {
                std::array::from_fn(|j| Complex64::new(free_x[3 * i + j][col], free_x[3 * i + j][col + 1]))
            });
            let (ci, bi) = rank_one_of(&r);
            rank1[t] = Some(c.len());
            c.push(ci);
            b.push(bi);
        }
        (rank1, State { c, b, own: free_x.clone() })
    };
    // Close pairs stay free: the lines cannot tell how a close cluster's
    // residues split between its poles, and at poles off the true modes a
    // rank-one split is a bias, not a constraint.
    let mut free: Vec<usize> = pairs
        .iter()
        .copied()
        .filter(|&t| pairs.iter().any(|&u| u != t && super::within_bandwidth(poles[t].p, poles[u].p)))
        .collect();
    let (mut rank1, mut state) = start(&free);
    let mut rss = z.sweeps(&mut state, &rank1)?;
    loop {
        let mut best: Option<(usize, f64, Vec<Option<usize>>, State)> = None;
        for &t in &pairs {
            if free.contains(&t) {
                continue;
            }
            let (r1, mut s) = freed(&z, &rank1, &state, t);
            let Ok(v) = z.sweeps(&mut s, &r1) else { continue };
            if best.as_ref().is_none_or(|b| v < b.1) {
                best = Some((t, v, r1, s));
            }
        }
        match best {
            Some((t, v, r1, s)) if rss - v > penalty => {
                free.push(t);
                (rss, rank1, state) = (v, r1, s);
            }
            _ => break,
        }
    }
    free.sort_unstable();
    let entries = (0..ENTRIES)
        .map(|e| {
            let x = z.coefficients(&state, &rank1, e);
            to_model(&poles, &x.as_slice()[..z.m - 1], x[z.m - 1], w_scale)
        })
        .collect();
    Ok(RankOne { entries, free, rss, rss_free })
}

/// `state` with term `t` freed: its residues c_t b_t become the entries'
/// own coefficients (a warm start for the sweeps).
fn freed(z: &Compressed, rank1: &[Option<usize>], state: &State, t: usize) -> (Vec<Option<usize>>, State) {
    let own = (0..ENTRIES)
        .map(|e| {
            let mut x = z.coefficients(state, rank1, e);
            let col = z.cols[t].0;
            for c in [col, col + 1] {
                if z.held[e][c] {
                    x[c] = 0.0;
                }
            }
            x
        })
        .collect();
    let (mut c, mut b) = (Vec::new(), Vec::new());
    let mut next = vec![None; rank1.len()];
    for (u, slot) in rank1.iter().enumerate() {
        if let (Some(q), true) = (slot, u != t) {
            next[u] = Some(c.len());
            c.push(state.c[*q]);
            b.push(state.b[*q]);
        }
    }
    (next, State { c, b, own })
}

/// σ₂/σ₁ of a 3x3 residue `r` (0 for a zero one): how far from one mode
/// shape c·bᵀ it is.
pub fn rank_two_share(r: &nalgebra::Matrix3<Complex64>) -> f64 {
    let sv = r.singular_values();
    if sv[0] > 0.0 {
        sv[1] / sv[0]
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::matrix::{refit_kept, MatrixData, MatrixModel};
    use crate::fit::PoleResidueModel;

    /// Three modes (800, 2 500 and 3 300 Hz) with real mode shapes c_k b_kᵀ
    /// (a structure's modes), direct terms the identity, and optionally a
    /// second mode at 2 500 Hz with another shape: a repeated pole whose
    /// residue has rank two.
    fn truth(repeated: bool) -> MatrixModel {
        let modes: [(f64, f64, [f64; 3], [f64; 3]); 3] = [
            (800.0, 0.02, [1.0, 0.3, -0.1], [0.8, 0.2, 0.05]),
            (2500.0, 0.015, [0.2, 1.0, 0.3], [0.1, 0.9, -0.2]),
            (3300.0, 0.01, [-0.1, 0.2, 1.0], [0.05, -0.1, 0.7]),
        ];
        let second = ([1.0, -0.2, 0.1], [0.6, 0.1, 0.3]);
        let entries = (0..ENTRIES)
            .map(|e| {
                let (i, j) = (e / 3, e % 3);
                let mut terms = Vec::new();
                for (k, (f, z, c, b)) in modes.iter().enumerate() {
                    let w = 2.0 * PI * f;
                    let pole = Complex64::new(-z * w, w * (1.0 - z * z).sqrt());
                    let mut r = c[i] * b[j];
                    if repeated && k == 1 {
                        r += second.0[i] * second.1[j];
                    }
                    // Peak |G_ij| ≈ |r| / (2ζ) for a residue −j·r·ω/2.
                    terms.push(Term::Pair { pole, residue: Complex64::new(0.0, -0.5 * r * w) * (4.0 * z) });
                }
                PoleResidueModel { terms, d: if i == j { 1.0 } else { 0.0 } }
            })
            .collect();
        MatrixModel { entries }
    }

    /// `truth` on 2 Hz lines 20 Hz-4 kHz with complex noise of RMS `noise`
    /// (seeded), weights 1/noise².
    fn measured(truth: &MatrixModel, noise: f64, seed: u64) -> (Vec<f64>, Vec<Vec<Complex64>>, Vec<f64>) {
        crate::fit::matrix::noisy_lines(truth, noise, (10..=2000).map(|k| 2.0 * f64::from(k)).collect(), seed)
    }

    fn data<'a>(freq: &'a [f64], h: &'a [Vec<Complex64>], w: &'a [f64]) -> MatrixData<'a> {
        MatrixData { freq_hz: freq, h: std::array::from_fn(|e| h[e].as_slice()), w: [w; ENTRIES] }
    }

    /// RMS over the lines and entries of |Ĝ − G| against the truth.
    fn model_error(model: &MatrixModel, truth: &MatrixModel, freq: &[f64]) -> f64 {
        let sum: f64 = freq.iter().map(|f| (model.frf(*f) - truth.frf(*f)).norm_squared()).sum();
        (sum / (ENTRIES * freq.len()) as f64).sqrt()
    }

    /// Against the known truth, at the true poles: the rank-one residues are
    /// closer to it than the free ones on every seed (the error of 10 rather
    /// than 18 parameters per pair: about √(10/18) ≈ 0.75 of it), and every
    /// pair is kept rank one. Negative control: the same fit forced free
    /// (`rss_free`) is the free least squares, whose error is the larger.
    #[test]
    fn rank_one_residues_are_closer_to_a_structure_s_modes() {
        let t = truth(false);
        let mut ratios = Vec::new();
        for seed in [1, 2, 3, 4, 5] {
            let (freq, h, w) = measured(&t, 0.02, seed);
            let d = data(&freq, &h, &w);
            let free = refit_kept(&d, &t, &[true; 3]).unwrap();
            let sigma2 = d.rss(&free) / (d_points(&d) - 3 * 2 - 9 * 7) as f64;
            let (model, r1) = held(&d, &t, sigma2);
            assert!(r1.free.is_empty(), "seed {seed}: pairs {:?} kept free", r1.free);
            assert!((d.rss(&free) - r1.rss_free).abs() < 1e-6 * r1.rss_free, "the free fit is the least squares");
            assert!(r1.rss >= r1.rss_free, "rank one cannot fit the lines better than free residues");
            let (e1, ef) = (model_error(&model, &t, &freq), model_error(&free, &t, &freq));
            ratios.push(e1 / ef);
            assert!(e1 < 0.9 * ef, "seed {seed}: rank-one error {e1:.3e} against free {ef:.3e}");
        }
        eprintln!("rank-one / free model error: {ratios:.3?}");
    }

    /// A repeated pole with a rank-two residue keeps its free residues, and
    /// the fit is then no worse than the free one; the other pairs stay
    /// rank one. Negative control: that pair held rank one misfits the lines
    /// by far more than the noise.
    #[test]
    fn a_repeated_pole_keeps_free_residues() {
        let t = truth(true);
        let (freq, h, w) = measured(&t, 0.02, 9);
        let d = data(&freq, &h, &w);
        let free = refit_kept(&d, &t, &[true; 3]).unwrap();
        let sigma2 = d.rss(&free) / (d_points(&d) - 3 * 2 - 9 * 7) as f64;
        let (model, r1) = held(&d, &t, sigma2);
        assert_eq!(r1.free, vec![1], "the repeated 2 500 Hz pole is freed, no other");
        let (e1, ef) = (model_error(&model, &t, &freq), model_error(&free, &t, &freq));
        assert!(e1 < 1.05 * ef, "rank-one error {e1:.3e} against free {ef:.3e}");
        assert!(share(&t, 1) > 0.1 && share(&t, 0) < 1e-12);
        // Control: every pair rank one (an infinite noise scale never frees one).
        let (forced_model, forced) = held(&d, &t, 1e30);
        assert!(forced.free.is_empty());
        assert!(forced.rss - forced.rss_free > 1e3 * sigma2, "{} against {}", forced.rss, forced.rss_free);
        assert!(model_error(&forced_model, &t, &freq) > 3.0 * ef);
    }

    /// Two pairs within each other's half-power bandwidth keep free
    /// residues, and a residue the input model holds at zero stays zero;
    /// the pairs apart are held rank one. Control: the input's own residue
    /// there is not zero once refitted free (the lines show that mode in
    /// that entry), so the zero is the input's, kept.
    #[test]
    fn close_pairs_stay_free_and_absent_terms_stay_absent() {
        let mut t = truth(false);
        for entry in t.entries.iter_mut() {
            if let Term::Pair { pole, residue } = entry.terms[0] {
                let w = 1.01 * pole.im;
                entry.terms.push(Term::Pair { pole: Complex64::new(pole.re, w), residue: residue * 0.5 });
            }
        }
        let (freq, h, w) = measured(&t, 0.02, 4);
        let d = data(&freq, &h, &w);
        let mut input = refit_kept(&d, &t, &[true; 4]).unwrap();
        if let Term::Pair { residue, .. } = &mut input.entries[1].terms[3] {
            assert!(residue.norm() > 0.0, "control: the free fit sees the close pair in G_xy");
            *residue = Complex64::new(0.0, 0.0);
        }
        let (model, r1) = held(&d, &input, d.rss(&input) / d_points(&d) as f64);
        assert_eq!(r1.free, vec![0, 3], "the close pair is free, the others rank one");
        assert!(matches!(model.entries[1].terms[3], Term::Pair { residue, .. } if residue.norm() == 0.0));
        assert!(share(&model, 1) < 1e-9 && share(&model, 2) < 1e-9);
    }

    /// [`rank_one_residues`] on `d` from `m`, as a matrix model.
    fn held(d: &MatrixData, m: &MatrixModel, sigma2: f64) -> (MatrixModel, RankOne) {
        let lines = Lines { freq_hz: d.freq_hz, h: d.h, w: d.w };
        let r = rank_one_residues(&lines, &m.entries, sigma2).unwrap();
        (MatrixModel { entries: r.entries.clone() }, r)
    }

    fn share(m: &MatrixModel, k: usize) -> f64 {
        rank_two_share(&m.residue(k))
    }

    fn d_points(d: &MatrixData) -> usize {
        d.w.iter().map(|w| 2 * w.iter().filter(|v| **v > 0.0).count()).sum()
    }
}
