//! `dynocomp design --report DIR`: plots of each axis's design, as SVG, and
//! an `index.html` that shows the design summary and embeds them
//! ([`write_report`]).
//!
//! Every file is rendered in memory first, then written atomically
//! ([`crate::io::atomic`]); if writing fails, the files this run created are
//! removed again, so a report directory never holds a half-written file.
//! Plots use plotters' SVG backend without its font stack: text is emitted as
//! SVG `<text>` in a generic `sans-serif` family and laid out by the viewer.

use anyhow::{anyhow, bail, Context, Result};
use num_complex::Complex64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use crate::design::axis::AxisDesign;
use crate::design::bands::ranges_hz;
use crate::design::sensitivity::Sensitivity;
use crate::fit::Term;
use crate::frf::{axis_name, AxisFrf, Frf};
use crate::realize::quantize::filter_response;
use crate::report::page::{index_html, write_pages, Page, Section};
use crate::report::plot::*;

const C_MEASURED: RGBColor = RGBColor(31, 119, 180);
const C_MODEL: RGBColor = RGBColor(214, 39, 40);
const C_RAW: RGBColor = RGBColor(127, 127, 127);
const C_COH: RGBColor = RGBColor(44, 140, 44);
const C_TOL: RGBColor = RGBColor(230, 120, 0);
const C_COH_BAND: RGBColor = RGBColor(150, 150, 150);
const C_FLAT_BAND: RGBColor = RGBColor(44, 160, 44);
/// Lines where the box output is worse than raw (a non-minimum-phase zero).
const C_WORSE: RGBColor = RGBColor(214, 39, 40);
/// A further model drawn for reference (dashed), e.g. an interpolated state.
const C_REFERENCE: RGBColor = RGBColor(40, 40, 40);
/// Returns the paths written, `index.html` last.
pub fn write_report(
    dir: &Path,
    frf: &Frf,
    designs: &[AxisDesign],
    sensitivities: &[Option<Sensitivity>],
    fs_hz: f64,
    summary_text: &str,
) -> Result<Vec<PathBuf>> {
    write_report_with(dir, frf, designs, sensitivities, fs_hz, summary_text, &|_| Ok(Vec::new()))
}

/// A plot of a report: (file name, title, caption, SVG).
pub type Plot = (String, String, String, String);

/// [`write_report`] with `extra(axis)`'s plots in each axis's section
/// (e.g. the two-state design's range): one with the file name of a
/// standard plot takes its place, the others are appended.
pub fn write_report_with(
    dir: &Path,
    frf: &Frf,
    designs: &[AxisDesign],
    sensitivities: &[Option<Sensitivity>],
    fs_hz: f64,
    summary_text: &str,
    extra: &dyn Fn(usize) -> Result<Vec<Plot>>,
) -> Result<Vec<PathBuf>> {
    if !(fs_hz.is_finite() && fs_hz > 0.0) {
        bail!("report: sample rate fs = {fs_hz} Hz must be > 0");
    }
    if frf.freq_hz.is_empty() {
        bail!("report: the FRF has no frequency lines");
    }
    // Render everything in memory first: a plotting error writes nothing.
    let mut pages: Vec<Page> = Vec::new();
    let mut sections: Vec<Section> = Vec::new();
    for (i, d) in designs.iter().enumerate() {
        let name = axis_name(d.axis);
        let meas = frf.axis(d.axis).ok_or_else(|| anyhow!("report: the FRF has no measured data for axis {name}"))?;
        if meas.frf.len() != frf.freq_hz.len() {
            bail!("report: axis {name}: {} FRF values for {} frequency lines", meas.frf.len(), frf.freq_hz.len());
        }
        let mut plots = axis_plots(&frf.freq_hz, meas, d, sensitivities.get(i).and_then(Option::as_ref), fs_hz)?;
        for plot in extra(d.axis)? {
            match plots.iter_mut().find(|p| p.0 == plot.0) {
                Some(same) => *same = plot,
                None => plots.push(plot),
            }
        }
        let mut entries = Vec::new();
        for (file, title, caption, svg) in plots {
            entries.push((file.clone(), title, caption));
            pages.push(Page { name: file, content: svg });
        }
        sections.push((format!("Axis {name}"), entries));
    }
    let index = index_html("dynocomp design report", summary_text, &sections);
    pages.push(Page { name: "index.html".into(), content: index });
    write_pages(dir, &pages)
}

/// The plots of one design `d` against its measured FRF `meas`: the fit,
/// the compensated response and the pole map, then [`further_plots`].
fn axis_plots(
    freq: &[f64],
    meas: &AxisFrf,
    d: &AxisDesign,
    sens: Option<&Sensitivity>,
    fs_hz: f64,
) -> Result<Vec<Plot>> {
    let name = axis_name(d.axis);
    if let Some(why) = &d.pass_through {
        return Ok(vec![(
            format!("{name}_frf_fit.svg"),
            format!("Axis {name}: NOT COMPENSATED, passed through raw"),
            format!(
                "The measured FRF G and its coherence γ². The design could not compensate this axis ({}); \
                 the image outputs its measured force delayed by the latency (the flat line, Ĝ = 1).",
                why
            ),
            plot_frf_fit(freq, meas, d).with_context(|| format!("report: axis {name}: FRF plot"))?,
        )]);
    }
    let mut plots = vec![
        (
            format!("{name}_frf_fit.svg"),
            format!("Axis {name}: measured FRF and fitted model"),
            format!(
                "Magnitude and phase of the measured FRF G (impact test) with the fitted model Ĝ, \
                 and the coherence γ². Shaded: the coherent band used for the design{}.",
                if d.bands.is_empty() {
                    String::new()
                } else {
                    format!(" and, in violet, the fitting bands ({})", crate::design::bands::describe(&d.bands))
                }
            ),
            plot_frf_fit(freq, meas, d).with_context(|| format!("report: axis {name}: FRF plot"))?,
        ),
        (
            format!("{name}_compensated.svg"),
            format!("Axis {name}: compensated response H·G"),
            compensated_caption(d, measured_flat_band(freq, meas, d, fs_hz)),
            plot_compensated(freq, meas, d, fs_hz).with_context(|| format!("report: axis {name}: compensated plot"))?,
        ),
    ];
    let (poles_svg, zoom) = plot_poles(d, fs_hz).with_context(|| format!("report: axis {name}: pole map"))?;
    plots.push((
        format!("{name}_poles.svg"),
        format!("Axis {name}: pole map (z-plane)"),
        format!(
            "Poles of the compensator's modal sections (×) and of the fitted sensor model (○, z = exp(p/fs)): \
             the whole z-plane, and a zoom on the poles nearest z = 1 in the upper half plane ({zoom}, \
             equal scales).{}",
            if d.realization.fir.is_empty() {
                String::new()
            } else {
                format!(
                    " The compensator's fast poles are realized as {} FIR taps and are not shown.",
                    d.realization.fir.len()
                )
            }
        ),
        poles_svg,
    ));
    plots.extend(further_plots(d, sens, fs_hz)?);
    Ok(plots)
}

