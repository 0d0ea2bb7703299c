//! The 3x3 compensator in the kernel's form ([`dynocomp_core::mimo`]):
//! modal 2x2 sections whose modes the three estimates share, each with a
//! 2x3 input row and a 3x2 output column, plus 3x3 FIR taps for the fast
//! poles; rounded to f32 and verified (DESIGN.md steps 6-7 for the matrix).
//! Part of the realize stage: [`realize_blocks`] takes the design's state
//! spaces and reuses the per-axis steps of [`crate::realize::modal`].

use anyhow::{bail, Context, Result};
use dynocomp_core::budget::{load_permille, MimoCostModel, MimoShape};
use dynocomp_core::mimo::{Matrix3, MimoFilter, MimoSection, MimoState, MAX_MIMO_FIR, MAX_MIMO_SECTIONS};
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;
use serde::Serialize;
use std::f64::consts::PI;

use crate::fit::linalg::sweeps;
use crate::numeric::lti::MimoStateSpace;
use crate::realize::modal::{
    section_poles, thresholds, triangular_eigenvectors, ComplexSchur, FIR_TAIL_TOL, FIR_TAIL_TOL_FULL,
};
use crate::realize::quantize::{
    test_signal, MAX_FREQ_ERROR, MAX_POLE_SHIFT, MAX_TIME_ERROR, POLE_MARGIN, VERIFY_GRID, VERIFY_SAMPLES,
};

/// One section in f64 (the kernel's `MimoSection` before rounding).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MimoSection64 {
    /// A − I, row-major.
    pub delta: [f64; 4],
    /// Input rows `b[s][j]`.
    pub b: [[f64; 3]; 2],
    /// Output columns `c[i][s]`.
    pub c: [[f64; 2]; 3],
}

impl MimoSection64 {
    /// C (zI − I − Δ)⁻¹ B of this section (3x3).
    pub fn response(&self, z: Complex64) -> [[Complex64; 3]; 3] {
        let zm1 = z - 1.0;
        let [d11, d12, d21, d22] = self.delta;
        let (m11, m12, m21, m22) = (zm1 - d11, Complex64::new(-d12, 0.0), Complex64::new(-d21, 0.0), zm1 - d22);
        let det = m11 * m22 - m12 * m21;
        let mut out = [[Complex64::new(0.0, 0.0); 3]; 3];
        for j in 0..3 {
            let (b1, b2) = (self.b[0][j], self.b[1][j]);
            let x1 = (m22 * b1 - m12 * b2) / det;
            let x2 = (m11 * b2 - m21 * b1) / det;
            for (i, row) in out.iter_mut().enumerate() {
                row[j] = x1 * self.c[i][0] + x2 * self.c[i][1];
            }
        }
        out
    }

    fn round(&self) -> MimoSection {
        MimoSection {
            delta: self.delta.map(|v| v as f32),
            b: self.b.map(|r| r.map(|v| v as f32)),
            c: self.c.map(|r| r.map(|v| v as f32)),
        }
    }
}

/// A compensator in the kernel's form, f64.
#[derive(Clone, Debug, Default)]
pub struct MimoRealization {
    /// Sections (slow poles).
    pub sections: Vec<MimoSection64>,
    /// Direct term (output × input).
    pub d: [[f64; 3]; 3],
    /// FIR taps H_1..H_m (fast poles).
    pub fir: Vec<[[f64; 3]; 3]>,
    /// Poles the sections carry (z-plane).
    pub poles: Vec<Complex64>,
    /// Largest condition number estimate of a block's modal transform.
    pub modal_condition: f64,
    /// Largest norm of a block's cluster decoupling 1 + ‖X‖.
    pub decoupling_norm: f64,
    /// Largest relative size of a block's truncated FIR tail.
    pub fir_truncation: f64,
}

impl MimoRealization {
    /// H(e^{j2πf/fs}) from the realization (f64).
    pub fn freq_response(&self, f_hz: f64, fs_hz: f64) -> [[Complex64; 3]; 3] {
        let z = Complex64::from_polar(1.0, 2.0 * PI * f_hz / fs_hz);
        let mut h = self.d.map(|r| r.map(|v| Complex64::new(v, 0.0)));
        for s in &self.sections {
            let r = s.response(z);
            for (hi, ri) in h.iter_mut().zip(r) {
                for (hij, rij) in hi.iter_mut().zip(ri) {
                    *hij += rij;
                }
            }
        }
        let zi = z.inv();
        let mut zm = zi;
        for tap in &self.fir {
            for (hi, ti) in h.iter_mut().zip(tap) {
                for (hij, t) in hi.iter_mut().zip(ti) {
                    *hij += zm * t;
                }
            }
            zm *= zi;
        }
        h
    }

