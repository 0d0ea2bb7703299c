//! The declared output latency L of an image, chosen when the user does not
//! give one (`design` without `--latency`, [`design_axes_choosing_latency`]).
//!
//! The fixed-lag smoother sees L samples past the force it estimates (plus
//! the discrete model's advance D, `crate::design::discretize`). Usually 4 is
//! plenty: the flat band reaches the top of the compensated band. Where a
//! sensor mode sits near or above the Nyquist frequency (a DAQ at 10.24 kHz),
//! inverting it over the whole band needs a longer look ahead.

use anyhow::{anyhow, Result};
use dynocomp_core::budget::{load_permille, AxisShape, CostModel};
use serde::Serialize;
use std::time::Instant;

use crate::design::axis::{design_prepared, prepare_axis, AxisDesign, DesignOptions, PreparedAxis};
use crate::design::discretize::{Discretization, NYQUIST_FIT_FRACTION};
use crate::design::look_ahead::{self, LookAhead};
use crate::design::paper_orders::design_axis;
use crate::design::progress::Progress;
use crate::frf::{axis_name, AxisFrf};
use crate::numeric::parallel::map_on_threads;

/// Latency designed first, and kept unless a longer one buys accuracy (samples).
pub const DEFAULT_LATENCY: usize = 4;
/// Latencies tried when the default falls short (samples; at most 8).
pub const LONGER_LATENCIES: [usize; 2] = [6, 8];
/// The longest latency the design chooses by itself (samples).
pub const LONGEST_LATENCY: usize = LONGER_LATENCIES[LONGER_LATENCIES.len() - 1];
/// A flat band whose top is below this fraction of the compensated band's top
/// falls short.
pub const FLAT_BAND_SHORT: f64 = 0.95;
/// A predicted in-band distortion (`AxisDesign::predicted_distortion`)
/// above this (fraction) falls short too: the accuracy target (median
/// ≤ 0.5 %). At 10.24 kHz the designs at latency 4 predict 0.7-1.9 %
/// of distortion on a flat force even where their flat band reaches the top
/// of the band: the smoother's own distortion near the band's top. Latency 8
/// brings stiff axes from 2.2-3.0x to 1.05-1.09x their noise floor there
/// (BENCHMARKS.md, "The declared latency, chosen"). The noise part is left out: an axis whose predicted error
/// is mostly noise (a weak force, `--force-prior level`) gains nothing from
/// looking further ahead. Designs that predict less, like the bundled
/// example's 0.02 % of distortion at 51.2 kHz, are designed once.
pub const PREDICTED_SHORT: f64 = 0.005;
/// A design quiet above its band ([`crate::design::above_band`]) whose noise
/// written above the band (√ of the q criterion's out-of-band part) exceeds
/// this multiple of its predicted in-band error falls short too: q was
/// chosen mostly for the noise above the band, which costs accuracy in it,
/// and a longer look-ahead separates the band from what lies above it more
/// sharply. On the bundled example at latency 4, y writes 0.69 % of noise
/// above the band against 0.25 % of error in it; at 8, 0.40 % and 0.17 %.
/// On the random sweep (seeds 0-199) this put 8 more axes of 600 within
/// 1.3x of their floor and 25 more outputs as written within 1.1x of a
/// perfect band-limited estimate (BENCHMARKS.md, "Longer latencies where
/// the noise above the band dominates").
pub const ABOVE_BAND_SHORT: f64 = 1.0;
/// The shortest latency whose every axis's predicted in-band error is
/// within this factor of that axis's best is kept: a longer latency must buy
/// more than 10 %.
pub const GAIN_NOT_WORTH: f64 = 1.1;