/// The plots of `d` that only some designs have: the discrete model's
/// match (default method), the sensitivity `sens` to moving sensor modes and
/// q for a record's force spectrum.
fn further_plots(d: &AxisDesign, sens: Option<&Sensitivity>, fs_hz: f64) -> Result<Vec<Plot>> {
    let name = axis_name(d.axis);
    let mut plots = Vec::new();
    if let Some((dm, _)) = &d.discrete {
        plots.push((
            format!("{name}_model_match.svg"),
            format!("Axis {name}: discrete model against the sampled-data relation"),
            format!(
                "The Kalman design's discrete model Ĝ_d ({}, advance {} samples, {} FIR taps) against the fitted Ĝ(j2πf), \
                 which relates the sampled force and measurement exactly for band-limited signals: |Ĝ_d/Ĝ − 1| in dB, \
                 beside the first- and zero-order holds. Shaded: the compensated band; the maximum there is the \
                 reported model match ({:.3} %).",
                dm.method.name(),
                dm.advance,
                dm.fir.len(),
                100.0 * d.model_match
            ),
            plot_model_match(d, dm, fs_hz).with_context(|| format!("report: axis {name}: model match plot"))?,
        ));
    }
    if let Some(sens) = sens {
        plots.push((
            format!("{name}_sensitivity.svg"),
            format!("Axis {name}: sensitivity to moving sensor modes"),
            crate::report::sensitivity::plot_caption(sens),
            crate::report::sensitivity::plot(name, sens)
                .with_context(|| format!("report: axis {name}: sensitivity plot"))?,
        ));
    }
    let spectrum = crate::report::force_spectrum::plot(d, fs_hz)
        .with_context(|| format!("report: axis {name}: force spectrum plot"))?;
    if let Some(svg) = spectrum {
        let s = d.force_spectrum.as_ref().expect("plotted only with a force spectrum");
        plots.push((
            format!("{name}_force_spectrum.svg"),
            format!("Axis {name}: q for the record's force spectrum"),
            crate::report::force_spectrum::plot_caption(s),
            svg,
        ));
    }
    Ok(plots)
}

// ------------------------------------------------------------ plot 1: FRF fit

/// `a_frf_fit.svg`: measured FRF magnitude (dB) and phase with the fitted
/// model overlaid, the fit's residual, and the coherence γ²; the coherent
/// band is shaded.
fn plot_frf_fit(freq: &[f64], meas: &AxisFrf, d: &AxisDesign) -> Result<String> {
    let (title, fitted) = match d.pass_through {
        Some(_) => (
            format!("Axis {} — NOT COMPENSATED: passed through raw; the measured FRF", axis_name(d.axis)),
            "no model: the output is the measurement (Ĝ = 1)",
        ),
        None => (
            format!(
                "Axis {} — measured FRF and fitted model (order {}, fit error {:.2} % in the {})",
                axis_name(d.axis),
                d.model.order(),
                100.0 * d.fit_nrmse,
                if d.bands.is_empty() { "coherent band" } else { "fitting bands" }
            ),
            "fitted model Ĝ",
        ),
    };
    let model = freq.iter().map(|f| d.fitted_frf(*f)).collect();
    let fit = FitPair {
        meas,
        model,
        measured: "measured G (on top)".into(),
        fitted: fitted.into(),
        colors: (C_MEASURED, C_MODEL),
    };
    plot_frf_fits(freq, &[fit], None, d, &title)
}

/// A measured FRF and the model it is judged against, with their legend
/// entries and colours (measured, model).
pub struct FitPair<'a> {
    pub meas: &'a AxisFrf,
    /// The model on the FRF's lines.
    pub model: Vec<Complex64>,
    pub measured: String,
    pub fitted: String,
    pub colors: (RGBColor, RGBColor),
}

/// The FRF-fit figure of one or more measured FRFs, each against its own
/// model (`fits`), with an optional further model drawn dashed (`reference`:
/// values on the lines and its legend entry): magnitude, phase, each fit's
/// residual and each FRF's coherence; `d`'s coherent and fitting bands shaded.
pub fn plot_frf_fits(
    freq: &[f64],
    fits: &[FitPair<'_>],
    reference: Option<(&[Complex64], &str)>,
    d: &AxisDesign,
    title: &str,
) -> Result<String> {
    let s: Vec<FitSeries> = fits.iter().map(|f| fit_series(freq, f)).collect();
    let r = reference.map(|(z, label)| (each_line(freq, z, db), each_line(freq, z, wrap_deg), label));
    let xr = x_range(freq);
    let mags = s.iter().flat_map(|x| x.mag_m.iter().chain(&x.mag_f)).chain(r.iter().flat_map(|r| &r.0));
    let (lo, hi) = finite_range(mags.map(|p| p.1)).unwrap_or((-20.0, 20.0));
    // keep the plot readable when a line has (almost) zero magnitude
    let yr_mag = pad_range((lo.max(hi - 80.0), hi), 0.06, 6.0);
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 1240)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let root = root.titled(title, (FONT, 20)).map_err(perr)?;
        let (top, rest) = root.split_vertically(380);
        let (midp, rest) = rest.split_vertically(300);
        let (resp, bot) = rest.split_vertically(260);
        let band = d.coherent_band_hz;
        let band_txt = match band.1 > band.0 {
            true => format!("coherent band {:.0}–{:.0} Hz", band.0, band.1),
            false => "no band compensated".to_string(),
        };
        let caption = format!("Magnitude |G| ({band_txt})");
        let magnitude = Panel::new(&caption, "|G| (dB re 1 N/N)", yr_mag, true);
        let mut c = magnitude.chart(&top, xr, d, &|v| format!("{v:.0}"), 7)?;
        let mag: Vec<_> = s.iter().map(|x| (&x.mag_f, &x.mag_m)).collect();
        let refm = r.as_ref().map(|r| (r.0.as_slice(), r.2));
        fitted_and_measured(&mut c, fits, &mag, refm, yr_mag, f64::INFINITY, SeriesLabelPosition::UpperLeft, d, true)?;
        let yr_ph = (-190.0, 190.0);
        let phase = Panel::new("Phase ∠G (wrapped)", "Phase (°)", yr_ph, false);
        let mut c = phase.chart(&midp, xr, d, &|v| format!("{v:.0}"), 9)?;
        let ph: Vec<_> = s.iter().map(|x| (&x.ph_f, &x.ph_m)).collect();
        let refp = r.as_ref().map(|r| (r.1.as_slice(), r.2));
        fitted_and_measured(&mut c, fits, &ph, refp, yr_ph, 180.0, SeriesLabelPosition::LowerLeft, d, false)?;
        fit_residual(&resp, fits, &s, xr, d)?;
        coherence(&bot, freq, fits, d, xr, &band_txt)?;
        root.present().map_err(perr)?;
    }
    Ok(buf)
}

