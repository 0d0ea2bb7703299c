//! Opt-in harmonic force prior for offline estimation: the tooth-passing
//! and runout harmonics of a steady milling cut in the Kalman state, tuned
//! from a representative measured record ([`HarmonicPrior`]).
//!
//! The default random-walk force model lets every frequency of the band
//! through, so its estimate carries the measurement noise through the exact
//! inverse of Ĝ. A steady cut puts its force on the spindle harmonics k·f_sp;
//! a model that knows this rejects the noise between the lines. Offline only
//! (`compensate --offline`): tens of lightly damped resonators fit neither the
//! box's sections nor its f32 arithmetic.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;
use rustfft::FftPlanner;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

use crate::design::discretize::DiscreteModel;
use crate::design::force_spectrum::MIN_BROADBAND_SHARE;
use crate::design::kalman::{self, AugmentedPlant};

/// Most resonators per axis (2 states each): the strongest lines against
/// the noise. Beyond that the smoother's state (and its O(n²) per-sample
/// cost, O(n³) design) grows for lines that carry little.
pub const MAX_LINES: usize = 64;

/// Largest share of the representative record's in-band force power
/// (noise removed) that may lie away from the harmonics: above it the
/// record is not a steady cut at this spindle speed (chatter, another
/// speed, transients), and the design refuses the prior. Below it, the
/// measured share sets the criterion's broadband part, so q_bb follows it.
pub const MAX_OFF_LINE_SHARE: f64 = 0.10;

/// A record compensated with the prior may carry at most this many times
/// the off-line share of the record the prior was tuned on
/// ([`HarmonicPrior::record_off_line_share`]): more is force (chatter,
/// another speed) that the prior suppresses, and [`check_record`] refuses it.
pub const OFF_LINE_MARGIN: f64 = 2.0;

/// Least off-line share [`check_record`] accepts whatever the
/// representative record's: the scatter of the share's estimate between
/// two records of the same steady cut (other noise) is below 1e-4 on the
/// rates harness's cases.
pub const MIN_OFF_LINE_LIMIT: f64 = 5e-4;

/// One modelled harmonic line.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HarmonicLine {
    /// Harmonic number k of the spindle frequency.
    pub k: u32,
    /// Frequency k·f_sp (Hz).
    pub freq_hz: f64,
    /// Measured line power P = A²/2 (N²), A the amplitude of the force line.
    pub power_n2: f64,
}

/// The harmonic force prior of one axis.
///
/// The applied force is F_k = F^bb_k + Σ_i r_i,1\[k\]: the default broadband
/// random walk F^bb_{k+1} = F^bb_k + w_k, E\[w²\] = q_bb (N²/sample), plus one
/// lightly damped resonator per line i at f_i (Hz):
///
/// ```text
/// r_i[k+1] = ρ·R(θ_i)·r_i[k] + u_i[k],  θ_i = 2π f_i/fs,  ρ = exp(−π B/fs),  E[u uᵀ] = q_i I₂
/// ```
///
/// R(θ) the 2x2 rotation. Each resonator is a narrow-band process of
/// half-power bandwidth ≈ B (Hz, `line_width_hz`): it lets the line's
/// amplitude and phase change with a time constant 1/(πB) (tool entry, feed
/// changes). Its stationary variance per component is q_i/(1 − ρ²), the mean
/// square A_i²/2 of a sine of amplitude A_i, so **q_i = (1 − ρ²)·A_i²/2**
/// ([`line_q`]): the line amplitudes A_i (N) are measured in the record
/// ([`analyze_record`]: the raw inverse Y(f)/Ĝ(f) of its Hann-windowed
/// spectrum around each line, less the expected noise).
///
/// Why: with the default model no unbiased inverse gets below the noise
/// floor sqrt(R·(2/fs)·∫|1/G|² df); the lines' model rejects the noise between
/// them. Where: offline only, as the box's kernel holds at most 24 sections
/// per axis (`dynocomp_core::kernel::MAX_SECTIONS`) and a useful prior needs
/// lines up to the top of the band; the box image of a design with the prior
/// is the default design, unchanged.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HarmonicPrior {
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Spindle frequency f_sp = rpm/60 (Hz).
    pub spindle_hz: f64,
    /// Teeth Z of the cutter (TPF = Z·f_sp).
    pub teeth: u32,
    /// Bandwidth B of each resonator (Hz).
    pub line_width_hz: f64,
    /// The modelled lines.
    pub lines: Vec<HarmonicLine>,
    /// Broadband random-walk intensity q_bb (N²/sample).
    pub q_broadband: f64,
    /// Band of the record analysis and the criterion (Hz): the design's
    /// compensated band.
    pub band_hz: (f64, f64),
    /// Share of the force power off the lines that the criterion assumed
    /// (P_bb over the total, at least [`MIN_BROADBAND_SHARE`]).
    pub broadband_share: f64,
    /// Share of the representative record's force off the lines, as
    /// measured (noise removed): [`check_record`] refuses a record with more
    /// than [`OFF_LINE_MARGIN`] times it (at least [`MIN_OFF_LINE_LIMIT`]).
    pub record_off_line_share: f64,
}

