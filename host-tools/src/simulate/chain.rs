//! The acquisition chain between the dynamometer and the samples: an optional
//! analog front end (e.g. the box's 4th-order Butterworth at 12 kHz), then the
//! DAQ's sigma-delta decimation filter, modelled as an ideal zero-phase brick
//! wall at [`BRICK_WALL_FRACTION`]·fs, then sampling at fs (noise and ADC
//! quantization come after, see [`super::measurement`]).

use anyhow::{bail, Context, Result};
use num_complex::Complex64;
use rustfft::FftPlanner;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

use super::dynamometer::{phi_k, Dynamometer};

/// Cutoff of the DAQ's decimation filter as a fraction of the sample rate.
pub const BRICK_WALL_FRACTION: f64 = 0.45;

/// Output samples of lead-in and of lead-out around the record for the
/// brick-wall FFT (the lead-out's second half is the taper).
pub const EDGE_SAMPLES: usize = 2048;

/// An analog Butterworth low-pass, |B(j2πf)|² = 1/(1 + (f/fc)^(2·order)).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Butterworth {
    /// Filter order (1..=12).
    pub order: u32,
    /// −3 dB frequency (Hz).
    pub fc_hz: f64,
}

impl Butterworth {
    /// Poles in the s-plane (rad/s): ωc·e^{jπ(2k+n+1)/(2n)}, k = 0..n.
    pub fn poles(&self) -> Vec<Complex64> {
        let n = self.order as f64;
        let wc = 2.0 * PI * self.fc_hz;
        (0..self.order).map(|k| Complex64::from_polar(wc, PI * (2.0 * k as f64 + n + 1.0) / (2.0 * n))).collect()
    }

    /// B(s) = ωc^n / Π(s − p_k), at a complex s (rad/s).
    pub fn at(&self, s: Complex64) -> Complex64 {
        let wc = 2.0 * PI * self.fc_hz;
        self.poles().iter().fold(Complex64::new(wc.powi(self.order as i32), 0.0), |acc, p| acc / (s - p))
    }

    /// B(j2πf).
    pub fn frf(&self, f_hz: f64) -> Complex64 {
        self.at(Complex64::new(0.0, 2.0 * PI * f_hz))
    }
}

/// The acquisition chain of one channel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum AntiAlias {
    /// No filter: every `oversample`-th sample is kept as it is (the
    /// simulator before issue #12; the truth then holds aliases).
    None,
    /// The DAQ's ideal sigma-delta brick wall at 0.45 fs, zero-phase (default).
    #[default]
    Ideal,
    /// An analog Butterworth front end (causal, with its phase) in front of
    /// the ideal brick wall.
    Butterworth(Butterworth),
}

impl std::str::FromStr for AntiAlias {
    type Err = anyhow::Error;

    /// `ideal`, `none` or `butterworth:ORDER:FC_HZ`.
    fn from_str(s: &str) -> Result<Self> {
        let parts: Vec<&str> = s.trim().split(':').collect();
        match parts.as_slice() {
            ["ideal"] => Ok(AntiAlias::Ideal),
            ["none"] => Ok(AntiAlias::None),
            ["butterworth", order, fc] => {
                let order: u32 =
                    order.parse().with_context(|| format!("--anti-alias {s}: order {order:?} is not an integer"))?;
                let fc_hz: f64 =
                    fc.parse().with_context(|| format!("--anti-alias {s}: cutoff {fc:?} is not a number"))?;
                let b = AntiAlias::Butterworth(Butterworth { order, fc_hz });
                b.validate()?;
                Ok(b)
            }
            _ => bail!("--anti-alias {s}: expected ideal, none or butterworth:ORDER:FC_HZ"),
        }
    }
}

impl std::fmt::Display for AntiAlias {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AntiAlias::None => write!(f, "none"),
            AntiAlias::Ideal => write!(f, "ideal"),
            AntiAlias::Butterworth(b) => write!(f, "butterworth:{}:{}", b.order, b.fc_hz),
        }
    }
}

impl AntiAlias {
    /// Check the filter; the error names it.
    pub fn validate(&self) -> Result<()> {
        if let AntiAlias::Butterworth(b) = self {
            if !((1..=12).contains(&b.order) && b.fc_hz.is_finite() && b.fc_hz > 0.0) {
                bail!(
                    "anti-alias butterworth: order {} must be in 1..=12 and cutoff {} Hz finite and > 0",
                    b.order,
                    b.fc_hz
                );
            }
        }
        Ok(())
    }

