//! Discrete linear time-invariant systems in state-space form (f64): the
//! compensators the design produces and the realizations check.

use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;

/// c (pI − A)⁻¹ b + d at the complex point p (z for a discrete system, jω
/// for a continuous one), by an LU solve; NaN if pI − A is singular.
pub fn resolvent_response(a: &DMatrix<f64>, b: &DVector<f64>, c: &DVector<f64>, d: f64, p: Complex64) -> Complex64 {
    let n = a.nrows();
    let m = DMatrix::<Complex64>::from_fn(n, n, |i, j| {
        let v = Complex64::new(-a[(i, j)], 0.0);
        if i == j {
            v + p
        } else {
            v
        }
    });
    let rhs = DVector::<Complex64>::from_iterator(n, b.iter().map(|v| Complex64::new(*v, 0.0)));
    match m.lu().solve(&rhs) {
        Some(x) => x.iter().zip(c.iter()).map(|(x, c)| x * c).sum::<Complex64>() + d,
        None => Complex64::new(f64::NAN, f64::NAN),
    }
}

/// Solve M X = RHS in place for an upper Hessenberg M (n×n, row-major) and
/// `r` right-hand sides (X: n×r, row-major): Gaussian elimination with
/// partial pivoting, where only the subdiagonal needs eliminating, so each
/// column's pivot is between two rows. `false` if a pivot is zero or not
/// finite (M singular).
fn solve_hessenberg(m: &mut [Complex64], x: &mut [Complex64], n: usize, r: usize) -> bool {
    for k in 0..n.saturating_sub(1) {
        let (top, below) = (k * n, (k + 1) * n);
        // |re| + |im|: no hypot per comparison, and no underflow to 0.
        if m[below + k].l1_norm() > m[top + k].l1_norm() {
            for j in k..n {
                m.swap(top + j, below + j);
            }
            for c in 0..r {
                x.swap(k * r + c, (k + 1) * r + c);
            }
        }
        let pivot = m[top + k];
        if !(pivot.l1_norm() > 0.0) {
            return false;
        }
        let l = m[below + k] / pivot;
        if l != Complex64::new(0.0, 0.0) {
            for j in k..n {
                let v = m[top + j];
                m[below + j] -= l * v;
            }
            for c in 0..r {
                let v = x[k * r + c];
                x[(k + 1) * r + c] -= l * v;
            }
        }
    }
    for i in (0..n).rev() {
        let p = m[i * n + i];
        if !(p.l1_norm() > 0.0 && p.is_finite()) {
            return false;
        }
        for c in 0..r {
            let mut s = x[i * r + c];
            for j in i + 1..n {
                s -= m[i * n + j] * x[j * r + c];
            }
            x[i * r + c] = s / p;
        }
    }
    true
}

/// zI − H (row-major, n×n) for an upper Hessenberg H, into `m`.
fn shifted_hessenberg(h: &DMatrix<f64>, z: Complex64, m: &mut [Complex64]) {
    let n = h.nrows();
    for i in 0..n {
        // Below the subdiagonal H is zero (left so by `unpack`).
        for j in i.saturating_sub(1)..n {
            m[i * n + j] = Complex64::new(-h[(i, j)], 0.0);
        }
        for j in 0..i.saturating_sub(1) {
            m[i * n + j] = Complex64::new(0.0, 0.0);
        }
        m[i * n + i] += z;
    }
}

/// The left resolvent R (zI − A)⁻¹ (r×n) of the rows R (r×n) at
/// z = e^{j·2π·f/fs} for every frequency of `f_hz` (Hz): with Aᵀ = Q H Qᵀ
/// reduced once to Hessenberg form, (zI − A)⁻ᵀ Rᵀ = Q (zI − H)⁻¹ Qᵀ Rᵀ, one
/// O(n²) elimination per point for all r rows (as
/// [`StateSpace::freq_responses`]). NaN where zI − A is singular.
pub fn left_resolvent(a: &DMatrix<f64>, rows: &DMatrix<f64>, f_hz: &[f64], fs_hz: f64) -> Vec<DMatrix<Complex64>> {
    let (n, r) = (a.nrows(), rows.nrows());
    let (q, h) = a.transpose().hessenberg().unpack();
    // Qᵀ Rᵀ (n×r), the right-hand sides.
    let qr = q.transpose() * rows.transpose();
    let mut m = vec![Complex64::new(0.0, 0.0); n * n];
    let mut x = vec![Complex64::new(0.0, 0.0); n * r];
    f_hz.iter()
        .map(|f| {
            let z = Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f / fs_hz);
            shifted_hessenberg(&h, z, &mut m);
            for i in 0..n {
                for c in 0..r {
                    x[i * r + c] = Complex64::new(qr[(i, c)], 0.0);
                }
            }
            if !solve_hessenberg(&mut m, &mut x, n, r) {
                return DMatrix::from_element(r, n, Complex64::new(f64::NAN, f64::NAN));
            }
            // Row c of the result is (Q x_c)ᵀ.
            DMatrix::from_fn(r, n, |c, i| (0..n).map(|k| x[k * r + c] * q[(i, k)]).sum())
        })
        .collect()
}

