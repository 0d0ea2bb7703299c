//! The multi-rate accuracy harness: simulated dynamometers and cuts at the
//! sample rates DAQs use, designed and compensated with the public API (as
//! `dynocomp design` + `compensate` do), scored against the band-limited truth.
//!
//! Used by `examples/rates.rs` (the benchmark table of BENCHMARKS.md) and
//! meant for end-to-end threshold tests: [`cases`], [`run_case`] and
//! [`summarize`] are the whole pipeline. Every design goes through
//! [`design_options`], the one place that turns the harness's [`RunOptions`]
//! into [`DesignOptions`].

use anyhow::Result;
use num_complex::Complex64;
use std::time::Instant;

use crate::design::axis::DesignOptions;
use crate::design::image::build_image;
use crate::design::kalman::KalmanDesign;
use crate::io::signal_csv::SignalRecord;
use crate::metrics::{accuracy, accuracy_as_written, sample_variance, AsWritten};
use crate::offline::compensate::compensate_record;
use crate::simulate::{
    simulate_with, Chatter, Dynamometer, Mode, ModeRanges, MultiAxisDynamometer, SimOutput, SimParams,
};
use dynocomp_core::budget::BOX_LOAD_LIMIT_PERMILLE;

/// The DAQ sample rates of the harness (Hz).
pub const RATES_HZ: [f64; 4] = [10_240.0, 25_600.0, 51_200.0, 102_400.0];

/// Upper edge of the scoring band at `fs_hz`: min(4 kHz, 0.4 fs).
pub fn scoring_band_hz(fs_hz: f64) -> f64 {
    crate::metrics::scoring_band_hz(fs_hz)
}

/// How the dynamometer of a case is made.
#[derive(Clone, Debug)]
pub enum DynoSpec {
    /// Random axes from these ranges (seeded by the case).
    Random(ModeRanges),
    /// Random axes, then on each a second mode `spacing` (relative, e.g.
    /// 0.06 = 6 %) above the main one, carrying `share` of its residue.
    ClosePair {
        /// Ranges of the random axes.
        ranges: ModeRanges,
        /// Relative spacing of the pair.
        spacing: f64,
        /// Share of the main residue moved to the second mode.
        share: f64,
    },
}

/// One simulated situation, run at every rate of [`RATES_HZ`].
#[derive(Clone, Debug)]
pub struct RateCase {
    /// Short name for the table.
    pub name: &'static str,
    /// Seed of the dynamometer, impact test and noise (the same at every fs).
    pub seed: u64,
    /// Dynamometer.
    pub dyno: DynoSpec,
    /// Impact test line spacing (Hz).
    pub frf_df_hz: f64,
    /// Impact test band: lines 0..=frf_max_hz.
    pub frf_max_hz: f64,
    /// Spindle speed (rpm).
    pub spindle_rpm: f64,
    /// Number of teeth.
    pub teeth: usize,
    /// Regenerative chatter frequency (Hz), if any.
    pub chatter_hz: Option<f64>,
}

impl RateCase {
    /// Tooth-passing frequency (Hz).
    pub fn tpf_hz(&self) -> f64 {
        self.spindle_rpm / 60.0 * self.teeth as f64
    }

    /// The simulation parameters of this case at `fs_hz` (default chain: the
    /// ideal brick wall at 0.45 fs).
    pub fn sim_params(&self, fs_hz: f64) -> SimParams {
        let mut p = SimParams { fs_hz, duration_s: 0.4, idle_duration_s: 0.3, ..Default::default() };
        p.milling.spindle_rpm = self.spindle_rpm;
        p.milling.teeth = self.teeth;
        p.milling.chatter =
            self.chatter_hz.map(|f| Chatter { freq_hz: f, amplitude_mm: 0.01, onset_s: 0.2, growth_s: 0.02 });
        p.impact.df_hz = self.frf_df_hz;
        // The impact test covers frf_max_hz whatever the box's rate (an impact
        // analyzer has its own; the design compensates up to 0.45 fs and fits
        // the lines above).
        p.impact.n_lines = (self.frf_max_hz / self.frf_df_hz).floor() as usize + 1;
        // A metal tip: the hammer's spectrum is flat past the FRF band.
        p.impact.hammer_cutoff_hz = 5000f64.max(1.25 * self.frf_max_hz);
        let (DynoSpec::Random(r) | DynoSpec::ClosePair { ranges: r, .. }) = &self.dyno;
        p.modes = r.clone();
        p
    }

