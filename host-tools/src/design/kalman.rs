//! Kalman compensator design (DESIGN.md, signal chain steps 2-3 and 5): the
//! discrete sensor model augmented with a random-walk force
//! ([`augmented_plant`]), the filter DARE ([`solve_filter_dare`]) and the
//! fixed-lag smoother that estimates the force L samples late as a
//! fixed-size LTI filter ([`design`]).

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};

use crate::numeric::dense::Lu;
use crate::numeric::lti::StateSpace;
use num_complex::Complex64;

use crate::design::discretize::{DTerm, DiscreteModel};

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
    /// Lag of the estimate in the model's time frame: L + D (samples).
    pub lag: usize,
}

impl AugmentedPlant {
    /// Index of the state F_{k−L−D} that the compensator outputs.
    pub fn output_index(&self) -> usize {
        self.n_plant + self.lag
    }
}

/// Build the augmented plant of the discrete model `dm` for a declared
/// output latency of `lag` samples. Plant states are scaled by 1/|1 − ζ| so
/// that every state has about the magnitude of a force.
///
/// The discrete model is Ĝ_d(z) = z^D·M(z) ([`crate::design::discretize`]): by
/// default fitted on the unit circle to the sampled-data relation Ĝ(j2πf) of
/// a band-limited chain, with an advance of D samples (the band-limited
/// relation is two-sided) and M causal: M(z) = d + Σ ρ/(z − ζ) + Σ_m h_m z^{−m}.
/// Hold equivalents (FOH, ZOH) have the same form with D = 0 and no taps.
/// Augmentation: x_e = [x_s; F_k; F_{k−1}; …; F_{k−N}] with the force a random
/// walk, F_{k+1} = F_k + w_k, E\[w²\] = q (N²/sample), and N = max(L + D, M) so
/// that both the taps and the output lag are states. The measurement is
/// ỹ_k = y_{k−D} = M(z)F_k + v_k (causal in F).
pub fn augmented_plant(dm: &DiscreteModel, lag: usize) -> AugmentedPlant {
    augmented_plant_shaped(dm, lag, None)
}

/// The band-limited force prior: the force is a random walk u
/// (u_{k+1} = u_k + w_k, E\[w²\] = q) through an all-pole Butterworth
/// low-pass S(z) of even order with S(1) = 1, so that in the band the force
/// is the random walk the q criterion assumes, and above the corner its
/// prior power falls by 20·order dB/decade more. The smoother then takes
/// what it measures above the corner for noise instead of inverting Ĝ there.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ForceShape {
    /// −3 dB corner of S (Hz).
    pub corner_hz: f64,
    /// Order of S: 2 or 4 (one or two all-pole sections).
    pub order: usize,
}

impl ForceShape {
    /// The sections of S at the sample rate `fs_hz`: for each analog
    /// Butterworth pole pair p, p* (|p| = 2π f_c), the matched discrete pair
    /// ζ = e^{p/fs}: (2 Re ζ, |ζ|², gain 1 − 2 Re ζ + |ζ|²), the section
    /// y_{k+1} = 2 Re ζ·y_k − |ζ|²·y_{k−1} + gain·x_k with unit gain at DC.
    pub fn sections(&self, fs_hz: f64) -> Vec<(f64, f64, f64)> {
        let n = self.order as f64;
        (0..self.order / 2)
            .map(|k| {
                let theta = std::f64::consts::PI * (2.0 * k as f64 + n + 1.0) / (2.0 * n);
                let p = Complex64::from_polar(2.0 * std::f64::consts::PI * self.corner_hz, theta);
                let z = (p / fs_hz).exp();
                let (a1, a2) = (2.0 * z.re, z.norm_sqr());
                (a1, a2, 1.0 - a1 + a2)
            })
            .collect()
    }
}

/// States the force shape of `sections` ([`ForceShape::sections`]) adds to
/// an augmented plant: the random walk u and two per section before the
/// last (the last one's are F_k and F_{k−1} of the delay line); 0 unshaped.
pub(crate) fn shape_states(sections: &[(f64, f64, f64)]) -> usize {
    if sections.is_empty() {
        0
    } else {
        1 + 2 * (sections.len() - 1)
    }
}

