//! The 3x3 design's report (`design --report DIR` on a complete FRF
//! matrix): the measured matrix G_ij against its common-pole fit Ĝ_ij, and
//! per output axis i the error of each entry of the compensated matrix,
//! |(H·G·e^{j2πfL/fs})_ij − δ_ij| on the measured G (DESIGN.md "Signal
//! chain", the 3x3 system), for the filter the image holds and for the
//! per-axis filter alone, whose row is H_ii·G_ij.

use anyhow::Result;
use nalgebra::Matrix3;
use num_complex::Complex64;
use plotters::prelude::*;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use crate::design::mimo::{MatrixDesign, RowSource};
use crate::frf::{axis_name, Frf};
use crate::report::page::{index_html, write_pages, Page};
use crate::report::plot::{build_chart, draw_line, finite_range, legend, mesh, perr, shade, FONT};

const C_MEASURED: RGBColor = RGBColor(110, 110, 110);
const C_FIT: RGBColor = RGBColor(31, 119, 180);
const C_USED: RGBColor = RGBColor(214, 39, 40);
const C_BAND: RGBColor = RGBColor(44, 160, 44);
/// Where the image's filter is worse than raw (the design's WARNING).
const C_WORSE: RGBColor = RGBColor(255, 127, 14);

/// Write the report (index.html and its two plots) into `dir`; `summary`
/// is the design's text summary. Returns the written files.
pub fn write_matrix_report(
    dir: &Path,
    md: &MatrixDesign,
    frf: &Frf,
    fs_hz: f64,
    summary: &str,
) -> Result<Vec<PathBuf>> {
    let bands: [(f64, f64); 3] = std::array::from_fn(|i| md.summary.axes[i].band_hz);
    let g = measured_lines(frf, &bands);
    let entries = vec![
        (
            "matrix_frf.svg".to_string(),
            "The measured FRF matrix and its common-pole fit".to_string(),
            "Row i is the measured channel, column j the hammer direction; |G_ij| in dB re 1 N/N. Grey: the \
             impact test; blue: the fitted model Ĝ the 3x3 design runs on. Green: each row's compensated band. \
             Off-diagonal panels are the crosstalk the per-axis design leaves."
                .to_string(),
        ),
        (
            "matrix_rows.svg".to_string(),
            "What each output axis is left with, per force direction".to_string(),
            format!(
                "Panel (i, j): |(H·G·e^(j2πfL/fs))_ij − δ_ij| in dB, on the measured G at L = {} samples: the share of \
                 force j that reaches estimate i wrongly (on the diagonal, the distortion of force i itself). Red: \
                 the filter the image holds (row {}); grey dashed: the per-axis filter alone.{}{} −40 dB is 1 %.",
                md.summary.latency,
                (0..3)
                    .map(|i| format!(
                        "{} {}",
                        axis_name(i),
                        if md.rows[i] == RowSource::Matrix { "3x3" } else { "per axis" }
                    ))
                    .collect::<Vec<_>>()
                    .join(", "),
                worse_note(md),
                match &md.summary.reduction {
                    Some(r) if r.used => format!(
                        " Blue: the full {}-state 3x3 filter, which the image holds reduced to {} states to fit the \
                         box's load limit (the summary gives the predicted cost).",
                        r.full_states, r.states
                    ),
                    _ => String::new(),
                }
            ),
        ),
    ];
    let pages = vec![
        Page { name: "matrix_frf.svg".into(), content: plot_frf(md, &g, &bands)? },
        Page { name: "matrix_rows.svg".into(), content: plot_rows(md, &g, fs_hz, &bands)? },
        Page {
            name: "index.html".into(),
            content: index_html("dynocomp 3x3 design report", summary, &[("The 3x3 system".to_string(), entries)]),
        },
    ];
    write_pages(dir, &pages)
}