    /// The dynamometer of this case.
    pub fn dynamometer(&self, params: &SimParams) -> Result<MultiAxisDynamometer> {
        let base = MultiAxisDynamometer::random(crate::simulate::sub_seed(self.seed, 1), params);
        match &self.dyno {
            DynoSpec::Random(_) => Ok(base),
            DynoSpec::ClosePair { spacing, share, .. } => {
                let pair = |d: &Dynamometer| -> Result<Dynamometer> {
                    let main = d.main_mode();
                    let mut modes: Vec<Mode> = d.modes.iter().copied().filter(|m| *m != main).collect();
                    modes.push(Mode { residue: main.residue * (1.0 - share), ..main });
                    modes.push(Mode { fn_hz: main.fn_hz * (1.0 + spacing), residue: main.residue * share, ..main });
                    Dynamometer::from_modes_normalized(modes)
                };
                Ok(MultiAxisDynamometer { axes: [pair(base.axis(0))?, pair(base.axis(1))?, pair(base.axis(2))?] })
            }
        }
    }
}

/// The case list: sensor modes 1.8-6 kHz (above 0.45 fs
/// at 10.24 kHz), a close mode pair, machine modes 80-900 Hz, FRF resolution
/// 0.5-4 Hz, tooth-passing frequencies 60 Hz-1.6 kHz, chatter.
pub fn cases() -> Vec<RateCase> {
    let d = ModeRanges::default();
    vec![
        RateCase {
            name: "default",
            seed: 11,
            dyno: DynoSpec::Random(d.clone()),
            frf_df_hz: 1.0,
            frf_max_hz: 4096.0,
            spindle_rpm: 4125.0,
            teeth: 4,
            chatter_hz: None,
        },
        RateCase {
            name: "low-modes",
            seed: 12,
            dyno: DynoSpec::Random(ModeRanges {
                main_xy_hz: (1800.0, 2000.0),
                main_z_hz: (1900.0, 2200.0),
                ..d.clone()
            }),
            frf_df_hz: 0.5,
            frf_max_hz: 4096.0,
            spindle_rpm: 1800.0,
            teeth: 2,
            chatter_hz: None,
        },
        RateCase {
            name: "high-modes",
            seed: 13,
            dyno: DynoSpec::Random(ModeRanges {
                main_xy_hz: (4500.0, 5200.0),
                main_z_hz: (5400.0, 6000.0),
                secondary_hz: (5000.0, 6000.0),
                ..d.clone()
            }),
            frf_df_hz: 2.0,
            frf_max_hz: 8192.0,
            spindle_rpm: 24_000.0,
            teeth: 4,
            chatter_hz: None,
        },
        RateCase {
            name: "close-pair",
            seed: 14,
            dyno: DynoSpec::ClosePair { ranges: d.clone(), spacing: 0.06, share: 0.35 },
            frf_df_hz: 4.0,
            frf_max_hz: 4096.0,
            spindle_rpm: 12_000.0,
            teeth: 4,
            chatter_hz: None,
        },
        RateCase {
            name: "machine-80-900",
            seed: 15,
            dyno: DynoSpec::Random(ModeRanges { machine_count: (3, 4), machine_hz: (80.0, 900.0), ..d.clone() }),
            frf_df_hz: 1.0,
            frf_max_hz: 4096.0,
            spindle_rpm: 3900.0,
            teeth: 2,
            chatter_hz: None,
        },
        RateCase {
            name: "chatter",
            seed: 16,
            dyno: DynoSpec::Random(d),
            frf_df_hz: 1.0,
            frf_max_hz: 4096.0,
            spindle_rpm: 6000.0,
            teeth: 4,
            chatter_hz: Some(1710.0),
        },
    ]
}

