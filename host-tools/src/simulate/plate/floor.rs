//! The noise floor of the exact inverse (DESIGN.md, "Accuracy"): white
//! measurement noise through G⁻¹, in the band, relative to the truth's
//! standard deviation ([`inverse_noise_floor`]), and the per-axis floor.

use anyhow::{bail, Result};
use nalgebra::Matrix3;
use num_complex::Complex64;

/// Grid step of the integral (Hz, at most).
pub const FLOOR_STEP_HZ: f64 = 0.25;

/// Largest condition number of G accepted: past it G⁻¹ is noise.
pub const MAX_CONDITION: f64 = 1e8;

/// The band and noise of a floor computation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FloorSpec {
    /// Noise variance per channel (N²).
    pub r_n2: [f64; 3],
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Band (Hz): lo < hi ≤ fs/2.
    pub band_hz: (f64, f64),
    /// Standard deviation of the (band-limited) true force per axis (N).
    pub std_truth_n: [f64; 3],
}

impl FloorSpec {
    fn check(&self) -> Result<()> {
        let (lo, hi) = self.band_hz;
        if !(self.fs_hz.is_finite() && self.fs_hz > 0.0) {
            bail!("noise floor: sample rate {} Hz must be > 0", self.fs_hz);
        }
        if !(lo >= 0.0 && hi > lo && hi <= self.fs_hz / 2.0) {
            bail!("noise floor: band {lo}..{hi} Hz must satisfy 0 ≤ lo < hi ≤ fs/2 = {} Hz", self.fs_hz / 2.0);
        }
        for a in 0..3 {
            if !(self.r_n2[a].is_finite() && self.r_n2[a] >= 0.0) {
                bail!("noise floor: noise variance {} N² of channel {a} must be ≥ 0", self.r_n2[a]);
            }
            if !(self.std_truth_n[a].is_finite() && self.std_truth_n[a] > 0.0) {
                bail!("noise floor: std of the truth {} N of axis {a} must be > 0", self.std_truth_n[a]);
            }
        }
        Ok(())
    }

    /// (2/fs)·trapezoid ∫ v(f) df over the band, per axis, then sqrt/std.
    fn integrate(&self, v: impl Fn(f64) -> Result<[f64; 3]>) -> Result<[f64; 3]> {
        let (lo, hi) = self.band_hz;
        let n = ((hi - lo) / FLOOR_STEP_HZ).ceil().max(1.0) as usize;
        let h = (hi - lo) / n as f64;
        let mut sum = [0.0; 3];
        for k in 0..=n {
            let w = if k == 0 || k == n { 0.5 } else { 1.0 };
            let x = v(lo + k as f64 * h)?;
            for a in 0..3 {
                sum[a] += w * x[a];
            }
        }
        Ok(std::array::from_fn(|a| (2.0 / self.fs_hz * h * sum[a]).sqrt() / self.std_truth_n[a]))
    }
}

/// The exact 3x3 inverse's noise floor per output axis, for the FRF matrix
/// `g(f_hz)`. Refuses a G that is singular or worse conditioned than
/// [`MAX_CONDITION`] anywhere in the band.
///
/// White measurement noise of variance R_j (N²) on channel j, through G⁻¹,
/// in the band, relative to the truth's standard deviation. Per output axis i:
///
/// floor_i = sqrt((2/fs)·∫_band Σ_j R_j |(G⁻¹)_ij(j2πf)|² df) / std(truth_i),
///
/// the floor of any unbiased 3x3 compensator; and the per-axis floor with
/// 1/G_ii, what inverting each direct FRF alone reaches on its noise (its
/// error from the crosstalk comes on top). The integral is the trapezoid rule
/// on a grid of at most [`FLOOR_STEP_HZ`], as for the single-axis floor of
/// the benchmarks.
pub fn inverse_noise_floor(g: &dyn Fn(f64) -> Matrix3<Complex64>, spec: &FloorSpec) -> Result<[f64; 3]> {
    spec.check()?;
    spec.integrate(|f| {
        let m = g(f);
        let sv = m.singular_values();
        let (smax, smin) = (sv.max(), sv.min());
        if !(smin > 0.0 && smax / smin < MAX_CONDITION) {
            bail!("noise floor: G is singular at {f} Hz (condition number {:e}): no inverse", smax / smin);
        }
        let Some(inv) = m.try_inverse() else {
            bail!("noise floor: G is singular at {f} Hz: no inverse");
        };
        // Check the inverse: ‖G·G⁻¹ − I‖ small against the conditioning.
        let res = (m * inv - Matrix3::identity()).norm();
        if res.is_nan() || res >= 1e-6 {
            bail!("noise floor: G⁻¹ at {f} Hz is inaccurate (‖G·G⁻¹ − I‖ = {res:e})");
        }
        Ok(std::array::from_fn(|i| (0..3).map(|j| spec.r_n2[j] * inv[(i, j)].norm_sqr()).sum()))
    })
}

/// The per-axis floor with 1/G_ii (the noise of inverting each direct FRF
/// alone, without its crosstalk error). Refuses a G_ii that vanishes.
pub fn per_axis_noise_floor(g: &dyn Fn(f64) -> Matrix3<Complex64>, spec: &FloorSpec) -> Result<[f64; 3]> {
    spec.check()?;
    spec.integrate(|f| {
        let m = g(f);
        let mut out = [0.0; 3];
        for (i, o) in out.iter_mut().enumerate() {
            let d = m[(i, i)].norm_sqr();
            if !(d > 0.0 && d.is_finite()) {
                bail!("noise floor: G_ii of axis {i} is {} at {f} Hz: no inverse", m[(i, i)]);
            }
            *o = spec.r_n2[i] / d;
        }
        Ok(out)
    })
}
