//! The two-state design's summary lines, its `--json` document and its
//! figure: each candidate's predicted error over the range between the two
//! measured states.

use anyhow::Result;
use std::fmt::Write as _;

use crate::design::sensitivity::Sensitivity;
use crate::design::two_state::range::{HeldDesign, RangeDesign, RANGE_STATES};
use crate::frf::{axis_name, AxisFrf};

/// The summary lines of one axis designed for the range: the paired modes
/// and the chosen state, the machine modes shared or kept apart, and the
/// sensor modes above the compensated band fitted jointly or apart.
pub fn describe(name: &str, rd: &RangeDesign) -> String {
    let mut lines = String::new();
    let (ts, cands) = (&rd.states, &rd.candidates);
    let c = &cands[rd.best];
    let (first, last) = rd.single_state_worst();
    let (moved, background) = paired_and_background(ts);
    let _ = writeln!(
        lines,
        "{name} two states: modes paired {} Hz{}; {}: worst-case predicted error {:.2} % over s ∈ [0, 1] and both measured FRFs (designs for the first / second FRF alone: {:.2} / {:.2} %)",
        moved.join(", "),
        if background.is_empty() {
            String::new()
        } else {
            format!(" (background terms of one fit only, faded between the states: {})", background.join(", "))
        },
        if rd.kept_single_state() {
            "kept the first FRF's single-state design for this axis: no design for the range predicts less error over it".to_string()
        } else {
            format!("image for the range designed at s = {:.2}", c.s)
        },
        100.0 * c.worst,
        100.0 * first,
        100.0 * last
    );
    for (s, why) in &rd.skipped {
        let _ = writeln!(lines, "{name} candidate state s = {s:.2} not designed: {why}");
    }
    let shared = shared_modes_hz(rd);
    let apart: Vec<String> = rd
        .machine
        .iter()
        .filter(|m| !m.shared)
        .map(|m| {
            format!(
                "{:.0}→{:.0} Hz (misfit ×{:.1} / ×{:.1} if shared)",
                m.fn_hz.0, m.fn_hz.1, m.misfit_growth.0, m.misfit_growth.1
            )
        })
        .collect();
    if !rd.machine.is_empty() {
        let _ = writeln!(
            lines,
            "{name} machine modes measured alike in both FRFs, averaged: {}; kept apart: {}",
            if shared.is_empty() { "none".to_string() } else { format!("{} Hz", shared.join(", ")) },
            if apart.is_empty() { "none".to_string() } else { apart.join(", ") }
        );
    }
    if let Some(m0) = rd.above_band.first() {
        let modes: Vec<String> = rd
            .above_band
            .iter()
            .map(|m| {
                if m.joint {
                    let (j, f) = (m.joint_fn_hz, m.fn_hz);
                    format!("{:.0}→{:.0} Hz (separately {:.0}→{:.0} Hz)", j.0, j.1, f.0, f.1)
                } else {
                    format!("{:.0}→{:.0} Hz", m.fn_hz.0, m.fn_hz.1)
                }
            })
            .collect();
        let growth = 100.0 * (m0.misfit_growth - 1.0);
        let how = if m0.joint {
            format!("fitted to both FRFs at once, modal shares and direct term common (misfit {growth:+.2} %)")
        } else {
            format!(
                "each FRF's own fit kept: fitted at once with a common static gain the misfit grows {growth:+.1} %, more than {:.0} %",
                100.0 * crate::design::two_state::joint::JOINT_TOLERANCE
            )
        };
        let _ = writeln!(lines, "{name} sensor modes above the compensated band {how}: {}", modes.join(", "));
    }
    lines
}

/// The summary line of an axis whose two states could not be paired: the
/// first FRF's design held over the range, and what that predicts at both
/// ends as measured.
pub fn describe_held(name: &str, h: &HeldDesign) -> String {
    format!(
        "{name} two states: NOT FOLLOWED, the first FRF's design held over the range ({}); predicted error {:.2} % on the first FRF, {:.2} % on the second as measured\n",
        h.why,
        100.0 * h.measured.0,
        100.0 * h.measured.1
    )
}