/// A small subset of [`cases`] (`--quick`): the default and the high-mode case.
pub fn quick_cases() -> Vec<RateCase> {
    cases().into_iter().filter(|c| matches!(c.name, "default" | "high-modes")).collect()
}

/// Options of a harness run that reach the design.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Declared latency L (samples); `None`: chosen as `design` does
    /// without `--latency` ([`crate::design::latency`]).
    pub lag: Option<usize>,
    /// Discrete model of the Kalman design.
    pub discretization: crate::design::discretize::Discretization,
    /// A noise-free impact test: the FRF is exactly the chain's G (for the
    /// "distortion below noise" check, where only the discrete model and
    /// the filter can make the error exceed the exact inverse's noise floor).
    pub exact_frf: bool,
    /// Choose q for the force spectrum of a representative record
    /// (`design --force-prior spectrum`): the case's steady cut simulated
    /// again with other noise (seed + [`REPRESENTATIVE_SEED_OFFSET`]).
    pub force_spectrum: bool,
    /// With `force_spectrum`: use only the record's force level, the
    /// spectrum stays flat (`design --force-prior level`).
    pub force_level_only: bool,
    /// The discrete model's static gain
    /// ([`DesignOptions::discrete_static_gain`]).
    pub static_gain: crate::design::discretize::StaticGain,
    /// The output above the band ([`DesignOptions::above_band`]).
    pub above_band: crate::design::above_band::AboveBand,
    /// The fit refined to the maximum-likelihood model of its order
    /// ([`crate::fit::vf::VfOptions::refine`]; off for before/after studies).
    pub refine_fit: bool,
    /// Pairs seeded where the fit leaves more than the noise
    /// ([`crate::fit::vf::VfOptions::seed_unfitted`]; off for before/after
    /// studies).
    pub seed_fit: bool,
    /// Pairs the lines do not support dropped from the fit
    /// ([`crate::fit::vf::VfOptions::drop_unsupported`]; off for
    /// before/after studies).
    pub drop_unsupported: bool,
    /// Lines a seeded pair must span ([`crate::fit::vf::VfOptions::seed_resolved_lines`]).
    pub seed_resolved_lines: f64,
    /// Also run `compensate --offline`'s smoother on each axis and score it
    /// ([`AxisScore::offline_nrmse`]).
    pub score_offline: bool,
    /// Predict and score these look-aheads on every axis
    /// ([`DesignOptions::look_ahead_every_axis`]); empty: the design's rule.
    pub look_ahead_every_axis: Vec<usize>,
}

impl Default for RunOptions {
    fn default() -> Self {
        Self {
            lag: None,
            discretization: crate::design::discretize::Discretization::Fit,
            exact_frf: false,
            force_spectrum: false,
            force_level_only: false,
            static_gain: crate::design::discretize::StaticGain::Exact,
            above_band: crate::design::above_band::AboveBand::Quiet,
            refine_fit: true,
            seed_fit: true,
            drop_unsupported: true,
            seed_resolved_lines: crate::fit::vf::SEED_RESOLVED_LINES,
            score_offline: false,
            look_ahead_every_axis: Vec::new(),
        }
    }
}

/// Seed offset of the representative record ([`RunOptions::force_spectrum`]).
pub const REPRESENTATIVE_SEED_OFFSET: u64 = 1000;