/// How the latency was chosen, for the summary, `--json` and the report.
#[derive(Clone, Debug, Serialize)]
pub struct LatencyChoice {
    /// The latency kept (samples).
    pub chosen: usize,
    /// Every latency designed, with each axis's predicted in-band error
    /// (fraction; `None` where that axis's design failed) and the predicted
    /// box load of the three designs (‰ of the period, pessimistic).
    pub tried: Vec<LatencyTrial>,
    /// Why the default was not enough (empty when it was).
    pub reason: String,
    /// Per axis: its discrete model was fitted up to Nyquist
    /// ([`crate::design::discretize::NYQUIST_FIT_FRACTION`]) instead of 0.45 fs,
    /// because that predicted a smaller error at the chosen latency.
    pub fit_to_nyquist: Vec<bool>,
    /// The axes whose box filter predicts over twice `compensate
    /// --offline`'s error, with what longer look-aheads would predict
    /// ([`crate::design::look_ahead`]).
    pub look_ahead: Vec<LookAhead>,
}

/// One latency designed.
#[derive(Clone, Debug, Serialize)]
pub struct LatencyTrial {
    /// Latency (samples).
    pub latency: usize,
    /// Predicted in-band error per axis (fraction), `None` if it failed.
    pub predicted_error: Vec<Option<f64>>,
    /// √ of each axis's q criterion at its q (fraction;
    /// `AxisDesign::predicted_criterion`): the in-band error with the noise
    /// written above the band, for a design quiet there.
    pub predicted_criterion: Vec<Option<f64>>,
    /// Predicted box load (‰, pessimistic), `None` if a design failed.
    pub load_permille: Option<u32>,
}

/// One axis's design and its wall time (s).
pub type TimedDesign = (Result<AxisDesign>, f64);

/// Design every axis of `axes` (one thread each) with `opts`, at `opts.lag`.
/// `r[i]` is axis i's noise variance (N²).
pub fn design_axes(freq_hz: &[f64], axes: &[AxisFrf], r: &[f64], opts: &DesignOptions) -> Vec<TimedDesign> {
    design_axes_reporting(freq_hz, axes, r, opts, &Progress::none())
}

/// [`design_axes`], telling `progress` when each axis starts and when it is
/// designed ([`axis_done`]).
pub fn design_axes_reporting(
    freq_hz: &[f64],
    axes: &[AxisFrf],
    r: &[f64],
    opts: &DesignOptions,
    progress: &Progress,
) -> Vec<TimedDesign> {
    let n = axes.len();
    on_threads(axes.iter().zip(r).enumerate(), |(i, (a, rv))| {
        progress.say(&format!(
            "{}: fitting {} FRF lines and designing at latency {}…",
            axis_of(a, i, n),
            freq_hz.len(),
            opts.lag
        ));
        let t = Instant::now();
        let d = design_axis(freq_hz, a, *rv, opts);
        progress.say(&axis_done(&axis_of(a, i, n), &format!("latency {}", opts.lag), &d, t.elapsed().as_secs_f64()));
        d
    })
}

/// "axis y (2/3)": axis `a`, the `i`-th (from 0) of `n`.
fn axis_of(a: &AxisFrf, i: usize, n: usize) -> String {
    format!("axis {} ({}/{n})", axis_name(a.axis), i + 1)
}

/// The stage line of one axis designed at `stage` in `seconds`: "axis y
/// (2/3) at latency 4: predicted error 0.12 %, flat to 3634 Hz, 248 ms".
fn axis_done(axis: &str, stage: &str, d: &Result<AxisDesign>, seconds: f64) -> String {
    let what = match d {
        Ok(d) => format!("predicted error {:.2} %, flat to {:.0} Hz", 100.0 * d.predicted_error, d.flat_band_hz.1),
        Err(_) => "failed".to_string(),
    };
    format!("{axis} at {stage}: {what}, {:.0} ms", seconds * 1e3)
}

/// `f` of every item on the machine's cores ([`map_on_threads`]), with each
/// one's wall time (s).
fn on_threads<I: Copy + Sync, T: Send>(items: impl Iterator<Item = I>, f: impl Fn(I) -> T + Sync) -> Vec<(T, f64)> {
    let items: Vec<I> = items.collect();
    map_on_threads(&items, |i| {
        let t = Instant::now();
        let d = f(*i);
        (d, t.elapsed().as_secs_f64())
    })
}

