//! The seed paper's compensator (§3.1, §4; `design --method paper`,
//! [`design`]): a continuous Kalman filter on the companion form of the fitted
//! G(s) = B(s')/A(s'), discretized by Tustin with prewarping. Where the path
//! breaks, it stops with the condition numbers and the observability rank (the
//! paper, §3.1: "the observability matrix is not full rank due to round-off
//! errors").

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use std::f64::consts::PI;

use crate::design::kalman::KalmanDesign;
use crate::fit::linalg;
pub use crate::fit::rfp::condition_number;
use crate::fit::rfp::RationalTf;
use crate::numeric::lti::StateSpace;

/// Condition numbers and ranks along the paper's path (reported by
/// `design --method paper` and `compare`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct PaperDiagnostics {
    /// Condition number of the RFP least-squares matrix.
    pub rfp_condition: f64,
    /// Condition number of the Gauss–Newton Jacobian at the solution.
    pub jacobian_condition: f64,
    /// Condition number of the companion matrix A_s (rescaled time).
    pub companion_condition: f64,
    /// Numerical rank of the observability matrix of (A_e, C_e).
    pub observability_rank: usize,
    /// Its full rank (augmented order na + 1).
    pub observability_dim: usize,
    /// Condition number of the (row-normalized) observability matrix.
    pub observability_condition: f64,
    /// Relative residual of the continuous Riccati equation (7).
    pub care_residual: f64,
    /// Prewarping frequency of the Tustin transform (Hz).
    pub prewarp_hz: f64,
    /// Frequency scale ω_0/2π (Hz).
    pub frequency_scale_hz: f64,
}

/// Largest accepted condition number of the row-normalized observability
/// matrix of the augmented system: beyond it the Kalman gain is decided by
/// rounding, not by the model (the paper, §3.1).
pub const MAX_OBSERVABILITY_CONDITION: f64 = 1e12;

/// A continuous state-space system (rescaled time unless stated).
#[derive(Clone, Debug)]
pub struct ContinuousSs {
    /// State matrix.
    pub a: DMatrix<f64>,
    /// Input column.
    pub b: DVector<f64>,
    /// Output row.
    pub c: DVector<f64>,
    /// Direct term.
    pub d: f64,
}

/// The controllable companion form of eq. (2) for G(s') = B/A (monic A):
/// first row −a_{na−1} … −a_0, ones on the subdiagonal, B_s = e_1,
/// C_s = the coefficients of the strictly proper numerator, D = b_na when
/// nb = na. Time is rescaled (τ = ω_0 t).
pub fn companion_form(tf: &RationalTf) -> ContinuousSs {
    let n = tf.na();
    let d = if tf.nb() == n { tf.b[n] } else { 0.0 };
    let a = DMatrix::<f64>::from_fn(n, n, |i, j| {
        if i == 0 {
            -tf.a[n - 1 - j]
        } else if i == j + 1 {
            1.0
        } else {
            0.0
        }
    });
    let mut b = DVector::<f64>::zeros(n);
    b[0] = 1.0;
    // strictly proper numerator B − d·A, coefficient of s'^(n−1−j) in C_j
    let c = DVector::<f64>::from_fn(n, |j, _| {
        let p = n - 1 - j;
        tf.b.get(p).copied().unwrap_or(0.0) - d * tf.a[p]
    });
    ContinuousSs { a, b, c, d }
}

/// The augmented system of eq. (4)–(5): x_e = [x_s; F_a], Ḟ_a = w.
/// Returns (A_e, Γ, C_e).
pub fn augmented(ss: &ContinuousSs) -> (DMatrix<f64>, DVector<f64>, DVector<f64>) {
    let n = ss.a.nrows();
    let mut ae = DMatrix::<f64>::zeros(n + 1, n + 1);
    ae.view_mut((0, 0), (n, n)).copy_from(&ss.a);
    ae.view_mut((0, n), (n, 1)).copy_from(&ss.b);
    let mut gamma = DVector::<f64>::zeros(n + 1);
    gamma[n] = 1.0;
    let mut ce = DVector::<f64>::zeros(n + 1);
    ce.rows_mut(0, n).copy_from(&ss.c);
    ce[n] = ss.d;
    (ae, gamma, ce)
}

