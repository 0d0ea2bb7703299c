//! `dynocomp design`: FRF → fit → Kalman → realization → verified f32
//! filter, per axis, and the image that carries them.
//!
//! **Q criterion (declared).** q is chosen to minimize the predicted
//! relative error variance of the compensated force inside the coherent band
//! [f_lo, f_hi], for a force with a flat spectrum of RMS `force_rms` (N) in
//! that band and white measurement noise of variance R:
//!
//! J(q) = mean_f |H(f)·Ĝ(f)·e^{j2πfL/fs} − 1|²  +  (2R/fs)·(f_hi − f_lo)/force_rms² · mean_f |H(f)|²
//!
//! (distortion of the force + amplified noise inside the band, both relative
//! to the force variance), subject to the white-noise gain of H staying below
//! `max_noise_gain`. √J is reported as the predicted in-band error.
//!
//! With a representative record of the cut ([`DesignOptions::force_record`],
//! `--force-prior spectrum`) the mean over the lines in the distortion term
//! becomes a mean weighted by the record's force power in each line's cell,
//! and `force_rms`² the record's in-band force power
//! ([`crate::force_spectrum`], [`criterion_j_weighted`]).

use anyhow::{bail, Context, Result};
use dynocomp_core::kernel::AxisFilter;
use num_complex::Complex64;
use std::f64::consts::PI;

use crate::bands::{band_mask, Band};
use crate::discretize::{discretize_to, DiscreteModel, Discretization, FitDiagnostics, MATCH_BAND_FRACTION};
use crate::fit::rfp::{paper_weights, rfp_fit, RationalTf, RfpOptions};
use crate::fit::vf::{coherence_weights, vector_fit, VfOptions};
use crate::fit::{relative_rms_error, PoleResidueModel};
use crate::frf::{axis_name, AxisFrf};
use crate::kalman::{self, KalmanDesign, StateSpace};
use crate::paper::{self, PaperDiagnostics};
use crate::quantize::{self, Verification};
use crate::realize::{self, ModalRealization};

/// Design options shared by all axes.
#[derive(Clone, Debug)]
pub struct DesignOptions {
    /// Sample rate of the box (Hz).
    pub fs_hz: f64,
    /// Fixed lag L of the smoother = declared output latency (samples).
    pub lag: usize,
    /// Assumed RMS of the cutting force inside the band (N), for the Q criterion.
    pub force_rms: f64,
    /// Upper limit of the white-noise gain of the compensator (ratio).
    pub max_noise_gain: f64,
    /// Coherence γ² at or above which a line counts as coherent.
    pub coherence_threshold: f64,
    /// Fix q instead of searching (N²/sample).
    pub q_override: Option<f64>,
    /// Vector fitting options.
    pub vf: VfOptions,
    /// Fitting method.
    pub method: FitMethod,
    /// Fitting bands (paper §3.2); empty = the whole coherent band. With
    /// bands, the fit, the q criterion and the flat band use the band lines.
    pub bands: Vec<Band>,
    /// Discrete model of the Kalman design (default method only).
    pub discretization: Discretization,
    /// CPU budget of this axis on the box: cycles per sample it may cost
    /// (`dynocomp_core::budget::axis_budget`); `None` = no limit. The
    /// realization within it is preferred ([`choose_realization_within`]).
    pub axis_cycle_budget: Option<u32>,
    /// The paper's method chooses its orders NB:NA per axis
    /// ([`crate::paper_orders`]); the orders in [`FitMethod::Paper`] are
    /// then ignored.
    pub paper_orders_auto: bool,
    /// Upper edge of the discrete model's fit grid as a fraction of fs
    /// ([`MATCH_BAND_FRACTION`] by default; [`crate::discretize::NYQUIST_FIT_FRACTION`]
    /// is tried by [`crate::latency`] where the default falls short).
    pub discrete_fit_top: f64,
    /// The discrete model's static gain: exact (the default) or fitted like
    /// any other line ([`crate::discretize::StaticGain`]).
    pub discrete_static_gain: crate::discretize::StaticGain,
    /// A representative record of the cut: q is chosen for its force
    /// spectrum instead of a flat one of `force_rms`
    /// ([`crate::force_spectrum`], `--force-prior spectrum`).
    pub force_record: Option<std::sync::Arc<crate::force_spectrum::ForceRecord>>,
    /// Use only the record's in-band force level: the criterion's spectrum
    /// stays flat, of the record's power instead of `force_rms`
    /// (`--force-prior level`): honest predicted errors, the default's
    /// robustness to chatter.
    pub force_record_level_only: bool,
}

/// Largest accepted fit error: relative RMS of Ĝ against the coherent
/// measured lines inside the fitting bands (or the compensated band). A
/// model further from the measurement than this is not the sensor the
/// compensator would invert, whatever its predicted error says (that one is
/// computed on the model). The lines themselves are noisy: the random error
/// of an H1 line at the coherence threshold γ² = 0.9 is √((1 − γ²)/(2·n·γ²))
/// = 10.5 % from n = 5 averages (8.9 % from 7), so 15 % is 1.5x that noise
/// floor; a good fit of a good FRF is at 1-5 %.
pub const MAX_FIT_ERROR: f64 = 0.15;

/// Largest accepted predicted in-band error √J. Beating the raw force is not
/// enough when the raw force is far off (a 400 % raw error is beaten by a
/// filter that outputs almost nothing): at 50 % RMS error a "compensated"
/// force says little more than its mean, so such an axis is refused.
pub const MAX_PREDICTED_ERROR: f64 = 0.5;

/// Largest accepted relative change of the fitted Ĝ from the first coherent
/// FRF line down to 0 Hz ([`design_axis`]): the flat-band tolerance.
pub const MAX_STATIC_ERROR: f64 = 0.05;

/// Weight of an out-of-band line relative to its coherence weight when the
/// default method fits bands (the paper's method drops those lines).
pub const VF_OUT_OF_BAND_WEIGHT: f64 = 1e-2;

/// Which fit and Kalman formulation designs the compensator.
#[derive(Clone, Debug)]
pub enum FitMethod {
    /// Default: vector fitting, discrete FOH Kalman fixed-lag smoother.
    Vf,
    /// The seed paper: RFP + damped Gauss–Newton, companion form, continuous
    /// Riccati, Tustin with prewarping (latency 0).
    Paper {
        /// Numerator and denominator orders of eq. (1).
        rfp: RfpOptions,
        /// Tustin prewarp frequency (Hz); `None` = centre of the fitted band.
        prewarp_hz: Option<f64>,
    },
}