/// One axis prepared for every design round (`design::prepare_axis`: the
/// fit, done once), and its wall time (s).
type TimedPrepared = (Result<PreparedAxis>, f64);

/// Design every prepared axis at `opts.lag` and `opts.discrete_fit_top`;
/// each axis's time includes its preparation. An axis that could not be
/// prepared fails in every round with the same message. `progress` hears
/// each axis (labelled `labels[i]`) as it is designed at `stage`.
fn design_round(
    prepared: &[TimedPrepared],
    opts: &DesignOptions,
    labels: &[String],
    progress: &Progress,
    stage: &str,
) -> Vec<TimedDesign> {
    on_threads(prepared.iter().zip(labels), |((p, _), label)| {
        let t = Instant::now();
        let d = match p {
            Ok(p) => design_prepared(p, opts),
            Err(e) => Err(anyhow!("{e:#}")),
        };
        progress.say(&axis_done(label, stage, &d, t.elapsed().as_secs_f64()));
        d
    })
    .into_iter()
    .zip(prepared)
    .map(|((d, t), (_, tp))| (d, t + tp))
    .collect()
}

/// The reasons `why` gives for the axes of `designs` (each labelled by its
/// name in `axis_names`), joined ("" if it gives none).
fn axes_falling_short(
    designs: &[TimedDesign],
    axis_names: &[String],
    why: impl Fn(&Result<AxisDesign>, &str) -> Option<String>,
) -> String {
    let why: Vec<String> = designs.iter().zip(axis_names).filter_map(|((d, _), name)| why(d, name)).collect();
    why.join(", ")
}

/// Why the designs at the default latency fall short in their band ("" if
/// they do not): a flat band short of the band's top, a failed axis, or
/// more than [`PREDICTED_SHORT`] of distortion.
fn shortfall(designs: &[TimedDesign], axis_names: &[String]) -> String {
    axes_falling_short(designs, axis_names, |d, name| match d {
        Err(_) => Some(format!("axis {name} failed")),
        Ok(d) => {
            let (flat, comp) = (d.flat_band_hz.1, d.compensated_band_hz.1);
            if flat < FLAT_BAND_SHORT * comp {
                Some(format!("axis {name} flat to {flat:.0} of {comp:.0} Hz"))
            } else {
                (d.predicted_distortion > PREDICTED_SHORT).then(|| {
                    format!(
                        "axis {name} predicts {:.2} % of distortion (> {:.1} %)",
                        100.0 * d.predicted_distortion,
                        100.0 * PREDICTED_SHORT
                    )
                })
            }
        }
    })
}

/// The axes of `designs` whose noise written above the band exceeds
/// [`ABOVE_BAND_SHORT`] times their in-band error ("" if none).
fn noisy_above_band(designs: &[TimedDesign], axis_names: &[String]) -> String {
    axes_falling_short(designs, axis_names, |d, name| {
        let d = d.as_ref().ok()?;
        let above = (d.predicted_criterion.powi(2) - d.predicted_error.powi(2)).max(0.0).sqrt();
        (above > ABOVE_BAND_SHORT * d.predicted_error).then(|| {
            format!(
                "axis {name} writes {:.2} % of noise above the band, more than its {:.2} % in it",
                100.0 * above,
                100.0 * d.predicted_error
            )
        })
    })
}

/// Predicted box load (‰ of the period, pessimistic) of `designs`, if all succeeded.
fn box_load(designs: &[TimedDesign], fs_hz: f64) -> Option<u32> {
    box_load_of(designs.iter(), fs_hz)
}