/// The one place where the harness builds its [`DesignOptions`].
pub fn design_options(fs_hz: f64, run: &RunOptions) -> DesignOptions {
    DesignOptions {
        fs_hz,
        lag: run.lag.unwrap_or(crate::design::latency::DEFAULT_LATENCY),
        discretization: run.discretization,
        discrete_static_gain: run.static_gain,
        above_band: run.above_band,
        look_ahead_every_axis: run.look_ahead_every_axis.clone(),
        vf: crate::fit::vf::VfOptions {
            refine: run.refine_fit,
            seed_unfitted: run.seed_fit,
            drop_unsupported: run.drop_unsupported,
            seed_resolved_lines: run.seed_resolved_lines,
            ..Default::default()
        },
        ..Default::default()
    }
}

/// Figures of one axis of one case at one rate.
#[derive(Clone, Debug)]
pub struct AxisScore {
    /// Axis index.
    pub axis: usize,
    /// NRMSE of the raw measurement against the truth (scoring band).
    pub raw_nrmse: f64,
    /// NRMSE of the compensated force, or the design's error.
    pub comp_nrmse: std::result::Result<f64, String>,
    /// Exact-inverse noise floor sqrt(R·(2/fs)·∫|1/G|² df)/std(truth) with
    /// the simulator's true G (including an analog front end), R the noise in
    /// the record (variance + quantization).
    pub noise_floor: f64,
    /// The design's predicted in-band error (NaN if the design failed).
    pub predicted_error: f64,
    /// The same with the fit's uncertainty counted
    /// (`AxisDesign::predicted_error_with_fit`; NaN if the design failed).
    pub predicted_with_fit: f64,
    /// The design's flat band (Hz) (NaN if the design failed).
    pub flat_band_hz: (f64, f64),
    /// Wall time of the axis's design (s).
    pub design_s: f64,
    /// The compensated force as written against the anti-aliased truth,
    /// beside a perfect band-limited estimate (None if the design failed).
    pub as_written: Option<AsWritten>,
    /// Shape of the axis's filter on the box (None if the design failed).
    pub shape: Option<dynocomp_core::budget::AxisShape>,
    /// Lines (Hz) where the axis's fit seeded a pair (empty if the design
    /// failed; [`crate::design::axis::AxisDesign::seeded_hz`]).
    pub seeded_hz: Vec<f64>,
    /// The design's non-minimum-phase zeros where the box is worse than raw
    /// ([`crate::design::phase_limit`]; empty if the design failed).
    pub phase_limits: Vec<crate::design::phase_limit::PhaseLimit>,
    /// NRMSE of `compensate --offline`'s smoother of the image
    /// (with [`RunOptions::score_offline`]; NaN otherwise or if the design
    /// failed).
    pub offline_nrmse: f64,
    /// The design's prediction of it, with the fit's uncertainty
    /// ([`crate::design::axis::AxisDesign::offline_predicted`]; NaN if the
    /// design failed).
    pub offline_predicted: f64,
    /// Where the design predicted longer look-aheads
    /// ([`crate::design::look_ahead`]): each latency tried (samples), its
    /// prediction with the fit's uncertainty, and the NRMSE of its f64
    /// fixed-lag smoother against the truth ([`f64_smoother_nrmse`]; NaN
    /// where no design).
    pub look_ahead: Vec<(usize, f64, f64)>,
    /// The box design's own f64 filter scored the same way (NaN unless the
    /// axis has `look_ahead`): the control that the f64 scoring agrees with
    /// the image's `comp_nrmse`.
    pub box_f64_nrmse: f64,
}

/// NRMSE against `truth` (band-limited to `band_hz`) of the f64 fixed-lag
/// smoother `kal` run on the measurement `y` (N): its output at k is the
/// force at k − L ([`crate::design::kalman::design`]), scored over the
/// samples whose look-ahead the record holds (the last L are left out).
pub fn f64_smoother_nrmse(kal: &KalmanDesign, y: &[f64], truth: &[f64], fs_hz: f64, band_hz: f64) -> f64 {
    let out = kal.compensator.simulate(y);
    let n = y.len().saturating_sub(kal.lag);
    accuracy(&out[kal.lag..kal.lag + n], &truth[..n], fs_hz, band_hz).nrmse
}