impl Default for DesignOptions {
    fn default() -> Self {
        DesignOptions {
            fs_hz: 51_200.0,
            lag: 4,
            force_rms: 100.0,
            max_noise_gain: 30.0,
            coherence_threshold: 0.9,
            q_override: None,
            vf: VfOptions::default(),
            method: FitMethod::Vf,
            bands: Vec::new(),
            discretization: Discretization::Fit,
            axis_cycle_budget: None,
            paper_orders_auto: false,
            discrete_fit_top: MATCH_BAND_FRACTION,
            discrete_static_gain: crate::discretize::StaticGain::Exact,
            force_record: None,
            force_record_level_only: false,
        }
    }
}

/// Everything designed for one axis.
#[derive(Clone, Debug)]
pub struct AxisDesign {
    /// Axis index.
    pub axis: usize,
    /// Fitted sensor model.
    pub model: PoleResidueModel,
    /// Order search trace of the fit: (order, weighted RMS error).
    pub order_trace: Vec<(usize, f64)>,
    /// Relative RMS fit error over the coherent band.
    pub fit_nrmse: f64,
    /// Coherent band (Hz).
    pub coherent_band_hz: (f64, f64),
    /// Kalman design (f64).
    pub kalman: KalmanDesign,
    /// Realization (f64).
    pub realization: ModalRealization,
    /// The f32 filter that goes into the image.
    pub filter: AxisFilter,
    /// Verification of the f32 filter.
    pub verification: Verification,
    /// Flat band: |H·Ĝ| within ±5 % and ±5° of the pure delay (Hz), with the
    /// fitted model Ĝ over the coherent band (the fit error is reported apart).
    pub flat_band_hz: (f64, f64),
    /// White-noise gain of the compensator (ratio of RMS).
    pub noise_gain: f64,
    /// Predicted in-band relative RMS error √J (fraction).
    pub predicted_error: f64,
    /// Its distortion part alone, √J with the noise term left out
    /// (fraction): what a longer look-ahead can lower ([`crate::latency`]).
    pub predicted_distortion: f64,
    /// Evaluations of J during the q search: (q, J).
    pub q_trace: Vec<(f64, f64)>,
    /// Fitting bands used (empty = whole coherent band).
    pub bands: Vec<Band>,
    /// Relative RMS fit error on coherent lines outside the bands (NaN
    /// without bands or without such lines).
    pub fit_nrmse_out_of_band: f64,
    /// The paper's fitted transfer function and diagnostics (`--method paper`).
    pub paper: Option<(RationalTf, PaperDiagnostics)>,
    /// The discrete model of the Kalman design and its fit diagnostics
    /// (default method; the paper's method discretizes by Tustin).
    pub discrete: Option<(DiscreteModel, FitDiagnostics)>,
    /// Model match max |Ĝ_d(e^{j2πf/fs})/Ĝ(j2πf) − 1| over the compensated
    /// band (NaN for the paper's method).
    pub model_match: f64,
    /// Predicted in-band relative RMS error of the uncompensated force
    /// (distortion |Ĝ − 1| plus noise), the figure `predicted_error` must beat.
    pub raw_predicted_error: f64,
    /// Compensated band (Hz): the coherent band, capped at 0.45 fs.
    pub compensated_band_hz: (f64, f64),
    /// Notes for the user (e.g. FRF lines beyond the box's band).
    pub notes: Vec<String>,
    /// Predicted in-band error when the sensor modes shift by −5…+5 %
    /// ([`crate::sensitivity`]; `None` when the model has no mode).
    pub sensitivity: Option<crate::sensitivity::Sensitivity>,
    /// The record's force spectrum q was chosen for (`None`: the flat
    /// spectrum of `force_rms`, the default).
    pub force_spectrum: Option<crate::force_spectrum::AxisForceSpectrum>,
}

impl AxisDesign {
    /// Fitted response Ĝ(j2πf): the paper's B/A itself, else the pole-residue model.
    pub fn fitted_frf(&self, f_hz: f64) -> Complex64 {
        match &self.paper {
            Some((tf, _)) => tf.frf(f_hz),
            None => self.model.frf(f_hz),
        }
    }
}

/// The coherent band: from the first to the last line of the longest run of
/// lines whose coherence (median over ±5 lines) is at least `threshold`.
/// Without coherence, the whole measured band.
pub fn coherent_band(freq_hz: &[f64], coherence: Option<&[f64]>, threshold: f64) -> (f64, f64) {
    let n = freq_hz.len();
    let Some(c) = coherence else {
        return (freq_hz[0], freq_hz[n - 1]);
    };
    let ok: Vec<bool> = (0..n)
        .map(|i| {
            let lo = i.saturating_sub(5);
            let hi = (i + 6).min(n);
            let mut w: Vec<f64> = c[lo..hi].to_vec();
            w.sort_by(f64::total_cmp);
            w[w.len() / 2] >= threshold
        })
        .collect();
    let (mut best, mut start) = ((0, 0), None);
    for i in 0..=n {
        let good = i < n && ok[i];
        match (good, start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                if i - s > best.1 - best.0 {
                    best = (s, i);
                }
                start = None;
            }
            _ => {}
        }
    }
    if best.1 == best.0 {
        return (freq_hz[0], freq_hz[0]);
    }
    (freq_hz[best.0], freq_hz[best.1 - 1])
}

/// White-noise gain of H estimated from its response: RMS of |H| over
/// 0..fs/2 (Parseval) on a 512-point midpoint grid, for responses that are
/// not one state space (`compare`'s parallel elaboration). It undersamples
/// peaks narrower than fs/1024; a state space has the exact
/// [`StateSpace::white_noise_gain`].
pub fn noise_gain(response: impl Fn(f64) -> Complex64, fs_hz: f64) -> f64 {
    let n = 512;
    let s: f64 = (0..n)
        .map(|i| response((i as f64 + 0.5) / n as f64 * fs_hz / 2.0).norm_sqr())
        .sum();
    (s / n as f64).sqrt()
}

/// The flat band of H·G: from the first line of `mask` up to the last line
/// before the first masked line where |H·G·e^{jωL/fs}| leaves 1 ± 5 % or its
/// phase leaves ±5°.
pub fn flat_band(
    response: impl Fn(f64) -> Complex64,
    freq_hz: &[f64],
    frf: &[Complex64],
    mask: &[bool],
    lag: usize,
    fs_hz: f64,
) -> (f64, f64) {
    let mut lo = None;
    let mut hi = 0.0;
    for ((f, g), m) in freq_hz.iter().zip(frf).zip(mask) {
        if !*m {
            continue;
        }
        let e = response(*f) * g * Complex64::from_polar(1.0, 2.0 * PI * f * lag as f64 / fs_hz);
        let ok = (e.norm() - 1.0).abs() <= 0.05 && e.arg().abs() <= 5f64.to_radians();
        if !ok {
            break;
        }
        lo.get_or_insert(*f);
        hi = *f;
    }
    match lo {
        Some(l) => (l, hi),
        None => (0.0, 0.0),
    }
}