/// `--json` of a two-state design.
#[derive(serde::Serialize)]
pub struct RangeJson {
    /// The image's path.
    pub image: String,
    /// Its id, 8 hex digits.
    pub image_id: String,
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Declared latency (samples).
    pub latency_samples: usize,
    /// How the image was chosen.
    pub criterion: &'static str,
    /// The states the candidates are evaluated at.
    pub range_states: [f64; 5],
    /// Per axis.
    pub axes: Vec<RangeAxisEntry>,
}

/// One axis of [`RangeJson`], tagged `"range"`: designed for the range,
/// the first FRF's design held over it, or passed through raw.
#[derive(serde::Serialize)]
#[serde(tag = "range", rename_all = "snake_case")]
pub enum RangeAxisEntry {
    /// Designed for the range.
    Designed(RangeAxisJson),
    /// The two states could not be paired.
    Held(HeldAxisJson),
    /// The first FRF cannot be designed: the axis outputs its measurement.
    PassedThrough {
        /// Axis letter.
        axis: &'static str,
        /// Why.
        reason: String,
    },
}

/// An axis holding the first FRF's design over the range ([`HeldDesign`]).
#[derive(serde::Serialize)]
pub struct HeldAxisJson {
    axis: &'static str,
    /// Why the two states could not be paired.
    why: String,
    /// The design's own predicted in-band error on the first FRF's model.
    predicted_error: f64,
    /// Its predicted error on the first / second FRF as measured.
    measured_frf_errors: (f64, f64),
    /// The error to expect from the image over the range: the largest of these.
    expected_error: f64,
    /// Its sensitivity to shifted sensor modes.
    sensitivity: Option<Sensitivity>,
}

impl HeldAxisJson {
    /// Axis `axis` holding `h`, `sensitivity` that of its image.
    pub fn new(axis: &'static str, h: &HeldDesign, sensitivity: Option<Sensitivity>) -> Self {
        HeldAxisJson {
            axis,
            why: h.why.clone(),
            predicted_error: h.design.predicted_error,
            measured_frf_errors: h.measured,
            expected_error: h.worst(),
            sensitivity,
        }
    }
}

/// One axis of [`RangeJson`].
#[derive(serde::Serialize)]
pub struct RangeAxisJson {
    axis: &'static str,
    /// (Hz, ζ) of the paired modes in each state.
    modes_before: Vec<(f64, f64)>,
    modes_after: Vec<(f64, f64)>,
    /// Machine-structure modes: shared between the states or kept apart.
    machine_modes: Vec<crate::design::two_state::range::MachineMode>,
    /// Sensor modes above the compensated band: fitted to both FRFs at once
    /// or each FRF's own fit kept.
    above_band_modes: Vec<crate::design::two_state::joint::AboveBandMode>,
    /// Model state the image was designed for.
    chosen_state: f64,
    /// Its worst-case predicted in-band error over the range.
    worst_case_error: f64,
    /// The same for the designs from the first and the second FRF alone.
    single_state_worst_case: (f64, f64),
    /// Whether the image keeps the first FRF's single-state design for
    /// this axis (no design for the range predicts less error over it).
    kept_single_state: bool,
    /// (state, worst case, error at each range state) of every candidate.
    candidates: Vec<(f64, f64, Vec<f64>)>,
    /// Each candidate's predicted error on the first / second FRF as measured.
    measured_frf_errors: Vec<(f64, f64)>,
    /// Candidate states that could not be designed, with why.
    skipped_states: Vec<(f64, String)>,
    /// The image's predicted error at its own state only (a best case).
    predicted_error: f64,
    /// The error to expect from the image: its worst case over the range
    /// (`worst_case_error`), the figure the summary table leads with.
    expected_error: f64,
    /// Its sensitivity to shifted sensor modes.
    sensitivity: Option<Sensitivity>,
}

