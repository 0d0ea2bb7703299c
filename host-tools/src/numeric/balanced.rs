//! Model reduction of a stable discrete system by balancing (Moore 1981;
//! square-root form of Tombs & Postlethwaite 1987; singular perturbation of
//! Liu & Anderson 1989): the states that are both hard to reach from the
//! inputs and hard to see in the outputs are removed.
//!
//! With the Gramians P = A P Aᵀ + B Bᵀ and Q = Aᵀ Q A + Cᵀ C, the Hankel
//! singular values σ_k are the square roots of the eigenvalues of P Q. Both
//! reductions to order r keep a stable system and bound the error of the
//! transfer matrix on the unit circle:
//!
//! ```text
//! max_ω ‖H(e^{jω}) − H_r(e^{jω})‖₂ ≤ 2 Σ_{k>r} σ_k
//! ```
//!
//! Truncation is exact at z → ∞ (high frequency); the singular perturbation
//! is exact at z = 1 (DC), which is where a force measurement must not be
//! biased.

use anyhow::{bail, Result};
use nalgebra::DMatrix;

use super::lti::{stein_refined, MimoStateSpace};

/// A system in balanced coordinates (states ordered by their Hankel
/// singular value, largest first), ready to be reduced to any order.
#[derive(Clone, Debug)]
pub struct Balanced {
    /// The balanced system (only the states with σ above the numerical
    /// floor: the others are removed exactly, see [`balance`]).
    pub system: MimoStateSpace,
    /// Hankel singular values σ_1 ≥ σ_2 ≥ … of the kept states.
    pub hankel: Vec<f64>,
    /// States of the system given to [`balance`].
    pub full_order: usize,
    /// The leading states whose balanced Gramians are diag(σ) to
    /// [`BALANCED_TOL`]·σ₁: reductions keep at most these.
    pub trusted: usize,
    /// The largest error of the balanced Gramians against diag(σ) over all
    /// kept states, relative to σ₁.
    pub worst_off_diag: f64,
}

/// Relative size below which a Hankel singular value is numerical noise:
/// its state is dropped before balancing (truncating it changes H by less
/// than 2·n·`HANKEL_FLOOR`·σ_1).
pub const HANKEL_FLOOR: f64 = 1e-11;

/// The symmetric positive semidefinite `m` as Z Zᵀ (Z = V·√Λ, negative
/// eigenvalues of rounding set to zero).
fn factor(m: &DMatrix<f64>) -> DMatrix<f64> {
    let sym = (m + m.transpose()) * 0.5;
    let eig = sym.symmetric_eigen();
    let mut z = eig.eigenvectors;
    for (k, l) in eig.eigenvalues.iter().enumerate() {
        let s = l.max(0.0).sqrt();
        z.column_mut(k).scale_mut(s);
    }
    z
}

/// The balanced realization of the stable system `ss` (square-root method):
/// Gramians by Smith doubling, P = Z_c Z_cᵀ, Q = Z_o Z_oᵀ, the SVD
/// Z_oᵀ Z_c = U Σ Vᵀ, and T = Z_c V Σ^{−1/2}, T⁻¹ = Σ^{−1/2} Uᵀ Z_oᵀ over the
/// σ above [`HANKEL_FLOOR`]·σ_1; where not every state balances in the
/// given coordinates, also after [`scale_states`], and the one with more
/// trusted states is kept. The Gramians are
/// solved with iterative refinement ([`stein_refined`]). The balanced
/// system's Gramians are checked against diag(σ) state by state: the
/// leading states within [`BALANCED_TOL`] are [`Balanced::trusted`] (the
/// columns of the transform for the smallest σ carry the rounding of the
/// Gramians, amplified by σ^{−1/2}). An error when A is not stable, the
/// Gramians do not converge, or not even the first state is balanced.
pub fn balance(ss: &MimoStateSpace) -> Result<Balanced> {
    let given = balance_as_given(ss);
    if given.as_ref().is_ok_and(|b| b.trusted == b.hankel.len()) {
        return given;
    }
    let Some(scaled) = scale_states(ss).map(|s| balance_as_given(&s)) else { return given };
    match (given, scaled) {
        (Ok(g), Ok(s)) => Ok(if s.trusted > g.trusted { s } else { g }),
        (Ok(g), Err(_)) => Ok(g),
        (Err(_), scaled) => scaled,
    }
}