fn box_load_of<'a>(designs: impl Iterator<Item = &'a TimedDesign>, fs_hz: f64) -> Option<u32> {
    let shapes: Option<Vec<AxisShape>> =
        designs.map(|(d, _)| d.as_ref().ok().map(|d| AxisShape::of(&d.filter))).collect();
    Some(load_permille(CostModel::CORTEX_M4.sample_cost(&shapes?).high, fs_hz as u32))
}

/// The trial record of one latency's designs.
fn trial(latency: usize, designs: &[TimedDesign], fs_hz: f64) -> LatencyTrial {
    LatencyTrial {
        latency,
        predicted_error: designs.iter().map(|(d, _)| d.as_ref().ok().map(|d| d.predicted_error)).collect(),
        predicted_criterion: designs.iter().map(|(d, _)| d.as_ref().ok().map(|d| d.predicted_criterion)).collect(),
        load_permille: box_load(designs, fs_hz),
    }
}

/// The index in `trials` of the latency kept
/// ([`design_axes_choosing_latency`]).
pub fn pick(trials: &[LatencyTrial], limit_permille: Option<u32>) -> usize {
    let runnable = |t: &LatencyTrial| match (limit_permille, t.load_permille) {
        (Some(l), Some(p)) => p <= l,
        (None, Some(_)) => true,
        (_, None) => false,
    };
    // The box's limit first: among the runnable latencies when there are any.
    let any_runnable = trials.iter().any(runnable);
    let candidates: Vec<usize> = (0..trials.len()).filter(|i| !any_runnable || runnable(&trials[*i])).collect();
    let n_axes = trials.first().map_or(0, |t| t.predicted_error.len());
    let best: Vec<f64> = (0..n_axes)
        .map(|a| candidates.iter().filter_map(|i| trials[*i].predicted_error[a]).fold(f64::INFINITY, f64::min))
        .collect();
    let good = |t: &LatencyTrial| {
        t.predicted_error.iter().zip(&best).all(|(e, b)| match e {
            Some(e) => *e <= GAIN_NOT_WORTH * b,
            None => !b.is_finite(),
        })
    };
    // Axes whose bests lie at different latencies: the least worst ratio to them.
    let worst_ratio = |t: &LatencyTrial| {
        t.predicted_error.iter().zip(&best).map(|(e, b)| e.map_or(f64::INFINITY, |e| e / b)).fold(0.0, f64::max)
    };
    candidates
        .iter()
        .copied()
        .find(|i| good(&trials[*i]))
        .or_else(|| {
            candidates.iter().copied().min_by(|a, b| worst_ratio(&trials[*a]).total_cmp(&worst_ratio(&trials[*b])))
        })
        .unwrap_or(0)
}

/// Design every axis at the chosen latency. `opts.lag` is ignored; `limit_permille` is the box's load limit the image should meet.
/// `progress` hears when each axis's fit starts ("axis y (2/3): fitting
/// 4097 FRF lines…"), each candidate latency as its round starts, with what
/// it is for ("latency 6 samples (candidate 2/3): axis z flat to 2088 of
/// 4096 Hz at latency 4: designing again…"), and each axis as it is
/// designed in a round ("axis y (2/3) at latency 6: predicted error …").
///
/// Design at [`DEFAULT_LATENCY`]. Where an axis fails, its flat band stops
/// short of its compensated band ([`FLAT_BAND_SHORT`]), its predicted
/// in-band distortion (the error without the noise, what looking further
/// ahead can lower) is above [`PREDICTED_SHORT`], or the noise it writes
/// above the band exceeds its in-band error ([`ABOVE_BAND_SHORT`]), design
/// again at each of [`LONGER_LATENCIES`] and keep the shortest latency at
/// which every axis's predicted in-band error (`AxisDesign::predicted_error`,
/// DESIGN.md's criterion) is within [`GAIN_NOT_WORTH`] of the best that
/// axis reached at any latency tried, among the latencies whose image the
/// box can still run (when a load limit is given and any candidate meets
/// it; [`pick`]). One latency serves all axes: the image declares one.
/// Where the default fell short in its band, each axis's discrete model is
/// also fitted up to Nyquist at the chosen latency
/// ([`NYQUIST_FIT_FRACTION`]), and the one with the smaller predicted
/// in-band error is kept per axis.
pub fn design_axes_choosing_latency(
    freq_hz: &[f64],
    axes: &[AxisFrf],
    r: &[f64],
    opts: &DesignOptions,
    limit_permille: Option<u32>,
    progress: &Progress,
) -> (Vec<TimedDesign>, LatencyChoice) {
    let rounds = Rounds::new(freq_hz, axes, r, opts, progress);
    let Tried { trials, mut designed, reason, short_in_band } = try_latencies(&rounds);
    let i = pick(&trials, limit_permille);
    let mut designs = designed.swap_remove(i);
    let mut fit_to_nyquist = vec![false; designs.len()];
    if short_in_band && opts.discretization == Discretization::Fit {
        (designs, fit_to_nyquist) = fitted_to_nyquist_where_better(&rounds, designs, trials[i].latency, limit_permille);
    }
    let lag = trials[i].latency;
    let look_ahead = looked_further(&rounds, &designs, lag, &fit_to_nyquist);
    (designs, LatencyChoice { chosen: lag, tried: trials, reason, fit_to_nyquist, look_ahead })
}

