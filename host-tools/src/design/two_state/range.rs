//! The box image for a set-up that moves between two measured states: the
//! second FRF fitted and paired with the first, machine modes shared where
//! both measured them alike, and the design whose worst predicted error over
//! the range is least.

use anyhow::{bail, Context, Result};
use num_complex::Complex64;

use crate::design::axis::{design_axis, static_deviation, AxisDesign, DesignOptions, MAX_STATIC_ERROR};
use crate::design::criterion::{criterion_grid, criterion_j, criterion_ranges, noise_term};
use crate::design::two_state::joint::{fit_above_band_jointly, AboveBandMode, Lines};
use crate::design::two_state::model::{is_physical, pair_fading, term_fn_hz, TwoState};
use crate::fit::modes::{fn_hz, modal_share, residue_of_share, sensor_mode_indices, sensor_modes_from_hz};
use crate::fit::vf::{coherence_weights, fit_order, refit_kept, OrderFits, VfOptions};
use crate::fit::{PoleResidueModel, Term};
use crate::frf::{axis_name, AxisFrf};
use crate::numeric::parallel::map_on_threads;

/// States s at which a box image designed for the range is evaluated.
pub const RANGE_STATES: [f64; 5] = [0.0, 0.25, 0.5, 0.75, 1.0];

/// One candidate box design for the range between two states.
#[derive(Clone, Debug)]
pub struct RangeCandidate {
    /// Model state the candidate was designed for (0 = the first FRF as
    /// measured, 1 = the second as measured, in between the interpolated model).
    pub s: f64,
    /// The design.
    pub design: AxisDesign,
    /// Predicted in-band error of its filter at each of [`RANGE_STATES`].
    pub errors: Vec<f64>,
    /// Predicted in-band error of its filter on the first and the second
    /// FRF as measured (their lines in the criterion's band), not their
    /// fitted models: the check that the paired models tell the truth at
    /// the ends of the range.
    pub measured: (f64, f64),
    /// The largest of `errors` and `measured`.
    pub worst: f64,
}

/// The two states of an axis, as [`pair_second_state`] makes them.
#[derive(Clone, Debug)]
pub struct Paired {
    /// The paired states.
    pub states: TwoState,
    /// What became of each machine-structure mode ([`share_machine_modes`]).
    pub machine: Vec<MachineMode>,
    /// What became of each sensor mode above the compensated band
    /// ([`crate::design::two_state::joint`]).
    pub above_band: Vec<AboveBandMode>,
}

