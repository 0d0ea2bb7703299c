//! Simulated impact-hammer tests: H1 FRF estimate and coherence from averaged
//! auto- and cross-spectra, line by line ([`impact_test_channels`] and its
//! single-channel and three-axis forms).

use num_complex::Complex64;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::dynamometer::{Dynamometer, MultiAxisDynamometer};
use crate::frf::{AxisFrf, Frf};

/// Parameters of a simulated impact test.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImpactParams {
    /// Number of frequency lines, starting at 0 Hz (4097: 0..=4096 Hz at 1 Hz).
    pub n_lines: usize,
    /// Line spacing (Hz).
    pub df_hz: f64,
    /// Number of averaged impacts (7 in the paper).
    pub n_impacts: usize,
    /// Hammer spectrum cutoff (Hz): flat below, falling above.
    pub hammer_cutoff_hz: f64,
    /// Roll-off order above the cutoff (|S| ∝ f^-order).
    pub hammer_order: f64,
    /// Relative per-impact spread of the cutoff (uniform ±).
    pub cutoff_spread: f64,
    /// Relative per-impact spread of the impact strength (uniform ±).
    pub amplitude_spread: f64,
    /// Output (dynamometer channel) noise RMS per line per impact, relative to
    /// the flat hammer spectrum level.
    pub output_noise_rel: f64,
    /// Input (hammer load cell) noise RMS per line per impact, same scale.
    pub input_noise_rel: f64,
    /// Output noise multiplier at 0 Hz (drift / AC coupling of the charge
    /// amplifier): the multiplier is `1 + (dc_noise_factor-1)·exp(-f/low_freq_noise_hz)`.
    pub dc_noise_factor: f64,
    /// Decay frequency of the low-frequency noise rise (Hz).
    pub low_freq_noise_hz: f64,
}

impl Default for ImpactParams {
    fn default() -> Self {
        Self {
            n_lines: 4097,
            df_hz: 1.0,
            n_impacts: 7,
            hammer_cutoff_hz: 3000.0,
            hammer_order: 6.0,
            cutoff_spread: 0.05,
            amplitude_spread: 0.2,
            output_noise_rel: 0.03,
            input_noise_rel: 0.002,
            dc_noise_factor: 100.0,
            low_freq_noise_hz: 3.0,
        }
    }
}

impl ImpactParams {
    /// Nominal hammer spectrum magnitude at `f_hz` (1 in the flat band).
    pub fn hammer_spectrum(&self, f_hz: f64) -> f64 {
        hammer(f_hz, self.hammer_cutoff_hz, self.hammer_order)
    }
}

fn hammer(f_hz: f64, fc: f64, order: f64) -> f64 {
    1.0 / (1.0 + (f_hz.abs() / fc).powf(2.0 * order)).sqrt()
}

/// Frequency lines `k·df_hz`, k = 0..n_lines.
pub fn impact_freqs(n_lines: usize, df_hz: f64) -> Vec<f64> {
    (0..n_lines).map(|k| k as f64 * df_hz).collect()
}

/// Simulated impact test of one axis: H1 estimate and coherence on the lines
/// `k·df_hz`, k = 0..n_lines (line 0 is DC, with low coherence). The returned
/// [`AxisFrf`] has `axis = 0`; use [`impact_test_axis`] or [`impact_test_all`]
/// to label it. `params.n_lines`/`df_hz` are ignored here (the arguments rule).
pub fn impact_test(dyn_: &Dynamometer, n_lines: usize, df_hz: f64, seed: u64, params: &ImpactParams) -> AxisFrf {
    impact_test_axis(dyn_, 0, n_lines, df_hz, seed, params)
}

/// As [`impact_test`], labelled with `axis`.
pub fn impact_test_axis(
    dyn_: &Dynamometer,
    axis: usize,
    n_lines: usize,
    df_hz: f64,
    seed: u64,
    params: &ImpactParams,
) -> AxisFrf {
    impact_test_fn(&|f| dyn_.frf(f), axis, n_lines, df_hz, seed, params)
}

/// As [`impact_test_axis`], for any true response `g(f_hz)` (e.g. the
/// dynamometer through an analog front end).
pub fn impact_test_fn(
    g: &dyn Fn(f64) -> Complex64,
    axis: usize,
    n_lines: usize,
    df_hz: f64,
    seed: u64,
    params: &ImpactParams,
) -> AxisFrf {
    let mut out = impact_test_channels(&|f, y: &mut [Complex64]| y[0] = g(f), 1, n_lines, df_hz, seed, params);
    let (frf, coh) = out.remove(0);
    AxisFrf { axis, frf, coherence: Some(coh) }
}

