//! The text and JSON summaries of a design: what `design` prints and the
//! report shows.

use serde::Serialize;
use std::fmt::Write as _;

use crate::design::axis::AxisDesign;
use crate::design::bands::{self, Band};
use crate::design::mimo::{OFFLINE_FLAT_CAVEAT, OFFLINE_MUCH_BETTER};
use crate::design::paper::PaperDiagnostics;
use crate::design::sensitivity::Sensitivity;
use crate::frf::axis_name;
use crate::offline::force_prior::AxisPrior;

/// Machine-readable summary of one axis.
#[derive(Debug, Serialize)]
pub struct AxisJson {
    /// Axis letter.
    pub axis: &'static str,
    /// Fitted model order.
    pub model_order: usize,
    /// Order search trace (order, weighted RMS error).
    pub order_trace: Vec<(usize, f64)>,
    /// Relative RMS fit error over the coherent band.
    pub fit_nrmse: f64,
    /// Coherent band (Hz).
    pub coherent_band_hz: (f64, f64),
    /// Chosen q (N²/sample).
    pub q: f64,
    /// R (N²).
    pub r: f64,
    /// Flat band (Hz).
    pub flat_band_hz: (f64, f64),
    /// White-noise gain.
    pub noise_gain: f64,
    /// Predicted in-band relative error √J.
    pub predicted_error: f64,
    /// The fitted model's own uncertainty in the terms of
    /// `predicted_error` (`AxisDesign::fit_uncertainty`; null where not
    /// known).
    pub fit_uncertainty: Option<f64>,
    /// √(predicted_error² + fit_uncertainty²): the error to expect with
    /// what the FRF's noise leaves unknown in the model counted.
    pub predicted_error_with_fit: f64,
    /// What `compensate --offline` on the image is predicted to reach, the
    /// fit's uncertainty counted (`AxisDesign::offline_predicted_with_fit`;
    /// null where not known).
    pub offline_predicted_error: Option<f64>,
    /// Predicted in-band relative error of the uncompensated force; the
    /// design is refused unless `predicted_error` is below it.
    pub raw_predicted_error: f64,
    /// Compensated band (Hz): the coherent band capped at 0.45 fs.
    pub compensated_band_hz: (f64, f64),
    /// Discrete model: `fit`, `foh`, `zoh` (null for the paper's Tustin).
    pub discretization: Option<&'static str>,
    /// Model match max |Ĝ_d/Ĝ − 1| over the compensated band (null for the paper's method).
    pub model_match: Option<f64>,
    /// Advance D (samples) and FIR taps of the discrete model, and the
    /// condition number of its least-squares fit.
    pub discrete_advance: Option<usize>,
    /// FIR taps of the discrete model.
    pub discrete_taps: Option<usize>,
    /// Condition number of the discrete model's least-squares fit.
    pub discrete_condition: Option<f64>,
    /// Notes (e.g. FRF lines beyond 0.45 fs).
    pub notes: Vec<String>,
    /// Non-minimum-phase zeros in the compensated band where the box output
    /// is worse than raw ([`crate::design::phase_limit`]).
    pub phase_limits: Vec<crate::design::phase_limit::PhaseLimit>,
    /// Sections / FIR taps in the image.
    pub sections: usize,
    /// FIR taps.
    pub fir_taps: usize,
    /// Riccati residual.
    pub dare_residual: f64,
    /// f32 verification: frequency-response error, time-domain error, max pole radius.
    pub verify_freq_error: f64,
    /// Time-domain error of the f32 kernel.
    pub verify_time_error: f64,
    /// Largest pole radius.
    pub max_pole_radius: f64,
    /// Natural frequency (Hz) and damping of each fitted mode.
    pub modes: Vec<(f64, f64)>,
    /// Design time of this axis (s).
    pub design_time_s: f64,
    /// Relative RMS fit error on coherent lines outside the bands (null
    /// without bands).
    pub fit_nrmse_out_of_band: Option<f64>,
    /// Condition numbers, observability rank, Riccati residual and prewarp
    /// frequency of `--method paper`.
    pub paper: Option<PaperDiagnostics>,
    /// Predicted in-band error when the sensor modes shift by −5…+5 %
    /// (`crate::design::sensitivity`), with the shifts where it doubles.
    pub sensitivity: Option<crate::design::sensitivity::Sensitivity>,
    /// The harmonic force prior of `compensate --offline` (null without
    /// `--force-prior harmonics`).
    pub force_prior: Option<ForcePriorJson>,
    /// The record's force spectrum q was chosen for (null without
    /// `--force-prior spectrum`).
    pub force_spectrum: Option<crate::design::force_spectrum::AxisForceSpectrum>,
    /// The band-limited force model (`--above-band quiet`, the default;
    /// null for the random walk: `--above-band inverse`, bands, the paper's
    /// method).
    pub force_shape: Option<crate::design::kalman::ForceShape>,
    /// Why the axis is passed through raw, delayed by the latency (null
    /// where it is compensated; `design --strict` refuses such an image).
    pub passed_through_raw: Option<String>,
}

