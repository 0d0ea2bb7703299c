//! Plot helpers of every report: SVG charts drawn with plotters, lines
//! clipped to their frame, shaded bands, legends and axis labels. They know
//! nothing of designs; data arrive as numbers.
//!
//! Plots use plotters' SVG backend without its font stack: text is emitted as
//! SVG `<text>` in a generic `sans-serif` family and laid out by the viewer.

use anyhow::{anyhow, Result};
use num_complex::Complex64;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

/// Font family of all plot text (resolved by the SVG viewer).
pub const FONT: &str = "sans-serif";
/// Fitting bands (paper §3.2), shaded on the FRF and compensated plots.
pub const C_FIT_BAND: RGBColor = RGBColor(148, 103, 189);

pub type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;
pub type Chart<'a> = ChartContext<'a, SVGBackend<'a>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

pub fn perr<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("plotting failed: {e}")
}

/// Split a polyline into pieces inside `lo..=hi` (y), clipped exactly at the
/// bounds; non-finite points and jumps larger than `max_jump` (wrapped phase)
/// break the line.
pub fn clip_segments(points: &[(f64, f64)], lo: f64, hi: f64, max_jump: f64) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut cur: Vec<(f64, f64)> = Vec::new();
    let inside = |y: f64| y >= lo && y <= hi;
    let cross = |a: (f64, f64), b: (f64, f64), y: f64| -> (f64, f64) {
        let t = (y - a.1) / (b.1 - a.1);
        (a.0 + t * (b.0 - a.0), y)
    };
    let flush = |cur: &mut Vec<(f64, f64)>, out: &mut Vec<Vec<(f64, f64)>>| {
        if cur.len() >= 2 {
            out.push(std::mem::take(cur));
        } else {
            cur.clear();
        }
    };
    let mut prev: Option<(f64, f64)> = None;
    for &p in points {
        if !(p.0.is_finite() && p.1.is_finite()) {
            flush(&mut cur, &mut out);
            prev = None;
            continue;
        }
        let Some(a) = prev else {
            if inside(p.1) {
                cur.push(p);
            }
            prev = Some(p);
            continue;
        };
        if (p.1 - a.1).abs() > max_jump {
            flush(&mut cur, &mut out);
            if inside(p.1) {
                cur.push(p);
            }
            prev = Some(p);
            continue;
        }
        match (inside(a.1), inside(p.1)) {
            (true, true) => cur.push(p),
            (true, false) => {
                cur.push(cross(a, p, if p.1 > hi { hi } else { lo }));
                flush(&mut cur, &mut out);
            }
            (false, true) => {
                cur.push(cross(a, p, if a.1 > hi { hi } else { lo }));
                cur.push(p);
            }
            (false, false) => {
                if (a.1 < lo && p.1 > hi) || (a.1 > hi && p.1 < lo) {
                    let (y0, y1) = if a.1 < lo { (lo, hi) } else { (hi, lo) };
                    out.push(vec![cross(a, p, y0), cross(a, p, y1)]);
                }
            }
        }
        prev = Some(p);
    }
    flush(&mut cur, &mut out);
    out
}

/// (min, max) of the finite values, or `None`.
pub fn finite_range(v: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    v.filter(|x| x.is_finite()).fold(None, |acc, x| match acc {
        None => Some((x, x)),
        Some((a, b)) => Some((a.min(x), b.max(x))),
    })
}

pub fn pad_range((lo, hi): (f64, f64), frac: f64, min_span: f64) -> (f64, f64) {
    let span = (hi - lo).max(min_span);
    let mid = 0.5 * (lo + hi);
    (mid - 0.5 * span - frac * span, mid + 0.5 * span + frac * span)
}

pub fn db(z: Complex64) -> f64 {
    20.0 * z.norm().log10()
}

pub fn wrap_deg(z: Complex64) -> f64 {
    z.arg().to_degrees()
}

/// Draw a line (clipped to the chart's y range) with a legend entry.
#[allow(clippy::too_many_arguments)]
pub fn draw_line<'a>(
    chart: &mut Chart<'a>,
    pts: &[(f64, f64)],
    (ylo, yhi): (f64, f64),
    max_jump: f64,
    color: RGBColor,
    width: u32,
    dashed: bool,
    label: &str,
) -> Result<()> {
    let style = ShapeStyle::from(&color).stroke_width(width);
    let segs = clip_segments(pts, ylo, yhi, max_jump);
    if dashed {
        let mut first = true;
        for s in segs {
            let ann = chart.draw_series(DashedLineSeries::new(s, 6, 4, style)).map_err(perr)?;
            if first && !label.is_empty() {
                ann.label(label).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 8, y)], style));
                first = false;
            }
        }
        if first && !label.is_empty() {
            // nothing visible: still list it in the legend
            chart
                .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())
                .map_err(perr)?
                .label(label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 8, y)], style));
        }
    } else {
        let ann = chart.draw_series(segs.into_iter().map(|s| PathElement::new(s, style))).map_err(perr)?;
        if !label.is_empty() {
            ann.label(label).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        }
    }
    Ok(())
}

