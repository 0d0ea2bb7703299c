//! The modal form of the plate dynamometer, its exact FRF matrix and its
//! exact time response.
//! ([`PlateModal`]), from the set-up's matrices ([`undamped_modes`]).

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector, Matrix3, SymmetricEigen};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

use super::setup::{PlateMatrices, PlateSetup, DOF};
use crate::simulate::chain::{pole_sum_response, Butterworth};
use crate::simulate::dynamometer::{Hold, Mode, ModeStep};

/// Largest relative residual ‖Kφ − ω²Mφ‖/(‖K‖‖φ‖) and mass-orthogonality
/// error ‖ΦᵀMΦ − I‖ accepted from the eigensolver.
pub const EIGEN_TOL: f64 = 1e-9;

/// Largest ratio of the largest to the smallest eigenvalue ω² accepted: past
/// it the stiffness is (nearly) singular, the model is ill-posed.
pub const MAX_EIGEN_SPREAD: f64 = 1e14;

/// One mode of the plate dynamometer for a force at one point.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlateMode {
    /// Undamped natural frequency (Hz).
    pub fn_hz: f64,
    /// Damping ratio.
    pub zeta: f64,
    /// Input row b_r = φ_rᵀB(p): modal force per newton in x, y, z (kg^-½).
    pub input: [f64; 3],
    /// Output column c_r = S·Cd·φ_r: channel force per unit modal
    /// coordinate (N·kg^-½·m^-1).
    pub output: [f64; 3],
}

impl PlateMode {
    /// ω_r (rad/s).
    pub fn omega(&self) -> f64 {
        2.0 * PI * self.fn_hz
    }

    /// R_r = c_r b_rᵀ/ω_r²: this mode's share of the static gain in every
    /// entry (`[i][j]`: channel i, force j; dimensionless).
    pub fn residue(&self) -> [[f64; 3]; 3] {
        let w2 = self.omega().powi(2);
        std::array::from_fn(|i| std::array::from_fn(|j| self.output[i] * self.input[j] / w2))
    }

    /// b_r·F at sample `k` of `force` (x, y, z).
    fn modal_force(&self, force: [&[f64]; 3], k: usize) -> f64 {
        self.input[0] * force[0][k] + self.input[1] * force[1][k] + self.input[2] * force[2][k]
    }

    /// The scalar factor of this mode in G(s): (1 + 2ζs/ω)/(s² + 2ζωs + ω²).
    fn factor(&self, s: Complex64) -> Complex64 {
        let (w, z) = (self.omega(), self.zeta);
        (1.0 + 2.0 * z * s / w) / (s * s + 2.0 * z * w * s + w * w)
    }

    /// The pole in the upper half plane, −ζω + jω√(1−ζ²) (rad/s).
    pub fn pole(&self) -> Complex64 {
        let (w, z) = (self.omega(), self.zeta);
        Complex64::new(-z * w, w * (1.0 - z * z).sqrt())
    }
}

/// The modal form of a plate dynamometer for a force at one point: modes
/// ascending by frequency.
///
/// In modal coordinates q = Σ φ_r η_r ([`undamped_modes`]):
///
/// η̈_r + 2ζ_r ω_r η̇_r + ω_r² η_r = b_r·F,   b_r = φ_rᵀB(p)  (the input row),
///
/// Damping is per mode: each mode r has its own damping ratio ζ_r
/// ([`super::PlateSetup::zeta`]): in mode r every element (sensor or table
/// mount) dissipates a force 2ζ_r/ω_r times its elastic force, i.e. the
/// damping matrix is C = Σ_r (2ζ_r/ω_r)·K φ_r φ_rᵀ M = M Φ diag(2ζω) Φᵀ M
/// (Caughey's modal damping), which leaves the modes uncoupled. The sensors'
/// own damping force is therefore measured with their elastic force, and the
/// channels are
///
/// y = Σ_r c_r (η_r + (2ζ_r/ω_r) η̇_r),   c_r = S·Cd·φ_r  (the output column),
///
/// so G(s) = Σ_r c_r b_rᵀ (1 + 2ζ_r s/ω_r) / (s² + 2ζ_r ω_r s + ω_r²), and
/// G(0) = S·Cd·K⁻¹·B = S (the sensors carry the whole static load).
/// Each mode's static share ([`PlateMode::residue`]) is its residue in all
/// nine entries.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlateModal {
    /// Where the force acts (m).
    pub point_m: [f64; 3],
    /// The modes.
    pub modes: Vec<PlateMode>,
}