    /// This realization and `other` summed (sections concatenated, taps and
    /// direct terms added).
    fn plus(mut self, other: &MimoRealization) -> Self {
        self.sections.extend_from_slice(&other.sections);
        self.poles.extend_from_slice(&other.poles);
        for (a, b) in self.d.iter_mut().flatten().zip(other.d.iter().flatten()) {
            *a += b;
        }
        if self.fir.len() < other.fir.len() {
            self.fir.resize(other.fir.len(), [[0.0; 3]; 3]);
        }
        for (t, o) in self.fir.iter_mut().zip(&other.fir) {
            for (a, b) in t.iter_mut().flatten().zip(o.iter().flatten()) {
                *a += b;
            }
        }
        self.modal_condition = self.modal_condition.max(other.modal_condition);
        self.decoupling_norm = self.decoupling_norm.max(other.decoupling_norm);
        self.fir_truncation = self.fir_truncation.max(other.fir_truncation);
        self
    }
}

/// Verification figures of the f32 3x3 filter (the checks of [`realize_blocks`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct MimoVerification {
    /// Largest pole radius of the f32 sections.
    pub max_pole_radius: f64,
    /// Largest pole displacement by rounding, relative to |1 − λ|.
    pub max_pole_shift: f64,
    /// Per entry max_f |H32 − H64| over the peak of its row of H64.
    pub freq_error: [[f64; 3]; 3],
    /// Per output max |y32 − y64| / RMS(y64) of the time-domain run.
    pub time_error: [f64; 3],
    /// Sections (pairs, diagonal) and FIR taps: what the kernel runs per sample.
    pub pairs: usize,
    /// Diagonal sections.
    pub diagonal: usize,
    /// FIR taps (each 3x3).
    pub fir_taps: usize,
}

impl MimoVerification {
    /// The worse of the largest frequency-response and time-domain errors.
    pub fn score(&self) -> f64 {
        let f = self.freq_error.iter().flatten().fold(0.0f64, |m, v| m.max(*v));
        self.time_error.iter().fold(f, |m, v| m.max(*v))
    }
}

/// The error context of a 3x3 compensator none of whose realizations
/// verifies in f32: the design cannot be run as a 3x3 image (a caller may
/// fall back to the per-axis image, which has its own realization).
#[derive(Debug, Clone, Copy)]
pub struct NotVerified {
    /// The block (output rows sharing states) that failed.
    pub block: usize,
}

impl std::fmt::Display for NotVerified {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "3x3 compensator, block {}: no realization verifies in f32", self.block)
    }
}

/// The complex Schur form of `a` (iteration-limited), computed once for
/// every fast/slow threshold of [`block_candidates`].
fn complex_schur(a: &DMatrix<f64>) -> Result<ComplexSchur> {
    let n = a.nrows();
    ComplexSchur::new(a, f64::EPSILON, sweeps(n), || {
        anyhow::anyhow!(
            "realization: the Schur decomposition of the {n}x{n} compensator did not converge within {} sweeps",
            sweeps(n)
        )
    })
}

/// X of T11 X − X T22 = −T12 (the first `m` rows slow), column by column.
fn decouple(t: &DMatrix<Complex64>, m: usize) -> DMatrix<Complex64> {
    let nf = t.nrows() - m;
    let mut x = DMatrix::<Complex64>::zeros(m, nf);
    for j in 0..nf {
        let lam = t[(m + j, m + j)];
        let mut rhs: Vec<Complex64> = (0..m).map(|i| -t[(i, m + j)]).collect();
        for l in 0..j {
            let tl = t[(m + l, m + j)];
            for (i, r) in rhs.iter_mut().enumerate() {
                *r += x[(i, l)] * tl;
            }
        }
        for i in (0..m).rev() {
            let mut s = rhs[i];
            for k in i + 1..m {
                s -= t[(i, k)] * x[(k, j)];
            }
            x[(i, j)] = s / (t[(i, i)] - lam);
        }
    }
    x
}