impl AxisJson {
    /// The JSON summary of design `d`, designed in `design_time_s` (s), with
    /// its force prior and the sensitivity analysis of it.
    pub fn new(
        d: &AxisDesign,
        design_time_s: f64,
        prior: Option<&AxisPrior>,
        sensitivity: &Option<Sensitivity>,
    ) -> Self {
        AxisJson {
            axis: axis_name(d.axis),
            model_order: d.model.order(),
            order_trace: d.order_trace.clone(),
            fit_nrmse: d.fit_nrmse,
            coherent_band_hz: d.coherent_band_hz,
            q: d.kalman.q,
            r: d.kalman.r,
            flat_band_hz: d.flat_band_hz,
            noise_gain: d.noise_gain,
            predicted_error: d.predicted_error,
            fit_uncertainty: d.fit_uncertainty.is_finite().then_some(d.fit_uncertainty),
            predicted_error_with_fit: d.predicted_error_with_fit(),
            offline_predicted_error: Some(d.offline_predicted_with_fit()).filter(|v| v.is_finite()),
            raw_predicted_error: d.raw_predicted_error,
            compensated_band_hz: d.compensated_band_hz,
            discretization: d.discrete.as_ref().map(|x| x.0.method.name()),
            model_match: d.model_match.is_finite().then_some(d.model_match),
            discrete_advance: d.discrete.as_ref().map(|x| x.0.advance),
            discrete_taps: d.discrete.as_ref().map(|x| x.0.fir.len()),
            discrete_condition: d.discrete.as_ref().map(|x| x.1.condition),
            notes: d.notes.clone(),
            phase_limits: d.phase_limits.clone(),
            sections: d.filter.sections().len(),
            fir_taps: d.filter.fir().len(),
            dare_residual: d.kalman.dare_residual,
            verify_freq_error: d.verification.freq_error,
            verify_time_error: d.verification.time_error,
            max_pole_radius: d.verification.max_pole_radius,
            modes: d.model.modes(),
            design_time_s,
            fit_nrmse_out_of_band: (!d.bands.is_empty() && d.fit_nrmse_out_of_band.is_finite())
                .then_some(d.fit_nrmse_out_of_band),
            paper: d.paper.as_ref().map(|p| p.1.clone()),
            sensitivity: sensitivity.clone(),
            force_prior: prior.map(|p| ForcePriorJson {
                applies_to: "compensate --offline",
                prior: p.prior.clone(),
                prediction: p.prediction,
                off_line_share: p.record.off_line_share,
                record_spindle_rpm: 60.0 * p.record.best_spindle_hz,
            }),
            force_spectrum: d.force_spectrum.clone(),
            force_shape: d.kalman.force_shape,
            passed_through_raw: d.pass_through.clone(),
        }
    }
}

/// The force prior of one axis in the `--json` summary.
#[derive(Debug, Serialize)]
pub struct ForcePriorJson {
    /// Where it applies: always `compensate --offline`.
    pub applies_to: &'static str,
    /// The prior (lines, intensities, q_bb) as stored in the sidecar.
    pub prior: crate::offline::force_prior::HarmonicPrior,
    /// Predicted errors: steady cut (the record's spectrum) and flat spectrum,
    /// with the prior, the default smoother and no compensation.
    pub prediction: crate::offline::force_prior::PriorPrediction,
    /// Share of the record's in-band force away from the harmonics.
    pub off_line_share: f64,
    /// Spindle speed whose harmonics best fit the record (rpm).
    pub record_spindle_rpm: f64,
}

