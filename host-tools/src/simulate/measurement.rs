//! The measurement chain after the dynamometer: white noise of variance R
//! (charge amplifier + DAQ) and ADC quantization with saturation at the rails.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

/// Noise and ADC model of one measurement channel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeasurementParams {
    /// Variance R of the white measurement noise (N²); the paper measured 0.0519.
    pub noise_variance_n2: f64,
    /// ADC resolution (bits); 0 disables quantization.
    pub adc_bits: u32,
    /// ADC full scale ±range (N); values beyond it saturate at the rails.
    pub adc_range_n: f64,
}

impl Default for MeasurementParams {
    fn default() -> Self {
        Self { noise_variance_n2: 0.05, adc_bits: 16, adc_range_n: 2000.0 }
    }
}

impl MeasurementParams {
    /// Quantization step (N), or 0 without quantization.
    pub fn lsb_n(&self) -> f64 {
        if self.adc_bits == 0 {
            0.0
        } else {
            2.0 * self.adc_range_n / 2f64.powi(self.adc_bits as i32)
        }
    }

    /// Variance expected in an idle record: R + LSB²/12 (N²).
    pub fn expected_idle_variance(&self) -> f64 {
        self.noise_variance_n2 + self.lsb_n().powi(2) / 12.0
    }

    /// Quantize one value: round to the nearest code, saturate at the rails
    /// (codes −2^(bits−1) ..= 2^(bits−1)−1).
    pub fn quantize(&self, v: f64) -> f64 {
        if self.adc_bits == 0 {
            return v;
        }
        let lsb = self.lsb_n();
        let half = 2f64.powi(self.adc_bits as i32 - 1);
        (v / lsb).round().clamp(-half, half - 1.0) * lsb
    }

    /// `clean` (the dynamometer output, N) plus noise from `seed`, quantized.
    pub fn apply(&self, clean: &[f64], seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let sd = self.noise_variance_n2.max(0.0).sqrt();
        let normal = Normal::new(0.0, sd).expect("finite, non-negative standard deviation");
        clean.iter().map(|&v| self.quantize(v + normal.sample(&mut rng))).collect()
    }

    /// An idle record of `n` samples (spindle running, no engagement): noise and
    /// quantization only, the same model as [`Self::apply`].
    pub fn idle(&self, n: usize, seed: u64) -> Vec<f64> {
        self.apply(&vec![0.0; n], seed)
    }
}