/// What [`plot_frf_fits`] draws of one [`FitPair`], as (Hz, value) per line
/// of the FRF.
struct FitSeries {
    /// Measured and fitted magnitude (dB).
    mag_m: Vec<(f64, f64)>,
    mag_f: Vec<(f64, f64)>,
    /// Measured and fitted phase (°, wrapped).
    ph_m: Vec<(f64, f64)>,
    ph_f: Vec<(f64, f64)>,
    /// The residual |Ĝ − G|/|G| (log10 of %, 1e-4 % to 100 %).
    resid: Vec<(f64, f64)>,
}

/// `f` of each value `z` on the lines `freq`, as (Hz, value).
fn each_line(freq: &[f64], z: &[Complex64], f: fn(Complex64) -> f64) -> Vec<(f64, f64)> {
    freq.iter().zip(z).map(|(x, z)| (*x, f(*z))).collect()
}

/// The series of one fit of [`plot_frf_fits`].
fn fit_series(freq: &[f64], fit: &FitPair<'_>) -> FitSeries {
    let (g, model) = (&fit.meas.frf, &fit.model);
    let resid: Vec<(f64, f64)> = freq
        .iter()
        .zip(g)
        .zip(model)
        .map(|((f, g), m)| (*f, (100.0 * (m - g).norm() / g.norm()).clamp(1e-4, 1e3).log10()))
        .collect();
    FitSeries {
        mag_m: each_line(freq, g, db),
        mag_f: each_line(freq, model, db),
        ph_m: each_line(freq, g, wrap_deg),
        ph_f: each_line(freq, model, wrap_deg),
        resid,
    }
}

/// The frequency range of a plot (Hz): the FRF's lines, at least 1 Hz wide.
fn x_range(freq: &[f64]) -> (f64, f64) {
    let xr = (freq[0], *freq.last().unwrap_or(&freq[0]));
    if xr.1 > xr.0 {
        xr
    } else {
        (xr.0, xr.0 + 1.0)
    }
}

/// One panel over frequency of a design's plots: its caption, y axis and y
/// range; `labelled`: the coherent and fitting bands get legend entries.
struct Panel<'s> {
    caption: &'s str,
    y_desc: &'s str,
    yr: (f64, f64),
    labelled: bool,
}

impl<'s> Panel<'s> {
    fn new(caption: &'s str, y_desc: &'s str, yr: (f64, f64), labelled: bool) -> Self {
        Panel { caption, y_desc, yr, labelled }
    }

    /// The panel's chart on `area` over `xr` (Hz): its grid (`y_labels`
    /// labels formatted by `yfmt`), the coherent band and `d`'s fitting
    /// bands shaded.
    fn chart<'a>(
        &self,
        area: &Area<'a>,
        xr: (f64, f64),
        d: &AxisDesign,
        yfmt: &dyn Fn(&f64) -> String,
        y_labels: usize,
    ) -> Result<Chart<'a>> {
        let mut c = build_chart(area, self.caption, xr, self.yr)?;
        mesh(&mut c, "Frequency (Hz)", self.y_desc, &hz, yfmt, y_labels)?;
        let label = if self.labelled { "coherent band" } else { "" };
        shade(&mut c, d.coherent_band_hz, xr, self.yr, C_COH_BAND, 0.15, label)?;
        shade_bands(&mut c, &ranges_hz(&d.bands), xr, self.yr, self.labelled)?;
        Ok(c)
    }
}

/// The legend entries [`Panel::chart`] adds for `d`'s bands when labelled.
fn band_labels(d: &AxisDesign, labelled: bool) -> Vec<&'static str> {
    match (labelled, d.bands.is_empty()) {
        (false, _) => Vec::new(),
        (true, true) => vec!["coherent band"],
        (true, false) => vec!["coherent band", "fitting bands"],
    }
}

/// One fit's (fitted, measured) line, (Hz, value) points.
type FittedMeasured<'a> = (&'a Vec<(f64, f64)>, &'a Vec<(f64, f64)>);