/// The two states of an axis: the first is `d0`'s fitted model (of the
/// FRF `first`), the second FRF is fitted at the same order (its coherence
/// as weights) and paired with it ([`pair`]); then the machine-structure
/// modes the two FRFs measured alike are shared ([`share_machine_modes`])
/// and the sensor modes above `d0`'s compensated band are fitted to both
/// FRFs at once ([`crate::design::two_state::joint`]).
pub fn pair_second_state(
    freq_hz: &[f64],
    first: &AxisFrf,
    d0: &AxisDesign,
    second: &AxisFrf,
    vf: &VfOptions,
) -> Result<Paired> {
    let name = axis_name(second.axis);
    let w = coherence_weights(&second.frf, second.coherence.as_deref());
    // The mass change keeps the static gain, and below the first coherent
    // line no line constrains either fit. The second state's fit is to be
    // flat there as the single-state design's static check asks
    // (`design::axis`), without poles below that line where the first
    // state's fit has none: a pole there is a state the record cannot
    // settle, and takes up part of the mean force. In order of preference:
    // the fit at the first state's order with such terms left out and the
    // residues fitted again, if flat; the order the fit chooses among those
    // flat without such poles; among those flat once they are left out.
    let f_coherent = d0.compensated_band_hz.0;
    let slow_poles_allowed = d0.model.terms.iter().any(|t| term_fn_hz(t) < f_coherent);
    let slow = |m: &PoleResidueModel| !slow_poles_allowed && m.terms.iter().any(|t| term_fn_hz(t) < f_coherent);
    let unslowed = |m: PoleResidueModel| -> PoleResidueModel {
        if !slow(&m) {
            return m;
        }
        let keep: Vec<bool> = m.terms.iter().map(|t| term_fn_hz(t) >= f_coherent).collect();
        refit_kept(freq_hz, &second.frf, &w, &m, &keep).unwrap_or(m)
    };
    let flat = |m: &PoleResidueModel| static_deviation(|f| m.frf(f), freq_hz, f_coherent).0 <= MAX_STATIC_ERROR;
    let calm = |m: &PoleResidueModel| flat(m) && !slow(m);
    let unbiased = |m: &PoleResidueModel| calm(m) && low_lines_unbiased(m, freq_hz, second, f_coherent);
    let flat_once_calmed = |m: &PoleResidueModel| calm(&unslowed(m.clone()));
    let at_order = unslowed(
        fit_order(freq_hz, &second.frf, &w, d0.model.order(), vf)
            .with_context(|| format!("axis {name}: second FRF, fit at order {}", d0.model.order()))?,
    );
    let mut after = None;
    // The orders fitted once, where the fit at the first state's order fails the first criterion.
    let mut orders = None;
    for accept in [&unbiased as &dyn Fn(&PoleResidueModel) -> bool, &calm, &flat_once_calmed] {
        if accept(&at_order) {
            after = Some(at_order.clone());
            break;
        }
        if orders.is_none() {
            orders = Some(
                OrderFits::new(freq_hz, &second.frf, &w, vf)
                    .with_context(|| format!("axis {name}: second FRF, fit"))?,
            );
        }
        let fit = orders.as_mut().expect("fitted above").choose(accept)?;
        let fit = unslowed(fit.model);
        if accept(&fit) {
            after = Some(fit);
            break;
        }
    }
    let Some(after) = after else {
        let (dev, at, f_first) = static_deviation(|f| at_order.frf(f), freq_hz, f_coherent);
        bail!(
            "axis {name}: second FRF: no fitted model is flat below the first coherent line ({f_first:.1} Hz): at the first state's order it moves {:.1} % from its value there by {at:.2} Hz (limit {:.0} %); no line constrains it there, and the interpolated model's mean force would drift; check the second FRF's first lines (coherence near 0 Hz) or raise --max-order",
            100.0 * dev,
            100.0 * MAX_STATIC_ERROR
        );
    };
    // A mode without a partner may fade between the states where no line
    // constrains it: above the compensated band. In the band it does not
    // fade: a machine mode one fit resolved and the other did not, faded,
    // left the drift smoother 2-7x off its no-drift error on 7 of 8 such
    // axes of the drift sweep (BENCHMARKS.md); such a mode is met below by
    // refitting the second state with the first's machine poles. Partners
    // lie on the same side of the discrete models' Nyquist.
    let band_top = d0.compensated_band_hz.1;
    let nyquist_hz = d0.discrete.as_ref().map_or(f64::INFINITY, |(dm, _)| 0.5 * dm.fs_hz);
    let fade = |f: f64| f > band_top;
    let ts = match pair_fading(name, &d0.model, &after, &fade, nyquist_hz) {
        Ok(ts) => ts,
        // The fits resolved the machine structure differently (one split a
        // mode the other did not). A mass change on the table leaves the
        // machine's modes where they are: the second state is fitted again
        // with the first state's machine poles in place of its own, and
        // paired if that pairs.
        Err(e) => match with_first_machine_poles(&d0.model, &after, freq_hz, second, &w) {
            Some(m) => pair_fading(name, &d0.model, &m, &fade, nyquist_hz).map_err(|_| e)?,
            None => return Err(e),
        },
    };
    let w0 = coherence_weights(&first.frf, first.coherence.as_deref());
    let frfs = [(&first.frf[..], &w0[..]), (&second.frf[..], &w[..])];
    let (ts, machine) = share_machine_modes(&ts, freq_hz, frfs);
    let (states, above_band) = fit_above_band_jointly(&ts, &Lines::new(freq_hz, frfs), d0.compensated_band_hz);
    Ok(Paired { states, machine, above_band })
}

