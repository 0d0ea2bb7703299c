//! Modal models of a table dynamometer (one SISO model per axis) and their exact
//! time response.
//!
//! Per axis `G(s) = Σ_k r_k·ω_k² / (s² + 2ζ_k ω_k s + ω_k²)` with `Σ r_k = 1`
//! (unit DC gain, N/N). Each mode is simulated as its own 2x2 state-space system
//! `ẍ + 2ζω ẋ + ω² x = r ω² u`, discretized exactly: the matrix exponential and
//! its integrals are analytic functions of a 2x2 matrix, evaluated through the
//! eigenvalues (Cayley–Hamilton), with series for small arguments so that slow
//! modes at high rates lose no precision.

use anyhow::{bail, Result};
use num_complex::Complex64;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// One structural mode of the force path.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Mode {
    /// Undamped natural frequency (Hz).
    pub fn_hz: f64,
    /// Damping ratio ζ (0 < ζ < 1).
    pub zeta: f64,
    /// Residue r (dimensionless share of the static gain; may be negative).
    pub residue: f64,
}

impl Mode {
    /// Natural angular frequency ω (rad/s).
    pub fn omega(&self) -> f64 {
        2.0 * PI * self.fn_hz
    }

    /// This mode's contribution to the FRF at `f_hz`.
    pub fn frf(&self, f_hz: f64) -> Complex64 {
        let w = self.omega();
        let s = Complex64::new(0.0, 2.0 * PI * f_hz);
        self.residue * w * w / (s * s + 2.0 * self.zeta * w * s + w * w)
    }
}

/// How the force is interpolated between its samples by [`Dynamometer::measure_with`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Hold {
    /// Zero-order hold: the force is constant from one sample to the next.
    Zoh,
    /// First-order hold: the force is linear between samples (default; closer
    /// to a smooth physical force).
    Foh,
}

/// Ranges for the random generation of a dynamometer axis (see [`Dynamometer::random`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModeRanges {
    /// Number of machine-structure modes (inclusive range).
    pub machine_count: (usize, usize),
    /// Frequency range of machine-structure modes (Hz).
    pub machine_hz: (f64, f64),
    /// |residue| range of machine-structure modes.
    pub machine_residue: (f64, f64),
    /// Probability that a machine-structure residue is negative.
    pub machine_negative_prob: f64,
    /// Main dynamometer mode band of the x and y axes (Hz).
    pub main_xy_hz: (f64, f64),
    /// Main dynamometer mode band of the z axis (Hz).
    pub main_z_hz: (f64, f64),
    /// Number of secondary dynamometer modes (inclusive range).
    pub secondary_count: (usize, usize),
    /// Frequency range of secondary dynamometer modes (Hz).
    pub secondary_hz: (f64, f64),
    /// |residue| range of secondary dynamometer modes.
    pub secondary_residue: (f64, f64),
    /// Damping ratio range of every mode.
    pub zeta: (f64, f64),
}

impl Default for ModeRanges {
    fn default() -> Self {
        Self {
            machine_count: (1, 3),
            machine_hz: (100.0, 700.0),
            machine_residue: (0.02, 0.15),
            machine_negative_prob: 0.3,
            main_xy_hz: (2000.0, 2600.0),
            main_z_hz: (3000.0, 3500.0),
            secondary_count: (0, 1),
            secondary_hz: (2000.0, 5000.0),
            secondary_residue: (0.02, 0.10),
            zeta: (0.01, 0.06),
        }
    }
}

/// One axis of a table dynamometer: a modal model with unit DC gain.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Dynamometer {
    /// Modes, ascending by frequency.
    pub modes: Vec<Mode>,
}

/// Tolerance of the unit-DC-gain check of [`Dynamometer::from_modes`].
pub const DC_GAIN_TOL: f64 = 1e-9;