/// Each fit's model line under its measurement's (`lines`: (fitted,
/// measured) per fit), then the `reference` model dashed, and the legend
/// off the lines (`pos` preferred; `banded`: the panel's bands are in it).
#[allow(clippy::too_many_arguments)]
fn fitted_and_measured(
    c: &mut Chart<'_>,
    fits: &[FitPair<'_>],
    lines: &[FittedMeasured<'_>],
    reference: Option<(&[(f64, f64)], &str)>,
    yr: (f64, f64),
    max_jump: f64,
    pos: SeriesLabelPosition,
    d: &AxisDesign,
    banded: bool,
) -> Result<()> {
    let mut labels = band_labels(d, banded);
    let mut data: Vec<&[(f64, f64)]> = Vec::new();
    for (fit, (fitted, _)) in fits.iter().zip(lines) {
        draw_line(c, fitted, yr, max_jump, fit.colors.1, 3, false, &fit.fitted)?;
        labels.push(&fit.fitted);
        data.push(fitted);
    }
    for (fit, (_, measured)) in fits.iter().zip(lines) {
        draw_line(c, measured, yr, max_jump, fit.colors.0, 1, false, &fit.measured)?;
        labels.push(&fit.measured);
        data.push(measured);
    }
    if let Some((pts, label)) = reference {
        draw_line(c, pts, yr, max_jump, C_REFERENCE, 1, true, label)?;
        labels.push(label);
        data.push(pts);
    }
    legend_off_data(c, pos, &labels, &data)
}

/// Each fit's residual |Ĝ − G|/|G| per line: where the fit departs from the
/// measurement, on a log scale (1e-4 % to 100 %).
fn fit_residual(area: &Area<'_>, fits: &[FitPair<'_>], s: &[FitSeries], xr: (f64, f64), d: &AxisDesign) -> Result<()> {
    let yr_r = (-4.0, 2.0);
    let panel = Panel::new("Residual |Ĝ − G| / |G| of the fit (%, log scale)", "residual (%)", yr_r, false);
    let mut c = panel.chart(area, xr, d, &|v| format!("{}", 10f64.powf(*v)), 7)?;
    let one = fits.len() == 1;
    let labels: Vec<String> =
        fits.iter().map(|f| if one { "residual".to_string() } else { format!("residual: {}", f.measured) }).collect();
    for ((fit, x), label) in fits.iter().zip(s).zip(&labels) {
        draw_line(&mut c, &x.resid, yr_r, f64::INFINITY, fit.colors.0, 1, false, label)?;
    }
    let labels: Vec<&str> = labels.iter().map(String::as_str).collect();
    let data: Vec<&[(f64, f64)]> = s.iter().map(|x| x.resid.as_slice()).collect();
    legend_off_data(&mut c, SeriesLabelPosition::UpperLeft, &labels, &data)
}

/// Each measured FRF's coherence γ², or a note that the FRF file has none.
fn coherence(
    area: &Area<'_>,
    freq: &[f64],
    fits: &[FitPair<'_>],
    d: &AxisDesign,
    xr: (f64, f64),
    band_txt: &str,
) -> Result<()> {
    let yr_c = (0.0, 1.05);
    let caption = format!("Coherence γ² ({band_txt})");
    let panel = Panel::new(&caption, "γ²", yr_c, true);
    let mut c = panel.chart(area, xr, d, &|v| format!("{v:.1}"), 6)?;
    let mut labels = band_labels(d, true);
    let mut names = Vec::new();
    let mut lines = Vec::new();
    for fit in fits {
        if let Some(coh) = &fit.meas.coherence {
            lines.push((freq.iter().zip(coh).map(|(f, c)| (*f, *c)).collect::<Vec<_>>(), fit.colors.0));
            names.push(if fits.len() == 1 { "coherence γ²".to_string() } else { format!("γ²: {}", fit.measured) });
        }
    }
    if lines.is_empty() {
        c.draw_series(std::iter::once(Text::new(
            "no coherence in the FRF file: the whole band counts as coherent",
            (xr.0 + 0.05 * (xr.1 - xr.0), 0.5),
            (FONT, 16),
        )))
        .map_err(perr)?;
    }
    for ((pts, color), name) in lines.iter().zip(&names) {
        let color = if fits.len() == 1 { C_COH } else { *color };
        draw_line(&mut c, pts, yr_c, f64::INFINITY, color, 2, false, name)?;
    }
    labels.extend(names.iter().map(String::as_str));
    let data: Vec<&[(f64, f64)]> = lines.iter().map(|l| l.0.as_slice()).collect();
    legend_off_data(&mut c, SeriesLabelPosition::LowerLeft, &labels, &data)
}

// ------------------------------------------------------------ plot 2: compensated

/// H·G·e^{j2πfL/fs} on every line: the f32 filter H as it goes into the
/// image, times `g` on the same lines, the declared latency L removed.
fn compensated(freq: &[f64], g: &[Complex64], d: &AxisDesign, fs: f64) -> Vec<Complex64> {
    let lag = d.kalman.lag as f64;
    freq.iter()
        .zip(g)
        .map(|(f, g)| filter_response(&d.filter, *f, fs) * Complex64::from_polar(1.0, 2.0 * PI * f * lag / fs) * g)
        .collect()
}

/// The flat band of the measured G (Hz): the longest run of lines in the
/// coherent band on which the measured H·G is flat (±5 %, ±5°,
/// [`crate::design::criterion::longest_flat_run`]); `None` if no line is.
/// The design's flat band (`AxisDesign::flat_band_hz`) is computed with the
/// fitted model Ĝ instead, which is free of the measurement's noise.
fn measured_flat_band(freq: &[f64], meas: &AxisFrf, d: &AxisDesign, fs: f64) -> Option<(f64, f64)> {
    crate::design::criterion::longest_flat_run(freq, &compensated(freq, &meas.frf, d, fs), d.coherent_band_hz)
}

/// "4–3480 Hz", or "none".
fn describe_band(band: Option<(f64, f64)>) -> String {
    band.map_or("none".into(), |(a, b)| format!("{a:.0}–{b:.0} Hz"))
}

/// The caption of [`plot_compensated`]; `flat` is [`measured_flat_band`].
fn compensated_caption(d: &AxisDesign, flat: Option<(f64, f64)>) -> String {
    let model_flat = Some(d.flat_band_hz).filter(|b| b.1 > b.0);
    let differ = if describe_band(model_flat) == describe_band(flat) {
        ""
    } else {
        " The two differ where the measurement's noise takes the measured ratio out of the tolerances while the \
         model's stays within them (or the reverse)."
    };
    format!(
        "The f32 compensator H times the measured G, with the declared latency of {} samples removed, against the \
         uncompensated G. Dashed orange: the ±5 % and ±5° tolerances. Grey: the coherent band ({}). Green bar (at \
         the bottom) and dashed green edges: the flat band of the measured G, the longest run of coherent lines on \
         which the measured |H·G| stays within ±5 % and its phase within ±5° ({}); orange ticks beside the bar: the \
         coherent lines on which it does not. The summary's flat band, where \
         |H·Ĝ| with the fitted model Ĝ stays within them from the band's bottom up, is {}.{differ}{}",
        d.kalman.lag,
        describe_band(Some(d.coherent_band_hz)),
        describe_band(flat),
        describe_band(model_flat),
        d.phase_limits
            .iter()
            .map(|p| format!(
                " Red: {:.0}–{:.0} Hz, where the box output is further from the force than the raw measurement: the model \
                 has a non-minimum-phase zero at {:.0} Hz (real part +{:.1} Hz), whose phase no causal compensator corrects \
                 (the summary's WARNING).",
                p.worse_hz.0, p.worse_hz.1, p.zero_hz.0, p.zero_hz.1
            ))
            .collect::<String>()
    )
}

/// `a_compensated.svg`: the compensated response H·G·e^{j2πfL/fs} (measured
/// G, the f32 filter H as it goes into the image, the declared latency L
/// removed) against the uncompensated G: an overview in dB and zooms of the
/// magnitude ratio and the phase with the ±5 % / ±5° tolerances; the
/// coherent band shaded and the measured G's flat band
/// ([`measured_flat_band`]) marked by a bar along the bottom.
fn plot_compensated(freq: &[f64], meas: &AxisFrf, d: &AxisDesign, fs: f64) -> Result<String> {
    let s = compensated_series(freq, meas, d, fs);
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 1000)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let flat_txt = format!("flat band of the measured G {}", describe_band(s.flat));
        let title = format!(
            "Axis {} — compensated response H·G (latency {} samples removed), {flat_txt}",
            axis_name(d.axis),
            d.kalman.lag
        );
        let root = root.titled(&title, (FONT, 20)).map_err(perr)?;
        let (top, rest) = root.split_vertically(340);
        let (midp, bot) = rest.split_vertically(320);
        compensated_overview(&top, &s, d)?;
        let magnitude = Zoom {
            panel: Panel::new("Magnitude ratio, zoom (tolerance ±5 %)", "|H·G| (N/N)", (0.8, 1.2), false),
            yfmt: &|v| format!("{v:.2}"),
            tolerance: ((1.05, 0.95), "±5 % tolerance"),
            max_jump: f64::INFINITY,
            lines: [
                (&s.mag_g, "uncompensated |G|"),
                (&s.mag_hg, "compensated |H·G| (measured G)"),
                (&s.mag_hgm, "|H·Ĝ| (fitted model)"),
            ],
        };
        magnitude.draw(&midp, &s, d)?;
        let phase = Zoom {
            panel: Panel::new("Phase, zoom (tolerance ±5°)", "Phase (°)", (-20.0, 20.0), false),
            yfmt: &|v| format!("{v:.0}"),
            tolerance: ((5.0, -5.0), "±5° tolerance"),
            max_jump: 180.0,
            lines: [
                (&s.ph_g, "uncompensated ∠G"),
                (&s.ph_hg, "compensated ∠H·G (measured G)"),
                (&s.ph_hgm, "∠H·Ĝ (fitted model)"),
            ],
        };
        phase.draw(&bot, &s, d)?;
        root.present().map_err(perr)?;
    }
    Ok(buf)
}