/// Write the shaped force model into the state transition `a`: the random
/// walk at state `u` (its process noise is the caller's), driving the
/// all-pole `sections` in turn; the sections before the last take the
/// states after u, the last one outputs state `out` (F_k) with its second
/// state `out_prev` (F_{k−1}).
pub(crate) fn wire_shape(a: &mut DMatrix<f64>, sections: &[(f64, f64, f64)], u: usize, out: usize, out_prev: usize) {
    a[(u, u)] = 1.0;
    let mut input = u;
    for (k, &(a1, a2, gain)) in sections.iter().enumerate() {
        let (y, y1) = if k + 1 == sections.len() { (out, out_prev) } else { (u + 1 + 2 * k, u + 2 + 2 * k) };
        a[(y, y)] = a1;
        a[(y, y1)] = -a2;
        a[(y, input)] = gain;
        a[(y1, y)] = 1.0;
        input = y;
    }
}

/// [`augmented_plant`] with the force shaped by `shape` ([`ForceShape`]):
/// the random walk u and the first sections' two states each follow the
/// unshaped layout's states, and the last section's output is F_k itself,
/// its second state F_{k−1} of the delay line (which then has at least one
/// stage). Without a shape, exactly [`augmented_plant`].
pub fn augmented_plant_shaped(dm: &DiscreteModel, lag: usize, shape: Option<ForceShape>) -> AugmentedPlant {
    let n_plant = dm.order();
    let model_lag = lag + dm.advance;
    let sections = shape.map(|s| s.sections(dm.fs_hz)).unwrap_or_default();
    let min_delay = usize::from(!sections.is_empty());
    let n_delay = model_lag.max(dm.fir.len()).max(min_delay);
    let n = n_plant + 1 + n_delay + shape_states(&sections);
    let f = n_plant; // index of F_k
    let mut a = DMatrix::<f64>::zeros(n, n);
    let mut g = DVector::<f64>::zeros(n);
    let mut c = DVector::<f64>::zeros(n);
    let mut i = 0;
    for term in &dm.terms {
        match *term {
            DTerm::Real { pole, residue } => {
                let s = (1.0 - pole).abs().max(1e-12);
                a[(i, i)] = pole;
                a[(i, f)] = s;
                c[i] = residue / s;
                i += 1;
            }
            DTerm::Pair { pole, residue } => {
                // Complex state x (x[k+1] = ζ x[k] + F_k) as ξ = s·(Re x, Im x);
                // its output 2·Re(ρ x).
                let z = Complex64::new(pole.0, pole.1);
                let s = (Complex64::new(1.0, 0.0) - z).norm().max(1e-12);
                a[(i, i)] = z.re;
                a[(i, i + 1)] = -z.im;
                a[(i + 1, i)] = z.im;
                a[(i + 1, i + 1)] = z.re;
                a[(i, f)] = s;
                c[i] = 2.0 * residue.0 / s;
                c[i + 1] = -2.0 * residue.1 / s;
                i += 2;
            }
        }
    }
    c[f] = dm.d;
    for j in 1..=n_delay {
        a[(f + j, f + j - 1)] = 1.0;
    }
    for (m, h) in dm.fir.iter().enumerate() {
        c[f + m + 1] = *h;
    }
    if sections.is_empty() {
        a[(f, f)] = 1.0;
        g[f] = 1.0;
    } else {
        let u = f + 1 + n_delay;
        g[u] = 1.0;
        wire_shape(&mut a, &sections, u, f, f + 1);
    }
    AugmentedPlant { a, g, c, n_plant, lag: model_lag }
}

/// Solution of the filter DARE with its checks.
#[derive(Clone, Debug)]
pub struct DareSolution {
    /// Prior error covariance P (N² in the scaled coordinates).
    pub p: DMatrix<f64>,
    /// Relative residual of P ([`dare_residual`]).
    pub residual: f64,
    /// Doubling iterations used.
    pub iterations: usize,
}

/// Largest accepted relative residual of a DARE solution ([`dare_residual`]).
pub const DARE_TOLERANCE: f64 = 1e-8;

/// Newton (defect-correction) steps at most after the doubling.
pub(crate) const NEWTON_STEPS: usize = 4;

/// Ric(P) = A P Aᵀ − A P c (cᵀ P c + R)⁻¹ cᵀ P Aᵀ + Q, and the predictor
/// gain K̄ = A P c / (cᵀ P c + R) with s = cᵀ P c + R.
fn riccati_map(
    a: &DMatrix<f64>,
    c: &DVector<f64>,
    q: &DMatrix<f64>,
    r: f64,
    p: &DMatrix<f64>,
) -> (DMatrix<f64>, DVector<f64>, f64) {
    let s = (c.transpose() * p * c)[(0, 0)] + r;
    let kbar = a * p * c / s;
    let apa = a * p * a.transpose();
    let ric = &apa - &kbar * kbar.transpose() * s + q;
    (ric, kbar, s)
}