impl Dynamometer {
    /// A model from explicit modes. Each mode needs `fn_hz > 0`, `0 < zeta < 1`
    /// and a finite residue; the residues must sum to 1 (unit DC gain) within
    /// [`DC_GAIN_TOL`]. Modes are sorted by frequency.
    pub fn from_modes(modes: Vec<Mode>) -> Result<Self> {
        let d = Self::checked(modes)?;
        let g = d.dc_gain();
        if (g - 1.0).abs() > DC_GAIN_TOL {
            bail!("dynamometer modes: residues sum to {g}, expected 1 (unit DC gain)");
        }
        Ok(d)
    }

    /// A model from explicit modes whose residues are scaled to sum to 1.
    pub fn from_modes_normalized(mut modes: Vec<Mode>) -> Result<Self> {
        let sum: f64 = modes.iter().map(|m| m.residue).sum();
        if !sum.is_finite() || sum.abs() < 1e-12 {
            bail!("dynamometer modes: residues sum to {sum}, cannot normalise to unit DC gain");
        }
        for m in &mut modes {
            m.residue /= sum;
        }
        Self::checked(modes)
    }

    fn checked(mut modes: Vec<Mode>) -> Result<Self> {
        if modes.is_empty() {
            bail!("dynamometer modes: at least one mode is needed");
        }
        for (i, m) in modes.iter().enumerate() {
            if !(m.fn_hz.is_finite() && m.fn_hz > 0.0) {
                bail!("dynamometer mode {i}: natural frequency {} Hz must be finite and > 0", m.fn_hz);
            }
            if !(m.zeta > 0.0 && m.zeta < 1.0) {
                bail!("dynamometer mode {i}: damping ratio {} must be in (0, 1)", m.zeta);
            }
            if !m.residue.is_finite() {
                bail!("dynamometer mode {i}: residue {} must be finite", m.residue);
            }
        }
        modes.sort_by(|a, b| a.fn_hz.total_cmp(&b.fn_hz));
        Ok(Self { modes })
    }

