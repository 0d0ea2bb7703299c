//! The seed paper's fit (§3, eq. (1)): a rational fraction polynomial
//! ([`RationalTf`]) estimated in two steps, as MATLAB `invfreqs` does
//! ([`rfp_fit`]). A leaf of the chain.

// `!(x < limit)` on purpose: a NaN residual or condition number must fail
// the check, as in kalman.rs and quantize.rs.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;
use std::f64::consts::PI;

use super::{PoleResidueModel, Term};

/// Condition number above which the fit's least-squares matrix counts as
/// numerically singular (≈ 1/(√ε·…)): a solution then carries no digits.
pub const MAX_CONDITION: f64 = 1e12;

/// A rational transfer function in rescaled frequency `s' = s/ω_0` (eq. (1)):
///
/// `G(s) = B(s)/A(s) = (b_0 + b_1 s' + … + b_nb s'^nb) / (a_0 + a_1 s' + … + s'^na)`,
/// `s' = s/ω_0` (frequency rescaling, ω_0 in rad/s).
#[derive(Clone, Debug, PartialEq)]
pub struct RationalTf {
    /// Numerator coefficients b_0..b_nb, ascending powers of s' (N/N).
    pub b: Vec<f64>,
    /// Denominator coefficients a_0..a_na, ascending powers of s', monic (a_na = 1).
    pub a: Vec<f64>,
    /// Frequency scale ω_0 (rad/s).
    pub omega_scale: f64,
}

/// Evaluate a polynomial with ascending real coefficients at complex `x`.
pub fn poly_eval(c: &[f64], x: Complex64) -> Complex64 {
    c.iter().rev().fold(Complex64::new(0.0, 0.0), |acc, &v| acc * x + v)
}

/// Roots of a monic polynomial (ascending coefficients), as the eigenvalues
/// of its companion matrix, with an iteration limit
/// ([`super::linalg::poly_roots`]); `what` names the polynomial in errors.
pub fn poly_roots(a: &[f64], what: &str) -> Result<Vec<Complex64>> {
    super::linalg::poly_roots(a, what)
}

/// Monic real polynomial (ascending) with the given roots (conjugates paired).
pub fn poly_from_roots(roots: &[Complex64]) -> Vec<f64> {
    let mut c = vec![Complex64::new(1.0, 0.0)];
    for r in roots {
        let mut next = vec![Complex64::new(0.0, 0.0); c.len() + 1];
        for (i, v) in c.iter().enumerate() {
            next[i + 1] += v;
            next[i] -= v * r;
        }
        c = next;
    }
    c.iter().map(|v| v.re).collect()
}

impl RationalTf {
    /// Numerator order nb.
    pub fn nb(&self) -> usize {
        self.b.len() - 1
    }

    /// Denominator order na (the model order).
    pub fn na(&self) -> usize {
        self.a.len() - 1
    }

    /// G(s) at complex frequency `s` (rad/s).
    pub fn eval_s(&self, s: Complex64) -> Complex64 {
        let x = s / self.omega_scale;
        poly_eval(&self.b, x) / poly_eval(&self.a, x)
    }

    /// G(j·2π·f) at `f_hz` (Hz).
    pub fn frf(&self, f_hz: f64) -> Complex64 {
        self.eval_s(Complex64::new(0.0, 2.0 * PI * f_hz))
    }

    /// The denominator's name in errors.
    fn denominator(&self) -> String {
        format!("the denominator of the {}:{} rational fraction fit", self.nb(), self.na())
    }

    /// Poles (rad/s); an error if their eigenvalue iteration does not converge.
    pub fn poles(&self) -> Result<Vec<Complex64>> {
        Ok(poly_roots(&self.a, &self.denominator())?.into_iter().map(|p| p * self.omega_scale).collect())
    }

    /// Whether every pole has a negative real part; an error if their
    /// eigenvalue iteration does not converge.
    pub fn is_stable(&self) -> Result<bool> {
        Ok(poly_roots(&self.a, &self.denominator())?.iter().all(|p| p.re < 0.0))
    }

