//! Zero-phase band split for parallel elaboration (paper §3.3; DESIGN.md,
//! signal chain step 4, [`split`]). **Offline only**: the split looks at the
//! whole record, past and future. The bands' gains are real and non-negative
//! at every frequency and sum to exactly 1, so the bands add no phase and sum
//! back to the input to rounding.

use anyhow::{bail, Result};
use rustfft::{num_complex::Complex64, FftPlanner};

/// Order n of the Butterworth-squared crossovers ([`lowpass_gain`]).
pub const SPLIT_ORDER: i32 = 8;

/// Zero-phase Butterworth-squared low-pass gain
///
/// ```text
/// L_c(f) = 1 / (1 + (f / f_c)^(2n))          (n = SPLIT_ORDER = 8)
/// ```
///
/// the magnitude-squared of an order-n Butterworth low-pass (analog
/// prototype, −6 dB at f_c): what forward-backward filtering with an order-n
/// Butterworth gives (48 dB/octave per pass, 96 dB/octave in all).
pub fn lowpass_gain(f_hz: f64, crossover_hz: f64) -> f64 {
    1.0 / (1.0 + (f_hz.abs() / crossover_hz).powi(2 * SPLIT_ORDER))
}

/// Gain of band `k` at `f_hz` for the crossovers `f_c,1 < … < f_c,N−1`
/// (Hz) of N bands:
///
/// ```text
/// B_0(f) = L_{c,1}(f),  B_k(f) = L_{c,k+1}(f) − L_{c,k}(f),  B_N−1(f) = 1 − L_{c,N−1}(f)
/// ```
///
/// real and non-negative at every frequency: **zero phase**, and
/// `Σ_k B_k(f) = 1` exactly (the sum telescopes). Band 0 takes everything
/// down to DC, the last band everything up to Nyquist.
pub fn band_gain(f_hz: f64, k: usize, crossovers_hz: &[f64]) -> f64 {
    let upper = crossovers_hz.get(k).map_or(1.0, |c| lowpass_gain(f_hz, *c));
    let lower = if k == 0 { 0.0 } else { crossovers_hz.get(k - 1).map_or(1.0, |c| lowpass_gain(f_hz, *c)) };
    upper - lower
}

