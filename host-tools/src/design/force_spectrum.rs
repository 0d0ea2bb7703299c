//! Opt-in force spectrum for the box design's q criterion
//! (`design --force-prior spectrum --force-record REC`, or `level`).
//!
//! The default criterion ([`crate::design::axis`]) weighs the distortion alike
//! at every frequency of the band, for a flat force of `--force-rms`. A cutting
//! force is neither flat nor, often, of that level: most of its power sits at
//! the low harmonics of the tooth-passing frequency. Only q changes: the filter
//! keeps the default structure and its cost on the box, and the criterion
//! weighs each line by the force power a representative record has there
//! ([`estimate`], [`CellSpectrum::weights`]).

use anyhow::{bail, Result};
use num_complex::Complex64;
use rustfft::FftPlanner;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Least broadband share of the force power assumed by the criterion (a
/// steady cut is never only lines: entry, exit and feed changes are
/// broadband): 0.1 % of the power, a broadband part of about 3 % RMS. It
/// keeps q_bb from falling so low that the estimate cannot follow what the
/// representative record did not show. On the rates harness's low-mode
/// case (25.6 kHz, z) the measured off-line share is 1.2e-4; 1 % would cost
/// most of the gain (2.04 % instead of 1.33 %), 1e-4 would add little
/// (1.30 %), BENCHMARKS.md.
pub const MIN_BROADBAND_SHARE: f64 = 1e-3;

/// Least ratio of the record's in-band force power (noise removed) to the
/// noise power the raw inverse carries in the same band: below it the
/// record says more about the noise than about the force.
pub const MIN_SIGNAL_TO_NOISE: f64 = 1.0;

/// Longest segment of the spectrum's Welch average (samples): 1.6 Hz
/// resolution at 102.4 kHz, against cells of about 20 Hz; longer records are
/// averaged over half-overlapping segments, in bounded memory.
pub const WELCH_SEGMENT: usize = 1 << 16;

/// A representative record of the cut, one channel per axis (N), sampled
/// at the box's rate: the raw measured forces, as `compensate` reads them.
#[derive(Clone, Debug, Default)]
pub struct ForceRecord {
    /// Where it came from, for messages.
    pub source: String,
    /// Channels fx, fy, fz (None where the record has no column).
    pub channels: [Option<Vec<f64>>; 3],
}

/// The force spectrum of one axis on the criterion's cells.
#[derive(Clone, Debug, PartialEq)]
pub struct CellSpectrum {
    /// Force power per cell (N², noise removed, ≥ 0), in the order of the cells.
    pub power_n2: Vec<f64>,
    /// Noise power the raw inverse carries per cell (N²).
    pub noise_n2: Vec<f64>,
    /// Frequency resolution of the record's spectrum (Hz).
    pub resolution_hz: f64,
}

impl CellSpectrum {
    /// In-band force power P_F (N²).
    pub fn total_n2(&self) -> f64 {
        self.power_n2.iter().sum()
    }

    /// The criterion's weights w_i, Σ = 1. With them the criterion is
    ///
    /// J = Σ_i w_i |H(f_i)Ĝ(f_i)e^{j2πf_iL/fs} − 1|² + (2R/fs)·W·mean_i |H(f_i)|² / P_F,
    /// w_i = (1 − β)·P_i/P_F + β/n,
    ///
    /// with P_i the record's force power in line i's cell, P_F = Σ P_i, W the
    /// criterion's summed band width, n the number of lines and
    /// β = [`MIN_BROADBAND_SHARE`]: a share of the weight spread flat, so that no
    /// frequency is given up entirely (entries, exits and feed changes are
    /// broadband; chatter is not in a steady record). `--force-prior level`
    /// keeps the weights flat (w_i = 1/n) and uses only P_F.
    pub fn weights(&self) -> Vec<f64> {
        let n = self.power_n2.len() as f64;
        let total = self.total_n2();
        self.power_n2.iter().map(|p| (1.0 - MIN_BROADBAND_SHARE) * p / total + MIN_BROADBAND_SHARE / n).collect()
    }
}

/// Estimate the force spectrum of record `y` (N, at `fs_hz`) on `cells`
/// ((lo, hi) Hz, as [`crate::design::criterion::criterion_cells`] lays them out) with
/// the fitted sensor model `g` (Ĝ(j2πf)) and noise variance R (N²): the
/// one-sided power of the raw inverse Y(f)/Ĝ(f) of the Hann-windowed
/// record (Welch average of [`WELCH_SEGMENT`]-sample segments), summed per
/// cell, less the noise R·Σw²/|Ĝ|² each bin carries.
/// The errors say what is wrong and what to do.
pub fn estimate(
    y: &[f64],
    fs_hz: f64,
    g: &dyn Fn(f64) -> Complex64,
    r: f64,
    cells: &[(f64, f64)],
) -> Result<CellSpectrum> {
    let n = y.len();
    if let Some(k) = y.iter().position(|v| !v.is_finite()) {
        bail!("sample {k} is not finite");
    }
    let Some(narrowest) = cells.iter().map(|c| c.1 - c.0).reduce(f64::min) else {
        bail!("no frequency cells to estimate the force spectrum on");
    };
    // Welch: Hann segments of at most WELCH_SEGMENT samples, half
    // overlapping, their powers averaged (one segment: the whole record).
    let seg = n.min(WELCH_SEGMENT);
    let df = fs_hz / seg.max(1) as f64;
    if n < 64 || df > 0.5 * narrowest {
        bail!(
            "{n} samples resolve {df:.2} Hz, coarser than half the criterion's {narrowest:.1} Hz cells; give a record of at least {:.3} s",
            2.0 / narrowest
        );
    }
    let starts: Vec<usize> = (0..).map(|i| i * (seg / 2)).take_while(|s| s + seg <= n).collect();
    let w: Vec<f64> = (0..seg).map(|i| 0.5 - 0.5 * (2.0 * PI * i as f64 / seg as f64).cos()).collect();
    let sw2: f64 = w.iter().map(|v| v * v).sum();
    let fft = FftPlanner::<f64>::new().plan_fft_forward(seg);
    let mut periodogram = vec![0.0; seg / 2];
    let mut buf = vec![Complex64::new(0.0, 0.0); seg];
    for &s0 in &starts {
        let part = &y[s0..s0 + seg];
        let mean = part.iter().sum::<f64>() / seg as f64;
        for ((b, v), w) in buf.iter_mut().zip(part).zip(&w) {
            *b = Complex64::new((v - mean) * w, 0.0);
        }
        fft.process(&mut buf);
        for (p, x) in periodogram.iter_mut().zip(&buf) {
            *p += x.norm_sqr() / starts.len() as f64;
        }
    }
    let scale = 2.0 / (seg as f64 * sw2);
    let mut power = vec![0.0; cells.len()];
    let mut noise = vec![0.0; cells.len()];
    // Each bin b·df below Nyquist goes to the cell [lo, hi) holding it.
    let mut c = 0;
    for (b, x) in periodogram.iter().enumerate().skip(1) {
        let f = b as f64 * df;
        while c < cells.len() && f >= cells[c].1 {
            c += 1;
        }
        if c == cells.len() {
            break;
        }
        if f < cells[c].0 {
            continue;
        }
        let gi = g(f).norm_sqr();
        if !(gi > 0.0 && gi.is_finite()) {
            bail!("the fitted model is zero or not finite at {f:.1} Hz");
        }
        power[c] += scale * x / gi;
        noise[c] += scale * r * sw2 / gi;
    }
    let force: Vec<f64> = power.iter().zip(&noise).map(|(p, nz)| (p - nz).max(0.0)).collect();
    let (p_f, p_n): (f64, f64) = (force.iter().sum(), noise.iter().sum());
    if !(p_f > MIN_SIGNAL_TO_NOISE * p_n) {
        bail!(
            "its force in the band ({:.3} N RMS, noise removed) does not stand above the noise the inverse carries there ({:.3} N RMS): an idle or very light record says nothing about the cut's spectrum; give a record of the cut, or drop --force-prior spectrum",
            p_f.sqrt(),
            p_n.sqrt()
        );
    }
    Ok(CellSpectrum { power_n2: force, noise_n2: noise, resolution_hz: df })
}

/// What `design` reports of an axis designed on a record's force spectrum.
///
/// A force with more power where the record had little (chatter, a sharper
/// entry, another cut) meets a filter tuned for less: hence the chosen
/// filter's error for a flat spectrum of the same power beside the record's
/// (`flat_predicted_error`). The default stays the flat criterion.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AxisForceSpectrum {
    /// The record's in-band force RMS √P_F (N), noise removed.
    pub force_rms_n: f64,
    /// The criterion's weight per line (Σ = 1), on the criterion's grid.
    #[serde(skip)]
    pub weights: Vec<f64>,
    /// Predicted error √J of the chosen filter for the record's spectrum
    /// (also the design's `predicted_error`).
    pub predicted_error: f64,
    /// Predicted error √J of the chosen filter for a flat spectrum of the
    /// same power: what a broadband force (chatter, transients) meets.
    pub flat_predicted_error: f64,
    /// Resolution of the record's spectrum (Hz).
    pub resolution_hz: f64,
    /// Only the record's level was used (`--force-prior level`): q is chosen
    /// for a flat spectrum of the record's power, so `predicted_error` is
    /// `flat_predicted_error`.
    pub level_only: bool,
}