    /// The analog front end, if any.
    pub fn analog(&self) -> Option<&Butterworth> {
        match self {
            AntiAlias::Butterworth(b) => Some(b),
            _ => None,
        }
    }

    /// Whether the brick wall at 0.45 fs is applied.
    pub fn brick_wall(&self) -> bool {
        !matches!(self, AntiAlias::None)
    }

    /// Brick-wall cutoff (Hz) at sample rate `fs_hz`, or `None`.
    pub fn brick_wall_hz(&self, fs_hz: f64) -> Option<f64> {
        self.brick_wall().then_some(BRICK_WALL_FRACTION * fs_hz)
    }

    /// Response of the analog part at `f_hz` (1 without a front end): what an
    /// impact test through this chain measures besides G (the brick wall is
    /// flat in band; the impact analyzer has its own, higher rate).
    pub fn analog_frf(&self, f_hz: f64) -> Complex64 {
        self.analog().map_or(Complex64::new(1.0, 0.0), |b| b.frf(f_hz))
    }

    /// Fine samples of force to generate for `n` output samples: the record
    /// plus the lead-out the brick wall needs.
    pub fn fine_len(&self, n: usize, oversample: usize) -> usize {
        let os = oversample.max(1);
        let n_fine = (n.max(1) - 1) * os + 1;
        if self.brick_wall() {
            n_fine + EDGE_SAMPLES * os
        } else {
            n_fine
        }
    }

    /// Measure `force_fine` (rate fs·oversample, from t = 0, at least
    /// [`Self::fine_len`] samples) with `dyn_` through this chain: returns
    /// (band-limited truth, noise-free measurement), `n` samples each at fs.
    pub fn acquire(
        &self,
        dyn_: &Dynamometer,
        force_fine: &[f64],
        fs_hz: f64,
        oversample: usize,
        n: usize,
    ) -> (Vec<f64>, Vec<f64>) {
        let f_fine = fs_hz * oversample.max(1) as f64;
        let y = match self.analog() {
            None => dyn_.measure(force_fine, f_fine),
            Some(b) => measure_through(dyn_, b, force_fine, f_fine),
        };
        self.acquire_response(force_fine, &y, fs_hz, oversample, n)
    }

    /// As [`Self::acquire`], with the dynamometer's response `y` to
    /// `force_fine` (rate fs·oversample, including any analog front end)
    /// already computed, e.g. by a drifting model
    /// ([`super::drift::measure_drifting`]).
    ///
    /// The continuous applied force is the piecewise-linear interpolant of its
    /// fine samples (rate fs·oversample), which is also what the dynamometer model
    /// integrates exactly ([`super::Dynamometer::measure`]). Its spectrum below
    /// the brick wall is the fine samples' spectrum × sinc²(πf/f_fine), so the
    /// band-limited truth carries that factor: then, below 0.45 fs, the sampled
    /// truth and the sampled measurement are related exactly by G(j2πf)·B(j2πf)
    /// (B the analog front end), as they are in a real chain.
    pub fn acquire_response(
        &self,
        force_fine: &[f64],
        y: &[f64],
        fs_hz: f64,
        oversample: usize,
        n: usize,
    ) -> (Vec<f64>, Vec<f64>) {
        let os = oversample.max(1);
        let f_fine = fs_hz * os as f64;
        let decimate = |x: &[f64]| -> Vec<f64> { x.iter().step_by(os).take(n).copied().collect() };
        let Some(fc) = self.brick_wall_hz(fs_hz) else {
            return (decimate(force_fine), decimate(y));
        };
        // The piecewise-linear force's spectrum: the samples' × sinc²(πf/f_fine).
        let sinc2 = |f: f64| {
            let x = PI * f / f_fine;
            if x == 0.0 {
                1.0
            } else {
                (x.sin() / x).powi(2)
            }
        };
        let truth = band_limit(force_fine, f_fine, os, |f| if f <= fc { sinc2(f) } else { 0.0 });
        let clean = band_limit(y, f_fine, os, |f| if f <= fc { 1.0 } else { 0.0 });
        (decimate(&truth), decimate(&clean))
    }
}