    /// The same G(s) in pole-residue form (for reports and evaluation):
    /// residue of pole p = ω_0·B(p')/A'(p'). Fails on (numerically) repeated
    /// poles, where partial fractions do not exist.
    pub fn to_pole_residue(&self) -> Result<PoleResidueModel> {
        let roots = poly_roots(&self.a, &self.denominator())?;
        let da: Vec<f64> = self.a.iter().enumerate().skip(1).map(|(i, v)| i as f64 * v).collect();
        let (mut b, d) = (self.b.clone(), if self.nb() == self.na() { self.b[self.nb()] } else { 0.0 });
        if self.nb() == self.na() {
            // strictly proper part: B − d·A
            for (bi, ai) in b.iter_mut().zip(&self.a) {
                *bi -= d * ai;
            }
        }
        if self.nb() > self.na() {
            bail!("numerator order {} above denominator order {}: improper transfer function", self.nb(), self.na());
        }
        let mut terms = Vec::new();
        for p in &roots {
            let dp = poly_eval(&da, *p);
            if dp.norm() < 1e-10 * (1.0 + p.norm()).powi(self.na() as i32 - 1) {
                bail!(
                    "repeated pole near {:.1} Hz: no partial-fraction form",
                    (p * self.omega_scale).norm() / (2.0 * PI)
                );
            }
            let r = poly_eval(&b, *p) / dp * self.omega_scale;
            let pole = p * self.omega_scale;
            if p.im.abs() <= 1e-9 * p.norm().max(1e-300) {
                terms.push(Term::Real { pole: pole.re, residue: r.re });
            } else if p.im > 0.0 {
                terms.push(Term::Pair { pole, residue: r });
            }
        }
        Ok(PoleResidueModel { terms, d })
    }
}

/// Options of the paper's fit.
#[derive(Clone, Debug)]
pub struct RfpOptions {
    /// Numerator order nb.
    pub nb: usize,
    /// Denominator order na.
    pub na: usize,
    /// Gauss–Newton iterations at most (invfreqs default: 30).
    pub max_iterations: usize,
    /// Stop when the relative decrease of the error is below this.
    pub tol: f64,
}

impl Default for RfpOptions {
    fn default() -> Self {
        RfpOptions { nb: 6, na: 8, max_iterations: 30, tol: 1e-9 }
    }
}

/// Result of the fit with its conditioning diagnostics.
#[derive(Clone, Debug)]
pub struct RfpFit {
    /// Fitted transfer function.
    pub tf: RationalTf,
    /// Condition number of the RFP (linearized) least-squares matrix.
    pub rfp_condition: f64,
    /// Condition number of the Gauss–Newton Jacobian at the solution
    /// (large: more poles than the data support, near pole-zero cancellation).
    pub jacobian_condition: f64,
    /// Weighted output error sqrt(Σw|Ĝ−G|²/Σw|G|²) of the initial estimate.
    pub initial_error: f64,
    /// The same after Gauss–Newton.
    pub final_error: f64,
    /// Gauss–Newton iterations done.
    pub iterations: usize,
    /// Unstable roots reflected in the initial estimate.
    pub reflected_poles: usize,
}

/// Condition number σ_max/σ_min of a matrix (∞ when singular, and when its
/// singular values do not converge within [`super::linalg::sweeps`]: a
/// matrix whose SVD does not converge counts as singular). See
/// [`try_condition_number`] for the error instead.
pub fn condition_number(m: &DMatrix<f64>) -> f64 {
    try_condition_number(m, "matrix").unwrap_or(f64::INFINITY)
}

/// Condition number σ_max/σ_min of a matrix (∞ when singular); an error
/// naming `what` if its singular values do not converge.
pub fn try_condition_number(m: &DMatrix<f64>, what: &str) -> Result<f64> {
    Ok(condition_of(&super::linalg::singular_values(m, what)?))
}

/// max σ / min σ of the singular values `sv` (∞ if one is zero).
fn condition_of(sv: &DVector<f64>) -> f64 {
    let max = sv.iter().copied().fold(0.0, f64::max);
    let min = sv.iter().copied().fold(f64::INFINITY, f64::min);
    if min > 0.0 {
        max / min
    } else {
        f64::INFINITY
    }
}