impl RangeAxisJson {
    /// Axis `axis` designed for the range, `sensitivity` that of its image.
    pub fn new(axis: &'static str, rd: &RangeDesign, sensitivity: Option<Sensitivity>) -> Self {
        let (ts, cands) = (&rd.states, &rd.candidates);
        let c = &cands[rd.best];
        RangeAxisJson {
            axis,
            modes_before: ts.before.modes(),
            modes_after: ts.after.modes(),
            machine_modes: rd.machine.clone(),
            above_band_modes: rd.above_band.clone(),
            chosen_state: c.s,
            worst_case_error: c.worst,
            single_state_worst_case: rd.single_state_worst(),
            kept_single_state: rd.kept_single_state(),
            candidates: cands.iter().map(|c| (c.s, c.worst, c.errors.clone())).collect(),
            measured_frf_errors: cands.iter().map(|c| c.measured).collect(),
            skipped_states: rd.skipped.clone(),
            predicted_error: c.design.predicted_error,
            expected_error: c.worst,
            sensitivity,
        }
    }
}

/// Caption of the report's range plot.
pub fn range_caption(rd: &RangeDesign) -> String {
    let shared = shared_modes_hz(rd);
    format!(
        "Predicted in-band error (the design's criterion, flat force spectrum) of each candidate image at the states s = 0, ¼, ½, ¾, 1 \
         of the range (joined by straight lines; 0 = the first FRF, 1 = the second, in between the model interpolated with 1/f² \
         linear). The image is the candidate \
         with the least worst case (thick); the first and second FRF's own designs are the candidates at s = 0 and 1. \
         Machine modes shared by both states: {}.{} A fixed image cannot follow a drift of a few %: \
         `compensate --offline --drift START:END` follows it with both states.",
        if shared.is_empty() { "none".to_string() } else { format!("{} Hz", shared.join(", ")) },
        match rd.above_band.first() {
            Some(m) if m.joint => format!(
                " Sensor modes above the compensated band, fitted to both FRFs at once: {} Hz.",
                rd.above_band.iter().map(|m| format!("{:.0}→{:.0}", m.joint_fn_hz.0, m.joint_fn_hz.1)).collect::<Vec<_>>().join(", ")
            ),
            Some(_) => " Sensor modes above the compensated band: each FRF's own fit (the FRFs disagree on their static gain).".to_string(),
            None => String::new(),
        }
    )
}

/// The report's SVG: each candidate's predicted error (%) against the state s.
pub fn plot_range(axis: &str, rd: &RangeDesign) -> Result<String> {
    use crate::report::plot::{build_chart, draw_line, legend_off_data, mesh, perr, FONT};
    use plotters::prelude::*;
    let top = rd.candidates.iter().flat_map(|c| c.errors.iter()).fold(0.0f64, |a, e| a.max(100.0 * e));
    let yr = (0.0, if top.is_finite() && top > 0.0 { 1.1 * top } else { 1.0 });
    let chosen = &rd.candidates[rd.best];
    let (first, last) = rd.single_state_worst();
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let title = format!(
            "Axis {axis} — image designed at s = {:.2}: worst case {:.2} % over the range (first / second FRF's design alone: {:.2} / {:.2} %)",
            chosen.s,
            100.0 * chosen.worst,
            100.0 * first,
            100.0 * last
        );
        let root = root.titled(&title, (FONT, 16)).map_err(perr)?;
        let mut c = build_chart(&root, "Predicted in-band RMS error (% of the force's std)", (0.0, 1.0), yr)?;
        mesh(
            &mut c,
            "State s (0 = first FRF, 1 = second FRF)",
            "Predicted error (%)",
            &|v| format!("{v:.2}"),
            &|v| format!("{v:.1}"),
            8,
        )?;
        const PALETTE: [RGBColor; 5] = [
            RGBColor(31, 119, 180),
            RGBColor(44, 160, 44),
            RGBColor(148, 103, 189),
            RGBColor(140, 86, 75),
            RGBColor(255, 127, 14),
        ];
        let mut lines = Vec::new();
        let mut labels = Vec::new();
        for (i, cand) in rd.candidates.iter().enumerate() {
            let pts: Vec<(f64, f64)> = RANGE_STATES.iter().zip(&cand.errors).map(|(s, e)| (*s, 100.0 * e)).collect();
            let (color, width) =
                if i == rd.best { (RGBColor(214, 39, 40), 3) } else { (PALETTE[i % PALETTE.len()], 1) };
            let label = format!("designed at s = {:.2}{}", cand.s, if i == rd.best { " (the image)" } else { "" });
            draw_line(&mut c, &pts, yr, f64::INFINITY, color, width, i != rd.best, &label)?;
            lines.push(pts);
            labels.push(label);
        }
        let labels: Vec<&str> = labels.iter().map(String::as_str).collect();
        let data: Vec<&[(f64, f64)]> = lines.iter().map(Vec::as_slice).collect();
        legend_off_data(&mut c, SeriesLabelPosition::UpperMiddle, &labels, &data)?;
        root.present().map_err(perr)?;
    }
    Ok(buf)
}