/// The fast cluster's taps H_m = C₂ T22^{m−1} B₂ ([`realize_split`], step 4),
/// the shortest length whose tail is below [`FIR_TAIL_TOL`] of Σ‖H_m‖ (or
/// [`FIR_TAIL_TOL_FULL`] at [`MAX_MIMO_FIR`]), and the tail's relative size;
/// imaginary parts judged against Σ‖H_m‖ + `scale` as in
/// [`super::modal`]'s `fast_fir`.
fn fast_taps(
    t22: &DMatrix<Complex64>,
    b2: &DMatrix<Complex64>,
    c2: &DMatrix<Complex64>,
    scale: f64,
) -> Result<(Vec<[[f64; 3]; 3]>, f64)> {
    if t22.nrows() == 0 {
        return Ok((Vec::new(), 0.0));
    }
    let mut v = b2.clone();
    let mut taps = Vec::new();
    for _ in 0..MAX_MIMO_FIR + 16 {
        taps.push(c2 * &v);
        v = t22 * v;
    }
    let norms: Vec<f64> = taps.iter().map(|h| h.norm()).collect();
    let total = norms.iter().sum::<f64>().max(f64::MIN_POSITIVE);
    let tail = |l: usize| norms[l..].iter().sum::<f64>();
    let mut len = (0..=MAX_MIMO_FIR).find(|&l| tail(l) <= FIR_TAIL_TOL * total).unwrap_or(MAX_MIMO_FIR + 1);
    if len > MAX_MIMO_FIR && tail(MAX_MIMO_FIR) <= FIR_TAIL_TOL_FULL * total {
        len = MAX_MIMO_FIR;
    }
    if len > MAX_MIMO_FIR {
        bail!(
            "realization: the fast poles need more than {MAX_MIMO_FIR} FIR taps (tail {:.1e} of the response)",
            tail(MAX_MIMO_FIR) / total
        );
    }
    let imag = taps[..len].iter().flat_map(|h| h.iter().map(|v| v.im.abs())).fold(0.0, f64::max);
    if imag > super::modal::MAX_IMAGINARY_TAP * (total + scale) {
        bail!(
            "realization: FIR taps are not real (imaginary part {imag:.1e}); the fast cluster is not conjugate-closed"
        );
    }
    let out = taps[..len].iter().map(|h| std::array::from_fn(|i| std::array::from_fn(|j| h[(i, j)].re))).collect();
    Ok((out, tail(len) / total))
}

/// Realize one block (a 3-in, 3-out state space) with the fast/slow
/// threshold `rho`, all f64: the steps of [`crate::realize::modal`] with
/// matrices for the input column and the output row:
/// 1. complex Schur form A = Q T Qᴴ (iteration-limited; `schur`, one for
///    every threshold, [`complex_schur`]);
/// 2. the slow eigenvalues (|λ| ≥ ρ) moved to the front by adjacent swaps;
/// 3. the clusters decoupled by T11 X − X T22 = −T12, and
///    B̃ = S⁻¹QᴴB, C̃ = CQS with S = [[I, X], [0, I]];
/// 4. the fast cluster as taps H_m = C̃₂ T22^{m−1} B̃₂ (3x3, real), as many
///    as its tail needs (the delay chain's poles at z = 0 and any pole of
///    |z| ≲ 0.5);
/// 5. the slow cluster diagonalized by the eigenvectors W of T11 (back
///    substitution; cond(W) checked): each eigenvalue λ gets an input row
///    β = (W⁻¹B̃₁)_λ (1x3) and an output column γ = (C̃₁W)_λ (3x1), its term
///    γβ/(z − λ), realized by [`sections_of`].
fn realize_split(ss: &MimoStateSpace, schur: &ComplexSchur, rho: f64) -> Result<MimoRealization> {
    let c64 = |m: &DMatrix<f64>| m.map(|v| Complex64::new(v, 0.0));
    let (q, t, m) = schur.slow_first(rho)?;
    let n = t.nrows();
    let nf = n - m;
    let x = decouple(&t, m);
    let decoupling_norm = 1.0 + x.norm();
    if !(decoupling_norm < 1e8) {
        bail!("realization: fast and slow poles are not separable (decoupling norm {decoupling_norm:.1e})");
    }
    let bq = q.adjoint() * c64(&ss.b);
    let cq = c64(&ss.c) * &q;
    let b_fast = bq.rows(m, nf).into_owned();
    let b_slow = bq.rows(0, m) - &x * &b_fast;
    let c_slow = cq.columns(0, m).into_owned();
    let c_fast = cq.columns(m, nf) + &c_slow * &x;
    let scale = ss.d.norm() + ss.b.norm() * ss.c.norm();
    let (fir, fir_truncation) = fast_taps(&t.view((m, m), (nf, nf)).into_owned(), &b_fast, &c_fast, scale)?;
    let (w, w_inv, modal_condition) = triangular_eigenvectors(&t.view((0, 0), (m, m)).into_owned())?;
    let bh = w_inv * b_slow;
    let ch = c_slow * w;
    let modes: Vec<(Complex64, DVector<Complex64>, DVector<Complex64>)> =
        (0..m).map(|i| (t[(i, i)], bh.row(i).transpose(), ch.column(i).into_owned())).collect();
    let (sections, poles) = sections_of(&modes)?;
    let d = std::array::from_fn(|i| std::array::from_fn(|j| ss.d[(i, j)]));
    Ok(MimoRealization { sections, d, fir, poles, modal_condition, decoupling_norm, fir_truncation })
}