/// Least squares by SVD with its condition number; columns are scaled to
/// unit norm first (the condition reported is that of the scaled problem,
/// i.e. what no diagonal rescaling can remove).
///
/// The matrix is tall (two rows per FRF line, a few tens of columns), so it
/// is reduced first: M = QR by Householder, and the SVD is that of the
/// square R, solving R x = (Qᵀ rhs)[..n]. R has M's singular values and the
/// same least-squares solution (Golub & Van Loan, "Matrix Computations",
/// §5.4.5, R-bidiagonalization); the SVD of M itself spent most of its time
/// forming and rotating its tall U.
fn lstsq(m: DMatrix<f64>, rhs: &DVector<f64>, what: &str) -> Result<(DVector<f64>, f64)> {
    let scale: Vec<f64> = m.column_iter().map(|c| c.norm().max(f64::MIN_POSITIVE)).collect();
    let mut ms = m;
    for (j, s) in scale.iter().enumerate() {
        ms.column_mut(j).scale_mut(1.0 / s);
    }
    let n = ms.ncols();
    if ms.nrows() < n {
        bail!("{what}: {} equations for {n} unknowns", ms.nrows());
    }
    let qr = ms.qr();
    let mut qt_rhs = rhs.clone();
    qr.q_tr_mul(&mut qt_rhs);
    // One SVD for both: the condition from its singular values.
    let svd = super::linalg::svd(qr.r(), what)?;
    let cond = condition_of(&svd.singular_values);
    let x = svd.solve(&qt_rhs.rows(0, n).into_owned(), 0.0).map_err(|e| anyhow::anyhow!("{what}: {e}"))?;
    Ok((DVector::from_iterator(x.len(), x.iter().zip(&scale).map(|(v, s)| v / s)), cond))
}

/// Weighted relative output error sqrt(Σw|Ĝ−G|²/Σw|G|²).
fn output_error(tf_b: &[f64], tf_a: &[f64], xs: &[Complex64], h: &[Complex64], w: &[f64]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for ((x, g), wk) in xs.iter().zip(h).zip(w) {
        num += wk * (poly_eval(tf_b, *x) / poly_eval(tf_a, *x) - g).norm_sqr();
        den += wk * g.norm_sqr();
    }
    (num / den).sqrt()
}

/// Fit eq. (1) to the lines `freq_hz`/`h` with weights `w` (zero = unused),
/// frequencies rescaled by ω_0 = 2π·(highest weighted line) ([`RationalTf`]):
/// the RFP initial estimate (step 1), then damped Gauss–Newton (step 2).
///
/// 1. **Initial estimate** (rational fraction polynomial, Richardson &
///    Formenti 1982; the linearized "equation error" of Levy 1959): minimize
///    `Σ w_k |B(s'_k) − G_k A(s'_k)|²`, linear in the coefficients. Richardson
///    and Formenti solve it through orthogonal (Forsythe) polynomials to
///    avoid the normal equations; here the same least-squares problem is
///    solved by SVD of the power-basis matrix, whose condition number is
///    reported: it is the paper's "poorly conditioned" diagnostic (§3.1).
///    Unstable roots of A are reflected into the left half-plane.
/// 2. **Damped Gauss–Newton** refinement of the weighted output error
///    `Σ w_k |B(s'_k)/A(s'_k) − G_k|²` (Dennis & Schnabel), halving the step
///    until the error decreases and A stays stable.
///
/// The weights are the coherence γ² of each line (paper §3: "the coherence
/// functions has been taken as weight"), zero outside the fitting bands.
pub fn rfp_fit(freq_hz: &[f64], h: &[Complex64], w: &[f64], opts: &RfpOptions) -> Result<RfpFit> {
    let (nb, na) = (opts.nb, opts.na);
    if na == 0 || nb > na {
        bail!("--paper-orders {nb}:{na}: need 1 ≤ denominator order and numerator order ≤ denominator order");
    }
    let lines = FitLines::new(freq_hz, h, w, nb, na)?;
    let (b0, a0, rfp_condition, reflected_poles) = initial_estimate(&lines, nb, na)?;
    let initial_error = output_error(&b0, &a0, &lines.xs, &lines.hs, &lines.ws);
    let gn = gauss_newton(&lines, b0, a0, initial_error, opts)?;
    // An ill-conditioned Jacobian (near pole-zero cancellation: more poles
    // than the data support) is reported, not fatal: the SVD step is the
    // minimum-norm one, and what breaks downstream (observability, Riccati)
    // is checked there.
    let tf = RationalTf { b: gn.b, a: gn.a, omega_scale: 2.0 * PI * lines.f_max };
    if !tf.is_stable()? {
        bail!("the {nb}:{na} fit has unstable poles after Gauss–Newton; lower the orders or fit narrower bands");
    }
    Ok(RfpFit {
        tf,
        rfp_condition,
        jacobian_condition: gn.jacobian_condition,
        initial_error,
        final_error: gn.error,
        iterations: gn.iterations,
        reflected_poles,
    })
}