/// Machine-readable summary of the whole design.
#[derive(Debug, Serialize)]
pub struct DesignJson {
    /// Image path.
    pub image: String,
    /// Image id.
    pub image_id: String,
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Declared latency (samples).
    pub latency_samples: usize,
    /// Method.
    pub method: &'static str,
    /// Fitting bands (empty = whole coherent band).
    pub bands: Vec<Band>,
    /// Axes.
    pub axes: Vec<AxisJson>,
    /// Total design time (s).
    pub design_time_s: f64,
    /// Predicted CPU load of the box at `fs_hz` (`dynocomp_core::budget`).
    pub box_load: crate::realize::load::LoadReport,
    /// Offline-only: over the load limit, the box never runs it.
    pub offline_only: bool,
    /// How the latency was chosen (absent when `--latency` was given).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub latency_choice: Option<crate::design::latency::LatencyChoice>,
    /// Band-fitted or paper-method axes beside the default design (absent
    /// for the default design).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub versus_default: Vec<VersusDefaultJson>,
}

/// One axis of [`DesignJson::versus_default`].
#[derive(Debug, serde::Serialize)]
pub struct VersusDefaultJson {
    /// The comparison ([`crate::design::versus_default::compare`]).
    #[serde(flatten)]
    pub comparison: crate::design::versus_default::VersusDefault,
    /// Whether the image carries the default design for the axis.
    pub replaced_by_default: bool,
}

/// What a design for the range between two states predicts for one axis:
/// the worst case over the range and the image's own state s.
#[derive(Clone, Copy, Debug)]
pub struct RangeFigures {
    /// Worst-case predicted in-band error over the range (fraction).
    pub worst: f64,
    /// The state the image was designed for.
    pub s: f64,
}

/// One-screen text summary: the image line and the fitting bands, a table
/// of one row per axis, then per axis its discrete model and notes, the
/// sensitivity and paper lines, and a legend of the table's columns. With
/// `range` (a design for the range between two states, one entry per axis
/// in order), the table leads with each axis's worst case over the range,
/// the error at the image's own state beside it.
#[allow(clippy::too_many_arguments)]
pub fn render_summary(
    designs: &[AxisDesign],
    sensitivities: &[Option<Sensitivity>],
    fs: f64,
    latency: usize,
    image: &str,
    id: u32,
    method: &str,
    range: Option<&[RangeFigures]>,
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "image {image} (id {id:08x}): fs {fs} Hz, latency {latency} samples ({:.1} µs), method {method}",
        latency as f64 * 1e6 / fs
    );
    if let Some(d) = designs.first().filter(|d| !d.bands.is_empty()) {
        let _ = writeln!(s, "fitting bands: {}", bands::describe(&d.bands));
    }
    s.push_str(&table(designs, range));
    if let Some(line) = fit_uncertainty_line(designs) {
        s.push_str(&line);
    }
    if let Some(line) = offline_line(designs).filter(|_| range.is_none()) {
        s.push_str(&line);
    }
    for d in designs {
        if let Some(why) = &d.pass_through {
            let _ = writeln!(
                s,
                "WARNING: axis {} is NOT COMPENSATED: passed through raw (delayed by {latency} samples): {why}",
                axis_name(d.axis)
            );
        }
        if let Some(line) = discrete_line(d) {
            s.push_str(&line);
        }
        for n in &d.notes {
            let _ = writeln!(s, "note: {n}");
        }
        for p in &d.phase_limits {
            let _ = writeln!(s, "{}", crate::design::phase_limit::note(axis_name(d.axis), p, latency, fs));
        }
    }
    for (d, sens) in designs.iter().zip(sensitivities) {
        if let Some(sens) = sens {
            let _ = writeln!(s, "{}", crate::design::sensitivity::summary_line(axis_name(d.axis), sens));
        }
    }
    for d in designs {
        if let Some((tf, p)) = &d.paper {
            let _ = writeln!(s, "{}", paper_line(d.axis, tf.nb(), tf.na(), p));
        }
    }
    s.push_str(&legend(designs, latency, range.is_some()));
    s
}