/// β and γ scaled to equal norms (their product unchanged).
fn balance(beta: &DVector<Complex64>, gamma: &DVector<Complex64>) -> (DVector<Complex64>, DVector<Complex64>) {
    let (nb, ng) = (beta.norm(), gamma.norm());
    if !(nb > 0.0 && ng > 0.0) {
        return (beta.clone(), gamma.clone());
    }
    let s = (ng / nb).sqrt();
    (beta * Complex64::new(s, 0.0), gamma / Complex64::new(s, 0.0))
}

/// The kernel's sections of the modes (λ, β, γ) ([`realize_split`], step 5).
///
/// A conjugate pair (Im λ > 0) becomes a normal-form section
/// Δ = [[σ, ω], [−ω, σ]] (λ = 1 + σ + jω) with states (Re x, −Im x):
/// input rows (Re β, −Im β), output columns (2 Re γ, 2 Im γ); a real
/// pole has a real rank-1 term γβ (its phase removed), and real poles go
/// two to a diagonal section. β and γ are scaled to equal norms
/// ([`balance`]): f32 rounding is relative, so the scale only keeps the
/// states O(input).
fn sections_of(
    modes: &[(Complex64, DVector<Complex64>, DVector<Complex64>)],
) -> Result<(Vec<MimoSection64>, Vec<Complex64>)> {
    let scale = modes.iter().map(|e| e.0.norm()).fold(1.0, f64::max);
    let mut used = vec![false; modes.len()];
    let (mut sections, mut poles, mut reals) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..modes.len() {
        if used[i] {
            continue;
        }
        used[i] = true;
        let lam = modes[i].0;
        if lam.im.abs() <= 1e-10 * scale {
            reals.push(i);
            continue;
        }
        let partner = (0..modes.len())
            .filter(|&j| !used[j])
            .min_by(|&a, &b| (modes[a].0 - lam.conj()).norm().total_cmp(&(modes[b].0 - lam.conj()).norm()));
        let Some(j) = partner.filter(|&j| (modes[j].0 - lam.conj()).norm() <= 1e-8 * scale) else {
            bail!("realization: pole {lam} has no conjugate partner");
        };
        used[j] = true;
        let (lam, beta, gamma) = if lam.im > 0.0 { &modes[i] } else { &modes[j] };
        let (beta, gamma) = balance(beta, gamma);
        sections.push(MimoSection64 {
            delta: [lam.re - 1.0, lam.im, -lam.im, lam.re - 1.0],
            b: [std::array::from_fn(|k| beta[k].re), std::array::from_fn(|k| -beta[k].im)],
            c: std::array::from_fn(|k| [2.0 * gamma[k].re, 2.0 * gamma[k].im]),
        });
        poles.push(*lam);
        poles.push(lam.conj());
    }
    let mut real_terms = Vec::with_capacity(reals.len());
    for &i in &reals {
        let (lam, beta, gamma) = &modes[i];
        // γβ is real: remove the eigenvector's phase, then keep real parts.
        let k = (0..beta.len()).max_by(|&a, &b| beta[a].norm().total_cmp(&beta[b].norm())).unwrap_or(0);
        let phase = if beta[k].norm() > 0.0 { beta[k] / beta[k].norm() } else { Complex64::new(1.0, 0.0) };
        let (beta, gamma) = balance(&(beta / phase), &(gamma * phase));
        let imag = beta.iter().chain(gamma.iter()).map(|v| v.im.abs()).fold(0.0, f64::max);
        let size = beta.norm().max(gamma.norm());
        if imag > 1e-8 * size.max(f64::MIN_POSITIVE) {
            bail!("realization: the term of real pole {lam} is not real (imaginary part {:.1e} of {size:.1e})", imag);
        }
        real_terms.push((lam.re, beta.map(|v| v.re), gamma.map(|v| v.re)));
    }
    for pair in real_terms.chunks(2) {
        let (p1, b1, c1) = &pair[0];
        poles.push(Complex64::new(*p1, 0.0));
        let mut sec = MimoSection64 {
            delta: [p1 - 1.0, 0.0, 0.0, -1.0],
            b: [std::array::from_fn(|k| b1[k]), [0.0; 3]],
            c: std::array::from_fn(|k| [c1[k], 0.0]),
        };
        if let Some((p2, b2, c2)) = pair.get(1) {
            poles.push(Complex64::new(*p2, 0.0));
            sec.delta[3] = p2 - 1.0;
            sec.b[1] = std::array::from_fn(|k| b2[k]);
            for k in 0..3 {
                sec.c[k][1] = c2[k];
            }
        }
        sections.push(sec);
    }
    Ok((sections, poles))
}