/// Undamped modes of `mats`: (ω² ascending, mass-normalised shapes as the
/// columns of Φ), checked for residual, orthogonality and spread.
///
/// K φ = ω² M φ, mass-normalised (φᵀMφ = 1), from the symmetric
/// eigenproblem of L⁻¹KL⁻ᵀ with M = LLᵀ (Cholesky; nalgebra's symmetric
/// eigensolver).
pub fn undamped_modes(mats: &PlateMatrices) -> Result<(Vec<f64>, DMatrix<f64>)> {
    let Some(chol) = mats.m.clone().cholesky() else {
        bail!("plate dynamometer: the mass matrix is not positive definite (a mass or inertia is zero)");
    };
    let l = chol.l();
    let Some(linv) = l.clone().try_inverse() else {
        bail!("plate dynamometer: the mass matrix is singular");
    };
    let a = &linv * &mats.k * linv.transpose();
    let a = (&a + a.transpose()) * 0.5;
    let eig = SymmetricEigen::new(a);
    let mut order: Vec<usize> = (0..DOF).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let lam: Vec<f64> = order.iter().map(|&i| eig.eigenvalues[i]).collect();
    let spread = lam[DOF - 1] / lam[0];
    if lam[0].is_nan() || lam[0] <= 0.0 || spread.is_nan() || spread >= MAX_EIGEN_SPREAD {
        bail!(
            "plate dynamometer: the stiffness is (nearly) singular (eigenvalues ω² from {:e} to {:e} rad²/s²): \
             every body must be held by its springs",
            lam[0],
            lam[DOF - 1]
        );
    }
    let lt_inv = linv.transpose();
    let phi = DMatrix::from_fn(DOF, DOF, |r, c| (&lt_inv * eig.eigenvectors.column(order[c]))[r]);
    // Residual and orthogonality: the eigensolver's answer, checked.
    let knorm = mats.k.norm();
    for (c, &l2) in lam.iter().enumerate() {
        let v: DVector<f64> = phi.column(c).into();
        let res = (&mats.k * &v - &mats.m * &v * l2).norm() / (knorm * v.norm());
        if res.is_nan() || res >= EIGEN_TOL {
            bail!("plate dynamometer: mode {} fails its eigen residual ({res:e})", c + 1);
        }
    }
    let ortho = (phi.transpose() * &mats.m * &phi - DMatrix::<f64>::identity(DOF, DOF)).norm();
    if ortho.is_nan() || ortho >= EIGEN_TOL * DOF as f64 {
        bail!("plate dynamometer: modes are not mass-orthonormal (error {ortho:e})");
    }
    Ok((lam, phi))
}

impl PlateModal {
    /// The modal form of `setup` for a force at `point_m` (validated).
    pub fn new(setup: &PlateSetup, point_m: [f64; 3]) -> Result<Self> {
        setup.validate()?;
        super::setup::check_point("force point", point_m)?;
        let mats = setup.matrices(point_m);
        let (lam, phi) = undamped_modes(&mats)?;
        let sc = DMatrix::from_fn(3, 3, |i, j| mats.s[(i, j)]) * &mats.cd;
        let modes = (0..DOF)
            .map(|r| {
                let b = mats.b.transpose() * phi.column(r);
                let c = &sc * phi.column(r);
                PlateMode {
                    fn_hz: lam[r].sqrt() / (2.0 * PI),
                    zeta: setup.zeta[r],
                    input: [b[0], b[1], b[2]],
                    output: [c[0], c[1], c[2]],
                }
            })
            .collect();
        Ok(Self { point_m, modes })
    }

    /// G(s) at a complex s (rad/s): `[(i, j)]` = channel i, force j.
    pub fn at(&self, s: Complex64) -> Matrix3<Complex64> {
        let mut g = Matrix3::zeros();
        for m in &self.modes {
            let f = m.factor(s);
            for i in 0..3 {
                for j in 0..3 {
                    g[(i, j)] += f * (m.output[i] * m.input[j]);
                }
            }
        }
        g
    }

    /// G(j2πf), the exact FRF matrix (N/N).
    pub fn frf(&self, f_hz: f64) -> Matrix3<Complex64> {
        self.at(Complex64::new(0.0, 2.0 * PI * f_hz))
    }

    /// The crosstalk figure: per entry, the peak of |G_ij|/|G_ii| over the
    /// frequencies `freqs_hz` (the diagonal is 1): how much of channel i's
    /// signal a force in direction j makes, against its own direction's.
    pub fn crosstalk_peak(&self, freqs_hz: &[f64]) -> [[f64; 3]; 3] {
        let mut peak = [[0.0f64; 3]; 3];
        for &f in freqs_hz {
            let g = self.frf(f);
            for (i, row) in peak.iter_mut().enumerate() {
                for (j, p) in row.iter_mut().enumerate() {
                    *p = p.max(g[(i, j)].norm() / g[(i, i)].norm());
                }
            }
        }
        peak
    }