/// The noise factor of J (module doc): (2R/fs)·(f_hi − f_lo)/force_rms², the
/// in-band noise variance relative to the force's, for `band_width_hz` = the
/// summed width of the criterion's bands.
pub fn noise_term(r: f64, fs_hz: f64, band_width_hz: f64, force_rms: f64) -> f64 {
    2.0 * r / fs_hz * band_width_hz / (force_rms * force_rms)
}

/// J of the Q criterion (module doc): mean over the grid of
/// |H·G·e^{j2πfL/fs} − 1|² plus `noise`·mean |H|², with `grid` = (f, G(j2πf))
/// (the plant the filter meets) and `h` = H(e^{j2πf/fs}) on the same lines.
pub fn criterion_j(grid: &[(f64, Complex64)], h: &[Complex64], lag: usize, fs_hz: f64, noise: f64) -> f64 {
    let (mut dist, mut amp) = (0.0, 0.0);
    for ((f, g), h) in grid.iter().zip(h) {
        dist += distortion(*f, *g, *h, lag, fs_hz).norm_sqr();
        amp += h.norm_sqr();
    }
    let n = grid.len() as f64;
    dist / n + noise * amp / n
}

/// The distortion H·G·e^{j2πfL/fs} − 1 of one line of the Q criterion
/// (module doc), with G = G(j2πf) and H = H(e^{j2πf/fs}).
pub fn distortion(f_hz: f64, g: Complex64, h: Complex64, lag: usize, fs_hz: f64) -> Complex64 {
    h * g * Complex64::from_polar(1.0, 2.0 * PI * f_hz * lag as f64 / fs_hz) - 1.0
}

/// J for the criterion's force spectrum: [`criterion_j`] when `weights` is
/// `None` (flat), else with the distortion of line i weighted by
/// `weights[i]` (Σ = 1: the force's share there, [`crate::force_spectrum`]);
/// the noise term stays the mean over the lines (white noise).
pub fn criterion_j_weighted(grid: &[(f64, Complex64)], h: &[Complex64], weights: Option<&[f64]>, lag: usize, fs_hz: f64, noise: f64) -> f64 {
    let Some(weights) = weights else {
        return criterion_j(grid, h, lag, fs_hz, noise);
    };
    let (mut dist, mut amp) = (0.0, 0.0);
    for (((f, g), h), w) in grid.iter().zip(h).zip(weights) {
        dist += w * distortion(*f, *g, *h, lag, fs_hz).norm_sqr();
        amp += h.norm_sqr();
    }
    dist + noise * amp / grid.len() as f64
}

/// The frequency ranges of the Q criterion of a design: its fitting bands,
/// or the compensated band without bands.
pub fn criterion_ranges(bands: &[Band], compensated_band_hz: (f64, f64)) -> Vec<(f64, f64)> {
    if bands.is_empty() {
        vec![compensated_band_hz]
    } else {
        bands.iter().map(|b| (b.lo_hz, b.hi_hz)).collect()
    }
}

/// The lines of the Q criterion: 200 spread over `ranges` (see
/// [`criterion_ranges`]), the centres of [`criterion_cells`].
pub fn criterion_grid(ranges: &[(f64, f64)]) -> Vec<f64> {
    band_grid(ranges, 200)
}

/// The cells (lo, hi) (Hz) whose centres are [`criterion_grid`]: each line
/// stands for the force in its cell ([`crate::force_spectrum`]).
pub fn criterion_cells(ranges: &[(f64, f64)]) -> Vec<(f64, f64)> {
    band_cells(ranges, 200)
}

struct Objective<'a> {
    design: &'a dyn Fn(f64) -> Result<KalmanDesign>,
    lag: usize,
    /// The criterion's lines: (f (Hz), Ĝ(j2πf)), and their frequencies alone.
    grid: &'a [(f64, Complex64)],
    grid_hz: &'a [f64],
    opts: &'a DesignOptions,
    r: f64,
    band_width: f64,
    /// The record's force spectrum on the grid (weights, power P_F in N²);
    /// `None`: flat, of power `force_rms`² (module doc).
    force: Option<(Vec<f64>, f64)>,
}

impl Objective<'_> {
    /// J of no compensation (H = 1, no lag): distortion |Ĝ − 1|² plus the
    /// measurement noise itself, in the same units as [`Objective::eval`].
    fn raw(&self) -> f64 {
        let ones = vec![Complex64::new(1.0, 0.0); self.grid.len()];
        criterion_j_weighted(self.grid, &ones, self.weights(), 0, self.opts.fs_hz, self.noise())
    }

    /// The record's weights on the grid, `None` for the flat spectrum.
    fn weights(&self) -> Option<&[f64]> {
        self.force.as_ref().map(|f| f.0.as_slice())
    }

    /// The noise factor of J: (2R/fs)·W relative to the force power, flat
    /// `force_rms`² or the record's P_F (N²).
    fn noise(&self) -> f64 {
        let power = self.force.as_ref().map_or(self.opts.force_rms * self.opts.force_rms, |f| f.1);
        2.0 * self.r / self.opts.fs_hz * self.band_width / power
    }

    /// The distortion part of J for the response `h` on the grid (the
    /// noise term left out), for the record's spectrum when there is one.
    fn distortion_of(&self, h: &[Complex64]) -> f64 {
        criterion_j_weighted(self.grid, h, self.weights(), self.lag, self.opts.fs_hz, 0.0)
    }

    /// J of the response `h` on the grid: for the record's spectrum when
    /// there is one, else flat (`flat` forces the flat spectrum at the same
    /// power).
    fn j_of(&self, h: &[Complex64], flat: bool) -> f64 {
        let weights = if flat { None } else { self.weights() };
        criterion_j_weighted(self.grid, h, weights, self.lag, self.opts.fs_hz, self.noise())
    }

    /// (J, noise gain, design) for one q; J = ∞ when the design fails or the
    /// noise-gain limit is exceeded.
    fn eval(&self, q: f64) -> (f64, f64, Option<KalmanDesign>) {
        let Ok(d) = (self.design)(q) else {
            return (f64::INFINITY, f64::NAN, None);
        };
        let fs = self.opts.fs_hz;
        let ss = &d.compensator;
        let ng = ss.white_noise_gain().unwrap_or(f64::INFINITY);
        let h = ss.freq_responses(self.grid_hz, fs);
        let j = self.j_of(&h, false);
        if ng > self.opts.max_noise_gain {
            return (f64::INFINITY, ng, Some(d));
        }
        (j, ng, Some(d))
    }
}