/// The f64 reference of a verification: the design's response on
/// [`VERIFY_GRID`] + 1 lines over 0..f_band and its output for three
/// decorrelated test signals ([`test_signal`]).
pub struct MimoReference {
    fs_hz: f64,
    grid: Vec<(f64, DMatrix<Complex64>)>,
    u: Vec<[f64; 3]>,
    y64: Vec<[f64; 3]>,
}

impl MimoReference {
    /// The responses of `ss` at `fs_hz` over 0..`f_band_hz`.
    pub fn of(ss: &MimoStateSpace, fs_hz: f64, f_band_hz: f64) -> Self {
        let freqs: Vec<f64> = (0..=VERIFY_GRID).map(|i| f_band_hz * i as f64 / VERIFY_GRID as f64).collect();
        let grid = freqs.iter().copied().zip(ss.freq_responses(&freqs, fs_hz)).collect();
        let n = VERIFY_SAMPLES;
        let sig = test_signal(3 * n, fs_hz, f_band_hz);
        let u: Vec<[f64; 3]> = (0..n).map(|k| [sig[k], sig[n + k], sig[2 * n + k]]).collect();
        let input: Vec<DVector<f64>> = u.iter().map(|v| DVector::from_column_slice(v)).collect();
        let y64 = ss.simulate(&input).iter().map(|y| [y[0], y[1], y[2]]).collect();
        MimoReference { fs_hz, grid, u, y64 }
    }
}

/// Round `real` to f32 and verify it against `reference` (the checks of [`realize_blocks`]).
pub fn quantize(real: &MimoRealization, reference: &MimoReference) -> Result<(MimoFilter, MimoVerification)> {
    let sections: Vec<MimoSection> = real.sections.iter().map(MimoSection64::round).collect();
    let d: Matrix3 = real.d.map(|r| r.map(|v| v as f32));
    let fir: Vec<Matrix3> = real.fir.iter().map(|t| t.map(|r| r.map(|v| v as f32))).collect();
    if sections.len() > MAX_MIMO_SECTIONS || fir.len() > MAX_MIMO_FIR {
        bail!(
            "the 3x3 compensator needs {} sections and {} FIR taps, the kernel holds {MAX_MIMO_SECTIONS} and {MAX_MIMO_FIR}",
            sections.len(),
            fir.len()
        );
    }
    let filter = MimoFilter::new(&sections, d, &fir).map_err(|e| {
        anyhow::anyhow!("the f32 3x3 compensator is invalid ({e:?}); its poles do not survive rounding")
    })?;
    let mut v = MimoVerification { fir_taps: fir.len(), ..Default::default() };
    (v.pairs, v.diagonal) = filter.kernel_counts();
    for (s64, s32) in real.sections.iter().zip(filter.sections()) {
        let e64 = section_poles(s64.delta);
        let e32 = section_poles(s32.delta.map(f64::from));
        v.max_pole_radius = e32.iter().map(|p| p.norm()).fold(v.max_pole_radius, f64::max);
        for p in &e64 {
            let shift = e32.iter().map(|q| (q - p).norm()).fold(f64::INFINITY, f64::min) / (1.0 - p).norm().max(1e-300);
            v.max_pole_shift = v.max_pole_shift.max(shift);
        }
        if !s32.block().poles_within(1.0 - POLE_MARGIN) {
            bail!("the quantized 3x3 compensator has a pole within {POLE_MARGIN:e} of the unit circle; refusing to write it");
        }
    }
    if !(v.max_pole_shift <= MAX_POLE_SHIFT) {
        bail!(
            "rounding to f32 moves a 3x3 compensator pole by {:.1e} of its distance from z = 1 (limit {MAX_POLE_SHIFT:e})",
            v.max_pole_shift
        );
    }
    let r32 = realization_of(&filter);
    let mut peak = [0.0f64; 3];
    for (_, h) in &reference.grid {
        for (i, p) in peak.iter_mut().enumerate() {
            *p = (0..3).map(|j| h[(i, j)].norm()).fold(*p, f64::max);
        }
    }
    for (f, h64) in &reference.grid {
        let h32 = r32.freq_response(*f, reference.fs_hz);
        for i in 0..3 {
            for j in 0..3 {
                let e = (h32[i][j] - h64[(i, j)]).norm() / peak[i].max(f64::MIN_POSITIVE);
                v.freq_error[i][j] = v.freq_error[i][j].max(if e.is_nan() { f64::INFINITY } else { e });
            }
        }
    }
    let worst_f = v.freq_error.iter().flatten().fold(0.0f64, |m, e| m.max(*e));
    if !(worst_f <= MAX_FREQ_ERROR) {
        bail!("the f32 3x3 compensator deviates from the f64 design by {worst_f:.1e} of a row's peak response (limit {MAX_FREQ_ERROR:e})");
    }
    let mut st = MimoState::default();
    let (mut err, mut ss) = ([0.0f64; 3], [0.0f64; 3]);
    for (u, y) in reference.u.iter().zip(&reference.y64) {
        let y32 = filter.step(&mut st, u.map(|v| v as f32));
        for i in 0..3 {
            err[i] = err[i].max((f64::from(y32[i]) - y[i]).abs());
            ss[i] += y[i] * y[i];
        }
    }
    let len = reference.y64.len().max(1) as f64;
    for i in 0..3 {
        let rms = (ss[i] / len).sqrt();
        v.time_error[i] = if rms > 0.0 {
            err[i] / rms
        } else if err[i] == 0.0 {
            0.0
        } else {
            f64::INFINITY
        };
    }
    let worst_t = v.time_error.iter().fold(0.0f64, |m, e| m.max(*e));
    if !(worst_t <= MAX_TIME_ERROR) {
        bail!("the f32 3x3 kernel's output deviates from the f64 design by {worst_t:.1e} of its RMS (limit {MAX_TIME_ERROR:e})");
    }
    Ok((filter, v))
}

