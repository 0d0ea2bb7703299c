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
use nalgebra::Matrix3;
use num_complex::Complex64;
use rustfft::FftPlanner;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

use crate::frf::axis_name;

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
    let inverse = |f: f64| -> Result<[[Complex64; 1]; 1]> {
        let gi = g(f);
        if !(gi.norm_sqr() > 0.0 && gi.norm_sqr().is_finite()) {
            bail!("the fitted model is zero or not finite at {f:.1} Hz");
        }
        Ok([[gi.inv()]])
    };
    let [s] = welch_cells([y], fs_hz, &inverse, [r], cells)?;
    Ok(s)
}

/// [`estimate`] for the three force directions of a 3x3 system: the power
/// of the raw inverse Ĝ⁻¹(f)·Y(f) of the records `y` (fx, fy, fz, N, of
/// equal length) per force direction and cell, less the noise
/// Σw²·Σ_c |Ĝ⁻¹_jc|²·R_c each bin carries (R_c the noise variance of
/// channel c, N²). `g` is the 3x3 model; a line where it is singular is
/// refused.
pub fn estimate_matrix(
    y: [&[f64]; 3],
    fs_hz: f64,
    g: &dyn Fn(f64) -> Matrix3<Complex64>,
    r: [f64; 3],
    cells: &[(f64, f64)],
) -> Result<[CellSpectrum; 3]> {
    let inverse = |f: f64| -> Result<[[Complex64; 3]; 3]> {
        let m = finite_inverse(g, f)?;
        Ok(std::array::from_fn(|j| std::array::from_fn(|c| m[(j, c)])))
    };
    welch_cells(y, fs_hz, &inverse, r, cells)
}

/// The mean force F̄ = Ĝ(0)⁻¹·ȳ (N) of the records `y` (fx, fy, fz as
/// measured) through the static gain of the 3x3 model `g`: the cut's static
/// force, which lies below every band of [`estimate_matrix`].
pub fn mean_force_matrix(y: [&[f64]; 3], g: &dyn Fn(f64) -> Matrix3<Complex64>) -> Result<[f64; 3]> {
    let inverse = finite_inverse(g, 0.0).map_err(|e| anyhow::anyhow!("the record's mean force: {e}"))?;
    let mean = y.map(|c| c.iter().sum::<f64>() / c.len().max(1) as f64);
    Ok(std::array::from_fn(|j| (0..3).map(|c| inverse[(j, c)].re * mean[c]).sum()))
}

/// Ĝ(j2πf)⁻¹ of the 3x3 model `g`, refused where it is singular or not
/// finite.
fn finite_inverse(g: &dyn Fn(f64) -> Matrix3<Complex64>, f: f64) -> Result<Matrix3<Complex64>> {
    let m = g(f).try_inverse().filter(|m| m.iter().all(|v| v.re.is_finite() && v.im.is_finite()));
    let Some(m) = m else {
        bail!("the 3x3 model is singular or not finite at {f:.1} Hz");
    };
    Ok(m)
}

/// The Welch power per cell of the raw inverse `inverse(f)·Y(f)` of the `C`
/// records `y` (Hann segments of at most [`WELCH_SEGMENT`] samples, half
/// overlapping), and the noise power each cell carries (noise variance
/// `r` per record), for [`estimate`] and [`estimate_matrix`].
fn welch_cells<const C: usize>(
    y: [&[f64]; C],
    fs_hz: f64,
    inverse: &dyn Fn(f64) -> Result<[[Complex64; C]; C]>,
    r: [f64; C],
    cells: &[(f64, f64)],
) -> Result<[CellSpectrum; C]> {
    check_records(&y)?;
    let seg = segment_length(y[0].len(), fs_hz, cells)?;
    let df = fs_hz / seg as f64;
    let bins = cell_bins(seg, df, cells, inverse)?;
    let (periodogram, sw2) = inverse_periodogram(&y, seg, &bins);
    let scale = 2.0 / (seg as f64 * sw2);
    let mut power = vec![vec![0.0; cells.len()]; C];
    let mut noise = vec![vec![0.0; cells.len()]; C];
    for (p, (_, cell, m)) in periodogram.iter().zip(&bins) {
        for j in 0..C {
            power[j][*cell] += scale * p[j];
            noise[j][*cell] += scale * sw2 * m[j].iter().zip(&r).map(|(v, rc)| v.norm_sqr() * rc).sum::<f64>();
        }
    }
    let mut out = Vec::with_capacity(C);
    for (j, (power, noise)) in power.into_iter().zip(noise).enumerate() {
        let which = if C == 1 { String::new() } else { format!("force f{}: ", axis_name(j)) };
        out.push(force_above_noise(power, noise, df).map_err(|e| anyhow::anyhow!("{which}{e}"))?);
    }
    out.try_into().map_err(|_| anyhow::anyhow!("one force spectrum per record expected"))
}

