//! The random two-state drifts of the sweep (`examples/drift_sweep.rs`, #34
//! item 5): a set-up of [`super::sweep::draw`] whose sensor modes drift by
//! ±1-5 % during the cut, with impact tests before and after. Each axis is
//! designed for the range as `design --frf BEFORE --frf AFTER` does and
//! scored against the band-limited truth, on the box and offline, beside the
//! single-state design of the first FRF and the same cut without drift.
//! The seeds are fixed in the example and were never picked by looking at
//! results.

use anyhow::Result;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::design::axis::AxisDesign;
use crate::design::image::build_image;
use crate::design::pass_through::pass_through;
use crate::design::two_state::range::{design_axes_over_range, RangeOutcome};
use crate::eval::rates::{design_options, scoring_band_hz, RateCase, RunOptions};
use crate::io::signal_csv::SignalRecord;
use crate::metrics::{accuracy, sample_variance};
use crate::offline::compensate::compensate_record;
use crate::offline::drift::{smooth_drifting, DriftSmoothing};
use crate::offline::smoother::Smoother;
use crate::simulate::drift::{simulate_drifting, Drift};
use crate::simulate::simulate_with;

/// One random drift: the set-up and cut, the rate, the kind of dynamometer
/// ([`super::sweep::draw`]) and the drift of its sensor modes.
#[derive(Clone, Debug)]
pub struct DriftCase {
    /// The set-up, impact test and cut.
    pub case: RateCase,
    /// DAQ rate (Hz).
    pub fs_hz: f64,
    /// Kind of dynamometer.
    pub kind: &'static str,
    /// The drift: ±1-5 %, starting in the first quarter of the record and
    /// ending in the last.
    pub drift: Drift,
}

/// Offset of the drift sweep's set-ups among [`super::sweep::draw`]'s seeds,
/// apart from the stationary sweep's 0..100.
pub const SETUP_SEED_OFFSET: u64 = 1000;

/// The drift of seed `seed`: the set-up of [`super::sweep::draw`]
/// (`SETUP_SEED_OFFSET + seed`) and a drift from its own random stream.
pub fn draw_drift(seed: u64) -> DriftCase {
    let (case, fs_hz, kind) = super::sweep::draw(SETUP_SEED_OFFSET + seed);
    let mut rng = ChaCha8Rng::seed_from_u64(0xd21f_0000 + seed);
    let size = rng.random_range(0.01..0.05);
    let delta = if rng.random_bool(0.5) { size } else { -size };
    let duration = case.sim_params(fs_hz).duration_s;
    let start_s = rng.random_range(0.0..0.25) * duration;
    let end_s = rng.random_range(0.75..1.0) * duration;
    DriftCase { case, fs_hz, kind, drift: Drift { delta, start_s, end_s } }
}

/// Figures of one axis of a drift case, NRMSE against the band-limited truth.
#[derive(Clone, Debug)]
pub struct DriftAxisScore {
    /// Axis index.
    pub axis: usize,
    /// Raw measurement of the drifting cut.
    pub raw: f64,
    /// The exact inverse's noise floor on the set-up before the drift
    /// ([`crate::eval::rates::noise_floor`]).
    pub noise_floor: f64,
    /// The axis's design, or why its first FRF cannot be designed (`design`
    /// then passes it through raw).
    pub design: std::result::Result<DriftDesigned, String>,
}

/// Figures of an axis whose first FRF was designed.
#[derive(Clone, Debug)]
pub struct DriftDesigned {
    /// Why the two states could not be paired, where the axis holds the
    /// first FRF's design (`None`: designed for the range).
    pub held: Option<String>,
    /// Model state of the chosen box design (0: the first FRF's own design kept).
    pub chosen_s: f64,
    /// Its predicted worst in-band error over the range.
    pub predicted_worst: f64,
    /// Box image of the range design on the drifting cut.
    pub box_two_state: f64,
    /// Box image of the first FRF's own design on the drifting cut.
    pub box_single: f64,
    /// `compensate --offline --drift` (both states, the drift's interval) on
    /// the drifting cut.
    pub offline_drift: f64,
    /// `compensate --offline` with the first FRF only, on the drifting cut.
    pub offline_held: f64,
    /// `compensate --offline` with the first FRF, on the same cut (force and
    /// noise) without drift: the error the drift smoother should come back to.
    pub offline_no_drift: f64,
    /// Static gain Re Ĝ(0) of the paired model at the first and the second
    /// state (N/N; NaN where held); the simulated drift, a mass change,
    /// keeps the true one.
    pub static_gains: (f64, f64),
}