/// `after` with its machine-structure poles (physical pairs below the first
/// state's sensor modes, [`crate::fit::modes::sensor_modes_from_hz`])
/// replaced by those of `first`, its residues and direct term fitted again
/// to `second` (weights `w`); None where `first` has no sensor modes or the
/// refit fails.
fn with_first_machine_poles(
    first: &PoleResidueModel,
    after: &PoleResidueModel,
    freq_hz: &[f64],
    second: &AxisFrf,
    w: &[f64],
) -> Option<PoleResidueModel> {
    let from = sensor_modes_from_hz(first)?;
    let machine = |m: &PoleResidueModel, i: usize| is_physical(m, i) && term_fn_hz(&m.terms[i]) < from;
    let terms: Vec<Term> = (0..first.terms.len())
        .filter(|&i| machine(first, i))
        .map(|i| first.terms[i])
        .chain((0..after.terms.len()).filter(|&i| !machine(after, i)).map(|i| after.terms[i]))
        .collect();
    let m = PoleResidueModel { terms, d: after.d };
    let keep = vec![true; m.terms.len()];
    refit_kept(freq_hz, &second.frf, w, &m, &keep).ok().filter(|m| m.is_stable())
}

/// Whether `m` stays within its FRF's noise where the mean force lives: on
/// the coherent lines from the first at or above `f_coherent` up to 8x that
/// (Hz), the mean of Re((Ĝ − H)/H) within 3 standard errors of 0, plus 0.2 %.
/// A fit whose static gain sits off its own low lines carries the mean
/// force off by as much (the drift sweep's seed 1 z: 1.3 %).
fn low_lines_unbiased(m: &PoleResidueModel, freq_hz: &[f64], frf: &AxisFrf, f_coherent: f64) -> bool {
    let f_first = freq_hz.iter().copied().find(|f| *f >= f_coherent).unwrap_or(f_coherent);
    let r: Vec<f64> = (0..freq_hz.len())
        .filter(|&k| freq_hz[k] >= f_first && freq_hz[k] <= 8.0 * f_first)
        .filter(|&k| frf.coherence.as_ref().is_none_or(|c| c[k] >= 0.9) && frf.frf[k].norm() > 0.0)
        .map(|k| ((m.frf(freq_hz[k]) - frf.frf[k]) / frf.frf[k]).re)
        .collect();
    if r.len() < 4 {
        return true;
    }
    let n = r.len() as f64;
    let mean = r.iter().sum::<f64>() / n;
    let se = (r.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
    mean.abs() <= 3.0 * se + 0.002
}

/// Largest growth of a machine mode's weighted misfit (either FRF, over
/// the mode's lines) at which the two states' fits of it are taken as two
/// measurements of one mode ([`share_machine_modes`]).
pub const SHARE_TOLERANCE: f64 = 1.5;

/// Half-width of the lines a machine mode is judged on, in half-power
/// bandwidths ζ·f_n (at least [`SHARE_MIN_LINES`] lines).
pub const SHARE_WINDOW: f64 = 3.0;

/// Fewest FRF lines a machine mode must span to be judged.
pub const SHARE_MIN_LINES: usize = 5;

/// What [`share_machine_modes`] did with one machine-structure mode.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MachineMode {
    /// Natural frequency in the first / second state's fit (Hz).
    pub fn_hz: (f64, f64),
    /// Weighted misfit of the shared mode over its own one's, on the first /
    /// second FRF (√ of the ratio of Σ w|Ĝ − H|² over the mode's lines).
    pub misfit_growth: (f64, f64),
    /// Shared (both states carry the average), or kept apart.
    pub shared: bool,
}

