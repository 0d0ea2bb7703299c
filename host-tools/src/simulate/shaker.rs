//! Shaker excitations of the seed paper's validation tests (§5, Figs. 8-9):
//! a pure sine and linear chirp sweeps, applied instead of a cutting force;
//! and band-limited random noise, the force whose spectrum the design's
//! default criterion assumes (flat in the band, DESIGN.md "Accuracy").
//!
//! The sine and the chirp are the same on the three axes: three single-axis
//! shaker tests in one record. The noise is independent on each axis. Each
//! excitation fades in and out over `taper_s` (a raised-cosine window), as a
//! shaker amplifier does, so the record carries no step.

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// A shaker force in place of the milling force.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Excitation {
    /// F(t) = A·sin(2π f t) (Fig. 8: 1185 Hz).
    Sine {
        /// Frequency (Hz).
        freq_hz: f64,
        /// Amplitude A (N).
        amplitude_n: f64,
        /// Fade-in and fade-out time (s).
        taper_s: f64,
    },
    /// Linear sweep F(t) = A·sin(2π(f0 t + (f1 − f0) t²/(2T))) over the record
    /// length T (Fig. 9: 10-650 Hz and 10-1300 Hz).
    Chirp {
        /// Start frequency f0 (Hz).
        f0_hz: f64,
        /// End frequency f1 (Hz).
        f1_hz: f64,
        /// Amplitude A (N).
        amplitude_n: f64,
        /// Fade-in and fade-out time (s).
        taper_s: f64,
    },
    /// Gaussian noise with a flat spectrum in [lo_hz, hi_hz] and none outside
    /// it, RMS `rms_n` (N) on each axis, the axes independent; from `seed`.
    Noise {
        /// Lower band edge (Hz).
        lo_hz: f64,
        /// Upper band edge (Hz).
        hi_hz: f64,
        /// RMS force per axis (N), before the fades.
        rms_n: f64,
        /// Seed of the noise.
        seed: u64,
        /// Fade-in and fade-out time (s).
        taper_s: f64,
    },
}

impl Excitation {
    /// The force a design's predicted error assumes (DESIGN.md, "Accuracy"):
    /// [`Excitation::Noise`] flat from 10 Hz to the scoring band's top at
    /// `fs_hz` ([`crate::metrics::scoring_band_hz`]), `rms_n` (N) per axis,
    /// fading in and out over 10 ms.
    pub fn flat_force(fs_hz: f64, rms_n: f64, seed: u64) -> Excitation {
        Excitation::Noise { lo_hz: 10.0, hi_hz: crate::metrics::scoring_band_hz(fs_hz), rms_n, seed, taper_s: 0.01 }
    }