/// Beside the chosen designs (at `lag`, each fitted up to Nyquist where
/// `fit_to_nyquist`), the longer look-aheads of the axes the box leaves
/// far behind `--offline` ([`crate::design::look_ahead`]).
fn looked_further(rounds: &Rounds, designs: &[TimedDesign], lag: usize, fit_to_nyquist: &[bool]) -> Vec<LookAhead> {
    let wanted: Vec<(&TimedPrepared, &AxisDesign, bool)> = rounds
        .prepared
        .iter()
        .zip(designs)
        .zip(fit_to_nyquist)
        .filter_map(|((p, (d, _)), n)| {
            d.as_ref().ok().filter(|d| look_ahead::wanted(d, rounds.opts)).map(|d| (p, d, *n))
        })
        .collect();
    if wanted.is_empty() {
        return Vec::new();
    }
    let names: Vec<&str> = wanted.iter().map(|w| axis_name(w.1.axis)).collect();
    rounds.progress.say(&format!(
        "axis {}: the box filter predicts over twice compensate --offline's error: predicting longer look-aheads…",
        names.join(", ")
    ));
    let at_top = |n: bool| match n {
        true => NYQUIST_FIT_FRACTION,
        false => rounds.opts.discrete_fit_top,
    };
    let t = Instant::now();
    let found: Vec<LookAhead> = on_threads(wanted.into_iter(), |((p, _), d, n)| {
        let o = DesignOptions { lag, discrete_fit_top: at_top(n), ..rounds.opts.clone() };
        p.as_ref().ok().and_then(|p| look_ahead::look_ahead(p, &o, d, LONGEST_LATENCY))
    })
    .into_iter()
    .filter_map(|(l, _)| l)
    .collect();
    rounds.progress.say(&format!("longer look-aheads predicted in {:.0} ms", 1e3 * t.elapsed().as_secs_f64()));
    found
}

/// The axes of [`design_axes_choosing_latency`], designed a round at a time:
/// each axis is fitted once for all rounds (only the discrete model's fit
/// top, the latency and what follows from them change between rounds),
/// except with `--paper-orders auto`, which designs each round whole.
struct Rounds<'a> {
    freq_hz: &'a [f64],
    axes: &'a [AxisFrf],
    r: &'a [f64],
    opts: &'a DesignOptions,
    progress: &'a Progress,
    /// "axis y (2/3)" of each axis.
    labels: Vec<String>,
    /// Each axis fitted (empty with `paper_orders_auto`).
    prepared: Vec<TimedPrepared>,
}