/// What the model sidecar keeps of an axis designed on a record's force
/// spectrum, so that `compensate` can say so whenever the image is used.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpectrumProvenance {
    /// The record (`--force-record`) as given to `design`.
    pub record: String,
    /// [`AxisForceSpectrum::force_rms_n`].
    pub force_rms_n: f64,
    /// [`AxisForceSpectrum::predicted_error`].
    pub predicted_error: f64,
    /// [`AxisForceSpectrum::flat_predicted_error`].
    pub flat_predicted_error: f64,
}

impl AxisForceSpectrum {
    /// What the model sidecar keeps of it, with the record's name.
    pub fn provenance(&self, record: String) -> SpectrumProvenance {
        SpectrumProvenance {
            record,
            force_rms_n: self.force_rms_n,
            predicted_error: self.predicted_error,
            flat_predicted_error: self.flat_predicted_error,
        }
    }
}

impl SpectrumProvenance {
    /// The note `compensate` prints for axis `axis`.
    pub fn note(&self, axis: &str) -> String {
        format!(
            "note: axis {axis}: q of this image was chosen for the force spectrum of {} ({:.2} N RMS in the band; predicted {:.3} % for it, {:.3} % for a flat spectrum of the same power): a force unlike that record's (chatter, another cut) is compensated less well than by the default design",
            self.record,
            self.force_rms_n,
            100.0 * self.predicted_error,
            100.0 * self.flat_predicted_error
        )
    }
}