/// Machine-structure modes measured twice. The workpiece's
/// loss of mass moves the sensor modes; the modes below
/// [`crate::fit::modes::SENSOR_FRACTION`] × the main mode's (the
/// sensitivity's and the simulator's rule) belong to the machine and may
/// stay put, and then the two impact tests are two independent measurements
/// of them: their average has half the variance of either fit. Near a
/// lightly damped machine mode and its anti-resonance that variance is what
/// limits the smoother (BENCHMARKS.md, the seed-4 gap).
///
/// **Rule (stated).** Per machine mode (a pair of the first state's model
/// below the sensor modes, not a background term of the fit,
/// [`TwoState::is_background`]), the shared mode is the average of the two
/// fits' poles and modal shares. Each FRF `(H, w)` (`w` the coherence
/// weights of the fit) is judged over its lines within ±[`SHARE_WINDOW`]
/// half-power bandwidths of the mode: the shared mode is kept if, on both
/// FRFs, √(Σ w|Ĝ_shared − H|² / Σ w|Ĝ − H|²) ≤ [`SHARE_TOLERANCE`], i.e. the
/// data cannot tell the two fits apart; otherwise (the mode moved, or is
/// not resolved by [`SHARE_MIN_LINES`] lines) both states keep their own.
pub fn share_machine_modes(
    ts: &TwoState,
    freq_hz: &[f64],
    frfs: [(&[Complex64], &[f64]); 2],
) -> (TwoState, Vec<MachineMode>) {
    let sensors = sensor_mode_indices(&ts.before);
    let mut out = ts.clone();
    let mut report = Vec::new();
    for (i, (t0, t1)) in ts.before.terms.iter().zip(&ts.after.terms).enumerate() {
        let (Term::Pair { pole: p0, residue: r0 }, Term::Pair { pole: p1, residue: r1 }) = (*t0, *t1) else { continue };
        if sensors.contains(&i) || ts.is_background(i) {
            continue;
        }
        let pole = (p0 + p1) * 0.5;
        let c = (modal_share(p0, r0) + modal_share(p1, r1)) * 0.5;
        let mean = Term::Pair { pole, residue: residue_of_share(pole, c) };
        let (f0, f1) = (fn_hz(p0), fn_hz(p1));
        let (zeta, f) = (-pole.re / pole.norm(), fn_hz(pole));
        let half = SHARE_WINDOW * zeta * f;
        let lines: Vec<usize> = (0..freq_hz.len()).filter(|&k| (freq_hz[k] - f).abs() <= half).collect();
        let growth = |m: &PoleResidueModel, (h, w): (&[Complex64], &[f64])| {
            let mut shared = m.clone();
            shared.terms[i] = mean;
            let chi =
                |g: &PoleResidueModel| lines.iter().map(|&k| w[k] * (g.frf(freq_hz[k]) - h[k]).norm_sqr()).sum::<f64>();
            (chi(&shared) / chi(m)).sqrt()
        };
        let g = (growth(&ts.before, frfs[0]), growth(&ts.after, frfs[1]));
        // NaN (no misfit at all: noise-free data) keeps the fits apart.
        let shared = lines.len() >= SHARE_MIN_LINES && g.0 <= SHARE_TOLERANCE && g.1 <= SHARE_TOLERANCE;
        if shared {
            out.before.terms[i] = mean;
            out.after.terms[i] = mean;
        }
        report.push(MachineMode { fn_hz: (f0, f1), misfit_growth: g, shared });
    }
    (out, report)
}

/// The result of [`design_over_range`] for one axis.
#[derive(Clone, Debug)]
pub struct RangeDesign {
    /// The paired states, machine modes shared where measured alike.
    pub states: TwoState,
    /// What became of each machine-structure mode ([`share_machine_modes`]).
    pub machine: Vec<MachineMode>,
    /// What became of each sensor mode above the compensated band
    /// ([`crate::design::two_state::joint`]).
    pub above_band: Vec<AboveBandMode>,
    /// Every candidate design.
    pub candidates: Vec<RangeCandidate>,
    /// Index of the chosen one in `candidates`.
    pub best: usize,
    /// Candidate states that could not be designed, with why.
    pub skipped: Vec<(f64, String)>,
}

impl RangeDesign {
    /// Whether the chosen design is the first FRF's own (single-state)
    /// design: no design for the range predicts less error over it.
    pub fn kept_single_state(&self) -> bool {
        self.candidates[self.best].s == 0.0
    }