impl<'a> Rounds<'a> {
    /// Fit every axis (one thread each), telling `progress`.
    fn new(
        freq_hz: &'a [f64],
        axes: &'a [AxisFrf],
        r: &'a [f64],
        opts: &'a DesignOptions,
        progress: &'a Progress,
    ) -> Self {
        let n = axes.len();
        let labels: Vec<String> = axes.iter().enumerate().map(|(i, a)| axis_of(a, i, n)).collect();
        let prepared = if opts.paper_orders_auto {
            Vec::new()
        } else {
            on_threads(axes.iter().zip(r).zip(&labels), |((a, rv), label)| {
                progress.say(&format!("{label}: fitting {} FRF lines…", freq_hz.len()));
                prepare_axis(freq_hz, a, *rv, opts)
            })
        };
        Rounds { freq_hz, axes, r, opts, progress, labels, prepared }
    }

    /// Every axis designed with `o` (at `o.lag`, `o.discrete_fit_top`).
    fn design(&self, o: &DesignOptions) -> Vec<TimedDesign> {
        if self.opts.paper_orders_auto {
            design_axes_reporting(self.freq_hz, self.axes, self.r, o, self.progress)
        } else {
            let stage = if o.discrete_fit_top == NYQUIST_FIT_FRACTION {
                format!("latency {}, fitted up to Nyquist", o.lag)
            } else {
                format!("latency {}", o.lag)
            };
            design_round(&self.prepared, o, &self.labels, self.progress, &stage)
        }
    }

    /// Every axis designed at latency `lag`.
    fn at(&self, lag: usize) -> Vec<TimedDesign> {
        self.design(&DesignOptions { lag, ..self.opts.clone() })
    }
}

/// The latencies tried, each with its designs, and why the default was not
/// enough (empty when it was).
struct Tried {
    trials: Vec<LatencyTrial>,
    designed: Vec<Vec<TimedDesign>>,
    reason: String,
    /// The default fell short in its band ([`shortfall`]), not only above
    /// it ([`noisy_above_band`]).
    short_in_band: bool,
}

/// Design at [`DEFAULT_LATENCY`] and, where that falls short in the band
/// ([`shortfall`]) or above it ([`noisy_above_band`]), again at each of
/// [`LONGER_LATENCIES`].
fn try_latencies(rounds: &Rounds) -> Tried {
    let (n, fs_hz, progress) = (rounds.axes.len(), rounds.opts.fs_hz, rounds.progress);
    let names: Vec<String> = rounds.axes.iter().map(|a| axis_name(a.axis).to_string()).collect();
    let candidates = 1 + LONGER_LATENCIES.len();
    progress
        .say(&format!("latency {DEFAULT_LATENCY} samples (candidate 1 of up to {candidates}): designing {n} axes…"));
    let first = rounds.at(DEFAULT_LATENCY);
    let in_band = shortfall(&first, &names);
    let short_in_band = !in_band.is_empty();
    let reason = [in_band, noisy_above_band(&first, &names)]
        .into_iter()
        .filter(|r| !r.is_empty())
        .collect::<Vec<_>>()
        .join(", ");
    let mut trials = vec![trial(DEFAULT_LATENCY, &first, fs_hz)];
    let mut designed = vec![first];
    if !reason.is_empty() {
        for (k, l) in LONGER_LATENCIES.into_iter().enumerate() {
            progress.say(&format!(
                "latency {l} samples (candidate {}/{candidates}): {reason} at latency {DEFAULT_LATENCY}: designing \
                 again…",
                k + 2
            ));
            let d = rounds.at(l);
            trials.push(trial(l, &d, fs_hz));
            designed.push(d);
        }
    }
    Tried { trials, designed, reason, short_in_band }
}

