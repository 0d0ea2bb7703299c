//! One axis's design: FRF lines → fit Ĝ → discrete model → Kalman filter
//! with q chosen by the criterion ([`crate::design::criterion`]) → the
//! realization the box runs, verified in f32 (`crate::realize`).
//!
//! With a representative record of the cut ([`DesignOptions::force_record`],
//! `--force-prior spectrum`) q is chosen for the record's force spectrum
//! ([`crate::design::force_spectrum`]).

use anyhow::{bail, Context, Result};
use dynocomp_core::kernel::AxisFilter;
use num_complex::Complex64;

use crate::design::above_band::{out_of_band_j, AboveBand};
use crate::design::bands::{band_mask, Band};
use crate::design::criterion::{
    criterion_cells, criterion_grid, criterion_j_weighted, criterion_ranges, flat_band, with_fit_uncertainty,
};
use crate::design::discretize::{discretize_to, DiscreteModel, Discretization, FitDiagnostics, MATCH_BAND_FRACTION};
use crate::design::kalman::{self, KalmanDesign};
use crate::design::paper::{self, PaperDiagnostics};
use crate::fit::rfp::{paper_weights, rfp_fit, RationalTf, RfpOptions};
use crate::fit::vf::{coherence_weights, vector_fit_accepting, VfOptions};
use crate::fit::{relative_rms_error, PoleResidueModel};
use crate::frf::{axis_name, AxisFrf};
use crate::numeric::search::golden_section;
use crate::realize::choose::choose_realization_within;
use crate::realize::modal::ModalRealization;
use crate::realize::quantize::{self, Verification};

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
    /// ([`crate::design::paper_orders`]); the orders in [`FitMethod::Paper`] are
    /// then ignored.
    pub paper_orders_auto: bool,
    /// Upper edge of the discrete model's fit grid as a fraction of fs
    /// ([`MATCH_BAND_FRACTION`] by default; [`crate::design::discretize::NYQUIST_FIT_FRACTION`]
    /// is tried by [`crate::design::latency`] where the default falls short).
    pub discrete_fit_top: f64,
    /// The discrete model's static gain: exact (the default) or fitted like
    /// any other line ([`crate::design::discretize::StaticGain`]).
    pub discrete_static_gain: crate::design::discretize::StaticGain,
    /// A representative record of the cut: q is chosen for its force
    /// spectrum instead of a flat one of `force_rms`
    /// ([`crate::design::force_spectrum`], `--force-prior spectrum`).
    pub force_record: Option<std::sync::Arc<crate::design::force_spectrum::ForceRecord>>,
    /// Use only the record's in-band force level: the criterion's spectrum
    /// stays flat, of the record's power instead of `force_rms`
    /// (`--force-prior level`): honest predicted errors, the default's
    /// robustness to chatter.
    pub force_record_level_only: bool,
    /// Where the paper's order search reports its candidates (`None`:
    /// nowhere; [`crate::design::paper_orders::design_axis_auto`]).
    pub order_search_progress: Option<crate::design::progress::Progress>,
    /// The output above the compensated band ([`AboveBand`]; default
    /// quiet). Band-fitted and paper-method designs, and designs with a
    /// force record, keep the in-band criterion and the random-walk force.
    pub above_band: AboveBand,
    /// For studies (`examples/sweep.rs --look-ahead=12,16`): predict these
    /// look-aheads on every axis, whatever [`crate::design::look_ahead::wanted`]
    /// says. Empty (the default): its rule and [`crate::design::look_ahead::LOOK_AHEADS`].
    pub look_ahead_every_axis: Vec<usize>,
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
            discrete_static_gain: crate::design::discretize::StaticGain::Exact,
            force_record: None,
            force_record_level_only: false,
            order_search_progress: None,
            above_band: AboveBand::Quiet,
            look_ahead_every_axis: Vec::new(),
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
    /// The fitted model's own uncertainty in the same terms, √J_fit with
    /// J_fit = Σ_f w_f |H(f)|² E|Ĝ(f) − G(f)|² over the criterion's lines
    /// (w_f the force's share of line f; flat: 1/lines): the error the
    /// FRF's noise leaves in Ĝ, which `predicted_error` (computed on Ĝ)
    /// cannot see ([`crate::fit::refine::frf_variance`]). NaN where it is
    /// not known (the paper's method, an axis passed through).
    pub fit_uncertainty: f64,
    /// Its distortion part alone, √J with the noise term left out
    /// (fraction): what a longer look-ahead can lower ([`crate::design::latency`]).
    pub predicted_distortion: f64,
    /// √ of the q criterion at the chosen q: the in-band J plus, for a
    /// design quiet above its band, the noise it writes above the band
    /// ([`crate::design::above_band::out_of_band_j`]); the figure q was
    /// chosen for. Equal to `predicted_error` for an in-band criterion.
    pub predicted_criterion: f64,
    /// Evaluations of the q criterion during the search: (q, J), J plus
    /// the noise written above the band for a quiet design
    /// ([`crate::design::above_band`]).
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
    /// Lines (Hz) where the fit seeded a pair its order search left out
    /// ([`crate::fit::vf::VfResult::seeded_hz`]); empty for the paper's method.
    pub seeded_hz: Vec<f64>,
    /// The record's force spectrum q was chosen for (`None`: the flat
    /// spectrum of `force_rms`, the default).
    pub force_spectrum: Option<crate::design::force_spectrum::AxisForceSpectrum>,
    /// Why the axis is passed through raw (`Some`: it could not be
    /// compensated, [`crate::design::pass_through`]).
    pub pass_through: Option<String>,
    /// Non-minimum-phase zeros of the model in the compensated band where
    /// the box output is further from the force than the raw measurement
    /// ([`crate::design::phase_limit`]).
    pub phase_limits: Vec<crate::design::phase_limit::PhaseLimit>,
    /// What `compensate --offline` on the image predicts for the axis: √J
    /// of the zero-lag smoother of the same discrete model, force shape and
    /// q ([`kalman::smoother_response`]) on the criterion's lines and
    /// forces, and its fit uncertainty in the same terms as
    /// `fit_uncertainty`. NaN where not known (the paper's method, an axis
    /// passed through).
    pub offline_predicted: (f64, f64),
}

