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

/// Legend font size (px) and the margin inside its frame (px), as
/// [`legend`] draws it.
const LEGEND_FONT: u32 = 13;
const LEGEND_MARGIN: i32 = 8;
/// Width of the legend's swatch column (plotters' default, px).
const LEGEND_SWATCH: i32 = 30;

/// The size (px) of the frame [`legend`] draws around `labels`, computed as
/// plotters lays it out (its text estimate, swatch column and margins).
pub fn legend_size(labels: &[&str]) -> (i32, i32) {
    let mut text = MultiLineText::<_, &str>::new((0, 0), (FONT, LEGEND_FONT));
    for l in labels {
        text.push_line(*l);
    }
    let (w, h) = text.estimate_dimension().unwrap_or((8 * LEGEND_FONT as i32, 20 * labels.len() as i32));
    (w + LEGEND_SWATCH + 2 * LEGEND_MARGIN, h + 2 * LEGEND_MARGIN)
}

/// The corners and edge middles a legend may take, in order of preference
/// when several cover no data.
const LEGEND_SPOTS: [SeriesLabelPosition; 8] = [
    SeriesLabelPosition::UpperRight,
    SeriesLabelPosition::UpperLeft,
    SeriesLabelPosition::LowerRight,
    SeriesLabelPosition::LowerLeft,
    SeriesLabelPosition::UpperMiddle,
    SeriesLabelPosition::LowerMiddle,
    SeriesLabelPosition::MiddleRight,
    SeriesLabelPosition::MiddleLeft,
];

/// Steps of the grid of further legend positions [`legend_spot`] tries
/// across the plot area's width and height.
const GRID_STEPS: i32 = 10;

/// The frame (x0, y0, x1, y1, px from the plot area's top left) plotters
/// gives a legend of size `(w, h)` at `pos` in a plot area of `dim` px.
fn legend_frame(pos: &SeriesLabelPosition, (w, h): (i32, i32), dim: (u32, u32)) -> (i32, i32, i32, i32) {
    use SeriesLabelPosition::*;
    let (aw, ah) = (dim.0 as i32, dim.1 as i32);
    let x = match pos {
        UpperLeft | MiddleLeft | LowerLeft => 5,
        UpperMiddle | MiddleMiddle | LowerMiddle => (aw - w) / 2,
        UpperRight | MiddleRight | LowerRight => aw - w - 5,
        Coordinate(x, _) => *x,
    };
    let y = match pos {
        UpperLeft | UpperMiddle | UpperRight => 5,
        MiddleLeft | MiddleMiddle | MiddleRight => (ah - h) / 2,
        LowerLeft | LowerMiddle | LowerRight => ah - h - 5,
        Coordinate(_, y) => *y,
    };
    (x, y, x + w, y + h)
}

/// A data point's pixel position (x, y) in the drawing area.
type ToPixel<'a> = dyn Fn(&(f64, f64)) -> (i32, i32) + 'a;

/// How many pixels of the polylines `data` (chart coordinates, pixel
/// positions `to_px`) fall inside `frame`: every vertex, and points every
/// 3 px along each segment, so that a line crossing the frame between two
/// distant vertices counts too. Non-finite points break a line.
fn covered(data: &[&[(f64, f64)]], to_px: &ToPixel<'_>, frame: (i32, i32, i32, i32)) -> usize {
    let inside = |(x, y): (f64, f64)| {
        x >= f64::from(frame.0) && x <= f64::from(frame.2) && y >= f64::from(frame.1) && y <= f64::from(frame.3)
    };
    let mut n = 0;
    for line in data {
        let mut prev: Option<(f64, f64)> = None;
        for p in line.iter() {
            if !(p.0.is_finite() && p.1.is_finite()) {
                prev = None;
                continue;
            }
            let (x, y) = to_px(p);
            let q = (f64::from(x), f64::from(y));
            match prev {
                Some(a) => {
                    let steps = ((q.0 - a.0).abs().max((q.1 - a.1).abs()) / 3.0).ceil().clamp(1.0, 1e4) as usize;
                    n += (1..=steps)
                        .filter(|k| {
                            let t = *k as f64 / steps as f64;
                            inside((a.0 + t * (q.0 - a.0), a.1 + t * (q.1 - a.1)))
                        })
                        .count();
                }
                None => n += usize::from(inside(q)),
            }
            prev = Some(q);
        }
    }
    n
}

