//! `dynocomp compare`'s tables and plots.

use anyhow::Result;
use plotters::prelude::*;
use std::fmt::Write as _;

use crate::design::bands::Band;
use crate::eval::compare::{AxisComparison, Comparison};

fn pct(v: Option<f64>) -> String {
    v.map_or("–".into(), |v| format!("{:.2}%", 100.0 * v))
}

/// The comparison as text tables, one per axis.
pub fn render(c: &Comparison) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "compare {} at fs {} Hz", c.frf, c.fs_hz);
    if c.bands.is_empty() {
        let _ = writeln!(s, "no fitting bands: \"in band\" = the coherent band");
    } else {
        let _ = writeln!(s, "fitting bands: {}", crate::design::bands::describe(&c.bands));
    }
    for ax in &c.axes {
        let _ =
            writeln!(s, "\naxis {} (coherent {:.0}–{:.0} Hz)", ax.axis, ax.coherent_band_hz.0, ax.coherent_band_hz.1);
        let _ = writeln!(
            s,
            "{:<28} {:>5} {:>8} {:>8} {:>8} {:>8} {:>13} {:>6} {:>3} {:>8} {:>8} {:>8} {:>5} {:>8}",
            "method",
            "order",
            "fit in",
            "fit out",
            "comp in",
            "comp out",
            "flat (Hz)",
            "noise",
            "L",
            "cond RFP",
            "cond GN",
            "cond obs",
            "rank",
            "time"
        );
        for r in &ax.rows {
            if let Some(diag) = &r.diagnostic {
                let _ = writeln!(
                    s,
                    "{:<28} FAILED after {:.0} ms: {}",
                    r.method,
                    r.design_time_s * 1e3,
                    short_diagnostic(diag)
                );
                continue;
            }
            let (c1, c2, c3, rank) = match &r.paper {
                Some(p) => (
                    format!("{:.1e}", p.rfp_condition),
                    format!("{:.1e}", p.jacobian_condition),
                    format!("{:.1e}", p.observability_condition),
                    format!("{}/{}", p.observability_rank, p.observability_dim),
                ),
                None => ("–".into(), "–".into(), "–".into(), "–".into()),
            };
            let flat = r.flat_band_hz.map_or("–".into(), |f| format!("{:.0}-{:.0}", f.0, f.1));
            let _ = writeln!(
                s,
                "{:<28} {:>5} {:>8} {:>8} {:>8} {:>8} {:>13} {:>6.2} {:>3} {:>8} {:>8} {:>8} {:>5} {:>6.0}ms",
                r.method,
                r.order.map_or("–".into(), |o| o.to_string()),
                pct(r.fit_error_in_band),
                pct(r.fit_error_out_of_band),
                pct(r.compensated_error_in_band),
                pct(r.compensated_error_out_of_band),
                flat,
                r.noise_gain.unwrap_or(f64::NAN),
                r.latency_samples.map_or("–".into(), |l| l.to_string()),
                c1,
                c2,
                c3,
                rank,
                r.design_time_s * 1e3
            );
        }
    }
    let _ = writeln!(
        s,
        "\nfit in/out: relative RMS |Ĝ−G|/|G| on coherent lines inside/outside the bands; comp in/out: RMS |H·G·e^(j2πfL/fs) − 1| with the f32 filter and the measured G; \
         flat: |H·Ĝ| within ±5 %/±5° of the delay from the first band line; noise: white-noise gain; L: latency (samples); cond: condition numbers of the RFP least squares, \
         the Gauss–Newton Jacobian and the observability matrix; rank: observability rank of the augmented system"
    );
    s
}

/// The first [`DIAG_CHARS`] characters of a failure's diagnostic, cut at a
/// word, for the table; compare.json keeps the whole message.
fn short_diagnostic(diag: &str) -> String {
    if diag.chars().count() <= DIAG_CHARS {
        return diag.to_string();
    }
    let cut: String = diag.chars().take(DIAG_CHARS).collect();
    let cut = cut.rsplit_once(' ').map_or(cut.as_str(), |(head, _)| head).trim_end_matches([',', ';', ':']);
    format!("{cut} … (whole message in compare.json)")
}

/// Characters of a failure's diagnostic in the table.
const DIAG_CHARS: usize = 110;

const COLORS: [RGBColor; 5] = [
    RGBColor(214, 39, 40),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
];