    /// Worst-case predicted error of the first and the second FRF's own
    /// designs (NaN for one that could not be designed).
    pub fn single_state_worst(&self) -> (f64, f64) {
        let at = |s: f64| self.candidates.iter().find(|c| c.s == s).map_or(f64::NAN, |c| c.worst);
        (at(0.0), at(1.0))
    }
}

/// The two measured FRFs of an axis on the lines of a design's criterion
/// band, to judge a filter on them as measured rather than on a fitted model.
struct MeasuredPlants {
    freqs: Vec<f64>,
    plants: [Vec<(f64, Complex64)>; 2],
    /// Total width of the criterion ranges (Hz).
    width: f64,
}

impl MeasuredPlants {
    /// The lines of `first` and `second` within the criterion ranges `ranges` (Hz).
    fn new(freq_hz: &[f64], first: &AxisFrf, second: &AxisFrf, ranges: &[(f64, f64)]) -> Self {
        let in_band: Vec<usize> =
            (0..freq_hz.len()).filter(|&k| ranges.iter().any(|b| freq_hz[k] >= b.0 && freq_hz[k] <= b.1)).collect();
        let freqs = in_band.iter().map(|&k| freq_hz[k]).collect();
        let plants = [first, second].map(|a| in_band.iter().map(|&k| (freq_hz[k], a.frf[k])).collect());
        let width = ranges.iter().map(|b| b.1 - b.0).sum();
        MeasuredPlants { freqs, plants, width }
    }

    /// The predicted in-band error ([`criterion_j`], √) of `design`'s filter
    /// on the first and the second FRF as measured.
    fn errors(&self, design: &AxisDesign, opts: &DesignOptions) -> (f64, f64) {
        let noise = noise_term(design.kalman.r, opts.fs_hz, self.width, opts.force_rms);
        let h = design.kalman.compensator.freq_responses(&self.freqs, opts.fs_hz);
        let j = |g: &[(f64, Complex64)]| criterion_j(g, &h, design.kalman.lag, opts.fs_hz, noise).sqrt();
        (j(&self.plants[0]), j(&self.plants[1]))
    }
}