/// Numerical rank and condition number of the observability matrix
/// [C; C A; …; C A^{n−1}] with each row normalized (so the figure measures
/// the loss of independence, not the growth of ‖A^k‖). Rank tolerance:
/// σ_max · n · ε. An error if the singular values do not converge.
pub fn observability(a: &DMatrix<f64>, c: &DVector<f64>) -> Result<(usize, f64)> {
    let n = a.nrows();
    let mut o = DMatrix::<f64>::zeros(n, n);
    let mut row = c.transpose();
    for i in 0..n {
        let norm = row.norm();
        if norm > 0.0 && norm.is_finite() {
            o.row_mut(i).copy_from(&(&row / norm));
        }
        row = &row * a;
    }
    let sv = linalg::singular_values(&o, "the observability matrix of the augmented system")?;
    let max = sv.iter().copied().fold(0.0, f64::max);
    let tol = max * n as f64 * f64::EPSILON;
    let rank = sv.iter().filter(|s| **s > tol).count();
    Ok((rank, condition_number(&o)))
}

/// Solution of the continuous filter Riccati equation (7).
#[derive(Clone, Debug)]
pub struct CareSolution {
    /// Error covariance P.
    pub p: DMatrix<f64>,
    /// Relative residual ‖A P + P Aᵀ − P Cᵀ C P/R + Q‖_F / ‖P Cᵀ C P/R‖_F.
    pub residual: f64,
    /// Sign-function iterations.
    pub iterations: usize,
}

/// Solve A P + P Aᵀ − P Cᵀ R⁻¹ C P + Q = 0 (eq. (7), steady state) by the
/// matrix sign function of the Hamiltonian H = [[Aᵀ, −CᵀC/R], [−Q, −A]]:
/// with W = sign(H), P solves [W12; W22 + I] P = −[W11 + I; W21] (Byers
/// 1987), refined by up to three Newton (Kleinman) steps. Checks the
/// residual (< 1e-8) and that A − K C is Hurwitz.
pub fn solve_filter_care(a: &DMatrix<f64>, c: &DVector<f64>, q: &DMatrix<f64>, r: f64) -> Result<CareSolution> {
    let g = c * c.transpose() / r;
    let (w, iterations) = sign_function(hamiltonian(a, &g, q))?;
    let p = stable_subspace_solution(&w)?;
    let (p, residual) = newton_refine(a, &g, q, p);
    if !(residual < 1e-8) {
        bail!(
            "continuous Riccati (7) solution rejected: relative residual {residual:.2e} after {iterations} sign \
             iterations (needs < 1e-8)"
        );
    }
    check_hurwitz(a, c, &(&p * c / r))?;
    Ok(CareSolution { p, residual, iterations })
}

/// The Hamiltonian H = [[Aᵀ, −G], [−Q, −A]] of eq. (7), G = Cᵀ C / R.
fn hamiltonian(a: &DMatrix<f64>, g: &DMatrix<f64>, q: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.nrows();
    let mut z = DMatrix::<f64>::zeros(2 * n, 2 * n);
    z.view_mut((0, 0), (n, n)).copy_from(&a.transpose());
    z.view_mut((0, n), (n, n)).copy_from(&(-g));
    z.view_mut((n, 0), (n, n)).copy_from(&(-q));
    z.view_mut((n, n), (n, n)).copy_from(&(-a));
    z
}

