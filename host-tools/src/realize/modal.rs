//! Realization of a compensator in the kernel's form (DESIGN.md step 6):
//! modal 2x2 sections in delta form for the slow poles, plus a short FIR for
//! the fast pole cluster, in f64. Every split of the poles into the two
//! clusters that works is a candidate ([`realize_candidates`]); the method
//! is on `realize_split`.

use anyhow::{bail, Result};
use dynocomp_core::kernel::{MAX_FIR, MAX_SECTIONS};
use nalgebra::{DMatrix, DVector, Schur};
use num_complex::Complex64;

use crate::numeric::lti::StateSpace;

/// One 2x2 section in f64 (A − I stored directly, as the kernel does).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Section64 {
    /// A − I, row-major.
    pub delta: [f64; 4],
    /// Input column.
    pub b: [f64; 2],
    /// Output row.
    pub c: [f64; 2],
}

/// The compensator in kernel form, f64.
#[derive(Clone, Debug)]
pub struct ModalRealization {
    /// Sections (slow poles).
    pub sections: Vec<Section64>,
    /// Direct term.
    pub d: f64,
    /// FIR taps h_1..h_m (fast poles).
    pub fir: Vec<f64>,
    /// Poles carried by the sections (z-plane).
    pub poles: Vec<Complex64>,
    /// Condition number estimate of the modal transform of the slow cluster.
    pub modal_condition: f64,
    /// Norm of the cluster decoupling solution X (1 = trivial).
    pub decoupling_norm: f64,
    /// Relative size of the truncated FIR tail.
    pub fir_truncation: f64,
}

impl ModalRealization {
    /// H(z) at z = e^{j2πf/fs}, evaluated from the realization (f64).
    pub fn freq_response(&self, f_hz: f64, fs_hz: f64) -> Complex64 {
        let z = Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f_hz / fs_hz);
        let mut h = Complex64::new(self.d, 0.0);
        for s in &self.sections {
            h += section_response(s.delta, s.b, s.c, z);
        }
        let zi = 1.0 / z;
        let mut zp = zi;
        for tap in &self.fir {
            h += zp * tap;
            zp *= zi;
        }
        h
    }
}

/// c (zI − I − Δ)⁻¹ b for one 2x2 section.
pub fn section_response(delta: [f64; 4], b: [f64; 2], c: [f64; 2], z: Complex64) -> Complex64 {
    let zm1 = z - 1.0;
    let (m11, m12, m21, m22) = (zm1 - delta[0], -delta[1], -delta[2], zm1 - delta[3]);
    let det = m11 * m22 - m12 * m21;
    let x1 = (m22 * b[0] - m12 * b[1]) / det;
    let x2 = (-m21 * b[0] + m11 * b[1]) / det;
    x1 * c[0] + x2 * c[1]
}

/// Poles of one 2x2 section: eigenvalues of I + Δ (z-plane), with the
/// discriminant formed as ((a − d)/2)² + b·c to avoid cancellation.
pub fn section_poles(delta: [f64; 4]) -> [Complex64; 2] {
    let (a, b, c, d) = (1.0 + delta[0], delta[1], delta[2], 1.0 + delta[3]);
    let tr = a + d;
    let disc = Complex64::new((a - d) * (a - d) / 4.0 + b * c, 0.0).sqrt();
    [tr / 2.0 + disc, tr / 2.0 - disc]
}