/// Split `x` (sampled at `fs_hz`) into `crossovers_hz.len() + 1` bands with
/// the zero-phase gains `B_k` ([`band_gain`]), applied exactly in the
/// frequency domain (FFT of the record, mirrored at both ends to avoid
/// wrap-around, times `B_k(|f|)`, inverse FFT), so there are no start-up
/// transients of a recursive filter. Returns one signal per band, each
/// as long as `x`; they sum to `x` to rounding.
pub fn split(x: &[f64], fs_hz: f64, crossovers_hz: &[f64]) -> Result<Vec<Vec<f64>>> {
    let nyquist = fs_hz / 2.0;
    if let Some(w) = crossovers_hz.windows(2).find(|w| w[0].partial_cmp(&w[1]) != Some(std::cmp::Ordering::Less)) {
        bail!("crossovers must ascend, got {} then {} Hz", w[0], w[1]);
    }
    if let Some(c) = crossovers_hz.iter().find(|c| !(**c > 0.0 && **c < nyquist)) {
        bail!("crossover {c} Hz outside (0, {nyquist}) Hz");
    }
    let n = x.len();
    let n_bands = crossovers_hz.len() + 1;
    if n < 2 || n_bands == 1 {
        // Nothing to split: everything goes to band 0 (the sum stays exact).
        let mut out = vec![vec![0.0; n]; n_bands];
        out[0] = x.to_vec();
        return Ok(out);
    }
    // Even mirror at both ends: [x_{n-1} … x_1] x [x_{n-2} … x_0].
    let pad = n - 1;
    let mut ext: Vec<f64> = Vec::with_capacity(n + 2 * pad);
    ext.extend(x[1..].iter().rev());
    ext.extend_from_slice(x);
    ext.extend(x[..n - 1].iter().rev());
    let m = ext.len();
    let mut planner = FftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(m);
    let inv = planner.plan_fft_inverse(m);
    let mut spec: Vec<Complex64> = ext.iter().map(|v| Complex64::new(*v, 0.0)).collect();
    fwd.process(&mut spec);
    let freq: Vec<f64> = (0..m).map(|i| i.min(m - i) as f64 * fs_hz / m as f64).collect();
    let mut out = Vec::with_capacity(n_bands);
    for k in 0..n_bands {
        let mut buf: Vec<Complex64> =
            spec.iter().zip(&freq).map(|(s, f)| s * band_gain(*f, k, crossovers_hz)).collect();
        inv.process(&mut buf);
        out.push(buf[pad..pad + n].iter().map(|v| v.re / m as f64).collect());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::bands::crossovers;
    use std::f64::consts::PI;

    #[test]
    fn crossovers_sit_in_the_middle_of_the_gaps() {
        let c = crossovers(&[(900.0, 1300.0), (2000.0, 2600.0), (2600.0, 3000.0)]).unwrap();
        assert_eq!(c, vec![1650.0, 2600.0]);
        assert!(crossovers(&[(900.0, 1300.0), (1200.0, 2600.0)]).is_err());
        assert!(crossovers(&[(1300.0, 900.0), (2000.0, 2600.0)]).is_err());
    }

    #[test]
    fn bands_sum_to_the_input_and_gains_sum_to_one() {
        let fs = 51_200.0;
        let c = [1650.0, 2600.0, 6000.0];
        for i in 0..2000 {
            let f = i as f64 * 12.8;
            let s: f64 = (0..4).map(|k| band_gain(f, k, &c)).sum();
            assert!((s - 1.0).abs() < 1e-15, "{f} Hz: {s}");
            assert!((0..4).all(|k| band_gain(f, k, &c) >= -1e-16));
        }
        // a rough record: noise plus a step (content at every frequency)
        let mut seed = 12345u64;
        let x: Vec<f64> = (0..5001)
            .map(|i| {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5 + if i > 2000 { 300.0 } else { 0.0 }
            })
            .collect();
        let bands = split(&x, fs, &c).unwrap();
        assert_eq!(bands.len(), 4);
        let worst = (0..x.len()).map(|i| (bands.iter().map(|b| b[i]).sum::<f64>() - x[i]).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-10, "bands do not sum to the input: {worst:e}");
        // and each band is not trivially the input (the split does something)
        let rms = |v: &[f64]| (v.iter().map(|a| a * a).sum::<f64>() / v.len() as f64).sqrt();
        assert!(rms(&bands[3]) < 0.5 * rms(&x));
    }

    #[test]
    fn each_band_has_the_documented_gain_and_zero_phase() {
        // Sines at exact FFT bins of the mirrored record are eigenfunctions of
        // the split only approximately (the mirror), so score the middle half
        // against the analytic gain B_k(f)·x (zero phase: same waveform).
        let fs = 51_200.0;
        let c = [1650.0, 2600.0];
        let n = 20_000;
        for f in [300.0, 1500.0, 1650.0, 1800.0, 2400.0, 2600.0, 2900.0, 5000.0] {
            let x: Vec<f64> = (0..n).map(|i| (2.0 * PI * f * i as f64 / fs + 0.3).cos()).collect();
            let bands = split(&x, fs, &c).unwrap();
            for (k, b) in bands.iter().enumerate() {
                let g = band_gain(f, k, &c);
                let expected_formula = match k {
                    0 => 1.0 / (1.0 + (f / 1650.0f64).powi(16)),
                    1 => 1.0 / (1.0 + (f / 2600.0f64).powi(16)) - 1.0 / (1.0 + (f / 1650.0f64).powi(16)),
                    _ => 1.0 - 1.0 / (1.0 + (f / 2600.0f64).powi(16)),
                };
                assert!((g - expected_formula).abs() < 1e-12);
                let err = (n / 4..3 * n / 4).map(|i| (b[i] - g * x[i]).abs()).fold(0.0, f64::max);
                assert!(err < 2e-3, "band {k} at {f} Hz: gain {g}, max deviation from g·x {err:e}");
            }
        }
        // at a crossover both neighbouring bands carry exactly half
        assert!((band_gain(1650.0, 0, &c) - 0.5).abs() < 1e-12);
        assert!((band_gain(1650.0, 1, &c) - 0.5).abs() < 1e-3);
    }

    #[test]
    fn bad_crossovers_are_refused() {
        assert!(split(&[0.0; 100], 1000.0, &[600.0]).is_err());
        assert!(split(&[0.0; 100], 1000.0, &[200.0, 100.0]).is_err());
        assert!(split(&[0.0; 100], 1000.0, &[0.0]).is_err());
    }
}