/// What [`plot_compensated`] draws, as (Hz, value) per line of the FRF: the
/// uncompensated G, the compensated H·G of the measured G and H·Ĝ of the
/// fitted model ([`compensated`]).
struct CompensatedSeries {
    /// Frequency range shown (Hz).
    xr: (f64, f64),
    /// |G| and |H·G| (dB), and the range shown.
    mag_g_db: Vec<(f64, f64)>,
    mag_hg_db: Vec<(f64, f64)>,
    yr_db: (f64, f64),
    /// |G|, |H·G| and |H·Ĝ| (N/N).
    mag_g: Vec<(f64, f64)>,
    mag_hg: Vec<(f64, f64)>,
    mag_hgm: Vec<(f64, f64)>,
    /// ∠G, ∠H·G and ∠H·Ĝ (°, wrapped).
    ph_g: Vec<(f64, f64)>,
    ph_hg: Vec<(f64, f64)>,
    ph_hgm: Vec<(f64, f64)>,
    /// The measured G's flat band ([`measured_flat_band`]).
    flat: Option<(f64, f64)>,
    /// The coherent lines (Hz) where the measured H·G is not flat: they end the run.
    off: Vec<f64>,
}

/// The series of [`plot_compensated`].
fn compensated_series(freq: &[f64], meas: &AxisFrf, d: &AxisDesign, fs: f64) -> CompensatedSeries {
    let hg = compensated(freq, &meas.frf, d, fs);
    let model: Vec<Complex64> = freq.iter().map(|f| d.fitted_frf(*f)).collect();
    let hg_model = compensated(freq, &model, d, fs);
    let g = &meas.frf;
    let each = |z: &[Complex64], f: fn(Complex64) -> f64| each_line(freq, z, f);
    let (mag_g_db, mag_hg_db) = (each(g, db), each(&hg, db));
    let (lo, hi) = finite_range(mag_g_db.iter().chain(&mag_hg_db).map(|p| p.1)).unwrap_or((-20.0, 20.0));
    let band = d.coherent_band_hz;
    let off: Vec<f64> = freq
        .iter()
        .zip(&hg)
        .filter(|(f, e)| **f >= band.0 && **f <= band.1 && !crate::design::criterion::is_flat(**e))
        .map(|(f, _)| *f)
        .collect();
    CompensatedSeries {
        xr: x_range(freq),
        yr_db: pad_range((lo.clamp(-60.0, -3.0), hi.clamp(3.0, 60.0)), 0.06, 6.0),
        mag_g_db,
        mag_hg_db,
        mag_g: each(g, |z| z.norm()),
        mag_hg: each(&hg, |z| z.norm()),
        mag_hgm: each(&hg_model, |z| z.norm()),
        ph_g: each(g, wrap_deg),
        ph_hg: each(&hg, wrap_deg),
        ph_hgm: each(&hg_model, wrap_deg),
        flat: measured_flat_band(freq, meas, d, fs),
        off,
    }
}

/// The flat band as a bar along the bottom of a panel and the coherent
/// lines off the tolerances as ticks beside it; legend entries if `labels`.
fn flat_band_marks(c: &mut Chart<'_>, s: &CompensatedSeries, yr: (f64, f64), labels: bool) -> Result<()> {
    // No flat line: an empty band, nothing drawn.
    let flat = s.flat.unwrap_or((f64::NAN, f64::NAN));
    let (bar, ticks) = if labels {
        ("flat band, measured G (±5 %, ±5°)", "coherent lines off the tolerances (measured)")
    } else {
        ("", "")
    };
    band_bar(c, flat, s.xr, yr, C_FLAT_BAND, bar)?;
    bottom_ticks(c, &s.off, yr, C_TOL, ticks)
}

/// Shade, over the chart's height, the lines around each non-minimum-phase
/// zero of `d`'s model where the box output is further from the force than
/// the raw measurement ([`crate::design::phase_limit`]); the legend entries
/// (one per zero) with `labels`. Returns them.
fn phase_limit_marks(
    c: &mut Chart<'_>,
    d: &AxisDesign,
    xr: (f64, f64),
    yr: (f64, f64),
    labels: bool,
) -> Result<Vec<String>> {
    let mut out = Vec::new();
    for p in &d.phase_limits {
        let label = format!("box worse than raw: non-minimum-phase zero at {:.0} Hz", p.zero_hz.0);
        shade(c, p.worse_hz, xr, yr, C_WORSE, 0.3, if labels { &label } else { "" })?;
        out.push(label);
    }
    Ok(out)
}

/// The overview of [`plot_compensated`]: |G| and |H·G| in dB.
fn compensated_overview(area: &Area<'_>, s: &CompensatedSeries, d: &AxisDesign) -> Result<()> {
    let panel = Panel::new("Magnitude, overview", "Magnitude (dB)", s.yr_db, true);
    let mut c = panel.chart(area, s.xr, d, &|v| format!("{v:.0}"), 7)?;
    let worse = phase_limit_marks(&mut c, d, s.xr, s.yr_db, true)?;
    flat_band_marks(&mut c, s, s.yr_db, true)?;
    draw_line(&mut c, &s.mag_g_db, s.yr_db, f64::INFINITY, C_RAW, 2, false, "uncompensated |G|")?;
    draw_line(&mut c, &s.mag_hg_db, s.yr_db, f64::INFINITY, C_MEASURED, 1, false, "compensated |H·G|")?;
    let mut labels = band_labels(d, true);
    labels.extend(worse.iter().map(|l| l.as_str()));
    labels.extend(["flat band, measured G (±5 %, ±5°)", "coherent lines off the tolerances (measured)"]);
    labels.extend(["uncompensated |G|", "compensated |H·G|"]);
    legend_off_data(&mut c, SeriesLabelPosition::UpperLeft, &labels, &[&s.mag_g_db, &s.mag_hg_db])
}