/// Resonator pole radius ρ = exp(−π·B/fs) for bandwidth `width_hz` (Hz).
pub fn pole_radius(width_hz: f64, fs_hz: f64) -> f64 {
    (-PI * width_hz / fs_hz).exp()
}

/// Process-noise intensity q = (1 − ρ²)·P (N²/sample) of a resonator of
/// radius `rho` whose stationary power per component is `power_n2` (N²).
pub fn line_q(power_n2: f64, rho: f64) -> f64 {
    (1.0 - rho * rho) * power_n2
}

impl HarmonicPrior {
    /// Check a prior read from a file: finite positive rates and
    /// intensities, a line width below the spindle frequency, at most
    /// [`MAX_LINES`] lines inside the band.
    pub fn validate(&self) -> Result<()> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        let ok = pos(self.fs_hz)
            && pos(self.spindle_hz)
            && pos(self.line_width_hz)
            && self.line_width_hz < self.spindle_hz
            && pos(self.q_broadband)
            && pos(self.broadband_share)
            && self.broadband_share <= 1.0
            && (0.0..=1.0).contains(&self.record_off_line_share)
            && self.band_hz.0.is_finite()
            && pos(self.band_hz.1)
            && self.band_hz.1 <= 0.5 * self.fs_hz
            && self.lines.len() <= MAX_LINES
            && self
                .lines
                .iter()
                .all(|l| l.power_n2.is_finite() && l.power_n2 >= 0.0 && l.freq_hz > 0.0 && l.freq_hz <= self.band_hz.1);
        if !ok {
            bail!("the force prior is not valid (non-finite or out-of-range values, or more than {MAX_LINES} lines); re-run `dynocomp design --force-prior harmonics`");
        }
        Ok(())
    }

    /// ρ of every resonator.
    pub fn rho(&self) -> f64 {
        pole_radius(self.line_width_hz, self.fs_hz)
    }

    /// Force spectrum of the model (N² per unit normalized frequency, the
    /// convention in which white noise of variance R has density R) at
    /// f (Hz): q_bb/|1 − e^{−jω}|² + Σ_i q_i·|e₁ᵀ(zI − ρR(θ_i))⁻¹|².
    pub fn force_psd(&self, f_hz: f64) -> f64 {
        let w = 2.0 * PI * f_hz / self.fs_hz;
        let z = Complex64::from_polar(1.0, w);
        let rw = self.q_broadband / (Complex64::new(1.0, 0.0) - z.inv()).norm_sqr();
        let rho = self.rho();
        rw + self
            .lines
            .iter()
            .map(|l| line_q(l.power_n2, rho) * resonator_gain2(z, rho, 2.0 * PI * l.freq_hz / self.fs_hz))
            .sum::<f64>()
    }
}