/// The legend position that covers the fewest pixels of `data` (chart
/// coordinates): `preferred`, then [`LEGEND_SPOTS`], then a grid over the
/// plot area, in that order; the first with the least cover wins. Returns it with the pixels it covers.
pub fn legend_spot(
    chart: &Chart<'_>,
    preferred: SeriesLabelPosition,
    labels: &[&str],
    data: &[&[(f64, f64)]],
) -> (SeriesLabelPosition, usize) {
    let area = chart.plotting_area();
    let base = area.get_base_pixel();
    let dim = area.dim_in_pixel();
    let to_px = |p: &(f64, f64)| {
        let (x, y) = chart.backend_coord(p);
        (x - base.0, y - base.1)
    };
    let size = legend_size(labels);
    // After the named spots, a grid of frames over the whole plot area.
    let (aw, ah) = (dim.0 as i32, dim.1 as i32);
    let grid = (0..=GRID_STEPS).flat_map(move |i| {
        (0..=GRID_STEPS).map(move |j| {
            let x = 5 + (aw - size.0 - 10).max(0) * i / GRID_STEPS;
            let y = 5 + (ah - size.1 - 10).max(0) * j / GRID_STEPS;
            SeriesLabelPosition::Coordinate(x, y)
        })
    });
    let mut best = (preferred.clone(), usize::MAX);
    for pos in std::iter::once(preferred).chain(LEGEND_SPOTS).chain(grid) {
        let n = covered(data, &to_px, legend_frame(&pos, size, dim));
        if n < best.1 {
            best = (pos, n);
        }
    }
    best
}

/// Draw the legend of `labels` where it covers the fewest pixels of `data`
/// ([`legend_spot`]).
pub fn legend_off_data<'a>(
    chart: &mut Chart<'a>,
    preferred: SeriesLabelPosition,
    labels: &[&str],
    data: &[&[(f64, f64)]],
) -> Result<()> {
    let (pos, _) = legend_spot(chart, preferred, labels, data);
    legend(chart, pos)
}

/// `yr` raised at the top so that a legend of `entries` lines fits above
/// the data in a plot area of `plot_px` pixels' height: for traces that
/// fill their frame from edge to edge (time records, spectra).
pub fn legend_headroom(yr: (f64, f64), entries: usize, plot_px: u32) -> (f64, f64) {
    let need = f64::from(legend_size(&vec!["M"; entries]).1 + 10);
    let free = (f64::from(plot_px) - need).max(0.25 * f64::from(plot_px));
    (yr.0, yr.0 + (yr.1 - yr.0) * f64::from(plot_px) / free)
}

/// The height (px) of the plot area [`build_chart`] leaves on `area`: less
/// its margins, caption and x-label area (the caption's height estimated).
pub fn plot_px_height(area: &Area<'_>) -> u32 {
    area.dim_in_pixel().1.saturating_sub(6 + 4 + 44 + 26)
}