/// A zoom of [`plot_compensated`] on the tolerances: the uncompensated,
/// the compensated measured and the compensated fitted-model line.
struct Zoom<'s> {
    panel: Panel<'s>,
    yfmt: &'s dyn Fn(&f64) -> String,
    /// The tolerance lines (upper, lower) and their legend entry.
    tolerance: ((f64, f64), &'s str),
    /// Largest jump drawn as a line (wrapped phase).
    max_jump: f64,
    /// G, H·G and H·Ĝ with their legend entries.
    lines: [(&'s Vec<(f64, f64)>, &'s str); 3],
}

impl Zoom<'_> {
    fn draw(&self, area: &Area<'_>, s: &CompensatedSeries, d: &AxisDesign) -> Result<()> {
        let yr = self.panel.yr;
        let mut c = self.panel.chart(area, s.xr, d, self.yfmt, 9)?;
        phase_limit_marks(&mut c, d, s.xr, yr, false)?;
        flat_band_marks(&mut c, s, yr, false)?;
        let ((hi, lo), label) = self.tolerance;
        let tol = |y: f64| vec![(s.xr.0, y), (s.xr.1, y)];
        draw_line(&mut c, &tol(hi), yr, f64::INFINITY, C_TOL, 2, true, label)?;
        draw_line(&mut c, &tol(lo), yr, f64::INFINITY, C_TOL, 2, true, "")?;
        for ((pts, label), (color, width)) in self.lines.iter().zip([(C_RAW, 2), (C_MEASURED, 1), (C_MODEL, 2)]) {
            draw_line(&mut c, pts, yr, self.max_jump, color, width, false, label)?;
        }
        let mut labels = vec![label];
        labels.extend(self.lines.iter().map(|l| l.1));
        let data: Vec<&[(f64, f64)]> = self.lines.iter().map(|l| l.0.as_slice()).collect();
        legend_off_data(&mut c, SeriesLabelPosition::UpperMiddle, &labels, &data)
    }
}

// ------------------------------------------------------------ plot 3: poles

/// The fitted model's poles in the z-plane, z = exp(p/fs), conjugates included.
fn model_z_poles(d: &AxisDesign, fs: f64) -> Vec<Complex64> {
    let mut z = Vec::new();
    for t in &d.model.terms {
        match *t {
            Term::Real { pole, .. } => z.push(Complex64::new((pole / fs).exp(), 0.0)),
            Term::Pair { pole, .. } => {
                let p = (pole / fs).exp();
                z.push(p);
                z.push(p.conj());
            }
        }
    }
    z
}

/// The poles of the zoom panel: the cluster nearest to z = 1 (the slow,
/// machine-structure modes) in the upper half plane, cut at the largest
/// ratio gap between consecutive distances |1 − z| (below 0.9) if that gap
/// is at least 2×, otherwise every pole within 0.9 of z = 1; if none is
/// that near, every pole in the upper half plane.
fn zoom_poles(poles: &[Complex64]) -> Vec<Complex64> {
    let upper: Vec<Complex64> =
        poles.iter().copied().filter(|z| z.re.is_finite() && z.im.is_finite() && z.im >= 0.0).collect();
    let mut dist: Vec<f64> = upper.iter().map(|z| (1.0 - z).norm()).filter(|r| *r > 1e-9 && *r < 0.9).collect();
    dist.sort_by(f64::total_cmp);
    dist.dedup_by(|a, b| (*a / *b) < 1.02);
    let Some(&last) = dist.last() else {
        return upper;
    };
    let mut cut = last;
    let mut best = 2.0;
    for w in dist.windows(2) {
        let ratio = w[1] / w[0];
        if ratio >= best {
            best = ratio;
            cut = w[0];
        }
    }
    // dedup kept the first of near-equal distances: keep its neighbours too
    upper.into_iter().filter(|z| (1.0 - z).norm() <= 1.02 * cut).collect()
}

/// The zoom panel's window (Re z range, Im z range) for a plotting area of
/// `px` pixels, at equal scales: the bounding box of `poles`
/// ([`zoom_poles`]) with a margin of a fifth of its size on every side and
/// room for the mode labels (drawn left of their poles) on the left. A box
/// smaller than a fifth of its distance from z = 1 (one pole, or poles on a
/// line) is widened to that; with no poles, the window is 0.2 wide at z = 1.
fn zoom_window(poles: &[Complex64], px: (u32, u32)) -> ((f64, f64), (f64, f64)) {
    let Some((re0, re1)) = finite_range(poles.iter().map(|z| z.re)) else {
        return equal_aspect(0.95, 0.05, 0.1, 0.1, px);
    };
    let (im0, im1) = finite_range(poles.iter().map(|z| z.im)).unwrap_or((0.0, 0.0));
    let far = poles.iter().map(|z| (1.0 - z).norm()).fold(0.0, f64::max);
    let size = (re1 - re0).max(im1 - im0).max(0.2 * far).max(1e-9);
    let margin = 0.2 * size;
    let label_room = 0.25 * size;
    let (x0, x1) = (re0 - margin - label_room, re1 + margin);
    let (y0, y1) = (im0 - margin, im1 + margin);
    equal_aspect(0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * (x1 - x0), 0.5 * (y1 - y0), px)
}

/// "Re z 0.9820–1.0060, Im z 0.0420–0.0880": a window with enough decimals
/// to tell its edges apart.
fn describe_window((x0, x1): (f64, f64), (y0, y1): (f64, f64)) -> String {
    let span = (x1 - x0).min(y1 - y0).max(1e-12);
    let p = ((-span.log10()).ceil() + 1.0).clamp(1.0, 12.0) as usize;
    format!("Re z {x0:.p$}–{x1:.p$}, Im z {y0:.p$}–{y1:.p$}")
}

/// Pixel size of the plotting area a [`build_chart`] would get on an area of
/// `dim` pixels (measured on a scratch backend: the layout depends on the
/// caption's text size).
fn plot_area_px(dim: (u32, u32), caption: &str) -> Result<(u32, u32)> {
    let mut scratch = String::new();
    let area = SVGBackend::with_string(&mut scratch, dim).into_drawing_area();
    let c = build_chart(&area, caption, (0.0, 1.0), (0.0, 1.0))?;
    Ok(c.plotting_area().dim_in_pixel())
}