/// Results of one case at one rate.
#[derive(Clone, Debug)]
pub struct CaseResult {
    /// Case name.
    pub case: &'static str,
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Scoring band upper edge (Hz).
    pub band_hz: f64,
    /// The three axes.
    pub axes: Vec<AxisScore>,
    /// Declared latency of the designs (samples).
    pub latency: usize,
}

/// sqrt(R·(2/fs)·∫_0^band |1/G(j2πf)|² df) / std_truth: the in-band RMS of
/// white noise of variance R through the exact inverse of `g`, relative to
/// the truth's standard deviation (trapezoid rule on a 0.25 Hz grid).
pub fn noise_floor(g: impl Fn(f64) -> Complex64, r: f64, fs_hz: f64, band_hz: f64, std_truth: f64) -> f64 {
    let n = (band_hz / 0.25).ceil().max(1.0) as usize;
    let h = band_hz / n as f64;
    let v = |k: usize| 1.0 / g(k as f64 * h).norm_sqr();
    let integral = h * ((1..n).map(v).sum::<f64>() + 0.5 * (v(0) + v(n)));
    (r * 2.0 / fs_hz * integral).sqrt() / std_truth
}

/// Make the impact test of `params` noise-free ([`RunOptions::exact_frf`]).
pub fn noise_free_impact(params: &mut SimParams) {
    params.impact.output_noise_rel = 0.0;
    params.impact.input_noise_rel = 0.0;
    params.impact.dc_noise_factor = 1.0;
}

/// Simulate `case` at `fs_hz`, design each axis, compensate through a
/// coefficient image (declared latency removed) and score it. A failed
/// design is recorded in its axis, not returned as an error.
pub fn run_case(case: &RateCase, fs_hz: f64, run: &RunOptions) -> Result<CaseResult> {
    run_case_on(case, &case.sim_params(fs_hz), run)
}

/// [`run_case`] with the scored record simulated from `params` (for
/// example the case's cut with chatter); a representative record
/// ([`RunOptions::force_spectrum`]) is always the case's own steady cut.
pub fn run_case_on(case: &RateCase, params: &SimParams, run: &RunOptions) -> Result<CaseResult> {
    let fs_hz = params.fs_hz;
    let mut params = params.clone();
    let mut steady = case.sim_params(fs_hz);
    if run.exact_frf {
        noise_free_impact(&mut params);
        noise_free_impact(&mut steady);
    }
    let dyno = case.dynamometer(&params)?;
    let record = match run.force_spectrum {
        false => None,
        true => {
            let rep = simulate_with(case.seed + REPRESENTATIVE_SEED_OFFSET, &steady, dyno.clone())?;
            let channels = [0, 1, 2].map(|a| Some(rep.measured[a].clone()));
            Some(std::sync::Arc::new(crate::design::force_spectrum::ForceRecord {
                source: format!("{} representative record", case.name),
                channels,
            }))
        }
    };
    let s = simulate_with(case.seed, &params, dyno)?;
    Ok(score_sim_with(case.name, &s, run, record))
}

/// Design, compensate and score an existing simulation (see [`run_case`]).
pub fn score_sim(name: &'static str, s: &SimOutput, run: &RunOptions) -> CaseResult {
    score_sim_with(name, s, run, None)
}