/// Shade the x interval `band` over the chart's full y range.
pub fn shade<'a>(
    chart: &mut Chart<'a>,
    band: (f64, f64),
    (xlo, xhi): (f64, f64),
    (ylo, yhi): (f64, f64),
    color: RGBColor,
    alpha: f64,
    label: &str,
) -> Result<()> {
    let (a, b) = (band.0.max(xlo), band.1.min(xhi));
    if b.is_nan() || a.is_nan() || b <= a {
        return Ok(());
    }
    let fill = color.mix(alpha).filled();
    let ann = chart.draw_series(std::iter::once(Rectangle::new([(a, ylo), (b, yhi)], fill))).map_err(perr)?;
    if !label.is_empty() {
        ann.label(label).legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 20, y + 6)], fill));
    }
    Ok(())
}

/// Mark the x interval `band` with a bar along the bottom of the chart (a
/// twentieth of its height) and dashed edges over its full height, so that a
/// band shaded underneath (e.g. the coherent band, [`shade`]) stays visible
/// where the two coincide. The legend shows the bar.
pub fn band_bar<'a>(
    chart: &mut Chart<'a>,
    band: (f64, f64),
    (xlo, xhi): (f64, f64),
    (ylo, yhi): (f64, f64),
    color: RGBColor,
    label: &str,
) -> Result<()> {
    let (a, b) = (band.0.max(xlo), band.1.min(xhi));
    if b.is_nan() || a.is_nan() || b < a {
        return Ok(());
    }
    let fill = color.mix(0.6).filled();
    let top = ylo + 0.05 * (yhi - ylo);
    let ann = chart.draw_series(std::iter::once(Rectangle::new([(a, ylo), (b, top)], fill))).map_err(perr)?;
    if !label.is_empty() {
        ann.label(label).legend(move |(x, y)| Rectangle::new([(x, y - 4), (x + 20, y + 4)], fill));
    }
    let edge = ShapeStyle::from(&color).stroke_width(1);
    for x in [a, b] {
        chart.draw_series(DashedLineSeries::new([(x, ylo), (x, yhi)], 5, 4, edge)).map_err(perr)?;
    }
    Ok(())
}

/// Short vertical ticks at `xs` in the bottom strip of the chart where
/// [`band_bar`] draws its bar (one legend entry, if there are any).
pub fn bottom_ticks<'a>(
    chart: &mut Chart<'a>,
    xs: &[f64],
    (ylo, yhi): (f64, f64),
    color: RGBColor,
    label: &str,
) -> Result<()> {
    let top = ylo + 0.05 * (yhi - ylo);
    let style = ShapeStyle::from(&color).stroke_width(1);
    let ann =
        chart.draw_series(xs.iter().map(|x| PathElement::new(vec![(*x, ylo), (*x, top)], style))).map_err(perr)?;
    if !label.is_empty() && !xs.is_empty() {
        ann.label(label).legend(move |(x, y)| {
            PathElement::new(
                (0..4).flat_map(|i| [(x + 6 * i, y + 5), (x + 6 * i, y - 5), (x + 6 * i, y + 5)]).collect::<Vec<_>>(),
                style,
            )
        });
    }
    Ok(())
}

/// Shade each fitting band (labelled once when `labelled`).
pub fn shade_bands<'a>(
    chart: &mut Chart<'a>,
    bands_hz: &[(f64, f64)],
    x: (f64, f64),
    y: (f64, f64),
    labelled: bool,
) -> Result<()> {
    for (i, b) in bands_hz.iter().enumerate() {
        let label = if labelled && i == 0 { "fitting bands" } else { "" };
        shade(chart, *b, x, y, C_FIT_BAND, 0.18, label)?;
    }
    Ok(())
}

pub fn legend<'a>(chart: &mut Chart<'a>, pos: SeriesLabelPosition) -> Result<()> {
    chart
        .configure_series_labels()
        .position(pos)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .label_font((FONT, 13))
        .margin(8)
        .draw()
        .map_err(perr)
}

pub fn build_chart<'a>(area: &Area<'a>, caption: &str, x: (f64, f64), y: (f64, f64)) -> Result<Chart<'a>> {
    ChartBuilder::on(area)
        .margin_top(6)
        .margin_bottom(4)
        .margin_left(10)
        .margin_right(20)
        .caption(caption, (FONT, 16))
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)
        .map_err(perr)
}

pub fn mesh<'a>(
    chart: &mut Chart<'a>,
    xdesc: &str,
    ydesc: &str,
    xfmt: &dyn Fn(&f64) -> String,
    yfmt: &dyn Fn(&f64) -> String,
    y_labels: usize,
) -> Result<()> {
    chart
        .configure_mesh()
        .x_desc(xdesc)
        .y_desc(ydesc)
        .axis_desc_style((FONT, 14))
        .label_style((FONT, 12))
        .x_labels(12)
        .y_labels(y_labels)
        .x_label_formatter(xfmt)
        .y_label_formatter(yfmt)
        .light_line_style(BLACK.mix(0.04))
        .bold_line_style(BLACK.mix(0.12))
        .draw()
        .map_err(perr)
}

pub fn hz(v: &f64) -> String {
    format!("{v:.0}")
}

/// A tick value with as few decimals as represent it (ticks are multiples of
/// a round step, up to floating-point noise).
pub fn fmt_num(v: &f64) -> String {
    let v = *v;
    if v.abs() < 1e-12 {
        return "0".into();
    }
    for p in 0..=8usize {
        let s = format!("{v:.p$}");
        if let Ok(r) = s.parse::<f64>() {
            if (r - v).abs() <= 1e-9 * v.abs().max(1e-3) {
                return s;
            }
        }
    }
    format!("{v:.3e}")
}