/// Colours of the second FRF and of the model at its state in
/// [`plot_frf_fits`] (the first FRF keeps the single-state plot's).
const C_SECOND: (plotters::style::RGBColor, plotters::style::RGBColor) =
    (plotters::style::RGBColor(148, 103, 189), plotters::style::RGBColor(255, 127, 14));

/// Relative RMS misfit |Ĝ − G| / |G| of `model` against the measured
/// `meas` on the lines of `band` (Hz).
fn misfit(freq: &[f64], model: &crate::fit::PoleResidueModel, meas: &AxisFrf, band: (f64, f64)) -> f64 {
    let mask: Vec<bool> = freq.iter().map(|f| *f >= band.0 && *f <= band.1).collect();
    crate::fit::relative_rms_error(|f| model.frf(f), freq, &meas.frf, &mask)
}

/// The report's FRF-fit figure of an axis designed for the range: the
/// first FRF against the model at s = 0, the second against the model at
/// s = 1, each with its residual and coherence, and the model at the
/// image's state dashed; the misfits over the coherent band in the title.
pub fn plot_frf_fits(freq: &[f64], first: &AxisFrf, second: &AxisFrf, rd: &RangeDesign) -> Result<String> {
    use crate::report::design::FitPair;
    let chosen = &rd.candidates[rd.best];
    let d = &chosen.design;
    let band = d.coherent_band_hz;
    let (m0, m1, ms) = (rd.states.at(0.0), rd.states.at(1.0), rd.states.at(chosen.s));
    let on_lines = |m: &crate::fit::PoleResidueModel| freq.iter().map(|f| m.frf(*f)).collect::<Vec<_>>();
    let (e0, e1) = (misfit(freq, &m0, first, band), misfit(freq, &m1, second, band));
    let fits = [
        FitPair {
            meas: first,
            model: on_lines(&m0),
            measured: "measured G, first FRF".into(),
            fitted: "model at s = 0 (first state)".into(),
            colors: (plotters::style::RGBColor(31, 119, 180), plotters::style::RGBColor(214, 39, 40)),
        },
        FitPair {
            meas: second,
            model: on_lines(&m1),
            measured: "measured G, second FRF".into(),
            fitted: "model at s = 1 (second state)".into(),
            colors: C_SECOND,
        },
    ];
    let title = format!(
        "Axis {} — both measured FRFs, each against the model at its own state \
         (misfit {:.2} % / {:.2} % in the coherent band)",
        axis_name(first.axis),
        100.0 * e0,
        100.0 * e1
    );
    let reference = on_lines(&ms);
    let label = format!("model at s = {:.2} (the image's state)", chosen.s);
    crate::report::design::plot_frf_fits(freq, &fits, Some((&reference, &label)), d, &title)
}