/// The matrix sign function W = sign(H) by the scaled Newton iteration
/// Z ← (c Z + Z⁻¹/c)/2, c = |det Z|^(−1/2n), until the relative change is
/// below 1e-13 or stagnates below 1e-6 (at most 100 steps). Returns W and
/// the iterations taken.
fn sign_function(mut z: DMatrix<f64>) -> Result<(DMatrix<f64>, usize)> {
    let n = z.nrows() / 2;
    let mut iterations = 0;
    let mut last_change = f64::INFINITY;
    for it in 1..=100 {
        iterations = it;
        let lu = z.clone().lu();
        let Some(zinv) = lu.try_inverse() else {
            bail!(
                "continuous Riccati: the Hamiltonian is singular (eigenvalue on the imaginary axis); the augmented \
                 system is not detectable"
            );
        };
        // determinant scaling c = |det Z|^(−1/2n), from the LU diagonal
        let lu = z.clone().lu();
        let log_det: f64 = lu.u().diagonal().iter().map(|v| v.abs().ln()).sum();
        let scale = (-log_det / (2 * n) as f64).exp();
        let scale = if scale.is_finite() && scale > 0.0 { scale } else { 1.0 };
        let next = (&z * scale + zinv / scale) * 0.5;
        let change = (&next - &z).norm() / next.norm();
        z = next;
        if !z.iter().all(|v| v.is_finite()) {
            bail!("continuous Riccati: sign iteration diverged (non-finite); the system is ill-conditioned");
        }
        // converged, or stagnating at the rounding floor
        if change < 1e-13 || (change < 1e-6 && change >= last_change) {
            break;
        }
        last_change = change;
    }
    Ok((z, iterations))
}

/// P from W = sign(H) (Byers 1987): the least-squares solution of
/// [W12; W22 + I] P = −[W11 + I; W21], symmetrized.
fn stable_subspace_solution(w: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    let n = w.nrows() / 2;
    let w11 = w.view((0, 0), (n, n)).into_owned();
    let w12 = w.view((0, n), (n, n)).into_owned();
    let w21 = w.view((n, 0), (n, n)).into_owned();
    let w22 = w.view((n, n), (n, n)).into_owned();
    let id = DMatrix::<f64>::identity(n, n);
    let mut lhs = DMatrix::<f64>::zeros(2 * n, n);
    lhs.view_mut((0, 0), (n, n)).copy_from(&w12);
    lhs.view_mut((n, 0), (n, n)).copy_from(&(&w22 + &id));
    let mut rhs = DMatrix::<f64>::zeros(2 * n, n);
    rhs.view_mut((0, 0), (n, n)).copy_from(&(-(&w11 + &id)));
    rhs.view_mut((n, 0), (n, n)).copy_from(&(-&w21));
    let p = linalg::svd(lhs, "continuous Riccati (7): the sign-function subspace")?
        .solve(&rhs, 0.0)
        .map_err(|e| anyhow::anyhow!("continuous Riccati: {e}"))?;
    Ok((&p + p.transpose()) * 0.5)
}

/// Up to three Newton (Kleinman 1968) steps on P, each kept only if it
/// lowers the relative residual ‖A P + P Aᵀ − P G P + Q‖_F / max(‖P G P‖_F,
/// ‖Q‖_F): the sign iteration stagnates at a residual set by the
/// Hamiltonian's conditioning; each step solves the Lyapunov equation
/// Â X + X Âᵀ = −Res, Â = A − P G. Returns P and its relative residual.
fn newton_refine(a: &DMatrix<f64>, g: &DMatrix<f64>, q: &DMatrix<f64>, p: DMatrix<f64>) -> (DMatrix<f64>, f64) {
    let residual_of = |p: &DMatrix<f64>| {
        let pcp = p * g * p;
        let res = a * p + p * a.transpose() - &pcp + q;
        let rel = res.norm() / pcp.norm().max(q.norm()).max(f64::MIN_POSITIVE);
        (res, rel)
    };
    let mut p = p;
    let (mut res, mut residual) = residual_of(&p);
    for _ in 0..3 {
        if residual < 1e-12 {
            break;
        }
        let Some(x) = solve_lyapunov(&(a - &p * g), &(-&res)) else { break };
        let candidate = &p + (&x + x.transpose()) * 0.5;
        let (cres, crel) = residual_of(&candidate);
        if !(crel < residual) {
            break;
        }
        (p, res, residual) = (candidate, cres, crel);
    }
    (p, residual)
}

