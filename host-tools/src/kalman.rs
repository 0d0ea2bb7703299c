//! Kalman compensator design (DESIGN.md, signal chain steps 2-3 and 5).
//!
//! 1. The fitted model G(s) = d + Σ r/(s − p) is discretized exactly per pole
//!    (the matrix exponential of a modal model is e^{pT} per pole) with the
//!    applied force Fa piecewise *linear* between samples (first-order hold):
//!    a real cutting force is continuous, and a zero-order hold would assume a
//!    half-sample lag that is not there.
//! 2. Augmentation: x_e = [x_s; F_k; F_{k−1}; …; F_{k−L}] with the force a
//!    random walk, F_{k+1} = F_k + w_k, E[w²] = q (N²/sample). With the FOH
//!    the increment w_k also drives the plant, so the process noise enters
//!    through g = [s·γ1; 1; 0…] (correlated, exact).
//! 3. The filter DARE P = A P Aᵀ − A P Cᵀ (C P Cᵀ + R)⁻¹ C P Aᵀ + q g gᵀ is
//!    solved by the structured doubling algorithm (Chu, Fan & Lin 2005), and
//!    its residual and the closed-loop spectral radius are checked.
//! 4. Compensator from y to the estimate of F_{k−L} (a fixed-lag smoother for
//!    L > 0, still a fixed-size LTI filter):
//!    x̂⁻[k+1] = A(I − K C) x̂⁻[k] + A K y[k],
//!    F̂[k−L] = e_Lᵀ (I − K C) x̂⁻[k] + e_Lᵀ K y[k],  K = P Cᵀ (C P Cᵀ + R)⁻¹.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;

use crate::fit::{PoleResidueModel, Term};

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

    /// Simulate in f64: y[k] = c x + d u, x ← A x + b u.
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

    /// Largest eigenvalue modulus of A.
    pub fn spectral_radius(&self) -> f64 {
        self.a.complex_eigenvalues().iter().map(|z| z.norm()).fold(0.0, f64::max)
    }
}

/// The augmented discrete plant of the estimator.
#[derive(Clone, Debug)]
pub struct AugmentedPlant {
    /// State transition.
    pub a: DMatrix<f64>,
    /// Process-noise input (force increment w).
    pub g: DVector<f64>,
    /// Measurement row.
    pub c: DVector<f64>,
    /// Number of plant (sensor) states.
    pub n_plant: usize,
    /// Fixed lag L (samples).
    pub lag: usize,
}

impl AugmentedPlant {
    /// Index of the state F_{k−L} that the compensator outputs.
    pub fn output_index(&self) -> usize {
        self.n_plant + self.lag
    }
}

/// FOH input weights of one pole over one sample: x[k+1] = e^{pT} x[k] +
/// γ0·F_k + γ1·F_{k+1} for ẋ = p x + F(t), F linear between samples.
/// γ0 = I1/T, γ1 = I0 − I1/T with I0 = ∫₀ᵀ e^{pu} du, I1 = ∫₀ᵀ u e^{pu} du.
fn foh_weights(p: Complex64, t: f64) -> (Complex64, Complex64, Complex64) {
    let x = p * t;
    let e = x.exp();
    let (i0, i1) = if x.norm() < 1e-4 {
        // series: I0 = T(1 + x/2 + x²/6), I1 = T²(1/2 + x/3 + x²/8)
        (t * (1.0 + x / 2.0 + x * x / 6.0), t * t * (0.5 + x / 3.0 + x * x / 8.0))
    } else {
        ((e - 1.0) / p, (e * (x - 1.0) + 1.0) / (p * p))
    };
    (e, i1 / t, i0 - i1 / t)
}

/// Build the augmented plant of a fitted model at sample rate `fs_hz` with
/// fixed lag `lag` (module doc, steps 1-2). Plant states are scaled by |p|
/// so that every state has the magnitude of a force.
pub fn augmented_plant(model: &PoleResidueModel, fs_hz: f64, lag: usize) -> AugmentedPlant {
    let t = 1.0 / fs_hz;
    let n_plant = model.order();
    let n = n_plant + 1 + lag;
    let f = n_plant; // index of F_k
    let mut a = DMatrix::<f64>::zeros(n, n);
    let mut g = DVector::<f64>::zeros(n);
    let mut c = DVector::<f64>::zeros(n);
    let mut i = 0;
    for term in &model.terms {
        match *term {
            Term::Real { pole, residue } => {
                let s = pole.abs();
                let (e, g0, g1) = foh_weights(Complex64::new(pole, 0.0), t);
                a[(i, i)] = e.re;
                a[(i, f)] = s * (g0 + g1).re;
                g[i] = s * g1.re;
                c[i] = residue / s;
                i += 1;
            }
            Term::Pair { pole, residue } => {
                let s = pole.norm();
                let (e, g0, g1) = foh_weights(pole, t);
                a[(i, i)] = e.re;
                a[(i, i + 1)] = -e.im;
                a[(i + 1, i)] = e.im;
                a[(i + 1, i + 1)] = e.re;
                let gin = (g0 + g1) * s;
                a[(i, f)] = gin.re;
                a[(i + 1, f)] = gin.im;
                g[i] = (g1 * s).re;
                g[i + 1] = (g1 * s).im;
                // 2·Re(r·x) with x = (ξ1 + jξ2)/s
                c[i] = 2.0 * residue.re / s;
                c[i + 1] = -2.0 * residue.im / s;
                i += 2;
            }
        }
    }
    a[(f, f)] = 1.0;
    g[f] = 1.0;
    c[f] = model.d;
    for j in 1..=lag {
        a[(f + j, f + j - 1)] = 1.0;
    }
    AugmentedPlant { a, g, c, n_plant, lag }
}