/// |e₁ᵀ(zI − ρR(θ))⁻¹|² summed over both inputs: the spectrum of the first
/// component of a resonator driven by unit white noise on both states.
fn resonator_gain2(z: Complex64, rho: f64, theta: f64) -> f64 {
    // (zI − M)⁻¹ = adj/det with M = ρ[[c, −s], [s, c]]: first row
    // [z − ρc, −ρs]/det, det = (z − ρc)² + (ρs)².
    let (s, c) = theta.sin_cos();
    let a = z - rho * c;
    let det = a * a + rho * rho * s * s;
    (a.norm_sqr() + (rho * s).powi(2)) / det.norm_sqr()
}

/// The augmented plant of the smoother with the prior's resonators
/// appended to the default plant of `dm` (lag 0), its process-noise matrix
/// and the row o with F_k = oᵀx_k (the total force).
pub fn plant_with_prior(dm: &DiscreteModel, prior: &HarmonicPrior) -> (AugmentedPlant, DMatrix<f64>, DVector<f64>) {
    let base = kalman::augmented_plant(dm, 0);
    let n0 = base.a.nrows();
    let nl = prior.lines.len();
    let n = n0 + 2 * nl;
    let f = base.n_plant;
    let rho = prior.rho();
    let mut a = DMatrix::<f64>::zeros(n, n);
    a.view_mut((0, 0), (n0, n0)).copy_from(&base.a);
    let mut c = DVector::<f64>::zeros(n);
    c.rows_mut(0, n0).copy_from(&base.c);
    let mut g = DVector::<f64>::zeros(n);
    g.rows_mut(0, n0).copy_from(&base.g);
    let mut q = &g * g.transpose() * prior.q_broadband;
    let mut o = DVector::<f64>::zeros(n);
    o[f] = 1.0;
    for (i, l) in prior.lines.iter().enumerate() {
        let j = n0 + 2 * i;
        let (s, co) = (2.0 * PI * l.freq_hz / prior.fs_hz).sin_cos();
        a[(j, j)] = rho * co;
        a[(j, j + 1)] = -rho * s;
        a[(j + 1, j)] = rho * s;
        a[(j + 1, j + 1)] = rho * co;
        // Wherever the plant takes F_k as its input (sensor states, the
        // first delay state, the direct term), the line's first component
        // enters the same way: F_k = F^bb_k + Σ r_i,1.
        for row in 0..n0 {
            if row != f {
                a[(row, j)] = base.a[(row, f)];
            }
        }
        c[j] = base.c[f];
        o[j] = 1.0;
        let qi = line_q(l.power_n2, rho);
        q[(j, j)] = qi;
        q[(j + 1, j + 1)] = qi;
    }
    (AugmentedPlant { a, g, c, n_plant: base.n_plant, lag: base.lag }, q, o)
}

/// Frequency response H = S_F·Ĝ_d*/(|Ĝ_d|²·S_F + R) of the offline
/// smoother away from the record's ends (the non-causal Wiener filter) for
/// the force spectrum `s_f` = S_F and noise R at f (Hz).
pub fn wiener_response(dm: &DiscreteModel, s_f: f64, r: f64, f_hz: f64) -> Complex64 {
    let g = dm.frf(f_hz);
    s_f * g.conj() / (g.norm_sqr() * s_f + r)
}

/// What a representative record says about the force of one axis
/// ([`analyze_record`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RecordSpectrum {
    /// Every harmonic k·f_sp in (0, band]: (k, f, measured power P = A²/2, N²).
    pub lines: Vec<HarmonicLine>,
    /// In-band force power away from the lines, noise removed (N², ≥ 0).
    pub off_line_power_n2: f64,
    /// Share of the in-band force power (noise removed) away from the lines.
    pub off_line_share: f64,
    /// Spindle frequency (Hz) whose harmonics best explain the record
    /// (search within ±5 % of the given one).
    pub best_spindle_hz: f64,
    /// Frequency resolution of the record's spectrum (Hz).
    pub resolution_hz: f64,
    /// Expected noise power of each line's window (N²), for line selection.
    pub line_noise_n2: Vec<f64>,
}