    /// What truth.json calls this force: `shaker sine`, `shaker chirp` or
    /// `flat noise`.
    pub fn name(&self) -> &'static str {
        match self {
            Excitation::Sine { .. } => "shaker sine",
            Excitation::Chirp { .. } => "shaker chirp",
            Excitation::Noise { .. } => "flat noise",
        }
    }

    /// The highest frequency the excitation carries (Hz).
    pub fn max_hz(&self) -> f64 {
        match self {
            Excitation::Sine { freq_hz, .. } => *freq_hz,
            Excitation::Chirp { f0_hz, f1_hz, .. } => f0_hz.max(*f1_hz),
            Excitation::Noise { hi_hz, .. } => *hi_hz,
        }
    }

    /// Check the parameters; the error names the offending one.
    pub fn validate(&self, fs_hz: f64) -> anyhow::Result<()> {
        let (lo, hi, a, taper) = match self {
            Excitation::Sine { freq_hz, amplitude_n, taper_s } => (*freq_hz, *freq_hz, *amplitude_n, *taper_s),
            Excitation::Chirp { f0_hz, f1_hz, amplitude_n, taper_s } => {
                (f0_hz.min(*f1_hz), f0_hz.max(*f1_hz), *amplitude_n, *taper_s)
            }
            Excitation::Noise { lo_hz, hi_hz, rms_n, taper_s, .. } => {
                if !(lo_hz < hi_hz) {
                    anyhow::bail!("shaker excitation: noise band {lo_hz}-{hi_hz} Hz is empty");
                }
                (*lo_hz, *hi_hz, *rms_n, *taper_s)
            }
        };
        if !(lo.is_finite() && lo > 0.0 && hi < fs_hz / 2.0) {
            anyhow::bail!(
                "shaker excitation: frequencies {lo}-{hi} Hz must lie between 0 and fs/2 = {} Hz",
                fs_hz / 2.0
            );
        }
        if !(a.is_finite() && a > 0.0) {
            if matches!(self, Excitation::Noise { .. }) {
                anyhow::bail!("flat force (--flat-force): the RMS {a} N must be finite and > 0");
            }
            anyhow::bail!("shaker excitation: amplitude {a} N must be finite and > 0");
        }
        if !(taper.is_finite() && taper >= 0.0) {
            anyhow::bail!("shaker excitation: taper {taper} s must be ≥ 0");
        }
        Ok(())
    }

    /// The force (N) at `n` samples t_k = k/fs_hz, the same on x, y and z
    /// (the noise: independent), for a record of `total_s` seconds (the
    /// chirp's sweep time; the fade-out ends there and the force is 0 after
    /// it).
    pub fn force(&self, fs_hz: f64, n: usize, total_s: f64) -> [Vec<f64>; 3] {
        let total = total_s;
        if let Excitation::Noise { lo_hz, hi_hz, rms_n, seed, taper_s } = self {
            return std::array::from_fn(|a| {
                let f = band_noise(fs_hz, n, (*lo_hz, *hi_hz), *rms_n, seed.wrapping_add(a as u64));
                f.iter().enumerate().map(|(k, v)| v * fade(k as f64 / fs_hz, total, *taper_s)).collect()
            });
        }
        let (taper, f): (f64, Vec<f64>) = match self {
            Excitation::Sine { freq_hz, amplitude_n, taper_s } => {
                (*taper_s, (0..n).map(|k| amplitude_n * (2.0 * PI * freq_hz * k as f64 / fs_hz).sin()).collect())
            }
            Excitation::Chirp { f0_hz, f1_hz, amplitude_n, taper_s } => {
                let rate = (f1_hz - f0_hz) / total;
                let f = (0..n)
                    .map(|k| {
                        let t = k as f64 / fs_hz;
                        amplitude_n * (2.0 * PI * (f0_hz * t + 0.5 * rate * t * t)).sin()
                    })
                    .collect();
                (*taper_s, f)
            }
            Excitation::Noise { .. } => unreachable!("returned above"),
        };
        let f: Vec<f64> = f.iter().enumerate().map(|(k, v)| v * fade(k as f64 / fs_hz, total, taper)).collect();
        [f.clone(), f.clone(), f]
    }
}

/// `n` samples at `fs_hz` of Gaussian noise with a flat spectrum on the DFT
/// lines in `band` (Hz) and none elsewhere, scaled to RMS `rms` exactly.
fn band_noise(fs_hz: f64, n: usize, band: (f64, f64), rms: f64, seed: u64) -> Vec<f64> {
    use num_complex::Complex64;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let df = fs_hz / n as f64;
    let mut spec = vec![Complex64::new(0.0, 0.0); n];
    for k in 1..n.div_ceil(2) {
        let f = k as f64 * df;
        if f >= band.0 && f <= band.1 {
            let (re, im): (f64, f64) = (StandardNormal.sample(&mut rng), StandardNormal.sample(&mut rng));
            spec[k] = Complex64::new(re, im);
            spec[n - k] = spec[k].conj();
        }
    }
    rustfft::FftPlanner::new().plan_fft_inverse(n).process(&mut spec);
    let x: Vec<f64> = spec.iter().map(|c| c.re).collect();
    let now = (x.iter().map(|v| v * v).sum::<f64>() / n.max(1) as f64).sqrt();
    let scale = if now > 0.0 { rms / now } else { 0.0 };
    x.iter().map(|v| v * scale).collect()
}