/// Choose q by the declared criterion: a coarse scan over decades, then a
/// golden-section refinement on log10 q around the best decade.
fn choose_q(obj: &Objective, trace: &mut Vec<(f64, f64)>) -> Result<(f64, KalmanDesign, f64, f64)> {
    let base = obj.r.log10();
    let mut best: Option<(f64, f64)> = None; // (log10 q, J)
    let mut lowest_gain = f64::INFINITY;
    let mut designed = 0;
    for i in -2..=14 {
        let lq = base + i as f64;
        let (j, ng, d) = obj.eval(10f64.powf(lq));
        designed += usize::from(d.is_some());
        lowest_gain = lowest_gain.min(ng);
        trace.push((10f64.powf(lq), j));
        if j.is_finite() && best.is_none_or(|b| j < b.1) {
            best = Some((lq, j));
        }
    }
    let Some((lq0, j0)) = best else {
        bail!(
            "no q gives a valid compensator within the noise-gain limit {} ({designed} of 17 trial q designed, lowest noise gain {lowest_gain:.1}); raise --max-noise-gain or check R",
            obj.opts.max_noise_gain
        );
    };
    let [(x1, f1), (x2, f2)] = golden_section(
        &mut |lq| {
            let j = obj.eval(10f64.powf(lq)).0;
            trace.push((10f64.powf(lq), j));
            j
        },
        lq0 - 1.0,
        lq0 + 1.0,
        12,
    );
    // The best of the coarse optimum and the final bracket (first wins a
    // tie); its J is known, only its design is computed again.
    let mut pick = (lq0, j0);
    for (lq, j) in [(x1, f1), (x2, f2)] {
        if j.is_finite() && j < pick.1 {
            pick = (lq, j);
        }
    }
    let q = 10f64.powf(pick.0);
    let (j, ng, d) = obj.eval(q);
    let d = d.ok_or_else(|| anyhow::anyhow!("q search failed"))?;
    Ok((q, d, j, ng))
}

/// Golden-section search for the minimum of `f` on [a, b] with `iters`
/// reductions after the first two evaluations; returns the final two
/// interior points (x, f(x)).
pub fn golden_section(f: &mut dyn FnMut(f64) -> f64, mut a: f64, mut b: f64, iters: usize) -> [(f64, f64); 2] {
    let gr = (5f64.sqrt() - 1.0) / 2.0;
    let mut x1 = b - gr * (b - a);
    let mut x2 = a + gr * (b - a);
    let mut f1 = f(x1);
    let mut f2 = f(x2);
    for _ in 0..iters {
        if f1 < f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - gr * (b - a);
            f1 = f(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + gr * (b - a);
            f2 = f(x2);
        }
    }
    [(x1, f1), (x2, f2)]
}

/// The fitted model of one axis, by either method.
struct Fitted {
    model: PoleResidueModel,
    order_trace: Vec<(usize, f64)>,
    paper: Option<(RationalTf, PaperDiagnostics)>,
}

impl Fitted {
    fn frf(&self, f_hz: f64) -> Complex64 {
        match &self.paper {
            Some((tf, _)) => tf.frf(f_hz),
            None => self.model.frf(f_hz),
        }
    }
}

/// `n` frequencies spread over `bands` in proportion to their widths (Hz).
fn band_grid(bands: &[(f64, f64)], n: usize) -> Vec<f64> {
    let total: f64 = bands.iter().map(|b| b.1 - b.0).sum();
    let mut out = Vec::with_capacity(n + bands.len());
    for b in bands {
        let k = ((n as f64 * (b.1 - b.0) / total).round() as usize).max(4);
        out.extend((0..k).map(|i| b.0 + (b.1 - b.0) * (i as f64 + 0.5) / k as f64));
    }
    out
}

/// The cells of [`band_grid`]: each of its frequencies is the centre of one.
fn band_cells(bands: &[(f64, f64)], n: usize) -> Vec<(f64, f64)> {
    let total: f64 = bands.iter().map(|b| b.1 - b.0).sum();
    let mut out = Vec::with_capacity(n + bands.len());
    for b in bands {
        let k = ((n as f64 * (b.1 - b.0) / total).round() as usize).max(4);
        let w = (b.1 - b.0) / k as f64;
        out.extend((0..k).map(|i| (b.0 + w * i as f64, b.0 + w * (i + 1) as f64)));
    }
    out
}

/// The FRF lines one axis is designed on.
struct AxisLines {
    /// Coherent band (Hz).
    band: (f64, f64),
    /// Compensated band: the coherent band capped at 0.45 fs (Hz).
    comp_band: (f64, f64),
    /// Notes for the user.
    notes: Vec<String>,
    /// Lines inside the compensated band.
    in_band: Vec<bool>,
    /// Lines where the compensator must be accurate (the bands or the
    /// compensated band).
    eval_band: Vec<bool>,
    /// Coherent lines of `eval_band`: the fit error is scored on them.
    target: Vec<bool>,
    /// Coherent lines outside the bands.
    out_of_band: Vec<bool>,
}

fn axis_lines(freq_hz: &[f64], frf: &AxisFrf, opts: &DesignOptions) -> Result<AxisLines> {
    let name = axis_name(frf.axis);
    let coh = frf.coherence.as_deref();
    let band = coherent_band(freq_hz, coh, opts.coherence_threshold);
    if band.1 <= band.0 {
        bail!("axis {name}: no coherent band (coherence ≥ {} nowhere); repeat the impact test", opts.coherence_threshold);
    }
    // The box's band ends at 0.45 fs (the pass band of the DAQ's and the
    // box's anti-aliasing filters): lines above it still inform the fit (a
    // sensor mode above Nyquist shapes the band below it) but are not
    // compensated.
    let f_cap = MATCH_BAND_FRACTION * opts.fs_hz;
    let mut notes = Vec::new();
    if band.0 >= f_cap {
        bail!("axis {name}: the coherent band {:.0}–{:.0} Hz lies above 0.45 fs = {f_cap:.0} Hz; raise --fs or repeat the impact test at lower frequencies", band.0, band.1);
    }
    let comp_band = (band.0, band.1.min(f_cap));
    if band.1 > f_cap {
        notes.push(format!(
            "axis {name}: FRF lines above 0.45 fs = {f_cap:.0} Hz (coherent to {:.0} Hz) inform the fit but are not compensated",
            band.1
        ));
    }
    let in_band: Vec<bool> = freq_hz.iter().map(|f| *f >= comp_band.0 && *f <= comp_band.1).collect();
    let coherent: Vec<bool> = match coh {
        Some(c) => in_band.iter().zip(c).map(|(b, c)| *b && *c >= opts.coherence_threshold).collect(),
        None => in_band.clone(),
    };
    // Lines where the compensator must be accurate: the fitting bands, or
    // the whole coherent band.
    let (eval_band, target, out_of_band): (Vec<bool>, Vec<bool>, Vec<bool>) = if opts.bands.is_empty() {
        (in_band.clone(), coherent.clone(), vec![false; freq_hz.len()])
    } else {
        let bm = band_mask(freq_hz, &opts.bands);
        let target = bm.iter().zip(&coherent).map(|(b, c)| *b && *c).collect();
        let out = bm.iter().zip(&coherent).map(|(b, c)| !*b && *c).collect();
        (bm, target, out)
    };
    if target.iter().filter(|m| **m).count() < 8 {
        bail!("axis {name}: fewer than 8 coherent FRF lines inside the fitting bands; widen the bands or check that they lie inside the coherent band {:.0}–{:.0} Hz", band.0, band.1);
    }
    Ok(AxisLines { band, comp_band, notes, in_band, eval_band, target, out_of_band })
}