/// Verify an f32 filter against the f64 compensator `ss` it realizes, over
/// 0..`f_band_hz` at `fs_hz` ([`realize_blocks`]: stability margin, frequency
/// response per entry, time-domain run of the kernel): an error where it
/// deviates beyond the limits.
pub fn verify_filter(filter: &MimoFilter, ss: &MimoStateSpace, fs_hz: f64, f_band_hz: f64) -> Result<MimoVerification> {
    quantize(&realization_of(filter), &MimoReference::of(ss, fs_hz, f_band_hz)).map(|(_, v)| v)
}

/// The f32 filter's coefficients as an f64 realization (for its response).
fn realization_of(f: &MimoFilter) -> MimoRealization {
    MimoRealization {
        sections: f
            .sections()
            .iter()
            .map(|s| MimoSection64 {
                delta: s.delta.map(f64::from),
                b: s.b.map(|r| r.map(f64::from)),
                c: s.c.map(|r| r.map(f64::from)),
            })
            .collect(),
        d: f.d().map(|r| r.map(f64::from)),
        fir: f.fir().iter().map(|t| t.map(|r| r.map(f64::from))).collect(),
        ..Default::default()
    }
}

/// Every valid realization of one block, one per fast/slow split, and the
/// reason of the last failure if none is valid.
fn block_candidates(ss: &MimoStateSpace) -> Result<Vec<MimoRealization>> {
    if ss.a.nrows() == 0 {
        let d = std::array::from_fn(|i| std::array::from_fn(|j| ss.d[(i, j)]));
        return Ok(vec![MimoRealization { d, modal_condition: 1.0, decoupling_norm: 1.0, ..Default::default() }]);
    }
    let moduli: Vec<f64> =
        crate::fit::linalg::eigenvalues(&ss.a, "the compensator's state matrix")?.iter().map(|z| z.norm()).collect();
    let schur = complex_schur(&ss.a)?;
    let mut out = Vec::new();
    let mut last_err = None;
    for rho in thresholds(&moduli) {
        match realize_split(ss, &schur, rho) {
            Ok(r) => out.push(r),
            Err(e) => last_err = Some(e),
        }
    }
    match (out.is_empty(), last_err) {
        (true, Some(e)) => Err(e),
        (true, None) => bail!("realization: no split of the poles"),
        _ => Ok(out),
    }
}

/// Realize the compensator given as `blocks` (their sum, block diagonal)
/// and round it to f32, verified over 0..`f_band_hz` at `fs_hz`. Per block
/// the split that verifies best in f32 is kept.
///
/// Blocks (the rows of a combined compensator, [`crate::design::mimo`])
/// are realized one by one, so poles of different blocks never meet in one
/// eigenvector matrix, and their sections, taps and direct terms are
/// concatenated and summed. Each block takes, among its fast/slow splits
/// (`crate::realize::modal::thresholds`), the one whose f32 rounding
/// verifies best against the block; the whole filter is then verified
/// against the whole f64 compensator: every f32 section stable with margin
/// ([`POLE_MARGIN`]), pole displacement ([`MAX_POLE_SHIFT`] of |1 − λ|),
/// frequency response per entry against the f64 design relative to its
/// row's peak ([`MAX_FREQ_ERROR`]), and a time-domain run of the real f32
/// kernel ([`MimoFilter::step`]) against the f64 simulation relative to
/// each output's RMS ([`MAX_TIME_ERROR`]). An image that fails is refused.
pub fn realize_blocks(
    blocks: &[MimoStateSpace],
    fs_hz: f64,
    f_band_hz: f64,
) -> Result<(MimoRealization, MimoFilter, MimoVerification)> {
    realize_blocks_by(blocks, fs_hz, f_band_hz, Prefer::Accuracy)
}