impl AxisDesign {
    /// What `compensate --offline` is predicted to reach, with the fit's
    /// uncertainty counted where it is known ([`Self::offline_predicted`]).
    pub fn offline_predicted_with_fit(&self) -> f64 {
        with_fit_uncertainty(self.offline_predicted.0, self.offline_predicted.1)
    }

    /// The predicted in-band error with the fit's uncertainty counted,
    /// √(J + J_fit) ([`AxisDesign::fit_uncertainty`]); `predicted_error`
    /// where that is not known.
    pub fn predicted_error_with_fit(&self) -> f64 {
        with_fit_uncertainty(self.predicted_error, self.fit_uncertainty)
    }

    /// Fitted response Ĝ(j2πf): the paper's B/A itself, else the pole-residue model.
    pub fn fitted_frf(&self, f_hz: f64) -> Complex64 {
        match &self.paper {
            Some((tf, _)) => tf.frf(f_hz),
            None => self.model.frf(f_hz),
        }
    }
}

/// The coherent band of `frf`: from the first to the last line of the
/// longest run of lines whose coherence (median over ±5 lines) is at least
/// `threshold`, two runs counted as one across an anti-resonance: a gap no
/// wider than [`ANTI_RESONANCE_GAP`] of the frequency where it starts, over
/// which the median |G| is under [`ANTI_RESONANCE_DIP`] of the median over
/// the lines within the same relative width on either side. There the
/// coherence dips because |G| does, and the fit weighs those lines by their
/// coherence; a gap where |G| does not dip (the hammer's spectrum running
/// out, a noisy patch) still ends the band. Without coherence, the whole
/// measured band.
pub fn coherent_band(freq_hz: &[f64], frf: &AxisFrf, threshold: f64) -> (f64, f64) {
    let n = freq_hz.len();
    let Some(c) = frf.coherence.as_deref() else {
        return (freq_hz[0], freq_hz[n - 1]);
    };
    let median = |mut w: Vec<f64>| {
        w.sort_by(f64::total_cmp);
        w.get(w.len() / 2).copied().unwrap_or(f64::NAN)
    };
    let ok: Vec<bool> = (0..n).map(|i| median(c[i.saturating_sub(5)..(i + 6).min(n)].to_vec()) >= threshold).collect();
    let level = |lo: usize, hi: usize| median(frf.frf[lo..hi].iter().map(|g| g.norm()).collect());
    // An anti-resonance between the run ending at line `e` (exclusive) and
    // the one starting at line `s`: narrow, and |G| over the gap well under
    // its level within the same relative width on either side.
    let anti_resonance = |e: usize, s: usize| {
        let (fe, fs) = (freq_hz[e - 1], freq_hz[s]);
        let narrow = fs - fe <= ANTI_RESONANCE_GAP * fe;
        let below = freq_hz.partition_point(|f| *f < fe * (1.0 - ANTI_RESONANCE_GAP));
        let above = freq_hz.partition_point(|f| *f <= fs * (1.0 + ANTI_RESONANCE_GAP));
        let edges = level(below, e).min(level(s, above));
        narrow && level(e, s) < ANTI_RESONANCE_DIP * edges
    };
    // Runs of coherent lines [s, e), merged across anti-resonances. A run
    // narrower than ISLAND_WIDTH of its frequency that does not join the
    // run before it is set aside (a candidate of its own): the next run is
    // judged against the run before it, so an island inside a dip is part
    // of the gap.
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let mut islands: Vec<(usize, usize)> = Vec::new();
    let mut start = None;
    for i in 0..=n {
        match (ok.get(i).copied().unwrap_or(false), start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                let island = freq_hz[i - 1] - freq_hz[s] < ISLAND_WIDTH * freq_hz[s];
                match runs.last_mut() {
                    Some(last) if anti_resonance(last.1, s) => last.1 = i,
                    Some(_) if island => islands.push((s, i)),
                    _ => runs.push((s, i)),
                }
                start = None;
            }
            _ => {}
        }
    }
    let longest = |r: &&(usize, usize)| (r.1 - r.0, std::cmp::Reverse(r.0));
    let Some(&best) = runs.iter().chain(&islands).max_by_key(longest) else {
        return (freq_hz[0], freq_hz[0]);
    };
    (freq_hz[best.0], freq_hz[best.1 - 1])
}

