//! The seed paper reproduced on its own experiments (`docs/paper.md`,
//! `examples/paper.rs`, `tests/paper_presets.rs`): a preset
//! ([`crate::simulate::presets`]) simulated, designed by one method,
//! compensated through the core kernel and scored against the simulator's
//! true force ([`evaluate`]).

use anyhow::{Context, Result};

use crate::design::axis::{AxisDesign, DesignOptions, FitMethod};
use crate::design::bands::{Band, BandSpec};
use crate::design::image::build_image;
use crate::design::paper_orders::design_axis;
use crate::eval::compare::{design_parallel, CompareSetup};
use crate::fit::rfp::RfpOptions;
use crate::frf::Frf;
use crate::io::signal_csv::SignalRecord;
use crate::metrics::{accuracy, accuracy_in_bands, sample_variance};
use crate::offline::compensate::compensate_record;
use crate::realize::quantize::filter_response;
use crate::simulate::presets::Preset;
use crate::simulate::{simulate_with, SimOutput};
use num_complex::Complex64;

/// Upper edge of the whole-record score (Hz): the impact test's band.
pub const F_MAX_HZ: f64 = 4_000.0;

/// The fitting bands of `preset` for `frf`, exactly as `design` resolves
/// the preset's flags (so the static band is added as the CLI adds it).
pub fn preset_bands(preset: &Preset, frf: &Frf) -> Result<Vec<Band>> {
    let spec =
        BandSpec::from_flags(&preset.design_flags).with_context(|| format!("preset {}: design flags", preset.name))?;
    spec.resolve(frf, preset.params.fs_hz)
}

/// Simulate `preset` with `seed`, its record shortened to `duration_s` when given.
pub fn simulate_preset(preset: &Preset, seed: u64, duration_s: Option<f64>) -> Result<SimOutput> {
    let mut p = preset.params.clone();
    if let Some(d) = duration_s {
        p.duration_s = d;
    }
    simulate_with(seed, &p, preset.dyno.clone())
}

/// How an axis is compensated.
#[derive(Clone, Debug, PartialEq)]
pub enum Method {
    /// The paper's method on the fitting bands, orders chosen per axis.
    PaperBandFitted,
    /// The paper's method on the whole coherent band, orders chosen per axis.
    PaperWholeBand,
    /// The paper's method at fixed orders NB:NA on the whole band.
    PaperWholeBandAt(usize, usize),
    /// The default method (vector fitting, fixed-lag smoother, lag 4).
    Default,
}

impl Method {
    /// A short label.
    pub fn label(&self) -> String {
        match self {
            Method::PaperBandFitted => "paper, band-fitted".into(),
            Method::PaperWholeBand => "paper, whole band".into(),
            Method::PaperWholeBandAt(nb, na) => format!("paper, whole band, {nb}:{na}"),
            Method::Default => "default (vf)".into(),
        }
    }
}

/// The figures of one axis under one method.
#[derive(Clone, Debug)]
pub struct AxisScore {
    /// Raw (measured) NRMSE in the fitting bands.
    pub raw_in_bands: f64,
    /// Compensated NRMSE in the fitting bands.
    pub comp_in_bands: f64,
    /// Raw NRMSE below [`F_MAX_HZ`].
    pub raw_full: f64,
    /// Compensated NRMSE below [`F_MAX_HZ`].
    pub comp_full: f64,
    /// Fit error of the design (relative RMS in its band; the worst band for parallel).
    pub fit_error: f64,
    /// The design's predicted in-band error (the worst band for parallel).
    pub predicted: f64,
    /// Model orders (per band for parallel), e.g. "7:8".
    pub orders: String,
}

/// One axis: its score, or why it could not be designed.
#[derive(Clone, Debug)]
pub struct AxisOutcome {
    /// Axis index.
    pub axis: usize,
    /// The score, or the design's refusal.
    pub result: std::result::Result<AxisScore, String>,
}

fn orders_of(d: &AxisDesign) -> String {
    match &d.paper {
        Some((tf, _)) => format!("{}:{}", tf.nb(), tf.na()),
        None => format!("vf {}", d.model.order()),
    }
}

fn paper_opts(fs_hz: f64, bands: Vec<Band>, orders: Option<(usize, usize)>) -> DesignOptions {
    let (nb, na) = orders.unwrap_or((6, 8));
    DesignOptions {
        fs_hz,
        lag: 0,
        method: FitMethod::Paper { rfp: RfpOptions { nb, na, ..Default::default() }, prewarp_hz: None },
        bands,
        paper_orders_auto: orders.is_none(),
        ..Default::default()
    }
}