/// [`balance`] in the coordinates of `ss`, without [`scale_states`].
fn balance_as_given(ss: &MimoStateSpace) -> Result<Balanced> {
    let n = ss.a.nrows();
    if n == 0 {
        return Ok(Balanced { system: ss.clone(), hankel: Vec::new(), full_order: 0, trusted: 0, worst_off_diag: 0.0 });
    }
    let Some(p) = stein_refined(&ss.a, &ss.b * ss.b.transpose()) else {
        bail!("balanced reduction: the controllability Gramian does not converge (is the {n}-state system stable?)")
    };
    let at = ss.a.transpose();
    let Some(q) = stein_refined(&at, ss.c.transpose() * &ss.c) else {
        bail!("balanced reduction: the observability Gramian does not converge (is the {n}-state system stable?)")
    };
    let (zc, zo) = (factor(&p), factor(&q));
    let product = zo.transpose() * &zc;
    let svd = crate::fit::linalg::checked_svd(product.clone().svd(true, true), &product, "balanced reduction: Zoᵀ·Zc")?;
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else { bail!("balanced reduction: the SVD failed") };
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|a, b| svd.singular_values[*b].total_cmp(&svd.singular_values[*a]));
    let s1 = order.first().map_or(0.0, |k| svd.singular_values[*k]);
    let kept: Vec<usize> = order.into_iter().filter(|k| svd.singular_values[*k] > HANKEL_FLOOR * s1).collect();
    let r = kept.len();
    let hankel: Vec<f64> = kept.iter().map(|k| svd.singular_values[*k]).collect();
    let mut t = DMatrix::zeros(n, r);
    let mut t_inv = DMatrix::zeros(r, n);
    for (col, &k) in kept.iter().enumerate() {
        let w = hankel[col].sqrt().recip();
        t.set_column(col, &((&zc * v_t.row(k).transpose()) * w));
        t_inv.set_row(col, &((u.column(k).transpose() * zo.transpose()) * w));
    }
    let system = MimoStateSpace { a: &t_inv * &ss.a * &t, b: &t_inv * &ss.b, c: &ss.c * &t, d: ss.d.clone() };
    // Check: the balanced Gramians are diag(σ), state by state: the error
    // of state k is the largest of row and column k within the leading
    // k + 1 states.
    let state_errors = |g: Option<DMatrix<f64>>| -> Vec<f64> {
        let Some(g) = g else { return vec![f64::INFINITY; r] };
        (0..r)
            .map(|k| {
                (0..=k)
                    .map(|j| {
                        let want = if j == k { hankel[k] } else { 0.0 };
                        (g[(k, j)] - want).abs().max((g[(j, k)] - want).abs()) / s1
                    })
                    .fold(0.0, f64::max)
            })
            .collect()
    };
    let ep = state_errors(stein_refined(&system.a, &system.b * system.b.transpose()));
    let eq = state_errors(stein_refined(&system.a.transpose(), system.c.transpose() * &system.c));
    let trusted = (0..r).take_while(|&k| ep[k].max(eq[k]) <= BALANCED_TOL).count();
    if trusted == 0 {
        bail!(
            "balanced reduction: the balanced Gramians of the {n}-state system are off diag(σ) by {:.1e} of σ₁ in \
             the first state; the balancing transform is too ill-conditioned",
            ep[0].max(eq[0])
        );
    }
    let worst = (0..r).map(|k| ep[k].max(eq[k])).fold(0.0, f64::max);
    Ok(Balanced { system, hankel, full_order: n, trusted, worst_off_diag: worst })
}

/// Largest error, relative to σ₁, of the balanced Gramians against diag(σ)
/// within the leading states [`Balanced::reduce`] keeps.
pub const BALANCED_TOL: f64 = 1e-6;