/// Relative residual of a DARE solution P: ‖P − Ric(P)‖_F over the sum of
/// the Frobenius norms of the terms Ric(P) adds, ‖P‖ + ‖A P Aᵀ‖ +
/// ‖A P c cᵀ P Aᵀ‖/s + ‖Q‖ (the normalization of SLICOT's and MATLAB's
/// DARE residual). Rounding alone leaves about n·ε relative to those terms,
/// however the problem is scaled; where A P Aᵀ and the correction nearly
/// cancel (lightly damped or slow states), ‖P‖ alone would call rounding an
/// error. A wrong P leaves a residual of the size of its error.
pub fn dare_residual(a: &DMatrix<f64>, c: &DVector<f64>, q: &DMatrix<f64>, r: f64, p: &DMatrix<f64>) -> f64 {
    let s = (c.transpose() * p * c)[(0, 0)] + r;
    let apc = a * p * c;
    let apa = a * p * a.transpose();
    let corr = &apc * apc.transpose() / s;
    let scale = p.norm() + apa.norm() + corr.norm() + q.norm();
    (p - (apa - corr + q)).norm() / scale.max(f64::MIN_POSITIVE)
}

/// The response (from ỹ to F̂, per line of `f_hz` in Hz) of the
/// steady-state fixed-interval smoother of `plant`
/// ([`crate::offline::smoother`], `compensate --offline`) for process noise
/// `q` (N²/sample) and measurement noise `r` (N²), its estimate the state at
/// [`AugmentedPlant::output_index`], so that the criterion judges it at
/// latency 0 as it judges the box's filter at its own. In steady state the
/// smoother is the non-causal Wiener filter of the model's spectra: with
/// Φ = (zI − A)⁻¹, T_y = cᵀΦγ and T_F = eᵀΦγ,
///
/// H(z) = q·T_F·conj(T_y) / (q·|T_y|² + r)
///
/// (the 3x3 form: [`crate::design::mimo::response::smoother_responses`]).
/// NaN where zI − A is singular (z = 1 for a random-walk force).
pub fn smoother_response(plant: &AugmentedPlant, q: f64, r: f64, f_hz: &[f64], fs_hz: f64) -> Vec<Complex64> {
    let n = plant.a.nrows();
    let out = plant.output_index();
    let sel = DMatrix::from_fn(2, n, |i, j| if i == 0 { plant.c[j] } else { f64::from(j == out) });
    crate::numeric::lti::left_resolvent(&plant.a, &sel, f_hz, fs_hz)
        .iter()
        .map(|rows| {
            let t = |i: usize| (0..n).map(|k| rows[(i, k)] * plant.g[k]).sum::<Complex64>();
            let (ty, tf) = (t(0), t(1));
            tf * ty.conj() * q / (ty.norm_sqr() * q + r)
        })
        .collect()
}

/// The structured doubling iteration (Chu, Fan & Lin 2005) of the DARE in
/// its dual form, from Â₀ = `ak`, G₀ = `gk`, H₀ = `hk`: at most 200 steps,
/// stopping when H changes by less than 10⁻¹⁴ of its norm. Returns H (the
/// solution P) and the steps taken; the caller checks the residual.
pub(crate) fn structured_doubling(
    mut ak: DMatrix<f64>,
    mut gk: DMatrix<f64>,
    mut hk: DMatrix<f64>,
) -> Result<(DMatrix<f64>, usize)> {
    let n = ak.nrows();
    let id = DMatrix::<f64>::identity(n, n);
    let mut iterations = 0;
    for it in 1..=200 {
        iterations = it;
        let w = &id + &gk * &hk;
        let lu = Lu::new(&w).ok_or_else(|| anyhow::anyhow!("Riccati doubling: I + G·H is singular"))?;
        let (w_inv_a, w_inv_g) = (lu.solve(&ak), lu.solve(&gk));
        let a_next = &ak * &w_inv_a;
        let g_next = &gk + &ak * &w_inv_g * ak.transpose();
        let h_next = &hk + ak.transpose() * &hk * &w_inv_a;
        let change = (&h_next - &hk).norm() / h_next.norm().max(f64::MIN_POSITIVE);
        ak = a_next;
        gk = (&g_next + g_next.transpose()) * 0.5;
        hk = (&h_next + h_next.transpose()) * 0.5;
        if !hk.as_slice().iter().all(|v| v.is_finite()) {
            bail!("Riccati doubling diverged (non-finite iterate); the model may be unobservable");
        }
        if change < 1e-14 {
            break;
        }
    }
    Ok((hk, iterations))
}