/// The weighted lines of a fit, in rescaled frequency.
struct FitLines {
    /// s'_k = j f_k / f_max.
    xs: Vec<Complex64>,
    hs: Vec<Complex64>,
    ws: Vec<f64>,
    /// Lowest and highest weighted line (Hz).
    f_min: f64,
    f_max: f64,
}

impl FitLines {
    /// The lines with a positive weight and a non-zero FRF: enough to
    /// determine the nb + 1 + na coefficients.
    fn new(freq_hz: &[f64], h: &[Complex64], w: &[f64], nb: usize, na: usize) -> Result<FitLines> {
        let used: Vec<usize> = (0..freq_hz.len()).filter(|&k| w[k] > 0.0 && h[k].norm() > 0.0).collect();
        let unknowns = nb + 1 + na;
        if 2 * used.len() < 2 * unknowns {
            bail!(
                "{} weighted lines cannot determine {unknowns} coefficients of a {nb}:{na} fit: widen the bands or \
                 lower the orders",
                used.len()
            );
        }
        let f_max = used.iter().map(|&k| freq_hz[k]).fold(0.0, f64::max);
        Ok(FitLines {
            xs: used.iter().map(|&k| Complex64::new(0.0, freq_hz[k] / f_max)).collect(),
            hs: used.iter().map(|&k| h[k]).collect(),
            ws: used.iter().map(|&k| w[k]).collect(),
            f_min: used.iter().map(|&k| freq_hz[k]).fold(f64::INFINITY, f64::min),
            f_max,
        })
    }
}

/// Step 1, the RFP / Levy initial estimate: least squares on the rows
/// sqrt(w)·[x^i (i ≤ nb) | −G x^i (i < na)] = sqrt(w)·G x^na, unstable roots
/// of A reflected. Returns B, A (monic), the condition number and the number
/// of roots reflected.
fn initial_estimate(lines: &FitLines, nb: usize, na: usize) -> Result<(Vec<f64>, Vec<f64>, f64, usize)> {
    let m = lines.xs.len();
    let mut mat = DMatrix::<f64>::zeros(2 * m, nb + 1 + na);
    let mut rhs = DVector::<f64>::zeros(2 * m);
    for (k, ((x, g), wk)) in lines.xs.iter().zip(&lines.hs).zip(&lines.ws).enumerate() {
        let sw = wk.sqrt();
        let mut xp = Complex64::new(1.0, 0.0);
        for i in 0..=na {
            if i <= nb {
                mat[(2 * k, i)] = sw * xp.re;
                mat[(2 * k + 1, i)] = sw * xp.im;
            }
            let gx = g * xp;
            if i < na {
                mat[(2 * k, nb + 1 + i)] = -sw * gx.re;
                mat[(2 * k + 1, nb + 1 + i)] = -sw * gx.im;
            } else {
                rhs[2 * k] = sw * gx.re;
                rhs[2 * k + 1] = sw * gx.im;
            }
            xp *= x;
        }
    }
    let (theta, rfp_condition) =
        lstsq(mat, &rhs, &format!("the {nb}:{na} rational fraction polynomial least squares"))?;
    if !(rfp_condition < MAX_CONDITION) || theta.iter().any(|v| !v.is_finite()) {
        bail!(
            "rational fraction polynomial fit {nb}:{na} over {:.0}–{:.0} Hz is ill-conditioned: condition number \
             {rfp_condition:.2e} (limit {MAX_CONDITION:.0e}); lower the orders or fit narrower bands (--band, \
             --spindle-rpm)",
            lines.f_min,
            lines.f_max
        );
    }
    let b0: Vec<f64> = theta.iter().take(nb + 1).copied().collect();
    let mut a0: Vec<f64> = theta.iter().skip(nb + 1).copied().collect();
    a0.push(1.0);
    // Reflect unstable roots (invfreqs does the same to its initial estimate).
    let roots = poly_roots(&a0, &format!("the denominator of the {nb}:{na} initial estimate"))?;
    let reflected_poles = roots.iter().filter(|r| r.re >= 0.0).count();
    let a0 = if reflected_poles > 0 {
        poly_from_roots(
            &roots
                .iter()
                .map(|r| if r.re >= 0.0 { Complex64::new(-r.re.abs().max(1e-6 * r.norm()), r.im) } else { *r })
                .collect::<Vec<_>>(),
        )
    } else {
        a0
    };
    Ok((b0, a0, rfp_condition, reflected_poles))
}