/// Fit the axis's model by `opts.method` on `lines`.
fn fit_axis(freq_hz: &[f64], frf: &AxisFrf, opts: &DesignOptions, lines: &AxisLines) -> Result<Fitted> {
    let name = axis_name(frf.axis);
    let coh = frf.coherence.as_deref();
    Ok(match &opts.method {
        FitMethod::Vf => {
            let mut weights = coherence_weights(&frf.frf, coh);
            if !opts.bands.is_empty() {
                for (w, b) in weights.iter_mut().zip(&lines.eval_band) {
                    if !*b {
                        *w *= VF_OUT_OF_BAND_WEIGHT;
                    }
                }
            }
            let vf = vector_fit(freq_hz, &frf.frf, &weights, &opts.vf).with_context(|| format!("axis {name}: fit"))?;
            if !vf.model.is_stable() {
                bail!("axis {name}: fitted model is unstable");
            }
            Fitted { model: vf.model, order_trace: vf.order_trace, paper: None }
        }
        FitMethod::Paper { rfp, .. } => {
            let fit_mask: &[bool] = if opts.bands.is_empty() { &lines.in_band } else { &lines.eval_band };
            let weights = paper_weights(coh, fit_mask);
            let fit = rfp_fit(freq_hz, &frf.frf, &weights, rfp).with_context(|| format!("axis {name}: paper fit (RFP + Gauss–Newton)"))?;
            let diag = PaperDiagnostics { rfp_condition: fit.rfp_condition, jacobian_condition: fit.jacobian_condition, ..Default::default() };
            let model = fit.tf.to_pole_residue().with_context(|| format!("axis {name}: paper fit"))?;
            Fitted { model, order_trace: vec![(fit.tf.na(), fit.final_error)], paper: Some((fit.tf, diag)) }
        }
    })
}

/// The fitted response Ĝ(j2πf) of `frf` by `opts.method` on its lines,
/// before any of the design's checks (for studies of the fit itself).
pub fn fitted_response(freq_hz: &[f64], frf: &AxisFrf, opts: &DesignOptions) -> Result<impl Fn(f64) -> Complex64> {
    let lines = axis_lines(freq_hz, frf, opts)?;
    let fitted = fit_axis(freq_hz, frf, opts, &lines)?;
    Ok(move |f: f64| fitted.frf(f))
}

/// The cheap part of a paper-method design at the orders of `opts.method`,
/// without the Q search: the fit, its stability and static gain, and the
/// observability of the augmented system (eq. (4)) in floating point.
/// Returns the relative RMS fit error on the coherent lines of the bands and
/// the diagnostics; an error says which check failed.
/// [`crate::paper_orders`] ranks orders with it.
pub fn probe_paper_fit(freq_hz: &[f64], frf: &AxisFrf, opts: &DesignOptions) -> Result<(f64, PaperDiagnostics)> {
    let lines = axis_lines(freq_hz, frf, opts)?;
    let fitted = fit_axis(freq_hz, frf, opts, &lines)?;
    let Some((tf, mut diag)) = fitted.paper.clone() else {
        bail!("probe_paper_fit needs the paper's method");
    };
    if !fitted.model.is_stable() {
        bail!("the fitted transfer function is unstable");
    }
    check_static(axis_name(frf.axis), freq_hz, lines.band.0, opts, &fitted)?;
    let ss = paper::companion_form(&tf);
    diag.companion_condition = paper::condition_number(&ss.a);
    let (ae, _, ce) = paper::augmented(&ss);
    let (rank, cond) = paper::observability(&ae, &ce);
    diag.observability_rank = rank;
    diag.observability_dim = ae.nrows();
    diag.observability_condition = cond;
    if rank < ae.nrows() {
        bail!("augmented system not observable in floating point (rank {rank} of {})", ae.nrows());
    }
    if !(cond < paper::MAX_OBSERVABILITY_CONDITION) {
        bail!("augmented system ill-conditioned (observability condition {cond:.1e} ≥ {:.0e})", paper::MAX_OBSERVABILITY_CONDITION);
    }
    let fit_nrmse = relative_rms_error(|f| fitted.frf(f), freq_hz, &frf.frf, &lines.target);
    Ok((fit_nrmse, diag))
}