/// Analyze a representative record `y` (N, at `fs_hz`) of one axis with
/// the fitted sensor model `g` (Ĝ(j2πf)) and noise variance R (N²): the
/// raw inverse Y(f)/Ĝ(f) of its Hann-windowed spectrum, up to `band_hz`.
/// Power around each harmonic k·`spindle_hz` (within ±max(B/2, 2 bins))
/// is that line's; the rest of (f_sp/2, band] is off the lines. The
/// expected noise (R·Σw² per bin through 1/|Ĝ|²) is removed from both.
pub fn analyze_record(
    y: &[f64],
    fs_hz: f64,
    g: &dyn Fn(f64) -> Complex64,
    r: f64,
    spindle_hz: f64,
    band_hz: f64,
    width_hz: f64,
) -> Result<RecordSpectrum> {
    let n = y.len();
    if let Some(k) = y.iter().position(|v| !v.is_finite()) {
        bail!("sample {k} of the force record is not finite");
    }
    if n < 4096 {
        bail!("{n} samples; the force record needs at least 4096 to resolve the harmonics");
    }
    if !(spindle_hz > 0.0 && spindle_hz.is_finite()) {
        bail!("spindle frequency {spindle_hz} Hz is not positive");
    }
    let df = fs_hz / n as f64;
    if spindle_hz < 4.0 * df {
        bail!("{n} samples resolve {df:.2} Hz, too coarse for harmonics {spindle_hz:.2} Hz apart; give a record of at least {:.2} s", 4.0 / spindle_hz);
    }
    let mean = y.iter().sum::<f64>() / n as f64;
    let w: Vec<f64> = (0..n).map(|i| 0.5 - 0.5 * (2.0 * PI * i as f64 / n as f64).cos()).collect();
    let sw2: f64 = w.iter().map(|v| v * v).sum();
    let mut buf: Vec<Complex64> = y.iter().zip(&w).map(|(v, w)| Complex64::new((v - mean) * w, 0.0)).collect();
    FftPlanner::<f64>::new().plan_fft_forward(n).process(&mut buf);
    let top = ((band_hz / df).floor() as usize).min(n / 2);
    // One-sided power of the raw inverse per bin and the noise's share of it.
    let scale = 2.0 / (n as f64 * sw2);
    let mut power = vec![0.0; top + 1];
    let mut noise = vec![0.0; top + 1];
    for b in 1..=top {
        let gi = g(b as f64 * df).norm_sqr();
        if !(gi > 0.0 && gi.is_finite()) {
            bail!("the fitted model is zero or not finite at {:.1} Hz", b as f64 * df);
        }
        power[b] = scale * buf[b].norm_sqr() / gi;
        noise[b] = scale * r * sw2 / gi;
    }
    let half = (0.5 * width_hz).max(2.0 * df);
    let lo = (0.5 * spindle_hz / df).ceil() as usize;
    let mut on_line = vec![false; top + 1];
    let mut lines = Vec::new();
    let mut line_noise_n2 = Vec::new();
    let mut k = 1u32;
    while f64::from(k) * spindle_hz <= band_hz {
        let f = f64::from(k) * spindle_hz;
        let b0 = (((f - half) / df).ceil().max(lo as f64)) as usize;
        let b1 = (((f + half) / df).floor() as usize).min(top);
        let (mut p, mut nz) = (0.0, 0.0);
        for b in b0..=b1 {
            if !on_line[b] {
                on_line[b] = true;
                p += power[b];
                nz += noise[b];
            }
        }
        lines.push(HarmonicLine { k, freq_hz: f, power_n2: (p - nz).max(0.0) });
        line_noise_n2.push(nz);
        k += 1;
    }
    let (mut off, mut off_noise) = (0.0, 0.0);
    for b in lo..=top {
        if !on_line[b] {
            off += power[b];
            off_noise += noise[b];
        }
    }
    let off_line_power_n2 = (off - off_noise).max(0.0);
    let line_total: f64 = lines.iter().map(|l| l.power_n2).sum();
    let total = line_total + off_line_power_n2;
    let off_line_share = if total > 0.0 { off_line_power_n2 / total } else { 1.0 };
    let best_spindle_hz = best_spindle(&power, &noise, df, spindle_hz, band_hz);
    Ok(RecordSpectrum { lines, off_line_power_n2, off_line_share, best_spindle_hz, resolution_hz: df, line_noise_n2 })
}