/// Solution of the filter DARE with its checks.
#[derive(Clone, Debug)]
pub struct DareSolution {
    /// Prior error covariance P (N² in the scaled coordinates).
    pub p: DMatrix<f64>,
    /// Relative residual ‖P − Ric(P)‖_F / ‖P‖_F.
    pub residual: f64,
    /// Doubling iterations used.
    pub iterations: usize,
}

/// Solve P = A P Aᵀ − A P Cᵀ (C P Cᵀ + R)⁻¹ C P Aᵀ + Q by structured doubling
/// (dual form: Â = Aᵀ, G = Cᵀ C / R, H = Q).
pub fn solve_filter_dare(a: &DMatrix<f64>, c: &DVector<f64>, q: &DMatrix<f64>, r: f64) -> Result<DareSolution> {
    let n = a.nrows();
    let id = DMatrix::<f64>::identity(n, n);
    let mut ak = a.transpose();
    let mut gk = c * c.transpose() / r;
    let mut hk = q.clone();
    let mut iterations = 0;
    for it in 1..=200 {
        iterations = it;
        let w = &id + &gk * &hk;
        let lu = w.lu();
        let w_inv_a = lu.solve(&ak).ok_or_else(|| anyhow::anyhow!("Riccati doubling: I + G·H is singular"))?;
        let w_inv_g = lu.solve(&gk).ok_or_else(|| anyhow::anyhow!("Riccati doubling: I + G·H is singular"))?;
        let a_next = &ak * &w_inv_a;
        let g_next = &gk + &ak * &w_inv_g * ak.transpose();
        let h_next = &hk + ak.transpose() * &hk * &w_inv_a;
        let change = (&h_next - &hk).norm() / h_next.norm().max(f64::MIN_POSITIVE);
        ak = a_next;
        gk = (&g_next + g_next.transpose()) * 0.5;
        hk = (&h_next + h_next.transpose()) * 0.5;
        if !hk.iter().all(|v| v.is_finite()) {
            bail!("Riccati doubling diverged (non-finite iterate); the model may be unobservable");
        }
        if change < 1e-14 {
            break;
        }
    }
    let p = hk;
    let s = (c.transpose() * &p * c)[(0, 0)] + r;
    let apc = a * &p * c;
    let ric = a * &p * a.transpose() - &apc * apc.transpose() / s + q;
    let residual = (&p - ric).norm() / p.norm().max(f64::MIN_POSITIVE);
    if !(residual < 1e-8) {
        bail!("Riccati solution rejected: relative residual {residual:.2e} after {iterations} doubling steps (needs < 1e-8)");
    }
    Ok(DareSolution { p, residual, iterations })
}

/// The designed compensator with its diagnostics.
#[derive(Clone, Debug)]
pub struct KalmanDesign {
    /// Compensator y → F̂[k−L] (f64).
    pub compensator: StateSpace,
    /// Kalman gain K (measurement update), in the scaled coordinates.
    pub kalman_gain: DVector<f64>,
    /// Riccati solution diagnostics.
    pub dare_residual: f64,
    /// Spectral radius of the compensator matrix A(I − K C).
    pub closed_loop_radius: f64,
    /// Fixed lag L (samples).
    pub lag: usize,
    /// Process-noise intensity q (N²/sample).
    pub q: f64,
    /// Measurement-noise variance R (N²).
    pub r: f64,
}

/// Design the compensator for model, rate, q, R and lag (module doc).
pub fn design(model: &PoleResidueModel, fs_hz: f64, q: f64, r: f64, lag: usize) -> Result<KalmanDesign> {
    if !(r > 0.0) || !r.is_finite() {
        bail!("measurement noise variance R must be positive and finite, got {r}");
    }
    if !(q > 0.0) || !q.is_finite() {
        bail!("process noise intensity q must be positive and finite, got {q}");
    }
    let plant = augmented_plant(model, fs_hz, lag);
    let qm = &plant.g * plant.g.transpose() * q;
    let sol = solve_filter_dare(&plant.a, &plant.c, &qm, r)?;
    let s = (plant.c.transpose() * &sol.p * &plant.c)[(0, 0)] + r;
    let k = &sol.p * &plant.c / s;
    let n = plant.a.nrows();
    let i_kc = DMatrix::<f64>::identity(n, n) - &k * plant.c.transpose();
    let out = plant.output_index();
    let comp = StateSpace {
        a: &plant.a * &i_kc,
        b: &plant.a * &k,
        c: i_kc.row(out).transpose(),
        d: k[out],
    };
    let radius = comp.spectral_radius();
    if !(radius < 1.0) {
        bail!("Kalman compensator is not stable (spectral radius {radius:.9}); the fitted model may be unobservable");
    }
    Ok(KalmanDesign {
        compensator: comp,
        kalman_gain: k,
        dare_residual: sol.residual,
        closed_loop_radius: radius,
        lag,
        q,
        r,
    })
}