/// An axis holding the first FRF's design over the range ([`HeldDesign`]):
/// both measured FRFs against the first FRF's model, the one the image and
/// `compensate --offline --drift` use at every state.
pub fn plot_held_frfs(freq: &[f64], first: &AxisFrf, second: &AxisFrf, h: &HeldDesign) -> Result<String> {
    use crate::report::design::FitPair;
    let d = &h.design;
    let band = d.coherent_band_hz;
    let model: Vec<_> = freq.iter().map(|f| d.model.frf(*f)).collect();
    let (e0, e1) = (misfit(freq, &d.model, first, band), misfit(freq, &d.model, second, band));
    let fits = [
        FitPair {
            meas: first,
            model: model.clone(),
            measured: "measured G, first FRF".into(),
            fitted: "the first FRF's model (held)".into(),
            colors: (plotters::style::RGBColor(31, 119, 180), plotters::style::RGBColor(214, 39, 40)),
        },
        FitPair {
            meas: second,
            model,
            measured: "measured G, second FRF".into(),
            fitted: "the same model".into(),
            colors: C_SECOND,
        },
    ];
    let title = format!(
        "Axis {} — NOT FOLLOWED: both measured FRFs against the first FRF's model, held over the range \
         (misfit {:.2} % / {:.2} % in the coherent band)",
        axis_name(first.axis),
        100.0 * e0,
        100.0 * e1
    );
    crate::report::design::plot_frf_fits(freq, &fits, None, d, &title)
}

/// Caption of [`plot_held_frfs`].
pub fn held_frfs_caption(h: &HeldDesign) -> String {
    format!(
        "Magnitude and phase of both measured FRFs (impact tests) against the first FRF's fitted model, which the box \
         image and `compensate --offline --drift` hold at every state: the two states could not be paired ({}). \
         Where the second FRF (violet) leaves the model, a cut in the second state is compensated with the first \
         state's model: predicted error {:.2} % on the first FRF, {:.2} % on the second. Below: each FRF's residual \
         against the model and both coherences. Shaded: the coherent band used for the design.",
        h.why,
        100.0 * h.measured.0,
        100.0 * h.measured.1
    )
}

/// Caption of [`plot_frf_fits`].
pub fn frf_fits_caption(rd: &RangeDesign) -> String {
    let s = rd.candidates[rd.best].s;
    format!(
        "Magnitude and phase of both measured FRFs (impact tests), each against the paired model at its own state: \
         the first FRF (blue) against the model at s = 0 (red), the second (violet) against the model at s = 1 \
         (orange). Dashed: the model at s = {s:.2}, the state the box image was designed for; it lies between the \
         two measurements and is judged against neither. Below: each FRF's residual against its own state's model \
         and both coherences. Shaded: the coherent band used for the design. Title: relative RMS misfit of each FRF \
         against its own state's model over the coherent band."
    )
}

/// The paired physical modes ("f0→f1") and the background terms of one
/// fit ("f Hz" pairs, "real pole f Hz") of the two states, by frequency.
fn paired_and_background(ts: &crate::design::two_state::model::TwoState) -> (Vec<String>, Vec<String>) {
    use crate::fit::modes::fn_hz;
    use crate::fit::Term;
    let mut moved = Vec::new();
    let mut background = Vec::new();
    for (i, (a, b)) in ts.before.terms.iter().zip(&ts.after.terms).enumerate() {
        match (*a, *b) {
            (Term::Pair { pole: p0, .. }, Term::Pair { pole: p1, .. }) if !ts.is_background(i) => {
                moved.push((fn_hz(p0), format!("{:.0}→{:.0}", fn_hz(p0), fn_hz(p1))));
            }
            (Term::Pair { pole, .. }, _) => background.push((fn_hz(pole), format!("{:.0} Hz", fn_hz(pole)))),
            (Term::Real { pole, .. }, _) => {
                let f = pole.abs() / (2.0 * std::f64::consts::PI);
                background.push((f, format!("real pole {f:.1} Hz")));
            }
        }
    }
    let sorted = |mut v: Vec<(f64, String)>| {
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        v.into_iter().map(|x| x.1).collect::<Vec<_>>()
    };
    (sorted(moved), sorted(background))
}

/// The shared machine modes' frequencies (Hz, mean of the two states).
pub fn shared_modes_hz(rd: &RangeDesign) -> Vec<String> {
    rd.machine.iter().filter(|m| m.shared).map(|m| format!("{:.0}", 0.5 * (m.fn_hz.0 + m.fn_hz.1))).collect()
}