/// At the chosen latency `lag`, the discrete models fitted up to Nyquist
/// instead ([`NYQUIST_FIT_FRACTION`]): per axis, the design that predicts
/// the smaller error, unless that puts the image over the box's load limit
/// where `designs` were not. Returns the designs kept and, per axis,
/// whether it is the one fitted up to Nyquist.
fn fitted_to_nyquist_where_better(
    rounds: &Rounds,
    designs: Vec<TimedDesign>,
    lag: usize,
    limit_permille: Option<u32>,
) -> (Vec<TimedDesign>, Vec<bool>) {
    let fs_hz = rounds.opts.fs_hz;
    let stage = format!("latency {lag} samples (chosen): fitting the discrete models up to Nyquist instead…");
    rounds.progress.say(&stage);
    let alt = rounds.design(&DesignOptions { lag, discrete_fit_top: NYQUIST_FIT_FRACTION, ..rounds.opts.clone() });
    let before = box_load(&designs, fs_hz);
    let taken: Vec<bool> = designs
        .iter()
        .zip(&alt)
        .map(|(d, a)| match (&d.0, &a.0) {
            (Ok(d), Ok(a)) => a.predicted_error < d.predicted_error,
            (Err(_), Ok(_)) => true,
            _ => false,
        })
        .collect();
    let pairs: Vec<(TimedDesign, TimedDesign)> = designs.into_iter().zip(alt).collect();
    let load_with = box_load_of(pairs.iter().zip(&taken).map(|((d, a), t)| if *t { a } else { d }), fs_hz);
    let runs = |p: Option<u32>| match (limit_permille, p) {
        (Some(lim), Some(p)) => p <= lim,
        _ => true,
    };
    // Never over the box's limit where the first choice was not.
    let fit_to_nyquist = if runs(load_with) || !runs(before) { taken } else { vec![false; pairs.len()] };
    let designs = pairs.into_iter().zip(&fit_to_nyquist).map(|((d, a), t)| if *t { a } else { d }).collect();
    (designs, fit_to_nyquist)
}