/// One impact test recording `n_channels` channels at once (a hammer
/// direction of a multi-component dynamometer): every channel sees the same
/// impacts and the same hammer load-cell signal, each with its own output
/// noise; `g(f_hz, out)` writes the channels' true responses at `f_hz` into
/// `out`. Returns (H1, coherence) per channel. With one channel this is
/// [`impact_test_fn`], draw for draw.
///
/// Per impact i and line f the analyser sees the hammer force
/// `X_i(f) = a_i·S_i(f) + n_x` and the dynamometer output
/// `Y_i(f) = G(f)·a_i·S_i(f) + n_y`, with a_i the impact strength (random spread),
/// `|S_i(f)| = 1/sqrt(1 + (f/fc_i)^(2·order))` the hammer tip's spectrum (flat to
/// the cutoff fc_i, which jitters per impact, then falling), and n_x, n_y
/// circular complex Gaussian noise. The output noise is white in the flat band
/// (`output_noise_rel`, relative to the flat hammer level) and grows towards
/// 0 Hz (charge-amplifier drift/AC coupling), reaching `dc_noise_factor` times
/// that at line 0. Then `Gxx = Σ|X|²`, `Gyy = Σ|Y|²`, `Gxy = Σ X̄·Y`,
/// `H1 = Gxy/Gxx`, `γ² = |Gxy|²/(Gxx·Gyy)`. Coherence therefore falls where the
/// hammer spectrum rolls off, at anti-resonances (|G| small) and at low
/// frequency, as in a real test; it is never invented.
pub fn impact_test_channels(
    g: &dyn Fn(f64, &mut [Complex64]),
    n_channels: usize,
    n_lines: usize,
    df_hz: f64,
    seed: u64,
    params: &ImpactParams,
) -> Vec<(Vec<Complex64>, Vec<f64>)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n_imp = params.n_impacts.max(1);
    // Per-impact strength and cutoff.
    let uni = |rng: &mut ChaCha8Rng, spread: f64| {
        let u: f64 = rand::RngExt::random_range(rng, -1.0..1.0);
        1.0 + spread * u
    };
    let impacts: Vec<(f64, f64)> = (0..n_imp)
        .map(|_| {
            (uni(&mut rng, params.amplitude_spread), params.hammer_cutoff_hz * uni(&mut rng, params.cutoff_spread))
        })
        .collect();
    let cgauss = |rng: &mut ChaCha8Rng, rms: f64, real_only: bool| {
        // Circular complex Gaussian with E|n|² = rms² (real Gaussian at DC).
        let a: f64 = StandardNormal.sample(rng);
        if real_only {
            Complex64::new(rms * a, 0.0)
        } else {
            let b: f64 = StandardNormal.sample(rng);
            Complex64::new(a, b) * (rms / std::f64::consts::SQRT_2)
        }
    };
    let mut out: Vec<(Vec<Complex64>, Vec<f64>)> =
        (0..n_channels).map(|_| (Vec::with_capacity(n_lines), Vec::with_capacity(n_lines))).collect();
    let mut gk = vec![Complex64::new(0.0, 0.0); n_channels];
    let mut gyy = vec![0.0f64; n_channels];
    let mut gxy = vec![Complex64::new(0.0, 0.0); n_channels];
    for k in 0..n_lines {
        let f = k as f64 * df_hz;
        g(f, &mut gk);
        let real_only = f == 0.0;
        let out_rms = params.output_noise_rel
            * (1.0 + (params.dc_noise_factor - 1.0).max(0.0) * (-f / params.low_freq_noise_hz.max(1e-12)).exp());
        let mut gxx = 0.0f64;
        gyy.iter_mut().for_each(|v| *v = 0.0);
        gxy.iter_mut().for_each(|v| *v = Complex64::new(0.0, 0.0));
        for &(a, fc) in &impacts {
            let x_true = a * hammer(f, fc, params.hammer_order);
            let x = Complex64::new(x_true, 0.0) + cgauss(&mut rng, params.input_noise_rel, real_only);
            gxx += x.norm_sqr();
            for c in 0..n_channels {
                let y = gk[c] * x_true + cgauss(&mut rng, out_rms, real_only);
                gyy[c] += y.norm_sqr();
                gxy[c] += x.conj() * y;
            }
        }
        for (c, (frf, coh)) in out.iter_mut().enumerate() {
            let h1 = if gxx > 0.0 { gxy[c] / gxx } else { Complex64::new(0.0, 0.0) };
            let v = if gxx > 0.0 && gyy[c] > 0.0 { (gxy[c].norm_sqr() / (gxx * gyy[c])).clamp(0.0, 1.0) } else { 0.0 };
            frf.push(h1);
            coh.push(v);
        }
    }
    out
}

/// Impact tests of all three axes (independent noise per axis) on
/// `n_lines` lines at `df_hz`.
pub fn impact_test_all(
    dyno: &MultiAxisDynamometer,
    n_lines: usize,
    df_hz: f64,
    seed: u64,
    params: &ImpactParams,
) -> Frf {
    impact_test_all_with(&|a, f| dyno.axis(a).frf(f), n_lines, df_hz, seed, params)
}

/// As [`impact_test_all`], for the true responses `g(axis, f_hz)` of the
/// three axes (e.g. through the acquisition chain's analog front end).
pub fn impact_test_all_with(
    g: &dyn Fn(usize, f64) -> Complex64,
    n_lines: usize,
    df_hz: f64,
    seed: u64,
    params: &ImpactParams,
) -> Frf {
    let axes = (0..3)
        .map(|a| {
            let s = seed.wrapping_mul(0xA076_1D64_78BD_642F).wrapping_add(0xE703_7ED1_A0B4_28DB ^ (a as u64 + 1));
            impact_test_fn(&|f| g(a, f), a, n_lines, df_hz, s, params)
        })
        .collect();
    Frf::direct(impact_freqs(n_lines, df_hz), axes)
}

/// Normalized random error of an H1 magnitude estimate from `n_avg` averages
/// at coherence `coh` (Bendat & Piersol): sqrt(1-γ²)/(|γ|·sqrt(2·n_avg)).
pub fn h1_random_error(coh: f64, n_avg: usize) -> f64 {
    let c = coh.clamp(1e-12, 1.0);
    ((1.0 - c) / c).sqrt() / (2.0 * n_avg as f64).sqrt()
}