/// [`score_sim`] designed on the force spectrum of `record` when given.
fn score_sim_with(
    name: &'static str,
    s: &SimOutput,
    run: &RunOptions,
    record: Option<std::sync::Arc<crate::design::force_spectrum::ForceRecord>>,
) -> CaseResult {
    let fs = s.params.fs_hz;
    let band = scoring_band_hz(fs);
    let opts = DesignOptions {
        force_record: record,
        force_record_level_only: run.force_level_only,
        ..design_options(fs, run)
    };
    let r_true = s.params.measurement.expected_idle_variance();
    // All three axes designed together, as `design` does: one latency per image.
    let t0 = Instant::now();
    let frfs: Vec<_> = (0..3).filter_map(|a| s.frf.axis(a).cloned()).collect();
    let r: Vec<f64> = frfs.iter().map(|f| sample_variance(&s.idle[f.axis])).collect();
    let (designs, (latency, look_ahead)) = match run.lag {
        Some(l) => (crate::design::latency::design_axes(&s.frf.freq_hz, &frfs, &r, &opts), (l, Vec::new())),
        None => {
            let (d, c) = crate::design::latency::design_axes_choosing_latency(
                &s.frf.freq_hz,
                &frfs,
                &r,
                &opts,
                Some(BOX_LOAD_LIMIT_PERMILLE),
                &crate::design::progress::Progress::none(),
            );
            (d, (c.chosen, c.look_ahead))
        }
    };
    // Per axis: its share of the wall time (the axes run on parallel threads).
    let design_s = t0.elapsed().as_secs_f64() / frfs.len().max(1) as f64;
    let mut designs = designs.into_iter();
    let mut axes = Vec::new();
    for a in 0..3 {
        let raw = accuracy(&s.measured[a], &s.truth[a], fs, band);
        let std_truth = raw.rms_error_n / raw.nrmse;
        let chain = s.params.anti_alias;
        let g = |f: f64| s.dyno.axis(a).frf(f) * chain.analog_frf(f);
        let noise_floor = noise_floor(g, r_true, fs, band, std_truth);
        let designed = match s.frf.axis(a) {
            Some(_) => designs.next().map(|d| d.0).unwrap_or_else(|| Err(anyhow::anyhow!("no design for axis {a}"))),
            None => Err(anyhow::anyhow!("no FRF for axis {a}")),
        };
        let shape = designed.as_ref().ok().map(|d| dynocomp_core::budget::AxisShape::of(&d.filter));
        let mut as_written = None;
        let phase_limits = designed.as_ref().map(|d| d.phase_limits.clone()).unwrap_or_default();
        let seeded_hz = designed.as_ref().map(|d| d.seeded_hz.clone()).unwrap_or_default();
        let predicted_with_fit = designed.as_ref().map_or(f64::NAN, |d| d.predicted_error_with_fit());
        let offline_predicted = designed.as_ref().map_or(f64::NAN, |d| d.offline_predicted_with_fit());
        let mut offline_nrmse = f64::NAN;
        let (mut look, mut box_f64_nrmse) = (Vec::new(), f64::NAN);
        if let (Some(l), Ok(d)) = (look_ahead.iter().find(|l| l.axis == a), &designed) {
            box_f64_nrmse = f64_smoother_nrmse(&d.kalman, &s.measured[a], &s.truth[a], fs, band);
            for ((lag, e), k) in l.tried.iter().zip(&l.designs) {
                let m = k.as_ref().map_or(f64::NAN, |k| f64_smoother_nrmse(k, &s.measured[a], &s.truth[a], fs, band));
                look.push((*lag, e.unwrap_or(f64::NAN), m));
            }
        }
        let (comp_nrmse, predicted_error, flat_band_hz) = match designed {
            Err(e) => (Err(format!("{e:#}")), f64::NAN, (f64::NAN, f64::NAN)),
            Ok(d) => {
                let image = build_image(std::slice::from_ref(&d), fs as u32, latency, 5000.0, [0; 32]);
                let rec = SignalRecord { t_s: None, channels: vec![(a, s.measured[a].clone())] };
                if let (true, Ok(img)) = (run.score_offline, &image) {
                    let sidecar = crate::offline::sidecar::ModelSidecar::of_designs(img, std::slice::from_ref(&d));
                    offline_nrmse = crate::offline::smoother::smooth_record(img, &sidecar, &rec, "rates")
                        .ok()
                        .and_then(|out| out.channel(a).map(|c| accuracy(c, &s.truth[a], fs, band).nrmse))
                        .unwrap_or(f64::NAN);
                }
                let comp = image.and_then(|img| compensate_record(&img, &rec, false, "rates"));
                let nrmse = comp
                    .and_then(|out| {
                        let c = out.channel(a).ok_or_else(|| anyhow::anyhow!("axis {a} missing"))?;
                        as_written = Some(accuracy_as_written(c, &s.truth[a], fs, band));
                        Ok(accuracy(c, &s.truth[a], fs, band).nrmse)
                    })
                    .map_err(|e| format!("{e:#}"));
                (nrmse, d.predicted_error, d.flat_band_hz)
            }
        };
        axes.push(AxisScore {
            axis: a,
            raw_nrmse: raw.nrmse,
            comp_nrmse,
            noise_floor,
            predicted_error,
            predicted_with_fit,
            flat_band_hz,
            design_s,
            shape,
            as_written,
            seeded_hz,
            phase_limits,
            offline_nrmse,
            offline_predicted,
            look_ahead: look,
            box_f64_nrmse,
        });
    }
    CaseResult { case: name, fs_hz: fs, band_hz: band, axes, latency }
}