/// SVG of one axis: |H·G·delay| and the phase of every method that produced
/// a filter, with the fitting bands shaded. Earlier methods are drawn wider,
/// so a later one on top does not hide them; the legend sits in its own
/// column, and lists the methods that failed.
pub fn plot_axis(freq: &[f64], ax: &AxisComparison, bands: &[Band]) -> Result<String> {
    use crate::report::plot::{build_chart, draw_line, mesh, perr, shade, shade_bands, FONT};
    let xr = (freq[0], freq[freq.len() - 1].max(freq[0] + 1.0));
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 760)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let root = root
            .titled(&format!("Axis {} — compensated response H·G of each method (measured G)", ax.axis), (FONT, 20))
            .map_err(perr)?;
        let (plots, key) = root.split_horizontally(840);
        let (top, bot) = plots.split_vertically(370);
        let yr_m = (0.5, 1.5);
        let mut c = build_chart(&top, "Magnitude |H·G| (1 = exact)", xr, yr_m)?;
        mesh(&mut c, "Frequency (Hz)", "|H·G|", &crate::report::plot::hz, &|v| format!("{v:.1}"), 6)?;
        shade(&mut c, ax.coherent_band_hz, xr, yr_m, RGBColor(150, 150, 150), 0.10, "")?;
        shade_bands(&mut c, &crate::design::bands::ranges_hz(bands), xr, yr_m, false)?;
        let yr_p = (-45.0, 45.0);
        let mut cp = build_chart(&bot, "Phase ∠(H·G) (0 = exact)", xr, yr_p)?;
        mesh(&mut cp, "Frequency (Hz)", "Phase (°)", &crate::report::plot::hz, &|v| format!("{v:.0}"), 7)?;
        shade_bands(&mut cp, &crate::design::bands::ranges_hz(bands), xr, yr_p, false)?;
        let n = ax.rows.len() as u32;
        let mut entries: Vec<(String, Option<(RGBColor, u32)>)> = Vec::new();
        for (i, (r, color)) in ax.rows.iter().zip(COLORS.iter().cycle()).enumerate() {
            if r.compensated.is_empty() {
                entries.push((format!("{}: FAILED (see the table)", r.method), None));
                continue;
            }
            let width = 1 + (n - 1 - i as u32).min(2);
            let mag: Vec<(f64, f64)> = freq.iter().zip(&r.compensated).map(|(f, h)| (*f, h.norm())).collect();
            let ph: Vec<(f64, f64)> =
                freq.iter().zip(&r.compensated).map(|(f, h)| (*f, h.arg().to_degrees())).collect();
            draw_line(&mut c, &mag, yr_m, 0.3, *color, width, false, "")?;
            draw_line(&mut cp, &ph, yr_p, 30.0, *color, width, false, "")?;
            entries.push((r.method.clone(), Some((*color, width))));
        }
        draw_key(&key, &entries, !bands.is_empty())?;
        root.present().map_err(perr)?;
    }
    Ok(buf)
}

/// The legend column of [`plot_axis`]: a swatch and the name of each method
/// (failed ones in grey, without a swatch), then the shaded bands.
fn draw_key(
    area: &crate::report::plot::Area<'_>,
    entries: &[(String, Option<(RGBColor, u32)>)],
    bands: bool,
) -> Result<()> {
    use crate::report::plot::{perr, FONT};
    let mut y = 40;
    let text = |area: &crate::report::plot::Area<'_>, s: &str, y: i32, color: RGBColor| {
        area.draw(&Text::new(s.to_string(), (40, y - 7), (FONT, 13).into_font().color(&color))).map_err(perr)
    };
    for (name, style) in entries {
        match style {
            Some((color, width)) => {
                area.draw(&PathElement::new(vec![(4, y), (32, y)], ShapeStyle::from(color).stroke_width(*width)))
                    .map_err(perr)?;
                text(area, name, y, BLACK)?;
            }
            None => text(area, name, y, RGBColor(120, 120, 120))?,
        }
        y += 24;
    }
    y += 12;
    let swatches =
        [(RGBColor(150, 150, 150), 0.10, "coherent band"), (crate::report::plot::C_FIT_BAND, 0.18, "fitting bands")];
    for (color, alpha, name) in swatches.into_iter().filter(|s| bands || s.2 != "fitting bands") {
        area.draw(&Rectangle::new([(4, y - 6), (32, y + 6)], color.mix(alpha).filled())).map_err(perr)?;
        text(area, name, y, BLACK)?;
        y += 24;
    }
    Ok(())
}