/// Runs of coherent lines narrower than this fraction of their frequency,
/// after a longer run, are islands in a gap ([`coherent_band`]).
pub const ISLAND_WIDTH: f64 = 0.01;

/// Median |G| over the gap, relative to the lower of the medians over the
/// lines within [`ANTI_RESONANCE_GAP`] of its edges on either side, under
/// which [`coherent_band`] takes a gap for an anti-resonance.
pub const ANTI_RESONANCE_DIP: f64 = 0.5;

/// Widest gap between two runs of coherent lines that [`coherent_band`]
/// bridges, relative to the frequency where the gap starts: an
/// anti-resonance of 5 % damping dips over about ±2ζ.
pub const ANTI_RESONANCE_GAP: f64 = 0.1;

struct Objective<'a> {
    design: &'a dyn Fn(f64) -> Result<KalmanDesign>,
    lag: usize,
    /// The criterion's lines: (f (Hz), Ĝ(j2πf)), and their frequencies alone.
    grid: &'a [(f64, Complex64)],
    grid_hz: &'a [f64],
    opts: &'a DesignOptions,
    r: f64,
    band_width: f64,
    /// Top of the band (Hz) and the weight of the noise above it
    /// ([`crate::design::above_band::out_of_band_j`]; 0: in-band J alone).
    f_top: f64,
    out_of_band_weight: f64,
    /// The record's force spectrum on the grid (weights, power P_F in N²);
    /// `None`: flat, of power `force_rms`² ([`crate::design::force_spectrum`]).
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
        2.0 * self.r / self.opts.fs_hz * self.band_width / self.force_power()
    }

    /// The distortion part of J for the response `h` on the grid (the
    /// noise term left out), for the record's spectrum when there is one.
    fn distortion_of(&self, h: &[Complex64]) -> f64 {
        criterion_j_weighted(self.grid, h, self.weights(), self.lag, self.opts.fs_hz, 0.0)
    }

    /// J_fit of the response `h` on the grid ([`AxisDesign::fit_uncertainty`])
    /// from the fitted model's variance `var` on the grid: for the record's
    /// spectrum when there is one.
    fn fit_part(&self, h: &[Complex64], var: &[f64]) -> f64 {
        let terms = h.iter().zip(var).map(|(h, v)| h.norm_sqr() * v);
        match self.weights() {
            Some(w) => terms.zip(w).map(|(t, w)| t * w).sum(),
            None => terms.sum::<f64>() / h.len() as f64,
        }
    }

    /// J of the response `h` on the grid: for the record's spectrum when
    /// there is one, else flat (`flat` forces the flat spectrum at the same
    /// power).
    fn j_of(&self, h: &[Complex64], flat: bool) -> f64 {
        let weights = if flat { None } else { self.weights() };
        criterion_j_weighted(self.grid, h, weights, self.lag, self.opts.fs_hz, self.noise())
    }

    /// The in-band force power the criterion assumes (N²): flat
    /// `force_rms`², or the record's P_F.
    fn force_power(&self) -> f64 {
        self.force.as_ref().map_or(self.opts.force_rms * self.opts.force_rms, |f| f.1)
    }

    /// The weighted out-of-band noise of the q criterion
    /// ([`crate::design::above_band`]): 0 unless the design is quiet above
    /// its band.
    fn out_of_band(&self, h: &crate::numeric::lti::StateSpace) -> f64 {
        if self.out_of_band_weight == 0.0 {
            return 0.0;
        }
        self.out_of_band_weight * out_of_band_j(h, self.f_top, self.opts.fs_hz, self.r, self.force_power())
    }

    /// (criterion, noise gain, design) for one q: the in-band J plus the
    /// weighted out-of-band noise; ∞ when the design fails or the
    /// noise-gain limit is exceeded.
    fn eval(&self, q: f64) -> (f64, f64, Option<KalmanDesign>) {
        let Ok(d) = (self.design)(q) else {
            return (f64::INFINITY, f64::NAN, None);
        };
        let fs = self.opts.fs_hz;
        let ss = &d.compensator;
        let ng = ss.white_noise_gain().unwrap_or(f64::INFINITY);
        let h = ss.freq_responses(self.grid_hz, fs);
        let j = self.j_of(&h, false) + self.out_of_band(ss);
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

/// The fitted model of one axis, by either method.
struct Fitted {
    model: PoleResidueModel,
    order_trace: Vec<(usize, f64)>,
    /// Lines (Hz) where the fit seeded a pair ([`crate::fit::vf::VfResult::seeded_hz`]).
    seeded_hz: Vec<f64>,
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
    let band = coherent_band(freq_hz, frf, opts.coherence_threshold);
    if band.1 <= band.0 {
        bail!(
            "axis {name}: no coherent band (coherence ≥ {} nowhere); repeat the impact test",
            opts.coherence_threshold
        );
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

/// The weights of the default method's fit: the coherence weights (the
/// H1 estimate's inverse variances up to a factor), lowered outside the
/// fitting bands where there are bands.
fn vf_weights(frf: &AxisFrf, opts: &DesignOptions, lines: &AxisLines) -> Vec<f64> {
    let mut weights = coherence_weights(&frf.frf, frf.coherence.as_deref());
    if !opts.bands.is_empty() {
        for (w, b) in weights.iter_mut().zip(&lines.eval_band) {
            if !*b {
                *w *= VF_OUT_OF_BAND_WEIGHT;
            }
        }
    }
    weights
}

/// Fit the axis's model by `opts.method` on `lines`.
fn fit_axis(freq_hz: &[f64], frf: &AxisFrf, opts: &DesignOptions, lines: &AxisLines) -> Result<Fitted> {
    let name = axis_name(frf.axis);
    let coh = frf.coherence.as_deref();
    Ok(match &opts.method {
        FitMethod::Vf => {
            let weights = vf_weights(frf, opts, lines);
            // Among the orders the lines cannot tell apart, one flat below
            // the first coherent line where there is one (`check_static`).
            let f_coherent = lines.band.0;
            let checked = static_checked(opts, f_coherent);
            let flat = |m: &PoleResidueModel| {
                !checked || static_deviation(|f| m.frf(f), freq_hz, f_coherent).0 <= MAX_STATIC_ERROR
            };
            // A real pole below the first coherent line is not kept: no line
            // there identifies it, and it would bend Ĝ where the mean force is.
            let f_identified_hz = if checked { f_coherent } else { opts.vf.f_identified_hz };
            let f_ceiling_hz = crate::fit::refine::ceiling_hz(opts.fs_hz);
            let vf_opts = VfOptions { f_identified_hz, f_ceiling_hz, ..opts.vf.clone() };
            let vf = vector_fit_accepting(freq_hz, &frf.frf, &weights, &vf_opts, &flat)
                .with_context(|| format!("axis {name}: fit"))?;
            if !vf.model.is_stable() {
                bail!("axis {name}: fitted model is unstable");
            }
            Fitted { model: vf.model, order_trace: vf.order_trace, seeded_hz: vf.seeded_hz, paper: None }
        }
        FitMethod::Paper { rfp, .. } => {
            let fit_mask: &[bool] = if opts.bands.is_empty() { &lines.in_band } else { &lines.eval_band };
            let weights = paper_weights(coh, fit_mask);
            let fit = rfp_fit(freq_hz, &frf.frf, &weights, rfp)
                .with_context(|| format!("axis {name}: paper fit (RFP + Gauss–Newton)"))?;
            let diag = PaperDiagnostics {
                rfp_condition: fit.rfp_condition,
                jacobian_condition: fit.jacobian_condition,
                ..Default::default()
            };
            let model = fit.tf.to_pole_residue().with_context(|| format!("axis {name}: paper fit"))?;
            Fitted {
                model,
                order_trace: vec![(fit.tf.na(), fit.final_error)],
                seeded_hz: Vec::new(),
                paper: Some((fit.tf, diag)),
            }
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

/// The fitted model of `frf` by `opts.method`, before any of the design's
/// checks (for studies of the fit itself).
pub fn fitted_model(freq_hz: &[f64], frf: &AxisFrf, opts: &DesignOptions) -> Result<PoleResidueModel> {
    let lines = axis_lines(freq_hz, frf, opts)?;
    Ok(fit_axis(freq_hz, frf, opts, &lines)?.model)
}

/// The cheap part of a paper-method design at the orders of `opts.method`,
/// without the Q search: the fit, its stability and static gain, and the
/// observability of the augmented system (eq. (4)) in floating point.
/// Returns the relative RMS fit error on the coherent lines of the bands and
/// the diagnostics; an error says which check failed.
/// [`crate::design::paper_orders`] ranks orders with it.
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
    let (rank, cond) = paper::observability(&ae, &ce)?;
    diag.observability_rank = rank;
    diag.observability_dim = ae.nrows();
    diag.observability_condition = cond;
    if rank < ae.nrows() {
        bail!("augmented system not observable in floating point (rank {rank} of {})", ae.nrows());
    }
    if !(cond < paper::MAX_OBSERVABILITY_CONDITION) {
        bail!(
            "augmented system ill-conditioned (observability condition {cond:.1e} ≥ {:.0e})",
            paper::MAX_OBSERVABILITY_CONDITION
        );
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
    if !static_checked(opts, f_coherent) {
        return Ok(());
    }
    let dc = fitted.frf(0.0).norm();
    if !(0.2..5.0).contains(&dc) {
        bail!("axis {name}: fitted static gain |G(0)| = {dc:.3} N/N; the FRF must be force/force (N/N), check units and calibration (with fitting bands: include the static band)");
    }
    let (worst_dev, worst_hz, f_first) = static_deviation(|f| fitted.frf(f), freq_hz, f_coherent);
    let worst = (worst_dev, worst_hz);
    if !(worst.0 <= MAX_STATIC_ERROR) {
        let next = match &fitted.paper {
            Some(_) => {
                "let the orders be chosen (omit --paper-orders) or try others, or use the default method (--method vf)"
            }
            None => "check the FRF's first lines (coherence near 0 Hz, units N/N) or raise --max-order",
        };
        bail!(
            "axis {name}: the fitted model is not flat below the FRF's first coherent line ({f_first:.1} Hz): from an eighth of that down to 0 Hz it moves {:.1} % from its value there by {:.2} Hz (limit {:.0} %); no line constrains it there, and the compensated mean force would drift; {next}",
            100.0 * worst.0,
            worst.1,
            100.0 * MAX_STATIC_ERROR
        );
    }
    Ok(())
}

/// Whether [`check_static`] applies: the fit covers the start of the
/// coherent band `f_coherent` (Hz).
fn static_checked(opts: &DesignOptions, f_coherent: f64) -> bool {
    opts.bands.is_empty() || opts.bands.iter().any(|b| b.contains(f_coherent))
}

/// How far `g` = Ĝ(j2πf) moves below the first line at or above
/// `f_coherent`, f_first: the largest |Ĝ(f) − Ĝ(f_first)|/|Ĝ(f_first)| from
/// f_first/8 down to 0 Hz ([`check_static`]), where it is (Hz), and f_first.
pub fn static_deviation(g: impl Fn(f64) -> Complex64, freq_hz: &[f64], f_coherent: f64) -> (f64, f64, f64) {
    let f_first = freq_hz.iter().copied().find(|f| *f >= f_coherent).unwrap_or(f_coherent).max(1e-3);
    let g_first = g(f_first);
    let (worst, at) = std::iter::once(0.0)
        .chain((0..=40).map(|i| 0.01 * (f_first / 8.0 / 0.01).powf(i as f64 / 40.0)))
        .map(|f| ((g(f) - g_first).norm() / g_first.norm(), f))
        .fold((0.0, 0.0), |a, b| if b.0 > a.0 || b.0.is_nan() { b } else { a });
    (worst, at, f_first)
}

/// Design one axis from its FRF and measurement noise variance R (N²).
/// The paper's method is designed at the orders of `opts.method`: where they
/// are to be chosen (`paper_orders_auto`), call
/// [`crate::design::paper_orders::design_axis`] instead.
pub fn design_axis(freq_hz: &[f64], frf: &AxisFrf, r: f64, opts: &DesignOptions) -> Result<AxisDesign> {
    debug_assert!(
        !(opts.paper_orders_auto && matches!(opts.method, FitMethod::Paper { .. })),
        "orders to be chosen: design through design::paper_orders::design_axis"
    );
    design_prepared(&prepare_axis(freq_hz, frf, r, opts)?, opts)
}

/// The part of one axis's design that does not depend on the declared
/// latency (`DesignOptions::lag`) nor on how far up the discrete model is
/// fitted (`DesignOptions::discrete_fit_top`): the fitted model Ĝ and its
/// checks, the criterion's grid, the record's force spectrum, and the
/// discrete model for `discrete_fit_top`. The latency rule
/// (`crate::design::latency`) designs one axis at up to four latencies and fit tops
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
    /// E|Ĝ − G|² of the fitted model on the grid, from its lines' noise
    /// ([`crate::fit::refine::frf_variance`]; `None` for the paper's
    /// method, or where it cannot be computed).
    fit_variance: Option<Vec<f64>>,
    spectrum: Option<crate::design::force_spectrum::CellSpectrum>,
    /// The discrete model at `discrete_fit_top` (`None` for the paper's
    /// method, or if it failed: `design_prepared` then says why).
    discrete: Option<(f64, (DiscreteModel, FitDiagnostics))>,
}

impl PreparedAxis {
    /// The fitted model Ĝ(j2πf) of the axis's direct FRF (N/N).
    pub fn model_frf(&self, f_hz: f64) -> Complex64 {
        self.fitted.frf(f_hz)
    }
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
    check_static(name, freq_hz, band.0, opts, &fitted)?;
    if !(fit_nrmse <= MAX_FIT_ERROR) {
        let next = match &fitted.paper {
            Some(_) => "let the orders be chosen (omit --paper-orders) or try others, fit narrower bands, or use the default method (--method vf)",
            None => "check the FRF (coherence, resolution, units N/N), raise --max-order, or narrow the compensated band with --band",
        };
        bail!(
            "axis {name}: the fitted model is {:.1} % (relative RMS) from the measured FRF on its coherent lines in the band, above the limit of {:.0} %; {next}",
            100.0 * fit_nrmse,
            100.0 * MAX_FIT_ERROR
        );
    }

    let ranges = criterion_ranges(&opts.bands, comp_band);
    let f_top = ranges.iter().map(|b| b.1).fold(0.0, f64::max);
    let grid: Vec<(f64, Complex64)> = criterion_grid(&ranges).into_iter().map(|f| (f, fitted.frf(f))).collect();
    let fit_variance = match fitted.paper {
        Some(_) => None,
        None => {
            let grid_hz: Vec<f64> = grid.iter().map(|g| g.0).collect();
            let weights = vf_weights(frf, opts, &lines);
            crate::fit::refine::frf_variance(freq_hz, &frf.frf, &weights, &fitted.model, &grid_hz)
        }
    };
    // The record's force spectrum on the grid's cells (--force-prior spectrum).
    let spectrum = match &opts.force_record {
        None => None,
        Some(rec) => {
            let y = rec.channels.get(frf.axis).and_then(|c| c.as_deref()).ok_or_else(|| {
                anyhow::anyhow!(
                    "{}: no column f{name} for axis {name}; the force record needs every designed axis",
                    rec.source
                )
            })?;
            let cells = criterion_cells(&ranges);
            let s = crate::design::force_spectrum::estimate(y, opts.fs_hz, &|f| fitted.frf(f), r, &cells)
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
        fit_variance,
        spectrum,
        discrete,
    })
}

/// The discrete model of the Kalman design (default method), matched to the
/// sampled-data relation over the compensated band `band_hz`.
fn discrete_model(
    fitted: &Fitted,
    band_hz: (f64, f64),
    opts: &DesignOptions,
) -> Result<(DiscreteModel, FitDiagnostics)> {
    discretize_to(
        &fitted.model,
        opts.fs_hz,
        opts.discretization,
        band_hz,
        opts.discrete_fit_top,
        opts.discrete_static_gain,
    )
}

/// The latency-dependent part of [`design_axis`]: `opts` must be the
/// options `p` was prepared with, apart from `lag`, `discrete_fit_top`,
/// `q_override` and `axis_cycle_budget`. Discrete model → Kalman filter with
/// q by the criterion → refusal unless it beats no compensation →
/// realization within the cycle budget → its flat band.
pub fn design_prepared(p: &PreparedAxis, opts: &DesignOptions) -> Result<AxisDesign> {
    let fs = opts.fs_hz;
    let grid_hz: Vec<f64> = p.grid.iter().map(|g| g.0).collect();
    let lag = if p.fitted.paper.is_some() { 0 } else { opts.lag };
    let discrete = p.discrete_for(opts)?;
    let model_match = match &discrete {
        Some((dm, _)) => dm.match_error(&grid_hz, |f| p.fitted.frf(f)),
        None => f64::NAN,
    };
    let prewarp_hz = p.prewarp_hz(opts);
    let design_fn = |q: f64| p.kalman_design(discrete.as_ref(), q, prewarp_hz, opts);
    let obj = p.objective(&design_fn, lag, &grid_hz, opts);
    let mut q_trace = Vec::new();
    let (kal, criterion, ng) = p.choose_kalman(&obj, opts, &mut q_trace)?;
    let h = kal.compensator.freq_responses(&grid_hz, opts.fs_hz);
    let j = obj.j_of(&h, false);
    let raw_j = obj.raw();
    p.refuse_unless_better(j, raw_j, ng)?;
    let paper = p.paper_design(kal.q, prewarp_hz, opts)?;
    let (realization, filter, verification) =
        choose_realization_within(&kal.compensator, fs, p.f_top, opts.axis_cycle_budget)
            .with_context(|| format!("axis {}", p.name))?;
    let flat = p.flat_band(&filter, lag, fs);
    let predicted_distortion = obj.distortion_of(&h).sqrt();
    let fit_uncertainty = p.fit_uncertainty(&obj, &h);
    let force_spectrum = p.force_spectrum(&obj, &h, j, opts);
    let phase_limits = match p.fitted.paper {
        Some(_) => Vec::new(),
        None => crate::design::phase_limit::phase_limit(&p.fitted.model, &kal.compensator, lag, fs, p.lines.comp_band),
    };
    let offline_predicted = match (&p.fitted.paper, &discrete) {
        (None, Some((dm, _))) => {
            let plant = kalman::augmented_plant_shaped(dm, 0, kal.force_shape);
            let lines: Vec<f64> = grid_hz.iter().map(|f| f.max(1e-6 * fs)).collect();
            let h_off = kalman::smoother_response(&plant, kal.q, kal.r, &lines, fs);
            let obj0 = p.objective(&design_fn, 0, &grid_hz, opts);
            let fit = p.fit_uncertainty(&obj0, &h_off);
            (obj0.j_of(&h_off, false).sqrt(), fit)
        }
        _ => (f64::NAN, f64::NAN),
    };
    Ok(AxisDesign {
        axis: p.axis,
        model: p.fitted.model.clone(),
        order_trace: p.fitted.order_trace.clone(),
        fit_nrmse: p.fit_nrmse,
        coherent_band_hz: p.lines.band,
        kalman: kal,
        realization,
        filter,
        verification,
        flat_band_hz: flat,
        noise_gain: ng,
        predicted_error: j.sqrt(),
        fit_uncertainty,
        predicted_distortion,
        predicted_criterion: criterion.sqrt(),
        q_trace,
        bands: opts.bands.clone(),
        fit_nrmse_out_of_band: p.fit_nrmse_out_of_band,
        paper,
        discrete,
        model_match,
        raw_predicted_error: raw_j.sqrt(),
        compensated_band_hz: p.lines.comp_band,
        notes: p.lines.notes.iter().cloned().chain(p.seeded_note()).collect(),
        seeded_hz: p.fitted.seeded_hz.clone(),
        force_spectrum,
        pass_through: None,
        phase_limits,
        offline_predicted,
    })
}

/// The in-band error (fraction) the Kalman design at `opts.lag` predicts,
/// with the fit's uncertainty counted ([`with_fit_uncertainty`]), and the
/// design itself: [`design_prepared`]'s q search without the realization,
/// the f32 verification or the refusals, for look-aheads the box cannot run
/// ([`crate::design::look_ahead`]). The default method only.
pub fn predict_prepared(p: &PreparedAxis, opts: &DesignOptions) -> Result<(f64, KalmanDesign)> {
    if p.fitted.paper.is_some() {
        bail!("axis {}: the paper's method has no look-ahead", p.name);
    }
    let grid_hz: Vec<f64> = p.grid.iter().map(|g| g.0).collect();
    let discrete = p.discrete_for(opts)?;
    let prewarp_hz = p.prewarp_hz(opts);
    let design_fn = |q: f64| p.kalman_design(discrete.as_ref(), q, prewarp_hz, opts);
    let obj = p.objective(&design_fn, opts.lag, &grid_hz, opts);
    let (kal, _, _) = p.choose_kalman(&obj, opts, &mut Vec::new())?;
    let h = kal.compensator.freq_responses(&grid_hz, opts.fs_hz);
    Ok((with_fit_uncertainty(obj.j_of(&h, false).sqrt(), p.fit_uncertainty(&obj, &h)), kal))
}

impl PreparedAxis {
    /// √J_fit of the response `h` on the grid under `obj`'s force
    /// ([`AxisDesign::fit_uncertainty`]); NaN where the fit's variance is
    /// not known.
    fn fit_uncertainty(&self, obj: &Objective, h: &[Complex64]) -> f64 {
        self.fit_variance.as_ref().map_or(f64::NAN, |v| obj.fit_part(h, v).sqrt())
    }

    /// The discrete model of the Kalman design (default method), matched to
    /// the sampled-data relation over the compensated band, once per axis
    /// and fit top: the prepared one if it is for `opts.discrete_fit_top`.
    fn discrete_for(&self, opts: &DesignOptions) -> Result<Option<(DiscreteModel, FitDiagnostics)>> {
        Ok(match (&self.fitted.paper, &self.discrete) {
            (Some(_), _) => None,
            (None, Some((top, d))) if *top == opts.discrete_fit_top => Some(d.clone()),
            (None, _) => Some(
                discrete_model(&self.fitted, (self.ranges[0].0, self.f_top), opts)
                    .with_context(|| format!("axis {}: discrete model", self.name))?,
            ),
        })
    }

    /// Whether this design is quiet above its band
    /// ([`crate::design::above_band`]): the default method without bands
    /// and without a force record. With `--force-prior level` the out-of-band
    /// term, relative to the record's (lower) force level, cut q so far that
    /// the example's predicted in-band distortion chose latency 8 for no
    /// measured gain (x predicted 0.99 %, measured 0.67 %): the record's
    /// criteria stay in-band for now.
    fn default_quiet(&self, opts: &DesignOptions) -> bool {
        opts.above_band == AboveBand::Quiet
            && opts.bands.is_empty()
            && self.fitted.paper.is_none()
            && opts.force_record.is_none()
    }

    /// The summary's note on the pairs the fit seeded, if any.
    fn seeded_note(&self) -> Option<String> {
        if self.fitted.seeded_hz.is_empty() {
            return None;
        }
        let hz: Vec<String> = self.fitted.seeded_hz.iter().map(|f| format!("{f:.0}")).collect();
        Some(format!(
            "axis {}: pole pairs added near {} Hz, where the fit left more than the impact test's noise (BIC); more impacts would confirm a weak mode there",
            self.name,
            hz.join(", ")
        ))
    }

    /// The band-limited force model of a quiet design, where its corner
    /// lies below 0.45 fs.
    fn force_shape(&self, opts: &DesignOptions) -> Option<crate::design::kalman::ForceShape> {
        match self.default_quiet(opts) {
            true => opts.above_band.force_shape(self.f_top, opts.fs_hz),
            false => None,
        }
    }

    /// The paper's Tustin prewarp frequency (Hz): the given one, else the
    /// centre of the compensated band.
    fn prewarp_hz(&self, opts: &DesignOptions) -> f64 {
        match &opts.method {
            FitMethod::Paper { prewarp_hz: Some(p), .. } => *p,
            _ => 0.5 * (self.ranges[0].0 + self.f_top),
        }
    }

    /// The Kalman design for q: the paper's continuous one on its fitted
    /// B/A, else the discrete one on `discrete` (always there for the
    /// default method).
    fn kalman_design(
        &self,
        discrete: Option<&(DiscreteModel, FitDiagnostics)>,
        q: f64,
        prewarp_hz: f64,
        opts: &DesignOptions,
    ) -> Result<KalmanDesign> {
        match (&self.fitted.paper, discrete) {
            (Some((tf, _)), _) => {
                paper::design(tf, opts.fs_hz, q, self.r, prewarp_hz, &mut PaperDiagnostics::default())
            }
            (None, Some((dm, _))) => kalman::design_shaped(dm, q, self.r, opts.lag, self.force_shape(opts)),
            (None, None) => unreachable!("the default method always has a discrete model"),
        }
    }

    /// The criterion over this axis's grid for the designs of `design`: for
    /// the record's force spectrum where there is one (flat, of its power,
    /// with `force_record_level_only`).
    fn objective<'a>(
        &'a self,
        design: &'a dyn Fn(f64) -> Result<KalmanDesign>,
        lag: usize,
        grid_hz: &'a [f64],
        opts: &'a DesignOptions,
    ) -> Objective<'a> {
        Objective {
            design,
            lag,
            grid: &self.grid,
            grid_hz,
            opts,
            r: self.r,
            band_width: self.ranges.iter().map(|b| b.1 - b.0).sum(),
            f_top: self.f_top,
            out_of_band_weight: match self.default_quiet(opts) {
                true => opts.above_band.out_of_band_weight(),
                false => 0.0,
            },
            force: self.spectrum.as_ref().map(|s| {
                let w = s.weights();
                match opts.force_record_level_only {
                    // Flat, of the record's power: J as criterion_j's mean.
                    true => (vec![1.0 / w.len() as f64; w.len()], s.total_n2()),
                    false => (w, s.total_n2()),
                }
            }),
        }
    }

    /// The Kalman design at the given q (`opts.q_override`) or at the q the
    /// criterion chooses, with its J and noise gain; `q_trace` gets the
    /// search's evaluations. A failed paper design says why from a design
    /// at a mid-range q (rank, conditions).
    fn choose_kalman(
        &self,
        obj: &Objective,
        opts: &DesignOptions,
        q_trace: &mut Vec<(f64, f64)>,
    ) -> Result<(KalmanDesign, f64, f64)> {
        let name = self.name;
        let chosen = match opts.q_override {
            Some(q) => {
                let (j, ng, d) = obj.eval(q);
                match d {
                    Some(d) => Ok((q, d, j, ng)),
                    None => (obj.design)(q)
                        .map(|d| (q, d, j, ng))
                        .with_context(|| format!("axis {name}: no valid compensator for q = {q}")),
                }
            }
            None => choose_q(obj, q_trace),
        };
        match (chosen, &self.fitted.paper) {
            (Ok((_q, kal, j, ng)), _) => Ok((kal, j, ng)),
            (Err(e), Some(_)) => Err(match (obj.design)(10f64.powf(self.r.log10() + 6.0)) {
                Err(why) => e.context(format!("axis {name}: at q = 1e6·R: {why:#}")),
                Ok(_) => e.context(format!("axis {name}")),
            }),
            (Err(e), None) => Err(e).with_context(|| format!("axis {name}")),
        }
    }

    /// Never silently worse than raw (README, "Never worse than no
    /// compensation"): refuse a design whose predicted in-band error J
    /// does not beat the uncompensated force's `raw_j`, or whose √J is
    /// above [`MAX_PREDICTED_ERROR`].
    fn refuse_unless_better(&self, j: f64, raw_j: f64, ng: f64) -> Result<()> {
        let worse = !(j < raw_j);
        if !worse && j.sqrt() < MAX_PREDICTED_ERROR {
            return Ok(());
        }
        let (name, lo, f_top) = (self.name, self.ranges[0].0, self.f_top);
        let next = match &self.fitted.paper {
            Some(_) => "let the orders be chosen (omit --paper-orders) or try others, other or narrower bands (--band, --spindle-rpm/--teeth), or the default method (--method vf)",
            None => "check the FRF (coherence, units N/N, resolution), narrow the compensated band with --band, or raise --max-noise-gain if the noise gain limits it",
        };
        let why = if worse {
            format!("would be worse than no compensation in its band ({lo:.0}–{f_top:.0} Hz)")
        } else {
            format!(
                "would barely compensate in its band ({lo:.0}–{f_top:.0} Hz), its predicted error above the limit of {:.0} % (noise gain {ng:.2})",
                100.0 * MAX_PREDICTED_ERROR
            )
        };
        bail!(
            "axis {name}: the compensator {why}: predicted in-band error {:.2} % against {:.2} % uncompensated (fit error {:.2} %); {next}",
            100.0 * j.sqrt(),
            100.0 * raw_j.sqrt(),
            100.0 * self.fit_nrmse
        );
    }

    /// The paper's fitted B/A with the diagnostics of its design at q (the
    /// fit's conditions stay); `None` for the default method.
    fn paper_design(
        &self,
        q: f64,
        prewarp_hz: f64,
        opts: &DesignOptions,
    ) -> Result<Option<(RationalTf, PaperDiagnostics)>> {
        match &self.fitted.paper {
            Some((tf, diag)) => {
                let mut diag = diag.clone();
                paper::design(tf, opts.fs_hz, q, self.r, prewarp_hz, &mut diag)?;
                Ok(Some((tf.clone(), diag)))
            }
            None => Ok(None),
        }
    }

    /// The flat band of the f32 `filter` (Hz), against the fitted model,
    /// not the raw lines: an H1 line with γ² = 0.97 from 7 averages has
    /// ~5 % random error, as large as the tolerance.
    fn flat_band(&self, filter: &AxisFilter, lag: usize, fs: f64) -> (f64, f64) {
        let model_frf: Vec<Complex64> = self.freq_hz.iter().map(|f| self.fitted.frf(*f)).collect();
        let response = |f| quantize::filter_response(filter, f, fs);
        flat_band(response, &self.freq_hz, &model_frf, &self.lines.eval_band, lag, fs)
    }

    /// What q for the record's force spectrum predicts, beside the flat
    /// spectrum's J of the same response `h` (`None` without a record).
    fn force_spectrum(
        &self,
        obj: &Objective,
        h: &[Complex64],
        j: f64,
        opts: &DesignOptions,
    ) -> Option<crate::design::force_spectrum::AxisForceSpectrum> {
        match (&self.spectrum, &obj.force) {
            (Some(s), Some((w, p))) => Some(crate::design::force_spectrum::AxisForceSpectrum {
                force_rms_n: p.sqrt(),
                weights: w.clone(),
                predicted_error: j.sqrt(),
                flat_predicted_error: obj.j_of(h, true).sqrt(),
                resolution_hz: s.resolution_hz,
                level_only: opts.force_record_level_only,
            }),
            _ => None,
        }
    }
}