/// A discrete SISO state-space system (f64).
#[derive(Clone, Debug)]
pub struct StateSpace {
    /// State matrix.
    pub a: DMatrix<f64>,
    /// Input column.
    pub b: DVector<f64>,
    /// Output row.
    pub c: DVector<f64>,
    /// Direct term.
    pub d: f64,
}

impl StateSpace {
    /// H(z) = c (zI − A)⁻¹ b + d at z = e^{j·2π·f/fs}.
    pub fn freq_response(&self, f_hz: f64, fs_hz: f64) -> Complex64 {
        let z = Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f_hz / fs_hz);
        resolvent_response(&self.a, &self.b, &self.c, self.d, z)
    }

    /// H(z) at every frequency of `f_hz` (Hz), as [`Self::freq_response`]
    /// but with A reduced once to upper Hessenberg form H = Qᵀ A Q
    /// (Householder, backward stable; Laub, "Efficient multivariable
    /// frequency response computations", IEEE TAC 26(2), 1981): then
    /// c (zI − A)⁻¹ b = (Qᵀc)ᵀ (zI − H)⁻¹ (Qᵀb), and each point is one
    /// O(n²) elimination with partial pivoting between neighbouring rows
    /// instead of an O(n³) LU. NaN where zI − A is singular.
    pub fn freq_responses(&self, f_hz: &[f64], fs_hz: f64) -> Vec<Complex64> {
        let n = self.a.nrows();
        if n == 0 {
            return vec![Complex64::new(self.d, 0.0); f_hz.len()];
        }
        let (q, h) = self.a.clone().hessenberg().unpack();
        let bt = q.transpose() * &self.b;
        let ct = q.transpose() * &self.c;
        let mut m = vec![Complex64::new(0.0, 0.0); n * n];
        let mut x = vec![Complex64::new(0.0, 0.0); n];
        f_hz.iter()
            .map(|f| {
                let z = Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f / fs_hz);
                shifted_hessenberg(&h, z, &mut m);
                for i in 0..n {
                    x[i] = Complex64::new(bt[i], 0.0);
                }
                match solve_hessenberg(&mut m, &mut x, n, 1) {
                    true => x.iter().zip(ct.iter()).map(|(x, c)| x * c).sum::<Complex64>() + self.d,
                    false => Complex64::new(f64::NAN, f64::NAN),
                }
            })
            .collect()
    }

    /// Simulate in f64: y\[k\] = c x + d u, x ← A x + b u.
    pub fn simulate(&self, input: &[f64]) -> Vec<f64> {
        let mut x = DVector::<f64>::zeros(self.a.nrows());
        input
            .iter()
            .map(|&u| {
                let y = self.c.dot(&x) + self.d * u;
                x = &self.a * &x + &self.b * u;
                y
            })
            .collect()
    }

    /// White-noise gain sqrt(Σ_k h_k²) = sqrt(d² + cᵀ W c), with the
    /// controllability Gramian W = A W Aᵀ + b bᵀ solved by Smith doubling
    /// (W ← W + A_k W A_kᵀ, A_k ← A_k²): exact, where a frequency grid
    /// undersamples the few-Hz-wide peaks of poles near z = 1. `None` when A
    /// is not stable or the doubling does not converge in 64 steps.
    pub fn white_noise_gain(&self) -> Option<f64> {
        let mut ak = self.a.clone();
        let mut w = &self.b * self.b.transpose();
        for _ in 0..64 {
            let step = &ak * &w * ak.transpose();
            // The Frobenius norm of a diverging Gramian overflows before its
            // entries do, and `x <= ∞` would end the doubling.
            let scale = w.norm();
            if !scale.is_finite() {
                return None;
            }
            let done = step.norm() <= 1e-15 * scale;
            w += step;
            if !w.as_slice().iter().all(|v| v.is_finite()) {
                return None;
            }
            if done {
                let h2 = self.d * self.d + self.c.dot(&(&w * &self.c));
                return (h2 >= 0.0).then(|| h2.sqrt());
            }
            ak = &ak * &ak;
        }
        None
    }

    /// Largest eigenvalue modulus of A; an error if the eigenvalue
    /// iteration does not converge within its limit
    /// ([`crate::fit::linalg::eigenvalues`]).
    pub fn spectral_radius(&self) -> anyhow::Result<f64> {
        let eig = crate::fit::linalg::eigenvalues(&self.a, "the compensator's state matrix A")?;
        Ok(eig.iter().map(|z| z.norm()).fold(0.0, f64::max))
    }
}