/// The mean cutting force sits at 0 Hz, below the impact test's first
/// coherent line, where no line constrains the fit: a model that bends there
/// (a pole-zero doublet near 0 Hz) is inverted exactly by the compensator,
/// and the compensated mean force drifts for seconds. When the design covers
/// the static band, Ĝ must stay within [`MAX_STATIC_ERROR`] of its value at
/// that first line from an eighth of its frequency down to 0 Hz, where the
/// mean force and its slow changes are (a feature just below the first line
/// only shapes transients).
///
/// Both checks apply when the fit covers the start of the coherent band
/// `f_coherent` (a band-pass segment of parallel elaboration does not); the
/// static gain |Ĝ(0)| must also be plausible for a force/force FRF.
fn check_static(name: &str, freq_hz: &[f64], f_coherent: f64, opts: &DesignOptions, fitted: &Fitted) -> Result<()> {
    if !(opts.bands.is_empty() || opts.bands.iter().any(|b| b.contains(f_coherent))) {
        return Ok(());
    }
    let dc = fitted.frf(0.0).norm();
    if !(0.2..5.0).contains(&dc) {
        bail!("axis {name}: fitted static gain |G(0)| = {dc:.3} N/N; the FRF must be force/force (N/N), check units and calibration (with fitting bands: include the static band)");
    }
    let f_first = freq_hz.iter().copied().find(|f| *f >= f_coherent).unwrap_or(f_coherent).max(1e-3);
    let g_first = fitted.frf(f_first);
    let worst = std::iter::once(0.0)
        .chain((0..=40).map(|i| 0.01 * (f_first / 8.0 / 0.01).powf(i as f64 / 40.0)))
        .map(|f| ((fitted.frf(f) - g_first).norm() / g_first.norm(), f))
        .fold((0.0, 0.0), |a, b| if b.0 > a.0 || b.0.is_nan() { b } else { a });
    if !(worst.0 <= MAX_STATIC_ERROR) {
        let next = match &fitted.paper {
            Some(_) => "let the orders be chosen (omit --paper-orders) or try others, or use the default method (--method vf)",
            None => "check the FRF's first lines (coherence near 0 Hz, units N/N) or raise --max-order",
        };
        bail!(
            "axis {name}: the fitted model is not flat below the FRF's first coherent line ({f_first:.1} Hz): from an eighth of that down to 0 Hz it moves {:.1} % from its value there by {:.2} Hz (limit {:.0} %); no line constrains it there, and the compensated mean force would drift; no image written; {next}",
            100.0 * worst.0,
            worst.1,
            100.0 * MAX_STATIC_ERROR
        );
    }
    Ok(())
}

/// Design one axis from its FRF and measurement noise variance R (N²).
pub fn design_axis(freq_hz: &[f64], frf: &AxisFrf, r: f64, opts: &DesignOptions) -> Result<AxisDesign> {
    if opts.paper_orders_auto && matches!(opts.method, FitMethod::Paper { .. }) {
        return crate::paper_orders::design_axis_auto(freq_hz, frf, r, &DesignOptions { paper_orders_auto: false, ..opts.clone() });
    }
    design_prepared(&prepare_axis(freq_hz, frf, r, opts)?, opts)
}

/// The part of one axis's design that does not depend on the declared
/// latency (`DesignOptions::lag`) nor on how far up the discrete model is
/// fitted (`DesignOptions::discrete_fit_top`): the fitted model Ĝ and its
/// checks, the criterion's grid, the record's force spectrum, and the
/// discrete model for `discrete_fit_top`. The latency rule
/// (`crate::latency`) designs one axis at up to four latencies and fit tops
/// from one of these instead of fitting its FRF four times.
pub struct PreparedAxis {
    name: &'static str,
    axis: usize,
    r: f64,
    freq_hz: Vec<f64>,
    lines: AxisLines,
    fitted: Fitted,
    fit_nrmse: f64,
    fit_nrmse_out_of_band: f64,
    ranges: Vec<(f64, f64)>,
    f_top: f64,
    grid: Vec<(f64, Complex64)>,
    spectrum: Option<crate::force_spectrum::CellSpectrum>,
    /// The discrete model at `discrete_fit_top` (`None` for the paper's
    /// method, or if it failed: `design_prepared` then says why).
    discrete: Option<(f64, (DiscreteModel, FitDiagnostics))>,
}

/// The latency-independent part of [`design_axis`] (not for
/// `paper_orders_auto`, which chooses its orders by whole designs).
pub fn prepare_axis(freq_hz: &[f64], frf: &AxisFrf, r: f64, opts: &DesignOptions) -> Result<PreparedAxis> {
    let name = axis_name(frf.axis);
    let lines = axis_lines(freq_hz, frf, opts)?;
    let fitted = fit_axis(freq_hz, frf, opts, &lines)?;
    let AxisLines { band, comp_band, target, out_of_band, .. } = &lines;
    let (band, comp_band) = (*band, *comp_band);
    let fit_nrmse = relative_rms_error(|f| fitted.frf(f), freq_hz, &frf.frf, target);
    let fit_nrmse_out_of_band = relative_rms_error(|f| fitted.frf(f), freq_hz, &frf.frf, out_of_band);
    check_static(&name, freq_hz, band.0, opts, &fitted)?;
    if !(fit_nrmse <= MAX_FIT_ERROR) {
        let next = match &fitted.paper {
            Some(_) => "let the orders be chosen (omit --paper-orders) or try others, fit narrower bands, or use the default method (--method vf)",
            None => "check the FRF (coherence, resolution, units N/N), raise --max-order, or narrow the compensated band with --band",
        };
        bail!(
            "axis {name}: the fitted model is {:.1} % (relative RMS) from the measured FRF on its coherent lines in the band, above the limit of {:.0} %; no image written; {next}",
            100.0 * fit_nrmse,
            100.0 * MAX_FIT_ERROR
        );
    }

    let ranges = criterion_ranges(&opts.bands, comp_band);
    let f_top = ranges.iter().map(|b| b.1).fold(0.0, f64::max);
    let grid: Vec<(f64, Complex64)> = criterion_grid(&ranges).into_iter().map(|f| (f, fitted.frf(f))).collect();
    // The record's force spectrum on the grid's cells (--force-prior spectrum).
    let spectrum = match &opts.force_record {
        None => None,
        Some(rec) => {
            let y = rec.channels.get(frf.axis).and_then(|c| c.as_deref()).ok_or_else(|| {
                anyhow::anyhow!("{}: no column f{name} for axis {name}; the force record needs every designed axis", rec.source)
            })?;
            let cells = criterion_cells(&ranges);
            let s = crate::force_spectrum::estimate(y, opts.fs_hz, &|f| fitted.frf(f), r, &cells)
                .with_context(|| format!("{}: axis {name}: --force-prior spectrum", rec.source))?;
            Some(s)
        }
    };
    let discrete = match &fitted.paper {
        Some(_) => None,
        None => discrete_model(&fitted, (ranges[0].0, f_top), opts).ok().map(|d| (opts.discrete_fit_top, d)),
    };
    Ok(PreparedAxis {
        name,
        axis: frf.axis,
        r,
        freq_hz: freq_hz.to_vec(),
        lines,
        fitted,
        fit_nrmse,
        fit_nrmse_out_of_band,
        ranges,
        f_top,
        grid,
        spectrum,
        discrete,
    })
}

/// The discrete model of the Kalman design (default method), matched to the
/// sampled-data relation over the compensated band `band_hz`.
fn discrete_model(fitted: &Fitted, band_hz: (f64, f64), opts: &DesignOptions) -> Result<(DiscreteModel, FitDiagnostics)> {
    discretize_to(&fitted.model, opts.fs_hz, opts.discretization, band_hz, opts.discrete_fit_top, opts.discrete_static_gain)
}