/// Which of a block's verified realizations [`realize_blocks_by`] keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Prefer {
    /// The one that verifies best in f32 (fewer sections and taps only
    /// within 2x of the best score): [`realize_blocks`].
    Accuracy,
    /// The one the box runs in the fewest cycles (Cortex-M4 model, high
    /// estimate), among those that verify: for a filter that must fit a
    /// load limit.
    Load,
    /// [`Prefer::Load`] within a load limit (‰ of the sample period, high
    /// estimate): a single block's realizations over it are not verified,
    /// and an error says so when none is within it.
    LoadWithin(u32),
}

impl Prefer {
    fn by_load(self) -> bool {
        matches!(self, Prefer::Load | Prefer::LoadWithin(_))
    }
}

/// The kernel's shape of a realization: its pairs as the kernel tells them
/// ([`MimoSection::is_pair`] of the rounded section), diagonal sections and
/// taps.
fn realization_shape(r: &MimoRealization) -> MimoShape {
    let pairs = r.sections.iter().filter(|s| s.round().is_pair()).count() as u32;
    MimoShape { pairs, diagonals: r.sections.len() as u32 - pairs, taps: r.fir.len() as u32 }
}

/// Cycles per sample of a realization on the box (Cortex-M4 model, high
/// estimate).
fn kernel_cost(r: &MimoRealization) -> u32 {
    MimoCostModel::CORTEX_M4.sample_cost(realization_shape(r)).high
}

/// Predicted load (‰ of the sample period, high estimate) of a 3x3 filter
/// of shape `s` at `fs_hz`.
pub fn shape_load(s: MimoShape, fs_hz: f64) -> u32 {
    load_permille(MimoCostModel::CORTEX_M4.sample_cost(s).high, fs_hz.round() as u32)
}

/// [`realize_blocks`] keeping, per block, the realization `prefer` says.
pub fn realize_blocks_by(
    blocks: &[MimoStateSpace],
    fs_hz: f64,
    f_band_hz: f64,
    prefer: Prefer,
) -> Result<(MimoRealization, MimoFilter, MimoVerification)> {
    let mut total = MimoRealization { modal_condition: 1.0, decoupling_norm: 1.0, ..Default::default() };
    let mut only = None;
    for (k, blk) in blocks.iter().enumerate() {
        let mut candidates = block_candidates(blk).with_context(|| format!("3x3 compensator, block {k}"))?;
        if prefer.by_load() {
            // The cheapest that verifies: in order of cost (stable, so the
            // first of equal cost), the first that verifies.
            candidates.sort_by_key(kernel_cost);
        }
        let reference = MimoReference::of(blk, fs_hz, f_band_hz);
        let mut best: Option<(f64, MimoRealization, MimoFilter, MimoVerification)> = None;
        let mut last_err = None;
        for c in candidates {
            if let (Prefer::LoadWithin(limit), 1) = (prefer, blocks.len()) {
                let load = shape_load(realization_shape(&c), fs_hz);
                if load > limit {
                    // This and every later candidate cost more than the limit.
                    last_err = Some(anyhow::anyhow!(
                        "{}.{} % of the sample period is over the limit of {}.{} %",
                        load / 10,
                        load % 10,
                        limit / 10,
                        limit % 10
                    ));
                    break;
                }
            }
            // A block that is the whole filter is judged as the image will
            // be: a realization the box's image check refuses is never
            // chosen (another split or reduction may pass).
            let verified = match blocks.len() {
                1 => quantize_whole(&c, &reference),
                _ => quantize(&c, &reference),
            };
            match verified {
                Ok((filter, v)) => {
                    let cost = c.sections.len() + c.fir.len();
                    let better = best.as_ref().is_none_or(|(s, b, ..)| match prefer {
                        Prefer::Accuracy => {
                            v.score() < 0.5 * s || (v.score() <= 2.0 * s && cost < b.sections.len() + b.fir.len())
                        }
                        Prefer::Load | Prefer::LoadWithin(_) => kernel_cost(&c) < kernel_cost(b),
                    });
                    if better {
                        best = Some((v.score(), c, filter, v));
                    }
                    if prefer.by_load() {
                        break;
                    }
                }
                Err(e) => last_err = Some(e),
            }
        }
        let Some((_, r, filter, v)) = best else {
            let e = last_err.unwrap_or_else(|| anyhow::anyhow!("no realization"));
            return Err(e.context(NotVerified { block: k }));
        };
        if blocks.len() == 1 {
            // The whole filter is this block's, already verified against
            // the same reference (the sum of one block is the block).
            only = Some((filter, v));
        }
        total = total.plus(&r);
    }
    let (filter, v) = match only {
        Some(fv) => fv,
        None => {
            let reference = MimoReference::of(&block_sum(blocks), fs_hz, f_band_hz);
            quantize_whole(&total, &reference).context("3x3 compensator: the f32 image is refused")?
        }
    };
    Ok((total, filter, v))
}