/// The summary's table: a header and one row per axis (the columns are
/// explained by [`legend`]); with `range`, the worst case over the range
/// and the error at the image's state s in place of `pred.`.
fn table(designs: &[AxisDesign], range: Option<&[RangeFigures]>) -> String {
    let mut s = String::new();
    let pred = |d: &AxisDesign, i: usize| match range.and_then(|r| r.get(i)) {
        Some(r) => format!("{:>6.2}% {:>5.2}%@{:.2}", 100.0 * r.worst, 100.0 * d.predicted_error, r.s),
        None => format!("{:>6.2}%", d.predicted_error * 100.0),
    };
    let _ = writeln!(
        s,
        "{:<4} {:>5} {:>7} {:>13} {:>10} {:>9} {:>15} {:>6} {:>7} {:>7} {:>8} {:>7}",
        "axis",
        "order",
        "fit err",
        "coherent (Hz)",
        "Q (N²)",
        "R (N²)",
        "flat band (Hz)",
        "noise",
        if range.is_some() { format!("{:>7} {:>11}", "worst*", "pred.@s") } else { "pred.".to_string() },
        "raw",
        "match",
        "sec+fir"
    );
    for (i, d) in designs.iter().enumerate() {
        if d.pass_through.is_some() {
            let _ = writeln!(s, "{:<4} NOT COMPENSATED: passed through raw (WARNING below)", axis_name(d.axis));
            continue;
        }
        let _ = writeln!(
            s,
            "{:<4} {:>5} {:>6.2}% {:>6.0}-{:<6.0} {:>10.3e} {:>9.4} {:>7.0}-{:<7.0} {:>6.2} {:>7} {:>6.2}% {:>8} \
             {:>4}+{}",
            axis_name(d.axis),
            d.model.order(),
            d.fit_nrmse * 100.0,
            d.coherent_band_hz.0,
            d.coherent_band_hz.1,
            d.kalman.q,
            d.kalman.r,
            d.flat_band_hz.0,
            d.flat_band_hz.1,
            d.noise_gain,
            pred(d, i),
            d.raw_predicted_error * 100.0,
            if d.model_match.is_finite() { format!("{:.3}%", d.model_match * 100.0) } else { "tustin".to_string() },
            d.filter.sections().len(),
            d.filter.fir().len()
        );
    }
    s
}

/// The predicted errors with the fitted model's own uncertainty counted
/// (`AxisDesign::predicted_error_with_fit`), where any axis has it.
fn fit_uncertainty_line(designs: &[AxisDesign]) -> Option<String> {
    let parts: Vec<String> = designs
        .iter()
        .filter(|d| d.pass_through.is_none() && d.fit_uncertainty.is_finite())
        .map(|d| {
            format!(
                "{} {:.2} % (pred. with it {:.2} %)",
                axis_name(d.axis),
                100.0 * d.fit_uncertainty,
                100.0 * d.predicted_error_with_fit()
            )
        })
        .collect();
    (!parts.is_empty()).then(|| {
        format!(
            "fit uncertainty (the impact test's noise left in Ĝ, which pred. cannot see; more impacts lower it): {}\n",
            parts.join(", ")
        )
    })
}

/// What `compensate --offline` on the image predicts per axis
/// (`AxisDesign::offline_predicted`, with the fit's uncertainty), where any
/// axis has it. For a flat force the line says that a cut gains less than
/// it shows; for a record's force spectrum it names the axes where the
/// smoother predicts under [`OFFLINE_MUCH_BETTER`] of the box filter's
/// error (BENCHMARKS.md, "What `compensate --offline` reaches per axis").
fn offline_line(designs: &[AxisDesign]) -> Option<String> {
    let known: Vec<&AxisDesign> =
        designs.iter().filter(|d| d.pass_through.is_none() && d.offline_predicted.0.is_finite()).collect();
    if known.is_empty() {
        return None;
    }
    let parts: Vec<String> = known
        .iter()
        .map(|d| format!("{} {:.2} %", axis_name(d.axis), 100.0 * d.offline_predicted_with_fit()))
        .collect();
    let tail = match designs.iter().all(|d| d.force_spectrum.is_none()) {
        true => format!("; {OFFLINE_FLAT_CAVEAT}"),
        false => {
            let better: Vec<String> = known
                .iter()
                .filter(|d| d.offline_predicted_with_fit() < OFFLINE_MUCH_BETTER * d.predicted_error_with_fit())
                .map(|d| axis_name(d.axis).to_string())
                .collect();
            match better.is_empty() {
                true => String::new(),
                false => format!(
                    "; for this cut, under half the box filter's error on {}: use it where the record can be \
                     processed after the cut",
                    better.join(", ")
                ),
            }
        }
    };
    Some(format!(
        "compensate --offline on this image (zero-lag smoother of the same model and q, the fit's uncertainty \
         counted): {}{tail}\n",
        parts.join(", ")
    ))
}