/// Simulate `c`, design the range for every axis and score it.
pub fn run_drift_case(c: &DriftCase) -> Result<Vec<DriftAxisScore>> {
    let fs = c.fs_hz;
    let params = c.case.sim_params(fs);
    let dyno = c.case.dynamometer(&params)?;
    let still = simulate_with(c.case.seed, &params, dyno.clone())?;
    let out = simulate_drifting(c.case.seed, &params, dyno, c.drift)?;
    let s = &out.sim;
    let band = scoring_band_hz(fs);
    let opts =
        design_options(fs, &RunOptions { lag: Some(crate::design::latency::DEFAULT_LATENCY), ..Default::default() });
    let r: [Option<f64>; 3] = [0, 1, 2].map(|a| Some(sample_variance(&s.idle[a])));
    let outcomes = design_axes_over_range(&s.frf.freq_hz, &s.frf.axes, &out.frf_after.axes, &r, &opts);
    // The box images as `design` writes them: an axis whose first FRF
    // cannot be designed passed through raw; none where no axis can be.
    let image_of = |pick: &dyn Fn(&RangeOutcome) -> AxisDesign| -> Result<Option<Vec<AxisDesign>>> {
        if outcomes.iter().all(|o| o.is_err()) {
            return Ok(None);
        }
        let designs = outcomes
            .iter()
            .zip(&s.frf.axes)
            .map(|(o, a)| match o {
                Ok(o) => Ok(pick(o)),
                Err(e) => pass_through(a, r[a.axis].unwrap_or_default(), &opts, format!("{e:#}")),
            })
            .collect::<Result<_>>()?;
        Ok(Some(designs))
    };
    let chosen = image_of(&|o| o.chosen().clone())?;
    let first = image_of(&|o| o.first().clone())?;
    let record = SignalRecord { t_s: None, channels: (0..3).map(|a| (a, s.measured[a].clone())).collect() };
    let on_box = |designs: &Option<Vec<AxisDesign>>| -> Result<Option<SignalRecord>> {
        let Some(d) = designs else { return Ok(None) };
        let image = build_image(d, fs as u32, opts.lag, 5000.0, [0; 32])?;
        Ok(Some(compensate_record(&image, &record, false, "drift sweep")?))
    };
    let (box_two, box_one) = (on_box(&chosen)?, on_box(&first)?);
    let score = |x: &[f64], a: usize| accuracy(x, &s.truth[a], fs, band).nrmse;
    let mut axes = Vec::new();
    for (a, outcome) in outcomes.into_iter().enumerate() {
        let raw = accuracy(&s.measured[a], &s.truth[a], fs, band);
        let std_truth = raw.rms_error_n / raw.nrmse;
        let r_true = params.measurement.expected_idle_variance();
        let noise_floor = crate::eval::rates::noise_floor(|f| s.dyno.axis(a).frf(f), r_true, fs, band, std_truth);
        let design = match outcome {
            Err(e) => Err(format!("{e:#}")),
            Ok(o) => {
                let (best, d0) = (o.chosen(), o.first());
                let (dm0, _) = d0.discrete.as_ref().ok_or_else(|| anyhow::anyhow!("axis {a}: no discrete model"))?;
                let held = Smoother::new(dm0, d0.kalman.q, d0.kalman.r)?;
                let held_est = held.smooth(&s.measured[a]);
                // The smoother settings of `compensate --offline --drift`
                // (offline::drift::axis_drift): the first state's band and
                // structure, the image's q and R; an axis holding the first
                // state is smoothed with its model alone.
                let (drift_est, static_gains) = match o.range() {
                    Some(rd) => {
                        let settings = DriftSmoothing {
                            fs_hz: fs,
                            interval_s: (c.drift.start_s, c.drift.end_s),
                            band_hz: d0.compensated_band_hz,
                            structure: (dm0.fir.len(), dm0.advance),
                            q: best.kalman.q,
                            r: best.kalman.r,
                        };
                        let est = smooth_drifting(&s.measured[a], &|x| rd.states.at(x), &settings)?;
                        (est, (rd.states.at(0.0).frf(0.0).re, rd.states.at(1.0).frf(0.0).re))
                    }
                    None => (held_est.clone(), (f64::NAN, f64::NAN)),
                };
                let column = |rec: &Option<SignalRecord>| {
                    rec.as_ref().and_then(|r| r.channel(a)).map_or(f64::NAN, |x| score(x, a))
                };
                let (chosen_s, predicted_worst, held_why) = match &o {
                    RangeOutcome::Range(rd) => (rd.candidates[rd.best].s, rd.candidates[rd.best].worst, None),
                    RangeOutcome::Held(h) => (0.0, h.worst(), Some(h.why.clone())),
                };
                Ok(DriftDesigned {
                    held: held_why,
                    chosen_s,
                    predicted_worst,
                    box_two_state: column(&box_two),
                    box_single: column(&box_one),
                    offline_drift: score(&drift_est, a),
                    offline_held: score(&held_est, a),
                    offline_no_drift: accuracy(&held.smooth(&still.measured[a]), &still.truth[a], fs, band).nrmse,
                    static_gains,
                })
            }
        };
        axes.push(DriftAxisScore { axis: a, raw: raw.nrmse, noise_floor, design });
    }
    Ok(axes)
}