/// Solve P = A P Aᵀ − A P Cᵀ (C P Cᵀ + R)⁻¹ C P Aᵀ + Q by structured doubling
/// (dual form: Â = Aᵀ, G = Cᵀ C / R, H = Q), then polish P by Newton's
/// method (defect correction): with Acl = A − K̄ cᵀ the closed loop of P,
/// Ric(P + X) ≈ Ric(P) + Acl X Aclᵀ, so X solves the Stein equation
/// X = Acl X Aclᵀ + (Ric(P) − P) ([`crate::numeric::lti::stein_smith`]); a
/// step is kept only if it lowers the residual. The doubling's own rounding
/// grows with the spread of the plant's time scales (a real pole near z = 1
/// beside one near z = 0); the Newton steps work on the residual itself.
/// Rejected unless [`dare_residual`] < [`DARE_TOLERANCE`].
pub fn solve_filter_dare(a: &DMatrix<f64>, c: &DVector<f64>, q: &DMatrix<f64>, r: f64) -> Result<DareSolution> {
    let (hk, iterations) = structured_doubling(a.transpose(), c * c.transpose() / r, q.clone())?;
    let mut p = hk;
    let mut residual = dare_residual(a, c, q, r, &p);
    for _ in 0..NEWTON_STEPS {
        if residual < 1e-15 {
            break;
        }
        let (ric, kbar, _) = riccati_map(a, c, q, r, &p);
        let acl = a - &kbar * c.transpose();
        let Some(x) = crate::numeric::lti::stein_smith(&acl, &ric - &p) else { break };
        let next = &p + x;
        let next = (&next + next.transpose()) * 0.5;
        let res = dare_residual(a, c, q, r, &next);
        if !(res < residual) {
            break;
        }
        (p, residual) = (next, res);
    }
    if !(residual < DARE_TOLERANCE) {
        bail!("Riccati solution rejected: relative residual {residual:.2e} after {iterations} doubling steps and Newton refinement (needs < {DARE_TOLERANCE:e})");
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
    /// The band-limited force model, or `None` for the random walk.
    pub force_shape: Option<ForceShape>,
}

/// Design the compensator for the discrete model, q, R and declared
/// latency `lag`.
///
/// The filter DARE P = A P Aᵀ − A P Cᵀ (C P Cᵀ + R)⁻¹ C P Aᵀ + q g gᵀ of the
/// [`augmented_plant`] is solved by the structured doubling algorithm (Chu,
/// Fan & Lin 2005, [`solve_filter_dare`]), and its residual and the
/// closed-loop spectral radius are checked. The compensator runs from ỹ to
/// the estimate of F_{k−L−D} (a fixed-lag smoother of lag L + D, still a
/// fixed-size LTI filter):
///
/// ```text
/// x̂⁻[k+1] = A(I − K C) x̂⁻[k] + A K ỹ[k],
/// F̂[k−L−D] = e_{L+D}ᵀ (I − K C) x̂⁻[k] + e_{L+D}ᵀ K ỹ[k],  K = P Cᵀ (C P Cᵀ + R)⁻¹.
/// ```
///
/// Fed with y instead of ỹ (D samples earlier), the same filter outputs
/// F̂[k−L]: the declared latency stays L.
pub fn design(dm: &DiscreteModel, q: f64, r: f64, lag: usize) -> Result<KalmanDesign> {
    design_shaped(dm, q, r, lag, None)
}

/// [`design`] on the force model shaped by `shape` ([`augmented_plant_shaped`]).
pub fn design_shaped(
    dm: &DiscreteModel,
    q: f64,
    r: f64,
    lag: usize,
    shape: Option<ForceShape>,
) -> Result<KalmanDesign> {
    if !(r > 0.0) || !r.is_finite() {
        bail!("measurement noise variance R must be positive and finite, got {r}");
    }
    if !(q > 0.0) || !q.is_finite() {
        bail!("process noise intensity q must be positive and finite, got {q}");
    }
    let plant = augmented_plant_shaped(dm, lag, shape);
    let qm = &plant.g * plant.g.transpose() * q;
    let sol = solve_filter_dare(&plant.a, &plant.c, &qm, r)?;
    let s = (plant.c.transpose() * &sol.p * &plant.c)[(0, 0)] + r;
    let k = &sol.p * &plant.c / s;
    let n = plant.a.nrows();
    let i_kc = DMatrix::<f64>::identity(n, n) - &k * plant.c.transpose();
    let out = plant.output_index();
    let comp = StateSpace { a: &plant.a * &i_kc, b: &plant.a * &k, c: i_kc.row(out).transpose(), d: k[out] };
    let radius = comp.spectral_radius()?;
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
        force_shape: shape,
    })
}