/// The result of step 2.
struct GaussNewton {
    b: Vec<f64>,
    a: Vec<f64>,
    /// Output error after the last accepted step.
    error: f64,
    iterations: usize,
    /// Condition number of the last Jacobian (NaN without iterations).
    jacobian_condition: f64,
}

/// Step 2, damped Gauss–Newton on the output error from (b, a) with error
/// `err`; parameters [b_0..b_nb, a_0..a_{na−1}]. Stops when a step does not
/// lower the error by more than `opts.tol` (relative), or after
/// `opts.max_iterations`.
fn gauss_newton(lines: &FitLines, b: Vec<f64>, a: Vec<f64>, err: f64, opts: &RfpOptions) -> Result<GaussNewton> {
    let (nb, na) = (opts.nb, opts.na);
    let mut gn = GaussNewton { b, a, error: err, iterations: 0, jacobian_condition: f64::NAN };
    for it in 1..=opts.max_iterations {
        gn.iterations = it;
        let (jac, res) = jacobian(lines, &gn.b, &gn.a, nb, na);
        let (step, cond) = lstsq(jac, &res, &format!("the {nb}:{na} Gauss–Newton step {it}"))?;
        gn.jacobian_condition = cond;
        if !damped_step(lines, &mut gn, &step, nb, na, opts.tol) {
            break;
        }
    }
    Ok(gn)
}

/// The weighted residual sqrt(w)·(G − B/A) and its Jacobian with respect to
/// [b_0..b_nb, a_0..a_{na−1}], real and imaginary parts in alternate rows.
fn jacobian(lines: &FitLines, b: &[f64], a: &[f64], nb: usize, na: usize) -> (DMatrix<f64>, DVector<f64>) {
    let m = lines.xs.len();
    let mut jac = DMatrix::<f64>::zeros(2 * m, nb + 1 + na);
    let mut res = DVector::<f64>::zeros(2 * m);
    for (k, ((x, g), wk)) in lines.xs.iter().zip(&lines.hs).zip(&lines.ws).enumerate() {
        let sw = wk.sqrt();
        let (bv, av) = (poly_eval(b, *x), poly_eval(a, *x));
        let e = sw * (g - bv / av);
        res[2 * k] = e.re;
        res[2 * k + 1] = e.im;
        let mut xp = Complex64::new(1.0, 0.0);
        for i in 0..na {
            if i <= nb {
                let d = sw * xp / av;
                jac[(2 * k, i)] = d.re;
                jac[(2 * k + 1, i)] = d.im;
            }
            let d = -sw * bv * xp / (av * av);
            jac[(2 * k, nb + 1 + i)] = d.re;
            jac[(2 * k + 1, nb + 1 + i)] = d.im;
            xp *= x;
        }
        if nb == na {
            let d = sw * xp / av;
            jac[(2 * k, nb)] = d.re;
            jac[(2 * k + 1, nb)] = d.im;
        }
    }
    (jac, res)
}