/// Check that the filter's error dynamics A − K C (gain `k`) are Hurwitz.
fn check_hurwitz(a: &DMatrix<f64>, c: &DVector<f64>, k: &DVector<f64>) -> Result<()> {
    let closed = a - k * c.transpose();
    let max_re = linalg::eigenvalues(&closed, "continuous Riccati (7): A_e − K C_e")?
        .iter()
        .map(|z| z.re)
        .fold(f64::NEG_INFINITY, f64::max);
    if !(max_re < 0.0) {
        bail!(
            "continuous Riccati (7): A_e − K C_e is not Hurwitz (max Re λ = {max_re:.3e}); the augmented system is \
             not detectable"
        );
    }
    Ok(())
}

/// Solve A X + X Aᵀ = C by the Kronecker form (I⊗A + A⊗I) vec X = vec C
/// with nalgebra's LU; `None` when singular. For the small orders of the
/// paper's method (n ≤ 41, so at most 1681 unknowns).
pub fn solve_lyapunov(a: &DMatrix<f64>, c: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = a.nrows();
    let id = DMatrix::<f64>::identity(n, n);
    let k = id.kronecker(a) + a.kronecker(&id);
    let rhs = DVector::from_column_slice(c.as_slice());
    let x = k.lu().solve(&rhs)?;
    Some(DMatrix::from_column_slice(n, n, x.as_slice()))
}

/// Bilinear (Tustin) transform with prewarping: s = k (z − 1)/(z + 1),
/// k = ω_p / tan(ω_p T/2), so that H_d(e^{jω_p T}) = H_c(jω_p) exactly.
/// `omega_p` (rad per time unit) and `t` (time units per sample) must use the
/// same time unit as `ss`; ω_p·T/2 < π/2 (below Nyquist).
pub fn tustin_prewarped(ss: &ContinuousSs, t: f64, omega_p: f64) -> Result<StateSpace> {
    let half = omega_p * t / 2.0;
    if !(half > 0.0 && half < PI / 2.0) {
        bail!("prewarp frequency must lie strictly between 0 and the Nyquist frequency");
    }
    let k = omega_p / half.tan();
    let n = ss.a.nrows();
    let id = DMatrix::<f64>::identity(n, n);
    let ima = &id - &ss.a / k;
    let cond = condition_number(&ima);
    if !(cond < 1e12) {
        bail!("Tustin transform: I − A/k is ill-conditioned (condition number {cond:.2e})");
    }
    let lu = ima.lu();
    let inv = lu.try_inverse().ok_or_else(|| anyhow::anyhow!("Tustin transform: I − A/k is singular"))?;
    let ad = &inv * (&id + &ss.a / k);
    let bd = &inv * &ss.b * (2.0 / k);
    let cd = (ss.c.transpose() * &inv).transpose();
    let dd = ss.d + 0.5 * ss.c.dot(&bd);
    Ok(StateSpace { a: ad, b: bd, c: cd, d: dd })
}