/// The records must be equally long and finite.
fn check_records<const C: usize>(y: &[&[f64]; C]) -> Result<()> {
    let n = y[0].len();
    for (c, ch) in y.iter().enumerate() {
        if ch.len() != n {
            bail!(
                "force f{} has {} samples, f{} {n}: the channels must be equally long",
                axis_name(c),
                ch.len(),
                axis_name(0)
            );
        }
        if let Some(k) = ch.iter().position(|v| !v.is_finite()) {
            match C {
                1 => bail!("sample {k} is not finite"),
                _ => bail!("force f{}: sample {k} is not finite", axis_name(c)),
            }
        }
    }
    Ok(())
}

/// The Welch segment for `n` samples: at most [`WELCH_SEGMENT`], and
/// resolving at least half the narrowest cell.
fn segment_length(n: usize, fs_hz: f64, cells: &[(f64, f64)]) -> Result<usize> {
    let Some(narrowest) = cells.iter().map(|c| c.1 - c.0).reduce(f64::min) else {
        bail!("no frequency cells to estimate the force spectrum on");
    };
    let seg = n.min(WELCH_SEGMENT);
    let df = fs_hz / seg.max(1) as f64;
    if n < 64 || df > 0.5 * narrowest {
        bail!(
            "{n} samples resolve {df:.2} Hz, coarser than half the criterion's {narrowest:.1} Hz cells; give a record of at least {:.3} s",
            2.0 / narrowest
        );
    }
    Ok(seg)
}

/// A bin of the segment's spectrum, the cell holding it, and the inverse there.
type CellBin<const C: usize> = (usize, usize, [[Complex64; C]; C]);

/// Each bin b·df below Nyquist that lies in a cell [lo, hi), with its cell
/// and the inverse at its frequency.
fn cell_bins<const C: usize>(
    seg: usize,
    df: f64,
    cells: &[(f64, f64)],
    inverse: &dyn Fn(f64) -> Result<[[Complex64; C]; C]>,
) -> Result<Vec<CellBin<C>>> {
    let mut bins = Vec::new();
    let mut c = 0;
    for b in 1..seg / 2 {
        let f = b as f64 * df;
        while c < cells.len() && f >= cells[c].1 {
            c += 1;
        }
        if c == cells.len() {
            break;
        }
        if f >= cells[c].0 {
            bins.push((b, c, inverse(f)?));
        }
    }
    Ok(bins)
}

/// The Welch average of |inverse·Y|² per bin of `bins` and force
/// direction (Hann segments of `seg` samples, half overlapping, each less
/// its mean), and the window's Σw².
fn inverse_periodogram<const C: usize>(y: &[&[f64]; C], seg: usize, bins: &[CellBin<C>]) -> (Vec<[f64; C]>, f64) {
    let n = y[0].len();
    let starts: Vec<usize> = (0..).map(|i| i * (seg / 2)).take_while(|s| s + seg <= n).collect();
    let w: Vec<f64> = (0..seg).map(|i| 0.5 - 0.5 * (2.0 * PI * i as f64 / seg as f64).cos()).collect();
    let sw2: f64 = w.iter().map(|v| v * v).sum();
    let fft = FftPlanner::<f64>::new().plan_fft_forward(seg);
    let mut periodogram = vec![[0.0; C]; bins.len()];
    let mut spectra = vec![vec![Complex64::new(0.0, 0.0); seg]; C];
    for &s0 in &starts {
        for (buf, ch) in spectra.iter_mut().zip(y) {
            let part = &ch[s0..s0 + seg];
            let mean = part.iter().sum::<f64>() / seg as f64;
            for ((b, v), w) in buf.iter_mut().zip(part).zip(&w) {
                *b = Complex64::new((v - mean) * w, 0.0);
            }
            fft.process(buf);
        }
        for (p, (b, _, m)) in periodogram.iter_mut().zip(bins) {
            for (pj, mj) in p.iter_mut().zip(m) {
                let x: Complex64 = mj.iter().zip(&spectra).map(|(mjc, s)| mjc * s[*b]).sum();
                *pj += x.norm_sqr() / starts.len() as f64;
            }
        }
    }
    (periodogram, sw2)
}

/// One direction's spectrum: its cells' power less their noise (≥ 0),
/// refused unless the force stands above the noise in the band.
fn force_above_noise(power: Vec<f64>, noise: Vec<f64>, df: f64) -> Result<CellSpectrum> {
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
