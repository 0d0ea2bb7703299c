//! The impact test's noise variance per line, averaged over neighbouring
//! lines before it weights a fit.
//!
//! A coherence weight w = γ²/((1 − γ²)|H|²) ([`super::vf::coherence_weights`])
//! is the inverse of v = (1 − γ²)|H|²/γ², the H1 estimate's variance up to
//! the factor 2·n_avg (Bendat & Piersol). That variance is the output
//! noise's spectrum over the hammer's, S_nn/S_ff: a smooth function of
//! frequency. Its estimate on one line comes from n_avg impacts, with about
//! 2(n_avg − 1) degrees of freedom (12 for the paper's 7), so a line where it
//! comes out low by chance gets a weight several times too high, and such
//! lines pull the fit towards their noise. [`smoothed_weights`] averages v
//! over a window of lines that widens with frequency, as the noise's own
//! features do.

use super::seed::line_spacing_hz;

/// Most lines each side of a line that [`smoothed_weights`] averages over:
/// 15 lines in all, about 180 degrees of freedom from 7 impacts.
pub const MAX_HALF_WIDTH: usize = 7;

/// The window's half-width as a fraction of the line's frequency: ±5 %.
/// The charge amplifier's drift, which raises the noise 100-fold below a
/// few hertz, spans a few lines there, and a window of fixed width would
/// spread it over the lines above (the tall plate's x lost 1.9-2.6x to it at
/// ±7 lines everywhere; BENCHMARKS.md, "The impact test's noise, averaged
/// over lines").
pub const RELATIVE_HALF_WIDTH: f64 = 0.05;

/// How a fit weights a line: by the coherence of the line alone, or with the
/// noise variance averaged over neighbouring lines.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LineWeights {
    /// Coherence weights as they are, line by line.
    #[default]
    PerLine,
    /// Coherence weights with their variance averaged over neighbouring
    /// lines ([`smoothed_weights`]).
    Averaged,
}

impl LineWeights {
    /// The weights `w` on the lines `freq_hz` (Hz) as this says.
    pub fn apply(self, freq_hz: &[f64], w: Vec<f64>) -> Vec<f64> {
        match self {
            LineWeights::PerLine => w,
            LineWeights::Averaged => smoothed_weights(freq_hz, &w),
        }
    }
}

/// `w` (weights on the lines `freq_hz`, Hz) with the variance 1/w averaged
/// over the lines k − m..=k + m of positive weight, m = min([`MAX_HALF_WIDTH`],
/// ⌊[`RELATIVE_HALF_WIDTH`]·f_k/Δf⌋) for the median line spacing Δf: w'_k =
/// 1/mean(1/w). Lines of weight 0 keep it (they carry no data).
pub fn smoothed_weights(freq_hz: &[f64], w: &[f64]) -> Vec<f64> {
    let n = w.len().min(freq_hz.len());
    let df = line_spacing_hz(&freq_hz[..n]);
    if !(df > 0.0) {
        return w.to_vec();
    }
    let carries = |v: f64| v > 0.0 && v.is_finite();
    // Prefix sums of the variance and of the lines that carry one.
    let (mut sum, mut count) = (vec![0.0; n + 1], vec![0usize; n + 1]);
    for k in 0..n {
        sum[k + 1] = sum[k] + if carries(w[k]) { 1.0 / w[k] } else { 0.0 };
        count[k + 1] = count[k] + usize::from(carries(w[k]));
    }
    (0..w.len())
        .map(|k| {
            if k >= n || !carries(w[k]) {
                return w[k];
            }
            let m = ((RELATIVE_HALF_WIDTH * freq_hz[k].abs() / df).floor() as usize).min(MAX_HALF_WIDTH);
            let (a, b) = (k.saturating_sub(m), (k + m + 1).min(n));
            let (v, c) = (sum[b] - sum[a], count[b] - count[a]);
            c as f64 / v
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{ChiSquared, Distribution};

    /// The true variance of a line: white output noise over a hammer that
    /// rolls off above 3 kHz, and the charge amplifier's drift 100-fold at
    /// 0 Hz, decaying over 3 Hz (as `simulate::impact`).
    fn true_variance(f: f64) -> f64 {
        let hammer = 1.0 / (1.0 + (f / 3000.0).powi(12));
        let drift = 1.0 + 99.0 * (-f / 3.0).exp();
        drift * drift / hammer
    }

    /// Per line, the variance estimated from 7 impacts (12 degrees of
    /// freedom): the averaged weights follow the true inverse
    /// variance to within ±50 % on every line from 150 Hz to 4 kHz,
    /// where the per-line ones (the control) are off by more than that on
    /// hundreds of lines. Below
    /// 20 Hz the window is one line and the drift's rise is kept as it was.
    #[test]
    fn averaged_over_lines_the_weights_follow_the_true_variance() {
        let freq: Vec<f64> = (0..4097).map(f64::from).collect();
        let chi2 = ChiSquared::new(12.0).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let raw: Vec<f64> = freq.iter().map(|f| 12.0 / (true_variance(*f) * chi2.sample(&mut rng))).collect();
        let smooth = smoothed_weights(&freq, &raw);
        let off = |w: &[f64], k: usize| (w[k] * true_variance(freq[k]) - 1.0).abs();
        let band = 150..4000;
        let worst = band.clone().map(|k| off(&smooth, k)).fold(0.0, f64::max);
        assert!(worst < 0.5, "averaged weights off the truth by up to {worst}");
        let control = band.filter(|&k| off(&raw, k) > 0.5).count();
        assert!(control > 500, "control: only {control} per-line weights off by half");
        for k in 0..20 {
            assert!((smooth[k] / raw[k] - 1.0).abs() < 1e-9, "line {k}: the drift's lines are their own");
        }
    }

    /// Lines of weight 0 keep it and do not enter their neighbours' mean;
    /// a constant variance is left as it is.
    #[test]
    fn lines_without_data_stay_out_of_the_average() {
        let freq: Vec<f64> = (0..400).map(|k| 0.5 * f64::from(k)).collect();
        let mut w = vec![4.0; 400];
        w[300] = 0.0;
        let s = smoothed_weights(&freq, &w);
        assert_eq!(s[300], 0.0);
        assert!(s.iter().enumerate().all(|(k, v)| k == 300 || (v - 4.0).abs() < 1e-12), "{s:?}");
        // Control: a line of ten times the variance lowers its neighbours'
        // weights.
        w[200] = 0.4;
        let s = smoothed_weights(&freq, &w);
        assert!(s[203] < 3.5 && s[200] > 0.4, "{} {}", s[203], s[200]);
    }
}