/// The caption's sentence on the orange spans: the rows whose image filter
/// is worse than raw there (empty where none is).
fn worse_note(md: &MatrixDesign) -> String {
    let rows: Vec<String> = md
        .summary
        .worse_than_raw
        .iter()
        .map(|w| format!("{} {:.0}-{:.0} Hz", w.axis, w.worse_hz.0, w.worse_hz.1))
        .collect();
    match rows.is_empty() {
        true => String::new(),
        false => format!(
            " Orange: where the image's filter leaves the estimate further from the force than no compensation \
             ({}; the WARNING of the summary).",
            rows.join(", ")
        ),
    }
}

/// dB of a magnitude, floored at −120 dB.
fn db(v: f64) -> f64 {
    20.0 * v.max(1e-6).log10()
}

/// One line of a panel: points (Hz, dB), colour, dashed, legend label.
type Series<'a> = (Vec<(f64, f64)>, RGBColor, bool, &'a str);

/// A 3x3 grid of panels of (x, y) lines (one list of series per panel:
/// points, colour, dashed, label), shaded over each row's band, and in
/// orange over the span `worse[i]` (Hz) of row i where there is one.
fn grid(
    title: &str,
    x_max: f64,
    bands: &[(f64, f64); 3],
    worse: &[Option<(f64, f64)>; 3],
    panels: &[Vec<Series<'_>>],
) -> Result<String> {
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 900)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let root = root.titled(title, (FONT, 18)).map_err(perr)?;
        let all = panels.iter().flatten().flat_map(|(pts, ..)| pts.iter().map(|p| p.1));
        let (lo, hi) = finite_range(all).unwrap_or((-80.0, 20.0));
        let yr = (lo.max(-100.0) - 3.0, hi + 3.0);
        let xr = (0.0, x_max);
        for (k, area) in root.split_evenly((3, 3)).iter().enumerate() {
            let (i, j) = (k / 3, k % 3);
            let caption =
                format!("{}{}: channel {}, hammer {}", axis_name(i), axis_name(j), axis_name(i), axis_name(j));
            let mut c = build_chart(area, &caption, xr, yr)?;
            mesh(&mut c, "Hz", "dB", &crate::report::plot::hz, &|v| format!("{v:.0}"), 6)?;
            shade(&mut c, bands[i], xr, yr, C_BAND, 0.06, "")?;
            if let Some(span) = worse[i] {
                shade(&mut c, span, xr, yr, C_WORSE, 0.2, "")?;
            }
            for (pts, color, dashed, label) in &panels[k] {
                let label = if k == 0 { label } else { "" };
                draw_line(&mut c, pts, yr, f64::INFINITY, *color, 1, *dashed, label)?;
            }
            if k == 0 {
                legend(&mut c, SeriesLabelPosition::UpperLeft)?;
            }
        }
        root.present().map_err(perr)?;
    }
    Ok(buf)
}

/// Most points a line of a panel has (an SVG of 9 panels stays light).
const MAX_POINTS: usize = 700;

/// A line of the measured matrix: frequency (Hz) and G (N/N).
type MeasuredLine = (f64, Matrix3<Complex64>);

/// The measured matrix on its lines up to the widest band's top, thinned
/// to [`MAX_POINTS`]: what both plots draw.
fn measured_lines(frf: &Frf, bands: &[(f64, f64); 3]) -> Vec<MeasuredLine> {
    let top = bands.iter().fold(0.0f64, |m, b| m.max(b.1));
    let inside: Vec<usize> = (0..frf.freq_hz.len()).filter(|&k| frf.freq_hz[k] <= top * 1.05).collect();
    let step = inside.len().div_ceil(MAX_POINTS).max(1);
    inside.into_iter().step_by(step).filter_map(|k| frf.matrix_at(k).map(|m| (frf.freq_hz[k], m))).collect()
}