/// The box image for a set-up that moves between two measured states.
/// **Criterion (stated):** the least worst-case
/// predicted in-band error over s ∈ [`RANGE_STATES`] and over both FRFs as
/// measured ([`RangeCandidate::measured`]), chosen among
/// candidate designs for the model states `candidate_states` and 0 (0 and 1 are
/// designed from the two measured FRFs as a single-state design would be,
/// states in between from the interpolated model's response on the same
/// lines, with the first FRF's coherence). Each candidate's filter is
/// evaluated against the interpolated model at every s with the design's own
/// criterion ([`crate::design::criterion::criterion_j`], the first FRF's band).
/// A state whose design fails is skipped ([`RangeDesign::skipped`]); the
/// first FRF's own design is always a candidate, and it wins ties, so the
/// image never predicts more error over the range than the single-state
/// design ([`RangeDesign::kept_single_state`]).
/// `d0` is the first FRF's own design.
fn design_over_range(
    freq_hz: &[f64],
    first: &AxisFrf,
    d0: AxisDesign,
    second: &AxisFrf,
    r: f64,
    opts: &DesignOptions,
    candidate_states: &[f64],
) -> Result<RangeDesign> {
    let name = axis_name(first.axis);
    let Paired { states: ts, machine, above_band } = pair_second_state(freq_hz, first, &d0, second, &opts.vf)?;
    let ranges = criterion_ranges(&d0.bands, d0.compensated_band_hz);
    let freqs = criterion_grid(&ranges);
    let plants: Vec<Vec<(f64, Complex64)>> = RANGE_STATES
        .iter()
        .map(|&s| {
            let m = ts.at(s);
            freqs.iter().map(|f| (*f, m.frf(*f))).collect()
        })
        .collect();
    let measured_plants = MeasuredPlants::new(freq_hz, first, second, &ranges);
    let interpolated_fit_error = measured_states_fit_error(&d0, freq_hz, second, &ts, opts.coherence_threshold);
    let mut cands = Vec::new();
    let mut skipped = Vec::new();
    let mut states = vec![0.0];
    states.extend(candidate_states.iter().copied().filter(|&s| s != 0.0));
    for &s in &states {
        let design = if s == 0.0 {
            Ok(d0.clone())
        } else if s == 1.0 {
            design_axis(freq_hz, second, r, opts).context("second FRF")
        } else {
            let m = ts.at(s);
            let synthetic = AxisFrf {
                axis: first.axis,
                frf: freq_hz.iter().map(|f| m.frf(*f)).collect(),
                coherence: first.coherence.clone(),
            };
            design_axis(freq_hz, &synthetic, r, opts)
                .map(|d| AxisDesign {
                    fit_nrmse: interpolated_fit_error,
                    fit_nrmse_out_of_band: d0.fit_nrmse_out_of_band,
                    // The model is interpolated between the two fits, not
                    // fitted to lines of its own.
                    fit_uncertainty: f64::NAN,
                    ..d
                })
                .with_context(|| format!("model state s = {s}"))
        };
        // A state that cannot be designed is not a candidate; the first
        // FRF's own design always is.
        let design = match design {
            Ok(d) => d,
            Err(e) => {
                skipped.push((s, format!("{e:#}")));
                continue;
            }
        };
        let h = design.kalman.compensator.freq_responses(&freqs, opts.fs_hz);
        let noise = noise_term(design.kalman.r, opts.fs_hz, measured_plants.width, opts.force_rms);
        let j =
            |g: &[(f64, Complex64)], h: &[Complex64]| criterion_j(g, h, design.kalman.lag, opts.fs_hz, noise).sqrt();
        let errors: Vec<f64> = plants.iter().map(|g| j(g, &h)).collect();
        let measured = measured_plants.errors(&design, opts);
        let worst = errors.iter().copied().fold(measured.0.max(measured.1), f64::max);
        cands.push(RangeCandidate { s, design, errors, measured, worst });
    }
    // Ties go to the first FRF's own design (candidate 0): a range design
    // must predict strictly less to replace it.
    let best = (0..cands.len())
        .min_by(|&a, &b| cands[a].worst.total_cmp(&cands[b].worst))
        .ok_or_else(|| anyhow::anyhow!("axis {name}: no candidate state"))?;
    Ok(RangeDesign { states: ts, machine, above_band, candidates: cands, best, skipped })
}

/// The fit error a design at an interpolated state s (0 < s < 1) carries.
/// Such a design is fitted to its own model's response, so its own fit
/// error is zero by construction; it is given instead the worse of the two
/// measured states' model errors: the first FRF's fit (`d0`), and the
/// paired second state's model against the second FRF (relative RMS on its
/// coherent lines in the first design's band).
fn measured_states_fit_error(
    d0: &AxisDesign,
    freq_hz: &[f64],
    second: &AxisFrf,
    ts: &TwoState,
    coherence_threshold: f64,
) -> f64 {
    let band = d0.compensated_band_hz;
    let mask: Vec<bool> = (0..freq_hz.len())
        .map(|k| {
            let coherent = second.coherence.as_ref().is_none_or(|c| c[k] >= coherence_threshold);
            freq_hz[k] >= band.0 && freq_hz[k] <= band.1 && coherent
        })
        .collect();
    let m1 = ts.at(1.0);
    let e1 = crate::fit::relative_rms_error(|f| m1.frf(f), freq_hz, &second.frf, &mask);
    d0.fit_nrmse.max(e1)
}

/// What the range design makes of one axis whose first FRF can be designed.
#[derive(Clone, Debug)]
pub enum RangeOutcome {
    /// Designed for the range between the two states.
    Range(Box<RangeDesign>),
    /// The two FRFs could not be made one model of two states (the second
    /// fit, or the pairing of its modes, failed): the first FRF's own design
    /// is held over the range.
    Held(Box<HeldDesign>),
}

/// The first FRF's own design of an axis whose two states could not be
/// paired ([`RangeOutcome::Held`]).
#[derive(Clone, Debug)]
pub struct HeldDesign {
    /// The first FRF's single-state design.
    pub design: AxisDesign,
    /// Why the range could not be designed.
    pub why: String,
    /// Predicted in-band error of its filter on the first and the second FRF
    /// as measured (their lines in the criterion's band): what holding the
    /// first state costs at the far end of the range.
    pub measured: (f64, f64),
}