/// The paper's compensator for the fitted `tf`: continuous Kalman filter
/// (eq. (6)–(8)) with Q = q·fs (N²/s; q is the per-sample random-walk
/// variance used by the default method's search, N²/sample) and measurement
/// noise intensity R/fs (R in N²), discretized by Tustin with prewarping at
/// `prewarp_hz`. `diag` receives the condition numbers as they are computed,
/// so a failure still reports what was measured.
///
/// From G(s) = B(s')/A(s'), s' = s/ω_0 ([`crate::fit::rfp`]):
///
/// 1. the controllable companion form of eq. (2)–(3), ẋ_s = A_s x_s + B_s F_a,
///    F_m = C_s x_s (+ D F_a when numerator and denominator orders are equal),
///    in rescaled time τ = ω_0·t (the paper's "frequency rescaling",
///    [`companion_form`]);
/// 2. the augmented system of eq. (4)–(5), x_e = [x_s; F_a], Ḟ_a = w
///    (E[w w] = Q δ, N²/s), measurement noise of intensity R/fs (N²·s)
///    ([`augmented`]);
/// 3. the continuous Riccati equation (7),
///    A_e P + P A_eᵀ − P C_eᵀ R⁻¹ C_e P + Γ Q Γᵀ = 0, solved by the matrix sign
///    function of the Hamiltonian (Roberts 1971; Byers 1987, determinant
///    scaling) refined by Newton (Kleinman 1968) steps, with its residual and
///    closed-loop stability checked ([`solve_filter_care`]);
/// 4. the gain (8), K = P C_eᵀ R⁻¹, and the compensator (6),
///    x̂̇ = (A_e − K C_e) x̂ + K F_m, F̂_a = C_0 x̂;
/// 5. the bilinear (Tustin) transform with frequency prewarping at f_p, exact
///    at f_p: H_d(e^{j2πf_p/fs}) = H_c(j2πf_p) ([`tustin_prewarped`]).
pub fn design(
    tf: &RationalTf,
    fs_hz: f64,
    q: f64,
    r: f64,
    prewarp_hz: f64,
    diag: &mut PaperDiagnostics,
) -> Result<KalmanDesign> {
    if !(r > 0.0 && r.is_finite() && q > 0.0 && q.is_finite()) {
        bail!("Q and R must be positive and finite (q = {q}, R = {r})");
    }
    let w0 = tf.omega_scale;
    diag.frequency_scale_hz = w0 / (2.0 * PI);
    diag.prewarp_hz = prewarp_hz;
    let ss = companion_form(tf);
    diag.companion_condition = condition_number(&ss.a);
    let (ae, gamma, ce) = augmented(&ss);
    let (rank, ocond) = observability(&ae, &ce)?;
    diag.observability_rank = rank;
    diag.observability_dim = ae.nrows();
    diag.observability_condition = ocond;
    if rank < ae.nrows() {
        bail!(
            "augmented system (eq. (4)) not observable in floating point: observability rank {rank} of {} (condition {ocond:.2e}), companion matrix condition {:.2e}; lower the orders or fit narrower bands",
            ae.nrows(),
            diag.companion_condition
        );
    }
    // Rescaled time τ = ω_0 t: Q' = Q/ω_0, R' = (R/fs)·ω_0.
    let q_c = q * fs_hz / w0;
    let r_c = r / fs_hz * w0;
    let qm = &gamma * gamma.transpose() * q_c;
    let care = solve_filter_care(&ae, &ce, &qm, r_c).map_err(|e| {
        e.context(format!(
            "observability rank {rank} of {}, condition {ocond:.2e}; companion condition {:.2e}",
            ae.nrows(),
            diag.companion_condition
        ))
    })?;
    diag.care_residual = care.residual;
    let k = &care.p * &ce / r_c;
    let n = ae.nrows();
    let mut c0 = DVector::<f64>::zeros(n);
    c0[n - 1] = 1.0;
    let comp = ContinuousSs { a: &ae - &k * ce.transpose(), b: k.clone(), c: c0, d: 0.0 };
    let disc = tustin_prewarped(&comp, w0 / fs_hz, 2.0 * PI * prewarp_hz / w0)?;
    let radius = disc.spectral_radius()?;
    if !(radius < 1.0) {
        bail!("discretized compensator is not stable (spectral radius {radius:.9})");
    }
    Ok(KalmanDesign {
        compensator: disc,
        kalman_gain: k,
        dare_residual: care.residual,
        closed_loop_radius: radius,
        lag: 0,
        q,
        r,
        force_shape: None,
    })
}

/// Continuous response C (jωI − A)⁻¹ B + D of `ss` at ω (rad per time unit).
pub fn continuous_response(ss: &ContinuousSs, omega: f64) -> num_complex::Complex64 {
    crate::numeric::lti::resolvent_response(&ss.a, &ss.b, &ss.c, ss.d, num_complex::Complex64::new(0.0, omega))
}