    /// A random, realistic axis from `seed`: `ranges.machine_count` machine-structure
    /// modes (small residues, possibly negative), one main dynamometer mode in
    /// `main_hz` carrying the rest of the unit residue, and
    /// `ranges.secondary_count` secondary dynamometer modes. Modes are kept at
    /// least 30 Hz (machine) / 300 Hz (dynamometer) apart; the main residue is
    /// kept ≥ 0.6.
    pub fn random(seed: u64, main_hz: (f64, f64), ranges: &ModeRanges) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let uni = |rng: &mut ChaCha8Rng, r: (f64, f64)| if r.1 > r.0 { rng.random_range(r.0..r.1) } else { r.0 };
        let count = |rng: &mut ChaCha8Rng, r: (usize, usize)| if r.1 > r.0 { rng.random_range(r.0..=r.1) } else { r.0 };
        let mut modes: Vec<Mode> = Vec::new();
        let n_machine = count(&mut rng, ranges.machine_count);
        let mut tries = 0;
        while modes.len() < n_machine && tries < 1000 {
            tries += 1;
            let f = uni(&mut rng, ranges.machine_hz);
            if modes.iter().any(|m| (m.fn_hz - f).abs() < 30.0) {
                continue;
            }
            let mag = uni(&mut rng, ranges.machine_residue);
            let sign = if rng.random_bool(ranges.machine_negative_prob.clamp(0.0, 1.0)) { -1.0 } else { 1.0 };
            modes.push(Mode { fn_hz: f, zeta: uni(&mut rng, ranges.zeta), residue: sign * mag });
        }
        let main_f = uni(&mut rng, main_hz);
        let main_zeta = uni(&mut rng, ranges.zeta);
        let n_sec = count(&mut rng, ranges.secondary_count);
        let mut secondary: Vec<Mode> = Vec::new();
        tries = 0;
        while secondary.len() < n_sec && tries < 1000 {
            tries += 1;
            let f = uni(&mut rng, ranges.secondary_hz);
            if (f - main_f).abs() < 300.0 || secondary.iter().any(|m| (m.fn_hz - f).abs() < 300.0) {
                continue;
            }
            let mag = uni(&mut rng, ranges.secondary_residue);
            secondary.push(Mode { fn_hz: f, zeta: uni(&mut rng, ranges.zeta), residue: mag });
        }
        modes.extend(secondary);
        // Keep the main mode dominant: the others together carry at most 0.4.
        let others: f64 = modes.iter().map(|m| m.residue).sum();
        if others > 0.4 {
            for m in &mut modes {
                m.residue *= 0.4 / others;
            }
        }
        let others: f64 = modes.iter().map(|m| m.residue).sum();
        modes.push(Mode { fn_hz: main_f, zeta: main_zeta, residue: 1.0 - others });
        Self::checked(modes).expect("random modes are valid by construction")
    }

    /// Static gain Σ r_k (1 for every model built here).
    pub fn dc_gain(&self) -> f64 {
        self.modes.iter().map(|m| m.residue).sum()
    }

    /// The mode with the largest residue (the dynamometer's main resonance).
    pub fn main_mode(&self) -> Mode {
        *self.modes.iter().max_by(|a, b| a.residue.total_cmp(&b.residue)).expect("at least one mode")
    }

    /// G(j2πf), the true FRF (N/N).
    pub fn frf(&self, f_hz: f64) -> Complex64 {
        self.modes.iter().map(|m| m.frf(f_hz)).sum()
    }

    /// Measured force for the applied `force` sampled at `fs_hz`, starting from
    /// rest, with the force linear between samples (first-order hold): the
    /// response at each sample instant is that of the continuous model to the
    /// piecewise-linear force, exact up to rounding. No internal oversampling is
    /// needed (or would change anything): a linear segment stays linear on any
    /// sub-step. To model content between the samples, generate the force at a
    /// multiple of the output rate, measure at that rate and decimate (as
    /// [`crate::simulate::simulate`] does with `SimParams::oversample`).
    /// A force that is non-zero at sample 0 acts as a step at t = 0.
    pub fn measure(&self, force: &[f64], fs_hz: f64) -> Vec<f64> {
        self.measure_with(force, fs_hz, Hold::Foh)
    }

    /// As [`Self::measure`], with the chosen hold between force samples.
    /// With [`Hold::Zoh`] the force is constant over each sample interval (so the
    /// output lags by half a sample compared to [`Hold::Foh`]).
    pub fn measure_with(&self, force: &[f64], fs_hz: f64, hold: Hold) -> Vec<f64> {
        assert!(fs_hz > 0.0 && fs_hz.is_finite(), "sample rate must be > 0");
        let mut y = vec![0.0; force.len()];
        for m in &self.modes {
            let d = ModeStep::new(m, 1.0 / fs_hz, hold);
            let (mut x, mut v) = (0.0f64, 0.0f64);
            for k in 1..force.len() {
                let (u0, u1) = (force[k - 1], force[k]);
                let xn = d.phi[0][0] * x + d.phi[0][1] * v + d.g0[0] * u0 + d.g1[0] * u1;
                let vn = d.phi[1][0] * x + d.phi[1][1] * v + d.g0[1] * u0 + d.g1[1] * u1;
                x = xn;
                v = vn;
                y[k] += x;
            }
        }
        y
    }
}

/// Exact one-step update of one mode: z⁺ = Φ z + g0·u[k-1] + g1·u[k].
#[derive(Clone, Copy, Debug)]
pub struct ModeStep {
    /// State transition e^{Ah}.
    pub phi: [[f64; 2]; 2],
    /// Input vector on the previous sample.
    pub g0: [f64; 2],
    /// Input vector on the current sample.
    pub g1: [f64; 2],
}