pub fn legend<'a>(chart: &mut Chart<'a>, pos: SeriesLabelPosition) -> Result<()> {
    chart
        .configure_series_labels()
        .position(pos)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .label_font((FONT, LEGEND_FONT))
        .margin(LEGEND_MARGIN as u32)
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

/// A tick of a log10 % axis: the value 10^v (%), one decimal from 1 %, two below.
pub fn log_pct_tick(v: &f64) -> String {
    let p = 10f64.powf(*v);
    if p >= 1.0 {
        format!("{p:.1}")
    } else {
        format!("{p:.2}")
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1100 × 440 chart over x, y ∈ [0, 1] drawn into a scratch SVG, given to `f`.
    fn with_chart<R>(yr: (f64, f64), f: impl FnOnce(&mut Chart<'_>) -> R) -> R {
        let mut buf = String::new();
        let root = SVGBackend::with_string(&mut buf, (1100, 440)).into_drawing_area();
        let mut c = build_chart(&root, "test", (0.0, 1.0), yr).unwrap();
        f(&mut c)
    }

    const LABELS: [&str; 3] = ["measured", "compensated", "true"];

    #[test]
    fn the_legend_moves_off_data_in_its_preferred_corner() {
        // A cloud in the upper right quarter only, another line along the bottom.
        let cloud: Vec<(f64, f64)> = (0..2000)
            .map(|k| (0.6 + 0.4 * ((k * 37) % 100) as f64 / 100.0, 0.6 + 0.4 * (k % 97) as f64 / 97.0))
            .collect();
        let floor: Vec<(f64, f64)> = (0..=100).map(|k| (k as f64 / 100.0, 0.05)).collect();
        with_chart((0.0, 1.0), |c| {
            let data: [&[(f64, f64)]; 2] = [&cloud, &floor];
            let (pos, n) = legend_spot(c, SeriesLabelPosition::UpperRight, &LABELS, &data);
            assert_eq!(n, 0, "a free spot exists (upper left)");
            assert!(matches!(pos, SeriesLabelPosition::UpperLeft), "{pos:?}");
            // Control: the fixed upper-right legend covers the cloud.
            let area = c.plotting_area();
            let base = area.get_base_pixel();
            let to_px = |p: &(f64, f64)| {
                let (x, y) = c.backend_coord(p);
                (x - base.0, y - base.1)
            };
            let fixed = legend_frame(&SeriesLabelPosition::UpperRight, legend_size(&LABELS), area.dim_in_pixel());
            assert!(covered(&data, &to_px, fixed) > 100);
        });
    }

    #[test]
    fn headroom_frees_the_top_of_a_trace_that_fills_its_frame() {
        // A dense oscillation from the bottom to the top of its range: no
        // legend spot is free in that range; with the headroom the top is.
        let trace: Vec<(f64, f64)> = (0..=4000).map(|k| (k as f64 / 4000.0, (k as f64 * 0.7).sin())).collect();
        let yr = (-1.0, 1.0);
        let data: [&[(f64, f64)]; 1] = [&trace];
        let (_, n) = with_chart(yr, |c| legend_spot(c, SeriesLabelPosition::UpperRight, &LABELS, &data));
        assert!(n > 0, "control: the plain range leaves no spot free");
        let mut buf = String::new();
        let root = SVGBackend::with_string(&mut buf, (1100, 440)).into_drawing_area();
        let raised = legend_headroom(yr, LABELS.len(), plot_px_height(&root));
        assert!(raised.0 == yr.0 && raised.1 > yr.1);
        let (pos, n) = with_chart(raised, |c| legend_spot(c, SeriesLabelPosition::UpperRight, &LABELS, &data));
        assert_eq!(n, 0, "with headroom the legend clears the trace");
        assert!(matches!(pos, SeriesLabelPosition::UpperRight), "{pos:?}");
    }

    #[test]
    fn a_line_crossing_the_frame_between_vertices_counts() {
        let frame = (100, 100, 200, 200);
        let to_px = |p: &(f64, f64)| (p.0 as i32, p.1 as i32);
        let line: [(f64, f64); 2] = [(0.0, 150.0), (400.0, 150.0)];
        assert!(covered(&[&line], &to_px, frame) > 20);
        let outside: [(f64, f64); 2] = [(0.0, 250.0), (400.0, 250.0)];
        assert_eq!(covered(&[&outside], &to_px, frame), 0);
    }
}