/// Take `step`, halved up to 20 times until the output error decreases and
/// A stays stable; true if a step was taken and lowered the error by more
/// than `tol` (relative).
fn damped_step(lines: &FitLines, gn: &mut GaussNewton, step: &DVector<f64>, nb: usize, na: usize, tol: f64) -> bool {
    let mut lambda = 1.0;
    for _ in 0..20 {
        let bt: Vec<f64> = gn.b.iter().enumerate().map(|(i, v)| v + lambda * step[i]).collect();
        let mut at: Vec<f64> = (0..na).map(|i| gn.a[i] + lambda * step[nb + 1 + i]).collect();
        at.push(1.0);
        let et = output_error(&bt, &at, &lines.xs, &lines.hs, &lines.ws);
        // A trial whose roots do not converge is a rejected step, like
        // one that is unstable or does not lower the error.
        let stable = || poly_roots(&at, "trial denominator").is_ok_and(|r| r.iter().all(|r| r.re < 0.0));
        if et.is_finite() && et < gn.error && stable() {
            let improvement = (gn.error - et) / gn.error;
            gn.b = bt;
            gn.a = at;
            gn.error = et;
            return improvement > tol;
        }
        lambda *= 0.5;
    }
    false
}

/// Paper fit weights: coherence γ² per line (1 without coherence), zero
/// where `mask` is false.
pub fn paper_weights(coherence: Option<&[f64]>, mask: &[bool]) -> Vec<f64> {
    mask.iter()
        .enumerate()
        .map(|(k, m)| if *m { coherence.map_or(1.0, |c| c[k].clamp(0.0, 1.0)) } else { 0.0 })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_squares_through_qr_matches_the_normal_equations() {
        // A tall system with badly scaled columns (what lstsq scales away),
        // against an independent solution: the normal equations AᵀA x = Aᵀb
        // by Cholesky, fine for a well-conditioned scaled problem.
        let (rows, cols) = (400, 9);
        let mut state = 7u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        };
        let m = DMatrix::<f64>::from_fn(rows, cols, |_, j| next() * 10f64.powi(j as i32 - 4));
        let b = DVector::<f64>::from_fn(rows, |_, _| next());
        let (x, cond) = lstsq(m.clone(), &b, "test").unwrap();
        let reference = (m.transpose() * &m).cholesky().unwrap().solve(&(m.transpose() * &b));
        let err = (&x - &reference).norm() / reference.norm();
        assert!(err < 1e-10, "QR-SVD solution {err:.1e} from the normal equations");
        // The condition of the column-scaled matrix, from its full SVD.
        let mut ms = m.clone();
        for mut c in ms.column_iter_mut() {
            let n = c.norm();
            c /= n;
        }
        let full = condition_number(&ms);
        assert!((cond / full - 1.0).abs() < 1e-10, "condition {cond} against {full} from the full SVD");
        // Negative control: the solution of a slightly different right-hand
        // side is seen at this tolerance.
        let (x2, _) = lstsq(m.clone(), &(b.clone() + DVector::from_element(rows, 1e-6)), "test").unwrap();
        assert!((&x2 - &reference).norm() / reference.norm() > 1e-8);
        // Fewer equations than unknowns: refused, not a made-up solution.
        assert!(lstsq(DMatrix::from_element(3, 5, 1.0), &DVector::from_element(3, 1.0), "test").is_err());
    }

    #[test]
    fn polynomial_roots_round_trip() {
        let roots = [Complex64::new(-0.1, 0.9), Complex64::new(-0.1, -0.9), Complex64::new(-0.5, 0.0)];
        let a = poly_from_roots(&roots);
        assert_eq!(a.len(), 4);
        let mut back = poly_roots(&a, "test").unwrap();
        back.sort_by(|x, y| x.im.total_cmp(&y.im));
        for (r, t) in back.iter().zip([roots[1], roots[2], roots[0]]) {
            assert!((r - t).norm() < 1e-12, "{r} vs {t}");
        }
    }
}