/// [`quantize`] of a whole 3x3 filter, which must also pass the checks the
/// box repeats on the image it runs (`docs/image-format.md` §13.5:
/// coefficient range, pole margin, ℓ1 gain bound per row, DC gain rows near
/// the identity). Only a whole filter is judged so: a block of a mixed image
/// (the 3x3 rows alone) has no identity DC gain.
fn quantize_whole(real: &MimoRealization, reference: &MimoReference) -> Result<(MimoFilter, MimoVerification)> {
    let (filter, v) = quantize(real, reference)?;
    dynocomp_core::image::validate_mimo(&filter).map_err(|e| {
        anyhow::anyhow!("the f32 3x3 compensator fails the box's image check: {}", super::image_check_refusal(&e))
    })?;
    Ok((filter, v))
}

/// The sum of `blocks` (3-in, 3-out each) as one block-diagonal state space.
pub fn block_sum(blocks: &[MimoStateSpace]) -> MimoStateSpace {
    let n: usize = blocks.iter().map(|b| b.a.nrows()).sum();
    let (mut a, mut b) = (DMatrix::zeros(n, n), DMatrix::zeros(n, 3));
    let (mut c, mut d) = (DMatrix::zeros(3, n), DMatrix::zeros(3, 3));
    let mut o = 0;
    for blk in blocks {
        let m = blk.a.nrows();
        a.view_mut((o, o), (m, m)).copy_from(&blk.a);
        b.view_mut((o, 0), (m, 3)).copy_from(&blk.b);
        c.view_mut((0, o), (3, m)).copy_from(&blk.c);
        d += &blk.d;
        o += m;
    }
    MimoStateSpace { a, b, c, d }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three first-order rows, poles 0.5 / 0.4 / 0.3, direct term `d` on
    /// the diagonal, each row's DC gain `dc` (C (I − A)⁻¹ B + D).
    fn rows(d: f64, dc: f64) -> MimoStateSpace {
        let poles = [0.5, 0.4, 0.3];
        let a = DMatrix::from_diagonal(&DVector::from_row_slice(&poles));
        let c = DMatrix::from_diagonal(&DVector::from_iterator(3, poles.iter().map(|p| (dc - d) * (1.0 - p))));
        MimoStateSpace { a, b: DMatrix::identity(3, 3), c, d: DMatrix::identity(3, 3) * d }
    }

    /// A whole filter whose DC gain rows are 0.7 from the identity matches
    /// its design in f32 but is refused, as the box would refuse its image;
    /// the same block as one of two whose sum has the identity DC gain (a
    /// mixed image's 3x3 rows) verifies, and so does the whole filter with
    /// the identity DC gain (the controls).
    #[test]
    fn only_the_whole_filter_is_held_to_the_image_check() {
        let (fs, band) = (51_200.0, 4000.0);
        let e = format!("{:#}", realize_blocks(&[rows(-0.2, 0.3)], fs, band).unwrap_err());
        assert!(e.contains("fails the box's image check") && e.contains("row 0's DC gain"), "{e}");

        let (_, filter, _) = realize_blocks(&[rows(-0.2, 0.3), rows(0.0, 0.7)], fs, band).unwrap();
        assert!(filter.dc_gain().iter().enumerate().all(|(i, g)| (g[i] - 1.0).abs() < 1e-5), "{:?}", filter.dc_gain());
        realize_blocks(&[rows(0.5, 1.0)], fs, band).unwrap();

        let e = format!("{:#}", realize_blocks(&[rows(-0.2, 0.3), rows(0.0, 0.1)], fs, band).unwrap_err());
        assert!(e.contains("the f32 image is refused") && e.contains("DC gain"), "{e}");
    }
}