/// A discrete state-space system with several inputs and outputs (f64): the
/// 3x3 compensator of the matrix design.
#[derive(Clone, Debug)]
pub struct MimoStateSpace {
    /// State matrix (n × n).
    pub a: DMatrix<f64>,
    /// Input matrix (n × inputs).
    pub b: DMatrix<f64>,
    /// Output matrix (outputs × n).
    pub c: DMatrix<f64>,
    /// Direct term (outputs × inputs).
    pub d: DMatrix<f64>,
}

impl MimoStateSpace {
    /// H(z) = C (zI − A)⁻¹ B + D (outputs × inputs) at z = e^{j·2π·f/fs}
    /// for every frequency of `f_hz` (Hz): A reduced once to Hessenberg
    /// form, as [`StateSpace::freq_responses`], one elimination per point
    /// for all input columns.
    /// NaN where zI − A is singular.
    pub fn freq_responses(&self, f_hz: &[f64], fs_hz: f64) -> Vec<DMatrix<Complex64>> {
        let (n, p, m) = (self.a.nrows(), self.c.nrows(), self.b.ncols());
        let dc = self.d.map(|v| Complex64::new(v, 0.0));
        if n == 0 {
            return vec![dc; f_hz.len()];
        }
        let (q, h) = self.a.clone().hessenberg().unpack();
        let bt = q.transpose() * &self.b;
        let ct = &self.c * &q;
        let mut mat = vec![Complex64::new(0.0, 0.0); n * n];
        let mut x = vec![Complex64::new(0.0, 0.0); n * m];
        f_hz.iter()
            .map(|f| {
                let z = Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f / fs_hz);
                shifted_hessenberg(&h, z, &mut mat);
                for r in 0..n {
                    for j in 0..m {
                        x[r * m + j] = Complex64::new(bt[(r, j)], 0.0);
                    }
                }
                if !solve_hessenberg(&mut mat, &mut x, n, m) {
                    return DMatrix::from_element(p, m, Complex64::new(f64::NAN, f64::NAN));
                }
                let mut out = dc.clone();
                for j in 0..m {
                    for i in 0..p {
                        out[(i, j)] += (0..n).map(|r| x[r * m + j] * ct[(i, r)]).sum::<Complex64>();
                    }
                }
                out
            })
            .collect()
    }

    /// Simulate in f64: y[k] = C x + D u, x ← A x + B u.
    pub fn simulate(&self, input: &[DVector<f64>]) -> Vec<DVector<f64>> {
        let mut x = DVector::<f64>::zeros(self.a.nrows());
        input
            .iter()
            .map(|u| {
                let y = &self.c * &x + &self.d * u;
                x = &self.a * &x + &self.b * u;
                y
            })
            .collect()
    }

    /// White-noise gain of each output for unit white noise on every input:
    /// sqrt((D Dᵀ + C W Cᵀ)_ii), with the controllability Gramian
    /// W = A W Aᵀ + B Bᵀ by Smith doubling. `None` when A is not stable or
    /// the doubling does not converge in 64 steps.
    pub fn white_noise_gains(&self) -> Option<Vec<f64>> {
        let w = stein_smith(&self.a, &self.b * self.b.transpose())?;
        let g = &self.d * self.d.transpose() + &self.c * &w * self.c.transpose();
        (0..g.nrows()).map(|i| (g[(i, i)] >= 0.0).then(|| g[(i, i)].sqrt())).collect()
    }
}