impl HeldDesign {
    /// The largest of the design's own predicted error and `measured`.
    pub fn worst(&self) -> f64 {
        self.design.predicted_error.max(self.measured.0).max(self.measured.1)
    }
}

impl RangeOutcome {
    /// The design the box image carries for the axis.
    pub fn chosen(&self) -> &AxisDesign {
        match self {
            RangeOutcome::Range(rd) => &rd.candidates[rd.best].design,
            RangeOutcome::Held(h) => &h.design,
        }
    }

    /// The first FRF's own (single-state) design.
    pub fn first(&self) -> &AxisDesign {
        match self {
            RangeOutcome::Range(rd) => &rd.candidates[0].design,
            RangeOutcome::Held(h) => &h.design,
        }
    }

    /// The range design, if the axis has one.
    pub fn range(&self) -> Option<&RangeDesign> {
        match self {
            RangeOutcome::Range(rd) => Some(rd),
            RangeOutcome::Held(_) => None,
        }
    }
}

/// The options of a two-state design: `opts` with both states fitted
/// without seeding pairs where the residual exceeds the noise
/// ([`VfOptions::seed_unfitted`]). The pairing of the two states' modes was
/// built and checked on fits without them; with them it failed the
/// independent case `two-state-z` and two drift tests. With the seeding
/// limited to below the main sensor mode, the drift sweep (40 drifts) still
/// held one more axis unpaired and took another's drift smoother from 1.01x
/// to 1.49x of its no-drift error (BENCHMARKS.md, "Terms the lines do not
/// support, dropped per axis").
pub fn two_state_options(opts: &DesignOptions) -> DesignOptions {
    DesignOptions { vf: VfOptions { seed_unfitted: false, ..opts.vf.clone() }, ..opts.clone() }
}

/// One axis for the range: [`design_over_range`], or where the first FRF
/// can be designed and the two states cannot be paired, the first FRF's own
/// design held over the range ([`RangeOutcome::Held`]), with
/// [`two_state_options`]. An error only where the first FRF itself cannot
/// be designed.
pub fn design_or_hold(
    freq_hz: &[f64],
    first: &AxisFrf,
    second: &AxisFrf,
    r: f64,
    opts: &DesignOptions,
    candidate_states: &[f64],
) -> Result<RangeOutcome> {
    let opts = &two_state_options(opts);
    let d0 = design_axis(freq_hz, first, r, opts).context("first FRF")?;
    match design_over_range(freq_hz, first, d0.clone(), second, r, opts, candidate_states) {
        Ok(rd) => Ok(RangeOutcome::Range(Box::new(rd))),
        Err(e) => {
            let ranges = criterion_ranges(&d0.bands, d0.compensated_band_hz);
            let measured = MeasuredPlants::new(freq_hz, first, second, &ranges).errors(&d0, opts);
            Ok(RangeOutcome::Held(Box::new(HeldDesign { design: d0, why: format!("{e:#}"), measured })))
        }
    }
}

/// [`design_or_hold`] for every axis of the FRFs `before` and `after`
/// (the same axes on the same lines `freq_hz`), on the machine's cores, with
/// the candidates [`RANGE_STATES`]; `r[axis]`: the measurement noise
/// variance R of each axis (N²). The results in axis order.
pub fn design_axes_over_range(
    freq_hz: &[f64],
    before: &[AxisFrf],
    after: &[AxisFrf],
    r: &[Option<f64>; 3],
    opts: &DesignOptions,
) -> Vec<Result<RangeOutcome>> {
    let pairs: Vec<(&AxisFrf, &AxisFrf)> = before.iter().zip(after).collect();
    map_on_threads(&pairs, |(a0, a1)| {
        let rv = r[a0.axis].expect("R set for every FRF axis");
        design_or_hold(freq_hz, a0, a1, rv, opts, &RANGE_STATES)
    })
}