/// `ss` in coordinates x' = D⁻¹x, D = diag((P_ii/Q_ii)^¼), where its
/// Gramians P and Q have equal diagonals; `None` when they do not converge
/// or every P_ii/Q_ii is within a factor 100 of every other.
///
/// A modal realization of a Kalman filter can hold states whose P_ii/Q_ii
/// spans 10¹³: the Gramians' small eigenvalues are then lost to rounding
/// (each only known to ε·‖P‖), and so are the balancing transform's
/// columns that carry them. The similarity changes no transfer function.
fn scale_states(ss: &MimoStateSpace) -> Option<MimoStateSpace> {
    let p = stein_refined(&ss.a, &ss.b * ss.b.transpose())?;
    let q = stein_refined(&ss.a.transpose(), ss.c.transpose() * &ss.c)?;
    let n = ss.a.nrows();
    let d: Vec<f64> = (0..n)
        .map(|i| {
            let (pi, qi) = (p[(i, i)], q[(i, i)]);
            if pi > 0.0 && qi > 0.0 && (pi / qi).is_finite() {
                (pi / qi).powf(0.25)
            } else {
                1.0
            }
        })
        .collect();
    let (lo, hi) = d.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), v| (lo.min(*v), hi.max(*v)));
    if hi / lo < 10f64.sqrt() {
        return None;
    }
    let a = DMatrix::from_fn(n, n, |i, j| ss.a[(i, j)] * d[j] / d[i]);
    let b = DMatrix::from_fn(n, ss.b.ncols(), |i, j| ss.b[(i, j)] / d[i]);
    let c = DMatrix::from_fn(ss.c.nrows(), n, |i, j| ss.c[(i, j)] * d[j]);
    Some(MimoStateSpace { a, b, c, d: ss.d.clone() })
}

/// How the removed states are removed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Reduction {
    /// Balanced truncation: exact at high frequency.
    Truncation,
    /// Balanced singular perturbation: exact at DC.
    SingularPerturbation,
}

impl Balanced {
    /// The bound 2 Σ_{k>r} σ_k on the largest error of the transfer matrix
    /// (its 2-norm, on the unit circle) of the order-`r` reduction. It does
    /// not count the states already dropped below [`HANKEL_FLOOR`].
    pub fn error_bound(&self, r: usize) -> f64 {
        2.0 * self.hankel.iter().skip(r).sum::<f64>()
    }