/// Design, compensate and score every axis of `s` (simulated from
/// `preset`) by `method`; `bands` are the preset's fitting bands (the
/// in-band score uses them for every method).
///
/// The measured record is compensated as `dynocomp compensate` does and
/// scored in the convention of DESIGN.md ([`crate::metrics`]): NRMSE = RMS
/// error / std of the truth, below 4 kHz, and the same restricted to the
/// fitting bands (both signals band-passed to them), which is what the
/// paper's band-fitting claims are about. Each axis is designed and scored
/// on its own, so one refused axis does not hide the others.
pub fn evaluate(s: &SimOutput, bands: &[Band], method: &Method) -> Vec<AxisOutcome> {
    let fs = s.params.fs_hz;
    let ranges: Vec<(f64, f64)> = bands.iter().map(|b| (b.lo_hz, b.hi_hz)).collect();
    (0..3)
        .map(|axis| {
            let result = evaluate_axis(s, axis, bands, method).map(|(comp, fit_error, predicted, orders)| AxisScore {
                raw_in_bands: accuracy_in_bands(&s.measured[axis], &s.truth[axis], fs, &ranges).nrmse,
                comp_in_bands: accuracy_in_bands(&comp, &s.truth[axis], fs, &ranges).nrmse,
                raw_full: accuracy(&s.measured[axis], &s.truth[axis], fs, F_MAX_HZ).nrmse,
                comp_full: accuracy(&comp, &s.truth[axis], fs, F_MAX_HZ).nrmse,
                fit_error,
                predicted,
                orders,
            });
            AxisOutcome { axis, result: result.map_err(|e| format!("{e:#}")) }
        })
        .collect()
}

/// (compensated record, fit error, predicted error, orders) of one axis.
fn evaluate_axis(s: &SimOutput, axis: usize, bands: &[Band], method: &Method) -> Result<(Vec<f64>, f64, f64, String)> {
    let fs = s.params.fs_hz;
    let a = s.frf.axis(axis).context("axis missing from the FRF")?;
    let r = sample_variance(&s.idle[axis]);
    let rec = SignalRecord { t_s: None, channels: vec![(axis, s.measured[axis].clone())] };
    let single = |opts: &DesignOptions| -> Result<(Vec<f64>, f64, f64, String)> {
        let d = design_axis(&s.frf.freq_hz, a, r, opts)?;
        let image = build_image(std::slice::from_ref(&d), fs as u32, opts.lag, 5000.0, [0; 32])?;
        let out = compensate_record(&image, &rec, false, "simulated record")?;
        let y = out.channel(axis).context("compensated channel missing")?.to_vec();
        Ok((y, d.fit_nrmse, d.predicted_error, orders_of(&d)))
    };
    match method {
        Method::PaperBandFitted => single(&paper_opts(fs, bands.to_vec(), None)),
        Method::PaperWholeBand => single(&paper_opts(fs, Vec::new(), None)),
        Method::PaperWholeBandAt(nb, na) => single(&paper_opts(fs, Vec::new(), Some((*nb, *na)))),
        Method::Default => single(&DesignOptions { fs_hz: fs, ..Default::default() }),
    }
}

/// RMS over the lines of `window` (Hz, 1 Hz apart) of |H(f)·G(f) − 1|, the
/// compensated response's error against the simulator's TRUE G (no lag: the
/// paper's filters have none).
fn true_response_error(s: &SimOutput, axis: usize, h: impl Fn(f64) -> Complex64, window: (f64, f64)) -> f64 {
    let g = s.dyno.axis(axis);
    let f: Vec<f64> = (window.0.ceil() as usize..=window.1.floor() as usize).map(|f| f as f64).collect();
    (f.iter().map(|f| (h(*f) * g.frf(*f) - 1.0).norm_sqr()).sum::<f64>() / f.len() as f64).sqrt()
}

/// The paper's parallel-elaboration finding (§5, Fig. 9b) on one axis:
/// the error of the compensated response against the true G inside
/// `window`, (single band-fitted design over `bands`, parallel elaboration
/// over `parallel_bands`). The single design is the paper's method with
/// orders chosen per axis; parallel elaboration is `compare`'s (orders
/// 2..8 per segment, [`design_parallel`]). Each is `Err` with the refusal.
pub fn local_error_single_vs_parallel(
    s: &SimOutput,
    axis: usize,
    bands: &[Band],
    parallel_bands: &[(f64, f64)],
    window: (f64, f64),
) -> (std::result::Result<f64, String>, std::result::Result<f64, String>) {
    let fs = s.params.fs_hz;
    let Some(a) = s.frf.axis(axis) else { return (Err("axis missing".into()), Err("axis missing".into())) };
    let r = sample_variance(&s.idle[axis]);
    let single = design_axis(&s.frf.freq_hz, a, r, &paper_opts(fs, bands.to_vec(), None))
        .map(|d| true_response_error(s, axis, |f| filter_response(&d.filter, f, fs), window))
        .map_err(|e| format!("{e:#}"));
    let setup = CompareSetup {
        freq_hz: &s.frf.freq_hz,
        base: DesignOptions { fs_hz: fs, lag: 0, ..Default::default() },
        paper: FitMethod::Paper { rfp: RfpOptions::default(), prewarp_hz: None },
        bands: parallel_bands
            .iter()
            .map(|b| Band { lo_hz: b.0, hi_hz: b.1, label: format!("{:.0}-{:.0} Hz", b.0, b.1) })
            .collect(),
    };
    let parallel = design_parallel(&setup, a, r)
        .map(|p| true_response_error(s, axis, |f| p.response(f), window))
        .map_err(|e| format!("{e:#}"));
    (single, parallel)
}