/// Poles at or beyond this modulus always go to the modal sections (an FIR of
/// 24 taps cannot carry them: 0.6^24 ≈ 5e-6).
pub(crate) const RHO_FAST_MAX: f64 = 0.6;
/// Required relative size of the FIR truncation tail (of Σ|h_j|).
pub(crate) const FIR_TAIL_TOL: f64 = 1e-7;
/// Largest relative truncation tail accepted at the full length
/// [`MAX_FIR`], when [`FIR_TAIL_TOL`] would need more taps. The tail adds at
/// most tail·max|u| to the output, ≤ 1e-6 of Σ|h_j|·max|u| here: the size
/// of f32 rounding of a well-scaled filter (16 ε_f32). It lets a fast pole
/// pair up to |z| ≈ 0.5 join the FIR instead of a section; split from a
/// cluster of poles near z = 0 (the smoother's delay chain), such a pair has
/// a residue ∝ 1/|z|^(cluster size) that the FIR taps must cancel, so its
/// section and the taps sum terms 10³ times the output (on axis y of the
/// bundled example, 1.6e-4 of peak-to-peak lost to f32 rounding).
pub(crate) const FIR_TAIL_TOL_FULL: f64 = 1e-6;
/// Largest acceptable modal-transform condition number.
pub(crate) const MAX_MODAL_CONDITION: f64 = 1e8;

/// Swap adjacent diagonal entries i, i+1 of the upper triangular T,
/// updating Q so that A = Q T Qᴴ still holds.
pub(crate) fn swap_adjacent(t: &mut DMatrix<Complex64>, q: &mut DMatrix<Complex64>, i: usize) {
    let n = t.nrows();
    let (a, b, x) = (t[(i, i)], t[(i + 1, i + 1)], t[(i, i + 1)]);
    // eigenvector of [[a, x], [0, b]] for b: v = [x, b − a]
    let v = [x, b - a];
    let nv = (v[0].norm_sqr() + v[1].norm_sqr()).sqrt();
    if nv == 0.0 {
        return;
    }
    let q1 = [v[0] / nv, v[1] / nv];
    let q2 = [-v[1].conj() / nv, v[0].conj() / nv];
    // rows i, i+1 ← Uᴴ·rows
    for j in 0..n {
        let (r0, r1) = (t[(i, j)], t[(i + 1, j)]);
        t[(i, j)] = q1[0].conj() * r0 + q1[1].conj() * r1;
        t[(i + 1, j)] = q2[0].conj() * r0 + q2[1].conj() * r1;
    }
    // cols i, i+1 ← cols·U
    for m in [&mut *t, &mut *q] {
        for r in 0..n {
            let (c0, c1) = (m[(r, i)], m[(r, i + 1)]);
            m[(r, i)] = c0 * q1[0] + c1 * q1[1];
            m[(r, i + 1)] = c0 * q2[0] + c1 * q2[1];
        }
    }
    t[(i + 1, i)] = Complex64::new(0.0, 0.0);
    t[(i, i)] = b;
    t[(i + 1, i + 1)] = a;
}

/// Candidate fast/slow thresholds: the midpoints of the gaps between the
/// distinct eigenvalue moduli below [`RHO_FAST_MAX`] (and 0: no fast cluster).
pub(crate) fn thresholds(moduli: &[f64]) -> Vec<f64> {
    let mut m: Vec<f64> = moduli.iter().copied().filter(|v| *v < RHO_FAST_MAX).collect();
    m.sort_by(f64::total_cmp);
    let mut out = vec![0.0];
    for w in m.windows(2) {
        if w[1] - w[0] > 1e-3 {
            out.push(0.5 * (w[0] + w[1]));
        }
    }
    if let Some(last) = m.last() {
        let above = moduli.iter().copied().filter(|v| *v > *last).fold(RHO_FAST_MAX, f64::min);
        out.push(0.5 * (last + above));
    }
    out
}

