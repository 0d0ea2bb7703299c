//! Accuracy scoring of compensated forces against a known true force, in
//! the one convention of DESIGN.md, "Accuracy, stated one way everywhere"
//! ([`accuracy`]).

use rustfft::{num_complex::Complex64, FftPlanner};

/// Upper edge of the scoring band at `fs_hz` (DESIGN.md, README): min(4
/// kHz, 0.4 fs), the band of every accuracy figure of the project (the
/// rates harness, `examples/score.rs`, `compensate --report`).
pub fn scoring_band_hz(fs_hz: f64) -> f64 {
    4000f64.min(0.4 * fs_hz)
}

/// Zero-phase brick-wall low-pass at `f_max_hz` via FFT (circular).
pub fn lowpass(x: &[f64], fs_hz: f64, f_max_hz: f64) -> Vec<f64> {
    keep_frequencies(x, fs_hz, |f| f <= f_max_hz)
}

/// Zero-phase brick-wall band-pass keeping the bins inside any of `bands`
/// (Hz, inclusive) via FFT (circular).
pub fn bandpass(x: &[f64], fs_hz: f64, bands: &[(f64, f64)]) -> Vec<f64> {
    keep_frequencies(x, fs_hz, |f| bands.iter().any(|b| f >= b.0 && f <= b.1))
}

/// Zero-phase FFT filter keeping the bins whose frequency satisfies `keep`.
fn keep_frequencies(x: &[f64], fs_hz: f64, keep: impl Fn(f64) -> bool) -> Vec<f64> {
    let n = x.len();
    if n == 0 {
        return Vec::new();
    }
    let mut planner = FftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(n);
    let inv = planner.plan_fft_inverse(n);
    let mut buf: Vec<Complex64> = x.iter().map(|v| Complex64::new(*v, 0.0)).collect();
    fwd.process(&mut buf);
    for (k, v) in buf.iter_mut().enumerate() {
        let f = (k.min(n - k)) as f64 * fs_hz / n as f64;
        if !keep(f) {
            *v = Complex64::new(0.0, 0.0);
        }
    }
    inv.process(&mut buf);
    buf.iter().map(|v| v.re / n as f64).collect()
}

/// Unbiased sample variance (n − 1), e.g. R (N²) from an idle record.
pub fn sample_variance(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)
}

/// Error figures of an estimate against the truth.
///
/// **NRMSE:** both signals are low-passed at `f_max` with a zero-phase FFT
/// brick-wall filter, the first and last 5 % of the record are dropped (edge
/// effects of the circular filter and the start-up of the compensator), and
/// `NRMSE = RMS(ŝ − s) / std(s)` over what remains, i.e. normalized by the
/// standard deviation of the band-limited true force (MATLAB `goodnessOfFit`
/// 'NRMSE'). The peak-to-peak normalization, which reads about 3-4x smaller
/// for milling forces, is kept only as a second, labelled figure
/// (`nrmse_p2p`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Accuracy {
    /// NRMSE: RMS error / standard deviation of the band-limited truth.
    pub nrmse: f64,
    /// Second, labelled figure: RMS error / peak-to-peak of the truth.
    pub nrmse_p2p: f64,
    /// RMS error (N).
    pub rms_error_n: f64,
}

/// Score `estimate` against `truth`, both sampled at `fs_hz`, below `f_max_hz`.
pub fn accuracy(estimate: &[f64], truth: &[f64], fs_hz: f64, f_max_hz: f64) -> Accuracy {
    accuracy_filtered(estimate, truth, |x| lowpass(x, fs_hz, f_max_hz))
}

/// [`accuracy`] restricted to `bands` (Hz): both signals band-passed to the
/// bands, the NRMSE normalized by the std of the band-passed truth (the
/// seed paper's band-fitting claims are about these bands only).
pub fn accuracy_in_bands(estimate: &[f64], truth: &[f64], fs_hz: f64, bands: &[(f64, f64)]) -> Accuracy {
    accuracy_filtered(estimate, truth, |x| bandpass(x, fs_hz, bands))
}

/// The output as users get it (DESIGN.md, "Accuracy"): the unfiltered
/// `estimate` against `truth` through the anti-aliasing filter alone (the
/// simulator's sampled truth), normalized by the std of that truth, beside
/// what a perfect band-limited estimate (the truth low-passed at
/// `band_hz`) reaches against the same truth. Above the band a good output
/// adds no error, so `output.nrmse / perfect.nrmse` near 1 is the target;
/// below 1 the output recovers part of the force above the band.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct AsWritten {
    /// The unfiltered estimate against the anti-aliased truth.
    pub output: Accuracy,
    /// The truth low-passed to the band, against the same truth.
    pub perfect: Accuracy,
}

/// [`AsWritten`] of `estimate` against the anti-aliased `truth`, sampled at
/// `fs_hz`, compensated band up to `band_hz`.
pub fn accuracy_as_written(estimate: &[f64], truth: &[f64], fs_hz: f64, band_hz: f64) -> AsWritten {
    let n = estimate.len().min(truth.len());
    let perfect_estimate = lowpass(&truth[..n], fs_hz, band_hz);
    AsWritten {
        output: accuracy_filtered(estimate, truth, |x| x.to_vec()),
        perfect: accuracy_filtered(&perfect_estimate, truth, |x| x.to_vec()),
    }
}

fn accuracy_filtered(estimate: &[f64], truth: &[f64], filter: impl Fn(&[f64]) -> Vec<f64>) -> Accuracy {
    let n = estimate.len().min(truth.len());
    let e = filter(&estimate[..n]);
    let t = filter(&truth[..n]);
    let skip = n / 20;
    let (e, t) = (&e[skip..n - skip], &t[skip..n - skip]);
    let m = t.len() as f64;
    let rms = (e.iter().zip(t).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / m).sqrt();
    let (lo, hi) = t.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(*v), h.max(*v)));
    let mean = t.iter().sum::<f64>() / m;
    let std = (t.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / m).sqrt();
    Accuracy { nrmse: rms / std, nrmse_p2p: rms / (hi - lo), rms_error_n: rms }
}