/// [`stein_smith`] with iterative refinement: the residual
/// R = A X Aᵀ + W − X is solved for again (X ← X + E, E = A E Aᵀ + R) while
/// it shrinks, at most three times.
///
/// The doubling's rounding grows with ‖A‖²: for a non-normal A (a Kalman
/// filter's modal realization, ‖A‖ in the hundreds) X can be off by 10⁻⁸
/// of ‖X‖, where the residual itself is computed to ε·‖A‖²·‖X‖.
pub fn stein_refined(a: &DMatrix<f64>, w: DMatrix<f64>) -> Option<DMatrix<f64>> {
    let residual = |x: &DMatrix<f64>| a * x * a.transpose() + &w - x;
    let mut x = stein_smith(a, w.clone())?;
    let mut r = residual(&x);
    for _ in 0..3 {
        if r.amax() <= 1e-15 * x.amax() {
            break;
        }
        let refined = &x + stein_smith(a, r.clone())?;
        let r_new = residual(&refined);
        if !(r_new.amax() < r.amax()) {
            break;
        }
        (x, r) = (refined, r_new);
    }
    Some(x)
}

/// The solution X of the Stein (discrete Lyapunov) equation X = A X Aᵀ + W
/// by Smith doubling (X ← X + A_k X A_kᵀ, A_k ← A_k²; X = Σ_k Aᵏ W Aᵏᵀ).
/// `None` when A is not stable (the sum diverges) or the doubling does not
/// converge in 64 steps (2⁶⁴ terms).
pub fn stein_smith(a: &DMatrix<f64>, w: DMatrix<f64>) -> Option<DMatrix<f64>> {
    let mut ak = a.clone();
    let mut x = w;
    for _ in 0..64 {
        let step = &ak * &x * ak.transpose();
        // Largest entries, not the Frobenius norm: that overflows on a
        // diverging sum before its entries do.
        let done = step.amax() <= 1e-15 * x.amax().max(f64::MIN_POSITIVE);
        x += step;
        if !x.as_slice().iter().all(|v| v.is_finite()) {
            return None;
        }
        if done {
            return Some(x);
        }
        ak = &ak * &ak;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stable, strongly non-normal A: 20 lightly damped pairs (radius
    /// 0.996-0.998) in coordinates x = V x', V = Q₁ diag(10^{0..4}) Q₂ᵀ with
    /// random orthogonal Q₁, Q₂ (‖A‖ in the hundreds, as a Kalman filter's
    /// modal realization has), and W = b bᵀ.
    fn non_normal() -> (DMatrix<f64>, DMatrix<f64>) {
        use rand::{RngExt, SeedableRng};
        let n = 40;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut random = |r: usize, c: usize| DMatrix::from_fn(r, c, |_, _| rng.random_range(-0.5..0.5));
        let mut modal = DMatrix::zeros(n, n);
        for k in 0..n / 2 {
            let (th, r) = (0.05 + 2.5 * k as f64 / 20.0, 0.998 - 0.002 * k as f64 / 20.0);
            let i = 2 * k;
            (modal[(i, i)], modal[(i, i + 1)]) = (r * th.cos(), r * th.sin());
            (modal[(i + 1, i)], modal[(i + 1, i + 1)]) = (-r * th.sin(), r * th.cos());
        }
        let (q1, q2) = (random(n, n).qr().q(), random(n, n).qr().q());
        let s = DMatrix::from_diagonal(&DVector::from_fn(n, |i, _| 10f64.powf(4.0 * i as f64 / (n - 1) as f64)));
        let v = &q1 * s * q2.transpose();
        let v_inv = v.clone().try_inverse().unwrap();
        let b = random(n, 1);
        (&v * modal * v_inv, &b * b.transpose())
    }

    fn residual(a: &DMatrix<f64>, w: &DMatrix<f64>, x: &DMatrix<f64>) -> f64 {
        (a * x * a.transpose() + w - x).amax() / x.amax()
    }

    /// The refined solution's residual is at the rounding level of the
    /// residual's own computation (ε·‖A‖²); negative control: the doubling
    /// alone leaves one at least a hundred times larger.
    #[test]
    fn refinement_brings_the_stein_residual_down_for_a_non_normal_a() {
        let (a, w) = non_normal();
        let plain = stein_smith(&a, w.clone()).unwrap();
        let refined = stein_refined(&a, w.clone()).unwrap();
        let (rp, rr) = (residual(&a, &w, &plain), residual(&a, &w, &refined));
        eprintln!("relative residual: doubling {rp:.1e}, refined {rr:.1e}");
        assert!(rr < 1e-9, "refined {rr:.1e}");
        assert!(rp > 100.0 * rr, "control: the doubling alone {rp:.1e} against {rr:.1e}");
    }
}