/// Ranges with equal scale on both axes around the given centre and minimum
/// half-spans, for a plotting area of `px` pixels.
fn equal_aspect(cx: f64, cy: f64, half_x: f64, half_y: f64, px: (u32, u32)) -> ((f64, f64), (f64, f64)) {
    let (w, h) = (px.0.max(1) as f64, px.1.max(1) as f64);
    let scale = (2.0 * half_x / w).max(2.0 * half_y / h); // data units per pixel
    let (hx, hy) = (0.5 * w * scale, 0.5 * h * scale);
    ((cx - hx, cx + hx), (cy - hy, cy + hy))
}

/// `a_poles.svg`, the pole map: the whole z-plane and a zoom framed on the
/// poles nearest z = 1, where the slow (machine-structure) modes sit
/// ([`zoom_poles`], [`zoom_window`]), with equal scales on both axes, the
/// unit circle, the fitted model's poles (○), the compensator's section
/// poles (×) and the model's modes named. Returns the SVG and, for the
/// caption, the zoom's window ([`describe_window`]).
fn plot_poles(d: &AxisDesign, fs: f64) -> Result<(String, String)> {
    let name = axis_name(d.axis);
    let comp = &d.realization.poles;
    let modelz = model_z_poles(d, fs);
    let all: Vec<Complex64> =
        comp.iter().chain(&modelz).copied().filter(|z| z.re.is_finite() && z.im.is_finite()).collect();

    let zoomed = zoom_poles(&all);

    let dim = (1100u32, 600u32);
    let panel = (dim.0 / 2, dim.1 - 40);
    let cap_full = "Whole z-plane";
    let cap_zoom = format!("Zoom on the {} poles nearest z = 1 (upper half plane)", zoomed.len());
    let px_full = plot_area_px(panel, cap_full)?;
    let px_zoom = plot_area_px(panel, &cap_zoom)?;
    let (xf, yf) = equal_aspect(0.0, 0.0, 1.15, 1.15, px_full);
    let (xz, yz) = zoom_window(&zoomed, px_zoom);
    let in_zoom = |z: &Complex64| z.re >= xz.0 && z.re <= xz.1 && z.im >= yz.0 && z.im <= yz.1;
    let max_r = comp.iter().map(|z| z.norm()).fold(0.0f64, f64::max);

    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, dim).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let title = format!(
            "Axis {name} — poles: {} compensator section poles (max |z| = {:.6}), {} model poles",
            comp.len(),
            max_r,
            modelz.len()
        );
        let root = root.titled(&title, (FONT, 20)).map_err(perr)?;
        let (left, right) = root.split_horizontally(panel.0);
        for (area, cap, xr, yr, full) in [(&left, cap_full, xf, yf, true), (&right, cap_zoom.as_str(), xz, yz, false)] {
            let mut c = build_chart(area, cap, xr, yr)?;
            mesh(&mut c, "Re z", "Im z", &fmt_num, &fmt_num, 9)?;
            draw_unit_circle(&mut c, xr, yr)?;
            let inr = |z: &&Complex64| z.re >= xr.0 && z.re <= xr.1 && z.im >= yr.0 && z.im <= yr.1;
            let ms = ShapeStyle::from(&C_MEASURED).stroke_width(2);
            c.draw_series(modelz.iter().filter(inr).map(|z| Circle::new((z.re, z.im), 6, ms)))
                .map_err(perr)?
                .label("fitted model, exp(p/fs)")
                .legend(move |(x, y)| Circle::new((x + 10, y), 6, ms));
            let cs = ShapeStyle::from(&C_MODEL).stroke_width(2);
            c.draw_series(comp.iter().filter(inr).map(|z| Cross::new((z.re, z.im), 5, cs)))
                .map_err(perr)?
                .label("compensator sections")
                .legend(move |(x, y)| Cross::new((x + 10, y), 5, cs));
            // In the zoom the modes inside it, in the whole plane those
            // outside the zoom.
            draw_mode_labels(&mut c, d, fs, &|z| inr(&z) && (!full || !in_zoom(z)))?;
            // Off the markers first (each weighs as a hundred pixels of
            // line) and the mode labels left of them (~120 px), then off
            // the unit circle.
            let px = if full { px_full } else { px_zoom };
            let left = 120.0 * (xr.1 - xr.0) / f64::from(px.0.max(1));
            let markers: Vec<Vec<(f64, f64)>> = modelz
                .iter()
                .chain(comp)
                .map(|z| std::iter::once((z.re - left, z.im)).chain(vec![(z.re, z.im); 100]).collect())
                .collect();
            let circle: Vec<(f64, f64)> =
                (0..=720).map(|k| (k as f64 * PI / 360.0).sin_cos()).map(|(s, c)| (c, s)).collect();
            let mut data: Vec<&[(f64, f64)]> = markers.iter().map(Vec::as_slice).collect();
            data.push(&circle);
            let labels = ["unit circle", "fitted model, exp(p/fs)", "compensator sections"];
            let preferred = if full { SeriesLabelPosition::LowerLeft } else { SeriesLabelPosition::UpperLeft };
            legend_off_data(&mut c, preferred, &labels, &data)?;
        }
        root.present().map_err(perr)?;
    }
    Ok((buf, describe_window(xz, yz)))
}

/// The unit circle inside the window `xr` × `yr`, sampled finely enough to
/// look smooth in it, split where the window cuts it.
fn draw_unit_circle(c: &mut Chart<'_>, (x0, x1): (f64, f64), (y0, y1): (f64, f64)) -> Result<()> {
    let n = ((2.0 * PI / ((y1 - y0) / 400.0)).ceil() as usize).clamp(720, 400_000);
    let circ: Vec<(f64, f64)> = (0..=n)
        .map(|i| {
            let t = 2.0 * PI * i as f64 / n as f64;
            (t.cos(), t.sin())
        })
        .filter(|(x, y)| *x >= x0 && *x <= x1 && *y >= y0 && *y <= y1)
        .collect();
    // the filter above may join the two ends across the gap of a zoom;
    // split where consecutive points are far apart
    let mut segs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for w in circ.windows(2) {
        if segs.last().is_some_and(|s| s.is_empty()) {
            segs.last_mut().unwrap().push(w[0]);
        }
        let far = ((w[1].0 - w[0].0).powi(2) + (w[1].1 - w[0].1).powi(2)).sqrt() > 0.05;
        if far {
            segs.push(Vec::new());
        } else {
            segs.last_mut().unwrap().push(w[1]);
        }
    }
    let st = ShapeStyle::from(&C_RAW).stroke_width(1);
    c.draw_series(segs.into_iter().filter(|s| s.len() >= 2).map(|s| PathElement::new(s, st)))
        .map_err(perr)?
        .label("unit circle")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], st));
    Ok(())
}