    /// Σ_r R_r = G(0).
    pub fn static_gain(&self) -> Matrix3<f64> {
        let mut g = Matrix3::zeros();
        for m in &self.modes {
            let r = m.residue();
            g += Matrix3::from_fn(|i, j| r[i][j]);
        }
        g
    }

    /// The three channels (N) for the applied force `force` (x, y, z, N)
    /// sampled at `fs_hz`, from rest, with the force linear between samples
    /// (first-order hold): each mode is discretized exactly
    /// ([`ModeStep`], fed with b_r·F/ω_r² so that its state is (η_r, η̇_r)),
    /// and its output uses both, c_r(η_r + 2ζ_r/ω_r·η̇_r).
    pub fn measure(&self, force: [&[f64]; 3], fs_hz: f64) -> [Vec<f64>; 3] {
        assert!(fs_hz > 0.0 && fs_hz.is_finite(), "sample rate must be > 0");
        let n = force[0].len().min(force[1].len()).min(force[2].len());
        let mut y: [Vec<f64>; 3] = std::array::from_fn(|_| vec![0.0; n]);
        for m in &self.modes {
            let w = m.omega();
            let unit = Mode { fn_hz: m.fn_hz, zeta: m.zeta, residue: 1.0 };
            let d = ModeStep::new(&unit, 1.0 / fs_hz, Hold::Foh);
            let u = |k: usize| m.modal_force(force, k) / (w * w);
            let kv = 2.0 * m.zeta / w;
            let (mut x, mut v) = (0.0f64, 0.0f64);
            for k in 1..n {
                let (u0, u1) = (u(k - 1), u(k));
                let xn = d.phi[0][0] * x + d.phi[0][1] * v + d.g0[0] * u0 + d.g1[0] * u1;
                let vn = d.phi[1][0] * x + d.phi[1][1] * v + d.g0[1] * u0 + d.g1[1] * u1;
                x = xn;
                v = vn;
                let out = x + kv * v;
                for (yi, ci) in y.iter_mut().zip(m.output) {
                    yi[k] += ci * out;
                }
            }
        }
        y
    }

    /// As [`Self::measure`], through the analog front end `b` on every
    /// channel: per mode, (1 + 2ζs/ω)·B(s)/(s² + 2ζωs + ω²) is expanded in
    /// partial fractions over its simple poles and each term is discretized
    /// exactly for the linear input b_r·F ([`pole_sum_response`]). Refuses a
    /// front-end pole within 1e-9 (relative) of a mode's pole.
    pub fn measure_through(&self, b: &Butterworth, force: [&[f64]; 3], fs_hz: f64) -> Result<[Vec<f64>; 3]> {
        let n = force[0].len().min(force[1].len()).min(force[2].len());
        let bp = b.poles();
        let wc_n = (2.0 * PI * b.fc_hz).powi(b.order as i32);
        let mut y: [Vec<f64>; 3] = std::array::from_fn(|_| vec![0.0; n]);
        for m in &self.modes {
            let (w, z) = (m.omega(), m.zeta);
            let p = m.pole();
            let num = |s: Complex64| 1.0 + 2.0 * z * s / w;
            let mut terms: Vec<(Complex64, Complex64)> = Vec::with_capacity(2 + bp.len());
            for q in [p, p.conj()] {
                let other = if q == p { p.conj() } else { p };
                terms.push((q, num(q) / (q - other) * b.at(q)));
            }
            for (i, &q) in bp.iter().enumerate() {
                if (q - p).norm() < 1e-9 * p.norm() || (q - p.conj()).norm() < 1e-9 * p.norm() {
                    bail!(
                        "analog front end: a pole of the Butterworth at {} Hz coincides with the mode at {:.1} Hz",
                        b.fc_hz,
                        m.fn_hz
                    );
                }
                let den: Complex64 = bp.iter().enumerate().filter(|(j, _)| *j != i).map(|(_, &ql)| q - ql).product();
                terms.push((q, wc_n / den * num(q) / ((q - p) * (q - p.conj()))));
            }
            let u: Vec<f64> = (0..n).map(|k| m.modal_force(force, k)).collect();
            let out = pole_sum_response(&terms, &u, fs_hz);
            for (yi, ci) in y.iter_mut().zip(m.output) {
                for (v, o) in yi.iter_mut().zip(&out) {
                    *v += ci * o;
                }
            }
        }
        Ok(y)
    }
}