/// The line of an axis's discrete model (none for the paper's Tustin).
fn discrete_line(d: &AxisDesign) -> Option<String> {
    let (dm, fd) = d.discrete.as_ref()?;
    let tail = match fd.modes_above_nyquist {
        0 => String::new(),
        n => format!(", {n} mode(s) above fs/2 fitted by their tail"),
    };
    Some(format!(
        "{} discrete model: {} (advance {} samples, {} FIR taps, LS condition {:.1e}{tail}); match {:.3} % over \
         {:.0}-{:.0} Hz\n",
        axis_name(d.axis),
        dm.method.name(),
        dm.advance,
        dm.fir.len(),
        fd.condition,
        d.model_match * 100.0,
        d.compensated_band_hz.0,
        d.compensated_band_hz.1
    ))
}

/// What the table's columns mean, with the force spectrum the predictions
/// are for.
fn legend(designs: &[AxisDesign], latency: usize, range: bool) -> String {
    let spectrum = match designs.iter().find_map(|d| d.force_spectrum.as_ref()) {
        Some(s) if !s.level_only => "the force spectrum of --force-record",
        Some(_) => "a flat force spectrum at the level of --force-record",
        None => "a flat force spectrum",
    };
    let pred = if range {
        format!(
            "worst*: predicted in-band RMS error for {spectrum}, worst case over the range s ∈ [0, 1] between the two \
             states and both measured FRFs: the error to expect; pred.@s: the same at the image's own state s only \
             (a best case, not a promise)"
        )
    } else {
        format!("pred.: predicted in-band RMS error for {spectrum}")
    };
    let raw = if range { "pred.@s" } else { "the same" };
    format!(
        "flat band: |H·Ĝ| within ±5 % and ±5° of the pure {latency}-sample delay (fitted model Ĝ); noise: white-noise \
         gain; {pred}; raw: {raw} for no compensation; match: max |Ĝ_d/Ĝ − 1| of the discrete model over the \
         compensated band\n"
    )
}

/// One line of the paper's diagnostics for an axis.
pub fn paper_line(axis: usize, nb: usize, na: usize, p: &PaperDiagnostics) -> String {
    format!(
        "{} paper {nb}:{na}: cond RFP {:.1e}, GN {:.1e}, companion {:.1e}; observability rank {}/{} (cond {:.1e}); CARE residual {:.1e}; Tustin prewarp {:.1} Hz; frequency scale {:.1} Hz",
        axis_name(axis),
        p.rfp_condition,
        p.jacobian_condition,
        p.companion_condition,
        p.observability_rank,
        p.observability_dim,
        p.observability_condition,
        p.care_residual,
        p.prewarp_hz,
        p.frequency_scale_hz
    )
}

/// One summary line of an axis designed on a record's force spectrum (or
/// its level).
pub fn spectrum_line(axis: usize, s: &crate::design::force_spectrum::AxisForceSpectrum, force_rms: f64) -> String {
    if s.level_only {
        return format!(
            "{} q chosen for a flat force spectrum at the level of --force-record ({:.2} N RMS in the band, in place of --force-rms {force_rms} N): predicted {:.3} %\n",
            axis_name(axis),
            s.force_rms_n,
            100.0 * s.predicted_error
        );
    }
    format!(
        "{} q chosen for the force spectrum of --force-record ({:.2} N RMS in the band, in place of a flat --force-rms {force_rms} N): predicted {:.3} % for that spectrum, {:.3} % for a flat spectrum of the same power (a broadband force: chatter, transients)\n",
        axis_name(axis),
        s.force_rms_n,
        100.0 * s.predicted_error,
        100.0 * s.flat_predicted_error
    )
}

/// One summary line of an axis's force prior.
pub fn prior_line(axis: usize, p: &crate::offline::force_prior::AxisPrior) -> String {
    let pr = &p.prior;
    let e = &p.prediction;
    format!(
        "{} force prior (compensate --offline only; the box runs the default design): {} harmonics of {:.2} Hz (TPF {:.2} Hz), line width {:.2} Hz, q_bb {:.3e}; predicted {:.3} % on the record's steady cut against {:.3} % for the default smoother (raw {:.2} %); for a flat force spectrum {:.2} % against {:.3} %; {:.2} % of the record's force off the harmonics\n",
        axis_name(axis),
        pr.lines.len(),
        pr.spindle_hz,
        pr.spindle_hz * f64::from(pr.teeth),
        pr.line_width_hz,
        pr.q_broadband,
        100.0 * e.with_prior,
        100.0 * e.default_smoother,
        100.0 * e.raw,
        100.0 * e.with_prior_flat,
        100.0 * e.default_flat,
        100.0 * p.record.off_line_share
    )
}