/// Name the model's modes (upper half plane) at their poles z = exp(p/fs)
/// by frequency and damping, those for which `show(z)` holds.
fn draw_mode_labels(c: &mut Chart<'_>, d: &AxisDesign, fs: f64, show: &dyn Fn(&Complex64) -> bool) -> Result<()> {
    let labels: Vec<(Complex64, String)> = d
        .model
        .terms
        .iter()
        .filter_map(|t| match *t {
            Term::Pair { pole, .. } => {
                let wn = pole.norm();
                let z = (pole / fs).exp();
                let zeta = 100.0 * -pole.re / wn;
                let prec = if zeta < 1.0 { 2 } else { 1 };
                Some((z, format!("{:.0} Hz, ζ {zeta:.prec$} %", wn / (2.0 * PI))))
            }
            _ => None,
        })
        .filter(|(z, _)| show(z))
        .collect();
    let font = (FONT, 12).into_font().color(&BLACK).pos(Pos::new(HPos::Right, VPos::Center));
    let label = |(z, s): (Complex64, String)| EmptyElement::at((z.re, z.im)) + Text::new(s, (-14, -6), font.clone());
    c.draw_series(labels.into_iter().map(label)).map_err(perr)?;
    Ok(())
}

// ------------------------------------------------------------ plot 4: model match

/// `a_model_match.svg` (default method): the discrete model's match to the
/// sampled-data relation, |Ĝ_d(e^{j2πf/fs})/Ĝ(j2πf) − 1| in dB over
/// 0..0.45 fs, for the design's discretization beside the first- and
/// zero-order holds of the same fitted Ĝ; the compensated band is shaded.
fn plot_model_match(d: &AxisDesign, dm: &crate::design::discretize::DiscreteModel, fs: f64) -> Result<String> {
    use crate::design::discretize::{discretize, Discretization, MATCH_BAND_FRACTION};
    let name = axis_name(d.axis);
    let f_hi = MATCH_BAND_FRACTION * fs;
    let xr = (0.0, f_hi);
    let grid: Vec<f64> = (1..=900).map(|i| f_hi * i as f64 / 900.0).collect();
    let curve = |m: &crate::design::discretize::DiscreteModel| -> Vec<(f64, f64)> {
        grid.iter().map(|f| (*f, 20.0 * ((m.frf(*f) / d.model.frf(*f) - 1.0).norm().max(1e-9)).log10())).collect()
    };
    let band = d.compensated_band_hz;
    let mut lines = vec![(curve(dm), C_MODEL, 2, format!("{} (this design)", dm.method.name()))];
    for m in [Discretization::Foh, Discretization::Zoh] {
        if m != dm.method {
            let (h, _) = discretize(&d.model, fs, m, band)?;
            lines.push((
                curve(&h),
                if m == Discretization::Foh { C_MEASURED } else { C_RAW },
                1,
                format!("{} (hold)", m.name()),
            ));
        }
    }
    let yr = (-100.0, 20.0);
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let title = format!(
            "Axis {name} — discrete model match |Ĝ_d/Ĝ − 1|: max {:.3} % in the compensated band",
            100.0 * d.model_match
        );
        let root = root.titled(&title, (FONT, 20)).map_err(perr)?;
        let mut c = build_chart(&root, "Relative model error (dB; −40 dB = 1 %, −60 dB = 0.1 %)", xr, yr)?;
        mesh(&mut c, "Frequency (Hz)", "|Ĝ_d/Ĝ − 1| (dB)", &hz, &|v| format!("{v:.0}"), 7)?;
        shade(&mut c, band, xr, yr, C_COH_BAND, 0.15, "compensated band")?;
        for (pts, col, w, label) in &lines {
            draw_line(&mut c, pts, yr, f64::INFINITY, *col, *w, false, label)?;
        }
        let mut labels = vec!["compensated band"];
        labels.extend(lines.iter().map(|l| l.3.as_str()));
        let data: Vec<&[(f64, f64)]> = lines.iter().map(|l| l.0.as_slice()).collect();
        legend_off_data(&mut c, SeriesLabelPosition::UpperLeft, &labels, &data)?;
        root.present().map_err(perr)?;
    }
    Ok(buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether every pole lies inside the window at least a tenth of its
    /// size from its edges, and the poles span at least 40 % of its height
    /// or width (the window is fitted to them, not just around them).
    fn framed(poles: &[Complex64], (x, y): ((f64, f64), (f64, f64))) -> bool {
        let (w, h) = (x.1 - x.0, y.1 - y.0);
        let inside = poles
            .iter()
            .all(|z| z.re >= x.0 + 0.1 * w && z.re <= x.1 - 0.1 * w && z.im >= y.0 + 0.1 * h && z.im <= y.1 - 0.1 * h);
        let (re, im) =
            (finite_range(poles.iter().map(|z| z.re)).unwrap(), finite_range(poles.iter().map(|z| z.im)).unwrap());
        inside && ((re.1 - re.0) >= 0.4 * w || (im.1 - im.0) >= 0.4 * h)
    }

    #[test]
    fn the_zoom_is_framed_on_the_poles_nearest_one() {
        let c = Complex64::new;
        // Slow modes at 470-600 Hz at 51.2 kHz, a sensor mode at 2.5 kHz.
        let slow = [c(0.9956, 0.0577), c(0.9941, 0.0680), c(0.9946, 0.0733), c(0.9958, 0.0554), c(0.9948, 0.0754)];
        let mut poles: Vec<Complex64> = slow.to_vec();
        poles.push(c(0.934, 0.300));
        poles.extend(slow.iter().map(|z| z.conj()));
        let zoomed = zoom_poles(&poles);
        assert_eq!(zoomed.len(), slow.len(), "{zoomed:?}");
        let px = (460, 480);
        assert!(framed(&zoomed, zoom_window(&zoomed, px)));
        // Control: a fixed window near z = 1 (Re 0.9-1.0) leaves them on its edge.
        assert!(!framed(&zoomed, equal_aspect(0.95, 0.045, 0.05, 0.05, px)));
        // Poles anywhere: one alone, and a cluster far from z = 1.
        for set in [vec![c(-0.5, 0.5)], vec![c(0.2, 0.7), c(0.25, 0.72), c(0.3, 0.6)]] {
            let zoomed = zoom_poles(&set);
            assert_eq!(zoomed.len(), set.len());
            let w = zoom_window(&zoomed, px);
            let inside = zoomed.iter().all(|z| z.re > w.0 .0 && z.re < w.0 .1 && z.im > w.1 .0 && z.im < w.1 .1);
            assert!(inside && (set.len() == 1 || framed(&zoomed, w)), "{set:?}: {w:?}");
        }
        assert!(describe_window((0.979, 1.006), (0.051, 0.079)).contains("Re z 0.979–1.006, Im z 0.051–0.079"));
    }
}