/// One summary line: "latency 8 samples, chosen: at 4 axis x flat to 2088 of
/// 4096 Hz; predicted error x/y/z 8.82/8.01/10.51 % at 4, … at 8".
pub fn describe(c: &LatencyChoice, axis_names: &[&str]) -> String {
    if c.reason.is_empty() {
        return format!("latency {} samples (default: on every axis the flat band reaches the compensated band's top, the predicted distortion is within {:.1} % and the noise written above the band within the in-band error)", c.chosen, 100.0 * PREDICTED_SHORT);
    }
    let pct = |v: &[Option<f64>]| -> String {
        v.iter().map(|e| e.map_or("failed".into(), |e| format!("{:.2}", 100.0 * e))).collect::<Vec<_>>().join("/")
    };
    let per: Vec<String> = c
        .tried
        .iter()
        .map(|t| {
            let load = t.load_permille.map_or(String::new(), |p| format!(", load {:.1} %", f64::from(p) / 10.0));
            let with_above = match t.predicted_criterion == t.predicted_error {
                true => String::new(),
                false => format!(" (with the noise written above the band {})", pct(&t.predicted_criterion)),
            };
            format!("{}{with_above} at {}{}", pct(&t.predicted_error), t.latency, load)
        })
        .collect();
    let nyq: Vec<&str> = axis_names.iter().zip(&c.fit_to_nyquist).filter(|(_, t)| **t).map(|(n, _)| *n).collect();
    let nyq = if nyq.is_empty() {
        String::new()
    } else {
        format!("; discrete model of {} fitted up to Nyquist (smaller predicted error)", nyq.join(", "))
    };
    // An axis that failed at every latency tried does not take part in the
    // choice ([`pick`]): said apart, so that the reason to look further does
    // not read as the reason for the latency kept.
    let failed: Vec<&str> = axis_names
        .iter()
        .enumerate()
        .filter(|(a, _)| c.tried.iter().all(|t| t.predicted_error.get(*a).is_some_and(|e| e.is_none())))
        .map(|(_, n)| *n)
        .collect();
    let failed = match failed.len() {
        0 => String::new(),
        _ => format!(
            "; axis {} failed at every latency tried, so its load is not known and the box's limit did not take part in the choice",
            failed.join(", ")
        ),
    };
    format!(
        "latency {} samples: longer latencies were tried because at {}: {}, and the shortest within {:.1}x of every axis's best predicted error kept (else the least worst ratio); predicted error {} %: {}{nyq}{failed}",
        c.chosen,
        DEFAULT_LATENCY,
        c.reason,
        GAIN_NOT_WORTH,
        axis_names.join("/"),
        per.join("; ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An axis that fails at every latency is said apart from the reason
    /// to look further (the example with z's calibration wrong tenfold read
    /// "chosen because at 4: axis z failed" for a latency y's gain chose).
    /// Control: an axis that fails only at the default is not.
    #[test]
    fn an_axis_failed_at_every_latency_is_said_apart() {
        let trial = |latency, z| LatencyTrial {
            latency,
            predicted_error: vec![Some(0.0026), Some(if latency == 8 { 0.0015 } else { 0.0027 }), z],
            predicted_criterion: vec![Some(0.0026), Some(if latency == 8 { 0.0015 } else { 0.0027 }), z],
            load_permille: None,
        };
        let choice = |z8| LatencyChoice {
            chosen: 8,
            tried: vec![trial(4, None), trial(8, z8)],
            reason: "axis z failed".into(),
            fit_to_nyquist: vec![false; 3],
            look_ahead: Vec::new(),
        };
        let text = describe(&choice(None), &["x", "y", "z"]);
        assert!(text.contains("longer latencies were tried because at 4: axis z failed"), "{text}");
        assert!(text.contains("axis z failed at every latency tried"), "{text}");
        let text = describe(&choice(Some(0.003)), &["x", "y", "z"]);
        assert!(!text.contains("failed at every latency"), "{text}");
    }

    fn t(latency: usize, e: &[Option<f64>], load: Option<u32>) -> LatencyTrial {
        LatencyTrial { latency, predicted_error: e.to_vec(), predicted_criterion: e.to_vec(), load_permille: load }
    }

    #[test]
    fn keeps_the_shortest_latency_within_reach_of_every_axis_best() {
        // x gains 3x from 4 to 6, nothing more at 8: 6 is kept.
        let tr = [
            t(4, &[Some(0.09), Some(0.01)], Some(80)),
            t(6, &[Some(0.03), Some(0.01)], Some(85)),
            t(8, &[Some(0.029), Some(0.01)], Some(90)),
        ];
        assert_eq!(pick(&tr, Some(600)), 1);
        // Negative control: with no gain anywhere, the default stays.
        let flat = [
            t(4, &[Some(0.03), Some(0.01)], Some(80)),
            t(6, &[Some(0.029), Some(0.01)], Some(85)),
            t(8, &[Some(0.028), Some(0.01)], Some(90)),
        ];
        assert_eq!(pick(&flat, Some(600)), 0);
    }

    #[test]
    fn an_axis_that_fails_at_the_default_is_rescued_and_the_load_limit_is_respected() {
        let tr = [
            t(4, &[None, Some(0.01)], None),
            t(6, &[Some(0.05), Some(0.01)], Some(90)),
            t(8, &[Some(0.02), Some(0.01)], Some(700)),
        ];
        // 8 is best but over the box's limit: 6, the best the box can run.
        assert_eq!(pick(&tr, Some(600)), 1);
        // Without a limit, 8.
        assert_eq!(pick(&tr, None), 2);
        // Axes whose bests lie apart: the least worst ratio (6: 1.2x, 8: 2x).
        let apart = [
            t(4, &[Some(0.09), Some(0.09)], Some(80)),
            t(6, &[Some(0.03), Some(0.024)], Some(85)),
            t(8, &[Some(0.06), Some(0.02)], Some(90)),
        ];
        assert_eq!(pick(&apart, Some(600)), 1);
    }
}