/// Every valid realization of a compensator, one per candidate split of the
/// poles into a fast (FIR) and a slow (modal) cluster, most accurate (f64,
/// against the dense transfer function) first. The caller picks the one that
/// survives f32 rounding best. Fails with the reason of the last attempt
/// when no split works.
pub fn realize_candidates(ss: &StateSpace) -> Result<Vec<ModalRealization>> {
    let eig = crate::fit::linalg::eigenvalues(&ss.a, "realization: the compensator's state matrix A")?;
    let moduli: Vec<f64> = eig.iter().map(|z| z.norm()).collect();
    let schur = complex_schur(ss)?;
    let mut out: Vec<ModalRealization> = Vec::new();
    let mut last_err = None;
    for rho in thresholds(&moduli) {
        match realize_split(ss, &schur, rho) {
            Ok(r) => out.push(r),
            Err(e) => last_err = Some(e),
        }
    }
    if out.is_empty() {
        return Err(last_err.unwrap_or_else(|| anyhow::anyhow!("realization: no eigenvalues")));
    }
    // Rank by measured accuracy: the largest deviation of the realization's
    // response from the dense transfer function over 0..fs/2 (relative to
    // its peak), on a grid in normalized frequency.
    let freqs: Vec<f64> = (0..=256).map(|i| 0.5 * i as f64 / 256.0).collect();
    let h = ss.freq_responses(&freqs, 1.0);
    let peak = h.iter().map(|h| h.norm()).fold(0.0, f64::max);
    let mut scored: Vec<(f64, ModalRealization)> = out
        .into_iter()
        .map(|r| {
            let worst = freqs.iter().zip(&h).map(|(f, h)| (r.freq_response(*f, 1.0) - h).norm()).fold(0.0, f64::max);
            (worst / peak, r)
        })
        .collect();
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(scored.into_iter().map(|x| x.1).collect())
}

/// The most accurate realization (see [`realize_candidates`]).
pub fn realize(ss: &StateSpace) -> Result<ModalRealization> {
    Ok(realize_candidates(ss)?.swap_remove(0))
}

/// Realize with a given fast/slow threshold `rho` on the pole modulus, in
/// five steps (all f64):
/// 1. complex Schur form A = Q T Qᴴ (nalgebra; `schur`, [`complex_schur`],
///    computed once for every threshold);
/// 2. reorder T by Givens swaps of adjacent eigenvalues so the slow poles
///    (|λ| ≥ ρ) come first, the fast ones (|λ| < ρ) last ([`ordered_schur`]);
/// 3. decouple the two clusters with the triangular Sylvester equation
///    T11 X − X T22 = −T12, well conditioned as the clusters are separated
///    ([`decouple`], [`ClusterIo::new`]);
/// 4. fast cluster → FIR taps h_j = C2 T22^{j−1} B2, exact up to the
///    truncation |λ|^m, which is checked ([`fast_fir`]);
/// 5. slow cluster → eigenvectors of the triangular T11 by back substitution
///    (the modal transform; its condition number is checked), residues
///    ρ_i = ĉ_i·b̂_i ([`slow_modes`]), and one real 2x2 section per conjugate
///    pair, real poles two to a diagonal section ([`sections_of`]).
fn realize_split(ss: &StateSpace, schur: &ComplexSchur, rho: f64) -> Result<ModalRealization> {
    let schur = ordered_schur(schur, rho)?;
    let (t, m) = (&schur.t, schur.slow);
    let x = decouple(t, m);
    let decoupling_norm = 1.0 + x.norm();
    if !(decoupling_norm < 1e8) {
        bail!("realization: fast and slow poles are not separable (decoupling norm {decoupling_norm:.1e})");
    }
    let io = ClusterIo::new(ss, &schur.q, &x, m);
    let scale = ss.d.abs() + ss.b.norm() * ss.c.norm();
    let (fir, fir_truncation) = fast_fir(t, m, io.b_fast, io.c_fast, scale)?;
    let (modes, modal_condition) = slow_modes(t, m, io.b_slow, io.c_slow)?;
    let (sections, poles) = sections_of(&modes)?;
    if sections.len() > MAX_SECTIONS {
        bail!(
            "compensator needs {} sections, the box holds {MAX_SECTIONS}; reduce the model order (--max-order) or the lag",
            sections.len()
        );
    }
    Ok(ModalRealization { sections, d: ss.d, fir, poles, modal_condition, decoupling_norm, fir_truncation })
}

/// The Schur form A = Q T Qᴴ with the `slow` eigenvalues (|λ| ≥ ρ) first on
/// T's diagonal.
struct OrderedSchur {
    q: DMatrix<Complex64>,
    t: DMatrix<Complex64>,
    slow: usize,
}