/// The spindle frequency within ±5 % of `given_hz` whose harmonics collect
/// the most signal-to-noise in the raw-inverse spectrum: Σ_k power/noise at
/// the bin of k·f (linear interpolation), on a grid of 1/20 of the finest
/// step that moves the highest harmonic by one bin.
fn best_spindle(power: &[f64], noise: &[f64], df: f64, given_hz: f64, band_hz: f64) -> f64 {
    let top = power.len() - 1;
    let score = |f_sp: f64| -> f64 {
        let mut s = 0.0;
        let mut k = 1.0;
        while k * f_sp <= band_hz {
            let x = k * f_sp / df;
            let b = x.floor() as usize;
            if b < top && b >= 1 {
                let t = x - b as f64;
                s += (1.0 - t) * power[b] / noise[b] + t * power[b + 1] / noise[b + 1];
            }
            k += 1.0;
        }
        s
    };
    let k_max = (band_hz / given_hz).floor().max(1.0);
    let step = df / k_max / 20.0;
    let n = ((0.05 * given_hz) / step).ceil() as i64;
    (-n..=n)
        .map(|i| given_hz + i as f64 * step)
        .map(|f| (score(f), f))
        .fold((f64::NEG_INFINITY, given_hz), |a, b| if b.0 > a.0 { b } else { a })
        .1
}

/// The figures of [`tune_and_predict`] for one set of filters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PriorPrediction {
    /// Predicted in-band error √J of the smoother with the prior (steady cut).
    pub with_prior: f64,
    /// √J of the default smoother (random walk, the design's q) on the same spectrum.
    pub default_smoother: f64,
    /// √J of the uncompensated force on the same spectrum.
    pub raw: f64,
    /// √J of the smoother with the prior for a flat force spectrum (the
    /// default criterion's assumption: what a broadband force meets).
    pub with_prior_flat: f64,
    /// √J of the default smoother for a flat force spectrum.
    pub default_flat: f64,
}

/// The steady-cut spectrum the criterion evaluates ([`tune_and_predict`]):
/// all measured lines and a flat broadband part.
#[derive(Clone, Debug)]
pub struct CutSpectrum {
    /// Lines (f, P) (Hz, N²).
    pub lines: Vec<(f64, f64)>,
    /// Flat broadband power over the band (N²).
    pub broadband_n2: f64,
    /// Band (Hz).
    pub band_hz: (f64, f64),
}

impl CutSpectrum {
    /// From a record's analysis, with P_bb at least [`MIN_BROADBAND_SHARE`].
    pub fn from_record(rs: &RecordSpectrum, band_hz: (f64, f64)) -> Self {
        let lines: Vec<(f64, f64)> = rs.lines.iter().map(|l| (l.freq_hz, l.power_n2)).collect();
        let total: f64 = lines.iter().map(|l| l.1).sum::<f64>() + rs.off_line_power_n2;
        let broadband_n2 = rs.off_line_power_n2.max(MIN_BROADBAND_SHARE * total);
        CutSpectrum { lines, broadband_n2, band_hz }
    }
}