/// The latency-dependent part of [`design_axis`]: `opts` must be the
/// options `p` was prepared with, apart from `lag`, `discrete_fit_top`,
/// `q_override` and `axis_cycle_budget`.
pub fn design_prepared(p: &PreparedAxis, opts: &DesignOptions) -> Result<AxisDesign> {
    let PreparedAxis { name, axis, r, freq_hz, lines, fitted, fit_nrmse, fit_nrmse_out_of_band, ranges, f_top, grid, spectrum, discrete: prepared } = p;
    let (name, r, fit_nrmse, fit_nrmse_out_of_band, f_top) = (*name, *r, *fit_nrmse, *fit_nrmse_out_of_band, *f_top);
    let AxisLines { band, comp_band, notes, eval_band, .. } = lines;
    let (band, comp_band) = (*band, *comp_band);
    let grid_hz: Vec<f64> = grid.iter().map(|g| g.0).collect();
    let lag = if fitted.paper.is_some() { 0 } else { opts.lag };
    let prewarp_hz = match &opts.method {
        FitMethod::Paper { prewarp_hz: Some(p), .. } => *p,
        _ => 0.5 * (ranges[0].0 + f_top),
    };
    // The discrete model of the Kalman design (default method), matched to
    // the sampled-data relation over the compensated band, once per axis
    // and fit top.
    let discrete = match (&fitted.paper, prepared) {
        (Some(_), _) => None,
        (None, Some((top, d))) if *top == opts.discrete_fit_top => Some(d.clone()),
        (None, _) => Some(discrete_model(fitted, (ranges[0].0, f_top), opts).with_context(|| format!("axis {name}: discrete model"))?),
    };
    let model_match = match &discrete {
        Some((dm, _)) => dm.match_error(&grid_hz, |f| fitted.frf(f)),
        None => f64::NAN,
    };
    let design_fn = |q: f64| -> Result<KalmanDesign> {
        match (&fitted.paper, &discrete) {
            (Some((tf, _)), _) => paper::design(tf, opts.fs_hz, q, r, prewarp_hz, &mut PaperDiagnostics::default()),
            (None, Some((dm, _))) => kalman::design(dm, q, r, opts.lag),
            (None, None) => unreachable!("the default method always has a discrete model"),
        }
    };
    let obj = Objective {
        design: &design_fn,
        lag,
        grid,
        grid_hz: &grid_hz,
        opts,
        r,
        band_width: ranges.iter().map(|b| b.1 - b.0).sum(),
        force: spectrum.as_ref().map(|s| {
            let w = s.weights();
            match opts.force_record_level_only {
                // Flat, of the record's power: J as criterion_j's mean.
                true => (vec![1.0 / w.len() as f64; w.len()], s.total_n2()),
                false => (w, s.total_n2()),
            }
        }),
    };
    let mut q_trace = Vec::new();
    let chosen = match opts.q_override {
        Some(q) => {
            let (j, ng, d) = obj.eval(q);
            match d {
                Some(d) => Ok((q, d, j, ng)),
                None => design_fn(q).map(|d| (q, d, j, ng)).with_context(|| format!("axis {name}: no valid compensator for q = {q}")),
            }
        }
        None => choose_q(&obj, &mut q_trace),
    };
    let (_q, kal, j, ng) = match (chosen, &fitted.paper) {
        (Ok(c), _) => c,
        // The paper's path: say why the design failed (rank, conditions),
        // from a design at a mid-range q.
        (Err(e), Some(_)) => {
            return Err(match design_fn(10f64.powf(r.log10() + 6.0)) {
                Err(why) => e.context(format!("axis {name}: at q = 1e6·R: {why:#}")),
                Ok(_) => e.context(format!("axis {name}")),
            });
        }
        (Err(e), None) => return Err(e).with_context(|| format!("axis {name}")),
    };
    // Never silently worse than raw (README, "Never worse than no
    // compensation"): refuse the design when its predicted in-band error
    // does not beat the uncompensated force's.
    let raw_j = obj.raw();
    let worse = !(j < raw_j);
    if worse || !(j.sqrt() < MAX_PREDICTED_ERROR) {
        let next = match &fitted.paper {
            Some(_) => "let the orders be chosen (omit --paper-orders) or try others, other or narrower bands (--band, --spindle-rpm/--teeth), or the default method (--method vf)",
            None => "check the FRF (coherence, units N/N, resolution), narrow the compensated band with --band, or raise --max-noise-gain if the noise gain limits it",
        };
        let why = if worse {
            format!("would be worse than no compensation in its band ({:.0}–{:.0} Hz)", ranges[0].0, f_top)
        } else {
            format!("would barely compensate in its band ({:.0}–{:.0} Hz), its predicted error above the limit of {:.0} % (noise gain {ng:.2})", ranges[0].0, f_top, 100.0 * MAX_PREDICTED_ERROR)
        };
        bail!(
            "axis {name}: the compensator {why}: predicted in-band error {:.2} % against {:.2} % uncompensated (fit error {:.2} %); no image written; {next}",
            100.0 * j.sqrt(),
            100.0 * raw_j.sqrt(),
            100.0 * fit_nrmse
        );
    }
    // The paper's diagnostics of the chosen design (the fit's conditions stay).
    let paper = match &fitted.paper {
        Some((tf, diag)) => {
            let mut diag = diag.clone();
            paper::design(tf, opts.fs_hz, kal.q, r, prewarp_hz, &mut diag)?;
            Some((tf.clone(), diag))
        }
        None => None,
    };
    let (realization, filter, verification) =
        choose_realization_within(&kal.compensator, opts.fs_hz, f_top, opts.axis_cycle_budget).with_context(|| format!("axis {name}"))?;
    let fs = opts.fs_hz;
    // Against the fitted model, not the raw lines: an H1 line with γ² = 0.97
    // from 7 averages has ~5 % random error, as large as the tolerance.
    let model_frf: Vec<Complex64> = freq_hz.iter().map(|f| fitted.frf(*f)).collect();
    let flat = flat_band(|f| quantize::filter_response(&filter, f, fs), freq_hz, &model_frf, &eval_band, lag, fs);
    let h = kal.compensator.freq_responses(&grid_hz, fs);
    let predicted_distortion = obj.distortion_of(&h).sqrt();
    let force_spectrum = match (&spectrum, &obj.force) {
        (Some(s), Some((w, p))) => {
            Some(crate::force_spectrum::AxisForceSpectrum {
                force_rms_n: p.sqrt(),
                weights: w.clone(),
                predicted_error: j.sqrt(),
                flat_predicted_error: obj.j_of(&h, true).sqrt(),
                resolution_hz: s.resolution_hz,
                level_only: opts.force_record_level_only,
            })
        }
        _ => None,
    };
    let mut design = AxisDesign {
        axis: *axis,
        model: fitted.model.clone(),
        order_trace: fitted.order_trace.clone(),
        fit_nrmse,
        coherent_band_hz: band,
        kalman: kal,
        realization,
        filter,
        verification,
        flat_band_hz: flat,
        noise_gain: ng,
        predicted_error: j.sqrt(),
        predicted_distortion,
        q_trace,
        bands: opts.bands.clone(),
        fit_nrmse_out_of_band,
        paper,
        discrete,
        model_match,
        raw_predicted_error: raw_j.sqrt(),
        compensated_band_hz: comp_band,
        notes: notes.clone(),
        sensitivity: None,
        force_spectrum,
    };
    design.sensitivity = crate::sensitivity::predict(&design, opts);
    Ok(design)
}