/// Step 1 of [`realize_split`]: the complex Schur form of `ss.a`.
fn complex_schur(ss: &StateSpace) -> Result<ComplexSchur> {
    let no_convergence = || anyhow::anyhow!("realization: Schur decomposition did not converge");
    ComplexSchur::new(&ss.a, 1e-15, 10_000, no_convergence)
}

/// Step 2 of [`realize_split`]: the slow eigenvalues (|λ| ≥ `rho`) of
/// `schur` bubbled to the front by adjacent swaps (the order otherwise
/// kept).
fn ordered_schur(schur: &ComplexSchur, rho: f64) -> Result<OrderedSchur> {
    let (q, t, slow) = schur.slow_first(rho)?;
    Ok(OrderedSchur { q, t, slow })
}

/// The complex Schur form A = Q·T·Qᴴ of a compensator's state matrix, T
/// upper triangular, in nalgebra's order of the eigenvalues: computed once
/// and reordered for each fast/slow threshold ([`Self::slow_first`]), since
/// the decomposition does not depend on the threshold.
pub(crate) struct ComplexSchur {
    q: DMatrix<Complex64>,
    t: DMatrix<Complex64>,
}

impl ComplexSchur {
    /// The form of `a` (tolerance `eps`, at most `max_sweeps` sweeps, else
    /// the error `no_convergence` makes); T's entries below the diagonal,
    /// rounding left by the iteration, set to zero.
    pub(crate) fn new(
        a: &DMatrix<f64>,
        eps: f64,
        max_sweeps: usize,
        no_convergence: impl FnOnce() -> anyhow::Error,
    ) -> Result<Self> {
        let n = a.nrows();
        let schur = Schur::try_new(a.map(|v| Complex64::new(v, 0.0)), eps, max_sweeps).ok_or_else(no_convergence)?;
        let (q, mut t) = schur.unpack();
        for i in 0..n {
            for j in 0..i {
                t[(i, j)] = Complex64::new(0.0, 0.0);
            }
        }
        Ok(ComplexSchur { q, t })
    }

    /// The form with the eigenvalues of modulus ≥ `rho` bubbled to the
    /// front of T's diagonal by adjacent swaps, the order otherwise kept:
    /// (Q, T, their number).
    pub(crate) fn slow_first(&self, rho: f64) -> Result<(DMatrix<Complex64>, DMatrix<Complex64>, usize)> {
        let (mut q, mut t) = (self.q.clone(), self.t.clone());
        let n = t.nrows();
        for _ in 0..n {
            let mut swapped = false;
            for i in 0..n.saturating_sub(1) {
                if t[(i, i)].norm() < rho && t[(i + 1, i + 1)].norm() >= rho {
                    swap_adjacent(&mut t, &mut q, i);
                    swapped = true;
                }
            }
            if !swapped {
                break;
            }
        }
        let slow = (0..n).take_while(|&i| t[(i, i)].norm() >= rho).count();
        if (slow..n).any(|i| t[(i, i)].norm() >= rho) {
            bail!("realization: eigenvalue reordering failed");
        }
        Ok((q, t, slow))
    }
}