impl CaseResult {
    /// Predicted sample-interrupt cost of the three axes' designs in one box
    /// image ([`CostModel::CORTEX_M4`](dynocomp_core::budget::CostModel)):
    /// (cycles, load low and high in thousandths of the period at
    /// `fs_hz`); None if a design failed.
    pub fn box_load(&self) -> Option<(dynocomp_core::budget::Cost, u32, u32)> {
        use dynocomp_core::budget::{load_permille, CostModel};
        let shapes: Option<Vec<_>> = self.axes.iter().map(|a| a.shape).collect();
        let cost = CostModel::CORTEX_M4.sample_cost(&shapes?);
        let fs = self.fs_hz as u32;
        Some((cost, load_permille(cost.low, fs), load_permille(cost.high, fs)))
    }
}

/// Per-rate summary of compensated NRMSEs.
#[derive(Clone, Debug)]
pub struct RateSummary {
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Median compensated NRMSE over the axes whose design succeeded.
    pub median: f64,
    /// Worst compensated NRMSE (failed designs are not counted here).
    pub worst: f64,
    /// Axes compensated worse than raw, as "case/axis".
    pub worse_than_raw: Vec<String>,
    /// Axes whose design failed, as "case/axis".
    pub failed: Vec<String>,
}

/// Median, worst and worse-than-raw per rate of `results`.
pub fn summarize(results: &[CaseResult]) -> Vec<RateSummary> {
    let mut rates: Vec<f64> = results.iter().map(|r| r.fs_hz).collect();
    rates.sort_by(f64::total_cmp);
    rates.dedup();
    rates
        .into_iter()
        .map(|fs| {
            let (mut v, mut worse, mut failed) = (Vec::new(), Vec::new(), Vec::new());
            for r in results.iter().filter(|r| r.fs_hz == fs) {
                for a in &r.axes {
                    let tag = format!("{}/{}", r.case, crate::frf::axis_name(a.axis));
                    match a.comp_nrmse {
                        Ok(c) => {
                            v.push(c);
                            if c.partial_cmp(&a.raw_nrmse) != Some(std::cmp::Ordering::Less) {
                                worse.push(tag);
                            }
                        }
                        Err(_) => failed.push(tag),
                    }
                }
            }
            v.sort_by(f64::total_cmp);
            let median = if v.is_empty() {
                f64::NAN
            } else if v.len() % 2 == 1 {
                v[v.len() / 2]
            } else {
                0.5 * (v[v.len() / 2 - 1] + v[v.len() / 2])
            };
            RateSummary {
                fs_hz: fs,
                median,
                worst: v.last().copied().unwrap_or(f64::NAN),
                worse_than_raw: worse,
                failed,
            }
        })
        .collect()
}