/// J of a filter response `h` (on y) against the plant `g` (Ĝ(j2πf)) for a
/// steady cut `cut`, relative to its force power: the measured line powers
/// P_i at f_i plus a flat broadband part P_bb,
///
/// J = [Σ_i P_i |H(f_i)Ĝ(f_i) − 1|² + P_bb·mean_band |HĜ − 1|² + (2R/fs)·W·mean_band |H|²] / (Σ_i P_i + P_bb)
///
/// (W the band width): the terms of the default q criterion
/// ([`crate::design::axis`]) with the record's spectrum for the flat one. With
/// `flat`, for a flat spectrum of the same total power.
fn criterion(
    h: &dyn Fn(f64) -> Complex64,
    g: &dyn Fn(f64) -> Complex64,
    cut: &CutSpectrum,
    r: f64,
    fs_hz: f64,
    flat: bool,
) -> f64 {
    let grid = crate::design::criterion::criterion_grid(&[cut.band_hz]);
    let width = cut.band_hz.1 - cut.band_hz.0;
    let m = grid.len() as f64;
    let (mut dist, mut amp) = (0.0, 0.0);
    for f in &grid {
        let hf = h(*f);
        dist += (hf * g(*f) - 1.0).norm_sqr() / m;
        amp += hf.norm_sqr() / m;
    }
    let line_total: f64 = cut.lines.iter().map(|l| l.1).sum();
    let total = line_total + cut.broadband_n2;
    let noise = 2.0 * r / fs_hz * width * amp;
    if flat {
        return dist + noise / total;
    }
    let lines: f64 = cut.lines.iter().map(|(f, p)| p * (h(*f) * g(*f) - 1.0).norm_sqr()).sum();
    (lines + cut.broadband_n2 * dist + noise) / total
}