/// Step 3 of [`realize_split`]: X of T11 X − X T22 = −T12 for the first `m`
/// (slow) rows of the triangular `t`, column by column.
fn decouple(t: &DMatrix<Complex64>, m: usize) -> DMatrix<Complex64> {
    let nf = t.nrows() - m;
    let mut x = DMatrix::<Complex64>::zeros(m, nf);
    for j in 0..nf {
        let lam = t[(m + j, m + j)];
        let mut rhs: Vec<Complex64> = (0..m).map(|i| -t[(i, m + j)]).collect();
        for l in 0..j {
            let tl = t[(m + l, m + j)];
            for i in 0..m {
                rhs[i] += x[(i, l)] * tl;
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

/// Input and output of the decoupled clusters: B̃ = S⁻¹ Qᴴ b and C̃ = c Q S
/// with S = [[I, X], [0, I]], split into the slow and the fast part.
struct ClusterIo {
    b_slow: Vec<Complex64>,
    b_fast: Vec<Complex64>,
    c_slow: Vec<Complex64>,
    c_fast: Vec<Complex64>,
}

impl ClusterIo {
    /// For the first `m` (slow) states of the Schur basis `q` and the
    /// decoupling `x` of [`decouple`].
    fn new(ss: &StateSpace, q: &DMatrix<Complex64>, x: &DMatrix<Complex64>, m: usize) -> Self {
        let nf = x.ncols();
        let bq = q.adjoint() * ss.b.map(|v| Complex64::new(v, 0.0));
        let cq = ss.c.map(|v| Complex64::new(v, 0.0)).transpose() * q;
        let mut b_slow: Vec<Complex64> = (0..m).map(|i| bq[i]).collect();
        let b_fast: Vec<Complex64> = (0..nf).map(|i| bq[m + i]).collect();
        for i in 0..m {
            for j in 0..nf {
                b_slow[i] -= x[(i, j)] * b_fast[j];
            }
        }
        let c_slow: Vec<Complex64> = (0..m).map(|i| cq[i]).collect();
        let mut c_fast: Vec<Complex64> = (0..nf).map(|j| cq[m + j]).collect();
        for j in 0..nf {
            for i in 0..m {
                c_fast[j] += c_slow[i] * x[(i, j)];
            }
        }
        ClusterIo { b_slow, b_fast, c_slow, c_fast }
    }
}

/// Largest imaginary part of a fast-cluster FIR tap relative to the
/// response's size ([`fast_fir`]).
pub(crate) const MAX_IMAGINARY_TAP: f64 = 1e-9;

/// Step 4 of [`realize_split`]: the fast cluster (the states after the
/// first `m` of `t`) as FIR taps h_j = C2 T22^{j−1} B2, the shortest length
/// whose tail is below [`FIR_TAIL_TOL`] of Σ|h_j| (or [`FIR_TAIL_TOL_FULL`]
/// at [`MAX_FIR`] taps); with the relative size of the truncated tail.
/// The taps' imaginary parts, rounding only for a conjugate-closed cluster,
/// must stay below [`MAX_IMAGINARY_TAP`] of Σ|h_j| + `scale`, the size of
/// the whole compensator's response (|D| + ‖B‖·‖C‖): a fast cluster that
/// contributes next to nothing has taps of the size of that rounding.
fn fast_fir(
    t: &DMatrix<Complex64>,
    m: usize,
    b2: Vec<Complex64>,
    c2: Vec<Complex64>,
    scale: f64,
) -> Result<(Vec<f64>, f64)> {
    let nf = t.nrows() - m;
    if nf == 0 {
        return Ok((Vec::new(), 0.0));
    }
    let t22 = t.view((m, m), (nf, nf)).clone_owned();
    let mut v = DVector::<Complex64>::from_vec(b2);
    let c2v = DVector::<Complex64>::from_vec(c2);
    let mut taps = Vec::new();
    for _ in 0..MAX_FIR + 16 {
        taps.push(c2v.dot(&v)); // c2ᵀ v (no conjugation)
        v = &t22 * v;
    }
    let total: f64 = taps.iter().map(|h| h.norm()).sum::<f64>().max(f64::MIN_POSITIVE);
    // shortest length whose tail is negligible
    let mut len = 0;
    for l in 0..=MAX_FIR {
        let tail: f64 = taps[l..].iter().map(|h| h.norm()).sum();
        if tail <= FIR_TAIL_TOL * total {
            len = l;
            break;
        }
        len = l + 1;
    }
    let full_tail: f64 = taps[MAX_FIR..].iter().map(|h| h.norm()).sum();
    if len > MAX_FIR && full_tail <= FIR_TAIL_TOL_FULL * total {
        len = MAX_FIR;
    }
    if len > MAX_FIR {
        bail!(
            "realization: the fast poles need more than {MAX_FIR} FIR taps (tail {:.1e} of the response); reduce the lag",
            full_tail / total
        );
    }
    let fir_truncation = taps[len..].iter().map(|h| h.norm()).sum::<f64>() / total;
    let imag = taps[..len].iter().map(|h| h.im.abs()).fold(0.0, f64::max);
    if imag > MAX_IMAGINARY_TAP * (total + scale) {
        bail!(
            "realization: FIR taps are not real (imaginary part {imag:.1e}); the fast cluster is not conjugate-closed"
        );
    }
    Ok((taps[..len].iter().map(|h| h.re).collect(), fir_truncation))
}

/// Step 5 of [`realize_split`], first half: the slow cluster's eigenvalues
/// The eigenvectors W of the upper triangular `t11` (unit diagonal, back
/// substitution) and W⁻¹, with W's condition number estimate.
pub(crate) fn triangular_eigenvectors(
    t11: &DMatrix<Complex64>,
) -> Result<(DMatrix<Complex64>, DMatrix<Complex64>, f64)> {
    let m = t11.nrows();
    let mut w = DMatrix::<Complex64>::identity(m, m);
    for k in 0..m {
        let lam = t11[(k, k)];
        for i in (0..k).rev() {
            let mut s = Complex64::new(0.0, 0.0);
            for l in i + 1..=k {
                s += t11[(i, l)] * w[(l, k)];
            }
            let den = t11[(i, i)] - lam;
            if den.norm() == 0.0 {
                bail!("realization: repeated pole {lam}; nearly coincident modes cannot be split into sections");
            }
            w[(i, k)] = -s / den;
        }
    }
    let w_inv = w
        .clone()
        .solve_upper_triangular(&DMatrix::identity(m, m))
        .ok_or_else(|| anyhow::anyhow!("realization: modal transform is singular"))?;
    let condition = w.norm() * w_inv.norm() / (m.max(1) as f64);
    if !(condition < MAX_MODAL_CONDITION) {
        bail!("realization: modal transform is ill-conditioned (condition {condition:.1e}); nearly coincident compensator poles");
    }
    Ok((w, w_inv, condition))
}

/// λ_i (the first `m` of `t`'s diagonal) with their residues ρ_i = ĉ_i·b̂_i,
/// through the eigenvectors of the triangular T11 (a unit upper triangular
/// W, by back substitution); with W's condition number estimate, at most
/// [`MAX_MODAL_CONDITION`].
fn slow_modes(
    t: &DMatrix<Complex64>,
    m: usize,
    b1: Vec<Complex64>,
    c1: Vec<Complex64>,
) -> Result<(Vec<(Complex64, Complex64)>, f64)> {
    let (w, w_inv, modal_condition) = triangular_eigenvectors(&t.view((0, 0), (m, m)).into_owned())?;
    let bh = &w_inv * DVector::from_vec(b1);
    let ch = DVector::from_vec(c1).transpose() * &w;
    Ok(((0..m).map(|i| (t[(i, i)], ch[i] * bh[i])).collect(), modal_condition))
}

/// Step 5 of [`realize_split`], second half: the kernel's sections for the
/// (pole, residue) pairs `eig`, with the poles they carry. A conjugate pair
/// λ, λ̄ becomes Δ = A − I = [[σ, ω], [−ω, σ]], b = [1, 0],
/// c = [2 Re ρ, 2 Im ρ] (λ = 1 + σ + jω, Im λ > 0); real poles go two to a
/// diagonal section (b = 1, c = ρ), a last odd one with its second state at
/// z = 0. These are the two shapes the kernel runs
/// (`dynocomp_core::kernel`); unit input gain makes the kernel's folding of
/// b into c exact, and f32 rounding is relative, so the state's scale does
/// not matter for accuracy.
fn sections_of(eig: &[(Complex64, Complex64)]) -> Result<(Vec<Section64>, Vec<Complex64>)> {
    let m = eig.len();
    let scale = eig.iter().map(|e| e.0.norm()).fold(1.0, f64::max);
    let mut used = vec![false; m];
    let mut sections = Vec::new();
    let mut poles = Vec::new();
    let mut reals: Vec<(f64, f64)> = Vec::new();
    for i in 0..m {
        if used[i] {
            continue;
        }
        let (lam, res) = eig[i];
        used[i] = true;
        if lam.im.abs() <= 1e-10 * scale {
            reals.push((lam.re, res.re));
            continue;
        }
        // partner: the unused eigenvalue closest to conj(lam)
        let partner = (0..m)
            .filter(|&j| !used[j])
            .min_by(|&a, &b| (eig[a].0 - lam.conj()).norm().total_cmp(&(eig[b].0 - lam.conj()).norm()));
        let Some(j) = partner else {
            bail!("realization: pole {lam} has no conjugate partner");
        };
        if (eig[j].0 - lam.conj()).norm() > 1e-8 * scale {
            bail!("realization: pole {lam} has no conjugate partner (closest {})", eig[j].0);
        }
        used[j] = true;
        let (lam, res) = if lam.im > 0.0 { (lam, res) } else { (eig[j].0, eig[j].1) };
        sections.push(Section64 {
            delta: [lam.re - 1.0, lam.im, -lam.im, lam.re - 1.0],
            b: [1.0, 0.0],
            c: [2.0 * res.re, 2.0 * res.im],
        });
        poles.push(lam);
        poles.push(lam.conj());
    }
    for pair in reals.chunks(2) {
        let mk = |(p, r): (f64, f64)| (p - 1.0, 1.0, r);
        let (d1, b1, c1) = mk(pair[0]);
        poles.push(Complex64::new(pair[0].0, 0.0));
        let sec = if let Some(&second) = pair.get(1) {
            let (d2, b2, c2) = mk(second);
            poles.push(Complex64::new(second.0, 0.0));
            Section64 { delta: [d1, 0.0, 0.0, d2], b: [b1, b2], c: [c1, c2] }
        } else {
            // second state unused, pole at z = 0 (kernel convention)
            Section64 { delta: [d1, 0.0, 0.0, -1.0], b: [b1, 0.0], c: [c1, 0.0] }
        };
        sections.push(sec);
    }
    Ok((sections, poles))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A compensator whose fast cluster (a delay line, poles at 0) adds next
    /// to nothing to the output: its FIR taps are of the size of the Schur
    /// form's rounding, imaginary parts included. Judged against the taps'
    /// own sum, that rounding looked like a cluster that is not
    /// conjugate-closed and no split realized; judged against the
    /// compensator's size (|D| + ‖B‖·‖C‖), it is realized, and matches the
    /// dense response.
    #[test]
    fn a_negligible_fast_cluster_is_realized() {
        let (r, th) = (0.99f64, 0.3f64);
        let mut a = DMatrix::<f64>::zeros(5, 5);
        a[(0, 0)] = r * th.cos();
        a[(0, 1)] = -r * th.sin();
        a[(1, 0)] = r * th.sin();
        a[(1, 1)] = r * th.cos();
        a[(3, 2)] = 1.0;
        a[(4, 3)] = 1.0;
        let b = DVector::from_vec(vec![1.0, 0.5, 1e-13, 0.0, 0.0]);
        let c = DVector::from_vec(vec![0.7, -0.2, 0.0, 0.0, 1e-13]);
        // Mix the states by a rotation, as a Kalman design's coordinates do.
        let mut seed = 11u64;
        let m = DMatrix::from_fn(5, 5, |_, _| {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        });
        let q = m.qr().q();
        let ss = StateSpace { a: &q * a * q.transpose(), b: &q * b, c: &q * c, d: 0.1 };
        let real = realize(&ss).expect("a negligible fast cluster is realized");
        let worst = (0..64)
            .map(|i| 0.5 * i as f64 / 64.0)
            .map(|f| (real.freq_response(f, 1.0) - ss.freq_response(f, 1.0)).norm())
            .fold(0.0, f64::max);
        assert!(worst < 1e-9, "realization against the dense response: {worst:e}");
    }
}