/// Realize the compensator `ss` and round it to f32, with no CPU budget:
/// [`choose_realization_within`] with `axis_budget = None`.
pub fn choose_realization(ss: &StateSpace, fs_hz: f64, f_band_hz: f64) -> Result<(ModalRealization, AxisFilter, Verification)> {
    choose_realization_within(ss, fs_hz, f_band_hz, None)
}

/// Largest verification score ([`Verification::score`]) a shortened FIR may
/// reach: a tenth of the verification limits, or 10x the full FIR's score
/// when that is larger.
const TRIM_SCORE_FLOOR: f64 = 1e-5;

/// A cheaper candidate may not be scaled worse than this or than the most
/// accurate candidate (`Verification::term_growth`: no part of the kernel's
/// sum beyond 2x the output).
const MAX_CHOICE_TERM_GROWTH: f64 = 2.0;

/// Realize the compensator `ss` and round it to f32.
///
/// Candidates: the valid realizations (one per fast/slow pole split,
/// `realize::realize_candidates`), each fully verified by `quantize` over
/// 0..`f_band_hz`, and for each one with FIR taps its shortest FIR that
/// still verifies with a score ≤ max(10x its own, [`TRIM_SCORE_FLOOR`])
/// (taps bought for nothing: the kernel's cost falls, the verification
/// limits hold). Only candidates scaled no worse than the most accurate one
/// or [`MAX_CHOICE_TERM_GROWTH`] are considered. Choice, the cheapest (ties:
/// the most accurate) of the first non-empty of: within `axis_budget`
/// (cycles per sample this axis may cost, high estimate of
/// `dynocomp_core::budget::CostModel::CORTEX_M4`) and within the score
/// bound max(10x the best score, [`TRIM_SCORE_FLOOR`]); within the budget;
/// within the score bound (so the box's cost is never paid for rounding).
pub fn choose_realization_within(
    ss: &StateSpace,
    fs_hz: f64,
    f_band_hz: f64,
    axis_budget: Option<u32>,
) -> Result<(ModalRealization, AxisFilter, Verification)> {
    use dynocomp_core::budget::{AxisShape, CostModel};
    let candidates = realize::realize_candidates(ss).context("realization")?;
    let reference = quantize::Reference::of(ss, fs_hz, f_band_hz);
    let mut verified: Vec<(ModalRealization, AxisFilter, Verification)> = Vec::new();
    let mut last_err = None;
    for r in candidates {
        match quantize::quantize(&r, &reference) {
            Ok((f, v)) => {
                if let Some(t) = shortest_fir(&r, &v, &reference) {
                    verified.push(t);
                }
                verified.push((r, f, v));
            }
            Err(e) => last_err = Some(e),
        }
    }
    let cost = |f: &AxisFilter| CostModel::CORTEX_M4.axis_cost(AxisShape::of(f)).high;
    // Well-scaled realizations first: when any verified one keeps every term
    // of the kernel's sum within MAX_CHOICE_TERM_GROWTH of the output, the
    // choice is made among those only (the most accurate candidate can be a
    // badly scaled one, e.g. a fast pair split from a long delay chain).
    if verified.iter().any(|c| c.2.term_growth <= MAX_CHOICE_TERM_GROWTH) {
        verified.retain(|c| c.2.term_growth <= MAX_CHOICE_TERM_GROWTH);
    }
    let Some(best) = verified.iter().min_by(|a, b| a.2.score().total_cmp(&b.2.score())) else {
        return Err(last_err.unwrap_or_else(|| anyhow::anyhow!("no realization")).context("quantization"));
    };
    let bound = (10.0 * best.2.score()).max(TRIM_SCORE_FLOOR);
    let growth = best.2.term_growth.max(MAX_CHOICE_TERM_GROWTH);
    type Cand = (ModalRealization, AxisFilter, Verification);
    let fits = |c: &Cand| axis_budget.is_some_and(|b| cost(&c.1) <= b);
    let accurate = |c: &Cand| c.2.score() <= bound && c.2.term_growth <= growth;
    let well_scaled = |c: &Cand| c.2.term_growth <= growth;
    // Most preferred first: within budget and as accurate as the best; within
    // budget; as accurate as the best (the best itself always is).
    let pools: [&dyn Fn(&Cand) -> bool; 3] = [&|c| fits(c) && accurate(c), &|c| fits(c) && well_scaled(c), &accurate];
    let chosen = pools.iter().find_map(|keep| {
        verified
            .iter()
            .filter(|c| keep(c))
            .min_by(|a, b| cost(&a.1).cmp(&cost(&b.1)).then(a.2.score().total_cmp(&b.2.score())))
            .cloned()
    });
    chosen.ok_or_else(|| last_err.unwrap_or_else(|| anyhow::anyhow!("no realization")).context("quantization"))
}

/// The realization `r` (verified as `v`) with the fewest FIR taps that still
/// passes `quantize` with a score ≤ max(10·v.score(), [`TRIM_SCORE_FLOOR`]);
/// `None` if no shorter FIR does.
fn shortest_fir(r: &ModalRealization, v: &Verification, reference: &quantize::Reference) -> Option<(ModalRealization, AxisFilter, Verification)> {
    let bound = (10.0 * v.score()).max(TRIM_SCORE_FLOOR);
    let total: f64 = r.fir.iter().map(|h| h.abs()).sum::<f64>();
    (0..r.fir.len()).find_map(|len| {
        let mut t = r.clone();
        t.fir.truncate(len);
        let dropped: f64 = r.fir[len..].iter().map(|h| h.abs()).sum();
        t.fir_truncation = r.fir_truncation + dropped / total.max(f64::MIN_POSITIVE);
        let (f, tv) = quantize::quantize(&t, reference).ok()?;
        (tv.score() <= bound).then_some((t, f, tv))
    })
}