/// Choose q_bb for `prior` (its lines and width fixed) by the least J on
/// `cut` (decades of q_default·1e-6…10, then golden section on log10 q_bb),
/// and predict the errors ([`PriorPrediction`]). `q_default` is the
/// default design's q, `g` the fitted Ĝ(j2πf).
///
/// The steady-state fixed-interval smoother of the prior's model is, away
/// from the record's ends, the non-causal Wiener filter
/// H = S_F·Ĝ_d*/(|Ĝ_d|²·S_F + R), S_F the model's force spectrum
/// ([`HarmonicPrior::force_psd`], [`wiener_response`]); J is that of a steady
/// cut (`criterion`), its broadband part P_bb the record's in-band force power
/// away from the lines, less the noise there, at least
/// [`MIN_BROADBAND_SHARE`] of the total. A force that is not a steady cut
/// (chatter, transients, a wrong spindle speed) is not in J; [`analyze_record`]
/// refuses a record whose force is not on the harmonics.
pub fn tune_and_predict(
    prior: &mut HarmonicPrior,
    dm: &DiscreteModel,
    g: &dyn Fn(f64) -> Complex64,
    cut: &CutSpectrum,
    r: f64,
    q_default: f64,
) -> PriorPrediction {
    let fs = prior.fs_hz;
    let j_of = |p: &HarmonicPrior, flat: bool| {
        let h = |f: f64| wiener_response(dm, p.force_psd(f), r, f);
        criterion(&h, g, cut, r, fs, flat)
    };
    let at = |lq: f64| {
        let mut p = prior.clone();
        p.q_broadband = 10f64.powf(lq);
        j_of(&p, false)
    };
    // Decades from q_default·1e-6 to q_default·10, then golden section
    // within ±1 decade of the best, inside that range: below it the random
    // walk's closed-loop pole creeps to 1 (its bandwidth falls as √q_bb)
    // and the Riccati solution loses accuracy (a residual above 1e-8 at
    // q_default·1e-9 on the rates harness's high-mode case at 10.24 kHz).
    let l0 = q_default.log10();
    let (lo, hi) = (l0 - 6.0, l0 + 1.0);
    let best = (-6..=1).map(|i| l0 + f64::from(i)).map(|lq| (lq, at(lq))).fold((l0, f64::INFINITY), |a, b| {
        if b.1 < a.1 {
            b
        } else {
            a
        }
    });
    let [p1, p2] =
        crate::numeric::search::golden_section(&mut |lq| at(lq), (best.0 - 1.0).max(lo), (best.0 + 1.0).min(hi), 30);
    let pick = [best, p1, p2].into_iter().fold((l0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
    prior.q_broadband = 10f64.powf(pick.0);
    let default = HarmonicPrior { lines: Vec::new(), q_broadband: q_default, ..prior.clone() };
    let raw = |_: f64| Complex64::new(1.0, 0.0);
    PriorPrediction {
        with_prior: j_of(prior, false).sqrt(),
        default_smoother: j_of(&default, false).sqrt(),
        raw: criterion(&raw, g, cut, r, fs, false).sqrt(),
        with_prior_flat: j_of(prior, true).sqrt(),
        default_flat: j_of(&default, true).sqrt(),
    }
}

/// The lines to model from a record's analysis: those whose power exceeds
/// the noise in their window, the [`MAX_LINES`] strongest against it.
pub fn select_lines(rs: &RecordSpectrum) -> Vec<HarmonicLine> {
    let mut idx: Vec<usize> = (0..rs.lines.len()).filter(|&i| rs.lines[i].power_n2 > rs.line_noise_n2[i]).collect();
    idx.sort_by(|&a, &b| {
        (rs.lines[b].power_n2 / rs.line_noise_n2[b]).total_cmp(&(rs.lines[a].power_n2 / rs.line_noise_n2[a]))
    });
    idx.truncate(MAX_LINES);
    idx.sort_unstable();
    idx.into_iter().map(|i| rs.lines[i].clone()).collect()
}

/// Options of the harmonic prior (`design --force-prior harmonics`).
#[derive(Clone, Debug, PartialEq)]
pub struct PriorOptions {
    /// Spindle speed (rev/min).
    pub spindle_rpm: f64,
    /// Teeth Z.
    pub teeth: u32,
    /// Bandwidth B of each line (Hz); `None` = [`default_line_width_hz`].
    pub line_width_hz: Option<f64>,
    /// Skip the record checks (spindle speed, off-line share): for
    /// measuring what a wrong prior costs, never from the command line.
    pub unchecked: bool,
}

/// Default line bandwidth B: a quarter of the spindle frequency, so that a
/// line's amplitude follows a change within 4/(π·f_sp) ≈ 1.3 revolutions
/// (tool entry, feed changes) and neighbouring resonators (f_sp apart) stay
/// separate.
pub fn default_line_width_hz(spindle_rpm: f64) -> f64 {
    spindle_rpm / 60.0 / 4.0
}

/// The prior of one axis ([`HarmonicPrior`]), tuned and checked.
#[derive(Clone, Debug)]
pub struct AxisPrior {
    /// The prior (lines, intensities, q_bb).
    pub prior: HarmonicPrior,
    /// The record's analysis.
    pub record: RecordSpectrum,
    /// Predicted errors.
    pub prediction: PriorPrediction,
}

/// Build, tune and check the harmonic prior of one axis from the default
/// design's discrete model `dm` and q (`q_default`), the fitted model `g`,
/// R, the compensated band and a representative record `y` (N). The errors
/// say what to do; the caller adds the file and axis.
#[allow(clippy::too_many_arguments)]
pub fn build_axis_prior(
    opts: &PriorOptions,
    dm: &DiscreteModel,
    g: &dyn Fn(f64) -> Complex64,
    r: f64,
    q_default: f64,
    band_hz: (f64, f64),
    y: &[f64],
) -> Result<AxisPrior> {
    let fs = dm.fs_hz;
    if !(opts.spindle_rpm > 0.0 && opts.spindle_rpm.is_finite()) || opts.teeth == 0 {
        bail!("--force-prior harmonics needs --spindle-rpm > 0 and --teeth ≥ 1");
    }
    let spindle_hz = opts.spindle_rpm / 60.0;
    let width = opts.line_width_hz.unwrap_or_else(|| default_line_width_hz(opts.spindle_rpm));
    if !(width > 0.0 && width < spindle_hz) {
        bail!("--line-width {width} Hz: must lie between 0 and the spindle frequency {spindle_hz:.2} Hz");
    }
    let rs = analyze_record(y, fs, g, r, spindle_hz, band_hz.1, width)?;
    let mut lines = select_lines(&rs);
    if !opts.unchecked {
        check_spectrum(&rs, &lines, spindle_hz, width, MAX_OFF_LINE_SHARE)?;
    }
    if lines.is_empty() {
        bail!("no harmonic of {spindle_hz:.2} Hz stands above the noise in the record; the prior has nothing to model, drop --force-prior");
    }
    lines.retain(|l| l.freq_hz >= band_hz.0);
    let cut = CutSpectrum::from_record(&rs, band_hz);
    let total = cut.lines.iter().map(|l| l.1).sum::<f64>() + cut.broadband_n2;
    let broadband_share = cut.broadband_n2 / total;
    let mut prior = HarmonicPrior {
        fs_hz: fs,
        spindle_hz,
        teeth: opts.teeth,
        line_width_hz: width,
        lines,
        q_broadband: q_default,
        band_hz,
        broadband_share,
        record_off_line_share: rs.off_line_share,
    };
    let prediction = tune_and_predict(&mut prior, dm, g, &cut, r, q_default);
    Ok(AxisPrior { prior, record: rs, prediction })
}

/// The record checks of the prior: at most `max_share` of
/// the record's force may lie off the lines, and its harmonics must sit
/// where the prior puts them (the best spindle frequency moves the highest
/// modelled line by less than half a line width, or one bin).
fn check_spectrum(
    rs: &RecordSpectrum,
    lines: &[HarmonicLine],
    spindle_hz: f64,
    width: f64,
    max_share: f64,
) -> Result<()> {
    if rs.off_line_share > max_share {
        bail!(
            "{:.2} % of the record's in-band force lies away from the harmonics of {:.2} Hz (limit {:.2} %): not the steady cut at {:.1} rpm the prior expects (chatter, transients, another speed), and the prior would suppress it; drop the force prior or record a steady cut",
            100.0 * rs.off_line_share,
            spindle_hz,
            100.0 * max_share,
            spindle_hz * 60.0
        );
    }
    let k_top = lines.iter().map(|l| l.k).max().unwrap_or(1);
    let shift = (rs.best_spindle_hz - spindle_hz).abs() * f64::from(k_top);
    if shift > (0.5 * width).max(rs.resolution_hz) {
        bail!(
            "the record's harmonics sit at {:.1} rpm, not {:.1} rpm: its line {k_top} would be {shift:.1} Hz off, beyond the lines' half-width {:.1} Hz (a wrong spindle speed, or a strong line off the harmonics: chatter); correct --spindle-rpm, or drop the force prior",
            rs.best_spindle_hz * 60.0,
            spindle_hz * 60.0,
            0.5 * width
        );
    }
    Ok(())
}

/// Check that a record to be compensated with `prior` is the steady cut it
/// was tuned for: `check_spectrum` on the record's own analysis, with at
/// most [`OFF_LINE_MARGIN`] times the off-line share of the record it was
/// tuned on (at least [`MIN_OFF_LINE_LIMIT`]).
/// Another spindle speed or chatter is refused, saying what to do; the
/// analysis is returned.
pub fn check_record(prior: &HarmonicPrior, y: &[f64], g: &dyn Fn(f64) -> Complex64, r: f64) -> Result<RecordSpectrum> {
    prior.validate()?;
    let rs =
        analyze_record(y, prior.fs_hz, g, r, prior.spindle_hz, prior.band_hz.1, prior.line_width_hz).map_err(|e| {
            anyhow::anyhow!("{e:#}; cannot check the record against the force prior (use --no-force-prior)")
        })?;
    let limit = (OFF_LINE_MARGIN * prior.record_off_line_share).max(MIN_OFF_LINE_LIMIT);
    check_spectrum(&rs, &prior.lines, prior.spindle_hz, prior.line_width_hz, limit).map_err(|e| {
        anyhow::anyhow!(
            "{}",
            format!("{e:#}")
                .replace("drop the force prior or record a steady cut", "compensate without it (--no-force-prior)")
                .replace(
                    "correct --spindle-rpm, or drop the force prior",
                    "re-design with the right --spindle-rpm, or compensate without it (--no-force-prior)"
                )
        )
    })?;
    Ok(rs)
}