/// Raised-cosine fade in over [0, taper] and out over [T − taper, T].
fn fade(t: f64, total: f64, taper: f64) -> f64 {
    if taper <= 0.0 {
        return 1.0;
    }
    let edge = t.min(total - t).max(0.0);
    if edge <= 0.0 {
        return 0.0;
    }
    if edge >= taper {
        1.0
    } else {
        0.5 * (1.0 - (PI * edge / taper).cos())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chirp_instantaneous_frequency_sweeps_linearly_from_f0_to_f1() {
        // Zero crossings of the chirp give its instantaneous frequency:
        // near t = T/2 it must be (f0 + f1)/2.
        let fs = 51_200.0;
        let n = 51_200;
        let e = Excitation::Chirp { f0_hz: 10.0, f1_hz: 1300.0, amplitude_n: 1.0, taper_s: 0.0 };
        let x = &e.force(fs, n, 1.0)[0];
        let mid = n / 2;
        let crossings: Vec<f64> =
            (mid - 2000..mid + 2000).filter(|&k| x[k] <= 0.0 && x[k + 1] > 0.0).map(|k| k as f64 / fs).collect();
        let f_mid = (crossings.len() - 1) as f64 / (crossings[crossings.len() - 1] - crossings[0]);
        assert!((f_mid - 655.0).abs() < 5.0, "mid-sweep frequency {f_mid} Hz, expected 655 Hz");
        // negative control: a sine at f0 has no such frequency there
        let s = Excitation::Sine { freq_hz: 10.0, amplitude_n: 1.0, taper_s: 0.0 }.force(fs, n, 1.0);
        let c2 = (mid - 2000..mid + 2000).filter(|&k| s[0][k] <= 0.0 && s[0][k + 1] > 0.0).count();
        assert!(c2 < 3);
    }

    /// The noise's power lies in its band, evenly, at the RMS asked for, and
    /// the axes are independent. Controls: the power outside the band, and
    /// the correlation of an axis with itself.
    #[test]
    fn noise_is_flat_in_its_band_and_independent_across_axes() {
        let (fs, n) = (25_600.0, 1 << 15);
        let e = Excitation::Noise { lo_hz: 10.0, hi_hz: 5_000.0, rms_n: 100.0, seed: 3, taper_s: 0.0 };
        let f = e.force(fs, n, n as f64 / fs);
        let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt();
        assert!(f.iter().all(|x| (rms(x) - 100.0).abs() < 1e-9), "RMS");
        let mut spec: Vec<num_complex::Complex64> = f[0].iter().map(|v| (*v).into()).collect();
        rustfft::FftPlanner::new().plan_fft_forward(n).process(&mut spec);
        let df = fs / n as f64;
        let power = |lo: f64, hi: f64| {
            (1..n / 2).filter(|k| (lo..hi).contains(&(*k as f64 * df))).map(|k| spec[k].norm_sqr()).sum::<f64>()
        };
        let total = power(0.0, fs / 2.0);
        assert!(power(5_001.0, fs / 2.0) < 1e-20 * total, "power above the band");
        // Equal halves of the band carry equal power, within the scatter of
        // ~3000 lines each (χ² with 6000 degrees of freedom: ±2 % at 1σ).
        let (a, b) = (power(10.0, 2_505.0), power(2_505.0, 5_000.0));
        assert!((a / b - 1.0).abs() < 0.1, "halves {a} / {b}");
        let dot = |x: &[f64], y: &[f64]| {
            x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>() / (rms(x) * rms(y) * x.len() as f64)
        };
        assert!(dot(&f[0], &f[1]).abs() < 0.05 && dot(&f[1], &f[2]).abs() < 0.05, "axes correlated");
        assert!((dot(&f[0], &f[0]) - 1.0).abs() < 1e-9);
        // A different seed, a different record.
        let g =
            Excitation::Noise { lo_hz: 10.0, hi_hz: 5_000.0, rms_n: 100.0, seed: 4, taper_s: 0.0 }.force(fs, n, 1.0);
        assert!(dot(&f[0], &g[0]).abs() < 0.05);
    }

    #[test]
    fn taper_removes_the_step_at_both_ends() {
        let e = Excitation::Sine { freq_hz: 1185.0, amplitude_n: 20.0, taper_s: 0.01 };
        let x = &e.force(51_200.0, 25_600, 0.5)[0];
        assert!(x[..20].iter().all(|v| v.abs() < 0.2) && x[x.len() - 20..].iter().all(|v| v.abs() < 0.2));
        let peak = x[5_000..20_000].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!((peak - 20.0).abs() < 0.1, "peak {peak}");
    }
}