/// Zero-phase filter `gain(|f|)` applied by FFT to `x` (rate `f_fine`) with
/// EDGE_SAMPLES·os zeros in front and the last EDGE_SAMPLES/2·os samples
/// tapered to zero (raised cosine); returns the filtered samples of `x`.
///
/// The lead-in is zeros because the force is zero before the cut starts; the
/// taper makes the circular FFT join zero to zero; both are dropped
/// afterwards.
fn band_limit(x: &[f64], f_fine: f64, os: usize, gain: impl Fn(f64) -> f64) -> Vec<f64> {
    let lead = EDGE_SAMPLES * os;
    let taper = (EDGE_SAMPLES / 2 * os).min(x.len());
    let len = (lead + x.len()).div_ceil(4096) * 4096;
    let mut buf = vec![Complex64::new(0.0, 0.0); len];
    let t0 = x.len() - taper;
    for (k, v) in x.iter().enumerate() {
        let w = if k < t0 { 1.0 } else { 0.5 * (1.0 + (PI * (k - t0) as f64 / taper as f64).cos()) };
        buf[lead + k] = Complex64::new(v * w, 0.0);
    }
    let mut planner = FftPlanner::<f64>::new();
    planner.plan_fft_forward(len).process(&mut buf);
    for (k, v) in buf.iter_mut().enumerate() {
        *v *= gain(k.min(len - k) as f64 * f_fine / len as f64);
    }
    planner.plan_fft_inverse(len).process(&mut buf);
    buf[lead..lead + x.len()].iter().map(|v| v.re / len as f64).collect()
}

/// Response of G(s)·B(s) to the piecewise-linear `force` (rate `fs_hz`) from
/// rest, exact up to rounding: the product is expanded in partial fractions
/// Σ ρ_i/(s − p_i) over the (simple) poles of G and B, and each first-order
/// term is discretized exactly for a linear input on each step (as the modes
/// are in [`Dynamometer::measure`]). The output is Re Σ x_i (conjugate poles
/// come in pairs, so the imaginary parts cancel).
pub fn measure_through(dyn_: &Dynamometer, b: &Butterworth, force: &[f64], fs_hz: f64) -> Vec<f64> {
    let g_at = |s: Complex64| -> Complex64 {
        dyn_.modes
            .iter()
            .map(|m| {
                let w = m.omega();
                m.residue * w * w / (s * s + 2.0 * m.zeta * w * s + w * w)
            })
            .sum()
    };
    let mut terms: Vec<(Complex64, Complex64)> = Vec::new();
    for m in &dyn_.modes {
        let (w, z) = (m.omega(), m.zeta);
        let p = Complex64::new(-z * w, w * (1.0 - z * z).sqrt());
        for p in [p, p.conj()] {
            // Residue of r ω²/((s − p)(s − p̄)) at p, times B(p).
            terms.push((p, m.residue * w * w / (p - p.conj()) * b.at(p)));
        }
    }
    let bp = b.poles();
    let wc_n = (2.0 * PI * b.fc_hz).powi(b.order as i32);
    for (i, &q) in bp.iter().enumerate() {
        let den: Complex64 = bp.iter().enumerate().filter(|(j, _)| *j != i).map(|(_, &ql)| q - ql).product();
        terms.push((q, wc_n / den * g_at(q)));
    }
    pole_sum_response(&terms, force, fs_hz)
}

/// Response Re Σ_i x_i of Σ_i ρ_i/(s − p_i) to the piecewise-linear `input`
/// (rate `fs_hz`) from rest, each first-order term discretized exactly for a
/// linear input on each step. The terms must hold conjugate poles in pairs
/// (with conjugate residues) for the sum to be the real response.
pub(crate) fn pole_sum_response(terms: &[(Complex64, Complex64)], input: &[f64], fs_hz: f64) -> Vec<f64> {
    let h = 1.0 / fs_hz;
    let mut y = vec![0.0; input.len()];
    for &(p, rho) in terms {
        // x⁺ = e^{ph} x + ρh[(φ1 − φ2)(ph)·u0 + φ2(ph)·u1]
        let ph = p * h;
        let e = phi_k(0, ph);
        let (p1, p2) = (phi_k(1, ph), phi_k(2, ph));
        let c0 = rho * h * (p1 - p2);
        let c1 = rho * h * p2;
        let mut x = Complex64::new(0.0, 0.0);
        for k in 1..input.len() {
            x = e * x + c0 * input[k - 1] + c1 * input[k];
            y[k] += x.re;
        }
    }
    y
}