    /// The order-`r` reduction (r ≥ the kept order: the balanced system; an
    /// error for r above [`Self::trusted`]).
    /// Singular perturbation: with the balanced system split after state r,
    /// A_r = A₁₁ + A₁₂ (I − A₂₂)⁻¹ A₂₁, B_r = B₁ + A₁₂ (I − A₂₂)⁻¹ B₂,
    /// C_r = C₁ + C₂ (I − A₂₂)⁻¹ A₂₁, D_r = D + C₂ (I − A₂₂)⁻¹ B₂.
    pub fn reduce(&self, r: usize, how: Reduction) -> Result<MimoStateSpace> {
        let s = &self.system;
        let n = s.a.nrows();
        if r >= n {
            return Ok(s.clone());
        }
        if r > self.trusted {
            bail!(
                "balanced reduction: only the leading {} of {n} states are balanced to {BALANCED_TOL:.0e} of σ₁ \
                 (worst {:.1e}); {r} states would keep ill-conditioned ones",
                self.trusted,
                self.worst_off_diag
            );
        }
        let a11 = s.a.view((0, 0), (r, r)).into_owned();
        let b1 = s.b.rows(0, r).into_owned();
        let c1 = s.c.columns(0, r).into_owned();
        if how == Reduction::Truncation {
            return Ok(MimoStateSpace { a: a11, b: b1, c: c1, d: s.d.clone() });
        }
        let m = n - r;
        let a12 = s.a.view((0, r), (r, m));
        let a21 = s.a.view((r, 0), (m, r));
        let a22 = s.a.view((r, r), (m, m));
        let b2 = s.b.rows(r, m);
        let c2 = s.c.columns(r, m);
        let lu = (DMatrix::identity(m, m) - a22).lu();
        let (Some(x_a), Some(x_b)) = (lu.solve(&a21.into_owned()), lu.solve(&b2.into_owned())) else {
            bail!("balanced reduction: I − A₂₂ is singular (a removed state has a pole at z = 1)")
        };
        Ok(MimoStateSpace { a: a11 + a12 * &x_a, b: b1 + a12 * &x_b, c: c1 + c2 * &x_a, d: &s.d + c2 * &x_b })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DVector;

    /// A 3-in, 3-out system of `pairs` lightly damped modes at fs = 1 and
    /// a few real poles, with residues of decreasing size.
    fn system(pairs: usize) -> MimoStateSpace {
        let n = 2 * pairs + 2;
        let mut a = DMatrix::zeros(n, n);
        let mut b = DMatrix::zeros(n, 3);
        let mut c = DMatrix::zeros(3, n);
        for k in 0..pairs {
            let (rho, th) = (0.995 - 0.02 * k as f64, 0.05 + 0.21 * k as f64);
            let (re, im) = (rho * th.cos(), rho * th.sin());
            let i = 2 * k;
            a[(i, i)] = re;
            a[(i, i + 1)] = im;
            a[(i + 1, i)] = -im;
            a[(i + 1, i + 1)] = re;
            let w = 0.5f64.powi(k as i32);
            for j in 0..3 {
                b[(i, j)] = w * (1.0 + 0.3 * j as f64);
                b[(i + 1, j)] = w * (0.2 * k as f64 - 0.1 * j as f64);
                c[(j, i)] = 1.0 + 0.1 * (j * k) as f64;
                c[(j, i + 1)] = 0.3 - 0.2 * j as f64;
            }
        }
        for (o, p) in [(n - 2, 0.9), (n - 1, 0.3)] {
            a[(o, o)] = p;
            for j in 0..3 {
                b[(o, j)] = 0.1 * (j + 1) as f64;
                c[(j, o)] = 0.05;
            }
        }
        let d = DMatrix::from_fn(3, 3, |i, j| if i == j { 1.0 } else { 0.1 });
        MimoStateSpace { a, b, c, d }
    }

    fn worst_error(x: &MimoStateSpace, y: &MimoStateSpace) -> f64 {
        let f: Vec<f64> = (0..=400).map(|k| 0.5 * k as f64 / 400.0).collect();
        let (hx, hy) = (x.freq_responses(&f, 1.0), y.freq_responses(&f, 1.0));
        hx.iter().zip(&hy).map(|(a, b)| (a - b).svd(false, false).singular_values[0]).fold(0.0, f64::max)
    }

    #[test]
    fn balanced_system_equals_the_original_and_each_reduction_obeys_the_hankel_bound() {
        let ss = system(5);
        let bal = balance(&ss).unwrap();
        assert_eq!(bal.full_order, 12);
        assert!(bal.hankel.windows(2).all(|w| w[0] >= w[1]));
        assert!(worst_error(&ss, &bal.system) < 1e-9 * bal.hankel[0]);
        for r in [2, 4, 6, 8, 10] {
            for how in [Reduction::Truncation, Reduction::SingularPerturbation] {
                let red = bal.reduce(r, how).unwrap();
                assert_eq!(red.a.nrows(), r);
                let e = worst_error(&ss, &red);
                let bound = bal.error_bound(r);
                assert!(e <= bound * (1.0 + 1e-9), "r {r} {how:?}: {e:e} > bound {bound:e}");
                // The bound is not vacuous: the error is a fair part of it.
                assert!(e >= 0.05 * bound, "r {r} {how:?}: {e:e} against bound {bound:e}");
                assert!(red.a.clone().complex_eigenvalues().iter().all(|z| z.norm() < 1.0), "r {r} {how:?}: unstable");
            }
        }
    }

    #[test]
    fn singular_perturbation_keeps_the_dc_gain_and_truncation_does_not() {
        let ss = system(4);
        let bal = balance(&ss).unwrap();
        let dc = |s: &MimoStateSpace| -> DMatrix<f64> {
            let n = s.a.nrows();
            let x = (DMatrix::identity(n, n) - &s.a).lu().solve(&s.b).unwrap();
            &s.c * x + &s.d
        };
        let want = dc(&ss);
        let spa = dc(&bal.reduce(3, Reduction::SingularPerturbation).unwrap());
        let trunc = dc(&bal.reduce(3, Reduction::Truncation).unwrap());
        assert!((&spa - &want).amax() < 1e-9 * want.amax(), "{spa} vs {want}");
        // Negative control: truncation misses the DC gain.
        assert!((&trunc - &want).amax() > 1e-3 * want.amax(), "{trunc} vs {want}");
    }

    #[test]
    fn a_state_nobody_sees_is_removed_exactly() {
        let mut ss = system(3);
        // One state fed from the inputs but never read: σ = 0.
        let n = ss.a.nrows();
        let grow = |m: &DMatrix<f64>, r: usize, c: usize| m.clone().resize(r, c, 0.0);
        ss.a = grow(&ss.a, n + 1, n + 1);
        ss.a[(n, n)] = 0.7;
        ss.b = grow(&ss.b, n + 1, 3);
        ss.b.set_row(n, &DVector::from_vec(vec![1.0, 2.0, 3.0]).transpose());
        ss.c = grow(&ss.c, 3, n + 1);
        let bal = balance(&ss).unwrap();
        assert_eq!(bal.system.a.nrows(), n, "σ {:?}", bal.hankel);
        assert!(worst_error(&ss, &bal.system) < 1e-9);
    }

    /// `ss` in coordinates x' = D⁻¹x with D = diag(10^{−4..4}).
    fn badly_scaled(ss: &MimoStateSpace) -> MimoStateSpace {
        let n = ss.a.nrows();
        let d: Vec<f64> = (0..n).map(|i| 10f64.powf(-4.0 + 8.0 * i as f64 / (n - 1) as f64)).collect();
        MimoStateSpace {
            a: DMatrix::from_fn(n, n, |i, j| ss.a[(i, j)] * d[j] / d[i]),
            b: DMatrix::from_fn(n, 3, |i, j| ss.b[(i, j)] / d[i]),
            c: DMatrix::from_fn(3, n, |i, j| ss.c[(i, j)] * d[j]),
            d: ss.d.clone(),
        }
    }

    /// A realization whose states are scaled over eight decades balances
    /// as well as the original once its states are scaled back
    /// ([`scale_states`]): the same Hankel singular values, every state
    /// trusted, the balanced Gramians diag(σ) to 10⁻⁹ of σ₁ (measured
    /// 1.4·10⁻¹³). Negative control: balanced as given, they are off by
    /// 1.4·10⁻⁶ already in the first state, and the balancing is refused.
    #[test]
    fn a_badly_scaled_realization_is_scaled_before_balancing() {
        let ss = system(5);
        let reference = balance(&ss).unwrap();
        let skewed = badly_scaled(&ss);
        let bal = balance(&skewed).unwrap();
        assert_eq!(bal.trusted, bal.hankel.len());
        assert_eq!(bal.hankel.len(), reference.hankel.len());
        for (a, b) in bal.hankel.iter().zip(&reference.hankel) {
            assert!((a - b).abs() <= 1e-9 * reference.hankel[0], "{a:e} against {b:e}");
        }
        assert!(worst_error(&ss, &bal.reduce(6, Reduction::SingularPerturbation).unwrap()) <= bal.error_bound(6));
        assert!(bal.worst_off_diag < 1e-9, "scaled: {:.1e}", bal.worst_off_diag);
        let err = balance_as_given(&skewed).map(|b| b.worst_off_diag).unwrap_err();
        assert!(format!("{err:#}").contains("too ill-conditioned"), "control: {err:#}");
    }

    /// A reduction keeps at most the trusted states.
    #[test]
    fn a_reduction_beyond_the_trusted_states_is_refused() {
        let mut bal = balance(&system(5)).unwrap();
        bal.trusted = 4;
        assert!(bal.reduce(4, Reduction::Truncation).is_ok());
        let err = bal.reduce(5, Reduction::Truncation).unwrap_err().to_string();
        assert!(err.contains("only the leading 4 of 12 states"), "{err}");
        // The full system is exact, trusted or not.
        assert!(bal.reduce(12, Reduction::Truncation).is_ok());
    }

    #[test]
    fn an_unstable_system_is_refused() {
        let mut ss = system(2);
        ss.a[(0, 0)] = 1.2;
        ss.a[(1, 1)] = 1.2;
        assert!(balance(&ss).unwrap_err().to_string().contains("does not converge"));
    }
}