impl ModeStep {
    /// Discretize `mode` (state [x, ẋ], A = [[0,1],[-ω²,-2ζω]], B = [0, rω²])
    /// over a step of `h` seconds. With u linear on the step,
    /// z(h) = e^{Ah} z0 + h φ1(Ah) B u0 + h φ2(Ah) B (u1 - u0), where
    /// φ1(M) = (e^M - I)M⁻¹ and φ2(M) = (e^M - I - M)M⁻²; ZOH drops the last term.
    pub fn new(mode: &Mode, h: f64, hold: Hold) -> Self {
        let w = mode.omega();
        let z = mode.zeta;
        let r = mode.residue;
        // A·h and the eigenvalue μ = h(-ζω + jω√(1-ζ²)) of A·h.
        let ah = [[0.0, h], [-w * w * h, -2.0 * z * w * h]];
        let mu = Complex64::new(-z * w * h, w * (1.0 - z * z).sqrt() * h);
        let phi = mat_fn(&ah, mu, phi_k(0, mu));
        let p1 = mat_fn(&ah, mu, phi_k(1, mu));
        let p2 = mat_fn(&ah, mu, phi_k(2, mu));
        let b = [0.0, r * w * w];
        let mv = |m: &[[f64; 2]; 2]| [h * (m[0][0] * b[0] + m[0][1] * b[1]), h * (m[1][0] * b[0] + m[1][1] * b[1])];
        let gam0 = mv(&p1);
        let gam1 = mv(&p2);
        match hold {
            Hold::Zoh => Self { phi, g0: gam0, g1: [0.0, 0.0] },
            Hold::Foh => Self { phi, g0: [gam0[0] - gam1[0], gam0[1] - gam1[1]], g1: gam1 },
        }
    }
}

/// f(M) for a real 2x2 matrix `m` with complex-conjugate eigenvalues μ, μ̄,
/// given f(μ): f(M) = c0 I + c1 M with c1 = Im f(μ)/Im μ, c0 = Re f(μ) - c1 Re μ.
fn mat_fn(m: &[[f64; 2]; 2], mu: Complex64, f_mu: Complex64) -> [[f64; 2]; 2] {
    let c1 = f_mu.im / mu.im;
    let c0 = f_mu.re - c1 * mu.re;
    [[c0 + c1 * m[0][0], c1 * m[0][1]], [c1 * m[1][0], c0 + c1 * m[1][1]]]
}

/// φ_k(z) = Σ_{n≥0} zⁿ/(n+k)! for k = 0, 1, 2 (φ0 = e^z, φ1 = (e^z-1)/z,
/// φ2 = (e^z-1-z)/z²): series for |z| < 1, closed form otherwise.
pub(crate) fn phi_k(k: u32, z: Complex64) -> Complex64 {
    if z.norm() < 1.0 {
        // Σ zⁿ/(n+k)!: 30 terms are far below f64 resolution for |z| < 1.
        let mut fact = 1.0;
        for i in 1..=k {
            fact *= i as f64;
        }
        let mut term = Complex64::new(1.0 / fact, 0.0);
        let mut sum = term;
        for n in 1..30 {
            term = term * z / (n + k) as f64;
            sum += term;
        }
        sum
    } else {
        let e = z.exp();
        match k {
            0 => e,
            1 => (e - 1.0) / z,
            _ => (e - 1.0 - z) / (z * z),
        }
    }
}

/// A three-axis table dynamometer, one independent SISO model per axis
/// (cross-axis terms are not modelled).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MultiAxisDynamometer {
    /// Models of the x, y and z axes (index 0, 1, 2).
    pub axes: [Dynamometer; 3],
}

impl MultiAxisDynamometer {
    /// Random axes from `seed` with `params.modes`: x/y main mode in
    /// `main_xy_hz` (≈ 2-2.6 kHz), z in `main_z_hz` (≈ 3-3.5 kHz). Each axis
    /// uses its own ChaCha stream, so the axes are independent and reproducible.
    pub fn random(seed: u64, params: &super::SimParams) -> Self {
        let r = &params.modes;
        let axis_seed = |axis: u64| seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(0xD1B5_4A32_D192_ED03 ^ axis);
        Self {
            axes: [
                Dynamometer::random(axis_seed(0), r.main_xy_hz, r),
                Dynamometer::random(axis_seed(1), r.main_xy_hz, r),
                Dynamometer::random(axis_seed(2), r.main_z_hz, r),
            ],
        }
    }

    /// The model of `axis` (0 = x, 1 = y, 2 = z).
    pub fn axis(&self, axis: usize) -> &Dynamometer {
        &self.axes[axis]
    }
}