fn plot_frf(md: &MatrixDesign, g: &[MeasuredLine], bands: &[(f64, f64); 3]) -> Result<String> {
    let panels = (0..9)
        .map(|e| {
            let (i, j) = (e / 3, e % 3);
            let mut s =
                vec![(g.iter().map(|(f, m)| (*f, db(m[(i, j)].norm()))).collect(), C_MEASURED, false, "measured")];
            if let Some(model) = &md.model {
                let fit = g.iter().map(|(f, _)| (*f, db(model.frf(*f)[(i, j)].norm()))).collect();
                s.push((fit, C_FIT, false, "fitted Ĝ (common poles)"));
            }
            s
        })
        .collect::<Vec<_>>();
    let x_max = g.last().map_or(1.0, |p| p.0);
    grid("|G_ij|: the measured matrix and its fit", x_max, bands, &[None; 3], &panels)
}

fn plot_rows(md: &MatrixDesign, g: &[MeasuredLine], fs_hz: f64, bands: &[(f64, f64); 3]) -> Result<String> {
    let lag = md.summary.latency as f64;
    let freqs: Vec<f64> = g.iter().map(|p| p.0).collect();
    let used: Vec<[[Complex64; 3]; 3]> = freqs.iter().map(|f| md.realization.freq_response(*f, fs_hz)).collect();
    let per_axis: Vec<Option<Vec<Complex64>>> =
        md.per_axis.iter().map(|a| a.as_ref().map(|a| a.kalman.compensator.freq_responses(&freqs, fs_hz))).collect();
    let full: Option<Vec<[[Complex64; 3]; 3]>> = md.full_compensator.as_ref().map(|c| {
        let h = c.freq_responses(&freqs, fs_hz);
        h.iter().map(|h| std::array::from_fn(|i| std::array::from_fn(|j| h[(i, j)]))).collect()
    });
    let delay = |f: f64| Complex64::from_polar(1.0, 2.0 * PI * f * lag / fs_hz);
    let delta = |i: usize, j: usize| if i == j { 1.0 } else { 0.0 };
    // Panel (i, j) of a 3x3 filter's responses `hs` on the lines of `g`.
    let residual = |hs: &[[[Complex64; 3]; 3]], i: usize, j: usize| -> Vec<(f64, f64)> {
        g.iter()
            .zip(hs)
            .map(|((f, m), h)| {
                let hg = (0..3).map(|k| h[i][k] * m[(k, j)]).sum::<Complex64>() * delay(*f);
                (*f, db((hg - delta(i, j)).norm()))
            })
            .collect()
    };
    let panels = (0..9)
        .map(|e| {
            let (i, j) = (e / 3, e % 3);
            let red = residual(&used, i, j);
            // The per-axis line first, so that the image's filter is drawn on top.
            let mut s = Vec::new();
            if let Some(h) = &per_axis[i] {
                let grey = g
                    .iter()
                    .zip(h)
                    .map(|((f, m), h)| (*f, db((h * m[(i, j)] * delay(*f) - delta(i, j)).norm())))
                    .collect();
                s.push((grey, C_MEASURED, true, "per-axis filter alone"));
            }
            if let Some(h) = &full {
                s.push((residual(h, i, j), C_FIT, false, "full filter (--full-order)"));
            }
            s.push((red, C_USED, false, "the image's filter"));
            s
        })
        .collect::<Vec<_>>();
    let x_max = freqs.last().copied().unwrap_or(1.0);
    let worse = std::array::from_fn(|i| {
        md.summary.worse_than_raw.iter().find(|w| w.axis == axis_name(i)).map(|w| widen(w.worse_hz, &freqs))
    });
    grid("|(H·G·e^(jωL))_ij − δ_ij| on the measured matrix", x_max, bands, &worse, &panels)
}

/// A span of FRF lines widened by half a line spacing on each side, so
/// that a single line shows.
fn widen((lo, hi): (f64, f64), freqs: &[f64]) -> (f64, f64) {
    let df = freqs.windows(2).map(|w| w[1] - w[0]).find(|d| *d > 0.0).unwrap_or(1.0);
    (lo - 0.5 * df, hi + 0.5 * df)
}
